//! `aptscope replay` end to end: real processes on real pseudo-terminals.

mod common;

use common::scratch;
use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_aptscope");
const SAMPLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/samples/kdc101-session.pcapng");
/// Generous: only reached when something is broken.
const DEADLINE: Duration = Duration::from_secs(60);

/// A child process killed when the test ends, however it ends.
struct Proc(Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Start `aptscope ARGS` with a pseudo-terminal link at `link`; wait for the link to appear.
fn start_with_link(args: &[&str], link: &Path) -> Child {
    let mut child = Command::new(BIN)
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let give_up = Instant::now() + DEADLINE;
    while std::fs::read_link(link).is_err() {
        if Instant::now() > give_up {
            let _ = child.kill();
            panic!("{} never appeared", link.display());
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    child
}

fn sim(dir: &Path) -> (Proc, PathBuf) {
    let link = dir.join("kdc101");
    let p = start_with_link(
        &[
            "sim",
            "apt",
            "--model",
            "kdc101",
            "--pty",
            link.to_str().unwrap(),
        ],
        &link,
    );
    (Proc(p), link)
}

fn run(args: &[&str]) -> Output {
    Command::new(BIN)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

#[test]
fn dry_run_lists_the_schedule_and_sends_nothing() {
    let o = run(&["replay", SAMPLE, "--dry-run"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    let lines: Vec<&str> = out.lines().filter(|l| l.starts_with('+')).collect();
    assert_eq!(lines.len(), 7, "{out}");
    assert!(lines[0].contains("HW_REQ_INFO  → HW_GET_INFO  [05 00 00 00 50 01]"));
    assert!(lines[4].starts_with("+    0.204000 s"), "{}", lines[4]);
    assert!(out.contains("# dry run: 7 messages to send (3 of them motion commands), nothing sent"));
    // Twice as fast, from record 7 on, twice.
    let o = run(&[
        "replay",
        SAMPLE,
        "--dry-run",
        "--json",
        "--speed",
        "2",
        "--from",
        "7",
        "--loop",
        "2",
    ]);
    let v: Vec<Value> = text(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let names: Vec<&str> = v.iter().map(|x| x["name"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        ["MOT_MOVE_HOME", "MOT_MOVE_ABSOLUTE", "HW_STOP_UPDATEMSGS"].repeat(2)
    );
    assert_eq!(v[1]["at_s"], 1.025);
    assert_eq!(v[3]["pass"], 2);
    assert_eq!(v[0]["motion"], true);
}

#[test]
fn motion_to_a_real_port_needs_confirmation() {
    // /dev/ptmx is a terminal device that is no pseudo-terminal's slave: a stand-in for a real
    // port (opening it makes a new pair nobody answers on).
    let o = run(&["replay", SAMPLE, "--port", "/dev/ptmx"]);
    assert!(!o.status.success());
    let err = text(&o.stderr);
    assert!(
        err.contains("/dev/ptmx is a real port and the replay sends motion commands: "),
        "{err}"
    );
    assert!(
        err.contains("MOT_MOVE_HOME ×1") && err.contains("give --yes"),
        "{err}"
    );
    // A selection without motion goes through the check (and is sent to a line nobody
    // answers on: the replies are missing).
    let o = run(&[
        "replay",
        SAMPLE,
        "--port",
        "/dev/ptmx",
        "-Y",
        "apt.name == \"HW_REQ_INFO\"",
    ]);
    assert!(!text(&o.stderr).contains("--yes"), "{}", text(&o.stderr));
}

#[test]
fn host_and_device_replays_of_one_capture_agree() {
    let dir = scratch("agree");
    let link = dir.join("ttyAPT");
    let dev = start_with_link(
        &[
            "replay",
            SAMPLE,
            "--as",
            "device",
            "--pty",
            link.to_str().unwrap(),
            "--quiet",
            "--duration",
            "60s",
        ],
        &link,
    );
    let rec = dir.join("seen.pcapng");
    let o = run(&[
        "replay",
        SAMPLE,
        "--port",
        link.to_str().unwrap(),
        "--check",
        "--json",
        "--quiet",
        "-w",
        rec.to_str().unwrap(),
    ]);
    assert!(
        o.status.success(),
        "{}\n{}",
        text(&o.stdout),
        text(&o.stderr)
    );
    let report: Value = serde_json::from_str(text(&o.stdout).lines().last().unwrap()).unwrap();
    assert_eq!(report["type"], "replay");
    assert_eq!(report["failures"], 0, "{report}");
    assert_eq!(report["matched"], 4);
    assert_eq!(report["sent"], 7);
    assert_eq!(
        report["unsolicited"]["MOT_GET_DCSTATUSUPDATE"],
        serde_json::json!({"captured": 9, "observed": 9})
    );
    // The device side saw the host hang up and reports every request answered.
    let out = dev.wait_with_output_bounded();
    assert!(
        out.contains("7 from the host, 7 answered from the capture"),
        "{out}"
    );
    // Its link is gone with it (a pseudo-terminal number is reused by other programs).
    assert!(
        std::fs::symlink_metadata(&link).is_err(),
        "link left behind"
    );
    // The recording decodes to the captured conversation.
    let d = run(&["decode", rec.to_str().unwrap(), "--json"]);
    let frames = text(&d.stdout)
        .lines()
        .filter(|l| l.contains("\"type\":\"frame\""))
        .count();
    assert_eq!(frames, 20);
}

trait Bounded {
    fn wait_with_output_bounded(self) -> String;
}

impl Bounded for Child {
    /// Wait for the process to end by itself (within [`DEADLINE`]) and return its stdout.
    fn wait_with_output_bounded(mut self) -> String {
        let give_up = Instant::now() + DEADLINE;
        loop {
            if self.try_wait().unwrap().is_some() {
                break;
            }
            if Instant::now() > give_up {
                let _ = self.kill();
                panic!("did not end");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let o = self.wait_with_output().unwrap();
        text(&o.stdout)
    }
}

#[test]
fn check_fails_when_the_device_answers_differently() {
    // The sample is not from this simulator: its move takes longer than captured.
    let dir = scratch("check");
    let (_sim, link) = sim(&dir);
    let o = run(&[
        "replay",
        SAMPLE,
        "--port",
        link.to_str().unwrap(),
        "--check",
        "--reply-timeout",
        "200ms",
        "--quiet",
    ]);
    assert!(!o.status.success());
    let out = text(&o.stdout);
    assert!(
        out.contains("MISSING  MOT_MOVE_COMPLETED ch1 (reply to #13 MOT_MOVE_ABSOLUTE ch1)"),
        "{out}"
    );
    assert!(text(&o.stderr).contains("differences found (--check)"));
}

#[test]
fn ctrl_c_stops_sending_and_stops_the_moving_channel() {
    let dir = scratch("abort");
    let (_sim, link) = sim(&dir);
    let rec = dir.join("aborted.pcapng");
    let child = Command::new(BIN)
        .args([
            "replay",
            SAMPLE,
            "--port",
            link.to_str().unwrap(),
            "--stop-on-abort",
            "-w",
            rec.to_str().unwrap(),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut p = Proc(child);
    let pid = nix::unistd::Pid::from_raw(p.0.id() as i32);
    let stdout = p.0.stdout.take().unwrap();
    let mut lines = BufReader::new(stdout).lines();
    // Homing takes the simulator 2 s: interrupt it in the middle.
    for l in lines.by_ref() {
        let l = l.unwrap();
        if l.contains("MOT_MOVE_HOME ") {
            break;
        }
    }
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT).unwrap();
    let rest: Vec<String> = lines.map(|l| l.unwrap()).collect();
    let rest = rest.join("\n");
    let status = p.0.wait().unwrap();
    assert!(status.success(), "{rest}");
    assert!(rest.contains("# aborted: SIGINT"), "{rest}");
    assert!(
        rest.contains("# sent on abort: MOT_MOVE_STOP ch1 to 0x50"),
        "{rest}"
    );
    assert!(rest.contains("# sent 5 of 7 messages"), "{rest}");
    // The recording ends with the stop, and nothing of the capture after it was sent.
    let d = run(&["decode", rec.to_str().unwrap()]);
    let host: Vec<String> = text(&d.stdout)
        .lines()
        .filter(|l| l.contains("host →"))
        .map(str::to_string)
        .collect();
    assert!(host.last().unwrap().contains("MOT_MOVE_STOP"), "{host:?}");
    assert!(!host.iter().any(|l| l.contains("MOT_MOVE_ABSOLUTE")));
}

/// What is wrong with the port, or with the options, is said before anything is asked or sent.
#[test]
fn port_and_option_errors_say_what_is_wrong_before_any_prompt() {
    let dir = scratch("port-errors");
    let file = dir.join("regular");
    std::fs::write(&file, b"").unwrap();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["--port".into(), dir.join("missing").display().to_string()],
            "no such port",
        ),
        (
            vec!["--port".into(), file.display().to_string()],
            "is a regular file, not a serial port",
        ),
        (
            vec!["--port".into(), "/dev/null".into()],
            "is not a terminal, so not a serial port",
        ),
        (
            vec!["--dry-run".into(), "--speed".into(), "0".into()],
            "--speed 0: give a factor above 0",
        ),
        (
            vec!["--dry-run".into(), "--from".into(), "1000".into()],
            "--from record 1000 is beyond the capture (its last record is 20)",
        ),
        (
            vec!["--dry-run".into(), "--from".into(), "100s".into()],
            "is beyond the capture (it lasts",
        ),
        (
            vec![
                "--dry-run".into(),
                "--from".into(),
                "10".into(),
                "--to".into(),
                "5".into(),
            ],
            "--from (record 10) is after --to (record 5)",
        ),
    ];
    for (extra, want) in cases {
        let mut args = vec!["replay", SAMPLE];
        args.extend(extra.iter().map(String::as_str));
        let o = run(&args);
        let err = text(&o.stderr);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(err.contains(want), "{args:?}: {err}");
        assert!(
            !err.contains("give --yes"),
            "{args:?}: asked before saying what is wrong"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Random bytes are not a capture: the replay refuses them (it planned to send the few headers
/// they happen to hold, `MOT_MOVE_STOP ch202` among them), saying why.
#[test]
fn a_file_that_is_not_a_capture_is_not_replayed() {
    let dir = scratch("replay-rand");
    let rand = dir.join("rand.bin");
    std::fs::write(&rand, common::noise(5000, 7)).unwrap();
    let o = run(&["replay", rand.to_str().unwrap(), "--dry-run"]);
    assert!(!o.status.success(), "{}", text(&o.stdout));
    assert!(
        text(&o.stderr).contains("not a capture"),
        "{}",
        text(&o.stderr)
    );
    assert!(!text(&o.stdout).contains("to send"), "{}", text(&o.stdout));
}

/// A device replay stopped by SIGINT or SIGTERM removes the link it made for the host.
#[test]
fn a_device_replay_removes_its_link_on_a_signal() {
    for sig in [
        nix::sys::signal::Signal::SIGINT,
        nix::sys::signal::Signal::SIGTERM,
    ] {
        let dir = scratch("device-link");
        let link = dir.join("ttyAPT");
        let args = [
            "replay",
            SAMPLE,
            "--as",
            "device",
            "--pty",
            link.to_str().unwrap(),
            "--quiet",
        ];
        let dev = start_with_link(&args, &link);
        nix::sys::signal::kill(nix::unistd::Pid::from_raw(dev.id() as i32), sig).unwrap();
        let _ = dev.wait_with_output_bounded();
        assert!(
            std::fs::symlink_metadata(&link).is_err(),
            "{sig}: link left behind"
        );
    }
}

/// A long wait for replies says what it waits for and for how long, once (it used to wait up to
/// 120 s in silence for a MOT_MOVE_HOMED that did not come); `--quiet` keeps it quiet.
#[test]
fn a_long_wait_for_replies_says_what_it_waits_for() {
    let dir = scratch("waiting");
    let (_sim, link) = sim(&dir);
    // A request the simulated KDC101 does not answer (a piezo message), and the reply captured.
    let capture = dir.join("unanswered.hex");
    std::fs::write(
        &capture,
        "81 06 01 00 50 01\n82 06 06 00 81 50 01 00 EE 02 00 00\n",
    )
    .unwrap();
    for quiet in [false, true] {
        let mut args = vec![
            "replay",
            capture.to_str().unwrap(),
            "--port",
            link.to_str().unwrap(),
            "--check",
            "--reply-timeout",
            "4s",
        ];
        if quiet {
            args.push("--quiet");
        }
        let o = run(&args);
        assert!(!o.status.success(), "the reply is missing");
        let err = text(&o.stderr);
        let said = "replay: waiting up to 4 s for PZ_GET_OUTPUTMAXVOLTS ch1 (1 reply outstanding)";
        assert_eq!(err.matches(said).count(), usize::from(!quiet), "{err}");
    }
}
