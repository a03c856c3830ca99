//! Elliptec: every example of the ELLx manual (`ell_examples.txt`), framing in any chunking,
//! bus state across address changes, pairing, and bad input.

mod common;

use aptscope_dissector::ell::{Bus, EllFrame, EllFramer, EllValue, Item as EllItem};
use aptscope_dissector::DiagKind;
use common::{frames_and_garbage, run_ell, Item};

struct Example {
    line: String,
    dir: String,
    bytes: String,
    expected: Vec<(String, String)>,
    typo: Option<String>,
}

fn examples() -> Vec<Example> {
    let mut v = vec![];
    for l in include_str!("ell_examples.txt")
        .lines()
        .filter(|l| l.starts_with('L'))
    {
        let (head, rest) = l.split_once('`').expect("opening backquote");
        let (bytes, tail) = rest.split_once('`').expect("closing backquote");
        let mut h = head.split_whitespace();
        let (line, dir) = (
            h.next().expect("line").to_string(),
            h.next().expect("dir").to_string(),
        );
        let tail = tail.trim().strip_prefix("=>").expect("=>");
        // `typo:` the printed bytes are wrong; `text-typo:` only the manual's text is (the bytes
        // decode exactly as meant).
        let (exp, typo) = match (tail.split_once("; typo:"), tail.split_once("; text-typo:")) {
            (Some((e, t)), _) => (e, Some(t.trim().to_string())),
            (None, Some((e, _))) => (e, None),
            (None, None) => (tail, None),
        };
        let expected = exp
            .split_whitespace()
            .map(|kv| {
                let (k, v) = kv.split_once('=').expect("key=value");
                (k.to_string(), v.to_string())
            })
            .collect();
        v.push(Example {
            line,
            dir,
            bytes: bytes.to_string(),
            expected,
            typo,
        });
    }
    v
}

/// Frame `input`: (frames, garbage bytes).
fn frames(input: &[u8]) -> (Vec<(u64, Vec<u8>, bool)>, usize) {
    frames_and_garbage(&run_ell(input, &[]))
}

fn value_str(v: &EllValue<'_>) -> String {
    match v {
        EllValue::U(x) => x.to_string(),
        EllValue::I(x) => x.to_string(),
        EllValue::Char(c) => c.to_string(),
        EllValue::Digits(d) => d.to_string(),
        EllValue::Raw(b) => format!("{} bytes", b.len()),
    }
}

fn normalise(k: &str, v: &str) -> String {
    if k == "addr" || k == "cmd" || k == "new_address" {
        return v.to_string();
    }
    if let Some(h) = v.strip_prefix("0x") {
        return u64::from_str_radix(h, 16)
            .map(|x| x.to_string())
            .unwrap_or(v.to_string());
    }
    v.trim_start_matches('0')
        .to_string()
        .chars()
        .next()
        .map_or("0".to_string(), |_| v.trim_start_matches('0').to_string())
}

/// What the decoder makes of an example: `addr=.. cmd=.. field=..` and the diagnostics.
fn decoded(bytes: &[u8]) -> (Vec<(String, String)>, Vec<String>, usize, usize) {
    let (fs, garbage) = frames(bytes);
    let mut vals = vec![];
    let mut diags = vec![];
    if let Some((off, b, tr)) = fs.first() {
        let f = EllFrame::decode(*off, b, *tr).expect("decodes");
        vals.push(("addr".to_string(), f.addr_char().to_string()));
        vals.push(("cmd".to_string(), f.code_str().to_string()));
        for (fd, v) in f.fields() {
            vals.push((fd.name.to_string(), value_str(&v)));
        }
        diags.extend(
            f.diags()
                .iter()
                .map(|d| format!("{}@{}", d.kind.name(), d.offset)),
        );
    }
    (vals, diags, fs.len(), garbage)
}

#[test]
fn every_manual_example_decodes_as_the_manual_means_or_its_typo_is_reported() {
    let all = examples();
    assert!(all.len() >= 50, "{} examples", all.len());
    let mut report = String::new();
    let mut failures = vec![];
    for ex in &all {
        // The manual prints replies without their CR LF terminator; the wire has it.
        let mut bytes = ex.bytes.clone().into_bytes();
        if ex.dir == "RX" {
            bytes.extend_from_slice(b"\r\n");
        }
        let (vals, diags, nframes, garbage) = decoded(&bytes);
        let want: Vec<(String, String)> = ex
            .expected
            .iter()
            .map(|(k, v)| (k.clone(), normalise(k, v)))
            .collect();
        let got: Vec<(String, String)> = vals
            .iter()
            .map(|(k, v)| (k.clone(), normalise(k, v)))
            .collect();
        let exact = got == want && nframes == 1 && garbage == 0;
        let got_s: Vec<String> = vals.iter().map(|(k, v)| format!("{k}={v}")).collect();
        report.push_str(&format!(
            "{} {} {:?} -> {} [{}]{}\n",
            ex.line,
            ex.dir,
            ex.bytes,
            got_s.join(" "),
            diags.join(" "),
            if garbage > 0 {
                format!(" +{garbage} garbage bytes")
            } else {
                String::new()
            }
        ));
        match &ex.typo {
            None if !(exact && diags.is_empty()) => failures.push(format!(
                "{} {:?}: got {got:?} diags {diags:?}, want {want:?}",
                ex.line, ex.bytes
            )),
            // A typo must be visible: reported by a diagnostic, or decoded as what is printed
            // rather than what the manual means.
            Some(t) if exact && diags.is_empty() => failures.push(format!(
                "{} {:?}: typo ({t}) not visible",
                ex.line, ex.bytes
            )),
            _ => {}
        }
    }
    assert!(
        failures.is_empty(),
        "{}\n\nreport:\n{report}",
        failures.join("\n")
    );
    // What the lenient decoder reports for every example, typos included, is recorded in a
    // golden file: a change in behaviour shows up as a diff here.
    let golden = include_str!("ell_examples.golden");
    if golden != report {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/ell_examples.golden.new");
        let _ = std::fs::write(path, &report);
        panic!("lenient-decoder report differs from tests/ell_examples.golden (new report written to {path})");
    }
}

