//! The tap's sides: the real serial ports and the pseudo-terminal the host program opens, each
//! read and written in ticks so that a stop is seen within [`TICK`].

use super::TICK;
use crate::live::error::LiveError;
use crate::live::pty::{Link, Pty};
use crate::live::serial::{self, LineSettings, SerialFd};
use crate::live::wait_fd;
use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::poll::PollFlags;
use std::fs::File;
use std::io::{self, Read, Write};
use std::os::fd::{AsFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// One handle on a side, used by one thread in one direction.
pub(super) trait Port: Send {
    /// Read what arrives within [`TICK`]: `Ok(0)` when nothing did; an error when the side is
    /// gone (end of file is `UnexpectedEof`).
    fn read_tick(&mut self, buf: &mut [u8]) -> io::Result<usize>;
    /// Write what the side accepts within [`TICK`]: `Ok(0)` when it accepted nothing.
    fn write_tick(&mut self, buf: &[u8]) -> io::Result<usize>;
}

fn eof() -> io::Error {
    io::Error::new(io::ErrorKind::UnexpectedEof, "end of file (hung up)")
}

fn transient(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted | io::ErrorKind::TimedOut
    )
}

/// A non-blocking file descriptor (the pty master; any fd in tests), waited on with poll.
pub(super) struct FdPort(File);

impl FdPort {
    pub(super) fn new(fd: OwnedFd) -> io::Result<Self> {
        let fl = fcntl(&fd, FcntlArg::F_GETFL)?;
        fcntl(
            &fd,
            FcntlArg::F_SETFL(OFlag::from_bits_truncate(fl) | OFlag::O_NONBLOCK),
        )?;
        Ok(FdPort(File::from(fd)))
    }
    pub(super) fn try_clone(&self) -> io::Result<Self> {
        Ok(FdPort(self.0.try_clone()?))
    }
}

impl Port for FdPort {
    fn read_tick(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if !wait_fd(self.0.as_fd(), PollFlags::POLLIN, TICK)? {
            return Ok(0);
        }
        match self.0.read(buf) {
            Ok(0) => Err(eof()),
            Ok(n) => Ok(n),
            Err(e) if transient(&e) => Ok(0),
            Err(e) => Err(e),
        }
    }
    fn write_tick(&mut self, buf: &[u8]) -> io::Result<usize> {
        if !wait_fd(self.0.as_fd(), PollFlags::POLLOUT, TICK)? {
            return Ok(0);
        }
        match self.0.write(buf) {
            Ok(n) => Ok(n),
            Err(e) if transient(&e) => Ok(0),
            Err(e) => Err(e),
        }
    }
}

/// A real serial port: our polled descriptor (see [`crate::live::serial`]), and the configured
/// port it belongs to, kept open as long as either handle is.
pub(super) struct SerialPort {
    fd: FdPort,
    hold: Arc<Mutex<SerialFd>>,
}

impl Port for SerialPort {
    fn read_tick(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        self.fd.read_tick(buf)
    }
    fn write_tick(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.fd.write_tick(buf)
    }
}

/// The device side: a read handle and a write handle.
pub(super) type DevicePair = (Box<dyn Port>, Box<dyn Port>);

/// Open a serial port (exclusively) with `settings`.
pub(super) fn open_serial(path: &str, settings: &LineSettings) -> Result<SerialPort, LiveError> {
    let s = serial::open_serial(path, settings)?;
    Ok(SerialPort {
        fd: FdPort::new(OwnedFd::from(s.file.try_clone()?))?,
        hold: Arc::new(Mutex::new(s)),
    })
}

pub(super) fn open_device(path: &str, settings: &LineSettings) -> Result<DevicePair, LiveError> {
    let r = open_serial(path, settings)?;
    let w = SerialPort {
        fd: r.fd.try_clone()?,
        hold: r.hold.clone(),
    };
    Ok((Box::new(r), Box::new(w)))
}

/// The host side: a raw-mode pseudo-terminal whose slave the host program opens.
pub(super) struct HostPty {
    /// Declared first: the link goes before the terminal it names.
    pub(super) link: Option<Link>,
    pub(super) master: FdPort,
    /// Held open so the master never sees a hang-up when the host program closes and reopens
    /// the slave, and so the raw settings stay.
    _slave: Option<OwnedFd>,
    pub(super) slave_path: PathBuf,
}

impl HostPty {
    pub(super) fn create(link: Option<&str>) -> Result<HostPty, LiveError> {
        let (master, slave, slave_path) = Pty::open()?.into_parts();
        let link = match link {
            Some(l) => Some(Link::create(Path::new(l), &slave_path)?),
            None => None,
        };
        Ok(HostPty {
            link,
            master: FdPort::new(master)?,
            _slave: slave,
            slave_path,
        })
    }

    /// Where host programs connect: the link, else the pseudo-terminal.
    pub(super) fn path(&self) -> &Path {
        self.link.as_ref().map_or(&self.slave_path, |l| l.path())
    }
}
