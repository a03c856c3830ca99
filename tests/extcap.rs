//! `aptscope extcap`, aptscope as a Wireshark capture source, through the real binary: the
//! extcap requests, tshark finding it in a personal extcap folder (a symlink named
//! `aptscope-extcap`), and live captures of a simulator through tshark and through a FIFO read
//! like Wireshark's, each stopped the ways Wireshark stops them.
//!
//! tshark is required (see `aptscope_capture::tools::require`). Every wait is a poll against a
//! generous deadline that only a broken build reaches.

mod common;

use aptscope_capture::tools::require;
use common::host::{ask_info, ready, start_sim, HW_REQ_INFO};
use common::proc::{wait_for, Proc};
use common::Scratch;
use nix::fcntl::OFlag;
use nix::poll::PollFlags;
use nix::sys::signal::Signal;
use nix::sys::stat::Mode;
use serde_json::Value;
use std::fs::File;
use std::io::{self, Read};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

const BIN: &str = env!("CARGO_BIN_EXE_aptscope");

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

fn run(cmd: &mut Command) -> Output {
    cmd.stdin(Stdio::null()).output().expect("run")
}

fn aptscope(args: &[&str]) -> Output {
    run(Command::new(BIN).args(args))
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// The frame names of `aptscope decode --json FILE`.
fn decoded_names(file: &Path) -> Vec<String> {
    let o = aptscope(&["decode", "--json", s(file)]);
    assert!(o.status.success(), "decode: {}", text(&o.stderr));
    text(&o.stdout)
        .lines()
        .map(|l| serde_json::from_str::<Value>(l).expect("NDJSON"))
        .filter(|r| r["type"] == "frame")
        .map(|r| r["name"].as_str().unwrap_or("?").to_string())
        .collect()
}

/// One line of the extcap grammar: `keyword {k=v}{k=v}…` → the keyword and its pairs.
fn sentence(line: &str) -> (String, Vec<(String, String)>) {
    let (kw, rest) = line
        .split_once(' ')
        .unwrap_or_else(|| panic!("no sentence: {line}"));
    assert!(rest.starts_with('{') && rest.ends_with('}'), "{line}");
    let pairs = rest[1..rest.len() - 1]
        .split("}{")
        .map(|p| {
            assert!(!p.contains(['{', '}']), "{line}");
            let (k, v) = p.split_once('=').unwrap_or_else(|| panic!("{line}"));
            (k.to_string(), v.to_string())
        })
        .collect();
    (kw.to_string(), pairs)
}

fn get<'a>(pairs: &'a [(String, String)], k: &str) -> Option<&'a str> {
    pairs.iter().find(|(a, _)| a == k).map(|(_, v)| v.as_str())
}

fn extcap_ok(args: &[&str]) -> Vec<(String, Vec<(String, String)>)> {
    let mut a = vec!["extcap"];
    a.extend_from_slice(args);
    let o = aptscope(&a);
    assert!(o.status.success(), "{args:?}: {}", text(&o.stderr));
    assert!(o.stderr.is_empty(), "{args:?}: {}", text(&o.stderr));
    text(&o.stdout).lines().map(sentence).collect()
}

