//! Problems reading captures, typed: a [`ReadDiag`] is an offset and a [`ReadProblem`] (damaged
//! pcap/pcapng blocks, text-log lines, USB records, MCAP records, USB device notes), each with
//! the kind name and text the output shows.

use crate::usb::FTDI_VID;
use std::fmt;

/// A problem reading the capture file, at a file offset.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReadDiag {
    /// Byte offset in the file.
    pub offset: u64,
    /// What went wrong: what was expected there and what was found.
    pub problem: ReadProblem,
}

impl ReadDiag {
    /// `problem` at byte `offset` of the file.
    pub fn new(offset: u64, problem: ReadProblem) -> Self {
        ReadDiag { offset, problem }
    }

    /// The problem's stable snake_case name (the `kind` of NDJSON `file_diag` records).
    pub fn kind(&self) -> &'static str {
        self.problem.kind()
    }

    /// The problem's explanation (the `msg` of NDJSON `file_diag` records).
    pub fn msg(&self) -> String {
        self.problem.to_string()
    }
}

impl fmt::Display for ReadDiag {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "@{}: {}: {}", self.offset, self.kind(), self.problem)
    }
}

/// What a capture reader found wrong in a file. Reading carries on where the format allows
/// (a damaged block is skipped to the next plausible one); the texts are the diagnostics'
/// `msg`, [`ReadProblem::kind`] their stable name.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum ReadProblem {
    /// Reading the file failed; nothing after `offset` is read.
    Io {
        /// What failed.
        kind: std::io::ErrorKind,
        /// The error's text.
        error: String,
    },
    /// The file name says one format, the content starts like another (read as the content).
    FormatMismatch {
        /// The format the name says.
        named: &'static str,
        /// The format the content is read as.
        read_as: &'static str,
    },
    /// Not a pcap or pcapng file: the magic expected at the start is not there.
    BadMagic {
        /// The first bytes found (up to 4).
        found: Vec<u8>,
    },
    /// A pcapng section header or pcap file header the parser rejects.
    BadFileHeader {
        /// pcapng (section header block) or pcap (file header).
        ng: bool,
        /// The parser's complaint.
        error: String,
    },
    /// A damaged block or record, skipped.
    Damaged {
        /// What was wrong with it.
        damage: Damage,
        /// How far reading skipped.
        skipped: Skipped,
    },
    /// A record longer than what is left of the file (a cut file).
    TruncatedRecord {
        /// Its declared length in bytes.
        expected: usize,
        /// The bytes left.
        found: usize,
    },
    /// Bytes at the end of the file too few for a record header (a cut file).
    TruncatedTail {
        /// How many.
        found: usize,
    },
    /// A link type that is neither aptscope serial nor USB: its packets are skipped.
    UnknownLinkType {
        /// The link type.
        linktype: u32,
    },
    /// A pcap serial record shorter than its 2-byte direction header.
    ShortRecord {
        /// Its length.
        found: usize,
    },
    /// A packet captured shorter than it was (snap length): the rest is lost.
    SnappedPacket {
        /// Bytes captured.
        captured: usize,
        /// Bytes on the wire.
        original: u32,
    },
    /// A pcapng packet of an interface no Interface Description Block declared.
    UnknownInterface {
        /// The interface id.
        interface: u32,
    },
    /// A problem of hex or raw input (bad hex digit …), as the dissector reports it.
    Input(aptscope_dissector::DiagKind),
    /// A problem of a text log (socat, interceptty, jpnevulator, hex dumps, hex columns).
    Log(LogProblem),
    /// A damaged record of a USB capture (usbmon, USBPcap).
    Usb(UsbProblem),
    /// A problem of an MCAP file.
    Mcap(McapProblem),
    /// What a USB device was found to be, its line settings (a note, not a damaged record).
    UsbNote(UsbNote),
}

/// What was wrong with a damaged block ([`ReadProblem::Damaged`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Damage {
    /// Its header declares a length no block can have.
    BadLength {
        /// The declared length.
        declared: usize,
    },
    /// The parser rejects it.
    Unparsable {
        /// The parser's complaint.
        error: String,
    },
}

/// How far reading skipped past a damaged block ([`ReadProblem::Damaged`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Skipped {
    /// To the next plausible record, this many bytes on.
    ToNext {
        /// Bytes skipped.
        bytes: usize,
    },
    /// To the end: no plausible record in the rest.
    ToEnd {
        /// Bytes left unread.
        rest: usize,
    },
}

impl ReadProblem {
    /// A failed read.
    pub fn io(e: &std::io::Error) -> Self {
        ReadProblem::Io {
            kind: e.kind(),
            error: e.to_string(),
        }
    }

