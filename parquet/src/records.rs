//! The `records` table's rows in plain vectors, one per column, turned into Arrow arrays when
//! the row group is taken. The kind tables' columns are known only at run time
//! ([`crate::buf::TableBuf`] picks each value's conversion by the column's type, through Arrow's
//! builders); these are fixed, so a row is one inlined push onto each column's vector. Measured
//! (callgrind, 114,823 records of a status log): 1,764 instructions a row instead of 2,014
//! through the builders (docs/performance.md, "Parquet, fourth pass"). Arrow's own builders
//! row by row, without the per-value choice, were slower still (2,150): a null through them
//! costs as much as a value.

use crate::schema::records_schema;
use crate::words::{self, Words};
use aptscope_dissector::diag::Diag;
use arrow_array::builder::{ArrayBuilder, StringBuilder};
use arrow_array::types::{
    Float64Type, Int64Type, TimestampNanosecondType, UInt16Type, UInt32Type, UInt64Type, UInt8Type,
};
use arrow_array::{
    ArrayRef, ArrowPrimitiveType, BinaryArray, ListArray, PrimitiveArray, RecordBatch, StringArray,
    StructArray,
};
use arrow_buffer::{NullBuffer, OffsetBuffer, ScalarBuffer};
use arrow_schema::{ArrowError, DataType, FieldRef, SchemaRef};
use std::fmt::{self, Write as _};
use std::sync::Arc;

/// Validity of a column's rows: kept from the first null on, as the bitmap Arrow takes (64
/// rows a word; a vector of `bool` packed when taken was 2.7 % of the rows' instructions).
#[derive(Default)]
pub(crate) struct Valid {
    /// `None` while every row has a value.
    words: Option<Vec<u64>>,
    rows: usize,
}

impl Valid {
    #[inline(always)]
    pub(crate) fn push(&mut self, valid: bool) {
        match &mut self.words {
            Some(w) => {
                let bit = self.rows % 64;
                if bit == 0 {
                    w.push(0);
                }
                if let Some(last) = w.last_mut() {
                    *last |= u64::from(valid) << bit;
                }
            }
            None if valid => {}
            None => self.first_null(),
        }
        self.rows += 1;
    }

    /// The first null: the rows before it had values.
    #[cold]
    fn first_null(&mut self) {
        let mut w = Vec::with_capacity((self.rows.max(64) * 2).div_ceil(64));
        w.resize(self.rows / 64, u64::MAX);
        let bit = self.rows % 64;
        if bit > 0 {
            // The rows of this word before the null are valid; the null's bit stays clear.
            w.push(u64::MAX >> (64 - bit));
        } else {
            w.push(0);
        }
        self.words = Some(w);
    }

    pub(crate) fn take(&mut self) -> Option<NullBuffer> {
        let rows = std::mem::take(&mut self.rows);
        self.words.take().map(|mut w| {
            // Arrow's bitmaps are bytes, least significant bit first.
            w.iter_mut().for_each(|x| *x = x.to_le());
            let buf = arrow_buffer::Buffer::from_vec(w);
            NullBuffer::new(arrow_buffer::BooleanBuffer::new(buf, 0, rows))
        })
    }
}

/// `len` bytes of zeros: a slice of one buffer the whole process shares (grown when a longer
/// one is asked for), so that columns of nulls touch no memory of their own.
fn zeros(len: usize) -> arrow_buffer::Buffer {
    static ZEROS: std::sync::Mutex<Option<arrow_buffer::Buffer>> = std::sync::Mutex::new(None);
    let mut z = ZEROS
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let b = match z.as_ref().filter(|b| b.len() >= len) {
        Some(b) => b.clone(),
        None => {
            // Of u64: aligned for every column's values.
            let words = vec![0u64; len.div_ceil(8).max(1 << 13)];
            z.insert(arrow_buffer::Buffer::from_vec(words)).clone()
        }
    };
    b.slice_with_length(0, len)
}

/// A column of `rows` nulls of type `dt` whose validity, values and offsets are [`zeros`]:
/// a raw capture's times, a status log's pairing, a kind table's unused fields cost no pages
/// (each page of Python's tables is a fault, a third of `to_arrow()`'s time); other types as
/// Arrow makes them.
///
/// A column of nulls of a type is a slice of the longest one made of that type: Arrow checks
/// every offset of a column of text it is given (120,000 instructions for a row group's), and
/// the same columns are null in every row group.
pub(crate) fn nulls(dt: &DataType, rows: usize) -> Result<ArrayRef, ArrowError> {
    static MADE: std::sync::Mutex<Vec<ArrayRef>> = std::sync::Mutex::new(Vec::new());
    let mut made = MADE
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let at = made.iter().position(|a| a.data_type() == dt);
    if let Some(a) = at.map(|i| &made[i]).filter(|a| a.len() >= rows) {
        return Ok(a.slice(0, rows));
    }
    let a = new_nulls(dt, rows.max(1 << 13))?;
    match at {
        Some(i) => made[i] = a.clone(),
        None => made.push(a.clone()),
    }
    Ok(a.slice(0, rows))
}

/// A column of `rows` nulls made anew (see [`nulls`]).
fn new_nulls(dt: &DataType, rows: usize) -> Result<ArrayRef, ArrowError> {
    let valid = NullBuffer::new(arrow_buffer::BooleanBuffer::new(
        zeros(rows.div_ceil(8)),
        0,
        rows,
    ));
    let b = arrow_data::ArrayDataBuilder::new(dt.clone())
        .len(rows)
        .nulls(Some(valid));
    let b = match dt {
        DataType::Utf8 | DataType::Binary => b.buffers(vec![
            zeros((rows + 1) * 4),
            arrow_buffer::Buffer::from_vec(Vec::<u8>::new()),
        ]),
        DataType::List(item) => b
            .buffers(vec![zeros((rows + 1) * 4)])
            .child_data(vec![arrow_data::ArrayData::new_empty(item.data_type())]),
        _ => match dt.primitive_width() {
            Some(w) => b.buffers(vec![zeros(rows * w)]),
            None => return Ok(arrow_array::new_null_array(dt, rows)),
        },
    };
    Ok(arrow_array::make_array(b.build()?))
}

