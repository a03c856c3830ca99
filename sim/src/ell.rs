//! The Elliptec bus simulator.

use super::{earliest, Line, Simulator, MS, SEC};
use aptscope_dissector::ell::table::{model, Mechanism, Model, CURVE_POINTS, MODELS};
use aptscope_dissector::ell::{curve_bytes, head, CurvePoint, EllFrame};
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
const VALUE_OUT_OF_RANGE: u8 = 4;
const BUSY: u8 = 9;
const OUT_OF_RANGE: u8 = 12;

/// An ELL module type as simulated: its row of the dissector's model table ([`MODELS`]), which
/// gives what `IN` answers, how it moves and which commands it has.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EllModel {
    /// The model's row.
    pub spec: &'static Model,
}

impl EllModel {
    /// The model with this name (`ELL14`, `ell9`, `14`), among the table's.
    pub fn parse(s: &str) -> Option<EllModel> {
        let s = s.trim();
        let n = s
            .get(..3)
            .filter(|p| p.eq_ignore_ascii_case("ell"))
            .map_or(s, |_| &s[3..]);
        let number: u8 = n.parse().ok()?;
        model(number).map(|spec| EllModel { spec })
    }

    /// ELL number (14 for ELL14).
    pub fn number(&self) -> u8 {
        self.spec.number
    }

    /// Pulses between two slider positions (the `IN` pulses, or, when those are 0 or 1 as on
    /// an ELL6, the travel: the manual's slider goes forward to 0x1F, p.43).
    fn spacing(&self) -> i64 {
        let (p, t) = (self.spec.pulses as i64, self.spec.travel as i64);
        if p > 1 {
            p
        } else {
            t.max(1)
        }
    }

    /// Lowest and highest position in pulses (`None`: unbounded, rotary).
    fn range(&self) -> Option<(i64, i64)> {
        let s = self.spec;
        match s.mechanism {
            Mechanism::Rotary => None,
            Mechanism::Linear => Some((0, s.travel as i64 * s.pulses as i64)),
            Mechanism::Shutter | Mechanism::Indexed => {
                Some((0, (s.slots.max(1) as i64 - 1) * self.spacing()))
            }
            Mechanism::OpenLoop => Some((0, 0)),
        }
    }

    /// Pulses per second at full speed: rotary 430°/s and linear 180 mm/s (an ELL14's and an
    /// ELL17's datasheet speeds), sliders 3 positions a second.
    fn pulses_per_s(&self) -> f64 {
        let p = self.spec.pulses as f64;
        match self.spec.mechanism {
            Mechanism::Rotary => 430.0 * p / 360.0,
            Mechanism::Linear => 180.0 * p,
            Mechanism::Shutter | Mechanism::Indexed => 3.0 * self.spacing() as f64,
            Mechanism::OpenLoop => 1.0,
        }
    }

    fn default_jog(&self) -> i64 {
        match self.spec.mechanism {
            Mechanism::Rotary => self.spec.pulses as i64 / 36,
            Mechanism::Linear => self.spec.pulses as i64,
            Mechanism::Shutter | Mechanism::Indexed => self.spacing(),
            Mechanism::OpenLoop => 0,
        }
    }

    /// The nearest position a slider can rest at (sliders stop on their detents only).
    fn settle(&self, p: i64) -> i64 {
        match self.spec.mechanism {
            Mechanism::Shutter | Mechanism::Indexed => {
                let d = self.spacing();
                (p + d / 2).div_euclid(d) * d
            }
            Mechanism::OpenLoop => 0,
            Mechanism::Rotary | Mechanism::Linear => p,
        }
    }
}

/// The simulated models' names: `ELL4, ELL5, …`.
fn model_names() -> String {
    let names: Vec<String> = MODELS.iter().map(|m| format!("ELL{}", m.number)).collect();
    names.join(", ")
}