#[test]
fn typos_the_lenient_decoder_recovers_from() {
    // Spaces or commas between fields: the values are read, the separators reported.
    let (vals, diags, _, _) = decoded(b"0 ca A");
    assert_eq!(
        vals,
        [
            ("addr".into(), "0".into()),
            ("cmd".into(), "ca".into()),
            ("new_address".into(), "A".into())
        ]
    );
    assert_eq!(diags, ["separators@1"]);
    // Letter O as the address.
    let (vals, diags, _, _) = decoded(b"OBS00\r\n");
    assert_eq!(vals[0], ("addr".into(), "0".into()));
    assert_eq!(diags, ["letter_o@0"]);
    // An extra digit: the data length is reported.
    let (_, diags, _, _) = decoded(b"0I2100428FFFFFFFFF00BD008B\r\n");
    assert_eq!(diags, ["data_length@3"]);
}

fn run_bus(input: &[u8]) -> Vec<(String, Option<u64>, bool, Option<String>)> {
    let mut bus = Bus::new();
    let mut n = 0;
    let mut out = vec![];
    for it in run_ell(input, &[]) {
        n += 1;
        if let Item::Frame(offset, bytes, truncated) = it {
            let fr = EllFrame::decode(offset, &bytes, truncated).expect("frame");
            let o = bus.observe(n, &fr, None);
            let phys = fr
                .fields()
                .find(|(fd, _)| fd.name == "position")
                .and_then(
                    |(_, v)| match (v, o.module.as_ref().and_then(|m| m.scale())) {
                        (EllValue::I(p), Some((ppu, unit))) => {
                            Some(format!("{:.3} {unit}", p as f64 / ppu))
                        }
                        _ => None,
                    },
                );
            out.push((
                format!("{}{}", fr.addr_char(), fr.code_str()),
                o.pair,
                o.unsolicited,
                phys,
            ));
        }
    }
    out
}

#[test]
fn positions_convert_with_the_module_type_and_follow_address_changes() {
    // An ELL14 rotation mount (IN: model 0E, serial 11400284, 2020, fw 0.1, metric hw 23,
    // 360 degrees, 0x23000 = 143360 pulses per revolution) at 0 moves to address 3.
    let s = b"0in0IN0E1140028420200117016800023000\r\n0ma00008C00\r\n0PO00008C00\r\n0ca3\r\n3GS00\r\n3gp\r\n3PO00004600\r\n";
    let r = run_bus(s);
    let codes: Vec<&str> = r.iter().map(|x| x.0.as_str()).collect();
    assert_eq!(
        codes,
        ["0in", "0IN", "0ma", "0PO", "0ca", "3GS", "3gp", "3PO"]
    );
    assert_eq!(r[1].1, Some(1), "IN answers in");
    assert_eq!(r[3].1, Some(3), "PO answers ma");
    assert_eq!(r[5].1, Some(5), "GS from the new address answers ca");
    assert_eq!(r[7].1, Some(7), "PO from address 3 answers gp");
    assert!(r.iter().all(|x| !x.2), "nothing unsolicited");
    // 0x8C00 = 35840 pulses = 90 degrees at 143360 pulses per 360 degrees.
    assert_eq!(r[3].3.as_deref(), Some("90.000 deg"));
    // After `ca`, the module (and its scale) answers at address 3.
    assert_eq!(r[7].3.as_deref(), Some("45.000 deg"));
}

#[test]
fn unanswered_and_unsolicited_are_flagged() {
    let mut bus = Bus::new();
    let mut n = 0;
    let mut unsolicited = vec![];
    for it in run_ell(b"0gs1GS00\r\n2gp", &[]) {
        n += 1;
        if let Item::Frame(offset, bytes, truncated) = it {
            let fr = EllFrame::decode(offset, &bytes, truncated).expect("frame");
            if bus.observe(n, &fr, None).unsolicited {
                unsolicited.push(n);
            }
        }
    }
    assert_eq!(
        unsolicited,
        [2],
        "GS from address 1 answers nothing sent to 1"
    );
    let left: Vec<(u64, &str)> = bus.finish().iter().map(|e| (e.n, e.code)).collect();
    assert_eq!(left, [(1, "gs"), (3, "gp")]);
}

#[test]
fn timeouts_use_timestamps() {
    let mut bus = Bus::new();
    let cmd = EllFrame::decode(0, b"0gs", false).expect("frame");
    assert!(bus.observe(1, &cmd, Some(0)).expired.is_empty());
    let late = EllFrame::decode(3, b"5gv", false).expect("frame");
    let o = bus.observe(2, &late, Some(3_000_000_000));
    assert_eq!(
        o.expired.iter().map(|e| e.n).collect::<Vec<_>>(),
        [1],
        "gs waited more than 2 s"
    );
    let reply = EllFrame::decode(6, b"5GV64\r\n", false).expect("frame");
    let o = bus.observe(3, &reply, Some(3_012_000_000));
    assert_eq!(o.pair, Some(2));
    assert_eq!(o.latency_ns, Some(12_000_000));
}

#[test]
fn any_chunking_gives_the_same_frames() {
    let input: &[u8] = b"0in\r\n0IN0E114002842020011701680000023000\r\n0gs0GS00\r\nAma00002000AGS09\r\nAPO00002000\r\nxx\r\n0 ca A\r\nAGS00\r\n0i1\r\n0I1100428FFFFFFFF00BD008B\r\n";
    let whole = frames(input);
    for cut in 0..input.len() {
        for cut2 in cut..input.len().min(cut + 7) {
            let (got, garbage) = frames_and_garbage(&run_ell(input, &[cut, cut2]));
            assert_eq!((got, garbage), whole, "cuts at {cut}, {cut2}");
        }
    }
    let total: usize = whole.0.iter().map(|f| f.1.len()).sum::<usize>() + whole.1;
    assert_eq!(total, input.len(), "every byte in a frame or garbage");
}

