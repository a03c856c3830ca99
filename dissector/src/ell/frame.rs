//! The streaming Elliptec framer.
//!
//! A frame is an address character, a two-letter command and its data, then an optional
//! terminator (CR LF, CR or LF). Host commands are often sent without a terminator, so they are
//! framed by the command's known data length; module replies end at CR LF. The framer is lenient
//! about what the manual's own examples contain: a space after the address or the command,
//! commas between fields, the letter O for the digit 0 as address, one or two extra data
//! characters before the terminator. Every byte ends up in one frame or garbage record.

use super::table::{lookup, Cmd, CURVE_SHORT_BYTES};
use crate::table::Dir;

/// Longest line accepted for a reply of an unknown command, or slack for extra characters.
const SLACK: usize = 24;
/// Longest unknown-command line.
const MAX_UNKNOWN: usize = 64;

/// Why bytes were not framed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GarbageKind {
    /// No frame starts at these bytes.
    NoFrame,
    /// Bytes at the end of the stream too short for a frame.
    TrailingBytes,
}

/// What the framer produces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Item<'a> {
    /// A frame with its terminator, if any.
    Frame {
        /// Stream offset.
        offset: u64,
        /// Bytes.
        bytes: &'a [u8],
        /// The stream ended inside it.
        truncated: bool,
    },
    /// Bytes outside frames.
    Garbage {
        /// Stream offset.
        offset: u64,
        /// Bytes.
        bytes: &'a [u8],
        /// Why.
        kind: GarbageKind,
    },
}

/// The parsed start of a frame: where address, command and data are.
#[derive(Debug, Clone, Copy)]
pub struct Head {
    /// Address 0–15 (the letter O read as 0).
    pub addr: u8,
    /// The address was the letter O.
    pub letter_o: bool,
    /// Offset of the two command characters.
    pub cmd_at: usize,
    /// Offset of the first data character.
    pub data_at: usize,
    /// A space followed the address or the command.
    pub spaced: bool,
    /// The command, when known.
    pub cmd: Option<&'static Cmd>,
}

fn addr_of(c: u8) -> Option<(u8, bool)> {
    match c {
        b'0'..=b'9' => Some((c - b'0', false)),
        b'A'..=b'F' => Some((c - b'A' + 10, false)),
        b'a'..=b'f' => Some((c - b'a' + 10, false)),
        b'O' | b'o' => Some((0, true)),
        _ => None,
    }
}

fn is_term(c: u8) -> bool {
    c == b'\r' || c == b'\n'
}

fn is_data_char(c: u8) -> bool {
    c.is_ascii_hexdigit() || c == b',' || c == b' ' || c == b'O'
}

/// Parse address and command at the start of `b`. `None` if no frame can start here, `Some(Err)`
/// if more bytes are needed to tell.
pub fn head(b: &[u8]) -> Option<Result<Head, ()>> {
    parse_head(b, false)
}

/// [`head`] of a whole frame: nothing follows `b`, so a command that ends right after its
/// letters has no data (rather than needing more bytes).
pub(crate) fn head_of_frame(b: &[u8]) -> Option<Head> {
    parse_head(b, true)?.ok()
}

fn parse_head(b: &[u8], whole: bool) -> Option<Result<Head, ()>> {
    let (addr, letter_o) = addr_of(*b.first()?)?;
    let mut at = 1;
    let mut spaced = false;
    if matches!(b.get(at), Some(b' ' | b',')) {
        at += 1;
        spaced = true;
    }
    let Some(code) = b.get(at..at + 2) else {
        return if whole { None } else { Some(Err(())) };
    };
    if !code[0].is_ascii_alphabetic() || !code[1].is_ascii_alphanumeric() {
        return None;
    }
    let cmd = lookup(code);
    // A letter-O address is only believed for a known command.
    if letter_o && cmd.is_none() {
        return None;
    }
    let cmd_at = at;
    at += 2;
    let mut data_at = at;
    if cmd.is_some_and(|c| c.data_len() > 0) && matches!(b.get(at), Some(b' ' | b',')) {
        data_at += 1;
        spaced = true;
    } else if b.len() <= at && !whole && cmd.is_some_and(|c| c.data_len() > 0) {
        return Some(Err(()));
    }
    Some(Ok(Head {
        addr,
        letter_o,
        cmd_at,
        data_at,
        spaced,
        cmd,
    }))
}

/// Decision at one position.
enum Step {
    /// A frame of this many bytes (terminator included); `true` if truncated at end of stream.
    Frame(usize, bool),
    Skip,
    NeedMore,
}

/// Length of the terminator at the start of `b`: CR LF, CR, LF or none. `None` when the end of
/// the buffer leaves it open (a CR that may be followed by LF).
fn term_len(b: &[u8], eof: bool) -> Option<usize> {
    match b {
        [b'\r', b'\n', ..] => Some(2),
        [b'\r'] if !eof => None,
        [b'\r', ..] | [b'\n', ..] => Some(1),
        [] if !eof => None,
        _ => Some(0),
    }
}

