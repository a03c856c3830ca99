//! The data model of the message table: what one `msg`, `sub`, `form` and field is.
//!
//! This file depends on `std` only: the build script includes it (with `parse.rs`) to check
//! the table at compile time.

use std::sync::OnceLock;

/// Who sends a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dir {
    /// Host → device (SET, REQ, MOVE and other commands).
    HostToDevice,
    /// Device → host (GET, status updates, completions, errors).
    DeviceToHost,
    /// Either side may send it.
    Both,
}

impl Dir {
    /// The short name used in the table files and JSON (`h2d`, `d2h`, `both`).
    pub fn as_str(self) -> &'static str {
        match self {
            Dir::HostToDevice => "h2d",
            Dir::DeviceToHost => "d2h",
            Dir::Both => "both",
        }
    }
}

/// A scalar type of a field or of an array's elements.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Prim {
    /// Unsigned byte.
    U8,
    /// Signed byte.
    I8,
    /// Unsigned 16-bit little-endian ("word").
    U16,
    /// Signed 16-bit little-endian ("short").
    I16,
    /// Unsigned 32-bit little-endian ("dword").
    U32,
    /// Signed 32-bit little-endian ("long").
    I32,
    /// IEEE-754 single precision, little-endian.
    F32,
}

impl Prim {
    /// Width in bytes.
    #[inline]
    pub fn width(self) -> usize {
        match self {
            Prim::U8 | Prim::I8 => 1,
            Prim::U16 | Prim::I16 => 2,
            Prim::U32 | Prim::I32 | Prim::F32 => 4,
        }
    }
    /// Name as written in the table files.
    pub fn as_str(self) -> &'static str {
        match self {
            Prim::U8 => "u8",
            Prim::I8 => "i8",
            Prim::U16 => "u16",
            Prim::I16 => "i16",
            Prim::U32 => "u32",
            Prim::I32 => "i32",
            Prim::F32 => "f32",
        }
    }
    /// Whether the type is a signed integer.
    pub fn signed(self) -> bool {
        matches!(self, Prim::I8 | Prim::I16 | Prim::I32)
    }
    fn from_name(s: &str) -> Option<Prim> {
        Some(match s {
            "u8" => Prim::U8,
            "i8" => Prim::I8,
            "u16" => Prim::U16,
            "i16" => Prim::I16,
            "u32" => Prim::U32,
            "i32" => Prim::I32,
            "f32" => Prim::F32,
            _ => return None,
        })
    }
}

/// The type of a field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ty {
    /// One scalar.
    Prim(Prim),
    /// `N` scalars in a row.
    Array(Prim, u16),
    /// Zero-padded ASCII text of `N` bytes.
    Str(u16),
    /// Opaque bytes.
    Bytes(u16),
    /// Reserved bytes.
    Pad(u16),
}

impl Ty {
    /// Width in bytes.
    #[inline]
    pub fn width(self) -> usize {
        match self {
            Ty::Prim(p) => p.width(),
            Ty::Array(p, n) => p.width() * n as usize,
            Ty::Str(n) | Ty::Bytes(n) | Ty::Pad(n) => n as usize,
        }
    }
    /// Parse a type name as written in the table (`u16`, `str[16]`, `i32[4]`).
    pub fn parse(s: &str) -> Option<Ty> {
        if let Some(p) = Prim::from_name(s) {
            return Some(Ty::Prim(p));
        }
        let (base, rest) = s.split_once('[')?;
        // `TYPE[*]`: as many elements as the data packet holds (the last field of an open form).
        if rest == "*]" {
            return Some(Ty::Array(Prim::from_name(base)?, 0));
        }
        let n: u16 = rest.strip_suffix(']')?.parse().ok()?;
        if n == 0 {
            return None;
        }
        Some(match base {
            "str" => Ty::Str(n),
            "bytes" => Ty::Bytes(n),
            "pad" => Ty::Pad(n),
            b => Ty::Array(Prim::from_name(b)?, n),
        })
    }
    /// The name as written in the table.
    pub fn name(self) -> String {
        match self {
            Ty::Prim(p) => p.as_str().to_string(),
            Ty::Array(p, 0) => format!("{}[*]", p.as_str()),
            Ty::Array(p, n) => format!("{}[{n}]", p.as_str()),
            Ty::Str(n) => format!("str[{n}]"),
            Ty::Bytes(n) => format!("bytes[{n}]"),
            Ty::Pad(n) => format!("pad[{n}]"),
        }
    }
}

