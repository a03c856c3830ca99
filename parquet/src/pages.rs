//! Row groups written page by page straight from the Arrow arrays, without parquet-rs's
//! column writers: their per-value encoders (a dictionary interner hashing every text value,
//! definition levels worked out from the arrays' structure, plain numbers for Snappy to
//! compress) were more than half of `--to parquet`'s instructions, three quarters of NDJSON's
//! whole run (docs/performance.md, "Parquet, fifth pass"). Here a column chunk is one pass over
//! its array: definition levels of a top-level column are its validity bitmap as it is,
//! values are copied plain or looked up in a dictionary table of our own, pages are compressed
//! with Snappy and spliced into parquet-rs's file writer
//! ([`parquet::file::writer::SerializedRowGroupWriter::append_column`]), which writes the page
//! headers, the footer and the Arrow schema as before.
//!
//! It writes what the dataset's tables hold: integers, floats, timestamps in nanoseconds, text
//! and bytes, at the top level or in a list, and lists of structs of those; [`supports`] says
//! whether a schema is all that (anything else goes through parquet-rs's Arrow writer). A
//! reader reads the same as from the Arrow writer's files: Parquet 1.0 data pages, dictionary
//! pages for text where the properties give one and for integer chunks of few distinct values
//! (status codes, addresses, message ids: a few bits a value instead of 4 or 8 bytes for
//! Snappy), chunk statistics where the properties enable them; no page indexes.

use aptscope_dissector::hash::{NumHasher, NumMap};
use arrow_array::cast::AsArray;
use arrow_array::types::*;
use arrow_array::{Array, ArrayRef, ArrowPrimitiveType, GenericByteArray, ListArray, RecordBatch};
use arrow_buffer::NullBuffer;
use arrow_schema::{DataType, Field, Schema, TimeUnit};
use bytes::Bytes;
use parquet::basic::{Compression, Encoding};
use parquet::column::page::{CompressedPage, Page, PageWriter};
use parquet::column::writer::ColumnCloseResult;
use parquet::data_type::ByteArray;
use parquet::errors::{ParquetError, Result};
use parquet::file::metadata::ColumnChunkMetaData;
use parquet::file::properties::{EnabledStatistics, WriterProperties, WriterPropertiesPtr};
use parquet::file::statistics::Statistics;
use parquet::file::writer::{SerializedFileWriter, SerializedPageWriter, TrackedWrite};
use parquet::schema::types::{ColumnDescPtr, SchemaDescPtr};
use std::hash::Hasher;
use std::io::Write;
use std::sync::Arc;

/// Level entries in a data page at most (parquet-rs's default row count limit).
const PAGE_ENTRIES: usize = 20_000;
/// Bytes of values in a data page at most before the next row starts a new one.
const PAGE_BYTES: usize = 1 << 20;
/// A dictionary larger than this is dropped for plain values (parquet-rs's default limit).
const DICT_BYTES: usize = 1 << 20;

/// Calls `$f::<ArrowType, PhysicalType>` for the primitive type of `$a`.
macro_rules! by_prim {
    ($a:expr, $f:ident ( $($arg:expr),* )) => {
        match $a.data_type() {
            DataType::Int8 => $f::<Int8Type, i32>($a.as_primitive(), $($arg),*),
            DataType::Int16 => $f::<Int16Type, i32>($a.as_primitive(), $($arg),*),
            DataType::Int32 => $f::<Int32Type, i32>($a.as_primitive(), $($arg),*),
            DataType::UInt8 => $f::<UInt8Type, i32>($a.as_primitive(), $($arg),*),
            DataType::UInt16 => $f::<UInt16Type, i32>($a.as_primitive(), $($arg),*),
            DataType::UInt32 => $f::<UInt32Type, i32>($a.as_primitive(), $($arg),*),
            DataType::Int64 => $f::<Int64Type, i64>($a.as_primitive(), $($arg),*),
            DataType::UInt64 => $f::<UInt64Type, i64>($a.as_primitive(), $($arg),*),
            DataType::Timestamp(_, _) => {
                $f::<Int64Type, i64>(&$a.as_primitive::<TimestampNanosecondType>().reinterpret_cast(), $($arg),*)
            }
            DataType::Float32 => $f::<Float32Type, f32>($a.as_primitive(), $($arg),*),
            DataType::Float64 => $f::<Float64Type, f64>($a.as_primitive(), $($arg),*),
            dt => Err(ParquetError::General(format!("{dt} not written here"))),
        }
    };
}

/// Whether every column of `schema` is of a type this writer encodes.
pub fn supports(schema: &Schema) -> bool {
    schema.fields().iter().all(|f| match f.data_type() {
        DataType::List(item) => match item.data_type() {
            DataType::Struct(fs) => fs.iter().all(|c| leaf_type(c.data_type())),
            dt => leaf_type(dt),
        },
        dt => leaf_type(dt),
    })
}

fn leaf_type(dt: &DataType) -> bool {
    matches!(
        dt,
        DataType::Int8
            | DataType::Int16
            | DataType::Int32
            | DataType::Int64
            | DataType::UInt8
            | DataType::UInt16
            | DataType::UInt32
            | DataType::UInt64
            | DataType::Float32
            | DataType::Float64
            | DataType::Timestamp(TimeUnit::Nanosecond, _)
            | DataType::Utf8
            | DataType::Binary
    )
}

/// A Parquet file of a table's row groups, written by [`PartWriter::write`].
pub struct PartWriter<W: Write + Send> {
    file: SerializedFileWriter<W>,
    leaves: Vec<ColumnDescPtr>,
    props: WriterPropertiesPtr,
    /// For [`PartWriter::write`]; empty when the caller lends one ([`PartWriter::write_with`]).
    scratch: Scratch,
}

/// The Parquet schema and writer properties of a table, worked out once for its part files.
#[derive(Clone)]
pub struct TableProps {
    schema: SchemaDescPtr,
    props: WriterPropertiesPtr,
}

impl TableProps {
    /// For a table of `schema` written with `props`: the Parquet schema, and the Arrow schema
    /// in the file's metadata (as the Arrow writer stores it, so readers get the same types
    /// and field metadata back).
    pub fn new(schema: &Schema, mut props: WriterProperties) -> Result<Self> {
        let descr = parquet::arrow::ArrowSchemaConverter::new().convert(schema)?;
        parquet::arrow::add_encoded_arrow_schema_to_metadata(schema, &mut props);
        Ok(TableProps {
            schema: Arc::new(descr),
            props: Arc::new(props),
        })
    }
}

impl<W: Write + Send> PartWriter<W> {
    /// A file into `out`.
    pub fn new(out: W, t: &TableProps) -> Result<Self> {
        let file = SerializedFileWriter::new(out, t.schema.root_schema_ptr(), t.props.clone())?;
        Ok(PartWriter {
            file,
            leaves: t.schema.columns().to_vec(),
            props: t.props.clone(),
            scratch: Scratch::default(),
        })
    }

