//! Reading jpnevulator logs.

use super::*;

/// `2024-05-01 12:00:00.123456:` with ` NAME` when more than one interface is read.
pub(super) fn jpn_header(s: &[u8]) -> Option<(u64, Option<&[u8]>)> {
    let (ts, n) = parse_datetime(s)?;
    let rest = s[n..].strip_prefix(b":")?;
    if rest.is_empty() {
        return Some((ts, None));
    }
    let name = rest.strip_prefix(b" ")?;
    if name.is_empty() || name.iter().any(|&b| is_ws(b)) {
        return None;
    }
    Some((ts, Some(name)))
}

/// `[XXXXXXXX<tab>]05 00 …[   <tab>ascii]`: appends the bytes; returns the byte count and the
/// ASCII column, or the column of a bad byte.
#[allow(clippy::type_complexity)]
pub(super) fn jpn_data<'a>(
    s: &'a [u8],
    out: &mut Vec<u8>,
) -> Result<(Option<u64>, Option<&'a [u8]>), usize> {
    let mut p = 0;
    let mut count = None;
    if s.len() > 9 && s[8] == b'\t' {
        if let Some(c) = parse_hex_u64(&s[..8]) {
            count = Some(c);
            p = 9;
        }
    }
    let body = &s[p..];
    let (hex, gutter) = match body.iter().position(|&b| b == b'\t') {
        Some(i) => (&body[..i], Some(&body[i + 1..])),
        None => (body, None),
    };
    let mut any = false;
    let mut i = 0;
    while i < hex.len() {
        if hex[i] == b' ' {
            i += 1;
            continue;
        }
        let end = hex[i..]
            .iter()
            .position(|&b| b == b' ')
            .map_or(hex.len(), |e| i + e);
        match (end - i == 2).then(|| pair(hex[i], hex[i + 1])).flatten() {
            Some(b) => out.push(b),
            None => return Err(p + i),
        }
        any = true;
        i = end;
    }
    if any {
        Ok((count, gutter))
    } else {
        Err(p)
    }
}

pub(super) fn is_pty(name: &str) -> bool {
    let l = name.to_ascii_lowercase();
    l.starts_with("/dev/pts/") || l.starts_with("/dev/ptmx") || l.starts_with("/dev/pty")
}

/// What an interface's name or alias says about its direction.
pub(super) fn classify_iface(name: &str) -> Option<Direction> {
    if is_pty(name) {
        return Some(Direction::HostToDevice);
    }
    let l = name.to_ascii_lowercase();
    let base = l.rsplit('/').next().unwrap_or(&l);
    const HOST: &[&str] = &[
        "host",
        "pc",
        "app",
        "application",
        "program",
        "computer",
        "software",
    ];
    const DEV: &[&str] = &[
        "device",
        "dev",
        "controller",
        "ctrl",
        "motor",
        "stage",
        "instrument",
    ];
    for word in base
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty())
    {
        if HOST.contains(&word) {
            return Some(Direction::HostToDevice);
        }
        if DEV.contains(&word) {
            return Some(Direction::DeviceToHost);
        }
    }
    None
}

pub(super) fn opposite(d: Direction) -> Direction {
    match d {
        Direction::HostToDevice => Direction::DeviceToHost,
        Direction::DeviceToHost => Direction::HostToDevice,
        Direction::Unknown => Direction::Unknown,
    }
}

/// Interface names in the first lines of a jpnevulator log, with the direction each carries.
pub(super) fn jpn_hints(head: &[u8]) -> Vec<(String, Direction)> {
    let mut names: Vec<String> = Vec::new();
    for line in head.split(|&b| b == b'\n').map(strip_cr) {
        let name = match jpn_header(line) {
            Some((_, Some(n))) => n,
            Some((_, None)) => continue,
            None if line.starts_with(b"/") && !line.iter().any(|&b| is_ws(b)) => line,
            None => continue,
        };
        let name = String::from_utf8_lossy(name).into_owned();
        if !names.contains(&name) && names.len() < 64 {
            names.push(name);
        }
    }
    let mut dirs: Vec<Option<Direction>> = names.iter().map(|n| classify_iface(n)).collect();
    if names.iter().any(|n| is_pty(n)) {
        for (n, d) in names.iter().zip(dirs.iter_mut()) {
            if d.is_none() && !is_pty(n) {
                *d = Some(Direction::DeviceToHost);
            }
        }
    }
    if let [a, b] = dirs[..] {
        match (a, b) {
            (Some(a), None) => dirs[1] = Some(opposite(a)),
            (None, Some(b)) => dirs[0] = Some(opposite(b)),
            _ => {}
        }
    }
    names
        .into_iter()
        .zip(dirs)
        .map(|(n, d)| (n, d.unwrap_or(Direction::Unknown)))
        .collect()
}

