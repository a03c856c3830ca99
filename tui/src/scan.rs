//! The background scan: every record rendered as its NDJSON object, matched against the display
//! filter (the matching record numbers are what the timeline shows) and counted into the
//! statistics. Follows the index while it is still being built; a new filter starts a new scan.

use crate::decode::json_of;
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
                    if let Some(v) = json_of(&ix, n, &mut buf) {
                        let keep = filter.as_ref().is_none_or(|f| f.matches(&v));
                        if keep {
                            if filter.is_some() {
                                found.push(n);
                            }
                            recs.push(v);
                        }
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
