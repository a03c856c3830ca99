//! Whether an input is serial traffic of these protocols at all: `decode`, `stats` and `replay`
//! refuse what is not (an image, random bytes, a capture of another link type) with a reason on
//! standard error and a failing exit, instead of pages of garbage records and success.

use crate::open::Format;
use aptscope_dissector::detect::Detection;
use aptscope_dissector::record::Decoder;
use std::io;

/// A raw byte file (no known container or log format) whose first 4 KiB frame as neither
/// protocol: not a capture (an image, a program), skipped rather than decoded as garbage.
pub fn not_a_capture(format: Format, d: &Detection) -> bool {
    matches!(format, Format::Raw) && d.proto.is_none() && d.apt.max(d.elliptec) < 0.1
}

/// The error that says so.
pub fn not_a_capture_error(d: &Detection) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidData,
        format!(
            "not a capture: no known file format, and {:.0}% of the first 4 KiB frame as APT, \
             {:.0}% as Elliptec (--proto or --format decode it anyway)",
            d.apt * 100.0,
            d.elliptec * 100.0
        ),
    )
}

/// What a whole input gave, to judge it once read.
#[derive(Debug, Clone, Copy, Default)]
pub struct Seen {
    /// Captured bytes of serial traffic.
    pub bytes: u64,
    /// Frames of either protocol.
    pub frames: u64,
    /// Problems of the file itself (damaged records, unknown link types).
    pub file_problems: u64,
}

/// Why a whole input is not traffic of these protocols, when it is not: it had bytes and none
/// framed, or it had no traffic at all but problems (a pcap of an Ethernet link). An empty
/// capture is not refused: nothing was there to decode. Callers ask only when the protocol was
/// detected: a forced one decodes whatever the input holds.
pub fn not_traffic(seen: Seen) -> Option<io::Error> {
    let why = if seen.frames == 0 && seen.bytes > 0 {
        format!(
            "no APT or Elliptec frame in its {} byte(s) of traffic: not a capture of these \
             protocols (--proto decodes it anyway)",
            seen.bytes
        )
    } else if seen.frames == 0 && seen.file_problems > 0 {
        format!(
            "no serial traffic aptscope can read: {} problem(s) of the file, see above",
            seen.file_problems
        )
    } else {
        return None;
    };
    Some(io::Error::new(io::ErrorKind::InvalidData, why))
}

/// The verdict on a whole input a decoder has read (`file_problems`: the reader's own
/// diagnostics): why it is not traffic of these protocols ([`not_a_capture`], [`not_traffic`]),
/// when it is not. Only asked when the protocol was detected: a forced one decodes whatever
/// the input holds.
pub fn refuse(dec: &Decoder, format: Format, file_problems: u64) -> Option<io::Error> {
    if let Some(d) = dec.detection().filter(|d| not_a_capture(format, d)) {
        return Some(not_a_capture_error(d));
    }
    not_traffic(Seen {
        bytes: dec.bytes(),
        frames: dec.frames(),
        file_problems,
    })
}
