//! USB captures of FTDI-based controllers: Linux usbmon (link types 189 and 220) and Windows
//! USBPcap (249).
//!
//! Thorlabs APT controllers enumerate as FTDI 0403:faf0 (other FTDI PIDs are accepted too).
//! [`UsbDemux`] is fed one captured packet at a time by the pcap/pcapng reader and turns the URBs
//! of each FTDI device into a stream of serial chunks:
//!
//! * bulk OUT data (the URB submission) is host → device;
//! * bulk IN data (the URB completion) is device → host, once the two FTDI modem/line-status
//!   bytes that start every max-packet-size piece (64 bytes at full speed, 512 at high speed) are
//!   removed. Completions that carry only the status bytes carry no data.
//! * control transfers identify devices (GET_DESCRIPTOR of the device and configuration
//!   descriptors) and carry the line settings (FTDI vendor requests SET_BAUDRATE, SET_DATA,
//!   SET_FLOW_CTRL), reported in [`StreamInfo::settings`] or, once the stream is announced, as a
//!   `line_settings` diagnostic.
//!
//! Formats (all checked against their sources):
//!
//! * usbmon (`Documentation/usb/usbmon.rst`, libpcap `pcap/usb.h`): a 48-byte header (link type
//!   189) or a 64-byte one (220): `id` u64 @0, `type` 'S'/'C'/'E' @8, `xfer_type` @9, `epnum`
//!   @10, `devnum` @11, `busnum` u16 @12, `flag_setup` @14 (0: setup present), `flag_data` @15
//!   (0: data present), `ts_sec` @16, `ts_usec` @24, `status` @28, `length` u32 @32, `len_cap`
//!   u32 @36 (bytes of data captured), `setup[8]` @40; then the data. Fields are in the byte order
//!   of the capturing host, which pcap files do not record in the packet: it is detected from the
//!   bus number and the microseconds field (both small numbers).
//! * USBPcap (`USBPCAP_BUFFER_PACKET_HEADER`, little-endian, packed): `headerLen` u16 @0, `irpId`
//!   u64 @2, `status` @10, `function` u16 @14, `info` @16 (bit 0: PDO→FDO, i.e. completion),
//!   `bus` u16 @17, `device` u16 @19, `endpoint` @21, `transfer` @22, `dataLength` u32 @23; control
//!   transfers add `stage` @27 (0 setup, 1 data, 2 status, 3 complete). Data at `headerLen`.
//! * FTDI (Linux `ftdi_sio.h`/`ftdi_sio.c`): IN packets start with modem status (bit 0 set, bits
//!   1–3 reserved) and line status; the baud divisor is 14 bits of integer and a 3-bit fraction
//!   code (`divfrac`), the 17th bit in `wIndex`; bit 17 selects the 120 MHz clock of H chips.

use std::collections::{HashMap, VecDeque};

use crate::model::{Direction, OwnedChunk, ReadDiag, StreamInfo};

/// Linux usbmon, 48-byte header (`LINKTYPE_USB_LINUX`).
pub const LINKTYPE_USB_LINUX: u32 = 189;
/// Linux usbmon, 64-byte header (`LINKTYPE_USB_LINUX_MMAPPED`).
pub const LINKTYPE_USB_LINUX_MMAPPED: u32 = 220;
/// Windows USBPcap (`LINKTYPE_USBPCAP`).
pub const LINKTYPE_USBPCAP: u32 = 249;

/// Whether a pcap link type is one of the USB captures [`UsbDemux`] reads.
pub fn is_usb_linktype(lt: u32) -> bool {
    matches!(
        lt,
        LINKTYPE_USB_LINUX | LINKTYPE_USB_LINUX_MMAPPED | LINKTYPE_USBPCAP
    )
}

/// What [`UsbDemux::packet`] produces (the owned counterpart of [`crate::Event`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum UsbOut {
    /// A device (or one port of a multi-port FTDI chip) is announced, before its first chunk.
    Stream(StreamInfo),
    /// Serial bytes, FTDI status bytes removed.
    Chunk(OwnedChunk),
    /// A problem in the capture, or a change of line settings (`line_settings`).
    Diag(ReadDiag),
}

const FTDI_VID: u16 = 0x0403;
const USBMON_HDR: usize = 48;
const USBMON_MMAP_HDR: usize = 64;
const USBPCAP_HDR: usize = 27;

const XFER_ISO: u8 = 0;
const XFER_INTERRUPT: u8 = 1;
const XFER_CONTROL: u8 = 2;
const XFER_BULK: u8 = 3;

const USBPCAP_IRP_INFO: u8 = 0xfe;
const USBPCAP_UNKNOWN: u8 = 0xff;
const USBPCAP_STAGE_SETUP: u8 = 0;
const USBPCAP_STAGE_STATUS: u8 = 2;

/// FTDI vendor requests (bRequest, with bmRequestType 0x40).
const SIO_RESET: u8 = 0;
const SIO_SET_FLOW_CTRL: u8 = 2;
const SIO_SET_BAUDRATE: u8 = 3;
const SIO_SET_DATA: u8 = 4;

