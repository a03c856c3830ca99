//! The dataset written from real decoder records, read back with the Parquet reader.

use aptscope_dissector::detect::Proto;
use aptscope_dissector::record::{Ctx, Decoder};
use aptscope_dissector::synth;
use aptscope_dissector::table::Dir;
use aptscope_dissector::Table;
use aptscope_parquet::{prepare_dir, CaptureWriter, DirSink, MemSink, Options};
use arrow_array::cast::AsArray;
use arrow_array::types::{Int32Type, UInt64Type};
use arrow_array::{Array, RecordBatch};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use std::io;

fn read(bytes: Vec<u8>) -> Vec<RecordBatch> {
    let r = ParquetRecordBatchReaderBuilder::try_new(bytes::Bytes::from(bytes))
        .expect("parquet")
        .build()
        .expect("reader");
    r.map(|b| b.expect("batch")).collect()
}

fn decode_mem(
    chunks: &[(Ctx, Vec<u8>)],
    proto: Option<Proto>,
    opts: Options,
) -> Vec<(String, Vec<u8>)> {
    let mut w = CaptureWriter::new(MemSink::new(opts), "cap.bin", opts);
    let mut d = Decoder::new(proto);
    for (c, b) in chunks {
        d.push(*c, b, &mut |r| w.record(r)).expect("push");
    }
    d.finish(&mut |r| w.record(r)).expect("finish");
    let (sink, sum) = w.finish().expect("finish writer");
    assert!(sum.records > 0);
    sink.finish().expect("bytes")
}

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace()
        .map(|x| u8::from_str_radix(x, 16).expect("hex"))
        .collect()
}

/// A move request, its completion (a status with position 0x1000) and 3 garbage bytes.
fn apt_session() -> Vec<(Ctx, Vec<u8>)> {
    let host = Ctx {
        stream: 0,
        dir: Some(Dir::HostToDevice),
        ts_ns: Some(1_000_000_000),
    };
    let dev = Ctx {
        stream: 0,
        dir: Some(Dir::DeviceToHost),
        ts_ns: Some(1_250_000_000),
    };
    // MOT_MOVE_ABSOLUTE (0x0453) chan 1, position 4096; MOT_MOVE_COMPLETED (0x0464) with a
    // 14-byte status: chan 1, position 4096, encoder 0, status bits 0x00000400.
    vec![
        (host, hex("53 04 06 00 d0 01 01 00 00 10 00 00")),
        (
            dev,
            hex("64 04 0e 00 81 50 01 00 00 10 00 00 00 00 00 00 00 04 00 00 aa bb cc"),
        ),
    ]
}

#[test]
fn records_and_kind_tables_are_typed() {
    let out = decode_mem(&apt_session(), Some(Proto::Apt), Options::default());
    let names: Vec<&str> = out.iter().map(|(n, _)| n.as_str()).collect();
    assert!(names.contains(&"records"), "{names:?}");
    assert!(names.contains(&"MOT_MOVE_ABSOLUTE"), "{names:?}");
    assert!(names.contains(&"MOT_MOVE_COMPLETED"), "{names:?}");
    let rec = &read(
        out.iter()
            .find(|(n, _)| n == "records")
            .expect("records")
            .1
            .clone(),
    )[0];
    let ty = rec.column_by_name("type").expect("type").as_string::<i32>();
    let types: Vec<&str> = (0..rec.num_rows()).map(|i| ty.value(i)).collect();
    assert_eq!(types, ["frame", "frame", "garbage"], "{types:?}");
    let file = rec.column_by_name("file").expect("file").as_string::<i32>();
    assert_eq!(file.value(0), "cap.bin");
    let pair = rec
        .column_by_name("pair")
        .expect("pair")
        .as_primitive::<UInt64Type>();
    assert!(pair.is_null(0));
    assert_eq!(pair.value(1), 1, "the completion pairs with the move");
    let lat = rec
        .column_by_name("latency_ms")
        .expect("latency")
        .as_primitive::<arrow_array::types::Float64Type>();
    assert!((lat.value(1) - 250.0).abs() < 1e-9);
    let diags = rec
        .column_by_name("diagnostics")
        .expect("diagnostics")
        .as_list::<i32>();
    assert_eq!(diags.value(0).len(), 0);
    let g = diags.value(2);
    let g = g.as_struct();
    assert_eq!(g.column(0).as_string::<i32>().value(0), "trailing_bytes");
    assert_eq!(
        g.column(1).as_primitive::<UInt64Type>().value(0),
        20,
        "offset in its lane"
    );

    let mv = &read(
        out.iter()
            .find(|(n, _)| n == "MOT_MOVE_ABSOLUTE")
            .expect("kind")
            .1
            .clone(),
    )[0];
    let pos = mv
        .column_by_name("absolute_position")
        .expect("absolute_position")
        .as_primitive::<Int32Type>();
    assert_eq!(pos.value(0), 4096);
    let schema = mv.schema();
    let meta = schema
        .field_with_name("absolute_position")
        .expect("field")
        .metadata();
    assert_eq!(meta.get("quantity").map(String::as_str), Some("pos"));
    assert_eq!(meta.get("unit").map(String::as_str), Some("counts"));
    let n = mv
        .column_by_name("n")
        .expect("n")
        .as_primitive::<UInt64Type>();
    assert_eq!(n.value(0), 1, "joins records on (file, n)");
}

