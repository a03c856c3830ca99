//! Tests of the USB demultiplexer.

use super::*;
use proptest::prelude::*;

fn chunk(ts: u64, dir: Direction, bytes: &[u8]) -> OwnedChunk {
    OwnedChunk {
        ts_ns: Some(ts),
        dir,
        stream: 0,
        bytes: bytes.to_vec(),
    }
}

/// Feed records (offsets: cumulative, as if each had a 16-byte pcap record header).
fn feed(demux: &mut UsbDemux, lt: u32, records: &[(u64, Vec<u8>)]) -> Vec<UsbOut> {
    let mut out = Vec::new();
    let mut off = 24u64;
    for (ts, r) in records {
        demux.packet(lt, r, r.len() as u32, *ts, off + 16, &mut out);
        off += 16 + r.len() as u64;
    }
    demux.finish(&mut out);
    out
}

fn chunks_of(out: &[UsbOut]) -> Vec<OwnedChunk> {
    out.iter()
        .filter_map(|o| match o {
            UsbOut::Chunk(c) => Some(c.clone()),
            _ => None,
        })
        .collect()
}

fn streams_of(out: &[UsbOut]) -> Vec<StreamInfo> {
    out.iter()
        .filter_map(|o| match o {
            UsbOut::Stream(s) => Some(s.clone()),
            _ => None,
        })
        .collect()
}

fn diags_of(out: &[UsbOut]) -> Vec<ReadDiag> {
    out.iter()
        .filter_map(|o| match o {
            UsbOut::Diag(d) => Some(d.clone()),
            _ => None,
        })
        .collect()
}

fn sample() -> Vec<OwnedChunk> {
    let long: Vec<u8> = (0..=255u8).cycle().take(700).collect();
    vec![
        chunk(
            1_000,
            Direction::HostToDevice,
            &[0x05, 0x00, 0x00, 0x00, 0x50, 0x01],
        ),
        chunk(
            2_000_500,
            Direction::DeviceToHost,
            &[0x06, 0x00, 0x54, 0x00, 0x81, 0x50],
        ),
        chunk(3_000_000_000, Direction::DeviceToHost, &[0xaa; 62]),
        chunk(3_000_001_000, Direction::DeviceToHost, &[0xbb; 63]),
        chunk(3_000_002_000, Direction::DeviceToHost, &long),
        chunk(4_000_000_000, Direction::HostToDevice, &long),
        chunk(4_000_000_001, Direction::DeviceToHost, &[0x01]),
    ]
}

#[test]
fn synth_round_trip() {
    for mps in [64, 512] {
        let input = sample();
        let recs = synth_usbmon(&input, 1, 7, mps);
        let out = feed(&mut UsbDemux::new(None), LINKTYPE_USB_LINUX_MMAPPED, &recs);
        assert_eq!(diags_of(&out), vec![], "mps {mps}");
        assert_eq!(
            streams_of(&out),
            vec![StreamInfo {
                id: 0,
                name: "usb 1:7 0403:faf0".into(),
                settings: Some("115200 8N1 RTS/CTS".into()),
            }]
        );
        assert!(matches!(out[0], UsbOut::Stream(_)));
        assert_eq!(chunks_of(&out), input, "mps {mps}");
    }
}

