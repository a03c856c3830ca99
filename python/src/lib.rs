//! The native part of the `aptscope` Python package. The Python module `aptscope` wraps it
//! (see `aptscope/__init__.py` for the documented API).
//!
//! Everything decodes through `record::Decoder` (directly or inside
//! `aptscope_parquet::decode_file`): records as dicts built by `json::record` straight into
//! Python objects (the documented NDJSON shape, no text in between), tables as the Arrow record
//! batches the Parquet writer would encode (the dataset's schema exactly), handed to pyarrow
//! through the Arrow C data interface.

use aptscope_capture::open::{open, OpenOptions};
use aptscope_capture::Reader;
use aptscope_dissector::apt::{encode_named, Addr, Named};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::json;
use aptscope_dissector::record::{Ctx, Decoder, Record};
use aptscope_dissector::table::Dir;
use aptscope_dissector::Table;
use aptscope_parquet::pool::{RowPool, Wanted};
use aptscope_parquet::schema::{records_schema, Kinds, RECORDS};
use aptscope_parquet::{decode_file, CaptureWriter, DecodeOpts, DirSink, Options, Sink};
use arrow_array::ffi_stream::FFI_ArrowArrayStream;
use arrow_array::{Array, RecordBatch, RecordBatchIterator, StructArray};
use arrow_data::ffi::FFI_ArrowArray;
use arrow_schema::ffi::FFI_ArrowSchema;
use pyo3::create_exception;
use pyo3::exceptions::{PyFileNotFoundError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyBytes, PyCapsule, PyDict, PyFloat, PyInt, PyList, PyString};
use std::cell::RefCell;
use std::collections::{HashMap, HashSet, VecDeque};
use std::convert::Infallible;
use std::io;
use std::path::Path;
use std::rc::Rc;
use std::sync::Arc;

create_exception!(
    _aptscope,
    AptscopeError,
    PyValueError,
    "An input aptscope cannot decode, or arguments it cannot use; the message is the diagnostic."
);
create_exception!(
    _aptscope,
    EncodeError,
    AptscopeError,
    "A message that cannot be encoded: unknown name, field or value."
);

fn err(e: io::Error) -> PyErr {
    match e.kind() {
        io::ErrorKind::NotFound => PyFileNotFoundError::new_err(e.to_string()),
        _ => AptscopeError::new_err(e.to_string()),
    }
}

fn proto_of(p: &str) -> PyResult<Option<Proto>> {
    match p {
        "auto" => Ok(None),
        "apt" => Ok(Some(Proto::Apt)),
        "elliptec" | "ell" => Ok(Some(Proto::Elliptec)),
        _ => Err(AptscopeError::new_err(format!(
            "proto {p:?}: one of \"auto\", \"apt\", \"elliptec\""
        ))),
    }
}

/// What to decode: a capture file, or the bytes of one serial stream.
enum Source {
    Path(String),
    Bytes(Vec<u8>),
}

fn source(obj: &Bound<'_, PyAny>) -> PyResult<Source> {
    if let Ok(b) = obj.cast::<PyBytes>() {
        return Ok(Source::Bytes(b.as_bytes().to_vec()));
    }
    if let Ok(b) = obj.extract::<Vec<u8>>() {
        if !obj.is_instance_of::<pyo3::types::PyString>() {
            return Ok(Source::Bytes(b));
        }
    }
    let os = obj.py().import("os")?;
    let p = os.call_method1("fspath", (obj,))?;
    Ok(Source::Path(p.extract()?))
}

/// A source being decoded: a capture file's reader, or the bytes of one stream.
struct Input {
    reader: Option<Box<dyn Reader>>,
    bytes: Option<Vec<u8>>,
    dec: Decoder,
}

impl Input {
    /// Open `source_obj`; with the name of the source (its path, or `<bytes>`).
    fn open(source_obj: &Bound<'_, PyAny>, proto: &str) -> PyResult<(Input, String)> {
        let dec = Decoder::new(proto_of(proto)?);
        Ok(match source(source_obj)? {
            Source::Path(p) => {
                let reader = open(&p, OpenOptions::default())
                    .map_err(|e| err(e.into()))?
                    .0;
                let i = Input {
                    reader: Some(reader),
                    bytes: None,
                    dec,
                };
                (i, p)
            }
            Source::Bytes(b) => {
                let i = Input {
                    reader: None,
                    bytes: Some(b),
                    dec,
                };
                (i, "<bytes>".into())
            }
        })
    }
}