    /// Write `batch` as one row group.
    pub fn write(&mut self, batch: &RecordBatch) -> Result<()> {
        let mut scratch = std::mem::take(&mut self.scratch);
        let r = self.write_with(batch, &mut scratch);
        self.scratch = scratch;
        r
    }

    /// Write `batch` as one row group with buffers lent by the caller: a sink writing the
    /// files of hundreds of tables at once keeps one set, not one a file (each grows to its
    /// table's largest page and holds a compressor's table).
    pub fn write_with(&mut self, batch: &RecordBatch, scratch: &mut Scratch) -> Result<()> {
        let mut rg = self.file.next_row_group()?;
        let mut leaf = 0;
        let schema = batch.schema();
        for (field, col) in schema.fields().iter().zip(batch.columns()) {
            // The fields of a list of structs have the list's levels unless their own values
            // may be null (the diagnostics' kind, offset and message): worked out once for
            // them all.
            let mut list_levels = false;
            for l in leaves(field, col)? {
                let descr = self
                    .leaves
                    .get(leaf)
                    .ok_or_else(|| ParquetError::General("more leaves than the schema".into()))?
                    .clone();
                leaf += 1;
                if descr.max_def_level() != l.max_def || descr.max_rep_level() != l.max_rep {
                    return Err(ParquetError::General(format!(
                        "{}: levels {}/{} where the schema has {}/{}",
                        descr.path(),
                        l.max_def,
                        l.max_rep,
                        descr.max_def_level(),
                        descr.max_rep_level()
                    )));
                }
                if !(list_levels && l.child.is_none()) {
                    scratch.levels(&l, batch.num_rows());
                }
                list_levels = l.list.is_some() && l.child.is_none();
                let (chunk, close) = scratch.chunk(&l, batch.num_rows(), descr, &self.props)?;
                rg.append_column(&chunk, close)?;
                // The chunk's buffer back for the next (fresh pages for each were slower than
                // the copies they saved).
                if let Ok(m) = chunk.try_into_mut() {
                    scratch.chunk = Vec::from(m);
                    scratch.chunk.clear();
                }
            }
        }
        rg.close()?;
        Ok(())
    }

    /// What was written so far handed to the output, and the output (to close a file between
    /// row groups, say).
    pub fn flushed(&mut self) -> Result<&mut W> {
        self.file.flush()?;
        Ok(self.file.inner_mut())
    }

    /// Write the footer; the output back.
    pub fn finish(self) -> Result<W> {
        self.file.into_inner()
    }
}

/// One leaf column of a batch: its values array and where its level entries come from.
struct Leaf<'a> {
    /// The values (the column itself, a list's values, or a struct child of them).
    values: &'a dyn Array,
    /// The top-level column's validity, when its field is nullable.
    top: Opt<'a>,
    /// The list above the values, if any, and its items' validity when they are nullable.
    list: Option<&'a ListArray>,
    item: Opt<'a>,
    /// The values' own validity inside a struct item, when the child is nullable.
    child: Opt<'a>,
    max_def: i16,
    max_rep: i16,
}

/// A nullable level: `Some(validity)` when nullable (`Some(None)`: nullable, no nulls).
type Opt<'a> = Option<Option<&'a NullBuffer>>;

/// The validity `a` must have under a field of nullability `opt`.
fn opt<'a>(a: &'a dyn Array, nullable: bool, what: &str) -> Result<Opt<'a>> {
    match (nullable, a.nulls()) {
        (true, n) => Ok(Some(n)),
        (false, None) => Ok(None),
        (false, Some(n)) if n.null_count() == 0 => Ok(None),
        (false, Some(_)) => Err(ParquetError::General(format!(
            "{what}: nulls in a column that may not have any"
        ))),
    }
}

fn leaves<'a>(field: &Field, col: &'a ArrayRef) -> Result<Vec<Leaf<'a>>> {
    let top = opt(col.as_ref(), field.is_nullable(), field.name())?;
    let d0 = top.is_some() as i16;
    let DataType::List(item) = field.data_type() else {
        return Ok(vec![Leaf {
            values: col.as_ref(),
            top,
            list: None,
            item: None,
            child: None,
            max_def: d0,
            max_rep: 0,
        }]);
    };
    let list = col.as_list::<i32>();
    let values = list.values().as_ref();
    let it = opt(values, item.is_nullable(), field.name())?;
    // The repeated level, then the item's optional level.
    let d1 = d0 + 1 + it.is_some() as i16;
    let DataType::Struct(children) = item.data_type() else {
        return Ok(vec![Leaf {
            values,
            top,
            list: Some(list),
            item: it,
            child: None,
            max_def: d1,
            max_rep: 1,
        }]);
    };
    let st = values.as_struct();
    children
        .iter()
        .zip(st.columns())
        .map(|(c, a)| {
            let child = opt(a.as_ref(), c.is_nullable(), c.name())?;
            Ok(Leaf {
                values: a.as_ref(),
                top,
                list: Some(list),
                item: it,
                child,
                max_def: d1 + child.is_some() as i16,
                max_rep: 1,
            })
        })
        .collect()
}

/// A top-level column's validity when it has nulls.
fn flat_nulls<'a>(l: &Leaf<'a>) -> Option<&'a NullBuffer> {
    l.top.flatten().filter(|n| n.null_count() > 0)
}

fn valid(o: &Opt<'_>, i: usize) -> bool {
    match o {
        Some(Some(n)) => n.is_valid(i),
        _ => true,
    }
}

/// Which values a chunk writes, in order.
enum Sel<'a> {
    /// Values `start..end` of the array (no nulls among them, no list).
    Range(usize, usize),
    /// These values.
    Some(&'a [u32]),
}

impl Sel<'_> {
    fn len(&self) -> usize {
        match self {
            Sel::Range(a, b) => b - a,
            Sel::Some(v) => v.len(),
        }
    }

    fn at(&self, k: usize) -> usize {
        match self {
            Sel::Range(a, _) => a + k,
            Sel::Some(v) => v[k] as usize,
        }
    }
}

/// Buffers kept from column to column (and lent from file to file: [`PartWriter::write_with`]).
#[derive(Default)]
pub struct Scratch {
    /// Definition and repetition levels of the chunk's entries (empty: all at the maximum).
    def: Vec<u8>,
    rep: Vec<u8>,
    /// The values written (when not a plain range), and their dictionary numbers.
    sel: Vec<u32>,
    keys: Vec<u32>,
    /// A page being made, compressed, and the chunk's pages.
    page: Vec<u8>,
    packed: Vec<u8>,
    chunk: Vec<u8>,
    dict: Dict,
    ints: IntDict,
    /// A dictionary array's words in this chunk's order of first sight, and each word's
    /// number here (`u32::MAX`: not seen yet).
    order: Vec<u32>,
    renum: Vec<u32>,
    snappy: Option<snap::raw::Encoder>,
}