/// At most this many devices are tracked (a garbage file cannot grow the table without bound).
const MAX_DEVICES: usize = 1024;
/// Bulk OUT bytes held for a device without descriptor until its first bulk IN data shows
/// whether it is an FTDI chip; past this, it is assumed to be one.
const PENDING_LIMIT: usize = 16 * 1024;
/// GET_DESCRIPTOR requests remembered per device while waiting for their answer.
const MAX_PENDING_CONTROLS: usize = 8;
/// FTDI chips have up to four serial ports (FT4232H).
const PORTS: usize = 4;

/// One URB event, format-independent.
struct Urb<'a> {
    bus: u16,
    addr: u16,
    /// Endpoint address (bit 7: IN).
    ep: u8,
    xfer: u8,
    /// Submission (host → host controller) rather than completion.
    submit: bool,
    /// URB (usbmon) or IRP (USBPcap) id, matching a completion to its submission.
    id: u64,
    setup: Option<[u8; 8]>,
    /// The data captured (possibly fewer bytes than the transfer had).
    data: &'a [u8],
    /// Why `data` is short, when it is.
    truncated: Option<String>,
}

/// One serial port of a device: its stream and line settings.
#[derive(Default)]
struct Port {
    stream: Option<u32>,
    baud: Option<String>,
    data: Option<u16>,
    flow: Option<u16>,
    /// Settings as last announced.
    shown: Option<String>,
}

impl Port {
    fn settings(&self) -> Option<String> {
        let mut parts = Vec::new();
        if let Some(b) = &self.baud {
            parts.push(b.clone());
        }
        if let Some(d) = self.data {
            parts.push(format_data_bits(d));
        }
        if let Some(f) = self.flow.filter(|f| *f != 0) {
            parts.push(format_flow(f));
        }
        if parts.is_empty() {
            None
        } else {
            Some(parts.join(" "))
        }
    }
}

/// Whether a device without descriptor is an FTDI chip.
#[derive(Clone, Copy, PartialEq, Eq, Default)]
enum Verdict {
    #[default]
    Undecided,
    Ftdi,
    NotFtdi,
}

#[derive(Default)]
struct Device {
    /// VID:PID from the device descriptor.
    ident: Option<(u16, u16)>,
    /// bcdDevice (the FTDI chip type).
    bcd: Option<u16>,
    /// wMaxPacketSize of bulk IN endpoints 0..15 from the configuration descriptor (0: unknown).
    in_mps: [u16; 16],
    /// Max packet size inferred from the data, when no descriptor says.
    guess_mps: Option<usize>,
    ports: [Port; PORTS],
    verdict: Verdict,
    /// Bulk OUT chunks held while `verdict` is undecided (stream 0 until flushed).
    pending: Vec<OwnedChunk>,
    pending_bytes: usize,
    /// GET_DESCRIPTOR setups awaiting their completion: (URB id, setup).
    controls: VecDeque<(u64, [u8; 8])>,
}

impl Device {
    fn multi_port(&self) -> bool {
        matches!(self.bcd, Some(0x0500 | 0x0700 | 0x0800))
            || matches!(self.ident, Some((FTDI_VID, 0x6010 | 0x6011)))
    }
}

enum Selection {
    Yes,
    No,
    /// No descriptor and no `--usb-device`: an FTDI chip if its traffic says so.
    Candidate,
}

/// Diagnostic kind: `--usb-device` named a device that sent no serial data in the capture.
pub const NOT_FOUND: &str = "usb_device_not_found";

/// Demultiplexes USB captures (usbmon, USBPcap) into the serial streams of FTDI devices.
pub struct UsbDemux {
    filter: Option<(u16, u8)>,
    devices: HashMap<(u16, u16), Device>,
    next_stream: u32,
    /// usbmon header byte order, once a header settled it.
    big_endian: Option<bool>,
    too_many_reported: bool,
    last_offset: u64,
}

impl UsbDemux {
    /// `device`: only this bus:address (from `--usb-device BUS:ADDR`), else every FTDI device.
    pub fn new(device: Option<(u16, u8)>) -> Self {
        UsbDemux {
            filter: device,
            devices: HashMap::new(),
            next_stream: 0,
            big_endian: None,
            too_many_reported: false,
            last_offset: 0,
        }
    }

    /// One captured packet: link type, the packet bytes as stored in the pcap record, its
    /// original length, timestamp, and the file offset of the record (for diagnostics).
    pub fn packet(
        &mut self,
        linktype: u32,
        data: &[u8],
        orig_len: u32,
        ts_ns: u64,
        file_offset: u64,
        out: &mut Vec<UsbOut>,
    ) {
        self.last_offset = file_offset;
        let urb = match linktype {
            LINKTYPE_USB_LINUX => self.parse_usbmon(data, USBMON_HDR, orig_len, file_offset, out),
            LINKTYPE_USB_LINUX_MMAPPED => {
                self.parse_usbmon(data, USBMON_MMAP_HDR, orig_len, file_offset, out)
            }
            LINKTYPE_USBPCAP => parse_usbpcap(data, orig_len, file_offset, out),
            _ => {
                diag(
                    out,
                    file_offset,
                    "usb_unknown_linktype",
                    format!("link type {linktype} is not a USB capture (189, 220, 249)"),
                );
                None
            }
        };
        let Some(urb) = urb else { return };
        match urb.xfer {
            XFER_CONTROL => self.control(&urb, file_offset, out),
            XFER_BULK => self.bulk(&urb, ts_ns, file_offset, out),
            _ => {}
        }
    }

