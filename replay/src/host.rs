//! Replaying as the host: the capture's host → device messages go to the device at their
//! captured times (or after the expected replies, `--wait-replies`); everything that comes back
//! is decoded, recorded and compared with the captured replies.

use crate::diff::{compare, Exchange, Report};
use crate::observe::Session;
use crate::port::Link;
use crate::safety::Moving;
use crate::sched::{wait_until, SendTiming, Waited};
use crate::script::{host_schedule, Msg, Script, Selection, Side, Timing};
use aptscope_capture::Writer;
use aptscope_dissector::detect::Proto;
use aptscope_dissector::pair::default_timeout_ns;
use aptscope_dissector::{ell, Table};
use std::collections::BTreeSet;
use std::io;

/// Options of [`run_host`].
#[derive(Debug, Clone)]
pub struct HostOptions {
    /// Speed and `--asap`.
    pub timing: Timing,
    /// Passes over the selection (`--loop`).
    pub loops: u32,
    /// Send each message only after the replies its captured request got (or a timeout).
    pub wait_replies: bool,
    /// How much longer than in the capture a reply may take before it counts as missing, ns;
    /// `None`: the timeout pairing gives the request ([`reply_allowance_ns`]).
    pub reply_timeout_ns: Option<u64>,
    /// On abort, stop the channels that replayed moves left moving (APT).
    pub stop_on_abort: bool,
    /// Fields not compared.
    pub ignore: Vec<String>,
    /// Render the live timeline.
    pub display: bool,
    /// … as NDJSON.
    pub json: bool,
    /// Say on standard error what a long wait for replies waits for (and, on a terminal, how
    /// long it has waited), instead of waiting in silence.
    pub say_waits: bool,
}

impl Default for HostOptions {
    fn default() -> Self {
        HostOptions {
            timing: Timing::default(),
            loops: 1,
            wait_replies: false,
            reply_timeout_ns: None,
            stop_on_abort: false,
            ignore: vec![],
            display: false,
            json: false,
            say_waits: false,
        }
    }
}

/// How a replay went.
#[derive(Debug, Default)]
pub struct Outcome {
    /// Messages in the schedule.
    pub planned: usize,
    /// Messages sent.
    pub sent: usize,
    /// Send-time errors.
    pub timing: SendTiming,
    /// Captured against observed replies.
    pub report: Report,
    /// Why the replay stopped early (a signal, the line gone).
    pub aborted: Option<String>,
    /// The other side went away (when, why).
    pub gone: Option<String>,
    /// Stop commands sent on abort.
    pub stops: Vec<String>,
    /// What was observed that is not a message.
    pub notes: Vec<String>,
    /// Length of the replay, ns.
    pub duration_ns: u64,
    /// The recording failed (the replay went on).
    pub record_error: Option<String>,
}

/// What a sent request waits for: its captured replies (name and channel) and how long.
struct Expect {
    want: Vec<(String, Option<i64>)>,
    /// Latest captured reply after the request, ns.
    captured_ns: u64,
    /// How much later than captured the replies may come, ns.
    allow_ns: u64,
}

/// How much later than in the capture the replies to `req` may come before they are missing:
/// `fixed` (`--reply-timeout`) when given, else the reply timeout pairing uses for the request
/// (APT: 2 s, 120 s for moves and homing; Elliptec: 2 s, longer for moves and scans), so a
/// capture without times (nothing captured to go by) still waits for a slow move.
pub fn reply_allowance_ns(proto: Proto, req: &Msg, fixed: Option<u64>) -> u64 {
    const DEFAULT: u64 = 2_000_000_000;
    fixed.unwrap_or_else(|| match proto {
        Proto::Apt => Table::global()
            .msg_by_name(&req.name)
            .map_or(DEFAULT, default_timeout_ns),
        Proto::Elliptec => req
            .raw
            .get(1..3)
            .and_then(ell::table::lookup)
            .map_or(DEFAULT, ell::timeout_ns),
    })
}

fn expectation(script: &Script, idx: usize, fixed: Option<u64>) -> Expect {
    let req = &script.msgs[idx];
    let mut e = Expect {
        want: vec![],
        captured_ns: 0,
        allow_ns: reply_allowance_ns(script.proto, req, fixed),
    };
    for &r in script.replies_to(idx) {
        let m = &script.msgs[r];
        e.want.push((m.name.clone(), m.channel()));
        if let (Some(a), Some(b)) = (m.ts_ns, req.ts_ns) {
            e.captured_ns = e.captured_ns.max(a.saturating_sub(b));
        }
    }
    e
}

/// Saying what a long wait for replies waits for: once, when more than [`Waiting::QUIET_NS`] of
/// it is left, then (on a terminal) a line counting the seconds.
struct Waiting {
    limit: u64,
    said: bool,
    terminal: bool,
    /// Seconds shown on the progress line.
    shown: Option<u64>,
    started: Option<u64>,
}

