//! The generated Wireshark dissector (`aptscope export wireshark-lua`) run by tshark on the
//! samples and on frames of every message form: the same names, frames and field values as
//! `aptscope decode --json`.
//!
//! tshark is required: without it these tests fail with an install hint (in CI always; locally
//! unless `APTSCOPE_SKIP_MISSING_TOOLS=1`, which makes them pass with a notice on stderr).

mod common;

use aptscope_dissector::synth::{all_forms, random_frame, Rng};
use aptscope_dissector::table::{Dir, FormKind, Table};
use common::Scratch;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn aptscope(args: &[&str]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_aptscope"))
        .args(args)
        .current_dir(ROOT)
        .output()
        .expect("run aptscope");
    assert!(
        o.status.success(),
        "aptscope {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The generated dissector in a scratch directory, or `None` when tshark is missing and the
/// user allowed skipping.
fn setup(name: &str) -> Option<(Scratch, PathBuf)> {
    // The project's one rule for a missing tool: fail, in CI always (README, Set-up).
    if !aptscope_capture::tools::require("tshark", "-v", "tshark") {
        return None;
    }
    let dir = Scratch::new(name);
    let lua = dir.join("aptscope.lua");
    aptscope(&[
        "export",
        "wireshark-lua",
        "-o",
        lua.to_str().expect("utf-8 path"),
    ]);
    Some((dir, lua))
}

/// Run tshark with the dissector (two passes, so frames reassembled or truncated at the end of
/// the capture are known); asserts that nothing is written to stderr (Lua errors and warnings).
fn tshark(lua: &Path, file: &Path, args: &[&str]) -> String {
    let o = Command::new("tshark")
        .arg("-X")
        .arg(format!("lua_script:{}", lua.display()))
        .arg("-2")
        .arg("-r")
        .arg(file)
        .args(args)
        .current_dir(ROOT)
        .output()
        .expect("run tshark");
    let err = String::from_utf8_lossy(&o.stderr);
    // tshark's own notice when run as root is not about the dissector.
    let err: Vec<&str> = err
        .lines()
        .filter(|l| !l.starts_with("Running as user \"root\""))
        .collect();
    assert!(
        o.status.success() && err.is_empty(),
        "tshark on {}: {}",
        file.display(),
        err.join("\n")
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The frame records of `aptscope decode --json`.
fn frames(file: &Path, extra: &[&str]) -> Vec<Value> {
    let mut args = vec!["decode", "--json", file.to_str().expect("utf-8 path")];
    args.extend_from_slice(extra);
    aptscope(&args)
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).expect("NDJSON"))
        .filter(|r| r["type"] == "frame")
        .collect()
}

/// The values tshark prints for the given fields, in packet order (several per packet split).
fn tshark_values(lua: &Path, file: &Path, fields: &[&str], filter: Option<&str>) -> Vec<String> {
    let mut args = vec!["-T", "fields", "-E", "occurrence=a"];
    for f in fields {
        args.push("-e");
        args.push(f);
    }
    if let Some(f) = filter {
        args.push("-Y");
        args.push(f);
    }
    tshark(lua, file, &args)
        .lines()
        .flat_map(|l| l.split(['\t', ',']).map(str::to_string).collect::<Vec<_>>())
        .filter(|s| !s.is_empty())
        .collect()
}

/// The name aptscope gives a frame, as tshark's `apt.name` / `ell.cmd` shows it.
fn name_of(r: &Value) -> Option<String> {
    let v = if r["proto"] == "ell" {
        &r["cmd"]
    } else {
        &r["name"]
    };
    v.as_str().map(str::to_string)
}

/// Every sample in the formats the dissector is registered for: aptscope's pcap and pcapng,
/// usbmon and USBPcap.
fn samples() -> Vec<PathBuf> {
    let mut v = vec![
        Path::new(ROOT).join("samples/kdc101-session.pcapng"),
        Path::new(ROOT).join("samples/kdc101-session.pcap"),
        // USB captures of the FTDI chip, without enumeration: found by the bulk heuristic.
        Path::new(ROOT).join("samples/kdc101-session.usbmon.pcap"),
        Path::new(ROOT).join("samples/kdc101-session.usbpcap.pcap"),
    ];
    let mut s: Vec<PathBuf> = std::fs::read_dir(Path::new(ROOT).join("samples/sessions"))
        .expect("samples/sessions")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "pcap" || e == "pcapng"))
        .collect();
    s.sort();
    assert!(s.len() >= 12, "samples/sessions: {s:?}");
    assert!(s.iter().any(|p| p.to_string_lossy().contains("elliptec")));
    v.extend(s);
    v
}