impl Scratch {
    /// Levels and the selection of values of `l` (`rows` rows). A top-level column keeps no
    /// levels here: its definition levels are its validity bitmap ([`Scratch::chunk`]).
    fn levels(&mut self, l: &Leaf<'_>, rows: usize) {
        self.def.clear();
        self.rep.clear();
        self.sel.clear();
        let max = l.max_def as u8;
        let Some(list) = l.list else {
            if let Some(n) = flat_nulls(l) {
                self.sel.extend(n.valid_indices().map(|i| i as u32));
            }
            return;
        };
        let offs = list.value_offsets();
        let base = l.top.is_some() as u8;
        let simple = l.item.flatten().is_none_or(|n| n.null_count() == 0)
            && l.child.flatten().is_none_or(|n| n.null_count() == 0);
        for i in 0..rows {
            let (s, e) = (offs[i] as usize, offs[i + 1] as usize);
            if !valid(&l.top, i) {
                self.def.push(0);
                self.rep.push(0);
                continue;
            }
            if s == e {
                self.def.push(base);
                self.rep.push(0);
                continue;
            }
            if simple {
                self.rep.push(0);
                self.rep.extend(std::iter::repeat_n(1, e - s - 1));
                self.def.extend(std::iter::repeat_n(max, e - s));
                self.sel.extend(s as u32..e as u32);
                continue;
            }
            for j in s..e {
                self.rep.push((j != s) as u8);
                let d = if !valid(&l.item, j) {
                    base + 1
                } else if !valid(&l.child, j) {
                    base + 1 + l.item.is_some() as u8
                } else {
                    self.sel.push(j as u32);
                    max
                };
                self.def.push(d);
            }
        }
    }

    /// The column chunk of leaf `l` of a `rows`-row batch (its [`Scratch::levels`] worked
    /// out), and what its footer entry says.
    fn chunk(
        &mut self,
        l: &Leaf<'_>,
        rows: usize,
        descr: ColumnDescPtr,
        props: &WriterProperties,
    ) -> Result<(Bytes, ColumnCloseResult)> {
        let flat = l.list.is_none();
        let flat_nulls = flat_nulls(l);
        let entries = if flat { rows } else { self.def.len() };
        let sel = if flat && flat_nulls.is_none() {
            Sel::Range(0, rows)
        } else {
            Sel::Some(&self.sel)
        };
        let path = descr.path();
        let codec = props.compression(path);
        let snappy = match codec {
            Compression::SNAPPY => true,
            Compression::UNCOMPRESSED => false,
            c => {
                return Err(ParquetError::General(format!(
                    "{path}: codec {c} not written here"
                )))
            }
        };
        let stats_on = props.statistics_enabled(path) != EnabledStatistics::None;
        let values = l.values;
        let max = l.max_def as u8;
        let nulls = (entries - sel.len()) as u64;

        // A dictionary for text and bytes where the properties give one and it stays small,
        // and for integers with few distinct values (their pages are then a few bits a value
        // for Snappy to compress instead of 4 or 8 bytes; every reader reads a dictionary).
        // A dictionary array (of words, crate::words): its text is the dictionary, renumbered
        // by first sight in this chunk as one made from the text would be (whatever the
        // properties say: words are few distinct values, and the dataset's text columns all
        // have dictionaries).
        let keyed = values.as_dictionary_opt::<Int32Type>();
        let byte_vals = match keyed {
            Some(d) => Some(as_bytes(d.values().as_ref()).ok_or_else(|| {
                ParquetError::General(format!(
                    "{path}: a dictionary of {}",
                    d.values().data_type()
                ))
            })?),
            None => as_bytes(values),
        };
        self.dict.clear();
        self.keys.clear();
        self.order.clear();
        // (No values, no dictionary: an empty dictionary page is one more thing for readers.)
        let dict = sel.len() > 0
            && match (keyed, &byte_vals) {
                (Some(d), _) => {
                    let (renum, order) = (&mut self.renum, &mut self.order);
                    renumber(d, &sel, renum, order, &mut self.keys, path)?;
                    true
                }
                (None, Some(b)) if props.dictionary_enabled(path) => {
                    self.keys.reserve(sel.len());
                    for k in 0..sel.len() {
                        self.keys.push(self.dict.intern(b.value(sel.at(k))));
                        if self.dict.data.len() > DICT_BYTES {
                            break;
                        }
                    }
                    self.dict.data.len() <= DICT_BYTES
                }
                (None, Some(_)) => false,
                (None, None) => {
                    self.ints.clear();
                    let (d, k) = (&mut self.ints, &mut self.keys);
                    by_prim!(values, intern_prim(&sel, d, k))?
                }
            };
        let dict_len = match (keyed, &byte_vals) {
            (Some(_), _) => self.order.len(),
            (None, Some(_)) => self.dict.len(),
            (None, None) => self.ints.vals.len(),
        };
        // The text dictionary's value `i`.
        let (order, own) = (&self.order, &self.dict);
        let dict_value = |i: usize| match (keyed, &byte_vals) {
            (Some(_), Some(b)) => b.value(order[i] as usize),
            _ => own.value(i),
        };
        let stats = match &byte_vals {
            _ if !stats_on => None,
            Some(_) if sel.len() == 0 => {
                Some(Statistics::byte_array(None, None, None, Some(nulls), false))
            }
            Some(b) => {
                // Over the dictionary's distinct values when there is one.
                let (lo, hi) = if dict {
                    min_max((0..dict_len).map(dict_value))
                } else {
                    min_max((0..sel.len()).map(|k| b.value(sel.at(k))))
                };
                Some(Statistics::byte_array(
                    Some(ByteArray::from(lo.to_vec())),
                    Some(ByteArray::from(hi.to_vec())),
                    None,
                    Some(nulls),
                    false,
                ))
            }
            None => Some(by_prim!(values, stats_prim(&sel, nulls))?),
        };

        let mut w = TrackedWrite::new(std::mem::take(&mut self.chunk));
        let mut pages = SerializedPageWriter::new(&mut w);
        let (mut compressed, mut uncompressed) = (0i64, 0i64);
        let mut dict_offset = None;
        if dict {
            self.page.clear();
            if byte_vals.is_some() {
                for v in (0..dict_len).map(dict_value) {
                    self.page.extend_from_slice(&(v.len() as u32).to_le_bytes());
                    self.page.extend_from_slice(v);
                }
            } else {
                let (ints, page) = (&self.ints.vals, &mut self.page);
                by_prim!(values, dict_page(ints, page))?;
            }
            let page = |buf| Page::DictionaryPage {
                buf,
                num_values: dict_len as u32,
                encoding: Encoding::PLAIN_DICTIONARY,
                is_sorted: false,
            };
            let (buf, n) = compress(&self.page, snappy, &mut self.packed, &mut self.snappy)?;
            let spec = pages.write_page(CompressedPage::new(page(buf), n))?;
            dict_offset = Some(spec.offset as i64);
            compressed += spec.compressed_size as i64;
            uncompressed += spec.uncompressed_size as i64;
        }
        let bw = bit_width(dict_len.saturating_sub(1) as u64).max(1);
        let mut data_offset = None;
        // Pages: up to PAGE_ENTRIES entries, cut where a row starts; plain bytes also after
        // PAGE_BYTES of values.
        let plain_bytes = if dict { None } else { byte_vals };
        let (mut e0, mut v0) = (0usize, 0usize);
        loop {
            let mut e1 = (e0 + PAGE_ENTRIES).min(entries);
            while e1 < entries && self.rep.get(e1).is_some_and(|&r| r != 0) {
                e1 += 1;
            }
            let mut v1 = match (flat, flat_nulls) {
                (true, None) => e1,
                (true, Some(n)) => v0 + (e1 - e0) - n.slice(e0, e1 - e0).null_count(),
                (false, _) => v0 + self.def[e0..e1].iter().filter(|&&d| d == max).count(),
            };
            if let (true, Some(b)) = (flat, &plain_bytes) {
                let mut bytes = 0;
                for k in v0..v1 {
                    bytes += 4 + b.value(sel.at(k)).len();
                    if bytes >= PAGE_BYTES && k + 1 < v1 {
                        // Up to this value's row.
                        e1 = sel.at(k) + 1;
                        v1 = k + 1;
                        break;
                    }
                }
            }
            self.page.clear();
            if l.max_rep > 0 {
                levels_block(&self.rep[e0..e1], 1, &mut self.page);
            }
            if l.max_def > 0 {
                let bwd = bit_width(l.max_def as u64);
                let def = &self.def;
                prefixed(&mut self.page, |out| match (flat, flat_nulls) {
                    (true, None) => rle_run(out, (e1 - e0) as u64, 1, bwd),
                    (true, Some(n)) => bitmap_run(n, e0, e1, out),
                    (false, _) => hybrid(&def[e0..e1], bwd, out),
                });
            }
            let encoding = if dict {
                self.page.push(bw);
                hybrid(&self.keys[v0..v1], bw, &mut self.page);
                Encoding::PLAIN_DICTIONARY
            } else {
                plain(values, &sel, v0..v1, &mut self.page)?;
                Encoding::PLAIN
            };
            let (buf, n) = compress(&self.page, snappy, &mut self.packed, &mut self.snappy)?;
            let page = Page::DataPage {
                buf,
                num_values: (e1 - e0) as u32,
                encoding,
                def_level_encoding: Encoding::RLE,
                rep_level_encoding: Encoding::RLE,
                statistics: None,
            };
            let spec = pages.write_page(CompressedPage::new(page, n))?;
            data_offset.get_or_insert(spec.offset as i64);
            compressed += spec.compressed_size as i64;
            uncompressed += spec.uncompressed_size as i64;
            if e1 >= entries {
                break;
            }
            (e0, v0) = (e1, v1);
        }
        pages.close()?;
        let buf = w.into_inner()?;
        let mut encodings = vec![Encoding::RLE];
        encodings.push(if dict {
            Encoding::PLAIN_DICTIONARY
        } else {
            Encoding::PLAIN
        });
        let mut md = ColumnChunkMetaData::builder(descr)
            .set_compression(codec)
            .set_encodings(encodings)
            .set_num_values(entries as i64)
            .set_total_compressed_size(compressed)
            .set_total_uncompressed_size(uncompressed)
            .set_data_page_offset(data_offset.unwrap_or(0))
            .set_dictionary_page_offset(dict_offset);
        if let Some(s) = stats {
            md = md.set_statistics(s);
        }
        let close = ColumnCloseResult {
            bytes_written: compressed as u64,
            rows_written: rows as u64,
            metadata: md.build()?,
            bloom_filter: None,
            column_index: None,
            offset_index: None,
        };
        Ok((Bytes::from(buf), close))
    }
}

