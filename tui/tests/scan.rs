//! The filter/statistics scan gives exactly what rendering every record to NDJSON, parsing it
//! and matching the filter on the whole object gives (and what `decode -Y` selects).

use aptscope_capture::model::Event;
use aptscope_capture::open::OpenOptions;
use aptscope_dissector::filter::Filter;
use aptscope_dissector::pipeline::{Format, Pipeline};
use aptscope_dissector::stats::Stats;
use aptscope_dissector::{synth, Table};
use aptscope_tui::decode::{direct, json_of, project, render, NOT_DIRECT};
use aptscope_tui::index::{load, Shared};
use aptscope_tui::scan::{Scan, STATS_KEYS};
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
];

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
        "{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}",
        s.frames, s.garbage, s.messages, s.addresses, s.directions, s.diags, s.bins, s.bin_ns
    )
}

/// What the scan did before: every record rendered and parsed whole.
fn reference(shared: &Arc<Shared>, filter: Option<&Filter>) -> (Vec<u64>, String) {
    let ix = shared.index.read().expect("lock");
    let mut buf = String::new();
    let mut found = vec![];
    let mut stats = Stats::new(1_000_000_000);
    for n in 1..=ix.recs.len() as u64 {
        let Some(v) = json_of(&ix, n, &mut buf) else {
            continue;
        };
        if filter.is_none_or(|f| f.matches(&v)) {
            if filter.is_some() {
                found.push(n);
            }
            stats.add(&v);
        }
    }
    (found, stats_text(&stats))
}

/// Every key of every record: `project` of the rendering and `direct` give the values of the
/// whole parsed object.
fn check_records(name: &str, shared: &Arc<Shared>) {
    let ix = shared.index.read().expect("lock");
    let mut buf = String::new();
    let mut direct_count = 0;
    for n in 1..=ix.recs.len() as u64 {
        let Some(full) = json_of(&ix, n, &mut buf) else {
            assert!(render(&ix, n, &mut buf).is_none(), "{name} #{n}");
            continue;
        };
        let obj = full.as_object().expect("object");
        let rd = render(&ix, n, &mut buf).expect("renders");
        let mut keys: Vec<&str> = obj.keys().map(String::as_str).collect();
        keys.push("not_a_key");
        assert_eq!(
            project(&buf, &rd, &keys, None).as_ref(),
            Some(&full),
            "{name} #{n}"
        );
        let some: Vec<&str> = keys.iter().copied().step_by(3).collect();
        let want: serde_json::Map<String, Value> = obj
            .iter()
            .filter(|(k, _)| some.contains(&k.as_str()))
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect();
        assert_eq!(
            project(&buf, &rd, &some, None),
            Some(Value::Object(want)),
            "{name} #{n}"
        );
        // `fields` reduced to some of its names (and one that is not there).
        let names: Vec<String> = obj
            .get("fields")
            .and_then(Value::as_object)
            .map(|m| m.keys().step_by(2).cloned().collect())
            .unwrap_or_default();
        let mut sub: Vec<&str> = names.iter().map(String::as_str).collect();
        sub.push("no_such_field");
        let mut want_sub = full.clone();
        if let Some(m) = want_sub.get_mut("fields").and_then(Value::as_object_mut) {
            m.retain(|k, _| sub.contains(&k.as_str()));
        }
        assert_eq!(
            project(&buf, &rd, &keys, Some(&sub)).as_ref(),
            Some(&want_sub),
            "{name} #{n}"
        );
        // Every key but those rendered, and some that APT frames do not have.
        let dkeys: Vec<&str> = keys
            .iter()
            .copied()
            .filter(|k| !NOT_DIRECT.contains(k))
            .chain(["addr", "cmd", "position", "module", "interim", "unpaired"])
            .collect();
        if let Some(d) = direct(&ix, n, &dkeys, &sub) {
            let want: serde_json::Map<String, Value> = want_sub
                .as_object()
                .expect("object")
                .iter()
                .filter(|(k, _)| dkeys.contains(&k.as_str()))
                .map(|(k, v)| (k.clone(), v.clone()))
                .collect();
            assert_eq!(d, Value::Object(want), "{name} #{n}");
            direct_count += 1;
        }
    }
    if ix.proto == Some(aptscope_dissector::detect::Proto::Apt) {
        assert!(direct_count > 0, "{name}");
    }
}

