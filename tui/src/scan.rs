//! The background scan: the display filter over every record of the index (the matching record
//! numbers are what the timeline shows) and the statistics of the matching records. It reads the
//! compact records ([`crate::fields::View`]): record-level filter terms and the counts cost no
//! decoding; only field terms, and diagnostics of damaged records, decode the frame's bytes.
//! Follows the index while it grows (a live source, or a file still being indexed): the results
//! extend as records arrive; a new filter starts a new scan.

use crate::fields::{self, View, DIRS};
use crate::index::{Index, Rec, Shared, F_ELL, F_GARBAGE, F_IS_REPLY};
use aptscope_dissector::filter::{Filter, IdSet, Matcher};
use aptscope_dissector::stats::{self, Latencies, Stats, StreamStat, Tally};
use aptscope_dissector::DiagKind;
use aptscope_dissector::Table;
use std::collections::{BTreeMap, VecDeque};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// What a scan has found so far.
#[derive(Debug)]
pub struct ScanState {
    /// The scan's generation (a newer filter makes older scans stop).
    pub gen: u64,
    /// The filter (`None`: every record is shown, only statistics are gathered).
    pub filter: Option<Filter>,
    /// Record numbers that match, in order (only with a filter).
    pub matches: Vec<u64>,
    /// Records scanned.
    pub scanned: u64,
    /// Statistics of the matching records (brought up to date every few tenths of a second
    /// and at the end).
    pub stats: Stats,
    /// The whole index has been scanned (and the index is complete).
    pub done: bool,
}

/// Width of the statistics' rate bins.
pub const BIN_NS: u64 = 1_000_000_000;

impl ScanState {
    fn new(gen: u64, filter: Option<Filter>) -> Self {
        ScanState {
            gen,
            filter,
            matches: vec![],
            scanned: 0,
            stats: Stats::new(BIN_NS),
            done: false,
        }
    }
}

/// The scan shared between its thread and the UI.
#[derive(Debug)]
pub struct Scan {
    /// The state.
    pub state: Mutex<ScanState>,
    gen: AtomicU64,
    /// Where the scan is and what it counted (held by whoever scans).
    work: Mutex<Work>,
    /// Threads a filter is evaluated on (the records of a batch split between them).
    threads: usize,
    /// Records a batch needs to be split between threads.
    split_from: usize,
    /// The results of the last complete scans, newest last: going back to a filter shows
    /// them at once instead of scanning again.
    done: Mutex<Vec<Done>>,
}

/// A complete scan's result, kept for its filter.
#[derive(Debug)]
struct Done {
    /// The filter's text (empty: none).
    key: String,
    /// Records of the (complete) index it covered.
    len: u64,
    /// Bit `n - 1` set: record `n` matched.
    bits: Vec<u64>,
    stats: Stats,
}

/// Complete scans kept ([`Scan::done`]): a bit a record each.
const DONE_KEPT: usize = 8;

/// Records a batch needs before its filter is evaluated on several threads (fewer are not
/// worth starting them).
const SPLIT_FROM: usize = 4096;

impl Default for Scan {
    fn default() -> Self {
        let cores = std::thread::available_parallelism().map_or(1, usize::from);
        Scan::with_threads(cores.min(4), SPLIT_FROM)
    }
}

impl Scan {
    /// A scan that evaluates filters on `threads` threads for batches of `split_from` records
    /// or more (one thread: the sequential scan tests compare the others with).
    pub fn with_threads(threads: usize, split_from: usize) -> Self {
        Scan {
            state: Mutex::new(ScanState::new(0, None)),
            gen: AtomicU64::new(0),
            work: Mutex::new(Work::new(0, None)),
            threads: threads.max(1),
            split_from: split_from.max(2),
            done: Mutex::new(vec![]),
        }
    }

    /// Whether the result of `filter` over the complete index of `len` records is kept.
    pub fn is_kept(&self, filter: Option<&Filter>, len: u64) -> bool {
        let key = filter.map_or(String::new(), Filter::to_string);
        self.done
            .lock()
            .is_ok_and(|d| d.iter().any(|x| x.key == key && x.len == len))
    }

    /// Keep a complete scan's result.
    fn keep(&self, s: &ScanState) {
        let len = s.scanned;
        let mut bits = vec![];
        if s.filter.is_some() {
            bits = vec![0u64; (len as usize).div_ceil(64)];
            for &n in &s.matches {
                if let Some(w) = bits.get_mut(((n - 1) / 64) as usize) {
                    *w |= 1 << ((n - 1) % 64);
                }
            }
        }
        let key = s.filter.as_ref().map_or(String::new(), Filter::to_string);
        if let Ok(mut d) = self.done.lock() {
            d.retain(|x| x.key != key);
            if d.len() >= DONE_KEPT {
                d.remove(0);
            }
            d.push(Done {
                key,
                len,
                bits,
                stats: s.stats.clone(),
            });
        }
    }