/// The selected keys of dictionary array `d` numbered by first sight (into `keys`), and its
/// words in that order (`order`; `renum`: each word's number, `u32::MAX` until seen).
fn renumber(
    d: &arrow_array::DictionaryArray<Int32Type>,
    sel: &Sel<'_>,
    renum: &mut Vec<u32>,
    order: &mut Vec<u32>,
    keys: &mut Vec<u32>,
    path: &parquet::schema::types::ColumnPath,
) -> Result<()> {
    let ks = d.keys().values();
    renum.clear();
    renum.resize(d.values().len(), u32::MAX);
    keys.reserve(sel.len());
    for k in 0..sel.len() {
        let w = ks[sel.at(k)];
        let n = usize::try_from(w)
            .ok()
            .and_then(|w| renum.get_mut(w))
            .ok_or_else(|| ParquetError::General(format!("{path}: key {w} out of range")))?;
        if *n == u32::MAX {
            *n = order.len() as u32;
            order.push(w as u32);
        }
        keys.push(*n);
    }
    Ok(())
}

/// The least and greatest of byte strings, as Parquet orders them (unsigned bytes); empty
/// when there are none (callers give at least one).
fn min_max<'a>(mut vals: impl Iterator<Item = &'a [u8]>) -> (&'a [u8], &'a [u8]) {
    let first = vals.next().unwrap_or_default();
    vals.fold((first, first), |(lo, hi), v| (lo.min(v), hi.max(v)))
}

/// The values of a text or bytes array, by index.
enum ByteVals<'a> {
    Text(&'a GenericByteArray<GenericStringType<i32>>),
    Bin(&'a GenericByteArray<GenericBinaryType<i32>>),
}

impl ByteVals<'_> {
    #[inline]
    fn value(&self, i: usize) -> &[u8] {
        match self {
            ByteVals::Text(a) => a.value(i).as_bytes(),
            ByteVals::Bin(a) => a.value(i),
        }
    }
}

fn as_bytes(a: &dyn Array) -> Option<ByteVals<'_>> {
    match a.data_type() {
        DataType::Utf8 => Some(ByteVals::Text(a.as_string::<i32>())),
        DataType::Binary => Some(ByteVals::Bin(a.as_binary::<i32>())),
        _ => None,
    }
}

