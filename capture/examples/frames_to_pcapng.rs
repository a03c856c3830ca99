//! `frames_to_pcapng IN.bin OUT.pcapng`: a raw APT stream as a realistic serial capture, one
//! packet per frame (as a tap records them), direction from the message table, 100 µs apart.
//! Used by `bench/compare-tshark.sh`.

use aptscope_capture::pcap::PcapNgOut;
use aptscope_capture::{Direction, OwnedChunk, StreamInfo, Writer};
use aptscope_dissector::apt::{AptFrame, AptFramer, Item};
use aptscope_dissector::table::Dir;
use aptscope_dissector::Table;
use std::io::{BufWriter, Read};

fn main() -> std::io::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(input), Some(output)) = (args.get(1), args.get(2)) else {
        eprintln!("usage: frames_to_pcapng IN.bin OUT.pcapng");
        std::process::exit(2);
    };
    let t = Table::global();
    let mut w = PcapNgOut::new(BufWriter::new(std::fs::File::create(output)?))?;
    w.stream(&StreamInfo {
        id: 0,
        name: "/dev/ttyUSB0".into(),
        settings: Some("115200 8N1 RTS/CTS".into()),
    })?;
    let mut f = AptFramer::new(t);
    let mut src = std::fs::File::open(input)?;
    let mut buf = vec![0u8; 1 << 16];
    let mut ts = 1_764_000_000_000_000_000u64;
    let mut eof = false;
    while !eof {
        let n = src.read(&mut buf)?;
        if n == 0 {
            f.finish();
            eof = true;
        } else {
            f.push(&buf[..n]);
        }
        while let Some(it) = f.next_item() {
            let (offset, bytes, truncated) = match it {
                Item::Frame {
                    offset,
                    bytes,
                    truncated,
                } => (offset, bytes, truncated),
                Item::Garbage { offset, bytes, .. } => (offset, bytes, true),
            };
            let dir = match AptFrame::decode(t, offset, bytes, truncated)
                .and_then(|x| x.msg)
                .map(|m| m.dir)
            {
                Some(Dir::DeviceToHost) => Direction::DeviceToHost,
                Some(_) => Direction::HostToDevice,
                None => Direction::Unknown,
            };
            ts += 100_000;
            let c = OwnedChunk {
                ts_ns: Some(ts),
                dir,
                stream: 0,
                bytes: bytes.to_vec(),
            };
            w.chunk(&c.as_chunk())?;
        }
    }
    w.finish()
}
