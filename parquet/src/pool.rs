//! Rows built on several threads: the decode chain runs on the caller's thread (it is one
//! sequential state: framing, pairing, numbering, units) and hands runs of records, owned
//! ([`Batch`]), to threads that each build a run's rows in a [`CaptureWriter`] of their own (cut
//! at the run's end and kept for the next, [`CaptureWriter::cut`]); the caller's thread builds
//! runs too rather than wait. The row groups come back in the order the runs were handed
//! over. Building the rows is most of
//! `to_arrow()`'s time (about four fifths, docs/performance.md), and each record's rows depend
//! only on the record, so this is the part that spreads over the cores.
//!
//! A run's tables are cut at its end: a table's rows come as one batch per run it has rows in
//! (and more where a run holds over a row group of them), in order, so the batches of a table
//! one after the other are the table one writer builds.

use crate::{CaptureWriter, Options, Sink};
use aptscope_dissector::owned::Batch;
use aptscope_dissector::record::Record;
use arrow_array::RecordBatch;
use std::collections::BTreeMap;
use std::io;
use std::ops::Range;
use std::panic::AssertUnwindSafe;
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

/// Records per batch or run when `APTSCOPE_BATCH_RECORDS` says (a positive number): the tests
/// cut small samples into many, in `aptscope decode -j`'s batches and in the runs of
/// `to_arrow()`'s threads alike.
pub fn records_from_env() -> Option<usize> {
    std::env::var("APTSCOPE_BATCH_RECORDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .filter(|n| *n > 0)
}

/// The row groups of one run, in the order its writer gave them: `(table, rows)`.
pub type Groups = Vec<(String, RecordBatch)>;

/// What a thread does to each row group before handing it back (the Python package turns the
/// columns of words into text there, on the thread, not on the caller's).
pub type Finish = fn(RecordBatch) -> io::Result<RecordBatch>;

/// Which tables are built, by name (as [`CaptureWriter::only_tables`]).
pub type Wanted = Arc<dyn Fn(&str) -> bool + Send + Sync>;

/// A run handed to the threads, or a part of one: its place in the order of runs and parts,
/// the run (its parts share it: the last run is handed over in parts, and copying them out of
/// it cost what building it on one thread did), and which of its records.
struct Part {
    seq: u64,
    run: Arc<Batch>,
    recs: Range<usize>,
}

/// A part's rows, or why they could not be built; the run, emptied, to be filled again, when
/// this was its last part built; and the records of the part.
type Done = (u64, io::Result<Groups>, Option<Batch>, usize);

impl Part {
    /// Its rows, built by `rows`; and its run, emptied, if no other part holds it now.
    fn build(self, rows: &mut Rows) -> Done {
        let built = rows.build(&self.run, self.recs.clone());
        (self.seq, built, emptied(self.run), self.recs.len())
    }
}

/// The run, emptied, if no other part holds it (of the parts of a run, exactly one gets it).
fn emptied(run: Arc<Batch>) -> Option<Batch> {
    Arc::into_inner(run).map(|mut b| {
        b.clear();
        b
    })
}

/// A [`Sink`] that keeps every row group.
struct Keep {
    groups: Groups,
    finish: Finish,
}

impl Sink for Keep {
    fn write(&mut self, table: &str, _part: u32, batch: &RecordBatch) -> io::Result<()> {
        self.groups
            .push((table.to_string(), (self.finish)(batch.clone())?));
        Ok(())
    }
}

/// The first run is a row group's records over this, and each next one twice the last up to a
/// row group's: a capture of one row group's records or less was decoded whole before its one
/// run was handed over, then built while the caller waited (1.45× the time of one thread on
/// 57,138 records); runs of a row group from the first would also leave the other threads idle
/// that long.
const FIRST_RUN: usize = 8;

/// Records of each part of the last run at least (see [`RowPool::flush`]): a smaller one is
/// not worth its batches.
const LAST_PART: usize = 4096;

/// Threads building the rows of runs of records, in order (see the module documentation).
pub struct RowPool {
    work: Option<Sender<Part>>,
    /// The runs handed over and not yet taken by a thread: the caller's thread takes them too
    /// when it would otherwise wait.
    queue: Arc<Mutex<Receiver<Part>>>,
    done: Receiver<Done>,
    threads: Vec<JoinHandle<()>>,
    /// Runs handed over (or built here), and runs handed back.
    sent: u64,
    taken: u64,
    /// Records of the runs handed to the threads and not yet back from them (built, or taken
    /// back from the queue and built here), whether or not earlier ones are: a run built and
    /// waiting for an earlier one no longer occupies a thread. Counted in records, not runs:
    /// the first runs are small (see [`FIRST_RUN`]), and while the threads held two of them
    /// the caller built the third, larger, itself, and a thread was left idle meanwhile.
    on_threads: usize,
    /// Runs built before an earlier one, by number.
    early: BTreeMap<u64, io::Result<Groups>>,
    /// Full runs' records on the threads at most (one more while the caller, its own run
    /// built and waiting for earlier ones, builds or waits for those).
    limit: usize,
    /// The last run built on the caller's thread, by number.
    here: Option<u64>,
    /// Runs handed back, emptied: their buffers are filled again rather than grown anew.
    spare: Vec<Batch>,
    /// The run being gathered, handed over when it holds `run_records` records or a row
    /// group's bytes of frames.
    run: Batch,
    run_records: usize,
    /// Records of a run once the first runs have grown to it (see [`FIRST_RUN`]).
    full_run: usize,
    /// Records of each part of the last run at least ([`LAST_PART`]).
    last_part: usize,
    /// Rows built on the caller's thread.
    here_rows: Rows,
    opts: Options,
}

/// How one thread builds runs' rows, and the writer it builds them in (made on the first run
/// and kept, [`CaptureWriter::cut`] after each).
struct Rows {
    writer: Option<CaptureWriter<Keep>>,
    file: Arc<str>,
    opts: Options,
    wanted: Option<Wanted>,
    finish: Finish,
}

impl RowPool {
    /// Rows built on `n` threads in all (at least two: the caller's, which decodes, and others
    /// it hands runs to) of capture `file` (its `file` column) cut as `opts` says, only of the
    /// tables `wanted` names (all without it), each row group passed through `finish`. Fails
    /// when a thread cannot be started.
    pub fn new(
        n: usize,
        file: &str,
        opts: Options,
        wanted: Option<Wanted>,
        finish: Finish,
    ) -> io::Result<Self> {
        let others = n.max(2) - 1;
        let (work, rx) = channel::<Part>();
        let rx = Arc::new(Mutex::new(rx));
        let (tx, done) = channel::<Done>();
        let rows = Rows {
            writer: None,
            file: Arc::from(file),
            opts,
            wanted,
            finish,
        };
        let mut threads = Vec::with_capacity(others);
        for _ in 0..others {
            let (rx, tx, mut rows) = (rx.clone(), tx.clone(), rows.another());
            let h = std::thread::Builder::new()
                .name("rows".into())
                .spawn(move || {
                    loop {
                        // The lock is held only to take a run; a closed queue ends the thread.
                        let Ok(part) = rx.lock().map_err(drop).and_then(|r| r.recv().map_err(drop))
                        else {
                            return;
                        };
                        if tx.send(part.build(&mut rows)).is_err() {
                            return;
                        }
                    }
                })?;
            threads.push(h);
        }
        Ok(RowPool {
            work: Some(work),
            queue: rx,
            done,
            threads,
            sent: 0,
            taken: 0,
            on_threads: 0,
            early: BTreeMap::new(),
            // One being built on each thread and one waiting: a thread that finishes need not
            // wait for the caller to decode the next run. (Memory grows with the threads: a
            // run of a status log is about 30 MiB of rows.)
            limit: others + 1,
            here: None,
            spare: Vec::new(),
            run: Batch::new(),
            // A `records` row group at most (that table's batches are then whole row groups),
            // after a few smaller runs.
            run_records: opts.rows_per_group.div_ceil(FIRST_RUN).max(1),
            full_run: opts.rows_per_group,
            last_part: LAST_PART,
            here_rows: rows,
            opts,
        })
    }

    /// Runs handed over (or built here) and not yet handed back.
    fn out(&self) -> usize {
        (self.sent - self.taken) as usize
    }

    /// Whether a run built on the caller's thread waits for an earlier one.
    fn here_waits(&self) -> bool {
        self.here.is_some_and(|h| h >= self.taken)
    }

    /// Records per run instead of a row group's (tests cut small inputs into many runs).
    pub fn set_run_records(&mut self, n: usize) {
        self.run_records = n.max(1);
        self.full_run = self.run_records;
    }

    /// Records of each part of the last run at least, instead of 4,096 (the fuzz
    /// target cuts the last runs of small inputs into parts too).
    pub fn set_last_part(&mut self, n: usize) {
        self.last_part = n.max(1);
    }

    /// Add one record to the run being gathered; a full run is handed over, and the row groups
    /// of the runs built by now are passed, in order, to `out`.
    pub fn push(&mut self, rec: &Record<'_>, out: &mut dyn FnMut(Groups)) -> io::Result<()> {
        self.run.push(rec);
        if self.run.len() >= self.run_records || self.run.byte_len() >= self.opts.bytes_per_group {
            self.run_records = (self.run_records * 2).min(self.full_run);
            self.hand_over(out)?;
        }
        Ok(())
    }

    /// The input has ended: hand the last run over. Its rows, and those of the runs still
    /// being built, come from [`RowPool::next`] or [`RowPool::ready`].
    pub fn flush(&mut self, out: &mut dyn FnMut(Groups)) -> io::Result<()> {
        let n = self.run.len();
        if n == 0 {
            return Ok(());
        }
        // The last run in a part for each thread: whole, it was built by one thread while
        // the others waited (the last tenth of `to_arrow()` of a status log on two cores).
        let parts = if n >= self.limit * self.last_part {
            self.limit
        } else {
            1
        };
        let each = n.div_ceil(parts);
        // No part empty (with parts of a few records, the last could be).
        let parts = n.div_ceil(each);
        let mut run = Some(Arc::new(std::mem::take(&mut self.run)));
        for p in 0..parts {
            // The last part takes the run itself (so that one of them hands it back).
            let part = if p + 1 == parts {
                run.take()
            } else {
                run.clone()
            };
            if let Some(r) = part {
                self.give(r, p * each..((p + 1) * each).min(n), out)?;
            }
        }
        Ok(())
    }

    /// Hand the run gathered over (it is then empty, with the room of one handed back, made
    /// for the next run's records), and pass the row groups of the runs built by now, in
    /// order, to `out`.
    fn hand_over(&mut self, out: &mut dyn FnMut(Groups)) -> io::Result<()> {
        let mut next = self.spare.pop().unwrap_or_default();
        // Grown as it fills, a run was copied each time its room doubled (the first runs, of
        // growing size, have no spare of their size).
        let (held, bytes) = (self.run.len().max(1), self.run.byte_len());
        let want = self.run_records;
        next.reserve(want, (bytes * want / held).min(self.opts.bytes_per_group));
        let run = Arc::new(std::mem::replace(&mut self.run, next));
        let n = run.len();
        self.give(run, 0..n, out)
    }

    /// Hand records `recs` of `run` over as the next part, and pass the row groups of the
    /// runs built by now, in order, to `out`. When the threads have as many records as they
    /// may, the caller's thread builds this part itself, rather than waiting idle. Once: while
    /// that part waits for earlier ones, it hands this one over all the same, then builds or
    /// waits for earlier ones until the threads hold no more than they may. (Had it waited
    /// with this part unsent, it would take the threads' next one from the queue to build,
    /// and a thread finishing meanwhile would find nothing: 25–40 ms idle at a time on two
    /// cores.)
    fn give(
        &mut self,
        run: Arc<Batch>,
        recs: Range<usize>,
        out: &mut dyn FnMut(Groups),
    ) -> io::Result<()> {
        self.ready(false, out)?;
        let n = recs.len();
        let seq = self.sent;
        let part = Part { seq, run, recs };
        if self.on_threads + n > self.limit * self.full_run && !self.here_waits() {
            let (_, rows, spare, _) = part.build(&mut self.here_rows);
            self.spare.extend(spare);
            self.early.insert(seq, rows);
            self.here = Some(seq);
            self.sent += 1;
            return Ok(());
        }
        let gone = || io::Error::other("the threads building rows stopped");
        self.work
            .as_ref()
            .ok_or_else(gone)?
            .send(part)
            .map_err(|_| gone())?;
        // Counted once handed over, as a part built here: a part the threads never got is
        // not waited for.
        self.sent += 1;
        self.on_threads += n;
        while self.on_threads > self.limit * self.full_run {
            out(self.next(true).ok_or_else(gone)??);
        }
        Ok(())
    }

    /// Pass the row groups of the runs built by now (`wait`: of every run handed over, waiting
    /// for them), in order, to `out`.
    pub fn ready(&mut self, wait: bool, out: &mut dyn FnMut(Groups)) -> io::Result<()> {
        while let Some(g) = self.next(wait) {
            out(g?);
        }
        Ok(())
    }

    /// The row groups of the next run in order: `None` when every run handed over was handed
    /// back, or (`wait` false) when the next one is not built yet.
    pub fn next(&mut self, wait: bool) -> Option<io::Result<Groups>> {
        while self.out() > 0 {
            if let Some(g) = self.early.remove(&self.taken) {
                self.taken += 1;
                return Some(g);
            }
            let got = match self.done.try_recv() {
                Ok(d) => Some(d),
                // Rather than wait idle for a thread, build a run still waiting for one (the
                // next in order, or one after it): at the end of the input, the last runs
                // were built by one thread while this one waited, and so was every run
                // after one built here.
                Err(_) if wait => self.steal().or_else(|| self.done.recv().ok()),
                Err(_) => None,
            };
            match got {
                Some((seq, g, spare, n)) => {
                    self.on_threads -= n;
                    self.early.insert(seq, g);
                    self.spare.extend(spare);
                }
                // Not built yet; or every thread is gone (a panic): say so once.
                None if wait => {
                    self.taken = self.sent;
                    return Some(Err(io::Error::other("the threads building rows stopped")));
                }
                None => return None,
            }
        }
        None
    }

    /// Build here a run handed over that no thread has taken yet, if there is one (and no
    /// thread is taking one now).
    fn steal(&mut self) -> Option<Done> {
        let part = self.queue.try_lock().ok()?.try_recv().ok()?;
        Some(part.build(&mut self.here_rows))
    }
}

impl Drop for RowPool {
    fn drop(&mut self) {
        // Closing the queue ends the threads once they finish what they hold.
        self.work = None;
        for h in self.threads.drain(..) {
            let _ = h.join();
        }
    }
}

impl Rows {
    /// The same building, for another thread (with a writer of its own).
    fn another(&self) -> Rows {
        Rows {
            writer: None,
            file: self.file.clone(),
            opts: self.opts,
            wanted: self.wanted.clone(),
            finish: self.finish,
        }
    }

    /// The rows of records `recs` of a run, cut at their end: the tables one writer of those
    /// records alone would make, in the buffers the last part's grew to. A panic is this
    /// part's error, not a part that never comes back (the caller would wait for it for ever
    /// while the other threads live), nor a panic of the caller's thread.
    fn build(&mut self, batch: &Batch, recs: Range<usize>) -> io::Result<Groups> {
        std::panic::catch_unwind(AssertUnwindSafe(|| self.build_in(batch, recs))).unwrap_or_else(
            |_| {
                // The writer may be half way through a row: a new one for the next.
                self.writer = None;
                Err(io::Error::other("building rows panicked"))
            },
        )
    }

    /// [`Rows::build`], unguarded.
    fn build_in(&mut self, batch: &Batch, recs: Range<usize>) -> io::Result<Groups> {
        let Rows {
            writer,
            file,
            opts,
            wanted,
            finish,
        } = self;
        let w = writer.get_or_insert_with(|| {
            let keep = Keep {
                groups: Vec::new(),
                finish: *finish,
            };
            let mut w = CaptureWriter::new(keep, file, *opts);
            if let Some(f) = wanted {
                let f = f.clone();
                w.only_tables(move |t| f(t));
            }
            w
        });
        // A row of the `records` table for each record.
        w.reserve_records(recs.len());
        let built = w.run(batch, recs).and_then(|()| w.cut());
        let groups = std::mem::take(&mut w.sink_mut().groups);
        if built.is_err() {
            // Rows of the run may be left in it: a new writer for the next.
            *writer = None;
        }
        built.map(|()| groups)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use aptscope_dissector::record::{Ctx, Decoder};
    use std::collections::HashMap;

    /// Every table's rows, in order, as one batch each.
    fn tables(groups: Groups) -> Vec<(String, RecordBatch)> {
        let mut by: BTreeMap<String, Vec<RecordBatch>> = BTreeMap::new();
        for (t, b) in groups {
            by.entry(t).or_default().push(b);
        }
        by.into_iter()
            .map(|(t, bs)| {
                let b = arrow_select::concat::concat_batches(&bs[0].schema(), &bs).unwrap();
                (t, b)
            })
            .collect()
    }

    fn ok(b: RecordBatch) -> io::Result<RecordBatch> {
        crate::words::declared(&b).map_err(io::Error::other)
    }

    /// Every table of `bytes` from one writer on this thread.
    fn one_writer(bytes: &[u8], opts: Options, finish: Finish) -> Vec<(String, RecordBatch)> {
        let keep = Keep {
            groups: Vec::new(),
            finish,
        };
        let mut w = CaptureWriter::new(keep, "x", opts);
        let mut dec = Decoder::new(None);
        dec.push(Ctx::default(), bytes, &mut |r| w.record(r))
            .unwrap();
        dec.finish(&mut |r| w.record(r)).unwrap();
        tables(w.finish().unwrap().0.groups)
    }

    /// A random stream of every form and its damage (a garbage run, truncated frames).
    fn every_form() -> Vec<u8> {
        aptscope_dissector::synth::stream(aptscope_dissector::Table::global(), 7, 40_000, true)
    }

    /// Words built straight into text columns give the tables of words turned into text
    /// afterwards: the same schemas (with their metadata), rows, nulls and lists.
    #[test]
    fn words_built_as_text_equal_words_turned_into_text() {
        let bytes = every_form();
        let keys = one_writer(&bytes, Options::default(), ok);
        let text = Options {
            words_as_text: true,
            ..Options::default()
        };
        let text = one_writer(&bytes, text, Ok);
        assert!(keys.len() > 20, "{} tables", keys.len());
        assert_eq!(keys.len(), text.len());
        for ((tk, bk), (tt, bt)) in keys.iter().zip(&text) {
            assert_eq!(tk, tt);
            assert_eq!(bk, bt, "{tk}");
        }
    }

    #[test]
    fn runs_on_threads_give_the_tables_of_one_writer() {
        let bytes = every_form();
        let one = one_writer(&bytes, Options::default(), ok);
        assert!(one.len() > 20, "{} tables", one.len());
        // Runs of 97 records on three threads (two and the caller's), taken back as they come;
        // then runs growing from 100 records to row groups of 800 (the first runs' ramp); then
        // runs of up to a row group of 65,536, the last of them in three parts.
        let ramp = Options {
            rows_per_group: 800,
            ..Options::default()
        };
        for (opts, run) in [
            (Options::default(), Some(97)),
            (ramp, None),
            (Options::default(), None),
        ] {
            let mut pool = RowPool::new(3, "x", opts, None, ok).unwrap();
            if let Some(n) = run {
                pool.set_run_records(n);
            }
            let mut got = Vec::new();
            let mut dec = Decoder::new(None);
            let mut each = |r: &Record<'_>| pool.push(r, &mut |g| got.extend(g));
            dec.push(Ctx::default(), &bytes, &mut each).unwrap();
            dec.finish(&mut each).unwrap();
            pool.flush(&mut |g| got.extend(g)).unwrap();
            pool.ready(true, &mut |g| got.extend(g)).unwrap();
            // The records table's batches: one per run, each twice the last up to a row
            // group, the last in parts.
            let sizes: Vec<usize> = got
                .iter()
                .filter(|(t, _)| t == "records")
                .map(|(_, b)| b.num_rows())
                .collect();
            if run.is_none() && opts.rows_per_group == 800 {
                assert_eq!(sizes[..4], [100, 200, 400, 800], "{sizes:?}");
            } else if run.is_none() {
                let [a, b, last @ ..] = &sizes[..] else {
                    panic!("{sizes:?}");
                };
                assert_eq!([*a, *b], [8192, 16_384], "{sizes:?}");
                let n: usize = last.iter().sum();
                assert!(n >= 3 * LAST_PART && last.len() == 3, "{sizes:?}");
                assert!(last.iter().all(|p| *p <= n.div_ceil(3)), "{sizes:?}");
            }
            let many = tables(got);
            let names =
                |t: &[(String, RecordBatch)]| t.iter().map(|x| x.0.clone()).collect::<Vec<_>>();
            assert_eq!(names(&one), names(&many));
            let many: HashMap<_, _> = many.into_iter().collect();
            for (t, b) in &one {
                assert_eq!(b, &many[t], "{t}");
            }
        }
    }

    /// Budgets small enough that, within a run of a stream of every form, row groups are cut
    /// by rows, the kind tables are written early (the biggest, when together over their
    /// budget) and closed (the least recently used, when too many are open).
    fn tight(batches_kept: bool) -> Options {
        Options {
            rows_per_group: 300,
            kind_rows: 500,
            max_open_kinds: 16,
            words_as_text: true,
            batches_kept,
            ..Options::default()
        }
    }

    /// The records of `bytes` in runs of `n`.
    fn runs(bytes: &[u8], n: usize) -> Vec<Batch> {
        let mut runs = vec![Batch::new()];
        let mut dec = Decoder::new(None);
        let mut each = |r: &Record<'_>| -> io::Result<()> {
            if runs.last().is_some_and(|b| b.len() >= n) {
                runs.push(Batch::new());
            }
            runs.last_mut().expect("a run").push(r);
            Ok(())
        };
        dec.push(Ctx::default(), bytes, &mut each).unwrap();
        dec.finish(&mut each).unwrap();
        runs
    }

    /// Kind rows built table by table over stretches of a run ([`CaptureWriter::run`]) are,
    /// table by table, the rows of a writer given each record in turn: with budgets that
    /// write kind tables early and close them within a stretch, and runs shorter and longer
    /// than a stretch.
    #[test]
    fn kind_rows_built_table_by_table_are_the_rows_of_each_record() {
        let bytes = every_form();
        for opts in [tight(false), tight(true), Options::default()] {
            let one = one_writer(&bytes, opts, Ok);
            assert!(one.len() > 20, "{} tables", one.len());
            for n in [997, 3 * crate::KIND_STRETCH + 5, usize::MAX] {
                let keep = Keep {
                    groups: Vec::new(),
                    finish: Ok,
                };
                let mut w = CaptureWriter::new(keep, "x", opts);
                for run in runs(&bytes, n) {
                    w.run(&run, 0..run.len()).unwrap();
                }
                let built = tables(w.finish().unwrap().0.groups);
                assert_eq!(one, built, "runs of {n}");
            }
        }
    }

    /// One writer cut after each run gives, row group by row group, what a writer made for
    /// each run gives; and keeping the batches (buffers taken back when a table opens again)
    /// changes no row group.
    #[test]
    fn a_writer_cut_after_each_run_gives_the_row_groups_of_a_new_one() {
        let runs = runs(&every_form(), 997);
        assert!(runs.len() > 5, "{} runs", runs.len());
        let mut each_new = Vec::new();
        for opts in [tight(false), tight(true), Options::default()] {
            let rows = || Rows {
                writer: None,
                file: Arc::from("x"),
                opts,
                wanted: None,
                finish: Ok,
            };
            let all = |r: &Batch| 0..r.len();
            let fresh: Vec<Groups> = runs
                .iter()
                .map(|r| rows().build(r, all(r)).unwrap())
                .collect();
            let mut one = rows();
            let cut: Vec<Groups> = runs.iter().map(|r| one.build(r, all(r)).unwrap()).collect();
            assert_eq!(fresh.len(), cut.len());
            for (i, (f, c)) in fresh.iter().zip(&cut).enumerate() {
                let names = |g: &Groups| g.iter().map(|x| x.0.clone()).collect::<Vec<_>>();
                assert_eq!(names(f), names(c), "run {i}");
                assert_eq!(f, c, "run {i}");
            }
            each_new.push(fresh);
        }
        assert_eq!(each_new[0], each_new[1], "batches kept");
        // The tight budgets did cut: more row groups than with the defaults.
        let count = |g: &[Groups]| g.iter().map(Vec::len).sum::<usize>();
        assert!(count(&each_new[0]) > count(&each_new[2]) + 100);
    }

    #[test]
    fn a_panic_on_a_thread_is_an_error_not_a_wait() {
        let bytes =
            aptscope_dissector::synth::stream(aptscope_dissector::Table::global(), 3, 50, false);
        let boom: Finish = |_| panic!("a row group that cannot be finished");
        let mut pool = RowPool::new(2, "x", Options::default(), None, boom).unwrap();
        let mut dec = Decoder::new(None);
        let mut n = 0;
        let mut each = |r: &Record<'_>| {
            n += 1;
            pool.push(r, &mut |_| {})
        };
        dec.push(Ctx::default(), &bytes, &mut each).unwrap();
        dec.finish(&mut each).unwrap();
        assert!(n >= 50);
        pool.flush(&mut |_| {}).unwrap();
        let err = pool.ready(true, &mut |_| {}).unwrap_err();
        assert!(err.to_string().contains("panicked"), "{err}");
        assert!(pool.next(true).is_none());
    }
}
