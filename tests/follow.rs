//! Live input: `dumpcap -w - | aptscope decode -` and `aptscope decode --follow FILE` print each
//! record as its bytes arrive, not when the input ends.

mod common;

use common::proc::{wait_for, Proc};
use common::scratch;
use std::fs::OpenOptions;
use std::io::Write;

/// The sample pcap cut into its file header and its records (each one APT frame).
fn pcap_pieces() -> (Vec<u8>, Vec<Vec<u8>>) {
    let b = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/samples/kdc101-session.pcap"
    ))
    .expect("sample");
    assert_eq!(
        &b[..4],
        &[0x4d, 0x3c, 0xb2, 0xa1],
        "little-endian nanosecond pcap"
    );
    let mut at = 24;
    let mut records = vec![];
    while at + 16 <= b.len() {
        let len = u32::from_le_bytes([b[at + 8], b[at + 9], b[at + 10], b[at + 11]]) as usize;
        records.push(b[at..at + 16 + len].to_vec());
        at += 16 + len;
    }
    (b[..24].to_vec(), records)
}

/// How many frame records a process has printed (NDJSON).
fn frames_out(p: &Proc) -> usize {
    p.stdout()
        .lines()
        .filter(|l| l.contains("\"type\":\"frame\""))
        .count()
}

/// A pcap written to `decode -` one record at a time: each record is printed before the next is
/// written (the pipe stays open, so only a streaming decoder can show it).
#[test]
fn decode_from_a_pipe_prints_each_record_as_it_arrives() {
    let (header, records) = pcap_pieces();
    let (mut p, mut pipe) = Proc::aptscope_piped(&["decode", "--json", "-"]);
    pipe.write_all(&header).expect("write");
    for (i, r) in records.iter().take(6).enumerate() {
        pipe.write_all(r).expect("write");
        pipe.flush().expect("flush");
        wait_for(
            &format!("record {} printed while the pipe is open", i + 1),
            || p.both(),
            || frames_out(&p) == i + 1,
        );
    }
    drop(pipe);
    assert!(p.wait_exit().success(), "{}", p.both());
    assert_eq!(frames_out(&p), 6);
}

/// `decode --follow FILE` on a capture another program is still writing: each record as it is
/// appended, until interrupted.
#[test]
fn decode_follow_prints_records_appended_to_a_file() {
    let (header, records) = pcap_pieces();
    let dir = scratch("follow-decode");
    let path = dir.join("growing.pcap");
    let mut f = OpenOptions::new()
        .create(true)
        .truncate(true)
        .write(true)
        .open(&path)
        .expect("create");
    f.write_all(&header).expect("write");
    f.write_all(&records[0]).expect("write");
    f.flush().expect("flush");
    let path_s = path.to_str().expect("utf-8 path");
    let mut p = Proc::aptscope(&["decode", "--json", "--follow", path_s]);
    wait_for("the first record", || p.both(), || frames_out(&p) == 1);
    for (i, r) in records.iter().enumerate().skip(1).take(4) {
        f.write_all(r).expect("write");
        f.flush().expect("flush");
        wait_for(
            &format!("record {} printed once appended", i + 1),
            || p.both(),
            || frames_out(&p) == i + 1,
        );
    }
    p.signal(nix::sys::signal::Signal::SIGINT);
    p.wait_exit();
    assert_eq!(frames_out(&p), 5, "{}", p.both());
}
