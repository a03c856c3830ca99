//! The public client libraries (PyPI) that the acceptance tests run against the simulators:
//! one virtual environment under `target/`, made once, as `python/run-tests` makes its own.

use aptscope_capture::tools::missing;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The client libraries, pinned: the versions the simulators were checked against.
pub const CLIENTS: &[&str] = &[
    "thorlabs-apt-device==0.3.8",
    "pylablib==1.4.5",
    "elliptec==0.1.0",
    "thorlabs-elliptec==1.3.0",
];

/// What the environment must import for it to count as made.
const IMPORTS: &str = "import thorlabs_apt_device, pylablib, elliptec, thorlabs_elliptec";

/// The interpreter of a virtual environment holding every [`CLIENTS`] library, or `None` when
/// it cannot be made and the tools rule says skip (in CI it fails).
pub fn client_python() -> Option<PathBuf> {
    let target = Path::new(env!("CARGO_MANIFEST_DIR")).join("target");
    let venv = target.join("client-venv");
    let py = venv.join("bin/python");
    // One maker at a time: the tests of a binary run at once, and on a fresh checkout they
    // would all make the same environment together (the lock is released when `_lock` drops).
    let _lock = std::fs::create_dir_all(&target)
        .and_then(|()| std::fs::File::create(target.join("client-venv.lock")))
        .and_then(|f| f.lock().map(|()| f));
    let has = |py: &Path| {
        Command::new(py)
            .args(["-c", IMPORTS])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if has(&py) {
        return Some(py);
    }
    let made = Command::new("python3")
        .args(["-m", "venv"])
        .arg(&venv)
        .status()
        .is_ok_and(|s| s.success())
        && Command::new(&py)
            .args(["-m", "pip", "install", "-q", "--disable-pip-version-check"])
            .args(CLIENTS)
            .status()
            .is_ok_and(|s| s.success());
    if made && has(&py) {
        return Some(py);
    }
    // The project's rule for a missing tool: fail in CI, skip outside it only when asked.
    let how = "python3 with venv (`apt-get install python3-venv`) and PyPI are needed";
    let what = format!(
        "a virtual environment with {} could not be made in {}",
        CLIENTS.join(", "),
        venv.display()
    );
    missing(&what, how);
    None
}
