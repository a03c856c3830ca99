//! Typed Parquet datasets from decoded records.
//!
//! A [`CaptureWriter`] takes the [`Record`]s one [`record::Decoder`] yields for one capture and
//! writes them as rows: every record into the `records` table (common columns), and each
//! decoded message also into its kind's table (`MOT_GET_DCSTATUSUPDATE`, `ELL_POSITION` …),
//! whose columns are the message's fields typed from the message tables ([`schema`]).
//!
//! Memory is bounded: each table buffers at most [`Options::rows_per_group`] rows, at most
//! [`Options::max_open_kinds`] kind tables buffer at once (the least recently used is flushed
//! when another opens; the default is more than there are kinds), and all kind buffers
//! together hold at most one row group's worth (the biggest is written when they reach it).
//! A [`DirSink`] writes every flushed buffer as one Parquet file of one row group
//! (`TABLE/part-FFFFF-SSSSS.parquet`, F the capture's index in the run, S a sequence number),
//! first under a `.partial` name then renamed: a killed run leaves every complete row group
//! readable and no torn file under a `.parquet` name. A [`MemSink`] keeps one in-memory Parquet
//! file per table instead (the Python package's `to_arrow`).
//!
//! [`record::Decoder`]: aptscope_dissector::record::Decoder

#![forbid(unsafe_code)]
#![warn(missing_docs)]

mod buf;
mod file;
pub mod schema;

pub use buf::V;
pub use file::{decode_file, not_a_capture, not_a_capture_error, DecodeOpts};

use aptscope_dissector::apt::phys_or_scaled;
use aptscope_dissector::diag::{Diag, DiagKind};
use aptscope_dissector::ell::table::{status_name, Kind as EllKind};
use aptscope_dissector::ell::EllValue;
use aptscope_dissector::hash::NumMap;
use aptscope_dissector::json;
use aptscope_dissector::record::{AptRec, EllRec, Record};
use aptscope_dissector::table::Dir;
use arrow_array::RecordBatch;
use arrow_schema::{DataType, Schema};
use buf::TableBuf;
use parquet::arrow::ArrowWriter;
use parquet::basic::Compression;
use parquet::file::properties::{EnabledStatistics, WriterProperties};
use parquet::schema::types::ColumnPath;
use schema::{Fill, KindSchema, Kinds, RECORDS};
use std::borrow::Cow;
use std::collections::{BTreeMap, HashMap};
use std::io;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// How tables are cut into row groups.
#[derive(Debug, Clone, Copy)]
pub struct Options {
    /// Rows per row group (and per part file of a [`DirSink`]).
    pub rows_per_group: usize,
    /// Kind tables buffering rows at once.
    pub max_open_kinds: usize,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            rows_per_group: 65_536,
            // More than there are kinds (544): a kind's rows are written when it has a row
            // group's worth or is the biggest when all together reach the budget, not when
            // another opens (which wrote a part file of a few rows each time a stream of many
            // kinds brought a new one).
            max_open_kinds: 1024,
        }
    }
}

/// How a table of `schema` is written. Snappy: fast, and read everywhere (see
/// docs/parquet.md for why not zstd). Dictionary encoding only for
/// the text columns (names, labels, units: few distinct values); numbers, times and raw bytes
/// are mostly distinct, and hashing each value for a dictionary that overflows was a sixth of
/// the writer's time.
fn props(rows: usize, schema: &Schema) -> WriterProperties {
    let mut b = WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .set_max_row_group_row_count(Some(rows.max(1)))
        .set_dictionary_enabled(false);
    for f in schema.fields() {
        let col = || ColumnPath::from(f.name().as_str());
        match f.data_type() {
            DataType::Utf8 => b = b.set_column_dictionary_enabled(col(), true),
            // Raw frames: a minimum and maximum of random bytes prune nothing, and comparing
            // every value for them cost a twentieth of the run.
            DataType::Binary => b = b.set_column_statistics_enabled(col(), EnabledStatistics::None),
            _ => {}
        }
    }
    b.build()
}

