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

/// The lengths a frame may have, by its header: the rule the framer cuts frames by
/// ([`AptFramer`]) and [`check_frame`] holds them to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LenRule {
    /// The length the header states: [`HEADER_LEN`] plus the length field when the 0x80 data
    /// flag is set, else [`HEADER_LEN`] (a header-only frame).
    pub declared: usize,
    /// For a header without the data flag: the frame length when its param bytes, read as a
    /// length, give a data form of its known message (example programs send data so). The
    /// framer takes it when the message has no header-only form, or when the bytes after it
    /// start a frame and the bytes after the header do not (or the stream ends there).
    pub unflagged: Option<usize>,
}

impl LenRule {
    /// The rule for the frame whose header is `h`.
    #[inline]
    pub fn of(table: &Table, h: Header<'_>) -> LenRule {
        let declared = HEADER_LEN + h.data_len();
        let unflagged = if h.has_data() {
            None
        } else {
            let len = usize::from(u16::from_le_bytes([h.param1(), h.param2()]));
            table
                .msg(h.msg_id())
                .filter(|m| len > 0 && len <= table.max_data_len(m))
                .filter(|m| table.accepts_len(m, true, len))
                .map(|_| HEADER_LEN + len)
        };
        LenRule {
            declared,
            unflagged,
        }
    }
    /// Whether a whole frame may be `len` bytes long.
    pub fn allows(&self, len: usize) -> bool {
        len == self.declared || Some(len) == self.unflagged
    }
    /// The longest frame the rule allows.
    pub fn longest(&self) -> usize {
        self.declared.max(self.unflagged.unwrap_or(0))
    }
}

