//! The rows alone: `rows CAPTURE [TABLE…]` decodes a capture into the record batches
//! `decode --to parquet` would write (and `to_arrow()` hands to Python), drops them, and prints
//! records per CPU-second of this thread — the part of both that is not Parquet encoding nor
//! Python (docs/performance.md). With TABLE names, only those tables are built.

mod common;

use aptscope_parquet::{decode_file, CaptureWriter, DecodeOpts, Options, Sink};
use arrow_array::RecordBatch;
use std::io;

/// Counts the rows it is given.
struct Drop(u64);

impl Sink for Drop {
    fn write(&mut self, _table: &str, _part: u32, batch: &RecordBatch) -> io::Result<()> {
        self.0 += batch.num_rows() as u64;
        Ok(())
    }
}

fn main() -> io::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .ok_or_else(|| io::Error::other("usage: rows CAPTURE [TABLE…]"))?;
    let tables: Vec<String> = args.collect();
    let opts = Options::default();
    let mut w = CaptureWriter::new(Drop(0), &path, opts);
    if !tables.is_empty() {
        w.only_tables(move |t| tables.iter().any(|x| x == t));
    }
    let t0 = common::cpu_s();
    let (rows, sum) = decode_file(&path, &DecodeOpts::default(), w, &mut |_| {})?;
    let cpu = common::cpu_s() - t0;
    println!(
        "{path}: {} records, {} rows in all, {cpu:.3} CPU-s: {:.2} M records per CPU-s",
        sum.records,
        rows.0,
        sum.records as f64 / cpu / 1e6
    );
    Ok(())
}
