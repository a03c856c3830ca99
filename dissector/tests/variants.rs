//! Real devices deviate from the spec: each variant described in the issue tracker, in the
//! shape the devices send it, decodes as its message with a diagnostic that explains it.

mod common;

use common::{frame, kinds};
use serde_json::Value;

/// Records of a stream fed in chunks of `step` bytes (0: all at once).
fn decode(bytes: &[u8], step: usize) -> Vec<Value> {
    common::decode_json(bytes, step)
}

fn names(recs: &[Value]) -> Vec<String> {
    recs.iter()
        .map(|r| match r["type"].as_str() {
            Some("frame") => r["name"].as_str().unwrap_or("UNKNOWN").to_string(),
            t => t.unwrap_or("?").to_string(),
        })
        .collect()
}

#[test]
fn replies_with_zero_addresses_are_frames_with_an_explanation() {
    // TDC001: replies with destination and source 0x00.
    let mut s = frame("HW_REQ_INFO", &[], None, 0x50, 0x01);
    s.extend(frame(
        "HW_GET_INFO",
        &[("serial_number", "83000001"), ("model_number", "TDC001")],
        None,
        0x00,
        0x00,
    ));
    let recs = decode(&s, 0);
    assert_eq!(names(&recs), ["HW_REQ_INFO", "HW_GET_INFO"]);
    assert_eq!(kinds(&recs[1]), ["zero_addresses"], "{}", recs[1]);
    assert_eq!(recs[1]["pair"], 1, "the reply is paired with its request");
    assert_eq!(recs[1]["fields"]["model_number"], "TDC001");
}

#[test]
fn a_move_completed_with_zero_addresses_on_connect_is_decoded() {
    // BSC201: an unsolicited header-only MOVE_COMPLETED with both addresses 0 on connect.
    let mut s = vec![0x64, 0x04, 0x01, 0x00, 0x00, 0x00];
    s.extend(frame("HW_REQ_INFO", &[], None, 0x50, 0x01));
    let recs = decode(&s, 0);
    assert_eq!(names(&recs)[..2], ["MOT_MOVE_COMPLETED", "HW_REQ_INFO"]);
    let k = kinds(&recs[0]);
    assert!(k.contains(&"zero_addresses"), "{k:?}");
}

#[test]
fn move_completed_decodes_header_only_and_with_status() {
    let mut s = frame(
        "MOT_MOVE_ABSOLUTE",
        &[("chan_ident", "1"), ("absolute_position", "1000")],
        Some("6"),
        0x50,
        0x01,
    );
    s.extend(frame(
        "MOT_MOVE_COMPLETED",
        &[("chan_ident", "1")],
        Some("hdr"),
        0x01,
        0x50,
    ));
    s.extend(frame(
        "MOT_MOVE_ABSOLUTE",
        &[("chan_ident", "1"), ("absolute_position", "0")],
        Some("6"),
        0x50,
        0x01,
    ));
    s.extend(frame(
        "MOT_MOVE_COMPLETED",
        &[("chan_ident", "1"), ("position", "0")],
        Some("14"),
        0x01,
        0x50,
    ));
    let recs = decode(&s, 0);
    assert_eq!(
        names(&recs),
        [
            "MOT_MOVE_ABSOLUTE",
            "MOT_MOVE_COMPLETED",
            "MOT_MOVE_ABSOLUTE",
            "MOT_MOVE_COMPLETED"
        ]
    );
    assert_eq!(recs[1]["pair"], 1);
    assert_eq!(recs[3]["pair"], 3);
    assert_eq!(recs[3]["data_len"], 14);
    for r in &recs {
        assert!(kinds(r).is_empty(), "{r}");
    }
}

#[test]
fn a_reply_from_another_address_is_paired_and_says_so() {
    // MFF101: the request goes to 0x21, the reply comes from 0x50.
    let mut s = frame("HW_REQ_INFO", &[], None, 0x21, 0x01);
    s.extend(frame(
        "HW_GET_INFO",
        &[("model_number", "MFF002")],
        None,
        0x01,
        0x50,
    ));
    let recs = decode(&s, 0);
    assert_eq!(recs[1]["pair"], 1);
    assert_eq!(recs[1]["pair_other_address"], true);
}

/// MOT_MOVE_ABSOLUTE with its 6-byte data packet but the 0x80 flag missing.
fn unflagged_move() -> Vec<u8> {
    let mut m = frame(
        "MOT_MOVE_ABSOLUTE",
        &[("chan_ident", "1"), ("absolute_position", "20000")],
        Some("6"),
        0x50,
        0x01,
    );
    m[4] &= 0x7F;
    m
}

