//! Opening any capture: format detection from content, readers and writers by format.

use crate::follow::{Follow, FollowStop, HEAD_WAIT};
use crate::model::{Chunk, Direction, Event, ReadDiag, ReadProblem, Reader, Writer};
use crate::raw::{ByteSource, InputFormat};
use crate::{mcap, pcap, textlog};
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use std::fs::File;
use std::io::{self, BufReader, Cursor, Read};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

/// A capture file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// Legacy pcap (serial or USB link types).
    Pcap,
    /// pcapng (serial or USB link types).
    PcapNg,
    /// MCAP.
    Mcap,
    /// A text log of a serial tool or a hex dump with columns.
    Text(textlog::TextFormat),
    /// Plain hex text, any whitespace.
    Hex,
    /// Raw bytes.
    Raw,
}

impl Format {
    /// Names accepted by `--format`.
    pub const NAMES: &'static [&'static str] = &[
        "pcap",
        "pcapng",
        "mcap",
        "socat",
        "jpnevulator",
        "interceptty",
        "xxd",
        "hexdump",
        "hexcols",
        "hex",
        "raw",
    ];

    /// Parse a `--format` name.
    pub fn parse(s: &str) -> Option<Format> {
        Some(match s {
            "pcap" => Format::Pcap,
            "pcapng" => Format::PcapNg,
            "mcap" => Format::Mcap,
            "hex" => Format::Hex,
            "raw" | "bin" => Format::Raw,
            other => Format::Text(textlog::TextFormat::parse(other)?),
        })
    }

    /// The name.
    pub fn name(self) -> &'static str {
        match self {
            Format::Pcap => "pcap",
            Format::PcapNg => "pcapng",
            Format::Mcap => "mcap",
            Format::Text(t) => t.name(),
            Format::Hex => "hex",
            Format::Raw => "raw",
        }
    }

    /// The format a file name asks for when writing (`.pcapng`, `.pcap`, `.mcap`, `.hex`,
    /// `.bin`/`.raw`).
    pub fn from_extension(path: &str) -> Option<Format> {
        let ext = path.rsplit('.').next()?.to_ascii_lowercase();
        Some(match ext.as_str() {
            "pcapng" => Format::PcapNg,
            "pcap" => Format::Pcap,
            "mcap" => Format::Mcap,
            "hex" => Format::Hex,
            "bin" | "raw" => Format::Raw,
            _ => return None,
        })
    }
}

impl Format {
    /// The format to write `path` in: `forced` (a format flag) when given, else the one its
    /// extension names, pcapng when it has none. An extension that names no format written
    /// (`.txt`) is refused rather than filled with another format.
    pub fn for_writing(path: &str, forced: Option<Format>) -> Result<Format, CreateError> {
        if let Some(f) = forced {
            return Ok(f);
        }
        if let Some(f) = Format::from_extension(path) {
            return Ok(f);
        }
        match std::path::Path::new(path).extension() {
            None => Ok(Format::PcapNg),
            Some(ext) => Err(CreateError::Extension {
                path: path.to_string(),
                ext: ext.to_string_lossy().into_owned(),
            }),
        }
    }
}

/// Why a capture could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// The file could not be opened or read.
    #[error("{path}: {source}")]
    File {
        /// The path given.
        path: String,
        /// What the system said.
        source: io::Error,
    },
    /// The path is a directory.
    #[error("{path} is a directory: give a capture file in it")]
    Directory {
        /// The path given.
        path: String,
    },
    /// `--format` names a container the content is not.
    #[error(
        "--format {forced} but the content is {found}: leave --format out to detect it, or \
         give --format {found}"
    )]
    ContainerMismatch {
        /// The format asked for.
        forced: &'static str,
        /// The format the first bytes show.
        found: &'static str,
    },
    /// `--usb-device` given for an input that is not a USB capture.
    #[error(
        "--usb-device {bus}:{addr} selects a device of a USB capture (usbmon or USBPcap in pcap \
         or pcapng), and this input is {format}"
    )]
    NotUsb {
        /// Bus asked for.
        bus: u16,
        /// Device address asked for.
        addr: u8,
        /// The input's format.
        format: &'static str,
    },
    /// Reading the first bytes (to detect the format) failed.
    #[error("{0}")]
    Read(#[from] io::Error),
}

impl From<OpenError> for io::Error {
    fn from(e: OpenError) -> io::Error {
        let kind = match &e {
            OpenError::File { source, .. } | OpenError::Read(source) => source.kind(),
            _ => io::ErrorKind::InvalidInput,
        };
        io::Error::new(kind, e)
    }
}