/// `aptscope sim elliptec --list`: every model with its mechanism, travel, pulses, slots,
/// motors, the source of those values and the commands it answers.
pub fn model_list() -> String {
    use std::fmt::Write;
    let mut out = String::from(
        "model  what                  mechanism  travel  pulses   slots  motors  source\n",
    );
    for m in MODELS {
        let _ = writeln!(
            out,
            "ELL{:<3} {:<21} {:<10} {:>6}  {:<8} {:>5}  {:>6}  {}",
            m.number,
            m.what,
            m.mechanism.name(),
            m.travel,
            format!("0x{:X}", m.pulses),
            m.slots,
            m.motors,
            m.source
        );
    }
    out.push_str(
        "\ncommands answered (any other host command: GS03, command error or not supported):\n",
    );
    for m in MODELS {
        let codes: Vec<&str> = m.commands().map(|c| c.code).collect();
        let _ = writeln!(out, "ELL{:<3} {}", m.number, codes.join(" "));
    }
    out
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
    /// Motor 1 and 2 drive state (`i1`/`i2` read it, `f1` … `h2` and `s1`/`s2` change it).
    motors: [Drive; 2],
    /// A frequency search or current-curve scan under way.
    scan: Option<Scan>,
}

/// One piezo motor's drive: what `I1`/`I2` report.
#[derive(Debug, Clone, Copy)]
struct Drive {
    /// Energised (`e1` … `h1`).
    on: bool,
    forward_period: u16,
    backward_period: u16,
}

/// Periods a frequency search settles on: the manual's `I1` example's (78 kHz forward,
/// 106 kHz backward, p.14).
const BEST_FORWARD: u16 = 0x00BD;
const BEST_BACKWARD: u16 = 0x008B;
/// The manual's `I1` example's current measurement (0.57 A).
const DRIVE_CURRENT: u16 = 0x0428;

impl Default for Drive {
    fn default() -> Drive {
        Drive {
            on: false,
            forward_period: BEST_FORWARD,
            backward_period: BEST_BACKWARD,
        }
    }
}

/// A motor scan: `s1`/`s2` (frequency search, answered `GS` when done) or `c1`/`c2` (current
/// curve, answered `C1`/`C2`).
#[derive(Debug, Clone, Copy)]
struct Scan {
    end_ns: u64,
    reply_addr: u8,
    /// Motor index (0, 1).
    motor: usize,
    curve: bool,
}

/// How long a frequency search runs (the manual gives no figure; a few seconds on hardware).
const SEARCH_NS: u64 = 2 * SEC;
/// How long a current-curve scan runs: "around 12 seconds" (p.21).
const CURVE_NS: u64 = 12 * SEC;

impl Module {
    /// Whether a motion or scan is under way.
    fn busy(&self, now: u64) -> bool {
        self.next_event().is_some_and(|t| now < t)
    }