#[test]
fn names_in_every_sample_are_aptscopes_in_the_same_order() {
    let Some((_dir, lua)) = setup("names") else {
        return;
    };
    for f in samples() {
        let want: Vec<String> = frames(&f, &[]).iter().filter_map(name_of).collect();
        assert!(!want.is_empty(), "{}", f.display());
        let got = tshark_values(&lua, &f, &["apt.name", "ell.cmd"], None);
        assert_eq!(got, want, "{}", f.display());
        // Lua errors while dissecting go into the tree, not to stderr.
        let tree = tshark(&lua, &f, &["-V"]);
        assert!(!tree.contains("Lua Error"), "{}:\n{tree}", f.display());
        assert!(
            tree.contains("Message id: 0x") || tree.contains("Command: "),
            "{}",
            f.display()
        );
    }
}

#[test]
fn a_msgid_filter_selects_the_same_frames_in_both_tools() {
    let Some((_dir, lua)) = setup("filter") else {
        return;
    };
    let mut seen = 0;
    for f in samples() {
        let want = frames(&f, &["-Y", "apt.msgid == 0x0491"]).len();
        let got = tshark_values(&lua, &f, &["apt.msgid"], Some("apt.msgid == 0x0491"))
            .iter()
            .filter(|v| v.as_str() == "0x0491")
            .count();
        assert_eq!(got, want, "{}", f.display());
        seen += want;
    }
    assert!(seen > 10, "the samples hold MOT_GET_DCSTATUSUPDATE frames");
}

/// A legacy pcap as aptscope writes it: LINKTYPE_USER1, each record `[direction, stream]` then
/// the bytes.
fn write_pcap(path: &Path, records: &[(u8, Vec<u8>)]) {
    let with_stream: Vec<(u8, u8, Vec<u8>)> =
        records.iter().map(|(d, b)| (*d, 0, b.clone())).collect();
    write_pcap_streams(path, &with_stream);
}

/// [`write_pcap`] with a stream byte per record: `(direction, stream, bytes)`.
fn write_pcap_streams(path: &Path, records: &[(u8, u8, Vec<u8>)]) {
    let mut b = vec![];
    b.extend_from_slice(&0xa1b2_c3d4u32.to_le_bytes());
    b.extend_from_slice(&2u16.to_le_bytes());
    b.extend_from_slice(&4u16.to_le_bytes());
    b.extend_from_slice(&[0; 8]);
    b.extend_from_slice(&65535u32.to_le_bytes());
    b.extend_from_slice(&148u32.to_le_bytes());
    for (i, (dir, stream, data)) in records.iter().enumerate() {
        b.extend_from_slice(&(1_700_000_000u32 + i as u32).to_le_bytes());
        b.extend_from_slice(&0u32.to_le_bytes());
        let n = data.len() as u32 + 2;
        b.extend_from_slice(&n.to_le_bytes());
        b.extend_from_slice(&n.to_le_bytes());
        b.extend_from_slice(&[*dir, *stream]);
        b.extend_from_slice(data);
    }
    std::fs::write(path, b).expect("write pcap");
}

/// tshark's apt trees of a capture, flattened: one map of field → values per APT frame.
fn tshark_apt_trees(lua: &Path, file: &Path) -> Vec<serde_json::Map<String, Value>> {
    let out = tshark(lua, file, &["-T", "json", "--no-duplicate-keys"]);
    let packets: Vec<Value> = serde_json::from_str(&out).expect("tshark JSON");
    let mut trees = vec![];
    for p in &packets {
        match &p["_source"]["layers"]["apt"] {
            Value::Array(a) => trees.extend(a.iter().cloned()),
            Value::Null => {}
            t => trees.push(t.clone()),
        }
    }
    trees
        .into_iter()
        .map(|t| {
            let mut flat = serde_json::Map::new();
            flatten(&t, &mut flat);
            flat
        })
        .collect()
}