/// The records of one source as dicts, produced as they are read.
#[pyclass(unsendable)]
struct Records {
    input: Input,
    queue: VecDeque<Py<PyAny>>,
    done: bool,
    keys: Keys,
}

#[pymethods]
impl Records {
    #[new]
    #[pyo3(signature = (source_obj, proto = "auto"))]
    fn new(source_obj: &Bound<'_, PyAny>, proto: &str) -> PyResult<Self> {
        Ok(Records {
            input: Input::open(source_obj, proto)?.0,
            queue: VecDeque::new(),
            done: false,
            keys: Keys::default(),
        })
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self, py: Python<'_>) -> PyResult<Option<Py<PyAny>>> {
        while self.queue.is_empty() && !self.done {
            self.fill(py)?;
        }
        Ok(self.queue.pop_front())
    }
}

impl Records {
    /// Decode the next event (or all the bytes) into the queue.
    fn fill(&mut self, py: Python<'_>) -> PyResult<()> {
        let (q, keys) = (&mut self.queue, &mut self.keys);
        let mut emit = |r: &Record<'_>| -> PyResult<()> {
            let mut sink = PySink::new(py, keys);
            json::record(&mut sink, r, None);
            q.push_back(sink.finish()?);
            Ok(())
        };
        let i = &mut self.input;
        if let Some(b) = i.bytes.take() {
            i.dec.push(Ctx::default(), &b, &mut emit)?;
            i.dec.finish(&mut emit)?;
            self.done = true;
            return Ok(());
        }
        let Some(r) = i.reader.as_mut() else {
            self.done = true;
            return Ok(());
        };
        match r.next_event() {
            Some(ev) => ev.feed(&mut i.dec, &mut emit),
            None => {
                self.done = true;
                i.dec.finish(&mut emit)
            }
        }
    }
}

/// A record's shape built straight as Python objects (dicts, lists, str, int, float, bool,
/// None) by `json::record`: the dicts `json.loads` would make of the NDJSON line, without the
/// line.
struct PySink<'py, 'k> {
    py: Python<'py>,
    keys: &'k mut Keys,
    /// Open dicts and lists, innermost last (each already placed in its parent).
    stack: Vec<Open<'py>>,
    /// The key of the next member of the innermost dict.
    key: Option<Bound<'py, PyString>>,
    /// The record, once its object is opened.
    top: Option<Bound<'py, PyAny>>,
    /// The first Python error met (the sink's methods cannot return one).
    err: Option<PyErr>,
}

