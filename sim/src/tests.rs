//! Scripted sessions on virtual time, and one real pseudo-terminal session.

use super::apt::build;
use super::*;
use aptscope_dissector::apt::{AptFrame, AptFramer, FieldValue, Item};
use aptscope_dissector::Table;

/// A decoded APT frame: time, name, source, destination, integer fields.
#[derive(Debug, Clone)]
struct Rx {
    t: u64,
    name: String,
    src: u8,
    dst: u8,
    fields: Vec<(String, i64)>,
}

impl Rx {
    fn get(&self, f: &str) -> i64 {
        self.fields
            .iter()
            .find(|(n, _)| n == f)
            .map(|(_, v)| *v)
            .unwrap_or_else(|| panic!("{} has no {f}: {:?}", self.name, self.fields))
    }
}

/// Everything the simulator sends from `from` to `to`, stepping from deadline to deadline.
fn drive<S: Simulator>(sim: &mut S, from: u64, to: u64) -> Vec<(u64, Vec<u8>)> {
    let mut out = vec![];
    let mut t = from;
    loop {
        while let Some(b) = sim.poll(t) {
            out.push((t, b));
        }
        match sim.next_deadline() {
            Some(d) if d <= to => t = d.max(t + 1),
            _ => break,
        }
    }
    while let Some(b) = sim.poll(to) {
        out.push((to, b));
    }
    out
}

fn decode_apt(chunks: &[(u64, Vec<u8>)]) -> Vec<Rx> {
    let table = Table::global();
    let mut out = vec![];
    for (t, b) in chunks {
        let mut fr = AptFramer::new(table);
        fr.push(b);
        fr.finish();
        while let Some(item) = fr.next_item() {
            let Item::Frame {
                bytes, truncated, ..
            } = item
            else {
                panic!("garbage in simulator output: {item:?}");
            };
            assert!(!truncated);
            let f = AptFrame::decode(table, 0, bytes, false).expect("decodes");
            assert!(!f.has_diags(), "{:?}", f.diags().collect::<Vec<_>>());
            out.push(Rx {
                t: *t,
                name: f.name().unwrap_or("?").to_string(),
                src: f.header().src_byte(),
                dst: f.header().dst_byte(),
                fields: f
                    .fields()
                    .filter_map(|(fd, v)| Some((fd.name.to_string(), v.as_i64()?)))
                    .collect(),
            });
        }
    }
    out
}

fn req(name: &str, dst: u8, vals: &[(&str, i64)]) -> Vec<u8> {
    let v: Vec<(&str, FieldValue)> = vals
        .iter()
        .map(|(k, x)| (*k, FieldValue::Int(*x)))
        .collect();
    let id = Table::global().msg_by_name(name).map_or(0, |m| m.id);
    build(id, None, dst, 0x01, &v).unwrap_or_else(|| panic!("cannot build {name}"))
}

/// Send `bytes` at `t` and collect what comes back until `until`.
fn talk<S: Simulator>(sim: &mut S, bytes: &[u8], t: u64, until: u64) -> Vec<(u64, Vec<u8>)> {
    sim.input(bytes, t);
    drive(sim, t, until)
}

#[test]
fn hw_get_info_has_the_models_serial_prefix() {
    for (model, prefix, name) in [
        (AptModel::Kdc101, 27, "KDC101"),
        (AptModel::Tdc001, 83, "TDC001"),
        (AptModel::Kpz101, 29, "KPZ101"),
        (AptModel::Bsc203, 70, "BSC203"),
        (AptModel::Tls001, 86, "TLS001"),
        (AptModel::Ttc001, 87, "TTC001"),
        (AptModel::Kpa101, 69, "KPA101"),
    ] {
        let mut sim = AptSim::new(model);
        let dst = if model == AptModel::Bsc203 {
            0x11
        } else {
            0x50
        };
        let out = talk(&mut sim, &req("HW_REQ_INFO", dst, &[]), 1000, SEC);
        let rx = decode_apt(&out);
        assert_eq!(rx.len(), 1, "{rx:?}");
        assert_eq!(rx[0].name, "HW_GET_INFO");
        assert_eq!((rx[0].src, rx[0].dst), (dst, 0x01));
        assert_eq!(rx[0].get("serial_number") / 1_000_000, prefix);
        // 90 bytes at 115200 baud after a 1 ms turnaround: answered within a few ms.
        assert!(
            rx[0].t > 1000 + MS && rx[0].t < 1000 + 20 * MS,
            "{}",
            rx[0].t
        );
        let raw = &out[0].1;
        assert_eq!(&raw[10..16], name.as_bytes());
    }
}

