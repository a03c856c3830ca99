//! Column buffers: rows of [`V`] values in, Arrow arrays out.

use arrow_array::builder::{
    BinaryBuilder, Float64Builder, Int64Builder, ListBuilder, StringBuilder, StructBuilder,
    UInt64Builder,
};
use arrow_array::{
    ArrayRef, Float32Array, Float64Array, Int16Array, Int32Array, Int64Array, Int8Array,
    RecordBatch, TimestampNanosecondArray, UInt16Array, UInt32Array, UInt64Array, UInt8Array,
};
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

enum Buf {
    Signed(DataType, Vec<Option<i64>>),
    Unsigned(DataType, Vec<Option<u64>>),
    Float(DataType, Vec<Option<f64>>),
    Ts(Option<Arc<str>>, Vec<Option<i64>>),
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

impl Buf {
    fn new(dt: &DataType) -> Buf {
        match dt {
            DataType::Int8 | DataType::Int16 | DataType::Int32 | DataType::Int64 => {
                Buf::Signed(dt.clone(), vec![])
            }
            DataType::UInt8 | DataType::UInt16 | DataType::UInt32 | DataType::UInt64 => {
                Buf::Unsigned(dt.clone(), vec![])
            }
            DataType::Float32 | DataType::Float64 => Buf::Float(dt.clone(), vec![]),
            DataType::Timestamp(_, tz) => Buf::Ts(tz.clone(), vec![]),
            DataType::Binary => Buf::Bin(BinaryBuilder::new()),
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
                _ => Buf::Str(StringBuilder::new()),
            },
            _ => Buf::Str(StringBuilder::new()),
        }
    }

    fn push(&mut self, v: &V<'_>) {
        match self {
            Buf::Signed(_, x) => x.push(match *v {
                V::I(i) => Some(i),
                V::U(u) => i64::try_from(u).ok(),
                _ => None,
            }),
            Buf::Unsigned(_, x) => x.push(match *v {
                V::U(u) => Some(u),
                V::I(i) => u64::try_from(i).ok(),
                _ => None,
            }),
            Buf::Float(_, x) => x.push(match *v {
                V::F(f) => Some(f),
                V::I(i) => Some(i as f64),
                V::U(u) => Some(u as f64),
                _ => None,
            }),
            Buf::Ts(_, x) => x.push(match *v {
                V::U(u) => i64::try_from(u).ok(),
                V::I(i) => Some(i),
                _ => None,
            }),
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
        fn take<T>(v: &mut Vec<T>) -> Vec<T> {
            std::mem::take(v)
        }
        match self {
            Buf::Signed(dt, x) => {
                let x = take(x);
                match dt {
                    DataType::Int8 => Arc::new(
                        x.into_iter()
                            .map(|v| v.map(|v| v as i8))
                            .collect::<Int8Array>(),
                    ),
                    DataType::Int16 => Arc::new(
                        x.into_iter()
                            .map(|v| v.map(|v| v as i16))
                            .collect::<Int16Array>(),
                    ),
                    DataType::Int32 => Arc::new(
                        x.into_iter()
                            .map(|v| v.map(|v| v as i32))
                            .collect::<Int32Array>(),
                    ),
                    _ => Arc::new(x.into_iter().collect::<Int64Array>()),
                }
            }
            Buf::Unsigned(dt, x) => {
                let x = take(x);
                match dt {
                    DataType::UInt8 => Arc::new(
                        x.into_iter()
                            .map(|v| v.map(|v| v as u8))
                            .collect::<UInt8Array>(),
                    ),
                    DataType::UInt16 => Arc::new(
                        x.into_iter()
                            .map(|v| v.map(|v| v as u16))
                            .collect::<UInt16Array>(),
                    ),
                    DataType::UInt32 => Arc::new(
                        x.into_iter()
                            .map(|v| v.map(|v| v as u32))
                            .collect::<UInt32Array>(),
                    ),
                    _ => Arc::new(x.into_iter().collect::<UInt64Array>()),
                }
            }
            Buf::Float(dt, x) => {
                let x = take(x);
                match dt {
                    DataType::Float32 => Arc::new(
                        x.into_iter()
                            .map(|v| v.map(|v| v as f32))
                            .collect::<Float32Array>(),
                    ),
                    _ => Arc::new(x.into_iter().collect::<Float64Array>()),
                }
            }
            Buf::Ts(tz, x) => {
                let a = TimestampNanosecondArray::from(take(x));
                Arc::new(match tz {
                    Some(tz) => a.with_timezone(tz.clone()),
                    None => a,
                })
            }
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
        let bufs = schema
            .fields()
            .iter()
            .map(|f| Buf::new(f.data_type()))
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
        self.rows = 0;
        RecordBatch::try_new(self.schema.clone(), cols)
    }
}
