//! Opening a real serial port for polled I/O.
//!
//! The serialport crate configures the line (baud, 8N1, flow control) and holds it
//! exclusively, but its reads and writes wait with `ppoll` and an *empty* signal mask: every
//! signal is unblocked while they wait, so a Ctrl-C that a program receives through a signalfd
//! (blocking SIGINT) would kill it instead. So the port is configured with serialport, and the
//! I/O goes through a second, non-blocking descriptor of the same port, waited on with `poll`,
//! which leaves the signal mask alone.

use super::tap::LineSettings;
use nix::fcntl::OFlag;
use std::fs::File;
use std::io;
use std::os::unix::fs::OpenOptionsExt;

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

/// Open `path` exclusively with `settings` (8 data bits, no parity, one stop bit). What the
/// device sent before is kept (a tap must not lose it).
pub fn open_serial(path: &str, settings: &LineSettings) -> io::Result<SerialFd> {
    let mut port = serialport::new(path, settings.baud)
        .data_bits(serialport::DataBits::Eight)
        .parity(serialport::Parity::None)
        .stop_bits(serialport::StopBits::One)
        .flow_control(settings.flow.to_serialport())
        .open_native()
        .map_err(|e| io::Error::new(io::Error::from(e.clone()).kind(), format!("{path}: {e}")))?;
    // The second descriptor is opened while the exclusive lock is briefly lifted.
    port.set_exclusive(false).map_err(io::Error::from)?;
    let file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags((OFlag::O_NOCTTY | OFlag::O_NONBLOCK).bits())
        .open(path)
        .map_err(|e| io::Error::new(e.kind(), format!("{path}: {e}")));
    port.set_exclusive(true).map_err(io::Error::from)?;
    Ok(SerialFd { file: file?, port })
}