/// Fields of a tree and of its text subtrees (arrays); flag bit subtrees left out.
fn flatten(t: &Value, out: &mut serde_json::Map<String, Value>) {
    let Value::Object(m) = t else { return };
    for (k, v) in m {
        if k.ends_with("_tree") {
            continue;
        }
        match v {
            Value::Object(_) => flatten(v, out),
            Value::Array(a) if a.iter().all(Value::is_object) => {
                a.iter().for_each(|x| flatten(x, out))
            }
            _ if k.starts_with("apt.") => {
                let vals = match v {
                    Value::Array(a) => a.clone(),
                    x => vec![x.clone()],
                };
                match out.get_mut(k) {
                    Some(Value::Array(have)) => have.extend(vals),
                    _ => {
                        out.insert(k.clone(), Value::Array(vals));
                    }
                }
            }
            _ => {}
        }
    }
}

fn as_num(s: &str) -> Option<f64> {
    let s = s.trim();
    if let Some(h) = s.strip_prefix("0x") {
        return i64::from_str_radix(h, 16).ok().map(|x| x as f64);
    }
    s.parse().ok()
}

/// Whether tshark's values `got` of a field equal aptscope's JSON value `want`.
fn same_value(
    table: &Table,
    field: &aptscope_dissector::table::Field,
    want: &Value,
    got: &[Value],
) -> bool {
    let g: Vec<&str> = got.iter().filter_map(Value::as_str).collect();
    // tshark prints floats with 6 significant digits.
    let tol = if field.ty.name().starts_with("f32") {
        1e-5
    } else {
        0.0
    };
    let one = |w: &Value, s: &str| -> bool {
        match w {
            Value::Number(n) => match (n.as_f64(), as_num(s)) {
                (Some(a), Some(b)) => a == b || (a - b).abs() <= tol * a.abs().max(1.0),
                _ => false,
            },
            Value::String(label) => {
                if let (Some(e), Some(n)) = (field.enumeration, as_num(s)) {
                    table.enum_def(e).label(n as i64) == Some(label.as_str())
                } else if field.ty.name().starts_with("bytes") {
                    s.replace(':', "").eq_ignore_ascii_case(label)
                } else {
                    s == label
                }
            }
            _ => false,
        }
    };
    match want {
        Value::Array(items) if field.flags.is_some() => {
            let (Some(fl), [s]) = (field.flags, g.as_slice()) else {
                return false;
            };
            let Some(n) = as_num(s) else { return false };
            let n = n as u64;
            let mut labels: Vec<&str> = table
                .flags_def(fl)
                .items
                .iter()
                .filter(|(m, _)| n & m == *m)
                .map(|(_, l)| *l)
                .collect();
            let mut w: Vec<&str> = items.iter().filter_map(Value::as_str).collect();
            labels.sort_unstable();
            w.sort_unstable();
            // aptscope may name unknown bits too; every known bit must agree.
            labels.iter().all(|l| w.contains(l))
                && w.iter().all(|l| labels.contains(l) || l.starts_with("0x"))
        }
        Value::Array(items) => {
            items.len() == g.len() && items.iter().zip(&g).all(|(w, s)| one(w, s))
        }
        w => g.len() == 1 && one(w, g[0]),
    }
}