#[test]
fn stats_keys_are_sorted_and_buildable() {
    let mut s = STATS_KEYS.to_vec();
    s.sort_unstable();
    assert_eq!(s, STATS_KEYS);
    assert!(STATS_KEYS.iter().all(|k| !NOT_DIRECT.contains(k)));
}

#[test]
fn reduced_records_equal_the_whole_ones() {
    for path in samples() {
        let shared = load(&path, OpenOptions::default()).expect("opens");
        check_records(&path, &shared);
    }
    let (_dir, path) = synthetic();
    let shared = load(&path, OpenOptions::default()).expect("opens");
    check_records("synthetic", &shared);
}

#[test]
fn scan_equals_matching_whole_records() {
    let (_dir, synth) = synthetic();
    for path in samples().into_iter().chain([synth]) {
        let shared = load(&path, OpenOptions::default()).expect("opens");
        assert_eq!(scan(&shared, None), reference(&shared, None), "{path}");
        for text in FILTERS {
            let f = Filter::parse(text).expect("filter");
            assert_eq!(
                scan(&shared, Some(f.clone())),
                reference(&shared, Some(&f)),
                "{path}: {text}"
            );
        }
    }
}

/// The records `decode --json -Y FILTER` selects, with each late `no_reply` diagnostic merged
/// into the record it refers to (as the viewer shows it).
fn pipeline_matches(path: &str, filters: &[Filter]) -> Vec<Vec<u64>> {
    let (mut r, _) = aptscope_capture::open::open(path, OpenOptions::default()).expect("opens");
    let mut p = Pipeline::new(None, Format::Json);
    let mut out: Vec<Value> = vec![];
    let mut emit = |l: &str| -> Result<(), ()> {
        out.push(serde_json::from_str(l).expect("json"));
        Ok(())
    };
    while let Some(ev) = r.next_event() {
        if let Event::Chunk(c) = ev {
            let ctx = c.ctx();
            p.push_chunk(ctx, c.bytes, &mut emit).expect("push");
        }
    }
    p.finish(&mut emit).expect("finish");
    let late: Vec<(u64, Vec<Value>)> = out
        .iter()
        .filter(|v| v["type"] == "diag")
        .filter_map(|v| Some((v["ref"].as_u64()?, v["diag"].as_array()?.clone())))
        .collect();
    let mut recs: Vec<Value> = out.into_iter().filter(|v| v.get("n").is_some()).collect();
    for (n, ds) in late {
        let rec = recs
            .iter_mut()
            .find(|v| v["n"].as_u64() == Some(n))
            .expect("late diag refers to a record");
        rec["diag"].as_array_mut().expect("diag list").extend(ds);
    }
    filters
        .iter()
        .map(|f| {
            recs.iter()
                .filter(|v| f.matches(v))
                .filter_map(|v| v["n"].as_u64())
                .collect()
        })
        .collect()
}

#[test]
fn scan_matches_equal_the_pipeline_selection() {
    let filters: Vec<Filter> = FILTERS
        .iter()
        .map(|t| Filter::parse(t).expect("filter"))
        .collect();
    let mut total = vec![0; filters.len()];
    for path in samples() {
        let want = pipeline_matches(&path, &filters);
        let shared = load(&path, OpenOptions::default()).expect("opens");
        for (i, (f, want)) in filters.iter().zip(want).enumerate() {
            let (got, _) = scan(&shared, Some(f.clone()));
            assert_eq!(got, want, "{path}: {f}");
            total[i] += got.len();
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