#[test]
fn linktype_189_and_big_endian_headers() {
    let input = sample();
    let recs = synth_usbmon(&input, 3, 12, 64);
    // 48-byte headers: drop bytes 48..64 of every record.
    let short: Vec<(u64, Vec<u8>)> = recs
        .iter()
        .map(|(t, r)| (*t, [&r[..48], &r[64..]].concat()))
        .collect();
    let out = feed(&mut UsbDemux::new(None), LINKTYPE_USB_LINUX, &short);
    assert_eq!(diags_of(&out), vec![]);
    assert_eq!(streams_of(&out)[0].name, "usb 3:12 0403:faf0");
    assert_eq!(chunks_of(&out), input);
    // Written on a big-endian host: every multi-byte header field swapped.
    let swapped: Vec<(u64, Vec<u8>)> = recs
        .iter()
        .map(|(t, r)| {
            let mut r = r.clone();
            for (at, n) in [
                (0, 8),
                (12, 2),
                (16, 8),
                (24, 4),
                (28, 4),
                (32, 4),
                (36, 4),
                (48, 4),
                (52, 4),
                (56, 4),
                (60, 4),
            ] {
                r[at..at + n].reverse();
            }
            (*t, r)
        })
        .collect();
    let out = feed(
        &mut UsbDemux::new(None),
        LINKTYPE_USB_LINUX_MMAPPED,
        &swapped,
    );
    assert_eq!(diags_of(&out), vec![]);
    assert_eq!(streams_of(&out)[0].name, "usb 3:12 0403:faf0");
    assert_eq!(chunks_of(&out), input);
}

/// A bulk IN completion record (usbmon, 64-byte header) with `data` as on the wire.
fn bulk_in(bus: u16, addr: u8, ts: u64, data: &[u8]) -> Vec<u8> {
    MonHdr {
        id: 0x1234,
        event: b'C',
        xfer: XFER_BULK,
        ep: 0x81,
        addr,
        bus,
        ts_ns: ts,
        status: 0,
        length: data.len() as u32,
        setup: None,
    }
    .record(Some(data))
}

fn bulk_out(bus: u16, addr: u8, ts: u64, data: &[u8]) -> Vec<u8> {
    MonHdr {
        id: 0x5678,
        event: b'S',
        xfer: XFER_BULK,
        ep: 0x02,
        addr,
        bus,
        ts_ns: ts,
        status: -115,
        length: data.len() as u32,
        setup: None,
    }
    .record(Some(data))
}

#[test]
fn status_bytes_removed_at_every_piece() {
    // 64-byte pieces: 2 status + 62 data, 2 status + 62 data, 2 status + 3 data, then a
    // completion with the status bytes only.
    let mut wire = vec![0x01, 0x60];
    wire.extend(0..62u8);
    wire.extend([0x31, 0x60]);
    wire.extend(62..124u8);
    wire.extend([0x31, 0x62]);
    wire.extend(124..127u8);
    let recs = vec![
        (10, bulk_in(2, 3, 10, &wire)),
        (20, bulk_in(2, 3, 20, &[0x01, 0x60])),
        // A final piece of exactly the 2 status bytes adds nothing.
        (
            30,
            bulk_in(
                2,
                3,
                30,
                &[[0x01, 0x60].as_slice(), &[9; 62], &[0x01, 0x60]].concat(),
            ),
        ),
    ];
    let out = feed(&mut UsbDemux::new(None), LINKTYPE_USB_LINUX_MMAPPED, &recs);
    let s = streams_of(&out);
    assert_eq!(s.len(), 1);
    assert_eq!(
        s[0].name,
        "usb 2:3 (assumed FTDI: no device descriptor in capture)"
    );
    let c = chunks_of(&out);
    assert_eq!(c.len(), 2);
    assert_eq!(c[0].bytes, (0..127u8).collect::<Vec<_>>());
    assert_eq!(c[0].dir, Direction::DeviceToHost);
    assert_eq!(c[0].ts_ns, Some(10));
    assert_eq!(c[1].bytes, vec![9; 62]);
    assert_eq!(strip_ftdi_status(&[1, 2, 3, 4, 5, 6, 7], 3), vec![3, 6]);
    assert_eq!(strip_ftdi_status(&[1, 2], 64), Vec::<u8>::new());
}