/// A native value as the Parquet physical type it is stored in.
trait Phys: Copy + PartialOrd {
    /// Whether a chunk of these may be dictionary-encoded (integers).
    const DICT: bool;
    /// Zero, and zero as a minimum in statistics (−0 for floats, as the format asks).
    const ZERO: Self;
    const MIN_ZERO: Self;
    fn put(self, out: &mut Vec<u8>);
    /// Its bits, for a dictionary of integers (and back, for its page).
    fn bits(self) -> u64;
    fn from_bits(b: u64) -> Self;
    fn stats(min: Option<Self>, max: Option<Self>, nulls: u64) -> Statistics;
    /// A zero's sign as the format wants it in statistics: −0 as a minimum, +0 as a maximum.
    fn zero_sign(self, min: bool) -> Self {
        match (self == Self::ZERO, min) {
            (true, true) => Self::MIN_ZERO,
            (true, false) => Self::ZERO,
            _ => self,
        }
    }
}

macro_rules! phys {
    ($($t:ty: $stat:ident, dict $dict:expr, zero $zero:expr, $min_zero:expr,
        bits |$s:ident| $bits:expr, from |$b:ident| $from:expr;)*) => {$(
        impl Phys for $t {
            const DICT: bool = $dict;
            const ZERO: Self = $zero;
            const MIN_ZERO: Self = $min_zero;
            fn put(self, out: &mut Vec<u8>) {
                out.extend_from_slice(&self.to_le_bytes())
            }
            fn bits(self) -> u64 {
                let $s = self;
                $bits
            }
            fn from_bits($b: u64) -> Self {
                $from
            }
            fn stats(min: Option<Self>, max: Option<Self>, nulls: u64) -> Statistics {
                Statistics::$stat(min, max, None, Some(nulls), false)
            }
        }
    )*};
}

phys! {
    i32: int32, dict true, zero 0, 0, bits |v| v as u32 as u64, from |b| b as u32 as i32;
    i64: int64, dict true, zero 0, 0, bits |v| v as u64, from |b| b as i64;
    f32: float, dict false, zero 0.0, -0.0, bits |v| v.to_bits() as u64, from |b| f32::from_bits(b as u32);
    f64: double, dict false, zero 0.0, -0.0, bits |v| v.to_bits(), from |b| f64::from_bits(b);
}

/// Native to physical: integers by `as` (an unsigned value keeps its bits), floats as they are.
trait ToPhys<P> {
    fn phys(self) -> P;
}

macro_rules! to_phys {
    ($($t:ty => $p:ty),*) => {$(
        impl ToPhys<$p> for $t {
            #[inline(always)]
            fn phys(self) -> $p {
                self as $p
            }
        }
    )*};
}
to_phys!(i8 => i32, i16 => i32, i32 => i32, u8 => i32, u16 => i32, u32 => i32, i64 => i64,
    u64 => i64, f32 => f32, f64 => f64);

fn plain_prim<T: ArrowPrimitiveType, P: Phys>(
    a: &arrow_array::PrimitiveArray<T>,
    sel: &Sel<'_>,
    range: std::ops::Range<usize>,
    out: &mut Vec<u8>,
) -> Result<()>
where
    T::Native: ToPhys<P>,
{
    let v = a.values();
    out.reserve(range.len() * std::mem::size_of::<P>());
    match sel {
        // The same width (and, for integers, bits) as stored: the buffer's bytes as they are.
        Sel::Range(s, _) if std::mem::size_of::<T::Native>() == std::mem::size_of::<P>() => {
            let w = std::mem::size_of::<P>();
            let bytes = v.inner().as_slice();
            out.extend_from_slice(&bytes[(s + range.start) * w..(s + range.end) * w]);
        }
        Sel::Range(s, _) => {
            for &x in &v[s + range.start..s + range.end] {
                x.phys().put(out);
            }
        }
        Sel::Some(ix) => {
            for &i in &ix[range] {
                v[i as usize].phys().put(out);
            }
        }
    }
    Ok(())
}

/// The dictionary page of integers: `vals` plain in the physical type.
fn dict_page<T: ArrowPrimitiveType, P: Phys>(
    _a: &arrow_array::PrimitiveArray<T>,
    vals: &[u64],
    out: &mut Vec<u8>,
) -> Result<()> {
    for &v in vals {
        P::from_bits(v).put(out);
    }
    Ok(())
}

/// Distinct integers at most in a dictionary (more, and the chunk is written plain).
const DICT_INTS: usize = 1024;

/// The selected values interned in `dict` with their numbers in `keys`; false when they are
/// not integers or too many are distinct.
fn intern_prim<T: ArrowPrimitiveType, P: Phys>(
    a: &arrow_array::PrimitiveArray<T>,
    sel: &Sel<'_>,
    dict: &mut IntDict,
    keys: &mut Vec<u32>,
) -> Result<bool>
where
    T::Native: ToPhys<P>,
{
    if !P::DICT {
        return Ok(false);
    }
    let v = a.values();
    keys.reserve(sel.len());
    for k in 0..sel.len() {
        keys.push(dict.intern(v[sel.at(k)].phys().bits()));
        // Too many distinct (or mostly distinct from the start: counts, times, offsets).
        if dict.vals.len() > DICT_INTS || (k == 255 && dict.vals.len() > 192) {
            return Ok(false);
        }
    }
    Ok(true)
}

/// Values `range` of the selection, plain.
fn plain(
    a: &dyn Array,
    sel: &Sel<'_>,
    range: std::ops::Range<usize>,
    out: &mut Vec<u8>,
) -> Result<()> {
    // (A chunk of only nulls: no values, whatever their type.)
    if range.is_empty() {
        return Ok(());
    }
    if let Some(b) = as_bytes(a) {
        for k in range {
            let v = b.value(sel.at(k));
            out.extend_from_slice(&(v.len() as u32).to_le_bytes());
            out.extend_from_slice(v);
        }
        return Ok(());
    }
    by_prim!(a, plain_prim(sel, range, out))
}

fn stats_prim<T: ArrowPrimitiveType, P: Phys>(
    a: &arrow_array::PrimitiveArray<T>,
    sel: &Sel<'_>,
    nulls: u64,
) -> Result<Statistics>
where
    T::Native: ToPhys<P> + PartialOrd,
{
    let v = a.values();
    let mut lo: Option<T::Native> = None;
    let mut hi: Option<T::Native> = None;
    for k in 0..sel.len() {
        let x = v[sel.at(k)];
        // NaN is in no order: left out of the statistics, as the format asks.
        #[allow(clippy::eq_op)]
        if x != x {
            continue;
        }
        if lo.is_none_or(|l| x < l) {
            lo = Some(x);
        }
        if hi.is_none_or(|h| x > h) {
            hi = Some(x);
        }
    }
    Ok(match (lo, hi) {
        (Some(l), Some(h)) => P::stats(
            Some(l.phys().zero_sign(true)),
            Some(h.phys().zero_sign(false)),
            nulls,
        ),
        _ => P::stats(None, None, nulls),
    })
}
/// `page` compressed (or as it is), and its length before.
fn compress(
    page: &[u8],
    snappy: bool,
    out: &mut Vec<u8>,
    enc: &mut Option<snap::raw::Encoder>,
) -> Result<(Bytes, usize)> {
    if !snappy {
        return Ok((Bytes::copy_from_slice(page), page.len()));
    }
    // Grown, never cleared: zeroing the room for every page cost more than compressing.
    let need = snap::raw::max_compress_len(page.len());
    if out.len() < need {
        out.resize(need, 0);
    }
    let n = enc
        .get_or_insert_with(snap::raw::Encoder::new)
        .compress(page, out)
        .map_err(|e| ParquetError::General(format!("snappy: {e}")))?;
    Ok((Bytes::copy_from_slice(&out[..n]), page.len()))
}

