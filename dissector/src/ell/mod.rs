//! The Elliptec ELLx ASCII protocol: command table, streaming framer, decoder, encoder, bus
//! state and request/reply pairing, and the command listing.

mod bus;
mod decode;
pub mod encode;
mod frame;
pub mod listing;
pub mod table;

pub use bus::{timeout_ns, Bus, Expired, Module, Observation};
pub use decode::{
    curve_bytes, curve_points, fmt_value, CurvePoint, EllFrame, EllValue, CURRENT_PER_AMP,
    PERIOD_CLOCK_HZ,
};
pub use encode::{encode, EncodeError};
pub use frame::{head, EllFramer, GarbageKind, Head, Item};
