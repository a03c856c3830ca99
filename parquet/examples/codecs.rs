//! Compare Parquet compression codecs on a capture's tables: `codecs CAPTURE`.
//!
//! Decodes the capture once into the record batches `decode --to parquet` would write, then
//! writes them all with each codec through parquet-rs's Arrow writer (the dataset's writer
//! properties otherwise; the dataset itself is written by `pages`, which takes Snappy or no
//! compression) and prints the
//! CPU time of the writing (this thread's, from /proc: the machine is shared) and the bytes
//! written. Used to choose the codec (docs/parquet.md "Compression").

mod common;

use aptscope_parquet::{decode_file, writer_properties, CaptureWriter, DecodeOpts, Options, Sink};
use arrow_array::RecordBatch;
use parquet::arrow::ArrowWriter;
use parquet::basic::{Compression, ZstdLevel};
use parquet::file::properties::{EnabledStatistics, WriterVersion};
use std::io;

/// Every row group, by table, as the writer flushed it.
struct Keep(Vec<(String, RecordBatch)>);

impl Sink for Keep {
    fn write(&mut self, table: &str, _part: u32, batch: &RecordBatch) -> io::Result<()> {
        // The Arrow writer gets the table's declared types (text, not dictionaries of words).
        let batch = aptscope_parquet::words::declared(batch).map_err(io::Error::other)?;
        self.0.push((table.to_string(), batch));
        Ok(())
    }
}

fn main() -> io::Result<()> {
    let path = std::env::args()
        .nth(1)
        .ok_or_else(|| io::Error::other("usage: codecs CAPTURE"))?;
    let opts = Options::default();
    let w = CaptureWriter::new(Keep(vec![]), &path, opts);
    let t0 = common::cpu_s();
    let (keep, sum) = decode_file(&path, &DecodeOpts::default(), w, &mut |_| {})?;
    let decode = common::cpu_s() - t0;
    let batches = keep.0;
    let input = std::fs::metadata(&path)?.len() as f64 / 1e6;
    println!(
        "{path}: {input:.1} MB, {} records in {} row groups, decoded into batches in {decode:.3} CPU-s",
        sum.records,
        batches.len()
    );
    let codecs = [
        ("none", Compression::UNCOMPRESSED),
        ("snappy", Compression::SNAPPY),
        ("lz4_raw", Compression::LZ4_RAW),
        (
            "zstd(1)",
            Compression::ZSTD(ZstdLevel::try_new(1).map_err(io::Error::other)?),
        ),
        (
            "zstd(3)",
            Compression::ZSTD(ZstdLevel::try_new(3).map_err(io::Error::other)?),
        ),
    ];
    let variant = std::env::var("VARIANT").unwrap_or_default();
    println!("| codec | write CPU-s (best of 3) | MB written | ratio to input |");
    println!("|---|---|---|---|");
    // CODEC=NAME: that codec alone, written once (for callgrind's instruction counts).
    let only = std::env::var("CODEC").ok();
    let reps = if only.is_some() { 1 } else { 3 };
    for (name, c) in codecs {
        if only.as_deref().is_some_and(|o| o != name) {
            continue;
        }
        let mut best = f64::INFINITY;
        let mut bytes = 0;
        for _ in 0..reps {
            let t0 = common::cpu_s();
            bytes = 0;
            for (_, b) in &batches {
                let mut pb = writer_properties(opts.rows_per_group, &b.schema())
                    .into_builder()
                    .set_compression(c);
                for v in variant.split(',') {
                    pb = match v {
                        "nostats" => pb.set_statistics_enabled(EnabledStatistics::None),
                        "chunkstats" => pb.set_statistics_enabled(EnabledStatistics::Chunk),
                        "nodict" => pb.set_dictionary_enabled(false),
                        "v2" => pb.set_writer_version(WriterVersion::PARQUET_2_0),
                        "bigbatch" => pb.set_write_batch_size(65536),
                        "noindex" => pb.set_offset_index_disabled(true),
                        _ => pb,
                    };
                }
                let p = pb.build();
                let mut w = ArrowWriter::try_new(Vec::new(), b.schema(), Some(p))
                    .map_err(io::Error::other)?;
                w.write(b).map_err(io::Error::other)?;
                bytes += w.into_inner().map_err(io::Error::other)?.len();
            }
            best = best.min(common::cpu_s() - t0);
        }
        let mb = bytes as f64 / 1e6;
        println!("| {name} | {best:.3} | {mb:.2} | {:.2} |", mb / input);
    }
    Ok(())
}