#[test]
fn bad_input() {
    // Non-hex data in a host command: framed by its length, the character reported.
    let f = EllFrame::decode(0, b"0ma0000G000", false).expect("frame");
    assert!(f
        .diags()
        .iter()
        .any(|d| d.kind == DiagKind::BadDataChar { ch: 'G' } && d.offset == 7));
    // A reply without CR LF before the next frame.
    let (fs, garbage) = frames(b"0GS000gs");
    assert_eq!((fs.len(), garbage), (2, 0));
    let f = EllFrame::decode(0, &fs[0].1, false).expect("frame");
    assert!(f
        .diags()
        .iter()
        .any(|d| d.kind == DiagKind::MissingTerminator));
    // A reply cut off by the end of the stream.
    let (fs, _) = frames(b"0PO0000");
    assert!(fs[0].2, "truncated");
    // An unknown command on its own line is framed and reported; random binary is garbage.
    let (fs, _) = frames(b"0zz12\r\n");
    let f = EllFrame::decode(0, &fs[0].1, false).expect("frame");
    assert!(f.diags().iter().any(|d| d.kind == DiagKind::UnknownCommand));
    let (fs, garbage) = frames(&[0xFF, 0x00, 0x13, 0x37, 0x80]);
    assert_eq!((fs.len(), garbage), (0, 5));
    assert_eq!(frames(b""), (vec![], 0));
}

/// Hosts send commands without a terminator: with directions known, a command is framed when
/// the module starts answering, so it comes before its reply and pairs with it.
#[test]
fn an_unterminated_host_command_is_framed_when_the_module_answers() {
    use aptscope_dissector::detect::Proto;
    use aptscope_dissector::pipeline::{Ctx, Format, Pipeline};
    use aptscope_dissector::table::Dir;
    let mut p = Pipeline::new(Some(Proto::Elliptec), Format::Json);
    let mut out: Vec<serde_json::Value> = vec![];
    let mut emit = |l: &str| -> Result<(), ()> {
        out.push(serde_json::from_str(l).unwrap());
        Ok(())
    };
    let ctx = |dir, t| Ctx {
        stream: 0,
        dir: Some(dir),
        ts_ns: Some(t),
    };
    p.push_chunk(ctx(Dir::HostToDevice, 1_000), b"0gp", &mut emit)
        .unwrap();
    p.push_chunk(
        ctx(Dir::DeviceToHost, 5_000_000),
        b"0PO00002000\r\n",
        &mut emit,
    )
    .unwrap();
    // The host's next command arrives in two pieces: the first is not cut by anything.
    p.push_chunk(ctx(Dir::HostToDevice, 9_000_000), b"1g", &mut emit)
        .unwrap();
    p.push_chunk(ctx(Dir::HostToDevice, 9_100_000), b"s", &mut emit)
        .unwrap();
    p.push_chunk(ctx(Dir::DeviceToHost, 12_000_000), b"1GS00\r\n", &mut emit)
        .unwrap();
    p.finish(&mut emit).unwrap();
    let frames: Vec<(String, Option<u64>)> = out
        .iter()
        .filter(|v| v["type"] == "frame")
        .map(|v| (v["text"].as_str().unwrap().to_string(), v["pair"].as_u64()))
        .collect();
    assert_eq!(
        frames,
        [
            ("0gp".to_string(), None),
            ("0PO00002000\r\n".to_string(), Some(1)),
            ("1gs".to_string(), None),
            ("1GS00\r\n".to_string(), Some(3)),
        ]
    );
    assert!(
        out.iter()
            .all(|v| v["diag"].as_array().is_none_or(|d| d.is_empty())),
        "{out:?}"
    );
}

// ------------------------------------------------------------------------------------------
// The command table, listing and encoder.

use aptscope_dissector::ell::encode::{encode, EncodeError};
use aptscope_dissector::ell::table::{lookup, Answer, Class, Kind, COMMANDS};
use aptscope_dissector::table::Dir;

fn cmd(code: &str) -> &'static aptscope_dissector::ell::table::Cmd {
    lookup(code.as_bytes()).unwrap_or_else(|| panic!("{code} in the table"))
}

#[test]
fn the_table_has_one_consistent_row_per_command() {
    for (i, c) in COMMANDS.iter().enumerate() {
        assert_eq!(c.code.len(), 2, "{}", c.code);
        assert!(
            COMMANDS[..i]
                .iter()
                .all(|o| o.code != c.code && o.name != c.name),
            "{} twice",
            c.code
        );
        let host = c.code.as_bytes()[0].is_ascii_lowercase();
        assert_eq!(c.dir == Dir::HostToDevice, host, "{}: direction", c.code);
        assert!(
            !c.doc.is_empty() && c.doc.contains("(p."),
            "{}: doc",
            c.code
        );
        for r in c.replies {
            assert_eq!(cmd(r).dir, Dir::DeviceToHost, "{} → {r}", c.code);
        }
        if host {
            assert!(
                !matches!(c.class, Class::Reply | Class::Spontaneous),
                "{}",
                c.code
            );
            // A timeout exactly when a reply is expected.
            assert_eq!(c.replies.is_empty(), c.timeout_ms == 0, "{}", c.code);
        } else {
            assert!(matches!(c.class, Class::Reply | Class::Spontaneous));
            assert!(c.replies.is_empty() && c.timeout_ms == 0, "{}", c.code);
            // Every reply answers something, except the button messages.
            assert_eq!(
                c.answers().next().is_none(),
                c.class == Class::Spontaneous,
                "{}",
                c.code
            );
        }
        let mut names: Vec<&str> = c.fields.iter().map(|f| f.name).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), c.fields.len(), "{}: field names", c.code);
    }
    for k in Kind::ALL {
        assert!(!k.name().is_empty() && !k.doc().is_empty());
    }
}

