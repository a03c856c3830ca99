//! The MCAP reader: the raw channels back as capture events, streaming and resynchronising
//! after damage; and the decoded channels as written.

use super::MAGIC;
use crate::model::{
    Chunk, Direction, Event, McapProblem, ReadDiag, ReadProblem, Reader, StreamInfo,
};
use ::mcap::records::{op, MessageHeader};
use ::mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use ::mcap::McapError;
use std::collections::{HashMap, HashSet, VecDeque};
use std::io::{self, Read};

/// A message of a decoded channel: the JSON line of one record.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DecodedMsg {
    /// Its channel's topic (`/apt/HW_GET_INFO`, `/ell/garbage`, `/aptscope/detect` …).
    pub topic: String,
    /// Its `log_time` (ns).
    pub log_time: u64,
    /// Its `sequence` (the record number, for frames and garbage).
    pub sequence: u32,
    /// The record's JSON line, as `decode --json` writes it.
    pub json: String,
}

/// The messages of the decoded (json-encoded) channels of an MCAP file, in file order (the
/// order they were written in: for our files, the order `decode --json` writes the records).
/// Reads the whole file in memory with the `mcap` crate; for tests and tools, not for damaged
/// or huge files ([`McapReader`] is for those).
pub fn read_decoded(bytes: &[u8]) -> io::Result<Vec<DecodedMsg>> {
    let mut out = vec![];
    for m in ::mcap::MessageStream::new(bytes).map_err(super::mcap_err)? {
        let m = m.map_err(super::mcap_err)?;
        if m.channel.message_encoding != "json" {
            continue;
        }
        let json = String::from_utf8(m.data.into_owned())
            .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e))?;
        out.push(DecodedMsg {
            topic: m.channel.topic.clone(),
            log_time: m.log_time,
            sequence: m.sequence,
            json,
        });
    }
    Ok(out)
}

/// Size of the file read buffer.
const BUF: usize = 64 * 1024;
/// Largest record (outside chunks: anything but chunks and attachments; inside chunks: any)
/// read into memory. Larger ones are skipped with a diagnostic.
const MAX_RECORD: usize = 64 * 1024 * 1024;
/// Largest schema/channel/metadata record considered while resynchronising.
const MAX_PEEK_RECORD: usize = 16 * 1024;

/// A buffered byte source that knows its file offset.
struct Src {
    r: Box<dyn Read>,
    buf: Box<[u8]>,
    pos: usize,
    len: usize,
    off: u64,
    eof: bool,
    /// CRC-32 of the bytes consumed so far, while the data section lasts.
    crc: Option<u32>,
}

impl Src {
    fn new(r: Box<dyn Read>) -> Self {
        Src {
            r,
            buf: vec![0; BUF].into_boxed_slice(),
            pos: 0,
            len: 0,
            off: 0,
            eof: false,
            crc: Some(!0),
        }
    }

    fn avail(&self) -> &[u8] {
        &self.buf[self.pos..self.len]
    }

