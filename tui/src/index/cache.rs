//! The index kept between two openings of the same capture.
//!
//! Once a capture file that stays put (not standard input, not followed) has been indexed
//! completely, the whole index is written to `cache_dir()/index/<key>.idx` (to a temporary name,
//! then renamed). The next opening of the same unchanged capture (same canonical path, size,
//! modification and change times, device and inode, the same options that change the index,
//! the same aptscope version and file layout) reads it back instead of indexing again: the
//! index is complete at once. Its records are not loaded: the file's record section is read by
//! position a chunk at a time, as the records spilled over the memory budget are; the bytes of
//! non-raw formats come from its arena section, a raw capture's from the capture itself.
//!
//! Layout: a header (magic, layout number, its own length, aptscope version, the key's text,
//! the sections' positions and lengths, the metadata's checksum, its own checksum), the records
//! (24 bytes each, [`Packed::to_bytes`]), the arena bytes, the metadata (everything else the
//! index holds). The header and metadata are checksummed; the file's length must be the one the
//! header gives. A file that fails any check is ignored (the capture is indexed again and the
//! file replaced), never trusted.

use super::*;
use std::collections::HashMap;
use std::io::Write;
use std::os::unix::fs::{FileExt, MetadataExt};
use std::path::{Path, PathBuf};

/// The first bytes of a cache file.
const MAGIC: [u8; 8] = *b"APTSIDX\0";

/// The layout of the file: changed whenever what is written changes.
pub(super) const LAYOUT: u32 = 1;

/// The aptscope version that wrote a file (a cache of another build's version is ignored).
pub(super) const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The running program's build: its executable's size and modification time. A rebuilt
/// aptscope whose version number has not changed (a developer's build) may index differently,
/// so it does not read the indexes an earlier build wrote.
fn build_id() -> &'static str {
    static ID: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    ID.get_or_init(|| {
        std::env::current_exe()
            .and_then(std::fs::metadata)
            .map_or_else(
                |_| "unknown".into(),
                |m| format!("{} {}.{:09}", m.len(), m.mtime(), m.mtime_nsec()),
            )
    })
}

/// Total size the cache directory is kept under by default ([`cache_max`]).
pub const DEFAULT_CACHE_MAX: u64 = 4 << 30;

/// Cache files whose write never finished (a viewer that quit while writing) are removed
/// once this old.
const STALE_TMP: std::time::Duration = std::time::Duration::from_secs(3600);

static CACHE_OFF: AtomicBool = AtomicBool::new(false);

/// Turn the index cache off (`aptscope view --no-cache`) or on again for the indexes made from
/// now on.
pub fn set_index_cache(on: bool) {
    CACHE_OFF.store(!on, Ordering::Relaxed);
}

/// The directory of the index cache ([`cache_dir`]`/index`), or `None` when it is off
/// ([`set_index_cache`], or `APTSCOPE_NO_INDEX_CACHE` set to anything but empty or `0`).
pub fn default_cache() -> Option<PathBuf> {
    let env_off =
        std::env::var_os("APTSCOPE_NO_INDEX_CACHE").is_some_and(|v| !v.is_empty() && v != "0");
    (!CACHE_OFF.load(Ordering::Relaxed) && !env_off).then(|| cache_dir().join("index"))
}

/// The total size the cache directory is kept under: `APTSCOPE_INDEX_CACHE_MAX` (a size as
/// `--index-memory` takes it), else [`DEFAULT_CACHE_MAX`]. The index written last is kept
/// whatever its size.
pub fn cache_max() -> u64 {
    std::env::var("APTSCOPE_INDEX_CACHE_MAX")
        .ok()
        .and_then(|s| parse_size(&s))
        .unwrap_or(DEFAULT_CACHE_MAX)
}

/// What names the cache file of a capture and is checked against the one in it: the capture
/// file's identity and state, and the options that change its index.
#[derive(Debug, Clone)]
pub(super) struct Key {
    /// The capture as given.
    pub(super) path: String,
    /// The options' part of the key.
    opts: String,
    /// The whole key.
    pub(super) text: String,
    /// The cache file.
    pub(super) file: PathBuf,
    /// The capture's size.
    pub(super) size: u64,
}

