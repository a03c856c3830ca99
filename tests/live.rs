//! End-to-end tests of the live tools through the real binary and real pseudo-terminals:
//! a host (this test) ⇄ `aptscope tap` ⇄ `aptscope sim`, each a process of its own, stopped
//! with real signals. Every wait is a poll against a generous deadline that only a broken
//! build reaches.

mod common;

use aptscope_capture::open::{open, Format, OpenOptions};
use aptscope_capture::{Direction, Event};
use common::clients::client_python;
use common::host::{
    ask_info, open_host, ready, start_sim, start_sim_with, start_tap, tap_args, HW_GET_INFO_LEN,
};
use common::proc::{lock, wait_for, Proc, DEADLINE, POLL};
use common::term::Term;
use common::{apt_frames as frames, scratch};
use nix::fcntl::OFlag;
use nix::poll::PollFlags;
use nix::sys::signal::{kill, Signal};
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, ControlFlags, SetArg};
use nix::unistd::Pid;
use std::cell::RefCell;
use std::fs::File;
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

// ---------------------------------------------------------------------------------------------
// The host program

/// Write `bytes` to the host's port as fast as it takes them; returns how many were written
/// before the other side went away (all of them normally).
fn write_polled(f: &mut File, bytes: &[u8]) -> usize {
    let t0 = Instant::now();
    let mut done = 0;
    while done < bytes.len() {
        assert!(t0.elapsed() < DEADLINE, "host write timed out at {done}");
        if !ready(f, PollFlags::POLLOUT) {
            continue;
        }
        match f.write(&bytes[done..]) {
            Ok(n) => done += n,
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(_) => break,
        }
    }
    done
}

/// [`write_polled`] in a thread of its own.
fn send(mut f: File, bytes: Vec<u8>) -> JoinHandle<usize> {
    thread::spawn(move || write_polled(&mut f, &bytes))
}

/// Everything the host receives, read as it comes until `stop` or the other side goes away.
struct Receiver {
    got: Arc<Mutex<Vec<u8>>>,
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
}

impl Receiver {
    fn start(mut f: File) -> Receiver {
        let got = Arc::new(Mutex::new(vec![]));
        let stop = Arc::new(AtomicBool::new(false));
        let (g, s) = (got.clone(), stop.clone());
        let handle = thread::spawn(move || {
            let mut buf = vec![0u8; 8192];
            while !s.load(Ordering::SeqCst) {
                if !ready(&f, PollFlags::POLLIN) {
                    continue;
                }
                match f.read(&mut buf) {
                    Ok(0) => break,
                    Ok(n) => lock(&g).extend_from_slice(&buf[..n]),
                    Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                    Err(_) => break, // EIO: the tap is gone
                }
            }
        });
        Receiver {
            got,
            stop,
            handle: Some(handle),
        }
    }

    fn got(&self) -> Vec<u8> {
        lock(&self.got).clone()
    }

    fn len(&self) -> usize {
        lock(&self.got).len()
    }

    fn finish(mut self) -> Vec<u8> {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(h) = self.handle.take() {
            h.join().unwrap();
        }
        self.got()
    }
}

impl Drop for Receiver {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
    }
}

// ---------------------------------------------------------------------------------------------
// Traffic

const HW_REQ_INFO: u16 = 0x0005;
const MOD_IDENTIFY: u16 = 0x0223;
const MOT_SET_VELPARAMS: u16 = 0x0413;
const MOT_REQ_VELPARAMS: u16 = 0x0414;
const MOT_REQ_DCSTATUSUPDATE: u16 = 0x0490;
const MOT_REQ_STATUSBITS: u16 = 0x0429;
const MOT_REQ_POSCOUNTER: u16 = 0x0411;

/// A header-only request to the controller (0x50) from the host, channel 1.
fn req(id: u16) -> [u8; 6] {
    let [a, b] = id.to_le_bytes();
    [a, b, 0x01, 0x00, 0x50, 0x01]
}

/// The id of the reply the simulator sends to a request.
fn reply_id(id: u16) -> u16 {
    match id {
        HW_REQ_INFO => 0x0006,
        MOT_REQ_VELPARAMS => 0x0415,
        MOT_REQ_DCSTATUSUPDATE => 0x0491,
        MOT_REQ_STATUSBITS => 0x042A,
        MOT_REQ_POSCOUNTER => 0x0412,
        _ => unreachable!(),
    }
}

/// About `target` bytes of back-to-back valid frames: groups of MOT_SET_VELPARAMS (no reply,
/// remembered), a MOD_IDENTIFY (no reply) and the requests `reqs` (each answered); returns the
/// bytes and the reply ids expected, in order, with the acceleration each MOT_GET_VELPARAMS
/// must carry (the last one set before it).
fn traffic(target: usize, reqs: &[u16]) -> (Vec<u8>, Vec<(u16, Option<i32>)>) {
    let mut v = Vec::with_capacity(target + 8192);
    let mut replies = vec![];
    let mut acc = 0i32;
    while v.len() < target {
        for _ in 0..250 {
            acc = acc.wrapping_add(7919) & 0x3fff_ffff;
            let [a, b] = MOT_SET_VELPARAMS.to_le_bytes();
            v.extend_from_slice(&[a, b, 14, 0, 0xd0, 0x01, 1, 0]);
            v.extend_from_slice(&0i32.to_le_bytes());
            v.extend_from_slice(&acc.to_le_bytes());
            v.extend_from_slice(&(acc / 3).to_le_bytes());
        }
        v.extend_from_slice(&req(MOD_IDENTIFY));
        for &r in reqs {
            v.extend_from_slice(&req(r));
            replies.push((reply_id(r), (r == MOT_REQ_VELPARAMS).then_some(acc)));
        }
    }
    (v, replies)
}

fn msg_id(f: &[u8]) -> u16 {
    u16::from_le_bytes([f[0], f[1]])
}

/// Occurrences of `pat` in `hay`.
fn count(hay: &[u8], pat: &[u8]) -> usize {
    hay.windows(pat.len()).filter(|w| *w == pat).count()
}

