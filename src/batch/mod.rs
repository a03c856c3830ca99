//! `decode` over many files: files decoded in parallel, text and NDJSON written per file in
//! input order, or a Parquet dataset; a progress bar on a terminal.
//!
//! Text and NDJSON: each worker decodes and renders whole files into a bounded channel of its
//! own (256 KiB blocks); the main thread copies file 0's channel to standard output, then file
//! 1's, and so on. A worker ahead of the writer does not wait for it: when its channel is full
//! it keeps its blocks in memory (up to [`QUEUED_MAX`], 64 MiB, for all files together) and
//! beyond that appends them to a spill file of its own (unlinked temporary file), announcing
//! what it kept through the channel when there is room, so the order stays that of `-j 1` while
//! every core renders, and memory stays bounded whatever the files' sizes (disk holds what is
//! ahead, at most [`SPILL_MAX`] per file, beyond which the worker waits). Parquet: each
//! worker writes its file's row groups as part files of their own (named by the file's
//! index), so nothing is ordered or merged.
//!
//! Cores the files leave spare (one file with `-j 2`, two with `-j 4`) render inside each file:
//! its decode chain runs on its worker, which hands the records to render threads and writes
//! what they rendered in order ([`split`], which says why this rather than cutting the capture
//! into parts); Parquet builds the rows on the worker and encodes the row groups on the spare
//! cores ([`Threaded`]). Either way the output is byte for byte that of `-j 1`.

use crate::common::{compile_filter, fatal, proto_of, ProtoArg};
use aptscope_capture::judge::{not_a_capture, not_a_capture_error, refuse};
use aptscope_capture::live::signals::{Signals, STOP};
use aptscope_capture::open::{open_with_progress, OpenOptions, Progress};
use aptscope_capture::{Chunk, Direction};
use aptscope_capture::{Event, Reader};
use aptscope_dissector::detect::{detect, Proto, SAMPLE};
use aptscope_dissector::json;
use aptscope_dissector::pipeline::{Format as PFormat, Pipeline};
use aptscope_dissector::record::Decoder;
use aptscope_dissector::units::UnitsOpts;
use aptscope_parquet::{decode_file, CaptureWriter, DirSink, Threaded};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use split::{Engine, Look, Split};
use std::cell::{Cell, RefCell};
use std::fs::File;
use std::io::{self, IsTerminal, Read, Seek, SeekFrom, Write};
use std::os::unix::fs::FileExt;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{channel, sync_channel, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};

mod split;

/// What `decode` writes.
pub enum Output {
    /// Text lines, or NDJSON.
    Lines {
        /// NDJSON rather than text.
        json: bool,
    },
    /// A Parquet dataset in this directory (already prepared).
    Parquet(PathBuf),
}

/// One `decode` run.
pub struct Job<'a> {
    pub files: &'a [String],
    pub open: OpenOptions,
    pub proto: ProtoArg,
    pub filter: Option<&'a str>,
    pub timeout: Option<u64>,
    pub units: UnitsOpts,
    pub out: Output,
    /// Threads: files decoded at once, and the spare ones render inside files.
    pub jobs: usize,
}

/// Progress shown on a terminal: bytes and files done, rate, ETA.
struct Bar {
    bar: Option<ProgressBar>,
    files: usize,
    done: AtomicUsize,
}

impl Bar {
    fn new(job: &Job<'_>) -> Bar {
        let stdout_free = matches!(job.out, Output::Parquet(_)) || !io::stdout().is_terminal();
        let on = io::stderr().is_terminal() && stdout_free && job.files.iter().all(|f| f != "-");
        let bar = on.then(|| {
            let total: u64 = job
                .files
                .iter()
                .filter_map(|f| std::fs::metadata(f).ok())
                .map(|m| m.len())
                .sum();
            let b = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
            if let Ok(s) = ProgressStyle::with_template(
                "{bar:30} {bytes}/{total_bytes} {binary_bytes_per_sec} ETA {eta} {msg}",
            ) {
                b.set_style(s);
            }
            b.set_message(format!("0/{} files", job.files.len()));
            b
        });
        Bar {
            bar,
            files: job.files.len(),
            done: AtomicUsize::new(0),
        }
    }

    /// Count what a file's reader has read since `seen`.
    fn tick(&self, p: &Progress, seen: &mut u64) {
        if let Some(b) = &self.bar {
            let now = p.read.load(Ordering::Relaxed);
            b.inc(now.saturating_sub(*seen));
            *seen = now;
        }
    }

    fn file_done(&self) {
        let d = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        if let Some(b) = &self.bar {
            b.set_message(format!("{d}/{} files", self.files));
        }
    }

    fn finish(&self) {
        if let Some(b) = &self.bar {
            b.finish_and_clear();
        }
    }

    /// Print above the bar.
    fn note(&self, msg: &str) {
        match &self.bar {
            Some(b) => b.suspend(|| eprintln!("{msg}")),
            None => eprintln!("{msg}"),
        }
    }
}