/// Where a field lives in the frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Loc {
    /// Header byte 2 (param1).
    P1,
    /// Header byte 3 (param2).
    P2,
    /// Offset from the first byte of the data packet (frame byte 6).
    Data(u16),
}

impl Loc {
    /// Offset of the field's first byte from the start of the frame.
    #[inline]
    pub fn frame_offset(self) -> usize {
        match self {
            Loc::P1 => 2,
            Loc::P2 => 3,
            Loc::Data(o) => 6 + o as usize,
        }
    }
}

/// One field of a form.
#[derive(Debug, Clone)]
pub struct Field {
    /// snake_case name; the JSON key and the filter name.
    pub name: &'static str,
    /// Position.
    pub loc: Loc,
    /// Type.
    pub ty: Ty,
    /// Unit of the scaled value.
    pub unit: Option<&'static str>,
    /// Physical value = raw × scale.
    pub scale: Option<f64>,
    /// Index into [`TableData::enums`].
    pub enumeration: Option<usize>,
    /// Index into [`TableData::flags`].
    pub flags: Option<usize>,
    /// The motion quantity the raw value is (`q=`): converted to mm or degrees once the stage
    /// is known (spec section 8).
    pub q: Option<Quantity>,
    /// A percentage of the device's maximum (`pct_of=`): in volts or micrometres once the device
    /// has reported that maximum.
    pub pct_of: Option<Maximum>,
    /// The device's maximum itself (`max_of=`), in the field's scaled unit.
    pub max_of: Option<Maximum>,
}

/// [`MsgDef::data_form`] of one length: the form, none, or the walk of the forms.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct DataForm(pub(crate) u8);

impl DataForm {
    /// No form takes this length (and no `sub` form might).
    pub(crate) const NONE: DataForm = DataForm(0xFF);
    /// Walk the forms: a `sub` form comes first (or there are too many forms to say).
    pub(crate) const WALK: DataForm = DataForm(0xFE);
    /// The position of the data or open form that takes this length, when it is one.
    #[inline]
    pub(crate) fn form(self) -> Option<usize> {
        (self.0 < 0x80).then_some(usize::from(self.0))
    }
}

/// A device maximum that percentages refer to (piezo controllers: the output voltage limit of
/// PZ_GET_OUTPUTMAXVOLTS, the travel of PZ_GET_MAXTRAVEL).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Maximum {
    /// The maximum output voltage, in V.
    Volts,
    /// The maximum travel, in µm.
    Travel,
}

impl Maximum {
    /// The name used in the table (`volts`, `travel`).
    pub fn as_str(self) -> &'static str {
        match self {
            Maximum::Volts => "volts",
            Maximum::Travel => "travel",
        }
    }
    /// The physical unit of a value converted with this maximum.
    pub fn unit(self) -> &'static str {
        match self {
            Maximum::Volts => "V",
            Maximum::Travel => "um",
        }
    }
    /// Parse a table name.
    pub fn parse(s: &str) -> Option<Maximum> {
        match s {
            "volts" => Some(Maximum::Volts),
            "travel" => Some(Maximum::Travel),
            _ => None,
        }
    }
}