fn perr(e: impl std::fmt::Display) -> io::Error {
    io::Error::other(format!("parquet: {e}"))
}

/// Where flushed row groups go.
pub trait Sink {
    /// Write one row group of `table`; `part` counts the table's row groups of this capture.
    fn write(&mut self, table: &str, part: u32, batch: &RecordBatch) -> io::Result<()>;
}

/// Writes each row group as its own file in a dataset directory.
pub struct DirSink {
    root: PathBuf,
    index: usize,
    rows: usize,
    /// Writer properties of each table written (a table's directory exists once it is here).
    props: HashMap<String, WriterProperties>,
}

impl DirSink {
    /// A sink into dataset `root` (see [`prepare_dir`]) for the capture numbered `index` in the
    /// run (it names the part files: the same inputs in the same order give the same files).
    pub fn new(root: &Path, index: usize, opts: Options) -> Self {
        DirSink {
            root: root.to_path_buf(),
            index,
            rows: opts.rows_per_group,
            props: HashMap::new(),
        }
    }
}

impl Sink for DirSink {
    fn write(&mut self, table: &str, part: u32, batch: &RecordBatch) -> io::Result<()> {
        let dir = self.root.join(table);
        if !self.props.contains_key(table) {
            std::fs::create_dir_all(&dir)
                .map_err(|e| io::Error::new(e.kind(), format!("{}: {e}", dir.display())))?;
            let p = props(self.rows, &batch.schema());
            self.props.insert(table.to_string(), p);
        }
        let props = self.props.get(table).cloned();
        let name = format!("part-{:05}-{part:05}.parquet", self.index);
        let done = dir.join(&name);
        let tmp = dir.join(format!("{name}.partial"));
        let f = std::fs::File::create(&tmp)
            .map_err(|e| io::Error::new(e.kind(), format!("{}: {e}", tmp.display())))?;
        let mut w = ArrowWriter::try_new(f, batch.schema(), props).map_err(perr)?;
        w.write(batch).map_err(perr)?;
        // Renamed once complete: a killed run leaves no torn `.parquet`. (No fsync: a killed
        // process loses nothing the kernel has; a power cut may, and costs a sync per part.)
        w.close().map_err(perr)?;
        std::fs::rename(&tmp, &done)
    }
}

/// Keeps one in-memory Parquet file per table.
pub struct MemSink {
    rows: usize,
    tables: BTreeMap<String, ArrowWriter<Vec<u8>>>,
}

impl MemSink {
    /// An empty sink.
    pub fn new(opts: Options) -> Self {
        MemSink {
            rows: opts.rows_per_group,
            tables: BTreeMap::new(),
        }
    }

    /// The Parquet bytes of every table that got rows, by table name.
    pub fn finish(self) -> io::Result<Vec<(String, Vec<u8>)>> {
        self.tables
            .into_iter()
            .map(|(k, w)| Ok((k, w.into_inner().map_err(perr)?)))
            .collect()
    }
}

impl Sink for MemSink {
    fn write(&mut self, table: &str, _part: u32, batch: &RecordBatch) -> io::Result<()> {
        if !self.tables.contains_key(table) {
            let p = props(self.rows, &batch.schema());
            let w = ArrowWriter::try_new(Vec::new(), batch.schema(), Some(p)).map_err(perr)?;
            self.tables.insert(table.to_string(), w);
        }
        let w = self
            .tables
            .get_mut(table)
            .ok_or_else(|| io::Error::other("table vanished"))?;
        w.write(batch).map_err(perr)?;
        w.flush().map_err(perr)
    }
}