    /// The stable snake_case name (the NDJSON `file_diag` record's `kind`).
    pub fn kind(&self) -> &'static str {
        match self {
            ReadProblem::Io { .. } => "io_error",
            ReadProblem::FormatMismatch { .. } => "format_mismatch",
            ReadProblem::BadMagic { .. } => "bad_magic",
            ReadProblem::BadFileHeader { ng: true, .. } => "bad_section_header",
            ReadProblem::BadFileHeader { ng: false, .. } => "bad_pcap_header",
            ReadProblem::Damaged {
                damage: Damage::BadLength { .. },
                ..
            } => "bad_block_length",
            ReadProblem::Damaged {
                damage: Damage::Unparsable { .. },
                ..
            } => "bad_record",
            ReadProblem::TruncatedRecord { .. } | ReadProblem::TruncatedTail { .. } => {
                "truncated_record"
            }
            ReadProblem::UnknownLinkType { .. } => "unknown_linktype",
            ReadProblem::ShortRecord { .. } => "short_record",
            ReadProblem::SnappedPacket { .. } => "snapped_packet",
            ReadProblem::UnknownInterface { .. } => "unknown_interface",
            ReadProblem::Input(k) => k.name(),
            ReadProblem::Log(p) => p.kind(),
            ReadProblem::Usb(p) => p.kind(),
            ReadProblem::Mcap(p) => p.kind(),
            ReadProblem::UsbNote(n) => n.kind(),
        }
    }
}

impl fmt::Display for ReadProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReadProblem::Io { error, .. } => f.write_str(error),
            ReadProblem::FormatMismatch { named, read_as } => write!(
                f,
                "the name says {named} but the content does not start like one; read as \
                 {read_as} (--format {named} to force)"
            ),
            ReadProblem::BadMagic { found } => {
                f.write_str("not a pcap or pcapng file (starts ")?;
                hex_bytes(f, found)?;
                f.write_str(")")
            }
            ReadProblem::BadFileHeader { error, .. } => f.write_str(error),
            ReadProblem::Damaged { damage, skipped } => {
                match damage {
                    Damage::BadLength { declared } => {
                        write!(f, "declared length {declared} is not a valid length")?
                    }
                    Damage::Unparsable { error } => f.write_str(error)?,
                }
                match skipped {
                    Skipped::ToNext { bytes } => {
                        write!(f, "; skipped {bytes} bytes to the next plausible record")
                    }
                    Skipped::ToEnd { rest } => {
                        write!(f, "; no record follows in the last {rest} bytes")
                    }
                }
            }
            ReadProblem::TruncatedRecord { expected, found } => write!(
                f,
                "record of {expected} bytes runs past the end of the file ({found} bytes left)"
            ),
            ReadProblem::TruncatedTail { found } => {
                write!(
                    f,
                    "{found} bytes at the end of the file are not a whole record"
                )
            }
            ReadProblem::UnknownLinkType { linktype } => write!(
                f,
                "link type {linktype} is neither aptscope serial (147/148) nor USB \
                 (189/220/249): its packets are skipped"
            ),
            ReadProblem::ShortRecord { .. } => {
                f.write_str("record shorter than its 2-byte direction header")
            }
            ReadProblem::SnappedPacket { captured, original } => {
                write!(
                    f,
                    "{captured} of {original} bytes captured: the rest is lost"
                )
            }
            ReadProblem::UnknownInterface { interface } => write!(
                f,
                "packet of interface {interface}, which no Interface Description Block declared"
            ),
            ReadProblem::Input(k) => write!(f, "{k}"),
            ReadProblem::Log(p) => write!(f, "{p}"),
            ReadProblem::Usb(p) => write!(f, "{p}"),
            ReadProblem::Mcap(p) => write!(f, "{p}"),
            ReadProblem::UsbNote(n) => write!(f, "{n}"),
        }
    }
}

/// The part of a text log line that could not be read ([`LogProblem::Unreadable`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogField {
    /// The hex bytes.
    Hex,
    /// The time stamp.
    Timestamp,
    /// The line as a whole: no hex bytes where its columns start.
    Line,
}

