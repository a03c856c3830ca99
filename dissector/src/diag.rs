//! Diagnostics: what is wrong with the input, and where (stream byte offset).

use std::fmt;

/// Which header address a diagnostic is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Which {
    /// The source byte (5).
    Source,
    /// The destination byte (4).
    Destination,
}

/// What is wrong.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DiagKind {
    /// Bytes that are not part of any frame.
    Garbage {
        /// How many.
        len: u32,
    },
    /// A known message's header claims a data packet longer than any APT message.
    AbsurdLength {
        /// Message id.
        msg_id: u16,
        /// Claimed length.
        len: u16,
    },
    /// Fewer than 6 bytes left at the end of the stream.
    TrailingBytes {
        /// How many.
        len: u32,
    },
    /// The stream ended inside this frame.
    Truncated {
        /// Frame length the header announces.
        expected: u32,
        /// Bytes present.
        got: u32,
    },
    /// The message id is not in the table.
    UnknownId {
        /// The id.
        msg_id: u16,
    },
    /// An address byte the spec does not define.
    UnknownAddress {
        /// Source or destination.
        which: Which,
        /// The byte (without the 0x80 flag).
        value: u8,
    },
    /// The length matches none of the message's forms.
    LengthMismatch {
        /// Data length in the header (0 for header-only).
        len: u32,
        /// Whether the 0x80 data flag is set.
        has_data: bool,
    },
    /// A header-only message sent with the 0x80 "data follows" bit set.
    HeaderOnlyWithData {
        /// The data length it claims.
        len: u32,
    },
    /// A sub-message id the table does not know for this message.
    UnknownSubId {
        /// The sub id.
        sub_id: u16,
    },
    /// A character that is not a hex digit in hex text input.
    BadHex {
        /// The character.
        ch: char,
    },
    /// An odd number of hex digits at the end of hex text input.
    OddHexDigit,
    /// Elliptec: a two-letter command the manual does not define.
    UnknownCommand,
    /// Elliptec: a data character that is not valid for its field (not a hex digit).
    BadDataChar {
        /// The character.
        ch: char,
    },
    /// Elliptec: data of another length than the command's.
    DataLength {
        /// Characters the command has.
        expected: u32,
        /// Characters present.
        got: u32,
    },
    /// Elliptec: a command sent without its data (`0ma` then CR LF, `0ho` without the
    /// direction digit); the offset is where the data belongs.
    MissingData {
        /// Characters the command has.
        expected: u32,
    },
    /// Elliptec: a module reply without its CR LF terminator.
    MissingTerminator,
    /// Elliptec: spaces or commas between address, command and data.
    Separators,
    /// Elliptec: the letter O where the digit 0 belongs.
    LetterO,
    /// A command that got no reply within its timeout (or before the stream ended).
    NoReply {
        /// Record number of the command.
        cmd: u64,
    },
    /// A reply no command asked for.
    Unsolicited,
    /// A second reply to a request that was already answered.
    DuplicateReply {
        /// Record number of the request.
        request: u64,
    },
    /// A data packet sent without the 0x80 flag in the destination byte (recognised by the
    /// length its param bytes give).
    MissingDataFlag {
        /// The data length.
        len: u32,
    },
    /// Destination and source both 0x00 (some controllers reply so).
    ZeroAddresses,
    /// The device's model (from its HW_GET_INFO) does not list this message in the spec.
    NotForModel {
        /// The model, zero-padded ASCII.
        model: [u8; 8],
    },
}

impl DiagKind {
    /// Every [`DiagKind::name`], once: what a name saved elsewhere (the viewer's index cache)
    /// is mapped back through.
    pub const NAMES: [&'static str; 24] = [
        "garbage",
        "absurd_length",
        "trailing_bytes",
        "truncated",
        "unknown_id",
        "unknown_address",
        "length_mismatch",
        "header_only_with_data",
        "unknown_sub_id",
        "bad_hex",
        "odd_hex_digit",
        "unknown_command",
        "bad_data_char",
        "data_length",
        "missing_data",
        "missing_terminator",
        "separators",
        "letter_o",
        "no_reply",
        "unsolicited",
        "duplicate_reply",
        "not_for_model",
        "missing_data_flag",
        "zero_addresses",
    ];