    /// The kept result of `filter` over the complete index of `len` records, as a finished
    /// scan's state.
    fn kept(&self, gen: u64, filter: &Option<Filter>, len: u64) -> Option<ScanState> {
        let key = filter.as_ref().map_or(String::new(), Filter::to_string);
        let d = self.done.lock().ok()?;
        let x = d.iter().find(|x| x.key == key && x.len == len)?;
        let mut st = ScanState::new(gen, filter.clone());
        for (i, &w) in x.bits.iter().enumerate() {
            let mut w = w;
            while w != 0 {
                st.matches
                    .push(i as u64 * 64 + u64::from(w.trailing_zeros()) + 1);
                w &= w - 1;
            }
        }
        st.stats = x.stats.clone();
        st.scanned = len;
        st.done = true;
        Some(st)
    }
}

/// The scanning side of a scan.
#[derive(Debug)]
struct Work {
    gen: u64,
    filter: Option<Matcher>,
    /// The APT message ids whose frames can pass the filter (`None`: any).
    ids: Option<IdSet>,
    /// Next record to scan.
    next: u64,
    /// How many of the index's [`Index::late_no_reply`] were looked at.
    late_seen: usize,
    counts: Counts,
    /// When the statistics shown were last rebuilt.
    shown: Instant,
    found: Vec<u64>,
    /// The state was a kept result ([`Scan::kept`]), or this scan finished: nothing to scan
    /// (a synchronous scan's every later [`Scan::catch_up`] rebuilt the statistics and kept
    /// the result again, a few milliseconds a frame in a debug build).
    kept: bool,
}

impl Work {
    fn new(gen: u64, filter: Option<Filter>) -> Self {
        Work {
            gen,
            ids: filter.as_ref().and_then(|f| f.apt_ids(Table::global())),
            filter: filter.as_ref().map(Filter::matcher),
            next: 1,
            late_seen: 0,
            counts: Counts::default(),
            shown: Instant::now(),
            found: vec![],
            kept: false,
        }
    }
}

/// What one step of a scan came to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    /// Records are left to scan.
    More,
    /// Every record of the index so far is scanned; more may come.
    CaughtUp,
    /// The complete index is scanned.
    Finished,
    /// A newer scan replaced this one (or the viewer is closing).
    Stale,
}

/// Records scanned per hold of the index lock.
const BATCH: u64 = 1 << 15;

/// How often the statistics shown are rebuilt while a scan runs.
const STATS_EVERY: Duration = Duration::from_millis(200);

impl Scan {
    /// Start a scan with `filter` (replacing any running one). With `background` false the
    /// scan runs to the end of the index so far in the calling thread; [`Scan::catch_up`]
    /// scans what the index gains later.
    pub fn start(self: &Arc<Self>, index: Arc<Shared>, filter: Option<Filter>, background: bool) {
        let gen = self.gen.fetch_add(1, Ordering::SeqCst) + 1;
        // A filter scanned before over the same complete index: its result at once.
        let complete = index
            .index
            .read()
            .ok()
            .filter(|ix| ix.done)
            .map(|ix| ix.recs.len() as u64);
        let kept = complete.and_then(|len| self.kept(gen, &filter, len));
        if let Ok(mut w) = self.work.lock() {
            *w = Work::new(gen, filter.clone());
            w.kept = kept.is_some();
        }
        if let Ok(mut s) = self.state.lock() {
            *s = kept.unwrap_or_else(|| ScanState::new(gen, filter));
            if s.done {
                return;
            }
        }
        if !background {
            self.catch_up(&index);
            return;
        }
        let me = self.clone();
        let _ = std::thread::Builder::new()
            .name("aptscope-scan".into())
            .spawn(move || loop {
                match me.step(gen, &index, false) {
                    Step::More => {}
                    Step::CaughtUp => std::thread::sleep(Duration::from_millis(30)),
                    Step::Finished | Step::Stale => return,
                }
            });
    }

    /// Scan the records the index gained since the last step (a synchronous scan: tests, and
    /// the viewer without background threads). The matches and statistics extend; nothing is
    /// scanned twice.
    pub fn catch_up(&self, index: &Shared) {
        let gen = self.gen.load(Ordering::SeqCst);
        while self.step(gen, index, true) == Step::More {}
    }