/// What a motion field's raw value is, in the controller's own units (`q=` in the table).
///
/// How raw values relate to physical ones depends on the controller family and the stage
/// (spec section 8, "Conversion between position, velocity and acceleration values"): see
/// `crate::units`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Quantity {
    /// A position or distance: encoder counts (servo) or microsteps (stepper).
    Pos,
    /// A speed stated in position units per second (the spec's worked example for the pot
    /// parameters gives 3430 counts/s = 0.1 mm/s).
    PosPerSec,
    /// A velocity parameter in the controller's velocity units (section 8: VELAPT).
    Vel,
    /// An acceleration parameter in the controller's acceleration units (section 8: ACCAPT).
    Acc,
    /// A jerk parameter in the controller's jerk units (MOT_SET_PMDPROFILEMODEPARAMS).
    Jerk,
}

impl Quantity {
    /// Every quantity.
    pub const ALL: [Quantity; 5] = [
        Quantity::Pos,
        Quantity::PosPerSec,
        Quantity::Vel,
        Quantity::Acc,
        Quantity::Jerk,
    ];
    /// The name used by `q=` in the table (`pos`, `pos/s`, `vel`, `acc`, `jerk`).
    pub fn as_str(self) -> &'static str {
        match self {
            Quantity::Pos => "pos",
            Quantity::PosPerSec => "pos/s",
            Quantity::Vel => "vel",
            Quantity::Acc => "acc",
            Quantity::Jerk => "jerk",
        }
    }
    /// The `unit=` a field with this quantity carries: what the raw value honestly is.
    pub fn raw_unit(self) -> &'static str {
        match self {
            Quantity::Pos => "counts",
            Quantity::PosPerSec => "counts/s",
            Quantity::Vel => "vel_units",
            Quantity::Acc => "acc_units",
            Quantity::Jerk => "jerk_units",
        }
    }
    /// Parse a `q=` value.
    pub fn parse(s: &str) -> Option<Quantity> {
        Quantity::ALL.into_iter().find(|q| q.as_str() == s)
    }
}

/// Which bytes a form covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FormKind {
    /// The 6-byte header-only form.
    Header,
    /// A data packet of exactly this many bytes.
    Data(u16),
    /// The data packet is one of the message's sub-messages.
    Sub,
    /// A data packet of at least this many bytes: the fixed fields, then as many elements of
    /// the last field (`TYPE[*]`) as the packet holds (`form 8+`).
    Open(u16),
}

/// One length a message exists in, and its fields.
#[derive(Debug, Clone)]
pub struct Form {
    /// Header-only, a data length, or sub-message.
    pub kind: FormKind,
    /// Which variant this is, as the table says ("short version").
    pub note: &'static str,
    /// Fields in order.
    pub fields: Vec<Field>,
    /// What per-frame code asks of every form, worked out once when the table is built.
    pub(crate) idx: FormIdx,
    /// How to read each field that is not `pad`, in order (set by [`Form::index`]): the
    /// decoder's field loop reads these 12 bytes per field instead of the whole [`Field`].
    pub(crate) reads: Vec<FieldRead>,
}

/// How one field's value is read from a frame, worked out when the table is built.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FieldRead {
    /// Position of the field in its form's `fields`.
    pub(crate) field: u16,
    /// Offset of the field's first byte from the start of the frame.
    pub(crate) start: u32,
    /// Width in bytes (for the open array, that of one element).
    pub(crate) width: u32,
    /// What the bytes are.
    pub(crate) kind: ReadKind,
}

/// The kind of a [`FieldRead`]: one flat match per field instead of `Ty` then `Prim`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ReadKind {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    F32,
    /// An array of a fixed number of elements.
    Array(Prim),
    /// The open array ending an open form (`TYPE[*]`): the whole elements left in the frame.
    Open(Prim),
    Str,
    Bytes,
}