/// Compare every field of every APT frame of `file` between aptscope and tshark.
fn compare_fields(lua: &Path, file: &Path) -> usize {
    let table = Table::global();
    let want = frames(file, &[]);
    let got = tshark_apt_trees(lua, file);
    assert_eq!(got.len(), want.len(), "{}: APT frames", file.display());
    let mut checked = 0;
    for (w, g) in want.iter().zip(&got) {
        let name = w["name"].as_str().expect("known message");
        let m = table.msg_by_name(name).expect("in the table");
        assert_eq!(
            g.get("apt.msgid").and_then(|v| v[0].as_str()),
            Some(format!("0x{:04x}", m.id).as_str()),
            "{name}"
        );
        // The form aptscope chose, to know each field's enum and flag set.
        let data_len = w["data_len"].as_u64().unwrap_or(0) as u16;
        let form =
            if let Some(sub) = w["sub"]["name"].as_str().filter(|_| w["data_flag"] == true) {
                let s = table
                    .sub_by_name(m.subs.expect("group"), sub)
                    .expect("sub in table");
                s.forms.iter().find(|f| f.kind == FormKind::Data(data_len))
            } else if w["data_flag"] == true {
                m.forms
                    .iter()
                    .find(|f| f.kind == FormKind::Data(data_len))
                    .or_else(|| {
                        let max = table.max_data_len(m);
                        m.forms.iter().find(|f| f.open_fits(data_len as usize, max))
                    })
            } else {
                m.forms.iter().find(|f| f.kind == FormKind::Header)
            }
            .expect("form");
        let Some(fields) = w["fields"].as_object() else {
            continue;
        };
        for (k, v) in fields {
            let field = form
                .fields
                .iter()
                .find(|f| f.name == k)
                .expect("table field");
            let plain = format!("apt.{k}");
            let prefix = format!("apt.{k}.");
            let cands: Vec<(&String, &Value)> = g
                .iter()
                .filter(|(a, _)| **a == plain || a.starts_with(&prefix))
                .collect();
            let ok = cands.iter().any(|(_, vals)| {
                same_value(
                    table,
                    field,
                    v,
                    vals.as_array().map_or(&[][..], |a| a.as_slice()),
                )
            });
            assert!(
                ok,
                "{}: {name} field {k}: aptscope {v}, tshark {cands:?}",
                file.display()
            );
            checked += 1;
        }
        for (a, b) in [("src", "apt.src"), ("dst", "apt.dst")] {
            let want = w[a]["addr"].as_u64().expect("address");
            let got = g.get(b).and_then(|v| v[0].as_str()).and_then(as_num);
            assert_eq!(got, Some(want as f64), "{name} {a}");
        }
        if let Some(ch) = w["channel"].as_u64() {
            let got = g
                .get("apt.chan")
                .and_then(|v| v[0].as_str())
                .and_then(as_num);
            assert_eq!(got, Some(ch as f64), "{name} chan");
        }
    }
    checked
}

#[test]
fn field_values_equal_aptscopes_for_every_message_form() {
    let Some((dir, lua)) = setup("forms") else {
        return;
    };
    let table = Table::global();
    let mut r = Rng(17);
    let records: Vec<(u8, Vec<u8>)> = all_forms(table)
        .into_iter()
        .map(|(m, form, sub)| {
            let (bytes, _) = random_frame(table, &mut r, m, form, sub);
            assert!(!bytes.is_empty(), "{}", m.name);
            (if m.dir == Dir::DeviceToHost { 2 } else { 1 }, bytes)
        })
        .collect();
    let pcap = dir.join("forms.pcap");
    write_pcap(&pcap, &records);
    let checked = compare_fields(&lua, &pcap);
    assert!(checked > 1000, "only {checked} field values compared");
}

#[test]
fn encoded_messages_converted_to_pcapng_decode_alike() {
    let Some((dir, lua)) = setup("encoded") else {
        return;
    };
    // `aptscope encode` frames, several per packet once converted.
    let msgs: &[&[&str]] = &[
        &["HW_REQ_INFO", "--dest", "usb"],
        &[
            "HW_GET_INFO",
            "serial_number=83000001",
            "model_number=BSC203",
            "hw_type=45",
            "nchs=3",
        ],
        &[
            "MOT_MOVE_ABSOLUTE",
            "chan_ident=CH2",
            "absolute_position=-4096",
            "--dest",
            "bay1",
        ],
        &[
            "MOT_GET_DCSTATUSUPDATE",
            "chan_ident=CH1",
            "position=171520",
            "velocity=300",
            "status_bits=MOTOR_CONNECTED|HOMED|MOVING_CW|ENABLED",
        ],
        &[
            "MOD_SET_CHANENABLESTATE",
            "chan_ident=CH3",
            "enable_state=2",
        ],
        &["LA_REQ_PARAMS", "sub_id=9"],
        &["PZ_SET_OUTPUTVOLTS", "chan_ident=CH1", "voltage=16383"],
    ];
    let mut hex = String::new();
    for a in msgs {
        let mut args = vec!["encode"];
        args.extend_from_slice(a);
        hex.push_str(&aptscope(&args));
    }
    let hex_file = dir.join("encoded.hex");
    std::fs::write(&hex_file, &hex).expect("write hex");
    let pcapng = dir.join("encoded.pcapng");
    let _ = std::fs::remove_file(&pcapng);
    aptscope(&[
        "convert",
        hex_file.to_str().expect("utf-8"),
        pcapng.to_str().expect("utf-8"),
    ]);
    let n = compare_fields(&lua, &pcapng);
    assert!(n >= 15, "only {n} field values compared");
    assert_eq!(frames(&pcapng, &[]).len(), msgs.len());
}