#[test]
fn move_absolute_sends_updates_then_completes_at_the_target() {
    let mut sim = AptSim::new(AptModel::Kdc101);
    let mut rx = decode_apt(&talk(
        &mut sim,
        &req("HW_START_UPDATEMSGS", 0x50, &[]),
        0,
        0,
    ));
    assert!(rx.is_empty());
    let target = 69_110; // 2 mm on a Z8 stage
    let mv = req(
        "MOT_MOVE_ABSOLUTE",
        0x50,
        &[("chan_ident", 1), ("absolute_position", target)],
    );
    rx.extend(decode_apt(&talk(&mut sim, &mv, 50 * MS, 10 * SEC)));
    let done: Vec<&Rx> = rx
        .iter()
        .filter(|r| r.name == "MOT_MOVE_COMPLETED")
        .collect();
    assert_eq!(done.len(), 1, "{rx:?}");
    let done = done[0];
    assert_eq!(done.get("position"), target);
    // 2 mm at 2 mm/s max and 1.5 mm/s²: a triangular profile of about 2.3 s.
    let secs = (done.t - 50 * MS) as f64 / SEC as f64;
    assert!((2.0..2.7).contains(&secs), "took {secs} s");
    let ups: Vec<&Rx> = rx
        .iter()
        .filter(|r| r.name == "MOT_GET_DCSTATUSUPDATE")
        .collect();
    // The host never said it is alive (MOT_ACK_DCSTATUSUPDATE): the updates stop after 50.
    assert_eq!(ups.len(), 50, "{} updates in 10 s", ups.len());
    for w in ups.windows(2) {
        assert!(w[1].get("position") >= w[0].get("position"));
        let dt = w[1].t - w[0].t;
        assert!((99 * MS..=101 * MS).contains(&dt), "update period {dt}");
    }
    let moving: Vec<&&Rx> = ups.iter().filter(|r| r.t < done.t).collect();
    assert!(moving.len() >= 15);
    for r in &moving[1..] {
        assert_ne!(r.get("status_bits") & 0x10, 0, "MOVING_CW while moving");
        assert!(r.get("velocity") > 0);
    }
    let last = ups.last().unwrap();
    assert_eq!(last.get("position"), target);
    assert_eq!(last.get("status_bits") & 0x30, 0, "not moving at the end");
    assert_ne!(last.get("status_bits") as u32 & 0x8000_0000, 0, "ENABLED");
}

#[test]
fn home_ends_with_homed_and_the_homed_bit() {
    let mut sim = AptSim::new(AptModel::Kdc101);
    let rx = decode_apt(&talk(
        &mut sim,
        &req("MOT_MOVE_HOME", 0x50, &[("chan_ident", 1)]),
        0,
        5 * SEC,
    ));
    assert_eq!(rx.len(), 1, "{rx:?}");
    assert_eq!(rx[0].name, "MOT_MOVE_HOMED");
    assert_eq!(rx[0].get("chan_ident"), 1);
    assert!((2 * SEC..3 * SEC).contains(&rx[0].t), "{}", rx[0].t);
    let rx = decode_apt(&talk(
        &mut sim,
        &req("MOT_REQ_STATUSBITS", 0x50, &[("chan_ident", 1)]),
        5 * SEC,
        6 * SEC,
    ));
    assert_eq!(rx[0].name, "MOT_GET_STATUSBITS");
    assert_ne!(rx[0].get("status_bits") & 0x400, 0, "HOMED");
    assert_eq!(rx[0].get("status_bits") & 0x200, 0, "no longer HOMING");
}