    /// Scan the next batch of records of scan `gen`; `sync`: the caller waits for it (the
    /// statistics are brought up to date when it catches up).
    fn step(&self, gen: u64, index: &Shared, sync: bool) -> Step {
        if self.gen.load(Ordering::SeqCst) != gen || index.cancel.load(Ordering::Relaxed) {
            return Step::Stale;
        }
        let Ok(mut guard) = self.work.lock() else {
            return Step::Stale;
        };
        let w = &mut *guard;
        if w.gen != gen {
            return Step::Stale;
        }
        if w.kept {
            return Step::Finished;
        }
        w.found.clear();
        let Ok(ix) = index.index.read() else {
            return Step::Stale;
        };
        let len = ix.recs.len() as u64;
        let (from, end) = (w.next, (w.next + BATCH).min(len + 1));
        let recs = ix.recs.iter_from((from - 1) as usize);
        let take = (end - from) as usize;
        match &w.filter {
            Some(f) if self.threads > 1 && take >= self.split_from => {
                // The filter on several threads (field terms decode frames: the costly part),
                // each over a slice of the batch; then counted in order.
                let recs: Vec<Rec> = recs.take(take).collect();
                let part = recs.len().div_ceil(self.threads);
                let (ix, ids) = (&*ix, w.ids.as_ref());
                let keep: Vec<Vec<bool>> = std::thread::scope(|s| {
                    let handles: Vec<_> = recs
                        .chunks(part)
                        .enumerate()
                        .map(|(k, slice)| {
                            let first = from + (k * part) as u64;
                            s.spawn(move || {
                                slice
                                    .iter()
                                    .enumerate()
                                    .map(|(i, r)| passes(f, ids, ix, first + i as u64, r))
                                    .collect::<Vec<bool>>()
                            })
                        })
                        .collect();
                    // A thread that panicked (it cannot: no data reaches a panic) passes none.
                    handles
                        .into_iter()
                        .map(|h| h.join().unwrap_or_default())
                        .collect()
                });
                let keep = keep.iter().flatten();
                for (i, (r, &yes)) in recs.iter().zip(keep).enumerate() {
                    if yes {
                        let n = from + i as u64;
                        w.found.push(n);
                        w.counts.add(ix, n, r);
                    }
                }
            }
            _ => {
                for (i, r) in recs.take(take).enumerate() {
                    let (n, r) = (from + i as u64, &r);
                    if let Some(f) = &w.filter {
                        if !passes(f, w.ids.as_ref(), &ix, n, r) {
                            continue;
                        }
                        w.found.push(n);
                    }
                    w.counts.add(&ix, n, r);
                }
            }
        }
        // Records scanned before they got their `no_reply` (the timeline shows it on the row
        // now): counted now, with whether the filter takes them now.
        let mut late = vec![];
        for &n in ix.late_no_reply.get(w.late_seen..).unwrap_or(&[]) {
            if n >= from {
                continue; // scanned in this batch, or later: with the flag.
            }
            let now = ix.rec(n).is_some_and(|r| {
                w.filter
                    .as_ref()
                    .is_none_or(|f| f.matches(&View { ix: &ix, n, r: &r }))
            });
            late.push((n, now));
        }
        w.late_seen = ix.late_no_reply.len();
        w.next = end;
        let caught_up = end > len;
        let finished = ix.done && caught_up;
        // The statistics: rebuilt now and then, and at the end.
        let due = w.shown.elapsed() > STATS_EVERY;
        // Matches of the filter, to tell a late record that was shown from one that is shown
        // only now (which is counted whole, and inserted among the matches in order).
        let shown: Vec<(u64, bool)> = match &w.filter {
            None => late.iter().map(|&(n, _)| (n, true)).collect(),
            Some(_) => self.state.lock().map_or(vec![], |s| {
                late.iter()
                    .map(|&(n, _)| (n, s.matches.binary_search(&n).is_ok()))
                    .collect()
            }),
        };
        let mut newly = vec![];
        for (&(n, now), &(_, was)) in late.iter().zip(&shown) {
            match (was, now) {
                (true, _) => w.counts.bump_diag(DiagKind::NoReply { cmd: n }.name()),
                (false, true) => {
                    if let Some(r) = ix.rec(n) {
                        w.counts.add(&ix, n, &r);
                    }
                    newly.push(n);
                }
                (false, false) => {}
            }
        }
        let stats = (finished || due || (caught_up && (from < end || !late.is_empty()) && sync))
            .then(|| w.counts.stats(&ix));
        drop(ix);
        if stats.is_some() {
            w.shown = Instant::now();
        }
        if let Ok(mut s) = self.state.lock() {
            if s.gen != gen {
                return Step::Stale;
            }
            for n in newly {
                if let Err(at) = s.matches.binary_search(&n) {
                    s.matches.insert(at, n);
                }
            }
            s.matches.extend_from_slice(&w.found);
            if let Some(st) = stats {
                s.stats = st;
            }
            s.scanned = end - 1;
            s.done = finished;
            if finished {
                self.keep(&s);
            }
        }
        if finished {
            w.kept = true;
            Step::Finished
        } else if caught_up {
            Step::CaughtUp
        } else {
            Step::More
        }
    }
}

