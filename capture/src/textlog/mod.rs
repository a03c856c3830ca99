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

use crate::model::{
    Chunk, Direction, Event, LogField, LogProblem, ReadDiag, ReadProblem, Reader, StreamInfo,
};
use std::collections::VecDeque;
use std::io::{self, BufRead, Cursor, Read};

mod dump;
mod hexcols;
mod interceptty;
mod jpnevulator;
mod socat;
#[cfg(test)]
mod tests;

use dump::*;
use hexcols::*;
use interceptty::*;
use jpnevulator::*;
use socat::*;

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

/// Line `s` is not part of the log (`expected`: `a socat dump` …).
fn garbage(expected: &str, s: &[u8]) -> LogProblem {
    LogProblem::GarbageLine {
        expected: expected.to_string(),
        line: show(s),
    }
}

/// Not a hex byte at (0-based) column `col` of line `s`.
fn bad_hex(s: &[u8], col: usize) -> LogProblem {
    LogProblem::BadHex {
        column: col + 1,
        found: show(&s[col.min(s.len())..]),
    }
}

/// The `field` of line `s` unreadable from (0-based) column `col`.
fn unreadable(field: LogField, col: usize, s: &[u8]) -> LogProblem {
    LogProblem::Unreadable {
        field,
        column: col + 1,
        line: show(s),
    }
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
    fn diag(&mut self, offset: u64, problem: LogProblem) {
        self.read_diag(offset, ReadProblem::Log(problem));
    }

    fn read_diag(&mut self, offset: u64, problem: ReadProblem) {
        if self.mute_at != Some(offset) {
            let d = ReadDiag::new(offset, problem);
            self.q.push_back(Pending::Ev(Event::Diag(d)));
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
                        let problem = LogProblem::LineTooLong { max: MAX_LINE };
                        self.sink.diag(info.offset, problem);
                    } else if !info.terminated {
                        self.sink.diag(info.offset, LogProblem::TruncatedLine);
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
                    self.sink.read_diag(self.lines.pos, ReadProblem::io(&e));
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
