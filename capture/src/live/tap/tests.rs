//! The tap's tests: forwarding, recording, device loss, sniffing, streams, the file queue.

use super::mitm::Tap;
use super::port::{FdPort, HostPty, Port};
use super::queue::{FileQueue, QItem, Rec};
use super::record::Run;
use super::sniff::Sniff;
use super::writer::Merger;
use super::*;
use crate::live::serial::LineSettings;
use crate::live::stop::lock;
use crate::model::{Direction, Event, StreamInfo};
use crate::open::{open, OpenOptions};
use crate::scratch::scratch;
use nix::fcntl::OFlag;
use std::fs::File;
use std::io::{self, Read, Write};
use std::os::fd::OwnedFd;
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;
use std::sync::atomic::Ordering;
use std::sync::{mpsc, Arc, Mutex};
use std::thread;

/// Generous: only reached when something is broken.
const DEADLINE: Duration = Duration::from_secs(60);

/// A pseudo-terminal standing in for a device: the test holds the master, the tap opens
/// the slave path like a serial port.
fn fake_device() -> (FdPort, String) {
    let host = HostPty::create(None).unwrap();
    let path = host.slave_path.to_string_lossy().into_owned();
    let master = host.master.try_clone().unwrap();
    // The slave is closed here: the tap's open is then the only one.
    drop(host);
    (master, path)
}

/// Open a tty path as the host program would (no controlling terminal).
fn open_host(path: &Path) -> FdPort {
    let f = File::options()
        .read(true)
        .write(true)
        .custom_flags(OFlag::O_NOCTTY.bits())
        .open(path)
        .unwrap();
    FdPort::new(OwnedFd::from(f)).unwrap()
}

fn send(p: &mut FdPort, mut bytes: &[u8]) {
    let t0 = Instant::now();
    while !bytes.is_empty() {
        assert!(t0.elapsed() < DEADLINE, "write timed out");
        let n = p.write_tick(bytes).unwrap();
        bytes = &bytes[n..];
    }
}

fn recv(p: &mut FdPort, n: usize) -> Vec<u8> {
    let t0 = Instant::now();
    let mut out = vec![];
    let mut buf = vec![0; 8192];
    while out.len() < n {
        assert!(
            t0.elapsed() < DEADLINE,
            "read timed out after {} of {n} bytes",
            out.len()
        );
        let k = p.read_tick(&mut buf[..(n - out.len()).min(8192)]).unwrap();
        out.extend_from_slice(&buf[..k]);
    }
    out
}

/// `n` bytes of back-to-back MOT_MOVE_ABSOLUTE frames (12 bytes each), then a tail.
fn apt_moves(n: usize) -> Vec<u8> {
    let mut v = Vec::with_capacity(n + 12);
    let mut pos = 0i32;
    while v.len() < n {
        v.extend_from_slice(&[0x53, 0x04, 0x06, 0x00, 0xa2, 0x01, 0x01, 0x00]);
        v.extend_from_slice(&pos.to_le_bytes());
        pos = pos.wrapping_add(977);
    }
    v.truncate(n);
    v
}

/// `n` bytes of back-to-back MOT_GET_DCSTATUSUPDATE frames (20 bytes each).
fn apt_status(n: usize) -> Vec<u8> {
    let mut v = Vec::with_capacity(n + 20);
    let mut pos = 0i32;
    while v.len() < n {
        v.extend_from_slice(&[0x91, 0x04, 0x0e, 0x00, 0x81, 0x50, 0x01, 0x00]);
        v.extend_from_slice(&pos.to_le_bytes());
        v.extend_from_slice(&[0x2c, 0x01, 0x00, 0x00, 0x10, 0x05, 0x00, 0x80]);
        pos = pos.wrapping_sub(313);
    }
    v.truncate(n);
    v
}

/// The capture's bytes per direction, its streams, and whether it had diagnostics.
fn read_back(path: &Path) -> (Vec<u8>, Vec<u8>, Vec<StreamInfo>, Vec<String>) {
    let (mut r, f) = open(path.to_str().unwrap(), OpenOptions::default()).unwrap();
    let want = crate::open::Format::from_extension(path.to_str().unwrap());
    assert_eq!(Some(f), want);
    let (mut h2d, mut d2h, mut streams, mut diags) = (vec![], vec![], vec![], vec![]);
    while let Some(e) = r.next_event() {
        match e {
            Event::Stream(s) => streams.push(s),
            Event::Chunk(c) => {
                assert!(c.ts_ns.is_some());
                match c.dir {
                    Direction::HostToDevice => h2d.extend_from_slice(c.bytes),
                    Direction::DeviceToHost => d2h.extend_from_slice(c.bytes),
                    Direction::Unknown => panic!("chunk without direction"),
                }
            }
            Event::Diag(d) => diags.push(d.to_string()),
        }
    }
    (h2d, d2h, streams, diags)
}

