//! Column buffers: typed values put straight into Arrow builders, one row at a time, and
//! Arrow arrays out. No cell per value in between (building, matching and dropping a row of
//! cells was a third of the writer's instructions).

use crate::records::{nulls, repeated_text, scale, TextWords, Valid};
use crate::words::{self, Words};
use arrow_array::builder::{
    ArrayBuilder, BinaryBuilder, Float32Builder, Float64Builder, Int16Builder, Int32Builder,
    Int64Builder, Int8Builder, ListBuilder, StringBuilder, TimestampNanosecondBuilder,
    UInt16Builder, UInt32Builder, UInt64Builder, UInt8Builder,
};
use arrow_array::{ArrayRef, ListArray, RecordBatch};
use arrow_buffer::{OffsetBuffer, ScalarBuffer};
use arrow_schema::{ArrowError, DataType, Field, SchemaRef};
use std::fmt::Write as _;
use std::sync::Arc;

/// A column being built, in its own Arrow type (values stored at their width, no conversion
/// when the batch is taken). The variants larger than a number's builder (104 bytes) are
/// boxed: a column of words holds its set's 1.5 KiB cache of addresses, and every column of
/// the hundreds of kind tables a capture of every form opens was 1,768 bytes (8.8 MB of the
/// 50 MB at its peak, and its columns that far apart in the cache).
enum Buf {
    I8(Int8Builder),
    I16(Int16Builder),
    I32(Int32Builder),
    I64(Int64Builder),
    U8(UInt8Builder),
    U16(UInt16Builder),
    U32(UInt32Builder),
    U64(UInt64Builder),
    F32(Float32Builder),
    F64(Float64Builder),
    Ts(TimestampNanosecondBuilder),
    Str(StringBuilder),
    Bin(BinaryBuilder),
    ListS(Box<ListBuilder<StringBuilder>>),
    ListI(Box<ListBuilder<Int64Builder>>),
    ListF(Box<ListBuilder<Float64Builder>>),
    /// Words ([`crate::words`]), and lists of words.
    Words(Box<Words>),
    /// Words as text (Python's tables).
    TextW(Box<TextWords>),
    ListW(Box<ListWords>),
}

/// A column of lists of words: the words, and where each row's list ends among them.
struct ListWords {
    ends: Vec<i32>,
    valid: Valid,
    words: Words,
    item: Arc<Field>,
}

fn item(dt: DataType) -> Arc<Field> {
    Arc::new(Field::new("item", dt, true))
}

/// Append `x` (or null) to builder `b`, cast to the column's width (`as`).
macro_rules! put {
    ($b:expr, $x:expr, $t:ty) => {
        match $x {
            Some(x) => $b.append_value(x as $t),
            None => $b.append_null(),
        }
    };
}

