//! The Elliptec simulator per model, on virtual time: every command a model has is answered
//! and decodes without diagnostic, every other one gets `GS03`.

use super::*;
use aptscope_dissector::ell::encode::encode_cmd;
use aptscope_dissector::ell::table::{Cmd, Kind, COMMANDS, MODELS};
use aptscope_dissector::ell::{curve_points, Bus, EllFrame, EllFramer, Item};
use aptscope_dissector::table::Dir;

/// Everything the simulator sends from `from` to `to`, stepping from deadline to deadline.
fn drive<S: Simulator>(sim: &mut S, from: u64, to: u64) -> Vec<u8> {
    let mut out = vec![];
    let mut t = from;
    loop {
        while let Some(b) = sim.poll(t) {
            out.extend(b);
        }
        match sim.next_deadline() {
            Some(d) if d <= to => t = d.max(t + 1),
            _ => break,
        }
    }
    while let Some(b) = sim.poll(to) {
        out.extend(b);
    }
    out
}

/// Send `bytes` at `t` and collect what comes back until `until`.
fn talk(sim: &mut EllSim, bytes: &[u8], t: u64, until: u64) -> String {
    sim.input(bytes, t);
    String::from_utf8_lossy(&drive(sim, t, until)).into_owned()
}

/// A value every field of kind `k` takes (position 0: in range on every model).
fn value(k: Kind) -> &'static str {
    match k {
        Kind::Period => "0xBD",
        Kind::Percent => "50",
        Kind::Minutes => "1",
        _ => "0",
    }
}

/// `cmd` for the module at 0 with a valid value in every field.
fn command(cmd: &'static Cmd) -> Vec<u8> {
    let vals: Vec<(&str, &str)> = cmd.fields.iter().map(|f| (f.name, value(f.kind))).collect();
    encode_cmd(cmd, 0, &vals).unwrap_or_else(|e| panic!("{}: {e}", cmd.code))
}

/// The frames of `bytes` (one direction), each checked to decode without diagnostic.
fn frames(bytes: &[u8], ctx: &str) -> Vec<Vec<u8>> {
    let mut f = EllFramer::new();
    f.push(bytes);
    f.finish();
    let mut out = vec![];
    while let Some(it) = f.next_item() {
        match it {
            Item::Frame { bytes, .. } => out.push(bytes.to_vec()),
            Item::Garbage { bytes, kind, .. } => panic!("{ctx}: garbage {kind:?} {bytes:?}"),
        }
    }
    out
}

#[test]
fn every_model_answers_its_commands_and_refuses_the_others_with_gs03() {
    for m in MODELS {
        let mods = format!("0:ELL{}", m.number);
        for cmd in COMMANDS.iter().filter(|c| c.dir == Dir::HostToDevice) {
            let ctx = format!("ELL{} {}", m.number, cmd.code);
            let mut sim = EllSim::new(&parse_modules(&mods).unwrap()).unwrap();
            let sent = command(cmd);
            sim.input(&sent, 0);
            let got = drive(&mut sim, 0, 40 * SEC);
            // The host's frame and the replies, paired as the decoder pairs them.
            let mut bus = Bus::new();
            let host = frames(&sent, &ctx);
            assert_eq!(host.len(), 1, "{ctx}");
            let f = EllFrame::decode(0, &host[0], false).expect("host frame");
            assert!(f.diags().is_empty(), "{ctx}: {:?}", f.diags());
            bus.observe(0, &f, Some(0));
            let replies = frames(&got, &ctx);
            for (n, r) in replies.iter().enumerate() {
                let f = EllFrame::decode(0, r, false).expect("reply frame");
                assert!(f.diags().is_empty(), "{ctx}: {r:?} {:?}", f.diags());
                let o = bus.observe(n as u64 + 1, &f, Some(SEC));
                assert_eq!(o.pair, Some(0), "{ctx}: {r:?} pairs with the command");
                assert!(o.expired.is_empty(), "{ctx}");
            }
            let text = String::from_utf8_lossy(&got);
            if !m.supports(cmd.code) {
                assert_eq!(text, "0GS03\r\n", "{ctx}: not supported");
            } else if cmd.timeout_ms == 0 {
                assert!(got.is_empty(), "{ctx}: no reply expected, got {text:?}");
            } else {
                assert_eq!(replies.len(), 1, "{ctx}: {text:?}");
                let r = &replies[0];
                assert!(
                    cmd.replies.iter().any(|c| c.as_bytes() == &r[1..3]),
                    "{ctx}: {text:?}"
                );
                assert!(!text.ends_with("GS03\r\n"), "{ctx}: refused: {text:?}");
                assert!(bus.finish().is_empty(), "{ctx}: answered");
            }
        }
    }
}

