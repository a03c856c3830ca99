//! The APT controller simulator: one generic core for every model of [`crate::models`], with
//! the behaviour of each family in one place.
//!
//! Generic: every request of the model's message list (the table's device profile) is answered
//! with its GET, from what a SET stored for that channel, else from the spec's example for the
//! GET (or its SET, same layout) where the table holds one, else zeros (enumerations' first
//! value is not needed: the decoder checks structure, and zero is the spec's power-on value for
//! most fields). Messages the model does not implement are ignored, as a device ignores them,
//! and the simulator's log ([`Simulator::take_log`]) says so.

use crate::models::{self, Family, ModelSpec};
use crate::{earliest, Line, Simulator, MS, SEC};
use aptscope_dissector::apt::{encode, AptFrame, AptFramer, FieldValue, Item, Value};
use aptscope_dissector::msg;
use aptscope_dissector::table::{
    example_bytes, Access, DeviceProfile, FormKind, Loc, MsgDef, Table,
};
use aptscope_dissector::units;

mod model;
mod motion;
mod outputs;
mod status;

pub use model::{model_list, AptModel};
use model::{serial_of, Scaling};
use motion::{Kind, Motion};

/// Named field values, as the encoder takes them.
type Params = Vec<(&'static str, FieldValue)>;

/// Host address.
const HOST: u8 = 0x01;
/// Rack (motherboard) address.
const RACK: u8 = 0x11;
/// First bay address.
const BAY0: u8 = 0x21;
/// Generic USB unit address.
const USB: u8 = 0x50;
/// Period of status updates after HW_START_UPDATEMSGS.
const UPDATE_NS: u64 = 100 * MS;
/// Status updates a controller sends without the host's "server alive" ACK before it stops
/// (spec, MOT_ACK_DCSTATUSUPDATE: "about 50").
const KEEPALIVE_UPDATES: u32 = 50;
/// Homing: searching the limit switch and backing off, on top of the travel to it.
const HOME_BASE_NS: u64 = 2 * SEC;
/// 115 200 baud, 8N1: 10 bits per byte.
const BYTE_NS: u64 = 86_806;
/// Time from a request to the first byte of its reply.
const TURNAROUND_NS: u64 = MS;
/// Lines the log keeps before the oldest are dropped (nobody reading it).
const LOG_MAX: usize = 1000;

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
// ld_status bits (pylablib's KinesisLaserDiodeDriver reads the same).
const LD_OUTPUT: u32 = 0x1;
const LD_KEYSWITCH: u32 = 0x2;
const LD_PSU_OK: u32 = 0x1000;
const LD_STABLE: u32 = 0x8000_0000;
// nt_status bits: tracking with a signal; both channels connected.
const NT_TRACKING: u32 = 0x3;
const NT_CHANS: u32 = 0x3_0000;
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
/// Counts per mm or degree of a stage the units table does not know (MPC paddles, flippers).
const DEFAULT_COUNTS: f64 = 1000.0;

/// A parameter block a unit holds for one GET message (and sub-message): the frame's param
/// bytes or data packet, as a SET sent it or the defaults made it.
#[derive(Debug, Clone)]
struct Stored {
    get: u16,
    sub: u16,
    params: [u8; 2],
    data: Option<Vec<u8>>,
}

/// One addressable channel: a single unit's channel (address 0x50, also 0x21) or a rack's bay
/// (or the rack itself, at 0x11).
#[derive(Debug, Clone)]
struct Unit {
    addr: u8,
    /// Channel number (1-based) within its address.
    chan: u8,
    /// The rack's motherboard: rack messages only, no status.
    rack: bool,
    serial: u32,
    enabled: bool,
    /// Laser output on (LA_ENABLEOUTPUT).
    output: bool,
    homed: bool,
    pos: i64,
    motion: Option<Motion>,
    /// Next status update, while updates are on.
    next_update: Option<u64>,
    /// Status updates sent since the host's last ACK.
    unacked: u32,
    /// Updates stopped for want of the host's ACK (they resume with it).
    starved: bool,
    /// Where its status updates come from (0x50 or 0x21: where the host started them).
    update_src: u8,
    store: Vec<Stored>,
}

/// A simulated APT controller (sans-io): see the module documentation of `sim/src/apt/mod.rs`.
///
/// Single units answer at the generic USB address 0x50 and at bay address 0x21 (where
/// thorlabs-apt-device's TDC001 class sends), each reply from the address the request named;
/// racks answer as the motherboard at 0x11 (and 0x50) and as bays 0x21…, each bay from its own
/// address. Move commands are ignored while a channel is disabled, as real controllers do.
/// Moves follow a trapezoidal profile from the velocity parameters in the units of the model's
/// family (spec section 8), homing takes 2 s plus the travel back to 0 at the homing velocity.
/// The `velocity` of DC status updates is the speed in counts/s divided by 10 (the spec leaves
/// it to the model).
#[derive(Debug)]
pub struct AptSim {
    model: AptModel,
    profile: Option<DeviceProfile>,
    scaling: Scaling,
    serial: u32,
    units: Vec<Unit>,
    framer: AptFramer<'static>,
    line: Line,
    identified: u32,
    log: Vec<String>,
}

fn int(v: i64) -> FieldValue {
    FieldValue::Int(v)
}

/// A message to one unit, as the family handlers of [`AptSim`] take it.
#[derive(Clone, Copy)]
struct Req<'r, 'a> {
    f: &'r AptFrame<'a, 'static>,
    m: &'static MsgDef,
    /// Index of the unit addressed.
    ui: usize,
    /// The channel ident as the host sent it (echoed in replies).
    chan: i64,
    /// The address the request named: replies come from it.
    src: u8,
    now: u64,
}

impl AptSim {
    /// A controller of this model with a default serial number (prefix + `000123`).
    pub fn new(model: AptModel) -> AptSim {
        Self::with_serial(model, serial_of(model.0, 0))
    }

    /// A controller with this serial number.
    pub fn with_serial(model: AptModel, serial: u32) -> AptSim {
        let spec = model.0;
        let s = model.scaling();
        let mut units = vec![];
        let unit = |addr: u8, chan: u8, serial: u32, rack: bool| Unit {
            addr,
            chan,
            rack,
            serial,
            enabled: true,
            output: false,
            homed: false,
            pos: 0,
            motion: None,
            next_update: None,
            unacked: 0,
            starved: false,
            update_src: addr,
            store: vec![],
        };
        if spec.bays > 0 {
            units.push(unit(RACK, 1, serial, true));
            for b in 0..spec.bays {
                for c in 1..=spec.channels {
                    units.push(unit(BAY0 + b, c, serial + u32::from(b), false));
                }
            }
        } else {
            for c in 1..=spec.channels {
                units.push(unit(USB, c, serial, false));
            }
        }
        let mut sim = AptSim {
            model,
            profile: model.profile(),
            scaling: s,
            serial,
            units,
            framer: AptFramer::new(Table::global()),
            line: Line::new(BYTE_NS, TURNAROUND_NS),
            identified: 0,
            log: vec![],
        };
        for ui in 0..sim.units.len() {
            if !sim.units[ui].rack {
                sim.seed(ui);
            }
        }
        sim
    }

    /// The model simulated.
    pub fn model(&self) -> AptModel {
        self.model
    }

    /// How many MOD_IDENTIFY requests were received (the LED would flash).
    pub fn identify_count(&self) -> u32 {
        self.identified
    }

    fn note(&mut self, s: String) {
        if self.log.len() >= LOG_MAX {
            self.log.remove(0);
        }
        self.log.push(s);
    }

    /// Position counter of the unit at `addr` (0x50, or a bay address) at `now_ns`.
    pub fn position(&self, addr: u8, now_ns: u64) -> Option<i64> {
        let ui = self.units.iter().position(|u| u.addr == addr && !u.rack)?;
        Some(self.unit_pos(ui, now_ns))
    }

    /// Position counter of unit `ui` at `now`.
    fn unit_pos(&self, ui: usize, now: u64) -> i64 {
        let u = &self.units[ui];
        u.motion.map_or(u.pos, |m| m.pos(now).0)
    }

    /// The power-on parameters of a family that has them: motion parameters in the units of
    /// the model's stage, and the sub-message blocks of laser, TEC and quad controllers.
    fn seed(&mut self, ui: usize) {
        let s = self.scaling;
        let fam = self.model.0.family;
        let vals: Vec<(u16, Params)> = if fam.moves() {
            vec![
                (
                    msg::MOT_GET_VELPARAMS,
                    vec![
                        ("min_vel", int(0)),
                        ("acceleration", int(s.acc_param(1.5))),
                        ("max_vel", int(s.vel_param(2.0))),
                    ],
                ),
                (
                    msg::MOT_GET_JOGPARAMS,
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
                    msg::MOT_GET_HOMEPARAMS,
                    vec![
                        ("home_dir", int(2)),
                        ("limit_switch", int(1)),
                        ("home_velocity", int(s.vel_param(1.0))),
                        ("offset_distance", int((s.counts_per_mm * 0.1) as i64)),
                    ],
                ),
                (
                    msg::MOT_GET_LIMSWITCHPARAMS,
                    vec![
                        ("cw_hard_limit", int(2)),
                        ("ccw_hard_limit", int(2)),
                        ("cw_soft_limit", int(s.max_pos())),
                        ("ccw_soft_limit", int(0)),
                        ("soft_limit_mode", int(1)),
                    ],
                ),
                (
                    msg::MOT_GET_GENMOVEPARAMS,
                    vec![("backlash_distance", int(0))],
                ),
                (
                    msg::MOT_GET_MOVERELPARAMS,
                    vec![("relative_distance", int(0))],
                ),
                (
                    msg::MOT_GET_MOVEABSPARAMS,
                    vec![("absolute_position", int(0))],
                ),
                (
                    msg::MOT_GET_POWERPARAMS,
                    vec![("rest_factor", int(10)), ("move_factor", int(30))],
                ),
            ]
        } else if fam == Family::Piezo {
            vec![
                (msg::PZ_GET_OUTPUTVOLTS, vec![("voltage", int(0))]),
                (msg::PZ_GET_POSCONTROLMODE, vec![("mode", int(1))]),
                (msg::PZ_GET_OUTPUTPOS, vec![("position_sw", int(0))]),
                (
                    msg::PZ_GET_OUTPUTMAXVOLTS,
                    vec![("voltage", int(750)), ("flags", int(0x2))],
                ),
                (msg::PZ_GET_MAXTRAVEL, vec![("travel", int(0))]),
                (
                    msg::PZ_GET_INPUTVOLTSSRC,
                    vec![("volts_src", int(0)), ("source", int(0))],
                ),
            ]
        } else {
            vec![]
        };
        let chan = i64::from(self.units[ui].chan);
        for (get, v) in vals {
            let mut all = vec![("chan_ident", int(chan))];
            all.extend(v);
            if let Some(b) = build(get, None, HOST, USB, &all) {
                self.keep(ui, get, 0, &b);
            }
        }
        for (get, sub, v) in sub_params(fam) {
            if let Some(b) = build_sub(get, sub, HOST, USB, &v) {
                self.keep(ui, get, sub, &b);
            }
        }
    }

    /// Store the parameters of frame `b` (a GET or the SET of the same layout) as `get`'s.
    fn keep(&mut self, ui: usize, get: u16, sub: u16, b: &[u8]) {
        if b.len() < 6 {
            return;
        }
        let has_data = b[4] & 0x80 != 0;
        let st = Stored {
            get,
            sub,
            params: [b[2], b[3]],
            data: has_data.then(|| b[6..].to_vec()),
        };
        let store = &mut self.units[ui].store;
        match store.iter_mut().find(|s| s.get == get && s.sub == sub) {
            Some(slot) => *slot = st,
            None => store.push(st),
        }
    }

    /// The frame of `get` (sub-message `sub`) from `src` with what unit `ui` holds, or the
    /// defaults.
    fn held(&self, ui: usize, get: &'static MsgDef, sub: u16, src: u8) -> Option<Vec<u8>> {
        let st = self.units[ui]
            .store
            .iter()
            .find(|s| s.get == get.id && s.sub == sub);
        let (params, data) = match st {
            Some(s) => (s.params, s.data.clone()),
            None => defaults(get, sub)?,
        };
        Some(frame(get.id, params, data.as_deref(), HOST, src))
    }

    /// A numeric field of what unit `ui` holds for `get` (sub-message `sub`).
    fn held_field(&self, ui: usize, get: u16, sub: u16, field: &str) -> Option<i64> {
        let m = Table::global().msg(get)?;
        let b = self.held(ui, m, sub, USB)?;
        let f = AptFrame::decode(Table::global(), 0, &b, false)?;
        f.field(field).and_then(|(_, v)| v.as_i64())
    }

    /// Store one field of what unit `ui` holds for `get`.
    fn set_field(&mut self, ui: usize, get: u16, field: &str, v: i64) {
        let Some(m) = Table::global().msg(get) else {
            return;
        };
        let Some(mut b) = self.held(ui, m, 0, USB) else {
            return;
        };
        let Some(f) = AptFrame::decode(Table::global(), 0, &b, false) else {
            return;
        };
        let Some(form) = f.form else { return };
        let Some(fd) = form.fields.iter().find(|x| x.name == field) else {
            return;
        };
        let at = fd.loc.frame_offset();
        let w = fd.ty.width();
        let bytes = v.to_le_bytes();
        if at + w <= b.len() && w <= 8 {
            b[at..at + w].copy_from_slice(&bytes[..w]);
            self.keep(ui, get, 0, &b);
        }
    }

    /// Answer `r` with `get` from its unit: its channel, then `vals`.
    fn reply(&mut self, r: &Req<'_, '_>, get: u16, vals: &[(&str, FieldValue)]) {
        let mut all = vec![("chan_ident", int(r.chan))];
        all.extend_from_slice(vals);
        let b = build(get, None, HOST, r.src, &all);
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
        let dst = f.header().dst_byte();
        let rack = self.model.0.bays > 0;
        let implemented = self
            .profile
            .as_ref()
            .is_none_or(|p| table.implements(p, m.id));
        if !implemented {
            self.note(format!(
                "ignored {} to 0x{dst:02X}: not a message the {} implements",
                m.name,
                self.model.name()
            ));
            return;
        }
        let chan_raw = f
            .field("chan_ident")
            .and_then(|(_, v)| v.as_i64())
            .filter(|c| *c > 0);
        let chan = f.channel().filter(|c| *c > 0).unwrap_or(1);
        // Single units answer at 0x50 and as bay 0x21; racks as the motherboard (0x11, and
        // 0x50) and per bay.
        let addr = match (rack, dst) {
            (false, USB | BAY0) => USB,
            (true, USB | RACK) => RACK,
            (true, d) => d,
            (false, _) => 0,
        };
        let Some(ui) = self
            .units
            .iter()
            .position(|u| u.addr == addr && i64::from(u.chan) == chan)
            .or_else(|| self.units.iter().position(|u| u.addr == addr))
        else {
            self.note(format!(
                "ignored {} to 0x{dst:02X}: no such unit on a {}",
                m.name,
                self.model.name()
            ));
            return;
        };
        let r = Req {
            f: &f,
            m,
            ui,
            chan: chan_raw.unwrap_or(1),
            src: dst,
            now,
        };
        if self.units[ui].rack {
            if !self.rack_msg(&r) {
                self.generic(&r);
            }
            return;
        }
        let handled = self.module_msg(&r)
            || self.readback_msg(&r)
            || self.motion_msg(&r)
            || self.output_msg(&r);
        if !handled {
            self.generic(&r);
        }
    }

    /// Messages to a rack's motherboard rather than a bay.
    fn rack_msg(&mut self, r: &Req<'_, '_>) -> bool {
        let now = r.now;
        let bays = i64::from(self.model.0.bays);
        match r.m.id {
            msg::HW_REQ_INFO => {
                let b = self.info(r.src, self.serial, bays, 45);
                self.line.send(now, b);
            }
            msg::RACK_REQ_BAYUSED => {
                let bay = r.f.field("bay_ident").and_then(|(_, v)| v.as_i64());
                let bay = bay.unwrap_or(0);
                let state = if (0..bays).contains(&bay) { 1 } else { 2 };
                let b = build(
                    msg::RACK_GET_BAYUSED,
                    None,
                    HOST,
                    r.src,
                    &[("bay_ident", int(bay)), ("bay_state", int(state))],
                );
                self.send(now, b);
            }
            msg::MOD_IDENTIFY => self.identified += 1,
            msg::HW_START_UPDATEMSGS | msg::HW_STOP_UPDATEMSGS => {
                let start = r.m.id == msg::HW_START_UPDATEMSGS;
                for u in self.units.iter_mut().filter(|u| !u.rack) {
                    if start {
                        u.next_update.get_or_insert(now + UPDATE_NS);
                        u.unacked = 0;
                    } else {
                        u.next_update = None;
                    }
                }
            }
            _ => return false,
        }
        true
    }

    /// Module-level messages: information, identify, status update switches and their
    /// keep-alive, channel enable. False when `r` is not of this family.
    fn module_msg(&mut self, r: &Req<'_, '_>) -> bool {
        let Req {
            f, m, ui, now, src, ..
        } = *r;
        match m.id {
            msg::HW_REQ_INFO => {
                let hw = if self.model.0.bays > 0 { 45 } else { 44 };
                let nchs = i64::from(self.model.0.channels);
                let b = self.info(src, self.units[ui].serial, nchs, hw);
                self.line.send(now, b);
            }
            msg::MOD_IDENTIFY => self.identified += 1,
            msg::HW_START_UPDATEMSGS => {
                let addr = self.units[ui].addr;
                // An inertia motor controller's status message covers its four channels.
                let one = self.model.0.family == Family::InertiaMotor;
                for u in self.units.iter_mut().filter(|u| u.addr == addr) {
                    u.update_src = src;
                    if one && u.chan != 1 {
                        continue;
                    }
                    u.next_update.get_or_insert(now + UPDATE_NS);
                    u.unacked = 0;
                }
            }
            msg::HW_STOP_UPDATEMSGS => {
                let addr = self.units[ui].addr;
                for u in self.units.iter_mut().filter(|u| u.addr == addr) {
                    u.next_update = None;
                    u.starved = false;
                }
            }
            msg::MOT_ACK_DCSTATUSUPDATE
            | msg::PZ_ACK_PZSTATUSUPDATE
            | msg::PZ_ACK_NTSTATUSUPDATE
            | msg::LA_ACK_STATUSUPDATE
            | msg::LD_ACK_STATUSUPDATE
            | msg::TEC_ACK_STATUSUPDATE
            | msg::QUAD_ACK_STATUSUPDATE
            | msg::PZMOT_ACK_STATUSUPDATE => {
                // The host is alive: the count starts again, and updates stopped for want of
                // it resume (thorlabs-apt-device's first ACK can come after the 50th update).
                let addr = self.units[ui].addr;
                for u in self.units.iter_mut().filter(|u| u.addr == addr) {
                    u.unacked = 0;
                    if std::mem::take(&mut u.starved) {
                        u.next_update = Some(now + UPDATE_NS);
                    }
                }
            }
            msg::MOD_SET_CHANENABLESTATE => {
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
            msg::MOD_REQ_CHANENABLESTATE => {
                let st = if self.units[ui].enabled { 1 } else { 2 };
                self.reply(
                    r,
                    msg::MOD_GET_CHANENABLESTATE,
                    &[("enable_state", int(st))],
                );
            }
            _ => return false,
        }
        true
    }

    /// Requests for counters and status: answered from the unit's state. False when `r` is not of
    /// this family.
    fn readback_msg(&mut self, r: &Req<'_, '_>) -> bool {
        let Req { f, m, ui, now, .. } = *r;
        match m.id {
            msg::MOT_REQ_POSCOUNTER | msg::MOT_REQ_ENCCOUNTER => {
                let p = self.unit_pos(ui, now);
                let (get, field) = if m.id == msg::MOT_REQ_POSCOUNTER {
                    (msg::MOT_GET_POSCOUNTER, "position")
                } else {
                    (msg::MOT_GET_ENCCOUNTER, "encoder_count")
                };
                self.reply(r, get, &[(field, int(p))]);
            }
            msg::MOT_SET_POSCOUNTER | msg::MOT_SET_ENCCOUNTER => {
                let field = if m.id == msg::MOT_SET_POSCOUNTER {
                    "position"
                } else {
                    "encoder_count"
                };
                let u = &mut self.units[ui];
                if let (Some(v), None) = (f.field(field).and_then(|(_, v)| v.as_i64()), u.motion) {
                    u.pos = v;
                }
            }
            msg::MOT_REQ_STATUSBITS => {
                let bits = self.status_bits(ui, now);
                self.reply(
                    r,
                    msg::MOT_GET_STATUSBITS,
                    &[("status_bits", int(bits as i64))],
                );
            }
            msg::MOT_REQ_DCSTATUSUPDATE => {
                let b = self.dc_status(ui, now, msg::MOT_GET_DCSTATUSUPDATE, r.chan, r.src);
                self.send(now, b);
            }
            msg::MOT_REQ_STATUSUPDATE
            | msg::PZ_REQ_PZSTATUSUPDATE
            | msg::PZ_REQ_NTSTATUSUPDATE
            | msg::LA_REQ_STATUSUPDATE
            | msg::LD_REQ_STATUSUPDATE
            | msg::TEC_REQ_STATUSUPDATE
            | msg::QUAD_REQ_STATUSUPDATE
            | msg::PZMOT_REQ_STATUSUPDATE => {
                let get = Table::global()
                    .reply_ids(m)
                    .first()
                    .copied()
                    .unwrap_or(msg::MOT_GET_STATUSUPDATE);
                let b = self.status_update(ui, now, get, r.src);
                self.send(now, b);
            }
            msg::PZ_REQ_PZSTATUSBITS => {
                let bits = int(PZ_ACTUATOR_CONNECTED as i64);
                self.reply(r, msg::PZ_GET_PZSTATUSBITS, &[("status_bits", bits)]);
            }
            _ => return false,
        }
        true
    }

    /// Moves, homing and stops: start or end the unit's motion (motor families only). False
    /// when `r` is not of this family.
    fn motion_msg(&mut self, r: &Req<'_, '_>) -> bool {
        let Req {
            f,
            m,
            ui,
            chan,
            now,
            ..
        } = *r;
        let sc = self.scaling;
        let fam = self.model.0.family;
        let motion = matches!(
            m.id,
            msg::MOT_MOVE_HOME
                | msg::MOT_MOVE_ABSOLUTE
                | msg::MOT_MOVE_RELATIVE
                | msg::MOT_MOVE_JOG
                | msg::MOT_MOVE_VELOCITY
                | msg::MOT_MOVE_STOP
                | msg::PZMOT_MOVE_ABSOLUTE
                | msg::PZMOT_MOVE_JOG
        );
        if !motion {
            return false;
        }
        if !fam.moves() {
            return true;
        }
        let fv = |n: &str| f.field(n).and_then(|(_, v)| v.as_i64());
        match m.id {
            msg::MOT_MOVE_HOME => {
                let u = &self.units[ui];
                if !u.enabled {
                    return true;
                }
                let from = self.unit_pos(ui, now);
                let hv = self
                    .held_field(ui, msg::MOT_GET_HOMEPARAMS, 0, "home_velocity")
                    .unwrap_or(1);
                let hv = sc.counts_s(hv);
                let secs = HOME_BASE_NS as f64 / SEC as f64 + from.unsigned_abs() as f64 / hv;
                let mut mo = Motion::linear(Kind::Home, now, from, 0, secs, chan);
                if from == 0 {
                    // Already at zero: the search for the reverse limit switch still runs CCW.
                    mo.dir = -1;
                }
                self.units[ui].motion = Some(mo);
                self.units[ui].homed = false;
            }
            msg::PZMOT_MOVE_ABSOLUTE | msg::PZMOT_MOVE_JOG => {
                if !self.units[ui].enabled {
                    return true;
                }
                // Inertia motors count steps at the drive's step rate and acceleration
                // (PZMOT sub-messages 7 and 9); they have no end of travel.
                let from = self.unit_pos(ui, now);
                let g = msg::PZMOT_GET_PARAMS;
                let sub = |s: u16, n: &str| self.held_field(ui, g, s, n);
                let v = sub(msg::pzmot::DRIVE_OP_PARAMS, "step_rate").unwrap_or(500);
                let a = sub(msg::pzmot::DRIVE_OP_PARAMS, "step_accn").unwrap_or(100_000);
                let (v, a) = ((v as f64).max(1.0), (a as f64).max(1.0));
                let (kind, to) = if m.id == msg::PZMOT_MOVE_ABSOLUTE {
                    (Kind::Move, fv("abs_position").unwrap_or(from))
                } else {
                    let step = sub(msg::pzmot::TIM_JOG_PARAMS, "jog_step_size").unwrap_or(250);
                    let back = fv("jog_dir") == Some(2);
                    (Kind::Jog, if back { from - step } else { from + step })
                };
                self.units[ui].motion = Some(Motion::trapezoid(kind, now, from, to, v, a, chan));
            }
            msg::MOT_MOVE_ABSOLUTE
            | msg::MOT_MOVE_RELATIVE
            | msg::MOT_MOVE_JOG
            | msg::MOT_MOVE_VELOCITY => {
                if !self.units[ui].enabled {
                    return true;
                }
                let from = self.unit_pos(ui, now);
                let p = |get: u16, n: &str| self.held_field(ui, get, 0, n);
                let vel = |get: u16, vf: &str, af: &str| {
                    (
                        sc.counts_s(p(get, vf).unwrap_or(1)),
                        sc.counts_s2(p(get, af).unwrap_or(1)),
                    )
                };
                let (v, a) = vel(msg::MOT_GET_VELPARAMS, "max_vel", "acceleration");
                let (jv, ja) = vel(msg::MOT_GET_JOGPARAMS, "jog_max_vel", "jog_acceleration");
                let max = sc.max_pos();
                let (kind, to, v, a) = match m.id {
                    msg::MOT_MOVE_ABSOLUTE => {
                        let to = fv("absolute_position")
                            .or_else(|| p(msg::MOT_GET_MOVEABSPARAMS, "absolute_position"));
                        (Kind::Move, to.unwrap_or(from), v, a)
                    }
                    msg::MOT_MOVE_RELATIVE => {
                        let d = fv("relative_distance")
                            .or_else(|| p(msg::MOT_GET_MOVERELPARAMS, "relative_distance"));
                        (Kind::Move, from.saturating_add(d.unwrap_or(0)), v, a)
                    }
                    msg::MOT_MOVE_JOG if fam == Family::Flipper => {
                        // A flipper jogs between its two end positions.
                        let back = fv("direction") == Some(2);
                        (Kind::Move, if back { 0 } else { max }, v, a)
                    }
                    msg::MOT_MOVE_JOG => {
                        let back = fv("direction") == Some(2);
                        if p(msg::MOT_GET_JOGPARAMS, "jog_mode") == Some(1) {
                            (Kind::Velocity, if back { 0 } else { max }, jv, ja)
                        } else {
                            let step = p(msg::MOT_GET_JOGPARAMS, "jog_step_size").unwrap_or(0);
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
                let mut mo = Motion::trapezoid(kind, now, from, to, v, a, chan);
                mo.silent = self
                    .profile
                    .as_ref()
                    .is_some_and(|p| !Table::global().answers(p, m.id));
                self.units[ui].motion = Some(mo);
            }
            _ => {
                // MOT_MOVE_STOP.
                let profiled = fv("stop_mode") == Some(2);
                let u = &mut self.units[ui];
                let Some(mo) = u.motion else {
                    // Not moving: a stop is still acknowledged.
                    let b = self.dc_status(ui, now, msg::MOT_MOVE_STOPPED, chan, r.src);
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
                        silent: false,
                    });
                } else {
                    u.motion = None;
                    u.pos = p;
                    let b = self.dc_status(ui, now, msg::MOT_MOVE_STOPPED, chan, r.src);
                    self.send(now, b);
                }
            }
        }
        true
    }

    /// SET_x stores its parameters for GET_x (per channel); REQ_x answers with GET_x: what was
    /// stored, else the defaults. Sub-message groups (x_SET/REQ/GET_PARAMS) by sub-message id.
    fn generic(&mut self, r: &Req<'_, '_>) {
        let Req { f, m, ui, now, .. } = *r;
        let t = Table::global();
        let Some((gm, access)) = t.readback_of(m) else {
            return;
        };
        let sub = if m.subs.is_some() {
            let id = f
                .field("sub_id")
                .and_then(|(_, v)| v.as_i64())
                .and_then(|i| u16::try_from(i).ok())
                .or(f.sub.map(|s| s.id));
            let Some(id) = id else { return };
            id
        } else {
            0
        };
        // Laser sources, TEC and quad controllers have the blocks their family seeded; the
        // group's other blocks belong to its other models (TLD_, KLD_, KPA_ …).
        let seeded = matches!(
            self.model.0.family,
            Family::Laser | Family::Tec | Family::Quad
        );
        let held = self.units[ui]
            .store
            .iter()
            .any(|s| s.get == gm.id && s.sub == sub);
        if m.subs.is_some() && seeded && !held {
            self.note(format!(
                "ignored {} sub-message {sub}: a block the {} does not have",
                m.name,
                self.model.name()
            ));
            return;
        }
        if access == Access::Set {
            // Only what the GET can carry: a SET of another length is not its layout.
            let has_data = f.header().has_data();
            let len = f.data_len();
            if m.subs.is_some() || t.accepts_len(gm, has_data, len) {
                self.keep(ui, gm.id, sub, f.bytes);
            }
            return;
        }
        let Some(mut b) = self.held(ui, gm, sub, r.src) else {
            return;
        };
        // Live readings where the block has them.
        let live = self.live(ui, gm.id, sub, now);
        if !live.is_empty() {
            if let Some(fr) = AptFrame::decode(t, 0, &b, false) {
                let mut vals = values_of(&fr);
                vals.retain(|(n, _)| *n != "sub_id");
                for (name, v) in live {
                    if let Some(s) = vals.iter_mut().find(|(n, _)| *n == name) {
                        s.1 = v;
                    }
                }
                if let Some(nb) = build_sub(gm.id, sub, HOST, r.src, &vals) {
                    b = nb;
                }
            }
        }
        set_chan(&mut b, r.chan);
        self.line.send(now, b);
    }

    fn send(&mut self, now: u64, b: Option<Vec<u8>>) {
        if let Some(b) = b {
            self.line.send(now, b);
        }
    }

    fn info(&self, src: u8, serial: u32, nchs: i64, hw_type: i64) -> Vec<u8> {
        let (major, interim, minor) = self.model.0.firmware;
        build(
            msg::HW_GET_INFO,
            None,
            HOST,
            src,
            &[
                ("serial_number", int(i64::from(serial))),
                ("model_number", FieldValue::Text(self.model.name().into())),
                ("hw_type", int(hw_type)),
                ("fw_minor", int(minor.into())),
                ("fw_interim", int(interim.into())),
                ("fw_major", int(major.into())),
                ("hw_version", int(1)),
                ("mod_state", int(0)),
                ("nchs", int(nchs)),
            ],
        )
        .unwrap_or_default()
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
                let src = u.update_src;
                let b = if m.kind == Kind::Home {
                    self.units[ui].homed = true;
                    build(
                        msg::MOT_MOVE_HOMED,
                        None,
                        HOST,
                        src,
                        &[("chan_ident", int(m.chan))],
                    )
                } else if m.silent {
                    // pylablib's MFF class (written against the hardware) polls the status
                    // bits and takes a MOT_MOVE_COMPLETED for an error: a flipper sends none
                    // (the table's `silent` line for MFF101/MFF102).
                    None
                } else if self.model.0.family == Family::InertiaMotor {
                    let bits = i64::from(self.status_bits(ui, t) & 0x7FF);
                    build(
                        msg::PZMOT_MOVE_COMPLETED,
                        None,
                        HOST,
                        src,
                        &[
                            ("chan_ident", int(m.chan)),
                            ("abs_position", int(m.to)),
                            ("status_bits", int(bits)),
                        ],
                    )
                } else {
                    match m.kind {
                        Kind::Home => {
                            self.units[ui].homed = true;
                            build(
                                msg::MOT_MOVE_HOMED,
                                None,
                                HOST,
                                src,
                                &[("chan_ident", int(m.chan))],
                            )
                        }
                        Kind::Velocity | Kind::Stopping => {
                            self.dc_status(ui, t, msg::MOT_MOVE_STOPPED, m.chan, src)
                        }
                        Kind::Move | Kind::Jog => {
                            self.dc_status(ui, t, msg::MOT_MOVE_COMPLETED, m.chan, src)
                        }
                    }
                };
                self.send(t, b);
            } else {
                let u = &mut self.units[ui];
                u.unacked += 1;
                if u.unacked > KEEPALIVE_UPDATES {
                    // The host has not said it is alive: the controller stops its updates.
                    u.next_update = None;
                    u.starved = true;
                    let addr = u.addr;
                    self.note(format!(
                        "status updates of 0x{addr:02X} stopped: {KEEPALIVE_UPDATES} sent \
                         without the host's ACK"
                    ));
                    continue;
                }
                u.next_update = Some(t + UPDATE_NS);
                let src = u.update_src;
                let b = self.status_update(ui, t, self.status_msg(), src);
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

    /// Messages ignored as not for the model or to no address it has, sub-message blocks it
    /// does not have, status updates stopped for want of the host's ACK.
    fn take_log(&mut self) -> Vec<String> {
        std::mem::take(&mut self.log)
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

/// The numeric fields of a frame as the encoder takes them back.
fn values_of(f: &AptFrame<'_, '_>) -> Params {
    f.fields()
        .filter_map(|(fd, v)| match v {
            Value::F(x) => Some((fd.name, FieldValue::Float(x))),
            v => Some((fd.name, int(v.as_i64()?))),
        })
        .collect()
}

/// A frame of message `id` with these param bytes, or this data packet.
fn frame(id: u16, params: [u8; 2], data: Option<&[u8]>, dst: u8, src: u8) -> Vec<u8> {
    let mut b = Vec::with_capacity(6 + data.map_or(0, <[u8]>::len));
    b.extend_from_slice(&id.to_le_bytes());
    match data {
        Some(d) => {
            let len = u16::try_from(d.len()).unwrap_or(u16::MAX);
            b.extend_from_slice(&len.to_le_bytes());
            b.push(dst | 0x80);
            b.push(src);
            b.extend_from_slice(d);
        }
        None => {
            b.extend_from_slice(&params);
            b.push(dst);
            b.push(src);
        }
    }
    b
}

/// Write the host's channel ident into `b`'s `chan_ident` field, where its form has one.
fn set_chan(b: &mut [u8], chan: i64) {
    let Some(f) = AptFrame::decode(Table::global(), 0, b, false) else {
        return;
    };
    let Some(fd) = f.form.and_then(|fo| fo.chan_field()) else {
        return;
    };
    let (at, w) = (fd.loc.frame_offset(), fd.ty.width());
    if at + w <= b.len() && (1..=2).contains(&w) {
        b[at..at + w].copy_from_slice(&chan.to_le_bytes()[..w]);
    }
}

/// The power-on parameters of `get` (sub-message `sub`, 0 for none): the spec's example for
/// the GET or its SET where the table holds one that fits, else zeros in its first form (the
/// sub-message id in place).
fn defaults(get: &MsgDef, sub: u16) -> Option<([u8; 2], Option<Vec<u8>>)> {
    let t = Table::global();
    let set = get.name.find("_GET_").and_then(|i| {
        let name = format!("{}_SET_{}", &get.name[..i], &get.name[i + 5..]);
        t.msg_by_name(&name)
    });
    let examples: Vec<&aptscope_dissector::table::Example> = if sub != 0 {
        let sd = t.sub_of(get, get.subs?, sub)?;
        sd.examples.iter().collect()
    } else {
        get.examples
            .iter()
            .chain(set.iter().flat_map(|s| s.examples.iter()))
            .collect()
    };
    let ids: Vec<u16> = [Some(get.id), set.map(|s| s.id)]
        .into_iter()
        .flatten()
        .collect();
    for ex in examples.iter().filter(|e| e.bad_reason.is_none()) {
        let Ok(b) = example_bytes(ex.hex) else {
            continue;
        };
        let Some(f) = AptFrame::decode(t, 0, &b, false) else {
            continue;
        };
        let id = f.msg.map_or(0, |m| m.id);
        if !ids.contains(&id) || f.diags().next().is_some() {
            continue;
        }
        let has_data = f.header().has_data();
        if sub != 0 && f.sub.map(|s| s.id) != Some(sub) {
            continue;
        }
        if sub == 0 && !t.accepts_len(get, has_data, f.data_len()) {
            continue;
        }
        let data = has_data.then(|| b.get(6..6 + f.data_len()).unwrap_or(&[]).to_vec());
        return Some(([b[2], b[3]], data));
    }
    if sub != 0 {
        let sd = t.sub_of(get, get.subs?, sub)?;
        let form = sd.forms.first()?;
        let len = form.encoded_len(0)?;
        let mut b = vec![0u8; 6 + len];
        first_enum_values(form, &mut b);
        let mut d = b.split_off(6);
        if d.len() >= 2 {
            d[..2].copy_from_slice(&sub.to_le_bytes());
        }
        return Some(([0, 0], Some(d)));
    }
    let form = get
        .forms
        .iter()
        .find(|f| matches!(f.kind, FormKind::Data(_)))
        .or_else(|| get.forms.iter().find(|f| f.kind == FormKind::Header))?;
    match form.kind {
        FormKind::Data(_) => {
            let mut b = vec![0u8; 6 + form.encoded_len(0)?];
            first_enum_values(form, &mut b);
            Some(([0, 0], Some(b.split_off(6))))
        }
        _ => {
            // A header-only GET: its param bytes, a channel 1 where p1 is the channel.
            let p1 = form
                .fields
                .iter()
                .any(|f| f.loc == Loc::P1 && f.name == "chan_ident");
            Some(([u8::from(p1), 0], None))
        }
    }
}

/// In the zeroed frame `b` of `form`, each enumerated field whose 0 is no value of its
/// enumeration set to the enumeration's first value (clients reject what the device never
/// sends: pylablib's KPZ101 voltage range of 0).
fn first_enum_values(form: &aptscope_dissector::table::Form, b: &mut [u8]) {
    let t = Table::global();
    for f in &form.fields {
        let Some(e) = f.enumeration.map(|i| t.enum_def(i)) else {
            continue;
        };
        let Some(&(v, _)) = e.items.first() else {
            continue;
        };
        if e.label(0).is_some() {
            continue;
        }
        let (at, w) = (f.loc.frame_offset(), f.ty.width());
        if w <= 8 && at + w <= b.len() {
            b[at..at + w].copy_from_slice(&v.to_le_bytes()[..w]);
        }
    }
}

/// Encode message `id` from `src` to `dst`: the data form of length `len` when given, else the
/// first form holding every named field (header-only when no values). Values the form lacks
/// are dropped; `None` only if the table cannot encode them (a bug, never input-driven).
pub(crate) fn build(
    id: u16,
    len: Option<u16>,
    dst: u8,
    src: u8,
    vals: &[(&str, FieldValue)],
) -> Option<Vec<u8>> {
    let m = Table::global().msg(id)?;
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

/// Encode sub-message `sub` of the group of `get` (an `x_GET_PARAMS`) from `src` to `dst`,
/// with the sub-message id first and the fields its form has; `None` if the table has no such
/// block.
pub(crate) fn build_sub(
    get: u16,
    sub: u16,
    dst: u8,
    src: u8,
    vals: &[(&str, FieldValue)],
) -> Option<Vec<u8>> {
    let t = Table::global();
    let m = t.msg(get)?;
    let sd = t.sub_of(m, m.subs?, sub)?;
    let form = sd.forms.iter().find(|f| {
        vals.iter()
            .all(|(k, _)| f.fields.iter().any(|x| x.name == *k))
    })?;
    let mut v: Vec<(&str, FieldValue)> = vec![("sub_id", int(i64::from(sub)))];
    v.extend(
        vals.iter()
            .filter(|(k, _)| *k != "sub_id" && form.fields.iter().any(|x| x.name == *k))
            .cloned(),
    );
    encode(form, &v, m.id, dst, src).ok()
}

/// The sub-message parameter blocks of a family, with their power-on values (the others come
/// from the spec's examples).
fn sub_params(family: Family) -> Vec<(u16, u16, Params)> {
    let f = FieldValue::Float;
    match family {
        Family::Laser | Family::LaserDiode => {
            let g = msg::LA_GET_PARAMS;
            vec![
                (g, msg::la::SETPOINT, vec![("setpoint", int(0))]),
                (
                    g,
                    msg::la::CURRENT_POWER,
                    vec![("laser_current", int(0)), ("laser_power", int(0))],
                ),
                (g, msg::la::POWER_SOURCE, vec![("laser_source", int(0))]),
                (g, msg::la::STATUS_BITS, vec![("status_bits", int(0))]),
                (
                    g,
                    msg::la::MAX_LIMITS,
                    // 50 mA, 2.5 mW, 635 nm.
                    vec![
                        ("max_current", int(5000)),
                        ("max_power", int(25_000)),
                        ("wavelength", int(635)),
                    ],
                ),
                (
                    g,
                    msg::la::DISPLAY,
                    vec![("disp_intensity", int(255)), ("disp_units", int(2))],
                ),
            ]
        }
        Family::Tec => {
            let g = msg::TEC_GET_PARAMS;
            vec![
                (g, msg::tec::TEMP_SETPOINT, vec![("t_set", int(2500))]),
                (
                    g,
                    msg::tec::READINGS,
                    vec![("i_tec", int(0)), ("t_act", int(0)), ("t_set", int(0))],
                ),
                (
                    g,
                    msg::tec::IO_SETTINGS,
                    vec![("sensor", int(1)), ("i_lim", int(1000))],
                ),
                (g, msg::tec::STATUS_BITS, vec![("status_bits", int(0))]),
                (
                    g,
                    msg::tec::LOOP_PARAMS,
                    vec![
                        ("p_gain", int(0x5332)),
                        ("i_gain", int(0x6665)),
                        ("d_gain", int(0x4CCC)),
                    ],
                ),
                (
                    g,
                    msg::tec::DISP_SETTINGS,
                    vec![("disp_intensity", int(255)), ("disp_mode", int(0))],
                ),
            ]
        }
        Family::Quad => {
            let g = msg::QUAD_GET_PARAMS;
            vec![
                (
                    g,
                    msg::quad::LOOP_PARAMS,
                    vec![
                        ("p_gain", int(21_298)),
                        ("i_gain", int(26_213)),
                        ("d_gain", int(19_660)),
                    ],
                ),
                (
                    g,
                    msg::quad::READINGS,
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
                    msg::quad::POS_DEMAND_PARAMS,
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
                (g, msg::quad::OPER_MODE, vec![("mode", int(1))]),
                (g, msg::quad::STATUS_BITS, vec![("status_bits", int(0))]),
                (
                    g,
                    msg::quad::DISP_SETTINGS,
                    vec![
                        ("disp_intensity", int(255)),
                        ("disp_mode", int(1)),
                        ("disp_dim_timeout", int(0)),
                    ],
                ),
                (
                    g,
                    msg::quad::POS_DEMAND_OUTPUTS,
                    vec![("x_pos", int(0)), ("y_pos", int(0))],
                ),
                (
                    g,
                    msg::quad::LOOP_PARAMS2,
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
                    msg::quad::KPA_TRIG_IO_CONFIG,
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
                (g, msg::quad::KPA_DIG_OPS, vec![("dig_ops", int(0))]),
            ]
        }
        _ => vec![],
    }
}
