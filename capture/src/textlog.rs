//! Text logs of serial tools (socat, jpnevulator, interceptty) and hex dumps with columns (xxd,
//! `hexdump -C`, plain hex with offset and/or timestamp columns), read line by line.
//!
//! Every reader streams: it holds one line (at most [`MAX_LINE`] bytes) and one chunk (at most
//! [`MAX_CHUNK`] bytes) at a time. A line it cannot read gives an [`Event::Diag`] whose offset is
//! the byte offset of that line in the file (the column, when useful, is in the message), and
//! reading carries on with the next line. Diagnostic kinds:
//!
//! | kind | meaning |
//! |---|---|
//! | `bad_hex` | a byte column holds something other than two hex digits (the bytes before it on the line are kept) |
//! | `garbage_line` | a line that is not part of the format |
//! | `truncated_line` | the last line has no newline: the file was cut (what it holds is still read) |
//! | `line_too_long` | a line longer than [`MAX_LINE`] (skipped) |
//! | `length_mismatch` | socat: `length=` disagrees with the bytes that follow, or with `from=`/`to=` |
//! | `sequence_gap` | socat: `from=` is not where the previous block of that direction ended (blocks are missing) |
//! | `bad_header` | socat: a direction line that cannot be read (its data is kept, direction known) |
//! | `missing_header` | socat: hex data before any direction line (kept, direction unknown) |
//! | `bad_timestamp` | a timestamp column that cannot be read |
//! | `byte_count_gap` | jpnevulator `--byte-count`: the count does not follow on from the previous line |
//! | `offset_gap` | xxd/hexdump: a line's offset is not where the previous line ended |
//! | `bad_repeat` | xxd/hexdump: a `*` (repeated line) that does not fit between the offsets around it |
//! | `truncated_repeat` | xxd/hexdump: the dump ends after a `*`, so the repeat count is unknown |
//! | `ascii_mismatch` | the ASCII column disagrees with the hex bytes (the hex bytes are kept) |
//! | `io_error` | reading the file failed (reading stops) |
//!
//! Timestamps: logs write local time without a zone; they are read as if they were UTC, so
//! `ts_ns` is "nanoseconds since the epoch" of the wall-clock time printed. Formats that print
//! only the time of day (interceptty `-T`, time-of-day columns) give nanoseconds since the
//! midnight before the first line, counting a day on when the clock goes back by more than 12 h.

use crate::model::{Chunk, Direction, Event, ReadDiag, Reader, StreamInfo};
use std::collections::VecDeque;
use std::io::{self, BufRead, Cursor, Read};

/// Longest line a reader keeps; a longer line gives `line_too_long` and is skipped.
pub const MAX_LINE: usize = 256 * 1024;
/// Largest chunk a reader produces; longer runs of bytes come as several chunks.
pub const MAX_CHUNK: usize = 64 * 1024;
/// Most bytes one `*` line of a hex dump may stand for.
pub const MAX_REPEAT: u64 = 64 << 20;

/// How much of a jpnevulator log is read ahead to learn the names of its interfaces.
const HEAD_SCAN: usize = 64 * 1024;
/// How many lines [`sniff`] looks at.
const SNIFF_LINES: usize = 400;

const NS: u64 = 1_000_000_000;
const DAY_NS: u64 = 86_400 * NS;

/// A text format this module reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TextFormat {
    /// `socat -x -v` (or `-x`) data dump: `> 2024/05/01 12:00:00.123456  length=6 from=0 to=5`
    /// then ` 05 00 …` lines and `--`. `>` is data from socat's left address to its right one,
    /// `<` the other way; read as host → device and device → host, which holds when socat was
    /// started with the host side on the left (`socat -x -v PTY,link=/tmp/ttyV0 /dev/ttyUSB0`).
    Socat,
    /// `jpnevulator --read --timing-print` output: `2024-05-01 12:00:00.123456:` lines (followed
    /// by the interface name when reading more than one tty/pty), then `05 00 …` lines (with
    /// `--ascii`, an ASCII column after a tab; with `--byte-count`, an `XXXXXXXX<tab>` count
    /// before). A pty (`--pty`, `/dev/pts/N`) carries what the host program wrote (host →
    /// device), and a tty logged next to a pty carries the device's answers; names or aliases
    /// such as `host`/`pc` or `device`/`controller`/`motor` say so too. Otherwise unknown.
    Jpnevulator,
    /// interceptty output: one line per byte, `< 0x54 (T)` for a byte the program sent to the
    /// device (host → device) and `> <tab>0x4b (K)` for a byte from the device (device → host), as
    /// interceptty's manual says; with `-T`, lines start with `[HH:MM SS.uuuuuu]`; with `-e`,
    /// several `hh(c)` bytes joined by `:` per line.
    Interceptty,
    /// `xxd` dump: `00000000: 0500 0000 5001 …  ....P.` (any `-c`/`-g`, `*` from `-a`).
    Xxd,
    /// `hexdump -C` (or `hd`) dump: `00000000  05 00 00 00 50 01 …  |....P.|`, with `*` for
    /// repeated lines and the final length on its own line.
    HexdumpC,
    /// Hex bytes in columns with an optional leading timestamp (`2024-05-01 12:00:00.123`,
    /// `12:00:00.123`, `[…]`, or seconds like `0.123456`) and/or offset (`0000`, `00000010:`),
    /// and an optional trailing ASCII column (after two spaces, or in `|…|`). One chunk per line,
    /// direction unknown.
    HexColumns,
}

impl TextFormat {
    /// Every text format.
    pub const ALL: [TextFormat; 6] = [
        TextFormat::Socat,
        TextFormat::Jpnevulator,
        TextFormat::Interceptty,
        TextFormat::Xxd,
        TextFormat::HexdumpC,
        TextFormat::HexColumns,
    ];

    /// Short name (`socat`, `jpnevulator`, `interceptty`, `xxd`, `hexdump`, `hexcols`).
    pub fn name(self) -> &'static str {
        match self {
            TextFormat::Socat => "socat",
            TextFormat::Jpnevulator => "jpnevulator",
            TextFormat::Interceptty => "interceptty",
            TextFormat::Xxd => "xxd",
            TextFormat::HexdumpC => "hexdump",
            TextFormat::HexColumns => "hexcols",
        }
    }

    /// Parse a short name (also `hexdump-c`, `hd`, `hex-columns`).
    pub fn parse(s: &str) -> Option<TextFormat> {
        Some(match s {
            "socat" => TextFormat::Socat,
            "jpnevulator" => TextFormat::Jpnevulator,
            "interceptty" => TextFormat::Interceptty,
            "xxd" => TextFormat::Xxd,
            "hexdump" | "hexdump-c" | "hd" => TextFormat::HexdumpC,
            "hexcols" | "hex-columns" => TextFormat::HexColumns,
            _ => return None,
        })
    }

    /// What the reader says it reads ([`Reader::format`]).
    pub fn describe(self) -> &'static str {
        match self {
            TextFormat::Socat => "socat -x -v log",
            TextFormat::Jpnevulator => "jpnevulator log",
            TextFormat::Interceptty => "interceptty log",
            TextFormat::Xxd => "xxd dump",
            TextFormat::HexdumpC => "hexdump -C dump",
            TextFormat::HexColumns => "hex columns",
        }
    }
}

/// Recognise a text format from the first few KiB of a file. `None` for anything else: binary
/// data, pcap/pcapng/MCAP, plain spaced hex without columns (left to the plain hex reader), an
/// ASCII Elliptec stream, prose.
pub fn sniff(head: &[u8]) -> Option<TextFormat> {
    if head.is_empty() || looks_binary(head) {
        return None;
    }
    let mut lines: Vec<&[u8]> = Vec::new();
    let mut rest = head;
    while let Some(i) = rest.iter().position(|&b| b == b'\n') {
        lines.push(strip_cr(&rest[..i]));
        rest = &rest[i + 1..];
        if lines.len() >= SNIFF_LINES {
            break;
        }
    }
    // A last line without its newline was cut by the head's length: use it only if alone.
    if lines.is_empty() && !rest.is_empty() {
        lines.push(strip_cr(rest));
    }
    let lines: Vec<&[u8]> = lines.into_iter().filter(|l| !trim(l).is_empty()).collect();
    if lines.is_empty() {
        return None;
    }
    let mut scratch = Vec::with_capacity(256);
    [
        TextFormat::Socat,
        TextFormat::Jpnevulator,
        TextFormat::Interceptty,
        TextFormat::Xxd,
        TextFormat::HexdumpC,
        TextFormat::HexColumns,
    ]
    .into_iter()
    .find(|&f| sniff_as(f, &lines, &mut scratch))
}