#[test]
fn a_data_packet_without_the_data_flag_is_decoded_and_flagged() {
    let mut s = unflagged_move();
    s.extend(frame(
        "MOT_MOVE_COMPLETED",
        &[("chan_ident", "1")],
        Some("hdr"),
        0x01,
        0x50,
    ));
    let whole = decode(&s, 0);
    assert_eq!(
        names(&whole),
        ["MOT_MOVE_ABSOLUTE", "MOT_MOVE_COMPLETED"],
        "{whole:?}"
    );
    assert_eq!(kinds(&whole[0]), ["missing_data_flag"]);
    assert_eq!(whole[0]["fields"]["absolute_position"], 20000);
    assert_eq!(whole[0]["data_len"], 6);
    assert_eq!(whole[0]["data_flag"], false);
    assert_eq!(whole[1]["pair"], 1);
    // Any chunking gives the same records.
    for step in [1, 2, 5, 7] {
        assert_eq!(decode(&s, step), whole, "chunks of {step}");
    }
    // At the end of the stream too.
    let end = decode(&unflagged_move(), 0);
    assert_eq!(names(&end)[0], "MOT_MOVE_ABSOLUTE");
    assert_eq!(kinds(&end[0])[0], "missing_data_flag");
}

#[test]
fn a_message_without_header_form_sent_unflagged_is_decoded() {
    let mut s = frame(
        "MOT_SET_VELPARAMS",
        &[("chan_ident", "1"), ("max_vel", "1000")],
        None,
        0x50,
        0x01,
    );
    s[4] &= 0x7F;
    let recs = decode(&s, 0);
    assert_eq!(names(&recs), ["MOT_SET_VELPARAMS"]);
    assert_eq!(kinds(&recs[0]), ["missing_data_flag"]);
    assert_eq!(recs[0]["fields"]["max_vel"], 1000);
}

#[test]
fn genuine_header_only_frames_are_not_taken_for_unflagged_data() {
    // A header-only MOVE_ABSOLUTE whose params read as 6 (a data length of the message), then
    // frames: the bytes after it start a frame, so it stays header-only.
    let mut s = vec![0x53, 0x04, 0x06, 0x00, 0x50, 0x01];
    s.extend(frame("HW_REQ_INFO", &[], None, 0x50, 0x01));
    s.extend(frame("HW_REQ_INFO", &[], None, 0x50, 0x01));
    // (The requests get no reply: only the frames matter here.)
    let recs: Vec<Value> = decode(&s, 0)
        .into_iter()
        .filter(|r| r["type"] == "frame")
        .collect();
    assert_eq!(
        names(&recs),
        ["MOT_MOVE_ABSOLUTE", "HW_REQ_INFO", "HW_REQ_INFO"]
    );
    assert_eq!(recs[0]["data_len"], 0);
}

/// MOT_SET_MOVESYNCHARRAY breaks the spec's 255-byte rule (its own example is 1208 bytes): a
/// whole 100-row array for two channels frames and decodes, row values included, and the
/// frames around it are untouched.
#[test]
fn a_data_packet_over_255_bytes_frames_when_the_table_allows_it() {
    let rows: Vec<String> = (0..300).map(|i| (i * 7).to_string()).collect();
    let list = rows.join(",");
    let mut s = frame("HW_REQ_INFO", &[], None, 0x50, 0x01);
    let big = frame(
        "MOT_SET_MOVESYNCHARRAY",
        &[
            ("array_id", "1"),
            ("channels", "3"),
            ("num_points", "100"),
            ("start_ix", "0"),
            ("time_pos", &list),
        ],
        None,
        0xD0,
        0x01,
    );
    assert_eq!(big.len(), 6 + 1208, "the spec example's length");
    s.extend(&big);
    s.extend(frame("HW_REQ_INFO", &[], None, 0x50, 0x01));
    for step in [0, 7, 64] {
        let recs: Vec<Value> = decode(&s, step)
            .into_iter()
            .filter(|r| r["type"] != "diag")
            .collect();
        assert_eq!(
            names(&recs),
            ["HW_REQ_INFO", "MOT_SET_MOVESYNCHARRAY", "HW_REQ_INFO"],
            "chunks of {step}"
        );
        assert!(kinds(&recs[1]).is_empty(), "{}", recs[1]["diag"]);
        assert_eq!(recs[1]["data_len"], 1208);
        let tp = recs[1]["fields"]["time_pos"].as_array().expect("rows");
        assert_eq!(tp.len(), 300);
        assert_eq!(tp[299], 299 * 7);
    }
    // Another message claiming more than 255 bytes is still a corrupt header.
    let absurd = [0x53, 0x04, 0x00, 0x01, 0xD0, 0x01];
    let recs = decode(&absurd, 0);
    assert_eq!(recs[0]["type"], "garbage");
}
