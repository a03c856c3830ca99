//! The FTDI unwrapping of USB captures (`usb::UsbDemux`: usbmon with 48- and 64-byte headers,
//! USBPcap), packet by packet, without the pcap container around it.
//!
//! Input: `[mode, filter, mps, then the rest]`. Mode 0 (`mode % 3`): the rest is serial chunks
//! (`[dir, len, bytes...]` each) that `synth_usbmon` turns into a capture of one FTDI device
//! with `mps`-byte packets; mode 1: the same capture with bytes flipped (`[at_lo, at_hi, xor]`
//! triples after a NUL-length chunk); mode 2: the rest is packets (`[linktype, len_lo, len_hi,
//! cut, bytes...]`, `cut`: how many bytes the original was longer). Checks: streams are
//! announced once, each before its first chunk; diagnostics have snake_case kinds and the
//! offset of the packet they are about; chunks never hold more bytes than the packets; with a
//! `--usb-device` filter (`filter & 1`), one device's streams at most; mode 0: the bytes come
//! out as they went in, per direction, with no diagnostic but line settings.

use aptscope_capture::usb::{
    synth_usbmon, UsbDemux, UsbOut, LINKTYPE_USBPCAP, LINKTYPE_USB_LINUX,
    LINKTYPE_USB_LINUX_MMAPPED,
};
use aptscope_capture::{Direction, OwnedChunk};

/// Serial chunks from the input, up to an empty one (its length byte 0) or the end; what
/// follows it.
fn chunks(mut b: &[u8]) -> (Vec<OwnedChunk>, &[u8]) {
    let mut out = vec![];
    let mut ts = 1_000_000_000u64;
    while b.len() >= 2 {
        let (dir, len) = (b[0], b[1] as usize);
        b = &b[2..];
        if len == 0 {
            break;
        }
        let n = len.min(b.len());
        ts += u64::from(dir >> 2) * 1000;
        out.push(OwnedChunk {
            ts_ns: (dir & 2 != 0).then_some(ts),
            dir: if dir & 1 == 0 {
                Direction::HostToDevice
            } else {
                Direction::DeviceToHost
            },
            stream: 0,
            bytes: b[..n].to_vec(),
        });
        b = &b[n..];
    }
    (out, b)
}

/// Feed packets `(linktype, bytes, orig_len)`; check what holds for any packets.
fn feed(filter: Option<(u16, u8)>, packets: &[(u32, Vec<u8>, u32)]) -> Vec<UsbOut> {
    let mut d = UsbDemux::new(filter);
    let mut out = vec![];
    let mut offsets = vec![];
    let mut off = 24u64;
    for (lt, p, orig) in packets {
        let before = out.len();
        d.packet(*lt, p, *orig, off, off + 16, &mut out);
        offsets.extend(std::iter::repeat_n(off + 16, out.len() - before));
        off += 16 + p.len() as u64;
    }
    let before = out.len();
    d.finish(&mut out);
    offsets.extend(std::iter::repeat_n(off, out.len() - before));
    let total: usize = packets.iter().map(|(_, p, _)| p.len()).sum();
    let (mut streams, mut bytes) = (vec![], 0usize);
    for (o, at) in out.iter().zip(&offsets) {
        match o {
            UsbOut::Stream(s) => {
                assert!(!streams.contains(&s.id), "stream {} announced twice", s.id);
                streams.push(s.id);
            }
            UsbOut::Chunk(c) => {
                assert!(streams.contains(&c.stream), "chunk before its stream");
                bytes += c.bytes.len();
            }
            UsbOut::Diag(x) => {
                let k = x.kind();
                assert!(
                    !k.is_empty()
                        && k.bytes()
                            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_'),
                    "diag kind {k:?}"
                );
                // About the packet just fed (at the end: about any earlier one).
                assert!(x.offset <= *at, "diag {x} after its packet at {at}");
                let _ = x.to_string();
            }
        }
    }
    assert!(
        bytes <= total,
        "{bytes} bytes of chunks from {total} bytes of packets"
    );
    if let Some((bus, addr)) = filter {
        for o in &out {
            if let UsbOut::Stream(s) = o {
                let dev = s.name.split(' ').nth(1);
                assert_eq!(dev, Some(&*format!("{bus}:{addr}")), "{}", s.name);
            }
        }
    }
    out
}

/// The body of the target: panics when a check fails.
pub fn fuzz(data: &[u8]) {
    let [mode, filter, mps] = [0, 1, 2].map(|i| data.get(i).copied().unwrap_or(0));
    let rest = data.get(3..).unwrap_or(&[]);
    let (bus, addr) = (1 + u16::from(filter >> 6), 2 + (filter >> 1 & 0x1f));
    let dev = (filter & 1 != 0).then_some((bus, addr));
    match mode % 3 {
        0 | 1 => {
            let (cs, flips) = chunks(rest);
            let mut recs = synth_usbmon(&cs, bus, addr, usize::from(mps) * 8);
            let lt = LINKTYPE_USB_LINUX_MMAPPED;
            if mode % 3 == 1 {
                for f in flips.chunks_exact(3) {
                    let at = usize::from(u16::from_le_bytes([f[0], f[1]]));
                    if let Some((_, r)) = recs.get_mut(at / 128) {
                        if let Some(b) = r.get_mut(at % 128) {
                            *b ^= f[2];
                        }
                    }
                }
            }
            let packets: Vec<(u32, Vec<u8>, u32)> = recs
                .into_iter()
                .map(|(_, r)| (lt, r.clone(), r.len() as u32))
                .collect();
            let out = feed(dev, &packets);
            if mode % 3 == 1 {
                return;
            }
            // Unchanged: the serial bytes of the chosen device come out as they went in.
            let want = |d: Direction| -> Vec<u8> {
                cs.iter()
                    .filter(|c| c.dir == d)
                    .flat_map(|c| c.bytes.clone())
                    .collect()
            };
            let got = |d: Direction| -> Vec<u8> {
                out.iter()
                    .filter_map(|o| match o {
                        UsbOut::Chunk(c) if c.dir == d => Some(c.bytes.clone()),
                        _ => None,
                    })
                    .flatten()
                    .collect()
            };
            for d in [Direction::HostToDevice, Direction::DeviceToHost] {
                assert_eq!(got(d), want(d), "{d:?} bytes");
            }
            // Line settings are announced; a `--usb-device` whose device sent no serial byte
            // (no chunk given) is reported.
            let silent = !out.iter().any(|o| matches!(o, UsbOut::Chunk(_)));
            for o in &out {
                if let UsbOut::Diag(x) = o {
                    let expected = x.kind() == "line_settings"
                        || (silent && dev.is_some() && x.kind() == "usb_device_not_found");
                    assert!(expected, "{x}");
                }
            }
        }
        _ => {
            let mut b = rest;
            let mut packets = vec![];
            while b.len() >= 4 {
                let lt = match b[0] % 4 {
                    0 => LINKTYPE_USB_LINUX,
                    1 => LINKTYPE_USB_LINUX_MMAPPED,
                    2 => LINKTYPE_USBPCAP,
                    _ => u32::from(b[0]),
                };
                let len = usize::from(u16::from_le_bytes([b[1], b[2]])) % 512;
                let cut = u32::from(b[3]);
                b = &b[4..];
                let n = len.min(b.len());
                packets.push((lt, b[..n].to_vec(), n as u32 + cut));
                b = &b[n..];
            }
            feed(dev, &packets);
        }
    }
}
