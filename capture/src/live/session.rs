//! Scripted host sessions against the simulators, recorded as a tap would record them.
//!
//! A session is data: for each device (one serial port each), a simulator and a host script of
//! [`Step`]s (send an APT message built with the table-driven encoder, raw bytes or an
//! Elliptec command; wait for a named reply; let time pass). [`record_virtual`] plays a script
//! against the sans-io simulator core on a *virtual* clock: the host's bytes are paced at the
//! line's byte time (115 200 baud for APT, 9600 baud for Elliptec), the device's come out when
//! the simulator says they finish arriving, and every chunk gets its direction and a timestamp
//! from a fixed start ([`EPOCH_NS`], 2026-11-02T10:00:00Z). The result is byte-identical on
//! every run, which is what `samples/sessions/` is made of ([`record`], [`write_recording`]).
//!
//! [`run_real`] plays the same script in real time through real pseudo-terminals: the
//! simulator served on a pty ([`serve_pty`]), the real tap ([`tap_main`]) between it and a new
//! pty, and the host script writing to the tap's link. The tests compare the tap's capture with
//! what the script sent and read, and with the virtual recording.

use super::error::LiveError;
use super::sim::{
    parse_modules, serve_pty, stop_pair, AptModel, AptSim, EllSim, Pty, SimError, Simulator,
};
use super::tap::{tap_main, TapOptions, TapStats};
use crate::model::{Direction, Event, OwnedChunk, StreamInfo};
use crate::open::{create, open, Format, OpenOptions};
use aptscope_dissector::apt::{encode_named, EncodeError, Named};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::msg;
use aptscope_dissector::record::{Ctx, Decoder, Record};
use aptscope_dissector::table::Dir;
use aptscope_dissector::DiagKind;
use aptscope_dissector::Table;
use std::convert::Infallible;
use std::io::{self, Read, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Start of every virtual recording: 2026-11-02T10:00:00Z, in ns since the Unix epoch.
pub const EPOCH_NS: u64 = 1_793_613_600_000_000_000;
/// Nanoseconds per millisecond.
const MS: u64 = 1_000_000;
/// The host program's pause before each command it sends (it reacts, it is not a fuzzer).
pub const HOST_GAP_NS: u64 = 2 * MS;
/// How long after its last step a recording goes on (what the device still sends).
pub const END_DRAIN_NS: u64 = 50 * MS;
/// Pause between the parts (devices) of a session with several ports.
pub const PART_GAP_NS: u64 = 100 * MS;
/// Default time the host waits for a reply.
pub const REPLY_TIMEOUT_NS: u64 = 1_000 * MS;
/// Time the host waits for a move or homing to complete.
pub const MOVE_TIMEOUT_NS: u64 = 10_000 * MS;
/// Extra time allowed for every wait in real time (a loaded machine), so a real run fails
/// only when something is broken.
const REAL_SLACK: Duration = Duration::from_secs(20);
/// The host address of APT messages.
const HOST: u8 = 0x01;
/// Loop iterations allowed per step on the virtual clock (a stuck simulator is an error).
const MAX_ITER: usize = 1_000_000;

/// The names of the recorded sessions, in the order of `samples/sessions/README.md`.
pub const NAMES: &[&str] = &[
    "kdc101",
    "bsc203",
    "kpz101",
    "laser-tec-quad",
    "elliptec",
    "damaged",
];

/// Messages sent periodically (after HW_START_UPDATEMSGS): how many depends on timing.
pub const STATUS_UPDATES: &[u16] = &[
    msg::MOT_GET_DCSTATUSUPDATE,
    msg::MOT_GET_STATUSUPDATE,
    msg::PZ_GET_PZSTATUSUPDATE,
    msg::LA_GET_STATUSUPDATE,
    msg::TEC_GET_STATUSUPDATE,
    msg::QUAD_GET_STATUSUPDATE,
];

/// One step of a host script.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Step {
    /// Write these bytes (`what` names them: the APT message or the Elliptec command).
    Send {
        /// The bytes.
        bytes: Vec<u8>,
        /// What they are.
        what: String,
    },
    /// Read until a reply with this name arrives (an APT message name; for Elliptec the
    /// address and reply code, `0PO`), at most `timeout_ns`. Replies are taken in order: one
    /// that arrived before is found once; what comes in between (status updates) is skipped.
    Expect {
        /// The reply's name.
        name: String,
        /// How long to wait.
        timeout_ns: u64,
    },
    /// Let this much time pass, reading what the device sends.
    Wait(u64),
}

/// A simulated device.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Device {
    /// An APT controller.
    Apt(AptModel),
    /// An Elliptec bus: `0:ELL14,1:ELL9,2:ELL17`.
    Elliptec(String),
}