/// Why a capture could not be created.
#[derive(Debug, thiserror::Error)]
pub enum CreateError {
    /// The file exists and overwriting was not asked for.
    #[error("{path} exists (use --force to overwrite)")]
    Exists {
        /// The path given.
        path: String,
    },
    /// The file could not be created.
    #[error("{path}: {source}")]
    File {
        /// The path given.
        path: String,
        /// What the system said.
        source: io::Error,
    },
    /// The extension names no format that is written.
    #[error(
        "{path}: .{ext} names no capture format written (.pcapng, .pcap, .mcap, .hex, .bin): \
         rename it, or give the format (--to / --write-format)"
    )]
    Extension {
        /// The path given.
        path: String,
        /// Its extension.
        ext: String,
    },
    /// MCAP asked for on standard output.
    #[error("MCAP is written to a file (its index needs seeking), not to standard output")]
    McapToStdout,
    /// A format that is read but not written.
    #[error("aptscope reads {0} logs but does not write them")]
    ReadOnly(&'static str),
    /// Writing the file's header failed.
    #[error("{0}")]
    Write(#[from] io::Error),
}

impl From<CreateError> for io::Error {
    fn from(e: CreateError) -> io::Error {
        let kind = match &e {
            CreateError::Exists { .. } => io::ErrorKind::AlreadyExists,
            CreateError::File { source, .. } | CreateError::Write(source) => source.kind(),
            CreateError::Extension { .. } => io::ErrorKind::InvalidInput,
            CreateError::McapToStdout | CreateError::ReadOnly(_) => io::ErrorKind::Unsupported,
        };
        io::Error::new(kind, e)
    }
}

/// How much of a file [`sniff`] looks at.
pub const SNIFF_LEN: usize = 8192;

/// Guess the format from the first bytes of a file.
pub fn sniff(head: &[u8]) -> Format {
    if pcap::sniff_pcapng(head) {
        Format::PcapNg
    } else if pcap::sniff_pcap(head) {
        Format::Pcap
    } else if mcap::sniff(head) {
        Format::Mcap
    } else if let Some(t) = textlog::sniff(head) {
        Format::Text(t)
    } else if looks_like_plain_hex(head) {
        Format::Hex
    } else {
        Format::Raw
    }
}

/// Plain hex text: only hex digit pairs and whitespace/commas, and at least a few bytes' worth.
/// (An Elliptec stream is ASCII too, but has command letters beyond a-f.)
fn looks_like_plain_hex(head: &[u8]) -> bool {
    let digits = head.iter().filter(|c| c.is_ascii_hexdigit()).count();
    digits >= 6
        && head
            .iter()
            .all(|c| c.is_ascii_hexdigit() || c.is_ascii_whitespace() || *c == b',')
}

/// A raw or hex byte stream as a capture reader: one stream, unknown direction, no times.
pub struct ByteReader {
    src: ByteSource,
    offset: u64,
    hex: bool,
    pending: Vec<ReadDiag>,
    chunk: Vec<u8>,
    done: bool,
}

impl ByteReader {
    /// Wrap a reader of raw bytes or hex text.
    pub fn new(r: Box<dyn Read>, hex: bool) -> Self {
        ByteReader {
            src: ByteSource::from_reader(
                r,
                if hex {
                    InputFormat::Hex
                } else {
                    InputFormat::Raw
                },
            ),
            offset: 0,
            hex,
            pending: vec![],
            chunk: vec![],
            done: false,
        }
    }
}

impl Reader for ByteReader {
    fn next_event(&mut self) -> Option<Event<'_>> {
        if let Some(d) = self.pending.pop() {
            return Some(Event::Diag(d));
        }
        if self.done {
            return None;
        }
        match self.src.next_chunk() {
            Ok(Some((bytes, diags))) => {
                self.chunk.clear();
                self.chunk.extend_from_slice(bytes);
                for d in diags.iter().rev() {
                    self.pending
                        .push(ReadDiag::new(d.offset, ReadProblem::Input(d.kind)));
                }
                self.offset += bytes.len() as u64;
                if self.chunk.is_empty() {
                    return self.next_event();
                }
                Some(Event::Chunk(Chunk {
                    ts_ns: None,
                    dir: Direction::Unknown,
                    stream: 0,
                    bytes: &self.chunk,
                }))
            }
            Ok(None) => {
                self.done = true;
                None
            }
            Err(e) => {
                self.done = true;
                Some(Event::Diag(ReadDiag::new(self.offset, ReadProblem::io(&e))))
            }
        }
    }

    fn format(&self) -> String {
        if self.hex { "hex text" } else { "raw bytes" }.to_string()
    }
}

