//! End to end: the real binary under tmux. Needs tmux (`.ci/run` installs it): without it the
//! test fails, unless `APTSCOPE_SKIP_MISSING_TOOLS=1` outside CI (see the README's Tests
//! section).

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

/// The screen once it shows every one of `what` and has stopped changing (a capture can catch
/// a redraw half done: the parts of the expected state can be there while other cells still
/// show the previous one), or after 10 s.
fn wait_for(session: &str, what: &[&str]) -> String {
    let start = Instant::now();
    let mut last = String::new();
    loop {
        let screen = tmux(&["capture-pane", "-p", "-t", session]).unwrap_or_default();
        let shown = what.iter().all(|w| screen.contains(w));
        if (shown && screen == last) || start.elapsed() > Duration::from_secs(10) {
            return screen;
        }
        last = screen;
        sleep(Duration::from_millis(100));
    }
}

#[test]
fn real_binary_under_tmux() {
    if !aptscope_capture::tools::require("tmux", "-V", "tmux") {
        return;
    }
    // `cargo test` builds the example; a run of this test alone (`--test tmux`) may not have.
    let cmd = viewer().expect(
        "no viewer binary: build it with `cargo build -p aptscope-tui --example view` \
         (a plain `cargo test` builds it)",
    );
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
    // Column headers over the timeline.
    assert!(
        screen.contains("No.") && screen.contains("Message") && screen.contains("Info"),
        "{screen}"
    );
    // The help fits the width and scrolls to its end (colours and filter examples).
    tmux(&["send-keys", "-t", &session, "?"]);
    let screen = wait_for(&session, &["Help", "lines 1–"]);
    assert!(
        screen.contains("apply the selected detail line"),
        "{screen}"
    );
    tmux(&["send-keys", "-t", &session, "G"]);
    let screen = wait_for(&session, &["latency > 50ms", "Colours"]);
    assert!(screen.contains("latency > 50ms"), "{screen}");
    tmux(&["send-keys", "-t", &session, "Escape"]);
    wait_for(&session, &["Timeline 1/20"]);
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
    // Apply as filter: the selected row's message (MOT_MOVE_HOME, the first shown).
    tmux(&["send-keys", "-t", &session, "a"]);
    let screen = wait_for(&session, &["filter: apt.name == MOT_MOVE_HOME", "1 shown"]);
    assert!(screen.contains("1 shown"), "{screen}");
    // Prepare as filter from a detail line: the source address, in the filter bar.
    tmux(&[
        "send-keys",
        "-t",
        &session,
        "Tab",
        "j",
        "j",
        "j",
        "j",
        "j",
        "A",
    ]);
    let screen = wait_for(&session, &["/apt.src == host"]);
    assert!(screen.contains("/apt.src == host"), "{screen}");
    tmux(&["send-keys", "-t", &session, "Enter"]);
    let screen = wait_for(&session, &["filter: apt.src == host", "7 shown"]);
    assert!(screen.contains("7 shown"), "{screen}");
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
