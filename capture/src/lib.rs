//! aptscope-capture: where bytes come from and where they go. Capture files (pcap, pcapng, USB
//! captures of FTDI controllers, MCAP, raw and hex dumps, serial tool logs) are read as streams
//! of timestamped, directed chunks, and written back losslessly where the format allows.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod info;
pub mod live;
pub mod mcap_io;
pub mod model;
pub mod open;
pub mod pcap;
pub mod raw;
pub mod textlog;
pub mod tools;
pub mod usb;

pub use model::{Chunk, Direction, Event, OwnedChunk, ReadDiag, Reader, StreamInfo, Writer};
pub use raw::{ByteSource, InputFormat, CHUNK};