#[test]
fn behaviour_comes_from_the_table() {
    // Motions: 10 s, a busy GS is interim, PO or an error GS completes.
    for code in ["ho", "ma", "mr", "fw", "bw"] {
        let c = cmd(code);
        assert_eq!(c.class, Class::Motion);
        assert_eq!(c.timeout_ns(), 10_000_000_000);
        assert_eq!(c.answer("GS", Some(9)), Answer::Interim);
        assert_eq!(c.answer("GS", Some(2)), Answer::Final);
        assert_eq!(c.answer("PO", None), Answer::Final);
        assert_eq!(c.answer("GV", None), Answer::No);
        assert!(c.is_move() && c.class.moves());
    }
    // Scans: 30 s.
    for code in ["s1", "s2", "c1", "c2"] {
        assert_eq!(cmd(code).timeout_ns(), 30_000_000_000);
        assert_eq!(cmd(code).answer("GS", Some(9)), Answer::Interim);
    }
    assert_eq!(cmd("c1").answer("C1", None), Answer::Final);
    // Others: the manual's 2 s, and a busy GS is their final answer.
    assert_eq!(cmd("gs").timeout_ns(), 2_000_000_000);
    assert_eq!(cmd("gs").answer("GS", Some(9)), Answer::Final);
    assert_eq!(
        aptscope_dissector::ell::timeout_ns(cmd("sv")),
        2_000_000_000
    );
    assert!(cmd("e1").class.moves() && !cmd("so").class.moves());
    // The bus reads the timeouts: a motion may take 9 s, a status request may not take 3 s.
    let mut bus = Bus::new();
    let s = 1_000_000_000u64;
    let ma = EllFrame::decode(0, b"0ma00001000", false).expect("frame");
    let gs = EllFrame::decode(11, b"1gs", false).expect("frame");
    bus.observe(1, &ma, Some(0));
    bus.observe(2, &gs, Some(0));
    let po = EllFrame::decode(14, b"0PO00001000\r\n", false).expect("frame");
    let o = bus.observe(3, &po, Some(9 * s));
    assert_eq!(o.pair, Some(1));
    assert_eq!(o.expired.iter().map(|e| e.code).collect::<Vec<_>>(), ["gs"]);
}

#[test]
fn the_listing_has_every_command_with_its_attributes() {
    use aptscope_dissector::ell::listing;
    let text = listing::text(false);
    for c in COMMANDS {
        let line = text
            .lines()
            .find(|l| l.starts_with(&format!("{}  {} ", c.code, c.name)))
            .unwrap_or_else(|| panic!("{} not listed:\n{text}", c.code));
        assert!(line.contains(c.class.name()), "{line}");
    }
    let ma = text.lines().find(|l| l.starts_with("ma ")).expect("ma");
    assert!(
        ma.contains("h2d")
            && ma.contains("motion")
            && ma.contains("10 s")
            && ma.contains("→ PO,GS (GS BUSY interim)"),
        "{ma}"
    );
    let verbose = listing::text(true);
    assert!(verbose.contains("Move to an absolute position in pulses (p.33)"));
    assert!(verbose.contains("position") && verbose.contains("pulses"));
    assert!(verbose.contains("9=BUSY") && verbose.contains("ELL9=four-position slider"));

    let lines = listing::json_lines();
    let recs: Vec<serde_json::Value> = lines
        .iter()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect();
    let cmds: Vec<&serde_json::Value> = recs.iter().filter(|r| r["type"] == "cmd").collect();
    assert_eq!(cmds.len(), COMMANDS.len());
    for (r, c) in cmds.iter().zip(COMMANDS) {
        assert_eq!(r["code"], c.code);
        assert_eq!(r["name"], c.name);
        assert_eq!(r["dir"], c.dir.as_str());
        assert_eq!(r["class"], c.class.name());
        assert_eq!(r["timeout_ms"], c.timeout_ms);
        assert_eq!(r["data_len"], c.data_len());
        assert_eq!(r["doc"], c.doc);
        let fields = r["fields"].as_array().expect("fields");
        assert_eq!(fields.len(), c.fields.len());
        let mut at = 0;
        for (j, f) in fields.iter().zip(c.fields) {
            assert_eq!(j["name"], f.name);
            assert_eq!(j["width"], f.width);
            assert_eq!(j["offset"], at);
            assert_eq!(j["kind"], f.kind.name());
            assert_eq!(j["unit"], f.kind.unit());
            at += f.width;
        }
        let replies: Vec<&str> = r["replies"]
            .as_array()
            .expect("replies")
            .iter()
            .filter_map(|x| x.as_str())
            .collect();
        assert_eq!(replies, c.replies);
    }
    let po = cmds.iter().find(|r| r["code"] == "PO").expect("PO");
    assert_eq!(
        po["answers"],
        serde_json::json!(["ho", "ma", "mr", "fw", "bw", "gp"])
    );
    let ma = cmds.iter().find(|r| r["code"] == "ma").expect("ma");
    assert_eq!(ma["interim"], serde_json::json!(["GS"]));
    assert_eq!(ma["fields"][0]["unit"], "pulses");
    assert!(recs
        .iter()
        .any(|r| r["type"] == "status" && r["code"] == 9 && r["name"] == "BUSY"));
    assert!(recs
        .iter()
        .any(|r| r["type"] == "model" && r["name"] == "ELL12" && r["slots"] == 6));
}

/// A value of every kind, as text for the encoder and as the decoder gives it back.
fn sample(kind: Kind, width: u16, seed: usize) -> (String, String) {
    match kind {
        Kind::Position | Kind::Signed => {
            let v = [-1000i64, 1000, 0x7FFF_FFFF, -0x8000_0000][seed % 4];
            (v.to_string(), v.to_string())
        }
        Kind::Addr => ("b".into(), "B".into()),
        Kind::Dec => {
            let s: String = "0123456789"
                .chars()
                .cycle()
                .skip(seed)
                .take(width as usize)
                .collect();
            (s.clone(), s)
        }
        Kind::Bool | Kind::HomeDir => ("1".into(), "1".into()),
        Kind::Percent => ("0x32".into(), "50".into()),
        Kind::Status => ("BUSY".into(), "9".into()),
        Kind::Model => ("ELL14".into(), "14".into()),
        Kind::Firmware => ("1.5".into(), "21".into()),
        Kind::Raw => {
            let bytes: Vec<u8> = (0..width as usize).map(|i| (i * 7 + seed) as u8).collect();
            let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
            (hex, format!("{} bytes", bytes.len()))
        }
        _ => {
            let max = (1u64 << (4 * width)) - 1;
            let v = max / 3 + seed as u64;
            (v.to_string(), v.to_string())
        }
    }
}

