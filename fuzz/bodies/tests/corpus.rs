//! Every fuzz target's body, run as an ordinary test over its seed corpus
//! (`fuzz/corpus/<target>/`) and the inputs that once made it fail
//! (`fuzz/artifacts-found/<target>/`): a check that no longer states the code's rules fails here,
//! not only under libFuzzer.

use aptscope_fuzz_bodies::TARGETS;
use std::path::{Path, PathBuf};
use std::time::Instant;

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The regular files of `dir`, sorted (none when it does not exist).
fn files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file())
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// Sub-folders of `dir` by name.
fn folders(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .expect("folder")
        .filter_map(|e| e.ok())
        .filter(|e| e.path().is_dir())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Run target `name` over its corpus and found inputs; fails naming every input that panicked.
fn run_target(name: &str) {
    let body = TARGETS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, b)| *b)
        .expect("a target of that name");
    let dir = fuzz_dir();
    let seeds = files(&dir.join("corpus").join(name));
    assert!(!seeds.is_empty(), "{name}: no seed corpus");
    let found = files(&dir.join("artifacts-found").join(name));
    let start = Instant::now();
    let mut failed = vec![];
    let mut slowest = (std::time::Duration::ZERO, String::new());
    for p in seeds.iter().chain(&found) {
        let data = std::fs::read(p).expect("read input");
        let t = Instant::now();
        if std::panic::catch_unwind(|| body(&data)).is_err() {
            failed.push(p.display().to_string());
        }
        if t.elapsed() > slowest.0 {
            slowest = (t.elapsed(), p.display().to_string());
        }
    }
    // Seen with --nocapture: where the time goes, to keep the test short.
    eprintln!(
        "{name}: {} seeds, {} found inputs, {:.2?} (slowest {:.2?}: {})",
        seeds.len(),
        found.len(),
        start.elapsed(),
        slowest.0,
        slowest.1
    );
    assert!(
        failed.is_empty(),
        "{name} failed on (the panic of each is printed above):\n  {}",
        failed.join("\n  ")
    );
}

macro_rules! corpus_tests {
    ($($t:ident),* $(,)?) => {
        $(
            #[test]
            fn $t() {
                run_target(stringify!($t));
            }
        )*
        /// The names above, to check that none is missing.
        const TESTED: &[&str] = &[$(stringify!($t)),*];
    };
}

corpus_tests!(
    apt_framer,
    arrow_pool,
    dataset_rows,
    decode_pipeline,
    ell_encode,
    ell_framer,
    encode_roundtrip,
    filter_parse,
    follow_reader,
    mcap_reader,
    pcap_reader,
    textlog_reader,
    tui_view,
    units,
    usb_unwrap,
);

/// Targets, corpus folders, found-input folders and cargo-fuzz binaries name the same set: a new
/// target cannot go untested here, and no found input lies where no test reads it.
#[test]
fn every_target_is_tested_and_every_input_belongs_to_one() {
    let dir = fuzz_dir();
    let mut names: Vec<&str> = TARGETS.iter().map(|(n, _)| *n).collect();
    names.sort();
    let mut tested = TESTED.to_vec();
    tested.sort();
    assert_eq!(tested, names, "a target without its corpus test");
    assert_eq!(folders(&dir.join("corpus")), names, "corpus folders");
    for f in folders(&dir.join("artifacts-found")) {
        assert!(
            names.contains(&f.as_str()),
            "artifacts-found/{f}: no such target"
        );
    }
    for p in files(&dir.join("artifacts-found")) {
        assert!(
            p.extension().is_none_or(|e| e != "fuzz"),
            "{}: a target's input belongs in artifacts-found/<target>/",
            p.display()
        );
    }
    let manifest = std::fs::read_to_string(dir.join("Cargo.toml")).expect("fuzz/Cargo.toml");
    for n in &names {
        assert!(
            manifest.contains(&format!("name = \"{n}\"\npath = \"fuzz_targets/{n}.rs\"")),
            "fuzz/Cargo.toml has no [[bin]] {n}"
        );
        let src = std::fs::read_to_string(dir.join(format!("fuzz_targets/{n}.rs")))
            .expect("fuzz_targets/<target>.rs");
        assert!(
            src.contains(&format!("aptscope_fuzz_bodies::{n}::fuzz(data)")),
            "fuzz_targets/{n}.rs does not run its body"
        );
    }
}
