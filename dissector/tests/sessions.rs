//! Sessions of real client programs decode exactly: what thorlabs-apt-device, pylablib and the
//! Elliptec packages send, in the shapes they send it, gets no diagnostic it does not deserve.

mod common;

use common::{frame, kinds};
use serde_json::Value;

/// Every chunking the tests try: all at once, byte by byte, and sizes that cut frames anywhere.
const STEPS: [usize; 5] = [0, 1, 3, 5, 7];

fn frames(recs: &[Value]) -> Vec<&Value> {
    recs.iter().filter(|r| r["type"] == "frame").collect()
}

/// Every diagnostic kind of a decoded stream, with the record it is on (no_reply records too).
fn all_kinds(recs: &[Value]) -> Vec<String> {
    recs.iter()
        .flat_map(|r| {
            let n = r["n"].clone();
            kinds(r)
                .into_iter()
                .map(move |k| format!("{k} on {n}"))
                .collect::<Vec<_>>()
        })
        .chain(
            recs.iter()
                .filter(|r| r["type"] == "no_reply")
                .map(|r| format!("no_reply {r}")),
        )
        .collect()
}

fn stop(dst: u8, chan: &str) -> Vec<u8> {
    frame(
        "MOT_MOVE_STOP",
        &[("chan_ident", chan), ("stop_mode", "2")],
        None,
        dst,
        0x01,
    )
}

fn stopped(src: u8, chan: &str) -> Vec<u8> {
    frame(
        "MOT_MOVE_STOPPED",
        &[("chan_ident", chan)],
        Some("hdr"),
        0x01,
        src,
    )
}

/// thorlabs-apt-device's `close()` sends MOT_MOVE_STOP twice before reading; a KDC101 answers
/// each with MOT_MOVE_STOPPED. First in, first out: each STOPPED answers its own STOP.
#[test]
fn a_stop_sent_twice_gets_two_replies_paired_in_order() {
    let mut s = stop(0x50, "1");
    s.extend(stop(0x50, "1"));
    s.extend(stopped(0x50, "1"));
    s.extend(stopped(0x50, "1"));
    for step in STEPS {
        let recs = common::decode_json(&s, step);
        let f = frames(&recs);
        assert_eq!(f.len(), 4, "{recs:?}");
        assert_eq!(f[2]["pair"], f[0]["n"], "chunks of {step}: {}", f[2]);
        assert_eq!(f[3]["pair"], f[1]["n"], "chunks of {step}: {}", f[3]);
        assert!(all_kinds(&recs).is_empty(), "{:?}", all_kinds(&recs));
    }
}

/// thorlabs-apt-device's BSC class: three bays (0x21–0x23), two STOPs to each (its `close()`
/// stops every bay, and is called twice), the replies bay by bay as a rack sends them. Both the
/// order the class sends (every bay, then every bay again) and bay by bay.
#[test]
fn two_stops_to_each_of_three_bays_pair_per_bay() {
    let bays = [0x21u8, 0x22, 0x23];
    // The bays in sending order, and the frame indexes of bay i's (first, second) request.
    type Order = (Vec<u8>, [(usize, usize); 3]);
    let orders: [Order; 2] = [
        (
            vec![0x21, 0x22, 0x23, 0x21, 0x22, 0x23],
            [(0, 3), (1, 4), (2, 5)],
        ),
        (
            vec![0x21, 0x21, 0x22, 0x22, 0x23, 0x23],
            [(0, 1), (2, 3), (4, 5)],
        ),
    ];
    for (sent, at) in orders {
        let mut s: Vec<u8> = sent.iter().flat_map(|b| stop(*b, "1")).collect();
        for _ in 0..2 {
            for b in bays {
                s.extend(stopped(b, "1"));
            }
        }
        for step in STEPS {
            let recs = common::decode_json(&s, step);
            let f = frames(&recs);
            assert_eq!(f.len(), 12);
            for (i, (first, second)) in at.iter().enumerate() {
                // The first replies are frames 6..9, the second 9..12.
                assert_eq!(f[6 + i]["pair"], f[*first]["n"], "chunks of {step}");
                assert_eq!(f[9 + i]["pair"], f[*second]["n"], "chunks of {step}");
            }
            assert!(all_kinds(&recs).is_empty(), "{:?}", all_kinds(&recs));
        }
    }
}

/// A move stopped, then stopped again: the first MOVE_STOPPED ends the move and the stop that
/// ended it, the second answers the second stop.
#[test]
fn a_move_stopped_twice_pairs_every_request() {
    let mut s = frame(
        "MOT_MOVE_ABSOLUTE",
        &[("chan_ident", "1"), ("absolute_position", "100000")],
        Some("6"),
        0x50,
        0x01,
    );
    s.extend(stop(0x50, "1"));
    s.extend(stop(0x50, "1"));
    s.extend(stopped(0x50, "1"));
    s.extend(stopped(0x50, "1"));
    let recs = common::decode_json(&s, 0);
    let f = frames(&recs);
    assert_eq!(f[3]["pair"], f[0]["n"]);
    assert_eq!(f[4]["pair"], f[2]["n"]);
    assert!(all_kinds(&recs).is_empty(), "{:?}", all_kinds(&recs));
}