impl Key {
    /// The key of the capture at `path` opened with `open` and indexed with `proto` and
    /// `units`, its file in `dir`; `None` for a source that does not stay put.
    pub(super) fn new(
        path: &str,
        open: &OpenOptions,
        proto: Option<Proto>,
        units: &UnitsOpts,
        dir: &Path,
    ) -> Option<Key> {
        if path == "-" || open.follow.is_some() {
            return None;
        }
        let opts = format!(
            "format {:?}\nusb {:?}\nproto {proto:?}\nunits {units:?}\n",
            open.format, open.usb_device
        );
        Key::of(path, opts, dir)
    }

    fn of(path: &str, opts: String, dir: &Path) -> Option<Key> {
        let canon = std::fs::canonicalize(path).ok()?;
        let m = std::fs::metadata(&canon).ok()?;
        if !m.is_file() {
            return None;
        }
        let text = format!(
            "aptscope {VERSION} layout {LAYOUT} build {}\npath {}\nsize {}\nmtime {}.{:09}\nctime {}.{:09}\ndev {} ino {}\n{opts}",
            build_id(),
            canon.to_string_lossy(),
            m.len(),
            m.mtime(),
            m.mtime_nsec(),
            m.ctime(),
            m.ctime_nsec(),
            m.dev(),
            m.ino()
        );
        let file = dir.join(format!("{:016x}.idx", checksum(text.as_bytes())));
        Some(Key {
            path: path.to_string(),
            opts,
            text,
            file,
            size: m.len(),
        })
    }

    /// Whether the capture is still as it was when the key was made.
    pub(super) fn unchanged(&self) -> bool {
        let dir = self.file.parent().unwrap_or(Path::new("."));
        Key::of(&self.path, self.opts.clone(), dir).is_some_and(|k| k.text == self.text)
    }
}