/// What a text log reader found wrong ([`ReadProblem::Log`]); the line's text is shortened to
/// its first 60 bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum LogProblem {
    /// A line longer than the reader holds: skipped.
    LineTooLong {
        /// The longest line read.
        max: usize,
    },
    /// The last line has no end of line (a cut file); what it holds is still read.
    TruncatedLine,
    /// A line that is not part of the log's format.
    GarbageLine {
        /// What was expected (`a socat dump` …).
        expected: String,
        /// The line.
        line: String,
    },
    /// Not a hex byte where one was expected.
    BadHex {
        /// Its column (from 1).
        column: usize,
        /// The text from there.
        found: String,
    },
    /// A hex-column or interceptty line whose bytes or time stamp (or the line as a whole)
    /// cannot be read.
    Unreadable {
        /// Which part.
        field: LogField,
        /// Its column (from 1).
        column: usize,
        /// The line.
        line: String,
    },
    /// An ASCII column that does not show the line's hex bytes.
    AsciiMismatch {
        /// The ASCII column.
        ascii: String,
    },
    /// A hex dump's offset is not where the lines before it end: bytes are missing.
    OffsetGap {
        /// The offset due.
        expected: u64,
        /// The offset found.
        found: u64,
    },
    /// A jpnevulator byte count is not where the lines before it end: bytes are missing.
    ByteCountGap {
        /// The count due.
        expected: u64,
        /// The count found.
        found: u64,
    },
    /// A hex dump's `*` standing for more bytes than a dump repeats: not expanded.
    RepeatTooLong {
        /// The bytes it stands for.
        bytes: u64,
        /// The most expanded.
        max: u64,
    },
    /// A hex dump's `*` that does not fit before the next line's offset.
    RepeatMisfit {
        /// The next line's offset.
        before: u64,
    },
    /// A hex dump's `*` with no line before it to repeat.
    RepeatNothing,
    /// A hex dump ending after `*`: how often the line repeats is unknown.
    TruncatedRepeat,
    /// A socat block whose bytes are not as many as its header says.
    LengthMismatch {
        /// The header's `length=`.
        expected: u64,
        /// The bytes that follow.
        found: u64,
    },
    /// A socat header whose `from=` and `to=` do not span its `length=`.
    SpanMismatch {
        /// `from=`.
        from: u64,
        /// `to=`.
        to: u64,
        /// `length=`.
        length: u64,
    },
    /// A socat header whose `from=` is not what was logged before in its direction: blocks are
    /// missing.
    SequenceGap {
        /// The bytes logged before in this direction (the `from=` due).
        expected: u64,
        /// `from=`.
        found: u64,
    },
    /// Socat hex data without a direction line before it: kept, direction unknown.
    MissingHeader,
    /// A socat direction line that cannot be read.
    BadHeader {
        /// The line.
        line: String,
    },
}

impl LogProblem {
    /// The stable snake_case name.
    pub fn kind(&self) -> &'static str {
        match self {
            LogProblem::LineTooLong { .. } => "line_too_long",
            LogProblem::TruncatedLine => "truncated_line",
            LogProblem::GarbageLine { .. }
            | LogProblem::Unreadable {
                field: LogField::Line,
                ..
            } => "garbage_line",
            LogProblem::BadHex { .. }
            | LogProblem::Unreadable {
                field: LogField::Hex,
                ..
            } => "bad_hex",
            LogProblem::Unreadable {
                field: LogField::Timestamp,
                ..
            } => "bad_timestamp",
            LogProblem::AsciiMismatch { .. } => "ascii_mismatch",
            LogProblem::OffsetGap { .. } => "offset_gap",
            LogProblem::ByteCountGap { .. } => "byte_count_gap",
            LogProblem::RepeatTooLong { .. }
            | LogProblem::RepeatMisfit { .. }
            | LogProblem::RepeatNothing => "bad_repeat",
            LogProblem::TruncatedRepeat => "truncated_repeat",
            LogProblem::LengthMismatch { .. } | LogProblem::SpanMismatch { .. } => {
                "length_mismatch"
            }
            LogProblem::SequenceGap { .. } => "sequence_gap",
            LogProblem::MissingHeader => "missing_header",
            LogProblem::BadHeader { .. } => "bad_header",
        }
    }
}

