//! Every model of the spec, by family: each request of its message list is answered, and what
//! comes back decodes without a diagnostic.

use super::apt::build;
use super::models::Family;
use super::*;
use aptscope_dissector::apt::{AptFrame, AptFramer, FieldValue, Item};
use aptscope_dissector::table::Access;
use aptscope_dissector::Table;

/// Every frame in `bytes`, each checked for diagnostics.
fn frames(bytes: &[u8]) -> Vec<Vec<u8>> {
    let mut fr = AptFramer::new(Table::global());
    fr.push(bytes);
    let mut out = vec![];
    while let Some(item) = fr.next_item() {
        match item {
            Item::Frame { bytes, .. } => out.push(bytes.to_vec()),
            other => panic!("not a frame: {other:?}"),
        }
    }
    out
}

/// Send each request of each model of `family` and check its answer.
fn every_request_answered(family: Family) {
    let t = Table::global();
    let mut models = 0;
    for model in AptModel::all().filter(|m| m.spec().family == family) {
        models += 1;
        let profile = model.profile().expect("every model has a profile");
        let rack = model.spec().bays > 0;
        let mut sim = AptSim::new(model);
        let mut now = 1000;
        let mut asked = 0;
        for m in t.msgs() {
            if !t.implements(&profile, m.id) || !m.name.contains("_REQ_") {
                continue;
            }
            if !matches!(t.readback_of(m), Some((_, Access::Req))) && t.replies_of(m).is_empty() {
                continue;
            }
            let dst = match (rack, m.name.starts_with("RACK_") || m.name == "HW_REQ_INFO") {
                (true, true) => 0x11,
                (true, false) => 0x21,
                (false, _) => 0x50,
            };
            let subs: Vec<u16> = match m.subs {
                Some(g) => t
                    .subs()
                    .iter()
                    .filter(|s| s.group == g)
                    .map(|s| s.id)
                    .collect(),
                None => vec![0],
            };
            let mut answered = 0;
            for sub in &subs {
                let mut vals = vec![("chan_ident", FieldValue::Int(1))];
                if m.subs.is_some() {
                    vals.push(("sub_id", FieldValue::Int(i64::from(*sub))));
                }
                let req = build(m.id, None, dst, 0x01, &vals)
                    .unwrap_or_else(|| panic!("{}: cannot build {}", model.name(), m.name));
                sim.input(&req, now);
                let mut out = vec![];
                let until = now + 50 * MS;
                while let Some(d) = sim.next_deadline().filter(|d| *d <= until) {
                    if let Some(b) = sim.poll(d) {
                        out.extend(b);
                    }
                }
                now = until;
                let replies = t.reply_ids(m);
                for f in frames(&out) {
                    let fr = AptFrame::decode(t, 0, &f, false).expect("frame");
                    let diags: Vec<String> = fr.diags().map(|d| d.to_string()).collect();
                    assert!(
                        diags.is_empty(),
                        "{}: {} answered with {:?} {diags:?}",
                        model.name(),
                        m.name,
                        fr.name()
                    );
                    let id = fr.msg.map_or(0, |x| x.id);
                    assert!(
                        t.implements(&profile, id),
                        "{}: {} answered with {:?}, not the model's",
                        model.name(),
                        m.name,
                        fr.name()
                    );
                    if replies.contains(&id) {
                        answered += 1;
                    }
                }
            }
            assert!(
                answered > 0,
                "{}: {} not answered (subs {subs:?})",
                model.name(),
                m.name
            );
            asked += 1;
        }
        assert!(asked > 0, "{}: no request in its list", model.name());
    }
    assert!(models > 0, "no model of {family:?}");
}

#[test]
fn dc_servo_models_answer_every_request() {
    every_request_answered(Family::DcServo);
}

#[test]
fn brushless_models_answer_every_request() {
    every_request_answered(Family::Brushless);
}

