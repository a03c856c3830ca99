//! One file on several cores: the decode chain on one thread, rendering on the others.
//!
//! Why a pipeline rather than cutting the capture into parts decoded apart and stitched: what
//! makes the output what it is — framing with resync, numbering, pairing (requests waiting at the
//! end of a part answered at the start of the next), the units a device's HW_GET_INFO sets, the
//! Elliptec bus state, the streams seen — is one sequential state, and it is the cheap part:
//! measured on 100 MB of random frames (release build), `decode -Y` with a filter that keeps
//! nothing — reading, framing, decoding, pairing, numbering — takes 0.74 CPU-s, an eighth of
//! `decode --json`'s 6.1 CPU-s (a sixth of text's 4.2); rendering the lines takes the rest, and
//! each record renders on its own. So one thread runs the chain exactly as `-j 1` does and hands
//! the records, owned ([`Batch`]), in batches of a couple of thousand to render threads; what they
//! render is written in batch order. The output is that of `-j 1` by construction, whatever the
//! container (pcap, pcapng, MCAP, raw, hex text), with no stitching to get wrong; memory is
//! bounded by the batches in flight ([`IN_FLIGHT`]) and the rendered ones in the file's channel
//! to the writer (handed over whole, see `ChanWriter::write_rendered`).
//!
//! The display filter (`-Y`) reads one record at a time, so the render threads apply it too.

use super::{ChanWriter, Pool};
use aptscope_capture::Event;
use aptscope_dissector::filter::Filter;
use aptscope_dissector::owned::Batch;
use aptscope_dissector::pipeline::{Format, Pipeline, Renderer};
use aptscope_dissector::record::{Decoder, Record};
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::io::{self, Write};
use std::sync::mpsc::{Receiver, Sender};
use std::sync::Mutex;

/// Records per batch: enough that handing a batch over costs little beside rendering it.
/// Measured on 30 MB of random frames, `--json -j 2`, CPU time against `-j 1`, on a machine
/// at load 15: +40 % with batches of 4096 records, +25 % with 1024, +20 % with 64 to 256; but
/// on a quiet one (load 2, 100 MB, 5 alternating runs) 2048 records took 0.94× the wall time
/// of 256 and 0.98× the CPU (at 28 MiB peak instead of 15): when the cores are free, fewer
/// hand-overs matter more than the caches.
const BATCH_RECORDS: usize = 2048;

/// Bytes of frames and garbage per batch at most (long garbage runs).
const BATCH_BYTES: usize = 1 << 18;

/// Batches handed over and not yet written out, per render thread: one being rendered, some
/// waiting, some rendered waiting for an earlier one.
const IN_FLIGHT: usize = 4;

/// A batch to render: its place, its records, the streams seen before its first record, and
/// a buffer to render into.
pub(super) struct Work {
    seq: u64,
    batch: Batch,
    streams: Vec<u32>,
    out: Vec<u8>,
}

/// How the render threads render: format, the input's name when records name it, the filter.
pub(super) struct Look<'a> {
    pub(super) fmt: Format,
    pub(super) file: Option<&'a str>,
    pub(super) filter: Option<&'a Filter>,
}

/// A render thread: takes batches from `work` until it closes, renders each into its buffer
/// and sends it back on `done`.
pub(super) fn render_thread(look: &Look<'_>, work: &Mutex<Receiver<Work>>, done: Sender<Work>) {
    let mut r = Renderer::new(look.fmt);
    if let Some(f) = look.file {
        r.set_file(f);
    }
    if let Some(f) = look.filter {
        r.set_filter(f.clone());
    }
    loop {
        // The lock is held only while waiting for the next batch, not while rendering it.
        let next = match work.lock() {
            Ok(rx) => rx.recv(),
            Err(_) => return,
        };
        let Ok(mut w) = next else {
            return;
        };
        r.set_streams(&w.streams);
        let out = &mut w.out;
        let _ = w.batch.for_each(&mut |rec| {
            r.render(rec, &mut |line: &str| {
                out.extend_from_slice(line.as_bytes());
                out.push(b'\n');
                Ok::<(), ()>(())
            })
        });
        if done.send(w).is_err() {
            return;
        }
    }
}

/// What decodes a file: the whole pipeline here, or the chain here and rendering on the
/// render threads.
pub(super) enum Engine<'a> {
    /// Decode and render on this thread.
    Here(Box<Pipeline>),
    /// Decode here, render there.
    Split(Box<Split<'a>>),
}

/// The chain, and the batches handed to the render threads.
pub(super) struct Split<'a> {
    dec: Decoder,
    q: Queue<'a>,
}

struct Queue<'a> {
    batch: Batch,
    /// Tracks the streams seen, as the renderer that saw every record before would have.
    streams: Renderer,
    /// The streams seen before the current batch's first record.
    start: Vec<u32>,
    records: usize,
    work: Sender<Work>,
    done: &'a Receiver<Work>,
    in_flight: usize,
    /// Batches handed over, and written out.
    sent: u64,
    written: u64,
    /// Rendered batches waiting for an earlier one.
    ready: BTreeMap<u64, Work>,
    /// Batches (and their lists of streams) back from written batches, for the next.
    spare: Vec<(Batch, Vec<u32>)>,
    /// Buffers to render into: what the writer has written out comes back here.
    pool: &'a Pool,
}

type Out<'w, 'a> = RefCell<ChanWriter<'w>>;

fn stopped() -> io::Error {
    io::Error::other("a render thread stopped")
}

