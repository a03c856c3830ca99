//! End-to-end tests: run the `aptscope` binary on the bundled samples and on bad input.

use serde_json::Value;
mod common;

use common::aptscope;

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
    // Both revisions of the APT spec, and every Elliptec command of the table.
    for line in include_str!("../dissector/tests/spec_ids.txt")
        .lines()
        .chain(include_str!("../dissector/tests/spec_ids_2025.txt").lines())
        .filter(|l| !l.starts_with('#'))
    {
        let id = u64::from_str_radix(line[2..6].trim(), 16).expect("hex");
        assert!(ids.contains(&id), "{line} missing from `messages --json`");
    }
    let codes: std::collections::HashSet<&str> = recs
        .iter()
        .filter(|r| r["proto"] == "ell" && r["type"] == "cmd")
        .filter_map(|r| r["code"].as_str())
        .collect();
    for c in aptscope_dissector::ell::table::COMMANDS {
        assert!(codes.contains(c.code), "{} missing", c.code);
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
    // Out of range names the field's range, also for a number too long to read.
    for v in ["2147483648", "99999999999999999999999"] {
        let pos = format!("absolute_position={v}");
        let (_, err, ok) = aptscope(&["encode", "MOT_MOVE_ABSOLUTE", "chan_ident=1", &pos], None);
        assert!(!ok);
        assert!(
            err.contains("does not fit") && err.contains("-2147483648..2147483647 (i32)"),
            "{err}"
        );
    }
    // A bad address lists the good ones.
    let (_, err, ok) = aptscope(&["encode", "MOD_IDENTIFY", "--dest", "bay99"], None);
    assert!(!ok);
    assert!(err.contains("bay0…bay9") && err.contains("0x50"), "{err}");
}

