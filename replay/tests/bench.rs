//! Replays on a bench made of real pseudo-terminals: the simulator on one end, the replay on the
//! other; and the replay impersonating a device towards a scripted host.

#[path = "../../tests/common/scratch.rs"]
mod scratch;

use aptscope_capture::live::serial::LineSettings;
use aptscope_capture::live::sim::{serve_pty, stop_pair, AptModel, AptSim, Pty, Simulator};
use aptscope_capture::open::{create, Format, OpenOptions};
use aptscope_capture::{Chunk, Direction, StreamInfo};
use aptscope_dissector::apt::{encode, FieldValue};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::Table;
use aptscope_replay::diff::Kind;
use aptscope_replay::{
    run_device, run_host, DeviceOptions, DeviceOutcome, HostOptions, Link, Script, Selection, Side,
};
use scratch::scratch;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::thread;
use std::time::{Duration, Instant};

const MS: u64 = 1_000_000;
/// 2026-11-02T10:00:00Z: the virtual capture's start.
const EPOCH: u64 = 1_793_613_600_000_000_000;

/// An APT message from the host to the USB unit, built from the table.
fn enc(name: &str, vals: &[(&str, i64)]) -> Vec<u8> {
    let t = Table::global();
    let m = t.msg_by_name(name).unwrap();
    let form = m
        .forms
        .iter()
        .find(|f| {
            vals.iter()
                .all(|(k, _)| f.fields.iter().any(|x| x.name == *k))
        })
        .unwrap();
    let v: Vec<(&str, FieldValue)> = vals
        .iter()
        .map(|(k, x)| (*k, FieldValue::Int(*x)))
        .collect();
    encode(form, &v, m.id, 0x50, 0x01).unwrap()
}

/// A short KDC101 session: identify, enable, parameters, a short move, a status request.
fn session() -> Vec<(u64, Vec<u8>)> {
    vec![
        (0, enc("HW_REQ_INFO", &[])),
        (
            40 * MS,
            enc(
                "MOD_SET_CHANENABLESTATE",
                &[("chan_ident", 1), ("enable_state", 1)],
            ),
        ),
        (
            60 * MS,
            enc("MOD_REQ_CHANENABLESTATE", &[("chan_ident", 1)]),
        ),
        (90 * MS, enc("MOT_REQ_VELPARAMS", &[("chan_ident", 1)])),
        (
            120 * MS,
            enc(
                "MOT_MOVE_RELATIVE",
                &[("chan_ident", 1), ("relative_distance", 3000)],
            ),
        ),
        (
            700 * MS,
            enc("MOT_REQ_DCSTATUSUPDATE", &[("chan_ident", 1)]),
        ),
    ]
}

/// Run `steps` against the simulator on virtual time and write what crossed as a pcapng.
fn record_virtual(sim: &mut AptSim, steps: &[(u64, Vec<u8>)], end: u64, path: &Path) {
    let mut w = create(path.to_str().unwrap(), Format::PcapNg, true).unwrap();
    w.stream(&StreamInfo {
        id: 0,
        name: "sim".into(),
        settings: None,
    })
    .unwrap();
    let mut put = |t: u64, dir: Direction, b: &[u8]| {
        w.chunk(&Chunk {
            ts_ns: Some(EPOCH + t),
            dir,
            stream: 0,
            bytes: b,
        })
        .unwrap();
    };
    let drive =
        |sim: &mut AptSim, from: u64, to: u64, put: &mut dyn FnMut(u64, Direction, &[u8])| {
            let mut t = from;
            loop {
                while let Some(b) = sim.poll(t) {
                    put(t, Direction::DeviceToHost, &b);
                }
                match sim.next_deadline() {
                    Some(d) if d < to => t = d.max(t + 1),
                    _ => break,
                }
            }
        };
    for (i, (t, b)) in steps.iter().enumerate() {
        put(*t, Direction::HostToDevice, b);
        sim.input(b, *t);
        let next = steps.get(i + 1).map_or(end, |s| s.0);
        drive(sim, *t, next, &mut put);
    }
    w.finish().unwrap();
}

/// Serve a simulator on a pseudo-terminal in a thread; stop it by dropping the returned guard.
struct SimOnPty {
    path: PathBuf,
    stop: Option<aptscope_capture::live::sim::StopHandle>,
    h: Option<thread::JoinHandle<()>>,
}

