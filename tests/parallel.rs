//! One file on several cores (`decode -j N` with fewer files than N): the decode chain on one
//! thread, rendering on the others. What it writes — standard output, standard error, the exit
//! status — is byte for byte what `-j 1` writes, for every sample (every container) and for
//! random streams cut into many batches: APT and Elliptec, garbage between frames, a truncated
//! last frame, requests answered in the next batch.

mod common;

use aptscope_dissector::synth::{self, Rng};
use std::path::PathBuf;
use std::process::{Command, Stdio};

/// What a run wrote: standard output, standard error, exit code.
type Run = (Vec<u8>, String, Option<i32>);

/// Run `aptscope` with `args`, its batches of `batch` records (`None`: the default).
fn run(args: &[&str], batch: Option<usize>) -> Run {
    let mut c = Command::new(env!("CARGO_BIN_EXE_aptscope"));
    c.args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdin(Stdio::null());
    if let Some(b) = batch {
        c.env("APTSCOPE_BATCH_RECORDS", b.to_string());
    }
    let o = c.output().expect("run aptscope");
    (
        o.stdout,
        String::from_utf8_lossy(&o.stderr).into_owned(),
        o.status.code(),
    )
}

/// Every way of decoding one file that the render threads take over: text, NDJSON, and a
/// display filter that keeps some records (in text and NDJSON).
const MODES: [&[&str]; 4] = [
    &[],
    &["--json"],
    &[
        "-Y",
        "apt.name ~ \"GET\" || ell.cmd == \"PO\" || unpaired || diag",
    ],
    &["--json", "-Y", "dir == device || n > 100"],
];

/// `-j 2` and `-j 3` against `-j 1` on `file`, in every mode, with batches of `batch` records;
/// returns the `-j 1` output of the first mode.
fn same_as_one(file: &str, batch: Option<usize>) -> Vec<u8> {
    let mut first = vec![];
    for mode in MODES {
        let mut a = vec!["decode"];
        a.extend_from_slice(mode);
        a.extend(["-j", "1", file]);
        let at = a.len() - 2;
        let one = run(&a, batch);
        assert!(!one.1.contains("bad filter"), "{}", one.1);
        for j in ["2", "3"] {
            a[at] = j;
            let many = run(&a, batch);
            assert!(
                one == many,
                "{file} {mode:?} -j {j} (batches of {batch:?}): {} vs {} bytes out, \
                 stderr {:?} vs {:?}, exit {:?} vs {:?}",
                one.0.len(),
                many.0.len(),
                one.1,
                many.1,
                one.2,
                many.2
            );
        }
        if first.is_empty() {
            first = one.0;
        }
    }
    first
}

/// Every capture in samples/ and samples/sessions/.
fn samples() -> Vec<String> {
    let mut files = vec![];
    for dir in ["samples", "samples/sessions"] {
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
        for e in std::fs::read_dir(root.join(dir)).expect("samples dir") {
            let p = e.expect("entry").path();
            let name = p.file_name().and_then(|n| n.to_str()).unwrap_or_default();
            let script = name.ends_with(".sh") || name.ends_with(".py") || name == "README.md";
            if p.is_file() && !script {
                files.push(format!("{dir}/{name}"));
            }
        }
    }
    files.sort();
    files
}

#[test]
fn every_sample_decodes_the_same_on_several_cores() {
    let files = samples();
    assert!(files.len() > 15, "{files:?}");
    for f in &files {
        // Batches of 1 and 7: every record boundary a batch boundary, batches cut inside
        // every exchange (the default, one batch for a sample, is in the next test).
        for batch in [Some(1), Some(7)] {
            same_as_one(f, batch);
        }
    }
}

/// A random Elliptec bus: commands to modules 0–2, their replies (some missing, some late,
/// some unsolicited), garbage between frames; ASCII as the samples hold it.
fn elliptec_stream(seed: u64, ops: usize) -> Vec<u8> {
    let mut r = Rng(seed);
    let mut out = vec![];
    let hex8 = |r: &mut Rng| format!("{:08X}", r.below(1 << 32));
    for _ in 0..ops {
        let a = char::from(b'0' + r.below(3) as u8);
        let (cmd, reply) = match r.below(6) {
            0 => (
                format!("{a}in"),
                format!("{a}IN0E1140028420200117016800023000"),
            ),
            1 => (format!("{a}gs"), format!("{a}GS0{}", r.below(10))),
            2 => {
                let p = hex8(&mut r);
                (format!("{a}ma{p}"), format!("{a}PO{p}"))
            }
            3 => (format!("{a}gp"), format!("{a}PO{}", hex8(&mut r))),
            4 => (format!("{a}ho0"), format!("{a}GS09")),
            _ => (format!("{a}gv"), format!("{a}GV{:02X}", r.below(100))),
        };
        match r.below(10) {
            // No reply.
            0 => out.extend(cmd.as_bytes()),
            // A reply nobody asked for.
            1 => out.extend(reply.as_bytes()),
            // Garbage between frames.
            2 => {
                out.extend(cmd.as_bytes());
                out.extend(b"#~!zz");
                out.extend(reply.as_bytes());
            }
            _ => {
                out.extend(cmd.as_bytes());
                out.extend(reply.as_bytes());
            }
        }
    }
    out
}