#[test]
fn frames_split_across_packets_and_sharing_them_are_reassembled() {
    let Some((dir, lua)) = setup("split") else {
        return;
    };
    // The KDC101 session's host and device bytes cut into 7-byte pieces, the two directions
    // interleaved: frames span packets and packets hold the end of one frame and the next.
    let sample = Path::new(ROOT).join("samples/sessions/kdc101.pcapng");
    let recs = frames(&sample, &[]);
    let mut h2d = vec![];
    let mut d2h = vec![];
    for r in &recs {
        let raw = r["raw"].as_str().expect("raw");
        let bytes: Vec<u8> = (0..raw.len() / 2)
            .map(|i| u8::from_str_radix(&raw[2 * i..2 * i + 2], 16).expect("hex"))
            .collect();
        if r["dir"] == "d2h" {
            d2h.extend(bytes);
        } else {
            h2d.extend(bytes);
        }
    }
    let mut records = vec![];
    let (mut a, mut b) = (h2d.chunks(7), d2h.chunks(7));
    loop {
        let (x, y) = (a.next(), b.next());
        if x.is_none() && y.is_none() {
            break;
        }
        if let Some(x) = x {
            records.push((1, x.to_vec()));
        }
        if let Some(y) = y {
            records.push((2, y.to_vec()));
        }
    }
    let pcap = dir.join("split.pcap");
    write_pcap(&pcap, &records);
    let want: Vec<String> = frames(&pcap, &[]).iter().filter_map(name_of).collect();
    assert_eq!(want.len(), recs.len());
    let mut got = tshark_values(&lua, &pcap, &["apt.name"], None);
    let mut want_sorted = want.clone();
    // Frames show in the packet that completes them; per direction the order is the stream's.
    want_sorted.sort();
    got.sort();
    assert_eq!(got, want_sorted);
    let per_dir = |d: &str| -> Vec<String> {
        frames(&pcap, &[])
            .iter()
            .filter(|r| r["dir"] == d)
            .filter_map(name_of)
            .collect()
    };
    let got_d2h = tshark_values(&lua, &pcap, &["apt.name"], Some("aptscope.dir == 2"));
    assert_eq!(got_d2h, per_dir("d2h"));
    assert!(compare_fields_unordered_ok(&lua, &pcap));
}

/// Every frame of the split capture has its fields right (order within a direction kept).
fn compare_fields_unordered_ok(lua: &Path, file: &Path) -> bool {
    let trees = tshark_apt_trees(lua, file);
    trees.len() == frames(file, &[]).len()
        && trees
            .iter()
            .all(|t| t.contains_key("apt.msgid") && t.contains_key("apt.name"))
}

#[test]
fn elliptec_fields_equal_aptscopes() {
    let Some((_dir, lua)) = setup("ell") else {
        return;
    };
    for f in [
        "samples/sessions/elliptec.pcapng",
        "samples/sessions/elliptec.pcap",
    ] {
        let f = Path::new(ROOT).join(f);
        let want = frames(&f, &[]);
        let out = tshark(&lua, &f, &["-T", "json", "--no-duplicate-keys"]);
        let packets: Vec<Value> = serde_json::from_str(&out).expect("tshark JSON");
        let mut got = vec![];
        for p in &packets {
            match &p["_source"]["layers"]["ell"] {
                Value::Array(a) => got.extend(a.iter().cloned()),
                Value::Null => {}
                t => got.push(t.clone()),
            }
        }
        assert_eq!(got.len(), want.len(), "{}", f.display());
        let mut compared = 0;
        for (w, g) in want.iter().zip(&got) {
            assert_eq!(g["ell.cmd"], w["cmd"], "{}", f.display());
            assert_eq!(g["ell.addr"], w["addr"]);
            assert_eq!(g["ell.name"], w["name"]);
            let Value::Object(g) = g else { panic!("{g}") };
            for (k, v) in g {
                let Some(name) = k.strip_prefix("ell.") else {
                    continue;
                };
                if ["cmd", "addr", "name", "pair", "response_in", "latency_ms"].contains(&name) {
                    continue;
                }
                let name = name.split('.').next().unwrap_or(name);
                let s = v.as_str().expect("one value");
                let wv = &w["fields"][name];
                let ok = match wv {
                    Value::Number(n) => n.as_f64() == as_num(s),
                    // Status codes: aptscope names them; tshark shows the number (value string).
                    Value::String(t) if name == "status" => aptscope_dissector::ell::table::STATUS
                        .iter()
                        .any(|(c, l)| l == t && Some(*c as f64) == as_num(s)),
                    Value::String(t) => t == s,
                    _ => false,
                };
                assert!(ok, "{} {}: aptscope {wv}, tshark {s}", w["cmd"], name);
                compared += 1;
            }
        }
        assert!(compared >= 30, "only {compared} values compared");
    }
}