impl SimOnPty {
    fn start(mut sim: AptSim) -> SimOnPty {
        let pty = Pty::open().unwrap();
        let path = pty.path().to_path_buf();
        let (stop, sig) = stop_pair().unwrap();
        let h = thread::spawn(move || {
            let _ = serve_pty(&mut sim, pty, Some(&sig), &[]);
        });
        SimOnPty {
            path,
            stop: Some(stop),
            h: Some(h),
        }
    }
}

impl Drop for SimOnPty {
    fn drop(&mut self) {
        if let Some(s) = self.stop.take() {
            s.stop();
        }
        if let Some(h) = self.h.take() {
            let _ = h.join();
        }
    }
}

fn load(path: &Path) -> Script {
    Script::load(
        path.to_str().unwrap(),
        OpenOptions::default(),
        Some(Proto::Apt),
        None,
    )
    .unwrap()
}

fn captured(dir: &Path) -> (Script, PathBuf) {
    let cap = dir.join("kdc101.pcapng");
    record_virtual(
        &mut AptSim::new(AptModel::Kdc101),
        &session(),
        1200 * MS,
        &cap,
    );
    (load(&cap), cap)
}

fn replay_as_host(script: &Script, sim: AptSim, rec: Option<&Path>) -> aptscope_replay::Outcome {
    let bench = SimOnPty::start(sim);
    let mut link =
        Link::open_port(&bench.path, LineSettings::for_proto(Proto::Apt, None, None)).unwrap();
    let mut w = rec.map(|p| create(p.to_str().unwrap(), Format::PcapNg, true).unwrap());
    let opts = HostOptions::default();
    run_host(
        script,
        &Selection::default(),
        &opts,
        &mut link,
        w.as_mut()
            .map(|b| &mut **b as &mut dyn aptscope_capture::Writer),
        &mut |_| {},
        &mut || None,
    )
    .unwrap()
}

#[test]
fn replaying_a_simulator_capture_against_the_simulator_gives_an_empty_diff() {
    let dir = scratch("same");
    let (script, _) = captured(&dir);
    let replies = script
        .msgs
        .iter()
        .filter(|m| m.side == Side::Device && m.pair.is_some())
        .count();
    assert!(replies >= 5, "{:#?}", script.msgs);
    let rec = dir.join("observed.pcapng");
    let o = replay_as_host(&script, AptSim::new(AptModel::Kdc101), Some(&rec));
    assert_eq!(o.aborted, None);
    assert_eq!(o.sent, session().len());
    let r = &o.report;
    assert_eq!(r.failures(None), 0, "{}", r.text(None));
    assert_eq!(r.matched, replies, "{}", r.text(None));
    assert_eq!(o.timing.count(), o.sent);
    // The observed conversation was recorded, and decodes to the same requests.
    let seen = load(&rec);
    let names = |s: &Script, side| {
        s.msgs
            .iter()
            .filter(|m| m.side == side)
            .map(|m| m.name.clone())
            .collect::<Vec<_>>()
    };
    assert_eq!(names(&seen, Side::Host), names(&script, Side::Host));
}

#[test]
fn a_changed_device_shows_exactly_that_field() {
    let dir = scratch("changed");
    let (script, _) = captured(&dir);
    let o = replay_as_host(
        &script,
        AptSim::with_serial(AptModel::Kdc101, 27_000_999),
        None,
    );
    let r = &o.report;
    assert_eq!(r.diffs.len(), 1, "{}", r.text(None));
    let d = &r.diffs[0];
    assert_eq!(d.kind, Kind::Field);
    assert_eq!(d.reply, "HW_GET_INFO");
    assert_eq!(d.field.as_deref(), Some("serial_number"));
    assert_eq!(d.captured, serde_json::json!(27_000_123));
    assert_eq!(d.observed, serde_json::json!(27_000_999));
    assert!(r
        .text(None)
        .contains("HW_GET_INFO serial_number: captured 27000123, observed 27000999"));
}

#[test]
fn wait_replies_sends_after_each_reply() {
    let dir = scratch("wait");
    let (script, _) = captured(&dir);
    let bench = SimOnPty::start(AptSim::new(AptModel::Kdc101));
    let mut link =
        Link::open_port(&bench.path, LineSettings::for_proto(Proto::Apt, None, None)).unwrap();
    let opts = HostOptions {
        wait_replies: true,
        timing: aptscope_replay::Timing {
            speed: 1.0,
            asap: true,
        },
        ..HostOptions::default()
    };
    let o = run_host(
        &script,
        &Selection::default(),
        &opts,
        &mut link,
        None,
        &mut |_| {},
        &mut || None,
    )
    .unwrap();
    assert_eq!(o.report.failures(None), 0, "{}", o.report.text(None));
    // As fast as the replies allow, but the move's completion was awaited before the status
    // request that followed it: the position it reports is the target.
    assert!(o.report.matched >= 5);
}

