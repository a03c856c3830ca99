//! Linux usbmon packets (link types 189 and 220): header byte order, parsing, and writing
//! them (for tests and the simulators' captures).

use super::*;

impl UsbDemux {
    /// usbmon header byte order: the one in which the bus number and the microseconds are
    /// plausible; when both or neither are, the order settled by an earlier header, else LE.
    pub(super) fn usbmon_big_endian(&mut self, data: &[u8]) -> bool {
        let plausible = |be: bool| {
            let bus = rd16(data, 12, be);
            let usec = rd32(data, 24, be);
            bus != 0 && bus < 0x100 && usec < 1_000_000
        };
        match (plausible(false), plausible(true)) {
            (true, false) => {
                self.big_endian = Some(false);
                false
            }
            (false, true) => {
                self.big_endian = Some(true);
                true
            }
            _ => self.big_endian.unwrap_or(false),
        }
    }

    pub(super) fn parse_usbmon<'a>(
        &mut self,
        data: &'a [u8],
        hdr_len: usize,
        orig_len: u32,
        off: u64,
        out: &mut Vec<UsbOut>,
    ) -> Option<Urb<'a>> {
        if !holds_header(UsbFormat::Usbmon, hdr_len, data, orig_len, off, out) {
            return None;
        }
        let be = self.usbmon_big_endian(data);
        let id = rd64(data, 0, be);
        let event = data[8];
        let xfer = data[9];
        let ep = data[10];
        let addr = u16::from(data[11]);
        let bus = rd16(data, 12, be);
        let flag_setup = data[14];
        let flag_data = data[15];
        let length = rd32(data, 32, be);
        let len_cap = rd32(data, 36, be);
        let submit = match event {
            b'S' => true,
            b'C' => false,
            // A submission error: nothing was transferred.
            b'E' => return None,
            other => {
                usb_diag(out, off, UsbProblem::UnknownEvent { found: other });
                return None;
            }
        };
        if !shown_transfer(UsbFormat::Usbmon, xfer, &[], (bus, addr), off, out) {
            return None;
        }
        let setup = if submit && xfer == XFER_CONTROL && flag_setup == 0 {
            let mut s = [0u8; 8];
            s.copy_from_slice(&data[40..48]);
            Some(s)
        } else {
            None
        };
        let avail = &data[hdr_len..];
        let mut payload: &[u8] = &[];
        let mut truncated = None;
        if flag_data == 0 {
            let cap = usize::try_from(len_cap).unwrap_or(usize::MAX);
            if cap > avail.len() {
                payload = avail;
                truncated = Some(UrbCut::Record {
                    format: UsbFormat::Usbmon,
                    expected: u64::from(len_cap),
                    found: avail.len(),
                    record: data.len(),
                    original: orig_len,
                });
            } else {
                payload = &avail[..cap];
                if len_cap < length {
                    truncated = Some(UrbCut::Uncaptured {
                        length,
                        captured: len_cap,
                    });
                }
            }
        } else if (ep & 0x80 != 0) != submit && length > 0 {
            // OUT submissions and IN completions carry data; usbmon says why it has none.
            truncated = Some(UrbCut::NoData {
                length,
                flag: flag_data,
            });
        }
        Some(Urb {
            bus,
            addr,
            ep,
            xfer,
            submit,
            id,
            setup,
            data: payload,
            truncated,
        })
    }
}

/// Fields of a usbmon header (for [`synth_usbmon`]).
pub(super) struct MonHdr {
    pub(super) id: u64,
    pub(super) event: u8,
    pub(super) xfer: u8,
    pub(super) ep: u8,
    pub(super) addr: u8,
    pub(super) bus: u16,
    pub(super) ts_ns: u64,
    pub(super) status: i32,
    pub(super) length: u32,
    pub(super) setup: Option<[u8; 8]>,
}

impl MonHdr {
    /// The 64-byte header (little-endian) followed by `data`.
    pub(super) fn record(&self, data: Option<&[u8]>) -> Vec<u8> {
        let mut r = Vec::with_capacity(USBMON_MMAP_HDR + data.map_or(0, <[u8]>::len));
        r.extend_from_slice(&self.id.to_le_bytes());
        r.extend_from_slice(&[self.event, self.xfer, self.ep, self.addr]);
        r.extend_from_slice(&self.bus.to_le_bytes());
        r.push(if self.setup.is_some() { 0 } else { b'-' });
        r.push(match (data, self.ep & 0x80 != 0) {
            (Some(_), _) => 0,
            (None, true) => b'<',
            (None, false) => b'>',
        });
        let sec = (self.ts_ns / 1_000_000_000) as i64;
        let usec = ((self.ts_ns % 1_000_000_000) / 1000) as i32;
        r.extend_from_slice(&sec.to_le_bytes());
        r.extend_from_slice(&usec.to_le_bytes());
        r.extend_from_slice(&self.status.to_le_bytes());
        r.extend_from_slice(&self.length.to_le_bytes());
        let len_cap = data.map_or(0, <[u8]>::len) as u32;
        r.extend_from_slice(&len_cap.to_le_bytes());
        r.extend_from_slice(&self.setup.unwrap_or([0; 8]));
        // interval, start_frame, xfer_flags, ndesc
        r.extend_from_slice(&[0u8; 16]);
        if let Some(d) = data {
            r.extend_from_slice(d);
        }
        r
    }
}

/// Builds the records of [`synth_usbmon`].
pub(super) struct Synth {
    pub(super) bus: u16,
    pub(super) addr: u8,
    pub(super) next_id: u64,
    pub(super) records: Vec<(u64, Vec<u8>)>,
}