/// A current curve whose last bytes equal CR and LF keeps them as data in both tools: the
/// terminator is only what follows the curve's fixed length (the `ell_encode` fuzz target found
/// aptscope's decoder taking them for it; the Lua dissector did the same).
#[test]
fn a_current_curve_ending_in_cr_lf_bytes_is_whole_in_both_tools() {
    let Some((dir, lua)) = setup("curve") else {
        return;
    };
    let mut curve: Vec<u8> = (0..522u32).map(|i| (i * 7 % 251) as u8).collect();
    curve[518..].copy_from_slice(b"\n\r\r\n");
    let reply = [b"0C1".as_slice(), &curve, b"\r\n"].concat();
    let pcap = dir.join("curve.pcap");
    write_pcap(&pcap, &[(1, b"0c1\r\n".to_vec()), (2, reply)]);
    let want = frames(&pcap, &[]);
    assert_eq!(want.len(), 2, "{want:?}");
    assert_eq!(want[1]["cmd"], "C1");
    assert_eq!(want[1]["diag"], serde_json::json!([]), "{}", want[1]);
    let hex: String = curve.iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(want[1]["fields"]["curve"], hex.as_str());
    let got = tshark_values(&lua, &pcap, &["ell.curve"], Some("ell.cmd == \"C1\""));
    assert_eq!(got, [hex]);
    let expert = tshark(&lua, &pcap, &["-z", "expert,note"]);
    assert!(!expert.contains("shorter"), "{expert}");
}

/// A little-endian pcap of usbmon records (link type 220).
fn write_usbmon(path: &Path, records: &[(u64, Vec<u8>)]) {
    let mut b = vec![];
    b.extend_from_slice(&0xa1b2_c3d4u32.to_le_bytes());
    b.extend_from_slice(&2u16.to_le_bytes());
    b.extend_from_slice(&4u16.to_le_bytes());
    b.extend_from_slice(&[0; 8]);
    b.extend_from_slice(&65535u32.to_le_bytes());
    b.extend_from_slice(&220u32.to_le_bytes());
    for (ts, data) in records {
        b.extend_from_slice(&((ts / 1_000_000_000) as u32).to_le_bytes());
        b.extend_from_slice(&((ts % 1_000_000_000 / 1000) as u32).to_le_bytes());
        let n = data.len() as u32;
        b.extend_from_slice(&n.to_le_bytes());
        b.extend_from_slice(&n.to_le_bytes());
        b.extend_from_slice(data);
    }
    std::fs::write(path, b).expect("write usbmon pcap");
}