/// `cut`: the host's command is over (the other direction spoke), so a host command whose data
/// is complete ends where the bytes end, without waiting for an optional terminator.
fn step(b: &[u8], eof: bool, cut: bool) -> Step {
    let h = match head(b) {
        None => return Step::Skip,
        // The bytes end after a command's letters: when nothing more will come (the stream
        // ended, or the module answered), it is a command without its data.
        Some(Err(())) => match head_of_frame(b) {
            Some(h) if eof || cut => h,
            _ if eof => return Step::Skip,
            _ => return Step::NeedMore,
        },
        Some(Ok(h)) => h,
    };
    let Some(cmd) = h.cmd else {
        if b[h.cmd_at].is_ascii_lowercase() {
            return unknown_host(b, h.data_at, eof, cut);
        }
        // Unknown reply: only a whole terminated line of data characters is a frame.
        let rest = &b[h.data_at..];
        return match rest.iter().take(MAX_UNKNOWN).position(|&c| is_term(c)) {
            Some(p)
                if rest[..p]
                    .iter()
                    .all(|&c| is_data_char(c) || c.is_ascii_alphanumeric()) =>
            {
                match term_len(&rest[p..], eof) {
                    Some(t) => Step::Frame(h.data_at + p + t, false),
                    None => Step::NeedMore,
                }
            }
            None if rest.len() < MAX_UNKNOWN && !eof => Step::NeedMore,
            _ => Step::Skip,
        };
    };
    let n = cmd.data_len();
    let data = &b[h.data_at..];
    if cmd.is_binary() {
        return binary(data, n, eof, h.data_at);
    }
    if cmd.dir == Dir::HostToDevice {
        return host_command(b, &h, n, eof, cut);
    }
    // A module reply: up to its terminator, allowing separators and a few extra characters.
    let limit = n + SLACK;
    match data
        .iter()
        .take(limit + 1)
        .position(|&c| is_term(c) || !is_data_char(c))
    {
        Some(p) if is_term(data[p]) => match term_len(&data[p..], eof) {
            Some(t) => Step::Frame(h.data_at + p + t, false),
            None => Step::NeedMore,
        },
        // A non-data character (the next frame's command letters, say) before any terminator:
        // the reply had no terminator. Take its own length.
        Some(p) if p >= n => Step::Frame(h.data_at + n, false),
        // Data cut short by a byte that is neither data nor terminator: not a reply.
        Some(_) => Step::Skip,
        None if data.len() > limit => Step::Frame(h.data_at + n, false),
        None if eof => Step::Frame(b.len(), data.len() < n),
        None => Step::NeedMore,
    }
}

/// Binary data (the `C1`/`C2` current curve): a fixed length, then a terminator. Binary data
/// can hold anything, so only a terminator right after it makes it a frame; the length the
/// manual's byte table gives ([`CURVE_SHORT_BYTES`]) is accepted too when CR LF follows it.
fn binary(data: &[u8], n: usize, eof: bool, data_at: usize) -> Step {
    if data.len() >= n {
        match term_len(&data[n..], eof) {
            Some(0) => {}
            Some(t) => return Step::Frame(data_at + n + t, false),
            None => return Step::NeedMore,
        }
    } else if !eof {
        return Step::NeedMore;
    }
    let short = CURVE_SHORT_BYTES;
    if short < n && data.get(short..short + 2) == Some(b"\r\n".as_slice()) {
        return Step::Frame(data_at + short + 2, false);
    }
    if data.len() < n {
        Step::Frame(data_at + data.len(), true)
    } else {
        Step::Skip
    }
}

/// A host command: its data's length, then an optional terminator. A command sent short (or
/// without its data) ends early: at a terminator inside the data, where the next command
/// visibly starts inside it (`0ma1gp`), or where the bytes end once the module has answered
/// (`cut`).
fn host_command(b: &[u8], h: &Head, n: usize, eof: bool, cut: bool) -> Step {
    let data = &b[h.data_at..];
    let window = &data[..data.len().min(n)];
    // The first character that cannot be data decides, whatever the chunking: a terminator
    // ends the command there; if a known host command starts right before it (its address,
    // then the command letters), the data was left out. Any other character is bad data.
    if let Some(q) = window.iter().position(|&c| !is_data_char(c)) {
        if is_term(window[q]) {
            return term_at(data, q, eof, h.data_at);
        }
        for p in q.saturating_sub(2)..q {
            match head(&data[p..]) {
                Some(Ok(next)) if next.cmd.is_some_and(|c| c.dir == Dir::HostToDevice) => {
                    return Step::Frame(h.data_at + p, false);
                }
                Some(Err(())) if !eof => return Step::NeedMore,
                _ => {}
            }
        }
        // Bad data: a terminator further on still ends the command early.
        if let Some(t) = window[q..].iter().position(|&c| is_term(c)) {
            return term_at(data, q + t, eof, h.data_at);
        }
    }
    if data.len() < n {
        return if cut {
            Step::Frame(b.len(), false)
        } else if eof {
            Step::Frame(b.len(), true)
        } else {
            Step::NeedMore
        };
    }
    match term_len(&data[n..], eof || cut) {
        Some(t) => Step::Frame(h.data_at + n + t, false),
        None => Step::NeedMore,
    }
}

