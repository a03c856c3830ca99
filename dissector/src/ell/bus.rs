//! The Elliptec bus: up to 16 modules on one line. Tracks each module's type and scaling (from
//! `IN` replies) across address changes (`ca`, `ga`), and pairs each host command with its reply.

use super::decode::{EllFrame, EllValue};
use super::table::{model, Answer, Class, Cmd, UNKNOWN_COMMAND};
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
    /// degree for rotary ones (their `IN` gives pulses per revolution: the manual's ELL4/ELL8
    /// row), per slot for indexed sliders and wheels (ELL6, ELL9, ELL12: position = slot ×
    /// pulses per position, slot 0 first).
    ///
    /// The manual's ELL6 example (p.9) gives 1 "pulse per position" with a travel of 0x1F,
    /// while its `ga` example (p.43) shows a slider's forward position as 0x1F: when `IN` says
    /// 0 or 1 pulses, the travel is the spacing.
    pub fn scale(&self) -> Option<(f64, &'static str)> {
        let m = model(self.model?)?;
        let p = self.pulses? as f64;
        match m.unit {
            "deg" => Some((p / 360.0, "deg")),
            "mm" => Some((p, "mm")),
            "slot" if p > 1.0 => Some((p, "slot")),
            "slot" => Some((self.travel? as f64, "slot")).filter(|(t, _)| *t > 0.0),
            _ => None,
        }
    }

    /// The slot of an indexed slider at `position` pulses, when it sits on one (within a tenth
    /// of the spacing) and the slider has it.
    pub fn slot(&self, position: i64) -> Option<u8> {
        let slots = model(self.model?)?.slots;
        let (ppp, "slot") = self.scale()? else {
            return None;
        };
        let x = position as f64 / ppp;
        let r = x.round();
        ((x - r).abs() <= 0.1 && r >= 0.0 && r < slots as f64).then_some(r as u8)
    }
}

/// A command waiting for its reply.
#[derive(Debug, Clone)]
struct Pending {
    n: u64,
    offset: u64,
    /// Address the (first) reply comes from.
    reply_addr: u8,
    /// Addresses replies may come from: the reply address, and a group's members' own.
    from: u16,
    /// Final replies expected (one per module of a group).
    expect: u8,
    /// Final replies seen.
    got: u8,
    /// The module the command addressed (its address once the command took effect).
    target: u8,
    cmd: &'static Cmd,
    ts: Option<u64>,
}

/// What the bus made of one frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Observation {
    /// Record number of the command this reply answers.
    pub pair: Option<u64>,
    /// Time from the command's first byte to the reply's.
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

/// Default reply timeout of a command: its row of the table (the manual's 2 s; motions 10 s;
/// the frequency search and current-curve scans 30 s).
pub fn timeout_ns(cmd: &Cmd) -> u64 {
    cmd.timeout_ns()
}

/// Bus state and pairing.
#[derive(Debug, Default)]
pub struct Bus {
    modules: [Option<Module>; 16],
    /// `ga`: bit X of `groups[Y]` is set while the module at X also answers at Y.
    groups: [u16; 16],
    pending: VecDeque<Pending>,
    /// Overrides the per-command default reply timeout.
    pub timeout_ns: Option<u64>,
}

/// Bound on commands waiting for replies (a host that never gets answers must not grow memory).
const MAX_PENDING: usize = 256;

