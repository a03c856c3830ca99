//! pcap and pcapng: reading (serial captures written by aptscope, and USB captures of FTDI
//! controllers) and writing, streamed through a bounded buffer.
//!
//! aptscope's serial link types:
//! - **pcapng**: `LINKTYPE_USER0` (147). Each Enhanced Packet Block holds the bytes as they
//!   crossed the line, the direction in the EPB flags (outbound = host → device, inbound =
//!   device → host), ns timestamps (`if_tsresol` 9), one interface per port with its name and
//!   line settings in `if_name`/`if_description`. USER0 is reserved for private use, so no
//!   dissector claims it: Wireshark and tshark open the files, show the bytes, times and
//!   direction (`frame.p2p_dir`/packet flags) without errors, and a user can bind a dissector
//!   to it under *DLT_USER* preferences.
//! - **pcap**: `LINKTYPE_USER1` (148) with a 2-byte pseudo-header per record, `[direction,
//!   stream]` (direction 0 unknown, 1 host → device, 2 device → host), because legacy pcap has
//!   no per-packet flags and one link type for the whole file; ns timestamps (magic a1b23c4d).

use crate::model::{
    Chunk, Damage, Direction, Event, OwnedChunk, ReadDiag, ReadProblem, Reader, Skipped,
    StreamInfo, Writer,
};
use crate::usb::{is_usb_linktype, UsbDemux, UsbOut};
use pcap_file::pcap::{PcapHeader, PcapPacket, PcapParser, PcapWriter};
use pcap_file::pcapng::blocks::enhanced_packet::{EnhancedPacketBlock, EnhancedPacketOption};
use pcap_file::pcapng::blocks::interface_description::{
    InterfaceDescriptionBlock, InterfaceDescriptionOption,
};
use pcap_file::pcapng::{Block, PcapNgParser, PcapNgWriter};
use pcap_file::{DataLink, Endianness, PcapError, TsResolution};
use std::borrow::Cow;
use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::time::Duration;

/// Link type of aptscope's pcapng serial captures.
pub const LINKTYPE_SERIAL_NG: u32 = 147;
/// Link type of aptscope's legacy pcap serial captures (with a 2-byte pseudo-header).
pub const LINKTYPE_SERIAL_PCAP: u32 = 148;
/// Largest block or record accepted; a longer one is taken as corruption (bounded memory).
pub const MAX_RECORD: usize = 16 << 20;
const READ_SIZE: usize = 1 << 20;

/// The pcap magic numbers (both byte orders, µs and ns).
pub fn sniff_pcap(head: &[u8]) -> bool {
    matches!(
        head.get(..4),
        Some(
            [0xd4, 0xc3, 0xb2, 0xa1]
                | [0xa1, 0xb2, 0xc3, 0xd4]
                | [0x4d, 0x3c, 0xb2, 0xa1]
                | [0xa1, 0xb2, 0x3c, 0x4d]
        )
    )
}

/// The pcapng Section Header Block type.
pub fn sniff_pcapng(head: &[u8]) -> bool {
    head.get(..4) == Some(&[0x0a, 0x0d, 0x0d, 0x0a])
}

/// How many bytes the file header of a capture starting with `head` takes: a pcap's 24, a
/// pcapng's section header block as its length field says (12 bytes tell it).
fn file_header_len(head: &[u8]) -> usize {
    if !sniff_pcapng(head) {
        return 24;
    }
    match (head.get(4..8), head.get(8..12)) {
        (Some(l), Some(bom)) => {
            let l = [l[0], l[1], l[2], l[3]];
            let len = if bom == [0x4d, 0x3c, 0x2b, 0x1a] {
                u32::from_le_bytes(l)
            } else {
                u32::from_be_bytes(l)
            };
            (len as usize).clamp(28, MAX_RECORD)
        }
        _ => 12,
    }
}

enum Owned {
    Stream(StreamInfo),
    Chunk(OwnedChunk),
    Diag(ReadDiag),
}

enum Parser {
    None,
    Legacy(PcapParser),
    Ng(PcapNgParser),
}

/// What the reader knows of one pcapng interface.
#[derive(Clone)]
struct Iface {
    linktype: u32,
    /// Units per second of EPB timestamps.
    units_per_s: u64,
    stream: u32,
}

/// Streaming reader of pcap and pcapng files.
pub struct PcapReader<R: Read> {
    src: R,
    buf: Vec<u8>,
    /// How many bytes the next read asks for: twice what the last one gave, 4 KiB to
    /// [`READ_SIZE`]. Each read zeroes the room it asks for; at 1 MiB a read, a source giving a
    /// few bytes at a time (a pipe, a followed file as it grows) cost a 1 MiB memset for each
    /// (4.5 s in a debug build for a 4.7 KB usbmon capture read 31 bytes at a time).
    read_want: usize,
    start: usize,
    /// File offset of `buf[0]`.
    base: u64,
    eof: bool,
    parser: Parser,
    ng: bool,
    ifaces: Vec<Iface>,
    next_stream: u32,
    usb: UsbDemux,
    usb_out: Vec<UsbOut>,
    queue: VecDeque<Owned>,
    current: Option<Owned>,
    warned_linktypes: Vec<u32>,
    pcap_linktype: u32,
    pcap_streams: Vec<u32>,
    done: bool,
    usb_flushed: bool,
}

