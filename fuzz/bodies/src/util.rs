//! Helpers shared by the fuzz targets: input splitting, chunking derived from the input, a
//! reader that hands out short reads, and the checks every capture reader must pass.

use aptscope_capture::{Event, Reader};
use std::io::Read;

/// A small deterministic generator (xorshift64*) seeded from fuzz input bytes.
pub struct Lcg(u64);

impl Lcg {
    /// Seeded from up to 8 bytes.
    pub fn new(seed: &[u8]) -> Self {
        let mut s = 0x9E37_79B9_7F4A_7C15u64;
        for &b in seed.iter().take(8) {
            s = (s ^ b as u64).wrapping_mul(0x100_0000_01B3);
        }
        Lcg(s | 1)
    }
    /// Next value.
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// A value in 1..=max (max ≥ 1).
    pub fn size(&mut self, max: usize) -> usize {
        1 + (self.next_u64() % max.max(1) as u64) as usize
    }
}

/// Split the fuzz input into `n` control bytes (zero-padded when the input is shorter) and the
/// payload.
pub fn split_ctl<const N: usize>(data: &[u8]) -> ([u8; N], &[u8]) {
    let mut ctl = [0u8; N];
    let k = data.len().min(N);
    ctl[..k].copy_from_slice(&data[..k]);
    (ctl, &data[k..])
}

/// Cut points for `len` bytes from a control byte pair: `max == 0` means one piece, otherwise
/// pieces of 1..=max bytes drawn from the seed (so `max == 1` is byte by byte).
pub fn cuts(len: usize, max: u8, seed: u8) -> Vec<usize> {
    let mut out = vec![];
    if max == 0 {
        return out;
    }
    let mut r = Lcg::new(&[seed, max]);
    let mut at = 0;
    while at < len {
        at += r.size(max as usize);
        out.push(at.min(len));
    }
    out
}

/// A reader over owned bytes that returns at most `max` bytes per `read` (sizes drawn from a
/// seed), to exercise the buffering of streaming readers.
pub struct ShortReads {
    data: Vec<u8>,
    at: usize,
    max: usize,
    rng: Lcg,
}

impl ShortReads {
    /// `max == 0` means no limit.
    pub fn new(data: Vec<u8>, max: u8, seed: u8) -> Self {
        ShortReads {
            data,
            at: 0,
            max: max as usize,
            rng: Lcg::new(&[seed, max, 0x5a]),
        }
    }
}