/// The texts [`repeated_text`] keeps at most, and their columns' bytes at most beside the
/// last asked for: a capture's name and a few words (`apt`, `frame`, `d2h`…) at once, not the
/// names of every capture a notebook read (a long path's column of a row group is several
/// MB); the one asked for least recently goes first.
const REPEATED_TEXTS: usize = 16;
/// See [`REPEATED_TEXTS`].
const REPEATED_BYTES: usize = 16 << 20;

/// `text` in each of `rows` rows: a slice of one column of it repeated, shared by every table
/// and row group of the same text (the `file` column of Python's tables, 18 MB of the 10 MB
/// status log's tables, in pages of their own for every row group before; and columns of one
/// word, [`TextWords`]). Grown when more rows are asked for; the process keeps
/// [`REPEATED_TEXTS`] texts' columns at most, of [`REPEATED_BYTES`] (the last asked for kept
/// whatever its size).
pub(crate) fn repeated_text(text: &str, rows: usize) -> ArrayRef {
    use arrow_array::Array;
    static MADE: std::sync::Mutex<Vec<StringArray>> = std::sync::Mutex::new(Vec::new());
    let mut made = MADE
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let at = made.iter().position(|a| a.value(0) == text);
    let a = match at.map(|i| made.remove(i)).filter(|a| a.len() >= rows) {
        Some(a) => a,
        None => {
            let n = rows.max(1 << 13);
            let mut b = StringBuilder::with_capacity(n, n * text.len());
            b.append_value_n(text, n);
            b.finish()
        }
    };
    let slice = Arc::new(a.slice(0, rows));
    made.push(a);
    let bytes = |m: &[StringArray]| m.iter().map(|a| a.get_buffer_memory_size()).sum::<usize>();
    while made.len() > 1 && (made.len() > REPEATED_TEXTS || bytes(&made) > REPEATED_BYTES) {
        made.remove(0);
    }
    slice
}

/// A column of numbers. The values of null rows are written only once a value follows them
/// (or when the column is taken): a column of nulls alone is [`nulls`], not pages of zeros
/// written one row at a time.
struct Num<T: ArrowPrimitiveType> {
    vals: Vec<T::Native>,
    valid: Valid,
}

impl<T: ArrowPrimitiveType> Num<T> {
    fn new(cap: usize) -> Self {
        Num {
            vals: Vec::with_capacity(cap),
            valid: Valid::default(),
        }
    }

    /// Empty, with room for `rows` values.
    fn again(&self, rows: usize) -> Self {
        Self::new(rows)
    }

    /// Rows put.
    fn len(&self) -> usize {
        self.valid.rows
    }

    #[inline(always)]
    fn push(&mut self, v: Option<T::Native>) {
        if let Some(x) = v {
            if self.vals.len() < self.valid.rows {
                self.fill();
            }
            self.vals.push(x);
        }
        self.valid.push(v.is_some());
    }

    /// The null rows' values, up to the rows put.
    #[cold]
    fn fill(&mut self) {
        self.vals.resize(self.valid.rows, T::Native::default());
    }

    fn take(&mut self, dt: &DataType) -> Result<ArrayRef, ArrowError> {
        if self.vals.is_empty() && self.valid.rows > 0 {
            let rows = self.valid.rows;
            self.valid.take();
            return nulls(dt, rows);
        }
        self.fill();
        let vals = ScalarBuffer::from(std::mem::take(&mut self.vals));
        let a = PrimitiveArray::<T>::new(vals, self.valid.take()).with_data_type(dt.clone());
        Ok(Arc::new(a))
    }
}

/// A column of text or bytes: the values one after the other, and where each ends (the ends of
/// null rows written only once a value follows them, as [`Num`]'s values).
struct Bytes {
    data: Vec<u8>,
    ends: Vec<i32>,
    valid: Valid,
}

impl Bytes {
    fn new(cap: usize, bytes_each: usize) -> Self {
        let mut ends = Vec::with_capacity(cap + 1);
        ends.push(0);
        Bytes {
            data: Vec::with_capacity(cap * bytes_each),
            ends,
            valid: Valid::default(),
        }
    }

    /// Empty, with room for `rows` values and their bytes in the measure of this one's.
    fn again(&self, rows: usize) -> Self {
        let held = self.valid.rows;
        let mut b = Bytes::new(rows, 0);
        b.data.reserve(scale(self.data.len(), rows, held));
        b
    }

    #[inline(always)]
    fn push(&mut self, v: Option<&[u8]>) {
        self.valid.push(v.is_some());
        if let Some(v) = v {
            self.data.extend_from_slice(v);
            self.end();
        }
    }

    /// End the value written into `data` since the last (its row put as valid).
    #[inline(always)]
    fn end(&mut self) {
        if self.ends.len() < self.valid.rows {
            self.fill(self.valid.rows);
        }
        // Under 2 GiB a row group: `CaptureWriter::new` bounds its bytes and rows.
        self.ends.push(self.data.len() as i32);
    }

    /// The ends of the null rows before row `n`: where the last value ended.
    #[cold]
    fn fill(&mut self, n: usize) {
        let last = self.ends.last().copied().unwrap_or(0);
        self.ends.resize(n, last);
    }

    #[inline(always)]
    fn text(&mut self, v: Option<&str>) {
        self.push(v.map(str::as_bytes))
    }