#[test]
fn max_packet_512_inferred_without_descriptors() {
    let data: Vec<u8> = (0..600u32).map(|i| (i % 150 + 0x40) as u8).collect();
    let input = vec![
        chunk(5, Direction::HostToDevice, b"hello"),
        chunk(6, Direction::DeviceToHost, &data),
    ];
    let recs: Vec<_> = synth_usbmon(&input, 1, 4, 512)
        .into_iter()
        .filter(|(_, r)| r[9] == XFER_BULK)
        .collect();
    let out = feed(&mut UsbDemux::new(None), LINKTYPE_USB_LINUX_MMAPPED, &recs);
    let kinds: Vec<_> = diags_of(&out).iter().map(|d| d.kind()).collect();
    assert_eq!(kinds, vec!["usb_max_packet_inferred"]);
    assert_eq!(chunks_of(&out), input);
}

/// A USBPcap record: base header (+ control stage) and data.
#[allow(clippy::too_many_arguments)]
fn usbpcap(
    irp: u64,
    pdo_to_fdo: bool,
    bus: u16,
    dev: u16,
    ep: u8,
    transfer: u8,
    stage: Option<u8>,
    data: &[u8],
) -> Vec<u8> {
    let hlen: u16 = if stage.is_some() { 28 } else { 27 };
    let mut r = Vec::new();
    r.extend_from_slice(&hlen.to_le_bytes());
    r.extend_from_slice(&irp.to_le_bytes());
    r.extend_from_slice(&0u32.to_le_bytes());
    let function: u16 = if transfer == XFER_BULK {
        0x0009
    } else {
        0x0008
    };
    r.extend_from_slice(&function.to_le_bytes());
    r.push(u8::from(pdo_to_fdo));
    r.extend_from_slice(&bus.to_le_bytes());
    r.extend_from_slice(&dev.to_le_bytes());
    r.push(ep);
    r.push(transfer);
    r.extend_from_slice(&(data.len() as u32).to_le_bytes());
    if let Some(s) = stage {
        r.push(s);
    }
    assert_eq!(r.len(), usize::from(hlen));
    r.extend_from_slice(data);
    r
}

#[test]
fn usbpcap_packet_pair() {
    let recs = vec![
        (
            100,
            usbpcap(
                0xffffa001,
                false,
                1,
                5,
                0x02,
                XFER_BULK,
                None,
                b"\x05\x00\x00\x00\x50\x01",
            ),
        ),
        (
            101,
            usbpcap(0xffffa001, true, 1, 5, 0x02, XFER_BULK, None, b""),
        ),
        (
            102,
            usbpcap(0xffffa002, false, 1, 5, 0x81, XFER_BULK, None, b""),
        ),
        (
            103,
            usbpcap(
                0xffffa002,
                true,
                1,
                5,
                0x81,
                XFER_BULK,
                None,
                b"\x01\x60\x06\x00\x54\x00\x81\x50",
            ),
        ),
    ];
    let out = feed(&mut UsbDemux::new(None), LINKTYPE_USBPCAP, &recs);
    assert_eq!(diags_of(&out), vec![]);
    assert_eq!(
        streams_of(&out)[0].name,
        "usb 1:5 (assumed FTDI: no device descriptor in capture)"
    );
    assert_eq!(
        chunks_of(&out),
        vec![
            chunk(
                100,
                Direction::HostToDevice,
                &[0x05, 0x00, 0x00, 0x00, 0x50, 0x01]
            ),
            chunk(
                103,
                Direction::DeviceToHost,
                &[0x06, 0x00, 0x54, 0x00, 0x81, 0x50]
            ),
        ]
    );
    // With the descriptors USBPcapCMD injects (IRP id 0, setup / data / status stages), a
    // baud rate request (9600: 0x4138), and a full-speed IN transfer of two pieces.
    let device = [
        18, 1, 0, 2, 0, 0, 0, 8, 0x03, 0x04, 0xf0, 0xfa, 0, 6, 1, 2, 3, 1,
    ];
    let ctl =
        |pdo, ep, stage, data: &[u8]| usbpcap(0, pdo, 1, 5, ep, XFER_CONTROL, Some(stage), data);
    let mut wire = vec![0x01, 0x60];
    wire.extend([b'x'; 62]);
    wire.extend([0x01, 0x60, b'y']);
    let recs = vec![
        (1, ctl(false, 0x80, 0, &[0x80, 6, 0, 1, 0, 0, 18, 0])),
        (1, ctl(true, 0x80, 1, &device)),
        (1, ctl(true, 0x80, 2, &[])),
        (
            2,
            usbpcap(
                7,
                false,
                1,
                5,
                0x00,
                XFER_CONTROL,
                Some(0),
                &[0x40, 3, 0x38, 0x41, 0, 0, 0, 0],
            ),
        ),
        (2, usbpcap(7, true, 1, 5, 0x00, XFER_CONTROL, Some(3), &[])),
        (3, usbpcap(8, true, 1, 5, 0x81, XFER_BULK, None, &wire)),
    ];
    let out = feed(&mut UsbDemux::new(None), LINKTYPE_USBPCAP, &recs);
    assert_eq!(diags_of(&out), vec![]);
    assert_eq!(
        streams_of(&out),
        vec![StreamInfo {
            id: 0,
            name: "usb 1:5 0403:faf0".into(),
            settings: Some("9600".into()),
        }]
    );
    let mut want = vec![b'x'; 62];
    want.push(b'y');
    assert_eq!(
        chunks_of(&out),
        vec![chunk(3, Direction::DeviceToHost, &want)]
    );
}