/// Options for opening a capture.
#[derive(Debug, Clone, Copy, Default)]
pub struct OpenOptions {
    /// Force a format instead of detecting it.
    pub format: Option<Format>,
    /// For USB captures: only this BUS:ADDR.
    pub usb_device: Option<(u16, u8)>,
    /// Follow a file another process is still writing (see [`crate::follow`]): at its end,
    /// wait for more until this says the writer stopped. Not for standard input.
    pub follow: Option<FollowStop>,
}

/// How far reading has got: bytes read from the file so far, and the file's size when known.
#[derive(Debug, Clone, Default)]
pub struct Progress {
    /// Bytes read so far.
    pub read: Arc<AtomicU64>,
    /// Size of the file (`None` for standard input).
    pub total: Option<u64>,
    /// The input is live: a pipe or terminal on standard input, or a followed file. Its
    /// records are worth showing as its bytes arrive.
    pub live: bool,
    /// The last read returned less than it asked for: the input has nothing more just now.
    pub drained: Arc<AtomicBool>,
}

impl Progress {
    /// Whether a live input had nothing more at its last read: output made since is worth
    /// flushing now (`dumpcap -w - | aptscope decode -` prints each record as its bytes
    /// arrive), not when a buffer fills. Always `false` for a file read whole.
    pub fn idle(&self) -> bool {
        self.live && self.drained.load(Ordering::Relaxed)
    }

    /// Fraction read, 0..=1, when the size is known.
    pub fn fraction(&self) -> Option<f64> {
        let t = self.total.filter(|t| *t > 0)?;
        Some((self.read.load(Ordering::Relaxed) as f64 / t as f64).min(1.0))
    }
}

/// A reader that counts what passes through it, and says when a read came back short.
struct Counted<R> {
    inner: R,
    read: Arc<AtomicU64>,
    drained: Arc<AtomicBool>,
}

impl<R: Read> Read for Counted<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.read.fetch_add(n as u64, Ordering::Relaxed);
        self.drained.store(n < buf.len(), Ordering::Relaxed);
        Ok(n)
    }
}

/// Whether standard input is a regular file (`decode - < capture.pcap`).
fn stdin_is_file() -> bool {
    use std::os::fd::AsFd;
    nix::sys::stat::fstat(io::stdin().as_fd())
        .is_ok_and(|st| (st.st_mode & nix::libc::S_IFMT) == nix::libc::S_IFREG)
}

/// Whether the first bytes name a container format (no more needed to detect it).
fn names_container(head: &[u8]) -> bool {
    matches!(sniff(head), Format::Pcap | Format::PcapNg | Format::Mcap)
}

