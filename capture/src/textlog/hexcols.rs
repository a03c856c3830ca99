//! Reading plain hex with offset and/or timestamp columns.

use super::*;

pub(super) enum ColTs {
    Absolute(u64),
    TimeOfDay(u64),
}

pub(super) struct ColsLine {
    pub(super) ts: Option<ColTs>,
    pub(super) offset: bool,
}

/// A timestamp column at the start of `s`: (time, bytes used).
pub(super) fn col_timestamp(s: &[u8]) -> Option<(ColTs, usize)> {
    if let Some((t, n)) = parse_datetime(s) {
        let n = if s.get(n) == Some(&b'Z') { n + 1 } else { n };
        return Some((ColTs::Absolute(t), n));
    }
    if let Some((t, n)) = parse_tod(s, false) {
        return Some((ColTs::TimeOfDay(t), n));
    }
    parse_seconds(s).map(|(t, n)| (ColTs::Absolute(t), n))
}

pub(super) fn col_sep(b: u8) -> bool {
    b == b' ' || b == b'\t' || b == b','
}

/// `[timestamp] [offset] 05 00 … [ascii]`: appends the bytes. `Err((kind, column))` when
/// unreadable.
pub(super) fn cols_line(s: &[u8], out: &mut Vec<u8>) -> Result<ColsLine, (LogField, usize)> {
    let mut p = skip_ws(s, 0);
    let mut ts = None;
    if s.get(p) == Some(&b'[') {
        let close = s
            .iter()
            .position(|&b| b == b']')
            .ok_or((LogField::Timestamp, p))?;
        let inner = trim(&s[p + 1..close]);
        match col_timestamp(inner) {
            Some((t, n)) if n == inner.len() => ts = Some(t),
            _ => return Err((LogField::Timestamp, p)),
        }
        p = close + 1;
    } else if let Some((t, n)) = col_timestamp(&s[p..]) {
        let after = s.get(p + n).copied();
        if after.is_none() || after.is_some_and(|b| is_ws(b) || b == b':' || b == b',') {
            ts = Some(t);
            p += n;
        }
    }
    if ts.is_some() && matches!(s.get(p), Some(b':' | b',')) {
        p += 1;
    }
    let tok_end = |p: usize| {
        s[p..]
            .iter()
            .position(|&b| col_sep(b))
            .map_or(s.len(), |e| p + e)
    };
    // An offset: a hex number of 4+ digits, or any hex number ending in ':'.
    p = skip_ws(s, p);
    let mut offset = false;
    if p < s.len() {
        let end = tok_end(p);
        let tok = &s[p..end];
        let (num, colon) = match tok.strip_suffix(b":") {
            Some(t) => (t, true),
            None => (tok, false),
        };
        if parse_hex_u64(num).is_some() && (colon || (4..=16).contains(&num.len())) {
            offset = true;
            p = end;
        }
    }
    let first = out.len();
    let mut gap = 0;
    while p < s.len() {
        if col_sep(s[p]) {
            gap += if s[p] == b'\t' { 2 } else { 1 };
            p += 1;
            continue;
        }
        let end = tok_end(p);
        let tok = &s[p..end];
        let t = tok
            .strip_prefix(b"0x")
            .or_else(|| tok.strip_prefix(b"0X"))
            .unwrap_or(tok);
        match (t.len() == 2).then(|| pair(t[0], t[1])).flatten() {
            Some(b) => out.push(b),
            None if out.len() > first && (gap >= 2 || tok[0] == b'|' || tok[0] == b'>') => break,
            None if out.len() == first && tok.len() > 2 && ts.is_none() && !offset => {
                return Err((LogField::Line, p))
            }
            None => return Err((LogField::Hex, p)),
        }
        gap = 0;
        p = end;
    }
    Ok(ColsLine { ts, offset })
}

#[derive(Default)]
pub(super) struct HexCols {
    clock: TodClock,
    scratch: Vec<u8>,
}

impl LineParser for HexCols {
    fn line(&mut self, s: &[u8], off: u64, sink: &mut Sink) {
        let t = trim(s);
        if t.is_empty() || t.starts_with(b"#") || t.starts_with(b"//") {
            return;
        }
        self.scratch.clear();
        match cols_line(s, &mut self.scratch) {
            Ok(l) => {
                let ts = l.ts.map(|t| match t {
                    ColTs::Absolute(t) => t,
                    ColTs::TimeOfDay(t) => self.clock.at(t),
                });
                sink.chunk(ts, Direction::Unknown, 0, &self.scratch);
            }
            Err((field, col)) => {
                sink.diag(off, unreadable(field, col, s));
                sink.chunk(None, Direction::Unknown, 0, &self.scratch);
            }
        }
    }

    fn finish(&mut self, _end: u64, _sink: &mut Sink) {}
}