fn diag(offset: u64, problem: ReadProblem) -> Owned {
    Owned::Diag(ReadDiag::new(offset, problem))
}

/// A file header the parser rejects (`ng`: a pcapng section header).
fn bad_header(ng: bool, e: &PcapError) -> ReadProblem {
    ReadProblem::BadFileHeader {
        ng,
        error: e.to_string(),
    }
}

fn dir_of_flags(flags: u32) -> Direction {
    match flags & 3 {
        2 => Direction::HostToDevice,
        1 => Direction::DeviceToHost,
        _ => Direction::Unknown,
    }
}

fn dir_byte(d: Direction) -> u8 {
    match d {
        Direction::Unknown => 0,
        Direction::HostToDevice => 1,
        Direction::DeviceToHost => 2,
    }
}

fn dir_from_byte(b: u8) -> Direction {
    match b {
        1 => Direction::HostToDevice,
        2 => Direction::DeviceToHost,
        _ => Direction::Unknown,
    }
}

impl<R: Read> PcapReader<R> {
    /// Say which of the two the stream is (from its magic), so [`Reader::format`] is right
    /// before anything has been read.
    pub fn expect_pcapng(mut self, ng: bool) -> Self {
        self.ng = ng;
        self
    }

    /// Read a pcap or pcapng stream; `usb_device` restricts USB captures to one BUS:ADDR.
    pub fn new(src: R, usb_device: Option<(u16, u8)>) -> Self {
        PcapReader {
            src,
            buf: Vec::with_capacity(READ_SIZE),
            read_want: READ_SIZE,
            start: 0,
            base: 0,
            eof: false,
            parser: Parser::None,
            ng: false,
            ifaces: vec![],
            next_stream: 0,
            usb: UsbDemux::new(usb_device),
            usb_out: vec![],
            queue: VecDeque::new(),
            current: None,
            warned_linktypes: vec![],
            pcap_linktype: 0,
            pcap_streams: vec![],
            done: false,
            usb_flushed: false,
        }
    }

    fn offset(&self) -> u64 {
        self.base + self.start as u64
    }

