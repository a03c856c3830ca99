//! From bytes to rendered records: protocol detection, framing, decoding, bus state and
//! pairing, text or NDJSON lines. Pure: the caller feeds chunks and writes the lines out.

use crate::apt::{AptFrame, AptFramer, Item as AptItem};
use crate::detect::{detect, Detection, Proto, SAMPLE};
use crate::diag::{Diag, DiagKind};
use crate::ell::{Bus, EllFrame, EllFramer, Expired, Item as EllItem};
use crate::{json, text, Table};
use std::fmt::Write;

/// Output format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// One tshark-like line per record.
    Text,
    /// One JSON object per line.
    Json,
}

/// The decoding pipeline for one byte stream.
pub struct Pipeline {
    fmt: Format,
    proto: Option<Proto>,
    /// Bytes held back until the protocol is known.
    sample: Vec<u8>,
    apt: AptFramer<'static>,
    ell: EllFramer,
    bus: Bus,
    n: u64,
    line: String,
}

impl Pipeline {
    /// A pipeline for `proto`, or auto-detection from the first 4 KiB when `None`.
    pub fn new(proto: Option<Proto>, fmt: Format) -> Self {
        Pipeline {
            fmt,
            proto,
            sample: vec![],
            apt: AptFramer::new(Table::global()),
            ell: EllFramer::new(),
            bus: Bus::new(),
            n: 0,
            line: String::with_capacity(512),
        }
    }

    /// The protocol in use (after detection).
    pub fn proto(&self) -> Option<Proto> {
        self.proto
    }

    /// Feed stream bytes; `ts` is the capture time (ns) of the chunk, when known. Each rendered
    /// record is passed to `emit` (without newline).
    pub fn push<E>(
        &mut self,
        chunk: &[u8],
        ts: Option<u64>,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        if self.proto.is_none() {
            self.sample.extend_from_slice(chunk);
            if self.sample.len() < SAMPLE {
                return Ok(());
            }
            let sample = std::mem::take(&mut self.sample);
            self.choose(&sample, emit)?;
            return self.feed(&sample, ts, emit);
        }
        self.feed(chunk, ts, emit)
    }

    /// Report a problem of the input itself (e.g. a bad character in hex text).
    pub fn input_diag<E>(
        &mut self,
        d: &Diag,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        self.line.clear();
        match self.fmt {
            Format::Json => {
                self.line.push_str("{\"type\":\"input\",\"diag\":");
                json::diags(&mut self.line, std::iter::once(*d));
                self.line.push('}');
            }
            Format::Text => text::input_diag_line(&mut self.line, d),
        }
        emit(&self.line)
    }

    /// End of stream: flush what is left and report commands that got no reply.
    pub fn finish<E>(&mut self, emit: &mut impl FnMut(&str) -> Result<(), E>) -> Result<(), E> {
        if self.proto.is_none() {
            let sample = std::mem::take(&mut self.sample);
            if sample.is_empty() {
                return Ok(());
            }
            self.choose(&sample, emit)?;
            self.feed(&sample, None, emit)?;
        }
        self.apt.finish();
        self.ell.finish();
        self.drain(None, emit)?;
        let left = self.bus.finish();
        self.report_expired(&left, emit)
    }

    fn choose<E>(
        &mut self,
        sample: &[u8],
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        let d: Detection = detect(sample);
        let proto = d.proto.unwrap_or(if d.elliptec > d.apt {
            Proto::Elliptec
        } else {
            Proto::Apt
        });
        self.proto = Some(proto);
        self.line.clear();
        let verdict = if d.proto.is_some() {
            "detected"
        } else {
            "mixed or unknown stream; best guess"
        };
        match self.fmt {
            Format::Json => {
                let _ = write!(
                    self.line,
                    "{{\"type\":\"detect\",\"proto\":\"{}\",\"certain\":{},\"apt\":{:.3},\"elliptec\":{:.3}}}",
                    proto.name(),
                    d.proto.is_some(),
                    d.apt,
                    d.elliptec
                );
            }
            Format::Text => {
                let _ = write!(
                    self.line,
                    "# protocol {}: {verdict} ({:.0}% of the first {} bytes frame as APT, {:.0}% as Elliptec; --proto to choose)",
                    proto.name(),
                    d.apt * 100.0,
                    sample.len().min(SAMPLE),
                    d.elliptec * 100.0
                );
            }
        }
        emit(&self.line)
    }

    fn feed<E>(
        &mut self,
        chunk: &[u8],
        ts: Option<u64>,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        match self.proto {
            Some(Proto::Apt) => self.apt.push(chunk),
            _ => self.ell.push(chunk),
        }
        self.drain(ts, emit)
    }

    fn drain<E>(
        &mut self,
        ts: Option<u64>,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        let t = Table::global();
        if self.proto == Some(Proto::Apt) {
            while let Some(item) = self.apt.next_item() {
                self.n += 1;
                self.line.clear();
                match (item, self.fmt) {
                    (
                        AptItem::Frame {
                            offset,
                            bytes,
                            truncated,
                        },
                        fmt,
                    ) => {
                        if let Some(f) = AptFrame::decode(t, offset, bytes, truncated) {
                            match fmt {
                                Format::Json => json::apt_frame(&mut self.line, self.n, &f),
                                Format::Text => text::apt_line(&mut self.line, self.n, &f),
                            }
                        }
                    }
                    (
                        AptItem::Garbage {
                            offset,
                            bytes,
                            kind,
                        },
                        Format::Json,
                    ) => json::apt_garbage(&mut self.line, self.n, offset, bytes, kind),
                    (
                        AptItem::Garbage {
                            offset,
                            bytes,
                            kind,
                        },
                        Format::Text,
                    ) => text::garbage_line(&mut self.line, self.n, offset, bytes, kind),
                }
                emit(&self.line)?;
            }
            return Ok(());
        }
        let mut expired: Vec<Expired> = vec![];
        while let Some(item) = self.ell.next_item() {
            self.n += 1;
            self.line.clear();
            match item {
                EllItem::Frame {
                    offset,
                    bytes,
                    truncated,
                } => {
                    let Some(mut f) = EllFrame::decode(offset, bytes, truncated) else {
                        continue;
                    };
                    let o = self.bus.observe(self.n, &f, ts);
                    if o.unsolicited {
                        f.push_diag(Diag {
                            offset,
                            kind: DiagKind::Unsolicited,
                        });
                    }
                    expired.extend(o.expired.iter().copied());
                    match self.fmt {
                        Format::Json => json::ell_frame(&mut self.line, self.n, &f, &o),
                        Format::Text => text::ell_line(&mut self.line, self.n, &f, &o),
                    }
                }
                EllItem::Garbage { offset, bytes, .. } => match self.fmt {
                    Format::Json => json::ell_garbage(&mut self.line, self.n, offset, bytes),
                    Format::Text => text::ell_garbage_line(&mut self.line, self.n, offset, bytes),
                },
            }
            emit(&self.line)?;
            if !expired.is_empty() {
                self.report_expired(&expired, emit)?;
                expired.clear();
            }
        }
        Ok(())
    }

    fn report_expired<E>(
        &mut self,
        list: &[Expired],
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        for e in list {
            let d = Diag {
                offset: e.offset,
                kind: DiagKind::NoReply { cmd: e.n },
            };
            self.line.clear();
            match self.fmt {
                Format::Json => json::late_diag(&mut self.line, "ell", e.n, d),
                Format::Text => text::late_diag_line(&mut self.line, e.n, &d),
            }
            emit(&self.line)?;
        }
        Ok(())
    }
}
