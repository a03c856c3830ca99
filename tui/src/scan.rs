//! The background scan: every record rendered as its NDJSON object, matched against the display
//! filter (the matching record numbers are what the timeline shows) and counted into the
//! statistics. Follows the index while it is still being built; a new filter starts a new scan.

use crate::decode::{direct, direct_for_stats, project, render, Rendered, NOT_DIRECT};
use crate::index::Index;
use crate::index::Shared;
use aptscope_dissector::filter::Filter;
use aptscope_dissector::stats::Stats;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

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
    /// Statistics of the matching records.
    pub stats: Stats,
    /// The whole index has been scanned (and the index is complete).
    pub done: bool,
}

impl ScanState {
    fn new(gen: u64, filter: Option<Filter>) -> Self {
        ScanState {
            gen,
            filter,
            matches: vec![],
            scanned: 0,
            stats: Stats::new(1_000_000_000),
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
}

impl Default for Scan {
    fn default() -> Self {
        Scan {
            state: Mutex::new(ScanState::new(0, None)),
            gen: AtomicU64::new(0),
        }
    }
}

const BATCH: usize = 2048;

/// The top-level record keys [`Stats::add`] reads (sorted): statistics of records reduced to
/// these keys equal those of the full records (`tui/tests/scan.rs` checks it).
pub const STATS_KEYS: &[&str] = &[
    "addr",
    "cmd",
    "diag",
    "dir",
    "dst",
    "latency_ms",
    "len",
    "msgid_hex",
    "n",
    "name",
    "pair",
    "proto",
    "src",
    "ts_ns",
    "type",
];

impl Scan {
    /// Start a scan with `filter` (replacing any running one). With `background` false the
    /// scan runs to the end of the (complete) index in the calling thread.
    pub fn start(self: &Arc<Self>, index: Arc<Shared>, filter: Option<Filter>, background: bool) {
        let gen = self.gen.fetch_add(1, Ordering::SeqCst) + 1;
        if let Ok(mut s) = self.state.lock() {
            *s = ScanState::new(gen, filter.clone());
        }
        let me = self.clone();
        let work = move || me.run(gen, index, filter);
        if background {
            let _ = std::thread::Builder::new()
                .name("aptscope-scan".into())
                .spawn(work);
        } else {
            work();
        }
    }

    fn run(&self, gen: u64, index: Arc<Shared>, filter: Option<Filter>) {
        let mut buf = String::with_capacity(512);
        // Only the keys the filter reads (then, for matches, those the statistics read) are
        // built: from the index record and frame header when they can be, else rendered to
        // NDJSON text as `decode --json` writes it and parsed (key by key). `fields`, the
        // largest value, only when the filter needs it (see `Filter::record_keys_split`).
        let (keys, fallback) = filter
            .as_ref()
            .map(Filter::record_keys_split)
            .unwrap_or_default();
        let all_keys = filter.as_ref().map(Filter::record_keys).unwrap_or_default();
        let mut stats_keys = Keys::new(STATS_KEYS, None);
        stats_keys.lean = true;
        // Read through the fallback only, `fields` is read at those names only.
        let sub = (!keys.contains(&"fields")).then_some(&fallback[..]);
        let (keys, all_keys) = (Keys::new(&keys, None), Keys::new(&all_keys, sub));
        let mut next: u64 = 1;
        loop {
            if self.gen.load(Ordering::SeqCst) != gen || index.cancel.load(Ordering::Relaxed) {
                return;
            }
            let mut found = vec![];
            let mut recs = vec![];
            let (len, done) = {
                let Ok(ix) = index.index.read() else { return };
                let len = ix.recs.len() as u64;
                let end = (next + BATCH as u64).min(len + 1);
                for n in next..end {
                    let mut rd = None;
                    if let Some(f) = &filter {
                        let v = keys.get(&ix, n, &mut buf, &mut rd).and_then(|v| {
                            if fallback.iter().all(|k| v.get(k).is_some()) {
                                Some(v)
                            } else {
                                all_keys.get(&ix, n, &mut buf, &mut rd)
                            }
                        });
                        match v {
                            Some(v) if f.matches(&v) => found.push(n),
                            _ => continue,
                        }
                    }
                    if let Some(v) = stats_keys.get(&ix, n, &mut buf, &mut rd) {
                        recs.push(v);
                    }
                }
                next = end;
                (len, ix.done)
            };
            let finished = done && next > len;
            if let Ok(mut s) = self.state.lock() {
                if s.gen != gen {
                    return;
                }
                s.matches.extend(found);
                for v in &recs {
                    s.stats.add(v);
                }
                s.scanned = next - 1;
                s.done = finished;
            }
            if finished {
                return;
            }
            if next > len {
                std::thread::sleep(Duration::from_millis(30));
            }
        }
    }
}

/// A set of record keys to build.
struct Keys<'k> {
    keys: &'k [&'k str],
    /// Only these names of `fields` (else all).
    fields: Option<&'k [&'k str]>,
    /// All can be built by [`direct`].
    direct: bool,
    /// For statistics only: [`direct_for_stats`].
    lean: bool,
}

impl<'k> Keys<'k> {
    fn new(keys: &'k [&'k str], fields: Option<&'k [&'k str]>) -> Self {
        let direct = keys
            .iter()
            .all(|k| !NOT_DIRECT.contains(k) && (*k != "fields" || fields.is_some()));
        Keys {
            keys,
            fields,
            direct,
            lean: false,
        }
    }

    /// Record `n` reduced to the keys; `rd` caches the rendering in `buf` (`Some(None)`: the
    /// record does not render, and is skipped as [`crate::decode::json_of`] skips it).
    fn get(
        &self,
        ix: &Index,
        n: u64,
        buf: &mut String,
        rd: &mut Option<Option<Rendered>>,
    ) -> Option<serde_json::Value> {
        if self.direct {
            let v = if self.lean {
                direct_for_stats(ix, n, self.keys)
            } else {
                direct(ix, n, self.keys, self.fields.unwrap_or_default())
            };
            if v.is_some() {
                return v;
            }
        }
        let rd = *rd.get_or_insert_with(|| render(ix, n, buf));
        project(buf, &rd?, self.keys, self.fields)
    }
}