impl fmt::Display for LogProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LogProblem::LineTooLong { max } => write!(f, "line longer than {max} bytes, skipped"),
            LogProblem::TruncatedLine => {
                f.write_str("the last line has no end of line: the file was cut")
            }
            LogProblem::GarbageLine { expected, line } => {
                write!(f, "not part of {expected}: {line:?}")
            }
            LogProblem::BadHex { column, found } => {
                write!(f, "not a hex byte at column {column}: {found:?}")
            }
            LogProblem::Unreadable { column, line, .. } => {
                write!(f, "unreadable at column {column}: {line:?}")
            }
            LogProblem::AsciiMismatch { ascii } => {
                write!(f, "the ASCII column {ascii:?} does not match the hex bytes")
            }
            LogProblem::OffsetGap { expected, found } => {
                write!(f, "offset {found:#x} where {expected:#x} was due")
            }
            LogProblem::ByteCountGap { expected, found } => write!(
                f,
                "byte count {found:08X} where {expected:08X} was due: bytes are missing"
            ),
            LogProblem::RepeatTooLong { bytes, max } => write!(
                f,
                "a '*' line standing for {bytes} bytes (more than {max}); not expanded"
            ),
            LogProblem::RepeatMisfit { before } => {
                write!(f, "a '*' line that does not fit before offset {before:#x}")
            }
            LogProblem::RepeatNothing => f.write_str("a '*' line without a line to repeat"),
            LogProblem::TruncatedRepeat => {
                f.write_str("the dump ends after '*': how often the line repeats is unknown")
            }
            LogProblem::LengthMismatch { expected, found } => write!(
                f,
                "the header says length={expected} but {found} bytes follow"
            ),
            LogProblem::SpanMismatch { from, to, length } => {
                write!(f, "from={from} to={to} do not span length={length}")
            }
            LogProblem::SequenceGap { expected, found } => write!(
                f,
                "from={found} but {expected} bytes were logged before in this direction: blocks \
                 are missing"
            ),
            LogProblem::MissingHeader => {
                f.write_str("hex data without a direction line before it: kept, direction unknown")
            }
            LogProblem::BadHeader { line } => write!(f, "unreadable direction line {line:?}"),
        }
    }
}

/// The USB capture format of a record ([`UsbProblem`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UsbFormat {
    /// Linux usbmon (link types 189, 220).
    Usbmon,
    /// Windows USBPcap (link type 249).
    UsbPcap,
}

impl UsbFormat {
    fn name(self) -> &'static str {
        match self {
            UsbFormat::Usbmon => "usbmon",
            UsbFormat::UsbPcap => "USBPcap",
        }
    }
}

/// A record cut by the capture's snapshot length: what was on the wire.
struct Snap {
    record: usize,
    original: u32,
}

impl fmt::Display for Snap {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if u64::from(self.original) > self.record as u64 {
            write!(
                f,
                " (cut from {} by the capture's snapshot length)",
                self.original
            )?;
        }
        Ok(())
    }
}

/// Why a USB transfer's data is short ([`UsbProblem::TruncatedUrb`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum UrbCut {
    /// The record holds fewer data bytes than its header announces.
    Record {
        /// The format.
        format: UsbFormat,
        /// The data bytes the header announces.
        expected: u64,
        /// The data bytes the record holds.
        found: usize,
        /// The record's length.
        record: usize,
        /// The packet's length on the wire (more than `record` when the snapshot length cut
        /// it).
        original: u32,
    },
    /// usbmon captured none of the transfer's data (its data flag says why).
    NoData {
        /// The transfer's length.
        length: u32,
        /// usbmon's data flag.
        flag: u8,
    },
    /// usbmon captured fewer bytes of the transfer than it had.
    Uncaptured {
        /// The transfer's length.
        length: u32,
        /// The bytes captured.
        captured: u32,
    },
}

/// A damaged record of a USB capture ([`ReadProblem::Usb`]).
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum UsbProblem {
    /// A link type that is not USB.
    UnknownLinkType {
        /// The link type.
        linktype: u32,
    },
    /// A record shorter than its header.
    RecordTooShort {
        /// The format.
        format: UsbFormat,
        /// The header's length.
        expected: usize,
        /// The record's length.
        found: usize,
        /// The packet's length on the wire.
        original: u32,
    },
    /// A USBPcap header length below the smallest header.
    HeaderTooShort {
        /// The smallest header.
        min: usize,
        /// The length it says.
        found: usize,
    },
    /// A USBPcap control setup stage without its 8 setup bytes.
    ShortSetup {
        /// The bytes there.
        found: usize,
    },
    /// A usbmon event type other than S, C, E.
    UnknownEvent {
        /// The event type.
        found: u8,
    },
    /// A transfer type the format does not define.
    UnknownTransferType {
        /// The format.
        format: UsbFormat,
        /// The transfer type.
        found: u8,
        /// The device's bus.
        bus: u16,
        /// The device's address.
        addr: u16,
    },
    /// A transfer whose data is short: the bytes present are shown.
    TruncatedUrb {
        /// Why.
        cut: UrbCut,
        /// The device's bus.
        bus: u16,
        /// The device's address.
        addr: u16,
        /// The endpoint.
        ep: u8,
    },
}

