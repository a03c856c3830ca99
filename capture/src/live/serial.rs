//! Opening a real serial port for polled I/O.
//!
//! The serialport crate configures the line (baud, 8N1, flow control) and holds it
//! exclusively, but its reads and writes wait with `ppoll` and an *empty* signal mask: every
//! signal is unblocked while they wait, so a Ctrl-C that a program receives through a signalfd
//! (blocking SIGINT) would kill it instead. So the port is configured with serialport, and the
//! I/O goes through a second, non-blocking descriptor of the same port, waited on with `poll`,
//! which leaves the signal mask alone.

use crate::live::error::PortError;
use aptscope_dissector::detect::Proto;
use nix::fcntl::OFlag;
use std::fmt;
use std::fs::File;
use std::io;
use std::os::unix::fs::OpenOptionsExt;

/// Flow control on the real port.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flow {
    /// None.
    None,
    /// Hardware, RTS/CTS (APT controllers).
    RtsCts,
    /// Software, XON/XOFF.
    XonXoff,
}

impl Flow {
    /// Parse `none`, `rtscts` (`hw`, `rts/cts`), `xonxoff` (`sw`).
    pub fn parse(s: &str) -> Option<Flow> {
        Some(match s.to_ascii_lowercase().as_str() {
            "none" | "off" => Flow::None,
            "rtscts" | "rts/cts" | "hw" | "hardware" => Flow::RtsCts,
            "xonxoff" | "xon/xoff" | "sw" | "software" => Flow::XonXoff,
            _ => return None,
        })
    }

    pub(crate) fn to_serialport(self) -> serialport::FlowControl {
        match self {
            Flow::None => serialport::FlowControl::None,
            Flow::RtsCts => serialport::FlowControl::Hardware,
            Flow::XonXoff => serialport::FlowControl::Software,
        }
    }
}

/// Line settings of the real port: always 8 data bits, no parity, one stop bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LineSettings {
    /// Baud rate.
    pub baud: u32,
    /// Flow control.
    pub flow: Flow,
}

impl LineSettings {
    /// The protocol's settings (APT: 115200 8N1 RTS/CTS; Elliptec: 9600 8N1), with overrides.
    pub fn for_proto(proto: Proto, baud: Option<u32>, flow: Option<Flow>) -> LineSettings {
        let (b, f) = match proto {
            Proto::Apt => (115_200, Flow::RtsCts),
            Proto::Elliptec => (9_600, Flow::None),
        };
        LineSettings {
            baud: baud.unwrap_or(b),
            flow: flow.unwrap_or(f),
        }
    }
}

impl fmt::Display for LineSettings {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} 8N1", self.baud)?;
        match self.flow {
            Flow::None => Ok(()),
            Flow::RtsCts => f.write_str(" RTS/CTS"),
            Flow::XonXoff => f.write_str(" XON/XOFF"),
        }
    }
}

/// A serial port open for polled I/O.
#[derive(Debug)]
pub struct SerialFd {
    /// The non-blocking descriptor to read, write and poll.
    pub file: File,
    /// The configured port: its settings and exclusive lock last while it is open.
    port: serialport::TTYPort,
}

impl SerialFd {
    /// The configured port (to change settings, flush buffers …).
    pub fn port(&mut self) -> &mut serialport::TTYPort {
        &mut self.port
    }
}

/// A file or directory where a serial port was expected: say so, instead of the "Not a
/// typewriter" (ENOTTY) that configuring it as a terminal gives.
fn not_a_port(path: &str) -> Result<(), PortError> {
    use std::os::unix::fs::FileTypeExt;
    let Ok(meta) = std::fs::metadata(path) else {
        // Missing or unreadable: opening it says why.
        return Ok(());
    };
    let t = meta.file_type();
    let what = if t.is_dir() {
        "a directory"
    } else if t.is_file() {
        "a regular file"
    } else if t.is_char_device() {
        return Ok(());
    } else {
        "not a device"
    };
    Err(PortError::NotAPort {
        path: path.to_string(),
        what,
    })
}

/// Whether `path` can be a serial port to open now, before anything is asked or sent: it exists,
/// is a terminal device, and no other program holds it exclusively. The error says which.
pub fn check_port(path: &str) -> Result<(), PortError> {
    if std::fs::symlink_metadata(path).is_err() && std::fs::metadata(path).is_err() {
        return Err(PortError::Missing {
            path: path.to_string(),
        });
    }
    not_a_port(path)?;
    let f = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags((OFlag::O_NOCTTY | OFlag::O_NONBLOCK).bits())
        .open(path)
        .map_err(|source| {
            let path = path.to_string();
            match source.raw_os_error() {
                Some(ebusy) if ebusy == nix::errno::Errno::EBUSY as i32 => {
                    PortError::Busy { path, source }
                }
                _ => PortError::Open { path, source },
            }
        })?;
    if !nix::unistd::isatty(&f).unwrap_or(false) {
        return Err(PortError::NotATerminal {
            path: path.to_string(),
        });
    }
    Ok(())
}

/// Open `path` exclusively with `settings` (8 data bits, no parity, one stop bit). What the
/// device sent before is kept (a tap must not lose it).
pub fn open_serial(path: &str, settings: &LineSettings) -> Result<SerialFd, PortError> {
    not_a_port(path)?;
    let mut port = serialport::new(path, settings.baud)
        .data_bits(serialport::DataBits::Eight)
        .parity(serialport::Parity::None)
        .stop_bits(serialport::StopBits::One)
        .flow_control(settings.flow.to_serialport())
        .open_native()
        .map_err(|e| {
            let path = path.to_string();
            // A character device that is no terminal (/dev/null) fails with ENOTTY, which
            // strerror calls "Not a typewriter".
            let probe = std::fs::OpenOptions::new()
                .read(true)
                .custom_flags((OFlag::O_NOCTTY | OFlag::O_NONBLOCK).bits())
                .open(&path);
            if probe.is_ok_and(|f| !nix::unistd::isatty(&f).unwrap_or(true)) {
                return PortError::NotATerminal { path };
            }
            // (The library's message is its error's description, as the io::Error's is.)
            PortError::Open {
                path,
                source: io::Error::from(e),
            }
        })?;
    let configure = |e: serialport::Error| PortError::Configure {
        path: path.to_string(),
        source: io::Error::from(e),
    };
    // The second descriptor is opened while the exclusive lock is briefly lifted.
    port.set_exclusive(false).map_err(configure)?;
    let file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags((OFlag::O_NOCTTY | OFlag::O_NONBLOCK).bits())
        .open(path)
        .map_err(|source| PortError::Open {
            path: path.to_string(),
            source,
        });
    port.set_exclusive(true).map_err(configure)?;
    Ok(SerialFd { file: file?, port })
}
