//! The APT controller simulator.

use super::{earliest, Line, Simulator, MS, SEC};
use aptscope_dissector::apt::{encode, AptFrame, AptFramer, FieldValue, Item, Value};
use aptscope_dissector::table::{Access, FormKind, Table, Ty};

/// Host address.
const HOST: u8 = 0x01;
/// Rack (motherboard) address.
const RACK: u8 = 0x11;
/// First bay address.
const BAY0: u8 = 0x21;
/// Generic USB unit address.
const USB: u8 = 0x50;
/// Bays of a BSC203.
const BSC203_BAYS: u8 = 3;
/// Period of status updates after HW_START_UPDATEMSGS.
const UPDATE_NS: u64 = 100 * MS;
/// Homing: searching the limit switch and backing off, on top of the travel to it.
const HOME_BASE_NS: u64 = 2 * SEC;
/// 115 200 baud, 8N1: 10 bits per byte.
const BYTE_NS: u64 = 86_806;
/// Time from a request to the first byte of its reply.
const TURNAROUND_NS: u64 = MS;

// mot_status bits (dissector/msgs/21_motor_b.apt).
const CW_HW_LIMIT: u32 = 0x1;
const CCW_HW_LIMIT: u32 = 0x2;
const MOVING_CW: u32 = 0x10;
const MOVING_CCW: u32 = 0x20;
const JOGGING_CW: u32 = 0x40;
const JOGGING_CCW: u32 = 0x80;
const MOTOR_CONNECTED: u32 = 0x100;
const HOMING: u32 = 0x200;
const HOMED: u32 = 0x400;
const ENABLED: u32 = 0x8000_0000;
// pz_status bits.
const PZ_ACTUATOR_CONNECTED: u32 = 0x1;
// la_status bits (dissector/msgs/50_laser_tec.apt).
const LA_OUTPUT_ENABLED: u32 = 0x1;
const LA_KEYSWITCH_ENABLED: u32 = 0x2;
const LA_CLOSED_LOOP: u32 = 0x4;
const LA_UNITS_MW: u32 = 0x20;
// tec_status bits.
const TEC_OUTPUT_ENABLED: u32 = 0x1;
const TEC_DISP_TACT: u32 = 0x10;
/// Laser diode current as a fraction of full scale per unit of power setpoint (TLS001 model).
const LA_CURRENT_PER_POWER: f64 = 0.6;
/// TEC output current while holding the setpoint (mA).
const TEC_HOLD_MA: i64 = 420;
/// The beam's offset on the quad detector (XDIFF, YDIFF, SUM raw), and the residual error in
/// closed loop.
const QUAD_BEAM: (i64, i64, i64) = (1200, -800, 45_000);
const QUAD_RESIDUAL: (i64, i64) = (3, -2);

/// The controllers the simulator can be.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AptModel {
    /// K-Cube brushed DC servo controller (with a Z825B-like stage).
    Kdc101,
    /// T-Cube DC servo controller (same stage).
    Tdc001,
    /// K-Cube piezo controller (open loop, 75 V).
    Kpz101,
    /// Three-bay benchtop stepper controller: motherboard at 0x11, bays at 0x21–0x23.
    Bsc203,
    /// T-Cube laser source (LA_ PARAMS sub-messages, LA_ENABLEOUTPUT/DISABLEOUTPUT).
    Tls001,
    /// T-Cube TEC controller (TEC_ PARAMS sub-messages).
    Ttc001,
    /// K-Cube position aligner with a quad detector (QUAD_ PARAMS sub-messages).
    Kpa101,
}

