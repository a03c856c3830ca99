//! The one pseudo-terminal wrapper: the simulators serve on one, the tap offers one to the
//! host program; and the symlink that names it for programs.

use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
use std::fmt;
use std::io;
use std::os::fd::OwnedFd;
use std::path::{Path, PathBuf};

/// A pseudo-terminal pair in raw mode (no echo, no line editing, 8-bit clean) with a
/// non-blocking master: programs open [`path`](Self::path) as if it were a serial port.
#[derive(Debug)]
pub struct Pty {
    master: OwnedFd,
    slave: Option<OwnedFd>,
    path: PathBuf,
}

impl Pty {
    /// Open a new pair, raw, with the master non-blocking.
    pub fn open() -> io::Result<Pty> {
        let r = nix::pty::openpty(None, None)?;
        let mut t = tcgetattr(&r.slave)?;
        cfmakeraw(&mut t);
        tcsetattr(&r.slave, SetArg::TCSANOW, &t)?;
        let path = nix::unistd::ttyname(&r.slave)?;
        let fl = fcntl(&r.master, FcntlArg::F_GETFL)?;
        let fl = OFlag::from_bits_truncate(fl) | OFlag::O_NONBLOCK;
        fcntl(&r.master, FcntlArg::F_SETFL(fl))?;
        Ok(Pty {
            master: r.master,
            slave: Some(r.slave),
            path,
        })
    }

    /// The slave's path (`/dev/pts/N`).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Take the pair apart: the master (non-blocking), our copy of the slave (kept open so the
    /// line stays up, and raw, until a program opens the path) and the slave's path.
    pub fn into_parts(self) -> (OwnedFd, Option<OwnedFd>, PathBuf) {
        (self.master, self.slave, self.path)
    }
}

/// Why a symlink to a pseudo-terminal could not be made.
#[derive(Debug)]
pub enum LinkError {
    /// Something other than a symlink is at the path: it is not ours to replace.
    NotASymlink {
        /// The link's path.
        link: PathBuf,
    },
    /// Removing the old symlink or making the new one failed.
    Io {
        /// The link's path.
        link: PathBuf,
        /// What failed.
        source: io::Error,
    },
}

impl fmt::Display for LinkError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LinkError::NotASymlink { link } => {
                write!(f, "{}: exists and is not a symlink", link.display())
            }
            LinkError::Io { link, source } => write!(f, "{}: {source}", link.display()),
        }
    }
}

impl std::error::Error for LinkError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            LinkError::NotASymlink { .. } => None,
            LinkError::Io { source, .. } => Some(source),
        }
    }
}

impl From<LinkError> for io::Error {
    fn from(e: LinkError) -> io::Error {
        let kind = match &e {
            LinkError::NotASymlink { .. } => io::ErrorKind::AlreadyExists,
            LinkError::Io { source, .. } => source.kind(),
        };
        io::Error::new(kind, e)
    }
}

/// A symlink naming a pseudo-terminal (`/tmp/ttyAPT -> /dev/pts/7`), removed on drop while it
/// still points there (a program started since at the same path has replaced it otherwise).
#[derive(Debug)]
pub struct Link {
    link: PathBuf,
    target: PathBuf,
}

impl Link {
    /// Make `link` point at `target`, replacing an older symlink; anything else there is
    /// refused.
    pub fn create(link: &Path, target: &Path) -> Result<Link, LinkError> {
        let io = |source| LinkError::Io {
            link: link.to_path_buf(),
            source,
        };
        match std::fs::symlink_metadata(link) {
            Ok(m) if m.file_type().is_symlink() => std::fs::remove_file(link).map_err(io)?,
            Ok(_) => {
                return Err(LinkError::NotASymlink {
                    link: link.to_path_buf(),
                })
            }
            Err(_) => {}
        }
        std::os::unix::fs::symlink(target, link).map_err(io)?;
        Ok(Link {
            link: link.to_path_buf(),
            target: target.to_path_buf(),
        })
    }

    /// The link's path.
    pub fn path(&self) -> &Path {
        &self.link
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        if std::fs::read_link(&self.link).is_ok_and(|t| t == self.target) {
            let _ = std::fs::remove_file(&self.link);
        }
    }
}
