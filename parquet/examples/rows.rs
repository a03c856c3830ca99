//! The rows alone: `rows CAPTURE [--text] [--keep] [TABLE…]` decodes a capture into the record
//! batches `decode --to parquet` would write (and `to_arrow()` hands to Python), drops them, and
//! prints records per CPU-second of this thread — the part of both that is not Parquet encoding
//! nor Python (docs/performance.md). `--text`: the columns of words turned into text, as
//! Python gets them; `--keep`: every batch kept to the end, as `to_arrow()` keeps its tables.
//! With TABLE names, only those tables are built.

mod common;

use aptscope_parquet::{decode_file, CaptureWriter, DecodeOpts, Options, Sink};
use arrow_array::RecordBatch;
use std::io;

/// Counts the rows it is given (turned into text, kept, as asked).
struct Drop {
    rows: u64,
    text: bool,
    keep: Option<Vec<RecordBatch>>,
}

impl Sink for Drop {
    fn write(&mut self, _table: &str, _part: u32, batch: &RecordBatch) -> io::Result<()> {
        self.rows += batch.num_rows() as u64;
        let b = if self.text {
            aptscope_parquet::words::declared(batch).map_err(io::Error::other)?
        } else {
            batch.clone()
        };
        if let Some(k) = &mut self.keep {
            k.push(b);
        }
        Ok(())
    }
}

fn main() -> io::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .ok_or_else(|| io::Error::other("usage: rows CAPTURE [TABLE…]"))?;
    let mut tables: Vec<String> = args.collect();
    let mut flag = |f: &str| {
        let had = tables.iter().any(|t| t == f);
        tables.retain(|t| t != f);
        had
    };
    let sink = Drop {
        rows: 0,
        text: flag("--text"),
        keep: flag("--keep").then(Vec::new),
    };
    let opts = Options::default();
    let mut w = CaptureWriter::new(sink, &path, opts);
    if !tables.is_empty() {
        w.only_tables(move |t| tables.iter().any(|x| x == t));
    }
    let t0 = common::cpu_s();
    let (rows, sum) = decode_file(&path, &DecodeOpts::default(), w, &mut |_| {})?;
    let cpu = common::cpu_s() - t0;
    println!(
        "{path}: {} records, {} rows in all, {cpu:.3} CPU-s: {:.2} M records per CPU-s",
        sum.records,
        rows.rows,
        sum.records as f64 / cpu / 1e6
    );
    Ok(())
}