    /// When its motion or scan ends.
    fn next_event(&self) -> Option<u64> {
        earliest(self.motion.map(|mo| mo.end_ns), self.scan.map(|s| s.end_ns))
    }

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
        let pulses = self.model.spec.pulses as i64;
        match self.model.spec.mechanism {
            Mechanism::Rotary if pulses > 0 => p.rem_euclid(pulses),
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
    #[error("`{0}`: unknown module ({names}; `sim elliptec --list` describes them)", names = model_names())]
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
/// taken with it when already there); an unknown host command at its CR/LF when that is
/// already there, else right after its mnemonic.
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
        // A command the table does not know (pylablib's `0i3`, sent without CR LF): a module
        // cannot know its data, so it answers at once; data already on the line up to CR/LF
        // goes with it.
        None if b[h.cmd_at].is_ascii_lowercase() => {
            let known = |x: &[u8]| matches!(head(x), Some(Ok(k)) if k.cmd.is_some());
            let end = (h.data_at..b.len())
                .find(|&p| matches!(b[p], b'\r' | b'\n') || known(&b[p..]))
                .unwrap_or(h.data_at);
            end.min(h.data_at + MAX_LINE)
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
                serial: format!("1{:02}{:05}", model.number() % 100, 100 + ms.len()),
                pos: 0,
                jog: model.default_jog(),
                home_offset: 0,
                velocity: 100,
                group: None,
                motion: None,
                isolated_until: 0,
                error: OK,
                motors: [Drive::default(); 2],
                scan: None,
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
        let c = addr_char(addr);
        self.line
            .send(now, format!("{c}{code}{data}\r\n").into_bytes());
    }

    fn status(&mut self, now: u64, addr: u8, code: u8) {
        self.reply(now, addr, "GS", &format!("{code:02X}"));
    }

    /// Answer an error and keep it for the next `gs` (pylablib reads `gs` after an error
    /// "otherwise it is returned as the next status result").
    fn fail(&mut self, i: usize, now: u64, addr: u8, code: u8) {
        self.modules[i].error = code;
        self.status(now, addr, code);
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
            if bad_data || !self.modules[i].model.spec.supports(&code) {
                self.fail(i, now, addr, COMMAND_ERROR);
                continue;
            }
            self.command(i, addr, &code, f, now);
        }
    }