/// A checksum of `b` (not cryptographic: it tells a damaged file from a sound one), a word at
/// a time.
pub(super) fn checksum(b: &[u8]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64 ^ b.len() as u64;
    let mut words = b.chunks_exact(8);
    for w in &mut words {
        let mut a = [0u8; 8];
        a.copy_from_slice(w);
        h = (h ^ u64::from_le_bytes(a))
            .wrapping_mul(0x0000_0100_0000_01b3)
            .rotate_left(29);
    }
    for &x in words.remainder() {
        h = (h ^ u64::from(x)).wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// Encodes the metadata (little-endian, lengths before lists).
#[derive(Default)]
struct Enc(Vec<u8>);

impl Enc {
    fn u8(&mut self, x: u8) {
        self.0.push(x);
    }
    fn u16(&mut self, x: u16) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    fn u32(&mut self, x: u32) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    fn u64(&mut self, x: u64) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    fn len(&mut self, n: usize) {
        self.u64(n as u64);
    }
    fn f64(&mut self, x: f64) {
        self.u64(x.to_bits());
    }
    fn str(&mut self, s: &str) {
        self.len(s.len());
        self.0.extend_from_slice(s.as_bytes());
    }
    fn opt_u64(&mut self, x: Option<u64>) {
        self.u8(u8::from(x.is_some()));
        self.u64(x.unwrap_or(0));
    }
    fn opt_f64(&mut self, x: Option<f64>) {
        self.opt_u64(x.map(f64::to_bits));
    }
    fn opt_str(&mut self, x: Option<&str>) {
        self.u8(u8::from(x.is_some()));
        self.str(x.unwrap_or(""));
    }
    fn u64s(&mut self, v: &[u64]) {
        self.len(v.len());
        for x in v {
            self.u64(*x);
        }
    }
}

/// Decodes what [`Enc`] wrote; `None` at anything out of place.
struct Dec<'a>(&'a [u8]);

impl<'a> Dec<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        if n > self.0.len() {
            return None;
        }
        let (a, b) = self.0.split_at(n);
        self.0 = b;
        Some(a)
    }
    fn arr<const N: usize>(&mut self) -> Option<[u8; N]> {
        self.take(N)?.try_into().ok()
    }
    fn u8(&mut self) -> Option<u8> {
        Some(self.arr::<1>()?[0])
    }
    fn u16(&mut self) -> Option<u16> {
        Some(u16::from_le_bytes(self.arr()?))
    }
    fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes(self.arr()?))
    }
    fn u64(&mut self) -> Option<u64> {
        Some(u64::from_le_bytes(self.arr()?))
    }
    /// A list's length, when what is left can hold that many items of at least `min` bytes
    /// (no huge allocation for a damaged length).
    fn len(&mut self, min: usize) -> Option<usize> {
        let n = usize::try_from(self.u64()?).ok()?;
        (n.checked_mul(min.max(1))? <= self.0.len()).then_some(n)
    }
    fn f64(&mut self) -> Option<f64> {
        Some(f64::from_bits(self.u64()?))
    }
    fn bool(&mut self) -> Option<bool> {
        match self.u8()? {
            0 => Some(false),
            1 => Some(true),
            _ => None,
        }
    }
    fn str(&mut self) -> Option<String> {
        self.str_ref().map(str::to_string)
    }
    fn str_ref(&mut self) -> Option<&'a str> {
        let n = self.len(1)?;
        std::str::from_utf8(self.take(n)?).ok()
    }
    fn opt_str_ref(&mut self) -> Option<Option<&'a str>> {
        let some = self.bool()?;
        let s = self.str_ref()?;
        Some(some.then_some(s))
    }
    fn opt_u64(&mut self) -> Option<Option<u64>> {
        let some = self.bool()?;
        let x = self.u64()?;
        Some(some.then_some(x))
    }
    fn opt_f64(&mut self) -> Option<Option<f64>> {
        Some(self.opt_u64()?.map(f64::from_bits))
    }
    fn opt_str(&mut self) -> Option<Option<String>> {
        let some = self.bool()?;
        let s = self.str()?;
        Some(some.then_some(s))
    }
    fn u64s(&mut self) -> Option<Vec<u64>> {
        let n = self.len(8)?;
        (0..n).map(|_| self.u64()).collect()
    }
    fn list<T>(&mut self, min: usize, mut f: impl FnMut(&mut Self) -> Option<T>) -> Option<Vec<T>> {
        let n = self.len(min)?;
        (0..n).map(|_| f(self)).collect()
    }
}

fn proto_code(p: Option<Proto>) -> u8 {
    match p {
        None => 0,
        Some(Proto::Apt) => 1,
        Some(Proto::Elliptec) => 2,
    }
}

/// Everything the index holds but its records and bytes.
fn encode_meta(ix: &Index, e: &mut Enc) {
    e.str(&ix.format);
    e.u8(proto_code(ix.proto));
    e.u8(u8::from(ix.proto_certain));
    e.opt_f64(ix.proto_share);
    e.opt_u64(ix.first_ts);
    e.len(ix.streams.len());
    for s in &ix.streams {
        e.str(s);
    }
    e.u64(ix.streams_seen);
    e.len(ix.file_diags.len());
    for (o, s) in &ix.file_diags {
        e.u64(*o);
        e.str(s);
    }
    e.len(ix.units_notes.len());
    for s in &ix.units_notes {
        e.str(s);
    }
    e.len(ix.modules.len());
    for m in &ix.modules {
        e.opt_u64(m.model.map(u64::from));
        e.opt_str(m.serial.as_deref());
        e.opt_u64(m.travel);
        e.opt_u64(m.pulses);
        e.u8(m.first_addr);
    }
    e.len(ix.scales.len());
    for s in &ix.scales {
        use aptscope_dissector::table::Maximum;
        e.str(s.stage);
        e.opt_str(s.family.map(|f| f.name()));
        e.f64(s.counts_per_unit);
        e.str(s.unit);
        e.opt_f64(s.maximum(Maximum::Volts));
        e.opt_f64(s.maximum(Maximum::Travel));
    }
    e.len(ix.diag_sets.len());
    for set in &ix.diag_sets {
        e.len(set.len());
        for k in set {
            e.str(k);
        }
    }
    e.len(ix.not_for_model.len());
    for (n, m) in &ix.not_for_model {
        e.u64(*n);
        e.0.extend_from_slice(m);
    }
    e.u64s(&ix.late_no_reply);
    e.len(ix.series.len());
    for (k, pts) in &ix.series {
        e.str(k);
        e.len(pts.len());
        for (x, y) in pts {
            e.f64(*x);
            e.f64(*y);
        }
    }
    let r = &ix.recs;
    e.len(r.len);
    e.len(r.blocks.len());
    for b in &r.blocks {
        e.u64(b.first);
        e.u64(b.cap);
        e.u64(b.ts);
        e.u32(b.module);
    }
    match &r.starts {
        Starts::Cap => e.u8(0),
        Starts::Marks { marks, next } => {
            e.u8(1);
            e.u64s(marks);
            e.u64(*next);
        }
        Starts::All(v) => {
            e.u8(2);
            e.u64s(v);
        }
    }
    e.u64s(&r.apart);
    e.len(r.wide.len());
    for (i, w) in &r.wide {
        e.u64(*i);
        e.u32(w.len);
        e.u16(w.stream);
        e.u16(w.diags);
    }
}