#[test]
fn truncated_and_bad_records() {
    let good = bulk_out(1, 2, 50, b"abc");
    // len_cap says 10 bytes, the record holds 4 (snapshot length).
    let mut short_data = bulk_out(1, 2, 60, b"0123456789");
    short_data.truncate(64 + 4);
    // usbmon itself captured 3 of 8 bytes.
    let mut cut = bulk_out(1, 2, 70, b"xyz");
    cut[32..36].copy_from_slice(&8u32.to_le_bytes());
    // usbmon did not capture the data at all.
    let mut uncaptured = bulk_out(1, 2, 75, b"zz");
    uncaptured.truncate(64);
    uncaptured[15] = b'Z';
    uncaptured[36..40].copy_from_slice(&0u32.to_le_bytes());
    let mut unknown_xfer = bulk_out(1, 2, 80, b"q");
    unknown_xfer[9] = 7;
    let mut unknown_event = bulk_out(1, 2, 80, b"q");
    unknown_event[8] = b'Z';
    let recs: Vec<(u64, Vec<u8>)> = vec![
        (40, good[..30].to_vec()),
        (50, good.clone()),
        (60, short_data),
        (70, cut),
        (75, uncaptured),
        (80, unknown_xfer),
        (80, unknown_event),
        (90, bulk_in(1, 2, 90, &[0x01, 0x60, b'!'])),
    ];
    let mut out = Vec::new();
    let mut demux = UsbDemux::new(None);
    for (i, (ts, r)) in recs.iter().enumerate() {
        demux.packet(
            LINKTYPE_USB_LINUX_MMAPPED,
            r,
            200,
            *ts,
            1000 * i as u64,
            &mut out,
        );
    }
    demux.finish(&mut out);
    let d: Vec<(u64, &str)> = diags_of(&out)
        .iter()
        .map(|d| (d.offset, d.kind()))
        .collect();
    assert_eq!(
        d,
        vec![
            (0, "usb_record_too_short"),
            (2000, "truncated_urb"),
            (3000, "truncated_urb"),
            (4000, "truncated_urb"),
            (5000, "usb_unknown_transfer_type"),
            (6000, "usb_unknown_event"),
        ]
    );
    assert!(diags_of(&out)[0].msg().contains("snapshot length"));
    // The typed problems say what was expected and found, in the words they always had.
    let msgs: Vec<String> = diags_of(&out).iter().map(ReadDiag::msg).collect();
    let shown = "(usb 1:2 endpoint 0x02): the bytes present are shown";
    assert_eq!(
        msgs,
        [
            "usbmon record of 30 bytes (cut from 200 by the capture's snapshot length) is \
             shorter than its 64-byte header"
                .to_string(),
            format!(
                "usbmon header announces 10 captured bytes, the record holds 4 (cut from 200 by \
                 the capture's snapshot length) {shown}"
            ),
            format!("URB of 8 bytes of which usbmon captured 3 {shown}"),
            format!("URB of 2 bytes whose data usbmon did not capture (data flag 0x5a) {shown}"),
            "usbmon transfer type 7 is none of 0-3 (usb 1:2)".to_string(),
            "usbmon event type 0x5a is none of S, C, E".to_string(),
        ]
    );
    assert_eq!(
        diags_of(&out)[2].problem,
        ReadProblem::Usb(UsbProblem::TruncatedUrb {
            cut: UrbCut::Uncaptured {
                length: 8,
                captured: 3
            },
            bus: 1,
            addr: 2,
            ep: 2
        })
    );
    let bytes: Vec<Vec<u8>> = chunks_of(&out).into_iter().map(|c| c.bytes).collect();
    assert_eq!(
        bytes,
        vec![
            b"abc".to_vec(),
            b"0123".to_vec(),
            b"xyz".to_vec(),
            b"!".to_vec()
        ]
    );
    // USBPcap: header too short, headerLen past the record, data past the record.
    let mut out = Vec::new();
    let mut demux = UsbDemux::new(None);
    let mut bad_len = usbpcap(1, false, 1, 5, 0x02, XFER_BULK, None, b"abc");
    bad_len[0] = 200;
    let mut past = usbpcap(1, false, 1, 5, 0x02, XFER_BULK, None, b"abcdef");
    past.truncate(27 + 2);
    demux.packet(LINKTYPE_USBPCAP, &[0; 10], 10, 1, 11, &mut out);
    demux.packet(LINKTYPE_USBPCAP, &bad_len, 30, 2, 22, &mut out);
    demux.packet(LINKTYPE_USBPCAP, &past, 33, 3, 33, &mut out);
    let d: Vec<(u64, &str)> = diags_of(&out)
        .iter()
        .map(|d| (d.offset, d.kind()))
        .collect();
    assert_eq!(
        d,
        vec![
            (11, "usb_record_too_short"),
            (22, "usb_record_too_short"),
            (33, "truncated_urb")
        ]
    );
    let msgs: Vec<String> = diags_of(&out).iter().map(ReadDiag::msg).collect();
    assert_eq!(
        msgs,
        [
            "USBPcap record of 10 bytes is shorter than its 27-byte header",
            "USBPcap record of 30 bytes is shorter than its 200-byte header",
            "USBPcap header announces 6 data bytes, the record holds 2 (cut from 33 by the \
             capture's snapshot length) (usb 1:5 endpoint 0x02): the bytes present are shown"
        ]
    );
    demux.finish(&mut out);
    assert_eq!(chunks_of(&out).len(), 1);
    assert_eq!(chunks_of(&out)[0].bytes, b"ab".to_vec());
}

