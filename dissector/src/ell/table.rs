//! The Elliptec ELLx command table: every command and reply of the manual, described once.
//!
//! [`COMMANDS`] has one row per command: its mnemonic, name, class (what it does, which decides
//! how its replies pair), reply timeout, the replies that answer it, its data fields and a line
//! of documentation. Decoding, encoding, pairing, `aptscope messages --proto elliptec`, the
//! JSON field names and the docs all read these rows; no code matches on mnemonics to guess
//! behaviour.
//!
//! Host commands are lower case (`ma`), module replies upper case (`PO`): the direction follows
//! from the case (manual p.4, "Description of the message header"). Data is hex ASCII,
//! big-endian; widths are in characters.

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
    /// A position in encoder pulses (32-bit two's complement); in mm/deg (or a slider's slot)
    /// when the module's pulses per unit are known from an `IN` reply.
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
    /// Binary bytes, not hex text: the current curve of `C1`/`C2`, [`CURVE_POINTS`] points of
    /// [`CURVE_POINT_BYTES`] bytes (see [`CURVE_POINTS`] for the layout).
    Raw,
}

impl Kind {
    /// Every kind, for listings and tests.
    pub const ALL: [Kind; 16] = [
        Kind::Hex,
        Kind::Signed,
        Kind::Dec,
        Kind::Addr,
        Kind::Status,
        Kind::Model,
        Kind::Firmware,
        Kind::ThreadHw,
        Kind::Position,
        Kind::Period,
        Kind::Current,
        Kind::Bool,
        Kind::Percent,
        Kind::Minutes,
        Kind::HomeDir,
        Kind::Raw,
    ];

    /// snake_case name (listings, JSON).
    pub fn name(self) -> &'static str {
        match self {
            Kind::Hex => "hex",
            Kind::Signed => "signed",
            Kind::Dec => "dec",
            Kind::Addr => "addr",
            Kind::Status => "status",
            Kind::Model => "model",
            Kind::Firmware => "firmware",
            Kind::ThreadHw => "thread_hw",
            Kind::Position => "position",
            Kind::Period => "period",
            Kind::Current => "current",
            Kind::Bool => "bool",
            Kind::Percent => "percent",
            Kind::Minutes => "minutes",
            Kind::HomeDir => "home_dir",
            Kind::Raw => "raw",
        }
    }

    /// Unit of the raw value (`""` when it has none).
    pub fn unit(self) -> &'static str {
        match self {
            Kind::Position | Kind::Signed => "pulses",
            Kind::Period => "1/14.74MHz",
            Kind::Current => "1/1866 A",
            Kind::Percent => "%",
            Kind::Minutes => "min",
            _ => "",
        }
    }

    /// What the value means, in one line.
    pub fn doc(self) -> &'static str {
        match self {
            Kind::Hex => "unsigned hex number",
            Kind::Signed => "32-bit two's complement hex number",
            Kind::Dec => "decimal digits",
            Kind::Addr => "bus address character 0-F",
            Kind::Status => "status/error code (0 OK, 9 BUSY, …)",
            Kind::Model => "module type: the ELL number in hex",
            Kind::Firmware => "firmware release: high nibble major, low nibble minor",
            Kind::ThreadHw => "bit 7 thread (1 imperial, 0 metric), bits 0-6 hardware release",
            Kind::Position => "encoder pulses, 32-bit two's complement (mm, deg or slot once the module is known)",
            Kind::Period => "drive period: frequency = 14740000 / period Hz",
            Kind::Current => "motor current: 1866 points per ampere",
            Kind::Bool => "0 off, 1 on",
            Kind::Percent => "percent of the maximum, 0-100 (0x64)",
            Kind::Minutes => "minutes",
            Kind::HomeDir => "home direction: 0 clockwise, 1 counter-clockwise (rotary stages)",
            Kind::Raw => "binary current curve: 87 points of period (u16 LE) and current (u32 LE, 1866 per A)",
        }
    }

    /// Whether the field is binary bytes rather than ASCII characters.
    pub fn is_binary(self) -> bool {
        self == Kind::Raw
    }
}

