//! Row groups encoded on other threads: the thread that decodes and builds the rows hands each
//! finished batch over and goes on, while Parquet encoding and compression (about half of a
//! `--to parquet` run's CPU) happen beside it. Used where cores are spare: one capture with
//! `-j 2`, whose rows are built on one thread.

use crate::Sink;
use arrow_array::RecordBatch;
use std::collections::HashMap;
use std::io;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;

/// What a writing thread is given: a row group of a table's part, or the end of a part.
enum Msg {
    Write(String, u32, RecordBatch),
    Close(String, u32),
}

/// A [`Sink`] that writes every table on one of its threads, each thread into a sink of its
/// own: a table's row groups and the ends of its parts reach its thread in the order written,
/// so a sink that writes a part file of several row groups ([`DirSink`]) writes the files of
/// one thread. Which thread writes a table is decided when its first row group comes (the one
/// given the fewest rows so far), so the files do not depend on the threads' timing.
///
/// Memory: the row groups handed over and not yet written hold at most `rows` rows and `bytes`
/// bytes of arrays together (one larger than that waits alone); a kind table's row groups are
/// often small, so a budget in rows rather than in row groups lets many wait while the largest
/// are encoded, and the bytes bound row groups of long rows (garbage runs of 4 KiB each). A
/// write that fails is returned by a later [`Sink::write`] (the decoding stops there) or by
/// [`Sink::finish`], which waits for the threads.
///
/// [`DirSink`]: crate::DirSink
pub struct Threaded {
    /// Each thread's queue, and the rows it was given.
    txs: Vec<(Sender<Msg>, usize)>,
    /// The thread of each table met.
    route: HashMap<String, usize>,
    /// Rows and bytes handed over and not yet written, and the budget.
    gate: Arc<Gate>,
    threads: Vec<JoinHandle<()>>,
    /// The first write that failed.
    failed: Arc<Mutex<Option<io::Error>>>,
}

impl Threaded {
    /// `n` threads (at least one), each writing into the sink `make` gives it; at most `rows`
    /// rows and `bytes` bytes of arrays waiting. Fails when a thread cannot be started.
    pub fn new<S: Sink + Send + 'static>(
        n: usize,
        rows: usize,
        bytes: usize,
        make: impl Fn() -> S,
    ) -> io::Result<Self> {
        let failed = Arc::new(Mutex::new(None));
        let gate = Arc::new(Gate {
            held: Mutex::new(Load::default()),
            freed: Condvar::new(),
            max: Load { rows, bytes },
            closed: AtomicBool::new(false),
        });
        let mut t = Threaded {
            txs: Vec::new(),
            route: HashMap::new(),
            gate,
            threads: Vec::new(),
            failed,
        };
        for _ in 0..n.max(1) {
            let (tx, rx) = channel::<Msg>();
            let q = Queue {
                rx,
                gate: t.gate.clone(),
            };
            let (failed, gate, mut sink) = (t.failed.clone(), t.gate.clone(), make());
            // On failure, the threads started are joined when `t` drops.
            let h = std::thread::Builder::new()
                .name("parquet-write".into())
                .spawn(move || {
                    let done = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                        run(&q, &failed, &gate, &mut sink)
                    }));
                    if done.is_err() {
                        fail(
                            &failed,
                            io::Error::other("a Parquet writing thread panicked"),
                        );
                    }
                    // `q` drops here, after the error is kept: a write woken by the closed
                    // gate finds it.
                    drop(q);
                })?;
            t.txs.push((tx, 0));
            t.threads.push(h);
        }
        Ok(t)
    }

    /// The first error a thread met, taken.
    fn error(&self) -> Option<io::Error> {
        self.failed.lock().ok().and_then(|mut e| e.take())
    }

    /// Waits for every thread to write what it was given.
    fn join(&mut self) {
        self.txs.clear();
        for t in std::mem::take(&mut self.threads) {
            if t.join().is_err() {
                fail(
                    &self.failed,
                    io::Error::other("a Parquet writing thread panicked"),
                );
            }
        }
    }

    /// The queue of `table`'s thread (chosen now if it is new).
    fn queue(&mut self, table: &str) -> io::Result<&mut (Sender<Msg>, usize)> {
        let i = match self.route.get(table) {
            Some(&i) => i,
            None => {
                let i = (0..self.txs.len())
                    .min_by_key(|&i| self.txs[i].1)
                    .unwrap_or(0);
                self.route.insert(table.to_string(), i);
                i
            }
        };
        self.txs
            .get_mut(i)
            .ok_or_else(|| io::Error::other("sink finished"))
    }
}