    /// Make at least `n` (at most [`BUF`]) bytes available unless the file ends first; returns
    /// how many are.
    fn fill(&mut self, n: usize) -> io::Result<usize> {
        let n = n.min(BUF);
        if self.len - self.pos >= n || self.eof {
            return Ok(self.len - self.pos);
        }
        if self.pos > 0 {
            self.buf.copy_within(self.pos..self.len, 0);
            self.len -= self.pos;
            self.pos = 0;
        }
        while self.len < n {
            match self.r.read(&mut self.buf[self.len..]) {
                Ok(0) => {
                    self.eof = true;
                    break;
                }
                Ok(k) => self.len += k,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e),
            }
        }
        Ok(self.len - self.pos)
    }

    fn consume(&mut self, n: usize) {
        let n = n.min(self.len - self.pos);
        if let Some(c) = &mut self.crc {
            *c = crc32_update(*c, &self.buf[self.pos..self.pos + n]);
        }
        self.pos += n;
        self.off += n as u64;
    }

    /// The CRC-32 of everything consumed so far; stops hashing.
    fn take_crc(&mut self) -> Option<u32> {
        self.crc.take().map(|c| !c)
    }

    /// Read up to `dst.len()` bytes; 0 at the end of the file.
    fn read_some(&mut self, dst: &mut [u8]) -> io::Result<usize> {
        if dst.is_empty() {
            return Ok(0);
        }
        if self.pos == self.len {
            if self.eof {
                return Ok(0);
            }
            if dst.len() >= BUF {
                loop {
                    match self.r.read(dst) {
                        Ok(0) => {
                            self.eof = true;
                            return Ok(0);
                        }
                        Ok(k) => {
                            if let Some(c) = &mut self.crc {
                                *c = crc32_update(*c, &dst[..k]);
                            }
                            self.off += k as u64;
                            return Ok(k);
                        }
                        Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                        Err(e) => return Err(e),
                    }
                }
            }
            self.fill(1)?;
        }
        let k = dst.len().min(self.len - self.pos);
        dst[..k].copy_from_slice(&self.buf[self.pos..self.pos + k]);
        self.consume(k);
        Ok(k)
    }

    /// Fill `dst` completely unless the file ends; returns how many bytes were read.
    fn read_full(&mut self, dst: &mut [u8]) -> io::Result<usize> {
        let mut got = 0;
        while got < dst.len() {
            let k = self.read_some(&mut dst[got..])?;
            if k == 0 {
                break;
            }
            got += k;
        }
        Ok(got)
    }

    /// Skip `n` bytes; returns how many were skipped (fewer at the end of the file).
    fn skip(&mut self, n: u64) -> io::Result<u64> {
        let mut done = 0;
        while done < n {
            let a = self.fill(1)?;
            if a == 0 {
                break;
            }
            let k = (a as u64).min(n - done) as usize;
            self.consume(k);
            done += k as u64;
        }
        Ok(done)
    }
}

/// CRC-32 (IEEE, as MCAP uses), one table lookup per byte.
const CRC_TABLE: [u32; 256] = {
    let mut t = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
            k += 1;
        }
        t[i] = c;
        i += 1;
    }
    t
};

/// Continue a CRC-32 (pre- and post-inverted by the caller).
pub(super) fn crc32_update(mut c: u32, b: &[u8]) -> u32 {
    for &x in b {
        c = CRC_TABLE[((c ^ x as u32) & 0xFF) as usize] ^ (c >> 8);
    }
    c
}

fn u16le(b: &[u8]) -> u16 {
    u16::from_le_bytes([b[0], b[1]])
}
pub(super) fn u32le(b: &[u8]) -> u32 {
    u32::from_le_bytes([b[0], b[1], b[2], b[3]])
}
pub(super) fn u64le(b: &[u8]) -> u64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[..8]);
    u64::from_le_bytes(a)
}

fn op_name(o: u8) -> &'static str {
    match o {
        op::HEADER => "header",
        op::FOOTER => "footer",
        op::SCHEMA => "schema",
        op::CHANNEL => "channel",
        op::MESSAGE => "message",
        op::CHUNK => "chunk",
        op::MESSAGE_INDEX => "message index",
        op::CHUNK_INDEX => "chunk index",
        op::ATTACHMENT => "attachment",
        op::ATTACHMENT_INDEX => "attachment index",
        op::STATISTICS => "statistics",
        op::METADATA => "metadata",
        op::METADATA_INDEX => "metadata index",
        op::SUMMARY_OFFSET => "summary offset",
        op::DATA_END => "data end",
        0x80..=0xFF => "private",
        _ => "reserved",
    }
}

/// The fixed part of a chunk record (after opcode and length) is 40 bytes plus the compression
/// name.
const CHUNK_FIXED: usize = 40;

/// A chunk header read from `body`: (header length, compressed size, compression name).
fn chunk_header(body: &[u8]) -> Option<(usize, u64, &[u8])> {
    if body.len() < CHUNK_FIXED {
        return None;
    }
    let clen = u32le(&body[28..32]) as usize;
    if clen > 255 || body.len() < CHUNK_FIXED + clen {
        return None;
    }
    let comp = &body[32..32 + clen];
    let csize = u64le(&body[32 + clen..40 + clen]);
    Some((CHUNK_FIXED + clen, csize, comp))
}