#[test]
fn stop_updatemsgs_stops_the_updates() {
    let mut sim = AptSim::new(AptModel::Tdc001);
    let rx = decode_apt(&talk(
        &mut sim,
        &req("HW_START_UPDATEMSGS", 0x50, &[]),
        0,
        SEC + 10 * MS,
    ));
    assert_eq!(rx.len(), 10, "{rx:?}");
    assert!(rx.iter().all(|r| r.name == "MOT_GET_DCSTATUSUPDATE"));
    let rx = decode_apt(&talk(
        &mut sim,
        &req("HW_STOP_UPDATEMSGS", 0x50, &[]),
        SEC + 1,
        5 * SEC,
    ));
    assert!(rx.is_empty(), "{rx:?}");
    assert_eq!(sim.next_deadline(), None);
}

#[test]
fn parameters_set_then_requested_come_back() {
    let mut sim = AptSim::new(AptModel::Kdc101);
    let set = req(
        "MOT_SET_VELPARAMS",
        0x50,
        &[
            ("chan_ident", 1),
            ("min_vel", 0),
            ("acceleration", 500),
            ("max_vel", 700_000),
        ],
    );
    sim.input(&set, 0);
    let rx = decode_apt(&talk(
        &mut sim,
        &req("MOT_REQ_VELPARAMS", 0x50, &[("chan_ident", 1)]),
        MS,
        SEC,
    ));
    assert_eq!(rx[0].name, "MOT_GET_VELPARAMS");
    assert_eq!(rx[0].get("max_vel"), 700_000);
    assert_eq!(rx[0].get("acceleration"), 500);
    for name in [
        "MOT_REQ_JOGPARAMS",
        "MOT_REQ_HOMEPARAMS",
        "MOD_REQ_CHANENABLESTATE",
    ] {
        let rx = decode_apt(&talk(
            &mut sim,
            &req(name, 0x50, &[("chan_ident", 1)]),
            SEC,
            2 * SEC,
        ));
        assert_eq!(rx.len(), 1, "{name}: {rx:?}");
        assert_eq!(rx[0].name, name.replacen("_REQ_", "_GET_", 1));
    }
    // Disabled: moves are ignored.
    sim.input(
        &req(
            "MOD_SET_CHANENABLESTATE",
            0x50,
            &[("chan_ident", 1), ("enable_state", 2)],
        ),
        2 * SEC,
    );
    let mv = req(
        "MOT_MOVE_RELATIVE",
        0x50,
        &[("chan_ident", 1), ("relative_distance", 1000)],
    );
    assert!(decode_apt(&talk(&mut sim, &mv, 3 * SEC, 10 * SEC)).is_empty());
}

#[test]
fn kpz101_output_volts_and_status_updates() {
    let mut sim = AptSim::new(AptModel::Kpz101);
    sim.input(
        &req(
            "PZ_SET_OUTPUTVOLTS",
            0x50,
            &[("chan_ident", 1), ("voltage", 16383)],
        ),
        0,
    );
    let rx = decode_apt(&talk(
        &mut sim,
        &req("PZ_REQ_OUTPUTVOLTS", 0x50, &[("chan_ident", 1)]),
        MS,
        50 * MS,
    ));
    assert_eq!(rx[0].name, "PZ_GET_OUTPUTVOLTS");
    assert_eq!(rx[0].get("voltage"), 16383);
    let rx = decode_apt(&talk(
        &mut sim,
        &req("HW_START_UPDATEMSGS", 0x50, &[]),
        SEC,
        2 * SEC,
    ));
    assert!(rx.len() >= 9);
    assert!(rx
        .iter()
        .all(|r| r.name == "PZ_GET_PZSTATUSUPDATE" && r.get("op_voltage") == 16383));
}