/// One MOVE_COMPLETED still ends a move and the move sent over it (the second move supersedes
/// the first; the controller reports the end once).
#[test]
fn a_superseded_move_is_ended_by_the_one_completion() {
    let mv = |pos: &str| {
        frame(
            "MOT_MOVE_ABSOLUTE",
            &[("chan_ident", "1"), ("absolute_position", pos)],
            Some("6"),
            0x50,
            0x01,
        )
    };
    let mut s = mv("1000");
    s.extend(mv("2000"));
    s.extend(frame(
        "MOT_MOVE_COMPLETED",
        &[("chan_ident", "1")],
        Some("hdr"),
        0x01,
        0x50,
    ));
    let recs = common::decode_json(&s, 0);
    assert!(all_kinds(&recs).is_empty(), "{:?}", all_kinds(&recs));
}

/// A record of the one decode chain, as far as these tests look at it.
#[derive(Debug, Clone, PartialEq)]
struct Rec {
    n: u64,
    ts: Option<u64>,
    what: String,
    pair: Option<u64>,
    diags: Vec<String>,
}

/// Runs timed chunks `(direction, time in ms, bytes)` of one Elliptec stream through the
/// decoder: its records, and the requests it says got no reply.
fn decode_timed(chunks: &[(Dir, u64, &[u8])]) -> (Vec<Rec>, Vec<u64>) {
    let mut d = Decoder::new(Some(Proto::Elliptec));
    let mut recs = vec![];
    let mut no_reply = vec![];
    let mut emit = |r: &Record<'_>| -> Result<(), ()> {
        match r {
            Record::Ell(e) => recs.push(Rec {
                n: e.meta.n,
                ts: e.meta.ts_ns,
                what: String::from_utf8_lossy(e.frame.bytes)
                    .trim_end()
                    .to_string(),
                pair: e.obs.pair,
                diags: e
                    .frame
                    .diags()
                    .iter()
                    .map(|d| d.kind.name().to_string())
                    .collect(),
            }),
            Record::Garbage(g) => recs.push(Rec {
                n: g.meta.n,
                ts: g.meta.ts_ns,
                what: format!("garbage {:?}", String::from_utf8_lossy(g.bytes)),
                pair: None,
                diags: vec![],
            }),
            Record::NoReply(x) => no_reply.push(x.n),
            _ => {}
        }
        Ok(())
    };
    for (dir, ms, bytes) in chunks {
        let ctx = Ctx {
            stream: 0,
            dir: Some(*dir),
            ts_ns: Some(ms * 1_000_000),
        };
        d.push(ctx, bytes, &mut emit).expect("push");
    }
    d.finish(&mut emit).expect("finish");
    (recs, no_reply)
}

use aptscope_dissector::detect::Proto;
use aptscope_dissector::record::{Ctx, Decoder, Record};
use aptscope_dissector::table::Dir;

const H: Dir = Dir::HostToDevice;
const D: Dir = Dir::DeviceToHost;

/// pylablib's `ElliptecMotor.get_full_info()` asks motor 3's parameters, `0i3`, which the
/// manual does not list; a module answers `0GS03` (command error or not supported). The
/// command is a frame with `unknown_command`, and the answer is paired with it.
#[test]
fn an_unknown_host_command_is_framed_and_paired_with_its_gs_answer() {
    let (recs, no_reply) = decode_timed(&[
        (H, 1000, b"0i3"),
        (D, 1010, b"0GS03\r\n"),
        (H, 1100, b"0gs"),
        (D, 1110, b"0GS00\r\n"),
    ]);
    let what: Vec<&str> = recs.iter().map(|r| r.what.as_str()).collect();
    assert_eq!(what, ["0i3", "0GS03", "0gs", "0GS00"], "{recs:?}");
    assert_eq!(recs[0].diags, ["unknown_command"]);
    assert_eq!(recs[1].pair, Some(recs[0].n));
    assert!(recs[1].diags.is_empty(), "{:?}", recs[1]);
    assert_eq!(recs[3].pair, Some(recs[2].n));
    assert!(no_reply.is_empty());
}