/// A cursor over a record body that checks MCAP length prefixes against what is there.
struct Lens<'a> {
    b: &'a [u8],
    i: usize,
}

impl Lens<'_> {
    fn skip(&mut self, n: usize) -> Option<()> {
        self.i = self.i.checked_add(n).filter(|&e| e <= self.b.len())?;
        Some(())
    }
    fn u32(&mut self) -> Option<usize> {
        let v = u32le(self.b.get(self.i..self.i + 4)?) as usize;
        self.i += 4;
        Some(v)
    }
    fn string(&mut self) -> Option<()> {
        let n = self.u32()?;
        self.skip(n)
    }
    fn map(&mut self) -> Option<()> {
        let n = self.u32()?;
        let end = self.i.checked_add(n).filter(|&e| e <= self.b.len())?;
        while self.i < end {
            self.string()?;
            self.string()?;
        }
        (self.i == end).then_some(())
    }
}

/// Whether every length inside a record body fits in it, so parsing it cannot ask for more
/// memory than the body holds (the parser reserves a string's declared length up front).
pub(super) fn lengths_ok(opcode: u8, body: &[u8]) -> bool {
    let mut c = Lens { b: body, i: 0 };
    let ok = match opcode {
        op::HEADER => c.string().and_then(|_| c.string()),
        op::CHANNEL => c
            .skip(4)
            .and_then(|_| c.string())
            .and_then(|_| c.string())
            .and_then(|_| c.map()),
        op::METADATA => c.string().and_then(|_| c.map()),
        op::SCHEMA => c
            .skip(2)
            .and_then(|_| c.string())
            .and_then(|_| c.string())
            .and_then(|_| c.string()),
        op::MESSAGE => c.skip(22),
        _ => None,
    };
    ok.is_some()
}

/// [`mcap::parse_record`] for the records we read, after [`lengths_ok`].
fn parse(opcode: u8, body: &[u8]) -> Result<mcap::records::Record<'_>, String> {
    if !lengths_ok(opcode, body) {
        return Err("a length inside the record runs past its end".into());
    }
    mcap::parse_record(opcode, body).map_err(|e| e.to_string())
}

/// Encodings whose messages are structured data, not serial bytes.
const STRUCTURED: &[&str] = &[
    "json",
    "protobuf",
    "ros1",
    "ros2",
    "cdr",
    "flatbuffer",
    "cbor",
    "msgpack",
];

#[derive(Debug, Clone, Copy)]
enum Chan {
    Skip,
    Raw {
        stream: u32,
        dir: Direction,
        timed: bool,
    },
}

#[derive(Debug, Clone, PartialEq, Eq, Hash)]
enum StreamKey {
    Ours(u32),
    Foreign(String),
}

/// The direction a foreign topic names in its last path segment (`/port/tx`, `/serial_rx`),
/// and the topic without it.
fn topic_dir(topic: &str) -> (String, Direction) {
    let (base, last) = match topic.rfind('/') {
        Some(i) => (&topic[..i], &topic[i + 1..]),
        None => ("", topic),
    };
    if let Some(d) = Direction::parse(&last.to_ascii_lowercase()) {
        if !base.is_empty() {
            return (base.to_string(), d);
        }
    }
    if let Some(i) = last.rfind(['_', '-', '.']) {
        if let Some(d) = Direction::parse(&last[i + 1..].to_ascii_lowercase()) {
            return (format!("{base}/{}", &last[..i]), d);
        }
    }
    (topic.to_string(), Direction::Unknown)
}

