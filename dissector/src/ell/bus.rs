//! The Elliptec bus: up to 16 modules on one line. Tracks each module's type and scaling (from
//! `IN` replies) across address changes (`ca`, `ga`), and pairs each host command with its reply.

use super::decode::{EllFrame, EllValue};
use super::table::{model, Cmd};
use crate::table::Dir;
use std::collections::VecDeque;

/// What the bus knows of a module.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Module {
    /// ELL model number.
    pub model: Option<u8>,
    /// Serial number.
    pub serial: Option<String>,
    /// Travel (mm or degrees).
    pub travel: Option<u64>,
    /// Encoder pulses per measurement unit as the `IN` reply gives it.
    pub pulses: Option<u64>,
    /// Address the module had when first seen (stable identity across `ca`).
    pub first_addr: u8,
}

impl Module {
    /// Pulses per physical unit and the unit, when known: pulses per mm for linear stages, per
    /// degree for rotary ones (their `IN` gives pulses per revolution: the manual's ELL4/ELL8 row).
    pub fn scale(&self) -> Option<(f64, &'static str)> {
        let m = model(self.model?)?;
        let p = self.pulses? as f64;
        match m.unit {
            "deg" => Some((p / 360.0, "deg")),
            "mm" => Some((p, "mm")),
            _ => None,
        }
    }
}

/// A command waiting for its reply.
#[derive(Debug, Clone)]
struct Pending {
    n: u64,
    offset: u64,
    reply_addr: u8,
    cmd: &'static Cmd,
    ts: Option<u64>,
}

/// What the bus made of one frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Observation {
    /// Record number of the command this reply answers.
    pub pair: Option<u64>,
    /// Time from the end of the command to the end of the reply.
    pub latency_ns: Option<u64>,
    /// A reply no pending command expected (button messages `BS`/`BO` excepted).
    pub unsolicited: bool,
    /// A `GS` busy reply to a motion command: the final reply is still to come.
    pub interim: bool,
    /// The module the frame concerns, after address changes.
    pub module: Option<Module>,
    /// Commands whose timeout passed before this frame.
    pub expired: Vec<Expired>,
}

/// A command that got no reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Expired {
    /// Its record number.
    pub n: u64,
    /// Its stream offset.
    pub offset: u64,
    /// Its mnemonic.
    pub code: &'static str,
}

impl From<&Pending> for Expired {
    fn from(p: &Pending) -> Self {
        Expired {
            n: p.n,
            offset: p.offset,
            code: p.cmd.code,
        }
    }
}

/// Default reply timeout: the manual gives modules a 2 s timeout; motion and scans reply when
/// done (the current-curve scan takes about 12 s).
pub fn timeout_ns(cmd: &Cmd) -> u64 {
    const S: u64 = 1_000_000_000;
    match cmd.code {
        "c1" | "c2" | "s1" | "s2" => 30 * S,
        _ if cmd.is_move() => 10 * S,
        _ => 2 * S,
    }
}

/// Bus state and pairing.
#[derive(Debug, Default)]
pub struct Bus {
    modules: [Option<Module>; 16],
    /// `ga`: address Y temporarily answered by the module at X.
    alias: [Option<u8>; 16],
    pending: VecDeque<Pending>,
    /// Overrides the per-command default reply timeout.
    pub timeout_ns: Option<u64>,
}

/// Bound on commands waiting for replies (a host that never gets answers must not grow memory).
const MAX_PENDING: usize = 256;

impl Bus {
    /// An empty bus.
    pub fn new() -> Self {
        Self::default()
    }

    /// The module known at an address.
    pub fn module(&self, addr: u8) -> Option<&Module> {
        self.modules.get(addr as usize)?.as_ref()
    }

    fn module_mut(&mut self, addr: u8) -> &mut Module {
        let a = addr as usize & 15;
        self.modules[a].get_or_insert_with(|| Module {
            first_addr: addr,
            ..Module::default()
        })
    }

    fn expire(&mut self, now: Option<u64>, out: &mut Vec<Expired>) {
        let Some(now) = now else { return };
        let fixed = self.timeout_ns;
        self.pending.retain(|p| match p.ts {
            Some(t) if now > t.saturating_add(fixed.unwrap_or_else(|| timeout_ns(p.cmd))) => {
                out.push(p.into());
                false
            }
            _ => true,
        });
    }

    /// Observe frame number `n` (with the time of its last byte, when known).
    pub fn observe(&mut self, n: u64, f: &EllFrame<'_>, ts: Option<u64>) -> Observation {
        let mut o = Observation::default();
        self.expire(ts, &mut o.expired);
        let addr = f.addr;
        let Some(cmd) = f.cmd else {
            return o;
        };
        if f.dir() == Dir::HostToDevice {
            let mut reply_addr = addr;
            if let Some(EllValue::Char(c)) = f.field("new_address") {
                let new = c.to_digit(16).unwrap_or(0) as u8;
                reply_addr = new;
                match cmd.code {
                    "ca" => {
                        let m = self.modules[addr as usize & 15].take();
                        self.modules[new as usize & 15] = m;
                    }
                    _ => self.alias[new as usize & 15] = Some(addr),
                }
            }
            // The addressed module; after `ca` it already sits at its new address.
            o.module = self
                .module(addr)
                .or_else(|| self.module(reply_addr))
                .cloned();
            if !cmd.replies.is_empty() {
                if self.pending.len() == MAX_PENDING {
                    if let Some(p) = self.pending.pop_front() {
                        o.expired.push((&p).into());
                    }
                }
                self.pending.push_back(Pending {
                    n,
                    offset: f.offset,
                    reply_addr,
                    cmd,
                    ts,
                });
            }
            return o;
        }
        // A module reply.
        if cmd.code == "IN" {
            let m = self.module_mut(addr);
            for (fd, v) in f.fields() {
                match (fd.name, v) {
                    ("model", EllValue::U(x)) => m.model = u8::try_from(x).ok(),
                    ("serial", EllValue::Digits(s)) => m.serial = Some(s.to_string()),
                    ("travel", EllValue::U(x)) => m.travel = Some(x),
                    ("pulses_per_unit", EllValue::U(x)) => m.pulses = Some(x),
                    _ => {}
                }
            }
        }
        let owner = self.alias[addr as usize & 15].unwrap_or(addr);
        o.module = self.module(owner).or_else(|| self.module(addr)).cloned();
        let code = f.code_str();
        let found = self
            .pending
            .iter()
            .position(|p| p.reply_addr == addr && p.cmd.replies.contains(&code));
        match found {
            Some(i) => {
                let p = &self.pending[i];
                o.pair = Some(p.n);
                o.latency_ns = match (p.ts, ts) {
                    (Some(a), Some(b)) => Some(b.saturating_sub(a)),
                    _ => None,
                };
                let busy = code == "GS" && matches!(f.field("status"), Some(EllValue::U(9)));
                o.interim = p.cmd.is_move() && busy;
                if !o.interim {
                    // A group (`ga`) lasts for one operation: until a motion completes.
                    if p.cmd.is_move() {
                        self.alias[addr as usize & 15] = None;
                    }
                    self.pending.remove(i);
                }
            }
            None => o.unsolicited = !matches!(code, "BS" | "BO"),
        }
        o
    }

    /// End of stream: every command still waiting got no reply.
    pub fn finish(&mut self) -> Vec<Expired> {
        self.pending.drain(..).map(|p| (&p).into()).collect()
    }
}