enum Open<'py> {
    Dict(Bound<'py, PyDict>),
    List(Bound<'py, PyList>),
}

/// The Python strings of keys that live as long as the program, by address and length: made
/// once (with their hash computed once), not per record.
#[derive(Default)]
struct Keys(HashMap<(usize, usize), Py<PyString>>);

impl<'py, 'k> PySink<'py, 'k> {
    fn new(py: Python<'py>, keys: &'k mut Keys) -> Self {
        PySink {
            py,
            keys,
            stack: Vec::with_capacity(8),
            key: None,
            top: None,
            err: None,
        }
    }

    /// The record built, or the first error.
    fn finish(self) -> PyResult<Py<PyAny>> {
        if let Some(e) = self.err {
            return Err(e);
        }
        self.top
            .map(Bound::unbind)
            .ok_or_else(|| AptscopeError::new_err("empty record"))
    }

    /// Place a value under the pending key, at the end of the open list, or as the record.
    fn put(&mut self, v: Bound<'py, PyAny>) {
        let r = match self.stack.last() {
            None => {
                self.top = Some(v);
                Ok(())
            }
            Some(Open::Dict(d)) => match self.key.take() {
                Some(k) => d.set_item(k, v),
                None => Err(AptscopeError::new_err("a dict member without a key")),
            },
            Some(Open::List(l)) => l.append(v),
        };
        if let Err(e) = r {
            self.err.get_or_insert(e);
        }
    }

    fn put_int<T>(&mut self, x: T)
    where
        T: IntoPyObject<'py, Target = PyInt, Output = Bound<'py, PyInt>, Error = Infallible>,
    {
        let Ok(v) = x.into_pyobject(self.py);
        self.put(v.into_any());
    }
}

impl json::Sink for PySink<'_, '_> {
    fn begin_obj(&mut self) {
        let d = PyDict::new(self.py);
        self.put(d.clone().into_any());
        self.stack.push(Open::Dict(d));
    }
    fn end_obj(&mut self) {
        self.stack.pop();
    }
    fn begin_list(&mut self) {
        let l = PyList::empty(self.py);
        self.put(l.clone().into_any());
        self.stack.push(Open::List(l));
    }
    fn end_list(&mut self) {
        self.stack.pop();
    }
    fn key(&mut self, k: &str) {
        self.key = Some(PyString::new(self.py, k));
    }
    fn key_static(&mut self, k: &'static str) {
        let py = self.py;
        let s = self
            .keys
            .0
            .entry((k.as_ptr() as usize, k.len()))
            .or_insert_with(|| PyString::new(py, k).unbind());
        self.key = Some(s.bind(py).clone());
    }
    fn key_lit(&mut self, k: &json::Lit) {
        self.key_static(k.name);
    }
    fn str(&mut self, s: &str) {
        self.put(PyString::new(self.py, s).into_any());
    }
    fn hex(&mut self, b: &[u8]) {
        let mut s = String::with_capacity(b.len() * 2);
        json::hex_digits(&mut s, b);
        self.str(&s);
    }
    fn uint(&mut self, x: u64) {
        self.put_int(x);
    }
    fn int(&mut self, x: i64) {
        self.put_int(x);
    }
    fn float(&mut self, x: f64) {
        if !x.is_finite() {
            return self.null();
        }
        // NDJSON writes a whole float without a fraction, which `json.loads` reads as an int.
        if x.fract() == 0.0 {
            if x.abs() < 9.0e18 {
                return self.put_int(x as i64);
            }
            // Beyond 64 bits: the int of the digits NDJSON writes (`{x}` pads with zeros).
            let int = self.py.get_type::<PyInt>().call1((format!("{x}"),));
            return match int {
                Ok(v) => self.put(v),
                Err(e) => {
                    self.err.get_or_insert(e);
                }
            };
        }
        self.put(PyFloat::new(self.py, x).into_any());
    }
    fn fixed(&mut self, x: f64, decimals: usize) {
        // The value of the digits written, as `json.loads` reads them (`1.000` is a float).
        let v = format!("{x:.decimals$}").parse().unwrap_or(x);
        self.put(PyFloat::new(self.py, v).into_any());
    }
    fn bool(&mut self, b: bool) {
        self.put(PyBool::new(self.py, b).to_owned().into_any());
    }
    fn null(&mut self) {
        self.put(self.py.None().into_bound(self.py));
    }
}

/// Row groups as the writer flushes them, by table, for [`Batches`] to hand out.
type BatchQueue = Rc<RefCell<VecDeque<(String, RecordBatch)>>>;

/// A [`Sink`] that queues each row group as an Arrow record batch (no Parquet encoding).
struct QueueSink(BatchQueue);

impl Sink for QueueSink {
    fn write(&mut self, table: &str, _part: u32, batch: &RecordBatch) -> io::Result<()> {
        self.0
            .borrow_mut()
            .push_back((table.to_string(), batch.clone()));
        Ok(())
    }
}

/// Where the rows are built: on this thread, or on a pool's threads from runs of records.
enum Rows {
    One(Box<CaptureWriter<QueueSink>>),
    Pool {
        pool: Box<RowPool>,
        /// Whether the source is decoded to its end (the pool may still be building).
        decoded: bool,
    },
}

/// The tables of one source as `(table, batch)` pairs, each batch at most a row group of the
/// Parquet output's schema (exactly one with one thread), produced as the source is decoded
/// (memory stays that of a row group per table, or of a few runs per thread, whatever the
/// source's size).
#[pyclass(unsendable)]
struct Batches {
    input: Input,
    rows: Option<Rows>,
    queue: BatchQueue,
}

#[pymethods]
impl Batches {
    #[new]
    #[pyo3(signature = (source_obj, proto = "auto", name = None, tables = None, threads = None))]
    fn new(
        source_obj: &Bound<'_, PyAny>,
        proto: &str,
        name: Option<String>,
        tables: Option<Vec<String>>,
        threads: Option<usize>,
    ) -> PyResult<Self> {
        // Checked before the source is opened: a misspelt table is an error, not no rows.
        if let Some(t) = &tables {
            if let Some(bad) = t
                .iter()
                .find(|t| *t != RECORDS && !Kinds::global().contains(t))
            {
                return Err(AptscopeError::new_err(format!(
                    "table {bad:?}: neither \"records\" nor a message kind"
                )));
            }
        }
        let (input, label) = Input::open(source_obj, proto)?;
        let label = name.unwrap_or(label);
        let queue = BatchQueue::default();
        // Text columns built as text: Python gets the tables' declared types, and keeps the
        // batches.
        let opts = Options {
            words_as_text: true,
            batches_kept: true,
            ..Options::default()
        };
        // Only these are built: the others cost nothing.
        let wanted: Option<Wanted> = tables.map(|t| {
            let keep: HashSet<String> = t.into_iter().collect();
            Arc::new(move |n: &str| keep.contains(n)) as Wanted
        });
        let threads = threads
            .or_else(|| std::thread::available_parallelism().ok().map(usize::from))
            .unwrap_or(1);
        let rows = if threads > 1 {
            let mut pool = RowPool::new(threads, &label, opts, wanted, Ok).map_err(err)?;
            if let Some(n) = aptscope_parquet::pool::records_from_env() {
                pool.set_run_records(n);
            }
            Rows::Pool {
                pool: Box::new(pool),
                decoded: false,
            }
        } else {
            let mut w = CaptureWriter::new(QueueSink(queue.clone()), &label, opts);
            if let Some(f) = wanted {
                w.only_tables(move |n| f(n));
            }
            Rows::One(Box::new(w))
        };
        Ok(Batches {
            input,
            rows: Some(rows),
            queue,
        })
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self, py: Python<'_>) -> PyResult<Option<(String, ArrowBatch)>> {
        Ok(self.next_batch(py)?.map(|(t, b)| (t, ArrowBatch(b))))
    }
}

impl Batches {
    /// The next `(table, batch)`, decoding as much as it takes; `None` at the end.
    fn next_batch(&mut self, py: Python<'_>) -> PyResult<Option<(String, RecordBatch)>> {
        loop {
            if let Some(tb) = self.queue.borrow_mut().pop_front() {
                return Ok(Some(tb));
            }
            match &mut self.rows {
                None => return Ok(None),
                Some(Rows::Pool {
                    pool,
                    decoded: true,
                    ..
                }) => {
                    // Decoded: wait for the threads, without holding up Python's.
                    match py.detach(|| pool.next(true)) {
                        Some(g) => self.queue.borrow_mut().extend(g.map_err(err)?),
                        None => self.rows = None,
                    }
                }
                Some(_) => self.step().map_err(err)?,
            }
        }
    }

    /// Decode the next event (or all the bytes); at the end, flush what the writer holds.
    fn step(&mut self) -> io::Result<()> {
        let Some(rows) = self.rows.as_mut() else {
            return Ok(());
        };
        let queue = &self.queue;
        let mut emit = |r: &Record<'_>| match rows {
            Rows::One(w) => w.record(r),
            Rows::Pool { pool, .. } => pool.push(r, &mut |g| queue.borrow_mut().extend(g)),
        };
        let i = &mut self.input;
        let more = if let Some(b) = i.bytes.take() {
            i.dec.push(Ctx::default(), &b, &mut emit)?;
            false
        } else if let Some(ev) = i.reader.as_mut().and_then(|r| r.next_event()) {
            // A USB capture without the device asked for has nothing to decode.
            if let aptscope_capture::Event::Diag(d) = &ev {
                if d.kind() == aptscope_capture::usb::NOT_FOUND {
                    return Err(io::Error::new(io::ErrorKind::InvalidInput, d.msg()));
                }
            }
            ev.feed(&mut i.dec, &mut emit)?;
            true
        } else {
            false
        };
        if !more {
            i.dec.finish(&mut emit)?;
            match self.rows.as_mut() {
                Some(Rows::Pool { pool, decoded }) => {
                    pool.flush(&mut |g| queue.borrow_mut().extend(g))?;
                    // The threads' last runs are taken back by `__next__`.
                    *decoded = true;
                }
                _ => {
                    if let Some(Rows::One(w)) = self.rows.take() {
                        w.finish()?;
                    }
                }
            }
        }
        Ok(())
    }
}

