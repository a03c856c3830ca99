//! The rows alone: `rows CAPTURE [--text] [--keep] [TABLE…]` decodes a capture into the record
//! batches `decode --to parquet` would write (and `to_arrow()` hands to Python), drops them, and
//! prints records per CPU-second of this thread — the part of both that is not Parquet encoding
//! nor Python (docs/performance.md). `--text`: the columns of words as text, as Python gets
//! them ([`Options::words_as_text`]); `--keep`: every batch kept to the end, as `to_arrow()`
//! keeps its tables.
//! With TABLE names, only those tables are built. `--threads N` (N ≥ 2): the rows built on
//! N threads (this one among them) from runs of up to 65,536 records decoded on this one
//! ([`RowPool`], as `to_arrow()` with threads), a raw stream only; prints wall time (CPU time:
//! run it under `time`).

mod common;

use aptscope_dissector::record::{Ctx, Decoder};
use aptscope_parquet::pool::RowPool;
use aptscope_parquet::{decode_file, CaptureWriter, DecodeOpts, Options, Sink};
use arrow_array::RecordBatch;
use std::io;

/// Counts the rows it is given (and keeps them, if asked).
struct Drop {
    rows: u64,
    keep: Option<Vec<RecordBatch>>,
}

impl Sink for Drop {
    fn write(&mut self, _table: &str, _part: u32, batch: &RecordBatch) -> io::Result<()> {
        self.rows += batch.num_rows() as u64;
        if let Some(k) = &mut self.keep {
            k.push(batch.clone());
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
    let threads = tables.iter().position(|t| t == "--threads").map(|i| {
        let n = tables.get(i + 1).and_then(|n| n.parse().ok()).unwrap_or(2);
        tables.drain(i..(i + 2).min(tables.len()));
        n
    });
    let mut flag = |f: &str| {
        let had = tables.iter().any(|t| t == f);
        tables.retain(|t| t != f);
        had
    };
    let keep = flag("--keep");
    let opts = Options {
        words_as_text: flag("--text"),
        batches_kept: keep,
        ..Options::default()
    };
    if let Some(n) = threads {
        return pooled(&path, n, opts);
    }
    let sink = Drop {
        rows: 0,
        keep: keep.then(Vec::new),
    };
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

/// `--threads N`: the rows of a raw stream built on `n` threads.
fn pooled(path: &str, n: usize, opts: Options) -> io::Result<()> {
    let bytes = std::fs::read(path)?;
    let t0 = std::time::Instant::now();
    let mut pool = RowPool::new(n, path, opts, None, Ok)?;
    let (mut rows, mut records) = (0usize, 0u64);
    let mut count = |g: Vec<(String, RecordBatch)>| {
        rows += g.iter().map(|(_, b)| b.num_rows()).sum::<usize>();
    };
    let mut dec = Decoder::new(None);
    let mut each = |r: &aptscope_dissector::record::Record<'_>| -> io::Result<()> {
        records += 1;
        pool.push(r, &mut count)
    };
    dec.push(Ctx::default(), &bytes, &mut each)?;
    dec.finish(&mut each)?;
    pool.flush(&mut count)?;
    pool.ready(true, &mut count)?;
    let wall = t0.elapsed().as_secs_f64();
    println!(
        "{path}: {records} records, {rows} rows in all on {n} threads, {wall:.3} s wall: {:.2} M records per second",
        records as f64 / wall / 1e6
    );
    Ok(())
}
