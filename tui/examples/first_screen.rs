//! Time to the first screen of `aptscope view` on a capture (`first_screen FILE`): opens it like
//! the viewer does (background indexing), draws into an off-screen 120×40 terminal until a full
//! screen of rows is shown, then waits for the index to finish. Prints both times as JSON, and
//! the CPU time of the process when the index was complete (indexing, the statistics scan and
//! the drawing: on a busy machine wall times say little).
//! `--index-memory SIZE` as `aptscope view` takes it; `--no-cache` neither reads nor writes the
//! index cache (`$XDG_CACHE_HOME/aptscope/index`). With the cache, a first opening waits for the
//! index to be written there (`cache_write_s`) and a second one of the same capture reads it back
//! (`from_cache`); `stats_s` is the time until the statistics of every record are complete.
//! `bench/tui-first-screen.sh` runs it on a generated 10 M-frame capture, twice.

use aptscope_tui::{app::App, index, ui};
use ratatui::{backend::TestBackend, Terminal};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// CPU time of the process so far in seconds (Linux `/proc/self/stat`, 100 Hz ticks).
fn process_cpu() -> f64 {
    let Ok(s) = std::fs::read_to_string("/proc/self/stat") else {
        return f64::NAN;
    };
    // Fields after the command name (which may hold spaces): utime and stime are 14th, 15th.
    let rest = s.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let tick = |i: usize| f.get(i).and_then(|x| x.parse::<f64>().ok());
    match (tick(11), tick(12)) {
        (Some(u), Some(k)) => (u + k) / 100.0,
        _ => f64::NAN,
    }
}

fn main() -> std::io::Result<()> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let no_cache = args.iter().any(|a| a == "--no-cache");
    args.retain(|a| a != "--no-cache");
    let (path, budget) = match args.as_slice() {
        [p] => (p.clone(), None),
        [p, flag, size] if flag == "--index-memory" => (p.clone(), index::parse_size(size)),
        _ => (String::new(), None),
    };
    if path.is_empty() || (args.len() > 1 && budget.is_none()) {
        eprintln!("usage: first_screen FILE [--index-memory SIZE] [--no-cache]");
        std::process::exit(2);
    }
    if let Some(b) = budget {
        index::set_index_memory(b);
    }
    if no_cache {
        index::set_index_cache(false);
    }
    let t0 = Instant::now();
    let shared = index::spawn(&path, Default::default())?;
    let mut app = App::new(shared.clone(), "bench", true);
    let Ok(mut term) = Terminal::new(TestBackend::new(120, 40));
    let first = loop {
        let _ = term.draw(|f| ui::draw(f, &mut app));
        if app.len() >= 20 || shared.index.read().is_ok_and(|i| i.done) {
            break t0.elapsed();
        }
        std::thread::sleep(Duration::from_millis(1));
    };
    let frames_at_first = app.len();
    while !shared.index.read().is_ok_and(|i| i.done) {
        std::thread::sleep(Duration::from_millis(20));
        app.tick();
    }
    let total = t0.elapsed();
    let cpu = process_cpu();
    // The statistics of every record (the scan the viewer starts at once).
    while !app.scan().state.lock().is_ok_and(|s| s.done) {
        std::thread::sleep(Duration::from_millis(5));
        app.tick();
    }
    let stats = t0.elapsed();
    // A first opening writes the index to the cache after it is complete: wait for it (the
    // viewer does not; a write cut short is left as a temporary file, removed later).
    let t2 = Instant::now();
    while shared.cache.load(Ordering::Relaxed) == index::CACHE_SAVING {
        std::thread::sleep(Duration::from_millis(20));
    }
    let cache_write = t2.elapsed();
    let cache = match shared.cache.load(Ordering::Relaxed) {
        index::CACHE_READ => "read",
        index::CACHE_SAVED => "saved",
        index::CACHE_NOT_SAVED => "not saved",
        _ => "off",
    };
    // Scrolling to the end and drawing stays instant: only visible rows are decoded.
    let t1 = Instant::now();
    app.select(app.len().saturating_sub(1));
    let _ = term.draw(|f| ui::draw(f, &mut app));
    let jump = t1.elapsed();
    let (nfm, late, blocks) = shared.index.read().map_or((0, 0, 0), |i| {
        (
            i.not_for_model.len(),
            i.late_no_reply.len(),
            i.recs.blocks(),
        )
    });
    eprintln!("not_for_model {nfm} late_no_reply {late} blocks {blocks}");
    let (records, index_mb, plot_mb, spilled) = shared.index.read().map_or((0, 0.0, 0.0, 0), |i| {
        let points: usize = i.series.values().map(Vec::capacity).sum();
        let mb = |b: usize| b as f64 / 1e6;
        (
            i.recs.len(),
            mb(i.recs.memory() + i.arena.capacity()),
            mb(points * std::mem::size_of::<index::Point>()),
            i.recs.spilled_chunks(),
        )
    });
    println!(
        "{{\"first_screen_ms\":{:.1},\"records_at_first_screen\":{frames_at_first},\"index_s\":{:.3},\"cpu_s_when_indexed\":{cpu:.2},\"stats_s\":{:.3},\"records\":{records},\"records_mb\":{index_mb:.0},\"plot_mb\":{plot_mb:.0},\"spilled_chunks\":{spilled},\"jump_to_end_and_draw_ms\":{:.1},\"cache\":\"{cache}\",\"cache_write_s\":{:.2}}}",
        first.as_secs_f64() * 1e3,
        total.as_secs_f64(),
        stats.as_secs_f64(),
        jump.as_secs_f64() * 1e3,
        cache_write.as_secs_f64()
    );
    Ok(())
}