impl Buf {
    /// A column for about `cap` values (it grows beyond).
    fn new(dt: &DataType, cap: usize) -> Buf {
        match dt {
            DataType::Int8 => Buf::I8(Int8Builder::with_capacity(cap)),
            DataType::Int16 => Buf::I16(Int16Builder::with_capacity(cap)),
            DataType::Int32 => Buf::I32(Int32Builder::with_capacity(cap)),
            DataType::Int64 => Buf::I64(Int64Builder::with_capacity(cap)),
            DataType::UInt8 => Buf::U8(UInt8Builder::with_capacity(cap)),
            DataType::UInt16 => Buf::U16(UInt16Builder::with_capacity(cap)),
            DataType::UInt32 => Buf::U32(UInt32Builder::with_capacity(cap)),
            DataType::UInt64 => Buf::U64(UInt64Builder::with_capacity(cap)),
            DataType::Float32 => Buf::F32(Float32Builder::with_capacity(cap)),
            DataType::Float64 => Buf::F64(Float64Builder::with_capacity(cap)),
            DataType::Timestamp(_, _) => {
                Buf::Ts(TimestampNanosecondBuilder::with_capacity(cap).with_data_type(dt.clone()))
            }
            DataType::Binary => Buf::Bin(BinaryBuilder::with_capacity(cap, cap * 16)),
            DataType::Dictionary(..) => Buf::Words(Box::new(Words::new(cap))),
            DataType::List(f) if matches!(f.data_type(), DataType::Dictionary(..)) => {
                let mut ends = Vec::with_capacity(cap + 1);
                ends.push(0);
                Buf::ListW(Box::new(ListWords {
                    ends,
                    valid: Valid::default(),
                    words: Words::new(cap * 4),
                    item: f.clone(),
                }))
            }
            DataType::List(f) => match f.data_type() {
                DataType::Utf8 => Buf::ListS(Box::new(
                    ListBuilder::new(StringBuilder::new()).with_field(item(DataType::Utf8)),
                )),
                DataType::Int64 => Buf::ListI(Box::new(
                    ListBuilder::new(Int64Builder::new()).with_field(item(DataType::Int64)),
                )),
                DataType::Float64 => Buf::ListF(Box::new(
                    ListBuilder::new(Float64Builder::new()).with_field(item(DataType::Float64)),
                )),
                _ => Buf::Str(StringBuilder::with_capacity(cap, cap * 8)),
            },
            _ => Buf::Str(StringBuilder::with_capacity(cap, cap * 8)),
        }
    }

    /// An empty buffer of type `dt` with room for `cap` rows, and for text and list items in
    /// the measure this one held them over its `rows` rows (a name or a list of flags is
    /// longer than the defaults, and growing by doubling copies the column each time).
    fn again(&self, dt: &DataType, cap: usize, rows: usize) -> Buf {
        let scale = |n: usize| scale(n, cap, rows);
        match self {
            Buf::Str(b) => Buf::Str(StringBuilder::with_capacity(
                cap,
                scale(b.values_slice().len()),
            )),
            Buf::Bin(b) => Buf::Bin(BinaryBuilder::with_capacity(
                cap,
                scale(b.values_slice().len()),
            )),
            Buf::TextW(t) => Buf::TextW(Box::new(t.again(cap))),
            Buf::ListS(l) => {
                let v = l.values_ref();
                let items =
                    StringBuilder::with_capacity(scale(v.len()), scale(v.values_slice().len()));
                Buf::ListS(Box::new(
                    ListBuilder::with_capacity(items, cap).with_field(item(DataType::Utf8)),
                ))
            }
            _ => Buf::new(dt, cap),
        }
    }

    /// `n` rows without a value: nulls.
    fn nulls(&mut self, n: usize) {
        match self {
            Buf::I8(b) => b.append_nulls(n),
            Buf::I16(b) => b.append_nulls(n),
            Buf::I32(b) => b.append_nulls(n),
            Buf::I64(b) => b.append_nulls(n),
            Buf::U8(b) => b.append_nulls(n),
            Buf::U16(b) => b.append_nulls(n),
            Buf::U32(b) => b.append_nulls(n),
            Buf::U64(b) => b.append_nulls(n),
            Buf::F32(b) => b.append_nulls(n),
            Buf::F64(b) => b.append_nulls(n),
            Buf::Ts(b) => b.append_nulls(n),
            Buf::Str(b) => b.append_nulls(n),
            Buf::Bin(b) => b.append_nulls(n),
            Buf::ListS(b) => b.append_nulls(n),
            Buf::ListI(b) => b.append_nulls(n),
            Buf::ListF(b) => b.append_nulls(n),
            Buf::Words(w) => (0..n).for_each(|_| w.push(None)),
            Buf::TextW(t) => t.push_nulls(n),
            Buf::ListW(l) => {
                let ListWords {
                    ends, valid, words, ..
                } = &mut **l;
                let end = words.len() as i32;
                for _ in 0..n {
                    ends.push(end);
                    valid.push(false);
                }
            }
        }
    }