    fn command(&mut self, i: usize, addr: u8, code: &str, f: &EllFrame<'_>, now: u64) {
        let num = |name: &str| f.field(name).and_then(|v| v.as_i64());
        let busy = self.modules[i].busy(now);
        // The motor a motor command drives (`i1`, `f2` …).
        let motor = match code.as_bytes() {
            [_, b'2'] => 1,
            _ => 0,
        };
        let m = &self.modules[i];
        match code {
            "in" => {
                let md = m.model.spec;
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
                let d = m.motors[motor];
                // Loop on; the current measured while energised; ramps undefined (0xFFFF), as
                // in the manual's example (p.14).
                let current = if d.on { DRIVE_CURRENT } else { 0 };
                let data = format!(
                    "1{}{current:04X}FFFFFFFF{:04X}{:04X}",
                    u8::from(d.on),
                    d.forward_period,
                    d.backward_period
                );
                self.reply(now, addr, &code.to_ascii_uppercase(), &data);
            }
            "f1" | "f2" | "b1" | "b2" | "e1" | "e2" => match num("period") {
                Some(p @ 1..=0xFFFF) => {
                    let d = &mut self.modules[i].motors[motor];
                    match code.as_bytes()[0] {
                        b'f' => d.forward_period = p as u16,
                        b'b' => d.backward_period = p as u16,
                        _ => d.on = true,
                    }
                    self.status(now, addr, OK);
                }
                _ => self.fail(i, now, addr, VALUE_OUT_OF_RANGE),
            },
            "h1" | "h2" => {
                self.modules[i].motors[motor].on = false;
                self.status(now, addr, OK);
            }
            "s1" | "s2" | "c1" | "c2" => {
                if busy {
                    return self.status(now, addr, BUSY);
                }
                let curve = code.starts_with('c');
                let took = if curve { CURVE_NS } else { SEARCH_NS };
                self.modules[i].scan = Some(Scan {
                    end_ns: now.saturating_add(took),
                    reply_addr: addr,
                    motor,
                    curve,
                });
            }
            "sv" => match num("velocity") {
                Some(v) if (1..=100).contains(&v) => {
                    self.modules[i].velocity = v as u8;
                    self.status(now, addr, OK);
                }
                _ => self.fail(i, now, addr, VALUE_OUT_OF_RANGE),
            },
            "sj" => {
                self.modules[i].jog = num("step").unwrap_or(0);
                self.status(now, addr, OK);
            }
            "so" => {
                self.modules[i].home_offset = num("offset").unwrap_or(0);
                self.status(now, addr, OK);
            }
            "us" => self.status(now, addr, OK),
            "ca" => match num("new_address") {
                Some(a) if (0..16).contains(&a) => {
                    self.modules[i].addr = a as u8;
                    self.status(now, a as u8, OK);
                }
                _ => self.fail(i, now, addr, COMMAND_ERROR),
            },
            "ga" => match num("new_address") {
                Some(a) if (0..16).contains(&a) => {
                    self.modules[i].group = Some(a as u8);
                    self.status(now, a as u8, OK);
                }
                _ => self.fail(i, now, addr, COMMAND_ERROR),
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
                let model = m.model;
                let from = m.position(now);
                let to = match code {
                    "ho" => m.home_offset,
                    "ma" => match num("position") {
                        Some(p) => p,
                        None => return self.fail(i, now, addr, COMMAND_ERROR),
                    },
                    "mr" => match num("position") {
                        Some(d) => from.saturating_add(d),
                        None => return self.fail(i, now, addr, COMMAND_ERROR),
                    },
                    "fw" => from.saturating_add(m.jog),
                    _ => from.saturating_sub(m.jog),
                };
                let to = match (model.range(), code) {
                    // A slider's jog at its end stays there: ELL6 `fw` means "to position 2",
                    // sent by the `elliptec` package's Shutter.open wherever the slider is.
                    (Some((lo, hi)), "fw" | "bw") => to.clamp(lo, hi),
                    (Some((lo, hi)), _) if to < lo || to > hi => {
                        return self.fail(i, now, addr, OUT_OF_RANGE);
                    }
                    _ => to,
                };
                let to = model.settle(to);
                let pps = (model.pulses_per_s() * m.velocity as f64 / 100.0).max(1.0);
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
            _ => self.fail(i, now, addr, COMMAND_ERROR),
        }
    }

    fn run_events(&mut self, now: u64) {
        loop {
            let next = self
                .modules
                .iter()
                .enumerate()
                .filter_map(|(i, m)| m.next_event().map(|t| (t, i)))
                .filter(|(t, _)| *t <= now)
                .min();
            let Some((t, i)) = next else { break };
            let m = &mut self.modules[i];
            if let Some(mo) = m.motion.filter(|mo| mo.end_ns == t) {
                m.motion = None;
                m.group = None;
                // A rotary mount keeps its position within one turn.
                m.pos = m.reported(mo.to);
                let p = m.pos;
                self.reply(t, mo.reply_addr, "PO", &hex8(p));
            } else if let Some(sc) = m.scan.take() {
                if sc.curve {
                    let code = if sc.motor == 0 { "C1" } else { "C2" };
                    let mut b = format!("{}{code}", addr_char(sc.reply_addr)).into_bytes();
                    b.extend_from_slice(&current_curve(m.motors[sc.motor]));
                    b.extend_from_slice(b"\r\n");
                    self.line.send(t, b);
                } else {
                    m.motors[sc.motor] = Drive::default();
                    self.status(t, sc.reply_addr, OK);
                }
            } else {
                break;
            }
        }
    }
}

/// The address character of `addr` (0–F).
fn addr_char(addr: u8) -> char {
    char::from_digit(addr as u32 & 15, 16).map_or('0', |c| c.to_ascii_uppercase())
}

/// A current curve as `C1`/`C2` carry it: [`CURVE_POINTS`] points from 70 kHz up (period 210
/// down), the current peaking at the motor's forward and backward resonances.
fn current_curve(d: Drive) -> Vec<u8> {
    let peak = |period: u16, at: u16| {
        let x = (period as f64 - at as f64) / 4.0;
        DRIVE_CURRENT as f64 / (1.0 + x * x)
    };
    let points: Vec<CurvePoint> = (0..CURVE_POINTS as u16)
        .map(|k| {
            let period = 210 - k;
            let amps = 120.0 + peak(period, d.forward_period) + peak(period, d.backward_period);
            CurvePoint {
                period,
                current: amps.round() as u32,
            }
        })
        .collect();
    curve_bytes(&points)
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
            d = earliest(d, m.next_event());
        }
        d
    }
}
