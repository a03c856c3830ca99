//! The Elliptec ELLx command table: every command and reply of the manual, described once.
//!
//! Host commands are lower case (`ma`), module replies upper case (`PO`). Data is hex ASCII,
//! big-endian; widths below are in characters.

use crate::table::Dir;

/// How a field's characters are read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Unsigned hex number.
    Hex,
    /// Two's complement hex number (32-bit positions).
    Signed,
    /// Decimal digits (serial number, year).
    Dec,
    /// A bus address character `0`–`F`.
    Addr,
    /// Status/error code (hex), named by [`STATUS`].
    Status,
    /// Module type (hex): ELL number.
    Model,
    /// Firmware release byte: high nibble major, low nibble minor.
    Firmware,
    /// Thread (bit 7: 1 imperial, 0 metric) and hardware release (bits 0–6).
    ThreadHw,
    /// A position in encoder pulses (32-bit two's complement); in mm/deg when the module's
    /// pulses per unit are known from an `IN` reply.
    Position,
    /// Motor drive period: frequency = 14 740 000 / period Hz.
    Period,
    /// Motor current: 1866 points per ampere.
    Current,
    /// A 0/1 state.
    Bool,
    /// A percentage in hex (0x64 = 100 %).
    Percent,
    /// Minutes in hex.
    Minutes,
    /// Home direction: 0 clockwise, 1 counter-clockwise (rotary stages only).
    HomeDir,
    /// Raw bytes (the binary current curve of `C1`/`C2`).
    Raw,
}

/// One field of a command's data.
#[derive(Debug, Clone, Copy)]
pub struct Field {
    /// snake_case name (JSON key, filter name).
    pub name: &'static str,
    /// Width in characters.
    pub width: u16,
    /// How to read it.
    pub kind: Kind,
}

/// One command or reply.
#[derive(Debug, Clone, Copy)]
pub struct Cmd {
    /// The two-character mnemonic.
    pub code: &'static str,
    /// Name from the manual, without the `_HOSTREQ_`/`_DEVGET_` prefix.
    pub name: &'static str,
    /// Host → module (lower case) or module → host (upper case).
    pub dir: Dir,
    /// Data fields in order.
    pub fields: &'static [Field],
    /// Replies the module answers with (host commands only), first the final ones.
    pub replies: &'static [&'static str],
    /// Manual section (page) for reference.
    pub doc: &'static str,
}

impl Cmd {
    /// Data length in characters.
    pub fn data_len(&self) -> usize {
        self.fields.iter().map(|f| f.width as usize).sum()
    }
    /// Whether the command starts a motion (its `GS` replies while busy are interim).
    pub fn is_move(&self) -> bool {
        matches!(
            self.code,
            "ho" | "ma" | "mr" | "fw" | "bw" | "s1" | "s2" | "c1" | "c2"
        )
    }
}

const fn f(name: &'static str, width: u16, kind: Kind) -> Field {
    Field { name, width, kind }
}

const NONE: &[Field] = &[];
const STATUS_F: &[Field] = &[f("status", 2, Kind::Status)];
const POS_F: &[Field] = &[f("position", 8, Kind::Position)];
const PERIOD_F: &[Field] = &[f("period", 4, Kind::Period)];
const ADDR_F: &[Field] = &[f("new_address", 1, Kind::Addr)];
const MOTOR_INFO: &[Field] = &[
    f("loop", 1, Kind::Bool),
    f("motor", 1, Kind::Bool),
    f("current", 4, Kind::Current),
    f("ramp_up", 4, Kind::Hex),
    f("ramp_down", 4, Kind::Hex),
    f("forward_period", 4, Kind::Period),
    f("backward_period", 4, Kind::Period),
];
/// `C1`/`C2`: 519 data bytes (binary: period u16 + current u32 little endian, per point).
const CURVE: &[Field] = &[f("curve", 519, Kind::Raw)];
const MOVE_REPLIES: &[&str] = &["PO", "GS"];
const GS: &[&str] = &["GS"];

macro_rules! cmd {
    ($code:literal, $name:literal, $dir:ident, $fields:expr, $replies:expr, $doc:literal) => {
        Cmd {
            code: $code,
            name: $name,
            dir: Dir::$dir,
            fields: $fields,
            replies: $replies,
            doc: $doc,
        }
    };
}