/// One record batch, handed to pyarrow through the Arrow PyCapsule interface
/// (`pyarrow.record_batch(b)`): the columns are shared, not copied or re-encoded.
#[pyclass]
struct ArrowBatch(RecordBatch);

#[pymethods]
impl ArrowBatch {
    /// The batch as a struct array: `(schema capsule, array capsule)`.
    #[pyo3(signature = (requested_schema = None))]
    fn __arrow_c_array__<'py>(
        &self,
        py: Python<'py>,
        requested_schema: Option<Bound<'py, PyAny>>,
    ) -> PyResult<(Bound<'py, PyCapsule>, Bound<'py, PyCapsule>)> {
        // The schema is the Parquet output's; a requested one is not cast to.
        let _ = requested_schema;
        let schema = FFI_ArrowSchema::try_from(self.0.schema().as_ref())
            .map_err(|e| AptscopeError::new_err(e.to_string()))?;
        let array = FFI_ArrowArray::new(&StructArray::from(self.0.clone()).into_data());
        Ok((
            PyCapsule::new_with_value(py, schema, c"arrow_schema")?,
            PyCapsule::new_with_value(py, array, c"arrow_array")?,
        ))
    }

    /// Rows in the batch.
    fn __len__(&self) -> usize {
        self.0.num_rows()
    }
}

