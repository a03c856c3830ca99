//! Motion profiles: what a move is and where it is at a given time.

use super::*;

/// What a motion is, for status bits and the completion message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Kind {
    Move,
    Jog,
    Home,
    /// A velocity move or continuous jog: runs to the end of travel unless stopped.
    Velocity,
    /// Decelerating after MOT_MOVE_STOP (profiled).
    Stopping,
}

/// A 1-D motion: accelerate from `v0` to `vpeak`, cruise, decelerate to rest.
#[derive(Debug, Clone, Copy)]
pub(super) struct Motion {
    pub(super) kind: Kind,
    pub(super) start_ns: u64,
    pub(super) from: i64,
    /// Where it ends (exactly).
    pub(super) to: i64,
    pub(super) dir: i64,
    pub(super) v0: f64,
    pub(super) vpeak: f64,
    pub(super) a: f64,
    pub(super) t1: f64,
    pub(super) t2: f64,
    pub(super) t3: f64,
    /// Channel the host named, for the completion message.
    pub(super) chan: i64,
    /// Ends without a completion message: the model's table profile says it sends none for
    /// the request that started it (`silent`: a flipper's MOT_MOVE_JOG).
    pub(super) silent: bool,
}

impl Motion {
    /// A trapezoidal move from rest to rest.
    pub(super) fn trapezoid(
        kind: Kind,
        now: u64,
        from: i64,
        to: i64,
        v: f64,
        a: f64,
        chan: i64,
    ) -> Motion {
        let d = (to - from).unsigned_abs() as f64;
        let (vpeak, t1, t2) = if d >= v * v / a {
            (v, v / a, (d - v * v / a) / v)
        } else {
            let vp = (a * d).sqrt();
            (vp, vp / a, 0.0)
        };
        Motion {
            kind,
            start_ns: now,
            from,
            to,
            dir: if to >= from { 1 } else { -1 },
            v0: 0.0,
            vpeak,
            a,
            t1,
            t2,
            t3: t1,
            chan,
            silent: false,
        }
    }

    /// Constant speed for `secs` (homing).
    pub(super) fn linear(kind: Kind, now: u64, from: i64, to: i64, secs: f64, chan: i64) -> Motion {
        let d = (to - from).unsigned_abs() as f64;
        Motion {
            kind,
            start_ns: now,
            from,
            to,
            dir: if to >= from { 1 } else { -1 },
            v0: d / secs,
            vpeak: d / secs,
            a: 0.0,
            t1: 0.0,
            t2: secs,
            t3: 0.0,
            chan,
            silent: false,
        }
    }

    pub(super) fn total_s(&self) -> f64 {
        self.t1 + self.t2 + self.t3
    }

    pub(super) fn end_ns(&self) -> u64 {
        self.start_ns
            .saturating_add((self.total_s() * SEC as f64).min(1e18) as u64)
    }

    /// Distance covered and speed (counts, counts/s) at `now`.
    pub(super) fn at(&self, now: u64) -> (f64, f64) {
        let t = now.saturating_sub(self.start_ns) as f64 / SEC as f64;
        let x1 = self.v0 * self.t1 + 0.5 * self.a * self.t1 * self.t1;
        let x2 = x1 + self.vpeak * self.t2;
        if t < self.t1 {
            (self.v0 * t + 0.5 * self.a * t * t, self.v0 + self.a * t)
        } else if t < self.t1 + self.t2 {
            (x1 + self.vpeak * (t - self.t1), self.vpeak)
        } else if t < self.total_s() {
            let tau = t - self.t1 - self.t2;
            (
                x2 + self.vpeak * tau - 0.5 * self.a * tau * tau,
                (self.vpeak - self.a * tau).max(0.0),
            )
        } else {
            ((self.to - self.from).unsigned_abs() as f64, 0.0)
        }
    }

    /// Position and speed at `now`.
    pub(super) fn pos(&self, now: u64) -> (i64, f64) {
        if now >= self.end_ns() {
            return (self.to, 0.0);
        }
        let (d, v) = self.at(now);
        (self.from + self.dir * d.round() as i64, v)
    }
}