/// Open a reader of `kind` over `r`.
pub fn open(kind: TextFormat, r: impl BufRead + 'static) -> Box<dyn Reader> {
    match kind {
        TextFormat::Socat => Box::new(TextReader::new(r, Socat::default(), kind)),
        TextFormat::Jpnevulator => {
            let mut r = r;
            let mut head = Vec::with_capacity(HEAD_SCAN);
            // A read error here shows again (as `io_error`) when the reader gets to it.
            let _ = Read::by_ref(&mut r)
                .take(HEAD_SCAN as u64)
                .read_to_end(&mut head);
            let hints = jpn_hints(&head);
            Box::new(TextReader::new(
                Cursor::new(head).chain(r),
                Jpn::new(hints),
                kind,
            ))
        }
        TextFormat::Interceptty => Box::new(TextReader::new(r, Icpt::default(), kind)),
        TextFormat::Xxd => Box::new(TextReader::new(r, Dump::new(false), kind)),
        TextFormat::HexdumpC => Box::new(TextReader::new(r, Dump::new(true), kind)),
        TextFormat::HexColumns => Box::new(TextReader::new(r, HexCols::default(), kind)),
    }
}

// ---------------------------------------------------------------------------------------------
// Small helpers

fn hexv(b: u8) -> Option<u8> {
    match b {
        b'0'..=b'9' => Some(b - b'0'),
        b'a'..=b'f' => Some(b - b'a' + 10),
        b'A'..=b'F' => Some(b - b'A' + 10),
        _ => None,
    }
}

fn pair(a: u8, b: u8) -> Option<u8> {
    Some(hexv(a)? << 4 | hexv(b)?)
}

fn is_ws(b: u8) -> bool {
    b == b' ' || b == b'\t'
}

fn trim(s: &[u8]) -> &[u8] {
    let start = s.iter().position(|&b| !is_ws(b)).unwrap_or(s.len());
    let end = s.iter().rposition(|&b| !is_ws(b)).map_or(start, |i| i + 1);
    &s[start..end.max(start)]
}

fn strip_cr(s: &[u8]) -> &[u8] {
    s.strip_suffix(b"\r").unwrap_or(s)
}

fn skip_ws(s: &[u8], mut p: usize) -> usize {
    while p < s.len() && is_ws(s[p]) {
        p += 1;
    }
    p
}

fn parse_u64(s: &[u8]) -> Option<u64> {
    if s.is_empty() || s.len() > 19 || !s.iter().all(u8::is_ascii_digit) {
        return None;
    }
    Some(s.iter().fold(0u64, |v, &b| v * 10 + u64::from(b - b'0')))
}

fn parse_hex_u64(s: &[u8]) -> Option<u64> {
    if s.is_empty() || s.len() > 16 {
        return None;
    }
    s.iter()
        .try_fold(0u64, |v, &b| Some(v << 4 | u64::from(hexv(b)?)))
}

/// Whether a dump tool would print `bytes` as `shown` (printable ASCII as itself, else '.').
fn gutter_matches(bytes: &[u8], shown: &[u8]) -> bool {
    bytes.len() == shown.len()
        && bytes.iter().zip(shown).all(|(&b, &c)| {
            if (0x20..0x7f).contains(&b) {
                c == b
            } else {
                c == b'.'
            }
        })
}

fn show(s: &[u8]) -> String {
    let s = if s.len() > 60 { &s[..60] } else { s };
    String::from_utf8_lossy(s).into_owned()
}

/// Text, not binary: no NUL and almost no control characters.
fn looks_binary(head: &[u8]) -> bool {
    let ctrl = head
        .iter()
        .filter(|&&b| b < 0x20 && !matches!(b, b'\n' | b'\r' | b'\t' | 0x0c))
        .count();
    head.contains(&0) || ctrl * 100 > head.len()
}

// ---------------------------------------------------------------------------------------------
// Timestamps

/// Exactly `n` decimal digits at the start of `s`.
fn num(s: &[u8], n: usize) -> Option<u64> {
    if s.len() < n {
        return None;
    }
    let d = &s[..n];
    d.iter()
        .all(u8::is_ascii_digit)
        .then(|| d.iter().fold(0, |v, &b| v * 10 + u64::from(b - b'0')))
}

/// `.fraction` at the start of `s`: (nanoseconds, bytes used); (0, 0) without one.
fn frac(s: &[u8]) -> (u64, usize) {
    if s.first() != Some(&b'.') {
        return (0, 0);
    }
    let digits = s[1..].iter().take_while(|b| b.is_ascii_digit()).count();
    if digits == 0 {
        return (0, 0);
    }
    let ns = (0..9).fold(0u64, |v, i| {
        v * 10
            + if i < digits {
                u64::from(s[1 + i] - b'0')
            } else {
                0
            }
    });
    (ns, 1 + digits)
}

/// `HH:MM:SS[.f]` (or `HH:MM SS[.f]`, as interceptty `-T` writes it, when `space` allows):
/// (nanoseconds since midnight, bytes used).
fn parse_tod(s: &[u8], space: bool) -> Option<(u64, usize)> {
    let h = num(s, 2)?;
    if s.get(2) != Some(&b':') {
        return None;
    }
    let m = num(&s[3..], 2)?;
    let sep = *s.get(5)?;
    if sep != b':' && !(space && sep == b' ') {
        return None;
    }
    let sec = num(&s[6..], 2)?;
    if h > 23 || m > 59 || sec > 60 {
        return None;
    }
    let (f, n) = frac(&s[8..]);
    Some(((h * 3600 + m * 60 + sec) * NS + f, 8 + n))
}

/// Days from 1970-01-01 to a proleptic Gregorian date.
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = if y >= 0 { y } else { y - 399 } / 400;
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// `YYYY-MM-DD HH:MM:SS[.f]` (`/` also as the date separator, `T` also between date and time):
/// (nanoseconds since the epoch, read as UTC; bytes used).
fn parse_datetime(s: &[u8]) -> Option<(u64, usize)> {
    let y = num(s, 4)?;
    let dsep = *s.get(4)?;
    if dsep != b'-' && dsep != b'/' {
        return None;
    }
    let mo = num(&s[5..], 2)?;
    if s.get(7) != Some(&dsep) {
        return None;
    }
    let d = num(&s[8..], 2)?;
    let tsep = *s.get(10)?;
    if tsep != b' ' && tsep != b'T' {
        return None;
    }
    let (tod, n) = parse_tod(&s[11..], false)?;
    if !(1970..=2500).contains(&y) || !(1..=12).contains(&mo) || !(1..=31).contains(&d) {
        return None;
    }
    let days = u64::try_from(days_from_civil(y as i64, mo as i64, d as i64)).ok()?;
    Some((days * DAY_NS + tod, 11 + n))
}

/// Seconds with a fraction (`12.345678`): (nanoseconds, bytes used).
fn parse_seconds(s: &[u8]) -> Option<(u64, usize)> {
    let int = s.iter().take_while(|b| b.is_ascii_digit()).count();
    if int == 0 || int > 12 {
        return None;
    }
    let (f, n) = frac(&s[int..]);
    if n == 0 {
        return None;
    }
    Some((
        parse_u64(&s[..int])?.checked_mul(NS)?.checked_add(f)?,
        int + n,
    ))
}

/// Turns times of day into a running time, counting days when the clock goes back.
#[derive(Default)]
struct TodClock {
    last: Option<u64>,
    days: u64,
}

impl TodClock {
    fn at(&mut self, tod: u64) -> u64 {
        if let Some(last) = self.last {
            if tod + DAY_NS / 2 < last {
                self.days += 1;
            }
        }
        self.last = Some(tod);
        tod.saturating_add(self.days.saturating_mul(DAY_NS))
    }
}

// ---------------------------------------------------------------------------------------------
// The line engine shared by every reader

/// Reads lines of at most `max` bytes, whatever the input.
struct Lines<R> {
    r: R,
    buf: Vec<u8>,
    pos: u64,
    max: usize,
}

struct LineInfo {
    offset: u64,
    terminated: bool,
    too_long: bool,
}

