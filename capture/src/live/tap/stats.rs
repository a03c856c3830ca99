//! What a tap or sniff did, and its summary.

use super::clock_time;

/// A port (or the host side) that disappeared, and when.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Disconnect {
    /// When it was noticed, ns since the Unix epoch.
    pub ts_ns: u64,
    /// Which port.
    pub port: String,
    /// The error.
    pub error: String,
}

/// What a tap or sniff did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TapStats {
    /// Bytes forwarded host → device (sniff: received on the host-TX adapter).
    pub bytes_h2d: u64,
    /// Bytes forwarded device → host (sniff: received on the device-TX adapter).
    pub bytes_d2h: u64,
    /// Chunks forwarded (received).
    pub chunks: u64,
    /// Chunks written to the file.
    pub written: u64,
    /// Host → device bytes written to the file.
    pub written_h2d: u64,
    /// Device → host bytes written to the file.
    pub written_d2h: u64,
    /// Whether a file was written.
    pub file: bool,
    /// The file error, when writing failed.
    pub file_error: Option<String>,
    /// A stream's reader closed it ([`TapOptions::stream`](super::TapOptions::stream)): the
    /// normal end of a capture into Wireshark; `file_error` says so too.
    pub reader_closed: bool,
    /// Bytes not written to the file because writing it had failed.
    pub file_lost: u64,
    /// Times forwarding waited because the file's backlog was full.
    pub backpressure_waits: u64,
    /// Bytes skipped by the live display (a slow terminal); the file has them.
    pub display_skipped: u64,
    /// Bytes read from one side that could not be delivered to the other (it vanished, or the
    /// tap was stopped while the other side was not accepting them); not in the file.
    pub undelivered: u64,
    /// Bytes the host wrote while the device was away (discarded, not in the file).
    pub discarded_h2d: u64,
    /// Ports that disappeared.
    pub disconnects: Vec<Disconnect>,
}

impl TapStats {
    /// Whether the file holds exactly what was forwarded, per direction (true without a file).
    pub fn file_matches(&self) -> bool {
        !self.file
            || (self.file_error.is_none()
                && self.written_h2d == self.bytes_h2d
                && self.written_d2h == self.bytes_d2h
                && self.written == self.chunks)
    }

    /// A human summary, one line per fact.
    pub fn summary(&self, what: &str) -> String {
        let mut s = format!(
            "{what}: host → device {} bytes, device → host {} bytes, {} chunks",
            self.bytes_h2d, self.bytes_d2h, self.chunks
        );
        if self.file {
            s += &format!(
                "\n{what}: file: host → device {} bytes, device → host {} bytes, {} chunks: {}",
                self.written_h2d,
                self.written_d2h,
                self.written,
                if self.file_matches() {
                    "matches what was forwarded".to_string()
                } else if self.reader_closed {
                    "its reader closed it".to_string()
                } else {
                    format!(
                        "MISMATCH ({} bytes lost{})",
                        self.file_lost,
                        self.file_error
                            .as_ref()
                            .map(|e| format!(", error: {e}"))
                            .unwrap_or_default()
                    )
                }
            );
        }
        for (n, label) in [
            (self.display_skipped, "bytes skipped by the display"),
            (self.backpressure_waits, "waits for the disk"),
            (self.undelivered, "bytes read but not delivered"),
            (self.discarded_h2d, "host bytes discarded while away"),
        ] {
            if n > 0 {
                s += &format!("\n{what}: {n} {label}");
            }
        }
        for d in &self.disconnects {
            s += &format!(
                "\n{what}: {} gone at {}: {}",
                d.port,
                clock_time(d.ts_ns),
                d.error
            );
        }
        s
    }
}