    /// No value: null.
    fn null(&mut self) {
        self.nulls(1)
    }

    /// A signed value (an unsigned column takes a negative one as null).
    fn int(&mut self, v: i64) {
        match self {
            Buf::I8(b) => b.append_value(v as i8),
            Buf::I16(b) => b.append_value(v as i16),
            Buf::I32(b) => b.append_value(v as i32),
            Buf::I64(b) => b.append_value(v),
            Buf::U8(b) => put!(b, u64::try_from(v).ok(), u8),
            Buf::U16(b) => put!(b, u64::try_from(v).ok(), u16),
            Buf::U32(b) => put!(b, u64::try_from(v).ok(), u32),
            Buf::U64(b) => put!(b, u64::try_from(v).ok(), u64),
            // Through f64, as the cells were: `as f32` of a large integer rounds otherwise.
            Buf::F32(b) => b.append_value(v as f64 as f32),
            Buf::F64(b) => b.append_value(v as f64),
            Buf::Ts(b) => b.append_value(v),
            Buf::Str(b) => {
                let _ = write!(b, "{v}");
                b.append_value("");
            }
            _ => self.null(),
        }
    }

    /// An unsigned value (a signed column takes one beyond i64 as null).
    fn uint(&mut self, v: u64) {
        match self {
            Buf::I8(b) => put!(b, i64::try_from(v).ok(), i8),
            Buf::I16(b) => put!(b, i64::try_from(v).ok(), i16),
            Buf::I32(b) => put!(b, i64::try_from(v).ok(), i32),
            Buf::I64(b) => put!(b, i64::try_from(v).ok(), i64),
            Buf::U8(b) => b.append_value(v as u8),
            Buf::U16(b) => b.append_value(v as u16),
            Buf::U32(b) => b.append_value(v as u32),
            Buf::U64(b) => b.append_value(v),
            Buf::F32(b) => b.append_value(v as f64 as f32),
            Buf::F64(b) => b.append_value(v as f64),
            Buf::Ts(b) => put!(b, i64::try_from(v).ok(), i64),
            Buf::Str(b) => {
                let _ = write!(b, "{v}");
                b.append_value("");
            }
            _ => self.null(),
        }
    }

    /// A float (null in an integer column).
    fn float(&mut self, v: f64) {
        match self {
            Buf::F32(b) => b.append_value(v as f32),
            Buf::F64(b) => b.append_value(v),
            Buf::Str(b) => {
                let _ = write!(b, "{v}");
                b.append_value("");
            }
            _ => self.null(),
        }
    }

    /// Text (null in a column of another type).
    fn text(&mut self, v: &str) {
        match self {
            Buf::Str(b) => b.append_value(v),
            Buf::Words(w) => w.push_text(v),
            Buf::TextW(t) => t.push_text(v),
            _ => self.null(),
        }
    }

    /// A word from the tables (null in a column of another type).
    fn word(&mut self, v: &'static str) {
        match self {
            Buf::Words(w) => w.push(Some(v)),
            Buf::TextW(t) => t.push(Some(v)),
            Buf::Str(b) => b.append_value(v),
            _ => self.null(),
        }
    }

    fn bytes(&mut self, v: &[u8]) {
        match self {
            Buf::Bin(b) => b.append_value(v),
            _ => self.null(),
        }
    }