impl<'a> Split<'a> {
    /// The chain `dec`, its records rendered by `threads` render threads that take batches
    /// from `work` and return them on `done`.
    pub(super) fn new(
        dec: Decoder,
        threads: usize,
        work: Sender<Work>,
        done: &'a Receiver<Work>,
        pool: &'a Pool,
    ) -> Split<'a> {
        Split {
            dec,
            q: Queue {
                batch: Batch::new(),
                streams: Renderer::new(Format::Text),
                start: vec![],
                // Tests cut the samples, a few hundred records each, into many batches.
                records: aptscope_parquet::pool::records_from_env().unwrap_or(BATCH_RECORDS),
                work,
                done,
                in_flight: IN_FLIGHT * threads.max(1),
                sent: 0,
                written: 0,
                ready: BTreeMap::new(),
                spare: vec![],
                pool,
            },
        }
    }
}

impl Queue<'_> {
    fn add(&mut self, rec: &Record<'_>, out: &Out<'_, '_>) -> io::Result<()> {
        if self.batch.is_empty() {
            self.start.clear();
            self.start.extend_from_slice(self.streams.streams());
        }
        self.streams.note_streams(rec);
        self.batch.push(rec);
        if self.batch.len() >= self.records || self.batch.byte_len() >= BATCH_BYTES {
            self.submit(out)?;
        }
        Ok(())
    }

    /// Hand the current batch over (waiting while too many are in flight), and write out
    /// what is rendered.
    fn submit(&mut self, out: &Out<'_, '_>) -> io::Result<()> {
        if self.batch.is_empty() {
            return Ok(());
        }
        while self.sent - self.written >= self.in_flight as u64 {
            self.wait_one(out)?;
        }
        let (b, mut streams) = self.spare.pop().unwrap_or_default();
        streams.clear();
        streams.extend_from_slice(&self.start);
        let w = Work {
            seq: self.sent,
            batch: std::mem::replace(&mut self.batch, b),
            streams,
            out: self.pool.get(),
        };
        self.work.send(w).map_err(|_| stopped())?;
        self.sent += 1;
        while let Ok(w) = self.done.try_recv() {
            self.take(w, out)?;
        }
        Ok(())
    }

    fn wait_one(&mut self, out: &Out<'_, '_>) -> io::Result<()> {
        let w = self.done.recv().map_err(|_| stopped())?;
        self.take(w, out)
    }

    /// A rendered batch: written out with every one before it that is ready (its buffer
    /// handed to the writer whole, which returns it to the pool once written).
    fn take(&mut self, w: Work, out: &Out<'_, '_>) -> io::Result<()> {
        self.ready.insert(w.seq, w);
        while let Some(mut w) = self.ready.remove(&self.written) {
            out.borrow_mut().write_rendered(w.out)?;
            self.written += 1;
            w.batch.clear();
            self.spare.push((w.batch, w.streams));
        }
        Ok(())
    }

    /// Everything pushed so far rendered and written out.
    fn sync(&mut self, out: &Out<'_, '_>) -> io::Result<()> {
        self.submit(out)?;
        while self.written < self.sent {
            self.wait_one(out)?;
        }
        Ok(())
    }
}

/// Write a rendered line as `-j 1` does.
fn line_out(out: &Out<'_, '_>, line: &str) -> io::Result<()> {
    let mut o = out.borrow_mut();
    o.write_all(line.as_bytes())?;
    o.write_all(b"\n")
}

impl Engine<'_> {
    /// Feed one event of the capture.
    pub(super) fn feed(&mut self, ev: &Event<'_>, out: &Out<'_, '_>) -> io::Result<()> {
        match self {
            Engine::Here(p) => ev.feed(&mut **p, &mut |l: &str| line_out(out, l)),
            Engine::Split(s) => {
                let Split { dec, q } = &mut **s;
                ev.feed(dec, &mut |rec: &Record<'_>| q.add(rec, out))
            }
        }
    }

    /// See [`Pipeline::detect_if_certain`].
    pub(super) fn detect_if_certain(&mut self, out: &Out<'_, '_>) -> io::Result<()> {
        match self {
            Engine::Here(p) => p.detect_if_certain(&mut |l: &str| line_out(out, l))?,
            Engine::Split(s) => {
                let Split { dec, q } = &mut **s;
                dec.detect_if_certain(&mut |rec: &Record<'_>| q.add(rec, out))?
            }
        };
        Ok(())
    }

    /// End of the capture: the last records, all written out.
    pub(super) fn finish(&mut self, out: &Out<'_, '_>) -> io::Result<()> {
        match self {
            Engine::Here(p) => p.finish(&mut |l: &str| line_out(out, l)),
            Engine::Split(s) => {
                let Split { dec, q } = &mut **s;
                dec.finish(&mut |rec: &Record<'_>| q.add(rec, out))?;
                q.sync(out)
            }
        }
    }

    /// Everything decoded so far written out (before a flush, a release of held output, or
    /// an error that ends the file: what `-j 1` had written by then is written).
    pub(super) fn sync(&mut self, out: &Out<'_, '_>) -> io::Result<()> {
        match self {
            Engine::Here(_) => Ok(()),
            Engine::Split(s) => s.q.sync(out),
        }
    }

    /// The chain.
    pub(super) fn decoder(&self) -> &Decoder {
        match self {
            Engine::Here(p) => p.decoder(),
            Engine::Split(s) => &s.dec,
        }
    }
}