#[test]
fn bsc203_answers_per_bay_from_the_bay() {
    let mut sim = AptSim::new(AptModel::Bsc203);
    for (bay, state) in [(0, 1), (1, 1), (2, 1), (3, 2)] {
        let rx = decode_apt(&talk(
            &mut sim,
            &req("RACK_REQ_BAYUSED", 0x11, &[("bay_ident", bay)]),
            0,
            SEC,
        ));
        assert_eq!(rx.len(), 1);
        assert_eq!((rx[0].name.as_str(), rx[0].src), ("RACK_GET_BAYUSED", 0x11));
        assert_eq!(
            (rx[0].get("bay_ident"), rx[0].get("bay_state")),
            (bay, state)
        );
    }
    for bay in 0x21..=0x23u8 {
        let t0 = (bay as u64 - 0x20) * 10 * SEC;
        let rx = decode_apt(&talk(&mut sim, &req("HW_REQ_INFO", bay, &[]), t0, t0 + SEC));
        assert_eq!(rx.len(), 1, "bay {bay:#x}: {rx:?}");
        assert_eq!((rx[0].name.as_str(), rx[0].src), ("HW_GET_INFO", bay));
        assert_eq!(rx[0].get("serial_number") / 1_000_000, 70);
        let rx = decode_apt(&talk(
            &mut sim,
            &req("MOT_REQ_VELPARAMS", bay, &[("chan_ident", 1)]),
            t0 + SEC,
            t0 + 2 * SEC,
        ));
        assert_eq!((rx[0].name.as_str(), rx[0].src), ("MOT_GET_VELPARAMS", bay));
    }
    // Bay 0x24 does not exist: silence.
    assert!(decode_apt(&talk(
        &mut sim,
        &req("HW_REQ_INFO", 0x24, &[]),
        40 * SEC,
        41 * SEC
    ))
    .is_empty());
    let mv = req(
        "MOT_MOVE_RELATIVE",
        0x22,
        &[("chan_ident", 1), ("relative_distance", 204_800)],
    );
    let rx = decode_apt(&talk(&mut sim, &mv, 41 * SEC, 50 * SEC));
    assert_eq!(rx.len(), 1, "{rx:?}");
    assert_eq!(
        (rx[0].name.as_str(), rx[0].src),
        ("MOT_MOVE_COMPLETED", 0x22)
    );
    assert_eq!(rx[0].get("position"), 204_800);
    assert_eq!(sim.position(0x22, 50 * SEC), Some(204_800));
    assert_eq!(sim.position(0x21, 50 * SEC), Some(0));
    // Updates from every bay, each from its address, in the stepper's long form.
    let rx = decode_apt(&talk(
        &mut sim,
        &req("HW_START_UPDATEMSGS", 0x11, &[]),
        50 * SEC,
        51 * SEC + 10 * MS,
    ));
    for bay in 0x21..=0x23u8 {
        let n = rx
            .iter()
            .filter(|r| r.src == bay && r.name == "MOT_GET_STATUSUPDATE")
            .count();
        assert_eq!(n, 10, "bay {bay:#x}: {rx:?}");
    }
}

#[test]
fn stop_ends_a_velocity_move_with_stopped() {
    let mut sim = AptSim::new(AptModel::Kdc101);
    let mv = req(
        "MOT_MOVE_VELOCITY",
        0x50,
        &[("chan_ident", 1), ("direction", 1)],
    );
    assert!(decode_apt(&talk(&mut sim, &mv, 0, SEC)).is_empty());
    let stop = req(
        "MOT_MOVE_STOP",
        0x50,
        &[("chan_ident", 1), ("stop_mode", 2)],
    );
    let rx = decode_apt(&talk(&mut sim, &stop, SEC, 5 * SEC));
    assert_eq!(rx.len(), 1, "{rx:?}");
    assert_eq!(rx[0].name, "MOT_MOVE_STOPPED");
    assert!(rx[0].get("position") > 0);
}

