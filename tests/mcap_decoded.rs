//! MCAP's decoded channels carry exactly what `decode --json` writes: for every sample, the
//! messages of the json channels of `aptscope convert SAMPLE out.mcap`, in file order, are the
//! lines of `aptscope decode --json SAMPLE`, byte for byte and in the same order; each on the
//! channel of its message.
//!
//! The one exception: `{"type":"input"}` records (damage of the input file, e.g. a truncated
//! pcap record) are not in the MCAP, because `convert` reads the input and writes a sound file;
//! they name no record and take no record number, so nothing else shifts.

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

#[test]
fn mcap_decoded_channels_equal_decode_json_on_every_sample() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut all = vec![];
    files(&root.join("samples"), &mut all);
    let scratch =
        std::env::temp_dir().join(format!("aptscope-mcap-decoded-{}", std::process::id()));
    std::fs::create_dir_all(&scratch).expect("scratch dir");
    let (mut compared, mut records, mut not_captures) = (0, 0, vec![]);
    for path in &all {
        let name = path
            .strip_prefix(root)
            .unwrap_or(path)
            .display()
            .to_string();
        // The generators beside the samples.
        if matches!(
            path.extension().and_then(|e| e.to_str()),
            Some("sh" | "py" | "md")
        ) {
            not_captures.push(name);
            continue;
        }
        let (json, err, ok) = aptscope(&["decode", "--json", &name], None);
        assert!(ok, "{name} does not decode: {err}");
        let out = scratch.join(format!("{compared}.mcap"));
        let out_s = out.display().to_string();
        let (_, err, ok) = aptscope(&["convert", &name, &out_s, "--force"], None);
        assert!(ok, "convert {name}: {err}");
        let bytes = std::fs::read(&out).expect("read the MCAP");
        let got = aptscope_capture::mcap::read_decoded(&bytes).expect("decoded channels");
        let want: Vec<&str> = json
            .lines()
            .filter(|l| {
                let v: serde_json::Value = serde_json::from_str(l).expect("decode --json is JSON");
                v["type"] != "input"
            })
            .collect();
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
        records += want.len();
    }
    let _ = std::fs::remove_dir_all(&scratch);
    // Every capture sample (samples/ and samples/sessions/): none was left out.
    assert!(compared >= 30, "{compared} samples compared");
    assert!(records > 1000, "{records} records compared");
    assert!(not_captures.len() <= 3, "{not_captures:?}");
}
