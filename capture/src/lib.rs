//! aptscope-capture: where bytes come from and where they go. Capture files (pcap, pcapng, USB
//! captures of FTDI controllers, MCAP, raw and hex dumps, serial tool logs) are read as streams
//! of timestamped, directed chunks, and written back losslessly where the format allows.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod follow;
pub mod info;
pub mod judge;
pub mod live;
pub mod mcap;
pub mod model;
pub mod open;
pub mod pcap;
pub mod problem;
pub mod raw;
pub mod say;
pub mod textlog;
pub mod tools;
pub mod usb;

/// The scratch directories of the tests (one source for every crate's tests).
#[cfg(test)]
#[path = "../../tests/common/scratch.rs"]
mod scratch;

pub use model::{
    Chain, Chunk, Damage, Direction, Event, LogField, LogProblem, McapProblem, OwnedChunk,
    ReadDiag, ReadProblem, Reader, Skipped, StreamInfo, UrbCut, UsbDevice, UsbFormat, UsbNote,
    UsbProblem, Writer,
};
pub use raw::{ByteSource, InputFormat, CHUNK};
pub use say::Say;

/// `eprintln!` that cannot panic: a closed or failing standard error is ignored, so a live tool
/// never dies of its log (`aptscope tap … 2>&1 | tee log` after `tee` has gone) and nothing
/// between a signal and the stop depends on it. Live taps say their progress through a
/// [`Say`] instead, which can be silenced.
#[macro_export]
macro_rules! note {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($arg)*);
    }};
}