/// APT: random frames of every form, with garbage, its last frame cut short.
fn apt_stream(seed: u64, frames: usize) -> Vec<u8> {
    let table = aptscope_dissector::Table::global();
    let mut s = synth::stream(table, seed, frames, true);
    // Requests and their replies, so that pairs span batches.
    let req = [0x05, 0x00, 0x00, 0x00, 0x50, 0x01];
    let mut r = Rng(seed);
    let mut at = 0;
    while at < s.len() {
        at += 500 + r.below(3000) as usize;
        // Inserted anywhere: sometimes inside a frame, which the framer resyncs past.
        let at_ = at.min(s.len());
        s.splice(at_..at_, req);
    }
    // A truncated last frame.
    s.extend_from_slice(&[0x64, 0x04, 0x0e, 0x00, 0x81, 0x50, 0x01, 0x00]);
    s
}

#[test]
fn random_streams_decode_the_same_on_several_cores() {
    let dir = common::Scratch::new("parallel-random");
    let mut files = vec![];
    for seed in 1..=2u64 {
        let f = dir.join(&format!("apt{seed}.bin"));
        std::fs::write(&f, apt_stream(seed, 15_000)).expect("write");
        files.push(f);
        let f = dir.join(&format!("ell{seed}.txt"));
        std::fs::write(&f, elliptec_stream(seed, 8_000)).expect("write");
        files.push(f);
    }
    // The APT streams in containers too: pcapng and MCAP (records with times and
    // directions), converted by the binary.
    let raw = files[0].to_str().expect("utf-8").to_string();
    for ext in ["pcapng", "mcap"] {
        let f = dir.join(&format!("apt1.{ext}"));
        let out = f.to_str().expect("utf-8");
        let (_, err, code) = run(&["convert", &raw, out], None);
        assert_eq!(code, Some(0), "convert to {ext}: {err}");
        files.push(f);
    }
    for f in &files {
        let f = f.to_str().expect("utf-8");
        // Default batches (thousands of records: several of them), and batches of 13.
        for batch in [None, Some(13)] {
            let out = same_as_one(f, batch);
            assert!(out.len() > 200_000, "{f}: {} bytes", out.len());
        }
    }
}

/// Where the records come from does not change what the workers see: a file among others
/// with spare cores (two files, `-j 4`) is rendered by two threads each, and the output is
/// still that of `-j 1`.
#[test]
fn fewer_files_than_jobs_render_inside_each_file() {
    let dir = common::Scratch::new("parallel-two");
    let a = dir.join("a.bin");
    let b = dir.join("b.txt");
    std::fs::write(&a, apt_stream(7, 20_000)).expect("write");
    std::fs::write(&b, elliptec_stream(7, 10_000)).expect("write");
    let (a, b) = (a.to_str().expect("utf-8"), b.to_str().expect("utf-8"));
    for mode in MODES {
        let mut args = vec!["decode"];
        args.extend_from_slice(mode);
        args.extend(["-j", "1", a, "samples/damaged.bin", b]);
        let one = run(&args, None);
        assert_eq!(one.2, Some(0), "{}", one.1);
        for j in ["4", "8"] {
            let at = args.len() - 4;
            args[at] = j;
            assert!(one == run(&args, Some(100)), "{mode:?} -j {j}");
        }
    }
}

/// A reader that closes the pipe early (`| head -c N`): `-j 2` leaves off as `-j 1` does —
/// the same first bytes, nothing on standard error, exit status 0 — wherever the pipe closes
/// (inside the first block, inside a later one, past a rendered batch).
#[test]
fn a_closed_pipe_ends_several_cores_as_one() {
    use std::io::Read;
    let dir = common::Scratch::new("parallel-pipe");
    let f = dir.join("apt.bin");
    std::fs::write(&f, apt_stream(3, 60_000)).expect("write");
    let f = f.to_str().expect("utf-8");
    let whole = run(&["decode", "--json", "-j", "1", f], None).0;
    assert!(whole.len() > 4_000_000, "{} bytes", whole.len());
    for n in [10, 70_000, 1_000_000] {
        for j in ["1", "2"] {
            let mut child = Command::new(env!("CARGO_BIN_EXE_aptscope"))
                .args(["decode", "--json", "-j", j, f])
                .stdin(Stdio::null())
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .expect("run aptscope");
            let mut got = vec![0; n];
            child
                .stdout
                .take()
                .expect("stdout")
                .read_exact(&mut got)
                .expect("read");
            // The pipe is closed here; what is still to be written meets a broken pipe.
            let o = child.wait_with_output().expect("wait");
            assert!(
                got[..] == whole[..n],
                "-j {j}, {n} bytes: not the first bytes"
            );
            assert_eq!(
                (String::from_utf8_lossy(&o.stderr).as_ref(), o.status.code()),
                ("", Some(0)),
                "-j {j}, pipe closed after {n} bytes"
            );
        }
    }
}
