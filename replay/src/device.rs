//! Replaying as the device: impersonate the captured controller towards a host program. Each
//! request the host sends is matched to a captured request (the same bytes, else the same
//! message to the same channel and address, else the same message), and answered with that
//! request's captured replies at their captured latency; unsolicited messages (status updates)
//! follow the request that preceded them in the capture, at their captured distance from it.

use crate::observe::Session;
use crate::port::Link;
use crate::sched::{wait_until, SendTiming, Waited};
use crate::script::{Msg, Script, Selection, Side};
use serde_json::{json, Value};
use std::cmp::Reverse;
use std::collections::{BTreeMap, BinaryHeap, HashMap};
use std::fmt::Write;
use std::io;

/// What answering one request gives: the captured request it matched and the device messages
/// to send, each `delay_ns` after the request arrived.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Answer {
    /// Index of the captured request matched.
    pub matched: Option<usize>,
    /// It had been used already (the host asks more often than in the capture).
    pub reused: bool,
    /// (delay after the request, index of the captured device message).
    pub out: Vec<(u64, usize)>,
}

type Key = (String, Option<i64>, Option<u8>);

/// The matching of host requests to captured ones (pure: no I/O, no clock).
#[derive(Debug)]
pub struct Responder {
    by_raw: HashMap<Vec<u8>, Vec<usize>>,
    by_kind: HashMap<Key, Vec<usize>>,
    by_name: HashMap<String, Vec<usize>>,
    used: Vec<bool>,
    last: HashMap<usize, usize>,
    /// Device messages sent in answer to each captured request: its replies and the
    /// unsolicited ones until the next request, with their distance from it.
    follow: HashMap<usize, Vec<(u64, usize)>>,
    prelude: Vec<(u64, usize)>,
    speed: f64,
}

/// A message's kind: its name, channel and address (APT destination, Elliptec module).
fn kind(m: &Msg) -> Key {
    (m.name.clone(), m.channel(), m.addr)
}

fn take(list: Option<&Vec<usize>>, used: &[bool]) -> Option<usize> {
    list?.iter().copied().find(|&i| !used[i])
}

impl Responder {
    /// Index the captured requests and what followed each; only device messages `sel` selects
    /// are ever sent. `speed` scales the captured delays.
    pub fn new(script: &Script, sel: &Selection, speed: f64) -> Responder {
        let mut r = Responder {
            by_raw: HashMap::new(),
            by_kind: HashMap::new(),
            by_name: HashMap::new(),
            used: vec![false; script.msgs.len()],
            last: HashMap::new(),
            follow: HashMap::new(),
            prelude: vec![],
            speed: if speed > 0.0 { speed } else { 1.0 },
        };
        let t0 = script.first_ts();
        let mut prev_host: Option<usize> = None;
        for (i, m) in script.msgs.iter().enumerate() {
            if !sel.in_range(script, m) {
                continue;
            }
            match m.side {
                Side::Host => {
                    r.by_raw.entry(m.raw.clone()).or_default().push(i);
                    r.by_kind.entry(kind(m)).or_default().push(i);
                    r.by_name.entry(m.name.clone()).or_default().push(i);
                    prev_host = Some(i);
                }
                Side::Device => {
                    if !sel.selects(script, m, Side::Device) {
                        continue;
                    }
                    let anchor = match m.pair.and_then(|p| script.index_of(p)) {
                        Some(q) => Some(q),
                        None => prev_host,
                    };
                    let since = |a: Option<u64>| match (m.ts_ns, a) {
                        (Some(x), Some(y)) => x.saturating_sub(y),
                        _ => 0,
                    };
                    match anchor {
                        Some(q) => {
                            let d = since(script.msgs[q].ts_ns);
                            r.follow.entry(q).or_default().push((d, i));
                        }
                        None => r.prelude.push((since(t0), i)),
                    }
                }
            }
        }
        r
    }

    fn scaled(&self, v: &[(u64, usize)]) -> Vec<(u64, usize)> {
        v.iter()
            .map(|&(d, i)| ((d as f64 / self.speed) as u64, i))
            .collect()
    }

    /// Device messages captured before the host's first request, with their time from the
    /// capture's start.
    pub fn prelude(&self) -> Vec<(u64, usize)> {
        self.scaled(&self.prelude)
    }

    /// Answer the observed request `req`.
    pub fn respond(&mut self, req: &Msg) -> Answer {
        let k = kind(req);
        let fresh = take(self.by_raw.get(&req.raw), &self.used)
            .or_else(|| take(self.by_kind.get(&k), &self.used))
            .or_else(|| take(self.by_name.get(&req.name), &self.used));
        let (matched, reused) = match fresh {
            Some(i) => {
                self.used[i] = true;
                for key in [0usize, 1, 2] {
                    if let Some(slot) = self.slot(key, req) {
                        self.last.insert(slot, i);
                    }
                }
                (Some(i), false)
            }
            None => {
                let again = [0usize, 1, 2]
                    .iter()
                    .find_map(|&key| self.last.get(&self.slot(key, req)?).copied());
                (again, again.is_some())
            }
        };
        let out = matched
            .and_then(|i| self.follow.get(&i))
            .map(|v| self.scaled(v))
            .unwrap_or_default();
        Answer {
            matched,
            reused,
            out,
        }
    }