/// Why a scripted session could not be built, recorded or run.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// A script argument that is not `name=value`.
    #[error("`{0}` is not name=value")]
    NotNameValue(String),
    /// A message the table cannot encode.
    #[error("{name}: {source}")]
    Encode {
        /// The message asked for.
        name: String,
        /// Why.
        source: EncodeError,
    },
    /// No session of this name.
    #[error("no session named {0}")]
    Unknown(String),
    /// The device could not be simulated.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// The simulator keeps a deadline it never meets.
    #[error("the simulator does not advance")]
    Stuck,
    /// An expected reply did not come (virtual clock).
    #[error("step {step}: no {name} within {ms} ms")]
    NoReply {
        /// Index of the step.
        step: usize,
        /// The reply expected.
        name: String,
        /// The time it had.
        ms: u64,
    },
    /// An expected reply did not come (real time).
    #[error("step {step}: no {name} in time")]
    Late {
        /// Index of the step.
        step: usize,
        /// The reply expected.
        name: String,
    },
    /// The tap's link did not appear.
    #[error("the tap did not start")]
    TapNotStarted,
    /// The tap's link could not be opened.
    #[error("{path}: {source}")]
    Link {
        /// The link.
        path: String,
        /// What the system said.
        source: io::Error,
    },
    /// Input or output failed.
    #[error("{0}")]
    Io(#[from] io::Error),
    /// The tap failed.
    #[error(transparent)]
    Tap(#[from] LiveError),
    /// A thread of the run panicked.
    #[error("the {0} panicked")]
    Panicked(&'static str),
    /// The run failed, and so did the tap.
    #[error("{run} (tap: {tap})")]
    AndTap {
        /// What failed in the run.
        run: Box<SessionError>,
        /// The tap's error.
        tap: LiveError,
    },
    /// A part of a session failed.
    #[error("{session} ({port}): {error}")]
    In {
        /// The session.
        session: String,
        /// The part's port.
        port: String,
        /// What failed.
        error: Box<SessionError>,
    },
    /// The simulator's thread failed.
    #[error("simulator: {0}")]
    Simulator(io::Error),
}

impl Device {
    /// The protocol it speaks.
    pub fn proto(&self) -> Proto {
        match self {
            Device::Apt(_) => Proto::Apt,
            Device::Elliptec(_) => Proto::Elliptec,
        }
    }

    /// A fresh simulator of it.
    pub fn simulator(&self) -> Result<Box<dyn Simulator + Send>, SessionError> {
        Ok(match self {
            Device::Apt(m) => Box::new(AptSim::new(*m)),
            Device::Elliptec(mods) => Box::new(EllSim::new(&parse_modules(mods)?)?),
        })
    }

    /// The line settings as the tap records them.
    pub fn settings(&self) -> &'static str {
        match self {
            Device::Apt(_) => "115200 8N1 RTS/CTS",
            Device::Elliptec(_) => "9600 8N1",
        }
    }
}

/// One device of a session and the host's script for it.
#[derive(Debug, Clone)]
pub struct Part {
    /// The device.
    pub device: Device,
    /// Its port name (the capture's stream name).
    pub port: String,
    /// The host's script.
    pub steps: Vec<Step>,
}

/// A scripted session: one part per device, played one after the other.
#[derive(Debug, Clone)]
pub struct Session {
    /// Its name (`kdc101`): the sample's file name.
    pub name: String,
    /// The devices and scripts.
    pub parts: Vec<Part>,
}

/// A recorded session: streams and chunks as a capture file holds them.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Recording {
    /// The session's name.
    pub name: String,
    /// The protocol.
    pub proto: Proto,
    /// One stream per port.
    pub streams: Vec<StreamInfo>,
    /// Chunks in time order.
    pub chunks: Vec<OwnedChunk>,
}

// ------------------------------------------------------------------------------------- encoding

/// Build an APT frame from the message table, as `aptscope encode` does: `name` is a message
/// name, or `NAME:SUB` for a sub-message of a PARAMS group (`LA_SET_PARAMS:SETPOINT`); `args`
/// are `field=value` pairs separated by spaces (values as `encode` reads them: numbers, enum
/// labels, flags joined by `|`); the frame goes from the host to `dst`.
pub fn apt_frame(name: &str, args: &str, dst: u8) -> Result<Vec<u8>, SessionError> {
    let (mname, sub) = match name.split_once(':') {
        Some((m, s)) => (m, Some(s)),
        None => (name, None),
    };
    let pairs: Vec<(&str, &str)> = args
        .split_whitespace()
        .map(|a| {
            a.split_once('=')
                .ok_or_else(|| SessionError::NotNameValue(a.to_string()))
        })
        .collect::<Result<_, _>>()?;
    encode_named(
        Table::global(),
        &Named {
            name: mname,
            sub,
            values: &pairs,
            form: None,
            dst,
            src: HOST,
        },
    )
    .map_err(|source| SessionError::Encode {
        name: name.to_string(),
        source,
    })
}

/// The name the table gives message `id` (empty for an id it does not hold, which the encoder
/// then refuses by name).
fn msg_name(id: u16) -> &'static str {
    Table::global().msg(id).map_or("", |m| m.name)
}

/// A host script being written; the first error (a message the table cannot encode) is kept
/// and returned by [`finish`](Script::finish).
#[derive(Debug, Default)]
pub struct Script {
    steps: Vec<Step>,
    err: Option<SessionError>,
}

impl Script {
    /// An empty script.
    pub fn new() -> Script {
        Script::default()
    }

    /// Send APT message `id` (a [`msg`] constant; `args` as [`apt_frame`] reads them) to `dst`.
    pub fn apt(&mut self, id: u16, dst: u8, args: &str) -> &mut Script {
        self.send_apt(msg_name(id).to_string(), dst, args)
    }

    /// Send sub-message `sub` of the PARAMS message `id` (`msg::LA_SET_PARAMS`,
    /// `msg::la::SETPOINT`) to `dst`.
    pub fn apt_sub(&mut self, id: u16, sub: u16, dst: u8, args: &str) -> &mut Script {
        let table = Table::global();
        let sub_name = table
            .msg(id)
            .and_then(|m| table.sub(m.subs?, sub))
            .map_or("", |s| s.name);
        self.send_apt(format!("{}:{sub_name}", msg_name(id)), dst, args)
    }

    fn send_apt(&mut self, name: String, dst: u8, args: &str) -> &mut Script {
        match apt_frame(&name, args, dst) {
            Ok(bytes) => self.steps.push(Step::Send { bytes, what: name }),
            Err(e) => {
                self.err.get_or_insert(e);
            }
        }
        self
    }

