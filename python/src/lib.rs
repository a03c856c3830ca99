//! The native part of the `aptscope` Python package. The Python module `aptscope` wraps it
//! (see `aptscope/__init__.py` for the documented API).
//!
//! Everything decodes through `record::Decoder` (directly or inside `Pipeline` and
//! `aptscope_parquet::decode_file`): records as NDJSON lines (the documented shape, which the
//! Python side turns into dicts), tables as Parquet bytes (the dataset's schema exactly).

use aptscope_capture::open::{open, OpenOptions};
use aptscope_capture::{Event, Reader};
use aptscope_dissector::apt::{encode_named, Addr, Named};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::pipeline::{Format, Pipeline};
use aptscope_dissector::record::{Ctx, Decoder};
use aptscope_dissector::table::Dir;
use aptscope_dissector::Table;
use aptscope_parquet::{decode_file, CaptureWriter, DecodeOpts, DirSink, MemSink, Options};
use pyo3::create_exception;
use pyo3::exceptions::{PyFileNotFoundError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use std::collections::VecDeque;
use std::io;
use std::path::Path;

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

/// NDJSON lines of one source, produced as they are read.
#[pyclass(unsendable)]
struct Lines {
    reader: Option<Box<dyn Reader>>,
    bytes: Option<Vec<u8>>,
    p: Pipeline,
    queue: VecDeque<String>,
    done: bool,
}

#[pymethods]
impl Lines {
    #[new]
    #[pyo3(signature = (source_obj, proto = "auto"))]
    fn new(source_obj: &Bound<'_, PyAny>, proto: &str) -> PyResult<Self> {
        let proto = proto_of(proto)?;
        let (reader, bytes) = match source(source_obj)? {
            Source::Path(p) => (
                Some(
                    open(&p, OpenOptions::default())
                        .map_err(|e| err(e.into()))?
                        .0,
                ),
                None,
            ),
            Source::Bytes(b) => (None, Some(b)),
        };
        Ok(Lines {
            reader,
            bytes,
            p: Pipeline::new(proto, Format::Json),
            queue: VecDeque::new(),
            done: false,
        })
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self) -> PyResult<Option<String>> {
        while self.queue.is_empty() && !self.done {
            self.fill().map_err(err)?;
        }
        Ok(self.queue.pop_front())
    }
}

impl Lines {
    /// Decode the next event (or all the bytes) into the queue.
    fn fill(&mut self) -> io::Result<()> {
        let q = &mut self.queue;
        let mut emit = |l: &str| -> io::Result<()> {
            q.push_back(l.to_string());
            Ok(())
        };
        if let Some(b) = self.bytes.take() {
            self.p.push(&b, None, &mut emit)?;
            self.p.finish(&mut emit)?;
            self.done = true;
            return Ok(());
        }
        let Some(r) = self.reader.as_mut() else {
            self.done = true;
            return Ok(());
        };
        match r.next_event() {
            Some(Event::Chunk(c)) => self.p.push_chunk(c.ctx(), c.bytes, &mut emit),
            Some(Event::Diag(d)) => self.p.file_diag(d.offset, d.kind(), &d.msg(), &mut emit),
            Some(Event::Stream(s)) => {
                self.p
                    .stream_info(s.id, &s.name, s.settings.as_deref(), &mut emit)
            }
            None => {
                self.done = true;
                self.p.finish(&mut emit)
            }
        }
    }
}

/// Every table of one source as Parquet bytes: `[(table, bytes)]`, `records` first.
#[pyfunction]
#[pyo3(signature = (source_obj, proto = "auto", name = None))]
fn parquet_tables<'py>(
    py: Python<'py>,
    source_obj: &Bound<'py, PyAny>,
    proto: &str,
    name: Option<String>,
) -> PyResult<Vec<(String, Bound<'py, PyBytes>)>> {
    let proto = proto_of(proto)?;
    let src = source(source_obj)?;
    let opts = Options::default();
    let tables = py
        .detach(|| -> io::Result<Vec<(String, Vec<u8>)>> {
            let sink = match src {
                Source::Path(p) => {
                    let label = name.unwrap_or_else(|| p.clone());
                    let w = CaptureWriter::new(MemSink::new(opts), &label, opts);
                    let o = DecodeOpts {
                        proto,
                        ..Default::default()
                    };
                    decode_file(&p, &o, w, &mut |_| {})?.0
                }
                Source::Bytes(b) => {
                    let label = name.unwrap_or_else(|| "<bytes>".into());
                    let mut w = CaptureWriter::new(MemSink::new(opts), &label, opts);
                    let mut d = Decoder::new(proto);
                    d.push(Ctx::default(), &b, &mut |r| w.record(r))?;
                    d.finish(&mut |r| w.record(r))?;
                    w.finish()?.0
                }
            };
            let mut t = sink.finish()?;
            t.sort_by_key(|(n, _)| n != aptscope_parquet::schema::RECORDS);
            Ok(t)
        })
        .map_err(err)?;
    Ok(tables
        .into_iter()
        .map(|(n, b)| (n, PyBytes::new(py, &b)))
        .collect())
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
    m.add_class::<Lines>()?;
    m.add_function(wrap_pyfunction!(parquet_tables, m)?)?;
    m.add_function(wrap_pyfunction!(write_dataset, m)?)?;
    m.add_function(wrap_pyfunction!(prepare_dataset, m)?)?;
    m.add_function(wrap_pyfunction!(encode, m)?)?;
    m.add("AptscopeError", m.py().get_type::<AptscopeError>())?;
    m.add("EncodeError", m.py().get_type::<EncodeError>())?;
    Ok(())
}