/// In a capture without directions (one stream of both sides' bytes), in any chunking, the
/// unknown command ends where the module's answer starts.
#[test]
fn an_unknown_host_command_ends_where_the_next_frame_starts() {
    let s = b"0i30GS03\r\n0i10I1100428FFFFFFFF00BD008B\r\n0i3\r\n0GS03\r\n";
    for step in STEPS {
        let recs = common::decode_json(s, step);
        let f = frames(&recs);
        let raw: Vec<String> = f
            .iter()
            .map(|r| r["cmd"].as_str().unwrap_or("?").to_string())
            .collect();
        assert_eq!(f.len(), 6, "chunks of {step}: {raw:?} {recs:?}");
        assert!(recs.iter().all(|r| r["type"] != "garbage"), "{recs:?}");
        assert_eq!(f[1]["pair"], f[0]["n"], "{}", f[1]);
        assert_eq!(f[5]["pair"], f[4]["n"], "{}", f[5]);
        assert_eq!(kinds(f[0]), ["unknown_command"]);
        assert_eq!(kinds(f[4]), ["unknown_command"]);
        assert!(kinds(f[1]).is_empty() && kinds(f[5]).is_empty());
    }
}

/// The module stays silent on the unknown command (a simulator that does not know it): the host
/// goes on after its timeout. Every record keeps the time its first byte arrived, and the
/// records of the stream come in time order, not with the capture's end time.
#[test]
fn records_after_an_unanswered_unknown_command_keep_their_times_and_order() {
    let chunks: &[(Dir, u64, &[u8])] = &[
        (H, 10_000, b"0in"),
        (D, 10_020, b"0IN0E1140028020230201001F00000001\r\n"),
        (H, 10_100, b"0i3"),
        (H, 12_100, b"#?!"),
        (H, 12_200, b"0gs"),
        (D, 12_210, b"0GS00\r\n"),
        (H, 13_000, b"0gp"),
        (D, 13_010, b"0PO00000000\r\n"),
    ];
    let (recs, no_reply) = decode_timed(chunks);
    let times: Vec<u64> = recs
        .iter()
        .map(|r| r.ts.expect("timed") / 1_000_000)
        .collect();
    let what: Vec<&str> = recs.iter().map(|r| r.what.as_str()).collect();
    assert_eq!(
        what,
        [
            "0in",
            "0IN0E1140028020230201001F00000001",
            "0i3",
            "garbage \"#?!\"",
            "0gs",
            "0GS00",
            "0gp",
            "0PO00000000",
        ],
        "{recs:?}"
    );
    assert_eq!(
        times,
        [10_000, 10_020, 10_100, 12_100, 12_200, 12_210, 13_000, 13_010]
    );
    // `0i3` got no answer within its 2 s: said once, about it.
    assert_eq!(no_reply, [recs[2].n]);
}

/// HW_REQ_INFO and a HW_GET_INFO naming `model`, from address 0x50.
fn identified_as(model: &str) -> Vec<u8> {
    let mut s = frame("HW_REQ_INFO", &[], None, 0x50, 0x01);
    s.extend(frame(
        "HW_GET_INFO",
        &[("serial_number", "27000001"), ("model_number", model)],
        None,
        0x01,
        0x50,
    ));
    s
}

fn exchange(s: &mut Vec<u8>, req: &str, reply: &str) {
    s.extend(frame(req, &[("chan_ident", "1")], Some("hdr"), 0x50, 0x01));
    s.extend(frame(reply, &[("chan_ident", "1")], None, 0x01, 0x50));
}

/// pylablib's `KinesisMotor.get_full_info()` asks a KDC101 for MOT_REQ_KCUBETRIGIOCONFIG: the
/// lists leave it out, its own section (0x0523–0x0525, both revisions) names the KDC101.
/// pylablib's `KinesisPiezoController` polls a KPZ101 with PZ_REQ_PZSTATUSUPDATE: the lists
/// name its reply. Neither is flagged; a message neither source names still is.
#[test]
fn applicability_reads_the_lists_and_the_message_sections() {
    let mut s = identified_as("KDC101");
    exchange(
        &mut s,
        "MOT_REQ_KCUBETRIGIOCONFIG",
        "MOT_GET_KCUBETRIGIOCONFIG",
    );
    exchange(&mut s, "MOT_REQ_KCUBEMMIPARAMS", "MOT_GET_KCUBEMMIPARAMS");
    let recs = common::decode_json(&s, 0);
    assert!(all_kinds(&recs).is_empty(), "{:?}", all_kinds(&recs));

    let mut s = identified_as("KPZ101");
    exchange(&mut s, "PZ_REQ_PZSTATUSUPDATE", "PZ_GET_PZSTATUSUPDATE");
    let recs = common::decode_json(&s, 0);
    assert!(all_kinds(&recs).is_empty(), "{:?}", all_kinds(&recs));

    // A piezo message to a DC motor controller: neither source names it.
    let mut s = identified_as("KDC101");
    exchange(&mut s, "PZ_REQ_OUTPUTMAXVOLTS", "PZ_GET_OUTPUTMAXVOLTS");
    let recs = common::decode_json(&s, 0);
    let f = frames(&recs);
    assert_eq!(kinds(f[2]), ["not_for_model"], "{}", f[2]);
    let text = f[2]["diag"][0]["msg"].as_str().unwrap_or_default();
    assert!(
        text.contains("lists") && text.contains("section") && text.contains("Issue 23"),
        "the diagnostic says which sources were read: {text}"
    );
}