    /// End of the capture: bulk OUT data still held for devices without descriptor whose bulk
    /// IN data never showed whether they are FTDI chips is produced, with a diagnostic.
    pub fn finish(&mut self, out: &mut Vec<UsbOut>) {
        let mut keys: Vec<(u16, u16)> = self
            .devices
            .iter()
            .filter(|(_, d)| !d.pending.is_empty())
            .map(|(k, _)| *k)
            .collect();
        keys.sort_unstable();
        let UsbDemux {
            devices,
            next_stream,
            last_offset,
            ..
        } = self;
        for key in keys {
            let Some(dev) = devices.get_mut(&key) else {
                continue;
            };
            dev.verdict = Verdict::Ftdi;
            diag(
                out,
                *last_offset,
                "usb_unconfirmed_device",
                format!(
                    "usb {}:{} has no device descriptor and no bulk IN data in the capture: its bulk OUT data is shown as if it were an FTDI device",
                    key.0, key.1
                ),
            );
            flush_pending(dev, key, next_stream, out);
        }
        self.report_absent_filter(out);
    }

    /// `--usb-device` named a device that sent no serial data: say which devices the capture
    /// has, as a [`NOT_FOUND`] diagnostic (the command line makes it an error).
    fn report_absent_filter(&self, out: &mut Vec<UsbOut>) {
        let Some((bus, addr)) = self.filter else {
            return;
        };
        let key = (bus, u16::from(addr));
        let has_data = self
            .devices
            .get(&key)
            .is_some_and(|d| d.ports.iter().any(|p| p.stream.is_some()));
        if has_data {
            return;
        }
        let mut keys: Vec<&(u16, u16)> = self.devices.keys().collect();
        keys.sort_unstable();
        let present: Vec<String> = keys
            .iter()
            .map(|k| {
                let d = &self.devices[k];
                let what = match d.ident {
                    Some((FTDI_VID, pid)) => format!("{FTDI_VID:04x}:{pid:04x}, FTDI"),
                    Some((vid, pid)) => format!("{vid:04x}:{pid:04x}"),
                    None => "no descriptor in the capture".into(),
                };
                format!("{}:{} ({what})", k.0, k.1)
            })
            .collect();
        let why = if self.devices.contains_key(&key) {
            "is in the capture but sent no serial data"
        } else {
            "is not in the capture"
        };
        let list = if present.is_empty() {
            "the capture has no USB bulk or control transfers".to_string()
        } else {
            format!("devices present: {}", present.join(", "))
        };
        diag(
            out,
            self.last_offset,
            NOT_FOUND,
            format!("--usb-device {bus}:{addr}: usb {bus}:{addr} {why}; {list}"),
        );
    }