struct InChunk {
    /// File offset of the chunk record.
    at: u64,
    lr: LinearReader,
    /// Compressed bytes still to feed.
    to_feed: u64,
    /// Bytes after the compressed records, up to the record's end.
    padding: u64,
    /// The file ended before the chunk did.
    cut: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum St {
    Magic,
    Records,
    EndMagic,
    Done,
}

#[derive(Debug, Clone, Copy)]
struct Ready {
    ts: Option<u64>,
    dir: Direction,
    stream: u32,
}

/// A streaming MCAP reader (see the module documentation).
pub struct McapReader {
    src: Src,
    file_len: Option<u64>,
    st: St,
    queue: VecDeque<Event<'static>>,
    ready: Option<Ready>,
    data: Vec<u8>,
    body: Vec<u8>,
    chunk: Option<InChunk>,
    channels: HashMap<u16, Chan>,
    bad_channels: HashSet<u16>,
    keys: HashMap<StreamKey, u32>,
    infos: HashMap<u32, StreamInfo>,
    announced: HashSet<u32>,
    used: HashSet<u32>,
    seen_footer: bool,
    seen_data_end: bool,
    library: Option<String>,
    /// Private opcodes reported.
    private: HashSet<u8>,
    /// The data section's CRC, once its end was reached.
    data_crc: Option<u32>,
    /// A problem was reported (the data CRC then adds nothing).
    damaged: bool,
}

impl McapReader {
    /// Read MCAP from `r` (a file, standard input, any stream).
    pub fn new<R: Read + 'static>(r: R) -> Self {
        McapReader {
            src: Src::new(Box::new(r)),
            file_len: None,
            st: St::Magic,
            queue: VecDeque::new(),
            ready: None,
            data: Vec::new(),
            body: Vec::new(),
            chunk: None,
            channels: HashMap::new(),
            bad_channels: HashSet::new(),
            keys: HashMap::new(),
            infos: HashMap::new(),
            announced: HashSet::new(),
            used: HashSet::new(),
            seen_footer: false,
            seen_data_end: false,
            library: None,
            private: HashSet::new(),
            data_crc: None,
            damaged: false,
        }
    }

    /// Open a file (its size lets lengths that run past the end be caught before reading).
    pub fn open(path: impl AsRef<std::path::Path>) -> io::Result<Self> {
        let f = std::fs::File::open(path)?;
        let len = f.metadata().ok().map(|m| m.len());
        let mut r = Self::new(f);
        r.file_len = len;
        Ok(r)
    }

    /// Tell the reader the file's total length, when known.
    pub fn with_file_len(mut self, len: u64) -> Self {
        self.file_len = Some(len);
        self
    }

    fn diag(&mut self, offset: u64, problem: McapProblem) {
        self.problem(offset, ReadProblem::Mcap(problem));
    }

    fn problem(&mut self, offset: u64, problem: ReadProblem) {
        self.damaged = true;
        self.queue
            .push_back(Event::Diag(ReadDiag::new(offset, problem)));
    }

    fn io_fail(&mut self, e: io::Error) {
        let at = self.src.off;
        self.problem(at, ReadProblem::io(&e));
        self.st = St::Done;
        self.chunk = None;
    }

    /// One step of reading; may queue events or make a chunk ready.
    fn step(&mut self) {
        let r = match self.st {
            St::Magic => self.read_magic(),
            St::Records if self.chunk.is_some() => self.step_chunk(),
            St::Records => self.read_record(),
            St::EndMagic => self.read_end_magic(),
            St::Done => Ok(()),
        };
        if let Err(e) = r {
            self.io_fail(e);
        }
    }

    fn read_magic(&mut self) -> io::Result<()> {
        let n = self.src.fill(MAGIC.len())?;
        if n == 0 {
            self.diag(0, McapProblem::BadMagic { found: vec![] });
            self.st = St::Done;
            return Ok(());
        }
        if self.src.avail().starts_with(MAGIC) {
            self.src.consume(MAGIC.len());
            self.st = St::Records;
            return Ok(());
        }
        let found = self.src.avail().iter().take(8).copied().collect();
        self.diag(0, McapProblem::BadMagic { found });
        self.st = St::Records;
        self.resync(false)
    }

    fn read_end_magic(&mut self) -> io::Result<()> {
        let at = self.src.off;
        let n = self.src.fill(MAGIC.len())?;
        if n >= MAGIC.len() && self.src.avail().starts_with(MAGIC) {
            self.src.consume(MAGIC.len());
            let more = self.src.fill(1)?;
            if more > 0 {
                let at = self.src.off;
                self.diag(at, McapProblem::TrailingBytes);
            }
        } else {
            self.diag(at, McapProblem::BadEndMagic { left: n });
        }
        self.st = St::Done;
        Ok(())
    }