/// Points of a `C1`/`C2` current curve.
///
/// The manual (p.21 and p.31) is inconsistent: its byte table gives the reply 522 bytes with
/// data at bytes 3–521 (519 bytes), but also says the data is "87 points" of "Period (2
/// bytes) - Current (4 bytes)", which is 87 × 6 = 522 bytes. 519 bytes is not a whole number
/// of 6-byte points (86.5), so the table's "522 bytes" is taken to count the data alone (its
/// byte indices forgot the 3 header bytes): 87 points, 522 data bytes, then CR LF. 87 is also
/// the number of whole periods from 70 kHz (period 210) to 120 kHz (period 123), the range the
/// manual gives. A reply cut after 519 data bytes (the index table's reading) is still framed,
/// with a `data_length` diagnostic, and decodes as 86 points.
pub const CURVE_POINTS: usize = 87;
/// Bytes per current-curve point: period (u16) then current (u32), both little endian (the
/// manual states little endian for the current; the period is taken to be the same machine's
/// byte order).
pub const CURVE_POINT_BYTES: usize = 6;
/// Data bytes of a `C1`/`C2` reply as the manual's byte table numbers them (3–521): accepted too.
pub const CURVE_SHORT_BYTES: usize = 519;

/// What a command does; decides how its replies pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Class {
    /// Asks for data; the reply carries it (`in`, `gp`).
    Query,
    /// Changes a parameter; `GS` acknowledges (`sv`, `sj`, `us`).
    Setting,
    /// Moves the stage (`ma`, `ho`, `fw`): `GS` BUSY replies while it runs are interim, the
    /// final `PO` (or an error `GS`) completes it, and it ends a `ga` group (p.32–38, p.43).
    Motion,
    /// A motor scan that may move the stage and runs for seconds (`s1`, `c1`): busy replies
    /// are interim, as for a motion (p.19–21).
    Scan,
    /// Drives a motor directly: energise (`e1`, which may move the stage) or halt (`h1`).
    Drive,
    /// Moves the module to another address (`ca`): the reply comes from the new address.
    Address,
    /// Makes the module also answer at another address until its next motion ends (`ga`):
    /// the reply comes from that address, and a command sent there is answered by every module
    /// of the group (p.43).
    Group,
    /// Module housekeeping: reboot (`re`), isolate (`is`).
    System,
    /// A module's reply to a host command.
    Reply,
    /// Sent by a module on its own, when its hardware buttons move it (`BS`, `BO`, p.41).
    Spontaneous,
}

impl Class {
    /// Every class.
    pub const ALL: [Class; 10] = [
        Class::Query,
        Class::Setting,
        Class::Motion,
        Class::Scan,
        Class::Drive,
        Class::Address,
        Class::Group,
        Class::System,
        Class::Reply,
        Class::Spontaneous,
    ];

    /// snake_case name (listings, JSON).
    pub fn name(self) -> &'static str {
        match self {
            Class::Query => "query",
            Class::Setting => "setting",
            Class::Motion => "motion",
            Class::Scan => "scan",
            Class::Drive => "drive",
            Class::Address => "address",
            Class::Group => "group",
            Class::System => "system",
            Class::Reply => "reply",
            Class::Spontaneous => "spontaneous",
        }
    }

    /// Whether a `GS` BUSY reply is interim (the final reply is still to come).
    pub fn busy_is_interim(self) -> bool {
        matches!(self, Class::Motion | Class::Scan)
    }

    /// Whether the command may make the hardware move (asked for confirmation before a real
    /// port).
    pub fn moves(self) -> bool {
        matches!(self, Class::Motion | Class::Scan | Class::Drive)
    }
}

/// One field of a command's data.
#[derive(Debug, Clone, Copy)]
pub struct Field {
    /// snake_case name (JSON key, filter name).
    pub name: &'static str,
    /// Width in characters (bytes for binary data).
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
    /// What it does.
    pub class: Class,
    /// How long the host waits for the final reply, in ms (0: no reply expected).
    pub timeout_ms: u32,
    /// Data fields in order.
    pub fields: &'static [Field],
    /// Replies the module answers with (host commands only), first the final ones.
    pub replies: &'static [&'static str],
    /// What it does, with the manual page.
    pub doc: &'static str,
}