/// Output of one file's worker: blocks of bytes (with whether to flush them out now: a live
/// input's records as they come), rendered buffers handed over whole, ranges of its spill
/// file, then its result.
///
/// The bytes `-j 1` writes before an error ends a file are its whole blocks ([`BLOCK`]: what
/// [`ChanWriter`] had not sent yet is dropped), so what reaches the output in `-j N` must end
/// at the same points. A [`Msg::Part`] says where its buffer closes a block; the writer holds
/// back what follows until a later message closes that block, and drops it if the file ends
/// in error instead.
enum Msg {
    /// Everything held back, then these bytes: written out.
    Data(Vec<u8>, bool),
    /// A buffer of whole rendered lines, and how many of its bytes close the blocks begun
    /// before it (0: none). Those are written out after everything held back; the rest is
    /// held back.
    Part(Vec<u8>, usize),
    /// Blocks a worker ahead of the writer kept in memory, in order with the others.
    Blocks(Vec<Vec<u8>>),
    /// Bytes `start..end` of the worker's spill file, in order with the blocks.
    Spilled(Arc<File>, u64, u64),
    Done(io::Result<Stats>),
}

/// What one file gave (Parquet: for the summary line).
#[derive(Default)]
struct Stats {
    records: u64,
    row_groups: u64,
}

/// Blocks a file's channel holds (4 MiB): enough to ride out the writer's pauses; a file
/// further ahead keeps its blocks in memory (up to [`QUEUED_MAX`] for all files) or spills.
/// (Rendered buffers are bigger, a batch each: 16 of them are at most a few MiB.)
const CHANNEL_BLOCKS: usize = 16;

/// Blocks files ahead of the writer keep in memory, all together (64 MiB), beyond their
/// channels, before they spill to disk. Rendering ahead in memory rather than on disk: 50 files
/// of 4.2 MB to NDJSON at `-j 2` (quiet machine, 3 alternating runs) took 6.64 s against `-j
/// 1`'s 12.34 s, 0.63 system CPU-s, peak 84 MiB; spilling beyond the channel, 7.40 s, 1.9
/// system CPU-s, 19 MiB (the file ahead is rendered whole while the one before it is written:
/// writing it to the spill file and reading it back was the system time).
const QUEUED_MAX: usize = 256;

/// [`QUEUED_MAX`], or `APTSCOPE_QUEUED_MAX` (tests set 0: every file ahead spills).
fn queued_max() -> usize {
    static MAX: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
    *MAX.get_or_init(|| {
        std::env::var("APTSCOPE_QUEUED_MAX")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(QUEUED_MAX)
    })
}

/// Spare buffers a [`Pool`] keeps at most (it keeps only what was in use at once).
const POOL_MAX: usize = 320;

/// Buffers written out, for the next rendered batches: in the steady state no batch
/// allocates (fresh memory costs page faults on every batch).
#[derive(Default)]
struct Pool(Mutex<Vec<Vec<u8>>>, AtomicUsize);

impl Pool {
    /// An empty buffer, with the capacity of one used before when there is one.
    fn get(&self) -> Vec<u8> {
        self.0
            .lock()
            .ok()
            .and_then(|mut v| v.pop())
            .unwrap_or_default()
    }

    /// Blocks kept in memory ahead of the writer, by all files ([`QUEUED_MAX`]).
    fn queued(&self) -> &AtomicUsize {
        &self.1
    }

    /// Keep `b` for later (emptied).
    fn put(&self, mut b: Vec<u8>) {
        if b.capacity() == 0 {
            return;
        }
        b.clear();
        if let Ok(mut v) = self.0.lock() {
            if v.len() < POOL_MAX {
                v.push(b);
            }
        }
    }
}

/// What the writer holds back of a file's output: the tails of rendered buffers after the
/// last block they closed (see [`Msg`]), each with where its tail starts.
#[derive(Default)]
struct HeldBack(Vec<(Vec<u8>, usize)>);

impl HeldBack {
    /// Write out everything held back (the block it began is closed).
    fn write_out(&mut self, out: &mut impl Write, pool: &Pool) -> io::Result<()> {
        for (b, at) in self.0.drain(..) {
            out.write_all(&b[at..])?;
            pool.put(b);
        }
        Ok(())
    }

    /// A [`Msg::Part`]: everything held back and the bytes that close its block written out,
    /// the rest held back.
    fn part(
        &mut self,
        out: &mut impl Write,
        b: Vec<u8>,
        commit: usize,
        pool: &Pool,
    ) -> io::Result<()> {
        if commit > 0 {
            self.write_out(out, pool)?;
            out.write_all(&b[..commit])?;
        }
        if commit < b.len() {
            self.0.push((b, commit));
        } else {
            pool.put(b);
        }
        Ok(())
    }

    /// Drop everything held back (the file ended in error: `-j 1` dropped its last block).
    fn drop_all(&mut self, pool: &Pool) {
        for (b, _) in self.0.drain(..) {
            pool.put(b);
        }
    }
}

/// Bytes per block sent to the writer (and per write to the output). Each block wakes the
/// writing thread, a third thread on two cores at `-j 2`: with 64 KiB blocks, 50 files of
/// 4.2 MB to NDJSON made 20,000 futex calls for 1.5 GB and `-j 2` took 7.97 s; with 256 KiB,
/// 7.32–7.63 s (system time 2.9 → 1.9 s; quiet machine, `-j 1` 12.9 s).
const BLOCK: usize = 1 << 18;

