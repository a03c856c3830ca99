//! MCAP's decoded channels carry exactly what `decode --json` writes: for every sample (and
//! every damaged input of `tests/bad-input`, and a K10CR1 session for the units records), the
//! messages of the json channels of `aptscope convert SAMPLE out.mcap`, in file order, are the
//! lines of `aptscope decode --json SAMPLE`, byte for byte and in the same order; each on the
//! channel of its message. That includes the input file's own problems (`{"type":"input"}`,
//! a truncated pcap record …), which `convert` hands to the writer in their place.

mod common;

use common::aptscope;
use std::path::{Path, PathBuf};

/// Every file under `dir`, recursively, in name order.
fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    let mut es: Vec<PathBuf> = rd.filter_map(|e| e.ok().map(|e| e.path())).collect();
    es.sort();
    for p in es {
        if p.is_dir() {
            files(&p, out);
        } else {
            out.push(p);
        }
    }
}

/// The channel a record belongs on, from its JSON (frames, garbage and no-reply diagnostics).
fn topic_of(v: &serde_json::Value) -> Option<String> {
    let proto = v["proto"].as_str()?;
    match v["type"].as_str()? {
        "frame" if proto == "apt" => {
            Some(format!("/apt/{}", v["name"].as_str().unwrap_or("unknown")))
        }
        "frame" => Some(format!(
            "/ell/{}",
            if v["name"].is_null() {
                "unknown"
            } else {
                v["cmd"].as_str()?
            }
        )),
        "garbage" => Some(format!("/{proto}/garbage")),
        "diag" => Some(format!("/{proto}/diag")),
        _ => None,
    }
}

/// A K10CR1 (built-in stage): its HW_GET_INFO gives a units record, its motion values `phys`.
fn k10cr1(dir: &Path) -> PathBuf {
    let mut hex = String::new();
    for args in [
        &[
            "HW_GET_INFO",
            "model_number=K10CR1",
            "serial_number=55000123",
        ][..],
        &[
            "MOT_GET_VELPARAMS",
            "chan_ident=CH1",
            "min_vel=0",
            "acceleration=1502",
            "max_vel=73291093",
        ],
    ] {
        let mut a = vec!["encode"];
        a.extend_from_slice(args);
        a.extend_from_slice(&["--source", "usb", "--dest", "host"]);
        let (out, err, ok) = aptscope(&a, None);
        assert!(ok, "encode {args:?}: {err}");
        hex.push_str(&out);
    }
    let p = dir.join("k10cr1.hex");
    std::fs::write(&p, hex).expect("write the K10CR1 session");
    p
}

#[test]
fn mcap_decoded_channels_equal_decode_json_on_every_sample() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let scratch =
        std::env::temp_dir().join(format!("aptscope-mcap-decoded-{}", std::process::id()));
    std::fs::create_dir_all(&scratch).expect("scratch dir");
    let mut all = vec![];
    files(&root.join("samples"), &mut all);
    files(&root.join("tests/bad-input"), &mut all);
    all.push(k10cr1(&scratch));
    let (mut compared, mut not_captures, mut refused) = (0, vec![], vec![]);
    let mut types = std::collections::BTreeMap::<String, usize>::new();
    for path in &all {
        let name = path
            .strip_prefix(root)
            .unwrap_or(path)
            .display()
            .to_string();
        // The generators and notes beside the samples.
        if matches!(
            path.extension().and_then(|e| e.to_str()),
            Some("sh" | "py" | "md")
        ) || name.ends_with("expected.txt")
        {
            not_captures.push(name);
            continue;
        }
        let (json, err, ok) = aptscope(&["decode", "--json", &name], None);
        if !ok && (err.contains("not a capture") || err.contains("no serial traffic")) {
            // Refused as no traffic of these protocols (the bad-input catalogue's `exit=1`).
            refused.push(name);
            continue;
        }
        assert!(ok, "{name} does not decode: {err}");
        let out = scratch.join(format!("{compared}.mcap"));
        let out_s = out.display().to_string();
        let (_, err, ok) = aptscope(&["convert", &name, &out_s, "--force"], None);
        assert!(ok, "convert {name}: {err}");
        let bytes = std::fs::read(&out).expect("read the MCAP");
        let got = aptscope_capture::mcap::read_decoded(&bytes).expect("decoded channels");
        let want: Vec<&str> = json.lines().collect();
        for (i, (g, w)) in got.iter().zip(&want).enumerate() {
            assert_eq!(
                g.json, *w,
                "{name}: record {i} differs (MCAP topic {})",
                g.topic
            );
            let v: serde_json::Value = serde_json::from_str(w).expect("JSON");
            if let Some(t) = topic_of(&v) {
                assert_eq!(g.topic, t, "{name}: record {i} on the wrong channel: {w}");
            }
            if v["type"] == "frame" || v["type"] == "garbage" {
                assert_eq!(Some(u64::from(g.sequence)), v["n"].as_u64(), "{name}: {w}");
            }
            *types
                .entry(v["type"].as_str().unwrap_or("?").to_string())
                .or_default() += 1;
        }
        assert_eq!(
            got.len(),
            want.len(),
            "{name}: {} decoded messages in the MCAP, {} records from decode --json; the \
             first one more: {:?}",
            got.len(),
            want.len(),
            got.get(want.len())
                .map(|m| m.json.as_str())
                .or(want.get(got.len()).copied())
        );
        compared += 1;
    }
    let _ = std::fs::remove_dir_all(&scratch);
    // Every capture sample (samples/, samples/sessions/, tests/bad-input/): none left out, and
    // every kind of record met.
    assert!(compared >= 50, "{compared} inputs compared");
    assert!(not_captures.len() <= 6, "{not_captures:?}");
    refused.sort();
    assert_eq!(
        refused,
        [
            "tests/bad-input/random.bin",
            "tests/bad-input/unknown-linktype.pcap"
        ],
        "only what the bad-input catalogue marks exit=1 is refused"
    );
    for (t, min) in [
        ("frame", 1000),
        ("garbage", 20),
        ("diag", 10),
        ("detect", 30),
        ("stream", 20),
        ("input", 5),
        ("units", 1),
    ] {
        let n = types.get(t).copied().unwrap_or(0);
        assert!(n >= min, "{n} {t} records compared ({types:?})");
    }
}