#[test]
fn the_manuals_lists_per_mechanism() {
    let has = |n: u8, code: &str| {
        MODELS
            .iter()
            .find(|m| m.number == n)
            .is_some_and(|m| m.supports(code))
    };
    // Sliders: no velocity, jog step or home offset (p.45); single-motor ones no motor 2.
    for code in ["gv", "sv", "gj", "sj", "go", "so", "mr", "i2", "c2"] {
        assert!(!has(6, code) && !has(9, code), "{code}");
    }
    // The ELL6 has no `ma` (p.33), the multi-position sliders do (the elliptec package).
    assert!(!has(6, "ma") && has(9, "ma") && has(12, "ma"));
    // Rotation and linear stages: everything the manual lists (p.46, p.47).
    for n in [4, 7, 8, 14, 17, 18, 20] {
        for c in COMMANDS.iter().filter(|c| c.dir == Dir::HostToDevice) {
            assert!(has(n, c.code), "ELL{n} {}", c.code);
        }
    }
    // The open-loop actuator: one motor, jogs, no positioning.
    assert!(has(5, "fw") && !has(5, "ma") && !has(5, "i2"));
}

#[test]
fn an_unknown_command_without_terminator_gets_gs03_and_the_error_stays_for_gs() {
    // pylablib's get_full_info: `0i3` (motor 3), no CR LF, then `0gs` to clear the fault.
    let mut sim = EllSim::new(&parse_modules("0:ELL14").unwrap()).unwrap();
    assert_eq!(talk(&mut sim, b"0i3", 0, SEC), "0GS03\r\n");
    assert_eq!(talk(&mut sim, b"0gs", SEC, 2 * SEC), "0GS03\r\n");
    assert_eq!(talk(&mut sim, b"0gs", 2 * SEC, 3 * SEC), "0GS00\r\n");
    // Back to back in one write: each answered in turn.
    assert_eq!(
        talk(&mut sim, b"0i30gs0i1", 3 * SEC, 4 * SEC),
        "0GS03\r\n0GS03\r\n0I1100000FFFFFFFF00BD008B\r\n"
    );
    // With data and a terminator: one command.
    assert_eq!(
        talk(&mut sim, b"0xy12AB\r\n", 4 * SEC, 5 * SEC),
        "0GS03\r\n"
    );
    // Unknown addresses stay silent, known or unknown command.
    assert_eq!(talk(&mut sim, b"7in7i3\r\n", 5 * SEC, 6 * SEC), "");
}

/// Each command in turn, 3 s apart (long enough for any slider move), with the reply it gets.
fn script(sim: &mut EllSim, steps: &[(&str, &str)]) {
    for (k, (cmd, want)) in steps.iter().enumerate() {
        let t = k as u64 * 3 * SEC;
        assert_eq!(
            talk(sim, cmd.as_bytes(), t, t + 3 * SEC - 1),
            *want,
            "{cmd}"
        );
    }
}

