//! The streaming APT framer: feed bytes in any chunking, take frames and garbage records out.
//!
//! APT has no sync byte, so a position is taken as the start of a frame only when its header is
//! plausible: known source and destination addresses (or a known message id whose length fits
//! the table, with one address off), and a data length within [`MAX_DATA_LEN`]. Bytes that do
//! not start a plausible header are collected into garbage records. Every input byte ends up in
//! exactly one frame or garbage record, and the split of the input into chunks never changes the
//! output.

use super::header::{Header, HEADER_LEN, KNOWN_ADDR, MAX_DATA_LEN};
use crate::table::{Dir, Table};

/// Garbage runs are cut into records of at most this many bytes, so memory stays bounded.
pub const MAX_GARBAGE_RUN: usize = 4096;

/// Why bytes were not framed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GarbageKind {
    /// No plausible header starts at any of these bytes.
    NoHeader,
    /// A header of a known message with plausible addresses, but its length is beyond
    /// [`MAX_DATA_LEN`]: the 6 header bytes are skipped.
    AbsurdLength {
        /// The message id of the header.
        msg_id: u16,
        /// The length it claims.
        len: u16,
    },
    /// Bytes left at the end of the stream, too few for a header.
    TrailingBytes,
}

/// What the framer produces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Item<'a> {
    /// A frame: header plus its data packet.
    Frame {
        /// Stream offset of the first byte.
        offset: u64,
        /// The frame's bytes (shorter than its header says when `truncated`).
        bytes: &'a [u8],
        /// The stream ended before the data packet was complete.
        truncated: bool,
    },
    /// Bytes that are not part of any frame.
    Garbage {
        /// Stream offset of the first byte.
        offset: u64,
        /// The bytes.
        bytes: &'a [u8],
        /// Why.
        kind: GarbageKind,
    },
}

impl Item<'_> {
    /// Stream offset of the first byte.
    pub fn offset(&self) -> u64 {
        match self {
            Item::Frame { offset, .. } | Item::Garbage { offset, .. } => *offset,
        }
    }
    /// The bytes.
    pub fn bytes(&self) -> &[u8] {
        match self {
            Item::Frame { bytes, .. } | Item::Garbage { bytes, .. } => bytes,
        }
    }
}

/// The decision for the bytes at one position.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    /// A frame of this many bytes starts here.
    Frame(usize),
    /// This byte does not start a frame.
    Skip,
    /// A header with an absurd length starts here.
    Absurd(u16, u16),
    /// More bytes are needed to decide.
    NeedMore,
}

/// Decide what starts at `b[0]` by its header alone. Pure: depends on the bytes only.
#[inline]
fn step_header(table: &Table, b: &[u8]) -> Step {
    let Some(h) = Header::new(b) else {
        return Step::NeedMore;
    };
    let dst_ok = KNOWN_ADDR[h.dst_byte() as usize];
    let src_ok = KNOWN_ADDR[h.src_byte() as usize];
    // Some controllers answer from and to 0x00 (TDC001; a BSC201's MOVE_COMPLETED on connect):
    // judged on the message and its length.
    let zeros = h.dst_byte() == 0 && h.src_byte() == 0;
    if !dst_ok && !src_ok && !zeros {
        return Step::Skip;
    }
    let msg = table.msg(h.msg_id());
    let has_data = h.has_data();
    let raw_len = if has_data {
        u16::from_le_bytes([b[2], b[3]])
    } else {
        0
    };
    // Beyond the spec's 255 bytes only for a message whose table entry allows it (`maxlen=`).
    let max = msg.map_or(MAX_DATA_LEN, |m| table.max_data_len(m));
    if raw_len as usize > max {
        return match (msg, dst_ok && src_ok) {
            (Some(_), true) => Step::Absurd(h.msg_id(), raw_len),
            _ => Step::Skip,
        };
    }
    let plausible = if dst_ok && src_ok {
        true
    } else if zeros {
        // Only devices send so: a known device → host message whose length fits the table.
        msg.is_some_and(|m| {
            m.dir == Dir::DeviceToHost && table.accepts_len(m, has_data, raw_len as usize)
        })
    } else {
        // One address off: only trust a known message whose length fits the table.
        msg.is_some_and(|m| table.accepts_len(m, has_data, raw_len as usize))
    };
    if !plausible {
        return Step::Skip;
    }
    Step::Frame(HEADER_LEN + raw_len as usize)
}