    /// usbmon header byte order: the one in which the bus number and the microseconds are
    /// plausible; when both or neither are, the order settled by an earlier header, else LE.
    fn usbmon_big_endian(&mut self, data: &[u8]) -> bool {
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

    fn parse_usbmon<'a>(
        &mut self,
        data: &'a [u8],
        hdr_len: usize,
        orig_len: u32,
        off: u64,
        out: &mut Vec<UsbOut>,
    ) -> Option<Urb<'a>> {
        if data.len() < hdr_len {
            diag(
                out,
                off,
                "usb_record_too_short",
                format!(
                    "usbmon record of {} bytes{} is shorter than its {hdr_len}-byte header",
                    data.len(),
                    snap_note(data.len(), orig_len)
                ),
            );
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
                diag(
                    out,
                    off,
                    "usb_unknown_event",
                    format!("usbmon event type 0x{other:02x} is none of S, C, E"),
                );
                return None;
            }
        };
        match xfer {
            XFER_CONTROL | XFER_BULK => {}
            // Not used by FTDI serial converters.
            XFER_ISO | XFER_INTERRUPT => return None,
            other => {
                diag(
                    out,
                    off,
                    "usb_unknown_transfer_type",
                    format!("usbmon transfer type {other} is none of 0-3 (usb {bus}:{addr})"),
                );
                return None;
            }
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
                truncated = Some(format!(
                    "usbmon header announces {len_cap} captured bytes, the record holds {}{}",
                    avail.len(),
                    snap_note(data.len(), orig_len)
                ));
            } else {
                payload = &avail[..cap];
                if len_cap < length {
                    truncated = Some(format!(
                        "URB of {length} bytes of which usbmon captured {len_cap}"
                    ));
                }
            }
        } else if (ep & 0x80 != 0) != submit && length > 0 {
            // OUT submissions and IN completions carry data; usbmon says why it has none.
            truncated = Some(format!(
                "URB of {length} bytes whose data usbmon did not capture (data flag 0x{flag_data:02x})"
            ));
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

    fn ensure_device(&mut self, key: (u16, u16), off: u64, out: &mut Vec<UsbOut>) -> bool {
        if self.devices.contains_key(&key) {
            return true;
        }
        if self.devices.len() >= MAX_DEVICES {
            if !self.too_many_reported {
                self.too_many_reported = true;
                diag(
                    out,
                    off,
                    "usb_too_many_devices",
                    format!("more than {MAX_DEVICES} USB devices: usb {}:{} and later new devices are ignored", key.0, key.1),
                );
            }
            return false;
        }
        self.devices.insert(key, Device::default());
        true
    }

    fn control(&mut self, urb: &Urb<'_>, off: u64, out: &mut Vec<UsbOut>) {
        let key = (urb.bus, urb.addr);
        if urb.submit {
            let Some(s) = urb.setup else { return };
            let get_descriptor = s[0] == 0x80 && s[1] == 6 && matches!(s[3], 1 | 2);
            let vendor = s[0] == 0x40
                && matches!(
                    s[1],
                    SIO_RESET | SIO_SET_FLOW_CTRL | SIO_SET_BAUDRATE | SIO_SET_DATA
                );
            if !(get_descriptor || vendor) || !self.ensure_device(key, off, out) {
                return;
            }
            if get_descriptor {
                if let Some(dev) = self.devices.get_mut(&key) {
                    if dev.controls.len() >= MAX_PENDING_CONTROLS {
                        dev.controls.pop_front();
                    }
                    dev.controls.push_back((urb.id, s));
                }
            } else {
                self.vendor_request(key, s, off, out);
            }
        } else if urb.data.len() >= 2 {
            let Some(dev) = self.devices.get_mut(&key) else {
                return;
            };
            // Match by URB id; USBPcap's injected descriptors all have IRP id 0, so fall back to
            // the latest request, checked by the descriptor type of the answer.
            let pos = dev
                .controls
                .iter()
                .rposition(|(id, _)| *id == urb.id)
                .or_else(|| dev.controls.len().checked_sub(1));
            let Some(pos) = pos else { return };
            let dtype = dev.controls[pos].1[3];
            if urb.data[1] != dtype {
                return;
            }
            dev.controls.remove(pos);
            match dtype {
                1 => self.device_descriptor(key, urb.data, off, out),
                _ => config_descriptor(dev, urb.data),
            }
        }
    }

    fn device_descriptor(&mut self, key: (u16, u16), d: &[u8], off: u64, out: &mut Vec<UsbOut>) {
        if d.len() < 12 {
            return;
        }
        let ident = (le16(d, 8), le16(d, 10));
        let filter = self.filter;
        let UsbDemux {
            devices,
            next_stream,
            ..
        } = self;
        let Some(dev) = devices.get_mut(&key) else {
            return;
        };
        if d.len() >= 14 {
            dev.bcd = Some(le16(d, 12));
        }
        match dev.ident {
            Some(old) if old == ident => {}
            Some(old) => {
                // Another device now has this address: start afresh (new streams).
                let bcd = dev.bcd;
                *dev = Device {
                    ident: Some(ident),
                    bcd,
                    ..Device::default()
                };
                diag(
                    out,
                    off,
                    "usb_device_changed",
                    format!(
                        "usb {}:{} was {:04x}:{:04x}, is now {:04x}:{:04x}",
                        key.0, key.1, old.0, old.1, ident.0, ident.1
                    ),
                );
            }
            None => {
                dev.ident = Some(ident);
                let announced = dev.ports.iter().any(|p| p.stream.is_some());
                let selected = filter.is_some() || ident.0 == FTDI_VID;
                if announced {
                    let (kind, msg) = if selected {
                        ("usb_device_identified", "its stream continues")
                    } else {
                        (
                            "usb_not_ftdi",
                            "not an FTDI device: its traffic is no longer shown",
                        )
                    };
                    diag(
                        out,
                        off,
                        kind,
                        format!(
                            "usb {}:{} is {:04x}:{:04x}: {msg}",
                            key.0, key.1, ident.0, ident.1
                        ),
                    );
                }
                if selected {
                    dev.verdict = Verdict::Ftdi;
                    flush_pending(dev, key, next_stream, out);
                } else {
                    dev.verdict = Verdict::NotFtdi;
                    dev.pending.clear();
                    dev.pending_bytes = 0;
                }
            }
        }
    }

    fn vendor_request(&mut self, key: (u16, u16), s: [u8; 8], off: u64, out: &mut Vec<UsbOut>) {
        let Some(dev) = self.devices.get_mut(&key) else {
            return;
        };
        let wvalue = u16::from_le_bytes([s[2], s[3]]);
        let windex = u16::from_le_bytes([s[4], s[5]]);
        let port = port_of(windex);
        let port = match s[1] {
            SIO_SET_BAUDRATE => {
                let (port, hi) = if dev.multi_port() {
                    (port, windex >> 8)
                } else if windex >> 8 != 0 {
                    (0, windex >> 8)
                } else {
                    (0, windex & 0xff)
                };
                let sio = matches!(dev.ident, Some((FTDI_VID, 0x8372)));
                dev.ports[port].baud = Some(if sio {
                    sio_baud(wvalue)
                } else {
                    decode_baud(wvalue, hi)
                });
                port
            }
            SIO_SET_DATA => {
                dev.ports[port].data = Some(wvalue);
                port
            }
            SIO_SET_FLOW_CTRL => {
                dev.ports[port].flow = Some(windex >> 8);
                port
            }
            // SIO_RESET with wValue 0 resets the chip, flow control to none (1, 2 purge).
            _ if wvalue == 0 => {
                dev.ports[port].flow = Some(0);
                port
            }
            _ => return,
        };
        let name = stream_name(key, dev, port);
        let p = &mut dev.ports[port];
        let now = p.settings();
        if p.stream.is_some() && now != p.shown {
            diag(
                out,
                off,
                "line_settings",
                format!("{name}: {}", now.as_deref().unwrap_or("unknown")),
            );
            p.shown = now;
        }
    }

    fn bulk(&mut self, urb: &Urb<'_>, ts_ns: u64, off: u64, out: &mut Vec<UsbOut>) {
        let is_in = urb.ep & 0x80 != 0;
        // Data goes with the submission of an OUT transfer and the completion of an IN one.
        if is_in == urb.submit || (urb.data.is_empty() && urb.truncated.is_none()) {
            return;
        }
        let port = match urb.ep {
            0x81 | 0x02 => 0,
            0x83 | 0x04 => 1,
            0x85 | 0x06 => 2,
            0x87 | 0x08 => 3,
            _ => return,
        };
        let key = (urb.bus, urb.addr);
        if !self.ensure_device(key, off, out) {
            return;
        }
        let filter = self.filter;
        let UsbDemux {
            devices,
            next_stream,
            ..
        } = self;
        let Some(dev) = devices.get_mut(&key) else {
            return;
        };
        let selection = match filter {
            Some((b, a)) if key == (b, u16::from(a)) => Selection::Yes,
            Some(_) => Selection::No,
            None => match dev.ident {
                Some((vid, _)) if vid == FTDI_VID => Selection::Yes,
                Some(_) => Selection::No,
                None => Selection::Candidate,
            },
        };
        match selection {
            Selection::No => return,
            Selection::Yes => {}
            Selection::Candidate => {
                if port != 0 {
                    return;
                }
                match dev.verdict {
                    Verdict::NotFtdi => return,
                    Verdict::Ftdi => {}
                    Verdict::Undecided if is_in => {
                        let Some(&first) = urb.data.first() else {
                            return;
                        };
                        if !ftdi_status_ok(first) {
                            dev.verdict = Verdict::NotFtdi;
                            dev.pending.clear();
                            dev.pending_bytes = 0;
                            diag(
                                out,
                                off,
                                "usb_not_ftdi",
                                format!(
                                    "usb {}:{} (no device descriptor in the capture) sends bulk IN data that does not start with FTDI status bytes (0x{first:02x}): not shown",
                                    key.0, key.1
                                ),
                            );
                            return;
                        }
                        dev.verdict = Verdict::Ftdi;
                        flush_pending(dev, key, next_stream, out);
                    }
                    Verdict::Undecided => {
                        if !urb.data.is_empty() {
                            dev.pending_bytes += urb.data.len();
                            dev.pending.push(OwnedChunk {
                                ts_ns: Some(ts_ns),
                                dir: Direction::HostToDevice,
                                stream: 0,
                                bytes: urb.data.to_vec(),
                            });
                        }
                        if let Some(t) = &urb.truncated {
                            truncated_diag(out, off, key, urb.ep, t);
                        }
                        if dev.pending_bytes > PENDING_LIMIT {
                            dev.verdict = Verdict::Ftdi;
                            diag(
                                out,
                                off,
                                "usb_unconfirmed_device",
                                format!(
                                    "usb {}:{} has no device descriptor and no bulk IN data after {PENDING_LIMIT} bytes OUT: shown as if it were an FTDI device",
                                    key.0, key.1
                                ),
                            );
                            flush_pending(dev, key, next_stream, out);
                        }
                        return;
                    }
                }
            }
        }
        let (dir, bytes) = if is_in {
            let mps = in_max_packet(dev, key, urb.ep, urb.data, off, out);
            (Direction::DeviceToHost, strip_ftdi_status(urb.data, mps))
        } else {
            (Direction::HostToDevice, urb.data.to_vec())
        };
        if !bytes.is_empty() {
            let stream = announce(dev, key, port, next_stream, out);
            out.push(UsbOut::Chunk(OwnedChunk {
                ts_ns: Some(ts_ns),
                dir,
                stream,
                bytes,
            }));
        }
        if let Some(t) = &urb.truncated {
            truncated_diag(out, off, key, urb.ep, t);
        }
    }
}