/// Keep `e` unless an earlier error is kept.
fn fail(failed: &Mutex<Option<io::Error>>, e: io::Error) {
    if let Ok(mut f) = failed.lock() {
        f.get_or_insert(e);
    }
}

/// What row groups hold: rows, and bytes of arrays.
#[derive(Debug, Clone, Copy, Default)]
struct Load {
    rows: usize,
    bytes: usize,
}

impl Load {
    fn of(batch: &RecordBatch) -> Load {
        Load {
            rows: batch.num_rows(),
            bytes: batch.get_array_memory_size(),
        }
    }

    /// Whether `more` may join this load under `max`: both its rows and its bytes fit, or
    /// nothing is held (one row group larger than the budget goes alone).
    fn fits(self, more: Load, max: Load) -> bool {
        self.rows == 0
            || (self.rows + more.rows <= max.rows && self.bytes + more.bytes <= max.bytes)
    }
}

/// A thread's queue of row groups. When its thread is gone (it panicked), the row groups still
/// in it give their load back and the gate is closed: a write waiting for room then goes on to
/// the error instead of waiting for ever.
struct Queue {
    rx: Receiver<Msg>,
    gate: Arc<Gate>,
}

impl Drop for Queue {
    fn drop(&mut self) {
        for m in self.rx.try_iter() {
            if let Msg::Write(_, _, batch) = m {
                self.gate.give(Load::of(&batch));
            }
        }
        // Under the lock, so that a write about to wait sees it or is woken.
        let _h = self.gate.held.lock();
        self.gate.closed.store(true, Ordering::SeqCst);
        self.gate.freed.notify_all();
    }
}

/// Rows and bytes in flight, under a budget.
struct Gate {
    held: Mutex<Load>,
    freed: Condvar,
    max: Load,
    /// The queue is gone (every thread with it): nothing will be given back any more.
    closed: AtomicBool,
}

impl Gate {
    /// Wait until `l` more fits (or nothing is in flight, or the queue is gone: the send that
    /// follows then fails), then count it.
    fn take(&self, l: Load) {
        let Ok(mut h) = self.held.lock() else {
            return;
        };
        while !h.fits(l, self.max) && !self.closed.load(Ordering::SeqCst) {
            h = match self.freed.wait(h) {
                Ok(h) => h,
                Err(_) => return,
            };
        }
        h.rows += l.rows;
        h.bytes += l.bytes;
    }

    fn give(&self, l: Load) {
        if let Ok(mut h) = self.held.lock() {
            h.rows = h.rows.saturating_sub(l.rows);
            h.bytes = h.bytes.saturating_sub(l.bytes);
            self.freed.notify_all();
        }
    }
}

/// A writing thread: row groups until the channel closes, then the sink finished; after a
/// failure (its own or another's) the rest are dropped unwritten.
fn run<S: Sink + ?Sized>(q: &Queue, failed: &Mutex<Option<io::Error>>, gate: &Gate, sink: &mut S) {
    let stopped = || failed.lock().map_or(true, |e| e.is_some());
    while let Ok(m) = q.rx.recv() {
        let r = match m {
            Msg::Write(table, n, batch) => {
                // Its load is given back however the write ends, a panic included: otherwise
                // the decoding thread would wait on the gate for ever instead of meeting the
                // error.
                let _given = Given(gate, Load::of(&batch));
                if stopped() {
                    continue;
                }
                sink.write(&table, n, &batch)
            }
            Msg::Close(table, n) if !stopped() => sink.close(&table, n),
            Msg::Close(..) => continue,
        };
        if let Err(e) = r {
            fail(failed, e);
        }
    }
    if !stopped() {
        if let Err(e) = sink.finish() {
            fail(failed, e);
        }
    }
}

