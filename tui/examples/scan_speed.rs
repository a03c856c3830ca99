//! Speed of the display-filter/statistics scan of `aptscope view` (`scan_speed [MB] [FILTER…]`):
//! generates a stream of random APT frames of every form (like `gen_stream`, default 5 MB,
//! ≈ 360 k frames), indexes it synchronously, then times a synchronous scan per filter (the
//! empty filter: statistics of every record) and prints records/s as JSON lines.
//! `APTSCOPE_SCAN_ONCE=1` runs each scan once (for callgrind); otherwise the best of 3.
//! `APTSCOPE_SCAN_IN_MEMORY=1` keeps the records' bytes in memory instead of reading them back
//! from the (raw) file.
//! Besides wall time, the CPU time of the scanning thread (Linux `schedstat`) is given: on a
//! busy machine it is the figure that says what one core does.

use aptscope_dissector::filter::Filter;
use aptscope_dissector::{synth, Table};
use aptscope_tui::index;
use aptscope_tui::scan::Scan;
use std::sync::Arc;
use std::time::Instant;

/// CPU time of the calling thread in seconds (Linux), when known.
fn thread_cpu() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: f64 = s.split_whitespace().next()?.parse().ok()?;
    Some(ns / 1e9)
}

fn main() -> std::io::Result<()> {
    let mut args = std::env::args().skip(1);
    let mb: f64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(5.0);
    let mut filters: Vec<String> = args.collect();
    if filters.is_empty() {
        filters = [
            "",
            "apt.name == \"MOT_MOVE_ABSOLUTE\"",
            "apt.position > 1000",
            "dir == h2d && apt.chan == 1",
            "n > 100 && len > 10",
        ]
        .map(String::from)
        .to_vec();
    }
    let block = synth::stream(Table::global(), 1, 200_000, false);
    let mut data = Vec::new();
    let want = (mb * 1e6) as usize;
    while data.len() < want {
        let n = (want - data.len()).min(block.len());
        data.extend_from_slice(&block[..n]);
    }
    let dir = std::env::temp_dir().join(format!("aptscope-scan-speed-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let path = dir.join("big.bin");
    std::fs::write(&path, &data)?;
    let t0 = Instant::now();
    let c0 = thread_cpu();
    // `APTSCOPE_SCAN_IN_MEMORY=1`: the records' bytes in memory (as live sources keep them)
    // instead of read back from the file.
    let shared = if std::env::var_os("APTSCOPE_SCAN_IN_MEMORY").is_some() {
        index::load_in_memory(&path.to_string_lossy(), Default::default())?
    } else {
        index::load(&path.to_string_lossy(), Default::default())?
    };
    let index_cpu = thread_cpu().zip(c0).map_or(f64::NAN, |(b, a)| b - a);
    let _ = std::fs::remove_dir_all(&dir);
    let records = shared.index.read().map(|i| i.recs.len()).unwrap_or(0);
    eprintln!(
        "indexed {records} records ({:.1} MB) in {:.2} s ({index_cpu:.2} s CPU)",
        data.len() as f64 / 1e6,
        t0.elapsed().as_secs_f64()
    );
    let runs = if std::env::var_os("APTSCOPE_SCAN_ONCE").is_some() {
        1
    } else {
        3
    };
    for text in &filters {
        let filter = match Filter::parse(text) {
            Ok(f) => (!text.trim().is_empty()).then_some(f),
            Err(e) => {
                eprintln!("bad filter {text:?}: {e}");
                std::process::exit(2);
            }
        };
        let mut best = f64::INFINITY;
        let mut best_cpu = f64::INFINITY;
        let mut matches = 0;
        let mut frames = 0;
        for _ in 0..runs {
            let scan = Arc::new(Scan::default());
            let t = Instant::now();
            let c = thread_cpu();
            scan.start(shared.clone(), filter.clone(), false);
            best = best.min(t.elapsed().as_secs_f64());
            if let (Some(a), Some(b)) = (c, thread_cpu()) {
                best_cpu = best_cpu.min(b - a);
            }
            let state = scan.state.lock();
            if let Ok(s) = &state {
                matches = s.matches.len();
                frames = s.stats.frames.count;
            }
        }
        println!(
            "{{\"filter\":{},\"records\":{records},\"matches\":{matches},\"stats_frames\":{frames},\"s\":{best:.3},\"records_per_s\":{:.0},\"cpu_s\":{best_cpu:.3},\"records_per_cpu_s\":{:.0}}}",
            serde_json::Value::String(text.clone()),
            records as f64 / best,
            records as f64 / best_cpu
        );
    }
    Ok(())
}
