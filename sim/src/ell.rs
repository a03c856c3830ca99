//! The Elliptec bus simulator.

use super::{earliest, Line, Simulator, MS, SEC};
use aptscope_dissector::ell::{head, EllFrame};
use aptscope_dissector::table::Dir;

/// Longest line kept while waiting for the end of a command.
const MAX_LINE: usize = 64;
/// 9600 baud, 8N1: 10 bits per byte.
const BYTE_NS: u64 = 1_041_667;
/// Time from a command to the first byte of its reply.
const TURNAROUND_NS: u64 = 2 * MS;
/// Fixed overhead of every motion (start-up, settling).
const MOVE_OVERHEAD_NS: u64 = 50 * MS;

// Status codes (GS).
const OK: u8 = 0;
const COMMAND_ERROR: u8 = 3;
const BUSY: u8 = 9;
const OUT_OF_RANGE: u8 = 12;

/// How a module moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mech {
    /// Rotation: positions in pulses, `pulses` per revolution, any position accepted.
    Rotary,
    /// Linear stage: 0..=travel × pulses.
    Linear,
    /// Indexed slider: `n` positions `pulses` apart.
    Indexed(u8),
}

/// An ELL module type: what its `IN` reply says and how it moves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EllModel {
    /// ELL number (14 for ELL14).
    pub number: u8,
    /// Travel (mm, degrees, or positions × pulses for sliders) as `IN` gives it.
    pub travel: u16,
    /// Pulses per unit as `IN` gives it (per mm; per revolution for rotary; per position step
    /// for sliders).
    pub pulses: u32,
    mech: Mech,
    /// Full speed in units (mm or degrees) per second, or positions per second for sliders.
    speed: f64,
}

impl EllModel {
    /// The model with this name (`ELL14`, `ell9`, `14`), among those simulated: ELL6, ELL9,
    /// ELL12, ELL14, ELL17, ELL18, ELL20.
    pub fn parse(s: &str) -> Option<EllModel> {
        let s = s.trim();
        let n = s
            .strip_prefix("ELL")
            .or_else(|| s.strip_prefix("ell"))
            .or_else(|| s.strip_prefix("Ell"))
            .unwrap_or(s);
        let number: u8 = n.parse().ok()?;
        let (travel, pulses, mech, speed) = match number {
            6 => (0x1F, 0x1F, Mech::Indexed(2), 3.0),
            9 => (0x13, 0x20, Mech::Indexed(4), 3.0),
            12 => (0x1F, 0x20, Mech::Indexed(6), 3.0),
            14 => (360, 0x23000, Mech::Rotary, 430.0),
            17 => (0x1C, 0x800, Mech::Linear, 180.0),
            18 => (360, 0x40000, Mech::Rotary, 430.0),
            20 => (60, 0x400, Mech::Linear, 180.0),
            _ => return None,
        };
        Some(EllModel {
            number,
            travel,
            pulses,
            mech,
            speed,
        })
    }

    /// Lowest and highest position in pulses (`None`: unbounded, rotary).
    fn range(&self) -> Option<(i64, i64)> {
        match self.mech {
            Mech::Rotary => None,
            Mech::Linear => Some((0, self.travel as i64 * self.pulses as i64)),
            Mech::Indexed(n) => Some((0, (n as i64 - 1) * self.pulses as i64)),
        }
    }

    /// Pulses per second at full speed.
    fn pulses_per_s(&self) -> f64 {
        match self.mech {
            Mech::Rotary => self.speed * self.pulses as f64 / 360.0,
            _ => self.speed * self.pulses as f64,
        }
    }

    fn default_jog(&self) -> i64 {
        match self.mech {
            Mech::Rotary => self.pulses as i64 / 36,
            Mech::Linear | Mech::Indexed(_) => self.pulses as i64,
        }
    }
}

/// A running motion: it ends at `end_ns` at `to`, answering `PO` from `reply_addr`.
#[derive(Debug, Clone, Copy)]
struct Move {
    start_ns: u64,
    end_ns: u64,
    from: i64,
    to: i64,
    reply_addr: u8,
}

#[derive(Debug, Clone)]
struct Module {
    addr: u8,
    model: EllModel,
    serial: String,
    pos: i64,
    jog: i64,
    home_offset: i64,
    velocity: u8,
    /// `ga`: the module also listens at this address until its next motion completes.
    group: Option<u8>,
    motion: Option<Move>,
    /// `is`: silent until this time.
    isolated_until: u64,
    /// Last error, reported (and cleared) by the next `gs`.
    error: u8,
}