#[test]
fn stepper_models_answer_every_request() {
    every_request_answered(Family::Stepper);
}

#[test]
fn solenoid_models_answer_every_request() {
    every_request_answered(Family::Solenoid);
}

#[test]
fn flipper_models_answer_every_request() {
    every_request_answered(Family::Flipper);
}

#[test]
fn piezo_models_answer_every_request() {
    every_request_answered(Family::Piezo);
}

#[test]
fn strain_gauge_models_answer_every_request() {
    every_request_answered(Family::StrainGauge);
}

#[test]
fn nanotrak_models_answer_every_request() {
    every_request_answered(Family::NanoTrak);
}

#[test]
fn laser_models_answer_every_request() {
    every_request_answered(Family::Laser);
}

#[test]
fn laser_diode_models_answer_every_request() {
    every_request_answered(Family::LaserDiode);
}

#[test]
fn tec_models_answer_every_request() {
    every_request_answered(Family::Tec);
}

#[test]
fn quad_models_answer_every_request() {
    every_request_answered(Family::Quad);
}

#[test]
fn inertia_motor_models_answer_every_request() {
    every_request_answered(Family::InertiaMotor);
}

#[test]
fn polariser_models_answer_every_request() {
    every_request_answered(Family::Polariser);
}

#[test]
fn a_strain_gauge_zeroes_its_reading() {
    let t = Table::global();
    let mut sim = AptSim::new(AptModel::parse("ksg101").expect("model"));
    let ask = |sim: &mut AptSim, id: u16, now: u64| {
        let req = build(id, None, 0x50, 0x01, &[("chan_ident", FieldValue::Int(1))]).expect("req");
        sim.input(&req, now);
        let mut out = vec![];
        while let Some(d) = sim.next_deadline().filter(|d| *d <= now + 50 * MS) {
            out.extend(sim.poll(d).unwrap_or_default());
        }
        out
    };
    let reading = |b: &[u8]| {
        let f = AptFrame::decode(t, 0, b, false).expect("frame");
        f.field("reading").and_then(|(_, v)| v.as_i64())
    };
    let before = ask(&mut sim, aptscope_dissector::msg::PZ_REQ_TSG_READING, 1000);
    assert_ne!(
        reading(&before),
        Some(0),
        "the spec's example reading first"
    );
    ask(&mut sim, aptscope_dissector::msg::PZ_SET_ZERO, 100 * MS);
    let after = ask(
        &mut sim,
        aptscope_dissector::msg::PZ_REQ_TSG_READING,
        200 * MS,
    );
    assert_eq!(reading(&after), Some(0));
}

/// Send `req` at `now` and decode what comes back within 50 ms: (message id, source).
fn exchange(sim: &mut AptSim, req: &[u8], now: u64) -> Vec<(u16, u8)> {
    sim.input(req, now);
    let mut out = vec![];
    while let Some(d) = sim.next_deadline().filter(|d| *d <= now + 50 * MS) {
        out.extend(sim.poll(d).unwrap_or_default());
    }
    frames(&out)
        .iter()
        .map(|f| (u16::from_le_bytes([f[0], f[1]]), f[5]))
        .collect()
}

#[test]
fn a_single_unit_answers_at_0x50_and_0x21_from_the_address_named_and_ignores_the_rest() {
    use aptscope_dissector::msg;
    let mut sim = AptSim::new(AptModel::Tdc001);
    let vel = |dst| build(msg::MOT_REQ_VELPARAMS, None, dst, 0x01, &[]).expect("req");
    assert_eq!(
        exchange(&mut sim, &vel(0x50), 1000),
        [(msg::MOT_GET_VELPARAMS, 0x50)]
    );
    assert_eq!(
        exchange(&mut sim, &vel(0x21), 100 * MS),
        [(msg::MOT_GET_VELPARAMS, 0x21)]
    );
    assert_eq!(exchange(&mut sim, &vel(0x22), 200 * MS), []);
    // Not a TDC001's message: ignored, and the log says so.
    let pz = build(msg::PZ_REQ_OUTPUTVOLTS, None, 0x50, 0x01, &[]).expect("req");
    assert_eq!(exchange(&mut sim, &pz, 300 * MS), []);
    let log = sim.take_log();
    assert_eq!(log.len(), 2, "{log:?}");
    assert!(log[0].contains("no such unit"), "{log:?}");
    assert!(
        log[1].contains("PZ_REQ_OUTPUTVOLTS") && log[1].contains("not a message the TDC001"),
        "{log:?}"
    );
}

