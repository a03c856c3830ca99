//! The capture model: a capture is a sequence of chunks, each with a timestamp, a direction, a
//! stream (port or USB device) and bytes. Readers produce [`Event`]s; writers consume chunks.

use aptscope_dissector::pipeline::{Ctx, Pipeline};
use aptscope_dissector::record::{Decoder, Record};
use aptscope_dissector::table::Dir;

pub use crate::problem::*;

/// Which way bytes went.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Direction {
    /// Host → device (the host program wrote them).
    HostToDevice,
    /// Device → host (the controller sent them).
    DeviceToHost,
    /// Not recorded.
    Unknown,
}

impl Direction {
    /// `h2d`, `d2h` or `unknown` (the NDJSON `dir`).
    pub fn as_str(self) -> &'static str {
        match self {
            Direction::HostToDevice => "h2d",
            Direction::DeviceToHost => "d2h",
            Direction::Unknown => "unknown",
        }
    }
    /// The dissector's direction (`None` when not recorded).
    pub fn dir(self) -> Option<Dir> {
        match self {
            Direction::HostToDevice => Some(Dir::HostToDevice),
            Direction::DeviceToHost => Some(Dir::DeviceToHost),
            Direction::Unknown => None,
        }
    }

    /// From the dissector's direction (`None`: not recorded).
    pub fn from_dir(d: Option<Dir>) -> Direction {
        match d {
            Some(Dir::HostToDevice) => Direction::HostToDevice,
            Some(Dir::DeviceToHost) => Direction::DeviceToHost,
            _ => Direction::Unknown,
        }
    }

    /// Parse `h2d`/`d2h`/`unknown` (and `tx`/`rx`, `out`/`in`).
    pub fn parse(s: &str) -> Option<Direction> {
        Some(match s {
            "h2d" | "tx" | "out" | ">" => Direction::HostToDevice,
            "d2h" | "rx" | "in" | "<" => Direction::DeviceToHost,
            "unknown" | "?" => Direction::Unknown,
            _ => return None,
        })
    }
}

/// A chunk of captured bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Chunk<'a> {
    /// Capture time in ns since the Unix epoch (or since the capture's start when the format
    /// has no absolute time), when the format records one.
    pub ts_ns: Option<u64>,
    /// Direction.
    pub dir: Direction,
    /// Stream (serial port, or USB device) index, as announced by [`Event::Stream`]; 0 when the
    /// format has one stream.
    pub stream: u32,
    /// The bytes.
    pub bytes: &'a [u8],
}

/// An owned chunk (for tests, converters and writers that reorder).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OwnedChunk {
    /// Capture time in ns.
    pub ts_ns: Option<u64>,
    /// Direction.
    pub dir: Direction,
    /// Stream index.
    pub stream: u32,
    /// The bytes.
    pub bytes: Vec<u8>,
}

impl Chunk<'_> {
    /// Where and when the chunk was captured, as the decoding pipeline takes it.
    pub fn ctx(&self) -> Ctx {
        Ctx {
            stream: self.stream,
            dir: self.dir.dir(),
            ts_ns: self.ts_ns,
        }
    }

    /// Copy into an [`OwnedChunk`].
    pub fn to_owned(&self) -> OwnedChunk {
        OwnedChunk {
            ts_ns: self.ts_ns,
            dir: self.dir,
            stream: self.stream,
            bytes: self.bytes.to_vec(),
        }
    }
}

impl OwnedChunk {
    /// Borrow as a [`Chunk`].
    pub fn as_chunk(&self) -> Chunk<'_> {
        Chunk {
            ts_ns: self.ts_ns,
            dir: self.dir,
            stream: self.stream,
            bytes: &self.bytes,
        }
    }
}

/// What a stream is: a serial port, or a USB device.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct StreamInfo {
    /// Index used by chunks.
    pub id: u32,
    /// Name (`/dev/ttyUSB0`, `usb 1:7 0403:faf0`).
    pub name: String,
    /// Line settings when known (`115200 8N1 RTS/CTS`).
    pub settings: Option<String>,
}

/// What a reader produces.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Event<'a> {
    /// A stream is announced (before its first chunk).
    Stream(StreamInfo),
    /// Captured bytes.
    Chunk(Chunk<'a>),
    /// A problem in the file; reading carries on where the format allows.
    Diag(ReadDiag),
}

