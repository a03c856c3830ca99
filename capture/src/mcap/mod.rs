//! MCAP reading and writing.
//!
//! **Writing** ([`McapWriter`]) keeps the capture lossless and adds what the dissector makes of
//! it, so Foxglove can plot decoded fields without a plugin:
//!
//! - raw channels, one per (stream, direction): topic `/serial/<stream>/<h2d|d2h|unknown>`,
//!   message encoding `application/octet-stream`, no schema; each message is one chunk's bytes,
//!   `log_time` = `publish_time` = its capture time in ns, `sequence` = the chunk's number.
//!   Chunks without a capture time go to a channel of the same topic whose metadata says
//!   `time: missing` (their `log_time` is 0), so a reader restores "no time" exactly;
//! - decoded channels, message encoding `json`: each message is the line `aptscope decode
//!   --json` writes for one record of the decode chain ([`aptscope_dissector::record`]),
//!   byte for byte and in the same order (pairing, latency, units, capture context `dir`,
//!   `ts_ns`, `stream` included). One channel per message type: `/apt/<NAME>` (`/apt/unknown`,
//!   `/apt/garbage`, `/apt/diag` for requests without reply, `/apt/units` for unit notices) or
//!   `/ell/<cmd>` (`/ell/unknown`, `/ell/garbage`, `/ell/diag`); and `/aptscope/detect`,
//!   `/aptscope/stream` for the detector's verdict and the streams, `/aptscope/input` for
//!   problems of the input file its caller reports ([`McapWriter::file_diag`]). Schema encoding `jsonschema`, generated from the message tables to
//!   match those lines. `log_time` is the time of the chunk that completed a frame (garbage:
//!   of its first byte; 0 when unknown; detection: the first chunk's; other records: the
//!   latest chunk's), `sequence` the
//!   record number (0 for records without one). Plot
//!   `/apt/MOT_GET_DCSTATUSUPDATE.fields.position` in Foxglove, for example;
//! - metadata records: `aptscope` (version, what is lossless), `aptscope.stream` (one per
//!   declared stream, in order), `aptscope.decode` (protocol and how it was chosen) and
//!   `aptscope.times` (when some chunks have no capture time).
//!
//! Records are in zstd-compressed chunks (level 1, 4 MiB; [`McapOptions`] changes that) with
//! message indexes, and the file ends with the summary (schemas, channels, statistics, chunk and
//! metadata indexes), as `mcap::Writer` lays it out; the container is written by our own code
//! (`sink.rs`, which says why), the chunks compressed on a pool of threads.
//!
//! **Reading** ([`McapReader`]) streams the file record by record with bounded buffers (chunks
//! are decompressed incrementally through the `mcap` crate's sans-io [`LinearReader`]), so
//! multi-GB files read in constant memory. It produces the raw channels of our files and any
//! other channel that is not a structured encoding (json, protobuf, ros1, cdr …); decoded
//! channels are skipped. Damage (bad magic, a truncated record, a chunk with a bad CRC, garbage
//! between records, a missing footer, a data section whose CRC does not match) gives a
//! diagnostic with its file offset; records before and, after resynchronisation, after the
//! damage are still read. A chunk's CRC is known only once the chunk has been read through, so
//! the messages of a chunk with a bad CRC come out before the diagnostic that flags them.
//!
//! [`LinearReader`]: mcap::sans_io::LinearReader

use ::mcap::McapError;
use std::io;

mod reader;
mod schema;
mod sink;
#[cfg(test)]
mod tests;
mod writer;

pub use reader::{read_decoded, DecodedMsg, McapReader};
pub use schema::{apt_schema, ell_schema};
pub use sink::{McapOptions, DEFAULT_CHUNK_SIZE, DEFAULT_ZSTD_LEVEL};
pub use writer::McapWriter;

/// The MCAP magic, at the start and the end of every file.
pub const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// Whether `head` (the first bytes of a file) is MCAP.
pub fn sniff(head: &[u8]) -> bool {
    head.starts_with(MAGIC)
}

/// Message encoding of the raw channels.
pub const RAW_ENCODING: &str = "application/octet-stream";

/// An MCAP library error as an I/O error (its own I/O errors unchanged).
fn mcap_err(e: McapError) -> io::Error {
    match e {
        McapError::Io(e) => e,
        e => io::Error::other(e.to_string()),
    }
}

fn finished_err() -> io::Error {
    io::Error::other("MCAP writer already finished")
}

fn failed_err() -> io::Error {
    io::Error::other("MCAP writer stopped after an earlier error")
}