#[test]
fn usbmon_captures_with_and_without_enumeration_decode_completely() {
    use aptscope_capture::{Direction, OwnedChunk};
    let Some((dir, lua)) = setup("usbmon") else {
        return;
    };
    // The KDC101 session in 45-byte chunks per direction: frames span USB transfers, and the
    // device's transfers get FTDI status bytes every 64 bytes.
    let recs = frames(&Path::new(ROOT).join("samples/sessions/kdc101.pcapng"), &[]);
    let mut chunks = vec![];
    let (mut h2d, mut d2h) = (vec![], vec![]);
    for r in &recs {
        let raw = r["raw"].as_str().expect("raw");
        let bytes: Vec<u8> = (0..raw.len() / 2)
            .map(|i| u8::from_str_radix(&raw[2 * i..2 * i + 2], 16).expect("hex"))
            .collect();
        if r["dir"] == "d2h" {
            d2h.extend(bytes);
        } else {
            h2d.extend(bytes);
        }
    }
    let (mut a, mut b) = (h2d.chunks(45), d2h.chunks(100));
    let mut ts = 1_000_000_000u64;
    loop {
        let (x, y) = (a.next(), b.next());
        if x.is_none() && y.is_none() {
            break;
        }
        for (d, c) in [(Direction::HostToDevice, x), (Direction::DeviceToHost, y)] {
            if let Some(c) = c {
                ts += 1_000_000;
                chunks.push(OwnedChunk {
                    ts_ns: Some(ts),
                    dir: d,
                    stream: 0,
                    bytes: c.to_vec(),
                });
            }
        }
    }
    let records = aptscope_capture::usb::synth_usbmon(&chunks, 1, 7, 64);
    let with = dir.join("enumerated.usbmon.pcap");
    write_usbmon(&with, &records);
    // Without enumeration: bulk transfers only (usbmon header byte 9 is the transfer type).
    let bulk: Vec<(u64, Vec<u8>)> = records
        .iter()
        .filter(|(_, r)| r.get(9) == Some(&3))
        .cloned()
        .collect();
    assert!(bulk.len() < records.len());
    let without = dir.join("bulk-only.usbmon.pcap");
    write_usbmon(&without, &bulk);
    for f in [&with, &without] {
        let want: Vec<String> = frames(f, &[]).iter().filter_map(name_of).collect();
        assert_eq!(want.len(), recs.len(), "{}", f.display());
        let mut got = tshark_values(&lua, f, &["apt.name"], None);
        let mut w = want.clone();
        got.sort();
        w.sort();
        assert_eq!(got, w, "{}", f.display());
        assert_eq!(
            tshark_values(&lua, f, &["apt.name"], Some("aptscope.dir == 2")),
            frames(f, &[])
                .iter()
                .filter(|r| r["dir"] == "d2h")
                .filter_map(name_of)
                .collect::<Vec<_>>(),
            "{}",
            f.display()
        );
    }
}

#[test]
fn request_reply_pairs_and_latencies_are_aptscopes() {
    let Some((_dir, lua)) = setup("pairs") else {
        return;
    };
    let mut pairs = 0;
    for f in samples() {
        let recs = frames(&f, &[]);
        let by_n: std::collections::HashMap<u64, &Value> = recs
            .iter()
            .filter_map(|r| Some((r["n"].as_u64()?, r)))
            .collect();
        let want: Vec<(String, String, f64)> = recs
            .iter()
            .filter(|r| !r["diag"].to_string().contains("duplicate"))
            .filter_map(|r| {
                let req = by_n.get(&r["pair"].as_u64()?)?;
                Some((
                    name_of(r)?,
                    name_of(req)?,
                    r["latency_ms"].as_f64().unwrap_or(0.0),
                ))
            })
            .collect();
        // These samples hold one frame per packet: packet numbers name frames.
        let out = tshark(
            &lua,
            &f,
            &[
                "-T",
                "fields",
                "-e",
                "frame.number",
                "-e",
                "apt.name",
                "-e",
                "apt.pair",
                "-e",
                "apt.latency_ms",
                "-e",
                "ell.cmd",
                "-e",
                "ell.pair",
                "-e",
                "ell.latency_ms",
            ],
        );
        // frame, name, pair, latency of whichever protocol the packet holds.
        let rows: Vec<Vec<&str>> = out
            .lines()
            .map(|l| {
                let c: Vec<&str> = l.split('\t').collect();
                let pick = |a: usize, b: usize| {
                    let x = c.get(a).copied().unwrap_or("");
                    if x.is_empty() {
                        c.get(b).copied().unwrap_or("")
                    } else {
                        x
                    }
                };
                vec![c[0], pick(1, 4), pick(2, 5), pick(3, 6)]
            })
            .collect();
        let name: std::collections::HashMap<&str, &str> = rows
            .iter()
            .filter(|r| r.len() > 1)
            .map(|r| (r[0], r[1]))
            .collect();
        let got: Vec<(String, String, f64)> = rows
            .iter()
            .filter(|r| r.len() == 4 && !r[2].is_empty())
            .map(|r| {
                (
                    r[1].to_string(),
                    name.get(r[2]).copied().unwrap_or("?").to_string(),
                    r[3].parse().unwrap_or(f64::NAN),
                )
            })
            .collect();
        assert_eq!(got.len(), want.len(), "{}: {got:?}\n{want:?}", f.display());
        for (g, w) in got.iter().zip(&want) {
            assert!(
                g.0 == w.0 && g.1 == w.1 && (g.2 - w.2).abs() < 0.01,
                "{}: tshark {g:?}, aptscope {w:?}",
                f.display()
            );
        }
        pairs += want.len();
    }
    assert!(pairs > 60, "only {pairs} pairs compared");
}