    /// The offsets and values, and the validity; empty afterwards.
    fn parts(&mut self) -> (OffsetBuffer<i32>, arrow_buffer::Buffer, Option<NullBuffer>) {
        self.fill(self.valid.rows + 1);
        let ends = std::mem::replace(&mut self.ends, vec![0]);
        let data = std::mem::take(&mut self.data);
        (
            OffsetBuffer::new(ScalarBuffer::from(ends)),
            arrow_buffer::Buffer::from_vec(data),
            self.valid.take(),
        )
    }

    /// Nulls alone, as [`nulls`] of type `dt` (the column is then empty).
    fn only_nulls(&mut self, dt: &DataType) -> Option<Result<ArrayRef, ArrowError>> {
        let rows = self.valid.rows;
        if self.ends.len() > 1 || rows == 0 {
            return None;
        }
        self.valid.take();
        Some(nulls(dt, rows))
    }

    fn take_text(&mut self) -> Result<ArrayRef, ArrowError> {
        if let Some(a) = self.only_nulls(&DataType::Utf8) {
            return a;
        }
        let (o, d, n) = self.parts();
        Ok(Arc::new(StringArray::try_new(o, d, n)?))
    }

    fn take_bytes(&mut self) -> Result<ArrayRef, ArrowError> {
        if let Some(a) = self.only_nulls(&DataType::Binary) {
            return a;
        }
        let (o, d, n) = self.parts();
        Ok(Arc::new(BinaryArray::try_new(o, d, n)?))
    }
}

/// Whether two words are the same: the same text at the same address (words from the tables
/// mostly are) without comparing it.
#[inline(always)]
fn same(a: Option<&str>, b: Option<&str>) -> bool {
    match (a, b) {
        (Some(a), Some(b)) => std::ptr::eq(a, b) || a == b,
        (a, b) => a.is_none() && b.is_none(),
    }
}

/// A column of words: numbers in the row group's set of words, as the Parquet writer takes
/// them, or their text, as readers of batches (Python) get them: built straight into a text
/// column, rather than turned into text afterwards by Arrow's `take` (which was 13 % of
/// building the rows Python gets).
enum WordCol {
    Keys(Box<Words>),
    Text(TextWords),
}

/// A column of words as text, its rows kept unwritten while they are all one word (or all
/// null): a capture's `proto`, mostly its `type`, a one-way log's `dir`, a device's units and
/// channel in its kind tables are such columns, and taken as [`repeated_text`] or [`nulls`]
/// they cost no pages of their own (each page of Python's tables is a fault, a third of
/// `to_arrow()`'s time).
pub(crate) struct TextWords {
    b: StringBuilder,
    /// The word of every row so far and their count, none of them in `b`; `None` once two
    /// rows differed (every row is then in `b`).
    same: Option<(Option<&'static str>, usize)>,
}

impl TextWords {
    pub(crate) fn new(rows: usize, bytes: usize) -> Self {
        Self::over(StringBuilder::with_capacity(rows, bytes))
    }

    /// Empty, in builder `b` (empty) and its room.
    pub(crate) fn over(b: StringBuilder) -> Self {
        TextWords {
            b,
            same: Some((None, 0)),
        }
    }

    /// Rows put, and bytes of their text.
    pub(crate) fn held(&self) -> (usize, usize) {
        match self.same {
            Some((w, n)) => (n, n * w.map_or(0, str::len)),
            None => (self.b.len(), self.b.values_slice().len()),
        }
    }

    #[inline(always)]
    pub(crate) fn push(&mut self, w: Option<&'static str>) {
        match &mut self.same {
            Some((s, n)) if same(*s, w) || *n == 0 => {
                *s = w;
                *n += 1;
            }
            Some(_) => {
                self.spill();
                self.b.append_option(w);
            }
            None => self.b.append_option(w),
        }
    }

    /// `n` nulls.
    pub(crate) fn push_nulls(&mut self, n: usize) {
        match &mut self.same {
            Some((None, k)) => *k += n,
            Some((_, 0)) => self.same = Some((None, n)),
            Some(_) => {
                self.spill();
                self.b.append_nulls(n);
            }
            None => self.b.append_nulls(n),
        }
    }

    /// A word that is not `'static`.
    pub(crate) fn push_text(&mut self, w: &str) {
        self.spill();
        self.b.append_value(w);
    }

    /// A text that is not a word: `v` displayed.
    pub(crate) fn push_fmt(&mut self, v: &dyn fmt::Display) {
        self.spill();
        let _ = write!(self.b, "{v}");
        self.b.append_value("");
    }

    /// Empty, with room for `rows` rows and their text in the measure of what this one wrote
    /// (rows kept unwritten take none).
    pub(crate) fn again(&self, rows: usize) -> Self {
        let held = self.held().0;
        TextWords::new(rows, scale(self.b.values_slice().len(), rows, held))
    }

    /// Write the rows kept unwritten: they are no longer all one word.
    #[cold]
    fn spill(&mut self) {
        if let Some((w, n)) = self.same.take() {
            match w {
                Some(w) => self.b.append_value_n(w, n),
                None => self.b.append_nulls(n),
            }
        }
    }

    /// The first `n` rows of `other` (rows of this one, which has none yet).
    #[cold]
    fn copy_rows(&mut self, other: &TextWords, n: usize) {
        if let Some((w, _)) = other.same {
            self.same = Some((w, n));
            return;
        }
        self.spill();
        let b = &other.b;
        let (ends, data, nulls) = (b.offsets_slice(), b.values_slice(), b.validity_slice());
        for i in 0..n {
            let valid = nulls.is_none_or(|v| v[i / 8] & (1 << (i % 8)) != 0);
            let (s, e) = (ends[i] as usize, ends[i + 1] as usize);
            match std::str::from_utf8(&data[s..e]) {
                Ok(t) if valid => self.b.append_value(t),
                _ => self.b.append_null(),
            }
        }
    }