impl Read for ShortReads {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let left = self.data.len() - self.at;
        let mut n = buf.len().min(left);
        if self.max > 0 {
            n = n.min(self.rng.size(self.max));
        }
        buf[..n].copy_from_slice(&self.data[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
}

/// What a reader produced, for the checks.
#[derive(Debug, Default)]
pub struct Drained {
    /// Number of events.
    pub events: usize,
    /// Bytes in chunks.
    pub bytes: usize,
    /// Diagnostics (offset, kind).
    pub diags: Vec<(u64, &'static str)>,
}

/// Drain a capture reader, checking what holds for every reader on any input:
/// - it ends: no more than a bound of events proportional to the input (no endless loop), and
///   no more than `expansion_limit` bytes of chunks: beyond it, reading fails (or, with
///   `APTSCOPE_FUZZ_LENIENT=1`, stops): a hexdump `*` line once expanded without bound
///   (`fuzz/artifacts-found/hexdump-repeat-*`);
/// - every diagnostic has a stable snake_case kind and an offset within the file;
/// - when `check_streams`: every stream is announced once, before its first chunk (the
///   `Event::Stream` contract; stream 0 may stay implicit, as `Chunk::stream` allows for formats
///   with one stream);
/// - after `None`, the reader stays at its end.
pub fn drain_reader(r: &mut dyn Reader, file_len: usize, check_streams: bool) -> Drained {
    let mut d = Drained::default();
    let bound = 64 + 8 * file_len;
    let mut streams: Vec<u32> = vec![];
    while let Some(ev) = r.next_event() {
        d.events += 1;
        assert!(
            d.events <= bound,
            "reader produced more than {bound} events for {file_len} bytes: endless loop?"
        );
        match ev {
            Event::Stream(s) => {
                if check_streams {
                    assert!(!streams.contains(&s.id), "stream {} announced twice", s.id);
                }
                streams.push(s.id);
            }
            Event::Chunk(c) => {
                if check_streams && c.stream != 0 {
                    assert!(
                        streams.contains(&c.stream),
                        "chunk of stream {} before its announcement",
                        c.stream
                    );
                }
                d.bytes += c.bytes.len();
                if d.bytes > expansion_limit(file_len) {
                    assert!(
                        !strict(),
                        "{file_len} bytes of file expand to more than {} bytes of chunks",
                        expansion_limit(file_len)
                    );
                    return d;
                }
            }
            Event::Diag(x) => {
                assert!(
                    !x.kind().is_empty()
                        && x.kind()
                            .bytes()
                            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_'),
                    "diag kind {:?} is not snake_case",
                    x.kind()
                );
                assert!(
                    x.offset <= file_len as u64,
                    "diag {x} at an offset beyond the file's {file_len} bytes"
                );
                d.diags.push((x.offset, x.kind()));
            }
        }
    }
    assert!(r.next_event().is_none(), "events after the end");
    let _ = r.format();
    d
}

/// How many bytes of chunks a file of `file_len` bytes may give before the targets stop reading
/// (64 MiB plus 64 per byte of file; with `APTSCOPE_FUZZ_LENIENT=1`, 1 MiB plus 64 per byte).
pub fn expansion_limit(file_len: usize) -> usize {
    (if strict() { 64 << 20 } else { 1 << 20 }) + 64 * file_len
}

/// Events as comparable text: chunks and streams in full, diagnostics by kind and offset (their
/// message may say how much was buffered). At most `limit` events.
pub fn event_keys(r: &mut dyn Reader, limit: usize) -> Vec<String> {
    let mut out = vec![];
    while let Some(ev) = r.next_event() {
        out.push(match ev {
            Event::Diag(d) => format!("diag {}@{}", d.kind(), d.offset),
            e => format!("{e:?}"),
        });
        if out.len() > limit {
            break;
        }
    }
    out
}

/// Whether the checks the inputs of `fuzz/artifacts-found/` once failed are on: yes, since
/// both bugs are fixed; `APTSCOPE_FUZZ_LENIENT=1` turns them off (to look past a regression
/// for other bugs).
pub fn strict() -> bool {
    std::env::var_os("APTSCOPE_FUZZ_LENIENT").is_none_or(|v| v != "1")
}

/// Capture times for a sequence of frames, drawn from a control byte: none (`ctl & 0x80` clear),
/// or starting anywhere, near `u64::MAX`, small, or at 0, then moving by random steps (forwards,
/// by wrapping also backwards: lanes of a capture interleave).
pub struct Times {
    rng: Lcg,
    ts: Option<u64>,
}

impl Times {
    /// From a control byte.
    pub fn new(ctl: u8) -> Self {
        let mut rng = Lcg::new(&[ctl, 0x7e]);
        let ts = (ctl & 0x80 != 0).then(|| match (ctl >> 5) & 3 {
            0 => rng.next_u64(),
            1 => u64::MAX - rng.next_u64() % 20_000_000_000,
            2 => rng.next_u64() % 1_000_000_000_000,
            _ => 0,
        });
        Times { rng, ts }
    }
    /// The time of the next frame.
    pub fn next_time(&mut self) -> Option<u64> {
        if self.rng.next_u64().is_multiple_of(3) {
            let step = self.rng.next_u64() >> (self.rng.next_u64() % 64);
            self.ts = self.ts.map(|t| t.wrapping_add(step));
        }
        self.ts
    }
}