fn bit(addr: u8) -> u16 {
    1 << (addr & 15)
}

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

    /// A module of the group at `addr` (the lowest address), when the address has one.
    fn member(&self, addr: u8) -> Option<&Module> {
        let g = self.groups[addr as usize & 15];
        (0..16u8)
            .filter(|a| g & bit(*a) != 0)
            .find_map(|a| self.module(a))
    }

    /// Drop commands whose timeout passed; those that got no reply at all are reported (a group
    /// command already answered by one module is not).
    fn expire(&mut self, now: Option<u64>, out: &mut Vec<Expired>) {
        let Some(now) = now else { return };
        let fixed = self.timeout_ns;
        self.pending.retain(|p| match p.ts {
            Some(t) if now > t.saturating_add(fixed.unwrap_or_else(|| p.cmd.timeout_ns())) => {
                if p.got == 0 {
                    out.push(p.into());
                }
                false
            }
            _ => true,
        });
    }

    /// Observe frame number `n` (with the time of its first byte, when known).
    pub fn observe(&mut self, n: u64, f: &EllFrame<'_>, ts: Option<u64>) -> Observation {
        let mut o = Observation::default();
        self.expire(ts, &mut o.expired);
        let addr = f.addr & 15;
        let cmd = match f.cmd {
            Some(c) => c,
            // An unknown host command is still a command: a module answers it (`GS` 03).
            None if f.dir() == Dir::HostToDevice => &UNKNOWN_COMMAND,
            None => return o,
        };
        if f.dir() == Dir::HostToDevice {
            self.command(n, f, cmd, ts, &mut o);
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
        let code = f.code_str();
        let status = f.field("status").and_then(|v| v.as_i64()).map(|s| s as u64);
        // The oldest command still waiting for its first reply; else a group command that has
        // more modules to hear from.
        let pick = |first: bool| {
            self.pending.iter().position(|p| {
                (p.got == 0) == first
                    && p.from & bit(addr) != 0
                    && p.cmd.answer(code, status) != Answer::No
            })
        };
        let found = pick(true).or_else(|| pick(false));
        let owner = match found.map(|i| &self.pending[i]) {
            // The `ca`/`ga` reply comes from the new address, for the module addressed.
            Some(p) if matches!(p.cmd.class, Class::Address | Class::Group) => p.target,
            _ => addr,
        };
        o.module = self.module(owner).or_else(|| self.member(addr)).cloned();
        let Some(i) = found else {
            o.unsolicited = cmd.class != Class::Spontaneous;
            return o;
        };
        let p = &mut self.pending[i];
        o.pair = Some(p.n);
        o.latency_ns = match (p.ts, ts) {
            (Some(a), Some(b)) => Some(b.saturating_sub(a)),
            _ => None,
        };
        if p.cmd.answer(code, status) == Answer::Interim {
            o.interim = true;
            return o;
        }
        p.got = p.got.saturating_add(1);
        let (done, ends_group, group_addr) = (
            p.got >= p.expect,
            p.cmd.class == Class::Motion,
            p.reply_addr,
        );
        // A group (`ga`) lasts for one operation: until a motion completes.
        if ends_group {
            self.groups[group_addr as usize] = 0;
        }
        if done {
            self.pending.remove(i);
        }
        o
    }

    /// A host command: address changes, then what replies to wait for.
    fn command(
        &mut self,
        n: u64,
        f: &EllFrame<'_>,
        cmd: &'static Cmd,
        ts: Option<u64>,
        o: &mut Observation,
    ) {
        let addr = f.addr & 15;
        let mut reply_addr = addr;
        let mut target = addr;
        if let Some(EllValue::Char(c)) = f.field("new_address") {
            let new = c.to_digit(16).unwrap_or(0) as u8 & 15;
            match cmd.class {
                Class::Address => {
                    let m = self.modules[addr as usize].take();
                    self.modules[new as usize] = m;
                    for g in &mut self.groups {
                        *g &= !bit(addr);
                    }
                    reply_addr = new;
                    target = new;
                }
                Class::Group => {
                    // A module listens to one group address at a time.
                    for g in &mut self.groups {
                        *g &= !bit(addr);
                    }
                    if new != addr {
                        self.groups[new as usize] |= bit(addr);
                    }
                    reply_addr = new;
                }
                _ => {}
            }
        }
        // The addressed module; after `ca` it already sits at its new address.
        o.module = self.module(target).or_else(|| self.module(addr)).cloned();
        if cmd.replies.is_empty() {
            return;
        }
        // A command sent to a group address is answered by every module of the group: from
        // the group address or from their own (the manual's example, p.43, has both sliders
        // answer `0fw`, from 0 and from 2).
        let members = match cmd.class {
            Class::Address | Class::Group => 0,
            _ => self.groups[addr as usize] & !bit(addr),
        };
        if self.pending.len() == MAX_PENDING {
            if let Some(p) = self.pending.pop_front() {
                if p.got == 0 {
                    o.expired.push((&p).into());
                }
            }
        }
        self.pending.push_back(Pending {
            n,
            offset: f.offset,
            reply_addr,
            from: bit(reply_addr) | members,
            expect: 1 + members.count_ones() as u8,
            got: 0,
            target,
            cmd,
            ts,
        });
    }

    /// End of stream: every command still waiting for its first reply got none.
    pub fn finish(&mut self) -> Vec<Expired> {
        self.pending
            .drain(..)
            .filter(|p| p.got == 0)
            .map(|p| (&p).into())
            .collect()
    }
}