/// A small deterministic byte generator.
fn noise(seed: u64, n: usize) -> Vec<u8> {
    let mut x = seed;
    (0..n)
        .map(|_| {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 33) as u8
        })
        .collect()
}

#[test]
fn random_input_never_panics() {
    for seed in 0..40u64 {
        let bytes = noise(seed, 3000);
        let models = [
            AptModel::Kdc101,
            AptModel::Bsc203,
            AptModel::Kpz101,
            AptModel::Tls001,
            AptModel::Ttc001,
            AptModel::Kpa101,
        ];
        let mut a = AptSim::new(models[seed as usize % models.len()]);
        let mut e = EllSim::new(&parse_modules("0:ELL14,1:ELL9,2:ELL17").unwrap()).unwrap();
        for (i, c) in bytes.chunks(7).enumerate() {
            let t = i as u64 * 3 * MS;
            a.input(c, t);
            e.input(c, t);
            while a.poll(t).is_some() {}
            while e.poll(t).is_some() {}
        }
        drive(&mut a, 10 * SEC, 20 * SEC);
        drive(&mut e, 10 * SEC, 20 * SEC);
    }
    // Every message of the table, with random data, to every address.
    let table = Table::global();
    for model in [
        AptModel::Bsc203,
        AptModel::Tls001,
        AptModel::Ttc001,
        AptModel::Kpa101,
    ] {
        every_message_with_random_data(table, model);
    }
    // Every sub-message of every PARAMS group, set with random data, then requested.
    for model in [AptModel::Tls001, AptModel::Ttc001, AptModel::Kpa101] {
        let mut sim = AptSim::new(model);
        for (i, sub) in table.subs().iter().enumerate() {
            for form in &sub.forms {
                let aptscope_dissector::table::FormKind::Data(n) = form.kind else {
                    continue;
                };
                for m in table.msgs().iter().filter(|m| m.subs == Some(sub.group)) {
                    let mut b = noise(i as u64 + 7, 6 + n as usize);
                    b[0..2].copy_from_slice(&m.id.to_le_bytes());
                    b[2..4].copy_from_slice(&n.to_le_bytes());
                    b[4] = 0x50 | 0x80;
                    b[5] = 0x01;
                    b[6..8].copy_from_slice(&sub.id.to_le_bytes());
                    sim.input(&b, i as u64 * MS);
                    let mut r = vec![0u8; 6];
                    r[0..2].copy_from_slice(&m.id.to_le_bytes());
                    r[2] = sub.id as u8;
                    r[4] = 0x50;
                    r[5] = 0x01;
                    sim.input(&r, i as u64 * MS);
                }
            }
        }
        drive(&mut sim, 0, 100 * SEC);
    }
}

fn every_message_with_random_data(table: &Table, model: AptModel) {
    let mut sim = AptSim::new(model);
    for (i, m) in table.msgs().iter().enumerate() {
        for dst in [0x11u8, 0x21, 0x50] {
            let mut b = noise(i as u64, 6 + 14);
            b[0..2].copy_from_slice(&m.id.to_le_bytes());
            b[4] = dst;
            b[5] = 0x01;
            if i % 2 == 0 {
                b[4] |= 0x80;
                b[2] = 14;
                b[3] = 0;
            } else {
                b.truncate(6);
            }
            sim.input(&b, i as u64 * MS);
        }
    }
    drive(&mut sim, 0, 100 * SEC);
}

// ---------------------------------------------------------------------------------- Elliptec

fn ell_text(chunks: &[(u64, Vec<u8>)]) -> Vec<(u64, String)> {
    chunks
        .iter()
        .map(|(t, b)| (*t, String::from_utf8_lossy(b).into_owned()))
        .collect()
}

fn bus() -> EllSim {
    EllSim::new(&parse_modules("0:ELL14,1:ELL9,2:ELL17").unwrap()).unwrap()
}

