//! The APT binary protocol: header view, streaming framer, decoder and encoder.

mod decode;
mod encode;
mod frame;
mod header;

pub use decode::{
    fmt_value, fmt_value_in, phys, phys_or_scaled, read_prim, round_sig, summary, summary_in,
    text_of, AptFrame, Value,
};
pub use encode::{encode, encode_named, encode_named_report, EncodeError, FieldValue, Named};
pub use frame::{check_frame, AptFramer, GarbageKind, Item, LenRule, MAX_GARBAGE_RUN};
pub use header::{emit_header, Addr, AddrName, Header, DATA_FLAG, HEADER_LEN, MAX_DATA_LEN};
