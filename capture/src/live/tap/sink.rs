//! The capture file the tap writes: pcapng or pcap, flushed while it is written so that a
//! follower sees it and a killed tap leaves it readable; or the pipe of a stream.

use crate::live::error::LiveError;
use crate::live::stop::lock;
use crate::model::{StreamInfo, Writer};
use crate::open::{create_file, Format};
use crate::pcap::{PcapNgOut, PcapOut};
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::os::fd::AsFd;
use std::sync::{Arc, Mutex};

/// A buffered file whose buffer the writer thread can flush while the pcapng writer owns it.
#[derive(Clone)]
struct SharedFile(Arc<Mutex<BufWriter<File>>>);

impl Write for SharedFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        lock(&self.0).write(buf)
    }
    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        lock(&self.0).write_all(buf)
    }
    fn flush(&mut self) -> io::Result<()> {
        lock(&self.0).flush()
    }
}

/// The capture file: a pcapng or pcap writer (one stream) over a [`SharedFile`].
pub(super) struct FileSink {
    pub(super) out: Box<dyn Writer + Send>,
    file: SharedFile,
    /// A stream ([`TapOptions::stream`](super::TapOptions::stream)): the pipe, to see its
    /// reader go away.
    pub(super) stream: Option<File>,
    /// Flushed whenever something was written (a stream, or a file a live view follows).
    pub(super) eager: bool,
}

impl FileSink {
    /// The capture's format (checked before any port is opened). Streaming formats only:
    /// every block is whole once flushed, so a killed tap leaves a readable file. MCAP needs
    /// its footer (and text formats lose the times): convert.
    pub(super) fn format(path: &str, forced: Option<Format>) -> Result<Format, LiveError> {
        match Format::for_writing(path, forced)? {
            f @ (Format::PcapNg | Format::Pcap) => Ok(f),
            other => Err(LiveError::NotStreamable {
                path: path.to_string(),
                format: other.name(),
            }),
        }
    }

    /// Create `path` in `format` (refusing to overwrite unless `force`, as
    /// [`crate::open::create`] does; built here rather than with it to be able to flush
    /// periodically) and declare `stream`.
    fn create(
        path: &str,
        format: Format,
        force: bool,
        stream: &StreamInfo,
    ) -> Result<FileSink, LiveError> {
        let f = create_file(path, force)?;
        Ok(FileSink::over(f, format, stream, false)?)
    }

    /// The sink `opts` ask for: the pipe of a stream, else a file created, flushed as it is
    /// written when a live view follows it.
    pub(super) fn for_opts(
        path: &str,
        format: Format,
        (stream, force, followed): (bool, bool, bool),
        info: &StreamInfo,
    ) -> Result<FileSink, LiveError> {
        let mut sink = if stream {
            FileSink::open_stream(path, format, info)?
        } else {
            FileSink::create(path, format, force, info)?
        };
        sink.eager |= followed;
        Ok(sink)
    }

    /// Open the existing pipe `path` (waiting for its reader, as opening a FIFO does) and
    /// declare `stream` in `format`.
    fn open_stream(path: &str, format: Format, stream: &StreamInfo) -> Result<FileSink, LiveError> {
        use std::os::unix::fs::FileTypeExt;
        let failed = |source| LiveError::Stream {
            path: path.to_string(),
            source,
        };
        let t = std::fs::metadata(path).map_err(failed)?.file_type();
        // Written from its start without truncating: only right for a pipe (or a terminal).
        if !(t.is_fifo() || t.is_char_device() || t.is_socket()) {
            return Err(LiveError::NotAPipe {
                path: path.to_string(),
            });
        }
        let f = File::options().write(true).open(path).map_err(failed)?;
        Ok(FileSink::over(f, format, stream, true)?)
    }

    fn over(f: File, format: Format, stream: &StreamInfo, live: bool) -> io::Result<FileSink> {
        let pipe = if live { Some(f.try_clone()?) } else { None };
        let file = SharedFile(Arc::new(Mutex::new(BufWriter::with_capacity(1 << 16, f))));
        let mut out: Box<dyn Writer + Send> = match format {
            Format::Pcap => Box::new(PcapOut::new(file.clone())?),
            _ => Box::new(PcapNgOut::new(file.clone())?),
        };
        out.stream(stream)?;
        let mut sink = FileSink {
            out,
            file,
            stream: pipe,
            eager: live,
        };
        sink.flush()?;
        Ok(sink)
    }

    /// Whether the stream's reader has closed it (a pipe's write end polls as an error then).
    pub(super) fn reader_gone(&self) -> bool {
        let Some(p) = &self.stream else {
            return false;
        };
        let mut fds = [PollFd::new(p.as_fd(), PollFlags::POLLOUT)];
        matches!(poll(&mut fds, PollTimeout::ZERO), Ok(n) if n > 0)
            && fds[0]
                .revents()
                .is_some_and(|r| r.intersects(PollFlags::POLLERR | PollFlags::POLLHUP))
    }

    pub(super) fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}