/// Every command and reply of the ELLx manual.
pub static COMMANDS: &[Cmd] = &[
    cmd!(
        "in",
        "REQ_INFORMATION",
        HostToDevice,
        NONE,
        &["IN"],
        "Identify: model, serial, year, firmware, travel, pulses (p.9)"
    ),
    cmd!(
        "IN",
        "GET_INFORMATION",
        DeviceToHost,
        &[
            f("model", 2, Kind::Model),
            f("serial", 8, Kind::Dec),
            f("year", 4, Kind::Dec),
            f("firmware", 2, Kind::Firmware),
            f("thread_hw", 2, Kind::ThreadHw),
            f("travel", 4, Kind::Hex),
            f("pulses_per_unit", 8, Kind::Hex),
        ],
        &[],
        "Module information (p.9)"
    ),
    cmd!(
        "gs",
        "REQ_STATUS",
        HostToDevice,
        NONE,
        GS,
        "Get status or error; reading clears the error (p.10)"
    ),
    cmd!(
        "GS",
        "GET_STATUS",
        DeviceToHost,
        STATUS_F,
        &[],
        "Status or error code (p.10)"
    ),
    cmd!(
        "us",
        "SAVE_USER_DATA",
        HostToDevice,
        NONE,
        GS,
        "Save motor and user parameters (p.11)"
    ),
    cmd!(
        "re",
        "REBOOT",
        HostToDevice,
        NONE,
        &[],
        "Reboot the module (p.12)"
    ),
    cmd!(
        "ca",
        "CHANGE_ADDRESS",
        HostToDevice,
        ADDR_F,
        GS,
        "Change the bus address; the reply comes from the new address (p.12)"
    ),
    cmd!(
        "i1",
        "REQ_MOTOR1_INFO",
        HostToDevice,
        NONE,
        &["I1"],
        "Motor 1 parameters (p.13)"
    ),
    cmd!(
        "I1",
        "GET_MOTOR1_INFO",
        DeviceToHost,
        MOTOR_INFO,
        &[],
        "Motor 1 parameters (p.13)"
    ),
    cmd!(
        "f1",
        "SET_FWP_MOTOR1",
        HostToDevice,
        PERIOD_F,
        GS,
        "Motor 1 forward period (p.15)"
    ),
    cmd!(
        "b1",
        "SET_BWP_MOTOR1",
        HostToDevice,
        PERIOD_F,
        GS,
        "Motor 1 backward period (p.16)"
    ),
    cmd!(
        "e1",
        "ENERGIZE_MOTOR1",
        HostToDevice,
        PERIOD_F,
        GS,
        "Energize motor 1 at a period (p.17)"
    ),
    cmd!(
        "h1",
        "HALT_MOTOR1",
        HostToDevice,
        NONE,
        GS,
        "Stop motor 1 (p.18)"
    ),
    cmd!(
        "s1",
        "SEARCH_FREQ_MOTOR1",
        HostToDevice,
        NONE,
        GS,
        "Search the best frequencies of motor 1 (p.19)"
    ),
    cmd!(
        "c1",
        "SCAN_CURRENT_CURVE_MOTOR1",
        HostToDevice,
        NONE,
        &["C1", "GS"],
        "Scan the current curve of motor 1 (p.20)"
    ),
    cmd!(
        "C1",
        "GET_CURRENT_CURVE_MOTOR1",
        DeviceToHost,
        CURVE,
        &[],
        "Current curve of motor 1, binary (p.21)"
    ),
    cmd!(
        "is",
        "ISOLATE_MINUTES",
        HostToDevice,
        &[f("minutes", 2, Kind::Minutes)],
        &[],
        "Do not reply for N minutes (p.22)"
    ),
    cmd!(
        "i2",
        "REQ_MOTOR2_INFO",
        HostToDevice,
        NONE,
        &["I2"],
        "Motor 2 parameters (p.23)"
    ),
    cmd!(
        "I2",
        "GET_MOTOR2_INFO",
        DeviceToHost,
        MOTOR_INFO,
        &[],
        "Motor 2 parameters (p.23)"
    ),
    cmd!(
        "f2",
        "SET_FWP_MOTOR2",
        HostToDevice,
        PERIOD_F,
        GS,
        "Motor 2 forward period (p.25)"
    ),
    cmd!(
        "b2",
        "SET_BWP_MOTOR2",
        HostToDevice,
        PERIOD_F,
        GS,
        "Motor 2 backward period (p.26)"
    ),
    cmd!(
        "e2",
        "ENERGIZE_MOTOR2",
        HostToDevice,
        PERIOD_F,
        GS,
        "Energize motor 2 at a period (p.27)"
    ),
    cmd!(
        "h2",
        "HALT_MOTOR2",
        HostToDevice,
        NONE,
        GS,
        "Stop motor 2 (p.28)"
    ),
    cmd!(
        "s2",
        "SEARCH_FREQ_MOTOR2",
        HostToDevice,
        NONE,
        GS,
        "Search the best frequencies of motor 2 (p.29)"
    ),
    cmd!(
        "c2",
        "SCAN_CURRENT_CURVE_MOTOR2",
        HostToDevice,
        NONE,
        &["C2", "GS"],
        "Scan the current curve of motor 2 (p.30)"
    ),
    cmd!(
        "C2",
        "GET_CURRENT_CURVE_MOTOR2",
        DeviceToHost,
        CURVE,
        &[],
        "Current curve of motor 2, binary (p.31)"
    ),
    cmd!(
        "ho",
        "HOME",
        HostToDevice,
        &[f("direction", 1, Kind::HomeDir)],
        MOVE_REPLIES,
        "Move home; rotary stages: 0 CW, 1 CCW (p.32)"
    ),
    cmd!(
        "ma",
        "MOVE_ABSOLUTE",
        HostToDevice,
        POS_F,
        MOVE_REPLIES,
        "Move to an absolute position in pulses (p.33)"
    ),
    cmd!(
        "mr",
        "MOVE_RELATIVE",
        HostToDevice,
        POS_F,
        MOVE_REPLIES,
        "Move by a distance in pulses (p.34)"
    ),
    cmd!(
        "go",
        "REQ_HOME_OFFSET",
        HostToDevice,
        NONE,
        &["HO"],
        "Get the home offset (p.35)"
    ),
    cmd!(
        "HO",
        "GET_HOME_OFFSET",
        DeviceToHost,
        &[f("offset", 8, Kind::Position)],
        &[],
        "Home offset in pulses (p.35)"
    ),
    cmd!(
        "so",
        "SET_HOME_OFFSET",
        HostToDevice,
        &[f("offset", 8, Kind::Position)],
        GS,
        "Set the home offset in pulses (p.35)"
    ),
    cmd!(
        "gj",
        "REQ_JOG_STEP_SIZE",
        HostToDevice,
        NONE,
        &["GJ"],
        "Get the jog step size (p.37)"
    ),
    cmd!(
        "GJ",
        "GET_JOG_STEP_SIZE",
        DeviceToHost,
        &[f("step", 8, Kind::Position)],
        &[],
        "Jog step size in pulses (p.37)"
    ),
    cmd!(
        "sj",
        "SET_JOG_STEP_SIZE",
        HostToDevice,
        &[f("step", 8, Kind::Position)],
        GS,
        "Set the jog step size in pulses (p.37)"
    ),
    cmd!(
        "fw",
        "FORWARD",
        HostToDevice,
        NONE,
        MOVE_REPLIES,
        "Move forward by the jog step (p.38)"
    ),
    cmd!(
        "bw",
        "BACKWARD",
        HostToDevice,
        NONE,
        MOVE_REPLIES,
        "Move backward by the jog step (p.38)"
    ),
    cmd!(
        "gp",
        "GET_POSITION",
        HostToDevice,
        NONE,
        &["PO"],
        "Get the position (p.39)"
    ),
    cmd!(
        "PO",
        "POSITION",
        DeviceToHost,
        POS_F,
        &[],
        "Position in pulses (p.39)"
    ),
    cmd!(
        "gv",
        "REQ_VELOCITY",
        HostToDevice,
        NONE,
        &["GV"],
        "Get the velocity compensation (p.40)"
    ),
    cmd!(
        "GV",
        "GET_VELOCITY",
        DeviceToHost,
        &[f("velocity", 2, Kind::Percent)],
        &[],
        "Velocity compensation, % of maximum (p.40)"
    ),
    cmd!(
        "sv",
        "SET_VELOCITY",
        HostToDevice,
        &[f("velocity", 2, Kind::Percent)],
        GS,
        "Set the velocity compensation (p.40)"
    ),
    cmd!(
        "BS",
        "BUTTON_STATUS",
        DeviceToHost,
        STATUS_F,
        &[],
        "Unsolicited status while a button move runs (p.41)"
    ),
    cmd!(
        "BO",
        "BUTTON_POSITION",
        DeviceToHost,
        POS_F,
        &[],
        "Unsolicited position after a button move (p.41)"
    ),
    cmd!(
        "ga",
        "GROUP_ADDRESS",
        HostToDevice,
        ADDR_F,
        GS,
        "Listen to another address for one operation (p.43)"
    ),
];

