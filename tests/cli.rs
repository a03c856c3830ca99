//! End-to-end tests: run the `aptscope` binary on the bundled samples and on bad input.

use serde_json::Value;
use std::io::Write;
use std::process::{Command, Stdio};

fn aptscope(args: &[&str], stdin: Option<&[u8]>) -> (String, String, bool) {
    let mut c = Command::new(env!("CARGO_BIN_EXE_aptscope"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run aptscope");
    let mut si = c.stdin.take().expect("stdin");
    if let Some(b) = stdin {
        si.write_all(b).expect("write stdin");
    }
    drop(si);
    let o = c.wait_with_output().expect("wait");
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
        o.status.success(),
    )
}

/// The NDJSON records, without the protocol-detection notice.
fn ndjson(out: &str) -> Vec<Value> {
    out.lines()
        .map(|l| serde_json::from_str::<Value>(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
        .filter(|r| r["type"] != "detect")
        .collect()
}

#[test]
fn decodes_the_kdc101_sample_as_a_timeline() {
    let (out, err, ok) = aptscope(&["decode", "samples/kdc101-session.bin"], None);
    assert!(ok, "{err}");
    assert!(out.starts_with("# protocol apt: detected"), "{out}");
    let lines: Vec<&str> = out.lines().skip(1).collect();
    assert_eq!(lines.len(), 20);
    assert!(lines[0].contains("host → usb") && lines[0].contains("HW_REQ_INFO"));
    assert!(
        lines[1].contains("HW_GET_INFO")
            && lines[1].contains("serial_number=27000123")
            && lines[1].contains("\"KDC101\"")
    );
    assert!(
        lines[12].contains("MOT_MOVE_ABSOLUTE")
            && lines[12].contains("ch1")
            && lines[12].contains("absolute_position=171520 counts")
    );
    assert!(
        !out.contains("!!"),
        "a clean sample has no diagnostics:\n{out}"
    );
}

#[test]
fn json_output_has_the_documented_shape() {
    let (out, err, ok) = aptscope(&["decode", "--json", "samples/kdc101-session.bin"], None);
    assert!(ok, "{err}");
    let recs = ndjson(&out);
    assert_eq!(recs.len(), 20);
    let r = &recs[7];
    assert_eq!(r["n"], 8);
    assert_eq!(r["proto"], "apt");
    assert_eq!(r["type"], "frame");
    assert_eq!(r["offset"], 0x7e);
    assert_eq!(r["len"], 20);
    assert_eq!(r["msgid"], 0x0491);
    assert_eq!(r["name"], "MOT_GET_DCSTATUSUPDATE");
    assert_eq!(r["src"]["name"], "usb");
    assert_eq!(r["dst"]["addr"], 1);
    assert_eq!(r["data_flag"], true);
    assert_eq!(r["channel"], 1);
    assert_eq!(r["fields"]["position"], 0);
    assert_eq!(
        r["fields"]["status_bits"],
        serde_json::json!(["MOVING_CCW", "MOTOR_CONNECTED", "HOMING", "ENABLED"])
    );
    assert_eq!(r["diag"], serde_json::json!([]));
    assert_eq!(r["raw"].as_str().map(str::len), Some(40));
}

#[test]
fn rack_sample_names_bays() {
    let (out, _, ok) = aptscope(
        &["decode", "--json", "--hex", "samples/bsc203-rack.hex"],
        None,
    );
    assert!(ok);
    let recs = ndjson(&out);
    let bay2 = recs
        .iter()
        .find(|r| r["name"] == "MOT_MOVE_STOP")
        .expect("stop");
    assert_eq!(bay2["dst"]["name"], "bay2");
    assert_eq!(bay2["dst"]["bay"], 2);
    assert_eq!(bay2["dst"]["addr"], 0x23);
}

#[test]
fn damaged_sample_reports_every_problem_with_its_offset_and_carries_on() {
    let (out, err, ok) = aptscope(&["decode", "--json", "samples/damaged.bin"], None);
    assert!(ok, "{err}");
    let recs = ndjson(&out);
    let diags: Vec<(String, u64)> = recs
        .iter()
        .flat_map(|r| r["diag"].as_array().cloned().unwrap_or_default())
        .map(|d| {
            (
                d["kind"].as_str().unwrap_or("").to_string(),
                d["offset"].as_u64().unwrap_or(u64::MAX),
            )
        })
        .collect();
    let want = [
        ("garbage", 0),
        ("garbage", 10),
        ("unknown_id", 13),
        ("length_mismatch", 29),
        ("absurd_length", 37),
        ("truncated", 65),
        // Reported at the end: requests that never got their reply.
        ("no_reply", 4),
        ("no_reply", 27),
        ("no_reply", 43),
    ];
    let want: Vec<(String, u64)> = want.iter().map(|(k, o)| (k.to_string(), *o)).collect();
    assert_eq!(diags, want);
    // Nothing lost: records cover the file byte for byte.
    let total: u64 = recs.iter().map(|r| r["len"].as_u64().unwrap_or(0)).sum();
    assert_eq!(
        total,
        std::fs::metadata("samples/damaged.bin")
            .expect("sample")
            .len()
    );
    let names: Vec<&str> = recs.iter().filter_map(|r| r["name"].as_str()).collect();
    assert_eq!(
        names,
        [
            "HW_REQ_INFO",
            "MOD_IDENTIFY",
            "MOT_MOVE_ABSOLUTE",
            "MOT_MOVE_ABSOLUTE",
            "MOT_GET_DCSTATUSUPDATE"
        ]
    );
}

#[test]
fn hex_input_with_a_non_hex_character_is_reported_at_its_text_offset() {
    let (out, _, ok) = aptscope(
        &["decode", "--hex", "--json", "-"],
        Some(b"23 02 01 00 5O 01\n23 02 01 00 50 01\n"),
    );
    assert!(ok);
    let recs = ndjson(&out);
    let input: Vec<(&str, u64)> = recs
        .iter()
        .filter(|r| r["type"] == "input")
        .map(|r| {
            (
                r["diag"][0]["kind"].as_str().unwrap_or(""),
                r["diag"][0]["offset"].as_u64().unwrap_or(0),
            )
        })
        .collect();
    // The `O` is reported, and the `5` it left alone is dropped rather than shifting later bytes.
    assert_eq!(input, [("odd_hex_digit", 12), ("bad_hex", 13)]);
    let last = recs
        .iter()
        .rfind(|r| r["type"] == "frame")
        .expect("a frame");
    assert_eq!(last["name"], "MOD_IDENTIFY");
    // Only pairing has something to say about it (it looks like a reply nobody asked for).
    assert!(
        last["diag"]
            .as_array()
            .is_some_and(|d| d.iter().all(|x| x["kind"] == "unsolicited")),
        "{last}"
    );
}

#[test]
fn empty_input_prints_nothing_and_succeeds() {
    let (out, _, ok) = aptscope(&["decode", "-"], Some(b""));
    assert!(ok);
    assert!(out.is_empty());
}

#[test]
fn missing_file_is_an_error_with_the_name() {
    let (_, err, ok) = aptscope(&["decode", "no/such/file.bin"], None);
    assert!(!ok);
    assert!(err.contains("no/such/file.bin"));
}

#[test]
fn messages_json_lists_every_id_in_the_spec() {
    let (out, _, ok) = aptscope(&["messages", "--json"], None);
    assert!(ok);
    let recs = ndjson(&out);
    let ids: std::collections::HashSet<u64> = recs
        .iter()
        .filter(|r| r["type"] == "msg")
        .filter_map(|r| r["msgid"].as_u64())
        .collect();
    for line in include_str!("../dissector/tests/spec_ids.txt")
        .lines()
        .filter(|l| !l.starts_with('#'))
    {
        let id = u64::from_str_radix(line[2..6].trim(), 16).expect("hex");
        assert!(ids.contains(&id), "{line} missing from `messages --json`");
    }
    let abs = recs
        .iter()
        .find(|r| r["name"] == "MOT_MOVE_ABSOLUTE")
        .expect("listed");
    assert_eq!(abs["dir"], "h2d");
    assert_eq!(abs["forms"].as_array().map(Vec::len), Some(2));
    assert_eq!(abs["forms"][1]["fields"][1]["type"], "i32");
}

#[test]
fn encode_then_decode_gives_back_the_values() {
    let (hex, err, ok) = aptscope(
        &[
            "encode",
            "MOT_MOVE_ABSOLUTE",
            "chan_ident=CH1",
            "absolute_position=-5000",
            "--dest",
            "bay3",
        ],
        None,
    );
    assert!(ok, "{err}");
    assert_eq!(hex.trim(), "53 04 06 00 A4 01 01 00 78 EC FF FF");
    let (out, _, ok) = aptscope(&["decode", "--hex", "--json", "-"], Some(hex.as_bytes()));
    assert!(ok);
    let r = &ndjson(&out)[0];
    assert_eq!(r["fields"]["absolute_position"], -5000);
    assert_eq!(r["dst"]["name"], "bay3");
}

#[test]
fn encode_rejects_bad_values_with_a_reason() {
    let (_, err, ok) = aptscope(&["encode", "MOT_MOVE_ABSOLUTE", "chan_ident=CH9"], None);
    assert!(!ok);
    assert!(err.contains("chan_ident") && err.contains("CH1"), "{err}");
    let (_, err, ok) = aptscope(&["encode", "MOD_IDENTIFY", "chan_ident=300"], None);
    assert!(!ok);
    assert!(err.contains("does not fit"), "{err}");
}

#[test]
fn elliptec_bus_sample_is_detected_paired_and_scaled() {
    let (out, err, ok) = aptscope(&["decode", "--json", "samples/elliptec-bus.txt"], None);
    assert!(ok, "{err}");
    let all: Vec<Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON"))
        .collect();
    assert_eq!(all[0]["type"], "detect");
    assert_eq!(all[0]["proto"], "elliptec");
    assert_eq!(all[0]["certain"], true);
    let recs = ndjson(&out);
    let frames: Vec<&Value> = recs.iter().filter(|r| r["type"] == "frame").collect();
    assert_eq!(frames.len(), 35);
    assert!(frames.iter().all(|f| f["proto"] == "ell"));
    // IN of the ELL14: every field, thread and hardware release split out.
    let info = frames[1];
    assert_eq!(info["cmd"], "IN");
    assert_eq!(info["fields"]["model"], 14);
    assert_eq!(info["fields"]["serial"], "11400284");
    assert_eq!(info["fields"]["pulses_per_unit"], 143360);
    assert_eq!(info["fields"]["thread"], "metric");
    assert_eq!(info["fields"]["hw_release"], 23);
    assert_eq!(info["pair"], 1);
    // ma 0x8C00 on the ELL14 is 90 degrees; the busy GS is an interim reply.
    assert_eq!(frames[11]["phys"]["position"]["value"], 90.0);
    assert_eq!(frames[12]["interim"], true);
    assert_eq!(frames[13]["pair"], 12);
    // After 2ca5 the ELL17 answers at 5 and its positions stay in mm.
    let at5: Vec<&&Value> = frames
        .iter()
        .filter(|f| f["addr"] == "5" && f["cmd"] == "PO")
        .collect();
    assert_eq!(at5[0]["module"]["model"], "ELL17");
    assert_eq!(at5[0]["phys"]["position"]["value"], 6.0);
    assert_eq!(at5[0]["phys"]["position"]["unit"], "mm");
    // The out-of-range error is named; button messages are not unsolicited.
    assert!(frames
        .iter()
        .any(|f| f["fields"]["status"] == "OUT_OF_RANGE"));
    assert!(frames.iter().all(|f| f["diag"] == serde_json::json!([])));
    // The last request gets no reply: reported after the stream ends, pointing at it.
    let late: Vec<&Value> = recs.iter().filter(|r| r["type"] == "diag").collect();
    assert_eq!(late.len(), 1);
    assert_eq!(late[0]["ref"], 35);
    assert_eq!(late[0]["diag"][0]["kind"], "no_reply");
}

#[test]
fn proto_flag_overrides_detection() {
    let (out, _, ok) = aptscope(
        &[
            "decode",
            "--proto",
            "apt",
            "--json",
            "samples/elliptec-bus.txt",
        ],
        None,
    );
    assert!(ok);
    assert!(!out.contains("\"type\":\"detect\""));
    let recs = ndjson(&out);
    assert!(recs.iter().all(|r| r["proto"] == "apt"));
    // Read as APT, this ASCII is mostly garbage, and every byte is still accounted for.
    let total: u64 = recs.iter().map(|r| r["len"].as_u64().unwrap_or(0)).sum();
    assert_eq!(
        total,
        std::fs::metadata("samples/elliptec-bus.txt")
            .expect("sample")
            .len()
    );
}

#[test]
fn a_mixed_stream_is_reported_not_guessed_silently() {
    let mut mixed = std::fs::read("samples/kdc101-session.bin").expect("sample");
    mixed.extend(std::fs::read("samples/elliptec-bus.txt").expect("sample"));
    let (out, _, ok) = aptscope(&["decode", "-"], Some(&mixed));
    assert!(ok);
    let first = out.lines().next().unwrap_or("");
    assert!(
        first.starts_with("# protocol") && first.contains("mixed or unknown"),
        "{first}"
    );
}

#[test]
fn messages_looks_one_message_up() {
    let (out, err, ok) = aptscope(&["messages", "mgmsg_mot_move_home"], None);
    assert!(ok, "{err}");
    assert!(out.starts_with("MOT_MOVE_HOME  0x0443"), "{out}");
    assert!(out.contains("answered by: MOT_MOVE_HOMED"), "{out}");
    assert!(out.contains("KDC101"), "{out}");
    let (out, _, ok) = aptscope(&["messages", "0x0444", "--json"], None);
    assert!(ok);
    let v: Value = serde_json::from_str(out.trim()).expect("json");
    assert_eq!(v["name"], "MOT_MOVE_HOMED");
    assert_eq!(v["revisions"], serde_json::json!(["23", "2025"]));
    assert!(v["devices"]
        .as_array()
        .is_some_and(|d| d.iter().any(|x| x == "KDC101")));
    let (_, err, ok) = aptscope(&["messages", "MOT_MOVE_HOMD"], None);
    assert!(!ok);
    assert!(
        err.contains("did you mean") && err.contains("MOT_MOVE_HOMED"),
        "{err}"
    );
}
