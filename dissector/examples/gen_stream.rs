//! Write a synthetic APT byte stream of random valid frames of every form to stdout:
//! `gen_stream MEGABYTES [SEED]`. Used by benchmarks and the memory check.

use aptscope_dissector::{synth, Table};
use std::io::Write;

fn main() -> std::io::Result<()> {
    let mut args = std::env::args().skip(1);
    let mb: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(10);
    let seed: u64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(1);
    // One 4 MiB block of mixed frames (~200k frames), repeated: frames never straddle blocks.
    let block = synth::stream(Table::global(), seed, 200_000, false);
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    let mut left = mb * 1_000_000;
    while left > 0 {
        let n = left.min(block.len());
        // Cut only at the block end, so every block but a short last one is whole frames.
        out.write_all(&block[..n])?;
        left -= n;
    }
    out.flush()
}