/// Bytes one file spills at most before its worker waits for the writer instead.
const SPILL_MAX: u64 = 1 << 30;

/// A file's spill: an unlinked temporary file, and what of it is not yet announced.
struct Spill {
    file: Arc<File>,
    len: u64,
    announced: u64,
}

impl Spill {
    /// A new spill file, or `None` where none can be made (the worker then waits instead).
    fn create(i: usize) -> Option<Spill> {
        static SEQ: AtomicUsize = AtomicUsize::new(0);
        let seq = SEQ.fetch_add(1, Ordering::Relaxed);
        let path =
            std::env::temp_dir().join(format!("aptscope-{}-{i}-{seq}.spill", std::process::id()));
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&path)
            .ok()?;
        // Unlinked at once: it goes when the last handle closes, however the run ends.
        std::fs::remove_file(&path).ok()?;
        Some(Spill {
            file: Arc::new(file),
            len: 0,
            announced: 0,
        })
    }
}

/// A writer into a file's channel, in blocks of [`BLOCK`]. Held back until released: what a
/// file that turns out not to be a capture wrote is dropped.
struct ChanWriter<'a> {
    tx: &'a SyncSender<Msg>,
    buf: Vec<u8>,
    /// Bytes of the block being filled that went to the writer in [`Msg::Part`]s (before
    /// those in `buf`): held back there until the block is closed.
    open: usize,
    pool: &'a Pool,
    held: &'a Cell<bool>,
    /// The file's index in the run (names its spill file).
    index: usize,
    /// The index of the file the writer is copying out: that file's worker waits for it
    /// rather than spill.
    head: &'a AtomicUsize,
    spill: Option<Spill>,
    /// Blocks kept in memory ahead of the writer, not yet announced (before the spill file's
    /// unannounced bytes: a block goes here only when there are none).
    mem: Vec<Vec<u8>>,
    /// No spill file could be made, or written: wait for the writer.
    no_spill: bool,
}

impl ChanWriter<'_> {
    fn new<'a>(
        tx: &'a SyncSender<Msg>,
        held: &'a Cell<bool>,
        index: usize,
        head: &'a AtomicUsize,
        pool: &'a Pool,
    ) -> ChanWriter<'a> {
        ChanWriter {
            tx,
            buf: Vec::with_capacity(BLOCK),
            open: 0,
            pool,
            held,
            index,
            head,
            spill: None,
            mem: Vec::new(),
            no_spill: false,
        }
    }

    fn gone() -> io::Error {
        io::Error::from(io::ErrorKind::BrokenPipe)
    }

    /// Announce the blocks kept and the spilled bytes not yet announced; `wait`: even if the
    /// channel is full. Whether none is left unannounced.
    fn announce(&mut self, wait: bool) -> io::Result<bool> {
        if !self.mem.is_empty() {
            let m = Msg::Blocks(std::mem::take(&mut self.mem));
            if wait {
                self.tx.send(m).map_err(|_| Self::gone())?;
            } else {
                match self.tx.try_send(m) {
                    Ok(()) => {}
                    Err(TrySendError::Full(Msg::Blocks(v))) => {
                        self.mem = v;
                        return Ok(false);
                    }
                    Err(_) => return Err(Self::gone()),
                }
            }
        }
        let Some(sp) = self.spill.as_mut() else {
            return Ok(true);
        };
        if sp.announced == sp.len {
            return Ok(true);
        }
        let m = Msg::Spilled(sp.file.clone(), sp.announced, sp.len);
        if wait {
            self.tx.send(m).map_err(|_| Self::gone())?;
        } else {
            match self.tx.try_send(m) {
                Ok(()) => {}
                Err(TrySendError::Full(_)) => return Ok(false),
                Err(TrySendError::Disconnected(_)) => return Err(Self::gone()),
            }
        }
        sp.announced = sp.len;
        Ok(true)
    }

    /// Keep `b` ahead of the writer: in memory while all files together keep fewer than
    /// [`QUEUED_MAX`] blocks and none of this file's bytes wait in the spill file, else appended
    /// to the spill file (made now if need be). Gives `b` back when neither can take it.
    fn spill(&mut self, b: Vec<u8>) -> Option<Vec<u8>> {
        let on_disk = self.spill.as_ref().is_some_and(|sp| sp.announced < sp.len);
        if !on_disk && self.pool.queued().load(Ordering::Relaxed) < queued_max() {
            self.pool.queued().fetch_add(1, Ordering::Relaxed);
            self.mem.push(b);
            return None;
        }
        if self.spill_to_disk(&b) {
            self.pool.put(b);
            return None;
        }
        Some(b)
    }

    /// Append `b` to the spill file (made now if need be); false: it cannot take it.
    fn spill_to_disk(&mut self, b: &[u8]) -> bool {
        if self.spill.is_none() && !self.no_spill {
            self.spill = Spill::create(self.index);
            self.no_spill = self.spill.is_none();
        }
        match self.spill.as_mut() {
            Some(sp) if !self.no_spill && sp.len + b.len() as u64 <= SPILL_MAX => {
                // A full disk is no reason to fail: from then on the worker waits instead
                // (what was spilled before is still announced and copied out).
                if sp.file.write_all_at(b, sp.len).is_err() {
                    self.no_spill = true;
                    return false;
                }
                sp.len += b.len() as u64;
                true
            }
            _ => false,
        }
    }

    /// Send the block; `now`: and have it written out at once (waiting for the writer).
    fn send(&mut self, now: bool) -> io::Result<()> {
        if self.held.get() || (self.buf.is_empty() && self.open == 0) {
            return Ok(());
        }
        let mut next = self.pool.get();
        next.reserve(BLOCK);
        let b = std::mem::replace(&mut self.buf, next);
        // The file being written out: the writer is reading this channel, so waiting costs
        // nothing and spilling would only copy the bytes twice. (Bytes held back by the
        // writer mean it was, and still is: the head never goes back.)
        if now || self.open > 0 || self.head.load(Ordering::Relaxed) == self.index {
            self.announce(true)?;
            self.open = 0;
            return self.tx.send(Msg::Data(b, now)).map_err(|_| Self::gone());
        }
        // Blocks after those kept or spilled follow them until those are announced.
        let b = if self.announce(now)? {
            b
        } else {
            match self.spill(b) {
                None => return Ok(()),
                Some(b) => {
                    self.announce(true)?;
                    b
                }
            }
        };
        match self.tx.try_send(Msg::Data(b, false)) {
            Ok(()) => Ok(()),
            Err(TrySendError::Disconnected(_)) => Err(Self::gone()),
            Err(TrySendError::Full(m)) => {
                let Msg::Data(b, _) = m else {
                    return Ok(());
                };
                match self.spill(b) {
                    None => Ok(()),
                    Some(b) => self.tx.send(Msg::Data(b, false)).map_err(|_| Self::gone()),
                }
            }
        }
    }
}