impl Module {
    fn position(&self, now: u64) -> i64 {
        match self.motion {
            Some(m) if now < m.end_ns && m.end_ns > m.start_ns => {
                let f = (now - m.start_ns) as f64 / (m.end_ns - m.start_ns) as f64;
                m.from + ((m.to - m.from) as f64 * f).round() as i64
            }
            Some(m) => m.to,
            None => self.pos,
        }
    }

    fn reported(&self, p: i64) -> i64 {
        match self.model.mech {
            Mech::Rotary if self.model.pulses > 0 => p.rem_euclid(self.model.pulses as i64),
            _ => p,
        }
    }
}

/// A simulated Elliptec bus (sans-io): see the [module docs](super).
///
/// Modules answer commands at their address (and at a `ga` group address until their next
/// motion completes); `ca` moves a module to a new address at once, and its `GS` reply comes
/// from there. A motion replies `PO` when it ends; while it runs, `gs` answers `GS09` (busy) and
/// further motion commands are refused with `GS09`. Unknown or malformed commands get `GS03`, a
/// target outside the travel `GS0C`.
#[derive(Debug)]
pub struct EllSim {
    modules: Vec<Module>,
    /// Input not yet framed.
    pending: Vec<u8>,
    line: Line,
}

/// Why a simulator could not be made.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SimError {
    /// An APT model that is not simulated.
    #[error("unknown model `{0}` (`aptscope sim apt --list` lists them)")]
    UnknownApt(String),
    /// A part of the module list that is not `ADDRESS:MODEL`.
    #[error("`{0}`: expected ADDRESS:MODEL, e.g. 0:ELL14")]
    NotAddrModel(String),
    /// An address that is not one hex digit.
    #[error("`{0}`: an address is 0-F")]
    BadAddress(String),
    /// A model that is not simulated.
    #[error("`{0}`: unknown module (ELL6, ELL9, ELL12, ELL14, ELL17, ELL18, ELL20)")]
    UnknownModel(String),
    /// An empty module list.
    #[error("no modules given (e.g. 0:ELL14,1:ELL9)")]
    NoModules,
    /// An address beyond the bus's 16.
    #[error("address {0} is beyond F")]
    BeyondF(u8),
    /// Two modules given the same address.
    #[error("two modules at address {0:X}")]
    TwoAt(u8),
}

/// Parse a module list: `0:ELL14,1:ELL9,A:ELL20` (address `0`–`F`, model).
pub fn parse_modules(s: &str) -> Result<Vec<(u8, EllModel)>, SimError> {
    let mut out = vec![];
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (a, m) = part
            .split_once(':')
            .ok_or_else(|| SimError::NotAddrModel(part.to_string()))?;
        let addr = u8::from_str_radix(a.trim(), 16)
            .ok()
            .filter(|a| *a < 16)
            .ok_or_else(|| SimError::BadAddress(a.to_string()))?;
        let model = EllModel::parse(m).ok_or_else(|| SimError::UnknownModel(m.to_string()))?;
        out.push((addr, model));
    }
    if out.is_empty() {
        return Err(SimError::NoModules);
    }
    Ok(out)
}

/// Frame the next host command at the start of `b` (dropping leading garbage by reporting it
/// as a frame the decoder rejects): its length, or `None` when more bytes are needed. Unlike a
/// capture's framer, a live device cannot wait for the next command to end the current one: a
/// known command is complete as soon as its data is (separators allowed, CR/LF optional and
/// taken with it when already there); an unknown one at its CR/LF.
fn next_command(b: &[u8]) -> Option<usize> {
    if b.is_empty() {
        return None;
    }
    if matches!(b[0], b'\r' | b'\n' | b' ') {
        return Some(
            b.iter()
                .take_while(|c| matches!(c, b'\r' | b'\n' | b' '))
                .count(),
        );
    }
    let h = match head(b) {
        None => return Some(1),
        Some(Err(())) => return None,
        Some(Ok(h)) => h,
    };
    let eol = b.iter().position(|c| matches!(c, b'\r' | b'\n'));
    let end = match h.cmd {
        Some(c) if b[h.cmd_at].is_ascii_lowercase() => {
            let want = c.data_len();
            let mut got = 0;
            let mut at = h.data_at;
            while got < want {
                match b.get(at) {
                    None => return None,
                    Some(b' ' | b',') => {}
                    Some(b'\r' | b'\n') => break,
                    Some(_) => got += 1,
                }
                at += 1;
            }
            at
        }
        _ => match eol {
            Some(e) => e,
            None if b.len() > MAX_LINE => return Some(1),
            None => return None,
        },
    };
    let term = b[end..]
        .iter()
        .take(2)
        .take_while(|c| matches!(c, b'\r' | b'\n'))
        .count();
    Some(end + term)
}