    /// Send an APT request and wait (a second at most) for its reply.
    pub fn ask(&mut self, id: u16, dst: u8, args: &str, reply: u16) -> &mut Script {
        self.apt(id, dst, args).wait_reply(reply, REPLY_TIMEOUT_NS)
    }

    /// Wait for APT message `id`.
    pub fn wait_reply(&mut self, id: u16, timeout_ns: u64) -> &mut Script {
        self.wait_for(msg_name(id), timeout_ns)
    }

    /// Send an Elliptec command as is (no terminator unless it has one).
    pub fn ell(&mut self, cmd: &str) -> &mut Script {
        self.steps.push(Step::Send {
            bytes: cmd.as_bytes().to_vec(),
            what: cmd.to_string(),
        });
        self
    }

    /// Send an Elliptec command ended by CR LF and wait for the reply `reply` (`0PO`).
    pub fn ell_ask(&mut self, cmd: &str, reply: &str, timeout_ns: u64) -> &mut Script {
        self.ell(&format!("{cmd}\r\n")).wait_for(reply, timeout_ns)
    }

    /// Send raw bytes.
    pub fn raw(&mut self, bytes: &[u8], what: &str) -> &mut Script {
        self.steps.push(Step::Send {
            bytes: bytes.to_vec(),
            what: what.to_string(),
        });
        self
    }

    /// Wait for a reply.
    pub fn wait_for(&mut self, name: &str, timeout_ns: u64) -> &mut Script {
        self.steps.push(Step::Expect {
            name: name.to_string(),
            timeout_ns,
        });
        self
    }

    /// Let time pass.
    pub fn wait_ms(&mut self, ms: u64) -> &mut Script {
        self.steps.push(Step::Wait(ms * MS));
        self
    }

    /// The steps, or the first error.
    pub fn finish(&mut self) -> Result<Vec<Step>, SessionError> {
        match self.err.take() {
            Some(e) => Err(e),
            None => Ok(std::mem::take(&mut self.steps)),
        }
    }
}

// -------------------------------------------------------------------------------------- sessions

const USB: u8 = 0x50;
const RACK: u8 = 0x11;

fn part(device: Device, port: &str, s: &mut Script) -> Result<Part, SessionError> {
    Ok(Part {
        device,
        port: port.to_string(),
        steps: s.finish()?,
    })
}

/// KDC101: identify, enable, velocity parameters, status updates, home, an absolute and a
/// relative move, the position, updates off.
fn kdc101() -> Result<Vec<Part>, SessionError> {
    let mut s = Script::new();
    s.ask(msg::HW_REQ_INFO, USB, "", msg::HW_GET_INFO)
        .apt(
            msg::MOD_SET_CHANENABLESTATE,
            USB,
            "chan_ident=CH1 enable_state=1",
        )
        .ask(
            msg::MOD_REQ_CHANENABLESTATE,
            USB,
            "chan_ident=CH1",
            msg::MOD_GET_CHANENABLESTATE,
        )
        // 2.5 mm/s and 4 mm/s² on a Z8 stage (34 554.96 counts/mm).
        .apt(
            msg::MOT_SET_VELPARAMS,
            USB,
            "chan_ident=CH1 min_vel=0 acceleration=1055 max_vel=1932478",
        )
        .ask(
            msg::MOT_REQ_VELPARAMS,
            USB,
            "chan_ident=CH1",
            msg::MOT_GET_VELPARAMS,
        )
        .apt(msg::HW_START_UPDATEMSGS, USB, "")
        .apt(msg::MOT_MOVE_HOME, USB, "chan_ident=CH1")
        .wait_reply(msg::MOT_MOVE_HOMED, MOVE_TIMEOUT_NS)
        .apt(
            msg::MOT_MOVE_ABSOLUTE,
            USB,
            "chan_ident=CH1 absolute_position=69110",
        )
        .wait_reply(msg::MOT_MOVE_COMPLETED, MOVE_TIMEOUT_NS)
        .apt(
            msg::MOT_MOVE_RELATIVE,
            USB,
            "chan_ident=CH1 relative_distance=-34555",
        )
        .wait_reply(msg::MOT_MOVE_COMPLETED, MOVE_TIMEOUT_NS)
        .ask(
            msg::MOT_REQ_POSCOUNTER,
            USB,
            "chan_ident=CH1",
            msg::MOT_GET_POSCOUNTER,
        )
        .apt(msg::HW_STOP_UPDATEMSGS, USB, "")
        // Everything sent before this reply has arrived when it does: the session is over.
        .ask(
            msg::MOD_REQ_CHANENABLESTATE,
            USB,
            "chan_ident=CH1",
            msg::MOD_GET_CHANENABLESTATE,
        );
    Ok(vec![part(
        Device::Apt(AptModel::Kdc101),
        "/dev/ttyUSB0",
        &mut s,
    )?])
}