    fn finish(&mut self) -> Result<ArrayRef, ArrowError> {
        Ok(match self {
            Buf::I8(b) => Arc::new(b.finish()),
            Buf::I16(b) => Arc::new(b.finish()),
            Buf::I32(b) => Arc::new(b.finish()),
            Buf::I64(b) => Arc::new(b.finish()),
            Buf::U8(b) => Arc::new(b.finish()),
            Buf::U16(b) => Arc::new(b.finish()),
            Buf::U32(b) => Arc::new(b.finish()),
            Buf::U64(b) => Arc::new(b.finish()),
            Buf::F32(b) => Arc::new(b.finish()),
            Buf::F64(b) => Arc::new(b.finish()),
            Buf::Ts(b) => Arc::new(b.finish()),
            Buf::Str(b) => Arc::new(b.finish()),
            Buf::Bin(b) => Arc::new(b.finish()),
            Buf::ListS(b) => Arc::new(b.finish()),
            Buf::ListI(b) => Arc::new(b.finish()),
            Buf::ListF(b) => Arc::new(b.finish()),
            Buf::Words(w) => w.take()?,
            Buf::TextW(t) => t.take()?,
            Buf::ListW(l) => {
                let ListWords {
                    ends,
                    valid,
                    words,
                    item,
                } = &mut **l;
                let ends = std::mem::replace(ends, vec![0]);
                Arc::new(ListArray::try_new(
                    item.clone(),
                    OffsetBuffer::new(ScalarBuffer::from(ends)),
                    words.take()?,
                    valid.take(),
                )?)
            }
        })
    }
}

/// The rows of one table not yet written. A row is made by putting each column's value (by
/// index in the schema; a column put twice in a row keeps the first) and ending it with
/// [`TableBuf::end_row`]; the columns not put are null.
///
/// Nulls are not appended row by row: each column counts the rows it holds, and one behind
/// gets its missing rows as nulls in one go when it is next put or when the batch is taken (a
/// loop over every column at every row's end was a fifth of building the rows, and most
/// columns of a table are null in most rows).
pub struct TableBuf {
    schema: SchemaRef,
    bufs: Vec<Buf>,
    /// Rows each column holds (the row being made counts once it is put).
    filled: Vec<usize>,
    /// Columns of the same text in every row (the `file` key): filled when the batch is taken.
    constant: Vec<(usize, Arc<str>)>,
    rows: usize,
    /// Bytes of text and bytes put.
    bytes: usize,
}

impl TableBuf {
    /// An empty buffer for `schema`.
    pub fn new(schema: SchemaRef) -> Self {
        // Small to start with: hundreds of kind tables may be open with a few rows each (the
        // builders' default, 1024 values a column, was 8 KiB a column before any row).
        let bufs: Vec<Buf> = schema
            .fields()
            .iter()
            .map(|f| Buf::new(f.data_type(), 64))
            .collect();
        TableBuf {
            schema,
            filled: vec![0; bufs.len()],
            bufs,
            constant: Vec::new(),
            rows: 0,
            bytes: 0,
        }
    }

    /// The columns of words of `batch` (the table's batch schema, [`crate::words`]) as text
    /// columns of words ([`TextWords`]) in this one, whose schema has them as text (Python's
    /// tables).
    pub fn words_as_text(mut self, batch: &arrow_schema::Schema) -> Self {
        for (b, f) in self.bufs.iter_mut().zip(batch.fields()) {
            if let (Buf::Str(s), DataType::Dictionary(..)) = (&mut *b, f.data_type()) {
                *b = Buf::TextW(Box::new(TextWords::over(std::mem::take(s))));
            }
        }
        self
    }

    /// Text column `i` holds `v` in every row: written once per batch rather than per row. A
    /// column made constant is not put row by row (puts into it are ignored).
    pub fn constant_text(&mut self, i: usize, v: Arc<str>) {
        if let Some(f) = self.filled.get_mut(i) {
            // Never behind, never put: the taken batch fills it.
            *f = usize::MAX;
            self.constant.push((i, v));
        }
    }

    /// Rows buffered.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Bytes of text and bytes buffered (list elements included).
    pub fn bytes(&self) -> usize {
        self.bytes
    }

    /// Column `i` if it has no value in this row yet (given the nulls of the rows it missed).
    #[inline]
    fn col(&mut self, i: usize) -> Option<&mut Buf> {
        let row = self.rows;
        let f = self.filled.get_mut(i)?;
        if *f > row {
            return None;
        }
        let b = self.bufs.get_mut(i)?;
        if *f < row {
            b.nulls(row - *f);
        }
        *f = row + 1;
        Some(b)
    }