/// How a reply relates to a pending command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Answer {
    /// Not a reply to this command.
    No,
    /// A reply, but the final one is still to come (`GS` BUSY during a motion).
    Interim,
    /// The reply that completes the command.
    Final,
}

impl Cmd {
    /// Data length in characters.
    pub fn data_len(&self) -> usize {
        self.fields.iter().map(|f| f.width as usize).sum()
    }

    /// Whether the command starts a motion or scan (its `GS` BUSY replies are interim).
    pub fn is_move(&self) -> bool {
        self.class.busy_is_interim()
    }

    /// The reply timeout in ns (0: none expected).
    pub fn timeout_ns(&self) -> u64 {
        self.timeout_ms as u64 * 1_000_000
    }

    /// Whether the data is binary (framed by length, not read as hex text).
    pub fn is_binary(&self) -> bool {
        self.fields.iter().any(|f| f.kind.is_binary())
    }

    /// How the reply `code` (with its status, for `GS`) answers this command.
    ///
    /// `GS` 3, "command error or not supported" (p.10), answers any host command that expects a
    /// reply: a module that lacks a command (an ELL6 asked `gv`) says so instead of replying.
    pub fn answer(&self, code: &str, status: Option<u64>) -> Answer {
        if code == "GS"
            && status == Some(STATUS_COMMAND_ERROR as u64)
            && self.dir == Dir::HostToDevice
            && !self.replies.is_empty()
        {
            return Answer::Final;
        }
        if !self.replies.contains(&code) {
            return Answer::No;
        }
        if code == "GS" && status == Some(STATUS_BUSY as u64) && self.class.busy_is_interim() {
            return Answer::Interim;
        }
        Answer::Final
    }

    /// The host commands this reply answers (replies only).
    pub fn answers(&self) -> impl Iterator<Item = &'static Cmd> + '_ {
        COMMANDS
            .iter()
            .filter(move |c| c.replies.contains(&self.code))
    }

    /// A field by name.
    pub fn field(&self, name: &str) -> Option<&'static Field> {
        self.fields.iter().find(|f| f.name == name)
    }
}

/// The direction a mnemonic's case gives.
const fn dir_of(code: &str) -> Dir {
    if code.as_bytes()[0].is_ascii_lowercase() {
        Dir::HostToDevice
    } else {
        Dir::DeviceToHost
    }
}

/// `-`: no reply expected; `N`: N seconds.
macro_rules! timeout_ms {
    (-) => {
        0
    };
    ($s:literal) => {
        $s * 1000
    };
}

/// Builds [`COMMANDS`] from rows of
/// `code NAME Class timeout_s [REPLIES] [field: Kind(width), …]` then `"doc";`.
macro_rules! commands {
    ($(
        $code:ident $name:ident $class:ident $timeout:tt [$($reply:ident),*]
            [$($fname:ident : $kind:ident($width:literal)),*]
            $doc:literal;
    )*) => {
        /// Every command and reply of the ELLx manual, one row each.
        pub static COMMANDS: &[Cmd] = &[$(Cmd {
            code: stringify!($code),
            name: stringify!($name),
            dir: dir_of(stringify!($code)),
            class: Class::$class,
            timeout_ms: timeout_ms!($timeout),
            replies: &[$(stringify!($reply)),*],
            fields: &[$(Field { name: stringify!($fname), width: $width, kind: Kind::$kind }),*],
            doc: $doc,
        }),*];
    };
}