/// Bits needed for values up to `max`.
fn bit_width(max: u64) -> u8 {
    (64 - max.leading_zeros()) as u8
}

/// Levels as a data page (version 1) holds them: their length in 4 bytes, then the RLE /
/// bit-packed hybrid.
fn levels_block(levels: &[u8], bw: u8, out: &mut Vec<u8>) {
    prefixed(out, |out| hybrid(levels, bw, out));
}

/// What `write` appends to `out`, after its length in 4 bytes (levels in a version 1 page).
fn prefixed(out: &mut Vec<u8>, write: impl FnOnce(&mut Vec<u8>)) {
    let at = out.len();
    out.extend_from_slice(&[0; 4]);
    write(out);
    let len = (out.len() - at - 4) as u32;
    out[at..at + 4].copy_from_slice(&len.to_le_bytes());
}

/// Definition levels of a top-level column, rows `e0..e1`: one bit each, which is its
/// validity bitmap as it is (bit-packing is least significant bit first, as Arrow's bitmaps),
/// so one bit-packed run of its bytes.
fn bitmap_run(n: &NullBuffer, e0: usize, e1: usize, out: &mut Vec<u8>) {
    let bits = n.inner().slice(e0, e1 - e0);
    let groups = (e1 - e0).div_ceil(8);
    uleb(out, (groups as u64) << 1 | 1);
    let at = out.len();
    out.resize(at + groups, 0);
    let dst = &mut out[at..];
    if bits.offset().is_multiple_of(8) {
        let src = &bits.values()[bits.offset() / 8..];
        dst.copy_from_slice(&src[..groups]);
        // Bits past the last row are padding: whatever they are, the count says where to stop.
    } else {
        for (i, v) in bits.iter().enumerate() {
            dst[i / 8] |= (v as u8) << (i % 8);
        }
    }
}

/// `values` as the RLE / bit-packed hybrid of width `bw`: a group of 8 equal values starts an
/// RLE run as long as they last; other groups of 8 are bit-packed together (the last group
/// padded with zeros: the page's count of values says where they end).
fn hybrid<T: Copy + Eq + Into<u32>>(values: &[T], bw: u8, out: &mut Vec<u8>) {
    let n = values.len();
    let (mut i, mut lit) = (0, 0);
    while i + 8 <= n {
        let v = values[i];
        if values[i + 1..i + 8].iter().all(|&x| x == v) {
            let mut j = i + 8;
            while j < n && values[j] == v {
                j += 1;
            }
            bit_packed(&values[lit..i], bw, out);
            rle_run(out, (j - i) as u64, v.into(), bw);
            i = j;
            lit = j;
        } else {
            i += 8;
        }
    }
    bit_packed(&values[lit..], bw, out);
}

/// `values` bit-packed, least significant bit first, in runs of at most 63 groups of 8 (the
/// last group padded with zeros).
fn bit_packed<T: Copy + Into<u32>>(values: &[T], bw: u8, out: &mut Vec<u8>) {
    for run in values.chunks(63 * 8) {
        let groups = run.len().div_ceil(8);
        uleb(out, (groups as u64) << 1 | 1);
        let (mut acc, mut bits) = (0u64, 0u32);
        for &v in run {
            acc |= (v.into() as u64) << bits;
            bits += bw as u32;
            while bits >= 8 {
                out.push(acc as u8);
                acc >>= 8;
                bits -= 8;
            }
        }
        // The padding of the last group: zeros up to 8 values.
        let pad_bits = (groups * 8 - run.len()) * bw as usize + bits as usize;
        for _ in 0..pad_bits.div_ceil(8) {
            out.push(acc as u8);
            acc >>= 8;
        }
    }
}

/// One run of `n` times `v`.
fn rle_run(out: &mut Vec<u8>, n: u64, v: u32, bw: u8) {
    uleb(out, n << 1);
    out.extend_from_slice(&v.to_le_bytes()[..(bw as usize).div_ceil(8)]);
}