#[test]
fn every_command_encodes_and_decodes_back() {
    for (i, c) in COMMANDS.iter().enumerate() {
        let given: Vec<(&str, (String, String))> = c
            .fields
            .iter()
            .map(|f| (f.name, sample(f.kind, f.width, i)))
            .collect();
        let values: Vec<(&str, &str)> = given.iter().map(|(k, (t, _))| (*k, t.as_str())).collect();
        let addr = ["0", "5", "F"][i % 3];
        let bytes = encode(addr, c.code, &values).unwrap_or_else(|e| panic!("{}: {e}", c.code));
        // Framed alone and among other frames, it is one clean frame.
        let (fs, garbage) = frames(&[b"0gs".as_slice(), &bytes, b"1GS00\r\n"].concat());
        assert_eq!((fs.len(), garbage), (3, 0), "{}: {bytes:?}", c.code);
        let f = EllFrame::decode(3, &fs[1].1, fs[1].2).expect("decodes");
        assert_eq!(fs[1].1, bytes, "{}", c.code);
        assert!(f.diags().is_empty(), "{}: {:?}", c.code, f.diags());
        assert_eq!(f.cmd.map(|x| x.code), Some(c.code));
        assert_eq!(f.addr_char().to_string(), addr);
        let got: Vec<(&str, String)> = f.fields().map(|(fd, v)| (fd.name, value_str(&v))).collect();
        let want: Vec<(&str, String)> = given.iter().map(|(k, (_, v))| (*k, v.clone())).collect();
        assert_eq!(got, want, "{}", c.code);
        if let Some(raw) = f.field("curve") {
            let EllValue::Raw(b) = raw else {
                panic!("curve")
            };
            let hex: String = b.iter().map(|x| format!("{x:02x}")).collect();
            assert_eq!(hex, given[0].1 .0);
        }
    }
    // The brief's example, hex input, negative positions, names.
    assert_eq!(
        encode("0", "ma", &[("position", "1000")]).unwrap(),
        b"0ma000003E8"
    );
    assert_eq!(
        encode("a", "mr", &[("position", "-1")]).unwrap(),
        b"AmrFFFFFFFF"
    );
    assert_eq!(
        encode("0", "ma", &[("position", "0xFFFFFFFF")]).unwrap(),
        b"0maFFFFFFFF"
    );
    assert_eq!(
        encode("0", "MOVE_ABSOLUTE", &[("position", "0x2000")]).unwrap(),
        b"0ma00002000"
    );
    assert_eq!(encode("0", "ho", &[("direction", "ccw")]).unwrap(), b"0ho1");
    assert_eq!(encode("2", "ga", &[("new_address", "0")]).unwrap(), b"2ga0");
    assert_eq!(
        encode("0", "GS", &[("status", "OUT_OF_RANGE")]).unwrap(),
        b"0GS0C\r\n"
    );
}

#[test]
fn encoding_errors_say_what_is_wrong() {
    let e = |addr: &str, c: &str, v: &[(&str, &str)]| encode(addr, c, v).expect_err("an error");
    assert_eq!(
        e("0", "mx", &[]),
        EncodeError::UnknownCommand {
            given: "mx".into(),
            suggestion: Some("ma")
        }
    );
    assert!(matches!(
        e("0", "po", &[]),
        EncodeError::UnknownCommand {
            suggestion: Some("PO"),
            ..
        }
    ));
    assert!(matches!(
        e("0", "MOVE_ABSOLUT", &[]),
        EncodeError::UnknownCommand {
            suggestion: Some("MOVE_ABSOLUTE"),
            ..
        }
    ));
    assert!(matches!(
        e("0", "hello_world", &[]),
        EncodeError::UnknownCommand {
            suggestion: None,
            ..
        }
    ));
    let unknown = e("0", "I1", &[("lop", "1")]);
    assert!(matches!(&unknown, EncodeError::UnknownField { field, .. } if field == "lop"));
    let msg = unknown.to_string();
    assert!(
        msg.contains("loop, motor, current, ramp_up, ramp_down, forward_period, backward_period"),
        "{msg}"
    );
    assert_eq!(
        e("0", "ma", &[]),
        EncodeError::MissingField {
            cmd: "ma",
            field: "position"
        }
    );
    assert!(matches!(
        e("0", "sv", &[("velocity", "101")]),
        EncodeError::OutOfRange {
            field: "velocity",
            ..
        }
    ));
    assert!(matches!(
        e("0", "ma", &[("position", "2147483648")]),
        EncodeError::OutOfRange {
            field: "position",
            ..
        }
    ));
    assert!(matches!(
        e("0", "f1", &[("period", "0x10000")]),
        EncodeError::OutOfRange {
            field: "period",
            ..
        }
    ));
    assert!(matches!(
        e("0", "ma", &[("position", "1mm")]),
        EncodeError::BadValue {
            field: "position",
            ..
        }
    ));
    assert_eq!(e("G", "gs", &[]), EncodeError::BadAddress("G".into()));
    assert_eq!(e("16", "gs", &[]), EncodeError::BadAddress("16".into()));
    assert!(matches!(
        e("0", "gs", &[("status", "1")]),
        EncodeError::UnknownField { .. }
    ));
    assert_eq!(
        e("0", "ma", &[("position", "1"), ("position", "2")]),
        EncodeError::DuplicateField("position".into())
    );
    assert!(matches!(
        e("0", "C1", &[("curve", "00")]),
        EncodeError::BadValue { field: "curve", .. }
    ));
}

// ------------------------------------------------------------------------------------------
// Commands sent without their data.