/// Requests of every kind the simulator answers (~150 bytes of replies per group: a
/// megabyte's worth takes the simulated 115200-baud line about 3 s to answer).
const ALL_REQS: [u16; 5] = [
    HW_REQ_INFO,
    MOT_REQ_VELPARAMS,
    MOT_REQ_DCSTATUSUPDATE,
    MOT_REQ_STATUSBITS,
    MOT_REQ_POSCOUNTER,
];

/// The header of MOT_GET_POSCOUNTER from the controller to the host.
const GET_POSCOUNTER_HDR: [u8; 6] = [0x12, 0x04, 0x06, 0x00, 0x81, 0x50];

// ---------------------------------------------------------------------------------------------
// The capture

/// A capture read back: bytes per direction (in order) and the reader's diagnostics.
struct Capture {
    h2d: Vec<u8>,
    d2h: Vec<u8>,
    chunks: usize,
    diags: Vec<(&'static str, String)>,
}

fn read_capture(path: &Path) -> Capture {
    let (mut r, f) = open(path.to_str().unwrap(), OpenOptions::default()).unwrap();
    assert_eq!(f, Format::PcapNg);
    let mut c = Capture {
        h2d: vec![],
        d2h: vec![],
        chunks: 0,
        diags: vec![],
    };
    let mut last_ts = 0;
    while let Some(e) = r.next_event() {
        match e {
            Event::Stream(_) => {}
            Event::Chunk(ch) => {
                let ts = ch.ts_ns.expect("every chunk has a time");
                assert!(ts >= last_ts, "chunks out of time order");
                last_ts = ts;
                c.chunks += 1;
                match ch.dir {
                    Direction::HostToDevice => c.h2d.extend_from_slice(ch.bytes),
                    Direction::DeviceToHost => c.d2h.extend_from_slice(ch.bytes),
                    Direction::Unknown => panic!("a chunk without direction"),
                }
            }
            Event::Diag(d) => c.diags.push((d.kind(), d.to_string())),
        }
    }
    c
}

/// `aptscope decode --json FILE`: exits cleanly; returns the records.
fn decode_json(path: &Path) -> Vec<serde_json::Value> {
    let o = Command::new(env!("CARGO_BIN_EXE_aptscope"))
        .args(["decode", "--json", path.to_str().unwrap()])
        .output()
        .expect("run aptscope decode");
    assert!(
        o.status.success(),
        "decode failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
        .collect()
}

/// Whether `long` starts with `short` (asserted with [`first_difference`] rather than two
/// megabyte dumps).
fn is_prefix(short: &[u8], long: &[u8]) -> bool {
    short.len() <= long.len() && long[..short.len()] == *short
}

fn first_difference(a: &[u8], b: &[u8]) -> String {
    let i = a.iter().zip(b).take_while(|(x, y)| x == y).count();
    format!(
        "lengths {} and {}, first difference at {i}",
        a.len(),
        b.len()
    )
}

/// A megabyte of [`traffic`] with every request kind under way: simulator ⇄ tap ⇄ host, the
/// host writing in a thread of its own.
struct Burst {
    dir: PathBuf,
    sim: Proc,
    tap: Proc,
    /// What the host receives.
    rx: Receiver,
    /// What the host sends.
    sent: Vec<u8>,
    /// The replies expected (see [`traffic`]).
    expected: Vec<(u16, Option<i32>)>,
    /// The host's writer: how much it wrote.
    writer: JoinHandle<usize>,
}

impl Burst {
    fn start(name: &str) -> Burst {
        let dir = scratch(name);
        let sim = start_sim(&dir.join("dev"));
        let tap = start_tap(&dir, &[]);
        let host = open_host(&dir.join("host"));
        let rx = Receiver::start(host.try_clone().expect("dup"));
        let (sent, expected) = traffic(1 << 20, &ALL_REQS);
        let writer = send(host, sent.clone());
        Burst {
            dir,
            sim,
            tap,
            rx,
            sent,
            expected,
            writer,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Tests

#[test]
fn a_megabyte_burst_through_the_tap_is_recorded_exactly_and_ctrl_c_leaves_a_valid_file() {
    let mut b = Burst::start("burst");
    // Every request answered (the simulator paces its replies at 115200 baud: ~3 s).
    wait_for(
        "every reply",
        || format!("{} bytes received\n{}", b.rx.len(), b.tap.stderr()),
        || frames(&b.rx.got()).len() >= b.expected.len(),
    );
    assert_eq!(b.writer.join().unwrap(), b.sent.len());

    b.tap.signal(Signal::SIGINT);
    let status = b.tap.wait_exit();
    let err = b.tap.stderr();
    assert!(status.success(), "tap: {status}\n{err}");
    let got = b.rx.finish();

    // The host got exactly the replies, in order, and each velocity reply carries the
    // parameters set just before its request.
    let fs = frames(&got);
    assert_eq!(fs.concat().len(), got.len(), "a partial frame at the end");
    assert_eq!(fs.len(), b.expected.len());
    for (i, (f, (id, acc))) in fs.iter().zip(&b.expected).enumerate() {
        assert_eq!(msg_id(f), *id, "reply {i}");
        if let Some(acc) = acc {
            assert_eq!(f[12..16], acc.to_le_bytes(), "reply {i}: acceleration");
        }
    }

    // The tap counted what crossed and checked it against its file.
    assert!(err.contains("SIGINT: stopping"), "{err}");
    let counts = format!(
        "host → device {} bytes, device → host {} bytes",
        b.sent.len(),
        got.len()
    );
    assert!(err.contains(&format!("aptscope tap: {counts}")), "{err}");
    assert!(
        err.contains(&format!("aptscope tap: file: {counts}")),
        "{err}"
    );
    assert!(err.contains("matches what was forwarded"), "{err}");
    assert!(!err.contains("gone at"), "{err}");

    // The file holds exactly those bytes, in order, with their direction.
    let cap = read_capture(&b.dir.join("cap.pcapng"));
    assert!(cap.diags.is_empty(), "{:?}", cap.diags);
    assert!(
        cap.h2d == b.sent,
        "h2d: {}",
        first_difference(&cap.h2d, &b.sent)
    );
    assert!(cap.d2h == got, "d2h: {}", first_difference(&cap.d2h, &got));

    // And the decoder agrees: every frame whole, in the right direction, no framing problem.
    // (Pairing may flag replies: a burst leaves ~1000 requests waiting at once, and the last
    // replies come more than the 2 s request timeout after their requests.)
    let recs = decode_json(&b.dir.join("cap.pcapng"));
    let frames_of = |way: &str| {
        recs.iter()
            .filter(|r| r["type"] == "frame" && r["dir"] == way)
            .count()
    };
    assert_eq!(frames_of("h2d"), frames(&b.sent).len());
    assert_eq!(frames_of("d2h"), b.expected.len());
    let pairing = ["duplicate_reply", "unsolicited", "no_reply"];
    let flagged: Vec<_> = recs
        .iter()
        .filter(|r| {
            r["type"] == "garbage"
                || r["diag"]
                    .as_array()
                    .is_some_and(|d| d.iter().any(|k| !pairing.iter().any(|p| k["kind"] == *p)))
        })
        .take(5)
        .collect();
    assert!(flagged.is_empty(), "{flagged:?}");

    // The simulator stays up when the tap hangs up (a controller does not vanish with its
    // host); SIGINT ends it, and it removes its link.
    assert!(b.sim.running(), "{}", b.sim.both());
    b.sim.interrupt();
    assert!(std::fs::symlink_metadata(b.dir.join("dev")).is_err());
    // So does the tap's link.
    assert!(std::fs::symlink_metadata(b.dir.join("host")).is_err());
    let _ = std::fs::remove_dir_all(&b.dir);
}

#[test]
fn kill_9_of_the_tap_leaves_a_readable_prefix() {
    let mut b = Burst::start("kill9");

    // Mid-stream: replies still coming, and some of the file flushed.
    let cap_path = b.dir.join("cap.pcapng");
    wait_for(
        "replies and a flushed file",
        || b.tap.stderr(),
        || {
            frames(&b.rx.got()).len() >= 10
                && std::fs::metadata(&cap_path).is_ok_and(|m| m.len() > 100_000)
        },
    );
    b.tap.signal(Signal::SIGKILL);
    let st = b.tap.wait_exit();
    assert!(!st.success());
    let _ = b.writer.join().unwrap();
    let got = b.rx.finish();
    assert!(
        frames(&got).len() < b.expected.len(),
        "killed after the stream ended"
    );

    // Readable up to its last complete block: at worst a truncated tail.
    let cap = read_capture(&cap_path);
    for (kind, d) in &cap.diags {
        assert_eq!(*kind, "truncated_record", "{d}");
    }
    assert!(cap.diags.len() <= 1, "{:?}", cap.diags);
    assert!(cap.chunks > 0 && !cap.h2d.is_empty());
    assert!(
        is_prefix(&cap.h2d, &b.sent),
        "h2d: {}",
        first_difference(&cap.h2d, &b.sent)
    );
    // What the file says the host got and what it did get agree (either may be ahead: the
    // file lags by up to a second, and a hang-up may flush what the host had not read yet).
    let n = cap.d2h.len().min(got.len());
    assert!(
        cap.d2h[..n] == got[..n],
        "d2h: {}",
        first_difference(&cap.d2h, &got)
    );
    assert!(decode_json(&cap_path).iter().any(|r| r["type"] == "frame"));

    // The simulator outlives the host's session; SIGINT ends it.
    b.sim.interrupt();
    let _ = std::fs::remove_dir_all(&b.dir);
}

#[test]
fn the_device_vanishing_mid_stream_is_reported_with_its_time_and_ends_the_tap() {
    let mut b = Burst::start("devgone");
    wait_for(
        "some replies",
        || b.tap.stderr(),
        || frames(&b.rx.got()).len() >= 10,
    );

    // The cable is pulled.
    b.sim.signal(Signal::SIGKILL);
    b.sim.wait_exit();
    let t0 = Instant::now();
    let status = b.tap.wait_exit();
    let err = b.tap.stderr();
    assert!(status.success(), "tap: {status}\n{err}");
    assert!(t0.elapsed() < Duration::from_secs(30), "slow to notice");
    let dev = b.dir.join("dev");
    let gone = format!("aptscope: {} gone at ", dev.display());
    let line = err
        .lines()
        .find(|l| l.starts_with(&gone))
        .unwrap_or_else(|| panic!("no `gone` report:\n{err}"));
    // `gone at HH:MM:SS.mmm UTC (+S.sss s): error`
    let time = &line[gone.len()..];
    assert!(
        time.len() > 16 && time.as_bytes()[2] == b':' && time[12..].starts_with(" UTC"),
        "{line}"
    );
    assert!(err.contains("matches what was forwarded"), "{err}");
    let _ = b.writer.join().unwrap();
    let got = b.rx.finish();
    assert!(
        frames(&got).len() < b.expected.len(),
        "the sim was killed too late"
    );

    let cap = read_capture(&b.dir.join("cap.pcapng"));
    assert!(cap.diags.is_empty(), "{:?}", cap.diags);
    assert!(
        is_prefix(&cap.h2d, &b.sent),
        "{}",
        first_difference(&cap.h2d, &b.sent)
    );
    assert!(
        is_prefix(&got, &cap.d2h),
        "{}",
        first_difference(&got, &cap.d2h)
    );
    assert!(std::fs::symlink_metadata(b.dir.join("host")).is_err());
    let _ = std::fs::remove_dir_all(&b.dir);
}

#[test]
fn with_reconnect_traffic_continues_in_the_same_file_after_the_device_comes_back() {
    let dir = scratch("reconnect");
    let dev = dir.join("dev");
    let mut sim = start_sim(&dev);
    let mut tap = start_tap(&dir, &["--reconnect"]);
    let host = open_host(&dir.join("host"));
    let rx = Receiver::start(host.try_clone().unwrap());

    // Before: requests the second simulator never sees.
    let (a, _) = traffic(200_000, &[HW_REQ_INFO, MOT_REQ_STATUSBITS]);
    assert_eq!(
        send(host.try_clone().unwrap(), a.clone()).join().unwrap(),
        a.len()
    );
    wait_for(
        "some replies",
        || tap.stderr(),
        || frames(&rx.got()).len() >= 4,
    );
    sim.signal(Signal::SIGKILL);
    sim.wait_exit();
    tap.wait_stderr(&format!("{} gone at", dev.display()));
    tap.wait_stderr("waiting for");
    let before = rx.len();

    // The device comes back under the same name.
    let mut sim2 = start_sim(&dev);
    tap.wait_stderr("back at");
    let (b, b_replies) = traffic(100_000, &[MOT_REQ_POSCOUNTER]);
    assert_eq!(send(host, b.clone()).join().unwrap(), b.len());
    wait_for(
        "the replies after the reconnection",
        || tap.stderr(),
        || count(&rx.got()[before..], &GET_POSCOUNTER_HDR) >= b_replies.len(),
    );

    tap.signal(Signal::SIGTERM);
    let status = tap.wait_exit();
    let err = tap.stderr();
    assert!(status.success(), "tap: {status}\n{err}");
    assert!(err.contains("SIGTERM: stopping"), "{err}");
    assert!(err.contains("matches what was forwarded"), "{err}");
    assert_eq!(err.matches(" gone at ").count(), 2, "{err}"); // the report and the summary
    let got = rx.finish();

    let cap = read_capture(&dir.join("cap.pcapng"));
    assert!(cap.diags.is_empty(), "{:?}", cap.diags);
    // h2d: what reached the first device (a prefix of A), then all of B.
    assert!(cap.h2d.ends_with(&b), "h2d lacks the second part");
    let first = &cap.h2d[..cap.h2d.len() - b.len()];
    assert!(!first.is_empty() && is_prefix(first, &a));
    assert!(cap.d2h == got, "d2h: {}", first_difference(&cap.d2h, &got));
    assert_eq!(count(&got, &GET_POSCOUNTER_HDR), b_replies.len());

    sim2.interrupt();
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_simulator_exits_cleanly_on_sigint_and_sigterm_and_removes_its_link() {
    let dir = scratch("sim-signals");
    for sig in [Signal::SIGINT, Signal::SIGTERM] {
        let link = dir.join("dev");
        let mut sim = start_sim(&link);
        let target = std::fs::read_link(&link).unwrap();
        assert!(target.starts_with("/dev/pts"), "{}", target.display());
        sim.signal(sig);
        let st = sim.wait_exit();
        assert!(st.success(), "{sig}: {st}\n{}", sim.stderr());
        assert!(
            std::fs::symlink_metadata(&link).is_err(),
            "{sig}: link left"
        );
    }
    // Elliptec too.
    let link = dir.join("ell");
    let mut sim = start_sim_with(&["sim", "elliptec", "--modules", "0:ELL14,1:ELL9"], &link);
    sim.interrupt();
    assert!(std::fs::symlink_metadata(&link).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_simulator_leaves_a_link_it_no_longer_owns() {
    // A restarted simulator took over the link: the old one ending must not remove it.
    let dir = scratch("sim-link");
    let link = dir.join("dev");
    let mut old = start_sim(&link);
    let mut new = start_sim(&link);
    let target = std::fs::read_link(&link).unwrap();
    old.interrupt();
    assert_eq!(std::fs::read_link(&link).ok(), Some(target));
    new.interrupt();
    assert!(std::fs::symlink_metadata(&link).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `sim apt --port DEV` serves a serial port (here a pseudo-terminal's slave, the test holding
/// the far end of the "cable") and ends cleanly on SIGINT, even while it waits on the port.
#[test]
fn a_simulator_on_a_serial_port_answers_and_ends_cleanly_on_sigint() {
    let pty = nix::pty::openpty(None, None).expect("openpty");
    let mut t = tcgetattr(&pty.slave).expect("tcgetattr");
    cfmakeraw(&mut t);
    tcsetattr(&pty.slave, SetArg::TCSANOW, &t).expect("tcsetattr");
    let path = nix::unistd::ttyname(&pty.slave).expect("ttyname");
    let fl = nix::fcntl::fcntl(&pty.master, nix::fcntl::FcntlArg::F_GETFL).expect("flags");
    nix::fcntl::fcntl(
        &pty.master,
        nix::fcntl::FcntlArg::F_SETFL(OFlag::from_bits_truncate(fl) | OFlag::O_NONBLOCK),
    )
    .expect("non-blocking");
    let port = path.to_str().expect("utf-8 path");
    let mut sim = Proc::aptscope(&["sim", "apt", "--model", "kdc101", "--port", port]);
    let master = File::from(pty.master);
    // Ask until the simulator has the port open and answers.
    let mut got = vec![];
    let mut asked: Option<Instant> = None;
    wait_for(
        "HW_GET_INFO from the simulator on the port",
        || sim.stderr(),
        || {
            if got.is_empty() && asked.is_none_or(|t| t.elapsed() > Duration::from_millis(300)) {
                let _ = (&master).write_all(&req(HW_REQ_INFO));
                asked = Some(Instant::now());
            }
            let mut buf = [0u8; 256];
            if ready(&master, PollFlags::POLLIN) {
                if let Ok(n) = (&master).read(&mut buf) {
                    got.extend_from_slice(&buf[..n]);
                }
            }
            got.len() >= HW_GET_INFO_LEN
        },
    );
    assert_eq!(&got[..2], &[0x06, 0x00], "{got:02x?}");
    assert_eq!(&got[10..16], b"KDC101");
    sim.interrupt();
    drop(pty.slave);
}

/// A sniff's adapters only receive, so they are opened without flow control (RTS/CTS is APT's
/// default for the tap, not for the sniff): the ports, the banner and the capture's stream
/// agree on it, and `--flow rtscts` sets it on all three.
#[test]
fn the_sniff_opens_its_adapters_without_flow_control_unless_told_and_says_which() {
    for (flow, settings) in [(None, "115200 8N1"), (Some("rtscts"), "115200 8N1 RTS/CTS")] {
        let dir = scratch("sniff-flow");
        let ptys = [(); 2].map(|_| nix::pty::openpty(None, None).expect("openpty"));
        let [host_tx, device_tx] = ptys.each_ref().map(|p| {
            let path = nix::unistd::ttyname(&p.slave).expect("ttyname");
            path.to_str().expect("utf-8 path").to_string()
        });
        let cap = dir.join("y.pcapng");
        let mut args = vec!["sniff", "--host-tx", &host_tx, "--device-tx", &device_tx];
        args.extend(["--quiet", "-w", cap.to_str().expect("utf-8 path")]);
        args.extend(flow.map(|f| ["--flow", f]).into_iter().flatten());
        let mut sniff = Proc::aptscope(&args);
        sniff.wait_stderr(&format!("({settings}), writing"));
        // The banner comes once both ports are open; a pty master reads its slave's settings.
        for p in &ptys {
            let t = tcgetattr(&p.master).expect("tcgetattr");
            let rtscts = t.control_flags.contains(ControlFlags::CRTSCTS);
            assert_eq!(rtscts, flow.is_some(), "{}", sniff.both());
        }
        sniff.interrupt();
        let stream = decode_json(&cap)
            .into_iter()
            .find(|r| r["type"] == "stream")
            .expect("a stream record");
        let want = format!("{settings} (receive-only Y-cable)");
        assert_eq!(stream["settings"], want.as_str(), "{stream}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// A real controller does not vanish when the host program closes the port: the simulator
/// serves three programs in a row, each getting its own answer (none of the last one's
/// leftovers), and `--once` keeps the old behaviour of ending with the first.
#[test]
fn a_simulator_serves_one_host_session_after_another() {
    let dir = scratch("sim-sessions");
    let link = dir.join("dev");
    let mut sim = start_sim(&link);
    for session in 0..3 {
        ask_info(&link, || format!("session {session}\n{}", sim.both()));
        assert!(
            sim.running(),
            "session {session}: the simulator ended\n{}",
            sim.both()
        );
    }
    sim.interrupt();

    let once = dir.join("once");
    let mut sim = start_sim_with(&["sim", "apt", "--once"], &once);
    ask_info(&once, || sim.both());
    assert!(
        sim.wait_exit().success(),
        "--once ends with the host\n{}",
        sim.stderr()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `aptscope tap … 2>&1 | tee tap.log`, and `tee` goes away: standard output and error are now
/// broken pipes. SIGINT, SIGTERM and SIGHUP still stop the tap cleanly (nothing between the
/// signal and the stop may depend on printing) and the capture holds what crossed.
#[test]
fn the_tap_stops_on_signals_when_its_output_pipes_are_gone() {
    for sig in [Signal::SIGINT, Signal::SIGTERM, Signal::SIGHUP] {
        let dir = scratch("broken-pipes");
        let _sim = start_sim(&dir.join("dev"));
        let (host, cap) = (dir.join("host"), dir.join("cap.pcapng"));
        let mut child = Command::new(env!("CARGO_BIN_EXE_aptscope"))
            .args(tap_args(&dir, &[]))
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("run aptscope");
        let mut err = child.stderr.take().expect("stderr");
        // Up once its host side is there; then the reader of both pipes goes away.
        let mut seen = String::new();
        let mut buf = [0u8; 1024];
        let t0 = Instant::now();
        while !seen.contains("aptscope tap: host side") {
            assert!(t0.elapsed() < DEADLINE, "{sig}: no start: {seen}");
            match err.read(&mut buf) {
                Ok(0) | Err(_) => panic!("{sig}: stderr closed: {seen}"),
                Ok(n) => seen.push_str(&String::from_utf8_lossy(&buf[..n])),
            }
        }
        let h = open_host(&host);
        let rx = Receiver::start(h.try_clone().unwrap());
        assert_eq!(send(h, req(HW_REQ_INFO).to_vec()).join().unwrap(), 6);
        wait_for(
            "HW_GET_INFO",
            || format!("{:02x?}", rx.got()),
            || rx.len() >= HW_GET_INFO_LEN,
        );
        drop(err);
        drop(child.stdout.take());
        kill(Pid::from_raw(child.id() as i32), sig).expect("signal");
        let t0 = Instant::now();
        let status = loop {
            if let Some(s) = child.try_wait().expect("try_wait") {
                break s;
            }
            if t0.elapsed() > DEADLINE {
                let _ = child.kill();
                panic!("{sig}: the tap did not stop with its output pipes gone");
            }
            thread::sleep(POLL);
        };
        assert!(
            status.code().is_some(),
            "{sig}: killed by a signal: {status}"
        );
        drop(rx.finish());
        let c = read_capture(&cap);
        assert_eq!(c.h2d, req(HW_REQ_INFO), "{sig}");
        assert_eq!(c.d2h.len(), HW_GET_INFO_LEN, "{sig}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}

// ---------------------------------------------------------------------------------------------
// The live view, in a terminal (tmux)

/// The record count the view's title bar shows (`… · 4 records`).
fn shown_records(screen: &str) -> Option<u64> {
    let first = screen.lines().next()?;
    let at = first.find(" records")?;
    first[..at].rsplit(' ').next()?.parse().ok()
}

/// `aptscope SIM… --pty LINK --view -w CAP` in a terminal, once its link and view are up.
fn sim_view(dir: &Path, sim: &[&str], link: &Path, cap: &Path) -> Option<Term> {
    let path = |p: &Path| p.to_str().expect("utf-8 path").to_string();
    let mut args: Vec<String> = sim.iter().map(|s| s.to_string()).collect();
    args.extend([
        "--pty".into(),
        path(link),
        "--view".into(),
        "-w".into(),
        path(cap),
    ]);
    Term::start_view(dir, &args, link)
}

/// `decode --json` of a capture: frames only, whole, no diagnostics but pairing's; returns the
/// message names in order.
fn decoded_names(path: &Path) -> Vec<String> {
    let recs = decode_json(path);
    let bad: Vec<_> = recs
        .iter()
        .filter(|r| r["type"] == "garbage" || r["diag"].as_array().is_some_and(|d| !d.is_empty()))
        .collect();
    assert!(bad.is_empty(), "{bad:?}");
    recs.iter()
        .filter(|r| r["type"] == "frame")
        .map(|r| r["name"].as_str().unwrap_or("?").to_string())
        .collect()
}

#[test]
fn tap_view_shows_the_traffic_live_and_q_leaves_a_complete_capture() {
    let dir = scratch("tap-view");
    let mut sim = start_sim(&dir.join("dev"));
    let (host, cap) = (dir.join("host"), dir.join("cap.pcapng"));
    let Some(term) = Term::start_view(&dir, &tap_args(&dir, &["--view"]), &host) else {
        return;
    };
    // The title says where host programs connect.
    let title = format!("cap.pcapng · host {} ·", host.display());
    term.wait("the title", |s| s.contains(&title));

    // The reply is on the screen within a second of the request.
    let t0 = Instant::now();
    ask_info(&host, || term.stderr());
    let screen = term.wait("HW_GET_INFO on the screen", |s| s.contains("HW_GET_INFO"));
    let lag = t0.elapsed();
    assert!(
        lag < Duration::from_secs(1),
        "shown after {lag:?}\n{screen}"
    );

    // The selected frame's detail and hex.
    term.keys(&[":2", "Enter"]);
    let screen = term.wait("record 2's detail and hex", |s| {
        s.contains("Record 2") && s.contains("06 00 54 00 81 50")
    });
    assert!(screen.contains("serial_number"), "{screen}");

    // A filter applied live: a second host session shows up in it.
    term.keys(&["/apt.name == HW_GET_INFO", "Enter"]);
    term.wait("the filter", |s| s.contains("1 shown"));
    ask_info(&host, || term.stderr());
    let screen = term.wait("the new reply in the filter", |s| s.contains("2 shown"));
    assert!(!screen.contains("HW_REQ_INFO"), "{screen}");
    // The title says LIVE (not "[indexing 0%]" forever), and a filter that has caught up is
    // not "filtering…".
    let screen = term.wait("LIVE in the title", |s| {
        s.lines().next().is_some_and(|t| t.contains("LIVE"))
    });
    let title_line = screen.lines().next().unwrap_or("");
    assert!(
        !title_line.contains("indexing") && !title_line.contains("filtering"),
        "{title_line}"
    );

    // q stops the tap: a valid capture, the byte check, where the file is.
    term.keys(&["q"]);
    let (code, err) = term.exit();
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("matches what was forwarded"), "{err}");
    assert!(
        err.contains(&format!("capture in {}", cap.display())),
        "{err}"
    );
    assert!(
        err.contains("host → device 12 bytes, device → host 180 bytes"),
        "{err}"
    );
    assert_eq!(
        decoded_names(&cap),
        ["HW_REQ_INFO", "HW_GET_INFO", "HW_REQ_INFO", "HW_GET_INFO"]
    );
    assert!(std::fs::symlink_metadata(&host).is_err(), "the link stays");
    sim.interrupt();
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn view_follow_shows_a_file_a_running_tap_writes() {
    let dir = scratch("follow");
    let mut sim = start_sim(&dir.join("dev"));
    let mut tap = start_tap(&dir, &[]);
    let cap = dir.join("cap.pcapng");
    let Some(term) = Term::start(&dir, &["view", "--follow", cap.to_str().unwrap()]) else {
        return;
    };
    term.wait("the view", |s| s.contains("Timeline"));
    // Shown at once, not after 4 KiB of traffic: the protocol is detected from what there is.
    ask_info(&dir.join("host"), || tap.both());
    term.wait("the reply", |s| {
        s.contains("HW_GET_INFO") && shown_records(s) == Some(2)
    });
    ask_info(&dir.join("host"), || tap.both());
    let screen = term.wait("the second session", |s| shown_records(s) == Some(4));
    assert!(!screen.contains("truncated"), "{screen}");
    // The tap ends; the view stays on the complete file until q.
    tap.signal(Signal::SIGINT);
    assert!(tap.wait_exit().success(), "{}", tap.stderr());
    term.keys(&[":4", "Enter"]);
    term.wait("record 4", |s| s.contains("Record 4"));
    // Ctrl-C is a key in the view: it closes.
    term.keys(&["C-c"]);
    let (code, err) = term.exit();
    assert_eq!(code, 0, "{err}");
    sim.interrupt();
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sim_view_shows_the_simulators_traffic_across_sessions_and_ends_on_sigterm() {
    let dir = scratch("sim-view");
    let (link, cap) = (dir.join("dev"), dir.join("sim.pcapng"));
    let Some(term) = sim_view(&dir, &["sim", "apt"], &link, &cap) else {
        return;
    };
    // Two host programs one after the other: the simulator stays up.
    for n in [2, 4] {
        ask_info(&link, || term.stderr());
        term.wait("the session", |s| shown_records(s) == Some(n));
    }
    kill(term.pid(), Signal::SIGTERM).expect("signal");
    let (code, err) = term.exit();
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("matches what was forwarded"), "{err}");
    assert_eq!(decoded_names(&cap).len(), 4);
    assert!(std::fs::symlink_metadata(&link).is_err(), "the link stays");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Resident memory of a process, in KiB.
fn rss_kib(pid: Pid) -> Option<u64> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let l = s.lines().find(|l| l.starts_with("VmRSS:"))?;
    l.split_whitespace().nth(1)?.parse().ok()
}

/// The capture times of a capture's records (frames and garbage), in record order.
fn record_times(cap: &Path) -> Vec<u64> {
    decode_json(cap)
        .iter()
        .filter(|r| r["n"].is_u64())
        .map(|r| r["ts_ns"].as_u64().expect("a time"))
        .collect()
}

/// Waits until the view shows every record the capture file holds, and returns their times.
/// The file is read again at each look: the device may still answer after the host is done
/// (a stop's MOT_MOVE_STOPPED comes when the deceleration ends), so a count read once goes
/// stale.
fn wait_all_shown(term: &Term, cap: &Path) -> Vec<u64> {
    let ts = RefCell::new(vec![]);
    term.wait("every record on the screen", |s| {
        *ts.borrow_mut() = record_times(cap);
        shown_records(s) == Some(ts.borrow().len() as u64)
    });
    ts.into_inner()
}

/// The view's worst lag over `(time, records shown)` samples: at each, how long ago the first
/// record not yet shown was captured (`ts`: the records' capture times).
fn view_lag_ns(samples: &[(u64, u64)], ts: &[u64]) -> u64 {
    samples
        .iter()
        .filter_map(|&(t, n)| ts.get(n as usize).map(|&first| t.saturating_sub(first)))
        .max()
        .unwrap_or(0)
}

fn now_ns() -> u64 {
    let d = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default();
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

/// A soak of the live view: simulator ⇄ `tap --view` (in a terminal) ⇄ a scripted host
/// sending ten minutes' worth of status requests at the controller's rate (10 per second:
/// 6000), compressed into `APTSCOPE_SOAK_SECS` (default 20) seconds, plus two 1 MB bursts.
/// Checked: not a byte lost in the file; the view never more than 1 s behind the file (the
/// record count on screen, sampled every 100 ms, against the records' capture times); the
/// tap's memory flat but for the view's index of the records. Prints its figures
/// (`bench/live-view.sh` runs it in release for the README).
#[test]
fn soak_of_the_live_view_loses_nothing_lags_under_a_second_and_keeps_memory_flat() {
    let secs: f64 = std::env::var("APTSCOPE_SOAK_SECS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20.0);
    let dir = scratch("soak");
    let mut sim = start_sim(&dir.join("dev"));
    let (host, cap) = (dir.join("host"), dir.join("cap.pcapng"));
    let Some(term) = Term::start_view(&dir, &tap_args(&dir, &["--view"]), &host) else {
        return;
    };
    let pid = term.pid();
    let rss0 = rss_kib(pid).expect("the tap's memory");

    // The host's script, in one thread writing whole frames in order: a status request every
    // slot, a megabyte burst at a quarter and at 60 % of the run.
    const UPDATES: u32 = 6000;
    let slot = Duration::from_secs_f64(secs / f64::from(UPDATES));
    let (burst, burst_replies) = traffic(1 << 20, &ALL_REQS);
    let expected = 2 * burst_replies.len() + UPDATES as usize;
    let h = open_host(&host);
    let rx = Receiver::start(h.try_clone().unwrap());
    let script = thread::spawn(move || {
        let mut h = h;
        let mut sent = Vec::with_capacity(3 << 20);
        let mut write = |b: &[u8], sent: &mut Vec<u8>| {
            assert_eq!(write_polled(&mut h, b), b.len(), "host write");
            sent.extend_from_slice(b);
        };
        let t0 = Instant::now();
        for i in 0..UPDATES {
            if i == UPDATES / 4 || i == UPDATES * 3 / 5 {
                write(&burst, &mut sent);
            }
            write(&req(MOT_REQ_DCSTATUSUPDATE), &mut sent);
            // Paced like the controller's updates (the traffic's rate, not a wait for a
            // condition): the next request goes out when its slot comes.
            if let Some(d) = (slot * (i + 1)).checked_sub(t0.elapsed()) {
                thread::sleep(d);
            }
        }
        sent
    });

    // Sample the screen (records shown) and the tap's memory until every reply is in.
    let mut samples: Vec<(u64, u64)> = vec![];
    let mut rss: Vec<u64> = vec![rss0];
    let t0 = Instant::now();
    while !script.is_finished() || frames(&rx.got()).len() < expected {
        assert!(
            t0.elapsed() < DEADLINE + Duration::from_secs_f64(secs),
            "the soak did not finish: {} of {expected} replies\n{}",
            frames(&rx.got()).len(),
            term.stderr()
        );
        let screen = term.screen();
        let t = now_ns();
        if let Some(n) = shown_records(&screen) {
            samples.push((t, n));
        }
        rss.extend(rss_kib(pid));
        thread::sleep(Duration::from_millis(100));
    }
    let sent = script.join().unwrap();
    let run = t0.elapsed();

    // Every record ends up on the screen.
    let catch_up = Instant::now();
    let ts = wait_all_shown(&term, &cap);
    let total = ts.len() as u64;
    let catch_up = catch_up.elapsed();
    rss.extend(rss_kib(pid));

    term.keys(&["q"]);
    let (code, err) = term.exit();
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("matches what was forwarded"), "{err}");

    // Not a byte lost: the file holds what the host sent and what it received, in order.
    let got = rx.finish();
    let c = read_capture(&cap);
    assert!(c.diags.is_empty(), "{:?}", c.diags);
    assert!(c.h2d == sent, "h2d: {}", first_difference(&c.h2d, &sent));
    assert!(c.d2h == got, "d2h: {}", first_difference(&c.d2h, &got));

    let lag_ns = view_lag_ns(&samples, &ts);
    if std::env::var("APTSCOPE_SOAK_DEBUG").is_ok() {
        let t_first = ts.first().copied().unwrap_or(0);
        for &(t, n) in &samples {
            if let Some(&first) = ts.get(n as usize) {
                let l = t.saturating_sub(first) / 1_000_000;
                if l > 200 {
                    eprintln!("t={:.2}s shown={n} lag={l}ms", (t - t_first) as f64 / 1e9);
                }
            }
        }
    }
    // Memory: what the tap process holds beyond the view's index of the records (a record
    // costs about 40 bytes plus its bytes; 4× that is allowed for the UI's caches).
    let bytes = (sent.len() + got.len()) as u64;
    let index_kib = (40 * total + bytes) * 4 / 1024;
    let (rss_max, rss_end) = (
        rss.iter().copied().max().unwrap_or(0),
        rss.last().copied().unwrap_or(0),
    );
    eprintln!(
        "soak: {:.1} s, {total} records, {} bytes; view lag max {} ms over {} samples, catch-up \
         {} ms after the last reply; tap RSS {rss0} KiB at start, {rss_max} KiB max, {rss_end} \
         KiB at end",
        run.as_secs_f64(),
        bytes,
        lag_ns / 1_000_000,
        samples.len(),
        catch_up.as_millis()
    );
    assert!(samples.len() >= 10, "{} samples", samples.len());
    assert!(
        lag_ns < 1_000_000_000,
        "the view lagged {} ms",
        lag_ns / 1_000_000
    );
    assert!(
        rss_max.saturating_sub(rss0) <= index_kib + 16 * 1024,
        "memory grew from {rss0} to {rss_max} KiB for {total} records"
    );
    sim.interrupt();
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sim_elliptec_view_shows_host_commands_sent_without_terminator_at_once() {
    let dir = scratch("ell-view");
    let (link, cap) = (dir.join("ell"), dir.join("ell.pcapng"));
    let sim = ["sim", "elliptec", "--modules", "0:ELL14,1:ELL9"];
    let Some(term) = sim_view(&dir, &sim, &link, &cap) else {
        return;
    };
    let host = open_host(&link);
    let rx = Receiver::start(host.try_clone().unwrap());
    // Commands as hosts send them, without CR LF: each shown as soon as it is sent.
    for (cmd, reply_end, records) in [("0in", 1, 2), ("1gp", 2, 4)] {
        let h = host.try_clone().unwrap();
        assert_eq!(send(h, cmd.as_bytes().to_vec()).join().unwrap(), 3);
        wait_for(
            "the module's reply",
            || format!("{:?}", String::from_utf8_lossy(&rx.got())),
            || count(&rx.got(), b"\r\n") >= reply_end,
        );
        term.wait("the command and its reply", |s| {
            shown_records(s) == Some(records)
        });
    }
    let screen = term.screen();
    assert!(screen.contains("in REQ_INFORMATION"), "{screen}");
    assert!(screen.contains("gp GET_POSITION"), "{screen}");
    drop(rx.finish());
    drop(host);
    term.keys(&["q"]);
    let (code, err) = term.exit();
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("host → device 6 bytes"), "{err}");
    assert!(
        err.contains(&format!("capture in {}", cap.display())),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// thorlabs-apt-device's KDC101 class driving the simulator through the tap: it polls the
/// status every few milliseconds; homing and a move every 5 s; every `burst_s` a megabyte of
/// MOT_SET_VELPARAMS written on its port (the client's own serial object).
const CLIENT_SOAK: &str = r#"
import sys, time
from thorlabs_apt_device import KDC101
link, secs, burst_s = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
frame = bytes.fromhex("13040e00d0010100") + bytes(12)
burst = (frame * 250 + bytes.fromhex("230200005001")) * 210
d = KDC101(serial_port=link, home=False)
t0 = time.monotonic()
d.home()
next_move, next_burst, pos = 5.0, burst_s / 2, 0
while time.monotonic() - t0 < secs:
    t = time.monotonic() - t0
    if t >= next_move:
        pos = 20000 - pos
        d.move_absolute(pos)
        next_move += 5.0
    if t >= next_burst:
        d._port.write(burst)
        next_burst += burst_s
    time.sleep(0.05)
d.close()
time.sleep(0.5)
print("position", d.status["position"], "updates", d.status.get("msgid"))
"#;

/// The soak with a real client (issue: fuzzing and soaks that keep up): thorlabs-apt-device's
/// KDC101 class ⇄ `tap --view` in a terminal ⇄ the simulator for `APTSCOPE_CLIENT_SOAK_SECS`
/// (default 60; `bench/client-soak.sh` runs 600), a megabyte burst every
/// `APTSCOPE_CLIENT_SOAK_BURST_SECS` (default 60, the first half-way into the first period).
/// Checked: the client ran to the end; not a byte lost (the tap's own check); the view never
/// more than 1 s behind the file; the simulator's memory flat after the first third, the tap's
/// flat but for the view's index of the records. Prints its figures.
#[test]
fn soak_with_a_real_client_loses_nothing_and_keeps_memory_flat() {
    let env_secs = |k: &str, d: f64| {
        std::env::var(k)
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(d)
    };
    let secs = env_secs("APTSCOPE_CLIENT_SOAK_SECS", 60.0);
    let burst_s = env_secs("APTSCOPE_CLIENT_SOAK_BURST_SECS", 60.0);
    let Some(py) = client_python() else { return };
    let dir = scratch("client-soak");
    let mut sim = start_sim(&dir.join("dev"));
    let (host, cap) = (dir.join("host"), dir.join("cap.pcapng"));
    let Some(term) = Term::start_view(&dir, &tap_args(&dir, &["--view"]), &host) else {
        return;
    };
    let (tap_pid, sim_pid) = (term.pid(), sim.pid());
    let script = dir.join("client.py");
    std::fs::write(&script, CLIENT_SOAK).unwrap();
    let client = Command::new(&py)
        .arg(&script)
        .arg(&host)
        .arg(secs.to_string())
        .arg(burst_s.to_string())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run the client");
    let t0 = Instant::now();
    let (mut samples, mut rss) = (vec![], vec![]);
    let client = thread::spawn(move || client.wait_with_output());
    while !client.is_finished() {
        assert!(
            t0.elapsed() < DEADLINE + Duration::from_secs_f64(secs),
            "the client did not finish\n{}",
            term.stderr()
        );
        let screen = term.screen();
        let t = now_ns();
        if let Some(n) = shown_records(&screen) {
            samples.push((t, n));
        }
        if let (Some(a), Some(b)) = (rss_kib(tap_pid), rss_kib(sim_pid)) {
            rss.push((t0.elapsed().as_secs_f64(), a, b));
        }
        thread::sleep(Duration::from_millis(100));
    }
    let out = client.join().unwrap().expect("the client's output");
    assert!(
        out.status.success(),
        "the client failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let ts = wait_all_shown(&term, &cap);
    let total = ts.len() as u64;
    term.keys(&["q"]);
    let (code, err) = term.exit();
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("matches what was forwarded"), "{err}");
    sim.interrupt();

    let lag_ns = view_lag_ns(&samples, &ts);
    let bytes = std::fs::metadata(&cap).map_or(0, |m| m.len());
    // Memory after the first third, against the end.
    let third = rss.iter().find(|r| r.0 >= secs / 3.0).copied();
    let last = rss.last().copied();
    let (Some((_, tap_a, sim_a)), Some((_, tap_b, sim_b))) = (third, last) else {
        panic!("no memory samples: {rss:?}");
    };
    eprintln!(
        "client soak: {secs} s, {total} records, {bytes} bytes captured; view lag max {} ms \
         over {} samples; tap RSS {tap_a} → {tap_b} KiB, simulator RSS {sim_a} → {sim_b} KiB \
         (from a third of the run to its end); client: {}",
        lag_ns / 1_000_000,
        samples.len(),
        String::from_utf8_lossy(&out.stdout).trim()
    );
    assert!(
        lag_ns < 1_000_000_000,
        "the view lagged {} ms",
        lag_ns / 1_000_000
    );
    assert!(
        sim_b <= sim_a + 2048,
        "the simulator grew from {sim_a} to {sim_b} KiB"
    );
    // The tap holds the view's index of the records (about 40 bytes each, plus their bytes;
    // 4× allowed for the UI's caches): beyond that, flat.
    let index_kib = (40 * total + bytes) * 4 / 1024;
    assert!(
        tap_b <= tap_a + index_kib + 8 * 1024,
        "the tap grew from {tap_a} to {tap_b} KiB for {total} records"
    );
}
