//! The runner serving simulators on pseudo-terminals.

use super::*;
use aptscope_dissector::apt::AptFrame;
use aptscope_dissector::Table;

// ------------------------------------------------------------------------------ pseudo-terminal

fn read_until(f: &mut std::fs::File, want: usize, timeout_ms: u16) -> Vec<u8> {
    use nix::poll::{poll, PollFd, PollFlags};
    use std::io::Read;
    use std::os::fd::AsFd;
    let mut got = vec![];
    let mut buf = [0u8; 512];
    while got.len() < want {
        let mut fds = [PollFd::new(f.as_fd(), PollFlags::POLLIN)];
        let n = poll(&mut fds, timeout_ms).expect("poll");
        assert!(n > 0, "timed out with {} of {want} bytes", got.len());
        let n = f.read(&mut buf).expect("read");
        assert!(n > 0, "hang-up");
        got.extend_from_slice(&buf[..n]);
    }
    got
}

#[test]
fn pty_round_trip_hw_req_info() {
    use std::io::Write;
    let pty = Pty::open().expect("pty");
    let path = pty.path().to_path_buf();
    let (stop, signal) = stop_pair().expect("pipe");
    let runner = std::thread::spawn(move || {
        let mut sim = AptSim::new(AptModel::Kdc101);
        serve_pty(&mut sim, pty, Some(&signal), &[])
    });
    let mut f = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&path)
        .expect("open slave");
    let frame = crate::live::session::apt_frame("HW_REQ_INFO", "", 0x50).expect("frame");
    f.write_all(&frame).expect("write");
    let got = read_until(&mut f, 90, 5000);
    assert_eq!(got.len(), 90);
    let f2 = AptFrame::decode(Table::global(), 0, &got, false).expect("frame");
    assert_eq!(f2.name(), Some("HW_GET_INFO"));
    let serial = f2.field("serial_number").and_then(|(_, v)| v.as_i64());
    assert_eq!(serial.map(|s| s / 1_000_000), Some(27));
    stop.stop();
    runner.join().expect("runner").expect("runner result");
}

#[test]
fn pty_runner_ends_when_the_peer_hangs_up() {
    use std::io::Write;
    let pty = Pty::open().expect("pty");
    let path = pty.path().to_path_buf();
    let (_stop, signal) = stop_pair().expect("pipe");
    let runner = std::thread::spawn(move || {
        let mut sim = EllSim::new(&parse_modules("0:ELL14").unwrap()).unwrap();
        serve_pty(&mut sim, pty, Some(&signal), &[])
    });
    let mut f = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&path)
        .expect("open slave");
    f.write_all(b"0gs").expect("write");
    assert_eq!(read_until(&mut f, 7, 5000), b"0GS00\r\n");
    drop(f);
    runner.join().expect("runner").expect("runner result");
}
