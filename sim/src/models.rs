//! Every controller model the APT spec names (both revisions' "Messages Applicable to …" lists),
//! as data: its family (which behaviour it gets), its bays or channels, what HW_GET_INFO says
//! of it, and the stage its motion is scaled for. What messages a model takes is not here: it is
//! the message table's device profile (`Table::device_profile`, from `dissector/msgs/9*.apt`).

/// What a controller does, as the simulator models it: one behaviour per family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Family {
    /// Brushed DC servo motor controller.
    DcServo,
    /// Brushless DC servo motor controller.
    Brushless,
    /// Stepper motor controller (and the integrated stepper stages).
    Stepper,
    /// Solenoid (shutter) controller: on/off states.
    Solenoid,
    /// Motorised filter flipper: two positions.
    Flipper,
    /// Piezo amplifier: output voltage and position.
    Piezo,
    /// Strain gauge reader.
    StrainGauge,
    /// NanoTrak auto-alignment controller.
    NanoTrak,
    /// Laser source (LA_ messages).
    Laser,
    /// Laser diode driver (LA_ and LD_ messages).
    LaserDiode,
    /// Thermo-electric cooler controller.
    Tec,
    /// Quad detector / position aligner.
    Quad,
    /// Piezo inertia motor controller (PZMOT messages).
    InertiaMotor,
    /// Motorised polarisation controller: three paddles.
    Polariser,
}

impl Family {
    /// The family's name as `sim apt --list` shows it.
    pub fn name(self) -> &'static str {
        match self {
            Family::DcServo => "dc_servo",
            Family::Brushless => "brushless",
            Family::Stepper => "stepper",
            Family::Solenoid => "solenoid",
            Family::Flipper => "flipper",
            Family::Piezo => "piezo",
            Family::StrainGauge => "strain_gauge",
            Family::NanoTrak => "nanotrak",
            Family::Laser => "laser",
            Family::LaserDiode => "laser_diode",
            Family::Tec => "tec",
            Family::Quad => "quad",
            Family::InertiaMotor => "inertia_motor",
            Family::Polariser => "polariser",
        }
    }

    /// Whether the family drives motors: moves, homing, jogs and their end-of-move messages.
    pub fn moves(self) -> bool {
        matches!(
            self,
            Family::DcServo
                | Family::Brushless
                | Family::Stepper
                | Family::Flipper
                | Family::Polariser
                | Family::InertiaMotor
        )
    }
}

/// One controller model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelSpec {
    /// The model as HW_GET_INFO names it (`KDC101`).
    pub name: &'static str,
    /// Its behaviour.
    pub family: Family,
    /// Bays of a rack (card-slot benchtop: motherboard at 0x11, bays from 0x21); 0 for a
    /// single unit answering at 0x50.
    pub bays: u8,
    /// Channels of each unit (bay or single unit): 4 on the inertia motor controllers, 3
    /// paddles on the polarisation controllers, otherwise 1.
    pub channels: u8,
    /// The first two digits of its serial number.
    pub serial_prefix: u32,
    /// Whether the spec's table of serial prefixes gives it (otherwise a plausible free
    /// prefix).
    pub prefix_in_spec: bool,
    /// Firmware version (major, interim, minor) HW_GET_INFO reports.
    pub firmware: (u8, u8, u8),
    /// The stage whose scaling its moves use (`aptscope_dissector::units::STAGES`), and its
    /// travel in mm or degrees.
    pub stage: (&'static str, f64),
}

impl ModelSpec {
    /// Units that answer: one per bay of a rack, else one.
    pub fn units(&self) -> u8 {
        self.bays.max(1)
    }
}

const FW: (u8, u8, u8) = (3, 0, 11);
/// Prefix given by the spec's table.
const S: bool = true;
/// Prefix not in the spec's table.
const N: bool = false;