impl<R: BufRead> Lines<R> {
    /// The next line (its text, without `\n`/`\r\n`, in `self.buf`).
    fn next_line(&mut self) -> io::Result<Option<LineInfo>> {
        self.buf.clear();
        let offset = self.pos;
        let mut too_long = false;
        let mut any = false;
        loop {
            let avail = match self.r.fill_buf() {
                Ok(b) => b,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e),
            };
            if avail.is_empty() {
                return Ok(any.then_some(LineInfo {
                    offset,
                    terminated: false,
                    too_long,
                }));
            }
            any = true;
            let (take, found) = match avail.iter().position(|&b| b == b'\n') {
                Some(i) => (i + 1, true),
                None => (avail.len(), false),
            };
            let content = if found { take - 1 } else { take };
            let room = self.max - self.buf.len();
            if content > room {
                too_long = true;
            }
            self.buf.extend_from_slice(&avail[..content.min(room)]);
            self.r.consume(take);
            self.pos += take as u64;
            if found {
                if self.buf.last() == Some(&b'\r') {
                    self.buf.pop();
                }
                return Ok(Some(LineInfo {
                    offset,
                    terminated: true,
                    too_long,
                }));
            }
        }
    }
}

enum Pending {
    Ev(Event<'static>),
    Chunk {
        ts_ns: Option<u64>,
        dir: Direction,
        stream: u32,
        start: usize,
        end: usize,
    },
}

/// Where parsers put what they found, in file order; chunk bytes live in `out` until handed out.
#[derive(Default)]
struct Sink {
    q: VecDeque<Pending>,
    out: Vec<u8>,
    /// The offset of a cut last line, whose own complaints are left out (it is reported as
    /// `truncated_line`; what it holds is still read).
    mute_at: Option<u64>,
}

impl Sink {
    fn diag(&mut self, offset: u64, kind: &'static str, msg: String) {
        if self.mute_at != Some(offset) {
            self.q
                .push_back(Pending::Ev(Event::Diag(ReadDiag { offset, kind, msg })));
        }
    }

    fn stream(&mut self, info: StreamInfo) {
        self.q.push_back(Pending::Ev(Event::Stream(info)));
    }

    fn chunk(&mut self, ts_ns: Option<u64>, dir: Direction, stream: u32, bytes: &[u8]) {
        if bytes.is_empty() {
            return;
        }
        let start = self.out.len();
        self.out.extend_from_slice(bytes);
        self.q.push_back(Pending::Chunk {
            ts_ns,
            dir,
            stream,
            start,
            end: self.out.len(),
        });
    }
}

/// The chunk being gathered from several lines.
#[derive(Default)]
struct Acc {
    bytes: Vec<u8>,
    ts: Option<u64>,
    dir: Option<Direction>,
    stream: u32,
    open: bool,
}

impl Acc {
    fn start(&mut self, ts: Option<u64>, dir: Direction, stream: u32, sink: &mut Sink) {
        self.close(sink);
        self.ts = ts;
        self.dir = Some(dir);
        self.stream = stream;
        self.open = true;
    }

    fn push(&mut self, b: &[u8], sink: &mut Sink) {
        if !self.open {
            self.start(None, Direction::Unknown, 0, sink);
        }
        let mut b = b;
        while !b.is_empty() {
            let n = b.len().min(MAX_CHUNK - self.bytes.len());
            self.bytes.extend_from_slice(&b[..n]);
            b = &b[n..];
            if self.bytes.len() >= MAX_CHUNK {
                self.flush(sink);
            }
        }
    }

    fn flush(&mut self, sink: &mut Sink) {
        sink.chunk(
            self.ts,
            self.dir.unwrap_or(Direction::Unknown),
            self.stream,
            &self.bytes,
        );
        self.bytes.clear();
    }

    fn close(&mut self, sink: &mut Sink) {
        self.flush(sink);
        self.open = false;
    }
}

/// One format's line grammar.
trait LineParser {
    /// Handle a line (`s`, without its end of line) that starts at file offset `off`.
    fn line(&mut self, s: &[u8], off: u64, sink: &mut Sink);
    /// End of input at file offset `end`.
    fn finish(&mut self, end: u64, sink: &mut Sink);
    /// Produce pending output without reading a line; true when anything changed.
    fn pump(&mut self, _sink: &mut Sink) -> bool {
        false
    }
}

struct TextReader<R, P> {
    lines: Lines<R>,
    p: P,
    sink: Sink,
    kind: TextFormat,
    done: bool,
}

impl<R: BufRead, P: LineParser> TextReader<R, P> {
    fn new(r: R, p: P, kind: TextFormat) -> Self {
        TextReader {
            lines: Lines {
                r,
                buf: Vec::with_capacity(256),
                pos: 0,
                max: MAX_LINE,
            },
            p,
            sink: Sink::default(),
            kind,
            done: false,
        }
    }
}

impl<R: BufRead, P: LineParser> Reader for TextReader<R, P> {
    fn next_event(&mut self) -> Option<Event<'_>> {
        if self.sink.q.is_empty() {
            self.sink.out.clear();
        }
        while self.sink.q.is_empty() {
            if self.p.pump(&mut self.sink) {
                continue;
            }
            if self.done {
                return None;
            }
            match self.lines.next_line() {
                Ok(Some(info)) => {
                    if info.too_long {
                        self.sink.diag(
                            info.offset,
                            "line_too_long",
                            format!("line longer than {MAX_LINE} bytes, skipped"),
                        );
                    } else if !info.terminated {
                        self.sink.diag(
                            info.offset,
                            "truncated_line",
                            "the last line has no end of line: the file was cut".into(),
                        );
                        self.sink.mute_at = Some(info.offset);
                        self.p.line(&self.lines.buf, info.offset, &mut self.sink);
                        self.sink.mute_at = None;
                    } else {
                        self.p.line(&self.lines.buf, info.offset, &mut self.sink);
                    }
                }
                Ok(None) => {
                    self.p.finish(self.lines.pos, &mut self.sink);
                    self.done = true;
                }
                Err(e) => {
                    self.sink.diag(self.lines.pos, "io_error", e.to_string());
                    self.p.finish(self.lines.pos, &mut self.sink);
                    self.done = true;
                }
            }
        }
        let ev = match self.sink.q.pop_front()? {
            Pending::Ev(e) => e,
            Pending::Chunk {
                ts_ns,
                dir,
                stream,
                start,
                end,
            } => Event::Chunk(Chunk {
                ts_ns,
                dir,
                stream,
                bytes: &self.sink.out[start..end],
            }),
        };
        Some(ev)
    }

    fn format(&self) -> String {
        self.kind.describe().to_string()
    }
}

// ---------------------------------------------------------------------------------------------
// socat

struct SocatHeader {
    dir: Direction,
    ts: Option<u64>,
    length: u64,
    from: u64,
    to: u64,
}

/// `> 2024/05/01 12:00:00.123456  length=6 from=0 to=5` (the timestamp is optional).
fn socat_header(s: &[u8]) -> Option<SocatHeader> {
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
fn socat_log_line(s: &[u8]) -> bool {
    parse_datetime(s).is_some_and(|(_, n)| trim(&s[n..]).starts_with(b"socat["))
}

/// A socat hex line: ` 05 00 …` (16 at most with `-v`, then padding, two spaces and the ASCII
/// column; with `-x` alone, every byte of the block on one line). Appends the bytes to `out`;
/// returns the ASCII column, or the column of a bad byte.
fn socat_hex<'a>(s: &'a [u8], out: &mut Vec<u8>) -> Result<Option<&'a [u8]>, usize> {
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
struct Socat {
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
                    sink.diag(
                        off,
                        "length_mismatch",
                        format!("the header says length={len} but {} bytes follow", self.got),
                    );
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
                    sink.diag(
                        off,
                        "sequence_gap",
                        format!(
                            "from={} but {exp} bytes were logged before in this direction: \
                             blocks are missing",
                            h.from
                        ),
                    );
                }
            }
            if h.length == 0 || h.to.checked_sub(h.from) != Some(h.length - 1) {
                sink.diag(
                    off,
                    "length_mismatch",
                    format!(
                        "from={} to={} do not span length={}",
                        h.from, h.to, h.length
                    ),
                );
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
                sink.diag(
                    off,
                    "missing_header",
                    "hex data without a direction line before it: kept, direction unknown".into(),
                );
                self.begin(off, None, None, Direction::Unknown, sink);
            }
            self.scratch.clear();
            let res = socat_hex(s, &mut self.scratch);
            self.got += self.scratch.len() as u64;
            match res {
                Ok(Some(g)) if !gutter_matches(&self.scratch, g) => sink.diag(
                    off,
                    "ascii_mismatch",
                    format!(
                        "the ASCII column {:?} does not match the hex bytes",
                        show(g)
                    ),
                ),
                Ok(_) => {}
                Err(col) => sink.diag(
                    off,
                    "bad_hex",
                    format!(
                        "not a hex byte at column {}: {:?}",
                        col + 1,
                        show(&s[col.min(s.len())..])
                    ),
                ),
            }
            self.acc.push(&self.scratch, sink);
            return;
        }
        if let Some(&c) = s.first().filter(|&&c| c == b'>' || c == b'<') {
            if s.len() == 1 || s[1] == b' ' {
                sink.diag(
                    off,
                    "bad_header",
                    format!("unreadable direction line {:?}", show(s)),
                );
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
        sink.diag(
            off,
            "garbage_line",
            format!("not part of a socat dump: {:?}", show(s)),
        );
    }

    fn finish(&mut self, _end: u64, sink: &mut Sink) {
        self.end_block(sink);
    }
}

