//! End to end, what a first-time user trips over: messages that say only what is true for this
//! input, and errors that say what is wrong (the path, the reason, what to do instead).

mod common;

use common::scratch;
use std::path::Path;
use std::process::{Command, Output, Stdio};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// Run the binary in `dir` (the repository when `None`); stdin is empty.
fn run_in(dir: Option<&Path>, args: &[&str]) -> (String, String, bool) {
    let o: Output = Command::new(env!("CARGO_BIN_EXE_aptscope"))
        .args(args)
        .current_dir(dir.unwrap_or(Path::new(ROOT)))
        .stdin(Stdio::null())
        .output()
        .expect("run aptscope");
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
        o.status.success(),
    )
}

fn run(args: &[&str]) -> (String, String, bool) {
    run_in(None, args)
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

#[test]
fn convert_says_only_what_this_input_loses() {
    let dir = scratch("convert");
    let conv = |input: &str, out: &str| {
        let out = dir.join(out);
        let (_, err, ok) = run(&["convert", input, s(&out)]);
        assert!(ok, "{err}");
        err
    };
    // Every chunk has a time, one stream: pcapng loses nothing; pcap loses the stream's name
    // and settings (and says which), nothing about 255 streams.
    let err = conv("samples/kdc101-session.pcapng", "a.pcapng");
    assert!(!err.contains("cannot carry"), "{err}");
    let err = conv("samples/kdc101-session.socat.log", "b.pcapng");
    assert!(!err.contains("cannot carry"), "{err}");
    let err = conv("samples/kdc101-session.usbmon.pcap", "c.pcapng");
    assert!(!err.contains("cannot carry"), "{err}");
    let err = conv("samples/kdc101-session.pcapng", "d.pcap");
    assert!(
        err.contains("pcap cannot carry: stream names and line settings")
            && err.contains("/dev/ttyUSB0, 115200 8N1 RTS/CTS"),
        "{err}"
    );
    assert!(!err.contains("255") && !err.contains("time"), "{err}");
    // A pcap with no stream names converts back to pcap losing nothing.
    let d = dir.join("d.pcap");
    let err = conv(s(&d), "e.pcap");
    assert!(!err.contains("cannot carry"), "{err}");
    // Raw bytes have no time: pcapng says it writes time 0, and how many chunks.
    let err = conv("samples/kdc101-session.bin", "f.pcapng");
    assert!(
        err.contains("pcapng cannot carry: missing times: 1 chunk(s) without a timestamp"),
        "{err}"
    );
    // Raw to hex loses nothing; pcapng to hex loses times and directions, not streams.
    let err = conv("samples/kdc101-session.bin", "g.hex");
    assert!(!err.contains("cannot carry"), "{err}");
    let err = conv("samples/kdc101-session.pcapng", "h.hex");
    assert!(
        err.contains("hex cannot carry: times (20 chunk(s) had one)")
            && err.contains("hex cannot carry: directions"),
        "{err}"
    );
    assert!(!err.contains("streams"), "{err}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn convert_to_dash_writes_standard_output() {
    let dir = scratch("stdout");
    let sample = format!("{ROOT}/samples/kdc101-session.pcapng");
    let (out, err, ok) = run_in(Some(&dir), &["convert", &sample, "-", "--to", "hex"]);
    assert!(ok, "{err}");
    assert!(!dir.join("-").exists(), "a file named - was written");
    let hex =
        std::fs::read_to_string(format!("{ROOT}/samples/kdc101-session.hex")).expect("hex sample");
    let digits = |t: &str| -> String {
        t.chars()
            .filter(char::is_ascii_hexdigit)
            .collect::<String>()
            .to_lowercase()
    };
    assert_eq!(digits(&out), digits(&hex));
    // Without --to there is no extension to go by.
    let (_, err, ok) = run_in(Some(&dir), &["convert", &sample, "-"]);
    assert!(!ok && err.contains("--to"), "{err}");
    // MCAP needs a file.
    let (_, err, ok) = run_in(Some(&dir), &["convert", &sample, "-", "--to", "mcap"]);
    assert!(!ok && err.contains("MCAP is written to a file"), "{err}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_directory_as_input_is_named() {
    let (_, err, ok) = run(&["decode", "samples"]);
    assert!(!ok);
    assert!(err.contains("samples is a directory"), "{err}");
    let (_, err, ok) = run(&["info", "samples/sessions"]);
    assert!(
        !ok && err.contains("samples/sessions is a directory"),
        "{err}"
    );
}

#[test]
fn tap_on_something_that_is_no_serial_port_says_so() {
    let dir = scratch("tap");
    let file = dir.join("notaport");
    std::fs::write(&file, b"").expect("file");
    for (dev, what) in [
        (s(&file), "is a regular file, not a serial port"),
        (s(&dir), "is a directory, not a serial port"),
        ("/dev/null", "is not a terminal, so not a serial port"),
    ] {
        let (_, err, ok) = run(&["tap", "--device", dev, "--duration", "1s"]);
        assert!(!ok, "{dev}");
        assert!(err.contains(&format!("{dev} {what}")), "{dev}: {err}");
        assert!(!err.contains("typewriter"), "{err}");
    }
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn tap_refuses_a_capture_name_of_another_format() {
    let dir = scratch("tapw");
    let txt = dir.join("t.txt");
    // Refused before any port is opened (the device does not exist), and nothing is created.
    let (_, err, ok) = run(&["tap", "--device", "/nonexistent", "-w", s(&txt)]);
    assert!(!ok);
    assert!(
        err.contains("t.txt: .txt names no capture format") && err.contains("--write-format"),
        "{err}"
    );
    assert!(!txt.exists());
    // --write-format forces it: the name passes, the missing device is the error.
    let (_, err, ok) = run(&[
        "tap",
        "--device",
        "/nonexistent",
        "-w",
        s(&txt),
        "--write-format",
        "pcapng",
    ]);
    assert!(
        !ok && err.contains("/nonexistent") && !err.contains(".txt"),
        "{err}"
    );
    let (_, err, ok) = run(&[
        "tap",
        "--device",
        "/nonexistent",
        "-w",
        s(&dir.join("t.mcap")),
    ]);
    assert!(
        !ok && err.contains("the tap writes pcapng or pcap"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn a_usb_device_that_is_not_in_the_capture_is_an_error_listing_those_that_are() {
    let (out, err, ok) = run(&[
        "decode",
        "--usb-device",
        "9:9",
        "samples/kdc101-session.usbmon.pcap",
    ]);
    assert!(!ok, "{out}");
    assert!(
        err.contains("usb 9:9 is not in the capture; devices present: 1:7 (0403:faf0, FTDI)"),
        "{err}"
    );
    for cmd in ["info", "stats", "convert"] {
        let mut args = vec![
            cmd,
            "--usb-device",
            "9:9",
            "samples/kdc101-session.usbmon.pcap",
        ];
        if cmd == "convert" {
            args.extend(["-", "--to", "hex"]);
        }
        let (_, err, ok) = run(&args);
        assert!(!ok && err.contains("devices present: 1:7"), "{cmd}: {err}");
    }
    // The right one decodes.
    let (out, err, ok) = run(&[
        "decode",
        "--usb-device",
        "1:7",
        "samples/kdc101-session.usbmon.pcap",
    ]);
    assert!(ok && out.contains("HW_GET_INFO"), "{err}");
    // Not a USB capture.
    let (_, err, ok) = run(&[
        "stats",
        "--usb-device",
        "1:7",
        "samples/kdc101-session.pcapng",
    ]);
    assert!(
        !ok && err.contains("no USB bulk or control transfers"),
        "{err}"
    );
    let (_, err, ok) = run(&[
        "decode",
        "--usb-device",
        "1:7",
        "samples/kdc101-session.hex",
    ]);
    assert!(!ok && err.contains("this input is hex"), "{err}");
}

#[test]
fn a_forced_container_format_that_the_file_is_not_is_refused() {
    for (file, forced, is) in [
        ("samples/kdc101-session.pcapng", "pcap", "pcapng"),
        ("samples/kdc101-session.pcap", "pcapng", "pcap"),
        ("samples/kdc101-session.mcap", "pcapng", "mcap"),
    ] {
        for flag in ["-F", "--format"] {
            let (_, err, ok) = run(&["decode", flag, forced, file]);
            assert!(!ok, "{file} {forced}");
            assert!(
                err.contains(&format!("--format {forced} but the content is {is}")),
                "{err}"
            );
        }
    }
    let (out, err, ok) = run(&["decode", "-F", "pcapng", "samples/kdc101-session.pcapng"]);
    assert!(ok && out.contains("HW_GET_INFO"), "{err}");
}

/// `aptscope decode` with no file and a terminal as standard input would wait for typing: it
/// says what it needs instead. (Ctrl-D is typed beforehand, so a binary that read the terminal
/// would get end of file and succeed with no output rather than hang the test.)
#[test]
fn decode_without_a_file_in_a_terminal_says_what_it_needs() {
    let pty = nix::pty::openpty(None, None).expect("pseudo-terminal");
    // A reader may read more than once after an end of file: one Ctrl-D for each.
    nix::unistd::write(&pty.master, &[0x04; 16]).expect("type Ctrl-D");
    let o = Command::new(env!("CARGO_BIN_EXE_aptscope"))
        .arg("decode")
        .stdin(Stdio::from(pty.slave))
        .output()
        .expect("run aptscope");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("no capture given") && err.contains("`-` reads standard input"),
        "{err}"
    );
    // Piped input is read without `-`.
    let hex = std::fs::read(format!("{ROOT}/samples/kdc101-session.bin")).expect("sample");
    let mut c = Command::new(env!("CARGO_BIN_EXE_aptscope"))
        .arg("decode")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("run aptscope");
    std::io::Write::write_all(&mut c.stdin.take().expect("stdin"), &hex).expect("write");
    let o = c.wait_with_output().expect("wait");
    assert!(String::from_utf8_lossy(&o.stdout).contains("HW_GET_INFO"));
}

#[test]
fn stats_refuses_an_empty_bin_and_shows_empty_bins() {
    let (_, err, ok) = run(&["stats", "--bin", "0", "samples/kdc101-session.pcapng"]);
    assert!(!ok && err.contains("above zero"), "{err}");
    let (out, err, ok) = run(&["stats", "--bin", "100ms", "samples/kdc101-session.pcapng"]);
    assert!(ok, "{err}");
    let rate: Vec<&str> = out
        .lines()
        .skip_while(|l| !l.starts_with("Rate (frames per 0.1 s)"))
        .skip(1)
        .collect();
    // 0 to 2.8 s: every bin is there, the pause between 0.7 and 2.1 s as zeros.
    assert_eq!(rate.len(), 29, "{out}");
    assert_eq!(rate[10].trim(), "1.000 s      0", "{out}");
}

/// Forcing Elliptec on an APT capture: the bytes that frame nothing are shown as hex and
/// printable ASCII, at the time their first byte came (not at the end of the capture).
#[test]
fn garbage_is_hex_at_the_time_of_its_first_byte() {
    let (out, err, ok) = run(&[
        "decode",
        "--proto",
        "elliptec",
        "samples/kdc101-session.pcapng",
    ]);
    assert!(ok, "{err}");
    assert!(!out.contains("\\u{"), "{out}");
    let first = out
        .lines()
        .find(|l| l.contains("start no frame"))
        .expect("a garbage line");
    assert!(
        first.contains(
            "     1    0.000000        0x0  !! 48 byte(s) that start no frame: 05 00 00 00 50 01 10 02"
        ) && first.ends_with(" …  |....P.....P.....P.....P.|"),
        "{first}"
    );
    let (out, _, _) = run(&[
        "decode",
        "--json",
        "--proto",
        "elliptec",
        "samples/kdc101-session.pcapng",
    ]);
    let (chunks, _, _) = run(&["decode", "--json", "samples/kdc101-session.pcapng"]);
    let ts =
        |l: &str| serde_json::from_str::<serde_json::Value>(l).expect("JSON")["ts_ns"].as_u64();
    let garbage = out
        .lines()
        .find(|l| l.contains("\"garbage\""))
        .expect("garbage record");
    let first_frame = chunks
        .lines()
        .find(|l| l.contains("\"frame\""))
        .expect("a frame");
    assert_eq!(ts(garbage), ts(first_frame), "{garbage}");
}

/// Inputs that are not what they seem: random bytes and an image are refused by `decode` and
/// `stats` with the reason on stderr (no page of garbage records, no success); a forced
/// protocol that detection reads otherwise is decoded, with a note saying so.
#[test]
fn inputs_that_are_not_captures_are_refused_with_the_reason() {
    let dir = scratch("not-captures");
    let rand = dir.join("rand.bin");
    let bytes = common::noise(6000, 12345);
    std::fs::write(&rand, &bytes).expect("write");
    let jpg = dir.join("pic.jpg");
    let mut img = vec![
        0xFF, 0xD8, 0xFF, 0xE0, 0x00, 0x10, b'J', b'F', b'I', b'F', 0x00,
    ];
    img.extend(bytes.iter().rev());
    std::fs::write(&jpg, &img).expect("write");
    for f in [&rand, &jpg] {
        for cmd in ["decode", "stats"] {
            let (out, err, ok) = run(&[cmd, s(f)]);
            assert!(!ok, "{cmd} {}: succeeded\n{out}", f.display());
            assert!(err.contains("not a capture"), "{cmd}: {err}");
            if cmd == "decode" {
                assert!(out.is_empty(), "no garbage records: {out}");
            }
        }
    }
    // Forced: decoded anyway (the user said so).
    let (out, _, ok) = run(&["decode", "--proto", "apt", s(&rand)]);
    assert!(ok && out.lines().count() > 10, "{out}");

    let (out, err, ok) = run(&[
        "decode",
        "--proto",
        "elliptec",
        "samples/kdc101-session.pcapng",
    ]);
    assert!(ok, "{err}");
    assert!(!out.is_empty());
    assert!(
        err.contains("detection reads this input as apt (100%")
            && err.contains("the forced protocol, elliptec, frames 0%"),
        "{err}"
    );
}

/// A capture of another link type (Ethernet) has no serial traffic: `stats` says what
/// `decode` says (the file's problem, in text and JSON) and both fail; a capture cut in half
/// has its `truncated_record` in `stats` too (and, having frames, succeeds).
#[test]
fn stats_reports_the_problems_of_the_file() {
    let eth = "tests/bad-input/unknown-linktype.pcap";
    let (out, err, ok) = run(&["stats", eth]);
    assert!(!ok, "{out}");
    assert!(
        out.contains("File problems") && out.contains("unknown_linktype"),
        "{out}"
    );
    assert!(err.contains("no serial traffic"), "{err}");
    let (out, _, ok) = run(&["stats", "--json", eth]);
    assert!(!ok);
    let v: serde_json::Value = serde_json::from_str(out.trim()).expect("JSON");
    assert_eq!(v["file_problems"]["unknown_linktype"], 1, "{v}");
    assert_eq!(v["file_examples"][0]["offset"], 24, "{v}");
    let (out, err, ok) = run(&["decode", eth]);
    assert!(!ok && err.contains("no serial traffic"), "{out}{err}");

    let cut = "tests/bad-input/truncated-block.pcapng";
    let (out, err, ok) = run(&["stats", "--json", cut]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).expect("JSON");
    assert_eq!(v["file_problems"]["truncated_record"], 1, "{v}");
}

/// A container format forced on bytes that are not one is refused like one container forced
/// on another (both used to differ: a `bad_magic` line and success for raw bytes).
#[test]
fn a_forced_container_on_raw_bytes_is_refused() {
    for f in ["pcapng", "pcap", "mcap"] {
        let (out, err, ok) = run(&["decode", "--format", f, "samples/kdc101-session.bin"]);
        assert!(!ok, "{out}");
        assert!(
            err.contains(&format!("--format {f} but the content is raw")),
            "{err}"
        );
    }
}

/// `view` without a terminal says it needs one and names `decode` (it used to fail with
/// "No such device or address (os error 6)").
#[test]
fn view_without_a_terminal_names_decode() {
    let (out, err, ok) = run(&["view", "samples/kdc101-session.bin"]);
    assert!(!ok, "{out}");
    assert!(
        err.contains("needs a terminal") && err.contains("aptscope decode"),
        "{err}"
    );
}
