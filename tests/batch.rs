//! `decode` over many files: parallel output in input order, the Parquet dataset, bad inputs.

mod common;

use arrow_array::cast::AsArray;
use arrow_array::{Array, ArrayRef, RecordBatch};
use common::proc::{wait_for, Proc};
use common::{aptscope, aptscope_env};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use serde_json::Value;
use std::path::{Path, PathBuf};

const SAMPLES: [&str; 4] = [
    "samples/kdc101-session.pcapng",
    "samples/damaged.bin",
    "samples/elliptec-bus.txt",
    "samples/kdc101-session.mcap",
];

fn tmp(name: &str) -> PathBuf {
    let p = std::env::temp_dir().join(format!("aptscope-batch-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&p);
    let _ = std::fs::remove_file(&p);
    p
}

/// A batch's column of that name (the test fails without it).
fn column<'b>(b: &'b RecordBatch, name: &str) -> &'b ArrayRef {
    b.column_by_name(name)
        .unwrap_or_else(|| panic!("no column {name}"))
}

/// Rows of every part file of one table, in file-name order.
fn rows(dir: &Path) -> Vec<RecordBatch> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("table dir")
        .map(|e| e.expect("entry").path())
        .collect();
    files.sort();
    files
        .iter()
        .flat_map(|f| {
            let file = std::fs::File::open(f).expect("part");
            ParquetRecordBatchReaderBuilder::try_new(file)
                .expect("parquet")
                .build()
                .expect("reader")
                .map(|b| b.expect("batch"))
                .collect::<Vec<_>>()
        })
        .collect()
}

#[test]
fn parallel_output_is_the_sequential_output() {
    for fmt in ["--json", "--to=text"] {
        let mut a = vec!["decode", fmt, "-j", "1"];
        a.extend(SAMPLES);
        let (one, err, ok) = aptscope(&a, None);
        assert!(ok, "{err}");
        a[3] = "3";
        let (three, err, ok) = aptscope(&a, None);
        assert!(ok, "{err}");
        assert_eq!(one, three, "{fmt}");
        assert!(one.lines().count() > 50);
    }
}

/// Random streams large enough that a file's rendering runs far ahead of the writer (megabytes
/// of NDJSON each), beside every sample: `-j 2` and `-j 4` write exactly what `-j 1` writes,
/// with files ahead held in memory (the default) and spilled to disk (no memory allowed for
/// them: `APTSCOPE_QUEUED_MAX=0`).
#[test]
fn every_worker_renders_and_the_output_is_that_of_one() {
    let dir = common::Scratch::new("batch-random");
    let table = aptscope_dissector::Table::global();
    let mut files: Vec<String> = vec![];
    for (seed, frames, garbage) in [(1u64, 40_000, true), (2, 40_000, false), (3, 300, true)] {
        let f = dir.join(&format!("random{seed}.bin"));
        let s = aptscope_dissector::synth::stream(table, seed, frames, garbage);
        std::fs::write(&f, s).expect("write stream");
        files.push(f.to_str().expect("utf-8 path").to_string());
    }
    files.splice(1..1, SAMPLES.iter().map(|s| s.to_string()));
    for fmt in ["--json", "--to=text"] {
        let mut a = vec!["decode", fmt, "-j", "1"];
        a.extend(files.iter().map(String::as_str));
        // Text and NDJSON are UTF-8: equal strings are equal bytes.
        let (one, err, ok) = aptscope(&a, None);
        assert!(ok, "{err}");
        assert!(one.len() > 4 << 20, "{} bytes", one.len());
        for (j, queued) in [("2", None), ("4", None), ("2", Some("0")), ("4", Some("0"))] {
            a[3] = j;
            let env: Vec<_> = queued
                .map(|q| ("APTSCOPE_QUEUED_MAX", q))
                .into_iter()
                .collect();
            let (many, err, ok) = aptscope_env(&a, None, &env);
            assert!(ok, "{err}");
            assert!(
                one == many,
                "{fmt} -j {j} (queued at most {queued:?}): {} vs {} bytes",
                one.len(),
                many.len()
            );
        }
    }
}