/// Whether record `n` passes the filter (its message id first, when the filter names them).
#[inline]
fn passes(f: &Matcher, ids: Option<&IdSet>, ix: &Index, n: u64, r: &Rec) -> bool {
    let apt_frame = r.flags & (F_ELL | F_GARBAGE) == 0;
    if apt_frame && ids.is_some_and(|ids| !ids.contains(r.id)) {
        return false;
    }
    f.matches(&View { ix, n, r })
}

type IdMap<K, V> = aptscope_dissector::hash::NumMap<K, V>;

/// Count and bytes of frames of one kind, with one of them (whose names the kind takes).
#[derive(Debug, Clone, Copy)]
struct Class {
    rep: u64,
    count: u64,
    bytes: u64,
}

impl Class {
    fn add(slot: &mut Option<Class>, n: u64, len: u64) {
        let c = slot.get_or_insert(Class {
            rep: n,
            count: 0,
            bytes: 0,
        });
        c.count += 1;
        c.bytes += len;
    }
}

/// Requests remembered for their replies' latency (as [`Stats`] does).
const MAX_REQUESTS: usize = 1 << 16;

/// Rate bins counted in a vector; later ones (a time jump) in a map.
const DENSE_BINS: u64 = 1 << 20;

/// The statistics of the matching records, counted from the compact records by message (its
/// protocol and id), address pair and stream, direction, and made into a [`Stats`] with the
/// names read from one record of each kind through [`View`]: equal to [`Stats::add`] over the
/// records themselves (`tui/tests/scan.rs` checks it).
#[derive(Debug, Default)]
struct Counts {
    frames: Tally,
    garbage: Tally,
    /// By message: `(ell << 16 | id)`.
    messages: Vec<Option<Class>>,
    /// By stream, protocol and addresses.
    addresses: IdMap<u64, Class>,
    directions: [Tally; 3],
    /// Latencies by message of the request.
    latencies: IdMap<u32, Latencies>,
    /// Recent requests: (record number, message), in record order.
    requests: VecDeque<(u64, u32)>,
    /// Diagnostics by kind.
    diags: Vec<(&'static str, u64)>,
    first_ts: Option<u64>,
    bins: Vec<u64>,
    far_bins: BTreeMap<u64, u64>,
}

fn add_to<K: Ord>(map: &mut BTreeMap<K, Tally>, k: K, c: &Class) {
    let t = map.entry(k).or_default();
    t.count += c.count;
    t.bytes += c.bytes;
}

impl Counts {
    /// Count one diagnostic of kind `k`.
    fn bump_diag(&mut self, k: &'static str) {
        // Kinds are static names: found by address (one comparison) in a short list.
        match self
            .diags
            .iter_mut()
            .find(|(x, _)| std::ptr::eq(*x, k) || *x == k)
        {
            Some((_, c)) => *c += 1,
            None => self.diags.push((k, 1)),
        }
    }