#[test]
fn elliptec_kind_tables_carry_status_names_and_codes() {
    let host = Ctx {
        stream: 0,
        dir: None,
        ts_ns: None,
    };
    let out = decode_mem(
        &[(host, b"0gs\r\n0GS09\r\n0gp\r\n0PO00001000\r\n".to_vec())],
        Some(Proto::Elliptec),
        Options::default(),
    );
    let gs = &read(
        out.iter()
            .find(|(n, _)| n == "ELL_GET_STATUS")
            .expect("ELL_GET_STATUS")
            .1
            .clone(),
    )[0];
    assert_eq!(
        gs.column_by_name("status")
            .expect("status")
            .as_string::<i32>()
            .value(0),
        "BUSY"
    );
    assert_eq!(
        gs.column_by_name("status_code")
            .expect("code")
            .as_primitive::<arrow_array::types::UInt8Type>()
            .value(0),
        9
    );
    let po = &read(
        out.iter()
            .find(|(n, _)| n == "ELL_POSITION")
            .expect("ELL_POSITION")
            .1
            .clone(),
    )[0];
    assert_eq!(
        po.column_by_name("position")
            .expect("p")
            .as_primitive::<arrow_array::types::Int64Type>()
            .value(0),
        4096
    );
}

/// Many kinds and small row groups: every row still lands, once, in row groups no bigger than
/// asked; a directory dataset's part files hold several row groups each, at most as many as
/// asked, and files are closed early when the open ones hold too many column chunks.
#[test]
fn bounded_buffers_keep_every_row() -> io::Result<()> {
    let bytes = synth::stream(Table::global(), 7, 600, true);
    let opts = Options {
        rows_per_group: 100,
        max_open_kinds: 4,
        kind_rows: 100,
        groups_per_file: 3,
        open_chunks: 1000,
        ..Options::default()
    };
    let tmp = std::env::temp_dir().join(format!("aptscope-pq-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    prepare_dir(&tmp, false)?;
    assert!(
        prepare_dir(&tmp, false).is_err(),
        "an existing dataset needs force"
    );
    let mut w = CaptureWriter::new(DirSink::new(&tmp, 3, opts), "synth", opts);
    let mut d = Decoder::new(Some(Proto::Apt));
    for c in bytes.chunks(4096) {
        d.push(Ctx::default(), c, &mut |r| w.record(r))?;
    }
    d.finish(&mut |r| w.record(r))?;
    let (_, sum) = w.finish()?;
    let (mut rows, mut frames_in_kinds, mut files, mut groups) = (0usize, 0usize, 0usize, 0);
    let (mut full, mut cut) = (0, 0);
    for e in std::fs::read_dir(&tmp)? {
        let e = e?;
        let mut names = vec![];
        for p in std::fs::read_dir(e.path())? {
            let p = p?.path();
            let name = p
                .file_name()
                .and_then(|n| n.to_str())
                .unwrap_or_default()
                .to_string();
            assert!(
                name.starts_with("part-00003-") && name.ends_with(".parquet"),
                "{name}"
            );
            names.push(name.clone());
            files += 1;
            let r =
                ParquetRecordBatchReaderBuilder::try_new(bytes::Bytes::from(std::fs::read(&p)?))
                    .expect("parquet");
            let n_groups = r.metadata().num_row_groups();
            assert!((1..=3).contains(&n_groups), "{name}: {n_groups} row groups");
            groups += n_groups;
            if n_groups == 3 {
                full += 1;
            } else {
                cut += 1;
            }
            for i in 0..n_groups {
                let n = r.metadata().row_group(i).num_rows();
                assert!(n <= 100 && n > 0, "{name}: row group {i}: {n}");
            }
            let b = read(std::fs::read(&p)?);
            let n: usize = b.iter().map(|x| x.num_rows()).sum();
            if e.file_name() == "records" {
                rows += n;
            } else {
                frames_in_kinds += n;
            }
        }
        // Parts numbered from 0 in each table, none missing.
        names.sort();
        for (i, n) in names.iter().enumerate() {
            assert_eq!(n, &format!("part-00003-{i:05}.parquet"));
        }
    }
    assert_eq!(rows as u64, sum.records);
    assert_eq!(groups as u64, sum.row_groups);
    assert!(files < groups, "{files} files of {groups} row groups");
    assert!(full > 0 && cut > 0, "{full} files full, {cut} cut early");
    assert!(
        frames_in_kinds as u64 <= sum.frames && frames_in_kinds > 400,
        "{frames_in_kinds}"
    );
    prepare_dir(&tmp, true)?;
    assert_eq!(std::fs::read_dir(&tmp)?.count(), 0, "force replaced it");
    std::fs::remove_dir_all(&tmp)
}

/// A capture that fails part way (the writer dropped unfinished): the part files it had
/// begun are completed all the same, readable, with every row group written, and none is left
/// `.partial`.
#[test]
fn an_unfinished_capture_leaves_complete_files() -> io::Result<()> {
    let bytes = synth::stream(Table::global(), 11, 400, true);
    let opts = Options {
        rows_per_group: 50,
        kind_rows: 50,
        ..Options::default()
    };
    let tmp = std::env::temp_dir().join(format!("aptscope-pq-drop-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    prepare_dir(&tmp, false)?;
    let mut w = CaptureWriter::new(DirSink::new(&tmp, 0, opts), "synth", opts);
    let mut d = Decoder::new(Some(Proto::Apt));
    let mut records = 0;
    d.push(Ctx::default(), &bytes, &mut |r| {
        records += 1;
        w.record(r)
    })?;
    assert!(records > 200, "{records} records");
    drop(w);
    let mut rows = 0;
    let mut files = 0;
    for p in std::fs::read_dir(tmp.join("records"))? {
        let p = p?.path();
        assert_eq!(
            p.extension().and_then(|e| e.to_str()),
            Some("parquet"),
            "{}",
            p.display()
        );
        rows += read(std::fs::read(&p)?)
            .iter()
            .map(|b| b.num_rows())
            .sum::<usize>();
        files += 1;
    }
    // Row groups of 50 rows: those written are all there; the rows still buffered are lost.
    assert!(files >= 1);
    assert_eq!(rows, records / 50 * 50);
    for e in std::fs::read_dir(&tmp)? {
        for p in std::fs::read_dir(e?.path())? {
            let p = p?.path();
            assert!(
                !p.to_string_lossy().ends_with(".partial"),
                "{}",
                p.display()
            );
        }
    }
    std::fs::remove_dir_all(&tmp)
}

/// Counts the row groups written, by table.
#[derive(Default)]
struct Count(std::collections::BTreeMap<String, u32>);

impl aptscope_parquet::Sink for Count {
    fn write(&mut self, table: &str, _part: u32, _batch: &RecordBatch) -> io::Result<()> {
        *self.0.entry(table.to_string()).or_default() += 1;
        Ok(())
    }
}

/// The raw bytes of each `records` row group written.
#[derive(Default)]
struct RawBytes(Vec<usize>);

impl aptscope_parquet::Sink for RawBytes {
    fn write(&mut self, table: &str, _part: u32, batch: &RecordBatch) -> io::Result<()> {
        if table == "records" {
            let raw = batch.column_by_name("raw").expect("raw");
            let raw = raw.as_binary::<i32>();
            self.0.push(raw.iter().flatten().map(<[u8]>::len).sum());
        }
        Ok(())
    }
}

/// A line held high (0xFF bytes) is garbage runs of 4 KiB each: `records` is written when its
/// bytes reach the budget, not only when its rows do, so memory stays bounded (300 MB of 0xFF
/// held 268 MiB in one row group), and no row is lost.
#[test]
fn records_of_long_rows_are_cut_by_bytes() {
    let budget = 20_000;
    let opts = Options {
        bytes_per_group: budget,
        ..Options::default()
    };
    let mut w = CaptureWriter::new(RawBytes::default(), "ff.bin", opts);
    let mut d = Decoder::new(Some(Proto::Apt));
    let line = vec![0xFF; 200_000];
    d.push(Ctx::default(), &line, &mut |r| w.record(r))
        .expect("push");
    d.finish(&mut |r| w.record(r)).expect("finish");
    let (sink, sum) = w.finish().expect("finish writer");
    let groups = sink.0;
    assert!(groups.len() >= 200_000 / budget, "{groups:?}");
    // Each over the budget by one row at most (a garbage run: 4 KiB), and every byte kept.
    assert!(groups.iter().all(|b| *b < budget + 4096), "{groups:?}");
    assert_eq!(groups.iter().sum::<usize>(), line.len());
    assert!(sum.records > 40, "{sum:?}");
}

/// The rows of each row group written, by table.
#[derive(Default)]
struct Groups(std::collections::BTreeMap<String, Vec<usize>>);

impl aptscope_parquet::Sink for Groups {
    fn write(&mut self, table: &str, _part: u32, batch: &RecordBatch) -> io::Result<()> {
        self.0
            .entry(table.to_string())
            .or_default()
            .push(batch.num_rows());
        Ok(())
    }
}

/// Status messages with every flag set carry a list of a dozen names a row: the kind tables
/// are written when their text reaches the budget (each on its own, and together), not only
/// when their rows do, and no row is lost.
#[test]
fn kind_tables_of_long_rows_are_cut_by_bytes() {
    let frames = [
        "81 04 0e 00 81 2a 01 00 e8 03 00 00 d0 07 00 00 ff ff ff ff",
        "91 04 0e 00 81 2a 01 00 e8 03 00 00 14 00 00 00 ff ff ff ff",
        "2a 04 06 00 81 2a 01 00 ff ff ff ff",
    ];
    let one: Vec<u8> = frames.iter().flat_map(|f| hex(f)).collect();
    let opts = Options {
        bytes_per_group: 4096,
        ..Options::default()
    };
    let mut w = CaptureWriter::new(Groups::default(), "flags.bin", opts);
    let mut d = Decoder::new(Some(Proto::Apt));
    d.push(Ctx::default(), &one.repeat(300), &mut |r| w.record(r))
        .expect("push");
    d.finish(&mut |r| w.record(r)).expect("finish");
    let (groups, sum) = w.finish().expect("finish writer");
    assert_eq!(sum.frames, 900);
    let kinds: Vec<(&String, &Vec<usize>)> =
        groups.0.iter().filter(|(t, _)| *t != "records").collect();
    assert_eq!(kinds.len(), 3, "{:?}", groups.0);
    for (t, g) in kinds {
        // 300 rows, a dozen flag names each (about 120 bytes): cut into many row groups.
        assert_eq!(g.iter().sum::<usize>(), 300, "{t}: {g:?}");
        assert!(g.len() >= 8 && g.iter().all(|n| *n < 100), "{t}: {g:?}");
    }
}

/// A stream of every form brings hundreds of kinds in random order: each kind's rows are
/// written once they are many, not whenever another kind comes along (which wrote a row group
/// of a few rows for nearly every frame).
#[test]
fn many_kinds_do_not_make_a_row_group_per_few_rows() {
    let bytes = synth::stream(Table::global(), 11, 20_000, false);
    let opts = Options::default();
    let mut w = CaptureWriter::new(Count::default(), "cap.bin", opts);
    let mut d = Decoder::new(Some(Proto::Apt));
    d.push(Ctx::default(), &bytes, &mut |r| w.record(r))
        .expect("push");
    d.finish(&mut |r| w.record(r)).expect("finish");
    let (count, sum) = w.finish().expect("finish writer");
    let kinds = count.0.len();
    assert!(kinds > 100, "{kinds} kinds");
    // 20,000 frames, fewer than a row group's worth: one row group per table.
    assert!(count.0.values().all(|&n| n == 1), "{:?}", count.0);
    assert_eq!(sum.row_groups, kinds as u64);
}

/// The tables kept with `only_tables` are those of the whole dataset, byte for byte; the
/// others are not written.
#[test]
fn only_the_tables_asked_for() {
    let bytes = synth::stream(Table::global(), 11, 400, true);
    let opts = Options::default();
    let run = |keep: Option<&'static [&'static str]>| {
        let mut w = CaptureWriter::new(MemSink::new(opts), "cap.bin", opts);
        if let Some(k) = keep {
            w.only_tables(move |n| k.contains(&n));
        }
        let mut d = Decoder::new(Some(Proto::Apt));
        d.push(Ctx::default(), &bytes, &mut |r| w.record(r))
            .expect("push");
        d.finish(&mut |r| w.record(r)).expect("finish");
        let (sink, sum) = w.finish().expect("finish writer");
        (sink.finish().expect("bytes"), sum.records)
    };
    let (all, n) = run(None);
    let all: std::collections::BTreeMap<String, Vec<u8>> = all.into_iter().collect();
    let kind = all
        .keys()
        .find(|k| *k != "records")
        .expect("a kind table")
        .clone();
    let kind: &'static str = Box::leak(kind.into_boxed_str());
    for keep in [&["records"][..], &[kind], &["records", kind]] {
        let keep: &'static [&'static str] = Box::leak(keep.to_vec().into_boxed_slice());
        let (some, m) = run(Some(keep));
        assert_eq!(m, n, "records counted whichever tables are kept");
        let names: Vec<&str> = some.iter().map(|(t, _)| t.as_str()).collect();
        let mut want = keep.to_vec();
        want.sort();
        assert_eq!(names, want);
        for (t, b) in &some {
            assert_eq!(read(b.clone()), read(all[t].clone()), "{t}");
        }
    }
}

/// Which columns carry minimum/maximum statistics: the key `file` and the numbers and times
/// (they prune row groups), not the other text columns nor the raw bytes (a row group mixes
/// their values, and comparing every value cost the writer a twelfth of its instructions).
#[test]
fn statistics_where_they_prune() {
    let out = decode_mem(&apt_session(), Some(Proto::Apt), Options::default());
    for table in ["records", "MOT_MOVE_COMPLETED"] {
        let bytes = &out.iter().find(|(n, _)| n == table).expect("table").1;
        let meta = ParquetRecordBatchReaderBuilder::try_new(bytes::Bytes::from(bytes.clone()))
            .expect("parquet")
            .metadata()
            .clone();
        let rg = meta.row_group(0);
        let stats = |path: &str| {
            let c = rg
                .columns()
                .iter()
                .find(|c| c.column_path().string() == path)
                .unwrap_or_else(|| panic!("{table}: no column {path}"));
            c.statistics()
                .is_some_and(|s| s.min_bytes_opt().is_some() && s.max_bytes_opt().is_some())
        };
        for with in ["file", "n", "ts_ns"] {
            assert!(stats(with), "{table}: {with} has no minimum and maximum");
        }
        let without: &[&str] = if table == "records" {
            &["name", "dir", "type", "raw", "diagnostics.list.item.msg"]
        } else {
            &["chan_ident", "status_bits.list.item"]
        };
        for w in without {
            assert!(!stats(w), "{table}: {w} has a minimum and maximum");
        }
    }
}
