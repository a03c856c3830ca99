//! Column buffers: rows of [`V`] values in, Arrow arrays out.

use arrow_array::builder::{
    BinaryBuilder, Float32Builder, Float64Builder, Int16Builder, Int32Builder, Int64Builder,
    Int8Builder, ListBuilder, StringBuilder, StructBuilder, TimestampNanosecondBuilder,
    UInt16Builder, UInt32Builder, UInt64Builder, UInt8Builder,
};
use arrow_array::{ArrayRef, RecordBatch};
use arrow_schema::{ArrowError, DataType, Field, SchemaRef};
use std::borrow::Cow;
use std::sync::Arc;

/// One cell.
#[derive(Debug, Clone, Default)]
pub enum V<'a> {
    /// Null.
    #[default]
    Null,
    /// Signed integer.
    I(i64),
    /// Unsigned integer.
    U(u64),
    /// Float.
    F(f64),
    /// Text.
    S(Cow<'a, str>),
    /// Bytes.
    B(&'a [u8]),
    /// A list of names.
    ListS(Vec<&'a str>),
    /// A list of integers.
    ListI(Vec<i64>),
    /// A list of floats.
    ListF(Vec<f64>),
    /// Diagnostics: kind, offset, message.
    Diags(Vec<(Cow<'a, str>, u64, String)>),
}

/// A column being built, in its own Arrow type (values stored at their width, no conversion
/// when the batch is taken).
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
    ListS(ListBuilder<StringBuilder>),
    ListI(ListBuilder<Int64Builder>),
    ListF(ListBuilder<Float64Builder>),
    Diags(ListBuilder<StructBuilder>),
}

fn item(dt: DataType) -> Arc<Field> {
    Arc::new(Field::new("item", dt, true))
}

/// A value for a signed column (an unsigned one beyond i64 is null).
fn signed(v: &V<'_>) -> Option<i64> {
    match *v {
        V::I(i) => Some(i),
        V::U(u) => i64::try_from(u).ok(),
        _ => None,
    }
}

/// A value for an unsigned column (a negative one is null).
fn unsigned(v: &V<'_>) -> Option<u64> {
    match *v {
        V::U(u) => Some(u),
        V::I(i) => u64::try_from(i).ok(),
        _ => None,
    }
}

fn float(v: &V<'_>) -> Option<f64> {
    match *v {
        V::F(f) => Some(f),
        V::I(i) => Some(i as f64),
        V::U(u) => Some(u as f64),
        _ => None,
    }
}

/// Append `x` (or null) to builder `b`, cast to the column's width as before (`as`).
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
            DataType::List(f) => match f.data_type() {
                DataType::Utf8 => Buf::ListS(
                    ListBuilder::new(StringBuilder::new()).with_field(item(DataType::Utf8)),
                ),
                DataType::Int64 => Buf::ListI(
                    ListBuilder::new(Int64Builder::new()).with_field(item(DataType::Int64)),
                ),
                DataType::Float64 => Buf::ListF(
                    ListBuilder::new(Float64Builder::new()).with_field(item(DataType::Float64)),
                ),
                DataType::Struct(fs) => Buf::Diags(
                    ListBuilder::new(StructBuilder::from_fields(fs.clone(), 0))
                        .with_field(item(DataType::Struct(fs.clone()))),
                ),
                _ => Buf::Str(StringBuilder::with_capacity(cap, cap * 8)),
            },
            _ => Buf::Str(StringBuilder::with_capacity(cap, cap * 8)),
        }
    }

    fn push(&mut self, v: &V<'_>) {
        match self {
            Buf::I8(b) => put!(b, signed(v), i8),
            Buf::I16(b) => put!(b, signed(v), i16),
            Buf::I32(b) => put!(b, signed(v), i32),
            Buf::I64(b) => put!(b, signed(v), i64),
            Buf::U8(b) => put!(b, unsigned(v), u8),
            Buf::U16(b) => put!(b, unsigned(v), u16),
            Buf::U32(b) => put!(b, unsigned(v), u32),
            Buf::U64(b) => put!(b, unsigned(v), u64),
            Buf::F32(b) => put!(b, float(v), f32),
            Buf::F64(b) => put!(b, float(v), f64),
            Buf::Ts(b) => put!(
                b,
                match *v {
                    V::U(u) => i64::try_from(u).ok(),
                    V::I(i) => Some(i),
                    _ => None,
                },
                i64
            ),
            Buf::Str(b) => match v {
                V::S(s) => b.append_value(s),
                V::I(i) => b.append_value(i.to_string()),
                V::U(u) => b.append_value(u.to_string()),
                V::F(f) => b.append_value(f.to_string()),
                _ => b.append_null(),
            },
            Buf::Bin(b) => match v {
                V::B(s) => b.append_value(s),
                _ => b.append_null(),
            },
            Buf::ListS(b) => match v {
                V::ListS(l) => {
                    for s in l {
                        b.values().append_value(s);
                    }
                    b.append(true);
                }
                _ => b.append(false),
            },
            Buf::ListI(b) => match v {
                V::ListI(l) => {
                    b.values().append_slice(l);
                    b.append(true);
                }
                _ => b.append(false),
            },
            Buf::ListF(b) => match v {
                V::ListF(l) => {
                    b.values().append_slice(l);
                    b.append(true);
                }
                _ => b.append(false),
            },
            Buf::Diags(b) => {
                // Never null: no diagnostics is an empty list.
                if let V::Diags(ds) = v {
                    let s = b.values();
                    for (kind, offset, msg) in ds {
                        if let Some(k) = s.field_builder::<StringBuilder>(0) {
                            k.append_value(kind);
                        }
                        if let Some(o) = s.field_builder::<UInt64Builder>(1) {
                            o.append_value(*offset);
                        }
                        if let Some(m) = s.field_builder::<StringBuilder>(2) {
                            m.append_value(msg);
                        }
                        s.append(true);
                    }
                }
                b.append(true);
            }
        }
    }

    fn finish(&mut self) -> ArrayRef {
        match self {
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
            Buf::Diags(b) => Arc::new(b.finish()),
        }
    }
}

