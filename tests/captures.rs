//! End-to-end: every capture format in `samples/` decodes, through the binary, to the same
//! frames; USB captures of the FTDI chip decode like the serial capture they were made from;
//! `info` and `convert` on real files.

use serde_json::Value;
use std::process::Command;

fn run(args: &[&str]) -> (String, String, bool) {
    let o = Command::new(env!("CARGO_BIN_EXE_aptscope"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run aptscope");
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
        o.status.success(),
    )
}

/// (name, dir, fields) of a frame.
type Sig = (String, String, String);

/// The signature of every frame, the frame records, and every diagnostic (`kind@offset`).
fn frames(file: &str) -> (Vec<Sig>, Vec<Value>, Vec<String>) {
    let (out, err, ok) = run(&["decode", "--json", file]);
    assert!(ok, "{file}: {err}");
    let recs: Vec<Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON"))
        .collect();
    let frames: Vec<Value> = recs
        .iter()
        .filter(|r| r["type"] == "frame")
        .cloned()
        .collect();
    let sig = frames
        .iter()
        .map(|f| {
            (
                f["name"].to_string(),
                f["dir"].to_string(),
                f["fields"].to_string(),
            )
        })
        .collect();
    let diags = recs
        .iter()
        .flat_map(|r| r["diag"].as_array().cloned().unwrap_or_default())
        .map(|d| format!("{}@{}", d["kind"], d["offset"]))
        .collect();
    (sig, frames, diags)
}

const KDC101: &[&str] = &[
    "samples/kdc101-session.bin",
    "samples/kdc101-session.hex",
    "samples/kdc101-session.xxd.txt",
    "samples/kdc101-session.hexdump.txt",
    "samples/kdc101-session.socat.log",
    "samples/kdc101-session.jpnevulator.txt",
    "samples/kdc101-session.interceptty.log",
    "samples/kdc101-session.pcapng",
    "samples/kdc101-session.pcap",
    "samples/kdc101-session.mcap",
    "samples/kdc101-session.usbmon.pcap",
    "samples/kdc101-session.usbpcap.pcap",
];

#[test]
fn every_format_of_the_kdc101_session_decodes_to_the_same_frames() {
    let (reference, _, _) = frames(KDC101[0]);
    assert_eq!(reference.len(), 20);
    for f in KDC101 {
        let (sig, _, diags) = frames(f);
        assert!(diags.is_empty(), "{f}: {diags:?}");
        assert_eq!(sig, reference, "{f} decodes differently");
    }
}

#[test]
fn usb_capture_decodes_like_the_serial_capture_it_was_made_from() {
    let (_, serial, _) = frames("samples/kdc101-session.pcapng");
    let (_, usb, _) = frames("samples/kdc101-session.usbmon.pcap");
    assert_eq!(serial.len(), usb.len());
    for (a, b) in serial.iter().zip(&usb) {
        assert_eq!(a["raw"], b["raw"]);
        assert_eq!(a["dir"], b["dir"]);
        // usbmon records µs; the serial sample's times are whole µs.
        assert_eq!(a["ts_ns"], b["ts_ns"]);
    }
    let (out, _, _) = run(&["info", "--json", "samples/kdc101-session.usbmon.pcap"]);
    let i: Value = serde_json::from_str(out.trim()).expect("JSON");
    assert_eq!(i["streams"][0]["name"], "usb 1:7 0403:faf0");
    assert_eq!(i["streams"][0]["settings"], "115200 8N1 RTS/CTS");
}

#[test]
fn directions_and_times_reach_the_timeline() {
    let (_, f, _) = frames("samples/kdc101-session.socat.log");
    assert_eq!(f[0]["dir"], "h2d");
    assert_eq!(f[1]["dir"], "d2h");
    let t0 = f[0]["ts_ns"].as_u64().expect("ts");
    let t1 = f[1]["ts_ns"].as_u64().expect("ts");
    assert!(t1 > t0);
    let (text, _, _) = run(&["decode", "samples/kdc101-session.pcapng"]);
    let line = text
        .lines()
        .find(|l| l.contains("MOT_MOVE_HOMED"))
        .expect("homed");
    assert!(
        line.split_whitespace()
            .nth(1)
            .is_some_and(|t| t.contains('.')),
        "a time column: {line}"
    );
}

#[test]
fn info_reports_counts_per_direction_and_times() {
    let (out, err, ok) = run(&["info", "--json", "samples/kdc101-session.pcapng"]);
    assert!(ok, "{err}");
    let i: Value = serde_json::from_str(out.trim()).expect("JSON");
    assert_eq!(i["proto"], "apt");
    assert_eq!(i["lanes"][0]["dir"], "h2d");
    assert_eq!(i["lanes"][0]["frames"], 7);
    assert_eq!(i["lanes"][1]["dir"], "d2h");
    assert_eq!(i["lanes"][1]["frames"], 13);
    assert_eq!(i["lanes"][1]["bytes"], 302);
    assert_eq!(i["file_diags"], 0);
    assert!(i["duration_s"].as_f64().is_some_and(|d| d > 2.0));
}

#[test]
fn convert_is_lossless_and_never_overwrites_without_force() {
    let dir = std::env::temp_dir();
    let out = dir.join(format!("aptscope-cli-{}.pcapng", std::process::id()));
    let out_s = out.to_str().expect("utf-8");
    let _ = std::fs::remove_file(&out);
    let (_, err, ok) = run(&["convert", "samples/kdc101-session.socat.log", out_s]);
    assert!(ok && !err.contains("cannot carry"), "{err}");
    let (_, err, ok) = run(&["convert", "samples/kdc101-session.socat.log", out_s]);
    assert!(!ok && err.contains("--force"), "{err}");
    let (_, err, ok) = run(&[
        "convert",
        "--force",
        "samples/kdc101-session.socat.log",
        out_s,
    ]);
    assert!(ok, "{err}");
    let (a, fa, _) = frames("samples/kdc101-session.socat.log");
    let (b, fb, _) = frames(out_s);
    assert_eq!(a, b);
    for (x, y) in fa.iter().zip(&fb) {
        assert_eq!(x["ts_ns"], y["ts_ns"]);
    }
    // To raw bytes: it says what it cannot carry.
    let raw = dir.join(format!("aptscope-cli-{}.bin", std::process::id()));
    let (_, err, ok) = run(&["convert", "--force", out_s, raw.to_str().expect("utf-8")]);
    assert!(
        ok && err.contains("raw cannot carry: times (21 chunk(s) had one)"),
        "{err}"
    );
    assert_eq!(
        std::fs::read(&raw).expect("raw"),
        std::fs::read("samples/kdc101-session.bin").expect("bin")
    );
    let _ = std::fs::remove_file(out);
    let _ = std::fs::remove_file(raw);
}

#[test]
fn damaged_captures_report_file_offsets_and_keep_the_rest() {
    let dir = std::env::temp_dir();
    let p = dir.join(format!("aptscope-cut-{}.pcapng", std::process::id()));
    let full = std::fs::read("samples/kdc101-session.pcapng").expect("sample");
    std::fs::write(&p, &full[..full.len() - 7]).expect("write");
    let (out, _, ok) = run(&["decode", "--json", p.to_str().expect("utf-8")]);
    assert!(ok);
    let recs: Vec<Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON"))
        .collect();
    let input: Vec<&Value> = recs.iter().filter(|r| r["type"] == "input").collect();
    assert_eq!(input.len(), 1);
    assert_eq!(input[0]["diag"][0]["kind"], "truncated_record");
    assert_eq!(recs.iter().filter(|r| r["type"] == "frame").count(), 19);
    let _ = std::fs::remove_file(p);
}
