//! Python's `to_arrow()` on several threads: a capture of any format decoded once, its records
//! given both to a [`RowPool`] (runs of records built on two or three threads, the last run in
//! parts, runs built on the calling thread when the threads hold enough) and to one
//! [`CaptureWriter`] given each record in turn. The pool's tables must be the writer's.
//!
//! Input: `[flags, budget, run, last, file...]`: `flags % 3` is the protocol (auto, apt,
//! elliptec), `flags / 3 % 2` adds a third thread, bit 64 keeps the batches (as Python does),
//! bit 128 builds the columns of words as dictionaries (Python builds text), bit 32 builds only
//! the tables whose name has an even length (Python's `tables=`); `budget` sets the rows
//! (1 + budget % 32) and bytes (64 + 32 × budget) per row group, which also end runs; `run` is
//! the records of every run (0: runs growing to a row group, as `to_arrow()` makes them);
//! `last` the records of each part of the last run at least (0: as `to_arrow()`, whose parts
//! are of thousands, so that no input this small has its last run in parts).
//! Checks: no error and no panic; every array passes Arrow's full validation; the same tables,
//! each the same rows (its batches one after the other), as the one writer; a `records` row
//! per record.

use crate::decode_pipeline::decode_records;
use crate::util::split_ctl;
use aptscope_dissector::detect::Proto;
use aptscope_dissector::record::Record;
use aptscope_parquet::pool::{Groups, RowPool, Wanted};
use aptscope_parquet::{CaptureWriter, Options, Sink};
use arrow_array::{Array, RecordBatch};
use std::collections::BTreeMap;
use std::io;
use std::sync::Arc;

/// Keeps every row group, as the pool's threads do.
struct Keep(Groups);

impl Sink for Keep {
    fn write(&mut self, table: &str, _part: u32, batch: &RecordBatch) -> io::Result<()> {
        self.0.push((table.to_string(), batch.clone()));
        Ok(())
    }
}

/// Each table's rows, its batches one after the other; every array validated in full.
fn tables(groups: &Groups, by: &str) -> BTreeMap<String, RecordBatch> {
    let mut all: BTreeMap<String, Vec<RecordBatch>> = BTreeMap::new();
    for (t, b) in groups {
        assert!(b.num_rows() > 0, "{by}: {t}: an empty batch");
        for (f, c) in b.schema().fields().iter().zip(b.columns()) {
            c.to_data()
                .validate_full()
                .unwrap_or_else(|e| panic!("{by}: {t}.{}: {e}", f.name()));
        }
        all.entry(t.clone()).or_default().push(b.clone());
    }
    all.into_iter()
        .map(|(t, bs)| {
            let b = arrow_select::concat::concat_batches(&bs[0].schema(), &bs)
                .unwrap_or_else(|e| panic!("{by}: {t}: batches of different schemas: {e}"));
            (t, b)
        })
        .collect()
}

/// The target's body: panics when a check fails.
pub fn fuzz(data: &[u8]) {
    let ([flags, budget, run, last], file) = split_ctl::<4>(data);
    let proto = match flags % 3 {
        0 => None,
        1 => Some(Proto::Apt),
        _ => Some(Proto::Elliptec),
    };
    let threads = 2 + usize::from(flags / 3 % 2);
    let opts = Options {
        rows_per_group: 1 + usize::from(budget % 32),
        bytes_per_group: 64 + 32 * usize::from(budget),
        max_open_kinds: 3,
        kind_rows: 2 + usize::from(budget % 16),
        words_as_text: flags & 128 == 0,
        batches_kept: flags & 64 != 0,
        ..Options::default()
    };
    let wanted: Option<Wanted> =
        (flags & 32 != 0).then(|| Arc::new(|t: &str| t.len().is_multiple_of(2)) as Wanted);

    let mut one = CaptureWriter::new(Keep(Vec::new()), "fuzz.bin", opts);
    if let Some(f) = wanted.clone() {
        one.only_tables(move |t| f(t));
    }
    let mut pool = RowPool::new(threads, "fuzz.bin", opts, wanted, Ok).expect("threads");
    if run > 0 {
        pool.set_run_records(usize::from(run));
    }
    if last > 0 {
        pool.set_last_part(usize::from(last));
    }
    let mut got: Groups = Vec::new();
    let mut records = 0u64;
    let mut each = |rec: &Record<'_>| {
        records += 1;
        one.record(rec)?;
        pool.push(rec, &mut |g| got.extend(g))
    };

    decode_records(file, proto, &mut each);
    pool.flush(&mut |g| got.extend(g)).expect("the last run");
    pool.ready(true, &mut |g| got.extend(g)).expect("every run");
    drop(pool);

    let (Keep(groups), sum) = one.finish().expect("one writer");
    assert_eq!(sum.records, records);
    let one = tables(&groups, "one writer");
    let many = tables(&got, &format!("{threads} threads"));
    assert_eq!(
        one.keys().collect::<Vec<_>>(),
        many.keys().collect::<Vec<_>>(),
        "the same tables"
    );
    for (t, b) in &one {
        assert_eq!(b, &many[t], "{t}: the same rows");
    }
    if let Some(r) = many.get("records") {
        assert_eq!(r.num_rows() as u64, records, "a records row per record");
    }
}