    /// A signed integer.
    pub fn int(&mut self, i: usize, v: i64) {
        if let Some(b) = self.col(i) {
            b.int(v);
        }
    }

    /// An unsigned integer.
    pub fn uint(&mut self, i: usize, v: u64) {
        if let Some(b) = self.col(i) {
            b.uint(v);
        }
    }

    /// A float.
    pub fn float(&mut self, i: usize, v: f64) {
        if let Some(b) = self.col(i) {
            b.float(v);
        }
    }

    /// Text.
    pub fn text(&mut self, i: usize, v: &str) {
        if let Some(b) = self.col(i) {
            b.text(v);
            self.bytes += v.len();
        }
    }

    /// Bytes.
    pub fn put_bytes(&mut self, i: usize, v: &[u8]) {
        if let Some(b) = self.col(i) {
            b.bytes(v);
            self.bytes += v.len();
        }
    }

    /// A word from the tables (an enum's label, a unit).
    pub fn word(&mut self, i: usize, v: &'static str) {
        if let Some(b) = self.col(i) {
            b.word(v);
            self.bytes += v.len();
        }
    }

    /// A list of words from the tables (flag names; null in a column of another type).
    pub fn list_words(&mut self, i: usize, v: impl Iterator<Item = &'static str>) {
        let mut n = 0;
        if let Some(b) = self.col(i) {
            match b {
                Buf::ListW(l) => {
                    let ListWords {
                        ends, valid, words, ..
                    } = &mut **l;
                    for s in v {
                        words.push(Some(s));
                        n += s.len();
                    }
                    ends.push(words.len() as i32);
                    valid.push(true);
                }
                Buf::ListS(l) => {
                    for s in v {
                        l.values().append_value(s);
                        n += s.len();
                    }
                    l.append(true);
                }
                b => b.null(),
            }
        }
        self.bytes += n;
    }

    /// A list of integers.
    pub fn list_num(&mut self, i: usize, ints: impl Iterator<Item = i64>) {
        if let Some(b) = self.col(i) {
            match b {
                Buf::ListI(l) => {
                    l.values().extend(ints.map(Some));
                    l.append(true);
                }
                b => b.null(),
            }
        }
    }

    /// A list of floats.
    pub fn list_float(&mut self, i: usize, v: impl Iterator<Item = f64>) {
        if let Some(b) = self.col(i) {
            match b {
                Buf::ListF(l) => {
                    l.values().extend(v.map(Some));
                    l.append(true);
                }
                b => b.null(),
            }
        }
    }

    /// End the row: the columns not put are null.
    #[inline]
    pub fn end_row(&mut self) {
        self.rows += 1;
    }