/// One table's batches, handed to pyarrow as one stream (the Arrow PyCapsule protocol's
/// `__arrow_c_stream__`, `pyarrow.table(t)`): its schema crosses once, not with each batch.
/// Imported batch by batch, with `Table.from_batches` after, a capture of every message form
/// (6,785 batches of 526 tables) spent 0.5 s in pyarrow, a third of `to_arrow()`'s time.
#[pyclass]
struct ArrowTable {
    schema: arrow_schema::SchemaRef,
    batches: Vec<RecordBatch>,
}

#[pymethods]
impl ArrowTable {
    /// The batches as an Arrow C stream capsule.
    #[pyo3(signature = (requested_schema = None))]
    fn __arrow_c_stream__<'py>(
        &self,
        py: Python<'py>,
        requested_schema: Option<Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyCapsule>> {
        // The schema is the Parquet output's; a requested one is not cast to.
        let _ = requested_schema;
        let reader = RecordBatchIterator::new(
            self.batches.clone().into_iter().map(Ok),
            self.schema.clone(),
        );
        let stream = FFI_ArrowArrayStream::new(Box::new(reader));
        PyCapsule::new_with_value(py, stream, c"arrow_array_stream")
    }

    /// Rows in the table.
    fn __len__(&self) -> usize {
        self.batches.iter().map(RecordBatch::num_rows).sum()
    }
}

/// Every table of a source (as [`Batches`] gives them, gathered): `[(table, ArrowTable)]`,
/// `records` first (with no rows when the source has no record and it is wanted), the others
/// as they first came.
#[pyfunction]
#[pyo3(signature = (source_obj, proto = "auto", name = None, tables = None, threads = None))]
fn tables(
    py: Python<'_>,
    source_obj: &Bound<'_, PyAny>,
    proto: &str,
    name: Option<String>,
    tables: Option<Vec<String>>,
    threads: Option<usize>,
) -> PyResult<Vec<(String, ArrowTable)>> {
    let records_wanted = tables
        .as_ref()
        .is_none_or(|t| t.iter().any(|t| t == RECORDS));
    let mut b = Batches::new(source_obj, proto, name, tables, threads)?;
    let mut out: Vec<(String, ArrowTable)> = Vec::new();
    let mut at: HashMap<String, usize> = HashMap::new();
    if records_wanted {
        at.insert(RECORDS.to_string(), 0);
        out.push((
            RECORDS.to_string(),
            ArrowTable {
                schema: records_schema(),
                batches: Vec::new(),
            },
        ));
    }
    while let Some((t, batch)) = b.next_batch(py)? {
        let i = *at.entry(t).or_insert_with_key(|t| {
            out.push((
                t.clone(),
                ArrowTable {
                    schema: batch.schema(),
                    batches: Vec::new(),
                },
            ));
            out.len() - 1
        });
        if let Some((_, tb)) = out.get_mut(i) {
            if tb.batches.is_empty() {
                // The schema of its batches (the records table's first: the empty one's
                // otherwise).
                tb.schema = batch.schema();
            }
            tb.batches.push(batch);
        }
    }
    Ok(out)
}