fn hex8(v: i64) -> String {
    format!("{:08X}", v as u32)
}

impl EllSim {
    /// A bus with these modules (address, model); addresses must be distinct.
    pub fn new(modules: &[(u8, EllModel)]) -> Result<EllSim, SimError> {
        let mut ms: Vec<Module> = vec![];
        for &(addr, model) in modules {
            if addr > 15 {
                return Err(SimError::BeyondF(addr));
            }
            if ms.iter().any(|m| m.addr == addr) {
                return Err(SimError::TwoAt(addr));
            }
            ms.push(Module {
                addr,
                model,
                serial: format!("1{:02}{:05}", model.number % 100, 100 + ms.len()),
                pos: 0,
                jog: model.default_jog(),
                home_offset: 0,
                velocity: 100,
                group: None,
                motion: None,
                isolated_until: 0,
                error: OK,
            });
        }
        Ok(EllSim {
            modules: ms,
            pending: vec![],
            line: Line::new(BYTE_NS, TURNAROUND_NS),
        })
    }

    /// The modules' current addresses, in configuration order (`ca` changes them).
    pub fn addresses(&self) -> Vec<u8> {
        self.modules.iter().map(|m| m.addr).collect()
    }

    /// Position in pulses of the module now at `addr`, at `now_ns`.
    pub fn position(&self, addr: u8, now_ns: u64) -> Option<i64> {
        self.modules
            .iter()
            .find(|m| m.addr == addr)
            .map(|m| m.reported(m.position(now_ns)))
    }

    fn reply(&mut self, now: u64, addr: u8, code: &str, data: &str) {
        let c = char::from_digit(addr as u32, 16).map_or('0', |c| c.to_ascii_uppercase());
        self.line
            .send(now, format!("{c}{code}{data}\r\n").into_bytes());
    }

    fn status(&mut self, now: u64, addr: u8, code: u8) {
        self.reply(now, addr, "GS", &format!("{code:02X}"));
    }

    fn handle(&mut self, f: &EllFrame<'_>, now: u64) {
        if f.dir() != Dir::HostToDevice {
            return; // another module's reply echoed on the bus
        }
        let addr = f.addr;
        let targets: Vec<usize> = (0..self.modules.len())
            .filter(|&i| {
                let m = &self.modules[i];
                (m.addr == addr || m.group == Some(addr)) && now >= m.isolated_until
            })
            .collect();
        let code = f.code_str().to_string();
        let bad_data = !f.diags().is_empty() && f.cmd.is_some_and(|c| c.data_len() > 0);
        for i in targets {
            if bad_data {
                self.status(now, addr, COMMAND_ERROR);
                continue;
            }
            self.command(i, addr, &code, f, now);
        }
    }