#[test]
fn parquet_dataset_has_every_record_with_its_file() {
    let out = tmp("ds");
    let o = out.to_str().expect("utf-8 path");
    let mut a = vec!["decode", "--to", "parquet", "-o", o];
    a.extend(SAMPLES);
    let (_, err, ok) = aptscope(&a, None);
    assert!(ok, "{err}");
    assert!(err.contains("4 of 4 files"), "{err}");
    // Frames and garbage runs: as many rows as NDJSON has numbered records, per file.
    let mut j = vec!["decode", "--json"];
    j.extend(SAMPLES);
    let (nd, _, ok) = aptscope(&j, None);
    assert!(ok);
    let numbered: Vec<(String, u64)> = nd
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).expect("JSON"))
        .filter(|v| v["n"].is_u64())
        .map(|v| {
            (
                v["file"].as_str().unwrap_or_default().to_string(),
                v["n"].as_u64().unwrap_or(0),
            )
        })
        .collect();
    let mut got = vec![];
    for b in rows(&out.join("records")) {
        let file = column(&b, "file").as_string::<i32>();
        let n = column(&b, "n").as_primitive::<arrow_array::types::UInt64Type>();
        for i in 0..b.num_rows() {
            if !n.is_null(i) {
                got.push((file.value(i).to_string(), n.value(i)));
            }
        }
    }
    assert_eq!(got, numbered);
    // A typed kind table: positions as integers, joinable on (file, n).
    let st = rows(&out.join("MOT_GET_DCSTATUSUPDATE"));
    assert!(!st.is_empty());
    let pos = column(&st[0], "position");
    assert_eq!(pos.data_type(), &arrow_schema::DataType::Int32);
    // The damaged file's problems are in the diagnostics column.
    let mut damaged_diags = 0;
    for b in rows(&out.join("records")) {
        let file = column(&b, "file").as_string::<i32>();
        let d = column(&b, "diagnostics").as_list::<i32>();
        for i in 0..b.num_rows() {
            if file.value(i) == "samples/damaged.bin" {
                damaged_diags += d.value(i).len();
            }
        }
    }
    assert!(damaged_diags > 0);
    // An existing dataset is kept unless --force.
    let (_, err, ok) = aptscope(&a, None);
    assert!(!ok && err.contains("--force"), "{err}");
    a.insert(1, "--force");
    let (_, err, ok) = aptscope(&a, None);
    assert!(ok, "{err}");
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn bad_inputs_are_named_and_skipped() {
    let junk = tmp("junk.bin");
    // Bytes that frame as neither protocol (a PNG header and text).
    let mut b = b"\x89PNG\r\n\x1a\n".to_vec();
    b.extend(b"IHDR not a capture at all, just an image header and some prose. ".repeat(40));
    std::fs::write(&junk, &b).expect("write");
    let j = junk.to_str().expect("utf-8");
    let out = tmp("bad-ds");
    let o = out.to_str().expect("utf-8");
    let (_, err, ok) = aptscope(
        &[
            "decode",
            "--to",
            "parquet",
            "-o",
            o,
            "samples/kdc101-session.bin",
            j,
            "samples/nope.bin",
        ],
        None,
    );
    assert!(!ok, "skipped inputs fail the run at its end");
    assert!(
        err.contains(&format!("skipped {j}: not a capture")),
        "{err}"
    );
    assert!(err.contains("samples/nope.bin"), "{err}");
    assert!(err.contains("1 of 3 files"), "{err}");
    let good: usize = rows(&out.join("records"))
        .iter()
        .map(|b| b.num_rows())
        .sum();
    assert!(good > 0, "the good file is in the dataset");
    // Text output: the good file's lines, then the run fails.
    let (txt, err, ok) = aptscope(&["decode", "samples/kdc101-session.bin", j], None);
    assert!(!ok && err.contains("not a capture"), "{err}");
    assert!(
        txt.contains("MOT_MOVE_HOME") && !txt.contains("# file 2"),
        "{txt}"
    );
    // Alone, it is refused too, with the reason; a forced protocol decodes it anyway.
    let (txt, err, ok) = aptscope(&["decode", j], None);
    assert!(
        !ok && err.contains("not a capture") && txt.is_empty(),
        "{err}"
    );
    let (txt, _, ok) = aptscope(&["decode", "--proto", "apt", j], None);
    assert!(ok && !txt.is_empty());
    // No directory: said so.
    let (_, err, ok) = aptscope(
        &["decode", "--to", "parquet", "samples/kdc101-session.bin"],
        None,
    );
    assert!(!ok && err.contains("-o DIR"), "{err}");
    // -o without --to parquet: said in one sentence (no gap from a lost line continuation).
    let (_, err, ok) = aptscope(&["decode", "-o", o, "samples/kdc101-session.bin"], None);
    assert!(
        !ok && err.contains("text and NDJSON go to standard output"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&out);
    let _ = std::fs::remove_file(&junk);
}

/// Every file of a dataset under `dir`, by path below it, with its bytes.
fn dataset_files(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = vec![];
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).expect("dataset dir") {
            let p = e.expect("entry").path();
            if p.is_dir() {
                todo.push(p);
            } else {
                let rel = p.strip_prefix(dir).expect("below").to_path_buf();
                out.push((rel, std::fs::read(&p).expect("part file")));
            }
        }
    }
    out.sort();
    out
}