/// BSC203: bay discovery on the rack, each bay identified and enabled, three moves at once,
/// their completions as they come, a status request per bay.
fn bsc203() -> Result<Vec<Part>, SessionError> {
    let mut s = Script::new();
    s.ask(msg::HW_REQ_INFO, RACK, "", msg::HW_GET_INFO);
    for bay in 0..4 {
        s.ask(
            msg::RACK_REQ_BAYUSED,
            RACK,
            &format!("bay_ident={bay}"),
            msg::RACK_GET_BAYUSED,
        );
    }
    let bays = [0x21u8, 0x22, 0x23];
    for b in bays {
        s.ask(msg::HW_REQ_INFO, b, "", msg::HW_GET_INFO).apt(
            msg::MOD_SET_CHANENABLESTATE,
            b,
            "chan_ident=CH1 enable_state=1",
        );
    }
    s.apt(msg::MOD_IDENTIFY, RACK, "chan_ident=CH2");
    // 0.5, 0.25 and 1 mm (409 600 µsteps/mm), all running at once.
    for (b, d) in bays.iter().zip([204_800, 102_400, 409_600]) {
        s.apt(
            msg::MOT_MOVE_RELATIVE,
            *b,
            &format!("chan_ident=CH1 relative_distance={d}"),
        );
    }
    for _ in bays {
        s.wait_reply(msg::MOT_MOVE_COMPLETED, MOVE_TIMEOUT_NS);
    }
    for b in bays {
        s.ask(
            msg::MOT_REQ_STATUSUPDATE,
            b,
            "chan_ident=CH1",
            msg::MOT_GET_STATUSUPDATE,
        );
    }
    s.ask(msg::RACK_REQ_STATUSBITS, RACK, "", msg::RACK_GET_STATUSBITS);
    Ok(vec![part(
        Device::Apt(AptModel::Bsc203),
        "/dev/ttyUSB0",
        &mut s,
    )?])
}

/// KPZ101: identify, enable, open loop, the voltage limit, two output voltages with status
/// updates in between, the status (as pylablib polls it).
fn kpz101() -> Result<Vec<Part>, SessionError> {
    let mut s = Script::new();
    s.ask(msg::HW_REQ_INFO, USB, "", msg::HW_GET_INFO)
        .apt(
            msg::MOD_SET_CHANENABLESTATE,
            USB,
            "chan_ident=CH1 enable_state=1",
        )
        .apt(msg::PZ_SET_POSCONTROLMODE, USB, "chan_ident=CH1 mode=1")
        .ask(
            msg::PZ_REQ_POSCONTROLMODE,
            USB,
            "chan_ident=CH1",
            msg::PZ_GET_POSCONTROLMODE,
        )
        // Its voltage limit: a KPZ101 has PZ_REQ_TPZ_IOSETTINGS, not PZ_REQ_OUTPUTMAXVOLTS
        // (its lists in both revisions of the spec), and the simulator ignores the latter.
        .ask(
            msg::PZ_REQ_TPZ_IOSETTINGS,
            USB,
            "chan_ident=CH1",
            msg::PZ_GET_TPZ_IOSETTINGS,
        )
        .apt(msg::PZ_SET_OUTPUTVOLTS, USB, "chan_ident=CH1 voltage=16384")
        .ask(
            msg::PZ_REQ_OUTPUTVOLTS,
            USB,
            "chan_ident=CH1",
            msg::PZ_GET_OUTPUTVOLTS,
        )
        .apt(msg::HW_START_UPDATEMSGS, USB, "")
        .wait_ms(350)
        .apt(msg::PZ_SET_OUTPUTVOLTS, USB, "chan_ident=CH1 voltage=8192")
        .wait_ms(250)
        .apt(msg::HW_STOP_UPDATEMSGS, USB, "")
        .ask(
            msg::PZ_REQ_OUTPUTVOLTS,
            USB,
            "chan_ident=CH1",
            msg::PZ_GET_OUTPUTVOLTS,
        )
        // Its status as pylablib asks for it (PZ_REQ_PZSTATUSBITS is not in its lists).
        .ask(
            msg::PZ_REQ_PZSTATUSUPDATE,
            USB,
            "chan_ident=CH1",
            msg::PZ_GET_PZSTATUSUPDATE,
        );
    Ok(vec![part(
        Device::Apt(AptModel::Kpz101),
        "/dev/ttyUSB0",
        &mut s,
    )?])
}