fn parse_usbpcap<'a>(
    data: &'a [u8],
    orig_len: u32,
    off: u64,
    out: &mut Vec<UsbOut>,
) -> Option<Urb<'a>> {
    if data.len() < USBPCAP_HDR {
        diag(
            out,
            off,
            "usb_record_too_short",
            format!(
                "USBPcap record of {} bytes{} is shorter than its {USBPCAP_HDR}-byte header",
                data.len(),
                snap_note(data.len(), orig_len)
            ),
        );
        return None;
    }
    let hlen = usize::from(le16(data, 0));
    let transfer = data[22];
    let min = if transfer == XFER_CONTROL {
        USBPCAP_HDR + 1
    } else {
        USBPCAP_HDR
    };
    if hlen < min {
        diag(
            out,
            off,
            "usb_bad_header",
            format!("USBPcap header length {hlen} is less than {min}"),
        );
        return None;
    }
    if hlen > data.len() {
        diag(
            out,
            off,
            "usb_record_too_short",
            format!(
                "USBPcap record of {} bytes{} is shorter than its {hlen}-byte header",
                data.len(),
                snap_note(data.len(), orig_len)
            ),
        );
        return None;
    }
    let id = le64(data, 2);
    let submit = data[16] & 1 == 0;
    let bus = le16(data, 17);
    let addr = le16(data, 19);
    let ep = data[21];
    let data_len = le32(data, 23);
    match transfer {
        XFER_CONTROL | XFER_BULK => {}
        XFER_ISO | XFER_INTERRUPT | USBPCAP_IRP_INFO | USBPCAP_UNKNOWN => return None,
        other => {
            diag(
                out,
                off,
                "usb_unknown_transfer_type",
                format!("USBPcap transfer type 0x{other:02x} is none of 0-3, 0xfe, 0xff (usb {bus}:{addr})"),
            );
            return None;
        }
    }
    let avail = &data[hlen..];
    let (mut payload, truncated) = match usize::try_from(data_len) {
        Ok(n) if n <= avail.len() => (&avail[..n], None),
        _ => (
            avail,
            Some(format!(
                "USBPcap header announces {data_len} data bytes, the record holds {}{}",
                avail.len(),
                snap_note(data.len(), orig_len)
            )),
        ),
    };
    let mut setup = None;
    if transfer == XFER_CONTROL {
        match data[USBPCAP_HDR] {
            USBPCAP_STAGE_SETUP if submit => {
                if payload.len() < 8 {
                    diag(
                        out,
                        off,
                        "usb_bad_header",
                        format!(
                            "USBPcap control setup stage with {} bytes instead of 8",
                            payload.len()
                        ),
                    );
                    return None;
                }
                let mut s = [0u8; 8];
                s.copy_from_slice(&payload[..8]);
                setup = Some(s);
                payload = &payload[8..];
            }
            USBPCAP_STAGE_STATUS => payload = &[],
            _ => {}
        }
    }
    Some(Urb {
        bus,
        addr,
        ep,
        xfer: transfer,
        submit,
        id,
        setup,
        data: payload,
        truncated,
    })
}