    fn command(&mut self, i: usize, addr: u8, code: &str, f: &EllFrame<'_>, now: u64) {
        let num = |name: &str| f.field(name).and_then(|v| v.as_i64());
        let busy = self.modules[i].motion.is_some_and(|m| now < m.end_ns);
        let m = &self.modules[i];
        match code {
            "in" => {
                let md = m.model;
                let data = format!(
                    "{:02X}{}{}{:02X}{:02X}{:04X}{:08X}",
                    md.number, m.serial, "2023", 0x17, 0x01, md.travel, md.pulses
                );
                self.reply(now, addr, "IN", &data);
            }
            "gs" => {
                let code = if busy { BUSY } else { m.error };
                self.modules[i].error = OK;
                self.status(now, addr, code);
            }
            "gp" => {
                let p = m.reported(m.position(now));
                self.reply(now, addr, "PO", &hex8(p));
            }
            "gv" => {
                let v = m.velocity;
                self.reply(now, addr, "GV", &format!("{v:02X}"));
            }
            "gj" => {
                let j = m.jog;
                self.reply(now, addr, "GJ", &hex8(j));
            }
            "go" => {
                let o = m.home_offset;
                self.reply(now, addr, "HO", &hex8(o));
            }
            "i1" | "i2" => {
                let r = if code == "i1" { "I1" } else { "I2" };
                // Loop on, motor on, ~0.5 A, no ramps, ~103 kHz / ~83 kHz periods.
                self.reply(now, addr, r, "1103A5FFFFFFFF008F00B2");
            }
            "sv" => match num("velocity") {
                Some(v) if (1..=100).contains(&v) => {
                    self.modules[i].velocity = v as u8;
                    self.status(now, addr, OK);
                }
                _ => self.status(now, addr, OUT_OF_RANGE),
            },
            "sj" => {
                self.modules[i].jog = num("step").unwrap_or(0);
                self.status(now, addr, OK);
            }
            "so" => {
                self.modules[i].home_offset = num("offset").unwrap_or(0);
                self.status(now, addr, OK);
            }
            "us" | "f1" | "b1" | "e1" | "h1" | "f2" | "b2" | "e2" | "h2" => {
                self.status(now, addr, OK)
            }
            "ca" => match num("new_address") {
                Some(a) if (0..16).contains(&a) => {
                    self.modules[i].addr = a as u8;
                    self.status(now, a as u8, OK);
                }
                _ => self.status(now, addr, COMMAND_ERROR),
            },
            "ga" => match num("new_address") {
                Some(a) if (0..16).contains(&a) => {
                    self.modules[i].group = Some(a as u8);
                    self.status(now, a as u8, OK);
                }
                _ => self.status(now, addr, COMMAND_ERROR),
            },
            "is" => {
                let mins = num("minutes").unwrap_or(0).max(0) as u64;
                self.modules[i].isolated_until = now.saturating_add(mins * 60 * SEC);
            }
            // The reply says the module is in its bootloader (p.12).
            "re" => self.status(now, addr, OK),
            "ho" | "ma" | "mr" | "fw" | "bw" => {
                if busy {
                    self.status(now, addr, BUSY);
                    return;
                }
                let from = m.position(now);
                let to = match code {
                    "ho" => m.home_offset,
                    "ma" => match num("position") {
                        Some(p) => p,
                        None => return self.status(now, addr, COMMAND_ERROR),
                    },
                    "mr" => match num("position") {
                        Some(d) => from.saturating_add(d),
                        None => return self.status(now, addr, COMMAND_ERROR),
                    },
                    "fw" => from.saturating_add(m.jog),
                    _ => from.saturating_sub(m.jog),
                };
                if let Some((lo, hi)) = m.model.range() {
                    if to < lo || to > hi {
                        self.modules[i].error = OUT_OF_RANGE;
                        return self.status(now, addr, OUT_OF_RANGE);
                    }
                }
                let pps = (m.model.pulses_per_s() * m.velocity as f64 / 100.0).max(1.0);
                let secs = (to - from).unsigned_abs() as f64 / pps;
                let end = now
                    .saturating_add(MOVE_OVERHEAD_NS)
                    .saturating_add((secs * SEC as f64).min(1e15) as u64);
                let mm = &mut self.modules[i];
                mm.pos = from;
                mm.motion = Some(Move {
                    start_ns: now,
                    end_ns: end,
                    from,
                    to,
                    reply_addr: addr,
                });
            }
            _ => self.status(now, addr, COMMAND_ERROR),
        }
    }

    fn run_events(&mut self, now: u64) {
        loop {
            let next = self
                .modules
                .iter()
                .enumerate()
                .filter_map(|(i, m)| m.motion.map(|mo| (mo.end_ns, i)))
                .filter(|(t, _)| *t <= now)
                .min();
            let Some((t, i)) = next else { break };
            let Some(mo) = self.modules[i].motion.take() else {
                break;
            };
            let m = &mut self.modules[i];
            m.pos = mo.to;
            m.group = None;
            let p = m.reported(mo.to);
            // A rotary mount keeps its position within one turn.
            m.pos = p;
            self.reply(t, mo.reply_addr, "PO", &hex8(p));
        }
    }
}

impl Simulator for EllSim {
    fn input(&mut self, bytes: &[u8], now_ns: u64) {
        self.run_events(now_ns);
        self.pending.extend_from_slice(bytes);
        while let Some(n) = next_command(&self.pending) {
            let frame: Vec<u8> = self.pending.drain(..n).collect();
            if let Some(f) = EllFrame::decode(0, &frame, false) {
                self.handle(&f, now_ns);
            }
        }
        // A line that never became a command is dropped rather than kept forever.
        if self.pending.len() > MAX_LINE {
            self.pending.clear();
        }
    }

    fn poll(&mut self, now_ns: u64) -> Option<Vec<u8>> {
        self.run_events(now_ns);
        self.line.take_due(now_ns)
    }

    fn next_deadline(&self) -> Option<u64> {
        let mut d = self.line.next_due();
        for m in &self.modules {
            d = earliest(d, m.motion.map(|mo| mo.end_ns));
        }
        d
    }
}