    /// A number standing for one of the three keys of `req` (for `last`): the first index
    /// stored under that key, which identifies it.
    fn slot(&self, key: usize, req: &Msg) -> Option<usize> {
        let list = match key {
            0 => self.by_raw.get(&req.raw),
            1 => self.by_kind.get(&kind(req)),
            _ => self.by_name.get(&req.name),
        };
        list.and_then(|l| l.first()).map(|i| i * 3 + key)
    }
}

/// Options of [`run_device`].
#[derive(Debug, Clone)]
pub struct DeviceOptions {
    /// Time factor for the captured delays.
    pub speed: f64,
    /// Stop after this long (ns); otherwise when the host hangs up or on a signal.
    pub duration_ns: Option<u64>,
    /// Render the live timeline.
    pub display: bool,
    /// … as NDJSON.
    pub json: bool,
}

impl Default for DeviceOptions {
    fn default() -> Self {
        DeviceOptions {
            speed: 1.0,
            duration_ns: None,
            display: false,
            json: false,
        }
    }
}

/// How impersonating the device went.
#[derive(Debug, Default)]
pub struct DeviceOutcome {
    /// Requests the host sent.
    pub requests: usize,
    /// … answered from the capture.
    pub answered: usize,
    /// … of which with a captured request used before (the host asked more often).
    pub reused: usize,
    /// Requests with no captured counterpart, by name.
    pub unmatched: BTreeMap<String, usize>,
    /// Device messages sent.
    pub sent: usize,
    /// Send-time errors.
    pub timing: SendTiming,
    /// Why it ended early (a signal).
    pub aborted: Option<String>,
    /// The host went away (when, why).
    pub gone: Option<String>,
    /// What was observed that is not a message.
    pub notes: Vec<String>,
    /// Length, ns.
    pub duration_ns: u64,
    /// The recording failed.
    pub record_error: Option<String>,
}

impl DeviceOutcome {
    /// The summary as text.
    pub fn text(&self) -> String {
        let mut s = format!(
            "# requests: {} from the host, {} answered from the capture ({} reused), {} without a captured answer\n",
            self.requests,
            self.answered,
            self.reused,
            self.requests - self.answered
        );
        for (n, c) in &self.unmatched {
            let _ = writeln!(s, "UNMATCHED {n} ×{c}");
        }
        let _ = writeln!(
            s,
            "# {} device messages sent; {}",
            self.sent,
            self.timing.summary()
        );
        s
    }

    /// The summary as JSON.
    pub fn json(&self) -> Value {
        json!({
            "requests": self.requests,
            "answered": self.answered,
            "reused": self.reused,
            "unmatched": self.unmatched,
            "sent": self.sent,
            "timing": self.timing.json(),
        })
    }
}

/// Impersonate the device of `script` on `link` until the host hangs up, `abort` says so, or
/// `opts.duration_ns` passes.
pub fn run_device<'a>(
    script: &Script,
    sel: &Selection,
    opts: &DeviceOptions,
    link: &mut Link,
    rec: Option<&'a mut dyn aptscope_capture::Writer>,
    out: &'a mut dyn FnMut(&str),
    abort: &mut dyn FnMut() -> Option<String>,
) -> io::Result<DeviceOutcome> {
    let clock = link.clock;
    let name = link.name.clone();
    let mut sess = Session::new(
        script.proto,
        clock,
        &name,
        rec,
        out,
        opts.display,
        opts.json,
    );
    let mut resp = Responder::new(script, sel, opts.speed);
    let mut o = DeviceOutcome::default();
    let start = clock.now_ns();
    let end = opts
        .duration_ns
        .map_or(u64::MAX, |d| start.saturating_add(d));
    // Due device messages: (due, sequence, message index).
    let mut queue: BinaryHeap<Reverse<(u64, u64, usize)>> = BinaryHeap::new();
    let mut seq = 0u64;
    for (d, i) in resp.prelude() {
        queue.push(Reverse((start.saturating_add(d), seq, i)));
        seq += 1;
    }
    loop {
        let next = queue.peek().map_or(end, |Reverse((d, _, _))| (*d).min(end));
        let w = wait_until(
            &clock,
            next,
            &link.rx,
            &mut |ev| {
                let Some(ev) = ev else {
                    return sess.gone.is_some();
                };
                let t = match &ev {
                    crate::port::RxEvent::Data { t_ns, .. } => *t_ns,
                    crate::port::RxEvent::Gone { .. } => 0,
                };
                let before = sess.obs.msgs().len();
                sess.event(ev, Side::Host);
                let new: Vec<Msg> = sess.obs.msgs()[before..]
                    .iter()
                    .filter(|m| m.side == Side::Host)
                    .cloned()
                    .collect();
                let mut early = false;
                for m in new {
                    o.requests += 1;
                    let a = resp.respond(&m);
                    match a.matched {
                        Some(_) => {
                            o.answered += 1;
                            o.reused += a.reused as usize;
                        }
                        None => *o.unmatched.entry(m.name.clone()).or_default() += 1,
                    }
                    for (d, i) in a.out {
                        let due = t.saturating_add(d);
                        early |= due < next;
                        queue.push(Reverse((due, seq, i)));
                        seq += 1;
                    }
                }
                early || sess.gone.is_some()
            },
            abort,
        );
        if let Waited::Aborted(why) = w {
            o.aborted = Some(why);
            break;
        }
        if sess.gone.is_some() {
            break;
        }
        let now = clock.now_ns();
        if now >= end {
            break;
        }
        while let Some(Reverse((due, _, i))) = queue.peek().copied() {
            if due > clock.now_ns() {
                break;
            }
            queue.pop();
            let t = clock.now_ns();
            let raw = &script.msgs[i].raw;
            if let Err(e) = link.send(raw) {
                sess.gone = Some(format!("writing to {name} failed: {e}"));
                break;
            }
            o.timing.record(clock.now_ns().saturating_sub(due));
            o.sent += 1;
            sess.crossed(Side::Device, t, raw);
        }
        if sess.gone.is_some() {
            break;
        }
    }
    o.duration_ns = clock.now_ns().saturating_sub(start);
    sess.finish();
    o.gone = sess.gone.clone();
    o.record_error = sess.record_error.clone();
    o.notes = sess.obs.notes().to_vec();
    Ok(o)
}