impl ChanWriter<'_> {
    /// Write rendered lines (each ending in a newline) as `-j 1` writes them, one line's text
    /// and then its newline: blocks are sent where they would have been (so what reaches the
    /// output before an error ends a file is the same too).
    fn write_lines(&mut self, mut b: &[u8]) -> io::Result<()> {
        while !b.is_empty() {
            let need = BLOCK.saturating_sub(self.open + self.buf.len()).max(1);
            if b.len() < need {
                self.buf.extend_from_slice(b);
                return Ok(());
            }
            let cut = block_end(b, need);
            self.buf.extend_from_slice(&b[..cut]);
            b = &b[cut..];
            if self.open + self.buf.len() >= BLOCK {
                self.send(false)?;
            }
        }
        Ok(())
    }

    /// [`write_lines`](Self::write_lines) of a whole buffer, handed to the writer as it is
    /// (no copy): with where its last block ends, as `-j 1` would have cut it. Held output,
    /// or a file the writer is not copying out yet (its blocks may go to the spill file), is
    /// cut here as before.
    fn write_rendered(&mut self, b: Vec<u8>) -> io::Result<()> {
        if self.held.get() || self.head.load(Ordering::Relaxed) != self.index {
            self.write_lines(&b)?;
            self.pool.put(b);
            return Ok(());
        }
        if b.is_empty() {
            self.pool.put(b);
            return Ok(());
        }
        // The blocks `write_lines` would have sent: each ends at the first line end at or
        // past the bytes its block lacks; all but the last lie wholly inside `b`.
        let mut open = self.open + self.buf.len();
        let (mut at, mut commit) = (0, 0);
        loop {
            let need = BLOCK.saturating_sub(open).max(1);
            let rest = &b[at..];
            if rest.len() < need {
                open += rest.len();
                break;
            }
            at += block_end(rest, need);
            commit = at;
            open = 0;
        }
        // What spilled before goes first, then what this writer holds.
        self.announce(true)?;
        if !self.buf.is_empty() {
            let head = std::mem::take(&mut self.buf);
            self.tx.send(Msg::Part(head, 0)).map_err(|_| Self::gone())?;
        }
        self.open = open;
        self.tx.send(Msg::Part(b, commit)).map_err(|_| Self::gone())
    }
}

/// Where `-j 1` ends a block in `b` (lines, each ending in a newline) when it lacks `need`
/// bytes (`need` ≤ `b.len()`): it checks the block's size after each line's text and after its
/// newline, so the first such point at or past `need` bytes.
fn block_end(b: &[u8], need: usize) -> usize {
    b[need - 1..]
        .iter()
        .position(|&c| c == b'\n')
        .map_or(b.len(), |q| (need - 1 + q).max(need))
}

impl Drop for ChanWriter<'_> {
    /// What was spilled is announced however the worker ends: it was written as a sent block
    /// would have been.
    fn drop(&mut self) {
        if !self.held.get() {
            let _ = self.announce(true);
        }
    }
}

impl Write for ChanWriter<'_> {
    fn write(&mut self, b: &[u8]) -> io::Result<usize> {
        self.buf.extend_from_slice(b);
        if self.open + self.buf.len() >= BLOCK {
            self.send(false)?;
        }
        Ok(b.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        self.send(true)?;
        self.announce(true).map(|_| ())
    }
}

