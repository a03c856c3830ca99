//! `decode` over many files: files decoded in parallel, text and NDJSON written per file in
//! input order, or a Parquet dataset; a progress bar on a terminal.
//!
//! Text and NDJSON: each worker decodes and renders whole files into a bounded channel of its
//! own (64 KiB blocks); the main thread copies file 0's channel to standard output, then file
//! 1's, and so on. A worker ahead of the writer does not wait for it: when its channel is full
//! it appends its blocks to a spill file of its own (unlinked temporary file) and announces
//! each spilled range through the channel, so the order stays that of `-j 1` while every core
//! renders, and memory stays bounded whatever the files' sizes (disk holds what is ahead, at
//! most [`SPILL_MAX`] per file, beyond which the worker waits). Parquet: each worker writes its
//! file's row groups as part files of their own (named by the file's index), so nothing is
//! ordered or merged.
//!
//! Cores the files leave spare (one file with `-j 2`, two with `-j 4`) render inside each file:
//! its decode chain runs on its worker, which hands the records to render threads and writes
//! what they rendered in order ([`split`], which says why this rather than cutting the capture
//! into parts). Either way the output is byte for byte that of `-j 1`.

use crate::common::{compile_filter, fatal, proto_of, ProtoArg};
use aptscope_capture::judge::{not_a_capture, not_a_capture_error, refuse};
use aptscope_capture::open::{open_with_progress, OpenOptions, Progress};
use aptscope_capture::{Chunk, Direction};
use aptscope_capture::{Event, Reader};
use aptscope_dissector::detect::{detect, Proto, SAMPLE};
use aptscope_dissector::json;
use aptscope_dissector::pipeline::{Format as PFormat, Pipeline};
use aptscope_dissector::record::Decoder;
use aptscope_dissector::units::UnitsOpts;
use aptscope_parquet::{decode_file, CaptureWriter, DirSink};
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
/// input's records as they come), ranges of its spill file, then its result.
enum Msg {
    Data(Vec<u8>, bool),
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

/// Blocks a file's channel holds (1 MiB): enough to ride out the writer's pauses; a file
/// further ahead spills.
const CHANNEL_BLOCKS: usize = 16;

const BLOCK: usize = 1 << 16;

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

/// A writer into a file's channel, in 64 KiB blocks. Held back until released: what a file
/// that turns out not to be a capture wrote is dropped.
struct ChanWriter<'a> {
    tx: &'a SyncSender<Msg>,
    buf: Vec<u8>,
    held: &'a Cell<bool>,
    /// The file's index in the run (names its spill file).
    index: usize,
    /// The index of the file the writer is copying out: that file's worker waits for it
    /// rather than spill.
    head: &'a AtomicUsize,
    spill: Option<Spill>,
    /// No spill file could be made, or written: wait for the writer.
    no_spill: bool,
}

