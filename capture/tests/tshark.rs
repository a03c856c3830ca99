//! Wireshark's tshark must open every capture aptscope writes, with the right packet count,
//! times and direction. Needs tshark (`.ci/run` installs it): without it these tests fail,
//! unless `APTSCOPE_SKIP_MISSING_TOOLS=1` outside CI (see the README's Tests section).

use aptscope_capture::pcap::{PcapNgOut, PcapOut};
use aptscope_capture::{Direction, OwnedChunk, StreamInfo, Writer};
use std::process::Command;

/// Whether tshark runs; panics with how to install it when it does not (in CI always; see
/// [`aptscope_capture::tools::on_missing`]).
fn tshark() -> bool {
    aptscope_capture::tools::require("tshark", "--version", "tshark")
}

fn chunks() -> Vec<OwnedChunk> {
    (0..50u64)
        .map(|i| OwnedChunk {
            ts_ns: Some(1_700_000_000_000_000_000 + i * 100_000_123),
            dir: if i % 2 == 0 {
                Direction::HostToDevice
            } else {
                Direction::DeviceToHost
            },
            stream: 0,
            bytes: vec![0x23, 0x02, 0x01, 0x00, 0x50, 0x01][..(1 + (i as usize % 6))].to_vec(),
        })
        .collect()
}

fn fields(path: &std::path::Path, fields: &[&str]) -> Vec<Vec<String>> {
    let mut cmd = Command::new("tshark");
    cmd.arg("-r")
        .arg(path)
        .args(["-T", "fields", "-E", "separator=|"]);
    for f in fields {
        cmd.args(["-e", f]);
    }
    let out = cmd.output().expect("run tshark");
    assert!(
        out.status.success(),
        "tshark failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !stderr.to_lowercase().contains("error") && !stderr.contains("appears to be damaged"),
        "tshark complained: {stderr}"
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| l.split('|').map(str::to_string).collect())
        .collect()
}

#[test]
fn tshark_reads_our_pcapng_with_times_and_direction() {
    if !tshark() {
        return;
    }
    let path = std::env::temp_dir().join(format!("aptscope-tshark-{}.pcapng", std::process::id()));
    let mut w = PcapNgOut::new(std::fs::File::create(&path).expect("create")).expect("writer");
    w.stream(&StreamInfo {
        id: 0,
        name: "/dev/ttyUSB0".into(),
        settings: Some("115200 8N1 RTS/CTS".into()),
    })
    .expect("stream");
    for c in chunks() {
        w.chunk(&c.as_chunk()).expect("chunk");
    }
    w.finish().expect("finish");
    let rows = fields(
        &path,
        &[
            "frame.number",
            "frame.time_epoch",
            "frame.len",
            "frame.packet_flags_direction",
            "frame.interface_name",
        ],
    );
    assert_eq!(rows.len(), 50);
    for (row, c) in rows.iter().zip(chunks()) {
        let ts = c.ts_ns.expect("ts");
        assert_eq!(
            row[1],
            format!("{}.{:09}", ts / 1_000_000_000, ts % 1_000_000_000),
            "{row:?}"
        );
        assert_eq!(row[2], c.bytes.len().to_string());
        let want = match c.dir {
            Direction::HostToDevice => "2",
            Direction::DeviceToHost => "1",
            Direction::Unknown => "0",
        };
        assert!(
            row[3] == want || row[3] == format!("0x{want:0>8}") || row[3].ends_with(want),
            "{row:?}"
        );
        assert_eq!(row[4], "/dev/ttyUSB0");
    }
    let _ = std::fs::remove_file(path);
}

#[test]
fn tshark_reads_our_pcap() {
    if !tshark() {
        return;
    }
    let path = std::env::temp_dir().join(format!("aptscope-tshark-{}.pcap", std::process::id()));
    let mut w = PcapOut::new(std::fs::File::create(&path).expect("create")).expect("writer");
    for c in chunks() {
        w.chunk(&c.as_chunk()).expect("chunk");
    }
    w.finish().expect("finish");
    let rows = fields(&path, &["frame.number", "frame.time_epoch", "frame.len"]);
    assert_eq!(rows.len(), 50);
    for (row, c) in rows.iter().zip(chunks()) {
        let ts = c.ts_ns.expect("ts");
        assert_eq!(
            row[1],
            format!("{}.{:09}", ts / 1_000_000_000, ts % 1_000_000_000)
        );
        // Two bytes of pseudo-header (direction, stream) precede the data.
        assert_eq!(row[2], (c.bytes.len() + 2).to_string());
    }
    let _ = std::fs::remove_file(path);
}