    /// The file ended at a record boundary.
    fn at_eof(&mut self) {
        let at = self.src.off;
        if !self.seen_footer {
            let data_end = self.seen_data_end;
            self.diag(at, McapProblem::MissingFooter { data_end });
        }
        self.st = St::Done;
    }

    fn read_record(&mut self) -> io::Result<()> {
        let at = self.src.off;
        let n = self.src.fill(9)?;
        if n == 0 {
            self.at_eof();
            return Ok(());
        }
        if n < 9 {
            self.diag(at, McapProblem::TruncatedHeader { found: n });
            self.st = St::Done;
            return Ok(());
        }
        let b = self.src.avail();
        let opcode = b[0];
        let len = u64le(&b[1..9]);
        let name = op_name(opcode);
        if opcode == 0 || (0x10..0x80).contains(&opcode) {
            self.diag(at, McapProblem::BadOpcode { opcode });
            return self.resync(true);
        }
        let end = at.saturating_add(9).saturating_add(len);
        if let Some(fl) = self.file_len.filter(|&fl| end > fl) {
            let left = fl.saturating_sub(at + 9);
            self.diag(
                at,
                McapProblem::PastEnd {
                    record: name,
                    len,
                    left,
                },
            );
            return self.resync(true);
        }
        if opcode == op::DATA_END {
            // The data section's CRC covers every byte before this record.
            self.data_crc = self.src.take_crc();
        }
        let big = len > MAX_RECORD as u64;
        match opcode {
            op::CHUNK => self.start_chunk(at, len),
            op::ATTACHMENT => {
                self.src.consume(9);
                self.skip_body(at, name, len)
            }
            0x80..=0xFF => {
                // Application-defined; legal, but a damaged opcode looks like one too.
                if self.private.insert(opcode) {
                    self.diag(at, McapProblem::PrivateRecord { opcode, len });
                }
                self.src.consume(9);
                self.skip_body(at, name, len)
            }
            _ if big => {
                let limit = MAX_RECORD;
                self.diag(
                    at,
                    McapProblem::TooLong {
                        record: name,
                        len,
                        limit,
                    },
                );
                self.resync(true)
            }
            op::MESSAGE_INDEX
            | op::CHUNK_INDEX
            | op::ATTACHMENT_INDEX
            | op::STATISTICS
            | op::METADATA_INDEX
            | op::SUMMARY_OFFSET
            | op::SCHEMA => {
                self.src.consume(9);
                self.skip_body(at, name, len)
            }
            _ => {
                self.src.consume(9);
                let mut body = std::mem::take(&mut self.body);
                body.resize(len as usize, 0);
                let got = self.src.read_full(&mut body)?;
                if got < body.len() {
                    self.body = body;
                    self.truncated(at, name, len, got as u64);
                    return Ok(());
                }
                self.record(at, opcode, &body);
                self.body = body;
                Ok(())
            }
        }
    }

    fn truncated(&mut self, at: u64, name: &'static str, len: u64, got: u64) {
        let record = name;
        self.diag(at, McapProblem::TruncatedBody { record, len, got });
        self.st = St::Done;
    }

    fn unparsable(&mut self, at: u64, opcode: u8, in_chunk: bool, error: String) {
        let problem = McapProblem::Unparsable {
            record: op_name(opcode),
            in_chunk,
            error,
        };
        self.diag(at, problem);
    }

    fn skip_body(&mut self, at: u64, name: &'static str, len: u64) -> io::Result<()> {
        let got = self.src.skip(len)?;
        if got < len {
            self.truncated(at, name, len, got);
        }
        Ok(())
    }

    /// A whole record outside chunks.
    fn record(&mut self, at: u64, opcode: u8, body: &[u8]) {
        match opcode {
            op::FOOTER => {
                self.seen_footer = true;
                self.st = St::EndMagic;
            }
            op::DATA_END => {
                self.seen_data_end = true;
                let saved = body.get(..4).map_or(0, u32le);
                if let Some(calc) = self.data_crc.filter(|&c| saved != 0 && c != saved) {
                    if !self.damaged {
                        self.diag(
                            at,
                            McapProblem::BadDataCrc {
                                calculated: calc,
                                saved,
                                before: at,
                            },
                        );
                    }
                }
            }
            op::MESSAGE | op::CHANNEL | op::METADATA | op::HEADER => match parse(opcode, body) {
                Ok(r) => self.parsed(at, r),
                Err(e) => self.unparsable(at, opcode, false, e),
            },
            _ => {}
        }
    }

