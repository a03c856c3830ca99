//! Which controller the simulator is: the model, its serial numbers and its motion scaling.

use super::*;

/// A controller model the simulator can be: an entry of [`models::MODELS`].
#[derive(Debug, Clone, Copy)]
pub struct AptModel(pub(super) &'static ModelSpec);

impl PartialEq for AptModel {
    fn eq(&self, o: &AptModel) -> bool {
        self.0.name == o.0.name
    }
}

impl Eq for AptModel {}

/// The models the first simulators had, by the names their callers use.
#[allow(non_upper_case_globals)]
impl AptModel {
    /// K-Cube brushed DC servo controller.
    pub const Kdc101: AptModel = AptModel(&models::KDC101);
    /// T-Cube DC servo controller.
    pub const Tdc001: AptModel = AptModel(&models::TDC001);
    /// K-Cube piezo controller.
    pub const Kpz101: AptModel = AptModel(&models::KPZ101);
    /// Three-bay benchtop stepper controller.
    pub const Bsc203: AptModel = AptModel(&models::BSC203);
    /// T-Cube laser source.
    pub const Tls001: AptModel = AptModel(&models::TLS001);
    /// T-Cube TEC controller.
    pub const Ttc001: AptModel = AptModel(&models::TTC001);
    /// K-Cube position aligner.
    pub const Kpa101: AptModel = AptModel(&models::KPA101);
}

impl AptModel {
    /// Every model, in the spec's order.
    pub fn all() -> impl Iterator<Item = AptModel> {
        models::MODELS.iter().map(AptModel)
    }

    /// The model `s` names (any case: `kdc101`, `BSC203`).
    pub fn parse(s: &str) -> Option<AptModel> {
        models::find(s).map(AptModel)
    }

    /// The model name as HW_GET_INFO gives it.
    pub fn name(self) -> &'static str {
        self.0.name
    }

    /// Its data: family, bays, channels, serial prefix, firmware, stage.
    pub fn spec(self) -> &'static ModelSpec {
        self.0
    }

    /// The first digits of the serial number.
    pub fn serial_prefix(self) -> u32 {
        self.0.serial_prefix
    }

    /// What it implements: the table's device profile (every model here has one; a test says
    /// so).
    pub fn profile(self) -> Option<DeviceProfile> {
        Table::global().device_profile(self.0.name)
    }

    /// Motion scaling from the units table's stage rows (spec section 8).
    pub(super) fn scaling(self) -> Scaling {
        let (stage, travel) = self.0.stage;
        let fam = units::model(self.0.name)
            .and_then(|m| m.family)
            .unwrap_or(match self.0.family {
                Family::Brushless => units::Family::Brushless,
                Family::Stepper => units::Family::Trinamic,
                _ => units::Family::DcServo,
            });
        let counts = units::stage_for(stage, fam).map_or(DEFAULT_COUNTS, |s| s.counts_per_unit);
        let (vel, acc) = match fam {
            // Section 8's DC servo and Trinamic factors to the digits the first simulators
            // used: the committed session recordings (samples/sessions/) hold positions
            // computed with them.
            units::Family::DcServo => (22.369_621, 0.007_635_4),
            units::Family::Trinamic => (53.687_091, 0.010_995),
            f => {
                let q = |q| f.factor(q, 1.0).unwrap_or(1.0);
                (
                    q(aptscope_dissector::table::Quantity::Vel),
                    q(aptscope_dissector::table::Quantity::Acc),
                )
            }
        };
        Scaling {
            counts_per_mm: counts,
            travel_mm: travel,
            vel,
            acc,
        }
    }
}

/// One line of `sim apt --list` per model: name, family, bays, channels, HW_GET_INFO serial.
pub fn model_list() -> String {
    let mut out = String::from("MODEL    FAMILY         BAYS  CHANNELS  SERIAL\n");
    for m in models::MODELS {
        let note = if m.prefix_in_spec { "" } else { " *" };
        out.push_str(&format!(
            "{:<8} {:<14} {:>4}  {:>8}  {}{}\n",
            m.name,
            m.family.name(),
            if m.bays == 0 {
                "-".to_string()
            } else {
                m.bays.to_string()
            },
            m.channels,
            serial_of(m, 0),
            note
        ));
    }
    out.push_str(
        "(bays: a rack answering at 0x11 with bays from 0x21; -: a single unit at 0x50 and \
         0x21)\n(*: serial prefix not in the spec's table)\n",
    );
    out
}

/// The serial number of unit `i` of a model (8 digits from its prefix).
pub(super) fn serial_of(m: &ModelSpec, i: u32) -> u32 {
    let p = m.serial_prefix;
    let base = if p >= 100 { p * 100_000 } else { p * 1_000_000 };
    base + 123 + i
}

#[derive(Debug, Clone, Copy)]
pub(super) struct Scaling {
    pub(super) counts_per_mm: f64,
    pub(super) travel_mm: f64,
    pub(super) vel: f64,
    pub(super) acc: f64,
}

impl Scaling {
    pub(super) fn max_pos(&self) -> i64 {
        (self.counts_per_mm * self.travel_mm) as i64
    }
    pub(super) fn vel_param(&self, mm_s: f64) -> i64 {
        (mm_s * self.counts_per_mm * self.vel).round() as i64
    }
    pub(super) fn acc_param(&self, mm_s2: f64) -> i64 {
        (mm_s2 * self.counts_per_mm * self.acc).round() as i64
    }
    /// counts/s from a velocity parameter (at least 1 count/s).
    pub(super) fn counts_s(&self, param: i64) -> f64 {
        (param as f64 / self.vel).max(1.0)
    }
    /// counts/s² from an acceleration parameter (at least 1 count/s²).
    pub(super) fn counts_s2(&self, param: i64) -> f64 {
        (param as f64 / self.acc).max(1.0)
    }
}
