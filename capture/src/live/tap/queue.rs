//! The capture file's queue: bounded in bytes, never lossy while the file can be written
//! (forwarding waits for room instead, and that wait is counted).

use super::TICK;
use crate::live::stop::lock;
use crate::model::Direction;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

/// A captured chunk, shared between the file and the display.
#[derive(Debug)]
pub(super) struct Rec {
    pub(super) ts: u64,
    pub(super) dir: Direction,
    pub(super) bytes: Vec<u8>,
}

/// What the writer is handed.
pub(super) enum QItem {
    /// A chunk that crossed.
    Chunk(Arc<Rec>),
    /// Write everything queued and flush (a device went away).
    Sync,
}

#[derive(Default)]
struct QState {
    q: VecDeque<QItem>,
    bytes: usize,
    closed: bool,
    failed: bool,
}

/// The file's queue, bounded in bytes.
pub(super) struct FileQueue {
    st: Mutex<QState>,
    not_empty: Condvar,
    not_full: Condvar,
    budget: usize,
    /// Times a push waited for room.
    pub(super) waits: AtomicU64,
    /// Bytes not queued (or dropped from the queue) because writing the file had failed.
    pub(super) lost: AtomicU64,
}

impl FileQueue {
    pub(super) fn new(budget: usize) -> Self {
        FileQueue {
            st: Mutex::new(QState::default()),
            not_empty: Condvar::new(),
            not_full: Condvar::new(),
            budget,
            waits: AtomicU64::new(0),
            lost: AtomicU64::new(0),
        }
    }

    pub(super) fn push(&self, item: QItem) {
        let len = match &item {
            QItem::Chunk(r) => r.bytes.len(),
            QItem::Sync => 0,
        };
        let mut st = lock(&self.st);
        let mut waited = false;
        while !st.failed && st.bytes > 0 && st.bytes + len > self.budget {
            if !waited {
                self.waits.fetch_add(1, Ordering::Relaxed);
                waited = true;
            }
            st = match self.not_full.wait_timeout(st, TICK) {
                Ok((g, _)) => g,
                Err(e) => e.into_inner().0,
            };
        }
        if st.failed {
            self.lost.fetch_add(len as u64, Ordering::Relaxed);
            return;
        }
        st.bytes += len;
        st.q.push_back(item);
        self.not_empty.notify_one();
    }

    /// Everything queued (waiting up to `timeout` for something), and whether the queue is
    /// closed and now empty.
    pub(super) fn pop_all(&self, timeout: Duration) -> (Vec<QItem>, bool) {
        let mut st = lock(&self.st);
        if st.q.is_empty() && !st.closed {
            st = match self.not_empty.wait_timeout(st, timeout) {
                Ok((g, _)) => g,
                Err(e) => e.into_inner().0,
            };
        }
        let items: Vec<QItem> = st.q.drain(..).collect();
        st.bytes = 0;
        self.not_full.notify_all();
        (items, st.closed)
    }

    pub(super) fn close(&self) {
        lock(&self.st).closed = true;
        self.not_empty.notify_all();
    }

    pub(super) fn fail(&self) {
        let mut st = lock(&self.st);
        st.failed = true;
        for it in st.q.drain(..) {
            if let QItem::Chunk(r) = it {
                self.lost.fetch_add(r.bytes.len() as u64, Ordering::Relaxed);
            }
        }
        st.bytes = 0;
        self.not_full.notify_all();
    }
}