    pub(crate) fn take(&mut self) -> Result<ArrayRef, ArrowError> {
        match self.same.replace((None, 0)) {
            Some((_, 0)) | None => Ok(Arc::new(self.b.finish())),
            Some((Some(w), n)) => Ok(repeated_text(w, n)),
            Some((None, n)) => nulls(&DataType::Utf8, n),
        }
    }
}

impl WordCol {
    fn new(cap: usize, text: bool) -> Self {
        if text {
            WordCol::Text(TextWords::new(cap, cap * 8))
        } else {
            WordCol::Keys(Box::new(Words::new(cap)))
        }
    }

    /// Empty, with room for `rows` words (and their text in the measure of this one's).
    fn again(&self, rows: usize) -> Self {
        match self {
            WordCol::Keys(_) => WordCol::Keys(Box::new(Words::new(rows))),
            WordCol::Text(t) => WordCol::Text(t.again(rows)),
        }
    }

    #[inline(always)]
    fn push(&mut self, w: Option<&'static str>) {
        match self {
            WordCol::Keys(k) => k.push(w),
            WordCol::Text(t) => t.push(w),
        }
    }

    /// A word that is not `'static`.
    fn push_text(&mut self, w: &str) {
        match self {
            WordCol::Keys(k) => k.push_text(w),
            WordCol::Text(t) => t.push_text(w),
        }
    }

    fn take(&mut self) -> Result<ArrayRef, ArrowError> {
        match self {
            WordCol::Keys(k) => k.take(),
            WordCol::Text(t) => t.take(),
        }
    }
}

/// `n` things of `held` rows scaled to `rows` rows (the bytes of text to make room for).
pub(crate) fn scale(n: usize, rows: usize, held: usize) -> usize {
    n.saturating_mul(rows) / held.max(1)
}

/// The `records` table's columns of words (message, kind and diagnostic names, directions…).
const WORDS: [&str; 8] = [
    "file",
    "dir",
    "proto",
    "type",
    "name",
    "sub",
    "kind",
    "diagnostics.kind",
];

/// The schema of the batches: the table's, with its columns of words as dictionaries unless
/// `text`.
fn batch_schema(text: bool) -> SchemaRef {
    static S: std::sync::OnceLock<SchemaRef> = std::sync::OnceLock::new();
    if text {
        records_schema()
    } else {
        S.get_or_init(|| Arc::new(words::words_schema(&records_schema(), &WORDS)))
            .clone()
    }
}

/// One `records` row: each column's value, `None` for null (`file` is the writer's, `time`
/// is `ts_ns`).
#[derive(Default)]
pub struct Row<'a> {
    pub stream: Option<u32>,
    pub n: Option<u64>,
    pub ts_ns: Option<u64>,
    pub rel_s: Option<f64>,
    pub dir: Option<&'static str>,
    pub proto: Option<&'static str>,
    pub ty: &'static str,
    pub offset: Option<u64>,
    pub msgid: Option<u16>,
    pub name: Option<&'static str>,
    pub sub: Option<&'static str>,
    pub code: Option<&'a str>,
    pub kind: Option<&'static str>,
    pub src: Option<u8>,
    pub dst: Option<u8>,
    pub channel: Option<i64>,
    pub len: Option<u32>,
    pub raw: Option<&'a [u8]>,
    pub pair: Option<u64>,
    pub latency_ms: Option<f64>,
    pub refn: Option<u64>,
    pub detail: Option<&'a str>,
}

/// The rows of the `records` table not yet written.
pub struct RecordsBuf {
    schema: SchemaRef,
    /// Words as text ([`WordCol`]).
    text: bool,
    file: Arc<str>,
    rows: usize,
    /// Rows it was made with room for.
    room: usize,
    stream: Num<UInt32Type>,
    n: Num<UInt64Type>,
    ts_ns: Num<UInt64Type>,
    time: Num<TimestampNanosecondType>,
    rel_s: Num<Float64Type>,
    dir: WordCol,
    proto: WordCol,
    ty: WordCol,
    offset: Num<UInt64Type>,
    msgid: Num<UInt16Type>,
    name: WordCol,
    sub: WordCol,
    code: Bytes,
    kind: WordCol,
    /// Rows so far whose kind is their name (all, or `None`), not written in `kind`: the
    /// column is then the `name` column's array itself (text words only; an APT frame's kind
    /// table is its message's name).
    kind_is_name: Option<usize>,
    src: Num<UInt8Type>,
    dst: Num<UInt8Type>,
    channel: Num<Int64Type>,
    len: Num<UInt32Type>,
    raw: Bytes,
    /// Where each row's diagnostics end among the elements below.
    diag_ends: Vec<i32>,
    diag_kind: WordCol,
    diag_offset: Num<UInt64Type>,
    /// As words: most diagnostics' messages are a fixed text
    /// ([`aptscope_dissector::diag::DiagKind::fixed_text`]).
    diag_msg: TextWords,
    pair: Num<UInt64Type>,
    latency_ms: Num<Float64Type>,
    refn: Num<UInt64Type>,
    detail: Bytes,
}

impl RecordsBuf {
    /// An empty buffer for the records of capture `file`, with room for `cap` rows; its
    /// columns of words as text when `words_as_text` ([`crate::Options::words_as_text`]).
    pub fn new(file: Arc<str>, cap: usize, words_as_text: bool) -> Self {
        let text = || Bytes::new(cap, 8);
        let words = || WordCol::new(cap, words_as_text);
        let mut diag_ends = Vec::with_capacity(cap + 1);
        diag_ends.push(0);
        RecordsBuf {
            schema: batch_schema(words_as_text),
            text: words_as_text,
            file,
            rows: 0,
            room: cap,
            stream: Num::new(cap),
            n: Num::new(cap),
            ts_ns: Num::new(cap),
            time: Num::new(cap),
            rel_s: Num::new(cap),
            dir: words(),
            proto: words(),
            ty: words(),
            offset: Num::new(cap),
            msgid: Num::new(cap),
            name: words(),
            sub: words(),
            code: text(),
            kind: words(),
            kind_is_name: words_as_text.then_some(0),
            src: Num::new(cap),
            dst: Num::new(cap),
            channel: Num::new(cap),
            len: Num::new(cap),
            raw: Bytes::new(cap, 16),
            diag_ends,
            diag_kind: words(),
            diag_offset: Num::new(cap),
            diag_msg: TextWords::new(cap, cap * 32),
            pair: Num::new(cap),
            latency_ms: Num::new(cap),
            refn: Num::new(cap),
            detail: text(),
        }
    }