// One row per command (manual pages in the doc line). Columns: mnemonic, name, class, reply
// timeout in seconds (`-`: no reply), replies (first the final ones), data fields as
// `name: Kind(width in characters)`, then the doc line. Timeouts: the manual's 2 s; motions
// reply when done (10 s); the frequency search and current-curve scan take about 12 s (30 s).
#[rustfmt::skip]
commands! {
//  code name                      class        s   replies    data
    in   REQ_INFORMATION           Query        2   [IN]       []
        "Identify: model, serial, year, firmware, travel, pulses (p.9)";
    IN   GET_INFORMATION           Reply        -   []         [model: Model(2), serial: Dec(8), year: Dec(4), firmware: Firmware(2),
                                                                thread_hw: ThreadHw(2), travel: Hex(4), pulses_per_unit: Hex(8)]
        "Module information: travel in mm or deg, pulses per mm, per revolution or per slider position (p.9)";
    gs   REQ_STATUS                Query        2   [GS]       []
        "Get status or error; reading clears the error (p.10)";
    GS   GET_STATUS                Reply        -   []         [status: Status(2)]
        "Status or error code (p.10)";
    us   SAVE_USER_DATA            Setting      2   [GS]       []
        "Save motor and user parameters (p.11)";
    re   REBOOT                    System       2   [GS]       []
        "Reboot into the bootloader; GS OK says it is there (p.12)";
    ca   CHANGE_ADDRESS            Address      2   [GS]       [new_address: Addr(1)]
        "Change the bus address; the reply comes from the new address (p.12)";
    i1   REQ_MOTOR1_INFO           Query        2   [I1]       []
        "Motor 1 parameters (p.13)";
    I1   GET_MOTOR1_INFO           Reply        -   []         [loop: Bool(1), motor: Bool(1), current: Current(4), ramp_up: Hex(4),
                                                                ramp_down: Hex(4), forward_period: Period(4), backward_period: Period(4)]
        "Motor 1 parameters (p.13)";
    f1   SET_FWP_MOTOR1            Setting      2   [GS]       [period: Period(4)]
        "Motor 1 forward period (p.15)";
    b1   SET_BWP_MOTOR1            Setting      2   [GS]       [period: Period(4)]
        "Motor 1 backward period (p.16)";
    e1   ENERGIZE_MOTOR1           Drive        2   [GS]       [period: Period(4)]
        "Energize motor 1 at a period; the part may move until h1 (p.17)";
    h1   HALT_MOTOR1               Drive        2   [GS]       []
        "Stop motor 1 (p.18)";
    s1   SEARCH_FREQ_MOTOR1        Scan         30  [GS]       []
        "Search the best frequencies of motor 1; the part may move (p.19)";
    c1   SCAN_CURRENT_CURVE_MOTOR1 Scan         30  [C1, GS]   []
        "Scan the current curve of motor 1, about 12 s; the part may move (p.20)";
    C1   GET_CURRENT_CURVE_MOTOR1  Reply        -   []         [curve: Raw(522)]
        "Current curve of motor 1: 87 binary points from 70 kHz up (p.21)";
    is   ISOLATE_MINUTES           System       -   []         [minutes: Minutes(2)]
        "Do not reply for N minutes (p.22)";
    i2   REQ_MOTOR2_INFO           Query        2   [I2]       []
        "Motor 2 parameters (p.23)";
    I2   GET_MOTOR2_INFO           Reply        -   []         [loop: Bool(1), motor: Bool(1), current: Current(4), ramp_up: Hex(4),
                                                                ramp_down: Hex(4), forward_period: Period(4), backward_period: Period(4)]
        "Motor 2 parameters (p.23)";
    f2   SET_FWP_MOTOR2            Setting      2   [GS]       [period: Period(4)]
        "Motor 2 forward period (p.25)";
    b2   SET_BWP_MOTOR2            Setting      2   [GS]       [period: Period(4)]
        "Motor 2 backward period (p.26)";
    e2   ENERGIZE_MOTOR2           Drive        2   [GS]       [period: Period(4)]
        "Energize motor 2 at a period; the part may move until h2 (p.27)";
    h2   HALT_MOTOR2               Drive        2   [GS]       []
        "Stop motor 2 (p.28)";
    s2   SEARCH_FREQ_MOTOR2        Scan         30  [GS]       []
        "Search the best frequencies of motor 2; the part may move (p.29)";
    c2   SCAN_CURRENT_CURVE_MOTOR2 Scan         30  [C2, GS]   []
        "Scan the current curve of motor 2, about 12 s; the part may move (p.30)";
    C2   GET_CURRENT_CURVE_MOTOR2  Reply        -   []         [curve: Raw(522)]
        "Current curve of motor 2: 87 binary points from 70 kHz up (p.31)";
    ho   HOME                      Motion       10  [PO, GS]   [direction: HomeDir(1)]
        "Move home; rotary stages: 0 CW, 1 CCW, linear stages ignore it (p.32)";
    ma   MOVE_ABSOLUTE             Motion       10  [PO, GS]   [position: Position(8)]
        "Move to an absolute position in pulses (p.33)";
    mr   MOVE_RELATIVE             Motion       10  [PO, GS]   [position: Position(8)]
        "Move by a distance in pulses (p.34)";
    go   REQ_HOME_OFFSET           Query        2   [HO]       []
        "Get the home offset (p.35)";
    HO   GET_HOME_OFFSET           Reply        -   []         [offset: Position(8)]
        "Home offset in pulses (p.35)";
    so   SET_HOME_OFFSET           Setting      2   [GS]       [offset: Position(8)]
        "Set the home offset in pulses (p.35)";
    gj   REQ_JOG_STEP_SIZE         Query        2   [GJ]       []
        "Get the jog step size (p.37)";
    GJ   GET_JOG_STEP_SIZE         Reply        -   []         [step: Position(8)]
        "Jog step size in pulses (p.37)";
    sj   SET_JOG_STEP_SIZE         Setting      2   [GS]       [step: Position(8)]
        "Set the jog step size in pulses (p.37)";
    fw   FORWARD                   Motion       10  [PO, GS]   []
        "Move forward by the jog step (a slider: to the next position) (p.38)";
    bw   BACKWARD                  Motion       10  [PO, GS]   []
        "Move backward by the jog step (a slider: to the previous position) (p.38)";
    gp   GET_POSITION              Query        2   [PO]       []
        "Get the position (p.39)";
    PO   POSITION                  Reply        -   []         [position: Position(8)]
        "Position in pulses (p.39)";
    gv   REQ_VELOCITY              Query        2   [GV]       []
        "Get the velocity compensation (p.40)";
    GV   GET_VELOCITY              Reply        -   []         [velocity: Percent(2)]
        "Velocity compensation, % of maximum (p.40)";
    sv   SET_VELOCITY              Setting      2   [GS]       [velocity: Percent(2)]
        "Set the velocity compensation (p.40)";
    BS   BUTTON_STATUS             Spontaneous  -   []         [status: Status(2)]
        "Status while a move started by a hardware button runs (p.41)";
    BO   BUTTON_POSITION           Spontaneous  -   []         [position: Position(8)]
        "Position after a move started by a hardware button (p.41)";
    ga   GROUP_ADDRESS             Group        2   [GS]       [new_address: Addr(1)]
        "Also answer at another address until the next motion ends, to move a group together (p.43)";
}