/// Check what the framer claims of one frame (as [`Item::Frame`] gives it), against the length
/// rules: it holds a header; its header's data length is within the message's largest (255, or
/// its `maxlen=`); whole, its length is one [`LenRule`] allows; `truncated`, it is shorter than
/// one the rule allows. `Err` says which rule fails. (That only the stream's last frame is
/// truncated is for the caller to see.)
pub fn check_frame(table: &Table, bytes: &[u8], truncated: bool) -> Result<(), String> {
    let Some(h) = Header::new(bytes) else {
        return Err(format!("{} bytes: shorter than a header", bytes.len()));
    };
    let max = table
        .msg(h.msg_id())
        .map_or(MAX_DATA_LEN, |m| table.max_data_len(m));
    if h.data_len() > max {
        return Err(format!(
            "the header says {} data bytes, more than the {max} its message may have",
            h.data_len()
        ));
    }
    let rule = LenRule::of(table, h);
    let n = bytes.len();
    match truncated {
        false if !rule.allows(n) => Err(format!(
            "{n} bytes, where the header allows {} or {:?} (unflagged data)",
            rule.declared, rule.unflagged
        )),
        true if n >= rule.longest() => Err(format!(
            "{n} bytes and truncated, where the header allows at most {}",
            rule.longest()
        )),
        _ => Ok(()),
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
    let Some(h) = Header::new(b) else {
        return s;
    };
    let Some(whole) = LenRule::of(table, h).unflagged else {
        return s;
    };
    let Some(m) = table.msg(h.msg_id()) else {
        return s;
    };
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
    #[inline]
    pub fn next_item(&mut self) -> Option<Item<'_>> {
        if let Some(len) = self.plain_frame() {
            let start = self.pos;
            self.pos += len;
            return Some(Item::Frame {
                offset: self.base + start as u64,
                bytes: &self.buf[start..start + len],
                truncated: false,
            });
        }
        self.next_item_slow()
    }

    /// The length of the frame at the scan position when it is the common case, decided
    /// without the general loop: no garbage run open, both addresses known, the whole frame
    /// buffered, and either a flagged data packet within the spec's 255 bytes (no table lookup
    /// needed: every message may have that many) or a header-only frame whose params give no
    /// unflagged data length. What [`step`] decides for these; `None` leaves it to the loop.
    #[inline]
    fn plain_frame(&self) -> Option<usize> {
        if self.garbage.is_some() {
            return None;
        }
        let b = self.buf.get(self.pos..)?;
        let h = Header::new(b)?;
        if !(KNOWN_ADDR[usize::from(h.dst_byte())] && KNOWN_ADDR[usize::from(h.src_byte())]) {
            return None;
        }
        let len = if h.has_data() {
            let len = HEADER_LEN + h.data_len();
            if len == HEADER_LEN || h.data_len() > MAX_DATA_LEN {
                return None;
            }
            len
        } else {
            if LenRule::of(self.table, h).unflagged.is_some() {
                return None;
            }
            HEADER_LEN
        };
        (b.len() >= len).then_some(len)
    }

    /// [`next_item`](Self::next_item) for every case: garbage, look-ahead, the end of the stream.
    fn next_item_slow(&mut self) -> Option<Item<'_>> {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn rule(b: &[u8]) -> LenRule {
        LenRule::of(Table::global(), Header::new(b).expect("a header"))
    }

    #[test]
    fn the_length_rule_follows_the_flag_and_the_message_forms() {
        // MOT_MOVE_ABSOLUTE flagged with 6 data bytes: as the header says.
        let flagged = [0x53, 0x04, 0x06, 0x00, 0xD0, 0x01];
        assert_eq!(
            rule(&flagged),
            LenRule {
                declared: 12,
                unflagged: None
            }
        );
        // Unflagged, its params read as 6, one of its data lengths: either length.
        let unflagged = [0x53, 0x04, 0x06, 0x00, 0x50, 0x01];
        let r = rule(&unflagged);
        assert_eq!((r.declared, r.unflagged), (6, Some(12)));
        assert!(r.allows(6) && r.allows(12) && !r.allows(7));
        assert_eq!(r.longest(), 12);
        // Params that are no data length of the message, or an unknown message: header only.
        assert_eq!(rule(&[0x53, 0x04, 0x01, 0x02, 0x50, 0x01]).unflagged, None);
        assert_eq!(rule(&[0x34, 0x12, 0x06, 0x00, 0x50, 0x01]).unflagged, None);
        // An open form: any whole number of rows up to its `maxlen=` (4104).
        let sync = |len: u16, flag: u8| {
            let l = len.to_le_bytes();
            rule(&[0x00, 0x0A, l[0], l[1], 0x50 | flag, 0x01])
        };
        assert_eq!(sync(4104, 0).unflagged, Some(4110));
        assert_eq!(sync(4105, 0).unflagged, None, "not a whole row");
        assert_eq!(sync(4108, 0).unflagged, None, "beyond maxlen=");
        assert_eq!(sync(1208, 0x80).declared, 1214);
    }

    #[test]
    fn check_frame_states_what_the_framer_may_cut() {
        let t = Table::global();
        let unflagged = [0x53, 0x04, 0x06, 0x00, 0x50, 0x01, 1, 0, 0x20, 0x4E, 0, 0];
        assert_eq!(check_frame(t, &unflagged, false), Ok(()));
        assert_eq!(check_frame(t, &unflagged[..6], false), Ok(()));
        // MOT_SET_VELPARAMS has no header-only form, so the framer takes its unflagged data
        // without look-ahead and may end the stream within it: the fuzz harness's old rule (a
        // frame is as long as its flag says) failed on such a frame, longer than a header.
        let vel = [0x13, 0x04, 0x0E, 0x00, 0x50, 0x01, 1, 0];
        assert_eq!(check_frame(t, &vel, true), Ok(()));
        assert!(check_frame(t, &vel, false).is_err());
        assert!(
            check_frame(t, &unflagged, true).is_err(),
            "whole yet truncated"
        );
        assert!(check_frame(t, &unflagged[..5], true).is_err(), "no header");
        // More data than the message may have.
        assert!(check_frame(t, &[0x53, 0x04, 0x00, 0x01, 0xD0, 0x01], true).is_err());
    }

    /// Every frame the framer cuts from a stream of unflagged, header-only, flagged and open
    /// frames, whole and truncated at each length, keeps `check_frame`.
    #[test]
    fn the_framer_keeps_its_own_rules() {
        let t = Table::global();
        let mut s = vec![0x53, 0x04, 0x06, 0x00, 0x50, 0x01, 1, 0, 0x20, 0x4E, 0, 0];
        s.extend([0x53, 0x04, 0x06, 0x00, 0x50, 0x01]);
        s.extend([0x05, 0x00, 0x00, 0x00, 0x50, 0x01]);
        s.extend([0x00, 0x0A, 0x10, 0x00, 0xD0, 0x01]);
        s.extend([1, 0, 3, 0, 1, 0, 0, 0, 9, 0, 0, 0, 7, 0, 0, 0]);
        s.extend([0x13, 0x04, 0x0E, 0x00, 0x50, 0x01, 1, 0, 0, 0, 0, 0, 0, 0]);
        s.extend([0, 0, 0, 0, 0, 0, 0, 0]);
        for end in 0..=s.len() {
            let mut f = AptFramer::new(t);
            f.push(&s[..end]);
            f.finish();
            let mut frames = 0;
            while let Some(it) = f.next_item() {
                if let Item::Frame {
                    bytes, truncated, ..
                } = it
                {
                    frames += 1;
                    if let Err(e) = check_frame(t, bytes, truncated) {
                        panic!("{end} bytes: {bytes:02x?}: {e}");
                    }
                }
            }
            assert!(end < 6 || frames > 0);
        }
    }
}
