//! Reading interceptty logs.

use super::*;

pub(super) struct IcptLine {
    /// Time of day of a `[HH:MM SS.uuuuuu]` prefix (the first byte of a read).
    tod: Option<u64>,
    dir: Direction,
}

/// An interceptty line: `[ts]< 0x54 (T)`, `> \t0x4b (K)`, or with `-e`, `< 30(0):31(1)`.
/// `Ok(None)` for a line of another shape; `Err((kind, column))` for a bad one.
pub(super) fn icpt_line(
    s: &[u8],
    out: &mut Vec<u8>,
) -> Result<Option<IcptLine>, (LogField, usize)> {
    let mut p = 0;
    let mut tod = None;
    if s.first() == Some(&b'[') {
        let Some(close) = s.iter().position(|&b| b == b']') else {
            return Ok(None);
        };
        let inner = &s[1..close];
        match parse_tod(inner, true) {
            Some((t, n)) if n == inner.len() => tod = Some(t),
            _ => return Err((LogField::Timestamp, 1)),
        }
        p = close + 1;
    }
    p = skip_ws(s, p);
    let dir = match s.get(p) {
        Some(b'<') => Direction::HostToDevice,
        Some(b'>') => Direction::DeviceToHost,
        _ => return Ok(None),
    };
    if s.get(p + 1) != Some(&b' ') {
        return Ok(None);
    }
    p = skip_ws(s, p + 2);
    let bad = |p: usize| Err((LogField::Hex, p));
    if s[p..].starts_with(b"0x") || s[p..].starts_with(b"0X") {
        let Some(b) = s.get(p + 2..p + 4).and_then(|h| pair(h[0], h[1])) else {
            return bad(p);
        };
        let rest = &s[p + 4..];
        if !rest.is_empty() && !rest.starts_with(b" ") {
            return bad(p);
        }
        out.push(b);
        return Ok(Some(IcptLine { tod, dir }));
    }
    // -e (end-of-line character) mode: hh(c):hh(c)…
    loop {
        let Some(b) = s.get(p..p + 2).and_then(|h| pair(h[0], h[1])) else {
            return bad(p);
        };
        out.push(b);
        p += 2;
        if s.get(p) == Some(&b'(') {
            let r = &s[p + 1..];
            let used = if r.starts_with(b"[") {
                r.windows(2).position(|w| w == b"])").map(|i| i + 2)
            } else if r.starts_with(b"' ')") {
                Some(4)
            } else {
                (r.get(1) == Some(&b')')).then_some(2)
            };
            let Some(used) = used else {
                return bad(p);
            };
            p += 1 + used;
        }
        match s.get(p) {
            None => return Ok(Some(IcptLine { tod, dir })),
            Some(b':') => p += 1,
            Some(_) if trim(&s[p..]).is_empty() => return Ok(Some(IcptLine { tod, dir })),
            Some(_) => return bad(p),
        }
    }
}

#[derive(Default)]
pub(super) struct Icpt {
    acc: Acc,
    clock: TodClock,
    scratch: Vec<u8>,
}

impl LineParser for Icpt {
    fn line(&mut self, s: &[u8], off: u64, sink: &mut Sink) {
        if trim(s).is_empty() || s.starts_with(b"#") {
            return;
        }
        self.scratch.clear();
        match icpt_line(s, &mut self.scratch) {
            Ok(Some(l)) => {
                let ts = l.tod.map(|t| self.clock.at(t));
                if ts.is_some() || !self.acc.open || self.acc.dir != Some(l.dir) {
                    let ts = ts.or(if self.acc.open { self.acc.ts } else { None });
                    self.acc.start(ts, l.dir, 0, sink);
                }
                self.acc.push(&self.scratch, sink);
            }
            Ok(None) => {
                sink.diag(off, garbage("an interceptty log", s));
            }
            Err((field, col)) => {
                sink.diag(off, unreadable(field, col, s));
            }
        }
    }

    fn finish(&mut self, _end: u64, sink: &mut Sink) {
        self.acc.close(sink);
    }
}
