//! Which messages each controller implements (the spec's device lists), and the diagnostic for a
//! message the device's model does not implement.

mod common;

use aptscope_dissector::table::{model_matches, DeviceSource};
use aptscope_dissector::Table;
use common::kinds;

fn frame(name: &str, values: &[(&str, &str)], dst: u8, src: u8) -> Vec<u8> {
    common::frame(name, values, None, dst, src)
}

fn decode_json(bytes: &[u8]) -> Vec<serde_json::Value> {
    common::decode_json(bytes, 0)
        .into_iter()
        .filter(|v| v["type"] == "frame")
        .collect()
}

#[test]
fn model_patterns_follow_the_spec_spelling() {
    assert!(model_matches("BSC20x", "BSC203"));
    assert!(model_matches("KLSxxx", "kls635"));
    assert!(model_matches("KDC101", "KDC101 "));
    assert!(!model_matches("BSC20x", "BSC2030"));
    assert!(!model_matches("KDC101", "TDC001"));
}

#[test]
fn every_device_list_is_in_the_table() {
    let t = Table::global();
    assert!(
        t.devices().len() >= 35,
        "{} device lists",
        t.devices().len()
    );
    let home = t.msg_by_name("MOT_MOVE_HOME").expect("MOT_MOVE_HOME");
    let models = t.models_of(home);
    for m in ["TDC001", "KDC101", "BSC20x", "KBD101", "K10CR1"] {
        assert!(models.contains(&m), "{m} homes: {models:?}");
    }
    let kdc = t.device_profile("KDC101").expect("KDC101 is listed");
    let volts = t.msg_by_name("PZ_SET_OUTPUTVOLTS").expect("msg");
    assert!(!t.implements(&kdc, volts.id));
    assert!(t.implements(&kdc, home.id));
    assert!(t.device_profile("XYZ999").is_none());
    // Every listed model has a profile whatever its length, with spaces around it; models
    // listed nowhere have none, of a length some model has or of one none has.
    for g in t.devices() {
        for m in &g.models {
            let named = format!(" {} ", m.replace('x', "1"));
            let listed = t.devices().iter().any(|g| {
                g.source == DeviceSource::List && g.models.iter().any(|p| model_matches(p, &named))
            });
            assert_eq!(t.device_profile(&named).is_some(), listed, "{named}");
        }
    }
    assert!(t.device_profile(" KDC101 ").is_some());
    assert!(t.device_profile("KDC1011").is_none() && t.device_profile("KDC10").is_none());
    assert!(t.device_profile(&"K".repeat(70)).is_none());
}

#[test]
fn a_message_the_named_model_does_not_implement_is_flagged() {
    let mut s = frame("HW_REQ_INFO", &[], 0x50, 0x01);
    s.extend(frame(
        "HW_GET_INFO",
        &[("serial_number", "27000123"), ("model_number", "KDC101")],
        0x01,
        0x50,
    ));
    s.extend(frame("MOT_MOVE_HOME", &[("chan_ident", "1")], 0x50, 0x01));
    s.extend(frame(
        "PZ_SET_OUTPUTVOLTS",
        &[("chan_ident", "1"), ("voltage", "100")],
        0x50,
        0x01,
    ));
    let recs = decode_json(&s);
    let names: Vec<_> = recs
        .iter()
        .map(|r| r["name"].as_str().unwrap_or(""))
        .collect();
    assert_eq!(
        names,
        [
            "HW_REQ_INFO",
            "HW_GET_INFO",
            "MOT_MOVE_HOME",
            "PZ_SET_OUTPUTVOLTS"
        ]
    );
    assert!(!kinds(&recs[2]).contains(&"not_for_model"));
    assert!(kinds(&recs[3]).contains(&"not_for_model"), "{}", recs[3]);
    let msg = recs[3]["diag"].to_string();
    assert!(msg.contains("KDC101"), "{msg}");
}

#[test]
fn an_unknown_model_flags_nothing() {
    let mut s = frame(
        "HW_GET_INFO",
        &[("serial_number", "-1"), ("model_number", "MFF002")],
        0x01,
        0x50,
    );
    s.extend(frame(
        "PZ_SET_OUTPUTVOLTS",
        &[("chan_ident", "1"), ("voltage", "100")],
        0x50,
        0x01,
    ));
    let recs = decode_json(&s);
    assert!(
        !recs[1]["diag"].to_string().contains("not_for_model"),
        "{}",
        recs[1]
    );
}
