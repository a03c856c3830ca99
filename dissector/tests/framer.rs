//! The streaming framer: chunking invariance, byte accounting, and every kind of bad input.

mod common;

use aptscope_dissector::apt::{AptFrame, GarbageKind};
use aptscope_dissector::{DiagKind, Table};
use proptest::prelude::*;

use common::{run_apt as run, Item as Rec};

fn stream(seed: u64, frames: usize, garbage: bool) -> Vec<u8> {
    aptscope_dissector::synth::stream(Table::global(), seed, frames, garbage)
}

fn accounted(recs: &[Rec], len: usize) {
    let mut at = 0u64;
    for r in recs {
        let (off, n) = match r {
            Rec::Frame(o, b, _) | Rec::Garbage(o, b, _) => (*o, b.len()),
        };
        assert_eq!(off, at, "records are contiguous: nothing lost or repeated");
        at += n as u64;
    }
    assert_eq!(
        at, len as u64,
        "every input byte is in a frame or a garbage record"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn any_chunking_gives_the_same_records(seed in any::<u64>(), garbage in any::<bool>(), mut cuts in proptest::collection::vec(0usize..4000, 0..40)) {
        let input = stream(seed, 60, garbage);
        cuts.sort();
        let whole = run(&input, &[]);
        let chunked = run(&input, &cuts);
        prop_assert_eq!(&whole, &chunked);
        accounted(&whole, input.len());
    }

    #[test]
    fn random_bytes_are_fully_accounted_for(input in proptest::collection::vec(any::<u8>(), 0..3000), cut in 0usize..3000) {
        let whole = run(&input, &[]);
        accounted(&whole, input.len());
        prop_assert_eq!(whole, run(&input, &[cut]));
    }

    #[test]
    fn byte_by_byte_equals_one_shot(seed in any::<u64>()) {
        let input = stream(seed, 20, true);
        let cuts: Vec<usize> = (1..input.len()).collect();
        prop_assert_eq!(run(&input, &[]), run(&input, &cuts));
    }
}

#[test]
fn clean_stream_frames_without_garbage() {
    let input = stream(7, 2000, false);
    let recs = run(&input, &[]);
    assert_eq!(recs.len(), 2000);
    assert!(recs.iter().all(|r| matches!(r, Rec::Frame(_, _, false))));
}

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace()
        .map(|b| u8::from_str_radix(b, 16).expect("hex"))
        .collect()
}

const IDENTIFY: &str = "23 02 01 00 50 01";
const MOVE_ABS: &str = "53 04 06 00 a2 01 01 00 40 0d 03 00";

fn diags_of(recs: &[Rec]) -> Vec<(u64, &'static str)> {
    let t = Table::global();
    let mut v = vec![];
    for r in recs {
        match r {
            Rec::Frame(o, b, tr) => {
                let f = AptFrame::decode(t, *o, b, *tr).expect("frame");
                v.extend(f.diags().map(|d| (d.offset, d.kind.name())));
            }
            Rec::Garbage(o, b, k) => {
                let k = k.expect("the APT framer says what it saw");
                let d = aptscope_dissector::json::garbage_diag(*o, b.len(), k);
                v.push((d.offset, d.kind.name()));
            }
        }
    }
    v
}

#[test]
fn empty_input_gives_nothing() {
    assert!(run(&[], &[]).is_empty());
}

#[test]
fn truncated_final_frame_is_shown_with_its_offset() {
    let mut input = hex(IDENTIFY);
    input.extend(&hex(MOVE_ABS)[..9]);
    let recs = run(&input, &[]);
    assert_eq!(recs.len(), 2);
    assert!(matches!(&recs[1], Rec::Frame(6, b, true) if b.len() == 9));
    assert_eq!(diags_of(&recs), vec![(15, "truncated")]);
    let f = AptFrame::decode(Table::global(), 6, &input[6..], true).expect("frame");
    assert_eq!(f.name(), Some("MOT_MOVE_ABSOLUTE"));
    assert_eq!(
        f.diags().next().map(|d| d.kind),
        Some(DiagKind::Truncated {
            expected: 12,
            got: 9
        })
    );
}

#[test]
fn garbage_before_between_and_after_frames() {
    let mut input = hex("ff fe 00");
    input.extend(hex(IDENTIFY));
    input.extend(hex("99 98 97 96 95 94 93"));
    input.extend(hex(MOVE_ABS));
    input.extend(hex("aa bb"));
    let recs = run(&input, &[]);
    let kinds: Vec<&str> = recs
        .iter()
        .map(|r| match r {
            Rec::Frame(..) => "frame",
            Rec::Garbage(..) => "garbage",
        })
        .collect();
    assert_eq!(kinds, ["garbage", "frame", "garbage", "frame", "garbage"]);
    assert_eq!(
        diags_of(&recs),
        vec![(0, "garbage"), (9, "garbage"), (28, "trailing_bytes")]
    );
    accounted(&recs, input.len());
}