impl FieldRead {
    /// The read of field `i`, `f`; `None` for `pad` (never given out as a value).
    fn of(i: usize, f: &Field) -> Option<FieldRead> {
        let kind = match f.ty {
            Ty::Prim(Prim::U8) => ReadKind::U8,
            Ty::Prim(Prim::I8) => ReadKind::I8,
            Ty::Prim(Prim::U16) => ReadKind::U16,
            Ty::Prim(Prim::I16) => ReadKind::I16,
            Ty::Prim(Prim::U32) => ReadKind::U32,
            Ty::Prim(Prim::I32) => ReadKind::I32,
            Ty::Prim(Prim::F32) => ReadKind::F32,
            Ty::Array(p, 0) => ReadKind::Open(p),
            Ty::Array(p, _) => ReadKind::Array(p),
            Ty::Str(_) => ReadKind::Str,
            Ty::Bytes(_) => ReadKind::Bytes,
            Ty::Pad(_) => return None,
        };
        let width = match kind {
            ReadKind::Open(p) => p.width(),
            _ => f.ty.width(),
        };
        Some(FieldRead {
            field: u16::try_from(i).ok()?,
            start: u32::try_from(f.loc.frame_offset()).ok()?,
            width: u32::try_from(width).ok()?,
            kind,
        })
    }
}

/// Per-form facts read for every frame (set by [`Form::index`]): looking them up by field name
/// on each frame was most of the pairing and units cost.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct FormIdx {
    /// Position of `chan_ident` in `fields`.
    chan: Option<u16>,
    /// The frame offset of `chan_ident` when it is a `u16` (every form of the table): the
    /// decoder reads it so without the field's type and place.
    chan_u16_at: Option<u16>,
    /// Position of `sub_id` in `fields`.
    sub: Option<u16>,
    /// A field converts to physical units (`q=`, `pct_of=`, `max_of=`).
    units: bool,
    /// A field reports a device maximum (`max_of=`).
    maxima: bool,
    /// The largest data packet of the form's message ([`Table::max_data_len`]); 0 until set.
    ///
    /// [`Table::max_data_len`]: crate::table::Table::max_data_len
    pub(crate) max_data: u16,
}