/// Endpoint descriptors of a configuration descriptor: wMaxPacketSize of bulk IN endpoints.
fn config_descriptor(dev: &mut Device, d: &[u8]) {
    let mut i = 0usize;
    while i + 2 <= d.len() {
        let len = usize::from(d[i]);
        if len < 2 {
            break;
        }
        if d[i + 1] == 5 && len >= 7 && i + 7 <= d.len() {
            let addr = d[i + 2];
            let attrs = d[i + 3];
            let mps = le16(d, i + 4) & 0x7ff;
            if addr & 0x80 != 0 && attrs & 3 == 2 && mps != 0 {
                dev.in_mps[usize::from(addr & 0x0f)] = mps;
            }
        }
        i += len;
    }
}

/// The serial port of a `wIndex` (0 or 1: A, 2: B …).
fn port_of(windex: u16) -> usize {
    usize::from((windex & 0xff).saturating_sub(1)).min(PORTS - 1)
}

fn stream_name(key: (u16, u16), dev: &Device, port: usize) -> String {
    let mut s = format!("usb {}:{}", key.0, key.1);
    if let Some((vid, pid)) = dev.ident {
        s.push_str(&format!(" {vid:04x}:{pid:04x}"));
    }
    if port > 0 {
        s.push_str(" port ");
        s.push(char::from(b'A' + port as u8));
    }
    if dev.ident.is_none() {
        s.push_str(" (assumed FTDI: no device descriptor in capture)");
    }
    s
}

/// The stream of a port, announced on first use.
fn announce(
    dev: &mut Device,
    key: (u16, u16),
    port: usize,
    next_stream: &mut u32,
    out: &mut Vec<UsbOut>,
) -> u32 {
    if let Some(id) = dev.ports[port].stream {
        return id;
    }
    let id = *next_stream;
    *next_stream = next_stream.saturating_add(1);
    let name = stream_name(key, dev, port);
    let p = &mut dev.ports[port];
    let settings = p.settings();
    p.stream = Some(id);
    p.shown.clone_from(&settings);
    out.push(UsbOut::Stream(StreamInfo { id, name, settings }));
    id
}