#[test]
fn streams_of_a_pcapng_do_not_mix_when_their_frames_span_packets() {
    let Some((dir, lua)) = setup("streams") else {
        return;
    };
    // Two ports (the KDC101 and BSC203 sessions), each direction cut into 5-byte pieces, the
    // pieces of both ports interleaved, converted to a pcapng with one interface per port.
    let mut per_stream = vec![];
    for f in [
        "samples/sessions/kdc101.pcapng",
        "samples/sessions/bsc203.pcapng",
    ] {
        let (mut h2d, mut d2h) = (vec![], vec![]);
        for r in frames(&Path::new(ROOT).join(f), &[]) {
            let raw = r["raw"].as_str().expect("raw").to_string();
            let bytes: Vec<u8> = (0..raw.len() / 2)
                .map(|i| u8::from_str_radix(&raw[2 * i..2 * i + 2], 16).expect("hex"))
                .collect();
            if r["dir"] == "d2h" {
                d2h.extend(bytes);
            } else {
                h2d.extend(bytes);
            }
        }
        let mut pieces: Vec<(u8, Vec<u8>)> = vec![];
        let (mut a, mut b) = (h2d.chunks(5), d2h.chunks(5));
        loop {
            let (x, y) = (a.next(), b.next());
            if x.is_none() && y.is_none() {
                break;
            }
            pieces.extend(x.map(|x| (1, x.to_vec())));
            pieces.extend(y.map(|y| (2, y.to_vec())));
        }
        per_stream.push(pieces);
    }
    let mut records = vec![];
    let longest = per_stream.iter().map(Vec::len).max().unwrap_or(0);
    for i in 0..longest {
        for (s, pieces) in per_stream.iter().enumerate() {
            if let Some((d, p)) = pieces.get(i) {
                records.push((*d, s as u8, p.clone()));
            }
        }
    }
    let pcap = dir.join("streams.pcap");
    write_pcap_streams(&pcap, &records);
    let pcapng = dir.join("streams.pcapng");
    aptscope(&[
        "convert",
        pcap.to_str().expect("utf-8"),
        pcapng.to_str().expect("utf-8"),
    ]);
    for f in [&pcap, &pcapng] {
        let recs = frames(f, &[]);
        assert!(recs.len() > 60, "{}", f.display());
        for (stream, d) in [(0, "d2h"), (1, "d2h"), (0, "h2d"), (1, "h2d")] {
            let want: Vec<String> = recs
                .iter()
                .filter(|r| r["stream"] == stream && r["dir"] == d)
                .filter_map(name_of)
                .collect();
            // No display filter: with one, tshark builds the tree in its first pass too.
            let out = tshark(
                &lua,
                f,
                &[
                    "-T",
                    "fields",
                    "-E",
                    "occurrence=a",
                    "-e",
                    "aptscope.stream",
                    "-e",
                    "aptscope.dir",
                    "-e",
                    "apt.name",
                ],
            );
            let want_dir = if d == "h2d" { "1" } else { "2" };
            let got: Vec<String> = out
                .lines()
                .map(|l| l.split('\t').collect::<Vec<_>>())
                .filter(|c| c.len() == 3 && c[0] == stream.to_string() && c[1] == want_dir)
                .flat_map(|c| c[2].split(',').map(str::to_string).collect::<Vec<_>>())
                .filter(|n| !n.is_empty())
                .collect();
            assert_eq!(got, want, "{} stream {stream} {d}", f.display());
        }
    }
}