    /// The `'static` name equal to `name`, when it is one of [`DiagKind::NAMES`].
    pub fn static_name(name: &str) -> Option<&'static str> {
        Self::NAMES.iter().copied().find(|n| *n == name)
    }

    /// The message of a kind that has no parameter, as one `'static` text (what
    /// [`Display`](fmt::Display) writes): columns of messages share it rather than write it
    /// (a status log's "reply without a pending command", in four rows of five).
    pub fn fixed_text(&self) -> Option<&'static str> {
        Some(match self {
            DiagKind::OddHexDigit => "odd number of hex digits; last digit ignored",
            DiagKind::UnknownCommand => "command not in the ELLx manual",
            DiagKind::MissingTerminator => "reply not terminated by CR LF",
            DiagKind::Separators => "spaces or commas inside the frame (ignored)",
            DiagKind::LetterO => "letter O used for digit 0",
            DiagKind::Unsolicited => "reply without a pending command",
            DiagKind::ZeroAddresses => {
                "destination and source 0x00: some controllers reply so (TDC001) or send so on \
                 connect (BSC201 MOVE_COMPLETED)"
            }
            _ => return None,
        })
    }

    /// A stable snake_case name (JSON `diag[].kind`, filters).
    pub fn name(&self) -> &'static str {
        match self {
            DiagKind::Garbage { .. } => "garbage",
            DiagKind::AbsurdLength { .. } => "absurd_length",
            DiagKind::TrailingBytes { .. } => "trailing_bytes",
            DiagKind::Truncated { .. } => "truncated",
            DiagKind::UnknownId { .. } => "unknown_id",
            DiagKind::UnknownAddress { .. } => "unknown_address",
            DiagKind::LengthMismatch { .. } => "length_mismatch",
            DiagKind::HeaderOnlyWithData { .. } => "header_only_with_data",
            DiagKind::UnknownSubId { .. } => "unknown_sub_id",
            DiagKind::BadHex { .. } => "bad_hex",
            DiagKind::OddHexDigit => "odd_hex_digit",
            DiagKind::UnknownCommand => "unknown_command",
            DiagKind::BadDataChar { .. } => "bad_data_char",
            DiagKind::DataLength { .. } => "data_length",
            DiagKind::MissingData { .. } => "missing_data",
            DiagKind::MissingTerminator => "missing_terminator",
            DiagKind::Separators => "separators",
            DiagKind::LetterO => "letter_o",
            DiagKind::NoReply { .. } => "no_reply",
            DiagKind::Unsolicited => "unsolicited",
            DiagKind::DuplicateReply { .. } => "duplicate_reply",
            DiagKind::NotForModel { .. } => "not_for_model",
            DiagKind::MissingDataFlag { .. } => "missing_data_flag",
            DiagKind::ZeroAddresses => "zero_addresses",
        }
    }
}

/// A diagnostic at a stream byte offset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Diag {
    /// Byte offset in the stream (in the text for hex-input diagnostics).
    pub offset: u64,
    /// What.
    pub kind: DiagKind,
}

impl fmt::Display for DiagKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            DiagKind::OddHexDigit
            | DiagKind::UnknownCommand
            | DiagKind::MissingTerminator
            | DiagKind::Separators
            | DiagKind::LetterO
            | DiagKind::Unsolicited
            | DiagKind::ZeroAddresses => f.write_str(self.fixed_text().unwrap_or_default()),
            DiagKind::Garbage { len } => write!(f, "{len} byte(s) that start no frame"),
            DiagKind::AbsurdLength { msg_id, len } => {
                write!(f, "header of 0x{msg_id:04X} claims a {len}-byte data packet (max 255); header skipped")
            }
            DiagKind::TrailingBytes { len } => {
                write!(f, "{len} byte(s) at end of stream, too short for a header")
            }
            DiagKind::Truncated { expected, got } => {
                write!(
                    f,
                    "truncated: header announces {expected} bytes, stream ends after {got}"
                )
            }
            DiagKind::UnknownId { msg_id } => write!(f, "unknown message id 0x{msg_id:04X}"),
            DiagKind::UnknownAddress { which, value } => {
                let w = match which {
                    Which::Source => "source",
                    Which::Destination => "destination",
                };
                write!(f, "unknown {w} address 0x{value:02X}")
            }
            DiagKind::LengthMismatch { len, has_data } => {
                if has_data {
                    write!(f, "data length {len} matches no form of this message")
                } else {
                    write!(f, "header-only form does not exist for this message")
                }
            }
            DiagKind::HeaderOnlyWithData { len } => {
                write!(
                    f,
                    "header-only message sent with the 0x80 data flag ({len}-byte data packet)"
                )
            }
            DiagKind::UnknownSubId { sub_id } => write!(f, "unknown sub-message id 0x{sub_id:04X}"),
            DiagKind::BadHex { ch } => write!(f, "not a hex digit: {ch:?}; skipped"),
            DiagKind::BadDataChar { ch } => write!(f, "{ch:?} is not a valid data character"),
            DiagKind::DataLength { expected, got } => {
                write!(f, "{got} data characters, the command has {expected}")
            }
            DiagKind::MissingData { expected } => {
                write!(
                    f,
                    "data missing: the command takes {expected} data character(s)"
                )
            }
            DiagKind::NoReply { cmd } => write!(f, "no reply to record {cmd}"),
            DiagKind::DuplicateReply { request } => write!(f, "second reply to record {request}"),
            DiagKind::MissingDataFlag { len } => write!(
                f,
                "{len}-byte data packet sent without the 0x80 flag in the destination byte \
                 (as some example programs do); decoded by the length in its param bytes"
            ),
            DiagKind::NotForModel { model } => {
                let end = model.iter().position(|&c| c == 0).unwrap_or(model.len());
                let m = String::from_utf8_lossy(&model[..end]);
                write!(
                    f,
                    "the spec does not name this message for {} (the device's HW_GET_INFO model; read: the \"Messages Applicable to\" lists and the message's own section, Issue 23 and 2025)",
                    m.trim()
                )
            }
        }
    }
}