fn flush_pending(dev: &mut Device, key: (u16, u16), next_stream: &mut u32, out: &mut Vec<UsbOut>) {
    if dev.pending.is_empty() {
        return;
    }
    let id = announce(dev, key, 0, next_stream, out);
    for mut c in std::mem::take(&mut dev.pending) {
        c.stream = id;
        out.push(UsbOut::Chunk(c));
    }
    dev.pending_bytes = 0;
}

/// The max packet size of a bulk IN endpoint: from the configuration descriptor, else inferred
/// from the data (a full-speed chip puts status bytes every 64 bytes; if the data has none there
/// but is consistent with 512-byte packets, the chip runs at high speed), else 64.
fn in_max_packet(
    dev: &mut Device,
    key: (u16, u16),
    ep: u8,
    data: &[u8],
    off: u64,
    out: &mut Vec<UsbOut>,
) -> usize {
    let known = dev.in_mps[usize::from(ep & 0x0f)];
    if known != 0 {
        return usize::from(known);
    }
    if let Some(m) = dev.guess_mps {
        return m;
    }
    if data.len() > 64 && !pieces_look_ftdi(data, 64) && pieces_look_ftdi(data, 512) {
        dev.guess_mps = Some(512);
        diag(
            out,
            off,
            "usb_max_packet_inferred",
            format!(
                "usb {}:{} endpoint 0x{ep:02x}: no endpoint descriptor in the capture and no FTDI status bytes every 64 bytes: assuming 512-byte (high-speed) packets",
                key.0, key.1
            ),
        );
        return 512;
    }
    64
}

/// The first byte of an FTDI IN packet: modem status, bit 0 set ("reserved, must be 1"), bits 2
/// and 3 clear (bit 1 is seen set on some H chips).
fn ftdi_status_ok(b: u8) -> bool {
    b & 0x0c == 0 && b & 0x03 != 0
}

/// Whether every `mps` piece of `data` starts with a plausible FTDI status pair.
fn pieces_look_ftdi(data: &[u8], mps: usize) -> bool {
    data.chunks(mps)
        .all(|p| p.len() >= 2 && ftdi_status_ok(p[0]))
}

/// Bulk IN data without the two status bytes that start every `mps`-byte piece.
fn strip_ftdi_status(data: &[u8], mps: usize) -> Vec<u8> {
    let mps = mps.max(3);
    let mut v = Vec::with_capacity(data.len());
    for piece in data.chunks(mps) {
        if let Some(rest) = piece.get(2..) {
            v.extend_from_slice(rest);
        }
    }
    v
}

/// Inverse of the Linux driver's `divfrac` (fraction code → eighths).
const FRAC_INV: [u32; 8] = [0, 4, 2, 1, 3, 5, 6, 7];

/// Common baud rates: a decoded rate within 3 % of one (the FTDI tolerance) is reported as it.
const STANDARD_BAUDS: [u32; 26] = [
    300, 600, 1200, 2400, 4800, 9600, 14400, 19200, 28800, 38400, 57600, 76800, 115200, 128000,
    153600, 230400, 250000, 256000, 460800, 500000, 921600, 1000000, 1500000, 2000000, 3000000,
    12000000,
];

/// The baud rate of an FTDI (AM/BM/R/X/H) SET_BAUDRATE: `wValue` and the divisor's high bits
/// (bit 16: last fraction bit; bit 17: 120 MHz clock of H chips).
fn decode_baud(wvalue: u16, hi: u16) -> String {
    let raw = (u32::from(hi) << 16) | u32::from(wvalue);
    let h_clock = raw & 0x2_0000 != 0;
    let div = match raw & 0x1_ffff {
        0 => 1,
        1 => 0x4001,
        d => d,
    };
    let eighths = ((div & 0x3fff) << 3) | FRAC_INV[((div >> 14) & 7) as usize];
    if eighths == 0 {
        return format!("baud divisor 0x{raw:05x}");
    }
    let base: u64 = if h_clock { 96_000_000 } else { 24_000_000 };
    let baud = (base + u64::from(eighths) / 2) / u64::from(eighths);
    let nominal = STANDARD_BAUDS
        .iter()
        .copied()
        .find(|&s| baud.abs_diff(u64::from(s)) * 100 <= u64::from(s) * 3);
    match nominal {
        Some(s) => s.to_string(),
        None => baud.to_string(),
    }
}

/// The baud rate of the original FT8U100AX (SIO), which takes a code.
fn sio_baud(wvalue: u16) -> String {
    const RATES: [u32; 10] = [
        300, 600, 1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200,
    ];
    match RATES.get(usize::from(wvalue)) {
        Some(r) => r.to_string(),
        None => format!("baud code {wvalue}"),
    }
}