#[test]
fn ell_in_identifies_each_module_at_9600_baud() {
    let mut sim = bus();
    let out = ell_text(&talk(&mut sim, b"0in", 0, SEC));
    assert_eq!(out.len(), 1);
    let (t, s) = &out[0];
    assert!(
        s.starts_with("0IN0E") && s.ends_with("016800023000\r\n"),
        "{s}"
    );
    assert_eq!(s.len(), 35);
    // 35 bytes at 9600 baud (≈1.04 ms each) after the turnaround.
    assert!(*t >= 35 * 1_041_667 && *t < 45 * MS, "{t}");
    let out = ell_text(&talk(&mut sim, b"1in\r\n", SEC, 2 * SEC));
    assert!(out[0].1.starts_with("1IN09"), "{:?}", out);
    // Nobody at address 5.
    assert!(talk(&mut sim, b"5in", 2 * SEC, 3 * SEC).is_empty());
    // Two commands back to back: the replies follow each other on the line.
    let out = talk(&mut sim, b"0gs1gs", 3 * SEC, 4 * SEC);
    let all: String = ell_text(&out).into_iter().map(|(_, s)| s).collect();
    assert_eq!(all, "0GS00\r\n1GS00\r\n");
    let last = out.last().unwrap().0;
    assert!(last - 3 * SEC >= 14 * 1_041_667, "{}", last - 3 * SEC);
}

#[test]
fn ell_move_absolute_then_position() {
    let mut sim = bus();
    sim.input(b"0ma00008C00", 0); // 90 degrees
    assert_eq!(ell_text(&drive(&mut sim, 0, 50 * MS)), vec![]);
    let busy = ell_text(&talk(&mut sim, b"0gs", 60 * MS, 100 * MS));
    assert_eq!(busy[0].1, "0GS09\r\n");
    let out = ell_text(&drive(&mut sim, 100 * MS, 5 * SEC));
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].1, "0PO00008C00\r\n");
    // 90° at 430°/s plus the start-up: about 260 ms.
    assert!((200 * MS..400 * MS).contains(&out[0].0), "{}", out[0].0);
    let out = ell_text(&talk(&mut sim, b"0gp", 5 * SEC, 6 * SEC));
    assert_eq!(out[0].1, "0PO00008C00\r\n");
    // Relative, home, velocity, an out-of-range move on the linear stage.
    let out = ell_text(&talk(&mut sim, b"0mr00002300", 6 * SEC, 8 * SEC));
    assert_eq!(out[0].1, "0PO0000AF00\r\n");
    let out = ell_text(&talk(&mut sim, b"0ho0", 8 * SEC, 10 * SEC));
    assert_eq!(out[0].1, "0PO00000000\r\n");
    assert_eq!(
        ell_text(&talk(&mut sim, b"0gv", 10 * SEC, 11 * SEC))[0].1,
        "0GV64\r\n"
    );
    let out = ell_text(&talk(&mut sim, b"2ma0000F000", 11 * SEC, 12 * SEC));
    assert_eq!(out[0].1, "2GS0C\r\n");
    let out = ell_text(&talk(&mut sim, b"1fw", 12 * SEC, 14 * SEC));
    assert_eq!(out[0].1, "1PO0000001F\r\n");
    let out = ell_text(&talk(&mut sim, b"0zz\r\n", 14 * SEC, 15 * SEC));
    assert_eq!(out[0].1, "0GS03\r\n");
}

#[test]
fn ell_change_address_takes_effect() {
    let mut sim = bus();
    let out = ell_text(&talk(&mut sim, b"0ca3", 0, SEC));
    assert_eq!(out[0].1, "3GS00\r\n");
    assert!(
        talk(&mut sim, b"0gp", SEC, 2 * SEC).is_empty(),
        "nobody at 0 now"
    );
    let out = ell_text(&talk(&mut sim, b"3in", 2 * SEC, 3 * SEC));
    assert!(out[0].1.starts_with("3IN0E"));
    assert_eq!(sim.addresses(), vec![3, 1, 2]);
    // Back, with the manual's spacing.
    let out = ell_text(&talk(&mut sim, b"3ca1", 3 * SEC, 4 * SEC));
    assert_eq!(out[0].1, "1GS00\r\n");
    // Now two modules answer at 1 (a bus collision, as on real hardware).
    let out = ell_text(&talk(&mut sim, b"1gs", 4 * SEC, 5 * SEC));
    let all: String = out.into_iter().map(|(_, s)| s).collect();
    assert_eq!(all, "1GS00\r\n1GS00\r\n");
}

