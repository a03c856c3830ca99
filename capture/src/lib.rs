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

/// `eprintln!` that cannot panic: a closed or failing standard error is ignored, so a live tool
/// never dies of its log (`aptscope tap … 2>&1 | tee log` after `tee` has gone) and nothing
/// between a signal and the stop depends on it.
/// Silenced by [`set_notes`]`(false)`.
#[macro_export]
macro_rules! note {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        if $crate::notes_on() {
            let _ = writeln!(std::io::stderr(), $($arg)*);
        }
    }};
}

static NOTES_OFF: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Turn [`note!`]'s progress lines on or off (an extcap: Wireshark shows anything on its
/// standard error as an error, so only a failure may be said there).
pub fn set_notes(on: bool) {
    NOTES_OFF.store(!on, std::sync::atomic::Ordering::Relaxed);
}

/// Whether [`note!`] writes (see [`set_notes`]).
pub fn notes_on() -> bool {
    !NOTES_OFF.load(std::sync::atomic::Ordering::Relaxed)
}