impl AptModel {
    /// The names [`parse`](Self::parse) accepts.
    pub const NAMES: &'static [&'static str] = &[
        "kdc101", "tdc001", "kpz101", "bsc203", "tls001", "ttc001", "kpa101",
    ];

    /// Parse `kdc101`, `tdc001`, `kpz101`, `bsc203`, `tls001`, `ttc001`, `kpa101` (any case).
    pub fn parse(s: &str) -> Option<AptModel> {
        Some(match s.trim().to_ascii_lowercase().as_str() {
            "kdc101" => AptModel::Kdc101,
            "tdc001" => AptModel::Tdc001,
            "kpz101" => AptModel::Kpz101,
            "bsc203" => AptModel::Bsc203,
            "tls001" => AptModel::Tls001,
            "ttc001" => AptModel::Ttc001,
            "kpa101" => AptModel::Kpa101,
            _ => return None,
        })
    }

    /// The model name as HW_GET_INFO gives it.
    pub fn name(self) -> &'static str {
        match self {
            AptModel::Kdc101 => "KDC101",
            AptModel::Tdc001 => "TDC001",
            AptModel::Kpz101 => "KPZ101",
            AptModel::Bsc203 => "BSC203",
            AptModel::Tls001 => "TLS001",
            AptModel::Ttc001 => "TTC001",
            AptModel::Kpa101 => "KPA101",
        }
    }

    /// The first two digits of the serial number (the spec's table of serial prefixes).
    pub fn serial_prefix(self) -> u32 {
        match self {
            AptModel::Kdc101 => 27,
            AptModel::Tdc001 => 83,
            AptModel::Kpz101 => 29,
            AptModel::Bsc203 => 70,
            AptModel::Tls001 => 86,
            AptModel::Ttc001 => 87,
            AptModel::Kpa101 => 69,
        }
    }

    /// Whether the controller drives a motor (moves and homing); the others ignore motion.
    fn has_motor(self) -> bool {
        matches!(self, AptModel::Kdc101 | AptModel::Tdc001 | AptModel::Bsc203)
    }

    /// Motion scaling: position counts per mm, travel in mm, and the factors from counts/s and
    /// counts/s² to the units of the velocity and acceleration parameters.
    fn scaling(self) -> Scaling {
        match self {
            // Z8 stage on a DC servo controller: 34 554.96 counts/mm, T = 2048/6e6 s;
            // velocity = counts/s × T × 65536, acceleration = counts/s² × T² × 65536.
            AptModel::Kdc101
            | AptModel::Tdc001
            | AptModel::Kpz101
            | AptModel::Tls001
            | AptModel::Ttc001
            | AptModel::Kpa101 => Scaling {
                counts_per_mm: 34_554.96,
                travel_mm: 25.0,
                vel: 22.369_621,
                acc: 0.007_635_4,
            },
            // Stepper bay: 409 600 microsteps/mm; velocity = µsteps/s × 53.687091,
            // acceleration = µsteps/s² × 0.010995.
            AptModel::Bsc203 => Scaling {
                counts_per_mm: 409_600.0,
                travel_mm: 50.0,
                vel: 53.687_091,
                acc: 0.010_995,
            },
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Scaling {
    counts_per_mm: f64,
    travel_mm: f64,
    vel: f64,
    acc: f64,
}

impl Scaling {
    fn max_pos(&self) -> i64 {
        (self.counts_per_mm * self.travel_mm) as i64
    }
    fn vel_param(&self, mm_s: f64) -> i64 {
        (mm_s * self.counts_per_mm * self.vel).round() as i64
    }
    fn acc_param(&self, mm_s2: f64) -> i64 {
        (mm_s2 * self.counts_per_mm * self.acc).round() as i64
    }
    /// counts/s from a velocity parameter (at least 1 count/s).
    fn counts_s(&self, param: i64) -> f64 {
        (param as f64 / self.vel).max(1.0)
    }
    /// counts/s² from an acceleration parameter (at least 1 count/s²).
    fn counts_s2(&self, param: i64) -> f64 {
        (param as f64 / self.acc).max(1.0)
    }
}

/// What a motion is, for status bits and the completion message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
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
struct Motion {
    kind: Kind,
    start_ns: u64,
    from: i64,
    /// Where it ends (exactly).
    to: i64,
    dir: i64,
    v0: f64,
    vpeak: f64,
    a: f64,
    t1: f64,
    t2: f64,
    t3: f64,
    /// Channel the host named, for the completion message.
    chan: i64,
}

impl Motion {
    /// A trapezoidal move from rest to rest.
    fn trapezoid(kind: Kind, now: u64, from: i64, to: i64, v: f64, a: f64, chan: i64) -> Motion {
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
        }
    }

    /// Constant speed for `secs` (homing).
    fn linear(kind: Kind, now: u64, from: i64, to: i64, secs: f64, chan: i64) -> Motion {
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
        }
    }

    fn total_s(&self) -> f64 {
        self.t1 + self.t2 + self.t3
    }

    fn end_ns(&self) -> u64 {
        self.start_ns
            .saturating_add((self.total_s() * SEC as f64).min(1e18) as u64)
    }

    /// Distance covered and speed (counts, counts/s) at `now`.
    fn at(&self, now: u64) -> (f64, f64) {
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
    fn pos(&self, now: u64) -> (i64, f64) {
        if now >= self.end_ns() {
            return (self.to, 0.0);
        }
        let (d, v) = self.at(now);
        (self.from + self.dir * d.round() as i64, v)
    }
}

/// Parameters as the GET message carries them: field name and value.
type Params = Vec<(&'static str, FieldValue)>;

/// One addressable controller: a standalone unit (0x50) or a bay of the rack.
#[derive(Debug, Clone)]
struct Unit {
    addr: u8,
    serial: u32,
    motor: bool,
    enabled: bool,
    /// Laser output on (LA_ENABLEOUTPUT).
    output: bool,
    homed: bool,
    pos: i64,
    motion: Option<Motion>,
    /// Next status update, while updates are on.
    next_update: Option<u64>,
    /// Stored parameters by GET message name (answers REQ_, updated by SET_).
    params: Vec<(&'static str, Params)>,
    /// Sub-message parameter blocks: GET message name, sub-message id, fields (answers
    /// REQ_PARAMS for that id, updated by SET_PARAMS).
    subs: Vec<(&'static str, u16, Params)>,
}

impl Unit {
    fn param(&self, get: &str, field: &str) -> Option<i64> {
        self.params
            .iter()
            .find(|(n, _)| *n == get)?
            .1
            .iter()
            .find(|(f, _)| *f == field)
            .and_then(|(_, v)| match v {
                FieldValue::Int(i) => Some(*i),
                FieldValue::Float(x) => Some(*x as i64),
                _ => None,
            })
    }

    fn sub_param(&self, get: &str, id: u16, field: &str) -> Option<i64> {
        self.subs
            .iter()
            .find(|(n, i, _)| *n == get && *i == id)?
            .2
            .iter()
            .find(|(f, _)| *f == field)
            .and_then(|(_, v)| match v {
                FieldValue::Int(i) => Some(*i),
                FieldValue::Float(x) => Some(*x as i64),
                _ => None,
            })
    }

    fn set_param(&mut self, get: &'static str, field: &'static str, v: i64) {
        if let Some((_, p)) = self.params.iter_mut().find(|(n, _)| *n == get) {
            if let Some(slot) = p.iter_mut().find(|(f, _)| *f == field) {
                slot.1 = FieldValue::Int(v);
            } else {
                p.push((field, FieldValue::Int(v)));
            }
        } else {
            self.params.push((get, vec![(field, FieldValue::Int(v))]));
        }
    }
}

/// A simulated APT controller (sans-io): see the [module docs](super).
///
/// Standalone models answer at the generic USB address 0x50; a BSC203 answers as the
/// motherboard at 0x11 (and 0x50) and as bays 0x21–0x23, each bay from its own address.
/// Move commands are ignored while a channel is disabled, as real controllers do.
/// Positions are encoder counts (34 554.96/mm, 25 mm travel on DC models; 409 600 µsteps/mm,
/// 50 mm on BSC203 bays); moves follow a trapezoidal profile from the velocity parameters,
/// homing takes 2 s plus the travel back to 0 at the homing velocity. The `velocity` of
/// DC status updates is the speed in counts/s divided by 10 (the spec leaves it to the model).
#[derive(Debug)]
pub struct AptSim {
    model: AptModel,
    scaling: Scaling,
    serial: u32,
    units: Vec<Unit>,
    framer: AptFramer<'static>,
    line: Line,
    identified: u32,
}

fn int(v: i64) -> FieldValue {
    FieldValue::Int(v)
}

/// A decoded field's value as a SET message stores it for its GET (numbers only).
fn stored(ty: Ty, v: Value<'_>) -> Option<FieldValue> {
    match (ty, v) {
        (Ty::Prim(_), Value::F(x)) => Some(FieldValue::Float(x)),
        (Ty::Prim(_), v) => v.as_i64().map(FieldValue::Int),
        _ => None,
    }
}

/// A message to one unit, as the family handlers of [`AptSim`] take it.
#[derive(Clone, Copy)]
struct Req<'r, 'a> {
    f: &'r AptFrame<'a, 'static>,
    name: &'static str,
    /// Index of the unit addressed.
    ui: usize,
    chan: i64,
    now: u64,
}

impl AptSim {
    /// A controller of this model with a default serial number (prefix + `000123`).
    pub fn new(model: AptModel) -> AptSim {
        Self::with_serial(model, model.serial_prefix() * 1_000_000 + 123)
    }

    /// A controller with this serial number.
    pub fn with_serial(model: AptModel, serial: u32) -> AptSim {
        let s = model.scaling();
        let mut units = vec![];
        let addrs: Vec<u8> = match model {
            AptModel::Bsc203 => (0..BSC203_BAYS).map(|b| BAY0 + b).collect(),
            _ => vec![USB],
        };
        for (i, addr) in addrs.into_iter().enumerate() {
            let piezo = model == AptModel::Kpz101;
            let subs = sub_params(model);
            let params: Vec<(&'static str, Params)> = if !model.has_motor() && !piezo {
                vec![]
            } else if piezo {
                vec![
                    ("PZ_GET_OUTPUTVOLTS", vec![("voltage", int(0))]),
                    ("PZ_GET_POSCONTROLMODE", vec![("mode", int(1))]),
                    ("PZ_GET_OUTPUTPOS", vec![("position_sw", int(0))]),
                    (
                        "PZ_GET_OUTPUTMAXVOLTS",
                        vec![("voltage", int(750)), ("flags", int(0x2))],
                    ),
                    ("PZ_GET_MAXTRAVEL", vec![("travel", int(0))]),
                    (
                        "PZ_GET_INPUTVOLTSSRC",
                        vec![("volts_src", int(0)), ("source", int(0))],
                    ),
                ]
            } else {
                vec![
                    (
                        "MOT_GET_VELPARAMS",
                        vec![
                            ("min_vel", int(0)),
                            ("acceleration", int(s.acc_param(1.5))),
                            ("max_vel", int(s.vel_param(2.0))),
                        ],
                    ),
                    (
                        "MOT_GET_JOGPARAMS",
                        vec![
                            ("jog_mode", int(2)),
                            ("jog_step_size", int((s.counts_per_mm * 0.1) as i64)),
                            ("jog_min_vel", int(0)),
                            ("jog_acceleration", int(s.acc_param(1.5))),
                            ("jog_max_vel", int(s.vel_param(2.0))),
                            ("jog_stop_mode", int(2)),
                        ],
                    ),
                    (
                        "MOT_GET_HOMEPARAMS",
                        vec![
                            ("home_dir", int(2)),
                            ("limit_switch", int(1)),
                            ("home_velocity", int(s.vel_param(1.0))),
                            ("offset_distance", int((s.counts_per_mm * 0.1) as i64)),
                        ],
                    ),
                    (
                        "MOT_GET_LIMSWITCHPARAMS",
                        vec![
                            ("cw_hard_limit", int(2)),
                            ("ccw_hard_limit", int(2)),
                            ("cw_soft_limit", int(s.max_pos())),
                            ("ccw_soft_limit", int(0)),
                            ("soft_limit_mode", int(1)),
                        ],
                    ),
                    ("MOT_GET_GENMOVEPARAMS", vec![("backlash_distance", int(0))]),
                    ("MOT_GET_MOVERELPARAMS", vec![("relative_distance", int(0))]),
                    ("MOT_GET_MOVEABSPARAMS", vec![("absolute_position", int(0))]),
                    (
                        "MOT_GET_POWERPARAMS",
                        vec![("rest_factor", int(10)), ("move_factor", int(30))],
                    ),
                ]
            };
            units.push(Unit {
                addr,
                serial: serial + i as u32 * (model == AptModel::Bsc203) as u32,
                motor: model.has_motor(),
                enabled: true,
                output: false,
                homed: false,
                pos: 0,
                motion: None,
                next_update: None,
                params,
                subs,
            });
        }
        AptSim {
            model,
            scaling: s,
            serial,
            units,
            framer: AptFramer::new(Table::global()),
            line: Line::new(BYTE_NS, TURNAROUND_NS),
            identified: 0,
        }
    }

    /// The model simulated.
    pub fn model(&self) -> AptModel {
        self.model
    }

    /// How many MOD_IDENTIFY requests were received (the LED would flash).
    pub fn identify_count(&self) -> u32 {
        self.identified
    }

    /// Position counter of the unit at `addr` (0x50, or a bay address) at `now_ns`.
    pub fn position(&self, addr: u8, now_ns: u64) -> Option<i64> {
        let ui = self.units.iter().position(|u| u.addr == addr)?;
        Some(self.unit_pos(ui, now_ns))
    }

    /// Position counter of unit `ui` at `now`.
    fn unit_pos(&self, ui: usize, now: u64) -> i64 {
        let u = &self.units[ui];
        u.motion.map_or(u.pos, |m| m.pos(now).0)
    }

    /// Answer `r` with `get` from its unit to the host: its channel, then `vals`.
    fn reply(&mut self, r: &Req<'_, '_>, get: &str, vals: &[(&str, FieldValue)]) {
        let mut all = vec![("chan_ident", int(r.chan))];
        all.extend_from_slice(vals);
        let b = build(get, None, HOST, self.units[r.ui].addr, &all);
        self.send(r.now, b);
    }

    fn handle(&mut self, bytes: &[u8], now: u64) {
        let table = Table::global();
        let Some(f) = AptFrame::decode(table, 0, bytes, false) else {
            return;
        };
        let Some(m) = f.msg else {
            return;
        };
        let h = f.header();
        let dst = h.dst_byte();
        let chan = f.channel().filter(|c| *c > 0).unwrap_or(1);
        let bsc = self.model == AptModel::Bsc203;
        let to_rack = if bsc {
            dst == RACK || dst == USB
        } else {
            false
        };
        // Rack-level (and broadcast-ish) messages of the BSC203 motherboard.
        if to_rack {
            self.rack_msg(&f, m.name, now);
            return;
        }
        let Some(ui) = self.units.iter().position(|u| u.addr == dst) else {
            return;
        };
        let r = Req {
            f: &f,
            name: m.name,
            ui,
            chan,
            now,
        };
        let handled = self.module_msg(&r)
            || self.readback_msg(&r)
            || self.motion_msg(&r)
            || self.output_msg(&r);
        if !handled {
            self.generic(&r);
        }
    }

    /// Messages to the BSC203's rack (the motherboard) rather than a bay.
    fn rack_msg(&mut self, f: &AptFrame<'_, '_>, name: &str, now: u64) {
        match name {
            "HW_REQ_INFO" => {
                let b = self.info(RACK, self.serial, BSC203_BAYS as i64, 45);
                self.line.send(now, b);
            }
            "RACK_REQ_BAYUSED" => {
                let bay = f.field("bay_ident").and_then(|(_, v)| v.as_i64());
                let bay = bay.unwrap_or(0);
                let state = if (0..BSC203_BAYS as i64).contains(&bay) {
                    1
                } else {
                    2
                };
                let b = build(
                    "RACK_GET_BAYUSED",
                    None,
                    HOST,
                    RACK,
                    &[("bay_ident", int(bay)), ("bay_state", int(state))],
                );
                self.send(now, b);
            }
            "RACK_REQ_STATUSBITS" => {
                let b = build(
                    "RACK_GET_STATUSBITS",
                    None,
                    HOST,
                    RACK,
                    &[("status_bits", int(0))],
                );
                self.send(now, b);
            }
            "MOD_IDENTIFY" => self.identified += 1,
            "HW_START_UPDATEMSGS" => {
                for u in &mut self.units {
                    u.next_update.get_or_insert(now + UPDATE_NS);
                }
            }
            "HW_STOP_UPDATEMSGS" => {
                for u in &mut self.units {
                    u.next_update = None;
                }
            }
            _ => {}
        }
    }

    /// Module-level messages: information, identify, status update switches, channel enable. False
    /// when `r` is not of this family.
    fn module_msg(&mut self, r: &Req<'_, '_>) -> bool {
        let Req {
            f, name, ui, now, ..
        } = *r;
        let bsc = self.model == AptModel::Bsc203;
        match name {
            "HW_REQ_INFO" => {
                let u = &self.units[ui];
                let (serial, nchs, hw) = (u.serial, 1, if bsc { 45 } else { 44 });
                let b = self.info(u.addr, serial, nchs, hw);
                self.line.send(now, b);
            }
            "MOD_IDENTIFY" => self.identified += 1,
            "HW_START_UPDATEMSGS" => {
                self.units[ui].next_update.get_or_insert(now + UPDATE_NS);
            }
            "HW_STOP_UPDATEMSGS" => self.units[ui].next_update = None,
            "MOD_SET_CHANENABLESTATE" => {
                let st = f.field("enable_state").and_then(|(_, v)| v.as_i64());
                match st {
                    Some(1) => self.units[ui].enabled = true,
                    Some(2) => {
                        // Disabling stops the motor where it is.
                        let u = &mut self.units[ui];
                        if let Some(mo) = u.motion.take() {
                            u.pos = mo.pos(now).0;
                        }
                        u.enabled = false;
                    }
                    _ => {}
                }
            }
            "MOD_REQ_CHANENABLESTATE" => {
                let st = if self.units[ui].enabled { 1 } else { 2 };
                self.reply(r, "MOD_GET_CHANENABLESTATE", &[("enable_state", int(st))]);
            }
            _ => return false,
        }
        true
    }

    /// Requests for counters and status: answered from the unit's state. False when `r` is not of
    /// this family.
    fn readback_msg(&mut self, r: &Req<'_, '_>) -> bool {
        let Req {
            f,
            name,
            ui,
            chan,
            now,
        } = *r;
        match name {
            "MOT_REQ_POSCOUNTER" | "MOT_REQ_ENCCOUNTER" => {
                let p = self.unit_pos(ui, now);
                let (get, field) = if name == "MOT_REQ_POSCOUNTER" {
                    ("MOT_GET_POSCOUNTER", "position")
                } else {
                    ("MOT_GET_ENCCOUNTER", "encoder_count")
                };
                self.reply(r, get, &[(field, int(p))]);
            }
            "MOT_SET_POSCOUNTER" | "MOT_SET_ENCCOUNTER" => {
                let field = if name == "MOT_SET_POSCOUNTER" {
                    "position"
                } else {
                    "encoder_count"
                };
                let u = &mut self.units[ui];
                if let (Some(v), None) = (f.field(field).and_then(|(_, v)| v.as_i64()), u.motion) {
                    u.pos = v;
                }
            }
            "MOT_REQ_STATUSBITS" => {
                let bits = self.status_bits(ui, now);
                self.reply(
                    r,
                    "MOT_GET_STATUSBITS",
                    &[("status_bits", int(bits as i64))],
                );
            }
            "MOT_REQ_DCSTATUSUPDATE" => {
                let b = self.dc_status(ui, now, "MOT_GET_DCSTATUSUPDATE", chan);
                self.send(now, b);
            }
            "MOT_REQ_STATUSUPDATE"
            | "LA_REQ_STATUSUPDATE"
            | "TEC_REQ_STATUSUPDATE"
            | "QUAD_REQ_STATUSUPDATE" => {
                let b = self.status_update(ui, now);
                self.send(now, b);
            }
            "PZ_REQ_PZSTATUSBITS" => {
                let bits = int(PZ_ACTUATOR_CONNECTED as i64);
                self.reply(r, "PZ_GET_PZSTATUSBITS", &[("status_bits", bits)]);
            }
            _ => return false,
        }
        true
    }

    /// Moves, homing and stops: start or end the unit's motion. False when `r` is not of this
    /// family.
    fn motion_msg(&mut self, r: &Req<'_, '_>) -> bool {
        let Req {
            f,
            name,
            ui,
            chan,
            now,
        } = *r;
        let sc = self.scaling;
        match name {
            "MOT_MOVE_HOME" => {
                let u = &self.units[ui];
                if !u.motor || !u.enabled {
                    return true;
                }
                let from = self.unit_pos(ui, now);
                let hv = sc.counts_s(u.param("MOT_GET_HOMEPARAMS", "home_velocity").unwrap_or(1));
                let secs = HOME_BASE_NS as f64 / SEC as f64 + from.unsigned_abs() as f64 / hv;
                let mut mo = Motion::linear(Kind::Home, now, from, 0, secs, chan);
                if from == 0 {
                    // Already at zero: the search for the reverse limit switch still runs CCW.
                    mo.dir = -1;
                }
                self.units[ui].motion = Some(mo);
                self.units[ui].homed = false;
            }
            "MOT_MOVE_ABSOLUTE" | "MOT_MOVE_RELATIVE" | "MOT_MOVE_JOG" | "MOT_MOVE_VELOCITY" => {
                let u = &self.units[ui];
                if !u.motor || !u.enabled {
                    return true;
                }
                let from = self.unit_pos(ui, now);
                let fv = |n: &str| f.field(n).and_then(|(_, v)| v.as_i64());
                let vel = |get: &str, vf: &str, af: &str| {
                    (
                        sc.counts_s(u.param(get, vf).unwrap_or(1)),
                        sc.counts_s2(u.param(get, af).unwrap_or(1)),
                    )
                };
                let (v, a) = vel("MOT_GET_VELPARAMS", "max_vel", "acceleration");
                let (jv, ja) = vel("MOT_GET_JOGPARAMS", "jog_max_vel", "jog_acceleration");
                let max = sc.max_pos();
                let (kind, to, v, a) = match name {
                    "MOT_MOVE_ABSOLUTE" => {
                        let to = fv("absolute_position")
                            .or_else(|| u.param("MOT_GET_MOVEABSPARAMS", "absolute_position"));
                        (Kind::Move, to.unwrap_or(from), v, a)
                    }
                    "MOT_MOVE_RELATIVE" => {
                        let d = fv("relative_distance")
                            .or_else(|| u.param("MOT_GET_MOVERELPARAMS", "relative_distance"));
                        (Kind::Move, from.saturating_add(d.unwrap_or(0)), v, a)
                    }
                    "MOT_MOVE_JOG" => {
                        let back = fv("direction") == Some(2);
                        if u.param("MOT_GET_JOGPARAMS", "jog_mode") == Some(1) {
                            (Kind::Velocity, if back { 0 } else { max }, jv, ja)
                        } else {
                            let step = u.param("MOT_GET_JOGPARAMS", "jog_step_size").unwrap_or(0);
                            let to = if back { from - step } else { from + step };
                            (Kind::Jog, to, jv, ja)
                        }
                    }
                    _ => {
                        let back = matches!(fv("direction"), Some(2) | Some(0x20));
                        (Kind::Velocity, if back { 0 } else { max }, v, a)
                    }
                };
                // The stage cannot leave its travel.
                let to = to.clamp(0.min(from), max.max(from));
                let to = if kind == Kind::Move || kind == Kind::Jog {
                    to.clamp(0, max)
                } else {
                    to
                };
                self.units[ui].motion = Some(Motion::trapezoid(kind, now, from, to, v, a, chan));
            }
            "MOT_MOVE_STOP" => {
                let profiled = f.field("stop_mode").and_then(|(_, v)| v.as_i64()) == Some(2);
                let u = &mut self.units[ui];
                let Some(mo) = u.motion else {
                    // Not moving: a stop is still acknowledged.
                    let b = self.dc_status(ui, now, "MOT_MOVE_STOPPED", chan);
                    self.send(now, b);
                    return true;
                };
                let (p, speed) = mo.pos(now);
                if profiled && speed > 0.0 && mo.a > 0.0 {
                    let t = speed / mo.a;
                    let d = (speed * speed / (2.0 * mo.a)).round() as i64;
                    u.motion = Some(Motion {
                        kind: Kind::Stopping,
                        start_ns: now,
                        from: p,
                        to: p + mo.dir * d,
                        dir: mo.dir,
                        v0: speed,
                        vpeak: speed,
                        a: mo.a,
                        t1: 0.0,
                        t2: 0.0,
                        t3: t,
                        chan,
                    });
                } else {
                    u.motion = None;
                    u.pos = p;
                    let b = self.dc_status(ui, now, "MOT_MOVE_STOPPED", chan);
                    self.send(now, b);
                }
            }
            _ => return false,
        }
        true
    }

    /// Outputs: the laser source's enable, the piezo's output voltage. False when `r` is not of
    /// this family.
    fn output_msg(&mut self, r: &Req<'_, '_>) -> bool {
        let Req { f, name, ui, .. } = *r;
        match name {
            "LA_ENABLEOUTPUT" | "LA_DISABLEOUTPUT" if self.model == AptModel::Tls001 => {
                self.units[ui].output = name == "LA_ENABLEOUTPUT";
            }
            "PZ_SET_OUTPUTVOLTS" => {
                // Outputs within ±100 % only.
                if let Some(v) = f.field("voltage").and_then(|(_, v)| v.as_i64()) {
                    if self.units[ui].enabled {
                        self.units[ui].set_param(
                            "PZ_GET_OUTPUTVOLTS",
                            "voltage",
                            v.clamp(0, 32767),
                        );
                    }
                }
            }
            _ => return false,
        }
        true
    }

    /// SET_x stores its fields for GET_x; REQ_x answers with GET_x when it is modelled.
    fn generic(&mut self, r: &Req<'_, '_>) {
        let Req { f, ui, now, .. } = *r;
        let Some(m) = f.msg else { return };
        if m.subs.is_some() {
            self.sub_message(ui, f, now);
            return;
        }
        let Some((gm, access)) = Table::global().readback_of(m) else {
            return;
        };
        if access == Access::Set {
            let Some(slot) = self.units[ui]
                .params
                .iter_mut()
                .find(|(n, _)| *n == gm.name)
            else {
                return;
            };
            for (field, v) in f.fields() {
                if field.name == "chan_ident" {
                    continue;
                }
                let Some(fv) = stored(field.ty, v) else {
                    continue;
                };
                if let Some(s) = slot.1.iter_mut().find(|(n, _)| *n == field.name) {
                    s.1 = fv;
                } else {
                    slot.1.push((field.name, fv));
                }
            }
        } else {
            let Some((gname, p)) = self.units[ui].params.iter().find(|(n, _)| *n == gm.name) else {
                return;
            };
            let (gname, p) = (*gname, p.clone());
            self.reply(r, gname, &p);
        }
    }

    /// `x_SET_PARAMS` stores the sub-message's fields for `x_GET_PARAMS` (blocks the model
    /// has only); `x_REQ_PARAMS` answers the block named by its sub-message id, with live
    /// readings where the block has them.
    fn sub_message(&mut self, ui: usize, f: &AptFrame<'_, '_>, now: u64) {
        let Some(m) = f.msg else { return };
        let Some((gm, access)) = Table::global().readback_of(m) else {
            return;
        };
        let set = access == Access::Set;
        let id = f
            .field("sub_id")
            .and_then(|(_, v)| v.as_i64())
            .and_then(|i| u16::try_from(i).ok())
            .or(f.sub.map(|s| s.id));
        let Some(id) = id else { return };
        let addr = self.units[ui].addr;
        let Some(si) = self.units[ui]
            .subs
            .iter()
            .position(|(n, i, _)| *n == gm.name && *i == id)
        else {
            return;
        };
        if set {
            let mut new: Params = vec![];
            for (field, v) in f.fields() {
                if field.name == "sub_id" {
                    continue;
                }
                let Some(fv) = stored(field.ty, v) else {
                    continue;
                };
                new.push((field.name, fv));
            }
            let slot = &mut self.units[ui].subs[si].2;
            for (name, fv) in new {
                if let Some(s) = slot.iter_mut().find(|(n, _)| *n == name) {
                    s.1 = fv;
                }
            }
        } else {
            let mut vals = self.units[ui].subs[si].2.clone();
            for (name, v) in self.live(ui, gm.name, id) {
                if let Some(s) = vals.iter_mut().find(|(n, _)| *n == name) {
                    s.1 = v;
                }
            }
            let b = build_sub(gm.name, id, HOST, addr, &vals);
            self.send(now, b);
        }
    }

    /// Readings of a sub-message block that come from the unit's state, not from SET_PARAMS.
    fn live(&self, ui: usize, get: &str, id: u16) -> Params {
        match (get, id) {
            ("LA_GET_PARAMS", 3) => {
                let (c, p, _) = self.laser(ui);
                vec![("laser_current", int(c)), ("laser_power", int(p))]
            }
            ("LA_GET_PARAMS", 7) => vec![("status_bits", int(self.laser(ui).2 as i64))],
            ("TEC_GET_PARAMS", 3) => {
                let (i, ta, ts, _) = self.tec(ui);
                vec![("i_tec", int(i)), ("t_act", int(ta)), ("t_set", int(ts))]
            }
            ("TEC_GET_PARAMS", 7) => vec![("status_bits", int(self.tec(ui).3 as i64))],
            ("QUAD_GET_PARAMS", 3) => {
                let q = self.quad(ui);
                vec![
                    ("x_diff", int(q.0)),
                    ("y_diff", int(q.1)),
                    ("sum", int(q.2)),
                    ("x_pos", int(q.3)),
                    ("y_pos", int(q.4)),
                ]
            }
            ("QUAD_GET_PARAMS", 9) => vec![("status_bits", int(self.quad(ui).5 as i64))],
            _ => vec![],
        }
    }

    /// Laser current and power (0..32767) and status bits: the power follows the setpoint while
    /// the output is on.
    fn laser(&self, ui: usize) -> (i64, i64, u32) {
        let u = &self.units[ui];
        let sp = u.sub_param("LA_GET_PARAMS", 1, "setpoint").unwrap_or(0);
        let mut bits = LA_KEYSWITCH_ENABLED | LA_CLOSED_LOOP | LA_UNITS_MW;
        if u.output {
            bits |= LA_OUTPUT_ENABLED;
            let c = (sp as f64 * LA_CURRENT_PER_POWER).round() as i64;
            (c, sp, bits)
        } else {
            (0, 0, bits)
        }
    }

    /// TEC current (mA), actual and set temperature, status bits: the element holds its
    /// setpoint.
    fn tec(&self, ui: usize) -> (i64, i64, i64, u32) {
        let u = &self.units[ui];
        let ts = u.sub_param("TEC_GET_PARAMS", 1, "t_set").unwrap_or(0);
        let lim = u
            .sub_param("TEC_GET_PARAMS", 5, "i_lim")
            .unwrap_or(TEC_HOLD_MA);
        let disp = match u.sub_param("TEC_GET_PARAMS", 0x0B, "disp_mode") {
            Some(1) => 0x20,
            Some(2) => 0x40,
            Some(3) => 0x80,
            _ => TEC_DISP_TACT,
        };
        (TEC_HOLD_MA.min(lim), ts, ts, TEC_OUTPUT_ENABLED | disp)
    }

    /// Quad detector XDIFF, YDIFF, SUM, position outputs XPOS, YPOS and status bits, by
    /// operating mode: monitor (outputs 0), open loop (outputs as set), closed loop (the
    /// outputs cancel the beam's offset).
    fn quad(&self, ui: usize) -> (i64, i64, i64, i64, i64, u32) {
        let u = &self.units[ui];
        let (bx, by, sum) = QUAD_BEAM;
        match u.sub_param("QUAD_GET_PARAMS", 7, "mode") {
            Some(2) => {
                let x = u.sub_param("QUAD_GET_PARAMS", 0x0D, "x_pos").unwrap_or(0);
                let y = u.sub_param("QUAD_GET_PARAMS", 0x0D, "y_pos").unwrap_or(0);
                (bx, by, sum, x, y, 0x2)
            }
            Some(3) | Some(4) => {
                let (rx, ry) = QUAD_RESIDUAL;
                (rx, ry, sum, -2 * bx, -2 * by, 0x4)
            }
            _ => (bx, by, sum, 0, 0, 0x1),
        }
    }

    fn send(&mut self, now: u64, b: Option<Vec<u8>>) {
        if let Some(b) = b {
            self.line.send(now, b);
        }
    }

    fn info(&self, src: u8, serial: u32, nchs: i64, hw_type: i64) -> Vec<u8> {
        let (major, interim, minor) = match self.model {
            AptModel::Tdc001 => (2, 0, 4),
            _ => (3, 0, 11),
        };
        build(
            "HW_GET_INFO",
            None,
            HOST,
            src,
            &[
                ("serial_number", int(serial as i64)),
                ("model_number", FieldValue::Text(self.model.name().into())),
                ("hw_type", int(hw_type)),
                ("fw_minor", int(minor)),
                ("fw_interim", int(interim)),
                ("fw_major", int(major)),
                ("hw_version", int(1)),
                ("mod_state", int(0)),
                ("nchs", int(nchs)),
            ],
        )
        .unwrap_or_default()
    }

    fn status_bits(&self, ui: usize, now: u64) -> u32 {
        let u = &self.units[ui];
        let mut bits = MOTOR_CONNECTED;
        if u.enabled {
            bits |= ENABLED;
        }
        if u.homed {
            bits |= HOMED;
        }
        let (p, moving) = match u.motion {
            Some(m) if now < m.end_ns() => (m.pos(now).0, Some(m)),
            Some(m) => (m.to, None),
            None => (u.pos, None),
        };
        if let Some(m) = moving {
            let cw = m.dir > 0;
            bits |= match (m.kind, cw) {
                (Kind::Jog, true) => JOGGING_CW,
                (Kind::Jog, false) => JOGGING_CCW,
                (_, true) => MOVING_CW,
                (_, false) => MOVING_CCW,
            };
            if m.kind == Kind::Home {
                bits |= HOMING;
            }
        }
        let max = self.scaling.max_pos();
        if p >= max {
            bits |= CW_HW_LIMIT;
        }
        if p <= 0 && u.homed {
            bits |= CCW_HW_LIMIT;
        }
        bits
    }

    /// MOT_GET_DCSTATUSUPDATE (or MOVE_COMPLETED/MOVE_STOPPED, same structure). Velocity is the
    /// speed in counts/s divided by 10 (the spec leaves its scale to the controller).
    fn dc_status(&self, ui: usize, now: u64, name: &str, chan: i64) -> Option<Vec<u8>> {
        let u = &self.units[ui];
        let (p, v) = u.motion.map_or((u.pos, 0.0), |m| m.pos(now));
        build(
            name,
            Some(14),
            HOST,
            u.addr,
            &[
                ("chan_ident", int(chan)),
                ("position", int(p)),
                (
                    "velocity",
                    int(((v / 10.0).round() as i64).clamp(0, 0xFFFF)),
                ),
                ("status_bits", int(self.status_bits(ui, now) as i64)),
            ],
        )
    }

    /// The model's periodic status message.
    fn status_update(&self, ui: usize, now: u64) -> Option<Vec<u8>> {
        let u = &self.units[ui];
        match self.model {
            AptModel::Kpz101 => {
                let v = u.param("PZ_GET_OUTPUTVOLTS", "voltage").unwrap_or(0);
                let mut bits = PZ_ACTUATOR_CONNECTED;
                if u.param("PZ_GET_POSCONTROLMODE", "mode")
                    .is_some_and(|m| m == 2 || m == 4)
                {
                    bits |= 0x400;
                }
                build(
                    "PZ_GET_PZSTATUSUPDATE",
                    None,
                    HOST,
                    u.addr,
                    &[
                        ("chan_ident", int(1)),
                        ("op_voltage", int(v)),
                        ("position", int(0)),
                        ("status_bits", int(bits as i64)),
                    ],
                )
            }
            AptModel::Bsc203 => {
                let (p, _) = u.motion.map_or((u.pos, 0.0), |m| m.pos(now));
                // Stepper status bits share the low 11 bits with mot_status.
                let bits = self.status_bits(ui, now) & 0x7FF;
                build(
                    "MOT_GET_STATUSUPDATE",
                    Some(28),
                    HOST,
                    u.addr,
                    &[
                        ("chan_ident", int(1)),
                        ("position", int(p)),
                        ("enc_count", int(0)),
                        ("status_bits", int(bits as i64)),
                        ("chan_ident2", int(1)),
                    ],
                )
            }
            AptModel::Tls001 => {
                let (c, p, bits) = self.laser(ui);
                build(
                    "LA_GET_STATUSUPDATE",
                    None,
                    HOST,
                    u.addr,
                    &[
                        ("laser_current", int(c)),
                        ("laser_power", int(p)),
                        ("status_bits", int(bits as i64)),
                    ],
                )
            }
            AptModel::Ttc001 => {
                let (i, ta, ts, bits) = self.tec(ui);
                build(
                    "TEC_GET_STATUSUPDATE",
                    None,
                    HOST,
                    u.addr,
                    &[
                        ("i_tec", int(i)),
                        ("t_act", int(ta)),
                        ("t_set", int(ts)),
                        ("status_bits", int(bits as i64)),
                    ],
                )
            }
            AptModel::Kpa101 => {
                let q = self.quad(ui);
                build(
                    "QUAD_GET_STATUSUPDATE",
                    None,
                    HOST,
                    u.addr,
                    &[
                        ("x_diff", int(q.0)),
                        ("y_diff", int(q.1)),
                        ("sum", int(q.2)),
                        ("x_pos", int(q.3)),
                        ("y_pos", int(q.4)),
                        ("status_bits", int(q.5 as i64)),
                    ],
                )
            }
            _ => self.dc_status(ui, now, "MOT_GET_DCSTATUSUPDATE", 1),
        }
    }

    /// The next event (motion end or status update) at or before `now`, if any.
    fn next_event(&self, now: u64) -> Option<(u64, usize, bool)> {
        let mut best: Option<(u64, usize, bool)> = None;
        for (i, u) in self.units.iter().enumerate() {
            let cands = [
                u.motion.map(|m| (m.end_ns(), i, true)),
                u.next_update.map(|t| (t, i, false)),
            ];
            for c in cands.into_iter().flatten() {
                if c.0 <= now && best.is_none_or(|b| c.0 < b.0) {
                    best = Some(c);
                }
            }
        }
        best
    }

    fn run_events(&mut self, now: u64) {
        // Far behind (a stalled runner): skip missed status updates rather than flood.
        for u in &mut self.units {
            if let Some(t) = u.next_update {
                if now > t + SEC {
                    u.next_update = Some(now - (now - t) % UPDATE_NS);
                }
            }
        }
        while let Some((t, ui, is_motion)) = self.next_event(now) {
            if is_motion {
                let Some(m) = self.units[ui].motion.take() else {
                    continue;
                };
                let u = &mut self.units[ui];
                u.pos = m.to;
                let b = match m.kind {
                    Kind::Home => {
                        u.homed = true;
                        build(
                            "MOT_MOVE_HOMED",
                            None,
                            HOST,
                            u.addr,
                            &[("chan_ident", int(m.chan))],
                        )
                    }
                    Kind::Velocity | Kind::Stopping => {
                        self.dc_status(ui, t, "MOT_MOVE_STOPPED", m.chan)
                    }
                    Kind::Move | Kind::Jog => self.dc_status(ui, t, "MOT_MOVE_COMPLETED", m.chan),
                };
                self.send(t, b);
            } else {
                self.units[ui].next_update = Some(t + UPDATE_NS);
                let b = self.status_update(ui, t);
                self.send(t, b);
            }
        }
    }
}

impl Simulator for AptSim {
    fn input(&mut self, bytes: &[u8], now_ns: u64) {
        // Events due before this input happen first.
        self.run_events(now_ns);
        self.framer.push(bytes);
        let mut frames: Vec<Vec<u8>> = vec![];
        while let Some(item) = self.framer.next_item() {
            if let Item::Frame {
                bytes,
                truncated: false,
                ..
            } = item
            {
                frames.push(bytes.to_vec());
            }
        }
        for f in frames {
            self.handle(&f, now_ns);
        }
    }

    fn poll(&mut self, now_ns: u64) -> Option<Vec<u8>> {
        self.run_events(now_ns);
        self.line.take_due(now_ns)
    }

    fn next_deadline(&self) -> Option<u64> {
        let mut d = self.line.next_due();
        for u in &self.units {
            d = earliest(d, u.motion.map(|m| m.end_ns()));
            d = earliest(d, u.next_update);
        }
        d
    }
}

/// Encode `name` from `src` to `dst`: the data form of length `len` when given, else the first
/// form holding every named field (header-only when no values). Values the form lacks are
/// dropped; `None` only if the table cannot encode them (a bug, never input-driven).
pub(crate) fn build(
    name: &str,
    len: Option<u16>,
    dst: u8,
    src: u8,
    vals: &[(&str, FieldValue)],
) -> Option<Vec<u8>> {
    let m = Table::global().msg_by_name(name)?;
    let forms = m.forms.iter().filter(|f| f.kind != FormKind::Sub);
    let has = |f: &&aptscope_dissector::table::Form| {
        vals.iter()
            .all(|(k, _)| f.fields.iter().any(|x| x.name == *k))
    };
    let form = match len {
        Some(n) => forms.clone().find(|f| f.kind == FormKind::Data(n)),
        None => forms
            .clone()
            .find(|f| has(f) && (!vals.is_empty() || f.kind == FormKind::Header))
            .or_else(|| forms.clone().find(has))
            .or_else(|| forms.clone().next()),
    }?;
    let vals: Vec<(&str, FieldValue)> = vals
        .iter()
        .filter(|(k, _)| form.fields.iter().any(|x| x.name == *k))
        .cloned()
        .collect();
    encode(form, &vals, m.id, dst, src).ok()
}

/// Encode sub-message `id` of the group of `get` (an `x_GET_PARAMS`) from `src` to `dst`, with
/// the sub-message id first and the fields its form has; `None` if the table has no such block.
pub(crate) fn build_sub(
    get: &str,
    id: u16,
    dst: u8,
    src: u8,
    vals: &[(&str, FieldValue)],
) -> Option<Vec<u8>> {
    let t = Table::global();
    let m = t.msg_by_name(get)?;
    let sub = t.sub(m.subs?, id)?;
    let form = sub.forms.iter().find(|f| {
        vals.iter()
            .all(|(k, _)| f.fields.iter().any(|x| x.name == *k))
    })?;
    let mut v: Vec<(&str, FieldValue)> = vec![("sub_id", int(id as i64))];
    v.extend(
        vals.iter()
            .filter(|(k, _)| *k != "sub_id" && form.fields.iter().any(|x| x.name == *k))
            .cloned(),
    );
    encode(form, &v, m.id, dst, src).ok()
}

/// The sub-message parameter blocks a model answers, with their power-on values.
fn sub_params(model: AptModel) -> Vec<(&'static str, u16, Params)> {
    let f = FieldValue::Float;
    match model {
        AptModel::Tls001 => {
            let g = "LA_GET_PARAMS";
            vec![
                (g, 0x01, vec![("setpoint", int(0))]),
                (
                    g,
                    0x03,
                    vec![("laser_current", int(0)), ("laser_power", int(0))],
                ),
                (g, 0x05, vec![("laser_source", int(0))]),
                (g, 0x07, vec![("status_bits", int(0))]),
                (
                    g,
                    0x09,
                    // 50 mA, 2.5 mW, 635 nm.
                    vec![
                        ("max_current", int(5000)),
                        ("max_power", int(25_000)),
                        ("wavelength", int(635)),
                    ],
                ),
                (
                    g,
                    0x0B,
                    vec![("disp_intensity", int(255)), ("disp_units", int(2))],
                ),
            ]
        }
        AptModel::Ttc001 => {
            let g = "TEC_GET_PARAMS";
            vec![
                (g, 0x01, vec![("t_set", int(2500))]),
                (
                    g,
                    0x03,
                    vec![("i_tec", int(0)), ("t_act", int(0)), ("t_set", int(0))],
                ),
                (g, 0x05, vec![("sensor", int(1)), ("i_lim", int(1000))]),
                (g, 0x07, vec![("status_bits", int(0))]),
                (
                    g,
                    0x09,
                    vec![
                        ("p_gain", int(0x5332)),
                        ("i_gain", int(0x6665)),
                        ("d_gain", int(0x4CCC)),
                    ],
                ),
                (
                    g,
                    0x0B,
                    vec![("disp_intensity", int(255)), ("disp_mode", int(0))],
                ),
            ]
        }
        AptModel::Kpa101 => {
            let g = "QUAD_GET_PARAMS";
            vec![
                (
                    g,
                    0x01,
                    vec![
                        ("p_gain", int(21_298)),
                        ("i_gain", int(26_213)),
                        ("d_gain", int(19_660)),
                    ],
                ),
                (
                    g,
                    0x03,
                    vec![
                        ("x_diff", int(0)),
                        ("y_diff", int(0)),
                        ("sum", int(0)),
                        ("x_pos", int(0)),
                        ("y_pos", int(0)),
                    ],
                ),
                (
                    g,
                    0x05,
                    vec![
                        ("x_pos_demand_min", int(-32_767)),
                        ("y_pos_demand_min", int(-32_767)),
                        ("x_pos_demand_max", int(32_767)),
                        ("y_pos_demand_max", int(32_767)),
                        ("lv_out_route", int(2)),
                        ("open_loop_pos_demands", int(1)),
                        ("x_pos_demand_fb_sense", int(32_767)),
                        ("y_pos_demand_fb_sense", int(32_767)),
                    ],
                ),
                (g, 0x07, vec![("mode", int(1))]),
                (g, 0x09, vec![("status_bits", int(0))]),
                (
                    g,
                    0x0B,
                    vec![
                        ("disp_intensity", int(255)),
                        ("disp_mode", int(1)),
                        ("disp_dim_timeout", int(0)),
                    ],
                ),
                (g, 0x0D, vec![("x_pos", int(0)), ("y_pos", int(0))]),
                (
                    g,
                    0x0E,
                    vec![
                        ("pid_consts_p", f(65.7)),
                        ("pid_consts_i", f(80.3)),
                        ("pid_consts_d", f(60.9)),
                        ("pid_consts_dfc", f(500.0)),
                        ("filter_fc", f(500.0)),
                        ("filter_q", f(5.0)),
                        ("notch_filter_on", int(2)),
                        ("pid_deriv_filter_on", int(1)),
                    ],
                ),
                (
                    g,
                    0x0F,
                    vec![
                        ("trig1_mode", int(0x0B)),
                        ("trig1_polarity", int(1)),
                        ("trig1_sum_min", int(10)),
                        ("trig1_sum_max", int(90)),
                        ("trig1_diff_threshold", int(50)),
                        ("trig2_mode", int(0x0A)),
                        ("trig2_polarity", int(1)),
                        ("trig2_sum_min", int(10)),
                        ("trig2_sum_max", int(90)),
                        ("trig2_diff_threshold", int(50)),
                    ],
                ),
                (g, 0x10, vec![("dig_ops", int(0))]),
            ]
        }
        _ => vec![],
    }
}
