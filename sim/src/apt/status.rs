//! Status: the status bits of a unit and the status messages each family sends.

use super::*;

impl AptSim {
    pub(super) fn status_bits(&self, ui: usize, now: u64) -> u32 {
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
        if self.model.0.family != Family::InertiaMotor {
            if p >= max {
                bits |= CW_HW_LIMIT;
            }
            // A flipper reports its first position on the CCW switch.
            if p <= 0 && (u.homed || self.model.0.family == Family::Flipper) {
                bits |= CCW_HW_LIMIT;
            }
        }
        bits
    }

    /// MOT_GET_DCSTATUSUPDATE (or MOVE_COMPLETED/MOVE_STOPPED, same structure). Velocity is the
    /// speed in counts/s divided by 10 (the spec leaves its scale to the controller).
    pub(super) fn dc_status(
        &self,
        ui: usize,
        now: u64,
        id: u16,
        chan: i64,
        src: u8,
    ) -> Option<Vec<u8>> {
        let u = &self.units[ui];
        let (p, v) = u.motion.map_or((u.pos, 0.0), |m| m.pos(now));
        build(
            id,
            Some(14),
            HOST,
            src,
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

    /// The status message a family sends after HW_START_UPDATEMSGS: the first of its
    /// candidates the model implements.
    pub(super) fn status_msg(&self) -> u16 {
        let cands: &[u16] = match self.model.0.family {
            Family::DcServo | Family::Brushless | Family::Polariser => {
                &[msg::MOT_GET_DCSTATUSUPDATE, msg::MOT_GET_STATUSUPDATE]
            }
            Family::Stepper | Family::Solenoid | Family::Flipper => {
                &[msg::MOT_GET_STATUSUPDATE, msg::MOT_GET_DCSTATUSUPDATE]
            }
            Family::Piezo | Family::StrainGauge => &[msg::PZ_GET_PZSTATUSUPDATE],
            Family::NanoTrak => &[msg::PZ_GET_NTSTATUSUPDATE],
            Family::Laser => &[msg::LA_GET_STATUSUPDATE],
            Family::LaserDiode => &[msg::LD_GET_STATUSUPDATE, msg::LA_GET_STATUSUPDATE],
            Family::Tec => &[msg::TEC_GET_STATUSUPDATE],
            Family::Quad => &[msg::QUAD_GET_STATUSUPDATE],
            Family::InertiaMotor => &[msg::PZMOT_GET_STATUSUPDATE, msg::MOT_GET_STATUSUPDATE],
        };
        let t = Table::global();
        cands
            .iter()
            .copied()
            .find(|id| self.profile.as_ref().is_none_or(|p| t.implements(p, *id)))
            .unwrap_or(cands[0])
    }

    /// Status message `get` of unit `ui` from `src`: the family's live values in the message's
    /// fields, the rest as the defaults have them.
    pub(super) fn status_update(&self, ui: usize, now: u64, get: u16, src: u8) -> Option<Vec<u8>> {
        let u = &self.units[ui];
        let chan = i64::from(u.chan);
        let pos = u.motion.map_or(u.pos, |m| m.pos(now).0);
        let bits = i64::from(self.status_bits(ui, now));
        let vals: Vec<(&str, FieldValue)> = match get {
            msg::MOT_GET_DCSTATUSUPDATE => {
                return self.dc_status(ui, now, get, chan, src);
            }
            msg::PZ_GET_PZSTATUSUPDATE => {
                let v = self
                    .held_field(ui, msg::PZ_GET_OUTPUTVOLTS, 0, "voltage")
                    .unwrap_or(0);
                let mut bits = PZ_ACTUATOR_CONNECTED;
                let mode = self.held_field(ui, msg::PZ_GET_POSCONTROLMODE, 0, "mode");
                if mode.is_some_and(|m| m == 2 || m == 4) {
                    bits |= 0x400;
                }
                vec![
                    ("chan_ident", int(chan)),
                    ("op_voltage", int(v)),
                    ("position", int(0)),
                    ("status_bits", int(bits as i64)),
                ]
            }
            msg::MOT_GET_STATUSUPDATE => {
                // Stepper status bits share the low 11 bits with mot_status.
                vec![
                    ("chan_ident", int(chan)),
                    ("position", int(pos)),
                    ("enc_count", int(0)),
                    ("status_bits", int(bits & 0x7FF)),
                    ("chan_ident2", int(chan)),
                ]
            }
            msg::LA_GET_STATUSUPDATE => {
                let (c, p, bits) = self.laser(ui);
                vec![
                    ("laser_current", int(c)),
                    ("laser_power", int(p)),
                    ("status_bits", int(bits as i64)),
                ]
            }
            msg::LD_GET_STATUSUPDATE => {
                // A laser diode driver: the current follows the power setpoint while the output
                // is on; key switch, supply and stability bits set.
                let (c, _, _) = self.laser(ui);
                let on = self.units[ui].output;
                let out = if on { LD_OUTPUT } else { 0 };
                let bits = LD_KEYSWITCH | LD_PSU_OK | LD_STABLE | out;
                vec![
                    ("laser_current", int(c)),
                    ("photo_current", int(c / 2)),
                    ("laser_voltage", int(if on { 1800 } else { 0 })),
                    ("status_bits", int(i64::from(bits))),
                ]
            }
            msg::PZ_GET_NTSTATUSUPDATE => {
                // The spec's example status, with the tracking bits of the mode set.
                let m = Table::global().msg(get)?;
                let b = self.held(ui, m, 0, src)?;
                let f = AptFrame::decode(Table::global(), 0, &b, false)?;
                let mut vals = values_of(&f);
                let tracking = self.units[ui]
                    .store
                    .iter()
                    .find(|s| s.get == msg::PZ_GET_NTMODE)
                    .is_some_and(|s| s.params[0] >= 3);
                let bits = NT_CHANS | if tracking { NT_TRACKING } else { 0 };
                for (n, v) in &mut vals {
                    if *n == "status_bits" {
                        *v = int(i64::from(bits));
                    }
                }
                vals
            }
            msg::TEC_GET_STATUSUPDATE => {
                let t = self.tec(ui);
                let mut vals = outputs::tec_readings(t);
                vals.push(("status_bits", int(t.3 as i64)));
                vals
            }
            msg::QUAD_GET_STATUSUPDATE => {
                let q = self.quad(ui);
                let mut vals = outputs::quad_readings(q);
                vals.push(("status_bits", int(q.5 as i64)));
                vals
            }
            msg::PZMOT_GET_STATUSUPDATE => {
                // All four channels of the controller in one message.
                const NAMES: [[&str; 3]; 4] = [
                    ["chan_ident1", "position1", "status_bits1"],
                    ["chan_ident2", "position2", "status_bits2"],
                    ["chan_ident3", "position3", "status_bits3"],
                    ["chan_ident4", "position4", "status_bits4"],
                ];
                let mut v = vec![];
                let chans = self
                    .units
                    .iter()
                    .enumerate()
                    .filter(|(_, x)| x.addr == u.addr);
                for ((i, x), n) in chans.zip(NAMES) {
                    let bits = i64::from(self.status_bits(i, now) & 0x7FF);
                    v.push((n[0], int(1 << (x.chan - 1).min(3))));
                    v.push((n[1], int(self.unit_pos(i, now))));
                    v.push((n[2], int(bits)));
                }
                v
            }
            _ => {
                // No live values: the defaults (NanoTrak, laser diode readings).
                let m = Table::global().msg(get)?;
                let mut b = self.held(ui, m, 0, src)?;
                set_chan(&mut b, chan);
                return Some(b);
            }
        };
        build(get, None, HOST, src, &vals)
    }
}