/// A TLS001 laser source, a TTC001 TEC controller and a KPA101 position aligner on three ports:
/// LA_, TEC_ and QUAD_ PARAMS sub-messages set and requested, one status update each.
fn laser_tec_quad() -> Result<Vec<Part>, SessionError> {
    let la = msg::LA_GET_PARAMS;
    let mut s = Script::new();
    s.ask(msg::HW_REQ_INFO, USB, "", msg::HW_GET_INFO)
        .ask(msg::LA_REQ_PARAMS, USB, "sub_id=9", la)
        .ask(msg::LA_REQ_PARAMS, USB, "sub_id=5", la)
        .apt_sub(msg::LA_SET_PARAMS, msg::la::SETPOINT, USB, "setpoint=16384")
        .ask(msg::LA_REQ_PARAMS, USB, "sub_id=1", la)
        .apt_sub(
            msg::LA_SET_PARAMS,
            msg::la::DISPLAY,
            USB,
            "disp_intensity=128 disp_units=MW",
        )
        .apt(msg::LA_ENABLEOUTPUT, USB, "")
        .ask(msg::LA_REQ_PARAMS, USB, "sub_id=3", la)
        .ask(msg::LA_REQ_PARAMS, USB, "sub_id=7", la)
        .ask(msg::LA_REQ_STATUSUPDATE, USB, "", msg::LA_GET_STATUSUPDATE)
        .apt(msg::LA_DISABLEOUTPUT, USB, "")
        .ask(msg::LA_REQ_PARAMS, USB, "sub_id=7", la);
    let laser = part(Device::Apt(AptModel::Tls001), "/dev/ttyUSB0", &mut s)?;

    let tec = msg::TEC_GET_PARAMS;
    s.ask(msg::HW_REQ_INFO, USB, "", msg::HW_GET_INFO)
        .ask(msg::TEC_REQ_PARAMS, USB, "sub_id=5", tec)
        .apt_sub(
            msg::TEC_SET_PARAMS,
            msg::tec::TEMP_SETPOINT,
            USB,
            "t_set=2000",
        )
        .ask(msg::TEC_REQ_PARAMS, USB, "sub_id=1", tec)
        .apt_sub(
            msg::TEC_SET_PARAMS,
            msg::tec::LOOP_PARAMS,
            USB,
            "p_gain=0x5332 i_gain=0x6665 d_gain=0x4CCC",
        )
        .ask(msg::TEC_REQ_PARAMS, USB, "sub_id=9", tec)
        .ask(msg::TEC_REQ_PARAMS, USB, "sub_id=3", tec)
        .ask(msg::TEC_REQ_PARAMS, USB, "sub_id=7", tec)
        .ask(
            msg::TEC_REQ_STATUSUPDATE,
            USB,
            "",
            msg::TEC_GET_STATUSUPDATE,
        );
    let tec = part(Device::Apt(AptModel::Ttc001), "/dev/ttyUSB1", &mut s)?;

    let q = msg::QUAD_GET_PARAMS;
    s.ask(msg::HW_REQ_INFO, USB, "", msg::HW_GET_INFO)
        .ask(msg::QUAD_REQ_PARAMS, USB, "sub_id=7", q)
        .ask(msg::QUAD_REQ_PARAMS, USB, "sub_id=3", q)
        .apt_sub(
            msg::QUAD_SET_PARAMS,
            msg::quad::POS_DEMAND_OUTPUTS,
            USB,
            "x_pos=-2400 y_pos=1600",
        )
        .apt_sub(
            msg::QUAD_SET_PARAMS,
            msg::quad::OPER_MODE,
            USB,
            "mode=OPEN_LOOP",
        )
        .ask(msg::QUAD_REQ_PARAMS, USB, "sub_id=3", q)
        .apt_sub(
            msg::QUAD_SET_PARAMS,
            msg::quad::OPER_MODE,
            USB,
            "mode=CLOSED_LOOP",
        )
        .ask(msg::QUAD_REQ_PARAMS, USB, "sub_id=9", q)
        .ask(msg::QUAD_REQ_PARAMS, USB, "sub_id=14", q)
        .ask(
            msg::QUAD_REQ_STATUSUPDATE,
            USB,
            "",
            msg::QUAD_GET_STATUSUPDATE,
        );
    let quad = part(Device::Apt(AptModel::Kpa101), "/dev/ttyUSB2", &mut s)?;
    Ok(vec![laser, tec, quad])
}

/// An Elliptec bus of an ELL14 rotation mount (0), an ELL9 slider (1) and an ELL17 linear stage
/// (2): identify, home, moves, positions, the ELL17 readdressed to 5 and used there.
fn elliptec() -> Result<Vec<Part>, SessionError> {
    let t = REPLY_TIMEOUT_NS;
    let mv = MOVE_TIMEOUT_NS;
    let mut s = Script::new();
    s.ell_ask("0in", "0IN", t)
        .ell_ask("1in", "1IN", t)
        .ell_ask("2in", "2IN", t)
        .ell_ask("0ho0", "0PO", mv)
        .ell_ask("0ma00008C00", "0PO", mv) // 90°
        .ell_ask("0gp", "0PO", t)
        .ell_ask("1fw", "1PO", mv)
        .ell_ask("2ho0", "2PO", mv)
        .ell_ask("2ma00002000", "2PO", mv) // 4 mm
        .ell_ask("2mr00001000", "2PO", mv) // +2 mm
        .ell_ask("2gs", "2GS", t)
        .ell_ask("2ca5", "5GS", t)
        .ell_ask("5gp", "5PO", t)
        .ell_ask("5mrFFFFF800", "5PO", mv) // -1 mm
        .ell_ask("5gs", "5GS", t);
    Ok(vec![part(
        Device::Elliptec("0:ELL14,1:ELL9,2:ELL17".into()),
        "/dev/ttyUSB0",
        &mut s,
    )?])
}

/// The scripted session `name` (any of [`NAMES`] but `damaged`, which is made from `kdc101`).
pub fn session(name: &str) -> Result<Session, SessionError> {
    let parts = match name {
        "kdc101" => kdc101()?,
        "bsc203" => bsc203()?,
        "kpz101" => kpz101()?,
        "laser-tec-quad" => laser_tec_quad()?,
        "elliptec" => elliptec()?,
        _ => return Err(SessionError::Unknown(name.to_string())),
    };
    Ok(Session {
        name: name.to_string(),
        parts,
    })
}

// ------------------------------------------------------------------------------- the host's ear

/// What the host reads, and the names of the replies in it (decoded by the decode chain).
struct HostRx {
    dec: Decoder,
    names: Vec<String>,
    cursor: usize,
}

impl HostRx {
    fn new(proto: Proto) -> HostRx {
        HostRx {
            dec: Decoder::new(Some(proto)),
            names: vec![],
            cursor: 0,
        }
    }

    fn push(&mut self, b: &[u8]) {
        let ctx = Ctx {
            stream: 0,
            dir: Some(Dir::DeviceToHost),
            ts_ns: None,
        };
        let mut got = vec![];
        let Ok(()) = self.dec.push(ctx, b, &mut |r| name_of(r, &mut got));
        self.names.extend(got.into_iter().map(|(_, n)| n));
    }

    /// Take the next reply named `name` (skipping others before it).
    fn take(&mut self, name: &str) -> bool {
        match self.names[self.cursor..].iter().position(|n| n == name) {
            Some(i) => {
                self.cursor += i + 1;
                true
            }
            None => false,
        }
    }
}