#[test]
fn the_extcap_requests_answer_in_wiresharks_grammar() {
    let ifs = extcap_ok(&["--extcap-interfaces", "--extcap-version=4.0"]);
    assert_eq!(ifs[0].0, "extcap");
    assert_eq!(get(&ifs[0].1, "version"), Some(env!("CARGO_PKG_VERSION")));
    let names: Vec<&str> = ifs[1..]
        .iter()
        .map(|(kw, p)| {
            assert_eq!(kw, "interface");
            assert!(get(p, "display").is_some_and(|d| !d.is_empty()));
            get(p, "value").expect("value")
        })
        .collect();
    assert_eq!(names[0], "aptscope");
    assert!(
        names[1..].iter().all(|n| n.starts_with("aptscope-tty")),
        "{names:?}"
    );

    let v = extcap_ok(&["--extcap-version"]);
    assert_eq!(v.len(), 1);
    assert_eq!(v[0], ifs[0]);

    let dlts = extcap_ok(&["--extcap-dlts", "--extcap-interface", "aptscope"]);
    assert_eq!(dlts.len(), 1);
    assert_eq!(dlts[0].0, "dlt");
    assert_eq!(get(&dlts[0].1, "number"), Some("147"));
    assert_eq!(get(&dlts[0].1, "name"), Some("USER0"));

    for iface in ["aptscope", "aptscope-ttyUSB3"] {
        let cfg = extcap_ok(&["--extcap-config", "--extcap-interface", iface]);
        let args: Vec<&Vec<(String, String)>> = cfg
            .iter()
            .filter(|(k, _)| k == "arg")
            .map(|(_, p)| p)
            .collect();
        let calls: Vec<&str> = args.iter().map(|p| get(p, "call").expect("call")).collect();
        assert_eq!(
            calls,
            [
                "--device",
                "--link",
                "--proto",
                "--baud",
                "--flow",
                "--reconnect"
            ]
        );
        for (i, a) in args.iter().enumerate() {
            assert_eq!(get(a, "number"), Some(i.to_string().as_str()));
            let ty = get(a, "type").expect("type");
            let values: Vec<&Vec<(String, String)>> = cfg
                .iter()
                .filter(|(k, p)| k == "value" && get(p, "arg") == Some(&i.to_string()))
                .map(|(_, p)| p)
                .collect();
            if ty == "selector" {
                let defaults = values
                    .iter()
                    .filter(|v| get(v, "default") == Some("true"))
                    .count();
                assert_eq!(defaults, 1, "{:?}", get(a, "call"));
            } else {
                assert!(values.is_empty());
            }
        }
        let device = get(args[0], "default");
        let want = if iface == "aptscope" {
            "/dev/ttyUSB0"
        } else {
            "/dev/ttyUSB3"
        };
        assert_eq!(device, Some(want));
        // Every value belongs to an argument.
        for (k, p) in &cfg {
            assert!(
                k == "arg" || (k == "value" && get(p, "arg").is_some()),
                "{k} {p:?}"
            );
        }
    }

    // Wireshark checking a capture filter: an empty one is valid, any other is not.
    assert!(aptscope(&[
        "extcap",
        "--extcap-interface",
        "aptscope",
        "--extcap-capture-filter",
        ""
    ])
    .status
    .success());
    let o = aptscope(&[
        "extcap",
        "--extcap-interface",
        "aptscope",
        "--extcap-capture-filter",
        "port 80",
    ]);
    assert!(!o.status.success() && text(&o.stderr).contains("display filter"));
    // Mistakes say what is wrong.
    let o = aptscope(&["extcap", "--extcap-config", "--extcap-interface", "eth0"]);
    assert!(!o.status.success() && text(&o.stderr).contains("unknown interface eth0"));
    let o = aptscope(&["extcap"]);
    assert!(!o.status.success() && text(&o.stderr).contains("--extcap-interfaces"));
    let o = aptscope(&["extcap", "--capture", "--extcap-interface", "aptscope"]);
    assert!(!o.status.success() && text(&o.stderr).contains("--fifo"));
}

/// A personal Wireshark configuration whose extcap folder holds the symlink the README says
/// to make; tshark finds it through `XDG_CONFIG_HOME` (Wireshark 4.0:
/// `$XDG_CONFIG_HOME/wireshark/extcap`, else `~/.config/wireshark/extcap`).
fn personal_extcap(dir: &Scratch) -> PathBuf {
    let cfg = dir.join("config");
    let ext = cfg.join("wireshark").join("extcap");
    std::fs::create_dir_all(&ext).expect("extcap dir");
    std::os::unix::fs::symlink(BIN, ext.join("aptscope-extcap")).expect("symlink");
    cfg
}

fn tshark(cfg: &Path) -> Command {
    let mut c = Command::new("tshark");
    c.env("XDG_CONFIG_HOME", cfg);
    c
}