/// The first bytes of standard input, for format detection, without waiting for more than a
/// live source has sent (`dumpcap -w - | aptscope decode -`): as soon as they name a container,
/// or [`SNIFF_LEN`] bytes are there, or the input ended, or nothing more came for
/// [`HEAD_WAIT`] after a short read (a quiet raw or text stream).
fn stdin_head(input: &mut dyn Read) -> io::Result<Vec<u8>> {
    use std::os::fd::AsFd;
    let mut head = vec![0u8; SNIFF_LEN];
    let mut len = 0;
    loop {
        let n = match input.read(&mut head[len..]) {
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        len += n;
        if n == 0 || len == SNIFF_LEN || names_container(&head[..len]) {
            break;
        }
        let stdin = io::stdin();
        let mut fds = [PollFd::new(stdin.as_fd(), PollFlags::POLLIN)];
        let ms = u16::try_from(HEAD_WAIT.as_millis()).unwrap_or(u16::MAX);
        // Readable, hung up or failed: the next read says which. Nothing: judge what came.
        if matches!(poll(&mut fds, PollTimeout::from(ms)), Ok(0)) {
            break;
        }
    }
    head.truncate(len);
    Ok(head)
}

/// Open a capture (`-` = standard input), detecting its format from its first bytes unless
/// `opts.format` says. Returns the reader and the format used.
pub fn open(path: &str, opts: OpenOptions) -> Result<(Box<dyn Reader>, Format), OpenError> {
    open_with_progress(path, opts).map(|(r, f, _)| (r, f))
}

/// [`open`], also returning a [`Progress`] to show how far reading has got.
pub fn open_with_progress(
    path: &str,
    opts: OpenOptions,
) -> Result<(Box<dyn Reader>, Format, Progress), OpenError> {
    let mut progress = Progress::default();
    let mut input: Box<dyn Read> = if path == "-" {
        // A file redirected to standard input is read whole like any file.
        progress.live = !stdin_is_file();
        Box::new(Counted {
            inner: io::stdin(),
            read: progress.read.clone(),
            drained: progress.drained.clone(),
        })
    } else {
        let f = File::open(path).map_err(|source| OpenError::File {
            path: path.to_string(),
            source,
        })?;
        let meta = f.metadata().ok();
        if meta.as_ref().is_some_and(|m| m.is_dir()) {
            return Err(OpenError::Directory {
                path: path.to_string(),
            });
        }
        // A followed file has no size yet.
        let total = meta.map(|m| m.len()).filter(|_| opts.follow.is_none());
        let p = Progress {
            total,
            live: opts.follow.is_some(),
            ..progress.clone()
        };
        let (inner, head): (Box<dyn Read>, _) = match opts.follow {
            Some(stop) => {
                let mut f = Follow::new(f, stop);
                let head = f.head(SNIFF_LEN, names_container)?;
                progress
                    .read
                    .fetch_add(head.len() as u64, Ordering::Relaxed);
                // All the file had (so far): what it holds is shown before waiting for more.
                progress
                    .drained
                    .store(head.len() < SNIFF_LEN, Ordering::Relaxed);
                (Box::new(f), Some(head))
            }
            None => (Box::new(f), None),
        };
        let input = Box::new(Counted {
            inner,
            read: progress.read.clone(),
            drained: progress.drained.clone(),
        });
        let (reader, format, p) = finish_open(input, head, opts, p)?;
        // A name that promises a container the content is not: say so, rather than silently
        // decoding the container's headers as garbage.
        let named = Format::from_extension(path).filter(|f| {
            p.total != Some(0)
                && matches!(f, Format::Pcap | Format::PcapNg | Format::Mcap)
                && opts.format.is_none()
                && *f != format
                && !(matches!(f, Format::Pcap | Format::PcapNg)
                    && matches!(format, Format::Pcap | Format::PcapNg))
        });
        let reader: Box<dyn Reader> = match named {
            Some(n) => Box::new(Prefixed {
                first: Some(ReadDiag::new(
                    0,
                    ReadProblem::FormatMismatch {
                        named: n.name(),
                        read_as: format.name(),
                    },
                )),
                inner: reader,
            }),
            None => reader,
        };
        return Ok((reader, format, p));
    };
    let head = stdin_head(&mut *input)?;
    finish_open(input, Some(head), opts, progress)
}

/// A reader that reports one diagnostic before the events of another.
struct Prefixed {
    first: Option<ReadDiag>,
    inner: Box<dyn Reader>,
}

impl Reader for Prefixed {
    fn next_event(&mut self) -> Option<Event<'_>> {
        match self.first.take() {
            Some(d) => Some(Event::Diag(d)),
            None => self.inner.next_event(),
        }
    }
    fn format(&self) -> String {
        self.inner.format()
    }
}

/// Detect the format from `head` (the first bytes, already read; read from `input` when
/// `None`) and build its reader over the rest.
fn finish_open(
    mut input: Box<dyn Read>,
    head: Option<Vec<u8>>,
    opts: OpenOptions,
    progress: Progress,
) -> Result<(Box<dyn Reader>, Format, Progress), OpenError> {
    let head = match head {
        Some(h) => h,
        None => {
            let mut head = Vec::with_capacity(SNIFF_LEN);
            (&mut input).take(SNIFF_LEN as u64).read_to_end(&mut head)?;
            head
        }
    };
    let sniffed = sniff(&head);
    let format = opts.format.unwrap_or(sniffed);
    let container = |f: Format| matches!(f, Format::Pcap | Format::PcapNg | Format::Mcap);
    if container(format) && format != sniffed {
        // Reading one container as another, or bytes that are none as one, cannot work: say
        // what the file is (a text log or raw bytes read as pcapng would be one bad magic).
        return Err(OpenError::ContainerMismatch {
            forced: format.name(),
            found: sniffed.name(),
        });
    }
    if let (Some((bus, addr)), false) = (
        opts.usb_device,
        matches!(format, Format::Pcap | Format::PcapNg),
    ) {
        return Err(OpenError::NotUsb {
            bus,
            addr,
            format: format.name(),
        });
    }
    let stream: Box<dyn Read> = Box::new(Cursor::new(head).chain(input));
    let reader: Box<dyn Reader> = match format {
        Format::Pcap | Format::PcapNg => Box::new(
            pcap::PcapReader::new(stream, opts.usb_device).expect_pcapng(format == Format::PcapNg),
        ),
        Format::Mcap => Box::new(mcap::McapReader::new(stream)),
        Format::Text(t) => textlog::open(t, BufReader::new(stream)),
        Format::Hex => Box::new(ByteReader::new(stream, true)),
        Format::Raw => Box::new(ByteReader::new(stream, false)),
    };
    Ok((reader, format, progress))
}

