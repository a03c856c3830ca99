//! Outputs that react to their SETs: piezo, laser, laser diode, TEC and quad readings.

use super::*;

impl AptSim {
    /// Outputs that react beyond storing the value: the laser source's enable, the piezo's
    /// output voltage (within 0..100 %, only while the channel is enabled), the strain gauge's
    /// zero. False when `r` is not of this family.
    pub(super) fn output_msg(&mut self, r: &Req<'_, '_>) -> bool {
        let Req { f, m, ui, .. } = *r;
        match m.id {
            msg::LA_ENABLEOUTPUT | msg::LA_DISABLEOUTPUT => {
                self.units[ui].output = m.id == msg::LA_ENABLEOUTPUT;
            }
            msg::PZ_SET_OUTPUTVOLTS => {
                if let Some(v) = f.field("voltage").and_then(|(_, v)| v.as_i64()) {
                    if self.units[ui].enabled {
                        let v = v.clamp(0, 32767);
                        self.set_field(ui, msg::PZ_GET_OUTPUTVOLTS, "voltage", v);
                    }
                }
            }
            msg::PZ_SET_NTMODE => {
                // The mode set (piezo, latch, track on both axes or one) as PZ_GET_NTMODE
                // reports it: a tracking NanoTrak has a signal here.
                let (state, mode) = match f.field("state").and_then(|(_, v)| v.as_i64()) {
                    Some(1) => (1, 1),
                    Some(2) => (2, 1),
                    Some(3) => (4, 1),
                    Some(4) => (4, 2),
                    Some(5) => (4, 3),
                    _ => return true,
                };
                let b = frame(msg::PZ_GET_NTMODE, [state, mode], None, HOST, USB);
                self.keep(ui, msg::PZ_GET_NTMODE, 0, &b);
            }
            msg::PZ_SET_ZERO if self.model.0.family == Family::StrainGauge => {
                // The gauge takes its present reading as zero.
                self.set_field(ui, msg::PZ_GET_TSG_READING, "reading", 0);
                self.set_field(ui, msg::PZ_GET_TSG_READING, "smoothed", 0);
            }
            _ => return false,
        }
        true
    }

    /// Readings of a sub-message block that come from the unit's state, not from SET_PARAMS.
    pub(super) fn live(&self, ui: usize, get: u16, id: u16, now: u64) -> Params {
        match (get, id) {
            (msg::LA_GET_PARAMS, msg::la::CURRENT_POWER) => {
                let (c, p, _) = self.laser(ui);
                vec![("laser_current", int(c)), ("laser_power", int(p))]
            }
            (msg::LA_GET_PARAMS, msg::la::STATUS_BITS) => {
                vec![("status_bits", int(self.laser(ui).2 as i64))]
            }
            (msg::TEC_GET_PARAMS, msg::tec::READINGS) => tec_readings(self.tec(ui)),
            (msg::TEC_GET_PARAMS, msg::tec::STATUS_BITS) => {
                vec![("status_bits", int(self.tec(ui).3 as i64))]
            }
            (msg::QUAD_GET_PARAMS, msg::quad::READINGS) => quad_readings(self.quad(ui)),
            (msg::PZMOT_GET_PARAMS, msg::pzmot::POS_COUNTS) => {
                vec![("position", int(self.unit_pos(ui, now)))]
            }
            (msg::QUAD_GET_PARAMS, msg::quad::STATUS_BITS) => {
                vec![("status_bits", int(self.quad(ui).5 as i64))]
            }
            _ => vec![],
        }
    }

    /// Laser current and power (0..32767) and status bits: the power follows the setpoint while
    /// the output is on.
    pub(super) fn laser(&self, ui: usize) -> (i64, i64, u32) {
        let u = &self.units[ui];
        let sp = self
            .held_field(ui, msg::LA_GET_PARAMS, msg::la::SETPOINT, "setpoint")
            .unwrap_or(0);
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
    pub(super) fn tec(&self, ui: usize) -> (i64, i64, i64, u32) {
        let g = msg::TEC_GET_PARAMS;
        let ts = self
            .held_field(ui, g, msg::tec::TEMP_SETPOINT, "t_set")
            .unwrap_or(0);
        let lim = self
            .held_field(ui, g, msg::tec::IO_SETTINGS, "i_lim")
            .unwrap_or(TEC_HOLD_MA);
        let disp = match self.held_field(ui, g, msg::tec::DISP_SETTINGS, "disp_mode") {
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
    pub(super) fn quad(&self, ui: usize) -> (i64, i64, i64, i64, i64, u32) {
        let g = msg::QUAD_GET_PARAMS;
        let (bx, by, sum) = QUAD_BEAM;
        match self.held_field(ui, g, msg::quad::OPER_MODE, "mode") {
            Some(2) => {
                let d = msg::quad::POS_DEMAND_OUTPUTS;
                let x = self.held_field(ui, g, d, "x_pos").unwrap_or(0);
                let y = self.held_field(ui, g, d, "y_pos").unwrap_or(0);
                (bx, by, sum, x, y, 0x2)
            }
            Some(3) | Some(4) => {
                let (rx, ry) = QUAD_RESIDUAL;
                (rx, ry, sum, -2 * bx, -2 * by, 0x4)
            }
            _ => (bx, by, sum, 0, 0, 0x1),
        }
    }
}

/// TEC_GET_PARAMS READINGS from [`AptSim::tec`]'s values: also the start of TEC_GET_STATUSUPDATE.
pub(super) fn tec_readings((i, ta, ts, _): (i64, i64, i64, u32)) -> Params {
    vec![("i_tec", int(i)), ("t_act", int(ta)), ("t_set", int(ts))]
}

/// QUAD_GET_PARAMS READINGS from [`AptSim::quad`]'s values: also the start of
/// QUAD_GET_STATUSUPDATE.
pub(super) fn quad_readings(q: (i64, i64, i64, i64, i64, u32)) -> Params {
    vec![
        ("x_diff", int(q.0)),
        ("y_diff", int(q.1)),
        ("sum", int(q.2)),
        ("x_pos", int(q.3)),
        ("y_pos", int(q.4)),
    ]
}