impl ChanWriter<'_> {
    fn new<'a>(
        tx: &'a SyncSender<Msg>,
        held: &'a Cell<bool>,
        index: usize,
        head: &'a AtomicUsize,
    ) -> ChanWriter<'a> {
        ChanWriter {
            tx,
            buf: Vec::with_capacity(BLOCK),
            held,
            index,
            head,
            spill: None,
            no_spill: false,
        }
    }

    fn gone() -> io::Error {
        io::Error::from(io::ErrorKind::BrokenPipe)
    }

    /// Announce the spilled bytes not yet announced; `wait`: even if the channel is full.
    /// Whether none is left unannounced.
    fn announce(&mut self, wait: bool) -> io::Result<bool> {
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

    /// Append `b` to the spill file (made now if need be); false: it cannot take it.
    fn spill(&mut self, b: &[u8]) -> bool {
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
        if self.held.get() || self.buf.is_empty() {
            return Ok(());
        }
        let b = std::mem::replace(&mut self.buf, Vec::with_capacity(BLOCK));
        // The file being written out: the writer is reading this channel, so waiting costs
        // nothing and spilling would only copy the bytes twice.
        if now || self.head.load(Ordering::Relaxed) == self.index {
            self.announce(true)?;
            return self.tx.send(Msg::Data(b, now)).map_err(|_| Self::gone());
        }
        // Blocks after spilled bytes follow them into the spill until those are announced.
        if !self.announce(now)? {
            if self.spill(&b) {
                return Ok(());
            }
            self.announce(true)?;
        }
        match self.tx.try_send(Msg::Data(b, false)) {
            Ok(()) => Ok(()),
            Err(TrySendError::Disconnected(_)) => Err(Self::gone()),
            Err(TrySendError::Full(m)) => {
                let Msg::Data(b, _) = m else {
                    return Ok(());
                };
                if self.spill(&b) {
                    Ok(())
                } else {
                    self.tx.send(Msg::Data(b, false)).map_err(|_| Self::gone())
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
            let need = BLOCK.saturating_sub(self.buf.len()).max(1);
            if b.len() < need {
                self.buf.extend_from_slice(b);
                return Ok(());
            }
            // `-j 1` checks the block's size after each line's text and after its newline:
            // the first such point at or past `need` bytes.
            let cut = b[need - 1..]
                .iter()
                .position(|&c| c == b'\n')
                .map_or(b.len(), |q| (need - 1 + q).max(need));
            self.buf.extend_from_slice(&b[..cut]);
            b = &b[cut..];
            if self.buf.len() >= BLOCK {
                self.send(false)?;
            }
        }
        Ok(())
    }
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
        if self.buf.len() >= BLOCK {
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
    let stop = AtomicBool::new(false);
    let next = AtomicUsize::new(0);
    let head = AtomicUsize::new(0);
    let mut txs = Vec::with_capacity(n);
    let mut rxs: Vec<Receiver<Msg>> = Vec::with_capacity(n);
    for _ in 0..n {
        let (tx, rx) = sync_channel(CHANNEL_BLOCKS);
        txs.push(Mutex::new(Some(tx)));
        rxs.push(rx);
    }
    let jobs = job.jobs.clamp(1, n.max(1));
    // Cores the files leave spare render inside them (see `split`): one file with `-j 2` is
    // decoded on one thread and rendered on two.
    let helpers = if job.jobs > jobs { job.jobs / jobs } else { 0 };
    let job = &job;
    let (bar, stop, next, txs, head) = (&bar, &stop, &next, &txs, &head);
    let result = std::thread::scope(|sc| {
        for _ in 0..jobs {
            sc.spawn(move || loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= n || stop.load(Ordering::Relaxed) {
                    break;
                }
                let Some(tx) = txs[i].lock().ok().and_then(|mut t| t.take()) else {
                    break;
                };
                let r = one(job, i, &tx, bar, head, helpers);
                bar.file_done();
                // The receiver is gone only when the writer stopped: nothing left to do.
                if tx.send(Msg::Done(r)).is_err() {
                    stop.store(true, Ordering::Relaxed);
                }
            });
        }
        collect(job, rxs, bar, stop, head)
    });
    bar.finish();
    result
}

/// The writer side: every file's output in input order; errors reported by name.
fn collect(
    job: &Job<'_>,
    rxs: Vec<Receiver<Msg>>,
    bar: &Bar,
    stop: &AtomicBool,
    head: &AtomicUsize,
) -> io::Result<()> {
    let n = job.files.len();
    let mut out = io::stdout().lock();
    let (mut failed, mut records, mut groups) = (0usize, 0u64, 0u64);
    for (i, rx) in rxs.into_iter().enumerate() {
        let file = &job.files[i];
        head.store(i, Ordering::Relaxed);
        loop {
            match rx.recv() {
                Ok(Msg::Data(b, now)) => {
                    let w = out
                        .write_all(&b)
                        .and_then(|_| if now { out.flush() } else { Ok(()) });
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
                    records += s.records;
                    groups += s.row_groups;
                    break;
                }
                Ok(Msg::Done(Err(e))) => {
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
            n - failed
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
fn one(
    job: &Job<'_>,
    i: usize,
    tx: &SyncSender<Msg>,
    bar: &Bar,
    head: &AtomicUsize,
    helpers: usize,
) -> io::Result<Stats> {
    let file = job.files[i].as_str();
    let mut seen = 0u64;
    match &job.out {
        Output::Parquet(root) => {
            let opts = aptscope_parquet::Options::default();
            let w = CaptureWriter::new(DirSink::new(root, i, opts), file, opts);
            let o = aptscope_parquet::DecodeOpts {
                open: job.open,
                proto: proto_of(job.proto),
                units: job.units.clone(),
                timeout_ns: job.timeout,
                // What is not a capture is refused (one input: the run fails; among several,
                // it is skipped).
                judge: true,
            };
            let (_, s) = decode_file(file, &o, w, &mut |p| bar.tick(p, &mut seen))?;
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
            let mut out = ChanWriter::new(tx, &held, i, head);
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
                    Engine::Split(Box::new(Split::new(dec, helpers, work_tx, &done_rx)));
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