/// The rows of one table not yet written.
pub struct TableBuf {
    schema: SchemaRef,
    bufs: Vec<Buf>,
    rows: usize,
}

impl TableBuf {
    /// An empty buffer for `schema`.
    pub fn new(schema: SchemaRef) -> Self {
        // Small to start with: hundreds of kind tables may be open with a few rows each (the
        // builders' default, 1024 values a column, was 8 KiB a column before any row).
        let bufs = schema
            .fields()
            .iter()
            .map(|f| Buf::new(f.data_type(), 64))
            .collect();
        TableBuf {
            schema,
            bufs,
            rows: 0,
        }
    }

    /// Rows buffered.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Append a row (one value per column, in schema order; missing ones are null).
    pub fn push(&mut self, row: &[V<'_>]) {
        for (i, b) in self.bufs.iter_mut().enumerate() {
            b.push(row.get(i).unwrap_or(&V::Null));
        }
        self.rows += 1;
    }

    /// The buffered rows as a batch; the buffer is empty afterwards.
    pub fn take(&mut self) -> Result<RecordBatch, ArrowError> {
        let cols: Vec<ArrayRef> = self.bufs.iter_mut().map(Buf::finish).collect();
        // A table that filled a batch will likely fill the next: room for as many rows again
        // (a finished builder starts empty, and growing it by doubling was a tenth of the
        // run in reallocations).
        for (b, f) in self.bufs.iter_mut().zip(self.schema.fields()) {
            *b = Buf::new(f.data_type(), self.rows.min(8192));
        }
        self.rows = 0;
        RecordBatch::try_new(self.schema.clone(), cols)
    }
}