    /// A parsed record (outside or inside a chunk; `at` = the record's or chunk's offset).
    fn parsed(&mut self, at: u64, r: mcap::records::Record<'_>) {
        use mcap::records::Record;
        match r {
            Record::Header(h) if !h.library.is_empty() => {
                self.library = Some(h.library);
            }
            Record::Channel(c) => self.channel(c),
            Record::Metadata(m) if m.name == "aptscope.stream" => {
                let Some(id) = m.metadata.get("id").and_then(|s| s.parse::<u32>().ok()) else {
                    return;
                };
                let sid = self.stream_id(StreamKey::Ours(id));
                let info = StreamInfo {
                    id: sid,
                    name: m.metadata.get("name").cloned().unwrap_or_default(),
                    settings: m.metadata.get("settings").cloned(),
                };
                self.infos.insert(sid, info);
                self.announce(sid);
            }
            Record::Message { header, data } => self.message(at, header, &data),
            _ => {}
        }
    }

    fn stream_id(&mut self, key: StreamKey) -> u32 {
        if let Some(&id) = self.keys.get(&key) {
            return id;
        }
        let want = match key {
            StreamKey::Ours(id) => id,
            StreamKey::Foreign(_) => 0,
        };
        let mut id = want;
        while self.used.contains(&id) {
            id = id.wrapping_add(1);
        }
        self.used.insert(id);
        self.keys.insert(key, id);
        id
    }

    fn announce(&mut self, id: u32) {
        if self.announced.insert(id) {
            let info = self.infos.get(&id).cloned().unwrap_or(StreamInfo {
                id,
                name: String::new(),
                settings: None,
            });
            self.queue.push_back(Event::Stream(info));
        }
    }

    fn channel(&mut self, c: mcap::records::Channel) {
        let enc = c.message_encoding.to_ascii_lowercase();
        let decoded =
            (c.topic.starts_with("/apt/") || c.topic.starts_with("/ell/")) && enc == "json";
        if decoded || STRUCTURED.contains(&enc.as_str()) {
            self.channels.insert(c.id, Chan::Skip);
            return;
        }
        let md = &c.metadata;
        let ours = c
            .topic
            .starts_with("/serial/")
            .then(|| md.get("stream").and_then(|s| s.parse::<u32>().ok()))
            .flatten();
        let (key, dir, timed, name, settings) = match ours {
            Some(id) => {
                let dir = md
                    .get("direction")
                    .and_then(|d| Direction::parse(d))
                    .unwrap_or_else(|| topic_dir(&c.topic).1);
                let timed = md.get("time").map(String::as_str) != Some("missing");
                (
                    StreamKey::Ours(id),
                    dir,
                    timed,
                    md.get("name").cloned().unwrap_or_default(),
                    md.get("settings").cloned(),
                )
            }
            None => {
                let (base, mut dir) = topic_dir(&c.topic);
                if let Some(d) = md.get("direction").and_then(|d| Direction::parse(d)) {
                    dir = d;
                }
                (StreamKey::Foreign(base.clone()), dir, true, base, None)
            }
        };
        let stream = self.stream_id(key);
        self.infos.entry(stream).or_insert(StreamInfo {
            id: stream,
            name,
            settings,
        });
        self.channels.insert(c.id, Chan::Raw { stream, dir, timed });
    }

    fn message(&mut self, at: u64, h: MessageHeader, data: &[u8]) {
        match self.channels.get(&h.channel_id).copied() {
            None => {
                if self.bad_channels.insert(h.channel_id) {
                    let channel = h.channel_id;
                    self.diag(at, McapProblem::UnknownChannel { channel });
                }
            }
            Some(Chan::Skip) => {}
            Some(Chan::Raw { stream, dir, timed }) => {
                self.announce(stream);
                self.data.clear();
                self.data.extend_from_slice(data);
                self.ready = Some(Ready {
                    ts: timed.then_some(h.log_time),
                    dir,
                    stream,
                });
            }
        }
    }