impl Form {
    /// Work out [`FormIdx`] (after the fields are final).
    pub(crate) fn index(&mut self) {
        let at = |name: &str| {
            self.fields
                .iter()
                .position(|f| f.name == name)
                .and_then(|i| u16::try_from(i).ok())
        };
        let chan = at("chan_ident");
        let chan_field = chan.and_then(|i| self.fields.get(usize::from(i)));
        self.idx = FormIdx {
            chan,
            chan_u16_at: chan_field
                .filter(|f| f.ty == Ty::Prim(Prim::U16))
                .and_then(|f| u16::try_from(f.loc.frame_offset()).ok()),
            sub: at("sub_id"),
            units: self
                .fields
                .iter()
                .any(|x| x.q.is_some() || x.pct_of.is_some() || x.max_of.is_some()),
            maxima: self.fields.iter().any(|x| x.max_of.is_some()),
            // Set by the table (`Table::from_sources`), which knows the messages' `maxlen=`.
            max_data: 0,
        };
        let fields = self.fields.iter().enumerate();
        self.reads = fields.filter_map(|(i, f)| FieldRead::of(i, f)).collect();
    }
    /// The `chan_ident` field, if the form has one.
    #[inline]
    pub fn chan_field(&self) -> Option<&Field> {
        self.fields.get(usize::from(self.idx.chan?))
    }
    /// The frame offset of the `chan_ident` field when the form has one and it is a `u16`.
    #[inline]
    pub(crate) fn chan_u16_at(&self) -> Option<usize> {
        self.idx.chan_u16_at.map(usize::from)
    }
    /// The `sub_id` field, if the form has one.
    #[inline]
    pub fn sub_field(&self) -> Option<&Field> {
        self.fields.get(usize::from(self.idx.sub?))
    }
    /// Whether a field converts to physical units (`q=`, `pct_of=`, `max_of=`).
    #[inline]
    pub fn has_units(&self) -> bool {
        self.idx.units
    }
    /// Whether a field reports a device maximum (`max_of=`).
    #[inline]
    pub fn has_maxima(&self) -> bool {
        self.idx.maxima
    }
    /// `hdr`, the data length (`14`), or `sub`: how listings and `--form` name the form.
    pub fn label(&self) -> String {
        match self.kind {
            FormKind::Header => "hdr".into(),
            FormKind::Data(n) => n.to_string(),
            FormKind::Sub => "sub".into(),
            FormKind::Open(n) => format!("{n}+"),
        }
    }
    /// Width of one element of the open array ending an open form.
    pub fn open_elem(&self) -> Option<usize> {
        match self.fields.last()?.ty {
            Ty::Array(p, 0) => Some(p.width()),
            _ => None,
        }
    }
    /// Whether a data packet of `len` bytes fits this open form (`max`: the message's largest).
    pub fn open_fits(&self, len: usize, max: usize) -> bool {
        match (self.kind, self.open_elem()) {
            (FormKind::Open(n), Some(w)) => {
                len >= n as usize && len <= max && (len - n as usize).is_multiple_of(w)
            }
            _ => false,
        }
    }
    /// The largest data packet of this form's message: the spec's 255 bytes, or its `maxlen=`
    /// (for a sub-message's form, the largest of its group's messages).
    #[inline]
    pub fn max_data_len(&self) -> usize {
        usize::from(self.idx.max_data)
    }
    /// The length rule of forms, the one decoding matches frames to forms by and encoding
    /// builds by: whether a frame with (`has_data`) or without a data packet of `len` bytes is
    /// of this form. Header-only: no data packet; `LEN`: exactly `LEN` bytes; `LEN+`: `LEN`
    /// and whole elements of the open array, up to [`max_data_len`](Self::max_data_len).
    /// `sub` is a placeholder: its sub-messages' forms say (see `Table::accepts_len`).
    #[inline]
    pub fn accepts_len(&self, has_data: bool, len: usize) -> bool {
        match self.kind {
            FormKind::Header => !has_data,
            FormKind::Data(n) => has_data && usize::from(n) == len,
            FormKind::Open(_) => has_data && self.open_fits(len, self.max_data_len()),
            FormKind::Sub => false,
        }
    }
    /// The data packet length of a frame of this form whose open array (if it has one) holds
    /// `elems` elements; `None` when no such frame exists: a `sub` placeholder, elements given
    /// to a closed form, or a packet beyond [`max_data_len`](Self::max_data_len). What
    /// `encode` builds; [`accepts_len`](Self::accepts_len) accepts every `Some`.
    pub fn encoded_len(&self, elems: usize) -> Option<usize> {
        match self.kind {
            FormKind::Header | FormKind::Data(_) if elems > 0 => None,
            FormKind::Header => Some(0),
            FormKind::Data(n) => Some(usize::from(n)),
            FormKind::Sub => None,
            FormKind::Open(n) => elems
                .checked_mul(self.open_elem()?)
                .and_then(|x| x.checked_add(usize::from(n)))
                .filter(|&len| len <= self.max_data_len()),
        }
    }
}

/// A byte string from the spec with the values it should decode to.
#[derive(Debug, Clone)]
pub struct Example {
    /// The bytes as printed in the spec (hex pairs with commas/spaces).
    pub hex: &'static str,
    /// `(field, value)` pairs the spec states; empty for a bad example.
    pub checks: Vec<(&'static str, &'static str)>,
    /// For a spec example known to be wrong: why.
    pub bad_reason: Option<&'static str>,
    /// Where it is in the table files.
    pub file: &'static str,
    /// Line number in that file.
    pub line: usize,
}

