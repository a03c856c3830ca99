//! Which protocol a byte stream speaks: APT (binary) or Elliptec (ASCII), judged by how much of
//! a sample each framer turns into clean frames.

use crate::apt::{AptFrame, AptFramer, Item as AptItem};
use crate::ell::{EllFrame, EllFramer, Item as EllItem};
use crate::Table;

/// A protocol.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Proto {
    /// Thorlabs APT, binary.
    Apt,
    /// Elliptec ELLx, ASCII.
    Elliptec,
}

impl Proto {
    /// `apt` or `elliptec`.
    pub fn name(self) -> &'static str {
        match self {
            Proto::Apt => "apt",
            Proto::Elliptec => "elliptec",
        }
    }
    /// The short code every record's `proto` key uses (`apt`, `ell`), as filters spell it.
    pub fn code(self) -> &'static str {
        match self {
            Proto::Apt => "apt",
            Proto::Elliptec => "ell",
        }
    }
}

/// The verdict on a sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    /// The protocol chosen, if one is clearly better.
    pub proto: Option<Proto>,
    /// Fraction of the sample in clean APT frames.
    pub apt: f64,
    /// Fraction of the sample in clean Elliptec frames.
    pub elliptec: f64,
}

/// Bytes of a stream worth looking at.
pub const SAMPLE: usize = 4096;

/// Judge a sample (the first [`SAMPLE`] bytes of a stream, or all of a shorter one). A protocol
/// wins when at least half the sample frames cleanly with it and clearly more than with the
/// other; otherwise the stream is mixed or unknown and `proto` is `None`.
pub fn detect(sample: &[u8]) -> Detection {
    let sample = &sample[..sample.len().min(SAMPLE)];
    if sample.is_empty() {
        return Detection {
            proto: None,
            apt: 0.0,
            elliptec: 0.0,
        };
    }
    let t = Table::global();
    let mut clean_apt = 0usize;
    let mut fa = AptFramer::new(t);
    fa.push(sample);
    fa.finish();
    while let Some(it) = fa.next_item() {
        if let AptItem::Frame {
            offset,
            bytes,
            truncated,
        } = it
        {
            if AptFrame::decode(t, offset, bytes, truncated).is_some_and(|f| !f.has_diags()) {
                clean_apt += bytes.len();
            }
        }
    }
    let mut clean_ell = 0usize;
    let mut fe = EllFramer::new();
    fe.push(sample);
    fe.finish();
    while let Some(it) = fe.next_item() {
        if let EllItem::Frame {
            offset,
            bytes,
            truncated,
        } = it
        {
            if EllFrame::decode(offset, bytes, truncated)
                .is_some_and(|f| f.cmd.is_some() && f.diags().is_empty())
            {
                clean_ell += bytes.len();
            }
        }
    }
    let n = sample.len() as f64;
    let (apt, elliptec) = (clean_apt as f64 / n, clean_ell as f64 / n);
    let proto = if apt >= 0.5 && apt > 1.5 * elliptec {
        Some(Proto::Apt)
    } else if elliptec >= 0.5 && elliptec > 1.5 * apt {
        Some(Proto::Elliptec)
    } else {
        None
    };
    Detection {
        proto,
        apt,
        elliptec,
    }
}