/// Decide what starts at `b[0]`. Pure: depends on the bytes only and whether they are all
/// (`eof`).
///
/// Besides the header rules of [`step_header`], a data packet sent without the 0x80 flag
/// (example programs do it) is recognised: a known message whose param bytes, read as a length,
/// give one of its data forms, when the bytes after the header do not start a frame and the
/// bytes after the data packet do (or the stream ends there). A message that has no header-only
/// form needs no such evidence.
#[inline]
fn step(table: &Table, b: &[u8], eof: bool) -> Step {
    let s = step_header(table, b);
    let Step::Frame(HEADER_LEN) = s else {
        return s;
    };
    let Some(m) = Header::new(b).and_then(|h| table.msg(h.msg_id())) else {
        return s;
    };
    let len = u16::from_le_bytes([b[2], b[3]]) as usize;
    if len == 0 || len > table.max_data_len(m) || !table.accepts_len(m, true, len) {
        return s;
    }
    let whole = HEADER_LEN + len;
    if !table.accepts_len(m, false, 0) {
        return Step::Frame(whole);
    }
    let starts_frame = |at: usize| match b.get(at..) {
        Some(rest) => matches!(step_header(table, rest), Step::Frame(_)),
        None => false,
    };
    if b.len() < whole + HEADER_LEN {
        if !eof {
            return Step::NeedMore;
        }
        return if b.len() == whole && !starts_frame(HEADER_LEN) {
            Step::Frame(whole)
        } else {
            s
        };
    }
    if starts_frame(whole) && !starts_frame(HEADER_LEN) {
        Step::Frame(whole)
    } else {
        s
    }
}

/// Streaming, sans-io APT framer.
///
/// ```
/// use aptscope_dissector::{apt::{AptFramer, Item}, table::Table};
/// let mut f = AptFramer::new(Table::global());
/// f.push(&[0x23, 0x02, 0x01, 0x00]);
/// assert!(f.next_item().is_none()); // incomplete: waits for more
/// f.push(&[0x50, 0x01]);
/// assert!(matches!(f.next_item(), Some(Item::Frame { offset: 0, .. })));
/// ```
#[derive(Debug)]
pub struct AptFramer<'t> {
    table: &'t Table,
    buf: Vec<u8>,
    /// Scan position in `buf`.
    pos: usize,
    /// Start of the current garbage run in `buf`.
    garbage: Option<usize>,
    /// Stream offset of `buf[0]`.
    base: u64,
    eof: bool,
}

impl<'t> AptFramer<'t> {
    /// A framer using `table` to judge headers.
    pub fn new(table: &'t Table) -> Self {
        AptFramer {
            table,
            buf: Vec::with_capacity(64 * 1024),
            pos: 0,
            garbage: None,
            base: 0,
            eof: false,
        }
    }

    /// Stream offset of the next byte to be pushed.
    pub fn stream_len(&self) -> u64 {
        self.base + self.buf.len() as u64
    }

    /// Append input bytes. Consumed bytes are dropped first, so memory stays bounded by the
    /// largest chunk plus one frame and one garbage run.
    pub fn push(&mut self, data: &[u8]) {
        let keep = self.garbage.unwrap_or(self.pos);
        if keep > 0 {
            self.buf.drain(..keep);
            self.base += keep as u64;
            self.pos -= keep;
            if let Some(g) = self.garbage.as_mut() {
                *g -= keep;
            }
        }
        self.buf.extend_from_slice(data);
    }

    /// Declare the end of the stream: what is left comes out as truncated frame or garbage.
    pub fn finish(&mut self) {
        self.eof = true;
    }

    fn garbage_item(&mut self, start: usize, end: usize, kind: GarbageKind) -> Item<'_> {
        Item::Garbage {
            offset: self.base + start as u64,
            bytes: &self.buf[start..end],
            kind,
        }
    }

    /// The next frame or garbage record, or `None` when more input is needed (or, after
    /// [`finish`](Self::finish), when everything has been returned).
    pub fn next_item(&mut self) -> Option<Item<'_>> {
        loop {
            if let Some(g) = self.garbage {
                if self.pos - g >= MAX_GARBAGE_RUN {
                    let end = g + MAX_GARBAGE_RUN;
                    self.garbage = if end < self.pos { Some(end) } else { None };
                    return Some(self.garbage_item(g, end, GarbageKind::NoHeader));
                }
            }
            let rest = &self.buf[self.pos..];
            let s = step(self.table, rest, self.eof);
            match s {
                Step::Skip => {
                    if self.garbage.is_none() {
                        self.garbage = Some(self.pos);
                    }
                    self.pos += 1;
                    continue;
                }
                Step::NeedMore if !self.eof => return None,
                _ => {}
            }
            // Anything else ends the current garbage run first.
            if let Some(g) = self.garbage.take() {
                return Some(self.garbage_item(g, self.pos, GarbageKind::NoHeader));
            }
            let start = self.pos;
            match s {
                Step::Frame(len) => {
                    if rest.len() >= len {
                        self.pos += len;
                        return Some(Item::Frame {
                            offset: self.base + start as u64,
                            bytes: &self.buf[start..start + len],
                            truncated: false,
                        });
                    }
                    if !self.eof {
                        return None;
                    }
                    self.pos = self.buf.len();
                    return Some(Item::Frame {
                        offset: self.base + start as u64,
                        bytes: &self.buf[start..],
                        truncated: true,
                    });
                }
                Step::Absurd(msg_id, len) => {
                    self.pos += HEADER_LEN;
                    return Some(self.garbage_item(
                        start,
                        start + HEADER_LEN,
                        GarbageKind::AbsurdLength { msg_id, len },
                    ));
                }
                // NeedMore at end of stream: fewer than 6 bytes left.
                _ => {
                    if start == self.buf.len() {
                        return None;
                    }
                    self.pos = self.buf.len();
                    return Some(self.garbage_item(start, self.pos, GarbageKind::TrailingBytes));
                }
            }
        }
    }
}