fn tap_opts(device: &str, dir: &Path) -> TapOptions {
    let mut o = TapOptions::new(device, Some(dir.join("ttyAPT").to_string_lossy().into()));
    o.live.write = Some(dir.join("cap.pcapng").to_string_lossy().into());
    o.live.quiet = true;
    o.live.signals = false;
    o
}

/// Run `f` in a thread, failing (not hanging) when it takes longer than the deadline.
fn within<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> impl FnOnce() -> T {
    let (tx, rx) = mpsc::channel();
    thread::spawn(move || {
        let _ = tx.send(f());
    });
    move || rx.recv_timeout(DEADLINE).expect("did not finish in time")
}

#[derive(Clone, Default)]
struct Shown(Arc<Mutex<Vec<u8>>>);
impl Write for Shown {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        lock(&self.0).extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

#[test]
fn forwards_both_ways_losslessly_and_records_exactly_what_crossed() {
    let dir = scratch("both");
    let (mut dev, dev_path) = fake_device();
    let mut opts = tap_opts(&dev_path, &dir);
    opts.live.quiet = false;
    let stop = opts.live.stop.clone();
    let tap = Tap::new(opts).unwrap();
    let shown = Shown::default();
    let out = shown.clone();
    let done = within(move || tap.run(Some(Box::new(out))));
    let link = dir.join("ttyAPT");
    assert!(std::fs::read_link(&link).is_ok());
    let mut host = open_host(&link);

    // A request and its reply.
    let req = [0x05, 0x00, 0x00, 0x00, 0x50, 0x01]; // HW_REQ_INFO
    send(&mut host, &req);
    assert_eq!(recv(&mut dev, req.len()), req);
    let mut reply = vec![0x06, 0x00, 0x54, 0x00, 0x81, 0x50];
    reply.extend((0..84u8).map(|i| i.wrapping_mul(7)));
    send(&mut dev, &reply);
    assert_eq!(recv(&mut host, reply.len()), reply);

    // 1 MB of back-to-back frames each way at once.
    const MB: usize = 1 << 20;
    let (moves, status) = (apt_moves(MB), apt_status(MB));
    let mut host_rx = host.try_clone().unwrap();
    let mut dev_rx = dev.try_clone().unwrap();
    // (The threads hand their ports back: closing the device's master would hang it up.)
    let got_d2h = thread::spawn(move || (recv(&mut host_rx, MB), host_rx));
    let got_h2d = thread::spawn(move || (recv(&mut dev_rx, MB), dev_rx));
    let m = moves.clone();
    let w1 = thread::spawn(move || {
        send(&mut host, &m);
        host
    });
    let st = status.clone();
    let w2 = thread::spawn(move || {
        send(&mut dev, &st);
        dev
    });
    let _host = w1.join().unwrap();
    let _dev = w2.join().unwrap();
    let (got, _dev_rx) = got_h2d.join().unwrap();
    assert!(got == moves, "device got other bytes");
    let (got, _host_rx) = got_d2h.join().unwrap();
    assert!(got == status, "host got other bytes");

    stop.stop();
    let stats = done().unwrap();
    let sent_h2d = [&req[..], &moves].concat();
    let sent_d2h = [&reply[..], &status].concat();
    assert_eq!(stats.bytes_h2d, sent_h2d.len() as u64);
    assert_eq!(stats.bytes_d2h, sent_d2h.len() as u64);
    assert!(stats.file_matches(), "{}", stats.summary("test"));
    assert!(stats.disconnects.is_empty());
    assert_eq!(stats.undelivered, 0);

    let (h2d, d2h, streams, diags) = read_back(&dir.join("cap.pcapng"));
    assert!(diags.is_empty(), "{diags:?}");
    assert!(h2d == sent_h2d, "file h2d differs");
    assert!(d2h == sent_d2h, "file d2h differs");
    assert_eq!(streams.len(), 1);
    assert_eq!(streams[0].name, dev_path);
    assert_eq!(streams[0].settings.as_deref(), Some("115200 8N1 RTS/CTS"));

    let shown = String::from_utf8_lossy(&lock(&shown.0)).into_owned();
    let first = shown.lines().next().unwrap_or_default();
    assert!(first.contains("HW_REQ_INFO"), "{first}");
    assert!(shown.contains("MOT_MOVE_ABSOLUTE"));
    // The link goes with the tap.
    assert!(std::fs::symlink_metadata(&link).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn device_gone_mid_stream_is_reported_and_the_file_stays_valid() {
    let dir = scratch("gone");
    let (mut dev, dev_path) = fake_device();
    let tap = Tap::new(tap_opts(&dev_path, &dir)).unwrap();
    let done = within(move || tap.run(None));
    let mut host = open_host(&dir.join("ttyAPT"));
    let a = apt_moves(600);
    send(&mut host, &a);
    assert_eq!(recv(&mut dev, a.len()), a);
    let b = apt_status(400);
    send(&mut dev, &b);
    assert_eq!(recv(&mut host, b.len()), b);
    let before = Instant::now();
    drop(dev); // the cable is pulled
    let stats = done().unwrap();
    assert_eq!(stats.disconnects.len(), 1, "{}", stats.summary("test"));
    let d = &stats.disconnects[0];
    assert_eq!(d.port, dev_path);
    assert!(d.ts_ns > 0 && !d.error.is_empty());
    assert!(before.elapsed() < Duration::from_secs(10));
    assert!(stats.file_matches(), "{}", stats.summary("test"));
    let (h2d, d2h, _, diags) = read_back(&dir.join("cap.pcapng"));
    assert!(diags.is_empty(), "{diags:?}");
    assert_eq!((h2d, d2h), (a, b));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn reconnect_waits_for_the_device_and_carries_on_in_the_same_file() {
    let dir = scratch("reconnect");
    let dev_link = dir.join("ttyUSB0");
    let (mut dev, p1) = fake_device();
    std::os::unix::fs::symlink(&p1, &dev_link).unwrap();
    let mut opts = tap_opts(dev_link.to_str().unwrap(), &dir);
    opts.live.reconnect = true;
    let stop = opts.live.stop.clone();
    let tap = Tap::new(opts).unwrap();
    let done = within(move || tap.run(None));
    let mut host = open_host(&dir.join("ttyAPT"));
    let a = apt_moves(120);
    send(&mut host, &a);
    assert_eq!(recv(&mut dev, a.len()), a);
    drop(dev);

    // The device comes back under the same name.
    let (mut dev2, p2) = fake_device();
    std::fs::remove_file(&dev_link).unwrap();
    std::os::unix::fs::symlink(&p2, &dev_link).unwrap();
    // Written before the tap reopens it: waits in the pty until then.
    let b = apt_status(200);
    send(&mut dev2, &b);
    assert_eq!(recv(&mut host, b.len()), b);
    let c = apt_moves(240);
    send(&mut host, &c);
    assert_eq!(recv(&mut dev2, c.len()), c);

    stop.stop();
    let stats = done().unwrap();
    assert_eq!(stats.disconnects.len(), 1);
    assert!(stats.file_matches(), "{}", stats.summary("test"));
    let (h2d, d2h, _, diags) = read_back(&dir.join("cap.pcapng"));
    assert!(diags.is_empty(), "{diags:?}");
    assert_eq!(h2d, [a, c].concat());
    assert_eq!(d2h, b);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sniff_merges_two_receive_only_ports() {
    let dir = scratch("sniff");
    let (mut htx, hp) = fake_device();
    let (mut dtx, dp) = fake_device();
    let mut opts = SniffOptions::new(&hp, &dp);
    opts.live.write = Some(dir.join("sniff.pcapng").to_string_lossy().into());
    opts.live.quiet = true;
    opts.live.signals = false;
    let stop = opts.live.stop.clone();
    let sniff = Sniff::new(opts).unwrap();
    let fwd = sniff.rec.forwarded();
    let done = within(move || sniff.run(None));
    let (mut h, mut d) = (vec![], vec![]);
    for i in 0..20 {
        let q = apt_moves(12 * (i + 1));
        let r = apt_status(20 * (i + 1));
        send(&mut htx, &q);
        send(&mut dtx, &r);
        h.extend(q);
        d.extend(r);
    }
    let big = apt_status(256 << 10);
    send(&mut dtx, &big);
    d.extend(big);
    // Stop once the sniff has read everything (its counters say when).
    let t0 = Instant::now();
    while fwd[0].load(Ordering::SeqCst) < h.len() as u64
        || fwd[1].load(Ordering::SeqCst) < d.len() as u64
    {
        assert!(t0.elapsed() < DEADLINE, "the sniff did not read everything");
        thread::park_timeout(Duration::from_millis(5));
    }
    stop.stop();
    let stats = done().unwrap();
    assert!(stats.file_matches(), "{}", stats.summary("test"));
    assert_eq!(
        (stats.bytes_h2d, stats.bytes_d2h),
        (h.len() as u64, d.len() as u64)
    );
    let (fh, fd, streams, diags) = read_back(&dir.join("sniff.pcapng"));
    assert!(diags.is_empty(), "{diags:?}");
    assert_eq!(streams[0].name, format!("{hp} + {dp}"));
    assert!(fh == h && fd == d, "file differs");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_file_is_readable_while_the_tap_runs() {
    // What a `kill -9` would leave: the file as flushed so far, never finished.
    let dir = scratch("live-file");
    let (mut dev, dev_path) = fake_device();
    let opts = tap_opts(&dev_path, &dir);
    let stop = opts.live.stop.clone();
    let tap = Tap::new(opts).unwrap();
    let done = within(move || tap.run(None));
    let mut host = open_host(&dir.join("ttyAPT"));
    let a = apt_moves(1200);
    send(&mut host, &a);
    assert_eq!(recv(&mut dev, a.len()), a);
    let t0 = Instant::now();
    loop {
        let (h2d, _, _, diags) = read_back(&dir.join("cap.pcapng"));
        assert!(diags.is_empty(), "{diags:?}");
        if h2d == a {
            break;
        }
        assert!(t0.elapsed() < DEADLINE, "not flushed");
        thread::park_timeout(Duration::from_millis(20));
    }
    stop.stop();
    assert!(done().unwrap().file_matches());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_existing_file_is_kept_without_force() {
    let dir = scratch("exists");
    let (_dev, dev_path) = fake_device();
    let opts = tap_opts(&dev_path, &dir);
    std::fs::write(opts.live.write.as_ref().unwrap(), b"precious").unwrap();
    let e = Tap::new(opts.clone()).err().unwrap();
    assert_eq!(e.kind(), io::ErrorKind::AlreadyExists);
    assert_eq!(
        std::fs::read(opts.live.write.as_ref().unwrap()).unwrap(),
        b"precious"
    );
    // A missing device is an error at once without `reconnect`.
    let mut o = tap_opts(dir.join("nope").to_str().unwrap(), &dir);
    o.live.force = true;
    assert!(Tap::new(o).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_stream_goes_into_an_existing_pipe_and_ends_with_its_reader() {
    let dir = scratch("stream");
    let (mut dev, dev_path) = fake_device();
    let fifo = dir.join("fifo");
    // Never created, nor written over when it is a file.
    let mut o = tap_opts(&dev_path, &dir);
    o.stream = true;
    o.live.write = Some(fifo.to_string_lossy().into());
    assert_eq!(
        Tap::new(o.clone()).err().unwrap().kind(),
        io::ErrorKind::NotFound
    );
    assert!(!fifo.exists());
    std::fs::write(&fifo, b"precious").unwrap();
    let e = Tap::new(o.clone()).err().unwrap();
    assert!(e.to_string().contains("not a pipe"), "{e}");
    assert_eq!(std::fs::read(&fifo).unwrap(), b"precious");
    std::fs::remove_file(&fifo).unwrap();

    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
    let mut r = File::options()
        .read(true)
        .custom_flags(OFlag::O_NONBLOCK.bits())
        .open(&fifo)
        .unwrap();
    let tap = Tap::new(o).unwrap();
    let done = within(move || tap.run(None));
    let mut host = open_host(&dir.join("ttyAPT"));
    let a = apt_moves(48);
    send(&mut host, &a);
    assert_eq!(recv(&mut dev, a.len()), a);
    let mut got = vec![];
    let t0 = Instant::now();
    while !got.windows(a.len()).any(|w| w == a) {
        assert!(t0.elapsed() < DEADLINE, "never flushed");
        let mut buf = [0u8; 4096];
        match r.read(&mut buf) {
            Ok(n) => got.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                thread::park_timeout(Duration::from_millis(5))
            }
            Err(e) => panic!("{e}"),
        }
    }
    // The reader goes: the tap ends by itself, saying why.
    drop(r);
    let stats = done().unwrap();
    assert!(stats.reader_closed, "{}", stats.summary("test"));
    assert!(stats.summary("test").contains("its reader closed it"));
    let cap = dir.join("got.pcapng");
    std::fs::write(&cap, &got).unwrap();
    let (h2d, _, _, diags) = read_back(&cap);
    assert!(diags.is_empty(), "{diags:?}");
    assert_eq!(h2d, a);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn writes_pcap_by_extension_and_refuses_non_streaming_formats() {
    let dir = scratch("pcap");
    let (mut dev, dev_path) = fake_device();
    let mut opts = tap_opts(&dev_path, &dir);
    opts.live.write = Some(dir.join("cap.pcap").to_string_lossy().into());
    let stop = opts.live.stop.clone();
    let tap = Tap::new(opts).unwrap();
    let done = within(move || tap.run(None));
    let mut host = open_host(&dir.join("ttyAPT"));
    let a = apt_moves(48);
    send(&mut host, &a);
    assert_eq!(recv(&mut dev, a.len()), a);
    let b = apt_status(40);
    send(&mut dev, &b);
    assert_eq!(recv(&mut host, b.len()), b);
    stop.stop();
    assert!(done().unwrap().file_matches());
    let (h2d, d2h, _, diags) = read_back(&dir.join("cap.pcap"));
    assert!(diags.is_empty(), "{diags:?}");
    assert_eq!((h2d, d2h), (a, b));

    let mut o = tap_opts(&dev_path, &dir);
    o.live.write = Some(dir.join("cap.mcap").to_string_lossy().into());
    let e = Tap::new(o).err().unwrap();
    assert!(e.to_string().contains("pcapng or pcap"), "{e}");
    assert!(!dir.join("cap.mcap").exists(), "nothing created");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn merger_orders_by_time_and_keeps_each_direction_in_order() {
    let rec = |ts, dir, b: u8| {
        Arc::new(Rec {
            ts,
            dir,
            bytes: vec![b],
        })
    };
    let mut m = Merger::default();
    m.push(rec(10, Direction::HostToDevice, 1));
    m.push(rec(30, Direction::HostToDevice, 2));
    m.push(rec(20, Direction::DeviceToHost, 3));
    // 10 < 20: written; then 20 < 30; then 30 waits for the horizon.
    let got: Vec<u8> = std::iter::from_fn(|| m.pop(Some(25)))
        .map(|r| r.bytes[0])
        .collect();
    assert_eq!(got, [1, 3]);
    assert!(m.pop(Some(29)).is_none());
    assert_eq!(m.pop(None).unwrap().bytes, [2]);
}

#[test]
fn the_file_queue_applies_backpressure_instead_of_dropping() {
    let q = Arc::new(FileQueue::new(10));
    let rec = |n| {
        QItem::Chunk(Arc::new(Rec {
            ts: 0,
            dir: Direction::HostToDevice,
            bytes: vec![0; n],
        }))
    };
    q.push(rec(8));
    let q2 = q.clone();
    let pusher = thread::spawn(move || q2.push(rec(8)));
    let t0 = Instant::now();
    while q.waits.load(Ordering::SeqCst) == 0 {
        assert!(t0.elapsed() < DEADLINE);
        thread::park_timeout(Duration::from_millis(5));
    }
    assert_eq!(q.pop_all(TICK).0.len(), 1);
    pusher.join().unwrap();
    assert_eq!(q.pop_all(TICK).0.len(), 1);
    assert_eq!(q.lost.load(Ordering::SeqCst), 0);
    // Once writing failed, nothing waits and the loss is counted.
    q.fail();
    q.push(rec(30));
    assert_eq!(q.lost.load(Ordering::SeqCst), 30);
}

#[test]
fn line_settings_follow_the_protocol() {
    let apt = LineSettings::for_proto(Proto::Apt, None, None);
    assert_eq!(apt.to_string(), "115200 8N1 RTS/CTS");
    let ell = LineSettings::for_proto(Proto::Elliptec, None, None);
    assert_eq!(ell.to_string(), "9600 8N1");
    let o = LineSettings::for_proto(Proto::Apt, Some(9600), Flow::parse("none"));
    assert_eq!(o.to_string(), "9600 8N1");
    assert_eq!(clock_time(3_723_004_000_000), "01:02:03.004 UTC");
}