// ---------------------------------------------------------------------------------------------
// jpnevulator

/// `2024-05-01 12:00:00.123456:` with ` NAME` when more than one interface is read.
fn jpn_header(s: &[u8]) -> Option<(u64, Option<&[u8]>)> {
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
fn jpn_data<'a>(s: &'a [u8], out: &mut Vec<u8>) -> Result<(Option<u64>, Option<&'a [u8]>), usize> {
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

fn is_pty(name: &str) -> bool {
    let l = name.to_ascii_lowercase();
    l.starts_with("/dev/pts/") || l.starts_with("/dev/ptmx") || l.starts_with("/dev/pty")
}

/// What an interface's name or alias says about its direction.
fn classify_iface(name: &str) -> Option<Direction> {
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

fn opposite(d: Direction) -> Direction {
    match d {
        Direction::HostToDevice => Direction::DeviceToHost,
        Direction::DeviceToHost => Direction::HostToDevice,
        Direction::Unknown => Direction::Unknown,
    }
}

/// Interface names in the first lines of a jpnevulator log, with the direction each carries.
fn jpn_hints(head: &[u8]) -> Vec<(String, Direction)> {
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

struct Iface {
    name: String,
    dir: Direction,
    count: Option<u64>,
    /// Interfaces of known direction are the two ends of one serial line: one stream, 0.
    stream: u32,
}

struct Jpn {
    acc: Acc,
    hints: Vec<(String, Direction)>,
    ifaces: Vec<Iface>,
    cur: Option<usize>,
    /// Byte count of the unnamed interface (one tty).
    count: Option<u64>,
    scratch: Vec<u8>,
}

impl Jpn {
    fn new(hints: Vec<(String, Direction)>) -> Self {
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
                            sink.diag(
                                off,
                                "byte_count_gap",
                                format!(
                                    "byte count {c:08X} where {exp:08X} was due: bytes are missing"
                                ),
                            );
                        }
                    }
                    *slot = Some(c + n);
                }
                if let Some(g) = gutter {
                    if !gutter_matches(&self.scratch, g) {
                        sink.diag(
                            off,
                            "ascii_mismatch",
                            format!(
                                "the ASCII column {:?} does not match the hex bytes",
                                show(g)
                            ),
                        );
                    }
                }
            }
            Err(col) if n == 0 && col == 0 => {
                sink.diag(
                    off,
                    "garbage_line",
                    format!("not part of a jpnevulator log: {:?}", show(s)),
                );
            }
            Err(col) => sink.diag(
                off,
                "bad_hex",
                format!(
                    "not a hex byte at column {}: {:?}",
                    col + 1,
                    show(&s[col.min(s.len())..])
                ),
            ),
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

// ---------------------------------------------------------------------------------------------
// interceptty

struct IcptLine {
    /// Time of day of a `[HH:MM SS.uuuuuu]` prefix (the first byte of a read).
    tod: Option<u64>,
    dir: Direction,
}

/// An interceptty line: `[ts]< 0x54 (T)`, `> \t0x4b (K)`, or with `-e`, `< 30(0):31(1)`.
/// `Ok(None)` for a line of another shape; `Err((kind, column))` for a bad one.
fn icpt_line(s: &[u8], out: &mut Vec<u8>) -> Result<Option<IcptLine>, (&'static str, usize)> {
    let mut p = 0;
    let mut tod = None;
    if s.first() == Some(&b'[') {
        let Some(close) = s.iter().position(|&b| b == b']') else {
            return Ok(None);
        };
        let inner = &s[1..close];
        match parse_tod(inner, true) {
            Some((t, n)) if n == inner.len() => tod = Some(t),
            _ => return Err(("bad_timestamp", 1)),
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
    let bad = |p: usize| Err(("bad_hex", p));
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
struct Icpt {
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
                sink.diag(
                    off,
                    "garbage_line",
                    format!("not part of an interceptty log: {:?}", show(s)),
                );
            }
            Err((kind, col)) => {
                sink.diag(
                    off,
                    kind,
                    format!("unreadable at column {}: {:?}", col + 1, show(s)),
                );
            }
        }
    }

    fn finish(&mut self, _end: u64, sink: &mut Sink) {
        self.acc.close(sink);
    }
}

// ---------------------------------------------------------------------------------------------
// xxd and hexdump -C

enum DumpLine<'a> {
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
fn xxd_line<'a>(s: &'a [u8], out: &mut Vec<u8>) -> Result<Option<DumpLine<'a>>, usize> {
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
fn hexdump_line<'a>(s: &'a [u8], out: &mut Vec<u8>) -> Result<Option<DumpLine<'a>>, usize> {
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

struct Dump {
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
    fn new(hexdump: bool) -> Self {
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

    fn diag(&mut self, off: u64, kind: &'static str, msg: String, sink: &mut Sink) {
        self.acc.flush(sink);
        sink.diag(off, kind, msg);
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
                    "bad_repeat",
                    format!(
                        "a '*' line standing for {} bytes (more than {MAX_REPEAT}); not expanded",
                        offset - exp
                    ),
                    sink,
                ),
                Some(exp) if offset >= exp && plen > 0 && (offset - exp).is_multiple_of(plen) => {
                    self.repeat_left = offset - exp;
                    self.pattern.clear();
                    self.pattern.extend_from_slice(&self.prev);
                }
                _ => self.diag(
                    star_off,
                    "bad_repeat",
                    format!("a '*' line that does not fit before offset {offset:#x}"),
                    sink,
                ),
            }
        } else if let Some(exp) = self.expected {
            if offset != exp {
                self.diag(
                    off,
                    "offset_gap",
                    format!("offset {offset:#x} where {exp:#x} was due"),
                    sink,
                );
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
                    self.diag(
                        off,
                        "bad_repeat",
                        "a '*' line without a line to repeat".into(),
                        sink,
                    );
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
                        self.diag(
                            off,
                            "ascii_mismatch",
                            format!(
                                "the ASCII column {:?} does not match the hex bytes",
                                show(g)
                            ),
                            sink,
                        );
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
                self.diag(
                    off,
                    "garbage_line",
                    format!("not part of a {name} dump: {:?}", show(s)),
                    sink,
                );
            }
            Err(col) => {
                // Keep the bytes before the bad one; the next line's offset is then unknown.
                self.diag(
                    off,
                    "bad_hex",
                    format!(
                        "not a hex byte at column {}: {:?}",
                        col + 1,
                        show(&s[col.min(s.len())..])
                    ),
                    sink,
                );
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
            self.diag(
                star_off,
                "truncated_repeat",
                "the dump ends after '*': how often the line repeats is unknown".into(),
                sink,
            );
        }
        self.acc.close(sink);
    }
}

// ---------------------------------------------------------------------------------------------
// Hex columns

enum ColTs {
    Absolute(u64),
    TimeOfDay(u64),
}

struct ColsLine {
    ts: Option<ColTs>,
    offset: bool,
}

/// A timestamp column at the start of `s`: (time, bytes used).
fn col_timestamp(s: &[u8]) -> Option<(ColTs, usize)> {
    if let Some((t, n)) = parse_datetime(s) {
        let n = if s.get(n) == Some(&b'Z') { n + 1 } else { n };
        return Some((ColTs::Absolute(t), n));
    }
    if let Some((t, n)) = parse_tod(s, false) {
        return Some((ColTs::TimeOfDay(t), n));
    }
    parse_seconds(s).map(|(t, n)| (ColTs::Absolute(t), n))
}

fn col_sep(b: u8) -> bool {
    b == b' ' || b == b'\t' || b == b','
}

