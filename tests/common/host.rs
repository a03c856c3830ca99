//! The host's side of a live test: the simulator as a controller behind a pseudo-terminal, and
//! a host program opening a port and asking it something.

use super::proc::{wait_for, Proc};
use nix::fcntl::OFlag;
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
use std::cell::RefCell;
use std::fs::File;
use std::io::{self, Read, Write};
use std::os::fd::AsFd;
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;

/// HW_REQ_INFO from the host to a controller (0x50).
pub const HW_REQ_INFO: [u8; 6] = [0x05, 0x00, 0x00, 0x00, 0x50, 0x01];
/// The header of the simulated KDC101's HW_GET_INFO reply (84 data bytes, 0x81 → host).
pub const HW_GET_INFO_HDR: [u8; 6] = [0x06, 0x00, 0x54, 0x00, 0x81, 0x50];
/// The length of that reply.
pub const HW_GET_INFO_LEN: usize = 90;

/// `aptscope sim …` with `--pty LINK`, once its link is there (it says so on standard output
/// when it is).
pub fn start_sim_with(args: &[&str], link: &Path) -> Proc {
    let mut args = args.to_vec();
    args.extend(["--pty", link.to_str().expect("utf-8 path")]);
    let p = Proc::aptscope(&args);
    let said = format!("{} -> /dev/", link.display());
    wait_for(
        "the simulator's link",
        || p.both(),
        || p.stdout().contains(&said),
    );
    assert!(std::fs::read_link(link).is_ok(), "{}", p.both());
    p
}

/// `aptscope sim apt --model kdc101 --pty LINK`, once its link is there.
pub fn start_sim(link: &Path) -> Proc {
    start_sim_with(&["sim", "apt", "--model", "kdc101"], link)
}

/// The host's serial port: a link opened like a program would (no controlling terminal, raw
/// mode), non-blocking and waited on with [`ready`].
pub fn open_host(path: &Path) -> File {
    let f = File::options()
        .read(true)
        .write(true)
        .custom_flags((OFlag::O_NOCTTY | OFlag::O_NONBLOCK).bits())
        .open(path)
        .unwrap_or_else(|e| panic!("open {}: {e}", path.display()));
    let mut t = tcgetattr(&f).expect("tcgetattr");
    cfmakeraw(&mut t);
    tcsetattr(&f, SetArg::TCSANOW, &t).expect("tcsetattr");
    f
}

/// Whether `f` is ready for `ev` within 100 ms.
pub fn ready(f: &impl AsFd, ev: PollFlags) -> bool {
    let mut fds = [PollFd::new(f.as_fd(), ev)];
    matches!(poll(&mut fds, PollTimeout::from(100u16)), Ok(n) if n > 0)
}

/// One host session on `link` (waited for, as a tap or extcap makes it when it is up):
/// HW_REQ_INFO, and the whole 90-byte HW_GET_INFO it gets back. `ctx` says what was running
/// when it fails.
pub fn ask_info(link: &Path, ctx: impl Fn() -> String) -> Vec<u8> {
    wait_for("the host link", &ctx, || std::fs::read_link(link).is_ok());
    let mut host = open_host(link);
    host.write_all(&HW_REQ_INFO).expect("host write");
    let got = RefCell::new(vec![]);
    let mut buf = [0u8; 256];
    wait_for(
        "HW_GET_INFO at the host",
        || format!("host got {:02x?}\n{}", got.borrow(), ctx()),
        || {
            if ready(&host, PollFlags::POLLIN) {
                match host.read(&mut buf) {
                    Ok(n) => got.borrow_mut().extend_from_slice(&buf[..n]),
                    Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                    Err(e) => panic!("host read: {e}"),
                }
            }
            got.borrow().len() >= HW_GET_INFO_LEN
        },
    );
    let got = got.into_inner();
    assert_eq!(got[..6], HW_GET_INFO_HDR, "{got:02x?}");
    assert_eq!(got.len(), HW_GET_INFO_LEN, "exactly one reply: {got:02x?}");
    got
}

/// `tap --device DIR/dev --link DIR/host -w DIR/cap.pcapng EXTRA…`: the tap between the
/// simulator and the host in the tests' scratch directory.
pub fn tap_args(dir: &Path, extra: &[&str]) -> Vec<String> {
    let p = |f: &str| dir.join(f).to_str().expect("utf-8 path").to_string();
    let mut a: Vec<String> = vec!["tap".into(), "--device".into(), p("dev"), "--link".into()];
    a.extend([p("host"), "-w".into(), p("cap.pcapng")]);
    a.extend(extra.iter().map(|s| s.to_string()));
    a
}

/// `aptscope tap … --quiet EXTRA…` (see [`tap_args`]), once its link is there.
pub fn start_tap(dir: &Path, extra: &[&str]) -> Proc {
    let p = Proc::aptscope(&tap_args(dir, &[&["--quiet"], extra].concat()));
    p.wait_stderr("aptscope tap: host side");
    assert!(std::fs::read_link(dir.join("host")).is_ok(), "{}", p.both());
    p
}