/// A host command the manual does not list (pylablib's `get_full_info` asks `0i3`, motor 3's
/// parameters): a module answers it with `GS` and status 3, "command error or not supported"
/// (manual p.10). Pairing reads this row for every unknown host command, the simulators answer
/// as it says.
pub static UNKNOWN_COMMAND: Cmd = Cmd {
    code: "??",
    name: "UNKNOWN_COMMAND",
    dir: Dir::HostToDevice,
    class: Class::Query,
    timeout_ms: 2000,
    fields: &[],
    replies: &["GS"],
    doc: "A host command the manual does not list: answered with GS status 3, command error or not supported (p.10)",
};

/// Status code of `GS` a module answers an unknown command with: "command error or not
/// supported" (p.10).
pub const STATUS_COMMAND_ERROR: u32 = 3;

/// Status code of `GS`/`BS` that means the module is busy (a motion is running).
pub const STATUS_BUSY: u32 = 9;

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

/// The command with this name (`MOVE_ABSOLUTE`, any case).
pub fn by_name(name: &str) -> Option<&'static Cmd> {
    COMMANDS.iter().find(|c| c.name.eq_ignore_ascii_case(name))
}

/// How a module moves: decides which commands it has beyond the common ones (see
/// [`Model::supports`]) and how positions read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mechanism {
    /// Rotation: `IN` gives pulses per revolution; any position, reported within one turn.
    Rotary,
    /// Linear stage (and the iris): `IN` gives pulses per mm; positions 0 to travel × pulses.
    Linear,
    /// Bi-positional slider (the manual's "shutter devices", ELL6): two positions, moved by
    /// `fw`/`bw`.
    Shutter,
    /// Multi-position slider (ELL9, ELL12): `slots` positions, moved by `fw`/`bw` or `ma`.
    Indexed,
    /// Open loop, no encoder (ELL5 actuator): jogs only, the position always reads 0.
    OpenLoop,
}

