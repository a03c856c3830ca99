//! A fresh scratch directory per test, shared by the tests of every crate (the root's through
//! `tests/common`, the others with `#[path = "…/tests/common/scratch.rs"] mod scratch;`).

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

/// A new, empty directory under the system's temporary directory, named after the test crate,
/// the process and `name` (a counter keeps the calls of one process apart).
pub fn scratch(name: &str) -> PathBuf {
    static N: AtomicUsize = AtomicUsize::new(0);
    let d = std::env::temp_dir().join(format!(
        "aptscope-{}-{}-{}-{name}",
        env!("CARGO_CRATE_NAME"),
        std::process::id(),
        N.fetch_add(1, Ordering::SeqCst)
    ));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display()));
    d
}
