//! Reading socat logs (`socat -v -x`).

use super::*;

pub(super) struct SocatHeader {
    dir: Direction,
    ts: Option<u64>,
    length: u64,
    from: u64,
    to: u64,
}

/// `> 2024/05/01 12:00:00.123456  length=6 from=0 to=5` (the timestamp is optional).
pub(super) fn socat_header(s: &[u8]) -> Option<SocatHeader> {
    let dir = match *s.first()? {
        b'>' => Direction::HostToDevice,
        b'<' => Direction::DeviceToHost,
        _ => return None,
    };
    if s.get(1) != Some(&b' ') {
        return None;
    }
    let mut p = 2;
    let mut ts = None;
    if s.get(p).is_some_and(u8::is_ascii_digit) {
        let (t, n) = parse_datetime(&s[p..])?;
        ts = Some(t);
        p += n;
    }
    let mut it = s[p..].split(|&b| b == b' ').filter(|t| !t.is_empty());
    let field = |tok: Option<&[u8]>, name: &[u8]| parse_u64(tok?.strip_prefix(name)?);
    let length = field(it.next(), b"length=")?;
    let from = field(it.next(), b"from=")?;
    let to = field(it.next(), b"to=")?;
    if it.next().is_some() {
        return None;
    }
    Some(SocatHeader {
        dir,
        ts,
        length,
        from,
        to,
    })
}

/// socat's own log lines (`2024/05/01 12:00:00 socat[123] N …`), which share stderr with the dump.
pub(super) fn socat_log_line(s: &[u8]) -> bool {
    parse_datetime(s).is_some_and(|(_, n)| trim(&s[n..]).starts_with(b"socat["))
}

/// A socat hex line: ` 05 00 …` (16 at most with `-v`, then padding, two spaces and the ASCII
/// column; with `-x` alone, every byte of the block on one line). Appends the bytes to `out`;
/// returns the ASCII column, or the column of a bad byte.
pub(super) fn socat_hex<'a>(s: &'a [u8], out: &mut Vec<u8>) -> Result<Option<&'a [u8]>, usize> {
    let start = out.len();
    let mut p = 0;
    while p + 3 <= s.len() && s[p] == b' ' && (p + 3 == s.len() || s[p + 3] == b' ') {
        match pair(s[p + 1], s[p + 2]) {
            Some(b) => out.push(b),
            None => break,
        }
        p += 3;
    }
    let rest = &s[p..];
    let n = out.len() - start;
    if rest.is_empty() {
        return if n > 0 { Ok(None) } else { Err(0) };
    }
    if n == 0 || !rest.starts_with(b"  ") {
        return Err(p + 1);
    }
    Ok((rest.len() >= n + 2).then(|| &s[s.len() - n..]))
}

#[derive(Default)]
pub(super) struct Socat {
    acc: Acc,
    /// The block being read: its header's offset and `length=` (when readable).
    block: Option<(u64, Option<u64>)>,
    got: u64,
    next_from: [Option<u64>; 2],
    scratch: Vec<u8>,
}

impl Socat {
    fn end_block(&mut self, sink: &mut Sink) {
        if let Some((off, length)) = self.block.take() {
            if let Some(len) = length {
                if len != self.got {
                    let problem = LogProblem::LengthMismatch {
                        expected: len,
                        found: self.got,
                    };
                    sink.diag(off, problem);
                }
            }
            self.acc.close(sink);
        }
    }

    fn begin(
        &mut self,
        off: u64,
        length: Option<u64>,
        ts: Option<u64>,
        dir: Direction,
        sink: &mut Sink,
    ) {
        self.end_block(sink);
        self.block = Some((off, length));
        self.got = 0;
        self.acc.start(ts, dir, 0, sink);
    }
}

impl LineParser for Socat {
    fn line(&mut self, s: &[u8], off: u64, sink: &mut Sink) {
        if trim(s).is_empty() {
            return;
        }
        if let Some(h) = socat_header(s) {
            let di = usize::from(h.dir == Direction::DeviceToHost);
            if let Some(exp) = self.next_from[di] {
                if h.from != exp {
                    let problem = LogProblem::SequenceGap {
                        expected: exp,
                        found: h.from,
                    };
                    sink.diag(off, problem);
                }
            }
            if h.length == 0 || h.to.checked_sub(h.from) != Some(h.length - 1) {
                let problem = LogProblem::SpanMismatch {
                    from: h.from,
                    to: h.to,
                    length: h.length,
                };
                sink.diag(off, problem);
            }
            self.next_from[di] = Some(h.from.saturating_add(h.length));
            self.begin(off, Some(h.length), h.ts, h.dir, sink);
            return;
        }
        if s == b"--" {
            self.end_block(sink);
            return;
        }
        if s[0] == b' ' {
            if self.block.is_none() {
                sink.diag(off, LogProblem::MissingHeader);
                self.begin(off, None, None, Direction::Unknown, sink);
            }
            self.scratch.clear();
            let res = socat_hex(s, &mut self.scratch);
            self.got += self.scratch.len() as u64;
            match res {
                Ok(Some(g)) if !gutter_matches(&self.scratch, g) => {
                    sink.diag(off, LogProblem::AsciiMismatch { ascii: show(g) })
                }
                Ok(_) => {}
                Err(col) => sink.diag(off, bad_hex(s, col)),
            }
            self.acc.push(&self.scratch, sink);
            return;
        }
        if let Some(&c) = s.first().filter(|&&c| c == b'>' || c == b'<') {
            if s.len() == 1 || s[1] == b' ' {
                sink.diag(off, LogProblem::BadHeader { line: show(s) });
                let dir = if c == b'>' {
                    Direction::HostToDevice
                } else {
                    Direction::DeviceToHost
                };
                self.begin(off, None, None, dir, sink);
                return;
            }
        }
        if socat_log_line(s) {
            return;
        }
        sink.diag(off, garbage("a socat dump", s));
    }

    fn finish(&mut self, _end: u64, sink: &mut Sink) {
        self.end_block(sink);
    }
}