/// One APT message.
#[derive(Debug, Clone)]
pub struct MsgDef {
    /// Message id.
    pub id: u16,
    /// Name without `MGMSG_`.
    pub name: &'static str,
    /// Who sends it.
    pub dir: Dir,
    /// Messages that answer or complete it (besides the automatic REQ_x → GET_x).
    pub reply: Vec<&'static str>,
    /// Sub-message group, when the data packet starts with a sub-message id.
    pub subs: Option<&'static str>,
    /// Which revisions of the spec define it ([`Revs`]).
    pub revs: Revs,
    /// Largest data packet (`maxlen=`), for the messages that break the spec's 255-byte rule.
    pub max_len: Option<u16>,
    /// Behaviour classes (`class=` in the table).
    pub class: Class,
    /// How long its reply may take (`timeout=`); `None`: [`DEFAULT_TIMEOUT_MS`].
    pub timeout_ms: Option<u32>,
    /// One-line description.
    pub doc: &'static str,
    /// Every length the message exists in.
    pub forms: Vec<Form>,
    /// Position in `forms` of the first header-only form (what a frame without data packet
    /// decodes as), set when the table is built.
    pub(crate) hdr_form: Option<u8>,
    /// Per data packet length up to 255, set when the table is built: which form a frame with
    /// a data packet of that length decodes as, so that most frames take it without walking the
    /// forms. See [`DataForm`].
    pub(crate) data_form: [DataForm; 256],
    /// Spec examples.
    pub examples: Vec<Example>,
    /// Table file it is defined in.
    pub file: &'static str,
    /// Line in that file.
    pub line: usize,
}

/// The reply timeout of a message without `timeout=`: the spec gives none; requests are answered
/// within milliseconds.
pub const DEFAULT_TIMEOUT_MS: u32 = 2000;

/// What a message does, as pairing, replay safety and the simulators need to know it (`class=`
/// in the table, a comma-separated set).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Class(pub u8);

impl Class {
    /// Sent periodically or on request as a status stream: never "unsolicited".
    pub const STATUS: Class = Class(1);
    /// Sent by the device on its own (errors, button presses, disconnect): never "unsolicited".
    pub const SPONTANEOUS: Class = Class(2);
    /// Makes hardware move or changes an output (replay asks before sending it to a real port).
    pub const MOTION: Class = Class(4);
    /// Reports the end of a move (a message it answers started one).
    pub const END_OF_MOVE: Class = Class(8);
    /// Stops a move.
    pub const STOP: Class = Class(16);
    /// A reading of the device's state outside a status stream (a position counter): the
    /// terminal UI's plot draws it beside the status messages.
    pub const READING: Class = Class(32);
    const NAMES: [(Class, &'static str); 6] = [
        (Class::STATUS, "status"),
        (Class::SPONTANEOUS, "spontaneous"),
        (Class::MOTION, "motion"),
        (Class::END_OF_MOVE, "end_of_move"),
        (Class::STOP, "stop"),
        (Class::READING, "reading"),
    ];
    /// Parse a `class=` value (`motion`, `status,spontaneous`).
    pub fn parse(s: &str) -> Option<Class> {
        let mut c = 0;
        for p in s.split(',') {
            c |= Class::NAMES.iter().find(|(_, n)| *n == p)?.0 .0;
        }
        Some(Class(c))
    }
    /// Whether every class of `other` is in this set.
    pub fn has(self, other: Class) -> bool {
        self.0 & other.0 == other.0 && other.0 != 0
    }
    /// The names of the classes in the set.
    pub fn names(self) -> Vec<&'static str> {
        Class::NAMES
            .iter()
            .filter(|(c, _)| self.has(*c))
            .map(|(_, n)| *n)
            .collect()
    }
}

/// A set of revisions of the APT spec (`rev=` in the table; both when absent).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Revs(pub u8);