impl Waiting {
    /// A wait this short goes unsaid.
    const QUIET_NS: u64 = 3_000_000_000;

    fn new(limit: u64) -> Waiting {
        use std::io::IsTerminal;
        Waiting {
            limit,
            said: false,
            terminal: std::io::stderr().is_terminal(),
            shown: None,
            started: None,
        }
    }

    fn say(&mut self, now: u64, e: &Expect, outstanding: usize) {
        let left = self.limit.saturating_sub(now);
        if !self.said {
            if left <= Self::QUIET_NS {
                return;
            }
            let (name, chan) = &e.want[0];
            let chan = chan.map_or(String::new(), |c| format!(" ch{c}"));
            eprintln!(
                "replay: waiting up to {} s for {name}{chan} ({outstanding} repl{} outstanding)",
                left.div_ceil(1_000_000_000),
                if outstanding == 1 { "y" } else { "ies" }
            );
            self.said = true;
            self.started = Some(now);
        }
        let waited = now.saturating_sub(self.started.unwrap_or(now)) / 1_000_000_000;
        if self.terminal && self.shown != Some(waited) {
            eprint!(
                "\r  waited {waited} s of {} s\x1b[K",
                self.limit.saturating_sub(self.started.unwrap_or(now)) / 1_000_000_000
            );
            self.shown = Some(waited);
        }
    }

    /// The wait is over: the progress line goes.
    fn end(self) {
        if self.terminal && self.shown.is_some() {
            eprint!("\r\x1b[K");
        }
    }
}

/// Whether every wanted reply has been observed for the observed request `obs_req`; the time of
/// the last one (on the epoch clock) when so.
fn answered(sess: &Session<'_>, obs_req: Option<usize>, e: &Expect) -> Option<u64> {
    let msgs = sess.obs.msgs();
    let req = msgs.get(obs_req?)?;
    let got = sess.replies.get(&req.n).map(Vec::as_slice).unwrap_or(&[]);
    let mut used = vec![false; got.len()];
    let mut last = req.ts_ns.unwrap_or(0);
    for (name, ch) in &e.want {
        let k = got
            .iter()
            .enumerate()
            .position(|(j, &i)| !used[j] && msgs[i].name == *name && msgs[i].channel() == *ch)?;
        used[k] = true;
        last = last.max(msgs[got[k]].ts_ns.unwrap_or(0));
    }
    Some(last)
}