impl UsbProblem {
    /// The stable snake_case name.
    pub fn kind(&self) -> &'static str {
        match self {
            UsbProblem::UnknownLinkType { .. } => "usb_unknown_linktype",
            UsbProblem::RecordTooShort { .. } => "usb_record_too_short",
            UsbProblem::HeaderTooShort { .. } | UsbProblem::ShortSetup { .. } => "usb_bad_header",
            UsbProblem::UnknownEvent { .. } => "usb_unknown_event",
            UsbProblem::UnknownTransferType { .. } => "usb_unknown_transfer_type",
            UsbProblem::TruncatedUrb { .. } => "truncated_urb",
        }
    }
}

impl fmt::Display for UrbCut {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            UrbCut::Record {
                format,
                expected,
                found,
                record,
                original,
            } => {
                let what = match format {
                    UsbFormat::Usbmon => "captured bytes",
                    UsbFormat::UsbPcap => "data bytes",
                };
                let snap = Snap { record, original };
                write!(
                    f,
                    "{} header announces {expected} {what}, the record holds {found}{snap}",
                    format.name()
                )
            }
            UrbCut::NoData { length, flag } => write!(
                f,
                "URB of {length} bytes whose data usbmon did not capture (data flag 0x{flag:02x})"
            ),
            UrbCut::Uncaptured { length, captured } => {
                write!(
                    f,
                    "URB of {length} bytes of which usbmon captured {captured}"
                )
            }
        }
    }
}

impl fmt::Display for UsbProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            UsbProblem::UnknownLinkType { linktype } => {
                write!(
                    f,
                    "link type {linktype} is not a USB capture (189, 220, 249)"
                )
            }
            UsbProblem::RecordTooShort {
                format,
                expected,
                found,
                original,
            } => {
                let snap = Snap {
                    record: *found,
                    original: *original,
                };
                write!(
                    f,
                    "{} record of {found} bytes{snap} is shorter than its {expected}-byte header",
                    format.name()
                )
            }
            UsbProblem::HeaderTooShort { min, found } => {
                write!(f, "USBPcap header length {found} is less than {min}")
            }
            UsbProblem::ShortSetup { found } => write!(
                f,
                "USBPcap control setup stage with {found} bytes instead of 8"
            ),
            UsbProblem::UnknownEvent { found } => {
                write!(f, "usbmon event type 0x{found:02x} is none of S, C, E")
            }
            UsbProblem::UnknownTransferType {
                format: UsbFormat::Usbmon,
                found,
                bus,
                addr,
            } => write!(
                f,
                "usbmon transfer type {found} is none of 0-3 (usb {bus}:{addr})"
            ),
            UsbProblem::UnknownTransferType {
                format: UsbFormat::UsbPcap,
                found,
                bus,
                addr,
            } => write!(
                f,
                "USBPcap transfer type 0x{found:02x} is none of 0-3, 0xfe, 0xff (usb {bus}:{addr})"
            ),
            UsbProblem::TruncatedUrb { cut, bus, addr, ep } => write!(
                f,
                "{cut} (usb {bus}:{addr} endpoint 0x{ep:02x}): the bytes present are shown"
            ),
        }
    }
}

/// Bytes in hex, separated by spaces (`89 4d 43`).
fn hex_bytes(f: &mut fmt::Formatter<'_>, bytes: &[u8]) -> fmt::Result {
    for (i, b) in bytes.iter().enumerate() {
        let sep = if i == 0 { "" } else { " " };
        write!(f, "{sep}{b:02x}")?;
    }
    Ok(())
}