// ------------------------------------------------------------------- laser, TEC, quad (PARAMS)

/// A frame from the table as `aptscope encode` builds it (`NAME:SUB` for sub-messages).
fn enc(name: &str, args: &str) -> Vec<u8> {
    let (name, sub) = match name.split_once(':') {
        Some((m, s)) => (m, Some(s)),
        None => (name, None),
    };
    let values: Vec<(&str, &str)> = args
        .split_whitespace()
        .filter_map(|a| a.split_once('='))
        .collect();
    let named = aptscope_dissector::apt::Named {
        name,
        sub,
        values: &values,
        form: None,
        dst: 0x50,
        src: 0x01,
    };
    aptscope_dissector::apt::encode_named(Table::global(), &named).unwrap_or_else(|e| panic!("{e}"))
}

/// Send each frame in turn (10 ms apart) and decode everything that comes back.
fn exchange<S: Simulator>(sim: &mut S, frames: &[Vec<u8>]) -> Vec<Rx> {
    let mut out = vec![];
    for (i, f) in frames.iter().enumerate() {
        let t = 1000 + i as u64 * 10 * MS;
        out.extend(talk(sim, f, t, t + 10 * MS - 1));
    }
    decode_apt(&out)
}

#[test]
fn model_names_parse_and_are_listed() {
    for m in AptModel::all() {
        let n = m.name().to_ascii_lowercase();
        assert_eq!(AptModel::parse(&n), Some(m), "{n}");
        assert!(m.profile().is_some(), "{n}: no device profile in the table");
        assert!(model_list().contains(&format!("\n{} ", m.name())), "{n}");
    }
    assert_eq!(AptModel::parse("KDC102"), None);
}

#[test]
fn tls001_remembers_the_setpoint_and_reports_power_while_the_output_is_on() {
    let mut sim = AptSim::new(AptModel::Tls001);
    let rx = exchange(
        &mut sim,
        &[
            enc("LA_REQ_PARAMS", "sub_id=9"),
            enc("LA_SET_PARAMS:SETPOINT", "setpoint=16384"),
            enc("LA_REQ_PARAMS", "sub_id=1"),
            enc("LA_REQ_PARAMS", "sub_id=3"),
            enc("LA_ENABLEOUTPUT", ""),
            enc("LA_REQ_PARAMS", "sub_id=3"),
            enc("LA_REQ_PARAMS", "sub_id=7"),
            enc("LA_REQ_STATUSUPDATE", ""),
            enc("LA_DISABLEOUTPUT", ""),
            enc("LA_REQ_PARAMS", "sub_id=7"),
            // A block the model does not have, and a move it cannot make: no answer.
            enc("LA_REQ_PARAMS", "sub_id=13"),
            req("MOT_MOVE_HOME", 0x50, &[("chan_ident", 1)]),
        ],
    );
    let names: Vec<&str> = rx.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "LA_GET_PARAMS",
            "LA_GET_PARAMS",
            "LA_GET_PARAMS",
            "LA_GET_PARAMS",
            "LA_GET_PARAMS",
            "LA_GET_STATUSUPDATE",
            "LA_GET_PARAMS"
        ]
    );
    assert!(rx.iter().all(|r| (r.src, r.dst) == (0x50, 0x01)));
    assert_eq!(rx[0].get("sub_id"), 9);
    assert_eq!(rx[0].get("wavelength"), 635);
    assert_eq!((rx[1].get("sub_id"), rx[1].get("setpoint")), (1, 16384));
    // Output off: no power; on: the setpoint.
    assert_eq!(
        (rx[2].get("laser_power"), rx[2].get("laser_current")),
        (0, 0)
    );
    assert_eq!(rx[3].get("laser_power"), 16384);
    assert!(rx[3].get("laser_current") > 0);
    assert_eq!(rx[4].get("status_bits") & 1, 1);
    assert_eq!(rx[5].get("laser_power"), 16384);
    assert_eq!(rx[6].get("status_bits") & 1, 0);
}

