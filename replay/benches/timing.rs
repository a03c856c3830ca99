//! Send-time accuracy of the replay scheduler on pseudo-terminals: how late each message leaves
//! after its deadline (p50, p99, max), and whether a long replay drifts.
//!
//! `cargo bench -p aptscope-replay --bench timing` (add `-- --quick` for a short run). Two
//! benches: a dense stream of 2 ms gaps to a port that only reads, and the KDC101 session
//! sample looped against the simulator with `--wait-replies` (replies and status updates
//! arriving while waiting). The error is measured when the write has returned.

use aptscope_capture::live::serial::LineSettings;
use aptscope_capture::live::sim::{serve_pty, stop_pair, AptModel, AptSim, Pty};
use aptscope_capture::open::{create, Format, OpenOptions};
use aptscope_capture::{Chunk, Direction, StreamInfo};
use aptscope_dissector::detect::Proto;
use aptscope_replay::{run_host, HostOptions, Link, Outcome, Script, Selection};
use std::io::Read;
use std::path::Path;
use std::thread;

const MS: u64 = 1_000_000;

fn report(what: &str, o: &Outcome) {
    let p = |q: f64| o.timing.percentile(q).unwrap_or(0) as f64 / 1e3;
    println!(
        "{what:<44} {:>6} sends  p50 {:>7.1} µs  p99 {:>7.1} µs  max {:>8.1} µs  over {:.1} s",
        o.timing.count(),
        p(50.0),
        p(99.0),
        p(100.0),
        o.duration_ns as f64 / 1e9
    );
}

/// `n` MOD_IDENTIFY messages (no reply expected) `gap_ns` apart, as a pcapng.
fn dense_capture(path: &Path, n: u64, gap_ns: u64) {
    let mut w = create(path.to_str().unwrap_or_default(), Format::PcapNg, true).expect("create");
    w.stream(&StreamInfo {
        id: 0,
        name: "bench".into(),
        settings: None,
    })
    .expect("stream");
    let identify = [0x23, 0x02, 0x01, 0x00, 0x50, 0x01];
    for i in 0..n {
        w.chunk(&Chunk {
            ts_ns: Some(1_700_000_000_000_000_000 + i * gap_ns),
            dir: Direction::HostToDevice,
            stream: 0,
            bytes: &identify,
        })
        .expect("chunk");
    }
    w.finish().expect("finish");
}

fn replay(script: &Script, port: &Path, loops: u32, wait_replies: bool) -> Outcome {
    let mut link = Link::open_port(port, LineSettings::for_proto(Proto::Apt, None, None))
        .expect("open the pseudo-terminal");
    let opts = HostOptions {
        loops,
        wait_replies,
        ..HostOptions::default()
    };
    run_host(
        script,
        &Selection::default(),
        &opts,
        &mut link,
        None,
        &mut |_| {},
        &mut || None,
    )
    .expect("replay")
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let dir = std::env::temp_dir().join(format!("aptscope-timing-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);

    // 1. A dense stream to a port that only reads.
    let n = if quick { 500 } else { 5000 };
    let cap = dir.join("dense.pcapng");
    dense_capture(&cap, n, 2 * MS);
    let script = Script::load(
        cap.to_str().unwrap_or_default(),
        OpenOptions::default(),
        Some(Proto::Apt),
        None,
    )
    .expect("load");
    let pty = Pty::open().expect("pty");
    let path = pty.path().to_path_buf();
    let (master, slave, _) = pty.into_parts();
    let drain = thread::spawn(move || {
        let mut f = std::fs::File::from(master);
        let mut buf = [0u8; 4096];
        let mut got = 0usize;
        let _keep = slave;
        loop {
            match f.read(&mut buf) {
                Ok(0) => break,
                Ok(k) => got += k,
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                    thread::sleep(std::time::Duration::from_micros(200))
                }
                Err(_) => break,
            }
            if got >= (n as usize) * 6 {
                break;
            }
        }
        got
    });
    let o = replay(&script, &path, 1, false);
    report(&format!("{n} messages, 2 ms apart, to a reader"), &o);
    let _ = drain.join();

    // 2. The KDC101 session against the simulator, looped.
    let sample = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../samples/sessions/kdc101.pcapng"
    );
    let script =
        Script::load(sample, OpenOptions::default(), Some(Proto::Apt), None).expect("sample");
    let pty = Pty::open().expect("pty");
    let path = pty.path().to_path_buf();
    let (stop, sig) = stop_pair().expect("pipe");
    let sim = thread::spawn(move || {
        let mut sim = AptSim::new(AptModel::Kdc101);
        let _ = serve_pty(&mut sim, pty, Some(&sig), &[]);
    });
    let loops = if quick { 1 } else { 5 };
    // Waiting for replies: a later pass homes from where the last one ended, which takes
    // longer than the captured homing from 0.
    let o = replay(&script, &path, loops, true);
    report(
        &format!("kdc101 session ×{loops}, --wait-replies, simulator"),
        &o,
    );
    println!(
        "{:<44} {} matched, {} differences",
        "",
        o.report.matched,
        o.report.failures(None)
    );
    stop.stop();
    let _ = sim.join();
    let _ = std::fs::remove_dir_all(&dir);
}