#[test]
fn devices_filter_and_non_ftdi() {
    let a = synth_usbmon(&[chunk(1, Direction::HostToDevice, b"to a")], 1, 7, 64);
    let b = synth_usbmon(&[chunk(2, Direction::DeviceToHost, b"from b")], 2, 9, 64);
    let mut recs = a.clone();
    recs.extend(b);
    // A mass-storage device without descriptor on the same endpoints: CBW out, CSW in.
    recs.push((3, bulk_out(1, 4, 3, b"USBC\x01\x00\x00\x00")));
    recs.push((
        4,
        bulk_in(1, 4, 4, b"USBS\x01\x00\x00\x00\x00\x00\x00\x00\x00"),
    ));
    let out = feed(&mut UsbDemux::new(None), LINKTYPE_USB_LINUX_MMAPPED, &recs);
    let names: Vec<_> = streams_of(&out)
        .into_iter()
        .map(|s| (s.id, s.name))
        .collect();
    assert_eq!(
        names,
        vec![
            (0, "usb 1:7 0403:faf0".to_string()),
            (1, "usb 2:9 0403:faf0".to_string())
        ]
    );
    let c = chunks_of(&out);
    assert_eq!(
        (c[0].stream, c[0].bytes.as_slice()),
        (0, b"to a".as_slice())
    );
    assert_eq!(
        (c[1].stream, c[1].bytes.as_slice()),
        (1, b"from b".as_slice())
    );
    assert_eq!(c.len(), 2);
    let kinds: Vec<_> = diags_of(&out).iter().map(|d| d.kind()).collect();
    assert_eq!(kinds, vec!["usb_not_ftdi"]);
    // --usb-device 2:9
    let out = feed(
        &mut UsbDemux::new(Some((2, 9))),
        LINKTYPE_USB_LINUX_MMAPPED,
        &recs,
    );
    assert_eq!(streams_of(&out).len(), 1);
    assert_eq!(
        chunks_of(&out),
        vec![chunk(2, Direction::DeviceToHost, b"from b")]
    );
    // A described non-FTDI device is skipped silently.
    let mut other = synth_usbmon(&[chunk(1, Direction::HostToDevice, b"x")], 1, 3, 64);
    other[1].1[64 + 8] = 0x34; // idVendor 0x0434
    let out = feed(&mut UsbDemux::new(None), LINKTYPE_USB_LINUX_MMAPPED, &other);
    assert_eq!(out, vec![]);
    // --usb-device naming a device that is not there, or that sent no serial data: one
    // diagnostic listing the devices present.
    // (3:3 is enumerated, descriptors and all, and sends nothing.)
    recs.extend(synth_usbmon(&[], 3, 3, 64));
    for (want, why) in [
        ((9, 9), "usb 9:9 is not in the capture"),
        ((3, 3), "usb 3:3 is in the capture but sent no serial data"),
    ] {
        let out = feed(
            &mut UsbDemux::new(Some(want)),
            LINKTYPE_USB_LINUX_MMAPPED,
            &recs,
        );
        assert_eq!(chunks_of(&out), vec![]);
        let d = diags_of(&out);
        assert_eq!(d.len(), 1, "{d:?}");
        assert_eq!(d[0].kind(), NOT_FOUND);
        assert!(d[0].msg().contains(why), "{}", d[0].msg());
        let ReadProblem::UsbNote(UsbNote::DeviceNotFound { present, .. }) = &d[0].problem else {
            panic!("{:?}", d[0]);
        };
        let ftdi = Some((0x0403, 0xfaf0));
        let (bus, addr) = (1, 7);
        assert_eq!(present.len(), 4, "{present:?}");
        assert_eq!(
            present[1],
            UsbDevice {
                bus,
                addr,
                ids: ftdi
            }
        );
        assert!(
            d[0].msg().contains(
                "devices present: 1:4 (no descriptor in the capture), 1:7 (0403:faf0, FTDI), \
                 2:9 (0403:faf0, FTDI), 3:3 (0403:faf0, FTDI)"
            ),
            "{}",
            d[0].msg()
        );
    }
}