#[test]
fn status_updates_stop_after_50_without_the_hosts_ack_and_resume_with_it() {
    use aptscope_dissector::msg;
    let count = |sim: &mut AptSim, from: u64, to: u64| {
        let mut out = vec![];
        let mut t = from;
        while let Some(d) = sim.next_deadline().filter(|d| *d <= to) {
            t = t.max(d);
            out.extend(sim.poll(t).unwrap_or_default());
        }
        frames(&out).len()
    };
    // Without ACK: 50 updates, then silence.
    let mut sim = AptSim::new(AptModel::Kdc101);
    let start = build(msg::HW_START_UPDATEMSGS, None, 0x50, 0x01, &[]).expect("start");
    sim.input(&start, 0);
    assert_eq!(count(&mut sim, 0, 20 * SEC), 50);
    assert!(sim.take_log().iter().any(|l| l.contains("stopped")));
    // A late ACK: they resume.
    let ack = build(msg::MOT_ACK_DCSTATUSUPDATE, None, 0x50, 0x01, &[]).expect("ack");
    sim.input(&ack, 20 * SEC);
    // 20.1 s … 21.0 s; the last is still on the line at 21 s.
    assert_eq!(count(&mut sim, 20 * SEC, 21 * SEC), 9);
    // With an ACK every second (as thorlabs-apt-device sends it): they go on.
    let mut sim = AptSim::new(AptModel::Kdc101);
    sim.input(&start, 0);
    let mut n = 0;
    for s in 0..20 {
        n += count(&mut sim, s * SEC, (s + 1) * SEC - 1);
        sim.input(&ack, (s + 1) * SEC - 1);
    }
    assert_eq!(n, 199, "updates in 20 s");
}

#[test]
fn a_nanotrak_reports_the_mode_it_was_set_to() {
    use aptscope_dissector::msg;
    let t = Table::global();
    let mut sim = AptSim::new(AptModel::parse("kna101").expect("model"));
    let track = build(
        msg::PZ_SET_NTMODE,
        None,
        0x50,
        0x01,
        &[("state", FieldValue::Int(3))],
    );
    sim.input(&track.expect("set"), 1000);
    let req = |id| build(id, None, 0x50, 0x01, &[]).expect("req");
    let mut out = vec![];
    for (i, id) in [msg::PZ_REQ_NTMODE, msg::PZ_REQ_NTSTATUSUPDATE]
        .into_iter()
        .enumerate()
    {
        let now = (i as u64 + 1) * 100 * MS;
        sim.input(&req(id), now);
        while let Some(d) = sim.next_deadline().filter(|d| *d <= now + 50 * MS) {
            out.extend(sim.poll(d).unwrap_or_default());
        }
    }
    let fs = frames(&out);
    assert_eq!(fs.len(), 2);
    let get = |b: &[u8], n: &str| {
        let f = AptFrame::decode(t, 0, b, false).expect("frame");
        f.field(n).and_then(|(_, v)| v.as_i64())
    };
    // TRACKING_SIGNAL, DUAL_AXIS; TRACKING | TRACKING_WITH_SIGNAL and both channels.
    assert_eq!(
        (get(&fs[0], "state"), get(&fs[0], "mode")),
        (Some(4), Some(1))
    );
    assert_eq!(get(&fs[1], "status_bits"), Some(0x3_0003));
}