/// Replay the host side of `script` (as selected) on `link`. Lines of the live timeline go to
/// `out`; everything that crosses is recorded to `rec`; `abort` is asked often (a signal).
pub fn run_host<'a>(
    script: &Script,
    sel: &Selection,
    opts: &HostOptions,
    link: &mut Link,
    rec: Option<&'a mut dyn Writer>,
    out: &'a mut dyn FnMut(&str),
    abort: &mut dyn FnMut() -> Option<String>,
) -> io::Result<Outcome> {
    let timing = Timing {
        asap: opts.timing.asap || !script.has_times(),
        ..opts.timing
    };
    let plan = host_schedule(script, sel, timing, opts.loops);
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
    let mut o = Outcome {
        planned: plan.len(),
        ..Outcome::default()
    };
    let mut exchanges: Vec<Exchange> = Vec::with_capacity(plan.len());
    let mut sent_at: Vec<u64> = Vec::with_capacity(plan.len());
    let mut moving: BTreeSet<(u64, crate::safety::Moving)> = BTreeSet::new();
    let start = clock.now_ns();
    let mut shift: u64 = 0;
    let scale = |ns| timing.scale(ns);
    for s in &plan {
        let deadline = start.saturating_add(s.at_ns).saturating_add(shift);
        let w = wait_until(
            &clock,
            deadline,
            &link.rx,
            &mut |ev| {
                if let Some(ev) = ev {
                    sess.event(ev, Side::Device);
                }
                false
            },
            abort,
        );
        if let Waited::Aborted(why) = w {
            o.aborted = Some(why);
            break;
        }
        if let Some(g) = &sess.gone {
            o.aborted = Some(format!("the device went away: {g}"));
            break;
        }
        let m = &script.msgs[s.idx];
        let t = clock.now_ns();
        if let Err(e) = link.send(&m.raw) {
            o.aborted = Some(format!("writing to {name} failed: {e}"));
            break;
        }
        // Late by the time the bytes were handed over, not when the write began.
        o.timing.record(clock.now_ns().saturating_sub(deadline));
        o.sent += 1;
        let first = sess.crossed(Side::Host, t, &m.raw);
        let obs_idx = sess
            .obs
            .msgs()
            .get(first)
            .filter(|x| x.side == Side::Host)
            .map(|_| first);
        exchanges.push(Exchange {
            idx: s.idx,
            lap: s.lap,
            observed: obs_idx,
        });
        sent_at.push(t);
        if let (Some(mv), Some(i)) = (Moving::of(m), obs_idx) {
            moving.insert((sess.obs.msgs()[i].n, mv));
        }
        if opts.wait_replies {
            let e = expectation(script, s.idx, opts.reply_timeout_ns);
            if e.want.is_empty() {
                continue;
            }
            let limit = t.saturating_add(e.captured_ns).saturating_add(e.allow_ns);
            let mut got: Option<u64> = None;
            let mut waiting = opts.say_waits.then(|| Waiting::new(limit));
            let w = wait_until(
                &clock,
                limit,
                &link.rx,
                &mut |ev| {
                    if let Some(ev) = ev {
                        sess.event(ev, Side::Device);
                    }
                    got = answered(&sess, obs_idx, &e);
                    if let (Some(w), None) = (waiting.as_mut(), got) {
                        w.say(clock.now_ns(), &e, e.want.len());
                    }
                    got.is_some() || sess.gone.is_some()
                },
                abort,
            );
            if let Some(w) = waiting {
                w.end();
            }
            if let Waited::Aborted(why) = w {
                o.aborted = Some(why);
                break;
            }
            // Slower than in the capture: later messages keep their captured distance from
            // this reply.
            let arrived = got.map_or(clock.now_ns(), |ts| ts.saturating_sub(clock.epoch(0)));
            let planned = start
                .saturating_add(s.at_ns)
                .saturating_add(shift)
                .saturating_add(scale(e.captured_ns));
            shift = shift.saturating_add(arrived.saturating_sub(planned));
        }
        moving.retain(|(n, _)| !sess.replies.contains_key(n));
    }
    if o.aborted.is_none() {
        // Wait for the replies still due, and for the captured tail (status updates after the
        // last request), whichever is later.
        let tail = plan.last().map_or(0, |s| {
            let after = match (script.last_ts_in(sel), script.msgs[s.idx].ts_ns) {
                (Some(a), Some(b)) => a.saturating_sub(b),
                _ => 0,
            };
            start
                .saturating_add(s.at_ns)
                .saturating_add(shift)
                .saturating_add(scale(after))
        });
        let expects: Vec<(Option<usize>, Expect, u64)> = exchanges
            .iter()
            .zip(&sent_at)
            .map(|(x, &t)| {
                (
                    x.observed,
                    expectation(script, x.idx, opts.reply_timeout_ns),
                    t,
                )
            })
            .filter(|(_, e, _)| !e.want.is_empty())
            .collect();
        let limit = expects
            .iter()
            .map(|(_, e, t)| t.saturating_add(e.captured_ns).saturating_add(e.allow_ns))
            .max()
            .unwrap_or(0)
            .max(tail);
        let mut pending: Vec<usize> = (0..expects.len()).collect();
        let mut waiting = opts.say_waits.then(|| Waiting::new(limit));
        let w = wait_until(
            &clock,
            limit,
            &link.rx,
            &mut |ev| {
                if let Some(ev) = ev {
                    sess.event(ev, Side::Device);
                }
                pending.retain(|&k| answered(&sess, expects[k].0, &expects[k].1).is_none());
                let now = clock.now_ns();
                if let (Some(w), Some(&k)) = (waiting.as_mut(), pending.first()) {
                    w.say(now, &expects[k].1, pending.len());
                }
                (pending.is_empty() && now >= tail) || sess.gone.is_some()
            },
            abort,
        );
        if let Some(w) = waiting {
            w.end();
        }
        if let Waited::Aborted(why) = w {
            o.aborted = Some(why);
        }
    }
    moving.retain(|(n, _)| !sess.replies.contains_key(n));
    if o.aborted.is_some() && opts.stop_on_abort {
        let chans: BTreeSet<Moving> = moving.iter().map(|(_, m)| *m).collect();
        for mv in chans {
            if let Some(b) = mv.stop_command() {
                let t = clock.now_ns();
                if link.send(&b).is_ok() {
                    sess.crossed(Side::Host, t, &b);
                    o.stops
                        .push(format!("MOT_MOVE_STOP ch{} to 0x{:02X}", mv.chan, mv.dst));
                }
            }
        }
        // Take what is already there (the stops' answers, if quick).
        while let Ok(ev) = link.rx.try_recv() {
            sess.event(ev, Side::Device);
        }
    }
    o.duration_ns = clock.now_ns().saturating_sub(start);
    sess.finish();
    o.gone = sess.gone.clone();
    o.record_error = sess.record_error.clone();
    o.notes = sess.obs.notes().to_vec();
    let laps = opts.loops.max(1);
    o.report = compare(
        script,
        &exchanges,
        sess.obs.msgs(),
        &|m| sel.in_range(script, m),
        if o.aborted.is_some() { 0 } else { laps },
        &opts.ignore,
    );
    Ok(o)
}
