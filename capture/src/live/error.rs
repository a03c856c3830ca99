//! Typed errors of the live tools, each carrying the port, path or side it concerns (as
//! [`crate::open`]'s `OpenError` and `CreateError` do for capture files). Their messages are
//! what the command line prints; `From` impls turn them into `io::Error` with a fitting kind
//! for callers that deal in those.

use crate::live::pty::LinkError;
use crate::open::CreateError;
use std::io;

/// What a serial port looks like, for the messages that say a path is none.
const PORTS: &str = "serial port (/dev/ttyUSB0, /dev/ttyACM0, /dev/serial/by-id/…)";

/// Why a serial port could not be checked, opened or configured.
#[derive(Debug, thiserror::Error)]
pub enum PortError {
    /// Nothing is at the path.
    #[error("no such port: {path} does not exist")]
    Missing {
        /// The port's path.
        path: String,
    },
    /// Something other than a device is at the path.
    #[error("{path} is {what}, not a {PORTS}")]
    NotAPort {
        /// The port's path.
        path: String,
        /// What is there instead: `a directory`, `a regular file`, `not a device`.
        what: &'static str,
    },
    /// A device that is no terminal (`/dev/null`).
    #[error("{path} is not a terminal, so not a {PORTS}")]
    NotATerminal {
        /// The port's path.
        path: String,
    },
    /// Another program holds the port exclusively.
    #[error("{path} is busy: another program has it open exclusively")]
    Busy {
        /// The port's path.
        path: String,
        /// What the system said.
        source: io::Error,
    },
    /// Opening the port failed.
    #[error("{path}: {source}")]
    Open {
        /// The port's path.
        path: String,
        /// What the system (or the serial port library) said.
        source: io::Error,
    },
    /// Configuring the open port failed.
    #[error("{source}")]
    Configure {
        /// The port's path.
        path: String,
        /// What the system said.
        source: io::Error,
    },
}

impl PortError {
    /// The port the error concerns.
    pub fn path(&self) -> &str {
        match self {
            PortError::Missing { path }
            | PortError::NotAPort { path, .. }
            | PortError::NotATerminal { path }
            | PortError::Busy { path, .. }
            | PortError::Open { path, .. }
            | PortError::Configure { path, .. } => path,
        }
    }

    /// The kind of `io::Error` it becomes.
    pub fn kind(&self) -> io::ErrorKind {
        match self {
            PortError::Missing { .. } => io::ErrorKind::NotFound,
            PortError::NotAPort { .. } | PortError::NotATerminal { .. } => {
                io::ErrorKind::InvalidInput
            }
            PortError::Busy { source, .. }
            | PortError::Open { source, .. }
            | PortError::Configure { source, .. } => source.kind(),
        }
    }
}

impl From<PortError> for io::Error {
    fn from(e: PortError) -> io::Error {
        io::Error::new(e.kind(), e)
    }
}

/// Why a tap, sniff, live view or simulator runner could not start or went wrong.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// The capture file: its format cannot be told, it exists, or it cannot be created.
    #[error(transparent)]
    Capture(#[from] CreateError),
    /// The capture file's format is one a live tool cannot write as it goes.
    #[error(
        "{path}: the tap writes pcapng or pcap (readable up to the last block if it is \
         killed), not {format}; record a .pcapng and `aptscope convert` it"
    )]
    NotStreamable {
        /// The capture file's path.
        path: String,
        /// The format its name (or `--write-format`) asks for.
        format: &'static str,
    },
    /// A stream goes into an existing pipe, and this is none.
    #[error("{path}: not a pipe (a stream goes into an existing FIFO)")]
    NotAPipe {
        /// The path given.
        path: String,
    },
    /// The stream's pipe could not be looked at or opened.
    #[error("{path}: {source}")]
    Stream {
        /// The pipe's path.
        path: String,
        /// What the system said.
        source: io::Error,
    },
    /// A serial port (the device, an adapter, a simulator's port).
    #[error(transparent)]
    Port(#[from] PortError),
    /// The symlink naming the pseudo-terminal.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The tap's host side (the pseudo-terminal the host program opens) failed.
    #[error("host side: {0}")]
    HostSide(io::Error),
    /// The serial port a simulator serves on went away.
    #[error("the serial port went away")]
    PortGone {
        /// The port's path.
        path: String,
    },
    /// A live view was asked for without a capture file to follow.
    #[error("a live view follows the capture file: give one (-w)")]
    NoViewFile,
    /// The simulator behind a live view failed.
    #[error("simulator: {0}")]
    Simulator(io::Error),
    /// A thread of the run panicked (`tap`, `simulator`).
    #[error("the {0} panicked")]
    Panicked(&'static str),
    /// Anything else the system said (a pseudo-terminal, a signal descriptor, the file).
    #[error("{0}")]
    Io(#[from] io::Error),
}

impl LiveError {
    /// The kind of `io::Error` it becomes.
    pub fn kind(&self) -> io::ErrorKind {
        match self {
            LiveError::Capture(CreateError::Exists { .. }) => io::ErrorKind::AlreadyExists,
            LiveError::Capture(CreateError::File { source, .. } | CreateError::Write(source)) => {
                source.kind()
            }
            LiveError::Capture(CreateError::Extension { .. })
            | LiveError::NotStreamable { .. }
            | LiveError::NotAPipe { .. }
            | LiveError::NoViewFile => io::ErrorKind::InvalidInput,
            LiveError::Capture(CreateError::McapToStdout | CreateError::ReadOnly(_)) => {
                io::ErrorKind::Unsupported
            }
            LiveError::Stream { source, .. }
            | LiveError::HostSide(source)
            | LiveError::Simulator(source)
            | LiveError::Io(source) => source.kind(),
            LiveError::Port(e) => e.kind(),
            LiveError::Link(LinkError::NotASymlink { .. }) => io::ErrorKind::AlreadyExists,
            LiveError::Link(LinkError::Io { source, .. }) => source.kind(),
            LiveError::PortGone { .. } => io::ErrorKind::BrokenPipe,
            LiveError::Panicked(_) => io::ErrorKind::Other,
        }
    }
}

impl From<LiveError> for io::Error {
    fn from(e: LiveError) -> io::Error {
        io::Error::new(e.kind(), e)
    }
}

impl From<nix::errno::Errno> for LiveError {
    fn from(e: nix::errno::Errno) -> LiveError {
        LiveError::Io(e.into())
    }
}