/// Copy bytes `start..end` of a spill file to `out`. The writer alone moves the file's cursor
/// (the worker writes at positions); `io::copy` from a file to standard output is a kernel
/// copy (`copy_file_range`, `sendfile`) where the kernel can.
fn copy_spill(mut f: &File, start: u64, end: u64, out: &mut impl Write) -> io::Result<()> {
    f.seek(SeekFrom::Start(start))?;
    let n = io::copy(&mut f.take(end - start), out)?;
    if n < end - start {
        return Err(io::Error::other("the spill file is shorter than written"));
    }
    Ok(())
}

/// Run the job. Several inputs: a file that cannot be read, or is not a capture, is reported
/// by name and skipped, and the run fails at its end; one input: its error is the run's.
pub fn run(job: Job<'_>) -> io::Result<()> {
    if matches!(job.out, Output::Parquet(_)) && job.filter.is_some() {
        return Err(crate::common::bad(
            "--filter applies to text and NDJSON output; filter the Parquet dataset with a \
             query (DuckDB, pandas) instead"
                .into(),
        )
        .into());
    }
    // A bad filter is one error, not one per file.
    job.filter.map(compile_filter).transpose()?;
    let n = job.files.len();
    let bar = Bar::new(&job);
    // Only over files: a pipe's read waits for its writer, so a stop would wait with it.
    let halt = Halt::new(
        matches!(job.out, Output::Parquet(_))
            && job
                .files
                .iter()
                .all(|f| f != "-" && std::fs::metadata(f).is_ok_and(|m| m.is_file())),
    );
    let stop = AtomicBool::new(false);
    let next = AtomicUsize::new(0);
    let head = AtomicUsize::new(0);
    let mut txs = Vec::with_capacity(n);
    let mut rxs: Vec<Receiver<Msg>> = Vec::with_capacity(n);
    let jobs = job.jobs.clamp(1, n.max(1));
    // Cores the files leave spare render inside them (see `split`): one file with `-j 2` is
    // decoded on one thread and rendered on two.
    let helpers = if job.jobs > jobs { job.jobs / jobs } else { 0 };
    for _ in 0..n {
        let (tx, rx) = sync_channel(CHANNEL_BLOCKS);
        txs.push(Mutex::new(Some(tx)));
        rxs.push(rx);
    }
    let job = &job;
    let pool = Pool::default();
    let (bar, stop, next, txs, head, pool) = (&bar, &stop, &next, &txs, &head, &pool);
    let halt = &halt;
    let result = std::thread::scope(|sc| {
        for _ in 0..jobs {
            sc.spawn(move || loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= n || stop.load(Ordering::Relaxed) {
                    break;
                }
                if halt.check() {
                    // The files not started are not: their channels closed, so that the
                    // writer goes past them.
                    for t in txs.iter().skip(i) {
                        if let Ok(mut t) = t.lock() {
                            t.take();
                        }
                    }
                    break;
                }
                let Some(tx) = txs[i].lock().ok().and_then(|mut t| t.take()) else {
                    break;
                };
                let r = one(job, i, &tx, bar, head, pool, helpers, halt);
                bar.file_done();
                // The receiver is gone only when the writer stopped: nothing left to do.
                if tx.send(Msg::Done(r)).is_err() {
                    stop.store(true, Ordering::Relaxed);
                }
            });
        }
        collect(job, rxs, bar, stop, head, pool, halt)
    });
    bar.finish();
    result
}

/// A stop signal (SIGINT, SIGTERM, SIGHUP) during a Parquet run: the files being decoded stop
/// reading and complete their part files as at their end (a part file gets its footer only
/// when complete: killed, a run would leave its open files' row groups unreadable), the files
/// not started are not, and the run fails saying so. Text and NDJSON are written as they
/// come: a signal ends them as before; so it does a run reading a pipe or a device.
struct Halt {
    signals: Option<Signals>,
    flag: Arc<AtomicBool>,
    /// The signal, by name.
    by: Mutex<Option<String>>,
}

impl Halt {
    /// Watching the stop signals when `on` (blocked in this thread and those it starts, and
    /// read from a descriptor), else never set.
    fn new(on: bool) -> Halt {
        Halt {
            signals: on.then(|| Signals::install(STOP).ok()).flatten(),
            flag: Arc::new(AtomicBool::new(false)),
            by: Mutex::new(None),
        }
    }

    /// Whether the run is to stop (a signal received is taken here).
    fn check(&self) -> bool {
        if let Some(sig) = self.signals.as_ref().and_then(Signals::take) {
            if let Ok(mut by) = self.by.lock() {
                by.get_or_insert(sig);
            }
            self.flag.store(true, Ordering::Relaxed);
        }
        self.flag.load(Ordering::Relaxed)
    }
}

