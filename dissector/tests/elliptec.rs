//! Elliptec: every example of the ELLx manual (`ell_examples.txt`), framing in any chunking,
//! bus state across address changes, pairing, and bad input.

use aptscope_dissector::ell::{Bus, EllFrame, EllFramer, EllValue, Item};
use aptscope_dissector::DiagKind;

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

/// Frame and decode `input`: (frames, garbage bytes).
fn frames(input: &[u8]) -> (Vec<(u64, Vec<u8>, bool)>, usize) {
    let mut f = EllFramer::new();
    f.push(input);
    f.finish();
    let (mut out, mut garbage) = (vec![], 0);
    while let Some(it) = f.next_item() {
        match it {
            Item::Frame {
                offset,
                bytes,
                truncated,
            } => out.push((offset, bytes.to_vec(), truncated)),
            Item::Garbage { bytes, .. } => garbage += bytes.len(),
        }
    }
    (out, garbage)
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
    let mut f = EllFramer::new();
    f.push(input);
    f.finish();
    let mut bus = Bus::new();
    let mut n = 0;
    let mut out = vec![];
    while let Some(it) = f.next_item() {
        n += 1;
        if let Item::Frame {
            offset,
            bytes,
            truncated,
        } = it
        {
            let fr = EllFrame::decode(offset, bytes, truncated).expect("frame");
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
    let mut f = EllFramer::new();
    f.push(b"0gs1GS00\r\n2gp");
    f.finish();
    let mut bus = Bus::new();
    let mut n = 0;
    let mut unsolicited = vec![];
    while let Some(it) = f.next_item() {
        n += 1;
        if let Item::Frame {
            offset,
            bytes,
            truncated,
        } = it
        {
            let fr = EllFrame::decode(offset, bytes, truncated).expect("frame");
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
            let mut f = EllFramer::new();
            let mut got = vec![];
            let mut garbage = 0;
            for part in [&input[..cut], &input[cut..cut2], &input[cut2..]] {
                f.push(part);
                while let Some(it) = f.next_item() {
                    match it {
                        Item::Frame {
                            offset,
                            bytes,
                            truncated,
                        } => got.push((offset, bytes.to_vec(), truncated)),
                        Item::Garbage { bytes, .. } => garbage += bytes.len(),
                    }
                }
            }
            f.finish();
            while let Some(it) = f.next_item() {
                match it {
                    Item::Frame {
                        offset,
                        bytes,
                        truncated,
                    } => got.push((offset, bytes.to_vec(), truncated)),
                    Item::Garbage { bytes, .. } => garbage += bytes.len(),
                }
            }
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