/// Nanoseconds per byte on the protocol's line (8N1: 10 bits).
pub fn byte_ns(proto: Proto) -> u64 {
    match proto {
        Proto::Apt => 86_806,
        Proto::Elliptec => 1_041_667,
    }
}

// ------------------------------------------------------------------------------ virtual record

struct Virtual<'a> {
    sim: &'a mut dyn Simulator,
    now: u64,
    start_ns: u64,
    stream: u32,
    out: Vec<OwnedChunk>,
    host: HostRx,
}

impl Virtual<'_> {
    fn chunk(&mut self, t: u64, dir: Direction, bytes: Vec<u8>) {
        self.out.push(OwnedChunk {
            ts_ns: Some(self.start_ns.saturating_add(t)),
            dir,
            stream: self.stream,
            bytes,
        });
    }

    /// Run the simulator up to `to`, recording what it sends when it sends it.
    fn advance(&mut self, to: u64) -> Result<(), SessionError> {
        for _ in 0..MAX_ITER {
            let Some(d) = self.sim.next_deadline() else {
                break;
            };
            let t = d.max(self.now);
            if t > to {
                break;
            }
            self.now = t;
            let mut got = false;
            while let Some(b) = self.sim.poll(t) {
                got = true;
                self.host.push(&b);
                self.chunk(t, Direction::DeviceToHost, b);
            }
            if !got && self.sim.next_deadline().is_some_and(|n| n <= t) {
                // A deadline with nothing due yet: look again a little later.
                self.now = t + 1;
            }
        }
        if self
            .sim
            .next_deadline()
            .is_some_and(|d| d.max(self.now) <= to)
        {
            return Err(SessionError::Stuck);
        }
        self.now = self.now.max(to);
        Ok(())
    }
}

/// Play `steps` against `sim` on a virtual clock starting at `start_ns` (ns since the epoch),
/// and return the chunks a tap would have recorded on stream `stream`: what the host wrote
/// (at the time it wrote it, reaching the device a byte time per byte later) and what the
/// device sent (at the time its last byte arrived). Fails when an expected reply does not come
/// in time.
pub fn record_virtual(
    sim: &mut dyn Simulator,
    proto: Proto,
    steps: &[Step],
    stream: u32,
    start_ns: u64,
) -> Result<Vec<OwnedChunk>, SessionError> {
    let per_byte = byte_ns(proto);
    let mut v = Virtual {
        sim,
        now: 0,
        start_ns,
        stream,
        out: vec![],
        host: HostRx::new(proto),
    };
    for (i, step) in steps.iter().enumerate() {
        match step {
            Step::Send { bytes, .. } => {
                v.advance(v.now + HOST_GAP_NS)?;
                let t = v.now;
                v.chunk(t, Direction::HostToDevice, bytes.clone());
                let arrive = t + per_byte * bytes.len() as u64;
                v.advance(arrive)?;
                v.sim.input(bytes, arrive);
            }
            Step::Expect { name, timeout_ns } => {
                let deadline = v.now + timeout_ns;
                let mut n = 0;
                while !v.host.take(name) {
                    n += 1;
                    match v.sim.next_deadline() {
                        Some(d) if d.max(v.now) <= deadline && n < MAX_ITER => {
                            v.advance(d.max(v.now))?
                        }
                        _ => {
                            return Err(SessionError::NoReply {
                                step: i,
                                name: name.clone(),
                                ms: timeout_ns / MS,
                            })
                        }
                    }
                }
            }
            Step::Wait(d) => v.advance(v.now + d)?,
        }
    }
    v.advance(v.now + END_DRAIN_NS)?;
    Ok(v.out)
}

/// Record a session on the virtual clock from [`EPOCH_NS`]: `damaged` is the `kdc101` session
/// damaged by [`damage`]; the others come from [`session`].
pub fn record(name: &str) -> Result<Recording, SessionError> {
    if name == "damaged" {
        let mut r = record("kdc101")?;
        r.name = name.to_string();
        r.chunks = damage(&r.chunks);
        return Ok(r);
    }
    let s = session(name)?;
    let proto = s.parts.first().map_or(Proto::Apt, |p| p.device.proto());
    let mut streams = vec![];
    let mut chunks: Vec<OwnedChunk> = vec![];
    let mut start = EPOCH_NS;
    for (i, p) in s.parts.iter().enumerate() {
        let id = i as u32;
        streams.push(StreamInfo {
            id,
            name: p.port.clone(),
            settings: Some(p.device.settings().to_string()),
        });
        let mut sim = p.device.simulator()?;
        let c = record_virtual(&mut *sim, p.device.proto(), &p.steps, id, start).map_err(|e| {
            SessionError::In {
                session: name.to_string(),
                port: p.port.clone(),
                error: Box::new(e),
            }
        })?;
        let end = c.last().and_then(|c| c.ts_ns).unwrap_or(start);
        start = end + END_DRAIN_NS + PART_GAP_NS;
        chunks.extend(c);
    }
    chunks.sort_by_key(|c| c.ts_ns);
    Ok(Recording {
        name: name.to_string(),
        proto,
        streams,
        chunks,
    })
}