/// Status/error codes of `GS` and `BS` (p.10, p.44).
pub static STATUS: &[(u32, &str)] = &[
    (0, "OK"),
    (1, "COMMUNICATION_TIMEOUT"),
    (2, "MECHANICAL_TIMEOUT"),
    (3, "COMMAND_ERROR"),
    (4, "VALUE_OUT_OF_RANGE"),
    (5, "MODULE_ISOLATED"),
    (6, "MODULE_OUT_OF_ISOLATION"),
    (7, "INITIALIZING_ERROR"),
    (8, "THERMAL_ERROR"),
    (9, "BUSY"),
    (10, "SENSOR_ERROR"),
    (11, "MOTOR_ERROR"),
    (12, "OUT_OF_RANGE"),
    (13, "OVER_CURRENT"),
];

/// The name of a status code (`RESERVED` for 14–255).
pub fn status_name(code: u32) -> &'static str {
    STATUS
        .iter()
        .find(|(c, _)| *c == code)
        .map(|(_, n)| *n)
        .unwrap_or("RESERVED")
}

/// The command with this mnemonic (case-sensitive: `ma` and `MA` differ).
pub fn lookup(code: &[u8]) -> Option<&'static Cmd> {
    COMMANDS.iter().find(|c| c.code.as_bytes() == code)
}