impl Mechanism {
    /// snake_case name (listings, JSON).
    pub fn name(self) -> &'static str {
        match self {
            Mechanism::Rotary => "rotary",
            Mechanism::Linear => "linear",
            Mechanism::Shutter => "shutter",
            Mechanism::Indexed => "indexed",
            Mechanism::OpenLoop => "open_loop",
        }
    }

    /// The host commands a module of this mechanism has beyond [`COMMON_COMMANDS`] and the
    /// motor commands.
    ///
    /// Rotary and linear: the manual's "Messages Applicable to Rotation/Linear Devices" (p.46,
    /// p.47). Shutter: its "Shutter Devices" list (p.45) plus `ho`, which the manual says does
    /// not apply to bi-positional sliders, but the `elliptec` package homes its ELL6 (its
    /// device table lists "home") and Thorlabs' own ELL6 example homes it. Indexed: the
    /// shutter's plus `ma`, with which the `elliptec` package's `Slider.set_slot` moves an
    /// ELL9 (the manual predates the multi-position sliders).
    pub fn commands(self) -> &'static [&'static str] {
        match self {
            Mechanism::Rotary | Mechanism::Linear => {
                &["ho", "ma", "mr", "go", "so", "gj", "sj", "gv", "sv"]
            }
            Mechanism::Shutter => &["ho"],
            Mechanism::Indexed => &["ho", "ma"],
            Mechanism::OpenLoop => &[],
        }
    }
}

/// Host commands every module answers (the manual's shutter list, p.45, which the rotation and
/// linear lists contain): identify, status, save, reboot, addressing, isolation, jogs,
/// position.
pub static COMMON_COMMANDS: &[&str] = &["in", "gs", "us", "re", "ca", "is", "ga", "fw", "bw", "gp"];

/// Host commands of one motor, by motor (1, 2): what "THIS MESSAGE APPLIES ONLY TO DEVICES WITH
/// 2 MOTORS" (p.23–31) leaves out of single-motor modules.
pub static MOTOR_COMMANDS: [&[&str]; 2] = [
    &["i1", "f1", "b1", "e1", "h1", "s1", "c1"],
    &["i2", "f2", "b2", "e2", "h2", "s2", "c2"],
];

/// What the manual, real modules and the client libraries say about an ELL model number (the
/// `IN` reply's type): one row per model, read by the dissector (units) and the simulator
/// (what `IN` answers, how the module moves, which commands it has).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Model {
    /// ELL number (6 = ELL6).
    pub number: u8,
    /// Short description.
    pub what: &'static str,
    /// Unit of positions once converted: `mm`, `deg`, `slot` (indexed sliders and wheels) or
    /// `pulses` (no conversion).
    pub unit: &'static str,
    /// Number of positions of an indexed slider or wheel (0 for the others).
    pub slots: u8,
    /// How it moves.
    pub mechanism: Mechanism,
    /// Travel as `IN` gives it: mm, degrees (360), or a slider's travel.
    pub travel: u16,
    /// Pulses per unit as `IN` gives it: per mm, per revolution, per slider position (0: the
    /// slider's positions are `travel` apart, as on an ELL6). An ELL9's positions are 0x1F
    /// apart in Micro-Manager's adapter ("experimentally determined") and 32 in the `elliptec`
    /// package, which accepts ±5: 31 serves both.
    pub pulses: u32,
    /// Piezo motors (1 or 2): a single-motor module has no `i2` … `c2`.
    pub motors: u8,
    /// Where travel, pulses and motors come from.
    pub source: &'static str,
}

impl Model {
    /// Whether the module answers host command `code` (anything else gets `GS` 3, "command
    /// error or not supported", p.10).
    pub fn supports(&self, code: &str) -> bool {
        COMMON_COMMANDS.contains(&code)
            || self.mechanism.commands().contains(&code)
            || MOTOR_COMMANDS
                .iter()
                .take(self.motors as usize)
                .any(|m| m.contains(&code))
    }

    /// The host commands it answers, in table order.
    pub fn commands(&self) -> impl Iterator<Item = &'static Cmd> + '_ {
        COMMANDS
            .iter()
            .filter(move |c| c.dir == Dir::HostToDevice && self.supports(c.code))
    }
}