    /// The buffered rows as a batch; the buffer is empty afterwards, with room for `room` rows
    /// and their text and list items in the measure of these ([`crate::Options::batches_kept`]
    /// says how many and why).
    pub fn take(&mut self, room: usize) -> Result<RecordBatch, ArrowError> {
        let rows = self.rows;
        // A column with no value in these rows is `nulls` (no memory of its own: a raw
        // capture's times), not nulls written one at a time; a column of words keeps its own
        // (its dictionary is the writer's).
        let mut empty = Vec::new();
        for (i, (b, f)) in self.bufs.iter_mut().zip(&mut self.filled).enumerate() {
            if *f == 0 && rows > 0 && !matches!(b, Buf::Words(_) | Buf::ListW(_)) {
                empty.push(i);
            } else if *f < rows {
                b.nulls(rows - *f);
            }
            *f = 0;
        }
        let next: Vec<Buf> = self
            .bufs
            .iter()
            .zip(self.schema.fields())
            .map(|(b, f)| b.again(f.data_type(), room, rows))
            .collect();
        let mut cols = self
            .bufs
            .iter_mut()
            .map(Buf::finish)
            .collect::<Result<Vec<ArrayRef>, _>>()?;
        for i in empty {
            if let (Some(c), Some(f)) = (cols.get_mut(i), self.schema.fields().get(i)) {
                *c = nulls(f.data_type(), rows)?;
            }
        }
        for (i, v) in &self.constant {
            if let Some(c) = cols.get_mut(*i) {
                *c = match self.bufs.get(*i) {
                    Some(Buf::Str(_) | Buf::TextW(_)) => repeated_text(v, rows),
                    _ => words::repeated(v, rows),
                };
            }
            if let Some(f) = self.filled.get_mut(*i) {
                *f = usize::MAX;
            }
        }
        self.bufs = next;
        self.rows = 0;
        self.bytes = 0;
        RecordBatch::try_new(self.schema.clone(), cols)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arrow_array::cast::AsArray;
    use arrow_array::types::UInt64Type;
    use arrow_array::Array;
    use arrow_schema::Schema;

    fn schema() -> SchemaRef {
        Arc::new(Schema::new(vec![
            Field::new("file", DataType::Utf8, false),
            Field::new("n", DataType::UInt64, true),
            Field::new("name", DataType::Utf8, true),
            Field::new("flags", DataType::List(item(DataType::Utf8)), true),
        ]))
    }

    /// Rows with columns missing here and there, a column put twice, lists in rows apart: the
    /// batch has the nulls of the rows a column missed, wherever they are; with the text
    /// columns as text and as words (the batch read as text).
    #[test]
    fn columns_not_put_are_null_in_their_rows() {
        let words = Arc::new(words::words_schema(&schema(), &["file", "name", "flags"]));
        for s in [schema(), words] {
            rows_of(s);
        }
    }

    fn rows_of(schema: SchemaRef) {
        let declared = |b: RecordBatch| words::declared(&b).expect("declared");
        let mut t = TableBuf::new(schema);
        t.constant_text(0, Arc::from("cap.bin"));
        // Row 0: n and a list.
        t.uint(1, 10);
        t.list_words(3, ["a"].into_iter());
        t.end_row();
        // Row 1: nothing.
        t.end_row();
        // Row 2: name twice (the first kept), a list twice; a put into the constant column.
        t.text(2, "x");
        t.text(2, "y");
        t.text(0, "other");
        t.list_words(3, ["b", "c"].into_iter());
        t.list_words(3, ["d"].into_iter());
        t.end_row();
        // Row 3: n only.
        t.uint(1, 13);
        t.end_row();
        let b = declared(t.take(0).expect("batch"));
        assert_eq!(b.schema(), self::schema());
        assert_eq!(b.num_rows(), 4);
        let file = b.column(0).as_string::<i32>();
        assert!((0..4).all(|i| file.value(i) == "cap.bin"), "{file:?}");
        let n = b.column(1).as_primitive::<UInt64Type>();
        let n: Vec<Option<u64>> = n.iter().collect();
        assert_eq!(n, [Some(10), None, None, Some(13)]);
        let name: Vec<Option<&str>> = b.column(2).as_string::<i32>().iter().collect();
        assert_eq!(name, [None, None, Some("x"), None]);
        let l = b.column(3).as_list::<i32>();
        let valid: Vec<bool> = (0..4).map(|i| l.is_valid(i)).collect();
        assert_eq!(valid, [true, false, true, false]);
        let two = l.value(2);
        let two: Vec<Option<&str>> = two.as_string::<i32>().iter().collect();
        assert_eq!(two, [Some("b"), Some("c")]);
        // Taken, the buffer starts again: the constant column too.
        t.uint(1, 20);
        t.end_row();
        let b = declared(t.take(1).expect("batch"));
        assert_eq!(b.num_rows(), 1);
        assert_eq!(b.column(0).as_string::<i32>().value(0), "cap.bin");
        assert!(b.column(3).is_null(0));
    }
}