    /// Rows buffered.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Rows it was made with room for.
    pub fn room(&self) -> usize {
        self.room
    }

    /// Bytes of the columns of unbounded length buffered: raw bytes, diagnostics' messages,
    /// details (the others are a few names of at most a few dozen bytes a row).
    pub fn bytes(&self) -> usize {
        self.raw.data.len() + self.diag_msg.held().1 + self.detail.data.len()
    }

    /// One diagnostic of the row being made (before its [`Self::push`]), of any kind and
    /// message (the tests'; the writer's are [`Self::diagnostic`]).
    #[cfg(test)]
    pub fn diag(&mut self, kind: &'static str, offset: u64, msg: &dyn fmt::Display) {
        self.diag_kind.push(Some(kind));
        self.diag_rest(offset, msg);
    }

    /// Diagnostic `d` of the row being made (before its [`Self::push`]): its message as a word
    /// when it is a fixed text (a status log's "reply without a pending command", in four rows
    /// of five, was 14 MB of Python's tables written; a shared column of it now).
    pub fn diagnostic(&mut self, d: &Diag) {
        self.diag_kind.push(Some(d.kind.name()));
        self.diag_offset.push(Some(d.offset));
        match d.kind.fixed_text() {
            Some(t) => self.diag_msg.push(Some(t)),
            None => self.diag_msg.push_fmt(&d.kind),
        }
    }

    /// A diagnostic whose kind is not `'static` (a capture file's, held back).
    pub fn diag_text(&mut self, kind: &str, offset: u64, msg: &dyn fmt::Display) {
        self.diag_kind.push_text(kind);
        self.diag_rest(offset, msg);
    }

    fn diag_rest(&mut self, offset: u64, msg: &dyn fmt::Display) {
        self.diag_offset.push(Some(offset));
        self.diag_msg.push_fmt(msg);
    }

    /// Append `r`, and the diagnostics given since the last row.
    #[inline(always)]
    pub fn push(&mut self, r: &Row<'_>) {
        self.stream.push(r.stream);
        self.n.push(r.n);
        self.ts_ns.push(r.ts_ns);
        self.time.push(r.ts_ns.and_then(|t| i64::try_from(t).ok()));
        self.rel_s.push(r.rel_s);
        self.dir.push(r.dir);
        self.proto.push(r.proto);
        self.ty.push(Some(r.ty));
        self.offset.push(r.offset);
        self.msgid.push(r.msgid);
        self.name.push(r.name);
        self.sub.push(r.sub);
        self.code.text(r.code);
        match &mut self.kind_is_name {
            Some(n) if same(r.kind, r.name) => *n += 1,
            Some(_) => self.kind_apart(r.kind),
            None => self.kind.push(r.kind),
        }
        self.src.push(r.src);
        self.dst.push(r.dst);
        self.channel.push(r.channel);
        self.len.push(r.len);
        self.raw.push(r.raw);
        self.diag_ends.push(self.diag_offset.len() as i32);
        self.pair.push(r.pair);
        self.latency_ms.push(r.latency_ms);
        self.refn.push(r.refn);
        self.detail.text(r.detail);
        self.rows += 1;
    }

    /// The first row whose kind is not its name: the rows before it written in `kind`.
    #[cold]
    fn kind_apart(&mut self, kind: Option<&'static str>) {
        let n = self.kind_is_name.take().unwrap_or(0);
        if let (WordCol::Text(k), WordCol::Text(name)) = (&mut self.kind, &self.name) {
            k.copy_rows(name, n);
        }
        self.kind.push(kind);
    }

    /// Empty, with room for `rows` rows, and for their text and diagnostics in the measure of
    /// what this one holds (see [`Self::take`]); as [`Self::new`] when it holds none.
    pub(crate) fn again(&self, rows: usize) -> Self {
        let held = self.rows;
        if held == 0 {
            return RecordsBuf::new(self.file.clone(), rows, self.text);
        }
        let diags = scale(self.diag_offset.len(), rows, held);
        let mut diag_ends = Vec::with_capacity(rows + 1);
        diag_ends.push(0);
        RecordsBuf {
            schema: self.schema.clone(),
            text: self.text,
            file: self.file.clone(),
            rows: 0,
            room: rows,
            stream: self.stream.again(rows),
            n: self.n.again(rows),
            ts_ns: self.ts_ns.again(rows),
            time: self.time.again(rows),
            rel_s: self.rel_s.again(rows),
            dir: self.dir.again(rows),
            proto: self.proto.again(rows),
            ty: self.ty.again(rows),
            offset: self.offset.again(rows),
            msgid: self.msgid.again(rows),
            name: self.name.again(rows),
            sub: self.sub.again(rows),
            code: self.code.again(rows),
            kind: self.kind.again(rows),
            kind_is_name: self.text.then_some(0),
            src: self.src.again(rows),
            dst: self.dst.again(rows),
            channel: self.channel.again(rows),
            len: self.len.again(rows),
            raw: self.raw.again(rows),
            diag_ends,
            diag_kind: self.diag_kind.again(diags),
            diag_offset: self.diag_offset.again(diags),
            diag_msg: self.diag_msg.again(diags),
            pair: self.pair.again(rows),
            latency_ms: self.latency_ms.again(rows),
            refn: self.refn.again(rows),
            detail: self.detail.again(rows),
        }
    }

