//! The rows of `decode --to parquet` and Python's `to_arrow`: a capture of any format decoded
//! into a [`CaptureWriter`] with small budgets, so that every table is cut into many row groups
//! by rows, by bytes and by the kind tables' joint budgets.
//!
//! Input: `[flags, budget, file...]`: `flags % 3` is the protocol (auto, apt, elliptec), the
//! format is sniffed from the file; `budget` sets the rows (1 + budget % 16) and bytes
//! (64 + 16 × budget) per row group. Checks: no error and no panic; every array passes Arrow's
//! full validation (offsets, UTF-8, nulls of non-nullable columns); each table's row groups are
//! numbered 0, 1, 2 … and hold at most the rows per group; `records` has a row per record
//! and its `raw` column holds exactly the captured bytes of frames and garbage; every row group
//! written as Parquet and read back is the same batch (its columns of words as text).

use crate::decode_pipeline::decode_records;
use crate::util::split_ctl;
use aptscope_dissector::detect::Proto;
use aptscope_parquet::{CaptureWriter, Options, Sink, TableWriter};
use arrow_array::cast::AsArray;
use arrow_array::{Array, RecordBatch};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use std::collections::BTreeMap;
use std::io;

/// Checks each row group as it is written.
struct Check {
    rows_per_group: usize,
    groups_per_file: usize,
    /// Each table's part: its number, its row groups, whether it was closed.
    parts: BTreeMap<String, (u32, usize, bool)>,
    records: u64,
    raw: u64,
}

impl Sink for Check {
    fn write(&mut self, table: &str, part: u32, batch: &RecordBatch) -> io::Result<()> {
        let words = batch;
        // Parts numbered from 0, each after the last is closed; a part's row groups at most
        // as many as asked.
        let p = self.parts.entry(table.to_string()).or_insert((0, 0, false));
        if p.2 {
            *p = (p.0 + 1, 0, false);
        }
        assert_eq!(
            part, p.0,
            "{table}: parts numbered in order, each closed before the next"
        );
        p.1 += 1;
        assert!(
            p.1 <= self.groups_per_file,
            "{table}: part {part}: {} row groups",
            p.1
        );
        assert!(batch.num_rows() > 0, "{table}: empty row group");
        assert!(
            batch.num_rows() <= self.rows_per_group,
            "{table}: {} rows in a group of {}",
            batch.num_rows(),
            self.rows_per_group
        );
        for (f, c) in batch.schema().fields().iter().zip(batch.columns()) {
            c.to_data()
                .validate_full()
                .unwrap_or_else(|e| panic!("{table}.{}: {e}", f.name()));
            assert!(
                f.is_nullable() || c.null_count() == 0,
                "{table}.{}: nulls in a column that has none",
                f.name()
            );
        }
        // The table's declared types (its columns of words as text), as readers get them.
        let plain = aptscope_parquet::words::declared(batch).expect("declared");
        let batch = &plain;
        if table == "records" {
            self.records += batch.num_rows() as u64;
            let raw = batch.column_by_name("raw").expect("raw").as_binary::<i32>();
            let ty = batch.column_by_name("type").expect("type");
            let ty = ty.as_string::<i32>();
            for i in 0..batch.num_rows() {
                if matches!(ty.value(i), "frame" | "garbage") {
                    self.raw += raw.value(i).len() as u64;
                }
            }
        }
        // Parquet as the dataset writes it (from the words), read back: the same rows and
        // schema as the declared batch.
        let bytes = TableWriter::new(self.rows_per_group, &batch.schema())
            .expect("table writer")
            .write(Vec::new(), words)
            .expect("write");
        let r = ParquetRecordBatchReaderBuilder::try_new(bytes::Bytes::from(bytes))
            .expect("parquet")
            .build()
            .expect("reader");
        // At most 16 rows a group: one batch back.
        let back: Vec<RecordBatch> = r.map(|b| b.expect("batch")).collect();
        assert_eq!(
            back.as_slice(),
            std::slice::from_ref(batch),
            "{table}: read back differs"
        );
        Ok(())
    }

    fn close(&mut self, table: &str, part: u32) -> io::Result<()> {
        let p = self
            .parts
            .get_mut(table)
            .expect("a part written before it closes");
        assert_eq!(
            (part, p.2),
            (p.0, false),
            "{table}: the open part closed once"
        );
        assert!(p.1 > 0, "{table}: part {part} closed empty");
        p.2 = true;
        Ok(())
    }
}

/// The target's body: panics when a check fails.
pub fn fuzz(data: &[u8]) {
    let ([flags, budget], file) = split_ctl::<2>(data);
    let proto = match flags % 3 {
        0 => None,
        1 => Some(Proto::Apt),
        _ => Some(Proto::Elliptec),
    };
    let opts = Options {
        rows_per_group: 1 + usize::from(budget % 16),
        bytes_per_group: 64 + 16 * usize::from(budget),
        max_open_kinds: 3,
        kind_rows: 2 + usize::from(budget % 16),
        groups_per_file: 1 + usize::from(flags / 3 % 4),
        open_chunks: 8 * usize::from(budget),
        // Python's batches: the words built as text, and kept (buffers taken back when a
        // table opens again).
        words_as_text: flags >= 128,
        batches_kept: flags & 64 != 0,
    };
    let check = Check {
        rows_per_group: opts.rows_per_group,
        groups_per_file: opts.groups_per_file,
        parts: BTreeMap::new(),
        records: 0,
        raw: 0,
    };
    let mut w = CaptureWriter::new(check, "fuzz.bin", opts);
    let mut emit = |rec: &aptscope_dissector::record::Record<'_>| w.record(rec);
    let (bytes, expanded) = decode_records(file, proto, &mut emit);
    if expanded {
        return;
    }
    let (check, sum) = w.finish().expect("finish");
    assert_eq!(check.records, sum.records, "a records row per record");
    for (t, p) in &check.parts {
        assert!(p.2, "{t}: part {} left open", p.0);
    }
    assert_eq!(check.raw, bytes, "records hold exactly the captured bytes");
}