/// The scripted host: send each captured request (passed through `strip`) and read back the
/// bytes the capture says the device sent until the next request; returns the number of
/// requests and the device's outcome.
fn impersonate(script: &Script, dir: &Path, strip: fn(&[u8]) -> &[u8]) -> (usize, DeviceOutcome) {
    let link_path = dir.join("tty");
    let (mut link, _slave) = Link::open_pty(Some(&link_path)).unwrap();
    let s2 = script.clone();
    let dev = thread::spawn(move || {
        run_device(
            &s2,
            &Selection::default(),
            &DeviceOptions {
                display: true,
                ..DeviceOptions::default()
            },
            &mut link,
            None,
            &mut |l| assert!(!l.is_empty()),
            &mut || None,
        )
        .unwrap()
    });
    let mut host = serialport::new(link_path.to_str().unwrap(), 115_200)
        .timeout(Duration::from_millis(50))
        .open_native()
        .unwrap();
    let msgs = &script.msgs;
    let mut requests = 0;
    for (i, m) in msgs.iter().enumerate() {
        if m.side != Side::Host {
            continue;
        }
        requests += 1;
        let want: Vec<u8> = msgs[i + 1..]
            .iter()
            .take_while(|x| x.side == Side::Device)
            .flat_map(|x| x.raw.clone())
            .collect();
        host.write_all(strip(&m.raw)).unwrap();
        let mut got = vec![];
        let give_up = Instant::now() + Duration::from_secs(30);
        let mut buf = [0u8; 512];
        while got.len() < want.len() && Instant::now() < give_up {
            match host.read(&mut buf) {
                Ok(n) => got.extend_from_slice(&buf[..n]),
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(e) => panic!("{e}"),
            }
        }
        assert_eq!(
            String::from_utf8_lossy(&got),
            String::from_utf8_lossy(&want),
            "answer to {} (record {})",
            m.name,
            m.n
        );
    }
    drop(host);
    (requests, dev.join().unwrap())
}

#[test]
fn replaying_as_the_device_answers_every_request_with_the_captured_reply() {
    let dir = scratch("device");
    let (script, _) = captured(&dir);
    let (requests, o) = impersonate(&script, &dir, |b| b);
    assert!(o.gone.is_some(), "ends when the host closes the port");
    assert_eq!(o.requests, requests);
    assert_eq!(o.answered, requests, "{}", o.text());
    assert_eq!(o.reused, 0);
    assert!(o.unmatched.is_empty());
}

/// Elliptec hosts usually send no terminator: each command is still answered at once, by the
/// same command to the same address (the address change included).
#[test]
fn an_elliptec_bus_is_impersonated_for_a_host_that_sends_no_terminators() {
    let dir = scratch("ell");
    let sample = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../samples/sessions/elliptec.pcapng"
    );
    let script = Script::load(sample, OpenOptions::default(), None, None).unwrap();
    assert_eq!(script.proto, Proto::Elliptec);
    let (requests, o) = impersonate(&script, &dir, |b| b.strip_suffix(b"\r\n").unwrap_or(b));
    assert!(requests >= 10);
    assert_eq!(o.answered, requests, "{}", o.text());
    assert_eq!(o.reused, 0, "{}", o.text());
}

