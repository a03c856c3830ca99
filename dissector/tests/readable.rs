//! Decoded values a reader need not decode again (issue: "what a new user trips over").

mod common;

use aptscope_dissector::pipeline::Format;

fn frame(name: &str, values: &[(&str, &str)], dst: u8, src: u8) -> Vec<u8> {
    common::frame(name, values, None, dst, src)
}

fn decode(bytes: &[u8], fmt: Format) -> Vec<String> {
    common::decode_lines(bytes, fmt, 0)
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

/// Piezo percentages in volts and micrometres once the device has reported its voltage limit
/// and travel (PZ_GET_OUTPUTMAXVOLTS, PZ_GET_MAXTRAVEL); before that, in % as the spec gives.
#[test]
fn piezo_percentages_in_volts_and_micrometres_once_the_maxima_are_known() {
    let volts = |v: &str| {
        frame(
            "PZ_GET_OUTPUTVOLTS",
            &[("chan_ident", "1"), ("voltage", v)],
            0x01,
            0x50,
        )
    };
    let mut b = volts("16384");
    b.extend(frame(
        "PZ_GET_OUTPUTMAXVOLTS",
        &[
            ("chan_ident", "1"),
            ("voltage", "1500"),
            ("flags", "LIMIT_150V"),
        ],
        0x01,
        0x50,
    ));
    b.extend(volts("32767"));
    b.extend(frame(
        "PZ_GET_MAXTRAVEL",
        &[("chan_ident", "1"), ("travel", "200")],
        0x01,
        0x50,
    ));
    b.extend(frame(
        "PZ_GET_OUTPUTPOS",
        &[("chan_ident", "1"), ("position_sw", "16384")],
        0x01,
        0x50,
    ));
    let recs: Vec<serde_json::Value> = decode(&b, Format::Json)
        .iter()
        .filter_map(|l| serde_json::from_str(l).ok())
        .filter(|v: &serde_json::Value| v["type"] == "frame")
        .collect();
    let phys = |i: usize, f: &str| {
        (
            recs[i]["phys"][f]["value"].as_f64(),
            recs[i]["phys"][f]["unit"].clone(),
        )
    };
    let (pct, unit) = phys(0, "voltage");
    assert_eq!(unit, "%");
    assert!((pct.unwrap_or(0.0) - 50.0).abs() < 0.01);
    let (v, unit) = phys(2, "voltage");
    assert_eq!(unit, "V");
    assert!((v.unwrap_or(0.0) - 150.0).abs() < 1e-6, "{v:?}");
    let (um, unit) = phys(4, "position_sw");
    assert_eq!(unit, "um");
    assert!((um.unwrap_or(0.0) - 10.0).abs() < 0.01, "{um:?}");
    let text = decode(&b, Format::Text).join("\n");
    assert!(text.contains("voltage=32767 (150 V)"), "{text}");
}