/// A host command the table does not know (pylablib asks `0i3`): an address, a lower-case letter
/// and a letter or digit are a host command whatever the table says (the manual's own mix
/// letters and digits: `i1`, `f1`, `b2`). Its data, as text, runs to a terminator, to where the
/// next frame visibly starts, to a character that cannot be data, or to where the bytes end once
/// the module has answered (`cut`) or the stream has ended.
fn unknown_host(b: &[u8], data_at: usize, eof: bool, cut: bool) -> Step {
    let end = b.len().min(data_at + MAX_UNKNOWN);
    for p in data_at..end {
        let c = b[p];
        if is_term(c) {
            return match term_len(&b[p..], eof || cut) {
                Some(t) => Step::Frame(p + t, false),
                None => Step::NeedMore,
            };
        }
        if !(is_data_char(c) || c.is_ascii_alphanumeric()) || starts_frame(&b[p..]) {
            return Step::Frame(p, false);
        }
        // Too few bytes left to tell whether a frame starts here.
        if b.len() - p < 3 && c.is_ascii_alphanumeric() && !(eof || cut) {
            return Step::NeedMore;
        }
    }
    if end < b.len() || eof || cut || end - data_at >= MAX_UNKNOWN {
        Step::Frame(end, false)
    } else {
        Step::NeedMore
    }
}

/// Whether a frame visibly starts at `b`: a known command, or a host command's shape (an
/// address digit or upper-case letter, a lower-case letter, a letter or digit). Lower-case
/// address letters are left out: they are also lower-case hex data.
fn starts_frame(b: &[u8]) -> bool {
    match head(b) {
        Some(Ok(h)) if h.cmd.is_some() => true,
        _ => matches!(b, [a, c, d, ..] if (a.is_ascii_digit() || (b'A'..=b'F').contains(a))
            && c.is_ascii_lowercase() && d.is_ascii_alphanumeric()),
    }
}

/// A frame ending with the terminator at `data[p..]`.
fn term_at(data: &[u8], p: usize, eof: bool, data_at: usize) -> Step {
    match term_len(&data[p..], eof) {
        Some(t) => Step::Frame(data_at + p + t, false),
        None => Step::NeedMore,
    }
}

/// Streaming, sans-io Elliptec framer (same interface as the APT framer).
#[derive(Debug, Default)]
pub struct EllFramer {
    buf: Vec<u8>,
    pos: usize,
    garbage: Option<usize>,
    base: u64,
    eof: bool,
    cut: bool,
}

impl EllFramer {
    /// A new framer.
    pub fn new() -> Self {
        Self::default()
    }

    /// Append input bytes (consumed bytes are dropped first: bounded memory).
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
        self.cut = false;
    }

    /// Say that the other side of the line has spoken since the last [`push`](Self::push): a
    /// host command complete but for its optional terminator is framed now, not when the host's
    /// next bytes arrive (hosts often send no terminator). Only the Pipeline's knowledge of
    /// directions can tell this; the bytes alone cannot.
    pub fn cut(&mut self) {
        self.cut = true;
    }

    /// Declare the end of the stream.
    pub fn finish(&mut self) {
        self.eof = true;
    }

    /// The next frame or garbage record, or `None` when more input is needed.
    pub fn next_item(&mut self) -> Option<Item<'_>> {
        loop {
            if let Some(g) = self.garbage {
                if self.pos - g >= crate::apt::MAX_GARBAGE_RUN {
                    let end = g + crate::apt::MAX_GARBAGE_RUN;
                    self.garbage = if end < self.pos { Some(end) } else { None };
                    return Some(Item::Garbage {
                        offset: self.base + g as u64,
                        bytes: &self.buf[g..end],
                        kind: GarbageKind::NoFrame,
                    });
                }
            }
            if self.pos >= self.buf.len() {
                if self.eof {
                    if let Some(g) = self.garbage.take() {
                        return Some(Item::Garbage {
                            offset: self.base + g as u64,
                            bytes: &self.buf[g..self.pos],
                            kind: GarbageKind::NoFrame,
                        });
                    }
                }
                return None;
            }
            let s = step(&self.buf[self.pos..], self.eof, self.cut);
            match s {
                Step::Skip => {
                    if self.garbage.is_none() {
                        self.garbage = Some(self.pos);
                    }
                    self.pos += 1;
                    continue;
                }
                Step::NeedMore => return None,
                Step::Frame(..) => {}
            }
            if let Some(g) = self.garbage.take() {
                return Some(Item::Garbage {
                    offset: self.base + g as u64,
                    bytes: &self.buf[g..self.pos],
                    kind: GarbageKind::NoFrame,
                });
            }
            if let Step::Frame(len, truncated) = s {
                let start = self.pos;
                self.pos += len;
                return Some(Item::Frame {
                    offset: self.base + start as u64,
                    bytes: &self.buf[start..start + len],
                    truncated,
                });
            }
        }
    }
}