#[cfg(test)]
mod tests {
    use super::*;
    use aptscope_dissector::detect::Proto;

    fn script(msgs: Vec<Msg>) -> Script {
        Script::new(Proto::Apt, msgs, vec![], "t".into())
    }

    /// A message to address 0x50 on channel 1, with these bytes (hex).
    fn rec(n: u64, name: &str, raw: &str, side: Side, ts: u64, pair: Option<u64>) -> Msg {
        let mut m = Msg::fixture(n, name, side, ts, pair);
        m.raw = (0..raw.len() / 2)
            .filter_map(|i| u8::from_str_radix(raw.get(2 * i..2 * i + 2)?, 16).ok())
            .collect();
        m.addr = Some(0x50);
        m
    }

    fn session() -> Script {
        script(vec![
            rec(1, "HW_REQ_INFO", "01", Side::Host, 1_000, None),
            rec(2, "HW_GET_INFO", "02", Side::Device, 3_000, Some(1)),
            rec(3, "MOT_MOVE_ABSOLUTE", "03aa", Side::Host, 10_000, None),
            rec(
                4,
                "MOT_GET_DCSTATUSUPDATE",
                "04",
                Side::Device,
                20_000,
                None,
            ),
            rec(5, "MOT_MOVE_COMPLETED", "05", Side::Device, 90_000, Some(3)),
            rec(6, "MOT_MOVE_ABSOLUTE", "03bb", Side::Host, 100_000, None),
            rec(
                7,
                "MOT_MOVE_COMPLETED",
                "06",
                Side::Device,
                150_000,
                Some(6),
            ),
        ])
    }

    fn req(s: &Script, raw: &str, name: &str) -> Msg {
        let _ = s;
        rec(99, name, raw, Side::Host, 0, None)
    }

    #[test]
    fn a_request_gets_its_captured_replies_and_followers() {
        let s = session();
        let mut r = Responder::new(&s, &Selection::default(), 1.0);
        let a = r.respond(&req(&s, "01", "HW_REQ_INFO"));
        assert_eq!(a.matched, Some(0));
        assert_eq!(a.out, vec![(2_000, 1)]);
        let a = r.respond(&req(&s, "03aa", "MOT_MOVE_ABSOLUTE"));
        assert_eq!(
            a.out,
            vec![(10_000, 3), (80_000, 4)],
            "update, then completion"
        );
    }

    #[test]
    fn exact_bytes_first_then_the_same_message() {
        let s = session();
        let mut r = Responder::new(&s, &Selection::default(), 2.0);
        // The second captured move, by its bytes, although the first is unused.
        let a = r.respond(&req(&s, "03bb", "MOT_MOVE_ABSOLUTE"));
        assert_eq!(a.matched, Some(5));
        assert_eq!(a.out, vec![(25_000, 6)], "delays scaled by the speed");
        // Another position: the first unused move.
        let a = r.respond(&req(&s, "03cc", "MOT_MOVE_ABSOLUTE"));
        assert_eq!(a.matched, Some(2));
        // Asked again: the last one is used again.
        let a = r.respond(&req(&s, "03cc", "MOT_MOVE_ABSOLUTE"));
        assert_eq!((a.matched, a.reused), (Some(2), true));
        let a = r.respond(&req(&s, "09", "MOD_IDENTIFY"));
        assert_eq!(a, Answer::default(), "nothing captured");
    }
}