    fn add(&mut self, ix: &Index, n: u64, r: &Rec) {
        let v = View { ix, n, r };
        fields::diag_kinds(ix, n, r, &mut |k| self.bump_diag(k));
        let len = r.len as u64;
        if r.has(F_GARBAGE) {
            self.garbage.count += 1;
            self.garbage.bytes += len;
            return;
        }
        self.frames.count += 1;
        self.frames.bytes += len;
        let ell = r.has(F_ELL);
        let msg = (ell as u32) << 16 | r.id as u32;
        if self.messages.is_empty() {
            self.messages = vec![None; 2 << 16];
        }
        Class::add(&mut self.messages[msg as usize], n, len);
        let (src, dst) = if ell { (r.src, 0) } else { (r.src, r.dst) };
        let addr = (r.stream as u64) << 24 | (ell as u64) << 16 | (src as u64) << 8 | dst as u64;
        let c = self.addresses.entry(addr).or_insert(Class {
            rep: n,
            count: 0,
            bytes: 0,
        });
        c.count += 1;
        c.bytes += len;
        let dir = v.dir_slot().unwrap_or(2);
        self.directions[dir].count += 1;
        self.directions[dir].bytes += len;
        match (r.has(F_IS_REPLY) && r.pair != 0).then_some(r.pair as u64) {
            None => {
                // What can be a request is remembered (a reply names its request in `pair`).
                if dir != 1 {
                    self.requests.push_back((n, msg));
                    if self.requests.len() > MAX_REQUESTS {
                        self.requests.pop_front();
                    }
                }
            }
            Some(p) => {
                if let Some(l) = fields::latency(ix, r) {
                    if let Ok(i) = self.requests.binary_search_by_key(&p, |x| x.0) {
                        let req = self.requests[i].1;
                        self.latencies.entry(req).or_default().push(l as f64 / 1e6);
                    }
                }
            }
        }
        if let Some(ts) = r.ts() {
            let first = *self.first_ts.get_or_insert(ts);
            let bin = ts.saturating_sub(first) / BIN_NS;
            if bin < DENSE_BINS {
                let i = bin as usize;
                if self.bins.len() <= i {
                    self.bins.resize(i + 1, 0);
                }
                self.bins[i] += 1;
            } else {
                *self.far_bins.entry(bin * BIN_NS).or_default() += 1;
            }
        }
    }

    /// The [`Stats`] of what was counted.
    fn stats(&self, ix: &Index) -> Stats {
        let mut s = Stats::new(BIN_NS);
        s.frames = self.frames.clone();
        s.garbage = self.garbage.clone();
        for (k, c) in &self.diags {
            *s.diags.entry(k.to_string()).or_default() += c;
        }
        // Streams the capture names, as its `stream` records do.
        for (i, name) in ix.streams.iter().enumerate() {
            if !name.is_empty() {
                s.streams.insert(
                    i as u64,
                    StreamStat {
                        name: Some(name.clone()),
                        tally: Tally::default(),
                    },
                );
            }
        }
        // Named as `Stats` names them, from one record of each.
        for (msg, c) in self.messages.iter().enumerate() {
            let Some(c) = c else { continue };
            let Some(r) = ix.rec(c.rep) else { continue };
            let v = View {
                ix,
                n: c.rep,
                r: &r,
            };
            let mut key = String::new();
            stats::message_key(&v, &mut key);
            let m = s.messages.entry(key).or_default();
            m.tally.count += c.count;
            m.tally.bytes += c.bytes;
            if let Some(lat) = self.latencies.get(&(msg as u32)) {
                m.latencies = lat.clone();
            }
        }
        // Per stream too.
        for (k, c) in &self.addresses {
            let Some(r) = ix.rec(c.rep) else { continue };
            let v = View {
                ix,
                n: c.rep,
                r: &r,
            };
            let mut addr = String::new();
            stats::address_key(&v, &mut addr);
            let st = k >> 24;
            add_to(&mut s.stream_addresses, (st, addr.clone()), c);
            add_to(&mut s.addresses, addr, c);
            let t = &mut s.streams.entry(st).or_default().tally;
            t.count += c.count;
            t.bytes += c.bytes;
        }
        for (d, t) in DIRS.iter().zip(&self.directions) {
            if t.count > 0 {
                s.directions.insert(d.to_string(), t.clone());
            }
        }
        s.bins = self
            .bins
            .iter()
            .enumerate()
            .filter(|(_, c)| **c > 0)
            .map(|(i, c)| (i as u64 * BIN_NS, *c))
            .chain(self.far_bins.iter().map(|(b, c)| (*b, *c)))
            .collect();
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A synchronous scan that reached the end of a complete index is not done again at each
    /// later [`Scan::catch_up`] (each frame of the viewer without a scan thread).
    #[test]
    fn a_finished_synchronous_scan_is_not_redone() {
        let path = format!("{}/../samples/damaged.bin", env!("CARGO_MANIFEST_DIR"));
        let shared = crate::index::load(&path, aptscope_capture::open::OpenOptions::default())
            .expect("sample opens");
        let scan = Arc::new(Scan::default());
        scan.start(shared.clone(), None, false);
        assert!(scan.state.lock().expect("state").done);
        assert!(scan.work.lock().expect("work").kept);
        let gen = scan.gen.load(Ordering::SeqCst);
        assert!(scan.step(gen, &shared, true) == Step::Finished);
    }
}