/// What the MCAP reader found wrong ([`ReadProblem::Mcap`]); reading carries on at the next
/// plausible record where it can.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum McapProblem {
    /// The file does not start with the MCAP magic (records are looked for all the same).
    BadMagic {
        /// Its first bytes (up to 8); empty: the file is empty.
        found: Vec<u8>,
    },
    /// Bytes after the end magic.
    TrailingBytes,
    /// The footer is not followed by the end magic.
    BadEndMagic {
        /// The bytes left after the footer.
        left: usize,
    },
    /// The file ends without a footer (a recording cut short).
    MissingFooter {
        /// Whether the data section's end was seen.
        data_end: bool,
    },
    /// The file ends inside a record header.
    TruncatedHeader {
        /// The header's bytes there (of 9).
        found: usize,
    },
    /// A record whose length runs past the end of the file: records inside it are looked for.
    PastEnd {
        /// The record's kind (`message`, `chunk` …).
        record: &'static str,
        /// Its declared length.
        len: u64,
        /// The bytes left after its header.
        left: u64,
    },
    /// The file ends inside a record's body.
    TruncatedBody {
        /// The record's kind.
        record: &'static str,
        /// Its declared length (or what was left of a chunk to skip).
        len: u64,
        /// The bytes there.
        got: u64,
    },
    /// The file ends inside a chunk whose messages up to there were read.
    CutChunk {
        /// Where the file ends.
        end: u64,
    },
    /// An opcode MCAP reserves: not a record (a damaged one).
    BadOpcode {
        /// The opcode.
        opcode: u8,
    },
    /// A record longer than the reader accepts.
    TooLong {
        /// The record's kind.
        record: &'static str,
        /// Its declared length.
        len: u64,
        /// The largest record read.
        limit: usize,
    },
    /// A record that does not parse.
    Unparsable {
        /// The record's kind.
        record: &'static str,
        /// Whether it sits inside a chunk.
        in_chunk: bool,
        /// The parser's complaint.
        error: String,
    },
    /// A record with an application-defined opcode, skipped (said once per opcode).
    PrivateRecord {
        /// The opcode.
        opcode: u8,
        /// Its length.
        len: u64,
    },
    /// The data section's CRC does not match (said only when nothing else was found wrong).
    BadDataCrc {
        /// The CRC of the bytes read.
        calculated: u32,
        /// The CRC the data end record holds.
        saved: u32,
        /// The data end record's offset.
        before: u64,
    },
    /// A message on a channel no channel record defined (said once per channel).
    UnknownChannel {
        /// The channel id.
        channel: u16,
    },
    /// A chunk header inconsistent with the record's length.
    BadChunkHeader,
    /// A chunk whose CRC does not match.
    BadChunkCrc {
        /// The CRC of its data.
        calculated: u32,
        /// The CRC it holds.
        saved: u32,
    },
    /// A chunk compressed with something this reader lacks: skipped.
    UnsupportedCompression {
        /// The compression's name.
        compression: String,
    },
    /// A chunk that cannot be read further.
    BadChunk {
        /// The reader's complaint.
        error: String,
    },
    /// Bytes skipped looking for the next record.
    Skipped {
        /// How many.
        bytes: u64,
        /// The next record's offset; `None`: none up to the end of the file.
        next: Option<u64>,
    },
}

impl McapProblem {
    /// The stable snake_case name.
    pub fn kind(&self) -> &'static str {
        match self {
            McapProblem::BadMagic { .. } => "bad_magic",
            McapProblem::TrailingBytes => "trailing_bytes",
            McapProblem::BadEndMagic { .. } => "bad_end_magic",
            McapProblem::MissingFooter { .. } => "missing_footer",
            McapProblem::TruncatedHeader { .. }
            | McapProblem::PastEnd { .. }
            | McapProblem::TruncatedBody { .. }
            | McapProblem::CutChunk { .. } => "truncated_record",
            McapProblem::BadOpcode { .. }
            | McapProblem::TooLong { .. }
            | McapProblem::Unparsable { .. } => "bad_record",
            McapProblem::PrivateRecord { .. } => "private_record",
            McapProblem::BadDataCrc { .. } => "bad_data_crc",
            McapProblem::UnknownChannel { .. } => "unknown_channel",
            McapProblem::BadChunkHeader | McapProblem::BadChunk { .. } => "bad_chunk",
            McapProblem::BadChunkCrc { .. } => "bad_chunk_crc",
            McapProblem::UnsupportedCompression { .. } => "unsupported_compression",
            McapProblem::Skipped { .. } => "skipped_bytes",
        }
    }
}