/// The writer side: every file's output in input order; errors reported by name.
fn collect(
    job: &Job<'_>,
    rxs: Vec<Receiver<Msg>>,
    bar: &Bar,
    stop: &AtomicBool,
    head: &AtomicUsize,
    pool: &Pool,
    halt: &Halt,
) -> io::Result<()> {
    let n = job.files.len();
    let mut out = io::stdout().lock();
    let (mut failed, mut records, mut groups) = (0usize, 0u64, 0u64);
    let mut not_started = 0usize;
    for (i, rx) in rxs.into_iter().enumerate() {
        let file = &job.files[i];
        head.store(i, Ordering::Relaxed);
        let mut back = HeldBack::default();
        loop {
            match rx.recv() {
                Ok(Msg::Data(b, now)) => {
                    let w = back
                        .write_out(&mut out, pool)
                        .and_then(|_| out.write_all(&b))
                        .and_then(|_| if now { out.flush() } else { Ok(()) });
                    pool.put(b);
                    if let Err(e) = w {
                        stop.store(true, Ordering::Relaxed);
                        return Err(e);
                    }
                }
                Ok(Msg::Part(b, commit)) => {
                    if let Err(e) = back.part(&mut out, b, commit, pool) {
                        stop.store(true, Ordering::Relaxed);
                        return Err(e);
                    }
                }
                Ok(Msg::Blocks(v)) => {
                    pool.queued().fetch_sub(v.len(), Ordering::Relaxed);
                    let mut w = back.write_out(&mut out, pool);
                    for b in v {
                        w = w.and_then(|_| out.write_all(&b));
                        pool.put(b);
                    }
                    if let Err(e) = w {
                        stop.store(true, Ordering::Relaxed);
                        return Err(e);
                    }
                }
                Ok(Msg::Spilled(f, start, end)) => {
                    if let Err(e) = copy_spill(&f, start, end, &mut out) {
                        stop.store(true, Ordering::Relaxed);
                        return Err(e);
                    }
                }
                Ok(Msg::Done(Ok(s))) => {
                    // A file that ends well closed its last block (its final flush).
                    back.drop_all(pool);
                    records += s.records;
                    groups += s.row_groups;
                    break;
                }
                Ok(Msg::Done(Err(e))) => {
                    back.drop_all(pool);
                    if n == 1 {
                        return Err(e);
                    }
                    failed += 1;
                    let _ = out.flush();
                    // The name is in the message already when the file could not be opened.
                    if e.to_string().contains(file.as_str()) {
                        bar.note(&format!("aptscope: skipped: {e}"));
                    } else {
                        bar.note(&format!("aptscope: skipped {file}: {e}"));
                    }
                    break;
                }
                // Not started: the run was stopped (`Halt`).
                Err(_) if halt.check() => {
                    not_started += 1;
                    break;
                }
                Err(_) => {
                    return Err(io::Error::other(format!("{file}: its decoder stopped")));
                }
            }
        }
    }
    out.flush()?;
    if let Output::Parquet(root) = &job.out {
        bar.note(&format!(
            "{}: {} of {n} files, {records} records, {groups} row groups",
            root.display(),
            n - failed - not_started
        ));
    }
    if halt.check() {
        let by = halt.by.lock().ok().and_then(|b| b.clone());
        return Err(io::Error::new(
            io::ErrorKind::Interrupted,
            format!(
                "stopped by {}: the dataset holds the {records} records decoded before, in \
                 complete part files{}",
                by.as_deref().unwrap_or("a signal"),
                if not_started > 0 {
                    format!("; {not_started} of {n} files not started")
                } else {
                    String::new()
                }
            ),
        ));
    }
    if failed > 0 {
        return Err(io::Error::other(format!(
            "{failed} of {n} inputs skipped (see above)"
        )));
    }
    Ok(())
}