impl Synth {
    const EINPROGRESS: i32 = -115;

    /// A submission and its completion.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn urb(
        &mut self,
        ts: u64,
        xfer: u8,
        ep: u8,
        setup: Option<[u8; 8]>,
        length: u32,
        out_data: Option<&[u8]>,
        in_data: Option<&[u8]>,
    ) {
        let id = self.next_id;
        self.next_id += 0x100;
        let hdr = |event, status, length, setup| MonHdr {
            id,
            event,
            xfer,
            ep,
            addr: self.addr,
            bus: self.bus,
            ts_ns: ts,
            status,
            length,
            setup,
        };
        let s = hdr(b'S', Self::EINPROGRESS, length, setup).record(out_data);
        let done = in_data.map_or(length, |d| d.len() as u32);
        let c = hdr(b'C', 0, done, None).record(in_data);
        self.records.push((ts, s));
        self.records.push((ts, c));
    }

    pub(super) fn control_in(&mut self, ts: u64, setup: [u8; 8], answer: &[u8]) {
        let wlength = u16::from_le_bytes([setup[6], setup[7]]);
        self.urb(
            ts,
            XFER_CONTROL,
            0x80,
            Some(setup),
            u32::from(wlength),
            None,
            Some(answer),
        );
    }

    pub(super) fn control_out(&mut self, ts: u64, setup: [u8; 8]) {
        self.urb(ts, XFER_CONTROL, 0x00, Some(setup), 0, None, None);
    }
}

/// Build a usbmon capture (link type 220 records, as (ts_ns, record bytes)) of serial chunks
/// exchanged with one FTDI device, inserting the 2 FTDI modem-status bytes at the start of every
/// max-packet-size piece of bulk IN data, as a real FT232 does. For tests and samples.
///
/// The capture starts as after plugging in a Thorlabs controller: device and configuration
/// descriptors (0403:faf0, bulk endpoints 0x81/0x02 of `max_packet` bytes), then the FTDI vendor
/// requests for 115200 8N1 RTS/CTS and a status-only IN packet. Each chunk then becomes one bulk
/// URB (OUT for host → device, IN for device → host) at the chunk's timestamp (the previous one
/// when it has none, 0 before any). Chunks without bytes or of unknown direction are left out;
/// `stream` is ignored. `max_packet` is clamped to 3..=2047.
pub fn synth_usbmon(
    chunks: &[OwnedChunk],
    bus: u16,
    addr: u8,
    max_packet: usize,
) -> Vec<(u64, Vec<u8>)> {
    let mps = max_packet.clamp(3, 0x7ff);
    let mut w = Synth {
        bus,
        addr,
        next_id: 0xffff_8881_0a3c_0000,
        records: Vec::new(),
    };
    let t0 = chunks.iter().find_map(|c| c.ts_ns).unwrap_or(0);
    let high_speed = mps > 64;
    let [bcd_lo, bcd_hi] = (if high_speed { 0x0900u16 } else { 0x0600 }).to_le_bytes();
    let ep0 = if high_speed { 64 } else { 8 };
    let device = [
        18, 1, 0x00, 0x02, 0, 0, 0, ep0, 0x03, 0x04, 0xf0, 0xfa, bcd_lo, bcd_hi, 1, 2, 3, 1,
    ];
    let [m_lo, m_hi] = (mps as u16).to_le_bytes();
    let config = [
        9, 2, 32, 0, 1, 1, 0, 0xa0, 45, // configuration
        9, 4, 0, 0, 2, 0xff, 0xff, 0xff, 2, // interface 0, vendor class
        7, 5, 0x81, 2, m_lo, m_hi, 0, // bulk IN
        7, 5, 0x02, 2, m_lo, m_hi, 0, // bulk OUT
    ];
    w.control_in(t0, [0x80, 6, 0, 1, 0, 0, 18, 0], &device);
    w.control_in(t0, [0x80, 6, 0, 2, 0, 0, 32, 0], &config);
    w.control_out(t0, [0x40, SIO_RESET, 0, 0, 0, 0, 0, 0]);
    // 115200 baud: 3 MHz / 26 (Thorlabs APT)
    w.control_out(t0, [0x40, SIO_SET_BAUDRATE, 0x1a, 0, 0, 0, 0, 0]);
    w.control_out(t0, [0x40, SIO_SET_DATA, 8, 0, 0, 0, 0, 0]);
    w.control_out(t0, [0x40, SIO_SET_FLOW_CTRL, 0, 0, 0, 1, 0, 0]);
    const STATUS: [u8; 2] = [0x31, 0x60];
    w.urb(t0, XFER_BULK, 0x81, None, mps as u32, None, Some(&STATUS));
    let mut ts = t0;
    let mut piece = Vec::new();
    for c in chunks {
        if let Some(t) = c.ts_ns {
            ts = t;
        }
        if c.bytes.is_empty() {
            continue;
        }
        match c.dir {
            Direction::HostToDevice => {
                let len = c.bytes.len() as u32;
                w.urb(ts, XFER_BULK, 0x02, None, len, Some(&c.bytes), None);
            }
            Direction::DeviceToHost => {
                piece.clear();
                for part in c.bytes.chunks(mps - 2) {
                    piece.extend_from_slice(&STATUS);
                    piece.extend_from_slice(part);
                }
                let buf = piece.len().div_ceil(mps) * mps;
                w.urb(ts, XFER_BULK, 0x81, None, buf as u32, None, Some(&piece));
            }
            Direction::Unknown => {}
        }
    }
    w.records
}