/// SET_DATA `wValue`: bits 0–7 data bits, 8–10 parity, 11–13 stop bits → `8N1`.
fn format_data_bits(v: u16) -> String {
    let bits = v & 0xff;
    let parity = ['N', 'O', 'E', 'M', 'S']
        .get(usize::from((v >> 8) & 7))
        .copied()
        .unwrap_or('?');
    let stop = match (v >> 11) & 7 {
        0 => "1",
        1 => "1.5",
        2 => "2",
        _ => "?",
    };
    let mut s = format!("{bits}{parity}{stop}");
    if v & 0x4000 != 0 {
        s.push_str(" break");
    }
    s
}

/// SET_FLOW_CTRL protocol (high byte of `wIndex`).
fn format_flow(p: u16) -> String {
    let names: Vec<&str> = [(1, "RTS/CTS"), (2, "DTR/DSR"), (4, "XON/XOFF")]
        .iter()
        .filter(|(bit, _)| p & bit != 0)
        .map(|(_, n)| *n)
        .collect();
    if names.is_empty() {
        format!("flow 0x{p:02x}")
    } else {
        names.join("+")
    }
}

fn truncated_diag(out: &mut Vec<UsbOut>, off: u64, key: (u16, u16), ep: u8, why: &str) {
    diag(
        out,
        off,
        "truncated_urb",
        format!(
            "{why} (usb {}:{} endpoint 0x{ep:02x}): the bytes present are shown",
            key.0, key.1
        ),
    );
}

fn snap_note(have: usize, orig_len: u32) -> String {
    if u64::from(orig_len) > have as u64 {
        format!(" (cut from {orig_len} by the capture's snapshot length)")
    } else {
        String::new()
    }
}

fn diag(out: &mut Vec<UsbOut>, offset: u64, kind: &'static str, msg: String) {
    out.push(UsbOut::Diag(ReadDiag { offset, kind, msg }));
}

fn rd16(d: &[u8], at: usize, be: bool) -> u16 {
    let b = [d[at], d[at + 1]];
    if be {
        u16::from_be_bytes(b)
    } else {
        u16::from_le_bytes(b)
    }
}

fn rd32(d: &[u8], at: usize, be: bool) -> u32 {
    let b = [d[at], d[at + 1], d[at + 2], d[at + 3]];
    if be {
        u32::from_be_bytes(b)
    } else {
        u32::from_le_bytes(b)
    }
}

fn rd64(d: &[u8], at: usize, be: bool) -> u64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&d[at..at + 8]);
    if be {
        u64::from_be_bytes(b)
    } else {
        u64::from_le_bytes(b)
    }
}

fn le16(d: &[u8], at: usize) -> u16 {
    rd16(d, at, false)
}

fn le32(d: &[u8], at: usize) -> u32 {
    rd32(d, at, false)
}

fn le64(d: &[u8], at: usize) -> u64 {
    rd64(d, at, false)
}

/// Fields of a usbmon header (for [`synth_usbmon`]).
struct MonHdr {
    id: u64,
    event: u8,
    xfer: u8,
    ep: u8,
    addr: u8,
    bus: u16,
    ts_ns: u64,
    status: i32,
    length: u32,
    setup: Option<[u8; 8]>,
}

impl MonHdr {
    /// The 64-byte header (little-endian) followed by `data`.
    fn record(&self, data: Option<&[u8]>) -> Vec<u8> {
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
struct Synth {
    bus: u16,
    addr: u8,
    next_id: u64,
    records: Vec<(u64, Vec<u8>)>,
}

impl Synth {
    const EINPROGRESS: i32 = -115;

    /// A submission and its completion.
    #[allow(clippy::too_many_arguments)]
    fn urb(
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

    fn control_in(&mut self, ts: u64, setup: [u8; 8], answer: &[u8]) {
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

    fn control_out(&mut self, ts: u64, setup: [u8; 8]) {
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

#[cfg(test)]
mod tests {
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
        let kinds: Vec<_> = diags_of(&out).iter().map(|d| d.kind).collect();
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
        let ctl = |pdo, ep, stage, data: &[u8]| {
            usbpcap(0, pdo, 1, 5, ep, XFER_CONTROL, Some(stage), data)
        };
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
        let d: Vec<(u64, &str)> = diags_of(&out).iter().map(|d| (d.offset, d.kind)).collect();
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
        assert!(diags_of(&out)[0].msg.contains("snapshot length"));
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
        let d: Vec<(u64, &str)> = diags_of(&out).iter().map(|d| (d.offset, d.kind)).collect();
        assert_eq!(
            d,
            vec![
                (11, "usb_record_too_short"),
                (22, "usb_record_too_short"),
                (33, "truncated_urb")
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
        let kinds: Vec<_> = diags_of(&out).iter().map(|d| d.kind).collect();
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
            assert_eq!(d[0].kind, NOT_FOUND);
            assert!(d[0].msg.contains(why), "{}", d[0].msg);
            assert!(
                d[0].msg.contains(
                    "devices present: 1:4 (no descriptor in the capture), 1:7 (0403:faf0, FTDI), \
                     2:9 (0403:faf0, FTDI), 3:3 (0403:faf0, FTDI)"
                ),
                "{}",
                d[0].msg
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
            .map(|d| (d.kind, d.msg))
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
}