impl fmt::Display for Diag {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "@{}: {}", self.offset, self.kind)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`DiagKind::NAMES`] holds every kind's name once (a kind added without its name there
    /// would make the viewer's index cache of a capture with it invalid, not wrong).
    #[test]
    fn names_lists_every_kind_once() {
        let all = [
            DiagKind::Garbage { len: 1 },
            DiagKind::AbsurdLength { msg_id: 1, len: 1 },
            DiagKind::TrailingBytes { len: 1 },
            DiagKind::Truncated {
                expected: 1,
                got: 0,
            },
            DiagKind::UnknownId { msg_id: 1 },
            DiagKind::UnknownAddress {
                which: Which::Source,
                value: 1,
            },
            DiagKind::LengthMismatch {
                len: 1,
                has_data: false,
            },
            DiagKind::HeaderOnlyWithData { len: 1 },
            DiagKind::UnknownSubId { sub_id: 1 },
            DiagKind::BadHex { ch: 'x' },
            DiagKind::OddHexDigit,
            DiagKind::UnknownCommand,
            DiagKind::BadDataChar { ch: 'x' },
            DiagKind::DataLength {
                expected: 1,
                got: 0,
            },
            DiagKind::MissingData { expected: 1 },
            DiagKind::MissingTerminator,
            DiagKind::Separators,
            DiagKind::LetterO,
            DiagKind::NoReply { cmd: 1 },
            DiagKind::Unsolicited,
            DiagKind::DuplicateReply { request: 1 },
            DiagKind::MissingDataFlag { len: 1 },
            DiagKind::ZeroAddresses,
            DiagKind::NotForModel { model: [0; 8] },
        ];
        // Exhaustive: a new kind fails to compile here until it is listed above.
        for k in &all {
            match k {
                DiagKind::Garbage { .. }
                | DiagKind::AbsurdLength { .. }
                | DiagKind::TrailingBytes { .. }
                | DiagKind::Truncated { .. }
                | DiagKind::UnknownId { .. }
                | DiagKind::UnknownAddress { .. }
                | DiagKind::LengthMismatch { .. }
                | DiagKind::HeaderOnlyWithData { .. }
                | DiagKind::UnknownSubId { .. }
                | DiagKind::BadHex { .. }
                | DiagKind::OddHexDigit
                | DiagKind::UnknownCommand
                | DiagKind::BadDataChar { .. }
                | DiagKind::DataLength { .. }
                | DiagKind::MissingData { .. }
                | DiagKind::MissingTerminator
                | DiagKind::Separators
                | DiagKind::LetterO
                | DiagKind::NoReply { .. }
                | DiagKind::Unsolicited
                | DiagKind::DuplicateReply { .. }
                | DiagKind::MissingDataFlag { .. }
                | DiagKind::ZeroAddresses
                | DiagKind::NotForModel { .. } => {}
            }
        }
        let names: Vec<&str> = all.iter().map(|k| k.name()).collect();
        let mut listed = DiagKind::NAMES.to_vec();
        listed.sort_unstable();
        let mut got = names.clone();
        got.sort_unstable();
        assert_eq!(got, listed);
        for n in names {
            assert_eq!(DiagKind::static_name(n), Some(n));
        }
        assert_eq!(DiagKind::static_name("nonsense"), None);
        // A kind's fixed text is what it displays, and only a kind without parameters has one
        // (the Parquet and Arrow columns write the fixed text, the JSON its display).
        for k in &all {
            let shown = k.to_string();
            assert!(!shown.is_empty(), "{k:?}");
            if let Some(t) = k.fixed_text() {
                assert_eq!(shown, t);
                assert!(!format!("{k:?}").contains('{'), "{k:?} has parameters");
            }
        }
        assert_eq!(all.iter().filter(|k| k.fixed_text().is_some()).count(), 7);
    }
}