/// The index [`encode_meta`] wrote, its records left in `spill` (none in memory).
fn decode_meta(d: &mut Dec<'_>, spill: Spill) -> Option<Index> {
    use aptscope_dissector::diag::DiagKind;
    use aptscope_dissector::table::Maximum;
    use aptscope_dissector::units::{scale_stage, Family};
    let format = d.str()?;
    let proto = match d.u8()? {
        0 => None,
        1 => Some(Proto::Apt),
        2 => Some(Proto::Elliptec),
        _ => return None,
    };
    let proto_certain = d.bool()?;
    let proto_share = d.opt_f64()?;
    let first_ts = d.opt_u64()?;
    let streams = d.list(8, Dec::str)?;
    let streams_seen = d.u64()?;
    let file_diags = d.list(16, |d| Some((d.u64()?, d.str()?)))?;
    let units_notes = d.list(8, Dec::str)?;
    let modules = d.list(37, |d| {
        Some(Module {
            model: d.opt_u64()?.map(u8::try_from).transpose().ok()?,
            serial: d.opt_str()?,
            travel: d.opt_u64()?,
            pulses: d.opt_u64()?,
            first_addr: d.u8()?,
        })
    })?;
    // Conversions repeat (a device's, each time it changes back): each different one is built
    // once and copied (found by its bytes).
    let mut built: HashMap<&[u8], Scale> = HashMap::new();
    let scales = d.list(42, |d| {
        let from = d.0;
        let (stage, family) = (d.str_ref()?, d.opt_str_ref()?);
        let counts_per_unit = d.f64()?;
        let unit = d.str_ref()?;
        let maxima = [d.opt_f64()?, d.opt_f64()?];
        let bytes = &from[..from.len() - d.0.len()];
        if let Some(s) = built.get(bytes) {
            return Some(s.clone());
        }
        let family = match family {
            None => None,
            Some(f) => Some(Family::ALL.into_iter().find(|x| x.name() == f)?),
        };
        let mut s = Scale::new(scale_stage(stage)?, family, counts_per_unit, unit);
        for (m, v) in [Maximum::Volts, Maximum::Travel].into_iter().zip(maxima) {
            if let Some(v) = v {
                s.set_maximum(m, v);
            }
        }
        built.insert(bytes, s.clone());
        Some(s)
    })?;
    let diag_sets = d.list(8, |d| {
        // A kind this build does not know: the cache is not this build's.
        d.list(8, |d| DiagKind::static_name(&d.str()?))
    })?;
    let not_for_model = d
        .list(16, |d| Some((d.u64()?, d.arr::<8>()?)))?
        .into_iter()
        .collect();
    let late_no_reply = d.u64s()?;
    let series = d
        .list(16, |d| {
            let k = d.str()?;
            let pts = d.list(16, |d| Some((d.f64()?, d.f64()?)))?;
            Some((k, pts))
        })?
        .into_iter()
        .collect();
    let len = usize::try_from(d.u64()?).ok()?;
    let blocks = d.list(28, |d| {
        Some(Block {
            first: d.u64()?,
            cap: d.u64()?,
            ts: d.u64()?,
            module: d.u32()?,
        })
    })?;
    let starts = match d.u8()? {
        0 => Starts::Cap,
        1 => Starts::Marks {
            marks: d.u64s()?,
            next: d.u64()?,
        },
        2 => Starts::All(d.u64s()?),
        _ => return None,
    };
    let apart = d.u64s()?;
    let wide = d.list(16, |d| {
        Some((
            d.u64()?,
            Wide {
                len: d.u32()?,
                stream: d.u16()?,
                diags: d.u16()?,
            },
        ))
    })?;
    if !d.0.is_empty() {
        return None;
    }
    // What reading the records relies on: blocks in order from the first record, a start and
    // a stream offset for every record, wide values of records that exist.
    let blocks_ok = blocks.first().is_none_or(|b| b.first == 0)
        && blocks.windows(2).all(|w| w[0].first < w[1].first)
        && blocks.last().is_none_or(|b| b.first < len as u64)
        && (len == 0 || !blocks.is_empty())
        && blocks.iter().all(|b| b.module >= 1);
    let starts_ok = match &starts {
        Starts::Cap => true,
        Starts::Marks { marks, .. } => marks.len() == len.div_ceil(MARK),
        Starts::All(v) => v.len() == len,
    };
    let apart_ok = apart.is_empty() || apart.len() == len;
    let wide_ok = wide.windows(2).all(|w| w[0].0 < w[1].0)
        && wide.last().is_none_or(|(i, _)| *i < len as u64);
    let diags_ok = diag_sets.len() < usize::from(u16::MAX);
    if !(blocks_ok && starts_ok && apart_ok && wide_ok && diags_ok) {
        return None;
    }
    let chunks = len.div_ceil(CHUNK);
    let recs = Recs {
        packed: vec![Vec::new(); chunks],
        len,
        blocks,
        starts,
        apart,
        wide,
        spill: Some(Arc::new(spill)),
        spilled: chunks,
        budget: None,
        spill_gen: 0,
    };
    Some(Index {
        recs,
        modules,
        scales,
        units_notes,
        proto,
        proto_certain,
        proto_share,
        first_ts,
        streams,
        streams_seen,
        format,
        file_diags,
        series,
        diag_sets,
        not_for_model,
        late_no_reply,
        done: true,
        from_cache: true,
        ..Index::default()
    })
}