/// (text, diagnostics as `kind@offset`) of every frame, and the garbage byte count.
fn decode_all(input: &[u8]) -> (Vec<(String, Vec<String>)>, usize) {
    let (fs, garbage) = frames(input);
    let out = fs
        .iter()
        .map(|(off, b, tr)| {
            let f = EllFrame::decode(*off, b, *tr).expect("decodes");
            let diags = f
                .diags()
                .iter()
                .map(|d| format!("{}@{}", d.kind.name(), d.offset))
                .collect();
            (format!("{}{}", f.addr_char(), f.code_str()), diags)
        })
        .collect();
    (out, garbage)
}

#[test]
fn a_command_without_its_data_is_that_command_with_a_diagnostic() {
    let input = b"0ma\r\n0gs\r\n0ho\r\n1ma1gp0GS00\r\n2mr00\r\n2sj0000\n3ma1gp\r\n4ma00G0\r\n";
    let (got, garbage) = decode_all(input);
    assert_eq!(garbage, 0);
    let want: Vec<(String, Vec<String>)> = [
        ("0ma", vec!["missing_data@3"]),
        ("0gs", vec![]),
        ("0ho", vec!["missing_data@13"]),
        // The next command starts where the data should be: the data was left out.
        ("1ma", vec!["missing_data@18"]),
        ("1gp", vec![]),
        ("0GS", vec![]),
        // Some data, not all of it.
        ("2mr", vec!["data_length@31"]),
        ("2sj", vec!["data_length@38"]),
        // Chunked anywhere, the first character that is not data decides.
        ("3ma", vec!["missing_data@46"]),
        ("1gp", vec![]),
        ("4ma", vec!["data_length@54", "bad_data_char@56"]),
    ]
    .into_iter()
    .map(|(a, d)| (a.to_string(), d.into_iter().map(String::from).collect()))
    .collect();
    assert_eq!(got, want);
    let f = EllFrame::decode(0, b"0ma\r\n", false).expect("frame");
    assert_eq!(
        f.diags()[0].kind,
        DiagKind::MissingData { expected: 8 },
        "{:?}",
        f.diags()
    );
    assert_eq!(f.fields().count(), 0);
    // In any chunking.
    for cut in 0..input.len() {
        let mut fr = EllFramer::new();
        let mut n = 0;
        for part in [&input[..cut], &input[cut..]] {
            fr.push(part);
            while let Some(it) = fr.next_item() {
                assert!(matches!(it, EllItem::Frame { .. }), "cut {cut}: {it:?}");
                n += 1;
            }
        }
        fr.finish();
        while fr.next_item().is_some() {
            n += 1;
        }
        assert_eq!(n, want.len(), "cut {cut}");
    }
}

/// `0ho` sent without its direction digit and without a terminator: framed when the module
/// answers, as `ho` with the data missing, paired with the reply.
#[test]
fn a_command_cut_short_by_the_reply_is_framed_when_the_module_answers() {
    use aptscope_dissector::detect::Proto;
    use aptscope_dissector::pipeline::{Ctx, Format, Pipeline};
    let mut p = Pipeline::new(Some(Proto::Elliptec), Format::Json);
    let mut out: Vec<serde_json::Value> = vec![];
    let mut emit = |l: &str| -> Result<(), ()> {
        out.push(serde_json::from_str(l).expect("json"));
        Ok(())
    };
    let ctx = |dir, t| Ctx {
        stream: 0,
        dir: Some(dir),
        ts_ns: Some(t),
    };
    p.push_chunk(ctx(Dir::HostToDevice, 0), b"0ho", &mut emit)
        .unwrap();
    p.push_chunk(ctx(Dir::DeviceToHost, 5_000_000), b"0GS03\r\n", &mut emit)
        .unwrap();
    p.finish(&mut emit).unwrap();
    let frames: Vec<&serde_json::Value> = out.iter().filter(|v| v["type"] == "frame").collect();
    assert_eq!(frames.len(), 2, "{out:?}");
    assert_eq!(frames[0]["text"], "0ho");
    assert_eq!(frames[0]["cmd"], "ho");
    assert_eq!(frames[0]["diag"][0]["kind"], "missing_data");
    assert_eq!(frames[0]["diag"][0]["offset"], 3);
    assert_eq!(frames[1]["pair"], 1);
}

// ------------------------------------------------------------------------------------------
// Indexed sliders: positions as slots.

/// The text line of every frame of `input` (decoded through the pipeline).
fn text_lines(input: &[u8]) -> Vec<String> {
    use aptscope_dissector::detect::Proto;
    use aptscope_dissector::pipeline::{Ctx, Format, Pipeline};
    let mut p = Pipeline::new(Some(Proto::Elliptec), Format::Text);
    let mut out = vec![];
    let mut emit = |l: &str| -> Result<(), ()> {
        out.push(l.to_string());
        Ok(())
    };
    let ctx = Ctx {
        stream: 0,
        dir: None,
        ts_ns: None,
    };
    p.push_chunk(ctx, input, &mut emit).unwrap();
    p.finish(&mut emit).unwrap();
    out
}

fn json_records(input: &[u8]) -> Vec<serde_json::Value> {
    use aptscope_dissector::detect::Proto;
    use aptscope_dissector::pipeline::{Ctx, Format, Pipeline};
    let mut p = Pipeline::new(Some(Proto::Elliptec), Format::Json);
    let mut out = vec![];
    let mut emit = |l: &str| -> Result<(), ()> {
        out.push(serde_json::from_str(l).expect("json"));
        Ok(())
    };
    let ctx = Ctx {
        stream: 0,
        dir: None,
        ts_ns: None,
    };
    p.push_chunk(ctx, input, &mut emit).unwrap();
    p.finish(&mut emit).unwrap();
    out.into_iter()
        .filter(|v: &serde_json::Value| v["type"] == "frame")
        .collect()
}