#[test]
fn ttc001_holds_the_set_temperature() {
    let mut sim = AptSim::new(AptModel::Ttc001);
    let rx = exchange(
        &mut sim,
        &[
            enc("TEC_SET_PARAMS:TEMP_SETPOINT", "t_set=2000"),
            enc("TEC_REQ_PARAMS", "sub_id=1"),
            enc(
                "TEC_SET_PARAMS:LOOP_PARAMS",
                "p_gain=100 i_gain=200 d_gain=300",
            ),
            enc("TEC_REQ_PARAMS", "sub_id=9"),
            enc("TEC_REQ_PARAMS", "sub_id=3"),
            enc("TEC_REQ_PARAMS", "sub_id=7"),
            enc("TEC_REQ_STATUSUPDATE", ""),
        ],
    );
    let names: Vec<&str> = rx.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(names[..4], ["TEC_GET_PARAMS"; 4]);
    assert_eq!(names[4], "TEC_GET_STATUSUPDATE");
    assert_eq!(rx[0].get("t_set"), 2000);
    assert_eq!(
        (
            rx[1].get("p_gain"),
            rx[1].get("i_gain"),
            rx[1].get("d_gain")
        ),
        (100, 200, 300)
    );
    assert_eq!((rx[2].get("t_act"), rx[2].get("t_set")), (2000, 2000));
    assert_eq!(rx[3].get("status_bits") & 1, 1);
    assert_eq!(rx[4].get("t_act"), 2000);
}

#[test]
fn kpa101_operating_mode_drives_readings_and_status() {
    let mut sim = AptSim::new(AptModel::Kpa101);
    let rx = exchange(
        &mut sim,
        &[
            enc("QUAD_REQ_PARAMS", "sub_id=9"),
            enc(
                "QUAD_SET_PARAMS:POS_DEMAND_OUTPUTS",
                "x_pos=-2400 y_pos=1600",
            ),
            enc("QUAD_SET_PARAMS:OPER_MODE", "mode=OPEN_LOOP"),
            enc("QUAD_REQ_PARAMS", "sub_id=3"),
            enc("QUAD_SET_PARAMS:OPER_MODE", "mode=CLOSED_LOOP"),
            enc("QUAD_REQ_PARAMS", "sub_id=7"),
            enc("QUAD_REQ_PARAMS", "sub_id=9"),
            enc("QUAD_REQ_PARAMS", "sub_id=14"),
            enc("HW_START_UPDATEMSGS", ""),
        ],
    );
    let names: Vec<&str> = rx.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(names, ["QUAD_GET_PARAMS"; 5]);
    assert_eq!(rx[0].get("status_bits"), 0x1); // monitor
    assert_eq!((rx[1].get("x_pos"), rx[1].get("y_pos")), (-2400, 1600));
    assert!(rx[1].get("x_diff") != 0);
    assert_eq!(rx[2].get("mode"), 3);
    assert_eq!(rx[3].get("status_bits"), 0x4); // closed loop
    assert_eq!(rx[4].get("sub_id"), 14);
    // Status updates every 100 ms.
    let t = 1000 + 9 * 10 * MS;
    let ups = decode_apt(&drive(&mut sim, t, t + 350 * MS));
    assert_eq!(ups.len(), 3, "{ups:?}");
    assert!(ups.iter().all(|u| u.name == "QUAD_GET_STATUSUPDATE"));
    assert_eq!(ups[0].get("status_bits"), 0x4);
}