/// Decode capture `path` into dataset directory `out` as input number `index` (its part files
/// are `TABLE/part-INDEX-*.parquet`), as `aptscope decode --to parquet` does. Returns counts.
#[pyfunction]
#[pyo3(signature = (path, out, index, proto = "auto", name = None))]
fn write_dataset<'py>(
    py: Python<'py>,
    path: &Bound<'py, PyAny>,
    out: &Bound<'py, PyAny>,
    index: usize,
    proto: &str,
    name: Option<String>,
) -> PyResult<Bound<'py, PyDict>> {
    let proto = proto_of(proto)?;
    let Source::Path(path) = source(path)? else {
        return Err(AptscopeError::new_err(
            "write_dataset reads a capture file: give its path",
        ));
    };
    let Source::Path(out) = source(out)? else {
        return Err(AptscopeError::new_err("out is a directory path"));
    };
    let label = name.unwrap_or_else(|| path.clone());
    let s = py
        .detach(|| {
            let opts = Options::default();
            let w = CaptureWriter::new(DirSink::new(Path::new(&out), index, opts), &label, opts);
            let o = DecodeOpts {
                proto,
                judge: true,
                ..Default::default()
            };
            decode_file(&path, &o, w, &mut |_| {}).map(|(_, s)| s)
        })
        .map_err(err)?;
    let d = PyDict::new(py);
    d.set_item("records", s.records)?;
    d.set_item("frames", s.frames)?;
    d.set_item("diagnostics", s.diagnostics)?;
    d.set_item("row_groups", s.row_groups)?;
    Ok(d)
}

/// Create dataset directory `out` (with `force`, replace an earlier dataset there).
#[pyfunction]
#[pyo3(signature = (out, force = false))]
fn prepare_dataset(out: &Bound<'_, PyAny>, force: bool) -> PyResult<()> {
    let Source::Path(out) = source(out)? else {
        return Err(AptscopeError::new_err("out is a directory path"));
    };
    aptscope_parquet::prepare_dir(Path::new(&out), force).map_err(err)
}

/// The frame of APT message `name` (or Elliptec command, by name or mnemonic) with `fields`
/// (values as text, as `aptscope encode` takes them).
#[pyfunction]
#[pyo3(signature = (name, fields, dst = None, src = None, form = None, sub = None))]
fn encode<'py>(
    py: Python<'py>,
    name: &str,
    fields: Vec<(String, String)>,
    dst: Option<&str>,
    src: Option<&str>,
    form: Option<&str>,
    sub: Option<&str>,
) -> PyResult<Bound<'py, PyBytes>> {
    let pairs: Vec<(&str, &str)> = fields
        .iter()
        .map(|(k, v)| (k.as_str(), v.as_str()))
        .collect();
    let table = Table::global();
    let bytes = if let Some(m) = table.msg_by_name(name) {
        let to_host = m.dir == Dir::DeviceToHost;
        let (dd, ds) = if to_host {
            (Addr::Host, Addr::Usb)
        } else {
            (Addr::Usb, Addr::Host)
        };
        let addr = |s: Option<&str>, d: Addr| -> PyResult<u8> {
            match s {
                None => Ok(d.byte()),
                Some(t) => Addr::parse(t)
                    .map(Addr::byte)
                    .ok_or_else(|| EncodeError::new_err(format!("bad address {t}"))),
            }
        };
        let n = Named {
            name,
            sub,
            values: &pairs,
            form,
            dst: addr(dst, dd)?,
            src: addr(src, ds)?,
        };
        encode_named(table, &n).map_err(|e| EncodeError::new_err(e.to_string()))?
    } else if let Some(c) = aptscope_dissector::ell::table::by_name(name)
        .or_else(|| aptscope_dissector::ell::table::lookup(name.as_bytes()))
    {
        // Elliptec: the module's address is `dst` (a command) or `src` (a reply), default 0.
        let a = dst.or(src).unwrap_or("0");
        aptscope_dissector::ell::encode(a, c.code, &pairs)
            .map_err(|e| EncodeError::new_err(e.to_string()))?
    } else {
        return Err(EncodeError::new_err(
            aptscope_dissector::apt::EncodeError::unknown_message(table, name).to_string(),
        ));
    };
    Ok(PyBytes::new(py, &bytes))
}

/// The native module.
#[pymodule]
fn _aptscope(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Records>()?;
    m.add_class::<Batches>()?;
    m.add_class::<ArrowBatch>()?;
    m.add_class::<ArrowTable>()?;
    m.add_function(wrap_pyfunction!(tables, m)?)?;
    m.add_function(wrap_pyfunction!(write_dataset, m)?)?;
    m.add_function(wrap_pyfunction!(prepare_dataset, m)?)?;
    m.add_function(wrap_pyfunction!(encode, m)?)?;
    m.add("AptscopeError", m.py().get_type::<AptscopeError>())?;
    m.add("EncodeError", m.py().get_type::<EncodeError>())?;
    Ok(())
}