/// The header's fixed fields after the version and key.
#[derive(Debug, Default, Clone, Copy, PartialEq)]
struct Sections {
    recs_off: u64,
    recs: u64,
    arena_off: u64,
    arena_len: u64,
    meta_off: u64,
    meta_len: u64,
    meta_sum: u64,
}

/// The header of a cache file of `version` for `key` with `s`.
fn header(version: &str, key: &str, s: &Sections) -> Vec<u8> {
    let mut e = Enc::default();
    e.0.extend_from_slice(&MAGIC);
    e.u32(LAYOUT);
    // Its own length, filled in below.
    e.u32(0);
    e.str(version);
    e.str(key);
    for x in [
        s.recs_off,
        s.recs,
        s.arena_off,
        s.arena_len,
        s.meta_off,
        s.meta_len,
        s.meta_sum,
    ] {
        e.u64(x);
    }
    let len = (e.0.len() + 8) as u32;
    e.0[12..16].copy_from_slice(&len.to_le_bytes());
    let sum = checksum(&e.0);
    e.u64(sum);
    e.0
}

/// Headers longer than this are not read (the key is a path and a few numbers).
const MAX_HEADER: usize = 1 << 20;

/// Write the complete index `ix` of the capture `key` names to its cache file (a temporary
/// name, renamed when complete), as `version`. Records are written a chunk at a time and the
/// arena a window at a time: memory does not grow with the capture (but for the metadata).
pub(super) fn write(ix: &Index, key: &Key, version: &str) -> std::io::Result<()> {
    if !ix.done || ix.error.is_some() {
        return Err(std::io::Error::other("index not complete"));
    }
    let dir = key.file.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir)?;
    let mut meta = Enc::default();
    encode_meta(ix, &mut meta);
    let arena_len = match (&ix.file, &ix.arena_file) {
        (Some(_), _) => 0,
        (None, Some(f)) => f.file.metadata()?.len().saturating_sub(f.base),
        (None, None) => ix.arena.len() as u64,
    };
    let recs = ix.recs.len() as u64;
    let head_len = header(version, &key.text, &Sections::default()).len() as u64;
    let recs_off = head_len;
    let arena_off = recs_off + recs * std::mem::size_of::<Packed>() as u64;
    let meta_off = arena_off + arena_len;
    let s = Sections {
        recs_off,
        recs,
        arena_off,
        arena_len,
        meta_off,
        meta_len: meta.0.len() as u64,
        meta_sum: checksum(&meta.0),
    };
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let tmp = key.file.with_extension(format!(
        "idx.tmp-{}-{}",
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    ));
    let result = (|| {
        let f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&tmp)?;
        let mut out = std::io::BufWriter::with_capacity(1 << 20, f);
        out.write_all(&header(version, &key.text, &s))?;
        ix.recs.write_packed(&mut out)?;
        match (&ix.file, &ix.arena_file) {
            (Some(_), _) => {}
            (None, Some(f)) => {
                let mut buf = vec![0u8; 1 << 20];
                let mut at = 0;
                while at < arena_len {
                    let n = (arena_len - at).min(buf.len() as u64) as usize;
                    f.file.read_exact_at(&mut buf[..n], f.base + at)?;
                    out.write_all(&buf[..n])?;
                    at += n as u64;
                }
            }
            (None, None) => out.write_all(&ix.arena)?,
        }
        out.write_all(&meta.0)?;
        let f = out.into_inner().map_err(|e| e.into_error())?;
        if f.metadata()?.len() != meta_off + s.meta_len {
            return Err(std::io::Error::other("cache file of the wrong length"));
        }
        drop(f);
        std::fs::rename(&tmp, &key.file)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// The index in the cache file of `key`, when there is one and it is sound and of this build;
/// else `None` (it is then indexed again and the file replaced).
pub(super) fn read(key: &Key) -> Option<Index> {
    read_as(key, VERSION)
}

fn read_as(key: &Key, version: &str) -> Option<Index> {
    let file = std::fs::File::open(&key.file).ok()?;
    let file_len = file.metadata().ok()?.len();
    let mut fixed = [0u8; 16];
    file.read_exact_at(&mut fixed, 0).ok()?;
    let mut d = Dec(&fixed);
    if d.arr::<8>()? != MAGIC || d.u32()? != LAYOUT {
        return None;
    }
    let head_len = usize::try_from(d.u32()?).ok()?;
    if !(24..=MAX_HEADER).contains(&head_len) {
        return None;
    }
    let mut head = vec![0u8; head_len];
    file.read_exact_at(&mut head, 0).ok()?;
    let (body, sum) = head.split_at(head_len - 8);
    if checksum(body) != u64::from_le_bytes(sum.try_into().ok()?) {
        return None;
    }
    let mut d = Dec(&body[16..]);
    if d.str()? != version || d.str()? != key.text {
        return None;
    }
    let s = Sections {
        recs_off: d.u64()?,
        recs: d.u64()?,
        arena_off: d.u64()?,
        arena_len: d.u64()?,
        meta_off: d.u64()?,
        meta_len: d.u64()?,
        meta_sum: d.u64()?,
    };
    let recs_end = s
        .recs
        .checked_mul(std::mem::size_of::<Packed>() as u64)?
        .checked_add(s.recs_off)?;
    let sound = s.recs_off == head_len as u64
        && recs_end == s.arena_off
        && s.arena_off.checked_add(s.arena_len)? == s.meta_off
        && s.meta_off.checked_add(s.meta_len)? == file_len;
    if !sound {
        return None;
    }
    let mut meta = vec![0u8; usize::try_from(s.meta_len).ok()?];
    file.read_exact_at(&mut meta, s.meta_off).ok()?;
    if checksum(&meta) != s.meta_sum {
        return None;
    }
    let spill = Spill {
        file: file.try_clone().ok()?,
        id: next_spill_id(),
        base: s.recs_off,
    };
    let mut ix = decode_meta(&mut Dec(&meta), spill)?;
    if ix.recs.len() as u64 != s.recs {
        return None;
    }
    if ix.format == "raw bytes" {
        if s.arena_len != 0 {
            return None;
        }
        ix.file = Some(ReadBack::open(&key.path).ok()?);
    } else {
        ix.arena_file = Some(ReadBack::at(file, s.arena_off));
    }
    // Used now: the last to be evicted.
    if let Ok(f) = std::fs::File::options().write(true).open(&key.file) {
        let _ = f.set_modified(std::time::SystemTime::now());
    }
    Some(ix)
}

/// Keep the cache directory under `max` bytes: remove its least recently used cache files
/// (by modification time, which a use refreshes) but `keep`, and unfinished writes older than
/// an hour.
pub(super) fn evict(dir: &Path, keep: &Path, max: u64) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let now = std::time::SystemTime::now();
    let mut files = vec![];
    let mut total = 0u64;
    for e in entries.flatten() {
        let p = e.path();
        let name = e.file_name().to_string_lossy().into_owned();
        let Ok(m) = e.metadata() else { continue };
        if !m.is_file() {
            continue;
        }
        let when = m.modified().unwrap_or(std::time::UNIX_EPOCH);
        if name.contains(".idx.tmp-") {
            if now.duration_since(when).is_ok_and(|d| d > STALE_TMP) {
                let _ = std::fs::remove_file(&p);
            }
            continue;
        }
        if !name.ends_with(".idx") {
            continue;
        }
        total += m.len();
        if p != keep {
            files.push((when, m.len(), p));
        }
    }
    files.sort();
    for (_, len, p) in files {
        if total <= max {
            break;
        }
        if std::fs::remove_file(&p).is_ok() {
            total -= len;
        }
    }
}