impl fmt::Display for McapProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            McapProblem::BadMagic { found } if found.is_empty() => {
                f.write_str("the file is empty, not MCAP")
            }
            McapProblem::BadMagic { found } => {
                f.write_str("the file starts with ")?;
                hex_bytes(f, found)?;
                f.write_str(", not the MCAP magic 89 4d 43 41 50 30 0d 0a; looking for records")
            }
            McapProblem::TrailingBytes => f.write_str("bytes after the MCAP end magic (ignored)"),
            McapProblem::BadEndMagic { left } => write!(
                f,
                "the footer is not followed by the MCAP magic ({left} byte(s) left)"
            ),
            McapProblem::MissingFooter { data_end } => {
                let what = if *data_end {
                    "after the data section, without summary footer"
                } else {
                    "without data end, summary or footer"
                };
                write!(
                    f,
                    "the file ends {what}: the recording was probably cut short; everything \
                     before was read"
                )
            }
            McapProblem::TruncatedHeader { found } => write!(
                f,
                "the file ends {found} byte(s) into a record header (9 bytes)"
            ),
            McapProblem::PastEnd { record, len, left } => write!(
                f,
                "{record} record of {len} bytes runs past the end of the file ({left} bytes \
                 left); looking for records inside it"
            ),
            McapProblem::TruncatedBody { record, len, got } => write!(
                f,
                "{record} record of {len} bytes: the file ends after {got} of them"
            ),
            McapProblem::CutChunk { end } => write!(
                f,
                "the file ends at offset {end}, inside this chunk; its messages up to there \
                 were read"
            ),
            McapProblem::BadOpcode { opcode } => write!(
                f,
                "opcode 0x{opcode:02x} is not an MCAP record; looking for the next record"
            ),
            McapProblem::TooLong { record, len, limit } => write!(
                f,
                "{record} record claims {len} bytes (limit {limit}); looking for the next record"
            ),
            McapProblem::Unparsable {
                record,
                in_chunk,
                error,
            } => {
                let within = if *in_chunk { " in the chunk" } else { "" };
                write!(f, "{record} record{within} does not parse: {error}")
            }
            McapProblem::PrivateRecord { opcode, len } => write!(
                f,
                "record with private opcode 0x{opcode:02x} ({len} bytes) skipped (reported once \
                 per opcode)"
            ),
            McapProblem::BadDataCrc {
                calculated,
                saved,
                before,
            } => write!(
                f,
                "the data section's CRC is {calculated:08x}, the file says {saved:08x}: some \
                 bytes before offset {before} are damaged"
            ),
            McapProblem::UnknownChannel { channel } => write!(
                f,
                "message on channel {channel} which no channel record defined (skipped)"
            ),
            McapProblem::BadChunkHeader => f.write_str(
                "chunk header is inconsistent with the record length; looking for the next record",
            ),
            McapProblem::BadChunkCrc { calculated, saved } => write!(
                f,
                "chunk CRC is {calculated:08x}, the chunk says {saved:08x}: its messages (read \
                 above) may be damaged"
            ),
            McapProblem::UnsupportedCompression { compression } => write!(
                f,
                "chunk compressed with {compression:?}, which this reader lacks: skipped"
            ),
            McapProblem::BadChunk { error } => {
                write!(f, "chunk cannot be read further: {error}")
            }
            McapProblem::Skipped { bytes, next: None } => write!(
                f,
                "{bytes} byte(s) skipped: no MCAP record found up to the end of the file"
            ),
            McapProblem::Skipped {
                bytes,
                next: Some(at),
            } => write!(
                f,
                "{bytes} byte(s) skipped up to the next record at offset {at}"
            ),
        }
    }
}

/// A device of a USB capture ([`UsbNote::DeviceNotFound`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct UsbDevice {
    /// Its bus.
    pub bus: u16,
    /// Its address.
    pub addr: u16,
    /// Its vendor and product ids, when a device descriptor is in the capture.
    pub ids: Option<(u16, u16)>,
}

/// What the USB demultiplexer found out about a device or a port, and which of its traffic it
/// shows ([`ReadProblem::UsbNote`]): notes, not damage.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum UsbNote {
    /// `--usb-device` named a device that sent no serial data (the command line makes it an
    /// error): which devices the capture has.
    DeviceNotFound {
        /// The device's bus.
        bus: u16,
        /// The device's address.
        addr: u16,
        /// Whether it is in the capture at all.
        in_capture: bool,
        /// The devices present, in order.
        present: Vec<UsbDevice>,
    },
    /// More devices than the demultiplexer follows: this one and later new ones are ignored.
    TooManyDevices {
        /// The most it follows.
        max: usize,
        /// The device's bus.
        bus: u16,
        /// The device's address.
        addr: u16,
    },
    /// A device with no descriptor and no bulk IN data whose bulk OUT data is shown as FTDI.
    Unconfirmed {
        /// The device's bus.
        bus: u16,
        /// The device's address.
        addr: u16,
        /// The bytes OUT after which it was decided; `None`: at the end of the capture.
        after: Option<usize>,
    },
    /// A device whose descriptor changed (another device at the same address).
    DeviceChanged {
        /// The device's bus.
        bus: u16,
        /// The device's address.
        addr: u16,
        /// Vendor and product ids before.
        was: (u16, u16),
        /// Vendor and product ids now.
        now: (u16, u16),
    },
    /// A device already shown whose descriptor came late and confirms it.
    Identified {
        /// The device's bus.
        bus: u16,
        /// The device's address.
        addr: u16,
        /// Its vendor and product ids.
        ids: (u16, u16),
    },
    /// A device already shown whose descriptor came late and says it is not FTDI: no longer
    /// shown.
    NotFtdi {
        /// The device's bus.
        bus: u16,
        /// The device's address.
        addr: u16,
        /// Its vendor and product ids.
        ids: (u16, u16),
    },
    /// A device without descriptor whose bulk IN data lacks FTDI status bytes: not shown.
    NoStatusBytes {
        /// The device's bus.
        bus: u16,
        /// The device's address.
        addr: u16,
        /// The data's first byte.
        first: u8,
    },
    /// No endpoint descriptor and no status bytes every 64 bytes: 512-byte packets assumed.
    MaxPacketInferred {
        /// The device's bus.
        bus: u16,
        /// The device's address.
        addr: u16,
        /// The endpoint.
        ep: u8,
    },
    /// A port's line settings, now (set by vendor requests).
    LineSettings {
        /// The stream's name.
        stream: String,
        /// The settings (`115200 8N1 RTS/CTS`); `None`: unknown.
        settings: Option<String>,
    },
}