/// What the manual and real modules say about an ELL model number (the `IN` reply's type).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Model {
    /// ELL number (6 = ELL6).
    pub number: u8,
    /// Short description.
    pub what: &'static str,
    /// Unit of positions once converted: `mm`, `deg` or `pos` (indexed positions).
    pub unit: &'static str,
}

/// Known ELL models.
pub static MODELS: &[Model] = &[
    Model {
        number: 4,
        what: "rotator",
        unit: "deg",
    },
    Model {
        number: 5,
        what: "actuator",
        unit: "pulses",
    },
    Model {
        number: 6,
        what: "bi-positional slider",
        unit: "pos",
    },
    Model {
        number: 7,
        what: "linear stage",
        unit: "mm",
    },
    Model {
        number: 8,
        what: "rotary stage",
        unit: "deg",
    },
    Model {
        number: 9,
        what: "four-position slider",
        unit: "pos",
    },
    Model {
        number: 10,
        what: "linear stage",
        unit: "mm",
    },
    Model {
        number: 12,
        what: "six-position slider",
        unit: "pos",
    },
    Model {
        number: 14,
        what: "rotation mount",
        unit: "deg",
    },
    Model {
        number: 15,
        what: "motorized iris",
        unit: "pulses",
    },
    Model {
        number: 16,
        what: "rotation stage",
        unit: "deg",
    },
    Model {
        number: 17,
        what: "linear stage",
        unit: "mm",
    },
    Model {
        number: 18,
        what: "rotation stage",
        unit: "deg",
    },
    Model {
        number: 20,
        what: "linear stage",
        unit: "mm",
    },
];

/// The model with this ELL number.
pub fn model(number: u8) -> Option<&'static Model> {
    MODELS.iter().find(|m| m.number == number)
}