#[test]
fn the_symlink_answers_as_an_extcap_and_tshark_lists_the_interface() {
    if !require("tshark", "--version", "tshark") {
        return;
    }
    let dir = Scratch::new("list");
    let cfg = personal_extcap(&dir);
    let link = cfg.join("wireshark/extcap/aptscope-extcap");
    let o = run(Command::new(&link).args(["--extcap-interfaces", "--extcap-version=4.0"]));
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(text(&o.stdout).contains("interface {value=aptscope}{"));

    let o = run(tshark(&cfg).arg("-D"));
    let out = text(&o.stdout);
    assert!(o.status.success(), "tshark -D: {}", text(&o.stderr));
    assert_eq!(
        out.lines()
            .filter(|l| l.contains(". aptscope (Thorlabs APT and Elliptec serial tap"))
            .count(),
        1,
        "{out}"
    );
    // Its options are tshark preferences (`-o extcap.aptscope.device:…`).
    let o = run(tshark(&cfg).args(["-G", "currentprefs"]));
    let prefs = text(&o.stdout);
    for p in [
        "device: /dev/ttyUSB0",
        "link: /tmp/ttyAPT",
        "proto",
        "baud",
        "flow",
    ] {
        assert!(prefs.contains(&format!("#extcap.aptscope.{p}")), "{p}");
    }
}