impl UsbNote {
    /// The stable snake_case name.
    pub fn kind(&self) -> &'static str {
        match self {
            UsbNote::DeviceNotFound { .. } => crate::usb::NOT_FOUND,
            UsbNote::TooManyDevices { .. } => "usb_too_many_devices",
            UsbNote::Unconfirmed { .. } => "usb_unconfirmed_device",
            UsbNote::DeviceChanged { .. } => "usb_device_changed",
            UsbNote::Identified { .. } => "usb_device_identified",
            UsbNote::NotFtdi { .. } | UsbNote::NoStatusBytes { .. } => "usb_not_ftdi",
            UsbNote::MaxPacketInferred { .. } => "usb_max_packet_inferred",
            UsbNote::LineSettings { .. } => "line_settings",
        }
    }
}

impl fmt::Display for UsbNote {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            UsbNote::DeviceNotFound {
                bus,
                addr,
                in_capture,
                present,
            } => {
                let why = if *in_capture {
                    "is in the capture but sent no serial data"
                } else {
                    "is not in the capture"
                };
                write!(f, "--usb-device {bus}:{addr}: usb {bus}:{addr} {why}; ")?;
                if present.is_empty() {
                    return f.write_str("the capture has no USB bulk or control transfers");
                }
                f.write_str("devices present: ")?;
                for (i, UsbDevice { bus, addr, ids }) in present.iter().enumerate() {
                    let sep = if i == 0 { "" } else { ", " };
                    write!(f, "{sep}{bus}:{addr} (")?;
                    match ids {
                        Some((FTDI_VID, pid)) => write!(f, "{FTDI_VID:04x}:{pid:04x}, FTDI)")?,
                        Some((vid, pid)) => write!(f, "{vid:04x}:{pid:04x})")?,
                        None => f.write_str("no descriptor in the capture)")?,
                    }
                }
                Ok(())
            }
            UsbNote::TooManyDevices { max, bus, addr } => write!(
                f,
                "more than {max} USB devices: usb {bus}:{addr} and later new devices are ignored"
            ),
            UsbNote::Unconfirmed {
                bus,
                addr,
                after: None,
            } => write!(
                f,
                "usb {bus}:{addr} has no device descriptor and no bulk IN data in the capture: \
                 its bulk OUT data is shown as if it were an FTDI device"
            ),
            UsbNote::Unconfirmed {
                bus,
                addr,
                after: Some(n),
            } => write!(
                f,
                "usb {bus}:{addr} has no device descriptor and no bulk IN data after {n} bytes \
                 OUT: shown as if it were an FTDI device"
            ),
            UsbNote::DeviceChanged {
                bus,
                addr,
                was,
                now,
            } => write!(
                f,
                "usb {bus}:{addr} was {:04x}:{:04x}, is now {:04x}:{:04x}",
                was.0, was.1, now.0, now.1
            ),
            UsbNote::Identified { bus, addr, ids } => write!(
                f,
                "usb {bus}:{addr} is {:04x}:{:04x}: its stream continues",
                ids.0, ids.1
            ),
            UsbNote::NotFtdi { bus, addr, ids } => write!(
                f,
                "usb {bus}:{addr} is {:04x}:{:04x}: not an FTDI device: its traffic is no \
                 longer shown",
                ids.0, ids.1
            ),
            UsbNote::NoStatusBytes { bus, addr, first } => write!(
                f,
                "usb {bus}:{addr} (no device descriptor in the capture) sends bulk IN data that \
                 does not start with FTDI status bytes (0x{first:02x}): not shown"
            ),
            UsbNote::MaxPacketInferred { bus, addr, ep } => write!(
                f,
                "usb {bus}:{addr} endpoint 0x{ep:02x}: no endpoint descriptor in the capture and \
                 no FTDI status bytes every 64 bytes: assuming 512-byte (high-speed) packets"
            ),
            UsbNote::LineSettings { stream, settings } => {
                write!(f, "{stream}: {}", settings.as_deref().unwrap_or("unknown"))
            }
        }
    }
}
