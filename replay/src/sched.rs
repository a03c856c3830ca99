//! The scheduler: every send has an absolute deadline on the replay's clock (start + captured
//! offset), so errors never accumulate over a long replay. Waiting blocks on the receive
//! channel (handling replies as they come) until shortly before the deadline, then spins the
//! last [`SPIN_NS`], which keeps the send-time error well under a millisecond.

use crate::port::{Clock, RxEvent};
use serde_json::{json, Value};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::Duration;

/// The last stretch before a deadline is spun, not slept (sleep wake-ups are late by tens to
/// hundreds of µs).
pub const SPIN_NS: u64 = 300_000;
/// The longest a wait blocks before looking at abort requests again.
const SLICE_NS: u64 = 50_000_000;

/// How a wait ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Waited {
    /// The deadline came (or a condition held).
    Reached,
    /// An abort was asked for (the reason: `SIGINT` …).
    Aborted(String),
}

/// Wait until `deadline_ns` on `clock`, passing every event that arrives meanwhile to
/// `handle(Some(event))`, which returns whether the wait may end early (a condition holds);
/// `handle(None)` asks the same without an event, at least every 50 ms, as `abort` is asked.
pub fn wait_until(
    clock: &Clock,
    deadline_ns: u64,
    rx: &Receiver<RxEvent>,
    handle: &mut dyn FnMut(Option<RxEvent>) -> bool,
    abort: &mut dyn FnMut() -> Option<String>,
) -> Waited {
    loop {
        if let Some(why) = abort() {
            return Waited::Aborted(why);
        }
        if handle(None) {
            return Waited::Reached;
        }
        let now = clock.now_ns();
        if now >= deadline_ns {
            return Waited::Reached;
        }
        let left = deadline_ns - now;
        if left <= SPIN_NS {
            // Take what is already there, then spin to the deadline.
            let mut done = false;
            while let Ok(ev) = rx.try_recv() {
                done |= handle(Some(ev));
            }
            if done {
                return Waited::Reached;
            }
            while clock.now_ns() < deadline_ns {
                std::hint::spin_loop();
            }
            return Waited::Reached;
        }
        let block = (left - SPIN_NS).min(SLICE_NS);
        match rx.recv_timeout(Duration::from_nanos(block)) {
            Ok(ev) => {
                let mut done = handle(Some(ev));
                while let Ok(ev) = rx.try_recv() {
                    done |= handle(Some(ev));
                }
                if done {
                    return Waited::Reached;
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            // The reader has ended (the line is gone): just wait out the time.
            Err(RecvTimeoutError::Disconnected) => std::thread::sleep(Duration::from_nanos(block)),
        }
    }
}

/// Send-time errors: how late each send started after its deadline.
#[derive(Debug, Clone, Default)]
pub struct SendTiming {
    late_ns: Vec<u64>,
}

impl SendTiming {
    /// Record one send, `late_ns` after its deadline.
    pub fn record(&mut self, late_ns: u64) {
        self.late_ns.push(late_ns);
    }

    /// Sends recorded.
    pub fn count(&self) -> usize {
        self.late_ns.len()
    }

    /// The `p`-th percentile (0–100) of the errors, ns.
    pub fn percentile(&self, p: f64) -> Option<u64> {
        if self.late_ns.is_empty() {
            return None;
        }
        let mut v = self.late_ns.clone();
        v.sort_unstable();
        let i = ((p / 100.0) * (v.len() - 1) as f64).round() as usize;
        v.get(i.min(v.len() - 1)).copied()
    }

    /// `send-time error: p50 1.2 µs, p99 210.0 µs, max 1.350 ms (N sends)`.
    pub fn summary(&self) -> String {
        let f = |p: f64| {
            self.percentile(p).map_or("-".to_string(), |ns| {
                if ns < 1_000_000 {
                    format!("{:.1} µs", ns as f64 / 1e3)
                } else {
                    format!("{:.3} ms", ns as f64 / 1e6)
                }
            })
        };
        format!(
            "send-time error: p50 {}, p99 {}, max {} ({} sends)",
            f(50.0),
            f(99.0),
            f(100.0),
            self.count()
        )
    }

    /// As JSON (µs).
    pub fn json(&self) -> Value {
        let us = |p: f64| self.percentile(p).map(|ns| ns as f64 / 1e3);
        json!({
            "sends": self.count(),
            "p50_us": us(50.0),
            "p99_us": us(99.0),
            "max_us": us(100.0),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;

    #[test]
    fn percentiles() {
        let mut t = SendTiming::default();
        assert_eq!(t.percentile(50.0), None);
        for i in 1..=100 {
            t.record(i * 1000);
        }
        assert_eq!(t.percentile(0.0), Some(1000));
        assert_eq!(t.percentile(100.0), Some(100_000));
        assert_eq!(t.percentile(50.0), Some(51_000));
        assert!(
            t.summary().contains("max 100.0 µs (100 sends)"),
            "{}",
            t.summary()
        );
    }

    #[test]
    fn wait_reaches_the_deadline_and_hands_over_events() {
        let clock = Clock::start();
        let (tx, rx) = mpsc::channel();
        tx.send(RxEvent::Data {
            t_ns: 0,
            bytes: vec![1],
        })
        .unwrap();
        let mut got = 0;
        let deadline = clock.now_ns() + 5_000_000;
        let w = wait_until(
            &clock,
            deadline,
            &rx,
            &mut |e| {
                got += e.is_some() as u32;
                false
            },
            &mut || None,
        );
        assert_eq!(w, Waited::Reached);
        assert!(clock.now_ns() >= deadline);
        assert_eq!(got, 1);
    }

    #[test]
    fn abort_ends_a_wait() {
        let clock = Clock::start();
        let (_tx, rx) = mpsc::channel();
        let w = wait_until(&clock, u64::MAX, &rx, &mut |_| false, &mut || {
            Some("SIGINT".into())
        });
        assert_eq!(w, Waited::Aborted("SIGINT".into()));
    }
}