impl Revs {
    /// Issue 23, 21 August 2018.
    pub const ISSUE_23: Revs = Revs(1);
    /// The revision dated 9 December 2025.
    pub const REV_2025: Revs = Revs(2);
    /// Both revisions.
    pub const BOTH: Revs = Revs(3);
    /// Parse a `rev=` value: `23`, `2025` or `23,2025`.
    pub fn parse(s: &str) -> Option<Revs> {
        let mut r = 0;
        for p in s.split(',') {
            r |= match p {
                "23" => 1,
                "2025" => 2,
                _ => return None,
            };
        }
        (r != 0).then_some(Revs(r))
    }
    /// Whether `other`'s revisions are all in this set.
    pub fn contains(self, other: Revs) -> bool {
        self.0 & other.0 == other.0
    }
    /// The names of the revisions, as listings show them (`["23", "2025"]`).
    pub fn names(self) -> Vec<&'static str> {
        let mut v = vec![];
        if self.0 & 1 != 0 {
            v.push("23");
        }
        if self.0 & 2 != 0 {
            v.push("2025");
        }
        v
    }
}

/// One sub-message of a group (LA_, TEC_, QUAD_, PZMOT_ … PARAMS).
#[derive(Debug, Clone)]
pub struct SubDef {
    /// Group name (`la`, `tec`, …).
    pub group: &'static str,
    /// Sub-message id.
    pub id: u16,
    /// Name.
    pub name: &'static str,
    /// One-line description.
    pub doc: &'static str,
    /// Forms (each covering the whole data packet, `sub_id` first).
    pub forms: Vec<Form>,
    /// Spec examples (full frames of any message of the group).
    pub examples: Vec<Example>,
    /// Table file.
    pub file: &'static str,
    /// Line.
    pub line: usize,
}

/// An enumeration: value → label.
#[derive(Debug, Clone)]
pub struct EnumDef {
    /// Name referenced by `enum=`.
    pub name: &'static str,
    /// Values and labels.
    pub items: Vec<(i64, &'static str)>,
}

impl EnumDef {
    /// The label of a value.
    pub fn label(&self, v: i64) -> Option<&'static str> {
        self.items.iter().find(|(x, _)| *x == v).map(|(_, l)| *l)
    }
    /// The value of a label.
    pub fn value(&self, label: &str) -> Option<i64> {
        self.items
            .iter()
            .find(|(_, l)| l.eq_ignore_ascii_case(label))
            .map(|(v, _)| *v)
    }
}

/// A set of bit flags: mask → label.
#[derive(Debug, Clone)]
pub struct FlagsDef {
    /// Name referenced by `flags=`.
    pub name: &'static str,
    /// Masks and labels.
    pub items: Vec<(u64, &'static str)>,
    /// When the masks are distinct single bits (64 at most): for each byte of a value and
    /// each value of that byte, the items its bits set, as bits by item index; so that
    /// [`FlagsDef::set`] visits the items a value sets, not every item. Worked out on first
    /// use (the items are read line by line).
    pub(crate) by_byte: OnceLock<Option<Box<ByByte>>>,
}

/// See [`FlagsDef::by_byte`].
pub(crate) type ByByte = [[u64; 256]; 8];

impl FlagsDef {
    /// Flags named `name` with these items.
    pub fn new(name: &'static str, items: Vec<(u64, &'static str)>) -> Self {
        FlagsDef {
            name,
            items,
            by_byte: OnceLock::new(),
        }
    }

    /// The items (mask, label) whose mask's bits are all set in `x`, in the items' order.
    pub fn set(&self, x: u64) -> SetFlags<'_> {
        let by_byte = self.by_byte.get_or_init(|| {
            let mut all = 0u64;
            let mut t = Box::new([[0u64; 256]; 8]);
            for (i, (m, _)) in self.items.iter().enumerate() {
                if !m.is_power_of_two() || all & m != 0 || i >= 64 {
                    return None;
                }
                all |= m;
                let bit = m.trailing_zeros() as usize;
                for (v, items) in t[bit / 8].iter_mut().enumerate() {
                    if v >> (bit % 8) & 1 == 1 {
                        *items |= 1 << i;
                    }
                }
            }
            Some(t)
        });
        match by_byte {
            Some(t) => {
                let mut items = 0;
                for (k, byte) in x.to_le_bytes().into_iter().enumerate() {
                    if byte != 0 {
                        items |= t[k][usize::from(byte)];
                    }
                }
                SetFlags {
                    def: self,
                    walk: true,
                    x: items,
                    next: 0,
                }
            }
            None => SetFlags {
                def: self,
                walk: false,
                x,
                next: 0,
            },
        }
    }

    /// The mask of a label.
    pub fn mask(&self, label: &str) -> Option<u64> {
        self.items
            .iter()
            .find(|(_, l)| l.eq_ignore_ascii_case(label))
            .map(|(m, _)| *m)
    }
}