const fn m(
    name: &'static str,
    family: Family,
    bays: u8,
    channels: u8,
    serial_prefix: u32,
    prefix_in_spec: bool,
    stage: (&'static str, f64),
) -> ModelSpec {
    ModelSpec {
        name,
        family,
        bays,
        channels,
        serial_prefix,
        prefix_in_spec,
        firmware: FW,
        stage,
    }
}

use Family::*;

/// A Z8-type actuator on a DC servo controller: 25 mm.
const Z8: (&str, f64) = ("Z8xx", 25.0);
/// A DRV013-type actuator on a Trinamic stepper: 50 mm.
const DRV: (&str, f64) = ("DRV013", 50.0);
/// A DRV013-type actuator on a 128-microstep stepper: 50 mm.
const DRV_SM: (&str, f64) = ("DRV013", 50.0);
/// A DDS220 stage on a brushless controller.
const DDS: (&str, f64) = ("DDS220", 220.0);
/// A flipper's two positions, 1 unit apart.
const FLIP: (&str, f64) = ("MFF", 1.0);
/// No stage (outputs, not motion): positions are counts of a Z8 for what motion they have.
const NONE: (&str, f64) = ("Z8xx", 25.0);

/// The TDC001 (firmware 2.0.4 as the first simulators had it).
pub const TDC001: ModelSpec = ModelSpec {
    firmware: (2, 0, 4),
    ..m("TDC001", DcServo, 0, 1, 83, S, Z8)
};
/// The KDC101.
pub const KDC101: ModelSpec = m("KDC101", DcServo, 0, 1, 27, S, Z8);
/// The KPZ101.
pub const KPZ101: ModelSpec = m("KPZ101", Piezo, 0, 1, 29, S, NONE);
/// The BSC203.
pub const BSC203: ModelSpec = m("BSC203", Stepper, 3, 1, 70, S, DRV);
/// The TLS001.
pub const TLS001: ModelSpec = m("TLS001", Laser, 0, 1, 86, S, NONE);
/// The TTC001.
pub const TTC001: ModelSpec = m("TTC001", Tec, 0, 1, 87, S, NONE);
/// The KPA101.
pub const KPA101: ModelSpec = m("KPA101", Quad, 0, 1, 69, S, NONE);

/// Every model of the spec, in the order of its lists (a model spelt with an `x` in the spec,
/// BSC20x, is one entry per member: BSC201, BSC202, BSC203).
pub static MODELS: &[ModelSpec] = &[
    // Piezo.
    m("BPC201", Piezo, 1, 1, 41, N, NONE),
    m("BPC202", Piezo, 2, 1, 31, N, NONE),
    m("BPC203", Piezo, 3, 1, 71, S, NONE),
    m("BPC301", Piezo, 1, 1, 41, N, NONE),
    m("BPC302", Piezo, 2, 1, 31, N, NONE),
    m("BPC303", Piezo, 3, 1, 71, S, NONE),
    m("PPC001", Piezo, 0, 1, 44, S, NONE),
    m("PPC102", Piezo, 2, 1, 95, S, NONE),
    m("TPZ001", Piezo, 0, 1, 81, S, NONE),
    KPZ101,
    m("KPC101", Piezo, 0, 1, 113, N, NONE),
    m("MPZ601", Piezo, 2, 1, 51, S, NONE),
    m("CT1P", Piezo, 0, 1, 114, N, NONE),
    // Strain gauge readers.
    m("TSG001", StrainGauge, 0, 1, 84, S, NONE),
    m("KSG101", StrainGauge, 0, 1, 59, S, NONE),
    // DC servo.
    TDC001,
    KDC101,
    m("KVS30", DcServo, 0, 1, 24, N, ("KVS30", 30.0)),
    // Solenoid.
    m("TSC001", Solenoid, 0, 1, 85, S, NONE),
    m("KSC101", Solenoid, 0, 1, 68, S, NONE),
    // Steppers.
    m("TST001", Stepper, 0, 1, 80, S, DRV_SM),
    m("TST101", Stepper, 0, 1, 80, N, DRV),
    m("KST101", Stepper, 0, 1, 26, S, DRV),
    m("KST201", Stepper, 0, 1, 26, N, DRV),
    m("K10CR1", Stepper, 0, 1, 55, S, ("K10CR1", 360.0)),
    m("BSC101", Stepper, 1, 1, 40, S, DRV_SM),
    m("BSC102", Stepper, 2, 1, 30, N, DRV_SM),
    m("BSC103", Stepper, 3, 1, 70, S, DRV_SM),
    m("BSC201", Stepper, 1, 1, 40, N, DRV),
    m("BSC202", Stepper, 2, 1, 30, N, DRV),
    BSC203,
    m("LTS150", Stepper, 0, 1, 45, S, ("LTS150", 150.0)),
    m("LTS300", Stepper, 0, 1, 45, S, ("LTS300", 300.0)),
    m("MLJ050", Stepper, 0, 1, 49, S, ("MLJ050", 50.0)),
    m("MLJ150", Stepper, 0, 1, 49, S, ("MLJ150", 50.0)),
    m("MLJ250", Stepper, 0, 1, 49, N, ("MLJ250", 50.0)),
    // Flipper.
    m("MFF101", Flipper, 0, 1, 37, S, FLIP),
    m("MFF102", Flipper, 0, 1, 37, S, FLIP),
    // Brushless.
    m("BBD101", Brushless, 1, 1, 73, N, DDS),
    m("BBD102", Brushless, 2, 1, 73, N, DDS),
    m("BBD103", Brushless, 3, 1, 73, S, DDS),
    m("BBD201", Brushless, 1, 1, 73, N, DDS),
    m("BBD202", Brushless, 2, 1, 73, N, DDS),
    m("BBD203", Brushless, 3, 1, 73, N, DDS),
    m("BBD301", Brushless, 1, 1, 73, N, DDS),
    m("BBD302", Brushless, 2, 1, 73, N, DDS),
    m("BBD303", Brushless, 3, 1, 73, N, DDS),
    m("TBD001", Brushless, 0, 1, 67, S, DDS),
    m("KBD101", Brushless, 0, 1, 28, S, DDS),
    // Piezo inertia motors.
    m("PDXC2", InertiaMotor, 0, 1, 112, N, NONE),
    m("TIM101", InertiaMotor, 0, 4, 65, S, NONE),
    m("KIM101", InertiaMotor, 0, 4, 97, N, NONE),
    // NanoTrak.
    m("BNT001", NanoTrak, 0, 1, 22, S, NONE),
    m("MNA601", NanoTrak, 0, 1, 52, S, NONE),
    m("TNA001", NanoTrak, 0, 1, 82, S, NONE),
    m("KNA101", NanoTrak, 0, 1, 57, S, NONE),
    // Lasers.
    TLS001,
    m("KLS635", Laser, 0, 1, 56, S, NONE),
    m("KLS1550", Laser, 0, 1, 56, S, NONE),
    m("TLD001", LaserDiode, 0, 1, 64, S, NONE),
    m("KLD101", LaserDiode, 0, 1, 98, N, NONE),
    // Quad detectors.
    m("TQD001", Quad, 0, 1, 89, S, NONE),
    m("TPA101", Quad, 0, 1, 89, N, NONE),
    KPA101,
    // TEC.
    TTC001,
    // Polarisation controllers.
    m("MPC220", Polariser, 0, 3, 38, N, ("MPC", 170.0)),
    m("MPC320", Polariser, 0, 3, 38, N, ("MPC", 170.0)),
];

/// The model named `s` (any case).
pub fn find(s: &str) -> Option<&'static ModelSpec> {
    let s = s.trim();
    MODELS.iter().find(|m| m.name.eq_ignore_ascii_case(s))
}