/// Make `out` ready for a dataset: create it, or with `force` replace an earlier dataset.
/// Refuses to remove a directory that is not one (no `records/` in it and not empty).
pub fn prepare_dir(out: &Path, force: bool) -> io::Result<()> {
    if out.exists() {
        if !force {
            return Err(io::Error::new(
                io::ErrorKind::AlreadyExists,
                format!("{} exists: --force to replace it", out.display()),
            ));
        }
        let is_dataset = out.join(RECORDS).is_dir();
        let empty = out.is_dir() && std::fs::read_dir(out)?.next().is_none();
        if out.is_dir() && !is_dataset && !empty {
            return Err(io::Error::new(
                io::ErrorKind::AlreadyExists,
                format!(
                    "{} exists and is not an aptscope dataset (no records/): not removing it",
                    out.display()
                ),
            ));
        }
        if out.is_dir() {
            std::fs::remove_dir_all(out)?;
        } else {
            std::fs::remove_file(out)?;
        }
    }
    std::fs::create_dir_all(out)
        .map_err(|e| io::Error::new(e.kind(), format!("{}: {e}", out.display())))
}

/// What a capture gave.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Summary {
    /// Rows of the records table.
    pub records: u64,
    /// Frames decoded.
    pub frames: u64,
    /// Diagnostics.
    pub diagnostics: u64,
    /// Row groups written.
    pub row_groups: u64,
}

/// A message's kind table: its name, and its schema when it has one.
type KindOf = (Arc<str>, Option<Arc<KindSchema>>);

struct Open {
    buf: TableBuf,
    part: u32,
    used: u64,
}

/// Writes one capture's records as rows (see the crate documentation).
pub struct CaptureWriter<S: Sink> {
    sink: S,
    file: Arc<str>,
    opts: Options,
    records: Open,
    kinds: NumMap<String, Open>,
    /// Part numbers of kind tables flushed and closed, to continue from when they reopen.
    parts: HashMap<String, u32>,
    clock: u64,
    summary: Summary,
    /// Kind table names and schemas by message (the address of its table entry, and of its
    /// sub-message's).
    kind_names: NumMap<(usize, usize), KindOf>,
    layouts: Layouts,
    /// Rows the kind tables buffer, together.
    kind_rows: usize,
}

fn diag_v(d: &Diag) -> (Cow<'static, str>, u64, String) {
    (Cow::Borrowed(d.kind.name()), d.offset, d.kind.to_string())
}

fn dir_v(d: Option<Dir>) -> V<'static> {
    match d {
        Some(Dir::Both) | None => V::Null,
        Some(d) => V::S(Cow::Borrowed(d.as_str())),
    }
}

fn opt_u(x: Option<u64>) -> V<'static> {
    x.map_or(V::Null, V::U)
}

fn s(x: &str) -> V<'_> {
    V::S(Cow::Borrowed(x))
}

impl<S: Sink> CaptureWriter<S> {
    /// A writer of the records of capture `file` (its name in the `file` column) into `sink`.
    pub fn new(sink: S, file: &str, opts: Options) -> Self {
        CaptureWriter {
            sink,
            file: Arc::from(file),
            opts,
            records: Open {
                buf: TableBuf::new(schema::records_schema()),
                part: 0,
                used: 0,
            },
            kinds: NumMap::default(),
            parts: HashMap::new(),
            clock: 0,
            summary: Summary::default(),
            kind_names: NumMap::default(),
            layouts: Layouts::default(),
            kind_rows: 0,
        }
    }