    fn start_chunk(&mut self, at: u64, len: u64) -> io::Result<()> {
        // The fixed header and the compression name sit in the read buffer.
        let n = self.src.fill(9 + CHUNK_FIXED)?;
        let clen = if n >= 9 + CHUNK_FIXED {
            u32le(&self.src.avail()[9 + 28..9 + 32]) as usize
        } else {
            0
        };
        let want = 9 + CHUNK_FIXED + clen.min(255);
        let n = self.src.fill(want)?;
        if n < want && (want as u64) <= 9 + len {
            let got = n.saturating_sub(9) as u64;
            self.truncated(at, "chunk", len, got);
            return Ok(());
        }
        let hdr = chunk_header(&self.src.avail()[9..n]);
        let Some((hlen, csize, _)) = hdr.filter(|h| h.0 as u64 <= len && h.1 <= len - h.0 as u64)
        else {
            self.diag(at, McapProblem::BadChunkHeader);
            return self.resync(true);
        };
        let mut lr = LinearReader::new_with_options(
            LinearReaderOptions::default()
                .with_skip_start_magic(true)
                .with_skip_end_magic(true)
                .with_validate_chunk_crcs(true)
                .with_record_length_limit(MAX_RECORD),
        );
        // The reader sees a chunk record without the padding after its records, so records
        // that overrun the compressed data cannot reach into it.
        let buf = lr.insert(9 + hlen);
        buf[0] = op::CHUNK;
        buf[1..9].copy_from_slice(&(hlen as u64 + csize).to_le_bytes());
        buf[9..].copy_from_slice(&self.src.avail()[9..9 + hlen]);
        lr.notify_read(9 + hlen);
        self.src.consume(9 + hlen);
        self.chunk = Some(InChunk {
            at,
            lr,
            to_feed: csize,
            padding: len - hlen as u64 - csize,
            cut: false,
        });
        Ok(())
    }

    fn step_chunk(&mut self) -> io::Result<()> {
        let Some(mut ch) = self.chunk.take() else {
            return Ok(());
        };
        let at = ch.at;
        match ch.lr.next_event() {
            None => {
                // The chunk is done (CRC checked): skip what follows its records.
                let got = self.src.skip(ch.padding)?;
                if got < ch.padding {
                    self.truncated(at, "chunk", ch.padding, got);
                }
                return Ok(());
            }
            Some(Ok(LinearReadEvent::ReadRequest(need))) => {
                if ch.to_feed == 0 || ch.cut {
                    ch.lr.notify_read(0);
                } else {
                    let want = (need.max(1) as u64).min(ch.to_feed).min(BUF as u64) as usize;
                    let buf = ch.lr.insert(want);
                    let got = self.src.read_some(buf)?;
                    if got == 0 {
                        ch.cut = true;
                    }
                    ch.lr.notify_read(got);
                    ch.to_feed -= got as u64;
                }
            }
            Some(Ok(LinearReadEvent::Record { data, opcode })) => match opcode {
                op::MESSAGE | op::CHANNEL => match parse(opcode, data) {
                    Ok(r) => self.parsed(at, r),
                    Err(e) => self.unparsable(at, opcode, true, e),
                },
                _ => {}
            },
            Some(Err(e)) => {
                if ch.cut {
                    let end = self.src.off;
                    self.diag(at, McapProblem::CutChunk { end });
                    self.st = St::Done;
                    return Ok(());
                }
                let problem = match e {
                    McapError::BadChunkCrc { saved, calculated } => {
                        McapProblem::BadChunkCrc { calculated, saved }
                    }
                    McapError::UnsupportedCompression(compression) => {
                        McapProblem::UnsupportedCompression { compression }
                    }
                    e => McapProblem::BadChunk {
                        error: e.to_string(),
                    },
                };
                self.diag(at, problem);
                let rest = ch.to_feed + ch.padding;
                let got = self.src.skip(rest)?;
                if got < rest {
                    self.truncated(at, "chunk", rest, got);
                }
                return Ok(());
            }
        }
        self.chunk = Some(ch);
        Ok(())
    }