/// Damage a recorded APT session as a bad cable would: line noise before the first reply and
/// between two replies, and a pulled cable during the first move after homing: the device's
/// last message stops after 9 of its bytes and nothing crosses afterwards (a tap without
/// `--reconnect` ends there; it writes no marker, so the capture just stops).
pub fn damage(chunks: &[OwnedChunk]) -> Vec<OwnedChunk> {
    let names = chunk_names(Proto::Apt, chunks);
    let mut out: Vec<OwnedChunk> = vec![];
    let mut d2h_seen = 0;
    let mut after_move = None;
    for (i, c) in chunks.iter().enumerate() {
        let is = |id: u16| {
            names
                .get(i)
                .is_some_and(|v| v.iter().any(|x| x == msg_name(id)))
        };
        if c.dir == Direction::DeviceToHost {
            // Noise just before the first reply and before the fifth thing the device sends.
            if d2h_seen == 0 || d2h_seen == 4 {
                let noise: &[u8] = if d2h_seen == 0 {
                    &[0x00, 0xF8, 0x80, 0x00]
                } else {
                    &[0xFF, 0x13, 0x37]
                };
                out.push(OwnedChunk {
                    ts_ns: c.ts_ns.map(|t| t.saturating_sub(300_000)),
                    bytes: noise.to_vec(),
                    ..c.clone()
                });
            }
            d2h_seen += 1;
            if let Some(n) = after_move.as_mut() {
                *n += 1;
                if *n == 5 {
                    out.push(OwnedChunk {
                        bytes: c.bytes.iter().take(9).copied().collect(),
                        ..c.clone()
                    });
                    return out;
                }
            }
        } else if is(msg::MOT_MOVE_ABSOLUTE) {
            after_move = Some(0);
        }
        out.push(c.clone());
    }
    out
}

/// For each chunk, the names of the frames that end in it (APT message names; Elliptec address
/// and command as sent: `0in`, `0PO`), from the decode chain (one lane per stream and
/// direction).
pub fn chunk_names(proto: Proto, chunks: &[OwnedChunk]) -> Vec<Vec<String>> {
    names(proto, chunks)
        .0
        .into_iter()
        .map(|c| c.into_iter().map(|(_, n)| n).collect())
        .collect()
}

/// The frame names of a capture in order, with directions: [`chunk_names`] flattened, then
/// the frames only completed at the end of the capture.
pub fn frame_names(proto: Proto, chunks: &[OwnedChunk]) -> Vec<(Direction, String)> {
    let (per_chunk, end) = names(proto, chunks);
    let mut out = vec![];
    for n in per_chunk {
        out.extend(n);
    }
    out.extend(end);
    out
}

/// The names of the whole frames completed while each chunk is fed, and at the end, with the
/// direction each frame was captured in.
#[allow(clippy::type_complexity)]
fn names(
    proto: Proto,
    chunks: &[OwnedChunk],
) -> (Vec<Vec<(Direction, String)>>, Vec<(Direction, String)>) {
    let mut dec = Decoder::new(Some(proto));
    let mut per_chunk = vec![];
    for c in chunks {
        let mut got = vec![];
        let Ok(()) = dec.push(c.as_chunk().ctx(), &c.bytes, &mut |r| name_of(r, &mut got));
        per_chunk.push(got);
    }
    let mut end = vec![];
    let Ok(()) = dec.finish(&mut |r| name_of(r, &mut end));
    (per_chunk, end)
}

/// A whole frame's name (APT message name; Elliptec address and command as sent) and the
/// direction it was captured in.
fn name_of(r: &Record<'_>, out: &mut Vec<(Direction, String)>) -> Result<(), Infallible> {
    let truncated = |d: aptscope_dissector::Diag| matches!(d.kind, DiagKind::Truncated { .. });
    match r {
        Record::Apt(a) if !a.frame.diags().any(truncated) => out.push((
            Direction::from_dir(a.meta.cap_dir),
            a.frame.name().unwrap_or("?").to_string(),
        )),
        Record::Ell(e) if !e.frame.diags().iter().copied().any(truncated) => out.push((
            Direction::from_dir(e.meta.cap_dir),
            format!("{}{}", e.frame.addr_char(), e.frame.code_str()),
        )),
        _ => {}
    }
    Ok(())
}

// ------------------------------------------------------------------------------------ writing

/// The formats a recording is written in: the extension and format (`bin` only for
/// single-port APT sessions: a raw byte stream of the conversation).
pub fn formats(rec: &Recording) -> Vec<(&'static str, Format)> {
    let mut v = vec![
        ("pcapng", Format::PcapNg),
        ("pcap", Format::Pcap),
        ("mcap", Format::Mcap),
    ];
    if rec.proto == Proto::Apt && rec.streams.len() == 1 {
        v.push(("bin", Format::Raw));
    }
    v
}

/// Write `rec` into `dir` as `<name>.<ext>` in every format of [`formats`] (overwriting), and
/// return the paths written.
pub fn write_recording(rec: &Recording, dir: &Path) -> io::Result<Vec<PathBuf>> {
    let mut paths = vec![];
    for (ext, fmt) in formats(rec) {
        let p = dir.join(format!("{}.{ext}", rec.name));
        let ps = p.to_str().ok_or_else(|| {
            io::Error::new(io::ErrorKind::InvalidInput, "path is not UTF-8".to_string())
        })?;
        let mut w = create(ps, fmt, true)?;
        for s in &rec.streams {
            w.stream(s)?;
        }
        for c in &rec.chunks {
            w.chunk(&c.as_chunk())?;
        }
        w.finish()?;
        paths.push(p);
    }
    Ok(paths)
}

/// Read every chunk of a capture file, with the file's diagnostics.
pub fn read_capture(path: &Path) -> io::Result<(Vec<OwnedChunk>, Vec<String>)> {
    let ps = path.to_str().ok_or_else(|| {
        io::Error::new(io::ErrorKind::InvalidInput, "path is not UTF-8".to_string())
    })?;
    let (mut r, _) = open(ps, OpenOptions::default())?;
    let (mut chunks, mut diags) = (vec![], vec![]);
    while let Some(e) = r.next_event() {
        match e {
            Event::Chunk(c) => chunks.push(c.to_owned()),
            Event::Diag(d) => diags.push(d.to_string()),
            Event::Stream(_) => {}
        }
    }
    Ok((chunks, diags))
}