/// Gives a load back to the gate when dropped.
struct Given<'a>(&'a Gate, Load);

impl Drop for Given<'_> {
    fn drop(&mut self) {
        self.0.give(self.1);
    }
}

impl Sink for Threaded {
    fn write(&mut self, table: &str, part: u32, batch: &RecordBatch) -> io::Result<()> {
        if let Some(e) = self.error() {
            return Err(e);
        }
        let gate = self.gate.clone();
        let q = self.queue(table)?;
        q.1 += batch.num_rows();
        gate.take(Load::of(batch));
        // Arrays are shared, not copied.
        let sent = q.0.send(Msg::Write(table.to_string(), part, batch.clone()));
        if gate.closed.load(Ordering::SeqCst) || sent.is_err() {
            return Err(self
                .error()
                .unwrap_or_else(|| io::Error::other("a Parquet writing thread stopped")));
        }
        Ok(())
    }

    fn close(&mut self, table: &str, part: u32) -> io::Result<()> {
        let q = self.queue(table)?;
        q.0.send(Msg::Close(table.to_string(), part))
            .map_err(|_| io::Error::other("a Parquet writing thread stopped"))
    }

    fn finish(&mut self) -> io::Result<()> {
        self.join();
        match self.error() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
}

impl Drop for Threaded {
    /// Not finished (the decoding failed): the parts handed over are still written, so that
    /// no thread outlives the run.
    fn drop(&mut self) {
        self.join();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A row group joins those waiting when its rows and its bytes both fit; one larger than
    /// the budget goes alone.
    #[test]
    fn the_budget_bounds_rows_and_bytes() {
        let l = |rows, bytes| Load { rows, bytes };
        let max = l(100, 1000);
        assert!(l(0, 0).fits(l(500, 5000), max));
        assert!(l(50, 500).fits(l(50, 500), max));
        assert!(!l(50, 500).fits(l(51, 10), max), "rows over");
        assert!(!l(5, 900).fits(l(5, 101), max), "bytes over");
    }
    use arrow_array::{ArrayRef, UInt32Array};
    use std::collections::BTreeMap;

    /// Keeps what it is given in a map shared by the test; fails on table "bad".
    struct Keep(Arc<Mutex<BTreeMap<(String, u32), usize>>>);

    impl Sink for Keep {
        fn write(&mut self, table: &str, part: u32, batch: &RecordBatch) -> io::Result<()> {
            if table == "bad" {
                return Err(io::Error::other("bad table"));
            }
            let mut m = self.0.lock().map_err(|_| io::Error::other("poisoned"))?;
            m.insert((table.to_string(), part), batch.num_rows());
            Ok(())
        }
    }

    fn batch(rows: u32) -> RecordBatch {
        let a: ArrayRef = Arc::new(UInt32Array::from_iter_values(0..rows));
        RecordBatch::try_from_iter([("x", a)]).expect("batch")
    }

    /// Every part handed over is written once, whatever thread takes it.
    #[test]
    fn every_part_is_written_once() {
        let seen = Arc::new(Mutex::new(BTreeMap::new()));
        let mut t = Threaded::new(3, 10, usize::MAX, || Keep(seen.clone())).expect("threads");
        for p in 0..50u32 {
            t.write(if p % 2 == 0 { "a" } else { "b" }, p, &batch(p + 1))
                .expect("write");
        }
        t.finish().expect("finish");
        let seen = seen.lock().expect("lock");
        assert_eq!(seen.len(), 50);
        for ((table, p), rows) in seen.iter() {
            assert_eq!(table, if p % 2 == 0 { "a" } else { "b" });
            assert_eq!(*rows, *p as usize + 1);
        }
    }

    /// Panics on every write.
    struct Boom;

    impl Sink for Boom {
        fn write(&mut self, _: &str, _: u32, _: &RecordBatch) -> io::Result<()> {
            panic!("a writer that panics");
        }
    }

    /// A writing thread that panics gives its rows back: the next write over the budget fails
    /// instead of waiting for ever (run on a thread of its own, so a hang fails the test).
    #[test]
    fn a_panicking_writer_is_an_error_not_a_hang() {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut t = Threaded::new(1, 1, usize::MAX, || Boom).expect("threads");
            let r = (0..100)
                .map(|p| t.write("a", p, &batch(1)))
                .find(Result::is_err)
                .unwrap_or_else(|| t.finish());
            let _ = tx.send(r.is_err());
        });
        let failed = rx
            .recv_timeout(std::time::Duration::from_secs(60))
            .expect("the writes ended");
        assert!(failed, "the panic came back as an error");
    }

