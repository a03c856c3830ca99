//! End to end: the real binary under tmux (skipped, with a message, when tmux is missing).

use std::path::PathBuf;
use std::process::Command;
use std::thread::sleep;
use std::time::{Duration, Instant};

fn tmux(args: &[&str]) -> Option<String> {
    let out = Command::new("tmux").args(args).output().ok()?;
    Some(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The viewer: the `view` example (built by `cargo test`), else `aptscope view`.
fn viewer() -> Option<Vec<String>> {
    let exe = std::env::current_exe().ok()?;
    let dir = exe.parent()?.parent()?.to_path_buf(); // target/debug
    let example: PathBuf = dir.join("examples").join("view");
    if example.exists() {
        return Some(vec![example.to_string_lossy().into_owned()]);
    }
    let bin = dir.join("aptscope");
    bin.exists()
        .then(|| vec![bin.to_string_lossy().into_owned(), "view".into()])
}

/// The screen once it shows every one of `what` (a capture can catch a redraw half done, so
/// wait for all the parts of the expected state), or after 10 s.
fn wait_for(session: &str, what: &[&str]) -> String {
    let start = Instant::now();
    loop {
        let screen = tmux(&["capture-pane", "-p", "-t", session]).unwrap_or_default();
        if what.iter().all(|w| screen.contains(w)) || start.elapsed() > Duration::from_secs(10) {
            return screen;
        }
        sleep(Duration::from_millis(100));
    }
}

#[test]
fn real_binary_under_tmux() {
    if Command::new("tmux").arg("-V").output().is_err() {
        eprintln!("tmux not installed: skipping the end-to-end TUI test");
        return;
    }
    let Some(cmd) = viewer() else {
        eprintln!("no viewer binary found: skipping the end-to-end TUI test");
        return;
    };
    let sample = format!(
        "{}/../samples/kdc101-session.pcapng",
        env!("CARGO_MANIFEST_DIR")
    );
    let session = format!("aptscope-tui-test-{}", std::process::id());
    let line = format!("{} {sample}", cmd.join(" "));
    tmux(&[
        "new-session",
        "-d",
        "-s",
        &session,
        "-x",
        "80",
        "-y",
        "24",
        &line,
    ])
    .expect("tmux runs");
    let screen = wait_for(
        &session,
        &["HW_REQ_INFO", "Timeline 1/20", "MOD_SET_CHANENABLESTATE"],
    );
    assert!(screen.contains("Timeline 1/20"), "{screen}");
    assert!(screen.contains("MOD_SET_CHANENABLESTATE"), "{screen}");
    // Go to record 19, jump to its request, filter, then quit.
    tmux(&["send-keys", "-t", &session, ":19", "Enter"]);
    let screen = wait_for(&session, &["Timeline 19/20", "Record 19"]);
    assert!(screen.contains("Record 19"), "{screen}");
    tmux(&["send-keys", "-t", &session, "p"]);
    let screen = wait_for(&session, &["Timeline 13/20", "Record 13"]);
    assert!(screen.contains("Record 13"), "{screen}");
    tmux(&["send-keys", "-t", &session, "/apt.name ~ HOME", "Enter"]);
    let screen = wait_for(&session, &["2 shown", "MOT_MOVE_HOMED"]);
    assert!(screen.contains("MOT_MOVE_HOMED"), "{screen}");
    assert!(!screen.contains("MOT_MOVE_ABSOLUTE"), "{screen}");
    tmux(&["send-keys", "-t", &session, "q"]);
    let alive = || {
        Command::new("tmux")
            .args(["has-session", "-t", &session])
            .stderr(std::process::Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
    };
    let start = Instant::now();
    while alive() && start.elapsed() < Duration::from_secs(5) {
        sleep(Duration::from_millis(100));
    }
    if alive() {
        tmux(&["kill-session", "-t", &session]);
        panic!("the viewer did not quit on q");
    }
}
