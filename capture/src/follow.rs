//! Following a capture file that another process (a tap) is still writing: a reader that, at
//! the end of the file, waits for it to grow instead of ending, until told the writer stopped.
//!
//! Every capture reader reads through [`Follow`], so none of them needs to know: a block, line
//! or frame cut by the current end of the file is simply waited for (not reported as damage),
//! and once [`FollowStop::stop`] has been called the end of the file is the end again (then a
//! cut last block is reported as it always is).

use std::fs::File;
use std::io::{self, Read};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How often the end of a followed file is looked at again (no busy loop, no inotify).
pub const POLL: Duration = Duration::from_millis(20);

/// How long format detection waits, after the first byte, for enough of a file whose first
/// bytes name no container (a text log or raw bytes) before judging what it has.
pub const HEAD_WAIT: Duration = Duration::from_millis(500);

/// Says that the writer of a followed file has stopped: reading ends at the end of the file.
///
/// Copyable (so [`crate::open::OpenOptions`] stays `Copy`): the flag lives as long as the
/// program, one small allocation per followed file.
#[derive(Debug, Clone, Copy)]
pub struct FollowStop(&'static AtomicBool);

impl FollowStop {
    /// A flag, not yet stopped.
    pub fn new() -> FollowStop {
        FollowStop(Box::leak(Box::new(AtomicBool::new(false))))
    }

    /// The writer has stopped (its last bytes are in the file): read to the end, then end.
    pub fn stop(self) {
        self.0.store(true, Ordering::SeqCst);
    }

    /// Whether [`stop`](Self::stop) was called.
    pub fn is_stopped(self) -> bool {
        self.0.load(Ordering::SeqCst)
    }
}

impl Default for FollowStop {
    fn default() -> Self {
        FollowStop::new()
    }
}

/// A file read as it grows: `read` at the end of the file waits (polling every [`POLL`]) for
/// more bytes, and returns 0 only once the stop flag is set and everything written before it
/// has been read.
pub struct Follow {
    file: File,
    stop: FollowStop,
}

impl Follow {
    /// Follow `file` from its current position until `stop`.
    pub fn new(file: File, stop: FollowStop) -> Follow {
        Follow { file, stop }
    }

    /// The first bytes of the file, for format detection: waits for the first byte, then
    /// returns as soon as they name a container (`container`), or `limit` bytes are there, or
    /// the file has not reached `limit` [`HEAD_WAIT`] after its first byte (a quiet text log),
    /// or the writer stopped.
    pub fn head(&mut self, limit: usize, container: impl Fn(&[u8]) -> bool) -> io::Result<Vec<u8>> {
        let mut head = Vec::with_capacity(limit);
        let mut first: Option<Instant> = None;
        loop {
            let stopped = self.stop.is_stopped();
            let mut buf = vec![0u8; limit - head.len()];
            let n = self.file.read(&mut buf)?;
            head.extend_from_slice(&buf[..n]);
            if !head.is_empty() && first.is_none() {
                first = Some(Instant::now());
            }
            if head.len() >= limit
                || stopped
                || (n == 0 && head.len() >= 4 && container(&head))
                || first.is_some_and(|t| t.elapsed() >= HEAD_WAIT)
            {
                return Ok(head);
            }
            if n == 0 {
                std::thread::sleep(POLL);
            }
        }
    }
}

impl Read for Follow {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        loop {
            // Looked at before reading: what was written before the stop is still read.
            let stopped = self.stop.is_stopped();
            let n = self.file.read(buf)?;
            if n > 0 || buf.is_empty() || stopped {
                return Ok(n);
            }
            std::thread::sleep(POLL);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;
    use std::sync::mpsc;

    fn scratch(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("aptscope-follow-{}-{name}", std::process::id()));
        let _ = std::fs::remove_file(&d);
        d
    }

    #[test]
    fn reading_waits_for_the_file_to_grow_and_ends_only_after_the_stop() {
        let p = scratch("grow");
        let mut w = File::create(&p).unwrap();
        w.write_all(b"ab").unwrap();
        let stop = FollowStop::new();
        let mut f = Follow::new(File::open(&p).unwrap(), stop);
        let (tx, rx) = mpsc::channel();
        let t = std::thread::spawn(move || {
            let mut all = vec![];
            let r = f.read_to_end(&mut all);
            let _ = tx.send(());
            r.map(|_| all)
        });
        // Still reading at the end of what is there.
        assert!(
            rx.recv_timeout(POLL * 5).is_err(),
            "ended at the end of the file"
        );
        w.write_all(b"cd").unwrap();
        w.write_all(b"ef").unwrap();
        stop.stop();
        rx.recv_timeout(Duration::from_secs(30))
            .expect("ends after the stop");
        let all = t.join().unwrap().unwrap();
        assert_eq!(all, b"abcdef", "what was written before the stop is read");
        let _ = std::fs::remove_file(&p);
    }

    #[test]
    fn the_head_waits_for_a_first_byte_and_takes_a_container_at_once() {
        let p = scratch("head");
        let mut w = File::create(&p).unwrap();
        let stop = FollowStop::new();
        let mut f = Follow::new(File::open(&p).unwrap(), stop);
        let (tx, rx) = mpsc::channel();
        let t = std::thread::spawn(move || {
            let h = f.head(8192, |h| h.starts_with(b"\x0a\x0d\x0d\x0a"));
            let _ = tx.send(());
            (h, f)
        });
        assert!(rx.recv_timeout(POLL * 5).is_err(), "judged an empty file");
        w.write_all(b"\x0a\x0d\x0d\x0a\x1c\x00\x00\x00").unwrap();
        let (h, mut f) = t.join().unwrap();
        assert_eq!(h.unwrap().len(), 8, "a container is judged without 8 KiB");
        // A quiet text log: judged HEAD_WAIT after its first byte, with what there is.
        w.write_all(b"> 2025/01/01").unwrap();
        let start = Instant::now();
        let h = f.head(8192, |_| false).unwrap();
        assert_eq!(h, b"> 2025/01/01");
        assert!(start.elapsed() >= HEAD_WAIT);
        let _ = std::fs::remove_file(&p);
    }

    /// What a reader of a file (followed when `follow` is given) reports, as text, sent as it
    /// comes.
    fn events(path: std::path::PathBuf, follow: Option<FollowStop>, tx: mpsc::Sender<String>) {
        use crate::model::Event;
        let opts = crate::open::OpenOptions {
            follow,
            ..Default::default()
        };
        let (mut r, _) = match crate::open::open(&path.to_string_lossy(), opts) {
            Ok(x) => x,
            Err(e) => {
                let _ = tx.send(format!("error {e}"));
                return;
            }
        };
        while let Some(ev) = r.next_event() {
            let line = match ev {
                Event::Stream(s) => format!("stream {}", s.name),
                Event::Chunk(c) => format!("chunk {:02x?}", c.bytes),
                Event::Diag(d) => format!("diag {}", d.kind()),
            };
            let _ = tx.send(line);
        }
        let _ = tx.send("end".into());
    }

    #[test]
    fn a_pcapng_block_cut_by_the_end_of_the_file_is_waited_for_until_the_stop() {
        use crate::model::{Chunk, Direction, StreamInfo, Writer};
        let mut bytes = vec![];
        {
            let mut w = crate::pcap::PcapNgOut::new(&mut bytes).unwrap();
            let info = StreamInfo {
                id: 0,
                name: "/dev/ttyUSB0".into(),
                settings: None,
            };
            w.stream(&info).unwrap();
            for b in [[1u8, 2, 3], [4, 5, 6]] {
                let c = Chunk {
                    ts_ns: Some(1),
                    dir: Direction::HostToDevice,
                    stream: 0,
                    bytes: &b,
                };
                w.chunk(&c).unwrap();
            }
            w.finish().unwrap();
        }
        // The first packet block and half of the second.
        let block = 32 + 4; // an EPB with 3 bytes of data padded to 4
        let cut = bytes.len() - block / 2;
        let p = scratch("pcapng");
        let mut w = File::create(&p).unwrap();
        let stop = FollowStop::new();
        let (tx, rx) = mpsc::channel();
        let path = p.clone();
        let t = std::thread::spawn(move || events(path, Some(stop), tx));
        let wait = Duration::from_secs(30);
        // Nothing yet, not even an error: the file is empty.
        assert!(rx.recv_timeout(POLL * 5).is_err());
        w.write_all(&bytes[..cut]).unwrap();
        assert_eq!(rx.recv_timeout(wait).unwrap(), "stream /dev/ttyUSB0");
        assert_eq!(rx.recv_timeout(wait).unwrap(), "chunk [01, 02, 03]");
        // The cut block is waited for, not reported.
        assert!(rx.recv_timeout(POLL * 5).is_err());
        w.write_all(&bytes[cut..]).unwrap();
        assert_eq!(rx.recv_timeout(wait).unwrap(), "chunk [04, 05, 06]");
        // A new cut block at the stop is damage, as in any file.
        w.write_all(&bytes[bytes.len() - block..bytes.len() - 3])
            .unwrap();
        stop.stop();
        let rest: Vec<String> = rx.iter().collect();
        assert_eq!(rest.last().map(String::as_str), Some("end"), "{rest:?}");
        assert!(
            rest.iter().any(|l| l.starts_with("diag")),
            "a cut block after the stop is reported: {rest:?}"
        );
        t.join().unwrap();
        let _ = std::fs::remove_file(&p);
    }

    #[test]
    fn a_socat_log_written_in_pieces_reads_as_the_whole_file_does() {
        let sample = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../samples/kdc101-session.socat.log"
        );
        let whole = std::fs::read(sample).unwrap();
        let (tx, rx) = mpsc::channel();
        events(sample.into(), None, tx);
        let expected: Vec<String> = rx.iter().collect();
        assert!(expected.iter().filter(|l| l.starts_with("chunk")).count() > 10);

        let p = scratch("socat");
        let mut w = File::create(&p).unwrap();
        let stop = FollowStop::new();
        let (tx, rx) = mpsc::channel();
        let path = p.clone();
        let t = std::thread::spawn(move || events(path, Some(stop), tx));
        // Pieces cut inside lines: each is waited for, nothing reported as damage.
        let mut got = vec![];
        for piece in whole.chunks(700) {
            w.write_all(piece).unwrap();
            while let Ok(l) = rx.recv_timeout(POLL * 5) {
                assert!(!l.starts_with("diag"), "{l} after {} bytes", got.len());
                got.push(l);
            }
        }
        stop.stop();
        got.extend(rx.iter());
        t.join().unwrap();
        assert_eq!(got, expected);
        let _ = std::fs::remove_file(&p);
    }
}
