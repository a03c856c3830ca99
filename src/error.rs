//! The command line's errors, typed: a bad argument, a capture that cannot be opened or
//! created, a live tool's failure (each saying the path or port it concerns), or a verdict
//! (differences found, an incomplete capture). `main` prints them after `aptscope: ` and
//! picks the exit status.

use aptscope_capture::live::error::LiveError;
use aptscope_capture::live::probe::run::ProbeError;
use aptscope_capture::live::sim::SimError;
use aptscope_capture::open::{CreateError, OpenError};
use std::io;

/// What a subcommand returns.
pub(crate) type Result<T, E = CliError> = std::result::Result<T, E>;

/// Why a subcommand failed.
#[derive(Debug, thiserror::Error)]
pub(crate) enum CliError {
    /// A bad argument or combination of arguments (the message says which).
    #[error("{0}")]
    Usage(String),
    /// A capture could not be opened.
    #[error(transparent)]
    Open(#[from] OpenError),
    /// A capture could not be created.
    #[error(transparent)]
    Create(#[from] CreateError),
    /// A tap, sniff, live view or simulator failed.
    #[error(transparent)]
    Live(#[from] LiveError),
    /// A simulator's arguments name no model or bus it can be.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// A probe could not run (the port, or a device not answering APT).
    #[error(transparent)]
    Probe(#[from] ProbeError),
    /// `replay --check` found the replies differ from the captured ones.
    #[error("differences found (--check)")]
    Differences,
    /// A live capture's file does not hold every forwarded byte.
    #[error("the capture file does not hold every forwarded byte (see the counts above)")]
    CaptureIncomplete,
    /// Reading, decoding or writing failed.
    #[error("{0}")]
    Io(#[from] io::Error),
}

impl CliError {
    /// The kind of `io::Error` it is, or becomes.
    pub(crate) fn kind(&self) -> io::ErrorKind {
        match self {
            CliError::Usage(_) => io::ErrorKind::InvalidInput,
            CliError::Open(e) => match e {
                OpenError::File { source, .. } | OpenError::Read(source) => source.kind(),
                _ => io::ErrorKind::InvalidInput,
            },
            CliError::Create(e) => match e {
                CreateError::Exists { .. } => io::ErrorKind::AlreadyExists,
                CreateError::File { source, .. } | CreateError::Write(source) => source.kind(),
                CreateError::Extension { .. } => io::ErrorKind::InvalidInput,
                CreateError::McapToStdout | CreateError::ReadOnly(_) => io::ErrorKind::Unsupported,
            },
            CliError::Live(e) => e.kind(),
            CliError::Sim(_) => io::ErrorKind::InvalidInput,
            CliError::Probe(ProbeError::Port(e)) => e.kind(),
            CliError::Probe(ProbeError::Io { source, .. }) => source.kind(),
            CliError::Probe(ProbeError::NotApt { .. } | ProbeError::NotElliptec { .. }) => {
                io::ErrorKind::TimedOut
            }
            CliError::Probe(ProbeError::Interrupted { .. }) => io::ErrorKind::Interrupted,
            CliError::Differences | CliError::CaptureIncomplete => io::ErrorKind::Other,
            CliError::Io(e) => e.kind(),
        }
    }
}

impl From<CliError> for io::Error {
    fn from(e: CliError) -> io::Error {
        match e {
            CliError::Io(e) => e,
            e => io::Error::new(e.kind(), e),
        }
    }
}