    /// Sink number, table, part, whether it is the part's end.
    type Event = (usize, String, u32, bool);

    /// What each sink was given, by the sink's number: a table's row groups and part ends.
    struct Log(usize, Arc<Mutex<Vec<Event>>>);

    impl Sink for Log {
        fn write(&mut self, table: &str, part: u32, _: &RecordBatch) -> io::Result<()> {
            let mut l = self.1.lock().map_err(|_| io::Error::other("poisoned"))?;
            l.push((self.0, table.to_string(), part, false));
            Ok(())
        }

        fn close(&mut self, table: &str, part: u32) -> io::Result<()> {
            let mut l = self.1.lock().map_err(|_| io::Error::other("poisoned"))?;
            l.push((self.0, table.to_string(), part, true));
            Ok(())
        }
    }

    /// A table's row groups and the ends of its parts all reach one thread's sink, in the order
    /// written (a part file is written by one sink), and the tables are spread over the threads.
    #[test]
    fn a_table_is_written_by_one_thread_in_order() {
        let log = Arc::new(Mutex::new(Vec::new()));
        let made = std::sync::atomic::AtomicUsize::new(0);
        let mut t = Threaded::new(3, 10, usize::MAX, || {
            Log(made.fetch_add(1, Ordering::SeqCst), log.clone())
        })
        .expect("threads");
        let mut sent = vec![];
        for i in 0..600u32 {
            let table = format!("t{}", i % 7);
            let part = i / 70;
            t.write(&table, part, &batch(1)).expect("write");
            sent.push((table.clone(), part, false));
            if i % 70 >= 63 {
                t.close(&table, part).expect("close");
                sent.push((table, part, true));
            }
        }
        t.finish().expect("finish");
        let log = log.lock().expect("lock");
        let mut sinks = std::collections::BTreeSet::new();
        for k in 0..7 {
            let table = format!("t{k}");
            let got: Vec<_> = log.iter().filter(|e| e.1 == table).collect();
            let want: Vec<_> = sent.iter().filter(|e| e.0 == table).collect();
            assert_eq!(got.len(), want.len(), "{table}");
            for (g, w) in got.iter().zip(&want) {
                assert_eq!((&g.1, g.2, g.3), (&w.0, w.1, w.2), "{table}: in order");
            }
            assert!(got.iter().all(|g| g.0 == got[0].0), "{table}: one thread");
            sinks.insert(got[0].0);
        }
        assert_eq!(sinks.len(), 3, "tables on every thread");
    }

    /// A failed write comes back: from a later write or from finish.
    #[test]
    fn a_failed_write_is_returned() {
        let seen = Arc::new(Mutex::new(BTreeMap::new()));
        let mut t = Threaded::new(2, 10, usize::MAX, || Keep(seen.clone())).expect("threads");
        t.write("bad", 0, &batch(1)).expect("handed over");
        let mut err = None;
        for p in 0..1000 {
            if let Err(e) = t.write("a", p, &batch(1)) {
                err = Some(e);
                break;
            }
        }
        let err = err.or_else(|| t.finish().err()).expect("an error");
        assert!(err.to_string().contains("bad table"), "{err}");
    }
}
