//! Pairing, display filters and statistics through the binary, checked against hand counts of
//! the samples.

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

fn records(args: &[&str]) -> Vec<Value> {
    let (out, err, ok) = run(args);
    assert!(ok, "{err}");
    out.lines()
        .map(|l| serde_json::from_str::<Value>(l).expect("JSON"))
        .filter(|r| r["type"] != "detect" && r["type"] != "stream")
        .collect()
}

const KDC: &str = "samples/kdc101-session.pcapng";

#[test]
fn filters_select_what_the_hand_count_says() {
    let n = |f: &str| records(&["decode", "--json", "-Y", f, KDC]).len();
    assert_eq!(n(r#"apt.name == "MOT_GET_DCSTATUSUPDATE""#), 9);
    assert_eq!(n("dir == device"), 13);
    assert_eq!(n("dir == host && apt.chan == 1"), 4);
    assert_eq!(
        n(r#"apt.name ~ "^MOT_MOVE_" || apt.name == HW_REQ_INFO"#),
        5
    );
    assert_eq!(n("apt.fields.status_bits contains HOMED"), 6);
    assert_eq!(
        n("apt.fields.position > 100000 && !(apt.name == MOT_MOVE_COMPLETED)"),
        3
    );
    assert_eq!(n("latency > 1s"), 1);
    assert_eq!(n("latency >= 2ms && latency < 3ms"), 2);
    assert_eq!(n("paired"), 4);
    assert_eq!(n("apt.dst == host"), 13);
    assert_eq!(n("apt.dst == 0x50"), 7);
    assert_eq!(n("diag"), 0);
    // Text output is filtered the same way and keeps the record numbers.
    let (out, _, _) = run(&["decode", "-Y", "paired", KDC]);
    let numbers: Vec<&str> = out
        .lines()
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    assert_eq!(numbers, ["2", "5", "12", "19"]);
}

#[test]
fn unpaired_and_diag_on_damaged_and_rack_samples() {
    let un = records(&[
        "decode",
        "--json",
        "-Y",
        "unpaired",
        "samples/bsc203-rack.hex",
    ]);
    // REQ_STATUSUPDATE to each bay goes unanswered; MOVE_STOPPED answers the move and the stop.
    let refs: Vec<u64> = un.iter().filter_map(|r| r["ref"].as_u64()).collect();
    assert_eq!(refs, [8, 10, 12]);
    let d = records(&["decode", "--json", "-Y", "diag", "samples/damaged.bin"]);
    assert_eq!(d.len(), 9);
    let t = records(&[
        "decode",
        "--json",
        "-Y",
        r#"diag.kind == "truncated""#,
        "samples/damaged.bin",
    ]);
    assert_eq!(t.len(), 1);
    assert_eq!(t[0]["offset"], 55);
}

#[test]
fn filter_errors_point_at_the_column() {
    let (_, err, ok) = run(&["decode", "-Y", "apt.name == ", KDC]);
    assert!(!ok);
    assert!(err.contains("column 13"), "{err}");
    assert!(err.contains("            ^"), "{err}");
    let (_, err, ok) = run(&["decode", "-Y", "(dir == host", KDC]);
    assert!(!ok && err.contains("column"), "{err}");
}

#[test]
fn stats_match_the_hand_count() {
    let (out, err, ok) = run(&["stats", "--json", KDC]);
    assert!(ok, "{err}");
    let s: Value = serde_json::from_str(out.trim()).expect("JSON");
    assert_eq!(s["frames"]["count"], 20);
    assert_eq!(s["frames"]["bytes"], 350);
    assert_eq!(s["messages"]["apt MOT_GET_DCSTATUSUPDATE"]["count"], 9);
    assert_eq!(s["messages"]["apt MOT_GET_DCSTATUSUPDATE"]["bytes"], 180);
    assert_eq!(
        s["messages"]["apt MOT_MOVE_HOME"]["latency_ms"]["median"],
        2000.0
    );
    assert_eq!(
        s["messages"]["apt MOT_MOVE_ABSOLUTE"]["latency_ms"]["max"],
        502.0
    );
    assert_eq!(s["directions"]["h2d"]["count"], 7);
    assert_eq!(s["directions"]["d2h"]["bytes"], 302);
    assert_eq!(s["addresses"]["apt usb → host"]["count"], 13);
    let rate: Vec<(f64, u64)> = s["rate"]
        .as_array()
        .expect("rate")
        .iter()
        .map(|b| (b[0].as_f64().unwrap_or(-1.0), b[1].as_u64().unwrap_or(0)))
        .collect();
    assert_eq!(rate, [(0.0, 11), (1.0, 0), (2.0, 9)]);
    let (out, _, _) = run(&["stats", "--json", "samples/damaged.bin"]);
    let s: Value = serde_json::from_str(out.trim()).expect("JSON");
    assert_eq!(
        s["diags"],
        serde_json::json!({"absurd_length":1,"garbage":2,"length_mismatch":1,"no_reply":3,"truncated":1,"unknown_id":1})
    );
    // Filtered statistics count only what the filter selects.
    let (out, _, _) = run(&["stats", "--json", "-Y", "dir == host", KDC]);
    let s: Value = serde_json::from_str(out.trim()).expect("JSON");
    assert_eq!(s["frames"]["count"], 7);
}

#[test]
fn a_shorter_reply_timeout_flags_slow_replies() {
    // Homing takes 2 s and the absolute move 0.5 s: with 100 ms both requests expire, and
    // their completions arrive unsolicited.
    let recs = records(&["decode", "--json", "--timeout", "100ms", KDC]);
    let late: Vec<u64> = recs
        .iter()
        .filter(|r| r["type"] == "diag")
        .filter_map(|r| r["ref"].as_u64())
        .collect();
    assert_eq!(late, [7, 13]);
    let unsolicited: Vec<&str> = recs
        .iter()
        .filter(|r| {
            r["diag"]
                .as_array()
                .is_some_and(|d| d.iter().any(|x| x["kind"] == "unsolicited"))
        })
        .filter_map(|r| r["name"].as_str())
        .collect();
    assert_eq!(unsolicited, ["MOT_MOVE_HOMED", "MOT_MOVE_COMPLETED"]);
    let (_, err, ok) = run(&["decode", "--timeout", "1x", KDC]);
    assert!(!ok && err.contains("unknown unit"), "{err}");
}

/// Every name a record can hold is a name filters accept: each key of every record `decode
/// --json` writes for the samples (with and without a stage), under its protocol prefix, and
/// each field under `fields.` and `phys.`. (Filters reject names no record has.)
#[test]
fn every_key_decode_writes_is_a_filter_name() {
    use aptscope_dissector::filter::Filter;
    let mut names = std::collections::BTreeSet::new();
    for f in [
        "samples/kdc101-session.pcapng",
        "samples/damaged.bin",
        "samples/elliptec-bus.txt",
        "samples/sessions/bsc203.pcapng",
        "samples/sessions/kpz101.pcapng",
        "samples/sessions/laser-tec-quad.pcapng",
        "samples/sessions/elliptec.pcapng",
        "samples/sessions/damaged.pcapng",
    ] {
        for extra in [&[][..], &["--stage", "MTS25-Z8"][..]] {
            let mut args = vec!["decode", "--json"];
            args.extend_from_slice(extra);
            args.push(f);
            for r in records(&args) {
                let Some(p) = r["proto"].as_str().filter(|p| *p == "apt" || *p == "ell") else {
                    continue;
                };
                let Some(obj) = r.as_object() else { continue };
                for (k, v) in obj {
                    names.insert(format!("{p}.{k}"));
                    if k == "fields" || k == "phys" {
                        for f in v.as_object().into_iter().flat_map(|o| o.keys()) {
                            names.insert(format!("{p}.{k}.{f}"));
                            if k == "fields" {
                                names.insert(format!("{p}.{f}"));
                            }
                        }
                    }
                }
            }
        }
    }
    assert!(names.len() > 100, "{names:?}");
    let rejected: Vec<String> = names
        .iter()
        .filter_map(|n| Filter::parse(n).err().map(|e| format!("{n}: {e}")))
        .collect();
    assert!(rejected.is_empty(), "{rejected:#?}");
}