/// `[timestamp] [offset] 05 00 … [ascii]`: appends the bytes. `Err((kind, column))` when
/// unreadable.
fn cols_line(s: &[u8], out: &mut Vec<u8>) -> Result<ColsLine, (&'static str, usize)> {
    let mut p = skip_ws(s, 0);
    let mut ts = None;
    if s.get(p) == Some(&b'[') {
        let close = s
            .iter()
            .position(|&b| b == b']')
            .ok_or(("bad_timestamp", p))?;
        let inner = trim(&s[p + 1..close]);
        match col_timestamp(inner) {
            Some((t, n)) if n == inner.len() => ts = Some(t),
            _ => return Err(("bad_timestamp", p)),
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
                return Err(("garbage_line", p))
            }
            None => return Err(("bad_hex", p)),
        }
        gap = 0;
        p = end;
    }
    Ok(ColsLine { ts, offset })
}

#[derive(Default)]
struct HexCols {
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
            Err((kind, col)) => {
                sink.diag(
                    off,
                    kind,
                    format!("unreadable at column {}: {:?}", col + 1, show(s)),
                );
                sink.chunk(None, Direction::Unknown, 0, &self.scratch);
            }
        }
    }

    fn finish(&mut self, _end: u64, _sink: &mut Sink) {}
}

// ---------------------------------------------------------------------------------------------
// Detection

/// How a line fits a format: distinctive, acceptable, or not part of it.
#[derive(PartialEq, Eq)]
enum Fit {
    Strong,
    Ok,
    Bad,
}

fn sniff_as(f: TextFormat, lines: &[&[u8]], scratch: &mut Vec<u8>) -> bool {
    let mut strong = 0;
    let mut bad = 0;
    let mut data = 0;
    for (i, l) in lines.iter().enumerate() {
        scratch.clear();
        let fit = match f {
            TextFormat::Socat => {
                if socat_header(l).is_some() {
                    Fit::Strong
                } else if *l == b"--" || socat_log_line(l) {
                    Fit::Ok
                } else if l.first() == Some(&b' ') && socat_hex(l, scratch).is_ok() {
                    data += 1;
                    Fit::Ok
                } else {
                    Fit::Bad
                }
            }
            TextFormat::Jpnevulator => {
                if jpn_header(l).is_some() {
                    Fit::Strong
                } else if i == 0 {
                    return false; // --timing-print: a timing line comes first
                } else if jpn_data(l, scratch).is_ok() {
                    data += 1;
                    Fit::Ok
                } else if l.starts_with(b"le=")
                    || (l.starts_with(b"/") && !l.iter().any(|&b| is_ws(b)))
                {
                    Fit::Ok
                } else {
                    Fit::Bad
                }
            }
            TextFormat::Interceptty => match icpt_line(l, scratch) {
                Ok(Some(_)) => Fit::Strong,
                _ if l.starts_with(b"#") => Fit::Ok,
                _ => Fit::Bad,
            },
            TextFormat::Xxd => match xxd_line(l, scratch) {
                Ok(Some(DumpLine::Data { .. })) => Fit::Strong,
                Ok(Some(_)) => Fit::Ok,
                _ => Fit::Bad,
            },
            TextFormat::HexdumpC => match hexdump_line(l, scratch) {
                Ok(Some(DumpLine::Data {
                    gutter: Some(_), ..
                })) => Fit::Strong,
                Ok(Some(DumpLine::Repeat | DumpLine::End { .. })) => Fit::Ok,
                _ => Fit::Bad,
            },
            TextFormat::HexColumns => {
                if l.starts_with(b"#") {
                    Fit::Ok
                } else {
                    match cols_line(l, scratch) {
                        // Without a column this is plain hex, for the plain hex reader.
                        Ok(c)
                            if !scratch.is_empty()
                                && (c.ts.is_some() || c.offset || has_gutter(l, scratch.len())) =>
                        {
                            Fit::Strong
                        }
                        // A final offset (od, hexdump) or a line of plain bytes.
                        Ok(_) => Fit::Ok,
                        _ => return false,
                    }
                }
            }
        };
        match fit {
            Fit::Strong => strong += 1,
            Fit::Ok => {}
            Fit::Bad => bad += 1,
        }
    }
    let n = lines.len();
    match f {
        TextFormat::Socat | TextFormat::Jpnevulator => strong >= 1 && data >= 1 && bad * 10 <= n,
        TextFormat::Interceptty => strong >= n.min(2) && bad * 10 <= n,
        TextFormat::Xxd | TextFormat::HexdumpC => strong >= 1 && bad * 10 <= n,
        TextFormat::HexColumns => strong >= 1,
    }
}

/// Whether a hex-columns line has text after its bytes (an ASCII column).
fn has_gutter(l: &[u8], nbytes: usize) -> bool {
    let toks = l.split(|&b| col_sep(b)).filter(|t| !t.is_empty()).count();
    nbytes > 0 && toks > nbytes
}

