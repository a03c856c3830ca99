//! Decoded values a reader need not decode again (issue: "what a new user trips over").

use aptscope_dissector::apt::{encode_named, Named};
use aptscope_dissector::pipeline::{Format, Pipeline};
use aptscope_dissector::Table;

fn frame(name: &str, values: &[(&str, &str)], dst: u8, src: u8) -> Vec<u8> {
    encode_named(
        Table::global(),
        &Named {
            name,
            sub: None,
            values,
            form: None,
            dst,
            src,
        },
    )
    .unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn decode(bytes: &[u8], fmt: Format) -> Vec<String> {
    let mut p = Pipeline::new(None, fmt);
    let mut out: Vec<String> = vec![];
    let mut emit = |l: &str| -> Result<(), ()> {
        out.push(l.to_string());
        Ok(())
    };
    p.push(bytes, None, &mut emit).unwrap();
    p.finish(&mut emit).unwrap();
    out
}

#[test]
fn hw_get_info_notes_are_text() {
    let b = frame(
        "HW_GET_INFO",
        &[
            ("serial_number", "27000123"),
            ("model_number", "KDC101"),
            ("notes", "Brushed DC motor controller"),
        ],
        0x01,
        0x50,
    );
    let out = decode(&b, Format::Json);
    let v: serde_json::Value = serde_json::from_str(&out[1]).expect("json");
    assert_eq!(v["fields"]["notes"], "Brushed DC motor controller", "{v}");
}

#[test]
fn an_unknown_enum_value_names_its_enum() {
    let b = frame(
        "HW_GET_INFO",
        &[
            ("model_number", "MFF002"),
            ("hw_type", "16"),
            ("serial_number", "-1"),
        ],
        0x01,
        0x50,
    );
    let out = decode(&b, Format::Text);
    assert!(
        out.iter()
            .any(|l| l.contains("hw_type=16(not in enum hw_type)")),
        "{out:#?}"
    );
    assert!(
        out.iter().any(|l| l.contains("serial_number=-1")),
        "{out:#?}"
    );
}

#[test]
fn rack_bays_are_numbered_as_their_addresses() {
    let mut b = frame("RACK_REQ_BAYUSED", &[("bay_ident", "0")], 0x11, 0x01);
    b.extend(frame(
        "RACK_GET_BAYUSED",
        &[("bay_ident", "BAY0"), ("bay_state", "OCCUPIED")],
        0x01,
        0x11,
    ));
    b.extend(frame("HW_REQ_INFO", &[], 0x21, 0x01));
    let out = decode(&b, Format::Text);
    assert!(out.iter().any(|l| l.contains("bay_ident=BAY0")), "{out:#?}");
    assert!(out.iter().any(|l| l.contains("→ bay0")), "{out:#?}");
}

#[test]
fn elliptec_model_and_firmware_also_as_the_text_shows_them() {
    let out = decode(b"1in1IN0911300123202315010013000000020\r\n", Format::Json);
    let v: serde_json::Value = out
        .iter()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .find(|v| v["cmd"] == "IN")
        .expect("IN record");
    let f = &v["fields"];
    assert_eq!(
        (f["model"].as_u64(), f["model_name"].as_str()),
        (Some(9), Some("ELL9")),
        "{v}"
    );
    assert_eq!(
        (f["firmware"].as_u64(), f["firmware_version"].as_str()),
        (Some(0x15), Some("1.5")),
        "{v}"
    );
}
