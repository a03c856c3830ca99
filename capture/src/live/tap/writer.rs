//! The writer thread: the two directions merged by time (a chunk waits [`MERGE_WINDOW_NS`] for
//! an earlier one from the other side), written, and flushed in batches or at once.

use super::queue::{FileQueue, QItem, Rec};
use super::sink::FileSink;
use super::{Clock, StopHandle, FLUSH_CHUNKS, FLUSH_EVERY, MERGE_WINDOW_NS, TICK};
use crate::model::{Chunk, Direction};
use std::collections::VecDeque;
use std::io;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Instant;

/// Two per-direction queues merged by time: a chunk is written once the other direction has a
/// later one, or once it is older than the merge window.
#[derive(Default)]
pub(super) struct Merger {
    lanes: [VecDeque<Arc<Rec>>; 2],
}

impl Merger {
    pub(super) fn push(&mut self, r: Arc<Rec>) {
        let i = usize::from(r.dir == Direction::DeviceToHost);
        self.lanes[i].push_back(r);
    }
    /// The next chunk in time order whose time is at most `horizon` (`None`: any).
    pub(super) fn pop(&mut self, horizon: Option<u64>) -> Option<Arc<Rec>> {
        let i = match (self.lanes[0].front(), self.lanes[1].front()) {
            (Some(a), Some(b)) => usize::from(b.ts < a.ts),
            (Some(a), None) if horizon.is_none_or(|h| a.ts <= h) => 0,
            (None, Some(b)) if horizon.is_none_or(|h| b.ts <= h) => 1,
            _ => return None,
        };
        self.lanes[i].pop_front()
    }
}

/// What the writer did.
#[derive(Default)]
pub(super) struct WriterOut {
    /// Chunks written.
    pub(super) written: u64,
    /// Host → device bytes written.
    pub(super) h2d: u64,
    /// Device → host bytes written.
    pub(super) d2h: u64,
    /// Why writing stopped early.
    pub(super) error: Option<String>,
    /// A stream's reader closed it.
    pub(super) reader_closed: bool,
}

/// Write what the queue brings until it is closed. A stream sink is flushed whenever something
/// was written, and its reader going away stops the whole tap through `stop` (nothing left to
/// record into).
pub(super) fn writer_loop(
    q: &FileQueue,
    mut sink: FileSink,
    clock: Clock,
    stop: &StopHandle,
) -> WriterOut {
    let mut out = WriterOut::default();
    let mut merger = Merger::default();
    let mut since_flush = 0u64;
    let mut last_flush = Instant::now();
    let write = |sink: &mut FileSink, r: &Rec, out: &mut WriterOut| -> io::Result<()> {
        sink.out.chunk(&Chunk {
            ts_ns: Some(r.ts),
            dir: r.dir,
            stream: 0,
            bytes: &r.bytes,
        })?;
        out.written += 1;
        match r.dir {
            Direction::HostToDevice => out.h2d += r.bytes.len() as u64,
            _ => out.d2h += r.bytes.len() as u64,
        }
        Ok(())
    };
    let result = (|| -> io::Result<()> {
        loop {
            let (items, closed) = q.pop_all(TICK);
            let mut sync = closed;
            for it in items {
                match it {
                    QItem::Chunk(r) => merger.push(r),
                    QItem::Sync => sync = true,
                }
            }
            let horizon = if sync {
                None
            } else {
                Some(clock.now().saturating_sub(MERGE_WINDOW_NS))
            };
            while let Some(r) = merger.pop(horizon) {
                write(&mut sink, &r, &mut out)?;
                since_flush += 1;
            }
            if sync
                || since_flush >= FLUSH_CHUNKS
                || (since_flush > 0 && (sink.eager || last_flush.elapsed() >= FLUSH_EVERY))
            {
                sink.flush()?;
                since_flush = 0;
                last_flush = Instant::now();
            }
            // Seen at once even when nothing is being written (a quiet line).
            if sink.reader_gone() {
                return Err(io::Error::new(
                    io::ErrorKind::BrokenPipe,
                    "the reader closed the pipe",
                ));
            }
            if closed {
                return sink.out.finish();
            }
        }
    })();
    if let Err(e) = result {
        // (A pcapng writer's error may wrap the broken pipe: the pipe itself says.)
        if sink.stream.is_some() && (e.kind() == io::ErrorKind::BrokenPipe || sink.reader_gone()) {
            out.reader_closed = true;
            stop.stop();
        }
        q.fail();
        for lane in &merger.lanes {
            for r in lane {
                q.lost.fetch_add(r.bytes.len() as u64, Ordering::Relaxed);
            }
        }
        out.error = Some(e.to_string());
    }
    out
}
