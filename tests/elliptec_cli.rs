//! End-to-end: `aptscope messages --proto elliptec` and `aptscope encode --proto elliptec`,
//! run through the binary.

use serde_json::Value;
mod common;

use common::aptscope;

const CODES: &[&str] = &[
    "in", "IN", "gs", "GS", "us", "re", "ca", "i1", "I1", "f1", "b1", "e1", "h1", "s1", "c1", "C1",
    "is", "i2", "I2", "f2", "b2", "e2", "h2", "s2", "c2", "C2", "ho", "ma", "mr", "go", "HO", "so",
    "gj", "GJ", "sj", "fw", "bw", "gp", "PO", "gv", "GV", "sv", "BS", "BO", "ga",
];

#[test]
fn messages_lists_every_elliptec_command() {
    let (out, err, ok) = aptscope(&["messages", "--proto", "elliptec"], None);
    assert!(ok, "{err}");
    for code in CODES {
        assert!(
            out.lines().any(|l| l.starts_with(&format!("{code}  "))),
            "{code} missing:\n{out}"
        );
    }
    let ma = out.lines().find(|l| l.starts_with("ma  ")).expect("ma");
    for part in ["MOVE_ABSOLUTE", "h2d", "motion", "10 s", "→ PO,GS"] {
        assert!(ma.contains(part), "{part} not in {ma:?}");
    }
    let po = out.lines().find(|l| l.starts_with("PO  ")).expect("PO");
    assert!(po.contains("answers ho,ma,mr,fw,bw,gp"), "{po}");
    // Verbose: the doc line and the fields with widths, kinds and units.
    let (out, _, ok) = aptscope(&["messages", "--proto", "elliptec", "-v"], None);
    assert!(ok);
    assert!(out.contains("Move to an absolute position in pulses (p.33)"));
    let field = out
        .lines()
        .skip_while(|l| !l.starts_with("ma  "))
        .nth(2)
        .expect("ma's field line");
    for part in ["position", "@0", "8c", "pulses"] {
        assert!(field.contains(part), "{part} not in {field:?}");
    }
}

#[test]
fn messages_json_describes_every_elliptec_command() {
    let (out, err, ok) = aptscope(&["messages", "--proto", "elliptec", "--json"], None);
    assert!(ok, "{err}");
    let recs: Vec<Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
        .collect();
    let cmds: Vec<&Value> = recs.iter().filter(|r| r["type"] == "cmd").collect();
    let codes: Vec<&str> = cmds.iter().filter_map(|r| r["code"].as_str()).collect();
    assert_eq!(codes, CODES);
    assert!(cmds.iter().all(|r| r["proto"] == "ell"));
    let ma = cmds.iter().find(|r| r["code"] == "ma").expect("ma");
    assert_eq!(ma["class"], "motion");
    assert_eq!(ma["timeout_ms"], 10_000);
    assert_eq!(ma["replies"], serde_json::json!(["PO", "GS"]));
    assert_eq!(ma["interim"], serde_json::json!(["GS"]));
    assert_eq!(
        ma["fields"],
        serde_json::json!([{"name": "position", "offset": 0, "width": 8, "kind": "position",
            "unit": "pulses", "doc": ma["fields"][0]["doc"]}])
    );
    let c1 = cmds.iter().find(|r| r["code"] == "C1").expect("C1");
    assert_eq!(c1["binary"], true);
    assert_eq!(c1["data_len"], 522);
    assert_eq!(c1["answers"], serde_json::json!(["c1"]));
    let gs = cmds.iter().find(|r| r["code"] == "gs").expect("gs");
    assert_eq!(gs["timeout_ms"], 2000);
    assert_eq!(gs["class"], "query");
    assert!(recs
        .iter()
        .any(|r| r["type"] == "status" && r["name"] == "OUT_OF_RANGE"));
}