#[test]
fn slider_positions_show_as_slots() {
    // ELL9 (4 positions, IN: 0x20 pulses per position), ELL12 (6 positions), and the manual's
    // ELL6 example (p.9: 1 "pulse per position", travel 0x1F; p.43: forward position 0x1F).
    let s =
        b"1in1IN091130012320231501001300000020\r\n1ma00000040\r\n1PO00000040\r\n1gp1PO0000005D\r\n\
2in2IN0C1120000120231501001F00000020\r\n2gp2PO000000A0\r\n\
0in0IN061234567820150181001F00000001\r\n0fw0PO0000001F\r\n";
    let lines = text_lines(s);
    let find = |needle: &str| {
        lines
            .iter()
            .find(|l| l.contains(needle))
            .unwrap_or_else(|| panic!("no {needle:?} in {lines:#?}"))
            .clone()
    };
    assert!(find("host → 1  ma").contains("position=64 (slot 2)"));
    assert!(find("← 1  PO POSITION                     position=64").contains("(slot 2)"));
    // 0x5D = 93, not a multiple of 32: the nearest slot, marked.
    assert!(find("position=93").contains("(≈slot 3)"));
    assert!(find("position=160").contains("(slot 5)"), "ELL12");
    assert!(find("position=31").contains("(slot 1)"), "ELL6");
    let recs = json_records(s);
    let po = recs
        .iter()
        .find(|r| r["cmd"] == "PO" && r["fields"]["position"] == 64)
        .expect("PO");
    assert_eq!(po["phys"]["position"]["value"], 2.0);
    assert_eq!(po["phys"]["position"]["unit"], "slot");
    // The bus's module gives the slot number itself.
    let m = aptscope_dissector::ell::Module {
        model: Some(9),
        pulses: Some(32),
        travel: Some(19),
        ..Default::default()
    };
    assert_eq!(m.scale(), Some((32.0, "slot")));
    assert_eq!(
        [0, 32, 64, 96, 93, 128, 48, -32].map(|p| m.slot(p)),
        [
            Some(0),
            Some(1),
            Some(2),
            Some(3),
            Some(3),
            None,
            None,
            None
        ]
    );
}

// ------------------------------------------------------------------------------------------
// The binary current curve.

fn curve(points: usize) -> Vec<u8> {
    use aptscope_dissector::ell::{curve_bytes, CurvePoint};
    let pts: Vec<CurvePoint> = (0..points)
        .map(|i| CurvePoint {
            period: 210 - i as u16,
            current: 400 + (i as u32 * 37) % 700,
        })
        .collect();
    curve_bytes(&pts)
}

#[test]
fn current_curve_points_are_decoded() {
    // 87 points of period (u16 LE) and current (u32 LE): 522 bytes, then CR LF.
    let data = curve(87);
    assert_eq!(data.len(), 522);
    assert_eq!(&data[..6], &[210, 0, 144, 1, 0, 0]);
    let input = [b"Ac1AGS09\r\nAC1".as_slice(), &data, b"\r\nAgs"].concat();
    let (fs, garbage) = frames(&input);
    assert_eq!((fs.len(), garbage), (4, 0));
    let f = EllFrame::decode(fs[2].0, &fs[2].1, false).expect("C1");
    assert!(f.diags().is_empty(), "{:?}", f.diags());
    let pts: Vec<_> = f.curve().collect();
    assert_eq!(pts.len(), 87);
    assert_eq!((pts[0].period, pts[0].current), (210, 400));
    assert_eq!(
        (pts[86].period, pts[86].current),
        (124, 400 + (86 * 37) % 700)
    );
    assert!((pts[0].hz() - 70_190.48).abs() < 0.01);
    assert!((pts[0].amps() - 400.0 / 1866.0).abs() < 1e-9);
    // Text and JSON show the points.
    let mut s = String::new();
    let (fd, v) = f.fields().next().expect("curve field");
    aptscope_dissector::ell::fmt_value(fd, &v, None, &mut s);
    assert!(s.starts_with("87 points 70.2-118.9 kHz, peak "), "{s}");
    let recs = json_records(&input);
    let c1 = recs.iter().find(|r| r["cmd"] == "C1").expect("C1");
    let jp = c1["fields"]["curve_points"].as_array().expect("points");
    assert_eq!(jp.len(), 87);
    assert_eq!(jp[0]["period"], 210);
    assert_eq!(jp[0]["current"], 400);
    assert_eq!(c1["pair"], 1, "C1 answers c1");
    // The manual's byte table (data at 3-521, 519 bytes): framed, reported, 86 whole points.
    let short = [b"0C1".as_slice(), &data[..519], b"\r\n0GS00\r\n"].concat();
    let (fs, garbage) = frames(&short);
    assert_eq!((fs.len(), garbage), (2, 0));
    let f = EllFrame::decode(0, &fs[0].1, false).expect("C1");
    assert_eq!(
        f.diags().iter().map(|d| d.kind).collect::<Vec<_>>(),
        [DiagKind::DataLength {
            expected: 522,
            got: 519
        }]
    );
    assert_eq!(f.curve().count(), 86);
    // A curve cut by the end of the stream.
    let (fs, _) = frames(&[b"0C1".as_slice(), &data[..100]].concat());
    assert!(fs[0].2, "truncated");
    // Other frames have no curve.
    assert_eq!(
        EllFrame::decode(0, b"0gs", false)
            .expect("gs")
            .curve()
            .count(),
        0
    );
}

