//! The Elliptec ELLx ASCII protocol: command table, streaming framer, decoder, bus state and
//! request/reply pairing.

mod bus;
mod decode;
mod frame;
pub mod table;

pub use bus::{timeout_ns, Bus, Expired, Module, Observation};
pub use decode::{fmt_value, EllFrame, EllValue};
pub use frame::{head, EllFramer, GarbageKind, Head, Item};