#[test]
fn messages_without_proto_lists_both_apt_first() {
    let (plain, _, ok) = aptscope(&["messages"], None);
    assert!(ok);
    let (apt, _, ok2) = aptscope(&["messages", "--proto", "apt"], None);
    assert!(ok2);
    let (ell, _, ok3) = aptscope(&["messages", "--proto", "elliptec"], None);
    assert!(ok3);
    assert_eq!(plain, format!("{apt}{ell}"));
    assert!(
        plain.starts_with("0x"),
        "{}",
        &plain[..plain.len().min(200)]
    );
    assert!(apt.contains("MOT_MOVE_ABSOLUTE") && !apt.contains("GET_CURRENT_CURVE"));
    assert!(plain.contains("GET_CURRENT_CURVE"));
}

#[test]
fn encode_builds_elliptec_commands_that_decode_back() {
    let enc = |args: &[&str]| {
        let mut a = vec!["encode", "--proto", "elliptec"];
        a.extend_from_slice(args);
        let (out, err, ok) = aptscope(&a, None);
        assert!(ok, "{args:?}: {err}");
        out.trim_end().to_string()
    };
    assert_eq!(enc(&["0", "ma", "position=1000"]), "0ma000003E8");
    assert_eq!(enc(&["A", "mr", "position=-0x1000"]), "AmrFFFFF000");
    assert_eq!(enc(&["0", "ho", "direction=CCW"]), "0ho1");
    assert_eq!(enc(&["0", "gs"]), "0gs");
    assert_eq!(enc(&["2", "GS", "status=BUSY"]), "2GS09\\r\\n");
    assert_eq!(
        enc(&["0", "MOVE_RELATIVE", "position=0x800"]),
        "0mr00000800"
    );
    // The binary curve comes out as hex.
    let curve = "00".repeat(522);
    let c1 = enc(&["0", "C1", &format!("curve={curve}")]);
    assert!(
        c1.starts_with("30 43 31 00 00") && c1.ends_with("00 0D 0A"),
        "{c1}"
    );
    // What encode prints, decode reads back.
    let text = enc(&["3", "ma", "position=-5000"]);
    let (out, err, ok) = aptscope(
        &["decode", "--proto", "elliptec", "--json", "-F", "raw", "-"],
        Some(text.as_bytes()),
    );
    assert!(ok, "{err}");
    let r: Value = out
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .find(|r: &Value| r["type"] == "frame")
        .expect("a frame");
    assert_eq!(r["cmd"], "ma");
    assert_eq!(r["addr"], "3");
    assert_eq!(r["fields"]["position"], -5000);
    assert_eq!(r["diag"], serde_json::json!([]));
}

#[test]
fn encode_errors_are_named_and_fail() {
    let fail = |args: &[&str]| {
        let mut a = vec!["encode", "--proto", "elliptec"];
        a.extend_from_slice(args);
        let (out, err, ok) = aptscope(&a, None);
        assert!(!ok, "{args:?} succeeded: {out}");
        assert!(out.is_empty(), "{out}");
        err
    };
    let e = fail(&["0", "mv", "position=1"]);
    assert!(
        e.contains("no Elliptec command `mv`") && e.contains("did you mean"),
        "{e}"
    );
    let e = fail(&["0", "ma", "pos=1"]);
    assert!(
        e.contains("no field `pos`") && e.contains("its fields: position"),
        "{e}"
    );
    let e = fail(&["0", "sv", "velocity=200"]);
    assert!(e.contains("velocity") && e.contains("out of range"), "{e}");
    let e = fail(&["0", "ma"]);
    assert!(e.contains("needs `position=VALUE`"), "{e}");
    let e = fail(&["X", "gs"]);
    assert!(e.contains("not a bus address"), "{e}");
    let e = fail(&["0", "ma", "position"]);
    assert!(e.contains("not name=value"), "{e}");
    let e = fail(&["0"]);
    assert!(e.contains("usage"), "{e}");
    let e = fail(&["0", "gs", "--dest", "bay1"]);
    assert!(e.contains("APT options"), "{e}");
}