/// Decode file `i` of the job into its channel (text, NDJSON) or dataset parts (Parquet).
#[allow(clippy::too_many_arguments)]
fn one(
    job: &Job<'_>,
    i: usize,
    tx: &SyncSender<Msg>,
    bar: &Bar,
    head: &AtomicUsize,
    pool: &Pool,
    helpers: usize,
    halt: &Halt,
) -> io::Result<Stats> {
    let file = job.files[i].as_str();
    let mut seen = 0u64;
    match &job.out {
        Output::Parquet(root) => {
            let opts = aptscope_parquet::Options::default();
            let sink = || DirSink::new(root, i, opts);
            let o = aptscope_parquet::DecodeOpts {
                open: job.open,
                proto: proto_of(job.proto),
                units: job.units.clone(),
                timeout_ns: job.timeout,
                // What is not a capture is refused (one input: the run fails; among several,
                // it is skipped).
                judge: true,
                stop: Some(halt.flag.clone()),
            };
            let mut tick = |p: &Progress| {
                bar.tick(p, &mut seen);
                halt.check();
            };
            // Cores the files leave spare encode and compress the row groups, which is half
            // of the work; the rows are built on this thread, in the order of `-j 1`, so the
            // part files are the same.
            let s = if helpers > 1 {
                let w = CaptureWriter::new(
                    Threaded::new(
                        helpers - 1,
                        2 * opts.rows_per_group,
                        4 * opts.bytes_per_group,
                        sink,
                    )?,
                    file,
                    opts,
                );
                decode_file(file, &o, w, &mut tick)?.1
            } else {
                decode_file(file, &o, CaptureWriter::new(sink(), file, opts), &mut tick)?.1
            };
            Ok(Stats {
                records: s.records,
                row_groups: s.row_groups,
            })
        }
        Output::Lines { json: as_json } => {
            let (reader, format, progress) = open_with_progress(file, job.open)?;
            // Held until the detector has judged the first 4 KiB, so that what is not a capture
            // prints nothing (a given protocol: nothing to judge).
            let held = Cell::new(job.proto == ProtoArg::Auto);
            let mut out = ChanWriter::new(tx, &held, i, head, pool);
            let tag = (job.files.len() > 1).then_some((i, file));
            if let Some((i, name)) = tag {
                if *as_json {
                    let mut l = String::from("{\"file\":");
                    json::string(&mut l, name);
                    writeln!(out, "{l},\"type\":\"file\",\"index\":{i}}}")?;
                } else {
                    writeln!(out, "# file {}: {name}", i + 1)?;
                }
            }
            let fmt = if *as_json {
                PFormat::Json
            } else {
                PFormat::Text
            };
            let filter = job.filter.map(compile_filter).transpose()?;
            let name = tag.map(|(_, name)| name);
            // Rendering on other threads pays where there are cores to spare and a whole file
            // to read (a live input shows each record as it comes: rendered here).
            let split = helpers > 0
                && job.open.follow.is_none()
                && file != "-"
                && std::fs::metadata(file).is_ok_and(|m| m.is_file());
            if !split {
                let mut p = Pipeline::new(proto_of(job.proto), fmt);
                if let Some(name) = name {
                    p.set_file(name);
                }
                p.set_units(job.units.clone());
                if let Some(t) = job.timeout {
                    p.set_reply_timeout(t);
                }
                if let Some(f) = filter {
                    p.set_filter(f);
                }
                let mut engine = Engine::Here(Box::new(p));
                return lines(job, file, &mut engine, reader, format, &progress, out, bar);
            }
            let mut dec = Decoder::new(proto_of(job.proto));
            dec.set_units(job.units.clone());
            if let Some(t) = job.timeout {
                dec.set_reply_timeout(t);
            }
            let look = Look {
                fmt,
                file: name,
                filter: filter.as_ref(),
            };
            let (work_tx, work_rx) = channel();
            let work_rx = Mutex::new(work_rx);
            let (done_tx, done_rx) = channel();
            let (look, work_rx) = (&look, &work_rx);
            std::thread::scope(|sc| {
                for _ in 0..helpers {
                    let done = done_tx.clone();
                    sc.spawn(move || split::render_thread(look, work_rx, done));
                }
                drop(done_tx);
                // Dropped when `lines` returns, however it ends: the render threads then stop.
                let mut engine =
                    Engine::Split(Box::new(Split::new(dec, helpers, work_tx, &done_rx, pool)));
                lines(job, file, &mut engine, reader, format, &progress, out, bar)
            })
        }
    }
}

/// Decode one file into `out` (text or NDJSON) with `engine`.
#[allow(clippy::too_many_arguments)]
fn lines(
    job: &Job<'_>,
    file: &str,
    engine: &mut Engine<'_>,
    mut reader: Box<dyn Reader>,
    format: aptscope_capture::open::Format,
    progress: &Progress,
    out: ChanWriter<'_>,
    bar: &Bar,
) -> io::Result<Stats> {
    let held = out.held;
    let mut seen = 0u64;
    let mut k = 0u32;
    let out = RefCell::new(out);
    let mut file_problems = 0u64;
    // A forced protocol is checked against what detection would say of the input.
    let mut probing = job.proto != ProtoArg::Auto;
    let mut probe = Probe::default();
    while let Some(ev) = reader.next_event() {
        match &ev {
            Event::Diag(d) => {
                if let Err(e) = fatal(d) {
                    // What `-j 1` had written out before it is written out.
                    engine.sync(&out)?;
                    return Err(e.into());
                }
                file_problems += 1;
            }
            Event::Chunk(c) if probing => probing = probe.add(c),
            _ => {}
        }
        engine.feed(&ev, &out)?;
        // The input had nothing more just now (a pipe a live capture writes, a followed
        // file): what it gave is shown now, each record as its bytes arrive.
        let idle = progress.idle();
        if idle {
            engine.detect_if_certain(&out)?;
        }
        if held.get() {
            if let Some(d) = engine.decoder().detection() {
                if not_a_capture(format, d) {
                    return Err(not_a_capture_error(d));
                }
                // What was rendered while held is held as `-j 1` held it.
                engine.sync(&out)?;
                held.set(false);
            }
        }
        if idle && !held.get() {
            engine.sync(&out)?;
            out.borrow_mut().flush()?;
        }
        k = k.wrapping_add(1);
        if k.is_multiple_of(256) {
            bar.tick(progress, &mut seen);
        }
    }
    engine.finish(&out)?;
    if let Some(d) = engine.decoder().detection().filter(|_| held.get()) {
        if not_a_capture(format, d) {
            return Err(not_a_capture_error(d));
        }
    }
    held.set(false);
    if let Some(forced) = proto_of(job.proto) {
        if let Some(note) = forced_note(forced, &probe.sample) {
            bar.note(&format!("aptscope: {file}: {note}"));
        }
    }
    // A forced protocol decodes whatever the input holds (the note above says what
    // detection thinks of it).
    let refused = refuse(engine.decoder(), format, file_problems);
    if let Some(e) = refused.filter(|_| job.proto == ProtoArg::Auto) {
        out.borrow_mut().flush()?;
        return Err(e);
    }
    bar.tick(progress, &mut seen);
    out.borrow_mut().flush()?;
    Ok(Stats::default())
}

