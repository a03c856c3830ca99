//! Writes the binary capture samples of the KDC101 session (`samples/kdc101-session.*`): pcapng,
//! pcap, MCAP and a usbmon USB capture of the FTDI chip, all from the same timed, directed
//! chunks. Run from the repository root: `cargo run -p aptscope-capture --example make_samples`.

use aptscope_capture::mcap::McapWriter;
use aptscope_capture::pcap::{PcapNgOut, PcapOut};
use aptscope_capture::usb::synth_usbmon;
use aptscope_capture::{Direction, OwnedChunk, StreamInfo, Writer};
use aptscope_dissector::apt::AptFrame;
use aptscope_dissector::table::Dir;
use aptscope_dissector::Table;
use pcap_file::pcap::{PcapHeader, PcapPacket, PcapWriter};
use pcap_file::{DataLink, TsResolution};
use std::fs::File;
use std::io::BufWriter;
use std::time::Duration;

/// The session's frames with their directions and plausible times: replies 2 ms after their
/// request, status updates every 100 ms, homing 2 s.
pub fn session() -> Vec<OwnedChunk> {
    let text = std::fs::read_to_string("samples/kdc101-session.hex")
        .expect("run from the repository root");
    let mut t = 1_764_000_000_000_000_000u64; // 2025-11-24
    let mut out = vec![];
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let bytes: Vec<u8> = line
            .split_whitespace()
            .map(|b| u8::from_str_radix(b, 16).expect("hex"))
            .collect();
        let f = AptFrame::decode(Table::global(), 0, &bytes, false).expect("frame");
        let name = f.name().unwrap_or("");
        let dir = match f.msg.map(|m| m.dir) {
            Some(Dir::DeviceToHost) => Direction::DeviceToHost,
            _ => Direction::HostToDevice,
        };
        t += match (dir, name) {
            (_, "MOT_MOVE_HOMED") => 1_600_000_000,
            (_, "MOT_GET_DCSTATUSUPDATE") => 100_000_000,
            (Direction::DeviceToHost, _) => 2_000_000,
            _ => 50_000_000,
        };
        out.push(OwnedChunk {
            ts_ns: Some(t),
            dir,
            stream: 0,
            bytes,
        });
    }
    out
}

fn main() {
    let chunks = session();
    let port = StreamInfo {
        id: 0,
        name: "/dev/ttyUSB0".into(),
        settings: Some("115200 8N1 RTS/CTS".into()),
    };
    let writers: Vec<(&str, Box<dyn Writer>)> = vec![
        (
            "samples/kdc101-session.pcapng",
            Box::new(
                PcapNgOut::new(BufWriter::new(
                    File::create("samples/kdc101-session.pcapng").expect("create"),
                ))
                .expect("pcapng"),
            ),
        ),
        (
            "samples/kdc101-session.pcap",
            Box::new(
                PcapOut::new(BufWriter::new(
                    File::create("samples/kdc101-session.pcap").expect("create"),
                ))
                .expect("pcap"),
            ),
        ),
        (
            "samples/kdc101-session.mcap",
            Box::new(
                McapWriter::new(
                    BufWriter::new(File::create("samples/kdc101-session.mcap").expect("create")),
                    None,
                )
                .expect("mcap"),
            ),
        ),
    ];
    for (name, mut w) in writers {
        w.stream(&port).expect("stream");
        for c in &chunks {
            w.chunk(&c.as_chunk()).expect("chunk");
        }
        w.finish().expect("finish");
        eprintln!("wrote {name}");
    }
    let header = PcapHeader {
        datalink: DataLink::from(220),
        ts_resolution: TsResolution::MicroSecond,
        // As the capturing machine writes them (x86: little endian), like the usbmon and
        // USBPcap headers inside: a reader takes those in the file's byte order.
        endianness: pcap_file::Endianness::Little,
        ..PcapHeader::default()
    };
    let mut w = PcapWriter::with_header(
        BufWriter::new(File::create("samples/kdc101-session.usbmon.pcap").expect("create")),
        header,
    )
    .expect("usbmon");
    for (ts, rec) in synth_usbmon(&chunks, 1, 7, 64) {
        w.write_packet(&PcapPacket::new(
            Duration::from_nanos(ts),
            rec.len() as u32,
            &rec,
        ))
        .expect("packet");
    }
    eprintln!("wrote samples/kdc101-session.usbmon.pcap");
    let header = PcapHeader {
        datalink: DataLink::from(249),
        ts_resolution: TsResolution::MicroSecond,
        // As the capturing machine writes them (x86: little endian), like the usbmon and
        // USBPcap headers inside: a reader takes those in the file's byte order.
        endianness: pcap_file::Endianness::Little,
        ..PcapHeader::default()
    };
    let mut w = PcapWriter::with_header(
        BufWriter::new(File::create("samples/kdc101-session.usbpcap.pcap").expect("create")),
        header,
    )
    .expect("usbpcap");
    for (ts, rec) in usbpcap_records(&chunks) {
        w.write_packet(&PcapPacket::new(
            Duration::from_nanos(ts),
            rec.len() as u32,
            &rec,
        ))
        .expect("packet");
    }
    eprintln!("wrote samples/kdc101-session.usbpcap.pcap");
}

/// One USBPcap record (`USBPCAP_BUFFER_PACKET_HEADER`, 27 bytes, bulk transfer) and its data.
fn usbpcap(irp: u64, completion: bool, endpoint: u8, data: &[u8]) -> Vec<u8> {
    let mut r = Vec::with_capacity(27 + data.len());
    r.extend_from_slice(&27u16.to_le_bytes());
    r.extend_from_slice(&irp.to_le_bytes());
    r.extend_from_slice(&0u32.to_le_bytes()); // status: success
    r.extend_from_slice(&0x0009u16.to_le_bytes()); // URB_FUNCTION_BULK_OR_INTERRUPT_TRANSFER
    r.push(u8::from(completion)); // info bit 0: PDO -> FDO
    r.extend_from_slice(&1u16.to_le_bytes()); // bus (root hub)
    r.extend_from_slice(&5u16.to_le_bytes()); // device address
    r.push(endpoint);
    r.push(3); // bulk
    r.extend_from_slice(&(data.len() as u32).to_le_bytes());
    r.extend_from_slice(data);
    r
}

/// The chunks as Windows USBPcap sees an FT232's bulk endpoints: OUT data on 0x02, IN data on
/// 0x81 with the two FTDI modem-status bytes at the start of every 64-byte packet.
fn usbpcap_records(chunks: &[OwnedChunk]) -> Vec<(u64, Vec<u8>)> {
    let mut out = vec![];
    let mut irp = 0xffff_a000u64;
    for c in chunks {
        let ts = c.ts_ns.unwrap_or(0);
        irp += 1;
        match c.dir {
            Direction::HostToDevice => {
                out.push((ts, usbpcap(irp, false, 0x02, &c.bytes)));
                out.push((ts, usbpcap(irp, true, 0x02, &[])));
            }
            _ => {
                let mut data = vec![];
                for piece in c.bytes.chunks(62) {
                    data.extend_from_slice(&[0x01, 0x60]);
                    data.extend_from_slice(piece);
                }
                out.push((ts, usbpcap(irp, false, 0x81, &[])));
                out.push((ts, usbpcap(irp, true, 0x81, &data)));
            }
        }
    }
    out
}