pub(super) struct Iface {
    name: String,
    dir: Direction,
    count: Option<u64>,
    /// Interfaces of known direction are the two ends of one serial line: one stream, 0.
    stream: u32,
}

pub(super) struct Jpn {
    acc: Acc,
    hints: Vec<(String, Direction)>,
    ifaces: Vec<Iface>,
    cur: Option<usize>,
    /// Byte count of the unnamed interface (one tty).
    count: Option<u64>,
    scratch: Vec<u8>,
}

impl Jpn {
    pub(super) fn new(hints: Vec<(String, Direction)>) -> Self {
        Jpn {
            acc: Acc::default(),
            hints,
            ifaces: vec![],
            cur: None,
            count: None,
            scratch: vec![],
        }
    }

    fn select(&mut self, name: &[u8], sink: &mut Sink) -> usize {
        let name = String::from_utf8_lossy(name);
        if let Some(i) = self.ifaces.iter().position(|f| f.name == name) {
            return i;
        }
        let pty_seen = self.ifaces.iter().any(|f| is_pty(&f.name));
        let dir = self
            .hints
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, d)| *d)
            .or_else(|| classify_iface(&name))
            .or_else(|| (pty_seen && !is_pty(&name)).then_some(Direction::DeviceToHost))
            .unwrap_or(Direction::Unknown);
        // The pty (what the host wrote) and the tty (what the device answered) are one line.
        let directed = dir != Direction::Unknown;
        let line_known = self.ifaces.iter().any(|f| f.dir != Direction::Unknown);
        let first_directed = self
            .ifaces
            .iter()
            .find(|f| f.dir != Direction::Unknown)
            .map(|f| f.stream);
        let id = match (directed, first_directed) {
            (true, Some(s)) => s,
            _ => self.ifaces.len() as u32,
        };
        if !(directed && line_known) {
            sink.stream(StreamInfo {
                id,
                name: name.to_string(),
                settings: None,
            });
        }
        self.ifaces.push(Iface {
            name: name.into_owned(),
            dir,
            count: None,
            stream: id,
        });
        self.ifaces.len() - 1
    }

    fn start(&mut self, ts: Option<u64>, sink: &mut Sink) {
        let (dir, stream) = match self.cur {
            Some(i) => (self.ifaces[i].dir, self.ifaces[i].stream),
            None => (Direction::Unknown, 0),
        };
        self.acc.start(ts, dir, stream, sink);
    }
}

impl LineParser for Jpn {
    fn line(&mut self, s: &[u8], off: u64, sink: &mut Sink) {
        if trim(s).is_empty() {
            return;
        }
        if let Some((ts, name)) = jpn_header(s) {
            if let Some(name) = name {
                self.cur = Some(self.select(name, sink));
            }
            self.start(Some(ts), sink);
            return;
        }
        if s.starts_with(b"le=") {
            return; // modem control bits (--control)
        }
        let is_name = !s.iter().any(|&b| is_ws(b))
            && (s.starts_with(b"/") || self.ifaces.iter().any(|f| f.name.as_bytes() == s));
        if is_name {
            self.cur = Some(self.select(s, sink));
            self.start(None, sink);
            return;
        }
        self.scratch.clear();
        let res = jpn_data(s, &mut self.scratch);
        let n = self.scratch.len() as u64;
        match res {
            Ok((count, gutter)) => {
                if let Some(c) = count {
                    let slot = match self.cur {
                        Some(i) => &mut self.ifaces[i].count,
                        None => &mut self.count,
                    };
                    if let Some(exp) = *slot {
                        if exp != c {
                            let problem = LogProblem::ByteCountGap {
                                expected: exp,
                                found: c,
                            };
                            sink.diag(off, problem);
                        }
                    }
                    *slot = Some(c + n);
                }
                if let Some(g) = gutter {
                    if !gutter_matches(&self.scratch, g) {
                        sink.diag(off, LogProblem::AsciiMismatch { ascii: show(g) });
                    }
                }
            }
            Err(col) if n == 0 && col == 0 => {
                sink.diag(off, garbage("a jpnevulator log", s));
            }
            Err(col) => sink.diag(off, bad_hex(s, col)),
        }
        if n > 0 {
            if !self.acc.open {
                self.start(None, sink);
            }
            self.acc.push(&self.scratch, sink);
        }
    }

    fn finish(&mut self, _end: u64, sink: &mut Sink) {
        self.acc.close(sink);
    }
}