/// The first [`SAMPLE`] bytes of the first chunk's stream and direction (detection judges one
/// lane), to check a forced protocol against.
#[derive(Default)]
struct Probe {
    lane: Option<(u32, Direction)>,
    sample: Vec<u8>,
}

impl Probe {
    /// Keep what the sample still lacks of `c`; whether more is wanted.
    fn add(&mut self, c: &Chunk<'_>) -> bool {
        if *self.lane.get_or_insert((c.stream, c.dir)) == (c.stream, c.dir) {
            let take = (SAMPLE - self.sample.len()).min(c.bytes.len());
            self.sample.extend_from_slice(&c.bytes[..take]);
        }
        self.sample.len() < SAMPLE
    }
}

/// What to say of a protocol forced on an input that detection reads otherwise: which protocol
/// detection sees, and how much of the input the forced one frames.
fn forced_note(forced: Proto, sample: &[u8]) -> Option<String> {
    let d = detect(sample);
    let share = |p: Proto| match p {
        Proto::Apt => d.apt,
        Proto::Elliptec => d.elliptec,
    };
    let seen = d.proto.filter(|p| *p != forced)?;
    Some(format!(
        "detection reads this input as {} ({:.0}% of the first {} bytes frame cleanly); the \
         forced protocol, {}, frames {:.0}%",
        seen.name(),
        share(seen) * 100.0,
        sample.len(),
        forced.name(),
        share(forced) * 100.0
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use aptscope_dissector::synth::Rng;

    /// What the writer has written out of one file, applying its messages as `collect` does.
    #[derive(Default)]
    struct Sink {
        out: Vec<u8>,
        back: HeldBack,
    }

    impl Sink {
        fn take(&mut self, rx: &Receiver<Msg>, pool: &Pool) {
            while let Ok(m) = rx.try_recv() {
                match m {
                    Msg::Data(b, _) => {
                        self.back.write_out(&mut self.out, pool).unwrap();
                        self.out.extend_from_slice(&b);
                    }
                    Msg::Part(b, commit) => {
                        self.back.part(&mut self.out, b, commit, pool).unwrap();
                    }
                    Msg::Blocks(..) | Msg::Spilled(..) | Msg::Done(_) => panic!("not sent here"),
                }
            }
        }
    }

    /// Random lines (each ending in a newline), some longer than a block.
    fn lines(r: &mut Rng) -> Vec<u8> {
        let mut b = vec![];
        for _ in 0..r.below(400) {
            let len = match r.below(50) {
                0 => BLOCK as u64 + r.below(2 * BLOCK as u64),
                1 => 0,
                _ => 1 + r.below(600),
            };
            b.extend((0..len).map(|i| b'a' + (i % 26) as u8));
            b.push(b'\n');
        }
        b
    }

    /// A rendered buffer handed over whole puts on the output, at every point, exactly the
    /// bytes that cutting it into blocks (what `-j 1` sends) does: the same bytes are written
    /// out before an error ends the file, and all of them at its end. Held output, lines
    /// written through `Write` between buffers, and empty buffers included.
    #[test]
    fn whole_rendered_buffers_reach_the_output_at_the_blocks_ends() {
        let pool = Pool::default();
        let head = AtomicUsize::new(0);
        for seed in 1..=12u64 {
            let mut r = Rng(seed);
            let (ta, ra) = sync_channel(1 << 16);
            let (tb, rb) = sync_channel(1 << 16);
            let hold = seed % 3 == 0;
            let (held_a, held_b) = (Cell::new(hold), Cell::new(hold));
            let mut a = ChanWriter::new(&ta, &held_a, 0, &head, &pool);
            let mut b = ChanWriter::new(&tb, &held_b, 0, &head, &pool);
            let (mut sa, mut sb) = (Sink::default(), Sink::default());
            let mut whole = vec![];
            for step in 0..40 {
                if hold && step == 5 {
                    held_a.set(false);
                    held_b.set(false);
                }
                if r.below(8) == 0 {
                    writeln!(a, "# a line written {step}").unwrap();
                    writeln!(b, "# a line written {step}").unwrap();
                    whole.extend_from_slice(format!("# a line written {step}\n").as_bytes());
                }
                let buf = lines(&mut r);
                whole.extend_from_slice(&buf);
                a.write_lines(&buf).unwrap();
                b.write_rendered(buf).unwrap();
                sa.take(&ra, &pool);
                sb.take(&rb, &pool);
                assert_eq!(sa.out.len(), sb.out.len(), "seed {seed} step {step}");
                assert!(sa.out == sb.out, "seed {seed} step {step}");
            }
            a.flush().unwrap();
            b.flush().unwrap();
            sa.take(&ra, &pool);
            sb.take(&rb, &pool);
            assert!(
                sa.out == whole && sb.out == whole,
                "seed {seed}: all at the end"
            );
        }
    }
}