    /// Add one record.
    pub fn record(&mut self, rec: &Record<'_>) -> io::Result<()> {
        let (kname, kind) = self.kind_of(rec);
        // Columns of `records`, in schema order.
        let file = self.file.clone();
        let mut row: [V<'_>; 25] = Default::default();
        row[0] = s(&file);
        const STREAM: usize = 1;
        const N: usize = 2;
        const TS: usize = 3;
        const TIME: usize = 4;
        const REL: usize = 5;
        const DIR: usize = 6;
        const PROTO: usize = 7;
        const TYPE: usize = 8;
        const OFFSET: usize = 9;
        const MSGID: usize = 10;
        const NAME: usize = 11;
        const SUB: usize = 12;
        const CODE: usize = 13;
        const KIND: usize = 14;
        const SRC: usize = 15;
        const DST: usize = 16;
        const CHANNEL: usize = 17;
        const LEN: usize = 18;
        const RAW: usize = 19;
        const DIAGS: usize = 20;
        const PAIR: usize = 21;
        const LATENCY: usize = 22;
        const REF: usize = 23;
        const DETAIL: usize = 24;
        row[DIAGS] = V::Diags(vec![]);
        if let Some(m) = rec.meta() {
            row[STREAM] = V::U(m.stream as u64);
            row[N] = V::U(m.n);
            row[TS] = opt_u(m.ts_ns);
            row[TIME] = opt_u(m.ts_ns);
            row[REL] = m.rel_s.map_or(V::Null, V::F);
        }
        let mut diags: Vec<(Cow<'_, str>, u64, String)> = vec![];
        match rec {
            Record::Detect {
                proto, detection, ..
            } => {
                row[TYPE] = s("detect");
                row[PROTO] = s(proto.code());
                row[DETAIL] = V::S(Cow::Owned(format!(
                    "{} apt={:.3} ell={:.3}",
                    if detection.proto.is_some() {
                        "certain"
                    } else {
                        "best guess"
                    },
                    detection.apt,
                    detection.elliptec
                )));
            }
            Record::Stream { id, name, settings } => {
                row[TYPE] = s("stream");
                row[STREAM] = V::U(*id as u64);
                row[DETAIL] = V::S(match settings {
                    Some(x) => Cow::Owned(format!("{name} ({x})")),
                    None => Cow::Borrowed(name),
                });
            }
            Record::Input(d) => {
                row[TYPE] = s("input");
                row[OFFSET] = V::U(d.offset);
                diags.push(diag_v(d));
            }
            Record::FileDiag { offset, kind, msg } => {
                row[TYPE] = s("input");
                row[OFFSET] = V::U(*offset);
                diags.push((Cow::Borrowed(kind), *offset, msg.to_string()));
            }
            Record::Units(nt) => {
                row[TYPE] = s("units");
                row[PROTO] = s("apt");
                row[STREAM] = V::U(nt.stream as u64);
                let mut d = String::new();
                json::units_notice(&mut d, nt);
                row[DETAIL] = V::S(Cow::Owned(d));
            }
            Record::Apt(a) => {
                let f = a.frame;
                let h = f.header();
                row[TYPE] = s("frame");
                row[PROTO] = s("apt");
                row[DIR] = dir_v(a.dir());
                row[OFFSET] = V::U(f.offset);
                row[MSGID] = V::U(h.msg_id() as u64);
                if let Some(m) = f.msg {
                    row[NAME] = s(m.name);
                    row[KIND] = kname.as_deref().map_or(V::Null, s);
                }
                if let Some(x) = f.sub {
                    row[SUB] = s(x.name);
                }
                row[SRC] = V::U(h.src().byte() as u64);
                row[DST] = V::U(h.dst().byte() as u64);
                row[CHANNEL] = f.channel().map_or(V::Null, V::I);
                row[LEN] = V::U(f.bytes.len() as u64);
                row[RAW] = V::B(f.bytes);
                diags.extend(f.diags().chain(a.pair.diags(f.offset)).map(|d| diag_v(&d)));
                row[PAIR] = opt_u(a.pair.pair);
                row[LATENCY] = a.pair.latency_ns.map_or(V::Null, |l| V::F(l as f64 / 1e6));
                self.summary.frames += 1;
            }
            Record::Ell(e) => {
                let f = e.frame;
                row[TYPE] = s("frame");
                row[PROTO] = s("ell");
                let d = f.dir();
                row[DIR] = dir_v(Some(d));
                row[OFFSET] = V::U(f.offset);
                row[CODE] = s(f.code_str());
                if let Some(c) = f.cmd {
                    row[NAME] = s(c.name);
                    row[KIND] = kname.as_deref().map_or(V::Null, s);
                }
                // The module's address is the destination of a command, the source of a reply.
                let at = if d == Dir::HostToDevice { DST } else { SRC };
                row[at] = V::U(f.addr as u64);
                row[LEN] = V::U(f.bytes.len() as u64);
                row[RAW] = V::B(f.bytes);
                diags.extend(f.diags().iter().copied().map(|d| diag_v(&d)));
                row[PAIR] = opt_u(e.obs.pair);
                row[LATENCY] = e.obs.latency_ns.map_or(V::Null, |l| V::F(l as f64 / 1e6));
                self.summary.frames += 1;
            }
            Record::Garbage(g) => {
                row[TYPE] = s("garbage");
                row[PROTO] = s(g.proto.code());
                row[DIR] = dir_v(g.meta.cap_dir);
                row[OFFSET] = V::U(g.offset);
                row[LEN] = V::U(g.bytes.len() as u64);
                row[RAW] = V::B(g.bytes);
                let d = match g.kind {
                    Some(k) => json::garbage_diag(g.offset, g.bytes.len(), k),
                    None => Diag {
                        offset: g.offset,
                        kind: DiagKind::Garbage {
                            len: g.bytes.len() as u32,
                        },
                    },
                };
                diags.push(diag_v(&d));
            }
            Record::NoReply(e) => {
                row[TYPE] = s("no_reply");
                row[PROTO] = s(e.proto.code());
                row[STREAM] = V::U(e.stream as u64);
                row[OFFSET] = V::U(e.offset);
                row[if e.proto == aptscope_dissector::detect::Proto::Apt {
                    NAME
                } else {
                    CODE
                }] = s(e.name);
                row[REF] = V::U(e.n);
                diags.push(diag_v(&e.diag()));
            }
        }
        self.summary.diagnostics += diags.len() as u64;
        row[DIAGS] = V::Diags(diags);
        self.summary.records += 1;
        self.records.buf.push(&row);
        if self.records.buf.rows() >= self.opts.rows_per_group {
            self.flush_records()?;
        }
        if let (Some(k), Some(m)) = (kind, rec.meta()) {
            let mut row = Vec::with_capacity(4 + k.cols.len());
            row.extend([s(&file), V::U(m.n), V::U(m.stream as u64), opt_u(m.ts_ns)]);
            match rec {
                Record::Apt(a) => apt_values(&mut self.layouts, &k, a, &mut row),
                Record::Ell(e) => ell_values(&mut self.layouts, &k, e, &mut row),
                _ => {}
            }
            self.kind_row(&k, &row)?;
        }
        Ok(())
    }

    /// The kind table of a frame's message (its name, and its schema when it has one), looked
    /// up once per message rather than by a name made for every frame.
    fn kind_of(&mut self, rec: &Record<'_>) -> (Option<Arc<str>>, Option<Arc<KindSchema>>) {
        let (key, name): ((usize, usize), &dyn Fn() -> String) = match rec {
            Record::Apt(a) => match a.frame.msg {
                Some(m) => {
                    let sub = a.frame.sub;
                    let key = (
                        m as *const _ as usize,
                        sub.map_or(0, |x| x as *const _ as usize),
                    );
                    (key, &move || schema::apt_kind_name(m, sub))
                }
                None => return (None, None),
            },
            Record::Ell(e) => match e.frame.cmd {
                Some(c) => ((c as *const _ as usize, 1), &move || {
                    schema::ell_kind_name(c)
                }),
                None => return (None, None),
            },
            _ => return (None, None),
        };
        let (n, k) = self.kind_names.entry(key).or_insert_with(|| {
            let n = name();
            let k = Kinds::global().get(&n).cloned();
            (Arc::from(n), k)
        });
        (Some(n.clone()), k.clone())
    }

    fn kind_row(&mut self, k: &Arc<KindSchema>, row: &[V<'_>]) -> io::Result<()> {
        self.clock += 1;
        if !self.kinds.contains_key(&k.name) {
            if self.kinds.len() >= self.opts.max_open_kinds {
                // Too many open: the least recently used gives its rows up first.
                let lru = self
                    .kinds
                    .iter()
                    .min_by_key(|(_, o)| o.used)
                    .map(|(n, _)| n.clone());
                if let Some(n) = lru {
                    self.close_kind(&n)?;
                }
            }
            let part = self.parts.get(&k.name).copied().unwrap_or(0);
            self.kinds.insert(
                k.name.clone(),
                Open {
                    buf: TableBuf::new(k.schema.clone()),
                    part,
                    used: 0,
                },
            );
        }
        // One row group's worth across kinds (with the records table's own, the writer stays
        // under 64 MiB; four row groups' worth peaked at 100 MiB).
        let budget = self.opts.rows_per_group;
        let Some(o) = self.kinds.get_mut(&k.name) else {
            return Ok(());
        };
        o.used = self.clock;
        o.buf.push(row);
        self.kind_rows += 1;
        if o.buf.rows() >= self.opts.rows_per_group {
            self.kind_rows -= o.buf.rows();
            Self::flush(&mut self.sink, &k.name, o, &mut self.summary)?;
        }
        if self.kind_rows > budget {
            // Many kinds each short of a row group: the biggest is written early.
            let big = self
                .kinds
                .iter()
                .max_by_key(|(_, o)| o.buf.rows())
                .map(|(n, _)| n.clone());
            if let Some(n) = big {
                self.close_kind(&n)?;
            }
        }
        Ok(())
    }

    fn close_kind(&mut self, name: &str) -> io::Result<()> {
        if let Some(mut o) = self.kinds.remove(name) {
            self.kind_rows -= o.buf.rows();
            Self::flush(&mut self.sink, name, &mut o, &mut self.summary)?;
            self.parts.insert(name.to_string(), o.part);
        }
        Ok(())
    }

    fn flush_records(&mut self) -> io::Result<()> {
        Self::flush(
            &mut self.sink,
            RECORDS,
            &mut self.records,
            &mut self.summary,
        )
    }

    fn flush(sink: &mut S, table: &str, o: &mut Open, summary: &mut Summary) -> io::Result<()> {
        if o.buf.rows() == 0 {
            return Ok(());
        }
        let batch = o.buf.take().map_err(perr)?;
        sink.write(table, o.part, &batch)?;
        o.part += 1;
        summary.row_groups += 1;
        Ok(())
    }

    /// Write what is buffered; returns the sink and what was written.
    pub fn finish(mut self) -> io::Result<(S, Summary)> {
        self.flush_records()?;
        let mut names: Vec<String> = self.kinds.keys().cloned().collect();
        names.sort();
        for n in names {
            self.close_kind(&n)?;
        }
        Ok((self.sink, self.summary))
    }
}

/// Which of a frame's fields fills each column of its kind table, by layout of fields: the
/// kind, the first and last field's table entries and their count identify the form (and
/// sub-message form), so each is worked out once (by name, the first field of that name)
/// rather than searched for in every frame.
#[derive(Default)]
struct Layouts(NumMap<(usize, usize, usize, usize), Vec<Option<usize>>>);

impl Layouts {
    fn get<T, F: 'static>(
        &mut self,
        k: &KindSchema,
        fields: &[(&'static F, T)],
        name: impl Fn(&F) -> &'static str,
    ) -> &[Option<usize>] {
        let addr = |f: Option<&(&'static F, T)>| f.map_or(0, |(fd, _)| *fd as *const F as usize);
        let key = (
            k as *const KindSchema as usize,
            addr(fields.first()),
            addr(fields.last()),
            fields.len(),
        );
        self.0.entry(key).or_insert_with(|| {
            k.cols
                .iter()
                .map(|c| fields.iter().position(|(fd, _)| name(fd) == c.field))
                .collect()
        })
    }
}

/// The field columns of an APT frame's kind row.
fn apt_values<'a>(lay: &mut Layouts, k: &KindSchema, a: &'a AptRec<'a>, out: &mut Vec<V<'a>>) {
    let f = a.frame;
    let t = f.table();
    // Sized once: the iterator does not know its length, and growing by doubling was a
    // reallocation or two per frame.
    let mut fields = Vec::with_capacity(32);
    fields.extend(f.fields());
    let idx = lay.get(k, &fields, |fd| fd.name);
    let vals = k.cols.iter().zip(idx).map(|(c, i)| {
        let Some((fd, v)) = i.map(|i| &fields[i]) else {
            return V::Null;
        };
        use aptscope_dissector::apt::Value;
        match c.fill {
            Fill::Int => match *v {
                Value::U(x) => V::U(x),
                Value::I(x) => V::I(x),
                _ => V::Null,
            },
            Fill::Float => v.as_f64().map_or(V::Null, V::F),
            Fill::EnumLabel => {
                let label = fd
                    .enumeration
                    .zip(v.as_i64())
                    .and_then(|(e, x)| t.enum_def(e).label(x));
                label.map_or(V::Null, s)
            }
            Fill::FlagNames => match (fd.flags, *v) {
                (Some(fl), Value::U(x)) => V::ListS(
                    t.flags_def(fl)
                        .items
                        .iter()
                        .filter(|(m, _)| x & m == *m)
                        .map(|(_, l)| *l)
                        .collect(),
                ),
                _ => V::Null,
            },
            Fill::Text => match *v {
                Value::Str(b) => V::S(Cow::Owned(aptscope_dissector::apt::text_of(b).into_owned())),
                _ => V::Null,
            },
            Fill::Bytes => match *v {
                Value::Bytes(b) => V::B(b),
                _ => V::Null,
            },
            Fill::List => {
                let els = v.elements();
                if matches!(v, Value::Array(aptscope_dissector::table::Prim::F32, _)) {
                    V::ListF(els.filter_map(|e| e.as_f64()).collect())
                } else {
                    V::ListI(els.filter_map(|e| e.as_i64()).collect())
                }
            }
            Fill::Phys => phys_or_scaled(fd, v, a.scale).map_or(V::Null, |(x, _)| V::F(x)),
            Fill::PhysUnit => phys_or_scaled(fd, v, a.scale).map_or(V::Null, |(_, u)| s(u)),
            Fill::StatusName => V::Null,
        }
    });
    out.extend(vals);
}

/// The field columns of an Elliptec frame's kind row.
fn ell_values<'a>(lay: &mut Layouts, k: &KindSchema, e: &'a EllRec<'a>, out: &mut Vec<V<'a>>) {
    let f = e.frame;
    let mut fields = Vec::with_capacity(16);
    fields.extend(f.fields());
    let scale = e.obs.module.as_ref().and_then(|m| m.scale());
    let idx = lay.get(k, &fields, |fd| fd.name);
    let vals = k.cols.iter().zip(idx).map(|(c, i)| {
        let Some((fd, v)) = i.map(|i| &fields[i]) else {
            return V::Null;
        };
        match (c.fill, *v) {
            (Fill::StatusName, EllValue::U(x)) => s(status_name(x as u32)),
            (Fill::Int, EllValue::U(x)) => V::U(x),
            (Fill::Int, EllValue::I(x)) => V::I(x),
            (Fill::Text, EllValue::Char(ch)) => V::S(Cow::Owned(ch.to_string())),
            (Fill::Text, EllValue::Digits(d)) => V::S(Cow::Owned(d.to_string())),
            (Fill::Bytes, EllValue::Raw(b)) => V::B(b),
            (Fill::Phys | Fill::PhysUnit, EllValue::I(p)) if fd.kind == EllKind::Position => {
                match scale.filter(|(ppu, _)| *ppu > 0.0) {
                    Some((ppu, _)) if c.fill == Fill::Phys => {
                        V::F(aptscope_dissector::apt::round_sig(p as f64 / ppu))
                    }
                    Some((_, unit)) => s(unit),
                    None => V::Null,
                }
            }
            _ => V::Null,
        }
    });
    out.extend(vals);
}