    /// The buffered rows as a batch; the buffer is empty afterwards, with room for `room` rows
    /// and their text in the measure of these ([`crate::Options::batches_kept`] says how many
    /// and why).
    pub fn take(&mut self, room: usize) -> Result<RecordBatch, ArrowError> {
        let rows = self.rows;
        let mut b = self.again(room);
        std::mem::swap(self, &mut b);
        let s = b.schema.clone();
        // By name: the vector below is in schema order, the types are the schema's.
        let dt = |name: &str| s.field_with_name(name).map(|f| f.data_type());
        let name = b.name.take()?;
        let kind = match b.kind_is_name {
            Some(_) => name.clone(),
            None => b.kind.take()?,
        };
        let cols: Vec<ArrayRef> = vec![
            if self.text {
                repeated_text(&self.file, rows)
            } else {
                words::repeated(&self.file, rows)
            },
            b.stream.take(dt("stream")?)?,
            b.n.take(dt("n")?)?,
            b.ts_ns.take(dt("ts_ns")?)?,
            b.time.take(dt("time")?)?,
            b.rel_s.take(dt("rel_s")?)?,
            b.dir.take()?,
            b.proto.take()?,
            b.ty.take()?,
            b.offset.take(dt("offset")?)?,
            b.msgid.take(dt("msgid")?)?,
            name,
            b.sub.take()?,
            b.code.take_text()?,
            kind,
            b.src.take(dt("src")?)?,
            b.dst.take(dt("dst")?)?,
            b.channel.take(dt("channel")?)?,
            b.len.take(dt("len")?)?,
            b.raw.take_bytes()?,
            b.take_diags(dt("diagnostics")?)?,
            b.pair.take(dt("pair")?)?,
            b.latency_ms.take(dt("latency_ms")?)?,
            b.refn.take(dt("ref")?)?,
            b.detail.take_text()?,
        ];
        RecordBatch::try_new(s, cols)
    }

