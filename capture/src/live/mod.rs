//! Live traffic: device simulators, and taps between a host program and a device (being
//! written).

pub mod error;
pub mod probe;
pub mod pty;
pub mod serial;
pub mod session;
pub mod signals;
pub mod sim;
pub mod stop;
pub mod tap;

use nix::errno::Errno;
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use std::io;
use std::os::fd::BorrowedFd;
use std::time::Duration;

/// Wait up to `timeout` for `ev` on `fd`: whether something happened (readiness, hang-up or
/// error, which the following read or write reports).
pub(crate) fn wait_fd(fd: BorrowedFd<'_>, ev: PollFlags, timeout: Duration) -> io::Result<bool> {
    let ms = u16::try_from(timeout.as_millis()).unwrap_or(u16::MAX);
    let mut fds = [PollFd::new(fd, ev)];
    match poll(&mut fds, PollTimeout::from(ms)) {
        Ok(0) | Err(Errno::EINTR) => Ok(false),
        Ok(_) => Ok(true),
        Err(e) => Err(e.into()),
    }
}