#[test]
fn tshark_captures_a_simulator_through_the_extcap_and_decodes_it_live() {
    if !require("tshark", "--version", "tshark") {
        return;
    }
    let dir = Scratch::new("tshark");
    let cfg = personal_extcap(&dir);
    let (dev, host, out, lua) = (
        dir.join("dev"),
        dir.join("host"),
        dir.join("out.pcapng"),
        dir.join("aptscope.lua"),
    );
    let o = aptscope(&["export", "wireshark-lua", "-o", s(&lua)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let mut sim = start_sim(&dev);

    // Written to the file and printed (-P, line-buffered -l) with the Lua dissector's names.
    let mut c = tshark(&cfg);
    c.args(["-i", "aptscope", "-o"])
        .arg(format!("extcap.aptscope.device:{}", dev.display()))
        .arg("-o")
        .arg(format!("extcap.aptscope.link:{}", host.display()))
        .args(["-w", s(&out), "-P", "-l", "-X"])
        .arg(format!("lua_script:{}", lua.display()))
        .args(["-T", "fields", "-e", "apt.name"]);
    let mut ts = Proc::spawn(c, "tshark");
    ask_info(&host, || ts.both());
    wait_for(
        "the decoded frames from tshark",
        || ts.both(),
        || ts.stdout().contains("HW_GET_INFO"),
    );
    // Stopping tshark stops the extcap cleanly: the tap removes its link on the way out.
    ts.signal(Signal::SIGINT);
    let st = ts.wait_exit();
    assert!(st.success(), "{}", ts.both());
    let lines: Vec<String> = ts.stdout().lines().map(str::to_string).collect();
    assert_eq!(lines, ["HW_REQ_INFO", "HW_GET_INFO"], "{}", ts.both());
    assert!(!ts.stderr().contains("Error by extcap"), "{}", ts.both());
    wait_for(
        "the extcap to remove its link",
        || ts.both(),
        || std::fs::symlink_metadata(&host).is_err(),
    );
    assert_eq!(decoded_names(&out), ["HW_REQ_INFO", "HW_GET_INFO"]);
    // The simulator served the session and is still up for the next one.
    assert!(sim.running(), "{}", sim.both());
}

#[test]
fn a_tshark_duration_ends_the_capture_and_the_extcap_with_it() {
    if !require("tshark", "--version", "tshark") {
        return;
    }
    let dir = Scratch::new("duration");
    let cfg = personal_extcap(&dir);
    let (dev, host, out) = (dir.join("dev"), dir.join("host"), dir.join("out.pcapng"));
    let _sim = start_sim(&dev);
    let mut c = tshark(&cfg);
    c.args(["-i", "aptscope", "-o"])
        .arg(format!("extcap.aptscope.device:{}", dev.display()))
        .arg("-o")
        .arg(format!("extcap.aptscope.link:{}", host.display()))
        .args(["-a", "duration:2", "-w", s(&out)]);
    let mut ts = Proc::spawn(c, "tshark");
    // The tap ran (its link appeared), and went away by itself with tshark's end.
    wait_for(
        "the extcap's host link",
        || ts.both(),
        || std::fs::read_link(&host).is_ok(),
    );
    assert!(ts.wait_exit().success(), "{}", ts.both());
    assert!(!ts.stderr().contains("Error by extcap"), "{}", ts.both());
    wait_for(
        "the extcap to remove its link",
        || ts.both(),
        || std::fs::symlink_metadata(&host).is_err(),
    );
    assert!(decoded_names(&out).is_empty());
}

#[test]
fn a_device_that_cannot_be_opened_is_what_wireshark_shows() {
    if !require("tshark", "--version", "tshark") {
        return;
    }
    let dir = Scratch::new("nodev");
    let cfg = personal_extcap(&dir);
    let missing = dir.join("no-such-port");
    let o = run(tshark(&cfg)
        .args(["-i", "aptscope", "-o"])
        .arg(format!("extcap.aptscope.device:{}", missing.display()))
        .arg("-o")
        .arg(format!(
            "extcap.aptscope.link:{}",
            dir.join("host").display()
        ))
        .args(["-a", "duration:30", "-w", s(&dir.join("out.pcapng"))]));
    let err = text(&o.stderr);
    assert!(
        err.contains(&format!("{}: No such file", missing.display())),
        "{err}"
    );
}

/// A capture as Wireshark runs it: a simulator on DIR/dev, `aptscope extcap --capture
/// --extcap-interface aptscope --fifo DIR/fifo --device DIR/dev --link DIR/host EXTRA…`, and
/// the FIFO opened for reading without waiting for the writer. Returns the simulator, the
/// extcap and the FIFO.
fn fifo_capture(dir: &Scratch, extra: &[&str]) -> (Proc, Proc, File) {
    let (dev, host, fifo) = (dir.join("dev"), dir.join("host"), dir.join("fifo"));
    nix::unistd::mkfifo(&fifo, Mode::S_IRUSR | Mode::S_IWUSR).expect("mkfifo");
    let sim = start_sim(&dev);
    let mut c = Command::new(BIN);
    c.args(["extcap", "--capture", "--extcap-interface", "aptscope"])
        .args(["--fifo", s(&fifo), "--device", s(&dev), "--link", s(&host)])
        .args(extra);
    let ext = Proc::spawn(c, "aptscope extcap");
    let r = File::options()
        .read(true)
        .custom_flags(OFlag::O_NONBLOCK.bits())
        .open(&fifo)
        .expect("open fifo");
    (sim, ext, r)
}

/// The extcap ended cleanly: success, nothing on stderr (Wireshark would show it as an error),
/// its host link removed.
fn assert_clean_end(ext: &mut Proc, host: &Path) {
    assert!(ext.wait_exit().success(), "{}", ext.both());
    assert_eq!(ext.stderr(), "");
    assert!(std::fs::symlink_metadata(host).is_err(), "link left behind");
}

#[test]
fn the_extcap_ends_cleanly_when_the_fifo_reader_goes_away() {
    let dir = Scratch::new("fifo");
    let host = dir.join("host");
    let extra = ["--proto", "apt", "--baud", "auto", "--flow", "auto"];
    let (_sim, mut ext, mut r) = fifo_capture(&dir, &extra);
    // Read as Wireshark would.
    let mut got = vec![];
    let mut buf = [0u8; 4096];
    let mut pump = |got: &mut Vec<u8>| {
        if ready(&r, PollFlags::POLLIN) {
            match r.read(&mut buf) {
                Ok(n) => got.extend_from_slice(&buf[..n]),
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                Err(e) => panic!("fifo read: {e}"),
            }
        }
    };
    let reply = ask_info(&host, || ext.both());
    let has = |hay: &[u8], needle: &[u8]| hay.windows(needle.len()).any(|w| w == needle);
    wait_for(
        "both packets in the FIFO",
        || ext.both(),
        || {
            pump(&mut got);
            has(&got, &HW_REQ_INFO) && has(&got, &reply)
        },
    );
    // pcapng: a section header block first, flushed live.
    assert_eq!(got[..4], [0x0a, 0x0d, 0x0d, 0x0a]);
    drop(r);
    assert_clean_end(&mut ext, &host);
    // What went through the FIFO is a capture aptscope reads.
    let cap = dir.join("got.pcapng");
    std::fs::write(&cap, &got).expect("write");
    assert_eq!(decoded_names(&cap), ["HW_REQ_INFO", "HW_GET_INFO"]);
}

#[test]
fn sigterm_ends_the_capture_cleanly() {
    let dir = Scratch::new("sigterm");
    let host = dir.join("host");
    let (_sim, mut ext, _r) = fifo_capture(&dir, &[]);
    wait_for(
        "the extcap's host link",
        || ext.both(),
        || std::fs::read_link(&host).is_ok(),
    );
    ext.signal(Signal::SIGTERM);
    assert_clean_end(&mut ext, &host);
}