    /// The diagnostics column: a list of `(kind, offset, msg)` per row.
    fn take_diags(&mut self, dt: &DataType) -> Result<ArrayRef, ArrowError> {
        let DataType::List(item) = dt else {
            return Err(ArrowError::SchemaError(format!("diagnostics: {dt}")));
        };
        let DataType::Struct(fields) = item.data_type() else {
            return Err(ArrowError::SchemaError(format!("diagnostics: {dt}")));
        };
        let u64_type = DataType::UInt64;
        let parts = vec![
            self.diag_kind.take()?,
            self.diag_offset.take(&u64_type)?,
            self.diag_msg.take()?,
        ];
        let elements = StructArray::try_new(fields.clone(), parts, None)?;
        let ends = std::mem::replace(&mut self.diag_ends, vec![0]);
        let item: FieldRef = item.clone();
        Ok(Arc::new(ListArray::try_new(
            item,
            OffsetBuffer::new(ScalarBuffer::from(ends)),
            Arc::new(elements),
            None,
        )?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use aptscope_dissector::diag::DiagKind;
    use arrow_array::cast::AsArray;
    use arrow_array::types::UInt64Type;
    use arrow_array::Array;

    /// Validity is the bitmap Arrow makes of the same rows, whatever row the first null is
    /// (the first of a word, within one, the last), taken twice in a row.
    #[test]
    fn validity_is_the_bitmap_arrow_makes() {
        let mut v = Valid::default();
        for n in [1, 63, 64, 65, 130, 1000] {
            for first_null in [0, 1, 63, 64, 65, 127, n - 1] {
                let bits: Vec<bool> = (0..n)
                    .map(|i| i > first_null && (i * 7 + i / 3) % 5 != 0 || i < first_null)
                    .collect();
                for _ in 0..2 {
                    bits.iter().for_each(|b| v.push(*b));
                    let want = NullBuffer::from(bits.clone());
                    assert_eq!(v.take(), (want.null_count() > 0).then_some(want), "{n}");
                }
            }
        }
        // No null: no bitmap.
        (0..100).for_each(|_| v.push(true));
        assert_eq!(v.take(), None);
    }

    /// A column of nulls is Arrow's column of nulls of its type and length, whether made anew
    /// or a slice of a longer one made before (shorter, longer and equal lengths, in turn).
    #[test]
    fn columns_of_nulls_are_arrows_whatever_was_made_before() {
        let types = [
            DataType::Utf8,
            DataType::Binary,
            DataType::UInt16,
            DataType::Float64,
            DataType::List(Arc::new(arrow_schema::Field::new(
                "item",
                DataType::Utf8,
                true,
            ))),
        ];
        for rows in [3, 0, 9000, 9000, 20_000, 17, 40_000, 1] {
            for dt in &types {
                let a = nulls(dt, rows).expect("nulls");
                assert_eq!((a.data_type(), a.len(), a.null_count()), (dt, rows, rows));
                assert_eq!(
                    &a.to_data(),
                    &arrow_array::new_null_array(dt, rows).to_data()
                );
            }
        }
    }

    /// Columns of numbers and of text with nulls in every arrangement (none, all, leading,
    /// trailing, runs between values) are the arrays Arrow builds from the same options, with
    /// zero in every null row's value and the last end in every null row's end.
    #[test]
    fn nulls_written_late_are_the_nulls_of_arrow() {
        let patterns: Vec<Vec<bool>> = vec![
            vec![],
            vec![true; 5],
            vec![false; 5],
            vec![false, false, true, true],
            vec![true, true, false, false],
            vec![false, true, false, false, true, false],
            (0..300).map(|i| i % 7 == 3 || i > 250).collect(),
        ];
        for p in &patterns {
            let nums: Vec<Option<u64>> = p
                .iter()
                .enumerate()
                .map(|(i, v)| v.then_some(i as u64 + 1))
                .collect();
            let words: Vec<String> = (0..p.len()).map(|i| format!("w{i}")).collect();
            let text: Vec<Option<&str>> = p
                .iter()
                .zip(&words)
                .map(|(v, w)| v.then_some(w.as_str()))
                .collect();
            let (mut n, mut t) = (Num::<UInt64Type>::new(2), Bytes::new(2, 1));
            // Twice: a taken column starts again.
            for _ in 0..2 {
                for (x, w) in nums.iter().zip(&text) {
                    n.push(*x);
                    t.text(*w);
                }
                let a = n.take(&DataType::UInt64).expect("numbers");
                assert_eq!(
                    a.as_primitive::<UInt64Type>(),
                    &PrimitiveArray::from(nums.clone())
                );
                let raw = a.as_primitive::<UInt64Type>().values();
                assert!(
                    p.iter().zip(raw.iter()).all(|(v, x)| *v || *x == 0),
                    "{p:?}"
                );
                let b = t.take_text().expect("text");
                let b = b.as_string::<i32>();
                assert_eq!(b, &StringArray::from(text.clone()), "{p:?}");
                let ends = b.offsets();
                assert!(
                    (1..ends.len()).all(|i| p[i - 1] || ends[i] == ends[i - 1]),
                    "{p:?}"
                );
            }
        }
    }

    /// A repeated text is its text in every row, whatever was asked before it (other texts,
    /// fewer or more rows), and columns of nulls are nulls of their type.
    #[test]
    fn shared_columns_hold_what_was_asked() {
        let long = "/a/long/path/".repeat(30);
        for (text, rows) in [
            ("a.bin", 3),
            ("a.bin", 20_000),
            ("b", 5),
            ("a.bin", 7),
            ("", 4),
            // Over the bytes kept: the others go.
            (long.as_str(), 70_000),
            ("b", 6),
            (long.as_str(), 9),
        ] {
            let a = repeated_text(text, rows);
            let a = a.as_string::<i32>();
            assert_eq!(a.len(), rows);
            assert!(a.iter().all(|v| v == Some(text)), "{text} {rows}");
            assert_eq!(a.null_count(), 0);
        }
        assert_eq!(repeated_text("x", 0).len(), 0);
        let list = DataType::List(Arc::new(arrow_schema::Field::new(
            "item",
            DataType::Utf8,
            true,
        )));
        for dt in [
            DataType::UInt8,
            DataType::Float64,
            DataType::Utf8,
            DataType::Binary,
            list,
        ] {
            for rows in [0, 1, 70_000] {
                let a = nulls(&dt, rows).expect("nulls");
                assert_eq!((a.len(), a.null_count(), a.data_type()), (rows, rows, &dt));
                a.to_data().validate_full().expect("valid");
            }
        }
    }

    /// Rows with values missing here and there and diagnostics in rows apart: each column has
    /// its rows' values and nulls, each row its own diagnostics, and a buffer taken starts
    /// again.
    #[test]
    fn rows_keep_their_values_nulls_and_diagnostics() {
        let mut b = RecordsBuf::new(Arc::from("cap.bin"), 2, false);
        b.diag("a", 1, &"first");
        b.push(&Row {
            ty: "frame",
            n: Some(10),
            name: Some("MOT_MOVE_HOME"),
            raw: Some(b"\x43\x04"),
            ..Row::default()
        });
        b.push(&Row {
            ty: "garbage",
            ..Row::default()
        });
        b.diag("b", 2, &"second");
        b.diag("c", 3, &format_args!("{}", "third"));
        b.push(&Row {
            ty: "frame",
            n: Some(12),
            detail: Some("x"),
            ..Row::default()
        });
        let t = b.take(0).expect("batch");
        assert_eq!(t.schema(), batch_schema(false));
        assert_eq!(words::declared_schema(&t.schema()), *records_schema());
        // Read as the table's text (its columns of words are dictionaries).
        let t = words::declared(&t).expect("declared");
        assert_eq!(t.schema(), records_schema());
        assert_eq!(t.num_rows(), 3);
        let col = |n: &str| t.column_by_name(n).expect(n).clone();
        let file = col("file");
        assert!(file.as_string::<i32>().iter().all(|f| f == Some("cap.bin")));
        let n: Vec<Option<u64>> = col("n").as_primitive::<UInt64Type>().iter().collect();
        assert_eq!(n, [Some(10), None, Some(12)]);
        let name = col("name");
        let name: Vec<Option<&str>> = name.as_string::<i32>().iter().collect();
        assert_eq!(name, [Some("MOT_MOVE_HOME"), None, None]);
        let ty = col("type");
        let ty: Vec<Option<&str>> = ty.as_string::<i32>().iter().collect();
        assert_eq!(ty, [Some("frame"), Some("garbage"), Some("frame")]);
        let raw = col("raw");
        assert_eq!(raw.as_binary::<i32>().value(0), b"\x43\x04");
        assert!(raw.is_null(1) && raw.is_null(2));
        let detail = col("detail");
        assert_eq!(detail.null_count(), 2);
        let d = col("diagnostics");
        let d = d.as_list::<i32>();
        assert_eq!(d.null_count(), 0);
        let lens: Vec<usize> = (0..3).map(|i| d.value(i).len()).collect();
        assert_eq!(lens, [1, 0, 2]);
        let last = d.value(2);
        let msgs = last.as_struct().column(2).as_string::<i32>();
        assert_eq!(msgs.value(0), "second");
        assert_eq!(msgs.value(1), "third");
        let offsets = last.as_struct().column(1).as_primitive::<UInt64Type>();
        assert_eq!(offsets.values().to_vec(), [2, 3]);
        // Taken, the buffer starts again.
        b.push(&Row {
            ty: "units",
            ..Row::default()
        });
        let t = words::declared(&b.take(1).expect("batch")).expect("declared");
        assert_eq!(t.num_rows(), 1);
        assert_eq!(t.column(0).as_string::<i32>().value(0), "cap.bin");
        assert_eq!(
            t.column_by_name("diagnostics")
                .expect("d")
                .as_list::<i32>()
                .value(0)
                .len(),
            0
        );
    }

    /// Diagnostics' messages, fixed texts (kept unwritten while every one is the same) and
    /// displayed ones in every order, row group after row group, as words or as dictionaries:
    /// each message is its kind's display, and the bytes counted towards a row group are the
    /// messages' bytes whether written or not.
    #[test]
    fn diagnostics_messages_are_their_kinds_display() {
        let (u, l, g) = (
            DiagKind::Unsolicited,
            DiagKind::LetterO,
            DiagKind::Garbage { len: 3 },
        );
        let groups: Vec<Vec<DiagKind>> = vec![
            vec![u; 3],
            vec![],
            vec![u, g, u],
            vec![g, l],
            vec![l, u, u],
            vec![u, u, g],
            vec![g],
        ];
        for text in [false, true] {
            let mut buf = RecordsBuf::new(Arc::from("x"), 2, text);
            for (i, kinds) in groups.iter().enumerate() {
                for (at, k) in kinds.iter().enumerate() {
                    buf.diagnostic(&Diag {
                        offset: at as u64,
                        kind: *k,
                    });
                    // Each diagnostic in a row of its own but the last two.
                    if at + 2 < kinds.len() {
                        buf.push(&Row::default());
                    }
                }
                buf.push(&Row::default());
                let shown: Vec<String> = kinds.iter().map(ToString::to_string).collect();
                let bytes: usize = shown.iter().map(String::len).sum();
                assert_eq!(buf.bytes(), bytes, "{text} {i}");
                let t = buf.take(i % 3).expect("batch");
                let t = if text {
                    t
                } else {
                    words::declared(&t).expect("declared")
                };
                let d = t.column_by_name("diagnostics").expect("d");
                d.to_data().validate_full().expect("valid");
                let elems = d.as_list::<i32>().values().as_struct().clone();
                let texts = |c: usize| -> Vec<String> {
                    let col = elems.column(c).as_string::<i32>();
                    col.iter().flatten().map(String::from).collect()
                };
                assert_eq!(texts(2), shown, "{text} {i}");
                let want: Vec<&str> = kinds.iter().map(DiagKind::name).collect();
                let names = texts(0);
                assert_eq!(names, want, "{text} {i}");
            }
        }
    }

    /// Python's columns of words (text), in every arrangement of one word, nulls and words
    /// that differ (at the start, the middle, the end; a word not `'static`), row group after
    /// row group: each is the column a builder of the same words makes, and `kind` is the
    /// `name` column itself exactly while every row's kind is its name.
    #[test]
    fn words_kept_unwritten_are_the_words_put() {
        let (a, b) = (Some("MOT_MOVE_HOME"), Some("ELL_GS"));
        let patterns: Vec<Vec<(Option<&'static str>, Option<&'static str>)>> = vec![
            vec![],
            vec![(a, a); 3],
            vec![(None, None); 4],
            vec![(a, a), (a, a), (b, b), (a, a)],
            vec![(a, a), (a, a), (a, b)],
            vec![(a, b), (a, a)],
            vec![(None, None), (a, a), (a, None)],
            vec![(b, b), (a, a), (None, None), (b, b), (b, a)],
            (0..300)
                .map(|i| {
                    if i < 250 {
                        (a, a)
                    } else {
                        (b, if i % 3 == 0 { a } else { b })
                    }
                })
                .collect(),
        ];
        let mut buf = RecordsBuf::new(Arc::from("x"), 2, true);
        for (i, p) in patterns.iter().enumerate() {
            for &(name, kind) in p {
                buf.push(&Row {
                    ty: "frame",
                    dir: kind,
                    name,
                    kind,
                    ..Row::default()
                });
            }
            // One row group in four ends with a diagnostic kind that is not `'static`.
            let odd = i % 4 == 3;
            if odd {
                buf.diag_text(&String::from("late"), 1, &"m");
                buf.push(&Row {
                    ty: "frame",
                    ..Row::default()
                });
            }
            let t = buf.take(i % 3).expect("batch");
            assert_eq!(t.schema(), records_schema());
            let col = |n: &str| t.column_by_name(n).expect(n).clone();
            let text = |n: &str| -> Vec<Option<String>> {
                let c = col(n);
                c.to_data().validate_full().expect("valid");
                c.as_string::<i32>()
                    .iter()
                    .map(|v| v.map(String::from))
                    .collect()
            };
            // The names (0) or the kinds (1) put.
            let want = |k: usize| {
                let mut w: Vec<Option<String>> =
                    p.iter().map(|r| [r.0, r.1][k].map(String::from)).collect();
                if odd {
                    w.push(None);
                }
                w
            };
            assert_eq!(text("name"), want(0), "{i}");
            assert_eq!(text("kind"), want(1), "{i}");
            assert_eq!(text("dir"), want(1), "{i}");
            let same = p.iter().all(|r| r.0 == r.1);
            assert_eq!(Arc::ptr_eq(&col("name"), &col("kind")), same, "{i}");
            let ty = text("type");
            assert_eq!(ty.len(), p.len() + usize::from(odd));
            assert!(ty.iter().all(|t| t.as_deref() == Some("frame")));
            let d = col("diagnostics");
            let kinds = d.as_list::<i32>().values().as_struct().column(0).clone();
            assert_eq!(kinds.len(), usize::from(odd));
            if odd {
                assert_eq!(kinds.as_string::<i32>().value(0), "late");
            }
        }
    }
}