// ---------------------------------------------------------------------------------------------

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::OwnedChunk;
    use std::io::BufReader;

    fn samples() -> std::path::PathBuf {
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../samples")
    }

    fn sample(name: &str) -> Vec<u8> {
        std::fs::read(samples().join(name)).unwrap()
    }

    struct Got {
        chunks: Vec<OwnedChunk>,
        diags: Vec<ReadDiag>,
        streams: Vec<StreamInfo>,
    }

    impl Got {
        fn bytes(&self) -> Vec<u8> {
            self.chunks
                .iter()
                .flat_map(|c| c.bytes.iter().copied())
                .collect()
        }
        fn kinds(&self) -> Vec<(&'static str, u64)> {
            self.diags.iter().map(|d| (d.kind, d.offset)).collect()
        }
    }

    fn read_all(mut r: Box<dyn Reader>) -> Got {
        let mut g = Got {
            chunks: vec![],
            diags: vec![],
            streams: vec![],
        };
        while let Some(ev) = r.next_event() {
            match ev {
                Event::Chunk(c) => {
                    assert!(!c.bytes.is_empty() && c.bytes.len() <= MAX_CHUNK);
                    g.chunks.push(c.to_owned());
                }
                Event::Diag(d) => g.diags.push(d),
                Event::Stream(s) => g.streams.push(s),
            }
        }
        g
    }

    /// Offset of the line holding `needle` in `text`.
    fn at(text: &str, needle: &str) -> u64 {
        let i = text.find(needle).unwrap();
        text[..i].rfind('\n').map_or(0, |j| j as u64 + 1)
    }

    fn read_str(kind: TextFormat, text: &str) -> Got {
        read_all(open(kind, Cursor::new(text.as_bytes().to_vec())))
    }

    fn read_sample(kind: TextFormat, name: &str) -> Got {
        let f = std::fs::File::open(samples().join(name)).unwrap();
        read_all(open(kind, BufReader::new(f)))
    }

    /// The direction of each byte of the session, from its frames (one per line of the .hex).
    fn session_dirs() -> Vec<Direction> {
        let text = String::from_utf8(sample("kdc101-session.hex")).unwrap();
        let mut dirs = vec![];
        for line in text.lines().filter(|l| !l.trim().is_empty()) {
            let bytes: Vec<u8> = line
                .split_whitespace()
                .map(|h| u8::from_str_radix(h, 16).unwrap())
                .collect();
            let id = u16::from_le_bytes([bytes[0], bytes[1]]);
            // HW_GET_INFO, MOD_GET_CHANENABLESTATE, MOT_MOVE_HOMED, MOT_MOVE_COMPLETED,
            // MOT_GET_DCSTATUSUPDATE come from the controller; the rest from the host.
            let d2h = [0x0006, 0x0212, 0x0444, 0x0464, 0x0491].contains(&id);
            let d = if d2h {
                Direction::DeviceToHost
            } else {
                Direction::HostToDevice
            };
            dirs.extend(std::iter::repeat_n(d, bytes.len()));
        }
        dirs
    }

    fn check_session(g: &Got, directed: bool, timed: bool) {
        assert_eq!(g.diags, vec![], "no diagnostics");
        assert_eq!(g.bytes(), sample("kdc101-session.bin"));
        let dirs = session_dirs();
        let mut pos = 0;
        let mut last_ts = None;
        for c in &g.chunks {
            for (i, _) in c.bytes.iter().enumerate() {
                let want = if directed {
                    dirs[pos + i]
                } else {
                    Direction::Unknown
                };
                assert_eq!(c.dir, want, "direction of byte {}", pos + i);
            }
            pos += c.bytes.len();
            if timed {
                let ts = c.ts_ns.expect("timestamp");
                if let Some(l) = last_ts {
                    assert!(ts > l, "timestamps increase: {l} then {ts}");
                }
                last_ts = Some(ts);
            } else {
                assert_eq!(c.ts_ns, None);
            }
        }
    }

    /// 2024-05-01 12:00:00 as nanoseconds since the epoch (UTC).
    const T0: u64 = 1_714_564_800 * NS;

    #[test]
    fn socat_sample() {
        let g = read_sample(TextFormat::Socat, "kdc101-session.socat.log");
        check_session(&g, true, true);
        assert_eq!(g.chunks[0].ts_ns, Some(T0));
        assert_eq!(
            g.chunks.len(),
            21,
            "one chunk per read (the 90-byte reply comes in two)"
        );
        assert!(g.streams.is_empty());
    }

    #[test]
    fn jpnevulator_sample() {
        let g = read_sample(TextFormat::Jpnevulator, "kdc101-session.jpnevulator.txt");
        check_session(&g, true, true);
        // The pty and the tty are the two directions of one line: one stream.
        let names: Vec<_> = g.streams.iter().map(|s| (s.id, s.name.as_str())).collect();
        assert_eq!(names, vec![(0, "/dev/pts/3")]);
        assert!(g.chunks.iter().all(|c| c.stream == 0));
    }

    #[test]
    fn interceptty_sample() {
        let g = read_sample(TextFormat::Interceptty, "kdc101-session.interceptty.log");
        check_session(&g, true, true);
        // interceptty -T prints the time of day only: 12:00:00 after midnight.
        assert_eq!(g.chunks[0].ts_ns, Some(12 * 3600 * NS));
    }

    #[test]
    fn xxd_sample() {
        let g = read_sample(TextFormat::Xxd, "kdc101-session.xxd.txt");
        check_session(&g, false, false);
    }

    #[test]
    fn sniff_samples() {
        let head = |n: &str| {
            let mut b = sample(n);
            b.truncate(8192);
            b
        };
        assert_eq!(
            sniff(&head("kdc101-session.socat.log")),
            Some(TextFormat::Socat)
        );
        assert_eq!(
            sniff(&head("kdc101-session.jpnevulator.txt")),
            Some(TextFormat::Jpnevulator)
        );
        assert_eq!(
            sniff(&head("kdc101-session.interceptty.log")),
            Some(TextFormat::Interceptty)
        );
        assert_eq!(
            sniff(&head("kdc101-session.xxd.txt")),
            Some(TextFormat::Xxd)
        );
        assert_eq!(sniff(HEXDUMP_C.as_bytes()), Some(TextFormat::HexdumpC));
        assert_eq!(
            sniff(b"0000  05 00 00 00 50 01\n0006  06 00 54 00\n"),
            Some(TextFormat::HexColumns)
        );
        assert_eq!(
            sniff(b"12:00:00.000 05 00 00 00 50 01\n12:00:00.011 06 00 54 00 81 50\n"),
            Some(TextFormat::HexColumns)
        );
        // Not ours: binary, pcap, an Elliptec ASCII stream, plain hex, prose, empty.
        assert_eq!(sniff(&head("kdc101-session.bin")), None);
        assert_eq!(sniff(&head("elliptec-bus.txt")), None);
        assert_eq!(
            sniff(b"0in0IN0E1140028420200117016800023000\r\n0gs0GS00\r\n"),
            None
        );
        assert_eq!(sniff(&head("kdc101-session.hex")), None);
        assert_eq!(sniff(&head("damaged.bin")), None);
        assert_eq!(
            sniff(&[0xd4, 0xc3, 0xb2, 0xa1, 2, 0, 4, 0, 0, 0, 0, 0]),
            None
        );
        assert_eq!(
            sniff(&[0x0a, 0x0d, 0x0d, 0x0a, 0x1c, 0, 0, 0, 0x4d, 0x3c, 0x2b, 0x1a]),
            None
        );
        assert_eq!(sniff(b"Hello, this is a README.\nNothing to see.\n"), None);
        assert_eq!(
            sniff(b"2ca5\n0ca1\n"),
            None,
            "Elliptec commands made of hex letters"
        );
        assert_eq!(
            sniff(b"> 2024/05/01 12:00:00.000000  length=3 from=0 to=2\n012\n"),
            None,
            "socat -v"
        );
        assert_eq!(sniff(b""), None);
    }

    #[test]
    fn names_round_trip() {
        for f in TextFormat::ALL {
            assert_eq!(TextFormat::parse(f.name()), Some(f));
        }
        assert_eq!(TextFormat::parse("pcap"), None);
    }

    // --- socat ---

    const SOCAT_OK: &str = "> 2024/05/01 12:00:00.000100  length=6 from=0 to=5\n \
05 00 00 00 50 01                                ....P.\n--\n";

    #[test]
    fn socat_without_timestamps_and_hex_only() {
        // socat -x without -v: all bytes on one line, no ASCII column, no "--".
        let g = read_str(
            TextFormat::Socat,
            "> length=6 from=0 to=5\n 05 00 00 00 50 01\n< length=2 from=0 to=1\n 0a 0b\n",
        );
        assert_eq!(g.diags, vec![]);
        assert_eq!(g.chunks.len(), 2);
        assert_eq!(g.chunks[0].dir, Direction::HostToDevice);
        assert_eq!(g.chunks[1].dir, Direction::DeviceToHost);
        assert_eq!(g.chunks[1].bytes, vec![0x0a, 0x0b]);
        assert_eq!(g.chunks[0].ts_ns, None);
    }

    #[test]
    fn socat_bad_hex() {
        let text = format!(
            "{SOCAT_OK}< 2024/05/01 12:00:00.000200  length=4 from=0 to=3\n 12 0g 00 50\n--\n{}",
            SOCAT_OK.replace("from=0 to=5", "from=6 to=11")
        );
        let g = read_str(TextFormat::Socat, &text);
        let bad_line = at(&text, " 12 0g");
        assert_eq!(
            g.kinds(),
            vec![
                ("bad_hex", bad_line),
                ("length_mismatch", SOCAT_OK.len() as u64)
            ]
        );
        assert!(g.diags[0].msg.contains("column 5"), "{}", g.diags[0].msg);
        // What is readable is kept: the block before, the byte before the bad one, the block after.
        assert_eq!(
            g.bytes(),
            [&[5, 0, 0, 0, 0x50, 1][..], &[0x12], &[5, 0, 0, 0, 0x50, 1]].concat()
        );
        assert_eq!(g.chunks[1].dir, Direction::DeviceToHost);
    }

    #[test]
    fn socat_truncated_last_line() {
        let text =
            format!("{SOCAT_OK}< 2024/05/01 12:00:01.5  length=6 from=0 to=5\n 06 00 00 00 50");
        let g = read_str(TextFormat::Socat, &text);
        let hdr = SOCAT_OK.len() as u64;
        assert_eq!(
            g.kinds(),
            vec![
                ("truncated_line", at(&text, " 06 00")),
                ("length_mismatch", hdr)
            ]
        );
        assert_eq!(g.bytes(), vec![5, 0, 0, 0, 0x50, 1, 6, 0, 0, 0, 0x50]);
        assert_eq!(g.chunks[1].ts_ns, Some(T0 + 1_500_000_000));
    }

    #[test]
    fn socat_garbage_gap_and_headerless_data() {
        let text = format!(
            " 01 02\n2024/05/01 11:59:59 socat[42] N starting data transfer loop\n{SOCAT_OK}hello there\n{}",
            SOCAT_OK.replace("from=0 to=5", "from=10 to=15")
        );
        let g = read_str(TextFormat::Socat, &text);
        assert_eq!(
            g.kinds(),
            vec![
                ("missing_header", 0),
                ("garbage_line", at(&text, "hello")),
                (
                    "sequence_gap",
                    at(&text, "> 2024/05/01 12:00:00.000100  length=6 from=10")
                )
            ]
        );
        assert_eq!(g.chunks[0].dir, Direction::Unknown);
        assert_eq!(g.bytes().len(), 2 + 6 + 6);
    }

    #[test]
    fn socat_ascii_mismatch() {
        let g = read_str(TextFormat::Socat, &SOCAT_OK.replace("....P.", "....Q."));
        assert_eq!(g.kinds(), vec![("ascii_mismatch", 51)]);
        assert_eq!(g.bytes(), vec![5, 0, 0, 0, 0x50, 1]);
    }

    // --- jpnevulator ---

    #[test]
    fn jpnevulator_one_tty_byte_count_and_garbage() {
        let text = "2024-05-01 12:00:00.000000:\n00000000\t05 00 00 00 50 01\n\
                    2024-05-01 12:00:00.250000:\n00000006\t06 00\nthis is not hex\n00000009\t54 00\n";
        let g = read_str(TextFormat::Jpnevulator, text);
        assert_eq!(
            g.kinds(),
            vec![
                ("garbage_line", at(text, "this")),
                ("byte_count_gap", at(text, "00000009"))
            ]
        );
        assert!(g.streams.is_empty());
        assert_eq!(g.chunks.len(), 2);
        assert!(g
            .chunks
            .iter()
            .all(|c| c.dir == Direction::Unknown && c.stream == 0));
        assert_eq!(g.chunks[1].ts_ns, Some(T0 + 250_000_000));
        assert_eq!(g.bytes(), vec![5, 0, 0, 0, 0x50, 1, 6, 0, 0x54, 0]);
    }

    #[test]
    fn jpnevulator_aliases_and_bad_hex() {
        let text = "2024-05-01 12:00:00.000000: host\n05 00 00 00 50 01\n\
                    2024-05-01 12:00:00.010000: kcube\n06 00 5X 00\n";
        let g = read_str(TextFormat::Jpnevulator, text);
        assert_eq!(g.kinds(), vec![("bad_hex", at(text, "06 00 5X"))]);
        assert_eq!(g.chunks[0].dir, Direction::HostToDevice);
        // The other of two interfaces carries the other direction.
        assert_eq!(g.chunks[1].dir, Direction::DeviceToHost);
        assert_eq!(g.chunks[1].bytes, vec![6, 0]);
    }

    #[test]
    fn jpnevulator_two_ttys_unknown() {
        let text = "2024-05-01 12:00:00.000000: /dev/ttyS0\n05 00\n2024-05-01 12:00:00.000100: /dev/ttyUSB0\n06 00\n";
        let g = read_str(TextFormat::Jpnevulator, text);
        assert_eq!(g.diags, vec![]);
        assert!(g.chunks.iter().all(|c| c.dir == Direction::Unknown));
        assert_eq!(g.chunks[1].stream, 1);
    }

    // --- interceptty ---

    #[test]
    fn interceptty_classic_and_eol_mode() {
        // interceptty without -T: one byte per line; '<' to the device, '>' from it.
        let g = read_str(
            TextFormat::Interceptty,
            "< 0x30 (0)\n< 0x67 (g)\n> \t0x30 (0)\n> \t0x47 (G)\n> \t0x0d\n< 0x31 (1)\n",
        );
        assert_eq!(g.diags, vec![]);
        let got: Vec<_> = g
            .chunks
            .iter()
            .map(|c| (c.dir, c.bytes.clone(), c.ts_ns))
            .collect();
        assert_eq!(
            got,
            vec![
                (Direction::HostToDevice, b"0g".to_vec(), None),
                (Direction::DeviceToHost, b"0G\r".to_vec(), None),
                (Direction::HostToDevice, b"1".to_vec(), None),
            ]
        );
        // -e 0x0a: several bytes a line.
        let g = read_str(TextFormat::Interceptty, "# Using '[LF]' as end of line char\n< 30(0):67(g):73(s):0a([LF])\n> \t30(0):3a(:):29()):20(' ')\n");
        assert_eq!(g.diags, vec![]);
        assert_eq!(g.bytes(), b"0gs\n0:) ".to_vec());
    }

    #[test]
    fn interceptty_bad_lines() {
        let text = "[12:00 00.000000]< 0x05 ([ENQ])\n                 < 0xzz (?)\nwhat is this\n[12:00 0x.000000]> \t0x06 ([ACK])\n[12:00 00.100000]> \t0x07 ([BEL])\n> \t0x08";
        let g = read_str(TextFormat::Interceptty, text);
        assert_eq!(
            g.kinds(),
            vec![
                ("bad_hex", 32),
                ("garbage_line", 60),
                ("bad_timestamp", 73),
                ("truncated_line", 139)
            ]
        );
        assert_eq!(g.bytes(), vec![5, 7, 8]);
        assert_eq!(g.chunks[1].ts_ns, Some(12 * 3600 * NS + 100_000_000));
    }

    // --- xxd / hexdump ---

    /// `hexdump -C samples/kdc101-session.bin`, as hexdump printed it (a `*` for 3 zero lines).
    const HEXDUMP_C: &str = "\
00000000  05 00 00 00 50 01 06 00  54 00 81 50 3b fd 9b 01  |....P...T..P;...|
00000010  4b 44 43 31 30 31 00 00  2c 00 0b 00 03 00 00 00  |KDC101..,.......|
00000020  00 00 00 00 00 00 00 00  00 00 00 00 00 00 00 00  |................|
*
00000050  00 00 00 00 00 00 00 00  00 00 01 00 00 00 01 00  |................|
00000060  10 02 01 01 50 01 11 02  01 00 50 01 12 02 01 01  |....P.....P.....|
00000070  01 50 11 00 00 00 50 01  43 04 01 00 50 01 91 04  |.P....P.C...P...|
00000080  0e 00 81 50 01 00 00 00  00 00 78 00 00 00 20 03  |...P......x... .|
00000090  00 80 91 04 0e 00 81 50  01 00 50 fb ff ff 78 00  |.......P..P...x.|
000000a0  00 00 20 03 00 80 91 04  0e 00 81 50 01 00 e8 ea  |.. ........P....|
000000b0  ff ff 78 00 00 00 20 03  00 80 91 04 0e 00 81 50  |..x... ........P|
000000c0  01 00 b8 d9 ff ff 78 00  00 00 20 03 00 80 44 04  |......x... ...D.|
000000d0  01 00 01 50 53 04 06 00  d0 01 01 00 00 9e 02 00  |...PS...........|
000000e0  91 04 0e 00 81 50 01 00  00 50 00 00 2c 01 00 00  |.....P...P..,...|
000000f0  10 05 00 80 91 04 0e 00  81 50 01 00 00 0c 01 00  |.........P......|
00000100  2c 01 00 00 10 05 00 80  91 04 0e 00 81 50 01 00  |,............P..|
00000110  00 dc 01 00 2c 01 00 00  10 05 00 80 91 04 0e 00  |....,...........|
00000120  81 50 01 00 00 86 02 00  2c 01 00 00 10 05 00 80  |.P......,.......|
00000130  91 04 0e 00 81 50 01 00  00 9e 02 00 2c 01 00 00  |.....P......,...|
00000140  10 05 00 80 64 04 0e 00  81 50 01 00 00 9e 02 00  |....d....P......|
00000150  00 00 00 00 00 25 00 80  12 00 00 00 50 01        |.....%......P.|
0000015e
";

    #[test]
    fn hexdump_c_with_repeats() {
        let g = read_str(TextFormat::HexdumpC, HEXDUMP_C);
        check_session(&g, false, false);
    }

    #[test]
    fn hexdump_huge_repeat_is_streamed() {
        let text = "00000000  00 00 00 00 00 00 00 00  00 00 00 00 00 00 00 00  |................|\n*\n01000000\n";
        let mut r = open(TextFormat::HexdumpC, Cursor::new(text.as_bytes().to_vec()));
        let mut total = 0u64;
        while let Some(ev) = r.next_event() {
            match ev {
                Event::Chunk(c) => {
                    assert!(c.bytes.len() <= MAX_CHUNK && c.bytes.iter().all(|&b| b == 0));
                    total += c.bytes.len() as u64;
                }
                other => panic!("{other:?}"),
            }
        }
        assert_eq!(total, 0x0100_0000);
    }

    #[test]
    fn hexdump_bad_lines() {
        let text =
            "00000000  05 00 00 00 50 01 06 00  54 00 81 50 3b fd 9b 01  |....P...T..P;...|\n\
00000010  4b 44 43 31 30 31 00 00  2c 00 0b 00 03 00 00 00  |KDC101..,.......|\n\
00000030  00 00 00 00 00 00 00 00  00 00 00 00 00 00 00 00  |................|\n\
*\n";
        let g = read_str(TextFormat::HexdumpC, text);
        assert_eq!(
            g.kinds(),
            vec![("offset_gap", 158), ("truncated_repeat", 237)]
        );
        assert_eq!(g.bytes().len(), 48);
    }

    #[test]
    fn xxd_bad_hex_truncated_and_gap() {
        let xxd = String::from_utf8(sample("kdc101-session.xxd.txt")).unwrap();
        let lines: Vec<&str> = xxd.lines().collect();
        // Line 2 with a bad digit; line 4 missing; the last line cut in the middle.
        let bad = lines[1].replacen("4331", "43z1", 1);
        let cut = &lines[21][..20];
        let text = format!("{}\n{bad}\n{}\n{}\n{cut}", lines[0], lines[2], lines[4]);
        let g = read_str(TextFormat::Xxd, &text);
        let l = lines[0].len() as u64 + 1;
        assert_eq!(
            g.kinds(),
            vec![
                ("bad_hex", l),
                ("offset_gap", 3 * l),
                ("truncated_line", 4 * l)
            ]
        );
        assert!(g.diags[0].msg.contains("column 18"), "{}", g.diags[0].msg);
        let bin = sample("kdc101-session.bin");
        let want = [&bin[..19], &bin[32..48], &bin[64..80], &bin[336..340]].concat();
        assert_eq!(g.bytes(), want);
    }

    #[test]
    fn xxd_options_and_garbage() {
        // xxd -g1 -c8 -u, then a line that is not xxd.
        let g = read_str(
            TextFormat::Xxd,
            "00000000: 05 00 00 00 50 01 06 00  ....P...\n00000008: 54 00        T.\nnot xxd\n",
        );
        assert_eq!(g.kinds(), vec![("garbage_line", 70)]);
        assert_eq!(g.bytes(), vec![5, 0, 0, 0, 0x50, 1, 6, 0, 0x54, 0]);
        // A long run of lines is cut into chunks of MAX_CHUNK.
        let mut big = String::new();
        for i in 0..5000u32 {
            big += &format!(
                "{:08x}: 4142 4344 4546 4748 494a 4b4c 4d4e 4f50  ABCDEFGHIJKLMNOP\n",
                i * 16
            );
        }
        let g = read_str(TextFormat::Xxd, &big);
        assert_eq!(g.diags, vec![]);
        assert_eq!(
            g.chunks.iter().map(|c| c.bytes.len()).collect::<Vec<_>>(),
            vec![MAX_CHUNK, 80_000 - MAX_CHUNK]
        );
    }

    // --- hex columns ---

    #[test]
    fn hex_columns() {
        let text = "# a capture\n2024-05-01 12:00:00.000 05 00 00 00 50 01\n\
                    [2024-05-01T12:00:00.011Z] 0x06, 0x00\n\
                    12:00:00.262 0010: 12 02 01 01 01 50  ....P.\n\
                    0.5 000020 aa bb  |..|\n\
                    000030  cc dd ee\n";
        let g = read_str(TextFormat::HexColumns, text);
        assert_eq!(g.diags, vec![]);
        let got: Vec<_> = g
            .chunks
            .iter()
            .map(|c| (c.ts_ns, c.bytes.clone()))
            .collect();
        assert_eq!(
            got,
            vec![
                (Some(T0), vec![5, 0, 0, 0, 0x50, 1]),
                (Some(T0 + 11_000_000), vec![6, 0]),
                (
                    Some(12 * 3600 * NS + 262_000_000),
                    vec![0x12, 2, 1, 1, 1, 0x50]
                ),
                (Some(500_000_000), vec![0xaa, 0xbb]),
                (None, vec![0xcc, 0xdd, 0xee]),
            ]
        );
        // od -A x -t x1z
        let g = read_str(
            TextFormat::HexColumns,
            "000000 05 00 00 00 50 01  >....P.<\n000006\n",
        );
        assert_eq!(g.diags, vec![]);
        assert_eq!(g.bytes(), vec![5, 0, 0, 0, 0x50, 1]);
    }

    #[test]
    fn hex_columns_bad_lines() {
        let text = "0000  05 00 0q 00\nnonsense here\n[12:61:00.0] 01\n0004  50 01\n0006  06 0";
        let g = read_str(TextFormat::HexColumns, text);
        assert_eq!(
            g.kinds(),
            vec![
                ("bad_hex", 0),
                ("garbage_line", 18),
                ("bad_timestamp", 32),
                ("truncated_line", 60)
            ]
        );
        assert_eq!(g.bytes(), vec![5, 0, 0x50, 1, 6]);
    }

    #[test]
    fn line_too_long_is_skipped() {
        let text = format!(
            "0000  05 00\n{}\n0002  06 00\n",
            "ab ".repeat(MAX_LINE / 3 + 10)
        );
        let g = read_str(TextFormat::HexColumns, &text);
        assert_eq!(g.kinds(), vec![("line_too_long", 12)]);
        assert_eq!(g.bytes(), vec![5, 0, 6, 0]);
    }

    #[test]
    fn io_error_is_reported() {
        struct Failing(usize);
        impl Read for Failing {
            fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
                if self.0 == 0 {
                    return Err(io::Error::other("disk on fire"));
                }
                self.0 = 0;
                let line = b"00000000: 0500 0000 5001  ....P.\n";
                buf[..line.len()].copy_from_slice(line);
                Ok(line.len())
            }
        }
        let g = read_all(open(TextFormat::Xxd, BufReader::new(Failing(1))));
        assert_eq!(g.kinds(), vec![("io_error", 33)]);
        assert_eq!(g.bytes(), vec![5, 0, 0, 0, 0x50, 1]);
    }

    #[test]
    fn truncated_line_keeps_earlier_diagnostics() {
        // A short block without "--", then a cut header: the short block is still reported,
        // the cut line only as truncated (not also as an unreadable header).
        let block = SOCAT_OK
            .replace("length=6 from=0 to=5", "length=7 from=0 to=6")
            .replace("--\n", "");
        let text = format!("{block}> 2024/05/01 12:0");
        let g = read_str(TextFormat::Socat, &text);
        assert_eq!(
            g.kinds(),
            vec![
                ("truncated_line", block.len() as u64),
                ("length_mismatch", 0)
            ]
        );
        assert_eq!(g.bytes(), vec![5, 0, 0, 0, 0x50, 1]);
    }

    /// Every sample through read buffers of a few bytes gives the same events.
    #[test]
    fn small_read_buffers() {
        let cases = [
            (TextFormat::Socat, "kdc101-session.socat.log"),
            (TextFormat::Jpnevulator, "kdc101-session.jpnevulator.txt"),
            (TextFormat::Interceptty, "kdc101-session.interceptty.log"),
            (TextFormat::Xxd, "kdc101-session.xxd.txt"),
        ];
        for (kind, name) in cases {
            let whole = read_sample(kind, name);
            for cap in [1, 2, 7, 61] {
                let r = BufReader::with_capacity(cap, Cursor::new(sample(name)));
                let g = read_all(open(kind, r));
                assert_eq!(g.chunks, whole.chunks, "{name} with {cap}-byte reads");
                assert_eq!(g.streams, whole.streams);
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

        /// Damaged samples and noise never panic, and every byte a reader gives is bounded.
        #[test]
        fn damaged_input_never_panics(
            which in 0usize..4,
            edits in proptest::collection::vec((0usize..20_000, 0u8..=255, 0u8..3), 0..40),
            noise in proptest::collection::vec(proptest::sample::select(b" 0123456789abcdefABCDEF<>:.-/|*[]()x\t\n\r".to_vec()), 0..3000),
        ) {
            let names = [
                "kdc101-session.socat.log",
                "kdc101-session.jpnevulator.txt",
                "kdc101-session.interceptty.log",
                "kdc101-session.xxd.txt",
            ];
            let mut text = sample(names[which]);
            for (pos, b, op) in edits {
                let pos = pos % (text.len() + 1);
                match op {
                    0 => text.insert(pos, b),
                    1 if pos < text.len() => { text.remove(pos); }
                    _ if pos < text.len() => text[pos] = b,
                    _ => {}
                }
            }
            for input in [text, noise] {
                let _ = sniff(&input);
                for kind in TextFormat::ALL {
                    let g = read_all(open(kind, Cursor::new(input.clone())));
                    proptest::prop_assert!(g.bytes().len() <= input.len());
                    for d in &g.diags {
                        proptest::prop_assert!(d.offset <= input.len() as u64);
                    }
                }
            }
        }
    }

    #[test]
    fn timestamps() {
        assert_eq!(parse_datetime(b"1970-01-01 00:00:00"), Some((0, 19)));
        assert_eq!(
            parse_datetime(b"2024/05/01 12:00:00.123456 "),
            Some((T0 + 123_456_000, 26))
        );
        assert_eq!(
            parse_datetime(b"2024-02-30 00:00:00").map(|t| t.0),
            parse_datetime(b"2024-03-01 00:00:00").map(|t| t.0)
        );
        assert_eq!(parse_datetime(b"2024-13-01 00:00:00"), None);
        assert_eq!(
            parse_tod(b"23:59:59.999999999999", false),
            Some((DAY_NS - 1, 21))
        );
        assert_eq!(
            parse_tod(b"12:00 01.5", true),
            Some((43_201_500_000_000, 10))
        );
        assert_eq!(parse_tod(b"12:00 01.5", false), None);
        let mut c = TodClock::default();
        assert_eq!(c.at(DAY_NS - NS), DAY_NS - NS);
        assert_eq!(c.at(NS), DAY_NS + NS);
    }
}