/// Create a capture writer for `path` in `format`, refusing to overwrite unless `force`; `-`
/// is standard output (for every format but MCAP, which needs a file to seek in).
pub fn create(path: &str, format: Format, force: bool) -> Result<Box<dyn Writer>, CreateError> {
    if path == "-" {
        return create_on(io::stdout(), format);
    }
    let file = create_file(path, force)?;
    if format == Format::Mcap {
        let w = io::BufWriter::with_capacity(1 << 16, file);
        return Ok(Box::new(mcap::McapWriter::new(w, None)?));
    }
    create_on(file, format)
}

/// Create the file `path` (a capture's), refusing to overwrite it unless `force`.
pub(crate) fn create_file(path: &str, force: bool) -> Result<File, CreateError> {
    if force {
        File::create(path)
    } else {
        File::options().write(true).create_new(true).open(path)
    }
    .map_err(|source| {
        let path = path.to_string();
        if source.kind() == io::ErrorKind::AlreadyExists {
            CreateError::Exists { path }
        } else {
            CreateError::File { path, source }
        }
    })
}

/// A writer of `format` (any but MCAP) on `out`.
fn create_on(
    out: impl io::Write + 'static,
    format: Format,
) -> Result<Box<dyn Writer>, CreateError> {
    let w = io::BufWriter::with_capacity(1 << 16, out);
    Ok(match format {
        Format::PcapNg => Box::new(pcap::PcapNgOut::new(w)?),
        Format::Pcap => Box::new(pcap::PcapOut::new(w)?),
        Format::Mcap => return Err(CreateError::McapToStdout),
        Format::Hex | Format::Raw => Box::new(BytesOut {
            w,
            hex: format == Format::Hex,
            col: 0,
            timed: 0,
            directed: 0,
            streams: vec![],
        }),
        Format::Text(t) => return Err(CreateError::ReadOnly(t.name())),
    })
}

/// Writer of raw bytes or hex text: the bytes only, in capture order.
struct BytesOut<W: io::Write> {
    w: W,
    hex: bool,
    col: usize,
    /// Chunks that had a time, and a direction (both dropped).
    timed: u64,
    directed: u64,
    /// Streams seen (merged into one byte stream), up to a few for the note.
    streams: Vec<u32>,
}

impl<W: io::Write> Writer for BytesOut<W> {
    fn stream(&mut self, _s: &crate::model::StreamInfo) -> io::Result<()> {
        Ok(())
    }
    fn chunk(&mut self, c: &Chunk<'_>) -> io::Result<()> {
        self.timed += u64::from(c.ts_ns.is_some());
        self.directed += u64::from(c.dir != Direction::Unknown);
        if !self.streams.contains(&c.stream) && self.streams.len() < 2 {
            self.streams.push(c.stream);
        }
        if !self.hex {
            return self.w.write_all(c.bytes);
        }
        for b in c.bytes {
            write!(self.w, "{b:02x}")?;
            self.col += 1;
            if self.col == 32 {
                self.w.write_all(b"\n")?;
                self.col = 0;
            } else {
                self.w.write_all(b" ")?;
            }
        }
        Ok(())
    }
    fn finish(&mut self) -> io::Result<()> {
        if self.hex && self.col > 0 {
            self.w.write_all(b"\n")?;
        }
        self.w.flush()
    }
    fn lost(&self) -> Vec<String> {
        let mut v = vec![];
        if self.timed > 0 {
            v.push(format!("times ({} chunk(s) had one)", self.timed));
        }
        if self.directed > 0 {
            v.push(format!("directions ({} chunk(s) had one)", self.directed));
        }
        if self.streams.len() > 1 {
            v.push(
                "streams: the streams' bytes are written one after another, in capture order"
                    .into(),
            );
        }
        v
    }
}