#[test]
fn line_settings_change_after_announcement() {
    let mut recs = synth_usbmon(&[chunk(1, Direction::HostToDevice, b"a")], 1, 7, 64);
    let mut w = Synth {
        bus: 1,
        addr: 7,
        next_id: 1,
        records: Vec::new(),
    };
    // 9600 baud, 7E2, flow control off
    w.control_out(2, [0x40, SIO_SET_BAUDRATE, 0x38, 0x41, 0, 0, 0, 0]);
    w.control_out(2, [0x40, SIO_SET_DATA, 7, 0x12, 0, 0, 0, 0]);
    w.control_out(2, [0x40, SIO_SET_FLOW_CTRL, 0, 0, 0, 0, 0, 0]);
    recs.extend(w.records);
    let out = feed(&mut UsbDemux::new(None), LINKTYPE_USB_LINUX_MMAPPED, &recs);
    let d: Vec<(&str, String)> = diags_of(&out)
        .into_iter()
        .map(|d| (d.kind(), d.msg()))
        .collect();
    assert_eq!(
        d,
        vec![
            (
                "line_settings",
                "usb 1:7 0403:faf0: 9600 8N1 RTS/CTS".to_string()
            ),
            (
                "line_settings",
                "usb 1:7 0403:faf0: 9600 7E2 RTS/CTS".to_string()
            ),
            ("line_settings", "usb 1:7 0403:faf0: 9600 7E2".to_string()),
        ]
    );
}