impl Event<'_> {
    /// Pass the event to a decode chain ([`Decoder`], or a [`Pipeline`] that renders its
    /// records): bytes to [`Decoder::push`], a problem to [`Decoder::file_diag`], a stream to
    /// [`Decoder::stream_info`] (what every consumer of a capture does with each event).
    pub fn feed<C: Chain, E>(
        &self,
        chain: &mut C,
        emit: &mut impl FnMut(&C::Out<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        match self {
            Event::Chunk(c) => chain.chunk(c.ctx(), c.bytes, emit),
            Event::Diag(d) => chain.diag(d.offset, d.kind(), &d.msg(), emit),
            Event::Stream(s) => chain.stream(s.id, &s.name, s.settings.as_deref(), emit),
        }
    }
}

/// What [`Event::feed`] feeds: the decode chain ([`Decoder`], which emits [`Record`]s) or a
/// [`Pipeline`] (the chain and a renderer, which emits lines), so that the three kinds of event
/// are spelled once for both.
pub trait Chain {
    /// What it emits: a `Record<'r>` or a line (`str`).
    type Out<'r>: ?Sized;
    /// Bytes of a chunk ([`Decoder::push`]).
    fn chunk<E>(
        &mut self,
        ctx: Ctx,
        bytes: &[u8],
        emit: &mut impl FnMut(&Self::Out<'_>) -> Result<(), E>,
    ) -> Result<(), E>;
    /// A problem of the capture file ([`Decoder::file_diag`]).
    fn diag<E>(
        &mut self,
        offset: u64,
        kind: &str,
        msg: &str,
        emit: &mut impl FnMut(&Self::Out<'_>) -> Result<(), E>,
    ) -> Result<(), E>;
    /// A stream the capture announces ([`Decoder::stream_info`]).
    fn stream<E>(
        &mut self,
        id: u32,
        name: &str,
        settings: Option<&str>,
        emit: &mut impl FnMut(&Self::Out<'_>) -> Result<(), E>,
    ) -> Result<(), E>;
}

impl Chain for Decoder {
    type Out<'r> = Record<'r>;
    fn chunk<E>(
        &mut self,
        ctx: Ctx,
        bytes: &[u8],
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        self.push(ctx, bytes, emit)
    }
    fn diag<E>(
        &mut self,
        offset: u64,
        kind: &str,
        msg: &str,
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        self.file_diag(offset, kind, msg, emit)
    }
    fn stream<E>(
        &mut self,
        id: u32,
        name: &str,
        settings: Option<&str>,
        emit: &mut impl FnMut(&Record<'_>) -> Result<(), E>,
    ) -> Result<(), E> {
        self.stream_info(id, name, settings, emit)
    }
}

impl Chain for Pipeline {
    type Out<'r> = str;
    fn chunk<E>(
        &mut self,
        ctx: Ctx,
        bytes: &[u8],
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        self.push_chunk(ctx, bytes, emit)
    }
    fn diag<E>(
        &mut self,
        offset: u64,
        kind: &str,
        msg: &str,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        self.file_diag(offset, kind, msg, emit)
    }
    fn stream<E>(
        &mut self,
        id: u32,
        name: &str,
        settings: Option<&str>,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        self.stream_info(id, name, settings, emit)
    }
}

/// A capture reader: a lending iterator of events (each borrows the reader until the next call).
pub trait Reader {
    /// The next event, `None` at the end.
    fn next_event(&mut self) -> Option<Event<'_>>;
    /// The format's name (`pcapng`, `usbmon pcap`, `socat log` …).
    fn format(&self) -> String;
}

/// A capture writer.
pub trait Writer {
    /// Declare a stream before its chunks.
    fn stream(&mut self, s: &StreamInfo) -> std::io::Result<()>;
    /// Write one chunk.
    fn chunk(&mut self, c: &Chunk<'_>) -> std::io::Result<()>;
    /// A problem of the input being converted (a damaged record), in its place among the
    /// chunks: a format that carries decoded records keeps it (MCAP's `/aptscope/input`, as
    /// `decode --json` writes it); the others drop it.
    fn diag(&mut self, _d: &ReadDiag) -> std::io::Result<()> {
        Ok(())
    }
    /// Flush and close (writes summaries/footers).
    fn finish(&mut self) -> std::io::Result<()>;
    /// What of the chunks and streams written so far the format could not carry, one line
    /// each (said by `convert`): empty when the file holds all of it.
    fn lost(&self) -> Vec<String> {
        vec![]
    }
}