/// `encode` takes a message id as `messages` does.
#[test]
fn encode_takes_a_message_id() {
    let by_id = aptscope(
        &["encode", "0x0453", "chan_ident=1", "absolute_position=5"],
        None,
    );
    let by_name = aptscope(
        &[
            "encode",
            "MOT_MOVE_ABSOLUTE",
            "chan_ident=1",
            "absolute_position=5",
        ],
        None,
    );
    assert!(by_id.2, "{}", by_id.1);
    assert_eq!(by_id.0, by_name.0);
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
    assert_eq!(all[0]["proto"], "ell");
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

/// `--stage` shows motion values in mm beside the raw ones: the kdc101 session sets 2.5 mm/s
/// and 4 mm/s² on a Z8 stage and moves to 2 mm. Without it the raw values are labelled as
/// what they are (velocity units, not counts/s).
#[test]
fn a_stage_shows_positions_and_velocities_in_mm() {
    let cap = "samples/sessions/kdc101.pcapng";
    let (out, err, ok) = aptscope(&["decode", "--stage", "MTS25-Z8", cap], None);
    assert!(ok, "{err}");
    let line = |name: &str| {
        out.lines()
            .find(|l| l.contains(name))
            .unwrap_or_else(|| panic!("no {name} in\n{out}"))
            .to_string()
    };
    assert!(
        out.contains(
            "# units: stream 0 usb (KDC101): MTS25-Z8: 34554.96 counts/mm, brushed DC servo rules"
        ),
        "{out}"
    );
    let vel = line("MOT_SET_VELPARAMS");
    assert!(
        vel.contains("acceleration=1055 (3.99857 mm/s2) max_vel=1932478 (2.50003 mm/s)"),
        "{vel}"
    );
    assert!(line("MOT_MOVE_ABSOLUTE").contains("absolute_position=69110 (2 mm)"));
    assert!(line("MOT_MOVE_RELATIVE").contains("relative_distance=-34555 (-1 mm)"));
    assert!(line("MOT_GET_POSCOUNTER").contains("position=34555 (1 mm)"));

    let (out, _, ok) = aptscope(&["decode", "--json", "--stage", "MTS25-Z8", cap], None);
    assert!(ok);
    let recs = ndjson(&out);
    let units: Vec<&Value> = recs.iter().filter(|r| r["type"] == "units").collect();
    assert_eq!(units.len(), 1, "{units:?}");
    assert_eq!(units[0]["family"], "dc_servo");
    assert_eq!(units[0]["counts_per_unit"], 34554.96);
    let vel = recs
        .iter()
        .find(|r| r["name"] == "MOT_SET_VELPARAMS")
        .expect("velparams");
    assert_eq!(vel["fields"]["max_vel"], 1932478, "the raw value stays");
    assert_eq!(vel["phys"]["max_vel"]["unit"], "mm/s");
    assert_eq!(vel["phys"]["max_vel"]["value"], 2.50003);
    assert_eq!(vel["phys"]["acceleration"]["unit"], "mm/s2");

    // The same through a custom scale: the family comes from HW_GET_INFO (KDC101).
    let (out, _, ok) = aptscope(&["decode", "--scale", "34554.96/mm", cap], None);
    assert!(ok);
    assert!(out.contains("max_vel=1932478 (2.50003 mm/s)"), "{out}");

    let (out, _, ok) = aptscope(&["decode", cap], None);
    assert!(ok);
    assert!(out.contains("max_vel=1932478 vel_units"), "{out}");
    assert!(out.contains("acceleration=1055 acc_units"), "{out}");
    assert!(
        !out.contains("counts/s") && !out.contains("# units"),
        "{out}"
    );
    assert!(out.contains("absolute_position=69110 counts"), "{out}");
}

/// A K10CR1 has its stage built in: once its HW_GET_INFO is seen, positions are in degrees
/// with no option (409600 / 3 microsteps per degree, spec section 8).
#[test]
fn a_fixed_stage_model_is_recognised_from_hw_get_info() {
    let enc = |args: &[&str]| {
        let (out, err, ok) = aptscope(args, None);
        assert!(ok, "{err}");
        out
    };
    let mut hex = enc(&[
        "encode",
        "HW_GET_INFO",
        "model_number=K10CR1",
        "--source",
        "usb",
        "--dest",
        "host",
    ]);
    hex += &enc(&[
        "encode",
        "MOT_MOVE_ABSOLUTE",
        "chan_ident=CH1",
        "absolute_position=4096000",
        "--dest",
        "usb",
    ]);
    let (out, err, ok) = aptscope(&["decode", "--hex", "-"], Some(hex.as_bytes()));
    assert!(ok, "{err}");
    assert!(
        out.contains("# units: stream 0 usb (K10CR1): K10CR1: "),
        "{out}"
    );
    assert!(out.contains("absolute_position=4096000 (30 deg)"), "{out}");
}

#[test]
fn an_unknown_stage_is_an_error_listing_the_known_ones() {
    let (out, err, ok) = aptscope(
        &[
            "decode",
            "--stage",
            "MTS52-Z8",
            "samples/sessions/kdc101.pcapng",
        ],
        None,
    );
    assert!(!ok && out.is_empty(), "{out}");
    assert!(err.contains("unknown stage `MTS52-Z8`"), "{err}");
    let list = err.split("nearest first: ").nth(1).unwrap_or("");
    assert!(list.starts_with("MTS50-Z8, MTS25-Z8"), "{err}");
    assert!(list.contains("DDS220") && list.contains("K10CR1"), "{err}");
    let (_, err, ok) = aptscope(
        &["stats", "--scale", "x/mm", "samples/sessions/kdc101.pcapng"],
        None,
    );
    assert!(!ok && err.contains("bad --scale"), "{err}");
}

/// The message listing says what each motion field is.
#[test]
fn messages_json_marks_motion_quantities() {
    let (out, _, ok) = aptscope(&["messages", "--json"], None);
    assert!(ok);
    let recs = ndjson(&out);
    let vel = recs
        .iter()
        .find(|r| r["name"] == "MOT_SET_VELPARAMS")
        .expect("listed");
    let fields = &vel["forms"][0]["fields"];
    assert_eq!(fields[1]["name"], "min_vel");
    assert_eq!(
        (&fields[1]["unit"], &fields[1]["q"]),
        (&Value::from("vel_units"), &Value::from("vel"))
    );
    assert_eq!(
        (&fields[2]["unit"], &fields[2]["q"]),
        (&Value::from("acc_units"), &Value::from("acc"))
    );
    let (out, _, ok) = aptscope(&["messages", "-v"], None);
    assert!(ok && out.contains("MOT_SET_VELPARAMS"));
    assert!(
        !out.contains("counts/s2"),
        "no acceleration claims counts/s²"
    );
}

/// Several inputs: a `file` record starts each, every record names its file (numbers, offsets
/// and pairs count within a file, so they restart, but not silently), and filters see `file`.
#[test]
fn records_of_several_files_name_their_file() {
    let (out, err, ok) = aptscope(
        &[
            "decode",
            "--json",
            "samples/kdc101-session.bin",
            "samples/damaged.bin",
        ],
        None,
    );
    assert!(ok, "{err}");
    let recs: Vec<Value> = out
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON"))
        .collect();
    assert!(recs.iter().all(|r| r["file"].is_string()), "{out}");
    let starts: Vec<&Value> = recs.iter().filter(|r| r["type"] == "file").collect();
    assert_eq!(starts.len(), 2);
    assert_eq!(starts[1]["file"], "samples/damaged.bin");
    assert_eq!(starts[1]["index"], 1);
    let firsts = recs.iter().filter(|r| r["n"] == 1).count();
    assert_eq!(firsts, 2, "each file numbers from 1");
    let (out, _, ok) = aptscope(
        &[
            "decode",
            "--json",
            "-Y",
            "file contains damaged && apt.name == MOD_IDENTIFY",
            "samples/kdc101-session.bin",
            "samples/damaged.bin",
        ],
        None,
    );
    assert!(ok);
    let hits: Vec<Value> = ndjson(&out)
        .into_iter()
        .filter(|r| r["type"] == "frame")
        .collect();
    assert_eq!(hits.len(), 1, "{out}");
    // One file: no file key, as before.
    let (out, _, _) = aptscope(&["decode", "--json", "samples/damaged.bin"], None);
    assert!(!out.contains("\"file\""));
    // The detection record spells the protocol as every record does.
    let (out, _, _) = aptscope(&["decode", "--json", "samples/elliptec-bus.txt"], None);
    assert!(
        out.starts_with("{\"type\":\"detect\",\"proto\":\"ell\""),
        "{out}"
    );
}

#[test]
fn a_reader_that_has_gone_ends_every_command_quietly() {
    // `aptscope … | head`: stdout is a pipe whose reading end is already closed, so the
    // first write fails; the command must end with success and no panic.
    let s = "samples/kdc101-session.pcapng";
    let runs: [&[&str]; 10] = [
        &["decode", s],
        &["decode", "--json", s],
        &["stats", s],
        &["stats", "--json", s],
        &["info", s],
        &["info", "--json", s],
        &["messages"],
        &["messages", "--json"],
        &["messages", "MOT_MOVE_ABSOLUTE"],
        &[
            "encode",
            "MOT_MOVE_ABSOLUTE",
            "chan_ident=1",
            "absolute_position=100",
        ],
    ];
    for args in runs {
        let (reader, writer) = std::io::pipe().expect("pipe");
        drop(reader);
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_aptscope"))
            .args(args)
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .stdin(std::process::Stdio::null())
            .stdout(writer)
            .stderr(std::process::Stdio::piped())
            .output()
            .expect("run aptscope");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        assert!(o.status.success(), "{args:?}: {:?} {err}", o.status);
    }
}