/// The iterator of [`FlagsDef::set`].
pub struct SetFlags<'a> {
    def: &'a FlagsDef,
    /// Whether `x` is the items set, by index ([`FlagsDef::by_byte`]), not yet visited;
    /// otherwise the value, its items tested in turn from `next`.
    pub(crate) walk: bool,
    x: u64,
    next: usize,
}

impl<'a> Iterator for SetFlags<'a> {
    type Item = &'a (u64, &'static str);

    #[inline]
    fn next(&mut self) -> Option<Self::Item> {
        if self.walk {
            if self.x == 0 {
                return None;
            }
            let i = self.x.trailing_zeros() as usize;
            self.x &= self.x - 1;
            return self.def.items.get(i);
        }
        loop {
            let item = self.def.items.get(self.next)?;
            self.next += 1;
            if self.x & item.0 == item.0 {
                return Some(item);
            }
        }
    }
}

/// A `devices` block: controller models and the messages they implement (one of the spec's
/// "Messages Applicable to …" lists).
#[derive(Debug, Clone)]
pub struct DeviceGroup {
    /// Model names as the spec writes them; a lower-case `x` stands for any character
    /// (`BSC20x`, `KLSxxx`).
    pub models: Vec<&'static str>,
    /// Which part of the spec says so.
    pub source: DeviceSource,
    /// Message names.
    pub msgs: Vec<&'static str>,
    /// Messages these models end without the reply the table names for them (`silent`).
    pub silent: Vec<&'static str>,
    /// Table file.
    pub file: &'static str,
    /// Line.
    pub line: usize,
}

/// Where the spec says which models take a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeviceSource {
    /// A "Messages Applicable to …" list (`devices` block): what a model implements.
    List,
    /// A message section's own "applicable only to …" sentence (`section` block): adds to the
    /// lists of the models it names (the lists often leave such messages out).
    Section,
}

impl DeviceGroup {
    /// Whether a model string (as HW_GET_INFO reports it) is one of this group's models.
    pub fn matches(&self, model: &str) -> bool {
        self.matches_trimmed(model.trim())
    }

    /// [`Self::matches`] of a model already trimmed (a device's model is checked against every
    /// group: trimmed once, not once per group).
    pub fn matches_trimmed(&self, model: &str) -> bool {
        self.models.iter().any(|m| fits(m, model))
    }
}

/// Whether `model` (from a device) fits the spec's model `pattern` (`x` = any character).
pub fn model_matches(pattern: &str, model: &str) -> bool {
    fits(pattern, model.trim())
}

/// [`model_matches`] of a model already trimmed (trimmed once, not once per pattern: a
/// device's HW_GET_INFO is checked against every pattern of the table).
fn fits(pattern: &str, model: &str) -> bool {
    pattern.len() == model.len()
        && pattern
            .bytes()
            .zip(model.bytes())
            .all(|(p, m)| p == b'x' || p.eq_ignore_ascii_case(&m))
}

/// Everything the table files define.
#[derive(Debug, Clone, Default)]
pub struct TableData {
    /// Messages, in file order.
    pub msgs: Vec<MsgDef>,
    /// Sub-messages, in file order.
    pub subs: Vec<SubDef>,
    /// Enumerations.
    pub enums: Vec<EnumDef>,
    /// Flag sets.
    pub flags: Vec<FlagsDef>,
    /// Which messages each controller model implements.
    pub devices: Vec<DeviceGroup>,
}