fn uleb(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push(v as u8 | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// A dictionary of byte strings: the distinct values in order of first sight, found again
/// through an open-addressing table of their hashes (also the text of a [`crate::words`]
/// set). [`Dict::clear_with`] it before its first use.
#[derive(Default)]
pub(crate) struct Dict {
    /// The values, one after the other, and where each starts (and the last ends).
    data: Vec<u8>,
    starts: Vec<u32>,
    /// Slots: value number + 1 (0 when empty) and the high half of its hash; a power of two
    /// long.
    slots: Vec<(u32, u32)>,
    /// The last value's number (runs of one value skip the table).
    last: Option<u32>,
}

impl Dict {
    fn clear(&mut self) {
        self.clear_with(1024);
    }

    /// Empty, with a table of `slots` (a power of two) to start with.
    pub(crate) fn clear_with(&mut self, slots: usize) {
        self.data.clear();
        self.starts.clear();
        self.starts.push(0);
        self.slots.clear();
        self.slots.resize(slots, (0, 0));
        self.last = None;
    }

    pub(crate) fn len(&self) -> usize {
        self.starts.len() - 1
    }

    #[inline(always)]
    pub(crate) fn value(&self, i: usize) -> &[u8] {
        &self.data[self.starts[i] as usize..self.starts[i + 1] as usize]
    }

    /// The number of `v`, added if new.
    #[inline(always)]
    pub(crate) fn intern(&mut self, v: &[u8]) -> u32 {
        if let Some(k) = self.last {
            if self.value(k as usize) == v {
                return k;
            }
        }
        let h = hash(v);
        let tag = (h >> 32) as u32;
        let mask = self.slots.len() - 1;
        let mut at = slot(h, self.slots.len());
        let k = loop {
            let (s, t) = self.slots[at];
            if s == 0 {
                self.data.extend_from_slice(v);
                self.starts.push(self.data.len() as u32);
                let n = self.len() as u32;
                self.slots[at] = (n, tag);
                if self.len() * 2 > self.slots.len() {
                    self.grow();
                }
                break n - 1;
            }
            if t == tag && self.value(s as usize - 1) == v {
                break s - 1;
            }
            at = (at + 1) & mask;
        };
        self.last = Some(k);
        k
    }

    #[cold]
    fn grow(&mut self) {
        let size = self.slots.len() * 2;
        self.slots.clear();
        self.slots.resize(size, (0, 0));
        for i in 0..self.len() {
            let h = hash(self.value(i));
            let mut at = slot(h, size);
            while self.slots[at].0 != 0 {
                at = (at + 1) & (size - 1);
            }
            self.slots[at] = (i as u32 + 1, (h >> 32) as u32);
        }
    }
}

/// The slot of hash `h` in a table of `size` (a power of two) slots: the high bits of its
/// product with 2⁶⁴/φ (Fibonacci hashing: neighbouring hashes land far apart).
#[inline]
fn slot(h: u64, size: usize) -> usize {
    (h.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> (64 - size.trailing_zeros())) as usize
}

/// A dictionary of integers (their bits): the distinct values in order of first sight.
#[derive(Default)]
struct IntDict {
    vals: Vec<u64>,
    /// Each value's number.
    nums: NumMap<u64, u32>,
    /// The last value interned and its number (runs of one value skip the map).
    last: Option<(u64, u32)>,
}

impl IntDict {
    fn clear(&mut self) {
        self.vals.clear();
        self.nums.clear();
        self.last = None;
    }

    #[inline(always)]
    fn intern(&mut self, v: u64) -> u32 {
        if let Some((l, k)) = self.last {
            if l == v {
                return k;
            }
        }
        let vals = &mut self.vals;
        let k = *self.nums.entry(v).or_insert_with(|| {
            vals.push(v);
            vals.len() as u32 - 1
        });
        self.last = Some((v, k));
        k
    }
}

/// A hash of a short byte string: the project's number hasher over its words.
#[inline]
fn hash(v: &[u8]) -> u64 {
    let mut h = NumHasher::default();
    h.write(v);
    h.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::writer_properties;
    use arrow_array::builder::{
        BinaryBuilder, Float64Builder, Int16Builder, Int64Builder, ListBuilder, StringBuilder,
        StructBuilder, UInt64Builder, UInt8Builder,
    };
    use arrow_array::{Float32Array, TimestampNanosecondArray, UInt64Array};
    use arrow_schema::Fields;
    use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;

    /// xorshift64*: reproducible values without a dependency.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
        }
        fn below(&mut self, n: u64) -> u64 {
            self.next() % n
        }
    }

    /// A batch of every type this writer takes, `rows` rows; `shape` picks how values repeat
    /// and how many are null (runs, alternations, all distinct, all null, none null).
    fn batch(rows: usize, shape: u64, seed: u64) -> RecordBatch {
        let mut r = Rng(seed | 1);
        let null_every = [0, 2, 3, 7, 1][(shape % 5) as usize];
        let distinct = [1, 3, 40, 5000, u64::MAX][(shape / 5 % 5) as usize];
        let null = |r: &mut Rng| null_every == 1 || (null_every > 1 && r.below(null_every) == 0);
        // Runs: the same value for a stretch, then another.
        let mut run = 0u64;
        let mut cur = 0u64;
        let mut val = |r: &mut Rng| {
            if run == 0 {
                run = 1 + r.below(20);
                cur = r.below(distinct);
            }
            run -= 1;
            if shape.is_multiple_of(2) {
                cur
            } else {
                r.below(distinct)
            }
        };
        let (mut u8s, mut i16s, mut i64s, mut u64s, mut f64s) = (
            UInt8Builder::new(),
            Int16Builder::new(),
            Int64Builder::new(),
            UInt64Builder::new(),
            Float64Builder::new(),
        );
        let (mut text, mut bin) = (StringBuilder::new(), BinaryBuilder::new());
        let mut list = ListBuilder::new(StringBuilder::new());
        let mut nums = ListBuilder::new(Int64Builder::new());
        let sfields = Fields::from(vec![
            Field::new("kind", DataType::Utf8, false),
            Field::new("offset", DataType::UInt64, false),
            Field::new("note", DataType::Utf8, true),
        ]);
        let mut structs = ListBuilder::new(StructBuilder::from_fields(sfields.clone(), 0));
        let (mut f32s, mut ts, mut keys) = (vec![], vec![], vec![]);
        for i in 0..rows {
            let v = val(&mut r);
            u8s.append_option((!null(&mut r)).then_some(v as u8));
            i16s.append_option((!null(&mut r)).then_some((v as i16).wrapping_sub(7)));
            i64s.append_option((!null(&mut r)).then_some((v as i64).wrapping_mul(-3)));
            u64s.append_option((!null(&mut r)).then_some(v.wrapping_mul(1 << 40)));
            let f = match v % 5 {
                0 => f64::NAN,
                1 => -0.0,
                _ => v as f64 / 3.0,
            };
            f64s.append_option((!null(&mut r)).then_some(f));
            f32s.push((!null(&mut r)).then_some(v as f32));
            ts.push((!null(&mut r)).then_some(v as i64));
            keys.push(i as u64);
            let long = (v % 97 == 0).then(|| "x".repeat(3000 + v as usize % 5000));
            let t = long.unwrap_or_else(|| format!("name-{v}"));
            text.append_option((!null(&mut r)).then_some(&t));
            bin.append_option((!null(&mut r)).then(|| t.as_bytes().to_vec()));
            if null(&mut r) {
                list.append_null();
                nums.append_null();
            } else {
                for k in 0..r.below(4) {
                    let item = (!null(&mut r)).then(|| format!("flag{}", (v + k) % 9));
                    list.values().append_option(item);
                    nums.values()
                        .append_option((!null(&mut r)).then_some((v + k) as i64));
                }
                list.append(true);
                nums.append(true);
            }
            for k in 0..r.below(3) {
                let s = structs.values();
                s.field_builder::<StringBuilder>(0)
                    .expect("kind")
                    .append_value(format!("k{}", (v + k) % 4));
                s.field_builder::<UInt64Builder>(1)
                    .expect("offset")
                    .append_value(v + k);
                let note = (!null(&mut r)).then(|| format!("note {v}"));
                s.field_builder::<StringBuilder>(2)
                    .expect("note")
                    .append_option(note);
                s.append(true);
            }
            structs.append(true);
        }
        let cols: Vec<(&str, ArrayRef)> = vec![
            ("key", Arc::new(UInt64Array::from(keys))),
            ("u8", Arc::new(u8s.finish())),
            ("i16", Arc::new(i16s.finish())),
            ("i64", Arc::new(i64s.finish())),
            ("u64", Arc::new(u64s.finish())),
            ("f64", Arc::new(f64s.finish())),
            ("f32", Arc::new(Float32Array::from(f32s))),
            (
                "time",
                Arc::new(TimestampNanosecondArray::from(ts).with_timezone("UTC")),
            ),
            ("text", Arc::new(text.finish())),
            ("bin", Arc::new(bin.finish())),
            ("flags", Arc::new(list.finish())),
            ("nums", Arc::new(nums.finish())),
            ("diags", Arc::new(structs.finish())),
        ];
        let fields: Vec<Field> = cols
            .iter()
            .map(|(n, a)| {
                // The list of structs holds no null lists: a column that may not have any.
                let nullable = *n != "key" && *n != "diags";
                Field::new(*n, a.data_type().clone(), nullable)
            })
            .collect();
        let schema = Arc::new(Schema::new(fields));
        RecordBatch::try_new(schema, cols.into_iter().map(|(_, a)| a).collect()).expect("batch")
    }

    /// Every type, repetition and null pattern, in row groups of one to many pages (long
    /// text cuts pages by bytes, dictionaries overflow into plain): what a reader reads back
    /// is the batch, and the statistics are those of its values.
    #[test]
    fn read_back_is_the_batch() {
        for (case, rows) in [1usize, 7, 8, 9, 64, 1000, 20_001, 30_000]
            .iter()
            .enumerate()
        {
            for shape in 0..25u64 {
                if *rows > 1000 && shape % 4 != 0 {
                    continue;
                }
                let b = batch(*rows, shape, (case as u64 + 1) * 7919 + shape);
                assert!(supports(&b.schema()));
                let t = TableProps::new(&b.schema(), writer_properties(65_536, &b.schema()))
                    .expect("props");
                let mut w = PartWriter::new(Vec::new(), &t).expect("writer");
                w.write(&b).expect("write");
                // A slice: arrays that start at an offset, bitmaps not on a byte boundary.
                let part = b.slice(rows / 3, rows / 2);
                w.write(&part).expect("second row group");
                let bytes = w.finish().expect("finish");
                let r = ParquetRecordBatchReaderBuilder::try_new(Bytes::from(bytes))
                    .expect("parquet")
                    .with_batch_size(1 << 20)
                    .build()
                    .expect("reader");
                let back: Vec<RecordBatch> = r.map(|b| b.expect("batch")).collect();
                let whole = concat_batches(&[b.clone(), part]);
                let got = concat_batches(&back);
                assert_eq!(got, whole, "{rows} rows, shape {shape}");
            }
        }
    }

    /// Text as a dictionary array of words, as `crate::words` makes them but in another order
    /// (last seen first) and with a word no row uses: the writer renumbers by first sight.
    fn to_words(a: &dyn Array) -> ArrayRef {
        let t = a.as_string::<i32>();
        let mut seen: Vec<&str> = Vec::new();
        for v in t.iter().flatten() {
            if !seen.contains(&v) {
                seen.push(v);
            }
        }
        seen.reverse();
        seen.push("unused");
        let keys: Vec<Option<i32>> = t
            .iter()
            .map(|v| v.map(|v| seen.iter().position(|w| *w == v).expect("word") as i32))
            .collect();
        let words: ArrayRef = Arc::new(arrow_array::StringArray::from(seen));
        Arc::new(
            arrow_array::DictionaryArray::try_new(arrow_array::Int32Array::from(keys), words)
                .expect("dictionary"),
        )
    }

    /// `b` with its text columns `text`, `flags` (list items) and `diags.kind` as words.
    fn words_batch(b: &RecordBatch) -> RecordBatch {
        let schema = b.schema();
        let mut fields = Vec::new();
        let mut cols = Vec::new();
        for (f, c) in schema.fields().iter().zip(b.columns()) {
            let c: ArrayRef = match f.name().as_str() {
                "text" => to_words(c.as_ref()),
                "flags" => {
                    let l = c.as_list::<i32>();
                    let values = to_words(l.values().as_ref());
                    let item = Arc::new(Field::new("item", values.data_type().clone(), true));
                    Arc::new(
                        ListArray::try_new(item, l.offsets().clone(), values, l.nulls().cloned())
                            .expect("list"),
                    )
                }
                "diags" => {
                    let l = c.as_list::<i32>();
                    let st = l.values().as_struct();
                    let mut kids = st.columns().to_vec();
                    kids[0] = to_words(kids[0].as_ref());
                    let sf: Fields = st
                        .fields()
                        .iter()
                        .zip(&kids)
                        .map(|(f, k)| {
                            Arc::new(f.as_ref().clone().with_data_type(k.data_type().clone()))
                        })
                        .collect();
                    let st =
                        arrow_array::StructArray::try_new(sf.clone(), kids, None).expect("struct");
                    let item = Arc::new(Field::new("item", DataType::Struct(sf), true));
                    Arc::new(
                        ListArray::try_new(item, l.offsets().clone(), Arc::new(st), None)
                            .expect("list"),
                    )
                }
                _ => c.clone(),
            };
            fields.push(f.as_ref().clone().with_data_type(c.data_type().clone()));
            cols.push(c);
        }
        RecordBatch::try_new(Arc::new(Schema::new(fields)), cols).expect("words batch")
    }

    /// Text given as dictionaries of words is written byte for byte as the text itself: whole
    /// batches and slices, every null and repetition pattern, words out of order and unused.
    #[test]
    fn words_are_written_as_their_text() {
        for (case, rows) in [1usize, 9, 1000, 20_001].iter().enumerate() {
            for shape in 0..25u64 {
                if *rows > 1000 && shape % 4 != 0 {
                    continue;
                }
                let b = batch(*rows, shape, (case as u64 + 3) * 104_729 + shape);
                let w = words_batch(&b);
                assert_ne!(w.schema(), b.schema());
                let t = TableProps::new(&b.schema(), writer_properties(65_536, &b.schema()))
                    .expect("props");
                let write = |b: &RecordBatch| {
                    let mut w = PartWriter::new(Vec::new(), &t).expect("writer");
                    w.write(b).expect("write");
                    w.write(&b.slice(rows / 3, rows / 2)).expect("slice");
                    w.finish().expect("finish")
                };
                assert!(write(&w) == write(&b), "{rows} rows, shape {shape}");
            }
        }
    }

    /// The batches' rows one after the other.
    fn concat_batches(bs: &[RecordBatch]) -> RecordBatch {
        let schema = bs[0].schema();
        let cols = (0..schema.fields().len())
            .map(|i| {
                let parts: Vec<&dyn Array> = bs.iter().map(|b| b.column(i).as_ref()).collect();
                concat(&parts)
            })
            .collect();
        RecordBatch::try_new(schema, cols).expect("concat")
    }

    fn concat(parts: &[&dyn Array]) -> ArrayRef {
        let datas: Vec<arrow_data::ArrayData> = parts.iter().map(|a| a.to_data()).collect();
        let refs: Vec<&arrow_data::ArrayData> = datas.iter().collect();
        let mut m = arrow_data::transform::MutableArrayData::new(refs, false, 0);
        for (i, a) in parts.iter().enumerate() {
            m.try_extend(i, 0, a.len()).expect("extend");
        }
        arrow_array::make_array(m.freeze())
    }
}