#[test]
fn sliders_rest_on_their_positions() {
    let mut sim = EllSim::new(&parse_modules("0:ELL6,1:ELL9,2:ELL12").unwrap()).unwrap();
    script(
        &mut sim,
        &[
            // ELL6: IN gives travel 0x1F and 0 pulses; forward is 0x1F (the manual's `ga`
            // example); forward again stays there (the elliptec package's Shutter.open sends
            // fw wherever the slider is); no `ma` (p.33).
            ("0in", "0IN061060010020231701001F00000000\r\n"),
            ("0fw", "0PO0000001F\r\n"),
            ("0fw", "0PO0000001F\r\n"),
            ("0bw", "0PO00000000\r\n"),
            ("0ma00000000", "0GS03\r\n"),
            // ELL9: positions 0x1F apart (Micro-Manager's, measured); `ma` between two settles
            // on the nearer one (the elliptec package asks for 32, 64, 96).
            ("1ma0000003E", "1PO0000003E\r\n"),
            ("1ma00000040", "1PO0000003E\r\n"),
            ("1ma00000025", "1PO0000001F\r\n"),
            ("1ma00000080", "1GS0C\r\n"),
            ("1ho0", "1PO00000000\r\n"),
            // ELL12: six positions, the last at 5 × 31.
            ("2ma0000009B", "2PO0000009B\r\n"),
        ],
    );
}

#[test]
fn motor_settings_read_back_and_scans_take_their_time() {
    let mut sim = EllSim::new(&parse_modules("0:ELL18").unwrap()).unwrap();
    script(
        &mut sim,
        &[
            ("0f200C0", "0GS00\r\n"),
            ("0e2008D", "0GS00\r\n"),
            ("0i2", "0I2110428FFFFFFFF00C0008B\r\n"),
            ("0h2", "0GS00\r\n"),
            ("0f10000", "0GS04\r\n"),
            ("0gs", "0GS04\r\n"),
        ],
    );
    // The frequency search: busy, then GS00 and the best periods back.
    let t = 18 * SEC;
    sim.input(b"0s2", t);
    assert_eq!(
        talk(&mut sim, b"0gs", t + SEC, t + SEC + 50 * MS),
        "0GS09\r\n"
    );
    assert_eq!(
        drive(&mut sim, t + SEC + 50 * MS, t + 3 * SEC),
        b"0GS00\r\n"
    );
    assert!(talk(&mut sim, b"0i2", t + 3 * SEC, t + 4 * SEC).ends_with("00BD008B\r\n"));
    // The current curve: about 12 s, then 87 binary points.
    let t = t + 4 * SEC;
    sim.input(b"0c1", t);
    assert!(drive(&mut sim, t, t + 11 * SEC).is_empty());
    let c1 = drive(&mut sim, t + 11 * SEC, t + 20 * SEC);
    assert_eq!(&c1[..3], b"0C1");
    assert!(c1.ends_with(b"\r\n"));
    let pts: Vec<_> = curve_points(&c1[3..c1.len() - 2]).collect();
    assert_eq!(pts.len(), 87);
    assert_eq!((pts[0].period, pts[86].period), (210, 124));
    let peak = pts.iter().max_by_key(|p| p.current).expect("points");
    assert!([0xBD, 0x8B].contains(&peak.period), "{peak:?}");
}

#[test]
fn the_model_list_names_every_model_with_its_commands() {
    let list = ell::model_list();
    for m in MODELS {
        let row = format!("ELL{:<3} {}", m.number, m.what);
        assert!(list.contains(&row), "{row}\n{list}");
    }
    assert!(list.contains("ELL6   in gs us re ca i1 f1 b1 e1 h1 s1 c1 is ho fw bw gp ga\n"));
    assert_eq!(
        EllModel::parse("ell21").map(|m| m.number()),
        Some(21),
        "every row parses"
    );
    let e = parse_modules("0:ELL99").unwrap_err().to_string();
    assert!(
        e.contains("ELL4, ELL5, ELL6") && e.contains("--list"),
        "{e}"
    );
}