#[test]
fn unknown_id_is_framed_and_flagged() {
    let input = hex("ee ee 02 00 d0 01 12 34 23 02 01 00 50 01");
    let recs = run(&input, &[]);
    assert!(matches!(&recs[0], Rec::Frame(0, b, false) if b.len() == 8));
    assert_eq!(diags_of(&recs), vec![(0, "unknown_id")]);
}

#[test]
fn absurd_length_is_skipped_with_a_diagnostic_and_decoding_carries_on() {
    let mut input = hex("53 04 ff ff a2 01");
    input.extend(hex(MOVE_ABS));
    let recs = run(&input, &[]);
    assert_eq!(
        recs[0],
        Rec::Garbage(
            0,
            input[..6].to_vec(),
            Some(GarbageKind::AbsurdLength {
                msg_id: 0x0453,
                len: 0xFFFF
            })
        )
    );
    assert!(matches!(&recs[1], Rec::Frame(6, _, false)));
    assert_eq!(diags_of(&recs), vec![(0, "absurd_length")]);
}

#[test]
fn length_that_matches_no_form_is_shown_with_a_diagnostic() {
    // MOT_MOVE_ABSOLUTE exists header-only or with 6 data bytes; here with 4.
    let input = hex("53 04 04 00 a2 01 01 00 40 0d");
    let recs = run(&input, &[]);
    assert!(matches!(&recs[0], Rec::Frame(0, b, false) if b.len() == 10));
    assert_eq!(diags_of(&recs), vec![(2, "length_mismatch")]);
}

#[test]
fn header_only_message_with_data_flag_is_flagged() {
    // MOD_IDENTIFY is header-only; sent with the 0x80 bit and a 2-byte packet.
    let input = hex("23 02 02 00 d0 01 01 00");
    let recs = run(&input, &[]);
    assert!(matches!(&recs[0], Rec::Frame(0, b, false) if b.len() == 8));
    assert_eq!(diags_of(&recs), vec![(4, "header_only_with_data")]);
}

#[test]
fn one_unknown_address_is_tolerated_for_a_known_message_of_the_right_length() {
    let input = hex("23 02 01 00 50 07");
    let recs = run(&input, &[]);
    assert!(matches!(&recs[0], Rec::Frame(0, _, false)));
    assert_eq!(diags_of(&recs), vec![(5, "unknown_address")]);
}

#[test]
fn long_garbage_runs_are_cut_into_bounded_records() {
    let input = vec![0xFFu8; 10_000];
    let recs = run(&input, &[123, 5000]);
    // 4096 + 4096 + 1803 bytes of garbage, then the last 5 bytes, too few for a header.
    assert_eq!(recs.len(), 4);
    assert!(recs
        .iter()
        .all(|r| matches!(r, Rec::Garbage(_, b, _) if b.len() <= 4096)));
    assert!(matches!(
        recs[3],
        Rec::Garbage(9995, _, Some(GarbageKind::TrailingBytes))
    ));
    accounted(&recs, input.len());
}

/// The records of `input` as JSON lines, decoded with detection, pushed in pieces cut at
/// `cuts`, after a capture-file diagnostic (held until the protocol is known).
fn decoded(input: &[u8], cuts: &[usize]) -> Vec<String> {
    use aptscope_dissector::json;
    use aptscope_dissector::record::{Ctx, Decoder, Record};
    let mut out = Vec::new();
    let mut emit = |r: &Record<'_>| {
        let mut s = String::new();
        json::record(&mut s, r, None);
        out.push(s);
        Ok::<(), ()>(())
    };
    let mut dec = Decoder::new(None);
    dec.file_diag(0, "truncated_file", "a diagnostic of the file", &mut emit)
        .unwrap();
    let mut at = 0;
    for &c in cuts.iter().chain([&input.len()]) {
        dec.push(Ctx::default(), &input[at..c], &mut emit).unwrap();
        at = c;
    }
    dec.finish(&mut emit).unwrap();
    out
}

/// A first chunk of a whole detection sample or more is judged on its first bytes and fed as
/// it is: the records (the detection's, the diagnostic held before the first chunk, every
/// frame) are those of the same bytes in small chunks, or a small chunk and then the rest.
#[test]
fn records_do_not_depend_on_the_first_chunks_size() {
    use aptscope_dissector::detect::SAMPLE;
    for (seed, garbage) in [(1, false), (2, true), (3, true)] {
        let input = stream(seed, 3000, garbage);
        assert!(input.len() > 4 * SAMPLE);
        let whole = decoded(&input, &[]);
        assert!(whole.len() > 3000, "{} records", whole.len());
        assert!(whole[0].contains("\"detect\""), "{}", whole[0]);
        assert!(
            whole[1].contains("a diagnostic of the file"),
            "{}",
            whole[1]
        );
        let small: Vec<usize> = (1..input.len() / 700).map(|i| i * 700).collect();
        for cuts in [&small[..], &[100], &[SAMPLE], &[SAMPLE + 1, 3 * SAMPLE]] {
            assert_eq!(
                whole,
                decoded(&input, cuts),
                "seed {seed}, cuts {:?}",
                &cuts[..1]
            );
        }
    }
}
