//! Reading xxd and `hexdump -C` dumps.

use super::*;

pub(super) enum DumpLine<'a> {
    /// A line of bytes at an offset, with its ASCII column when present.
    Data {
        offset: u64,
        gutter: Option<&'a [u8]>,
    },
    /// `*`: the previous line repeats until the next offset.
    Repeat,
    /// hexdump's final line: the total length.
    End { offset: u64 },
}

/// `00000000: 0500 0000 5001 …  ....P.`; `Ok(None)` if not an xxd line.
pub(super) fn xxd_line<'a>(s: &'a [u8], out: &mut Vec<u8>) -> Result<Option<DumpLine<'a>>, usize> {
    if s == b"*" {
        return Ok(Some(DumpLine::Repeat));
    }
    let Some(colon) = s.iter().position(|&b| b == b':') else {
        return Ok(None);
    };
    let Some(offset) = parse_hex_u64(&s[..colon]) else {
        return Ok(None);
    };
    if s.get(colon + 1) != Some(&b' ') {
        return Ok(None);
    }
    let start = colon + 2;
    let area_end = s[start..]
        .windows(2)
        .position(|w| w == b"  ")
        .map_or(s.len(), |i| start + i);
    let first = out.len();
    let mut i = start;
    while i < area_end {
        if s[i] == b' ' {
            i += 1;
            continue;
        }
        let end = s[i..area_end]
            .iter()
            .position(|&b| b == b' ')
            .map_or(area_end, |e| i + e);
        let group = &s[i..end];
        if !group.len().is_multiple_of(2) {
            return Err(i);
        }
        for (j, h) in group.chunks(2).enumerate() {
            match pair(h[0], h[1]) {
                Some(b) => out.push(b),
                None => return Err(i + 2 * j),
            }
        }
        i = end;
    }
    let n = out.len() - first;
    if n == 0 {
        return Err(start);
    }
    let rest = &s[area_end..];
    let gutter = (rest.len() >= n + 2).then(|| &s[s.len() - n..]);
    Ok(Some(DumpLine::Data { offset, gutter }))
}

/// `00000000  05 00 00 00 50 01 06 00  54 00 …  |....P...T.|`; `Ok(None)` if not such a line.
pub(super) fn hexdump_line<'a>(
    s: &'a [u8],
    out: &mut Vec<u8>,
) -> Result<Option<DumpLine<'a>>, usize> {
    if s == b"*" {
        return Ok(Some(DumpLine::Repeat));
    }
    let digits = s.iter().take_while(|&&b| hexv(b).is_some()).count();
    if digits < 7 {
        return Ok(None);
    }
    let Some(offset) = parse_hex_u64(&s[..digits]) else {
        return Ok(None);
    };
    if trim(&s[digits..]).is_empty() {
        return Ok(Some(DumpLine::End { offset }));
    }
    if !s[digits..].starts_with(b"  ") {
        return Ok(None);
    }
    let bar = s.iter().position(|&b| b == b'|');
    let area_end = bar.unwrap_or(s.len());
    let first = out.len();
    let mut i = digits;
    while i < area_end {
        if s[i] == b' ' {
            i += 1;
            continue;
        }
        let end = s[i..area_end]
            .iter()
            .position(|&b| b == b' ')
            .map_or(area_end, |e| i + e);
        match (end - i == 2).then(|| pair(s[i], s[i + 1])).flatten() {
            Some(b) => out.push(b),
            None => return Err(i),
        }
        i = end;
    }
    if out.len() == first {
        return Err(digits);
    }
    let gutter = bar.map(|b| {
        let g = &s[b + 1..];
        g.strip_suffix(b"|").unwrap_or(g)
    });
    Ok(Some(DumpLine::Data { offset, gutter }))
}

pub(super) struct Dump {
    hexdump: bool,
    acc: Acc,
    scratch: Vec<u8>,
    /// The bytes of the previous line (what `*` repeats).
    prev: Vec<u8>,
    /// Where the next line should start.
    expected: Option<u64>,
    /// The offset of a `*` line waiting for the next offset.
    star: Option<u64>,
    /// A `*` being expanded: bytes left, the repeated line, the line that comes after.
    repeat_left: u64,
    pattern: Vec<u8>,
    deferred: Vec<u8>,
    repeat_buf: Vec<u8>,
}

impl Dump {
    pub(super) fn new(hexdump: bool) -> Self {
        Dump {
            hexdump,
            acc: Acc::default(),
            scratch: vec![],
            prev: vec![],
            expected: None,
            star: None,
            repeat_left: 0,
            pattern: vec![],
            deferred: vec![],
            repeat_buf: vec![],
        }
    }

