//! The bad-input catalogue (`tests/bad-input/`, made by its `make.sh`): `aptscope decode --json`
//! on each damaged file reports exactly the diagnostics `expected.txt` lists, kind and offset,
//! in order; it fails only on what is not traffic of these protocols at all (`exit=1` in the
//! list: random bytes, a capture of another link type), saying why; and for byte streams every
//! byte is in one record.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/bad-input")
}

/// The manifest: (file name, expected `kind@offset` items).
fn manifest() -> Vec<(String, Vec<String>)> {
    let text = std::fs::read_to_string(dir().join("expected.txt")).expect("expected.txt");
    text.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(|l| {
            let mut words = l.split_whitespace().map(str::to_string);
            let name = words.next().expect("a file name");
            (name, words.collect())
        })
        .collect()
}

/// `aptscope decode --json [ARGS] FILE`: the records, parsed; it must exit with `code`, and a
/// failure must say why on standard error.
fn decode_with(file: &Path, args: &[&str], code: i32) -> Vec<Value> {
    let out = Command::new(env!("CARGO_BIN_EXE_aptscope"))
        .args(["decode", "--json"])
        .args(args)
        .arg(file)
        .output()
        .expect("run aptscope");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.code() == Some(code) && (code == 0 || stderr.contains("aptscope: ")),
        "{}: exit {:?}, expected {code}\n{stderr}",
        file.display(),
        out.status.code(),
    );
    String::from_utf8(out.stdout)
        .expect("UTF-8 output")
        .lines()
        .map(|l| {
            serde_json::from_str(l)
                .unwrap_or_else(|e| panic!("{}: not JSON ({e}): {l}", file.display()))
        })
        .collect()
}

/// [`decode_with`] as the manifest says: `exit=1` first for an input that is refused.
fn decode(file: &Path, want: &[String]) -> Vec<Value> {
    decode_with(file, &[], if refused(want) { 1 } else { 0 })
}

fn refused(want: &[String]) -> bool {
    want.first().is_some_and(|w| w == "exit=1")
}

/// Every `diag` array of every record, in output order, as `kind@offset`.
fn diags(records: &[Value]) -> Vec<String> {
    records
        .iter()
        .filter_map(|r| r["diag"].as_array())
        .flatten()
        .map(|d| format!("{}@{}", d["kind"].as_str().unwrap_or("?"), d["offset"]))
        .collect()
}

#[test]
fn every_bad_input_gives_its_expected_diagnostics() {
    let mut wrong = vec![];
    for (name, want) in manifest() {
        let got = diags(&decode(&dir().join(&name), &want));
        let want: Vec<String> = want.into_iter().filter(|w| w != "exit=1").collect();
        if got != want {
            wrong.push(format!(
                "{name}\n  expected: {}\n  got:      {}",
                want.join(" "),
                got.join(" ")
            ));
        }
    }
    assert!(wrong.is_empty(), "\n{}", wrong.join("\n"));
}

#[test]
fn the_manifest_lists_every_file_of_the_catalogue() {
    let listed: Vec<String> = manifest().into_iter().map(|(n, _)| n).collect();
    let mut files: Vec<String> = std::fs::read_dir(dir())
        .expect("tests/bad-input")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .filter(|n| n != "make.sh" && n != "expected.txt")
        .collect();
    files.sort();
    let mut sorted = listed.clone();
    sorted.sort();
    assert_eq!(
        sorted, files,
        "expected.txt and the files of tests/bad-input/"
    );
    assert!(listed.len() >= 19, "{} cases", listed.len());
}

#[test]
fn byte_streams_are_accounted_for_byte_by_byte() {
    for (name, want) in manifest() {
        if !(name.ends_with(".bin") || name.ends_with(".txt")) {
            continue;
        }
        let path = dir().join(&name);
        let len = std::fs::metadata(&path).expect("file").len();
        let mut at = 0;
        // A refused stream is decoded anyway when the protocol is given.
        let forced: &[&str] = if refused(&want) {
            &["--proto", "apt"]
        } else {
            &[]
        };
        for r in decode_with(&path, forced, 0) {
            if !matches!(r["type"].as_str(), Some("frame" | "garbage")) {
                continue;
            }
            assert_eq!(
                r["offset"].as_u64(),
                Some(at),
                "{name}: contiguous records: {r}"
            );
            at += r["len"].as_u64().expect("len");
        }
        assert_eq!(at, len, "{name}: every byte is in a record");
    }
}