    /// Read more input; `false` at end of file.
    fn fill(&mut self) -> bool {
        if self.eof {
            return false;
        }
        if self.start > 0 {
            self.buf.drain(..self.start);
            self.base += self.start as u64;
            self.start = 0;
        }
        let old = self.buf.len();
        self.buf.resize(old + self.read_want, 0);
        loop {
            match self.src.read(&mut self.buf[old..]) {
                Ok(0) => {
                    self.buf.truncate(old);
                    self.eof = true;
                    return false;
                }
                Ok(n) => {
                    self.buf.truncate(old + n);
                    self.read_want = n.saturating_mul(2).clamp(4096, READ_SIZE);
                    return true;
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => {
                    self.buf.truncate(old);
                    self.eof = true;
                    let at = self.base + old as u64;
                    self.queue.push_back(diag(at, ReadProblem::io(&e)));
                    return false;
                }
            }
        }
    }

    fn endianness(&self) -> Endianness {
        match &self.parser {
            Parser::Ng(p) => p.section().endianness,
            Parser::Legacy(p) => p.header().endianness,
            Parser::None => Endianness::Little,
        }
    }

    fn read_u32(&self, at: usize) -> Option<u32> {
        let b: [u8; 4] = self.buf.get(at..at + 4)?.try_into().ok()?;
        Some(match self.endianness() {
            Endianness::Big => u32::from_be_bytes(b),
            Endianness::Little => u32::from_le_bytes(b),
        })
    }

    /// Declared length of the block/record at `start`, when its header is present.
    fn declared_len(&self) -> Option<usize> {
        if self.ng {
            self.read_u32(self.start + 4).map(|l| l as usize)
        } else {
            self.read_u32(self.start + 8).map(|l| l as usize + 16)
        }
    }

    /// Whether a plausible block/record starts at `at` (for resynchronisation).
    /// Whether a plausible block/record starts at `at` (for resynchronisation): `None` when
    /// more bytes are needed to tell (never at end of file), so the answer does not depend on
    /// where the last read ended.
    fn plausible_at(&self, at: usize) -> Option<bool> {
        let more = || if self.eof { Some(false) } else { None };
        if self.ng {
            let (Some(t), Some(l)) = (self.read_u32(at), self.read_u32(at + 4)) else {
                return more();
            };
            let l = l as usize;
            if !(matches!(t, 1 | 3 | 5 | 6 | 0x0A0D0D0A)
                && l >= 12
                && l.is_multiple_of(4)
                && l <= MAX_RECORD)
            {
                return Some(false);
            }
            match self.read_u32(at + l - 4) {
                Some(end) => Some(end == l as u32),
                None => more(),
            }
        } else {
            let (Some(cap), Some(orig)) = (self.read_u32(at + 8), self.read_u32(at + 12)) else {
                return more();
            };
            let snap = match &self.parser {
                Parser::Legacy(p) => p.header().snaplen.max(65535),
                _ => 65535,
            };
            if !(cap <= orig && cap <= snap && (cap as usize) < MAX_RECORD) {
                return Some(false);
            }
            if self.buf.len() >= at + 16 + cap as usize {
                Some(true)
            } else {
                more()
            }
        }
    }

    /// Skip a corrupt block: find the next plausible one.
    fn resync(&mut self, damage: Damage) {
        let from = self.offset();
        // pcapng blocks are 4-byte aligned; pcap records are not.
        let mut at = self.start + if self.ng { 4 } else { 1 };
        loop {
            while at < self.buf.len() {
                match self.plausible_at(at) {
                    Some(true) => {
                        let skipped = Skipped::ToNext {
                            bytes: at - self.start,
                        };
                        self.queue
                            .push_back(diag(from, ReadProblem::Damaged { damage, skipped }));
                        self.start = at;
                        return;
                    }
                    Some(false) => at += if self.ng { 4 } else { 1 },
                    None => break,
                }
            }
            // Reading more moves the buffer (consumed bytes are dropped): re-base `at` first.
            let rel = at - self.start;
            let more = self.fill();
            at = self.start + rel;
            if !more && at >= self.buf.len() {
                let skipped = Skipped::ToEnd {
                    rest: self.buf.len() - self.start,
                };
                self.queue
                    .push_back(diag(from, ReadProblem::Damaged { damage, skipped }));
                self.start = self.buf.len();
                return;
            }
        }
    }

    fn start_parser(&mut self) -> bool {
        // Only the file header: a live pipe (`dumpcap -w - | aptscope decode -`) may send
        // nothing more for long, and its first packets are to be shown at once.
        while self.buf.len() - self.start < file_header_len(&self.buf[self.start..]) && self.fill()
        {
        }
        let head = &self.buf[self.start..];
        if sniff_pcapng(head) {
            match PcapNgParser::new(head) {
                Ok((rem, p)) => {
                    self.start += head.len() - rem.len();
                    self.parser = Parser::Ng(p);
                    self.ng = true;
                    true
                }
                Err(e) => {
                    self.queue
                        .push_back(diag(self.offset(), bad_header(true, &e)));
                    false
                }
            }
        } else if sniff_pcap(head) {
            match PcapParser::new(head) {
                Ok((rem, p)) => {
                    self.start += head.len() - rem.len();
                    self.ng = false;
                    self.pcap_linktype = u32::from(p.header().datalink);
                    self.parser = Parser::Legacy(p);
                    self.announce_linktype(self.pcap_linktype);
                    true
                }
                Err(e) => {
                    self.queue
                        .push_back(diag(self.offset(), bad_header(false, &e)));
                    false
                }
            }
        } else {
            let found = head.iter().take(4).copied().collect();
            self.queue
                .push_back(diag(self.offset(), ReadProblem::BadMagic { found }));
            false
        }
    }

    fn announce_linktype(&mut self, lt: u32) {
        if lt == LINKTYPE_SERIAL_NG
            || lt == LINKTYPE_SERIAL_PCAP
            || is_usb_linktype(lt)
            || self.warned_linktypes.contains(&lt)
        {
            return;
        }
        self.warned_linktypes.push(lt);
        let at = self.offset();
        let problem = ReadProblem::UnknownLinkType { linktype: lt };
        self.queue.push_back(diag(at, problem));
    }

    fn stream_for(
        &mut self,
        known: &mut Vec<u32>,
        id: u32,
        name: String,
        settings: Option<String>,
    ) {
        if !known.contains(&id) {
            known.push(id);
            self.queue
                .push_back(Owned::Stream(StreamInfo { id, name, settings }));
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn packet(
        &mut self,
        lt: u32,
        data: Vec<u8>,
        orig_len: u32,
        ts: u64,
        at: u64,
        stream: u32,
        flags: Option<u32>,
    ) {
        if is_usb_linktype(lt) {
            self.usb
                .packet(lt, &data, orig_len, ts, at, &mut self.usb_out);
            self.push_usb_out();
            return;
        }
        if lt == LINKTYPE_SERIAL_PCAP {
            let (Some(&d), Some(&s)) = (data.first(), data.get(1)) else {
                let found = data.len();
                self.queue
                    .push_back(diag(at, ReadProblem::ShortRecord { found }));
                return;
            };
            let mut known = std::mem::take(&mut self.pcap_streams);
            self.stream_for(&mut known, s as u32, format!("stream {s}"), None);
            self.pcap_streams = known;
            self.queue.push_back(Owned::Chunk(OwnedChunk {
                ts_ns: Some(ts),
                dir: dir_from_byte(d),
                stream: s as u32,
                bytes: data[2..].to_vec(),
            }));
        } else if lt == LINKTYPE_SERIAL_NG {
            if orig_len as usize > data.len() {
                let problem = ReadProblem::SnappedPacket {
                    captured: data.len(),
                    original: orig_len,
                };
                self.queue.push_back(diag(at, problem));
            }
            self.queue.push_back(Owned::Chunk(OwnedChunk {
                ts_ns: Some(ts),
                dir: flags.map_or(Direction::Unknown, dir_of_flags),
                stream,
                bytes: data,
            }));
        }
    }

    fn push_usb_out(&mut self) {
        for o in self.usb_out.drain(..) {
            self.queue.push_back(match o {
                UsbOut::Stream(s) => Owned::Stream(s),
                UsbOut::Chunk(c) => Owned::Chunk(c),
                UsbOut::Diag(d) => Owned::Diag(d),
            });
        }
    }

    /// Parse the next block/record into the queue. `false` at the end.
    fn step(&mut self) -> bool {
        if matches!(self.parser, Parser::None) && (self.done || !self.start_parser()) {
            self.done = true;
            return !self.queue.is_empty();
        }
        if self.start >= self.buf.len() && !self.fill() {
            return false;
        }
        let at = self.offset();
        // A header whose length is absurd is corruption, not a reason to buffer the whole file.
        if let Some(len) = self.declared_len() {
            if len > MAX_RECORD || (self.ng && (len < 12 || !len.is_multiple_of(4))) {
                self.resync(Damage::BadLength { declared: len });
                return true;
            }
            while self.buf.len() - self.start < len {
                if !self.fill() {
                    let have = self.buf.len() - self.start;
                    let problem = ReadProblem::TruncatedRecord {
                        expected: len,
                        found: have,
                    };
                    self.queue.push_back(diag(at, problem));
                    self.start = self.buf.len();
                    return true;
                }
            }
        }
        let avail = &self.buf[self.start..];
        let result: Result<(usize, Option<Parsed>), PcapError> = match &mut self.parser {
            Parser::Legacy(p) => p.next_packet(avail).map(|(rem, pkt)| {
                (
                    avail.len() - rem.len(),
                    Some(Parsed::Packet(
                        u32::MAX,
                        pkt.timestamp.as_nanos() as u64,
                        pkt.orig_len,
                        pkt.data.into_owned(),
                        None,
                    )),
                )
            }),
            Parser::Ng(p) => match p.next_block(avail) {
                Ok((rem, block)) => {
                    let used = avail.len() - rem.len();
                    let parsed = match block {
                        Block::InterfaceDescription(idb) => Some(Parsed::Iface(iface_of(&idb))),
                        Block::EnhancedPacket(epb) => {
                            let flags = epb.options.iter().find_map(|o| match o {
                                EnhancedPacketOption::Flags(f) => Some(*f),
                                _ => None,
                            });
                            Some(Parsed::Packet(
                                epb.interface_id,
                                epb.timestamp.as_nanos() as u64,
                                epb.original_len,
                                epb.data.into_owned(),
                                flags,
                            ))
                        }
                        Block::SimplePacket(spb) => Some(Parsed::Packet(
                            0,
                            0,
                            spb.original_len,
                            spb.data.into_owned(),
                            None,
                        )),
                        Block::SectionHeader(_) => Some(Parsed::Section),
                        _ => None,
                    };
                    Ok((used, parsed))
                }
                Err(e) => Err(e),
            },
            Parser::None => return false,
        };
        match result {
            Ok((used, parsed)) => {
                self.start += used.max(1);
                match parsed {
                    Some(Parsed::Iface((lt, units, name, settings))) => {
                        let stream = self.next_stream;
                        self.next_stream += 1;
                        self.ifaces.push(Iface {
                            linktype: lt,
                            units_per_s: units,
                            stream,
                        });
                        self.announce_linktype(lt);
                        if lt == LINKTYPE_SERIAL_NG {
                            self.queue.push_back(Owned::Stream(StreamInfo {
                                id: stream,
                                name: name.unwrap_or_else(|| {
                                    format!("interface {}", self.ifaces.len() - 1)
                                }),
                                settings,
                            }));
                        }
                    }
                    Some(Parsed::Section) => self.ifaces.clear(),
                    Some(Parsed::Packet(ifid, raw_ts, orig, data, flags)) => {
                        let (lt, ts, stream) = if ifid == u32::MAX {
                            (self.pcap_linktype, raw_ts, 0)
                        } else {
                            match self.ifaces.get(ifid as usize).cloned() {
                                Some(i) => (i.linktype, scale_ts(raw_ts, i.units_per_s), i.stream),
                                None => {
                                    let problem = ReadProblem::UnknownInterface { interface: ifid };
                                    self.queue.push_back(diag(at, problem));
                                    return true;
                                }
                            }
                        };
                        self.packet(lt, data, orig, ts, at, stream, flags);
                    }
                    None => {}
                }
                true
            }
            Err(PcapError::IncompleteBuffer) => {
                if !self.fill() {
                    let have = self.buf.len() - self.start;
                    if have > 0 {
                        let problem = ReadProblem::TruncatedTail { found: have };
                        self.queue.push_back(diag(at, problem));
                        self.start = self.buf.len();
                    }
                    return have > 0;
                }
                true
            }
            Err(e) => {
                self.resync(Damage::Unparsable {
                    error: e.to_string(),
                });
                true
            }
        }
    }
}

enum Parsed {
    Iface((u32, u64, Option<String>, Option<String>)),
    Packet(u32, u64, u32, Vec<u8>, Option<u32>),
    Section,
}

fn iface_of(idb: &InterfaceDescriptionBlock<'_>) -> (u32, u64, Option<String>, Option<String>) {
    let mut units = 1_000_000u64;
    let (mut name, mut desc) = (None, None);
    for o in &idb.options {
        match o {
            InterfaceDescriptionOption::IfTsResol(r) => {
                units = if r & 0x80 != 0 {
                    1u64.checked_shl((r & 0x7F) as u32).unwrap_or(u64::MAX)
                } else {
                    10u64.checked_pow(*r as u32).unwrap_or(u64::MAX)
                };
            }
            InterfaceDescriptionOption::IfName(n) => name = Some(n.to_string()),
            InterfaceDescriptionOption::IfDescription(d) => desc = Some(d.to_string()),
            _ => {}
        }
    }
    (u32::from(idb.linktype), units, name, desc)
}

/// Convert timestamp units to ns.
fn scale_ts(units: u64, per_s: u64) -> u64 {
    if per_s == 1_000_000_000 {
        units
    } else {
        ((units as u128) * 1_000_000_000 / per_s.max(1) as u128) as u64
    }
}

impl<R: Read> Reader for PcapReader<R> {
    fn next_event(&mut self) -> Option<Event<'_>> {
        self.current = None;
        while self.queue.is_empty() {
            if !self.step() && self.queue.is_empty() {
                if self.usb_flushed {
                    return None;
                }
                // End of file: data the USB demultiplexer still holds comes out now.
                self.usb_flushed = true;
                self.usb.finish(&mut self.usb_out);
                self.push_usb_out();
            }
        }
        self.current = self.queue.pop_front();
        Some(match self.current.as_ref()? {
            Owned::Stream(s) => Event::Stream(s.clone()),
            Owned::Chunk(c) => Event::Chunk(c.as_chunk()),
            Owned::Diag(d) => Event::Diag(d.clone()),
        })
    }

    fn format(&self) -> String {
        if matches!(self.parser, Parser::None) && !self.done {
            return if self.ng { "pcapng" } else { "pcap" }.to_string();
        }
        let kind = if self.ng { "pcapng" } else { "pcap" };
        let lts: Vec<u32> = if self.ng {
            self.ifaces.iter().map(|i| i.linktype).collect()
        } else {
            vec![self.pcap_linktype]
        };
        let usb = lts.iter().any(|l| is_usb_linktype(*l));
        let mut lts = lts;
        lts.dedup();
        format!(
            "{kind}{} (link type {})",
            if usb { ", USB" } else { "" },
            lts.iter()
                .map(|l| l.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        )
    }
}

/// Writer of aptscope pcapng serial captures.
pub struct PcapNgOut<W: Write> {
    w: Option<PcapNgWriter<W>>,
    streams: Vec<u32>,
    /// Chunks written without a timestamp (at time 0).
    untimed: u64,
}

impl<W: Write> PcapNgOut<W> {
    /// Start a pcapng file.
    pub fn new(w: W) -> io::Result<Self> {
        let w = PcapNgWriter::new(w).map_err(io::Error::other)?;
        Ok(PcapNgOut {
            w: Some(w),
            streams: vec![],
            untimed: 0,
        })
    }

    fn iface(&mut self, s: &StreamInfo) -> io::Result<u32> {
        if let Some(i) = self.streams.iter().position(|x| *x == s.id) {
            return Ok(i as u32);
        }
        let w = self
            .w
            .as_mut()
            .ok_or_else(|| io::Error::other("writer finished"))?;
        let mut options = vec![
            InterfaceDescriptionOption::IfName(Cow::Owned(s.name.clone())),
            InterfaceDescriptionOption::IfTsResol(9),
        ];
        if let Some(d) = &s.settings {
            options.push(InterfaceDescriptionOption::IfDescription(Cow::Owned(
                d.clone(),
            )));
        }
        w.write_pcapng_block(InterfaceDescriptionBlock {
            linktype: DataLink::from(LINKTYPE_SERIAL_NG),
            snaplen: 0,
            options,
        })
        .map_err(io::Error::other)?;
        self.streams.push(s.id);
        Ok(self.streams.len() as u32 - 1)
    }
}

impl<W: Write> Writer for PcapNgOut<W> {
    fn stream(&mut self, s: &StreamInfo) -> io::Result<()> {
        self.iface(s).map(|_| ())
    }

    fn chunk(&mut self, c: &Chunk<'_>) -> io::Result<()> {
        let ifid = match self.streams.iter().position(|x| *x == c.stream) {
            Some(i) => i as u32,
            None => self.iface(&StreamInfo {
                id: c.stream,
                name: format!("serial{}", c.stream),
                settings: None,
            })?,
        };
        let flags = match c.dir {
            Direction::HostToDevice => 2,
            Direction::DeviceToHost => 1,
            Direction::Unknown => 0,
        };
        let w = self
            .w
            .as_mut()
            .ok_or_else(|| io::Error::other("writer finished"))?;
        self.untimed += u64::from(c.ts_ns.is_none());
        w.write_pcapng_block(EnhancedPacketBlock {
            interface_id: ifid,
            // pcap-file writes the Duration's nanoseconds as raw units: with if_tsresol 9
            // those are ns.
            timestamp: Duration::from_nanos(c.ts_ns.unwrap_or(0)),
            original_len: c.bytes.len() as u32,
            data: Cow::Borrowed(c.bytes),
            options: vec![EnhancedPacketOption::Flags(flags)],
        })
        .map_err(io::Error::other)?;
        Ok(())
    }

    fn finish(&mut self) -> io::Result<()> {
        if let Some(w) = self.w.take() {
            w.into_inner().flush()?;
        }
        Ok(())
    }

    fn lost(&self) -> Vec<String> {
        untimed_note(self.untimed).into_iter().collect()
    }
}

/// What a pcap or pcapng file says of chunks that had no time.
fn untimed_note(n: u64) -> Option<String> {
    (n > 0).then(|| {
        format!(
            "missing times: {n} chunk(s) without a timestamp are written at time 0 (1970-01-01)"
        )
    })
}

/// Writer of legacy pcap serial captures (USER1 with a `[direction, stream]` pseudo-header).
pub struct PcapOut<W: Write> {
    w: Option<PcapWriter<W>>,
    buf: Vec<u8>,
    /// Chunks written without a timestamp (at time 0).
    untimed: u64,
    /// Streams declared with a name or line settings that a reader of the file cannot get
    /// back (it names them `stream N`).
    named: Vec<String>,
    /// Chunks of streams above 255, written as stream 255.
    clamped: u64,
}

impl<W: Write> PcapOut<W> {
    /// Start a pcap file (ns resolution).
    pub fn new(w: W) -> io::Result<Self> {
        let header = PcapHeader {
            version_major: 2,
            version_minor: 4,
            ts_correction: 0,
            ts_accuracy: 0,
            snaplen: 65535,
            datalink: DataLink::from(LINKTYPE_SERIAL_PCAP),
            ts_resolution: TsResolution::NanoSecond,
            endianness: Endianness::Little,
        };
        let w = PcapWriter::with_header(w, header).map_err(io::Error::other)?;
        Ok(PcapOut {
            w: Some(w),
            buf: vec![],
            untimed: 0,
            named: vec![],
            clamped: 0,
        })
    }
}

impl<W: Write> Writer for PcapOut<W> {
    fn stream(&mut self, s: &StreamInfo) -> io::Result<()> {
        if s.name != format!("stream {}", s.id) || s.settings.is_some() {
            let mut d = s.name.clone();
            if let Some(x) = &s.settings {
                d.push_str(", ");
                d.push_str(x);
            }
            self.named.push(d);
        }
        Ok(())
    }

    fn chunk(&mut self, c: &Chunk<'_>) -> io::Result<()> {
        let w = self
            .w
            .as_mut()
            .ok_or_else(|| io::Error::other("writer finished"))?;
        self.untimed += u64::from(c.ts_ns.is_none());
        self.clamped += u64::from(c.stream > u32::from(u8::MAX));
        // Records longer than the snap length are split: the bytes stay in order.
        for piece in c.bytes.chunks(65535 - 2) {
            self.buf.clear();
            self.buf.push(dir_byte(c.dir));
            self.buf.push(u8::try_from(c.stream).unwrap_or(u8::MAX));
            self.buf.extend_from_slice(piece);
            let len = self.buf.len() as u32;
            w.write_packet(&PcapPacket::new(
                Duration::from_nanos(c.ts_ns.unwrap_or(0)),
                len,
                &self.buf,
            ))
            .map_err(io::Error::other)?;
        }
        Ok(())
    }

    fn finish(&mut self) -> io::Result<()> {
        if let Some(w) = self.w.take() {
            w.into_writer().flush()?;
        }
        Ok(())
    }

    fn lost(&self) -> Vec<String> {
        let mut v = vec![];
        if !self.named.is_empty() {
            let mut list = self.named[..self.named.len().min(4)].join("; ");
            if self.named.len() > 4 {
                list.push_str(&format!("; and {} more", self.named.len() - 4));
            }
            v.push(format!(
                "stream names and line settings (pcap has no interface descriptions): {list}"
            ));
        }
        if self.clamped > 0 {
            v.push(format!(
                "streams above 255: {} chunk(s) are written as stream 255",
                self.clamped
            ));
        }
        v.extend(untimed_note(self.untimed));
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A writer says what it dropped of what it was given, and nothing else.
    #[test]
    fn writers_say_only_what_they_lost() {
        let timed = |stream| OwnedChunk {
            ts_ns: Some(5),
            dir: Direction::HostToDevice,
            stream,
            bytes: vec![1, 2],
        };
        let plain = |id: u32| StreamInfo {
            id,
            name: format!("stream {id}"),
            settings: None,
        };
        let mut w = PcapOut::new(Vec::new()).expect("pcap");
        w.stream(&plain(0)).expect("stream");
        w.chunk(&timed(0).as_chunk()).expect("chunk");
        assert_eq!(w.lost(), Vec::<String>::new());
        w.chunk(&timed(300).as_chunk()).expect("chunk");
        w.chunk(
            &OwnedChunk {
                ts_ns: None,
                ..timed(0)
            }
            .as_chunk(),
        )
        .expect("chunk");
        assert_eq!(
            w.lost(),
            [
                "streams above 255: 1 chunk(s) are written as stream 255",
                "missing times: 1 chunk(s) without a timestamp are written at time 0 (1970-01-01)"
            ]
        );
        let mut w = PcapNgOut::new(Vec::new()).expect("pcapng");
        w.stream(&StreamInfo {
            id: 0,
            name: "/dev/ttyUSB0".into(),
            settings: Some("115200 8N1".into()),
        })
        .expect("stream");
        w.chunk(&timed(0).as_chunk()).expect("chunk");
        w.chunk(&timed(300).as_chunk()).expect("chunk");
        assert_eq!(w.lost(), Vec::<String>::new());
    }

    fn chunks() -> Vec<OwnedChunk> {
        vec![
            OwnedChunk {
                ts_ns: Some(1_700_000_000_123_456_789),
                dir: Direction::HostToDevice,
                stream: 0,
                bytes: vec![0x05, 0x00, 0x00, 0x00, 0x50, 0x01],
            },
            OwnedChunk {
                ts_ns: Some(1_700_000_000_223_456_789),
                dir: Direction::DeviceToHost,
                stream: 0,
                bytes: vec![0x12, 0x02, 0x01, 0x01, 0x01, 0x50],
            },
            OwnedChunk {
                ts_ns: Some(1_700_000_001_000_000_001),
                dir: Direction::Unknown,
                stream: 1,
                bytes: b"0gs".to_vec(),
            },
        ]
    }

    fn read_all(bytes: Vec<u8>) -> (Vec<OwnedChunk>, Vec<ReadDiag>, Vec<StreamInfo>) {
        let mut r = PcapReader::new(std::io::Cursor::new(bytes), None);
        let (mut c, mut d, mut s) = (vec![], vec![], vec![]);
        while let Some(ev) = r.next_event() {
            match ev {
                Event::Chunk(x) => c.push(x.to_owned()),
                Event::Diag(x) => d.push(x),
                Event::Stream(x) => s.push(x),
            }
        }
        (c, d, s)
    }

    #[test]
    fn pcapng_round_trip_keeps_bytes_times_direction_and_ports() {
        let mut w = PcapNgOut::new(Vec::new()).expect("writer");
        w.stream(&StreamInfo {
            id: 0,
            name: "/dev/ttyUSB0".into(),
            settings: Some("115200 8N1 RTS/CTS".into()),
        })
        .expect("stream");
        for c in chunks() {
            w.chunk(&c.as_chunk()).expect("chunk");
        }
        let bytes = w.w.take().expect("writer").into_inner();
        let (c, d, s) = read_all(bytes);
        assert!(d.is_empty(), "{d:?}");
        assert_eq!(c, chunks());
        assert_eq!(s[0].name, "/dev/ttyUSB0");
        assert_eq!(s[0].settings.as_deref(), Some("115200 8N1 RTS/CTS"));
        assert_eq!(s.len(), 2);
    }

    #[test]
    fn pcap_round_trip_keeps_bytes_times_direction_and_stream() {
        let mut w = PcapOut::new(Vec::new()).expect("writer");
        for c in chunks() {
            w.chunk(&c.as_chunk()).expect("chunk");
        }
        let bytes = w.w.take().expect("writer").into_writer();
        let (c, d, _) = read_all(bytes);
        assert!(d.is_empty(), "{d:?}");
        assert_eq!(c, chunks());
    }

    #[test]
    fn bad_magic_unknown_linktype_and_short_files() {
        let (c, d, _) = read_all(b"hello world, not a capture".to_vec());
        assert!(c.is_empty());
        assert_eq!(d[0].kind(), "bad_magic");
        assert_eq!(d[0].offset, 0);
        let (c, d, _) = read_all(vec![]);
        assert!(c.is_empty());
        assert_eq!(d.len(), 1, "{d:?}");
        // An Ethernet pcap: its packets are skipped with one diagnostic.
        let mut w = PcapWriter::with_header(
            Vec::new(),
            PcapHeader {
                datalink: DataLink::ETHERNET,
                ..PcapHeader::default()
            },
        )
        .expect("writer");
        w.write_packet(&PcapPacket::new(Duration::from_secs(1), 4, &[1, 2, 3, 4]))
            .expect("packet");
        let (c, d, _) = read_all(w.into_writer());
        assert!(c.is_empty());
        assert_eq!(
            d.iter().map(|x| x.kind()).collect::<Vec<_>>(),
            ["unknown_linktype"]
        );
    }

    /// A pcapng of [`chunks`] and where its blocks start.
    fn pcapng_blocks() -> (Vec<u8>, Vec<usize>) {
        let mut w = PcapNgOut::new(Vec::new()).expect("writer");
        for c in chunks() {
            w.chunk(&c.as_chunk()).expect("chunk");
        }
        let bytes = w.w.take().expect("writer").into_inner();
        let mut starts = vec![];
        let mut at = 0;
        while at + 8 <= bytes.len() {
            starts.push(at);
            at += u32::from_le_bytes([bytes[at + 4], bytes[at + 5], bytes[at + 6], bytes[at + 7]])
                as usize;
        }
        (bytes, starts)
    }

    #[test]
    fn damaged_and_cut_files_report_typed_problems_in_the_same_words() {
        let (bytes, starts) = pcapng_blocks();
        let last = *starts.last().expect("blocks");
        // The last packet's block declares a length no block has: skipped to the end.
        let mut bad = bytes.clone();
        bad[last + 4..last + 8].copy_from_slice(&7u32.to_le_bytes());
        let (c, d, _) = read_all(bad);
        assert_eq!(c.len(), chunks().len() - 1);
        let rest = bytes.len() - last;
        assert_eq!(
            d[0],
            ReadDiag::new(
                last as u64,
                ReadProblem::Damaged {
                    damage: Damage::BadLength { declared: 7 },
                    skipped: Skipped::ToEnd { rest },
                }
            )
        );
        assert_eq!(
            d[0].to_string(),
            format!(
                "@{last}: bad_block_length: declared length 7 is not a valid length; no record \
                 follows in the last {rest} bytes"
            )
        );
        // The second block of three damaged: reading resumes at the third.
        let second = starts[starts.len() - 2];
        let mut bad = bytes.clone();
        bad[second + 4..second + 8].copy_from_slice(&7u32.to_le_bytes());
        let (c, d, _) = read_all(bad);
        assert_eq!(c.len(), chunks().len() - 1);
        let skipped = Skipped::ToNext {
            bytes: last - second,
        };
        assert!(
            matches!(d[0].problem, ReadProblem::Damaged { skipped: s, .. } if s == skipped),
            "{d:?}"
        );
        assert!(
            d[0].msg().ends_with(&format!(
                "; skipped {} bytes to the next plausible record",
                last - second
            )),
            "{d:?}"
        );

        // Cut inside the last block: its length is known, the bytes are not there.
        let cut = last + 20;
        let (_, d, _) = read_all(bytes[..cut].to_vec());
        let expected = bytes.len() - last;
        assert_eq!(
            d[0].problem,
            ReadProblem::TruncatedRecord {
                expected,
                found: 20
            }
        );
        assert_eq!(d[0].kind(), "truncated_record");
        assert_eq!(
            d[0].msg(),
            format!("record of {expected} bytes runs past the end of the file (20 bytes left)")
        );
        // Cut inside its header: too few bytes for one.
        let (_, d, _) = read_all(bytes[..last + 5].to_vec());
        assert_eq!(
            (d[0].offset, &d[0].problem),
            (last as u64, &ReadProblem::TruncatedTail { found: 5 })
        );
        assert_eq!(
            d[0].msg(),
            "5 bytes at the end of the file are not a whole record"
        );

        // Not a capture: what was found instead of a magic.
        let (_, d, _) = read_all(b"hello".to_vec());
        assert_eq!(
            d[0].problem,
            ReadProblem::BadMagic {
                found: b"hell".to_vec()
            }
        );
        assert_eq!(
            d[0].to_string(),
            "@0: bad_magic: not a pcap or pcapng file (starts 68 65 6c 6c)"
        );
        let (_, d, _) = read_all(vec![]);
        assert_eq!(d[0].msg(), "not a pcap or pcapng file (starts )");
    }

    /// Yields at most `n` bytes per read, like a pipe.
    struct Short<R>(R, usize);

    impl<R: std::io::Read> std::io::Read for Short<R> {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = buf.len().min(self.1);
            self.0.read(&mut buf[..n])
        }
    }

    #[test]
    fn resynchronisation_does_not_depend_on_read_sizes() {
        let mut bytes = std::fs::read(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../samples/kdc101-session.pcap"
        ))
        .expect("sample");
        // Break the captured length of the third record: it runs past every later record.
        let mut at = 24;
        for _ in 0..2 {
            let cap =
                u32::from_le_bytes([bytes[at + 8], bytes[at + 9], bytes[at + 10], bytes[at + 11]])
                    as usize;
            at += 16 + cap;
        }
        bytes[at + 8..at + 12].copy_from_slice(&0x0200_0000u32.to_le_bytes());
        let events = |r: &mut dyn Reader| {
            let mut v = vec![];
            while let Some(ev) = r.next_event() {
                v.push(format!("{ev:?}"));
            }
            v
        };
        let whole = events(&mut PcapReader::new(
            std::io::Cursor::new(bytes.clone()),
            None,
        ));
        for n in [1, 7, 31, 64] {
            let short = events(&mut PcapReader::new(
                Short(std::io::Cursor::new(bytes.clone()), n),
                None,
            ));
            assert_eq!(short, whole, "reads of {n} bytes");
        }
        assert!(whole.iter().any(|e| e.starts_with("Diag")), "{whole:?}");
        assert!(
            whole.iter().filter(|e| e.starts_with("Chunk")).count() >= 18,
            "{whole:?}"
        );
    }
}