/// Bad input from the host is reported and decoding carries on: line noise before a request
/// (still answered), and a frame cut short when the host hangs up. (A header cut short and
/// followed at once by a whole frame is ambiguous in APT, which has no sync bytes: the framer
/// resynchronises where the bytes frame, as a controller would.)
#[test]
fn an_impersonated_device_survives_garbage_from_the_host() {
    let dir = scratch("garbage");
    let (script, _) = captured(&dir);
    let link_path = dir.join("tty");
    let (mut link, _slave) = Link::open_pty(Some(&link_path)).unwrap();
    let s2 = script.clone();
    let dev = thread::spawn(move || {
        run_device(
            &s2,
            &Selection::default(),
            &DeviceOptions::default(),
            &mut link,
            None,
            &mut |_| {},
            &mut || None,
        )
        .unwrap()
    });
    let mut host = serialport::new(link_path.to_str().unwrap(), 115_200)
        .timeout(Duration::from_millis(50))
        .open_native()
        .unwrap();
    // Noise, then the request.
    host.write_all(&[0xff, 0x00, 0x13, 0x37]).unwrap();
    host.write_all(&enc("HW_REQ_INFO", &[])).unwrap();
    let want = script.msgs[1].raw.clone();
    assert_eq!(script.msgs[1].name, "HW_GET_INFO");
    let mut got = vec![];
    let give_up = Instant::now() + Duration::from_secs(30);
    let mut buf = [0u8; 512];
    while got.len() < want.len() && Instant::now() < give_up {
        match host.read(&mut buf) {
            Ok(n) => got.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
            Err(e) => panic!("{e}"),
        }
    }
    assert_eq!(got, want);
    // A request cut after 3 bytes, and the host goes away.
    host.write_all(&[0x05, 0x00, 0x00]).unwrap();
    drop(host);
    let o = dev.join().unwrap();
    assert_eq!((o.requests, o.answered), (1, 1), "{}", o.text());
    assert!(
        o.notes.iter().any(|n| n.starts_with("garbage @0")),
        "the noise is reported at its offset: {:?}",
        o.notes
    );
    assert!(
        o.notes.iter().any(|n| n.contains("@10")),
        "the cut request is reported at its offset: {:?}",
        o.notes
    );
}

/// A capture without times (raw bytes) cannot say how long a move took: the replay waits for
/// its completion as long as pairing would (120 s for moves), not the 2 s of other requests,
/// so a move of about 2.8 s is not reported missing.
#[test]
fn a_slow_move_in_a_capture_without_times_is_not_missing() {
    let dir = scratch("untimed");
    let steps = vec![
        (
            0,
            enc(
                "MOD_SET_CHANENABLESTATE",
                &[("chan_ident", 1), ("enable_state", 1)],
            ),
        ),
        // 3 mm at 2 mm/s, 1.5 mm/s²: about 2.8 s.
        (
            20 * MS,
            enc(
                "MOT_MOVE_RELATIVE",
                &[("chan_ident", 1), ("relative_distance", 103_665)],
            ),
        ),
    ];
    let timed = dir.join("timed.pcapng");
    record_virtual(
        &mut AptSim::new(AptModel::Kdc101),
        &steps,
        10_000 * MS,
        &timed,
    );
    let s = load(&timed);
    let at = |name: &str| {
        s.msgs
            .iter()
            .find(|m| m.name == name)
            .and_then(|m| m.ts_ns)
            .unwrap_or_else(|| panic!("no {name} in {:#?}", s.msgs))
    };
    let took = at("MOT_MOVE_COMPLETED") - at("MOT_MOVE_RELATIVE");
    assert!(took > 2_300 * MS, "the move takes {took} ns");
    // The same bytes without times or directions.
    let raw = dir.join("untimed.bin");
    let mut w = create(raw.to_str().unwrap(), Format::Raw, true).unwrap();
    for m in &s.msgs {
        w.chunk(&Chunk {
            ts_ns: None,
            dir: Direction::Unknown,
            stream: 0,
            bytes: &m.raw,
        })
        .unwrap();
    }
    w.finish().unwrap();
    let script = load(&raw);
    assert!(!script.has_times());
    let mv = script
        .msgs
        .iter()
        .find(|m| m.name == "MOT_MOVE_RELATIVE")
        .unwrap();
    assert_eq!(
        aptscope_replay::host::reply_allowance_ns(Proto::Apt, mv, None),
        120_000 * MS
    );
    assert_eq!(
        aptscope_replay::host::reply_allowance_ns(Proto::Apt, mv, Some(5 * MS)),
        5 * MS
    );
    let bench = SimOnPty::start(AptSim::new(AptModel::Kdc101));
    let mut link =
        Link::open_port(&bench.path, LineSettings::for_proto(Proto::Apt, None, None)).unwrap();
    // As `aptscope replay` runs a capture without times: each message after its replies.
    let opts = HostOptions {
        wait_replies: true,
        ..HostOptions::default()
    };
    let o = run_host(
        &script,
        &Selection::default(),
        &opts,
        &mut link,
        None,
        &mut |_| {},
        &mut || None,
    )
    .unwrap();
    let r = &o.report;
    assert_eq!(r.missing, 0, "{}", r.text(None));
    assert!(
        r.matched >= 1 && o.duration_ns > 2_300 * MS,
        "{} after {} ns",
        r.text(None),
        o.duration_ns
    );
}