// ---------------------------------------------------------------------------------- real time

/// What a real-time run of a script produced.
#[derive(Debug)]
pub struct RealRun {
    /// The tap's capture file.
    pub capture: PathBuf,
    /// Every byte the host script wrote, in order.
    pub sent: Vec<u8>,
    /// Every byte the host script read, in order.
    pub read: Vec<u8>,
    /// The tap's statistics.
    pub stats: TapStats,
}

/// The host's end of the tap: the link opened as a terminal, read with deadlines.
struct HostPort {
    f: std::fs::File,
    rx: HostRx,
    read: Vec<u8>,
}

impl HostPort {
    /// Read what is there, waiting until `until` at most for something.
    fn read_some(&mut self, until: Instant) -> io::Result<()> {
        use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
        use std::os::fd::AsFd;
        let left = until.saturating_duration_since(Instant::now());
        let ms = u16::try_from(left.as_millis().min(1000)).unwrap_or(1000);
        let mut fds = [PollFd::new(self.f.as_fd(), PollFlags::POLLIN)];
        let n = poll(&mut fds, PollTimeout::from(ms)).map_err(io::Error::from)?;
        if n == 0 {
            return Ok(());
        }
        let mut buf = [0u8; 4096];
        let k = self.f.read(&mut buf)?;
        if k == 0 {
            return Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                "the tap closed the line",
            ));
        }
        self.read.extend_from_slice(&buf[..k]);
        self.rx.push(&buf[..k]);
        Ok(())
    }
}

/// Run `steps` in real time: `device` simulated on a pseudo-terminal, the tap between it and a
/// new pseudo-terminal linked at `dir/tty`, writing `dir/tap.pcapng`, and the script as the
/// host program on the link. Every wait of the script gets 20 s on top (it only matters when
/// something is broken). The tap is stopped once the script is done, then the
/// simulator.
pub fn run_real(device: &Device, steps: &[Step], dir: &Path) -> Result<RealRun, SessionError> {
    let proto = device.proto();
    let pty = Pty::open()?;
    let dev_path = pty.path().to_string_lossy().into_owned();
    let (sim_stop, sim_signal) = stop_pair()?;
    let mut sim = device.simulator()?;
    let sim_thread = std::thread::spawn(move || serve_pty(&mut *sim, pty, Some(&sim_signal), &[]));

    let link = dir.join("tty");
    let capture = dir.join("tap.pcapng");
    let mut opts = TapOptions::new(dev_path, Some(link.to_string_lossy().into_owned()));
    opts.live.proto = proto;
    opts.live.write = Some(capture.to_string_lossy().into_owned());
    opts.live.force = true;
    opts.live.quiet = true;
    opts.live.signals = false;
    let tap_stop = opts.live.stop.clone();
    let tap_thread = std::thread::spawn(move || tap_main(opts));

    let result = (|| -> Result<(Vec<u8>, Vec<u8>), SessionError> {
        // The link appears once the tap has opened the device and made its pseudo-terminal.
        let t0 = Instant::now();
        while std::fs::read_link(&link).is_err() {
            if t0.elapsed() > REAL_SLACK || tap_thread.is_finished() {
                return Err(SessionError::TapNotStarted);
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        let f = std::fs::File::options()
            .read(true)
            .write(true)
            .custom_flags(nix::fcntl::OFlag::O_NOCTTY.bits())
            .open(&link)
            .map_err(|source| SessionError::Link {
                path: link.display().to_string(),
                source,
            })?;
        let mut host = HostPort {
            f,
            rx: HostRx::new(proto),
            read: vec![],
        };
        let mut sent = vec![];
        for (i, step) in steps.iter().enumerate() {
            match step {
                Step::Send { bytes, .. } => {
                    host.f.write_all(bytes)?;
                    sent.extend_from_slice(bytes);
                }
                Step::Expect { name, timeout_ns } => {
                    let until = Instant::now() + Duration::from_nanos(*timeout_ns) + REAL_SLACK;
                    while !host.rx.take(name) {
                        if Instant::now() >= until {
                            return Err(SessionError::Late {
                                step: i,
                                name: name.clone(),
                            });
                        }
                        host.read_some(until)?;
                    }
                }
                Step::Wait(d) => {
                    let until = Instant::now() + Duration::from_nanos(*d);
                    while Instant::now() < until {
                        host.read_some(until)?;
                    }
                }
            }
        }
        Ok((sent, host.read))
    })();
    tap_stop.stop();
    let stats = tap_thread
        .join()
        .map_err(|_| SessionError::Panicked("tap"))?;
    sim_stop.stop();
    let sim_result = sim_thread
        .join()
        .map_err(|_| SessionError::Panicked("simulator"))?;
    let (sent, read) = match (result, &stats) {
        (Ok(r), _) => r,
        (Err(e), Ok(_)) => return Err(e),
        (Err(e), Err(_)) => {
            let tap = stats
                .err()
                .unwrap_or_else(|| LiveError::Io(io::Error::other("?")));
            return Err(SessionError::AndTap {
                run: Box::new(e),
                tap,
            });
        }
    };
    let stats = stats?;
    sim_result.map_err(SessionError::Simulator)?;
    Ok(RealRun {
        capture,
        sent,
        read,
        stats,
    })
}
