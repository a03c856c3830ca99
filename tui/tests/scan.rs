//! The filter/statistics scan over the compact index gives exactly what `decode --json -Y`
//! selects and what the statistics of those NDJSON records are; the compact view of a record
//! answers every field as the decoded record does.

use aptscope_capture::model::Event;
use aptscope_capture::open::OpenOptions;
use aptscope_dissector::fields::{Fields, Key, Num, Role, Val, KEYS};
use aptscope_dissector::filter::Filter;
use aptscope_dissector::pipeline::{Format, Pipeline};
use aptscope_dissector::stats::Stats;
use aptscope_dissector::{synth, Table};
use aptscope_tui::fields::{with_record, View};
use aptscope_tui::index::{
    cache_file_of, load, load_cached, load_in_memory, load_spilling, Rec, Shared, CACHE_NOT_SAVED,
    CACHE_READ, CACHE_SAVED, F_NO_REPLY,
};
use aptscope_tui::scan::{Scan, BIN_NS};
use serde_json::Value;
use std::sync::Arc;

const FILTERS: &[&str] = &[
    "apt.name == \"MOT_MOVE_ABSOLUTE\"",
    "apt.name ~ \"^MOT_MOVE_\" && apt.dst == bay2",
    "apt.position > 1000",
    "apt.fields.status_bits contains HOMED",
    "apt.status_bits contains HOMED",
    "dir == h2d && apt.chan == 1",
    "dir == device || !apt.chan",
    "n > 10 && len > 10",
    "latency > 1ms || unpaired || diag",
    "paired",
    "unpaired",
    "diag.kind == no_reply",
    "apt.src == usb && apt.msgid_hex == \"0x0491\"",
    "apt.sub || apt.velocity",
    "apt.pair_other_address",
    "apt.phys",
    "ts > 1s && stream == 0",
    "type == garbage",
    "proto == ell",
    "ell.cmd ~ \"(?-i)^[a-z]\" && ell.addr != \"F\"",
    "ell.position > 0",
    "ell",
    "apt",
    "offset < 200",
    // Every operator of the scan's specialised comparisons (numbers and words at hand).
    "len >= 14 && n <= 5000 && apt.chan != 2",
    "dir != d2h && apt.name != \"MOT_MOVE_ABSOLUTE\"",
    "dir == H2D || len < 8 || offset > 1.5",
];

/// [`FILTERS`] parsed.
fn filters() -> Vec<Filter> {
    FILTERS
        .iter()
        .map(|t| Filter::parse(t).expect("filter"))
        .collect()
}