/// After indexing `key`'s capture: write the index to the cache when it is complete, was not
/// stopped and the capture did not change meanwhile; then keep the directory within its size.
pub(super) fn save(shared: &Shared, key: &Key) {
    let state = |s| shared.cache.store(s, Ordering::Relaxed);
    if shared.cancel.load(Ordering::Relaxed) || !key.unchanged() {
        state(CACHE_NOT_SAVED);
        return;
    }
    let written = match shared.index.read() {
        Ok(ix) => write(&ix, key, VERSION).is_ok(),
        Err(_) => false,
    };
    if written {
        if let Some(dir) = key.file.parent() {
            evict(dir, &key.file, cache_max());
        }
    }
    state(if written {
        CACHE_SAVED
    } else {
        CACHE_NOT_SAVED
    });
}

/// [`Shared::cache`]: no cache file read or written (yet).
pub const CACHE_NONE: u8 = 0;
/// [`Shared::cache`]: the index is being written to the cache after indexing.
pub const CACHE_SAVING: u8 = 1;
/// [`Shared::cache`]: the index was written to the cache.
pub const CACHE_SAVED: u8 = 2;
/// [`Shared::cache`]: the index could not be written or was not to be (stopped, capture
/// changed while indexing, a write failed).
pub const CACHE_NOT_SAVED: u8 = 3;
/// [`Shared::cache`]: the index was read from the cache.
pub const CACHE_READ: u8 = 4;

#[cfg(test)]
pub(super) fn read_with_version(key: &Key, version: &str) -> Option<Index> {
    read_as(key, version)
}

/// Where a capture's cache file would be (tests).
pub fn cache_file_of(path: &str, cache: &Path) -> Option<PathBuf> {
    Key::new(
        path,
        &OpenOptions::default(),
        None,
        &UnitsOpts::default(),
        cache,
    )
    .map(|k| k.file)
}