/// Source of the manual's model table (p.7).
const MANUAL: &str = "manual p.7";
/// Source of values no document gives: a rotation stage a client library names, as an ELL18.
const AS_ELL18: &str = "assumed (ELL18's)";

/// Known ELL models: the manual's (ELL4–ELL8) and those the client libraries drive (`elliptec`:
/// ELL6, ELL9, ELL14, ELL15, ELL18, ELL20; thorlabs-elliptec: ELL7, ELL8, ELL10, ELL12, ELL16,
/// ELL17, ELL21 too).
#[rustfmt::skip]
pub static MODELS: &[Model] = &[
    Model { number: 4, what: "rotator", unit: "deg", slots: 0, mechanism: Mechanism::Rotary,
        travel: 360, pulses: 0x40000, motors: 2, source: MANUAL },
    Model { number: 5, what: "actuator", unit: "pulses", slots: 0, mechanism: Mechanism::OpenLoop,
        travel: 0, pulses: 0, motors: 1, source: MANUAL },
    Model { number: 6, what: "bi-positional slider", unit: "slot", slots: 2, mechanism: Mechanism::Shutter,
        travel: 31, pulses: 0, motors: 1, source: "manual p.7 (an ELL6K answers IN with these)" },
    Model { number: 7, what: "linear stage", unit: "mm", slots: 0, mechanism: Mechanism::Linear,
        travel: 26, pulses: 2048, motors: 2, source: MANUAL },
    Model { number: 8, what: "rotary stage", unit: "deg", slots: 0, mechanism: Mechanism::Rotary,
        travel: 360, pulses: 0x40000, motors: 2, source: MANUAL },
    Model { number: 9, what: "four-position slider", unit: "slot", slots: 4, mechanism: Mechanism::Indexed,
        travel: 19, pulses: 31, motors: 1, source: "Micro-Manager's measured positions 0, 0x1F, 0x3E, 0x5D" },
    Model { number: 10, what: "linear stage", unit: "mm", slots: 0, mechanism: Mechanism::Linear,
        travel: 60, pulses: 1024, motors: 2, source: "assumed (ELL20's)" },
    Model { number: 12, what: "six-position slider", unit: "slot", slots: 6, mechanism: Mechanism::Indexed,
        travel: 31, pulses: 31, motors: 1, source: "assumed (ELL9's spacing)" },
    Model { number: 14, what: "rotation mount", unit: "deg", slots: 0, mechanism: Mechanism::Rotary,
        travel: 360, pulses: 0x23000, motors: 2, source: "ELL14s' IN replies" },
    Model { number: 15, what: "motorized iris", unit: "mm", slots: 0, mechanism: Mechanism::Linear,
        travel: 12, pulses: 1024, motors: 2, source: "assumed (elliptec package: 1-11.5 mm aperture)" },
    Model { number: 16, what: "rotation stage", unit: "deg", slots: 0, mechanism: Mechanism::Rotary,
        travel: 360, pulses: 0x40000, motors: 2, source: AS_ELL18 },
    Model { number: 17, what: "linear stage", unit: "mm", slots: 0, mechanism: Mechanism::Linear,
        travel: 28, pulses: 2048, motors: 2, source: "manual p.7 (ELL7's 2048 pulses/mm)" },
    Model { number: 18, what: "rotation stage", unit: "deg", slots: 0, mechanism: Mechanism::Rotary,
        travel: 360, pulses: 0x40000, motors: 2, source: "manual p.7 (ELL8's pulses/rev)" },
    Model { number: 20, what: "linear stage", unit: "mm", slots: 0, mechanism: Mechanism::Linear,
        travel: 60, pulses: 1024, motors: 2, source: "60 mm travel; 1024 pulses/mm assumed" },
    Model { number: 21, what: "rotation stage", unit: "deg", slots: 0, mechanism: Mechanism::Rotary,
        travel: 360, pulses: 0x40000, motors: 2, source: AS_ELL18 },
];

/// The model with this ELL number.
pub fn model(number: u8) -> Option<&'static Model> {
    MODELS.iter().find(|m| m.number == number)
}