/// One capture with cores to spare: its row groups are encoded on other threads (one with
/// `-j 2`, two with `-j 3`), and the dataset is that of `-j 1`, part file for part file and byte
/// for byte (a stream of every message form: dozens of kind tables cut into row groups early,
/// the records table into several, part files of several row groups written by one thread
/// each).
#[test]
fn one_capture_encoded_on_spare_cores_is_the_dataset_of_one() {
    let dir = common::Scratch::new("batch-parquet-one");
    let f = dir.join("random.bin");
    let table = aptscope_dissector::Table::global();
    std::fs::write(
        &f,
        aptscope_dissector::synth::stream(table, 7, 200_000, true),
    )
    .expect("write");
    let f = f.to_str().expect("utf-8 path");
    let mut sets = vec![];
    for j in ["1", "2", "3"] {
        let out = dir.join(&format!("ds{j}"));
        let o = out.to_str().expect("utf-8 path");
        let (_, err, ok) = aptscope(&["decode", "--to", "parquet", "-j", j, "-o", o, f], None);
        assert!(ok, "{err}");
        sets.push(dataset_files(&out));
    }
    let parts = sets[0].len();
    assert!(parts > 100, "{parts} part files");
    // Part files of several row groups: the records table's and many kind tables'.
    let groups = |bytes: &Vec<u8>| {
        ParquetRecordBatchReaderBuilder::try_new(bytes::Bytes::from(bytes.clone()))
            .expect("parquet")
            .metadata()
            .num_row_groups()
    };
    let records: usize = sets[0]
        .iter()
        .filter(|(p, _)| p.starts_with("records"))
        .map(|(_, b)| groups(b))
        .sum();
    assert!(records > 2, "{records} row groups of records");
    let several = sets[0].iter().filter(|(_, b)| groups(b) > 1).count();
    assert!(several > 50, "{several} part files of several row groups");
    for (j, s) in [(2, &sets[1]), (3, &sets[2])] {
        let names =
            |s: &Vec<(PathBuf, Vec<u8>)>| s.iter().map(|(p, _)| p.clone()).collect::<Vec<_>>();
        assert_eq!(names(s), names(&sets[0]), "-j {j}: part files");
        for ((p, a), (_, b)) in sets[0].iter().zip(s) {
            assert!(a == b, "-j {j}: {} differs", p.display());
        }
    }
}

/// Ctrl-C during `decode --to parquet`: the file being decoded stops and its part files are
/// completed (none left `.partial`, every one readable, holding every record the message
/// counts), the files not started are named as such, and the run fails.
#[test]
fn a_stopped_parquet_run_leaves_complete_files() {
    let dir = common::Scratch::new("batch-parquet-stop");
    let table = aptscope_dissector::Table::global();
    // Large enough that the first file is still being decoded (a debug build: seconds) when
    // its first `records` row group is out.
    let big = dir.join("big.bin");
    std::fs::write(
        &big,
        aptscope_dissector::synth::stream(table, 5, 400_000, true),
    )
    .expect("write");
    let small = dir.join("small.bin");
    std::fs::write(
        &small,
        aptscope_dissector::synth::stream(table, 6, 2_000, true),
    )
    .expect("write");
    let out = dir.join("ds");
    let s = |p: &Path| p.to_str().expect("utf-8 path").to_string();
    let args = [
        "decode",
        "--to",
        "parquet",
        "-j",
        "1",
        "-o",
        &s(&out),
        &s(&big),
        &s(&small),
        &s(&small),
    ];
    let mut p = Proc::aptscope(&args);
    let records = out.join("records");
    wait_for(
        "the first records row group",
        || p.both(),
        || std::fs::read_dir(&records).is_ok_and(|mut d| d.next().is_some()),
    );
    p.signal(nix::sys::signal::Signal::SIGINT);
    let st = p.wait_exit();
    let err = p.stderr();
    assert!(!st.success(), "{err}");
    assert!(err.contains("stopped by SIGINT"), "{err}");
    assert!(err.contains("2 of 3 files not started"), "{err}");
    let said: usize = err
        .split("holds the ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|n| n.parse().ok())
        .expect("a record count");
    assert!(said >= 65_536, "{said}");
    let files = dataset_files(&out);
    assert!(
        files
            .iter()
            .all(|(p, _)| p.extension().is_some_and(|e| e == "parquet")),
        "{:?}",
        files.iter().map(|f| &f.0).collect::<Vec<_>>()
    );
    let rows: usize = rows(&records).iter().map(|b| b.num_rows()).sum();
    assert_eq!(rows, said);
}