fn sample(name: &str) -> String {
    format!("{}/../samples/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn samples() -> Vec<String> {
    let mut v = vec![];
    for dir in ["", "sessions/"] {
        let path = sample(dir);
        for e in std::fs::read_dir(&path).expect("samples") {
            let name = e.expect("entry").file_name().to_string_lossy().to_string();
            if name.ends_with(".pcapng") {
                v.push(format!("{path}{name}"));
            }
        }
    }
    v.sort();
    v.push(sample("elliptec-bus.txt"));
    v.push(sample("damaged.bin"));
    v.push(sample("sessions/damaged.bin"));
    v
}

/// A random stream of every APT form, with garbage, as a file.
fn synthetic() -> (tempdir::Dir, String) {
    let dir = tempdir::Dir::new("scan");
    let path = dir.0.join("synth.bin");
    std::fs::write(&path, synth::stream(Table::global(), 7, 8_000, true)).expect("write");
    let p = path.to_string_lossy().to_string();
    (dir, p)
}

mod tempdir {
    /// A directory removed on drop.
    pub struct Dir(pub std::path::PathBuf);
    impl Dir {
        pub fn new(tag: &str) -> Dir {
            let p = std::env::temp_dir().join(format!(
                "aptscope-tui-{tag}-{}-{:?}",
                std::process::id(),
                std::thread::current().id()
            ));
            std::fs::create_dir_all(&p).expect("tempdir");
            Dir(p)
        }
    }
    impl Drop for Dir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// The scan's matches and statistics (synchronous).
fn scan(shared: &Arc<Shared>, filter: Option<Filter>) -> (Vec<u64>, String) {
    let s = Arc::new(Scan::default());
    s.start(shared.clone(), filter, false);
    let st = s.state.lock().expect("lock");
    assert!(st.done);
    (st.matches.clone(), stats_text(&st.stats))
}

fn stats_text(s: &Stats) -> String {
    format!(
        "{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{}",
        s.frames,
        s.garbage,
        s.messages,
        s.addresses,
        s.directions,
        s.diags,
        s.bins,
        s.bin_ns,
        s.streams,
        s.stream_addresses,
        s.to_text()
    )
}

/// The records of `decode --json`: the streams, then the frames and garbage, with each late
/// `no_reply` diagnostic merged into the record it refers to (as the viewer shows it).
fn pipeline_records(path: &str) -> Vec<Value> {
    let (mut r, _) = aptscope_capture::open::open(path, OpenOptions::default()).expect("opens");
    let mut p = Pipeline::new(None, Format::Json);
    let mut out: Vec<Value> = vec![];
    let mut emit = |l: &str| -> Result<(), ()> {
        out.push(serde_json::from_str(l).expect("json"));
        Ok(())
    };
    while let Some(ev) = r.next_event() {
        match ev {
            Event::Chunk(c) => p.push_chunk(c.ctx(), c.bytes, &mut emit).expect("push"),
            Event::Stream(s) => p
                .stream_info(s.id, &s.name, s.settings.as_deref(), &mut emit)
                .expect("stream"),
            Event::Diag(_) => {}
        }
    }
    p.finish(&mut emit).expect("finish");
    let late: Vec<(u64, Vec<Value>)> = out
        .iter()
        .filter(|v| v["type"] == "diag")
        .filter_map(|v| Some((v["ref"].as_u64()?, v["diag"].as_array()?.clone())))
        .collect();
    let streams: Vec<Value> = out
        .iter()
        .filter(|v| v["type"] == "stream")
        .cloned()
        .collect();
    let mut recs: Vec<Value> = out.into_iter().filter(|v| v.get("n").is_some()).collect();
    for (n, ds) in late {
        let rec = recs
            .iter_mut()
            .find(|v| v["n"].as_u64() == Some(n))
            .expect("late diag refers to a record");
        rec["diag"].as_array_mut().expect("diag list").extend(ds);
    }
    streams.into_iter().chain(recs).collect()
}

/// What `decode --json -Y FILTER` selects, and `stats` of it.
fn reference(recs: &[Value], filter: Option<&Filter>) -> (Vec<u64>, String) {
    let mut found = vec![];
    let mut stats = Stats::new(BIN_NS);
    for v in recs {
        // The viewer names every stream, whatever the filter.
        if v["type"] == "stream" {
            stats.add(v);
            continue;
        }
        if filter.is_none_or(|f| f.matches(v)) {
            if filter.is_some() {
                found.extend(v["n"].as_u64());
            }
            stats.add(v);
        }
    }
    (found, stats_text(&stats))
}

#[test]
fn scan_equals_the_pipeline_selection_and_its_statistics() {
    let filters = filters();
    let mut total = vec![0; filters.len()];
    let (_dir, synth) = synthetic();
    for path in samples().into_iter().chain([synth]) {
        let recs = pipeline_records(&path);
        let shared = load(&path, OpenOptions::default()).expect("opens");
        assert_eq!(
            shared.index.read().expect("lock").recs.len(),
            recs.iter().filter(|v| v.get("n").is_some()).count(),
            "{path}"
        );
        let (got, want) = (scan(&shared, None), reference(&recs, None));
        for (a, b) in got.1.lines().zip(want.1.lines()) {
            assert_eq!(a, b, "{path}");
        }
        assert_eq!(got, want, "{path}");
        for (i, f) in filters.iter().enumerate() {
            let got = scan(&shared, Some(f.clone()));
            assert_eq!(got, reference(&recs, Some(f)), "{path}: {f}");
            total[i] += got.0.len();
        }
    }
    // Every filter selects something somewhere (the comparison is not vacuous).
    for (f, t) in filters.iter().zip(total) {
        assert!(
            t > 0 || f.as_str() == "apt.pair_other_address",
            "{f} matches nothing"
        );
    }
}

/// Everything a visit passes on, as text.
fn visit_text(rec: &dyn Fields, key: Key, rest: &[String]) -> (bool, Vec<String>) {
    let mut vals = vec![];
    let there = rec.visit(key, rest, &mut |v: Val<'_>, r: Role| {
        vals.push(format!("{v:?} {r:?}"))
    });
    (there, vals)
}

/// The compact view answers every key (and a path below it) as the re-decoded record does,
/// but for the `no_reply` diagnostic it adds to requests without reply.
#[test]
fn the_compact_view_reads_like_the_decoded_record() {
    let (_dir, synth) = synthetic();
    let paths = [
        sample("kdc101-session.pcapng"),
        sample("elliptec-bus.txt"),
        sample("damaged.bin"),
        sample("bsc203-rack.hex"),
        synth,
    ];
    let below = [vec![], vec!["name".to_string()], vec!["kind".to_string()]];
    let (mut compared, mut numbers, mut words) = (0, 0, 0);
    for path in paths {
        let shared = load(&path, OpenOptions::default()).expect("opens");
        let ix = shared.index.read().expect("lock");
        for (i, r) in ix.recs.iter().enumerate().take(3000) {
            let n = i as u64 + 1;
            let view = View { ix: &ix, n, r: &r };
            assert_eq!(
                view.proto().map(str::to_string),
                with_record(&ix, n, |rec| rec.proto().map(str::to_string)).flatten(),
                "{path} #{n}"
            );
            for def in KEYS {
                if def.key == Key::Diag && r.has(F_NO_REPLY) {
                    continue;
                }
                // A number the view has at hand is the one value the visit gives.
                if let Some(x) = view.number(def.key) {
                    let one = vec![format!(
                        "{:?} {:?}",
                        Val::Num(Num::I(i128::from(x))),
                        Role::Plain
                    )];
                    let want = with_record(&ix, n, |rec| visit_text(rec, def.key, &[]));
                    assert_eq!(want, Some((true, one)), "{path} #{n} {}", def.name);
                    numbers += 1;
                }
                // Likewise a word.
                if let Some(w) = view.word(def.key) {
                    let one = vec![format!("{:?} {:?}", Val::Str(w.into()), Role::Plain)];
                    let want = with_record(&ix, n, |rec| visit_text(rec, def.key, &[]));
                    assert_eq!(want, Some((true, one)), "{path} #{n} {}", def.name);
                    words += 1;
                }
                for rest in &below {
                    let want = with_record(&ix, n, |rec| visit_text(rec, def.key, rest))
                        .expect("record decodes");
                    assert_eq!(
                        visit_text(&view, def.key, rest),
                        want,
                        "{path} #{n} {}{rest:?}",
                        def.name
                    );
                    compared += 1;
                }
            }
        }
    }
    assert!(compared > 10_000);
    assert!(numbers > 1_000, "{numbers}");
    assert!(words > 1_000, "{words}");
}

/// Every file of samples/ (and samples/sessions/) that is a capture.
fn every_sample() -> Vec<String> {
    let mut v = vec![];
    for dir in ["", "sessions/"] {
        let path = sample(dir);
        for e in std::fs::read_dir(&path).expect("samples") {
            let e = e.expect("entry");
            let name = e.file_name().to_string_lossy().to_string();
            let script = [".sh", ".py", ".md"].iter().any(|x| name.ends_with(x));
            if !script && e.file_type().is_ok_and(|t| t.is_file()) {
                v.push(format!("{path}{name}"));
            }
        }
    }
    v.sort();
    v
}

/// Two indexes of one capture give the same answers: the same records (pairing links, so the
/// pair jumps, included), the same bytes and plot series, and for every filter
/// the same selection and statistics.
fn same_answers(path: &str, a: &Arc<Shared>, b: &Arc<Shared>, filters: &[Filter]) {
    {
        let (a, b) = (a.index.read().expect("lock"), b.index.read().expect("lock"));
        assert_eq!(a.recs.len(), b.recs.len(), "{path}");
        let same = |r: Rec| Rec { start: 0, ..r };
        for (i, (x, y)) in a.recs.iter().zip(b.recs.iter()).enumerate() {
            assert_eq!(same(x), same(y), "{path} #{}", i + 1);
            assert_eq!(a.bytes(&x), b.bytes(&y), "{path} #{}", i + 1);
        }
        // Records read one by one (no read-back window or chunk in common with the iteration).
        for n in [a.recs.len() as u64, 1, (a.recs.len() as u64).div_ceil(2)] {
            let (x, y) = (a.rec(n), b.rec(n));
            assert_eq!(x.map(same), y.map(same), "{path} #{n}");
            if let (Some(x), Some(y)) = (x, y) {
                assert_eq!(a.bytes(&x), b.bytes(&y), "{path} #{n}");
            }
        }
        // Not `late_no_reply`: which no-replies come after their record's publication depends
        // on when batches were published (every 50 ms too), not on where bytes are kept.
        assert_eq!(a.series, b.series, "{path}");
    }
    assert_eq!(scan(a, None), scan(b, None), "{path}");
    for f in filters {
        assert_eq!(
            scan(a, Some(f.clone())),
            scan(b, Some(f.clone())),
            "{path}: {f}"
        );
    }
}

/// The viewer's index reads records' bytes back (from a raw capture itself, else from the
/// arena it wrote to a scratch file) instead of keeping them: on every sample (every format)
/// records, bytes, pairing, plots, statistics and every filter's selection are those of the
/// index that keeps them in memory.
#[test]
fn reading_bytes_back_changes_no_answer() {
    let filters = filters();
    let (_dir, synth) = synthetic();
    let mut paths = every_sample();
    assert!(paths.len() > 30, "{paths:?}");
    paths.push(synth);
    for path in paths {
        let (back, mem) = (
            load(&path, OpenOptions::default()).expect("opens"),
            load_in_memory(&path, OpenOptions::default()).expect("opens"),
        );
        {
            let (a, b) = (
                back.index.read().expect("lock"),
                mem.index.read().expect("lock"),
            );
            let raw = a.format == "raw bytes";
            assert_eq!(a.file.is_some(), raw, "{path}");
            assert_eq!(a.arena_file.is_some(), !raw, "{path}");
            assert!(a.arena.is_empty(), "{path}");
            assert!(b.file.is_none() && b.arena_file.is_none(), "{path}");
            assert!(!b.arena.is_empty(), "{path}");
        }
        same_answers(&path, &back, &mem, &filters);
    }
}

/// An index over its memory budget writes the older records to a scratch file and reads them
/// back: the same answers as the index kept in memory, on a raw capture of 150,000 messages
/// (three chunks of records: the first spilled) and on its pcapng copy.
#[test]
fn an_index_over_its_budget_changes_no_answer() {
    let dir = tempdir::Dir::new("spill");
    let raw = dir.0.join("big.bin");
    std::fs::write(&raw, synth::stream(Table::global(), 11, 150_000, true)).expect("write");
    let raw = raw.to_string_lossy().to_string();
    let pcapng = dir.0.join("big.pcapng").to_string_lossy().to_string();
    to_pcapng(&raw, OpenOptions::default(), &pcapng);
    let filters: Vec<Filter> = ["apt.position > 1000", "unpaired", "diag", "n > 70000"]
        .iter()
        .map(|t| Filter::parse(t).expect("filter"))
        .collect();
    for path in [raw, pcapng] {
        let (spilled, mem) = (
            load_spilling(&path, OpenOptions::default(), 1).expect("opens"),
            load_in_memory(&path, OpenOptions::default()).expect("opens"),
        );
        let chunks = spilled.index.read().expect("lock").recs.spilled_chunks();
        assert!(chunks >= 1, "{path}: {chunks}");
        same_answers(&path, &spilled, &mem, &filters);
        // Written to the cache from memory and from the scratch file, read back from it.
        let cache = dir.0.join("cache");
        let first = load_cached(&path, OpenOptions::default(), Some(1), &cache).expect("opens");
        assert_eq!(cache_state(&first), (CACHE_SAVED, false), "{path}");
        assert!(first.index.read().expect("lock").recs.spilled_chunks() >= 1);
        let again = load_cached(&path, OpenOptions::default(), Some(1), &cache).expect("opens");
        assert_eq!(cache_state(&again), (CACHE_READ, true), "{path}");
        same_index(&path, &first, &again);
        same_answers(&path, &again, &mem, &filters);
    }
}

/// The scan split between threads (as field filters over huge captures run) gives the
/// sequential scan's selection and statistics, on every sample and for every filter, batches
/// split from two records on; a scan kept from before gives the same again without scanning.
#[test]
fn the_parallel_scan_and_a_kept_one_equal_the_sequential_scan() {
    let filters = filters();
    let (_dir, synth) = synthetic();
    let mut paths = every_sample();
    paths.push(synth);
    let run = |s: &Arc<Scan>, shared: &Arc<Shared>, f: Option<Filter>| {
        s.start(shared.clone(), f, false);
        let st = s.state.lock().expect("lock");
        assert!(st.done);
        (st.matches.clone(), stats_text(&st.stats))
    };
    for path in paths {
        let shared = load(&path, OpenOptions::default()).expect("opens");
        let len = shared.index.read().expect("lock").recs.len() as u64;
        let (one, three) = (
            Arc::new(Scan::with_threads(1, 2)),
            Arc::new(Scan::with_threads(3, 2)),
        );
        for f in std::iter::once(None).chain(filters.iter().cloned().map(Some)) {
            assert!(!three.is_kept(f.as_ref(), len));
            let want = run(&one, &shared, f.clone());
            assert_eq!(run(&three, &shared, f.clone()), want, "{path}: {f:?}");
            assert!(three.is_kept(f.as_ref(), len), "{path}: {f:?}");
        }
        // Going back to a filter: the result kept (the newest eight), the same answers.
        for f in filters.iter().rev().take(8) {
            let want = run(&one, &shared, Some(f.clone()));
            assert!(three.is_kept(Some(f), len), "{path}: {f}");
            assert_eq!(run(&three, &shared, Some(f.clone())), want, "{path}: {f}");
        }
        assert!(!three.is_kept(filters.first(), len));
    }
}

/// Everything an index holds besides its records and bytes is the same in both.
fn same_index(path: &str, a: &Arc<Shared>, b: &Arc<Shared>) {
    let (a, b) = (a.index.read().expect("lock"), b.index.read().expect("lock"));
    assert_eq!(a.modules, b.modules, "{path}");
    assert_eq!(a.scales, b.scales, "{path}");
    assert_eq!(a.units_notes, b.units_notes, "{path}");
    assert_eq!(
        (a.proto, a.proto_certain, a.proto_share),
        (b.proto, b.proto_certain, b.proto_share),
        "{path}"
    );
    assert_eq!(a.first_ts, b.first_ts, "{path}");
    assert_eq!(
        (&a.streams, a.streams_seen),
        (&b.streams, b.streams_seen),
        "{path}"
    );
    assert_eq!(a.format, b.format, "{path}");
    assert_eq!(a.file_diags, b.file_diags, "{path}");
    assert_eq!(a.diag_sets, b.diag_sets, "{path}");
    assert_eq!(a.not_for_model, b.not_for_model, "{path}");
    assert_eq!(a.late_no_reply, b.late_no_reply, "{path}");
    assert_eq!((a.done, &a.error), (b.done, &b.error), "{path}");
    // Records whole, their arena starts included.
    assert!(a.recs.iter().eq(b.recs.iter()), "{path}");
}

/// What became of the cache for an index ([`Shared::cache`]), and whether it was read from it.
fn cache_state(s: &Arc<Shared>) -> (u8, bool) {
    let from = s.index.read().expect("lock").from_cache;
    (s.cache.load(std::sync::atomic::Ordering::Relaxed), from)
}

/// An index written to the cache and read back on the next opening (complete at once, its
/// records left in the cache file) gives the same answers as the one written: on every sample
/// (every format), with the default memory budget and with records spilled over a tiny one.
#[test]
fn an_index_read_back_from_the_cache_changes_no_answer() {
    let filters = filters();
    let (_dir, synth) = synthetic();
    let mut paths = every_sample();
    paths.push(synth);
    let cache = tempdir::Dir::new("cache-every");
    for budget in [None, Some(1)] {
        let _ = std::fs::remove_dir_all(&cache.0);
        for path in &paths {
            let opts = OpenOptions::default();
            let first = load_cached(path, opts, budget, &cache.0).expect("opens");
            assert_eq!(cache_state(&first), (CACHE_SAVED, false), "{path}");
            let again = load_cached(path, opts, budget, &cache.0).expect("opens");
            assert_eq!(cache_state(&again), (CACHE_READ, true), "{path}");
            {
                let ix = again.index.read().expect("lock");
                assert!(ix.done, "{path}");
                assert!(ix.arena.is_empty(), "{path}");
                let raw = ix.format == "raw bytes";
                assert_eq!(
                    (ix.file.is_some(), ix.arena_file.is_some()),
                    (raw, !raw),
                    "{path}"
                );
                // None of its records loaded.
                assert_eq!(
                    ix.recs.spilled_chunks(),
                    ix.recs.len().div_ceil(1 << 16),
                    "{path}"
                );
            }
            same_index(path, &first, &again);
            same_answers(path, &first, &again, &filters);
        }
    }
}

/// A copy of a sample in a directory of its own.
fn copy_of(dir: &tempdir::Dir, name: &str) -> String {
    let to = dir.0.join(name.replace('/', "-"));
    std::fs::copy(sample(name), &to).expect("copy");
    to.to_string_lossy().to_string()
}

/// A changed capture (a frame appended; only its modification time changed) is indexed again,
/// with the new record, and its cache replaced.
#[test]
fn a_changed_capture_is_indexed_again() {
    let dir = tempdir::Dir::new("cache-changed");
    let cache = dir.0.join("cache");
    let filters: Vec<Filter> = ["unpaired", "diag", "apt.position > 1000"]
        .iter()
        .map(|t| Filter::parse(t).expect("filter"))
        .collect();
    for name in ["sessions/kdc101.bin", "sessions/kdc101.pcapng"] {
        let path = copy_of(&dir, name);
        let opts = OpenOptions::default();
        let first = load_cached(&path, opts, None, &cache).expect("opens");
        let n = first.index.read().expect("lock").recs.len();
        assert!(cache_state(&load_cached(&path, opts, None, &cache).expect("opens")).1);
        // Only the time changes: the same records, not read from the cache.
        let f = std::fs::File::options()
            .write(true)
            .open(&path)
            .expect("open");
        f.set_modified(std::time::SystemTime::now() + std::time::Duration::from_secs(60))
            .expect("touch");
        drop(f);
        let touched = load_cached(&path, opts, None, &cache).expect("opens");
        assert_eq!(cache_state(&touched), (CACHE_SAVED, false), "{path}");
        assert_eq!(touched.index.read().expect("lock").recs.len(), n, "{path}");
        assert!(cache_state(&load_cached(&path, opts, None, &cache).expect("opens")).1);
        // A frame appended: the raw copy gets a MOT_MOVE_HOME (0x0443) to channel 1 of the
        // USB device; the pcapng copy is rewritten from it with one more packet.
        let raw = dir.0.join("grown.bin");
        let mut bytes = std::fs::read(sample("sessions/kdc101.bin")).expect("read");
        bytes.extend_from_slice(&[0x43, 0x04, 0x01, 0x00, 0x50, 0x01]);
        std::fs::write(&raw, &bytes).expect("write");
        if path.ends_with(".bin") {
            std::fs::write(&path, &bytes).expect("append");
        } else {
            let tmp = dir.0.join("grown.pcapng");
            to_pcapng(&raw.to_string_lossy(), opts, &tmp.to_string_lossy());
            std::fs::rename(&tmp, &path).expect("replace");
        }
        let grown = load_cached(&path, opts, None, &cache).expect("opens");
        assert_eq!(cache_state(&grown), (CACHE_SAVED, false), "{path}");
        let fresh = load(&path, opts).expect("opens");
        {
            let (g, f) = (
                grown.index.read().expect("lock"),
                fresh.index.read().expect("lock"),
            );
            assert!(g.recs.len() > n, "{path}");
            let last = g.recs.last().expect("a record");
            assert_eq!(
                g.bytes(&last).as_ref(),
                &[0x43, 0x04, 0x01, 0x00, 0x50, 0x01],
                "{path}"
            );
            assert_eq!(g.recs.len(), f.recs.len(), "{path}");
        }
        same_answers(&path, &grown, &fresh, &filters);
        let again = load_cached(&path, opts, None, &cache).expect("opens");
        assert_eq!(cache_state(&again), (CACHE_READ, true), "{path}");
        same_answers(&path, &grown, &again, &filters);
    }
}

/// A cache file cut short (anywhere: in its header, records, bytes or metadata), filled with
/// garbage, or damaged in its header or metadata is ignored: the capture is indexed again, the
/// same answers, no panic, and the file is replaced by a sound one.
#[test]
fn a_damaged_cache_file_is_ignored_and_replaced() {
    let dir = tempdir::Dir::new("cache-damaged");
    let cache = dir.0.join("cache");
    let filters: Vec<Filter> = ["unpaired", "diag", "apt.position > 1000", "ell"]
        .iter()
        .map(|t| Filter::parse(t).expect("filter"))
        .collect();
    for name in [
        "sessions/bsc203.bin",
        "sessions/bsc203.pcapng",
        "sessions/elliptec.mcap",
    ] {
        let path = copy_of(&dir, name);
        let opts = OpenOptions::default();
        let fresh = load_cached(&path, opts, None, &cache).expect("opens");
        let file = cache_file_of(&path, &cache).expect("a cache file");
        let sound = std::fs::read(&file).expect("cache file");
        let len = sound.len();
        // The header: magic, layout, its length, version, key, then the sections' places.
        let u64_at = |i: usize| {
            let mut a = [0u8; 8];
            a.copy_from_slice(&sound[i..i + 8]);
            u64::from_le_bytes(a) as usize
        };
        let version_len = u64_at(16);
        let key_len = u64_at(24 + version_len);
        let meta_off = u64_at(32 + version_len + key_len + 32);
        let damaged: Vec<(String, Vec<u8>)> = vec![
            ("empty".into(), vec![]),
            ("header cut".into(), sound[..20].to_vec()),
            ("records cut".into(), sound[..len / 3].to_vec()),
            ("one byte short".into(), sound[..len - 1].to_vec()),
            ("one byte more".into(), [&sound[..], &[0]].concat()),
            (
                "garbage".into(),
                (0..len).map(|i| (i * 7919 % 251) as u8).collect(),
            ),
            ("magic".into(), {
                let mut b = sound.clone();
                b[0] ^= 1;
                b
            }),
            ("version".into(), {
                // The version's first character (after magic, layout, length and its own).
                let mut b = sound.clone();
                b[24] ^= 1;
                b
            }),
            ("metadata's end".into(), {
                let mut b = sound.clone();
                b[len - 3] ^= 0x40;
                b
            }),
            ("metadata's format".into(), {
                // A value that still decodes: only the checksum tells (the format's first
                // letter, after its length, at the start of the metadata).
                let mut b = sound.clone();
                b[meta_off + 8] ^= 1;
                b
            }),
        ];
        for (what, bytes) in damaged {
            std::fs::write(&file, &bytes).expect("damage");
            let got = load_cached(&path, opts, None, &cache).expect("opens");
            assert_eq!(cache_state(&got), (CACHE_SAVED, false), "{path}: {what}");
            same_answers(&path, &fresh, &got, &filters);
            // Replaced by a sound one.
            let again = load_cached(&path, opts, None, &cache).expect("opens");
            assert_eq!(cache_state(&again), (CACHE_READ, true), "{path}: {what}");
            same_index(&path, &got, &again);
        }
    }
}

/// A capture that is not there to read back, or a cache directory that cannot be made, does not
/// stop the view: the index is made and not saved.
#[test]
fn a_cache_that_cannot_be_written_is_skipped() {
    let dir = tempdir::Dir::new("cache-unwritable");
    // A file where the cache directory should be.
    let cache = dir.0.join("not-a-dir");
    std::fs::write(&cache, b"x").expect("write");
    let path = sample("sessions/kdc101.bin");
    let got = load_cached(&path, OpenOptions::default(), None, &cache).expect("opens");
    assert_eq!(cache_state(&got), (CACHE_NOT_SAVED, false));
    let fresh = load(&path, OpenOptions::default()).expect("opens");
    same_answers(&path, &fresh, &got, &[]);
}

/// Write the capture `src` again as pcapng at `out`.
fn to_pcapng(src: &str, opts: OpenOptions, out: &str) {
    let (mut r, _) = aptscope_capture::open::open(src, opts).expect("open");
    let mut w = aptscope_capture::open::create(
        out,
        aptscope_capture::open::Format::parse("pcapng").expect("pcapng"),
        true,
    )
    .expect("create");
    w.stream(&Default::default()).expect("stream");
    while let Some(ev) = r.next_event() {
        if let Event::Chunk(c) = ev {
            w.chunk(&c).expect("chunk");
        }
    }
    w.finish().expect("finish");
}