#[test]
fn baud_divisors() {
    // Values the Linux driver computes (ftdi_232bm_baud_base_to_divisor, 48 MHz).
    assert_eq!(decode_baud(0x001a, 0), "115200");
    assert_eq!(decode_baud(0x4138, 0), "9600");
    assert_eq!(decode_baud(0x0000, 0), "3000000");
    assert_eq!(decode_baud(0x0001, 0), "2000000");
    assert_eq!(decode_baud(0x8003, 0), "921600");
    assert_eq!(decode_baud(0x0006, 0), "500000");
    assert_eq!(decode_baud(0x000c, 0), "250000");
    // A 17th divisor bit: 0x1_c028 = 40 + 7/8 → 73394 baud (no standard rate near).
    assert_eq!(decode_baud(0xc028, 1), "73394");
    // H chips at 120 MHz (bit 17): 115200 → 833 eighths = 104 + 1/8 (code 3) → 115246.
    let d3 = 96_000_000u32 / 115_200; // 833 eighths
    let code = [0u32, 3, 2, 4, 1, 5, 6, 7][(d3 & 7) as usize];
    let div = (d3 >> 3) | (code << 14) | 0x2_0000;
    assert_eq!(decode_baud(div as u16, (div >> 16) as u16), "115200");
    assert_eq!(format_data_bits(0x0008), "8N1");
    assert_eq!(format_data_bits(0x1207), "7E2");
    assert_eq!(format_flow(1), "RTS/CTS");
    assert_eq!(format_flow(5), "RTS/CTS+XON/XOFF");
}

#[test]
fn garbage_never_panics() {
    let mut demux = UsbDemux::new(None);
    let mut out = Vec::new();
    let mut x: u32 = 12345;
    for n in 0..2000usize {
        let len = n % 140;
        let mut r = Vec::with_capacity(len);
        for _ in 0..len {
            x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
            r.push((x >> 16) as u8);
        }
        if len > 10 {
            r[8] = [b'S', b'C'][n % 2];
            r[9] = (n % 4) as u8;
        }
        for lt in [189, 220, 249, 1] {
            demux.packet(lt, &r, len as u32, n as u64, n as u64, &mut out);
        }
    }
    demux.finish(&mut out);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn synth_round_trips(
        spec in proptest::collection::vec(
            (any::<bool>(), proptest::collection::vec(any::<u8>(), 1..1500), 0u64..10_000_000_000),
            0..24,
        ),
        high_speed in any::<bool>(),
    ) {
        let mps = if high_speed { 512 } else { 64 };
        let mut ts = 1_700_000_000_000_000_000u64;
        let input: Vec<OwnedChunk> = spec
            .into_iter()
            .map(|(out, bytes, dt)| {
                ts += dt;
                OwnedChunk {
                    ts_ns: Some(ts - ts % 1000),
                    dir: if out { Direction::HostToDevice } else { Direction::DeviceToHost },
                    stream: 0,
                    bytes,
                }
            })
            .collect();
        let recs = synth_usbmon(&input, 1, 7, mps);
        let out = feed(&mut UsbDemux::new(None), LINKTYPE_USB_LINUX_MMAPPED, &recs);
        prop_assert_eq!(diags_of(&out), vec![]);
        prop_assert_eq!(streams_of(&out).len(), usize::from(!input.is_empty()));
        prop_assert_eq!(chunks_of(&out), input);
    }
}
