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

use crate::model::{
    Direction, OwnedChunk, ReadDiag, ReadProblem, StreamInfo, UrbCut, UsbDevice, UsbFormat,
    UsbNote, UsbProblem,
};

mod ftdi;
#[cfg(test)]
mod tests;
mod usbmon;
mod usbpcap;

use ftdi::*;
pub use usbmon::synth_usbmon;
#[cfg(test)]
use usbmon::*;
use usbpcap::*;

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

pub(crate) const FTDI_VID: u16 = 0x0403;
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
    truncated: Option<UrbCut>,
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
                usb_diag(out, file_offset, UsbProblem::UnknownLinkType { linktype });
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
            let (bus, addr) = key;
            let after = None;
            note(out, *last_offset, UsbNote::Unconfirmed { bus, addr, after });
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
        let mut present: Vec<_> = self
            .devices
            .iter()
            .map(|(&(bus, addr), d)| UsbDevice {
                bus,
                addr,
                ids: d.ident,
            })
            .collect();
        present.sort_unstable();
        let problem = UsbNote::DeviceNotFound {
            bus,
            addr: key.1,
            in_capture: self.devices.contains_key(&key),
            present,
        };
        note(out, self.last_offset, problem);
    }

    fn ensure_device(&mut self, key: (u16, u16), off: u64, out: &mut Vec<UsbOut>) -> bool {
        if self.devices.contains_key(&key) {
            return true;
        }
        if self.devices.len() >= MAX_DEVICES {
            if !self.too_many_reported {
                self.too_many_reported = true;
                let (bus, addr) = key;
                let max = MAX_DEVICES;
                note(out, off, UsbNote::TooManyDevices { max, bus, addr });
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
                let (bus, addr) = key;
                let (was, now) = (old, ident);
                note(
                    out,
                    off,
                    UsbNote::DeviceChanged {
                        bus,
                        addr,
                        was,
                        now,
                    },
                );
            }
            None => {
                dev.ident = Some(ident);
                let announced = dev.ports.iter().any(|p| p.stream.is_some());
                let selected = filter.is_some() || ident.0 == FTDI_VID;
                if announced {
                    let (bus, addr, ids) = (key.0, key.1, ident);
                    let n = if selected {
                        UsbNote::Identified { bus, addr, ids }
                    } else {
                        UsbNote::NotFtdi { bus, addr, ids }
                    };
                    note(out, off, n);
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
            let settings = now.clone();
            note(
                out,
                off,
                UsbNote::LineSettings {
                    stream: name,
                    settings,
                },
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
                            let (bus, addr) = key;
                            note(out, off, UsbNote::NoStatusBytes { bus, addr, first });
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
                            truncated_diag(out, off, key, urb.ep, t.clone());
                        }
                        if dev.pending_bytes > PENDING_LIMIT {
                            dev.verdict = Verdict::Ftdi;
                            let (bus, addr) = key;
                            let after = Some(PENDING_LIMIT);
                            note(out, off, UsbNote::Unconfirmed { bus, addr, after });
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
            truncated_diag(out, off, key, urb.ep, t.clone());
        }
    }
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
        let (bus, addr) = key;
        note(out, off, UsbNote::MaxPacketInferred { bus, addr, ep });
        return 512;
    }
    64
}

fn truncated_diag(out: &mut Vec<UsbOut>, off: u64, key: (u16, u16), ep: u8, cut: UrbCut) {
    let (bus, addr) = key;
    usb_diag(out, off, UsbProblem::TruncatedUrb { cut, bus, addr, ep });
}

/// Whether a `format` record (`data`, `orig_len` bytes on the wire) holds its `header` bytes;
/// when it does not, says so (at file offset `off`).
fn holds_header(
    format: UsbFormat,
    header: usize,
    data: &[u8],
    orig_len: u32,
    off: u64,
    out: &mut Vec<UsbOut>,
) -> bool {
    if data.len() >= header {
        return true;
    }
    let problem = UsbProblem::RecordTooShort {
        format,
        expected: header,
        found: data.len(),
        original: orig_len,
    };
    usb_diag(out, off, problem);
    false
}

/// Whether a `format` URB of transfer type `xfer` (device `bus`:`addr`) carries what is shown:
/// control and bulk. Isochronous, interrupt and the format's own `ignored` types are passed
/// over; any other type is reported (at file offset `off`).
fn shown_transfer(
    format: UsbFormat,
    xfer: u8,
    ignored: &[u8],
    (bus, addr): (u16, u16),
    off: u64,
    out: &mut Vec<UsbOut>,
) -> bool {
    match xfer {
        XFER_CONTROL | XFER_BULK => true,
        // Not used by FTDI serial converters.
        XFER_ISO | XFER_INTERRUPT => false,
        x if ignored.contains(&x) => false,
        found => {
            let problem = UsbProblem::UnknownTransferType {
                format,
                found,
                bus,
                addr,
            };
            usb_diag(out, off, problem);
            false
        }
    }
}

fn usb_diag(out: &mut Vec<UsbOut>, offset: u64, problem: UsbProblem) {
    out.push(UsbOut::Diag(ReadDiag::new(
        offset,
        ReadProblem::Usb(problem),
    )));
}

fn note(out: &mut Vec<UsbOut>, offset: u64, note: UsbNote) {
    out.push(UsbOut::Diag(ReadDiag::new(
        offset,
        ReadProblem::UsbNote(note),
    )));
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