/// Curve bytes are binary: those equal to CR or LF at the end of the data are data, not part
/// of the terminator (found by the `ell_encode` fuzz target: a built `C1` decoded as 484 data
/// bytes of 522, its last 38 bytes 0x0D).
#[test]
fn a_curve_ending_in_cr_and_lf_bytes_keeps_them() {
    let mut data = curve(87);
    // The last point's current: 0x0A0D0D0A.
    data[518..].copy_from_slice(&[0x0A, 0x0D, 0x0D, 0x0A]);
    for term in [&b"\r\n"[..], b"\r", b"\n"] {
        let input = [b"0C1".as_slice(), &data, term, b"0GS00\r\n"].concat();
        let (fs, garbage) = frames(&input);
        assert_eq!((fs.len(), garbage), (2, 0), "{term:?}");
        assert_eq!(fs[0].1.len(), 3 + 522 + term.len());
        let f = EllFrame::decode(0, &fs[0].1, false).expect("C1");
        assert!(f.diags().is_empty(), "{term:?}: {:?}", f.diags());
        let last = f.curve().last().expect("points");
        assert_eq!((f.curve().count(), last.current), (87, 0x0A0D_0D0A));
    }
    // Without a terminator (the stream ended): every data byte, and the terminator missed.
    let whole = [b"0C1".as_slice(), &data].concat();
    let f = EllFrame::decode(0, &whole, false).expect("C1");
    let kinds: Vec<_> = f.diags().iter().map(|d| d.kind).collect();
    assert_eq!(kinds, [DiagKind::MissingTerminator]);
    assert_eq!(f.curve().count(), 87);
    // The manual's shorter length ending in a CR byte: only the CR LF after it goes.
    let mut short = data[..519].to_vec();
    short[518] = b'\r';
    let short = [b"0C1".as_slice(), &short, b"\r\n"].concat();
    let f = EllFrame::decode(0, &short, false).expect("C1");
    let kinds: Vec<_> = f.diags().iter().map(|d| d.kind).collect();
    assert_eq!(
        kinds,
        [DiagKind::DataLength {
            expected: 522,
            got: 519
        }]
    );
    // Truncated: the bytes there are all data.
    let cut = [b"0C1".as_slice(), &data[..517], b"\r\n"].concat();
    let f = EllFrame::decode(0, &cut, true).expect("C1");
    assert_eq!(f.curve().count(), 86, "519 bytes: 86 whole points");
}

// ------------------------------------------------------------------------------------------
// Group moves.

#[test]
fn a_group_move_pairs_the_answer_of_every_module() {
    // The manual's example (p.43): sliders at 0 and 2; 2 listens to 0, then `0fw` moves both;
    // each answers, busy first, the final position from its own address (the manual) or from
    // the group address (what the simulator does).
    let s = b"0in0IN0911300123202315010013000000 20\r\n2in2IN0911300456202315010013000000 20\r\n\
2ga0\r\n0GS00\r\n0fw\r\n0GS09\r\n0GS09\r\n0PO00000020\r\n2PO00000020\r\n\
2ga0\r\n0GS00\r\n0bw\r\n0PO00000000\r\n0PO00000000\r\n\
0gp\r\n0PO00000000\r\n0PO00000000\r\n";
    let s: Vec<u8> = s.iter().copied().filter(|c| *c != b' ').collect();
    let r = run_bus(&s);
    let got: Vec<(&str, Option<u64>, bool)> = r.iter().map(|x| (x.0.as_str(), x.1, x.2)).collect();
    assert_eq!(
        got,
        [
            ("0in", None, false),
            ("0IN", Some(1), false),
            ("2in", None, false),
            ("2IN", Some(3), false),
            ("2ga", None, false),
            ("0GS", Some(5), false),
            ("0fw", None, false),
            ("0GS", Some(7), false),
            ("0GS", Some(7), false),
            ("0PO", Some(7), false),
            ("2PO", Some(7), false),
            ("2ga", None, false),
            ("0GS", Some(12), false),
            ("0bw", None, false),
            ("0PO", Some(14), false),
            ("0PO", Some(14), false),
            // The group ended with the motion: one module answers `0gp`.
            ("0gp", None, false),
            ("0PO", Some(17), false),
            ("0PO", None, true),
        ]
    );
    // A group command answered by one module only is not reported as unanswered.
    let mut bus = Bus::new();
    let mut n = 0;
    for fr in [b"0gaA".as_slice(), b"AGS00\r\n", b"Afw", b"APO00000020\r\n"] {
        n += 1;
        let f = EllFrame::decode(0, fr, false).expect("frame");
        let o = bus.observe(n, &f, None);
        assert!(!o.unsolicited, "{fr:?}");
    }
    assert!(bus.finish().is_empty());
}

// ------------------------------------------------------------------------------------------
// Chunking, on streams of commands with and without data, replies, curves and noise.

/// (offset, bytes, truncated, is a frame) of each item.
fn records(input: &[u8], cuts: &[usize]) -> Vec<(u64, Vec<u8>, bool, bool)> {
    run_ell(input, cuts)
        .into_iter()
        .map(|it| match it {
            Item::Frame(o, b, t) => (o, b, t, true),
            Item::Garbage(o, b, _) => (o, b, false, false),
        })
        .collect()
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]
    #[test]
    fn elliptec_records_do_not_depend_on_the_chunking(
        picks in proptest::collection::vec(0usize..17, 0..40),
        cuts in proptest::collection::vec(proptest::prelude::any::<u32>(), 0..40),
    ) {
        let c522 = [b"0C1".as_slice(), &curve(87), b"\r\n"].concat();
        let c519 = [b"1C2".as_slice(), &curve(87)[..519], b"\r\n"].concat();
        let tokens: [&[u8]; 17] = [
            b"0ma00002000", b"0ma", b"\r\n", b"1gp", b"1PO00000020\r\n", b"0ho", b"2ho1\r",
            b"\n", b"0GS09\r\n", b"xx", b"0ma1g", b"3sv3", b"0 ca A", &c522, &c519, b"\xff\x00",
            b"0ma1gp",
        ];
        let input: Vec<u8> = picks.iter().flat_map(|&i| tokens[i].iter().copied()).collect();
        let mut cuts: Vec<usize> = cuts.iter().map(|c| *c as usize % (input.len() + 1)).collect();
        cuts.sort_unstable();
        let whole = records(&input, &[]);
        proptest::prop_assert_eq!(&records(&input, &cuts), &whole);
        let total: usize = whole.iter().map(|r| r.1.len()).sum();
        proptest::prop_assert_eq!(total, input.len());
        for (off, b, tr, frame) in &whole {
            if *frame {
                proptest::prop_assert!(EllFrame::decode(*off, b, *tr).is_some(), "{:?}", b);
            }
        }
    }
}

#[test]
fn field_names_are_identifiers_json_keys_need_no_escaping() {
    // NDJSON writes field names (and `<name>_name`, `<name>_version`) as keys without
    // escaping; the APT table's parser refuses other names, this table is checked here.
    for c in COMMANDS {
        for f in c.fields {
            let ok = !f.name.is_empty()
                && f.name
                    .bytes()
                    .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_');
            assert!(ok, "{} field `{}`", c.code, f.name);
        }
    }
}