    fn name(&self) -> &'static str {
        if self.hexdump {
            "hexdump -C"
        } else {
            "xxd"
        }
    }

    fn diag(&mut self, off: u64, problem: LogProblem, sink: &mut Sink) {
        self.acc.flush(sink);
        sink.diag(off, problem);
    }

    /// Check a line's offset against the previous lines; set up a `*` expansion before it.
    fn place(&mut self, offset: u64, off: u64, sink: &mut Sink) {
        if let Some(star_off) = self.star.take() {
            let plen = self.prev.len() as u64;
            match self.expected {
                // A dump of a serial capture does not repeat a line for gigabytes: a huge gap is
                // damage, and expanding it would take minutes (found by fuzzing).
                Some(exp) if offset >= exp && offset - exp > MAX_REPEAT => self.diag(
                    star_off,
                    LogProblem::RepeatTooLong {
                        bytes: offset - exp,
                        max: MAX_REPEAT,
                    },
                    sink,
                ),
                Some(exp) if offset >= exp && plen > 0 && (offset - exp).is_multiple_of(plen) => {
                    self.repeat_left = offset - exp;
                    self.pattern.clear();
                    self.pattern.extend_from_slice(&self.prev);
                }
                _ => self.diag(star_off, LogProblem::RepeatMisfit { before: offset }, sink),
            }
        } else if let Some(exp) = self.expected {
            if offset != exp {
                let problem = LogProblem::OffsetGap {
                    expected: exp,
                    found: offset,
                };
                self.diag(off, problem, sink);
            }
        }
    }
}

impl LineParser for Dump {
    fn line(&mut self, s: &[u8], off: u64, sink: &mut Sink) {
        if trim(s).is_empty() {
            return;
        }
        self.scratch.clear();
        let parsed = if self.hexdump {
            hexdump_line(s, &mut self.scratch)
        } else {
            xxd_line(s, &mut self.scratch)
        };
        match parsed {
            Ok(Some(DumpLine::Repeat)) => {
                if self.prev.is_empty() || self.star.is_some() {
                    self.diag(off, LogProblem::RepeatNothing, sink);
                } else {
                    self.star = Some(off);
                }
            }
            Ok(Some(DumpLine::End { offset })) => {
                self.place(offset, off, sink);
                self.expected = Some(offset);
                self.prev.clear();
            }
            Ok(Some(DumpLine::Data { offset, gutter })) => {
                self.place(offset, off, sink);
                if let Some(g) = gutter {
                    if !gutter_matches(&self.scratch, g) {
                        self.diag(off, LogProblem::AsciiMismatch { ascii: show(g) }, sink);
                    }
                }
                self.expected = Some(offset.saturating_add(self.scratch.len() as u64));
                self.prev.clear();
                self.prev.extend_from_slice(&self.scratch);
                if self.repeat_left > 0 {
                    self.deferred.clear();
                    self.deferred.extend_from_slice(&self.scratch);
                } else {
                    self.acc.push(&self.scratch, sink);
                }
            }
            Ok(None) => {
                let name = self.name();
                let problem = LogProblem::GarbageLine {
                    expected: format!("a {name} dump"),
                    line: show(s),
                };
                self.diag(off, problem, sink);
            }
            Err(col) => {
                // Keep the bytes before the bad one; the next line's offset is then unknown.
                self.diag(off, bad_hex(s, col), sink);
                self.acc.push(&self.scratch, sink);
                self.expected = None;
                self.star = None;
                self.prev.clear();
            }
        }
    }

    fn pump(&mut self, sink: &mut Sink) -> bool {
        if self.repeat_left > 0 {
            self.acc.flush(sink);
            let plen = self.pattern.len().max(1);
            let per = (MAX_CHUNK / plen).max(1) * plen;
            let n = self.repeat_left.min(per as u64) as usize;
            self.repeat_buf.clear();
            while self.repeat_buf.len() < n {
                let k = (n - self.repeat_buf.len()).min(self.pattern.len());
                self.repeat_buf.extend_from_slice(&self.pattern[..k]);
            }
            sink.chunk(None, Direction::Unknown, 0, &self.repeat_buf);
            self.repeat_left -= n as u64;
            return true;
        }
        if !self.deferred.is_empty() {
            let d = std::mem::take(&mut self.deferred);
            self.acc.push(&d, sink);
            self.deferred = d;
            self.deferred.clear();
            return true;
        }
        false
    }

    fn finish(&mut self, _end: u64, sink: &mut Sink) {
        if let Some(star_off) = self.star.take() {
            self.diag(star_off, LogProblem::TruncatedRepeat, sink);
        }
        self.acc.close(sink);
    }
}
