//! aptscope's dissector: framing and decoding of the Thorlabs APT (binary) and Elliptec (ASCII)
//! serial protocols.
//!
//! A pure library: bytes in, frames and decoded messages out; no I/O, no clocks. Every APT
//! message is described once in the message table ([`table`]), which decode, encode, listings
//! and JSON output all read.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod apt;
pub mod detect;
pub mod diag;
pub mod ell;
pub mod fields;
pub mod filter;
pub mod hash;
pub mod hex;
pub mod json;
pub mod listing;
pub mod msg;
pub mod owned;
pub mod pair;
pub mod pipeline;
pub mod record;
pub mod shape;
pub mod spec_examples;
pub mod stats;
pub mod suggest;
pub mod synth;
pub mod table;
pub mod text;
pub mod units;
pub mod wireshark;

pub use diag::{Diag, DiagKind};
pub use table::Table;