    /// Whether a record plausibly starts at the head of `b` (file offset `at`).
    fn plausible(&self, b: &[u8], at: u64) -> bool {
        if b.len() < 9 {
            return false;
        }
        let opcode = b[0];
        let len = u64le(&b[1..9]);
        if let Some(fl) = self.file_len {
            if at.saturating_add(9).saturating_add(len) > fl {
                return false;
            }
        }
        let body = &b[9..];
        match opcode {
            op::CHUNK => match chunk_header(body) {
                Some((hlen, csize, comp)) => {
                    let usize_ = u64le(&body[16..24]);
                    let start = u64le(&body[0..8]);
                    let end = u64le(&body[8..16]);
                    start <= end
                        && matches!(comp, b"" | b"lz4" | b"zstd")
                        && (!comp.is_empty() || usize_ == csize)
                        && (hlen as u64).checked_add(csize) == Some(len)
                }
                None => false,
            },
            op::MESSAGE => {
                (22..=MAX_RECORD as u64).contains(&len)
                    && body.len() >= 2
                    && self.channels.contains_key(&u16le(body))
            }
            op::MESSAGE_INDEX => {
                len >= 6 && body.len() >= 6 && self.channels.contains_key(&u16le(body)) && {
                    let r = u32le(&body[2..6]) as u64;
                    r + 6 == len && r.is_multiple_of(16)
                }
            }
            op::DATA_END => len == 4,
            op::FOOTER => len == 20,
            op::CHANNEL | op::SCHEMA | op::METADATA | op::HEADER => {
                (len as usize) <= body.len() && parse(opcode, &body[..len as usize]).is_ok()
            }
            _ => false,
        }
    }

    /// Look for the next plausible record from the current offset (`skip_first`: not at the
    /// current offset itself). Reports the bytes skipped.
    fn resync(&mut self, skip_first: bool) -> io::Result<()> {
        let start = self.src.off;
        if skip_first {
            self.src.consume(1);
        }
        loop {
            let n = self.src.fill(64)?;
            if n == 0 {
                let bytes = self.src.off - start;
                self.diag(start, McapProblem::Skipped { bytes, next: None });
                self.at_eof();
                return Ok(());
            }
            let b = self.src.avail();
            let opcode = b[0];
            let interesting = matches!(
                opcode,
                op::CHUNK
                    | op::MESSAGE
                    | op::MESSAGE_INDEX
                    | op::DATA_END
                    | op::FOOTER
                    | op::CHANNEL
                    | op::SCHEMA
                    | op::METADATA
                    | op::HEADER
            );
            if interesting && n >= 9 {
                let len = u64le(&b[1..9]);
                let want = match opcode {
                    op::CHUNK => 9 + CHUNK_FIXED + 8,
                    op::CHANNEL | op::SCHEMA | op::METADATA | op::HEADER
                        if len <= MAX_PEEK_RECORD as u64 =>
                    {
                        9 + len as usize
                    }
                    _ => 9,
                };
                let n = self.src.fill(want)?;
                let at = self.src.off;
                if self.plausible(&self.src.avail()[..n], at) {
                    if at > start {
                        let (bytes, next) = (at - start, Some(at));
                        self.diag(start, McapProblem::Skipped { bytes, next });
                    }
                    return Ok(());
                }
            }
            self.src.consume(1);
        }
    }
}

impl Reader for McapReader {
    fn next_event(&mut self) -> Option<Event<'_>> {
        loop {
            if let Some(e) = self.queue.pop_front() {
                return Some(e);
            }
            if let Some(r) = self.ready.take() {
                return Some(Event::Chunk(Chunk {
                    ts_ns: r.ts,
                    dir: r.dir,
                    stream: r.stream,
                    bytes: &self.data,
                }));
            }
            if self.st == St::Done {
                return None;
            }
            self.step();
        }
    }

    fn format(&self) -> String {
        match &self.library {
            Some(l) => format!("mcap ({l})"),
            None => "mcap".to_string(),
        }
    }
}
