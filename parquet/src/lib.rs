//! Typed Parquet datasets from decoded records.
//!
//! A [`CaptureWriter`] takes the [`Record`]s one [`record::Decoder`] yields for one capture and
//! writes them as rows: every record into the `records` table (common columns), and each
//! decoded message also into its kind's table (`MOT_GET_DCSTATUSUPDATE`, `ELL_POSITION` …),
//! whose columns are the message's fields typed from the message tables ([`schema`]).
//!
//! Memory is bounded: each table buffers at most [`Options::rows_per_group`] rows and
//! [`Options::bytes_per_group`] bytes of frames and text, at most
//! [`Options::max_open_kinds`] kind tables buffer at once (the least recently used is flushed
//! when another opens; the default is more than there are kinds), and all kind buffers
//! together hold at most [`Options::kind_rows`] rows and `bytes_per_group` bytes (the biggest
//! is written when they reach either).
//! A [`DirSink`] writes each flushed buffer as a row group of its table's current part file
//! (`TABLE/part-FFFFF-SSSSS.parquet`, F the capture's index in the run, S the table's part
//! number), first under a `.partial` name then renamed once its footer is written: a file is
//! complete after [`Options::groups_per_file`] row groups, when the open files' metadata reaches
//! [`Options::open_chunks`] column chunks (the one holding most), or at the end. A killed run
//! leaves the files it completed readable and no torn file under a `.parquet` name. A
//! [`MemSink`] keeps one in-memory Parquet file per table instead.
//!
//! [`record::Decoder`]: aptscope_dissector::record::Decoder

#![forbid(unsafe_code)]
#![warn(missing_docs)]

mod buf;
mod file;
pub mod pages;
pub mod pool;
mod records;
pub mod schema;
mod threaded;
pub mod words;

pub use file::{decode_file, not_a_capture, not_a_capture_error, DecodeOpts};
pub use threaded::Threaded;

use aptscope_dissector::apt::{phys_or_scaled, Value as AptValue};
use aptscope_dissector::diag::{Diag, DiagKind};
use aptscope_dissector::ell::table::{status_name, Kind as EllKind};
use aptscope_dissector::ell::EllValue;
use aptscope_dissector::hash::NumMap;
use aptscope_dissector::json;
use aptscope_dissector::record::{AptRec, EllRec, Record};
use aptscope_dissector::table::{Dir, Field as AptField};
use aptscope_dissector::Table;
use arrow_array::RecordBatch;
use arrow_schema::{DataType, Schema, SchemaRef};
use buf::TableBuf;
use parquet::arrow::ArrowWriter;
use parquet::basic::Compression;
use parquet::file::properties::{EnabledStatistics, WriterProperties};
use parquet::schema::types::ColumnPath;
use records::{RecordsBuf, Row};
use schema::{Fill, KindSchema, Kinds, RECORDS};
use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::io;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// How tables are cut into row groups.
#[derive(Debug, Clone, Copy)]
pub struct Options {
    /// Rows per row group.
    pub rows_per_group: usize,
    /// Bytes of frames, garbage and text per row group at most (a table is written when its
    /// buffer reaches this, whatever its rows; the kind tables' buffers together hold at most
    /// this much too): rows of garbage runs are up to 4 KiB each, rows of status flags a list
    /// of up to 32 names.
    pub bytes_per_group: usize,
    /// Kind tables buffering rows at once.
    pub max_open_kinds: usize,
    /// Rows the kind tables buffer together at most (the biggest is written when they reach
    /// it).
    pub kind_rows: usize,
    /// Row groups per part file at most (the next start another file).
    pub groups_per_file: usize,
    /// Column chunks of the part files being written, together, at most: each chunk's
    /// metadata stays in memory until its file's footer is written, so a capture of hundreds
    /// of kinds closes the file of most chunks when they reach this.
    pub open_chunks: usize,
    /// Columns of words (names, labels, units…) as text, the tables' declared types, rather
    /// than as dictionaries of words: for a [`Sink`] that hands batches to readers (Python)
    /// instead of writing Parquet, whose page writer takes the dictionaries as they are.
    pub words_as_text: bool,
    /// Whether the row groups' batches are kept by the [`Sink`] (Python's tables) rather than
    /// written and dropped. A table that filled a row group will likely fill the next, and a
    /// taken buffer starts empty: when kept, it makes room for as many rows again at once,
    /// since growing a column by doubling copies it at each step into fresh pages (memory the
    /// batches hold never comes back to be reused): that was a tenth of building the rows
    /// Python gets. When dropped, room for 8,192 rows, grown from there: a row group's room
    /// at once sits in memory the last row group freed (peak 59 → 71 MiB for 100 MB of every
    /// form; 56 → 66 MiB when the kind tables did).
    pub batches_kept: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            rows_per_group: 65_536,
            // A status log's 65,536 rows hold about 3 MiB of frames and messages, and its
            // arrays 19 MiB: such logs are cut by rows. 300 MB of 0xFF bytes (a line held
            // high: 4 KiB garbage runs) held 65,536 rows, 268 MiB, in one row group.
            bytes_per_group: 8 << 20,
            // More than there are kinds (544): a kind's rows are written when it has a row
            // group's worth or is the biggest when all together reach the budget, not when
            // another opens (which wrote a part file of a few rows each time a stream of many
            // kinds brought a new one).
            max_open_kinds: 1024,
            // Two row groups' worth: a capture of hundreds of kinds (random frames of every
            // form) writes a row group whenever the kinds together reach this, each of about
            // twice this over the kinds' count rows. 10 MB of such frames (when each row group
            // was a part file): 2792 row groups and 1.75 s at one row group's worth, 1556 and
            // 1.54 s at two (peak 54 → 59 MiB), 960 and 1.37 s at four but 67 MiB, over the
            // 64 MiB a worker may use; a capture of a few kinds (status logs) cuts at
            // `rows_per_group` either way.
            kind_rows: 2 * 65_536,
            // 4 M rows of a status log's `records` (about 140 MB of Parquet) a file at most.
            groups_per_file: 64,
            // A chunk's metadata is about 1.3 KiB: 2.6 MiB. 100 MB of every form (526 tables)
            // then writes 7,580 part files (13,304 when each row group was one), peak
            // 64.5 MiB (60.1 before); at 1,024 chunks 9,649 files and 63.7 MiB, at 4,096
            // 5,244 files but 67.7 MiB, over the 64 MiB a worker may use. (Since a column's
            // buffer is 104 bytes, not 1,768: 58.3 MiB at 2,048.)
            open_chunks: 2048,
            words_as_text: false,
            batches_kept: false,
        }
    }
}

impl Options {
    /// Rows of room a buffer taken with `rows` rows makes again ([`Options::batches_kept`]).
    fn room(&self, rows: usize) -> usize {
        if self.batches_kept {
            rows
        } else {
            rows.min(8192)
        }
    }
}

/// How a table of `schema` is written. Snappy: fast, and read everywhere (see
/// docs/parquet.md for why not zstd). Dictionary encoding only for the text columns, also those
/// inside lists (names, labels, units, flag names, diagnostics: few distinct values, so the
/// pages Snappy compresses are indices, not the same words again); numbers, times and raw
/// bytes are mostly distinct, and hashing each value for a dictionary that overflows was a
/// sixth of parquet-rs's writer's time. (The page writer, [`pages`], which writes the tables
/// it takes, also gives integer chunks of few distinct values a dictionary of its own.)
pub fn writer_properties(rows: usize, schema: &Schema) -> WriterProperties {
    let mut b = WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .set_max_row_group_row_count(Some(rows.max(1)))
        .set_dictionary_enabled(false);
    let mut leaves = Vec::new();
    for f in schema.fields() {
        leaf_columns(vec![f.name().clone()], f.data_type(), &mut leaves);
    }
    for (path, dt) in leaves {
        let col = || ColumnPath::new(path.clone());
        match dt {
            // The key `file`: a part file holds one capture, so its minimum and maximum
            // prune every other capture's row groups.
            DataType::Utf8 if path.len() == 1 && path[0] == "file" => {
                b = b.set_column_dictionary_enabled(col(), true)
            }
            // Other text (names, directions, labels, units, flag names, diagnostics): a row
            // group mixes many values, so its minimum and maximum prune almost nothing (a
            // status log's span `HW_…`–`MOT_…`), and comparing every value for them was a
            // twelfth of the writer's instructions (docs/performance.md, fifth pass).
            DataType::Utf8 => {
                b = b
                    .set_column_dictionary_enabled(col(), true)
                    .set_column_statistics_enabled(col(), EnabledStatistics::None)
            }
            // Raw frames: a minimum and maximum of random bytes prune nothing, and comparing
            // every value for them cost a twentieth of the run.
            DataType::Binary => b = b.set_column_statistics_enabled(col(), EnabledStatistics::None),
            _ => {}
        }
    }
    b.build()
}

/// The Parquet leaf columns under a column of type `dt` at `path`, with their Arrow types (a
/// list's elements are under `list.<field>`, as the Arrow writer names them).
fn leaf_columns(path: Vec<String>, dt: &DataType, out: &mut Vec<(Vec<String>, DataType)>) {
    match dt {
        DataType::List(f) => {
            let mut p = path;
            p.push("list".into());
            p.push(f.name().clone());
            leaf_columns(p, f.data_type(), out);
        }
        DataType::Struct(fs) => {
            for f in fs {
                let mut p = path.clone();
                p.push(f.name().clone());
                leaf_columns(p, f.data_type(), out);
            }
        }
        _ => out.push((path, dt.clone())),
    }
}

fn perr(e: impl std::fmt::Display) -> io::Error {
    io::Error::other(format!("parquet: {e}"))
}

/// Where flushed row groups go.
pub trait Sink {
    /// Write one row group of `table` into its part `part`: the row groups of one part are one
    /// file, in the order written ([`DirSink`]); parts are numbered from 0 in each table.
    fn write(&mut self, table: &str, part: u32, batch: &RecordBatch) -> io::Result<()>;

    /// No more row groups go into part `part` of `table` (`u32::MAX`: whichever is open).
    fn close(&mut self, _table: &str, _part: u32) -> io::Result<()> {
        Ok(())
    }

    /// Complete what was written, every part still open too (a sink that writes later,
    /// [`Threaded`], waits for it here and returns what failed).
    fn finish(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// Writes each table's row groups into part files of a dataset directory, a file for each
/// part number the writer gives, completed when it closes that part (or at the end).
pub struct DirSink {
    root: PathBuf,
    index: usize,
    rows: usize,
    /// How each table is written (a table's directory exists once it is here).
    writers: HashMap<String, TableWriter>,
    /// Part files being written, by table.
    files: BTreeMap<String, PartFile>,
    /// The page writer's buffers, lent to each file in turn.
    scratch: pages::Scratch,
}

/// How a table's part files are written: page by page from the arrays ([`pages`]) when its
/// schema allows, else by parquet-rs's Arrow writer.
#[derive(Clone)]
pub enum TableWriter {
    /// Page by page ([`pages::supports`] the schema).
    Pages(pages::TableProps),
    /// By the Arrow writer, with the table's schema.
    Arrow(Box<WriterProperties>, SchemaRef),
}

/// A table's Parquet file being written: row groups one by one, then the footer.
pub enum TableFile<W: io::Write + Send> {
    /// Page by page.
    Pages(Box<pages::PartWriter<W>>),
    /// By the Arrow writer.
    Arrow(Box<ArrowWriter<W>>),
}

impl TableWriter {
    /// The writer of a table of `schema` with row groups of at most `rows` rows.
    pub fn new(rows: usize, schema: &Schema) -> io::Result<Self> {
        let p = writer_properties(rows, schema);
        Ok(if pages::supports(schema) {
            TableWriter::Pages(pages::TableProps::new(schema, p).map_err(perr)?)
        } else {
            TableWriter::Arrow(Box::new(p), Arc::new(schema.clone()))
        })
    }

    /// A file of the table into `out`.
    pub fn open<W: io::Write + Send>(&self, out: W) -> io::Result<TableFile<W>> {
        Ok(match self {
            TableWriter::Pages(t) => {
                TableFile::Pages(Box::new(pages::PartWriter::new(out, t).map_err(perr)?))
            }
            TableWriter::Arrow(p, schema) => TableFile::Arrow(Box::new(
                ArrowWriter::try_new(out, schema.clone(), Some((**p).clone())).map_err(perr)?,
            )),
        })
    }

    /// `batch` as a Parquet file of one row group into `out`.
    pub fn write<W: io::Write + Send>(&self, out: W, batch: &RecordBatch) -> io::Result<W> {
        let mut f = self.open(out)?;
        f.write(batch)?;
        f.finish()
    }
}

impl<W: io::Write + Send> TableFile<W> {
    /// `batch` as one row group.
    pub fn write(&mut self, batch: &RecordBatch) -> io::Result<()> {
        match self {
            // The file's own buffers.
            TableFile::Pages(w) => w.write(batch).map_err(perr),
            TableFile::Arrow(_) => self.write_with(batch, &mut pages::Scratch::default()),
        }
    }

    /// `batch` as one row group, with the page writer's buffers lent by the caller
    /// ([`pages::PartWriter::write_with`]).
    pub fn write_with(
        &mut self,
        batch: &RecordBatch,
        scratch: &mut pages::Scratch,
    ) -> io::Result<()> {
        match self {
            TableFile::Pages(w) => w.write_with(batch, scratch).map_err(perr),
            TableFile::Arrow(w) => {
                // The Arrow writer takes the table's own types (text, not words).
                w.write(&words::declared(batch).map_err(perr)?)
                    .map_err(perr)?;
                w.flush().map_err(perr)
            }
        }
    }

    /// What was written so far handed to the output, and the output.
    fn flushed(&mut self) -> io::Result<&mut W> {
        Ok(match self {
            TableFile::Pages(w) => w.flushed().map_err(perr)?,
            TableFile::Arrow(w) => {
                w.sync()?;
                w.inner_mut()
            }
        })
    }

    /// Write the footer; the output back.
    pub fn finish(self) -> io::Result<W> {
        match self {
            TableFile::Pages(w) => w.finish().map_err(perr),
            TableFile::Arrow(w) => w.into_inner().map_err(perr),
        }
    }
}

/// A part file's output, open only while a row group is written to it: a capture of hundreds
/// of kinds writes hundreds of part files at once, more than a process may hold open (and
/// opening an existing file again costs microseconds, creating one about a millisecond).
struct Parked {
    path: PathBuf,
    file: Option<std::fs::File>,
}

impl io::Write for Parked {
    fn write(&mut self, b: &[u8]) -> io::Result<usize> {
        let f = match &mut self.file {
            Some(f) => f,
            None => self.file.insert(
                std::fs::OpenOptions::new()
                    .append(true)
                    .open(&self.path)
                    .map_err(|e| at_path(e, &self.path))?,
            ),
        };
        f.write(b).map_err(|e| at_path(e, &self.path))
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

fn at_path(e: io::Error, p: &Path) -> io::Error {
    io::Error::new(e.kind(), format!("{}: {e}", p.display()))
}

/// A part file being written: its number, the file, and its name until complete.
struct PartFile {
    part: u32,
    file: TableFile<Parked>,
}

impl PartFile {
    /// Footer written, renamed from `.partial` to `.parquet`. (No fsync: a killed process
    /// loses nothing the kernel has; a power cut may, and costs a sync per part.)
    fn complete(self) -> io::Result<()> {
        let tmp = self.file.finish()?.path;
        let done = tmp.with_extension("");
        std::fs::rename(&tmp, &done).map_err(|e| at_path(e, &done))
    }
}

impl DirSink {
    /// A sink into dataset `root` (see [`prepare_dir`]) for the capture numbered `index` in the
    /// run (it names the part files: the same inputs in the same order give the same files).
    pub fn new(root: &Path, index: usize, opts: Options) -> Self {
        DirSink {
            root: root.to_path_buf(),
            index,
            rows: opts.rows_per_group,
            writers: HashMap::new(),
            files: BTreeMap::new(),
            scratch: pages::Scratch::default(),
        }
    }

    /// Part `part` of `table`, created (and the table's directory) unless it is being written.
    fn part_file(
        &mut self,
        table: &str,
        part: u32,
        batch: &RecordBatch,
    ) -> io::Result<&mut PartFile> {
        if self.files.get(table).is_some_and(|f| f.part != part) {
            self.close(table, u32::MAX)?;
        }
        if !self.files.contains_key(table) {
            let dir = self.root.join(table);
            if !self.writers.contains_key(table) {
                std::fs::create_dir_all(&dir).map_err(|e| at_path(e, &dir))?;
                let schema = words::declared_schema(&batch.schema());
                let w = TableWriter::new(self.rows, &schema)?;
                self.writers.insert(table.to_string(), w);
            }
            let writer = self
                .writers
                .get(table)
                .ok_or_else(|| io::Error::other("table vanished"))?;
            let path = dir.join(format!("part-{:05}-{part:05}.parquet.partial", self.index));
            let f = std::fs::File::create(&path).map_err(|e| at_path(e, &path))?;
            let file = writer.open(Parked {
                path,
                file: Some(f),
            })?;
            self.files
                .insert(table.to_string(), PartFile { part, file });
        }
        self.files
            .get_mut(table)
            .ok_or_else(|| io::Error::other("part file vanished"))
    }
}

impl Sink for DirSink {
    fn write(&mut self, table: &str, part: u32, batch: &RecordBatch) -> io::Result<()> {
        let mut scratch = std::mem::take(&mut self.scratch);
        let r = self.part_file(table, part, batch).and_then(|f| {
            f.file.write_with(batch, &mut scratch)?;
            // The descriptor closed until the table's next row group.
            f.file.flushed()?.file = None;
            Ok(())
        });
        self.scratch = scratch;
        r
    }

    fn close(&mut self, table: &str, part: u32) -> io::Result<()> {
        match self.files.remove(table) {
            Some(f) if part == u32::MAX || f.part == part => f.complete(),
            Some(f) => {
                self.files.insert(table.to_string(), f);
                Ok(())
            }
            None => Ok(()),
        }
    }

    fn finish(&mut self) -> io::Result<()> {
        while let Some((_, f)) = self.files.pop_first() {
            f.complete()?;
        }
        Ok(())
    }
}

impl Drop for DirSink {
    /// Not finished (the capture failed part way): the part files are completed all the same,
    /// so that the rows written stay readable (errors here have nowhere to go).
    fn drop(&mut self) {
        while let Some((_, f)) = self.files.pop_first() {
            let _ = f.complete();
        }
    }
}

/// Keeps one in-memory Parquet file per table.
pub struct MemSink {
    rows: usize,
    tables: BTreeMap<String, TableFile<Vec<u8>>>,
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
            .map(|(k, f)| Ok((k, f.finish()?)))
            .collect()
    }
}

impl Sink for MemSink {
    fn write(&mut self, table: &str, _part: u32, batch: &RecordBatch) -> io::Result<()> {
        if !self.tables.contains_key(table) {
            let schema = words::declared_schema(&batch.schema());
            let f = TableWriter::new(self.rows, &schema)?.open(Vec::new())?;
            self.tables.insert(table.to_string(), f);
        }
        self.tables
            .get_mut(table)
            .ok_or_else(|| io::Error::other("table vanished"))?
            .write(batch)
    }
}

/// Ask the C allocator (glibc's) to keep the memory row groups give back, for a process that
/// writes datasets: it returns to the kernel what a row group's arrays free, so each row group
/// is built in fresh pages again (23,500 page faults and 0.2 system CPU-s for a 10 MB status
/// log, NDJSON's run 1,300 and 0.04). glibc raises its mmap threshold to the size of a
/// mapped block that is freed, and its trim threshold to twice that (mallopt(3), "dynamic
/// mmap threshold"): one block of 31 MiB taken and freed, never touched, sets both above a
/// row group's allocations, which then come from and stay in the heap (10,200 faults,
/// 0.93× the CPU, peak +2 MiB: docs/performance.md, "Parquet, sixth pass"). Other allocators
/// do nothing with it. Process-wide, so the binary calls it, not the library's writers.
pub fn settle_allocator() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| drop(std::hint::black_box(Vec::<u8>::with_capacity(31 << 20))));
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

/// A message's kind table: its name (the global schema's, `'static` for the `records` table's
/// column of words; every message and sub-message has one, [`Kinds`]), and its schema when
/// the table is kept.
type KindOf = (Option<&'static str>, Option<&'static KindSchema>);

struct Open {
    buf: TableBuf,
    used: u64,
    /// The kind table's name.
    name: &'static str,
}

/// A table's part file being written: its number, and the row groups and column chunks in it.
#[derive(Debug, Clone, Copy)]
struct PartState {
    name: &'static str,
    part: u32,
    groups: usize,
    chunks: usize,
}

impl Default for PartState {
    fn default() -> Self {
        PartState {
            name: RECORDS,
            part: 0,
            groups: 0,
            chunks: 0,
        }
    }
}

/// Leaf columns of `fields` (a list's items, a struct's fields): a row group's column chunks.
fn leaves(fields: &arrow_schema::Fields) -> usize {
    fn of(dt: &DataType) -> usize {
        match dt {
            DataType::Struct(f) => leaves(f),
            DataType::List(f) | DataType::LargeList(f) => of(f.data_type()),
            _ => 1,
        }
    }
    fields.iter().map(|f| of(f.data_type())).sum()
}

/// Which tables to write, by name ([`CaptureWriter::only_tables`]).
type Keep = Box<dyn Fn(&str) -> bool + Send>;

/// Writes one capture's records as rows (see the crate documentation).
pub struct CaptureWriter<S: Sink> {
    sink: S,
    file: Arc<str>,
    opts: Options,
    records: RecordsBuf,
    /// The `records` table's part file.
    records_file: PartState,
    /// Text formatted for a `records` row (kept for its allocation).
    text: String,
    /// Kind tables buffering rows, by [`KindSchema::index`] (a vector, not a map by name: three
    /// lookups by name a frame were a tenth of building its rows). Scanned in that order (by
    /// name) when the least used or the biggest is picked, so the part files are cut at the
    /// same rows in every run.
    kinds: Vec<Option<Open>>,
    /// Kind tables buffering rows now.
    open: usize,
    /// Buffers of kind tables closed by [`CaptureWriter::cut`] (or written early and closed,
    /// when [`Options::batches_kept`]), by index, emptied with their room: opened again, a
    /// table takes its own back rather than growing a new one.
    spare: Vec<Option<TableBuf>>,
    /// Each kind table's part file (by index).
    files: Vec<PartState>,
    /// Column chunks of the part files not closed, together: their metadata waits in memory
    /// for the files' footers ([`Options::open_chunks`]).
    open_chunks: usize,
    clock: u64,
    summary: Summary,
    /// The kind table of each message met (the address of its table entry, and of its
    /// sub-message's), as its place in `kind_list`.
    kind_names: NumMap<(usize, usize), usize>,
    kind_list: Vec<KindOf>,
    layouts: Layouts,
    /// Fields of the frame being written (kept for its allocation).
    scratch: Scratch,
    /// The kind rows of a stretch of a run, by table ([`CaptureWriter::run`]).
    order: ByKind,
    /// Rows the kind tables buffer, together.
    kind_rows: usize,
    /// Bytes of text and bytes the kind tables buffer, together.
    kind_bytes: usize,
    /// Whether the `records` table is written ([`CaptureWriter::only_tables`]).
    keep_records: bool,
    /// Which kind tables are written; `None`: all.
    keep_kinds: Option<Keep>,
}

/// The `dir` column: null for both directions or none.
fn dir_text(d: Option<Dir>) -> Option<&'static str> {
    match d {
        Some(Dir::Both) | None => None,
        Some(d) => Some(d.as_str()),
    }
}

fn put_opt_u(b: &mut TableBuf, i: usize, x: Option<u64>) {
    if let Some(x) = x {
        b.uint(i, x);
    }
}

impl<S: Sink> CaptureWriter<S> {
    /// A writer of the records of capture `file` (its name in the `file` column) into `sink`.
    pub fn new(sink: S, file: &str, mut opts: Options) -> Self {
        // A column's values are addressed by 32-bit offsets (under 2 GiB a row group): the
        // frames and text by the byte budget, the short names by the rows (4 M rows of names
        // of at most a few dozen bytes).
        opts.bytes_per_group = opts.bytes_per_group.min(1 << 30);
        opts.rows_per_group = opts.rows_per_group.min(1 << 22);
        let file: Arc<str> = Arc::from(file);
        let n = Kinds::global().len();
        CaptureWriter {
            sink,
            records: RecordsBuf::new(file.clone(), 64, opts.words_as_text),
            records_file: PartState::default(),
            text: String::new(),
            file,
            opts,
            kinds: (0..n).map(|_| None).collect(),
            open: 0,
            spare: (0..n).map(|_| None).collect(),
            files: vec![PartState::default(); n],
            open_chunks: 0,
            clock: 0,
            summary: Summary::default(),
            kind_names: NumMap::default(),
            kind_list: Vec::new(),
            layouts: Layouts::default(),
            scratch: Scratch::default(),
            order: ByKind::default(),
            kind_rows: 0,
            kind_bytes: 0,
            keep_records: true,
            keep_kinds: None,
        }
    }

    /// Write only the tables `keep` says yes to (by name: [`RECORDS`], or a kind table's); the
    /// others are not built at all, which is what makes this cheaper than dropping them
    /// afterwards. Call before the first record. Without the records table, [`Summary`] still
    /// counts records but not frames and diagnostics.
    pub fn only_tables(&mut self, keep: impl Fn(&str) -> bool + Send + 'static) {
        self.keep_records = keep(RECORDS);
        self.keep_kinds = Some(Box::new(keep));
    }

    /// Make room for `rows` rows of the `records` table at once (up to a row group) unless it
    /// has it, when their count is known before the first: the columns are not grown row by
    /// row.
    pub fn reserve_records(&mut self, rows: usize) {
        let rows = rows.min(self.opts.rows_per_group);
        if self.records.rows() == 0 && rows > self.records.room() {
            self.records = self.records.again(rows);
        }
    }

    /// Add one record.
    pub fn record(&mut self, rec: &Record<'_>) -> io::Result<()> {
        if let Some(k) = self.records_part(rec)? {
            self.kind_part(k, rec)?;
        }
        Ok(())
    }

    /// Add records `recs` of an owned run, in order: the same rows as [`Self::record`] of each,
    /// but the kind rows of a stretch of `KIND_STRETCH` (2,048) records built table after table
    /// rather than record after record (each table's rows in their order; only when its
    /// batches are cut differs). Built record after record, a status log's kind rows went from
    /// one table's columns to another's at every row, and cost half as much again as when the
    /// same records came kind by kind (docs/performance.md).
    pub fn run(
        &mut self,
        batch: &aptscope_dissector::owned::Batch,
        recs: std::ops::Range<usize>,
    ) -> io::Result<()> {
        let mut order = std::mem::take(&mut self.order);
        let (mut start, stop) = (recs.start, recs.end.min(batch.len()));
        while start < stop {
            let end = (start + KIND_STRETCH).min(stop);
            for i in start..end {
                batch.with(i, &mut |r| {
                    if let Some(k) = self.records_part(r)? {
                        order.push(k.index, i);
                    }
                    Ok::<(), io::Error>(())
                })?;
            }
            for &(k, i) in order.sorted() {
                if let Some(k) = Kinds::global().by_index(k as usize) {
                    batch.with(i as usize, &mut |r| self.kind_part(k, r))?;
                }
            }
            start = end;
        }
        self.order = order;
        Ok(())
    }

    /// The `records` row of `rec`; its kind table if it has a row there.
    fn records_part(&mut self, rec: &Record<'_>) -> io::Result<Option<&'static KindSchema>> {
        let ki = self.kind_of(rec);
        let (kname, kind) = match ki.and_then(|i| self.kind_list.get(i)) {
            Some(&(n, k)) => (n, k),
            None => (None, None),
        };
        if self.keep_records {
            records_row(
                &mut self.records,
                &mut self.summary,
                rec,
                kname,
                &mut self.text,
            );
            if self.records.rows() >= self.opts.rows_per_group
                || self.records.bytes() >= self.opts.bytes_per_group
            {
                self.flush_records()?;
            }
        }
        self.summary.records += 1;
        Ok(kind.filter(|_| rec.meta().is_some()))
    }

    /// The row of `rec` in its kind table `k`.
    fn kind_part(&mut self, k: &'static KindSchema, rec: &Record<'_>) -> io::Result<()> {
        let Some(m) = rec.meta() else {
            return Ok(());
        };
        self.open_kind(k)?;
        let Some(Some(o)) = self.kinds.get_mut(k.index) else {
            return Ok(());
        };
        o.used = self.clock;
        let b = &mut o.buf;
        let before = b.bytes();
        b.uint(1, m.n);
        b.uint(2, m.stream as u64);
        put_opt_u(b, 3, m.ts_ns);
        match rec {
            Record::Apt(a) => apt_values(&mut self.layouts, &mut self.scratch, k, a, b),
            Record::Ell(e) => ell_values(&mut self.layouts, k, e, b),
            _ => {}
        }
        b.end_row();
        self.kind_rows += 1;
        self.kind_bytes += b.bytes() - before;
        self.kind_row_done(k)
    }

    /// The kind table of a frame's message (its place in `kind_list`), looked up once per
    /// message rather than by a name made for every frame.
    fn kind_of(&mut self, rec: &Record<'_>) -> Option<usize> {
        // `own`: the message's (or command's) name.
        let (key, own, name): ((usize, usize), &'static str, &dyn Fn() -> String) = match rec {
            Record::Apt(a) => {
                let m = a.frame.msg?;
                let sub = a.frame.sub;
                let key = (
                    m as *const _ as usize,
                    sub.map_or(0, |x| x as *const _ as usize),
                );
                (key, m.name, &move || schema::apt_kind_name(m, sub))
            }
            Record::Ell(e) => {
                let c = e.frame.cmd?;
                ((c as *const _ as usize, 1), c.name, &move || {
                    schema::ell_kind_name(c)
                })
            }
            _ => return None,
        };
        let list = &mut self.kind_list;
        let keep = &self.keep_kinds;
        let i = *self.kind_names.entry(key).or_insert_with(|| {
            let n = name();
            let k = Kinds::global().get(&n).map(|k| &**k);
            // The message's own name where they are the same text: the `records` rows compare
            // the two, by address first (`records::same`).
            let name = k.map(|k| if k.name == own { own } else { k.name.as_str() });
            let k = k.filter(|_| keep.as_ref().is_none_or(|f| f(&n)));
            list.push((name, k));
            list.len() - 1
        });
        Some(i)
    }

    /// Open kind table `k`'s buffer unless it is (closing another when too many are); a tick of
    /// the clock that says which was used least recently.
    fn open_kind(&mut self, k: &'static KindSchema) -> io::Result<()> {
        self.clock += 1;
        if matches!(self.kinds.get(k.index), Some(None)) {
            if self.open >= self.opts.max_open_kinds {
                // Too many open: the least recently used gives its rows up first.
                let lru = self
                    .kinds
                    .iter()
                    .enumerate()
                    .filter_map(|(i, o)| Some((i, o.as_ref()?.used)))
                    .min_by_key(|(_, used)| *used)
                    .map(|(i, _)| i);
                if let Some(i) = lru {
                    self.close_kind(i)?;
                }
            }
            let spare = self.spare.get_mut(k.index).and_then(Option::take);
            let buf = spare.unwrap_or_else(|| {
                let mut buf = if self.opts.words_as_text {
                    TableBuf::new(k.schema.clone()).words_as_text(&k.batch)
                } else {
                    TableBuf::new(k.batch.clone())
                };
                buf.constant_text(0, self.file.clone());
                buf
            });
            if let Some(slot) = self.kinds.get_mut(k.index) {
                *slot = Some(Open {
                    buf,
                    used: 0,
                    name: &k.name,
                });
                self.open += 1;
            }
        }
        Ok(())
    }

    /// After a row of kind table `k`: write what is due.
    fn kind_row_done(&mut self, k: &KindSchema) -> io::Result<()> {
        let budget = self.opts.kind_rows;
        let Some(Some(o)) = self.kinds.get_mut(k.index) else {
            return Ok(());
        };
        if o.buf.rows() >= self.opts.rows_per_group || o.buf.bytes() >= self.opts.bytes_per_group {
            self.kind_rows -= o.buf.rows();
            self.kind_bytes -= o.buf.bytes();
            self.flush_kind(k.index)?;
        }
        // Many kinds each short of a row group: the biggest is written early (the first by
        // name of equally big ones), by rows or by bytes, whichever is over.
        let measure: Option<fn(&TableBuf) -> usize> = if self.kind_rows > budget {
            Some(TableBuf::rows)
        } else if self.kind_bytes > self.opts.bytes_per_group {
            Some(TableBuf::bytes)
        } else {
            None
        };
        if let Some(size) = measure {
            let mut big: Option<(usize, usize)> = None;
            for (i, o) in self.kinds.iter().enumerate() {
                if let Some(o) = o {
                    if big.is_none_or(|(_, r)| size(&o.buf) > r) {
                        big = Some((i, size(&o.buf)));
                    }
                }
            }
            if let Some((i, _)) = big {
                self.close_kind(i)?;
            }
        }
        Ok(())
    }

    fn close_kind(&mut self, i: usize) -> io::Result<()> {
        let buf = self.shut_kind(i)?;
        // Kept, the batches never give their memory back: a table opened again takes its
        // buffer, with its room, rather than growing a new one from nothing (a status log's
        // kinds are closed and opened again every few thousand rows, the biggest first).
        if self.opts.batches_kept {
            self.keep_spare(i, buf);
        }
        Ok(())
    }

    /// Keep kind table `i`'s buffer, emptied, for when it opens again.
    fn keep_spare(&mut self, i: usize, buf: Option<TableBuf>) {
        if let Some(slot) = self.spare.get_mut(i) {
            *slot = buf.or(slot.take());
        }
    }

    /// Write kind table `i`'s rows and close it: its buffer, emptied, if it was open.
    fn shut_kind(&mut self, i: usize) -> io::Result<Option<TableBuf>> {
        if let Some(Some(o)) = self.kinds.get(i) {
            self.kind_rows -= o.buf.rows();
            self.kind_bytes -= o.buf.bytes();
            self.flush_kind(i)?;
            if let Some(o) = self.kinds.get_mut(i).and_then(Option::take) {
                self.open -= 1;
                return Ok(Some(o.buf));
            }
        }
        Ok(None)
    }

    fn flush_records(&mut self) -> io::Result<()> {
        if self.records.rows() == 0 {
            return Ok(());
        }
        let room = self.opts.room(self.records.rows());
        let batch = self.records.take(room).map_err(perr)?;
        self.write(None, RECORDS, &batch)
    }

    /// Kind table `i`'s rows as a row group (its buffer stays open).
    fn flush_kind(&mut self, i: usize) -> io::Result<()> {
        let Some(Some(o)) = self.kinds.get_mut(i) else {
            return Ok(());
        };
        let rows = o.buf.rows();
        if rows == 0 {
            return Ok(());
        }
        let batch = o.buf.take(self.opts.room(rows)).map_err(perr)?;
        let name = o.name;
        self.write(Some(i), name, &batch)
    }

    /// A row group of kind table `kind` (`None`: of `records`) to the sink, into its part
    /// file; counts it. A part file is closed when it holds [`Options::groups_per_file`] row
    /// groups, and the one of most column chunks when the open files together hold more than
    /// [`Options::open_chunks`] (decided here, from the rows alone, so every run of the same
    /// capture cuts the same files whatever thread writes them).
    fn write(
        &mut self,
        kind: Option<usize>,
        name: &'static str,
        batch: &RecordBatch,
    ) -> io::Result<()> {
        let Some(st) = (match kind {
            None => Some(&mut self.records_file),
            Some(i) => self.files.get_mut(i),
        }) else {
            return Ok(());
        };
        st.name = name;
        self.sink.write(name, st.part, batch)?;
        self.summary.row_groups += 1;
        let chunks = leaves(batch.schema().fields());
        st.groups += 1;
        st.chunks += chunks;
        self.open_chunks += chunks;
        if st.groups >= self.opts.groups_per_file {
            self.close_file(kind)?;
        }
        while self.open_chunks > self.opts.open_chunks {
            // The file holding the most: the first of equally big ones, `records` first.
            let mut big = (None, self.records_file.chunks);
            for (i, f) in self.files.iter().enumerate() {
                if f.chunks > big.1 {
                    big = (Some(i), f.chunks);
                }
            }
            if big.1 == 0 {
                break;
            }
            self.close_file(big.0)?;
        }
        Ok(())
    }

    /// Close kind table `kind`'s part file (`None`: `records`'s); the next row group starts
    /// the next part.
    fn close_file(&mut self, kind: Option<usize>) -> io::Result<()> {
        let Some(st) = (match kind {
            None => Some(&mut self.records_file),
            Some(i) => self.files.get_mut(i),
        }) else {
            return Ok(());
        };
        if st.groups == 0 {
            return Ok(());
        }
        self.sink.close(st.name, st.part)?;
        self.open_chunks -= st.chunks;
        *st = PartState {
            name: st.name,
            part: st.part + 1,
            groups: 0,
            chunks: 0,
        };
        Ok(())
    }

    /// Write what is buffered; returns the sink and what was written.
    pub fn finish(mut self) -> io::Result<(S, Summary)> {
        self.write_all(false)?;
        self.sink.finish()?;
        Ok((self.sink, self.summary))
    }

    /// Write what is buffered, as [`Self::finish`] does, and go on as a writer just made would
    /// (the next rows start new row groups and part files), but in the buffers of these, with
    /// their room: a thread building one run of records after another builds each in the
    /// memory the last one's columns grew to, not growing them again (see
    /// [`Options::batches_kept`]).
    pub fn cut(&mut self) -> io::Result<()> {
        self.write_all(true)
    }

    /// The sink, for what it gathered.
    pub fn sink_mut(&mut self) -> &mut S {
        &mut self.sink
    }

    /// Write every table's rows and close its part file; the kind tables' buffers kept as
    /// spares when `keep`.
    fn write_all(&mut self, keep: bool) -> io::Result<()> {
        self.flush_records()?;
        // By name, as the kinds are numbered.
        for i in 0..self.kinds.len() {
            let buf = self.shut_kind(i)?;
            if keep {
                self.keep_spare(i, buf);
            }
        }
        self.close_file(None)?;
        for i in 0..self.files.len() {
            self.close_file(Some(i))?;
        }
        Ok(())
    }
}

/// The `records` row of `rec` (`kname`: its kind table), counting its frames and diagnostics.
/// `text`: room for the rare text made by formatting (the detail of detect, stream, units).
fn records_row(
    b: &mut RecordsBuf,
    sum: &mut Summary,
    rec: &Record<'_>,
    kname: Option<&'static str>,
    text: &mut String,
) {
    let mut r = Row::default();
    if let Some(m) = rec.meta() {
        r.stream = Some(m.stream);
        r.n = Some(m.n);
        r.ts_ns = m.ts_ns;
        r.rel_s = m.rel_s;
    }
    let mut diag = |b: &mut RecordsBuf, d: &Diag| {
        b.diagnostic(d);
        sum.diagnostics += 1;
    };
    match rec {
        Record::Detect {
            proto, detection, ..
        } => {
            r.ty = "detect";
            r.proto = Some(proto.code());
            text.clear();
            let _ = write!(
                text,
                "{} apt={:.3} ell={:.3}",
                if detection.proto.is_some() {
                    "certain"
                } else {
                    "best guess"
                },
                detection.apt,
                detection.elliptec
            );
            r.detail = Some(text);
        }
        Record::Stream { id, name, settings } => {
            r.ty = "stream";
            // A stream record has no meta: its id is the stream column.
            r.stream = Some(*id);
            r.detail = Some(name);
            if let Some(x) = settings {
                text.clear();
                let _ = write!(text, "{name} ({x})");
                r.detail = Some(text);
            }
        }
        Record::Input(d) => {
            r.ty = "input";
            r.offset = Some(d.offset);
            diag(b, d);
        }
        Record::FileDiag { offset, kind, msg } => {
            r.ty = "input";
            r.offset = Some(*offset);
            b.diag_text(kind, *offset, msg);
            sum.diagnostics += 1;
        }
        Record::Units(nt) => {
            r.ty = "units";
            r.proto = Some("apt");
            r.stream = Some(nt.stream);
            text.clear();
            json::units_notice(text, nt);
            r.detail = Some(text);
        }
        Record::Apt(a) => {
            let f = a.frame;
            let h = f.header();
            r.ty = "frame";
            r.proto = Some("apt");
            r.dir = dir_text(a.dir());
            r.offset = Some(f.offset);
            r.msgid = Some(h.msg_id());
            if let Some(m) = f.msg {
                r.name = Some(m.name);
                r.kind = kname;
            }
            r.sub = f.sub.map(|x| x.name);
            r.src = Some(h.src().byte());
            r.dst = Some(h.dst().byte());
            r.channel = f.channel();
            r.len = Some(f.bytes.len() as u32);
            r.raw = Some(f.bytes);
            for d in f.diags().chain(a.pair.diags(f.offset)) {
                diag(b, &d);
            }
            r.pair = a.pair.pair;
            r.latency_ms = a.pair.latency_ns.map(|l| l as f64 / 1e6);
            sum.frames += 1;
        }
        Record::Ell(e) => {
            let f = e.frame;
            r.ty = "frame";
            r.proto = Some("ell");
            let d = f.dir();
            r.dir = dir_text(Some(d));
            r.offset = Some(f.offset);
            r.code = Some(f.code_str());
            if let Some(c) = f.cmd {
                r.name = Some(c.name);
                r.kind = kname;
            }
            // The module's address is the destination of a command, the source of a reply.
            if d == Dir::HostToDevice {
                r.dst = Some(f.addr);
            } else {
                r.src = Some(f.addr);
            }
            r.len = Some(f.bytes.len() as u32);
            r.raw = Some(f.bytes);
            for d in f.diags() {
                diag(b, d);
            }
            r.pair = e.obs.pair;
            r.latency_ms = e.obs.latency_ns.map(|l| l as f64 / 1e6);
            sum.frames += 1;
        }
        Record::Garbage(g) => {
            r.ty = "garbage";
            r.proto = Some(g.proto.code());
            r.dir = dir_text(g.meta.cap_dir);
            r.offset = Some(g.offset);
            r.len = Some(g.bytes.len() as u32);
            r.raw = Some(g.bytes);
            let d = match g.kind {
                Some(k) => json::garbage_diag(g.offset, g.bytes.len(), k),
                None => Diag {
                    offset: g.offset,
                    kind: DiagKind::Garbage {
                        len: g.bytes.len() as u32,
                    },
                },
            };
            diag(b, &d);
        }
        Record::NoReply(e) => {
            r.ty = "no_reply";
            r.proto = Some(e.proto.code());
            r.stream = Some(e.stream);
            r.offset = Some(e.offset);
            if e.proto == aptscope_dissector::detect::Proto::Apt {
                r.name = Some(e.name);
            } else {
                r.code = Some(e.name);
            }
            r.refn = Some(e.n);
            diag(b, &e.diag());
        }
    }
    b.push(&r);
}

/// Which of a frame's fields fills each column of its kind table, by layout of fields: the
/// kind, the first and last field's table entries and their count identify the form (and
/// sub-message form), so each is worked out once (by name, the first field of that name)
/// rather than searched for in every frame.
#[derive(Default)]
struct Layouts(Vec<Vec<Layout>>);

/// A form's key (its first and last field's table entries, their count) and its columns'
/// fields.
type Layout = ((usize, usize, usize), Vec<Option<usize>>);

impl Layouts {
    /// By kind (its [`KindSchema::index`]), then among the kind's forms (one or two): a few
    /// comparisons rather than a hash map by all four, looked up in every frame.
    fn get<T, F: 'static>(
        &mut self,
        k: &KindSchema,
        fields: &[(&'static F, T)],
        name: impl Fn(&F) -> &'static str,
    ) -> &[Option<usize>] {
        let addr = |f: Option<&(&'static F, T)>| f.map_or(0, |(fd, _)| *fd as *const F as usize);
        let key = (addr(fields.first()), addr(fields.last()), fields.len());
        if self.0.len() <= k.index {
            self.0.resize_with(k.index + 1, Vec::new);
        }
        let forms = &mut self.0[k.index];
        let at = match forms.iter().position(|(f, _)| *f == key) {
            Some(i) => i,
            None => {
                let cols = k
                    .cols
                    .iter()
                    .map(|c| fields.iter().position(|(fd, _)| name(fd) == c.field))
                    .collect();
                forms.push((key, cols));
                forms.len() - 1
            }
        };
        &forms[at].1
    }
}

/// The fields of the APT frame being written, in a vector whose allocation is kept from frame
/// to frame (a vector allocated and freed per frame, and grown by doubling before it was sized,
/// was a tenth of building a kind row). The fields borrow each frame's bytes: the vector is
/// emptied and given back under another lifetime, collected in place (same layout, same
/// allocation).
struct Scratch(Vec<(&'static AptField, AptValue<'static>)>);

impl Default for Scratch {
    fn default() -> Self {
        Scratch(Vec::with_capacity(32))
    }
}

// `filter_map(|_| None)`, not `filter`: the element type changes (its lifetime), which a
// filter cannot do; the vector is empty, so nothing is dropped or made.
#[allow(clippy::unnecessary_filter_map)]
impl Scratch {
    fn take<'a>(&mut self) -> Vec<(&'static AptField, AptValue<'a>)> {
        let mut v = std::mem::take(&mut self.0);
        v.clear();
        v.into_iter().filter_map(|_| None).collect()
    }

    fn put(&mut self, mut v: Vec<(&'static AptField, AptValue<'_>)>) {
        v.clear();
        self.0 = v.into_iter().filter_map(|_| None).collect();
    }
}

/// The first column of a kind table's fields (after [`schema::KEYS`]).
const FIELDS: usize = schema::KEYS.len();

/// Records of a run whose kind rows [`CaptureWriter::run`] builds table by table: a stretch
/// whose records are still in the cache when its kind rows are built, long enough that most
/// tables have many rows in it (2,048 records, or 512, gave most of what a whole run sorted by
/// kind did; 8,192 less).
pub(crate) const KIND_STRETCH: usize = 2048;

/// The kind rows of a stretch as `(table, record)`, put in order of table and then of record
/// by counting each table's rows (a stretch has rows in a few dozen of the hundreds of tables):
/// sorting them was 1.4 % of the instructions of a status log's rows on two threads, this 0.6.
#[derive(Default)]
struct ByKind {
    /// Rows of each table in the stretch, by table index (as far as the largest met); then
    /// where its next row goes. All zero between stretches.
    count: Vec<u32>,
    /// The tables with rows in the stretch, as met.
    met: Vec<u32>,
    /// The rows, as pushed (in order of record).
    rows: Vec<(u32, u32)>,
    /// The rows by table, then in order of record.
    sorted: Vec<(u32, u32)>,
}

impl ByKind {
    /// Record `i` has a row in table `k`; records come in order.
    #[inline]
    fn push(&mut self, k: usize, i: usize) {
        if k >= self.count.len() {
            self.count.resize(k + 1, 0);
        }
        if let Some(c) = self.count.get_mut(k) {
            if *c == 0 {
                self.met.push(k as u32);
            }
            *c += 1;
            self.rows.push((k as u32, i as u32));
        }
    }

    /// The rows pushed since the last call, by table (in order of index) and in order within
    /// each.
    fn sorted(&mut self) -> &[(u32, u32)] {
        self.met.sort_unstable();
        let mut at = 0;
        for &k in &self.met {
            if let Some(c) = self.count.get_mut(k as usize) {
                (*c, at) = (at, at + *c);
            }
        }
        self.sorted.clear();
        self.sorted.resize(self.rows.len(), (0, 0));
        for &(k, i) in &self.rows {
            if let Some(c) = self.count.get_mut(k as usize) {
                if let Some(s) = self.sorted.get_mut(*c as usize) {
                    *s = (k, i);
                }
                *c += 1;
            }
        }
        for &k in &self.met {
            if let Some(c) = self.count.get_mut(k as usize) {
                *c = 0;
            }
        }
        self.met.clear();
        self.rows.clear();
        &self.sorted
    }
}

/// The field columns of an APT frame's kind row.
fn apt_values<'a>(
    lay: &mut Layouts,
    scratch: &mut Scratch,
    k: &KindSchema,
    a: &'a AptRec<'a>,
    b: &mut TableBuf,
) {
    let f = a.frame;
    let t = f.table();
    let mut fields = scratch.take();
    fields.extend(f.fields());
    apt_columns(lay, k, a, t, &fields, b);
    scratch.put(fields);
}

/// The kind row's columns from the fields of [`apt_values`].
fn apt_columns<'a>(
    lay: &mut Layouts,
    k: &KindSchema,
    a: &'a AptRec<'a>,
    t: &Table,
    fields: &[(&'static AptField, AptValue<'a>)],
    b: &mut TableBuf,
) {
    use aptscope_dissector::apt::Value;
    let idx = lay.get(k, fields, |fd| fd.name);
    let mut last_phys = None;
    for (j, (c, i)) in k.cols.iter().zip(idx).enumerate() {
        let Some((i, (fd, v))) = i.and_then(|i| Some((i, fields.get(i)?))) else {
            continue;
        };
        let at = FIELDS + j;
        match c.fill {
            Fill::Int => match *v {
                Value::U(x) => b.uint(at, x),
                Value::I(x) => b.int(at, x),
                _ => {}
            },
            Fill::Float => {
                if let Some(x) = v.as_f64() {
                    b.float(at, x);
                }
            }
            Fill::EnumLabel => {
                let label = fd
                    .enumeration
                    .zip(v.as_i64())
                    .and_then(|(e, x)| t.enum_def(e).label(x));
                if let Some(l) = label {
                    b.word(at, l);
                }
            }
            Fill::FlagNames => {
                if let (Some(fl), Value::U(x)) = (fd.flags, *v) {
                    b.list_words(at, t.flags_def(fl).set(x).map(|(_, l)| *l));
                }
            }
            Fill::Text => {
                if let Value::Str(s) = *v {
                    b.text(at, &aptscope_dissector::apt::text_of(s));
                }
            }
            Fill::Bytes => {
                if let Value::Bytes(x) = *v {
                    b.put_bytes(at, x);
                }
            }
            Fill::List => {
                let els = v.elements();
                if matches!(v, Value::Array(aptscope_dissector::table::Prim::F32, _)) {
                    b.list_float(at, els.filter_map(|e| e.as_f64()));
                } else {
                    b.list_num(at, els.filter_map(|e| e.as_i64()));
                }
            }
            Fill::Phys | Fill::PhysUnit => {
                // The unit's column follows the value's: converted (and rounded) once.
                let p = match last_phys {
                    Some((at_field, p)) if at_field == i => p,
                    _ => phys_or_scaled(fd, v, a.scale),
                };
                last_phys = Some((i, p));
                match (c.fill, p) {
                    (Fill::Phys, Some((x, _))) => b.float(at, x),
                    (_, Some((_, u))) => b.text(at, u),
                    _ => {}
                }
            }
            Fill::StatusName => {}
        }
    }
}

/// The field columns of an Elliptec frame's kind row.
fn ell_values<'a>(lay: &mut Layouts, k: &KindSchema, e: &'a EllRec<'a>, b: &mut TableBuf) {
    let f = e.frame;
    let mut fields = Vec::with_capacity(16);
    fields.extend(f.fields());
    let scale = e.obs.module.as_ref().and_then(|m| m.scale());
    let idx = lay.get(k, &fields, |fd| fd.name);
    for (j, (c, i)) in k.cols.iter().zip(idx).enumerate() {
        let Some((fd, v)) = i.and_then(|i| fields.get(i)) else {
            continue;
        };
        let at = FIELDS + j;
        match (c.fill, *v) {
            (Fill::StatusName, EllValue::U(x)) => b.word(at, status_name(x as u32)),
            (Fill::Int, EllValue::U(x)) => b.uint(at, x),
            (Fill::Int, EllValue::I(x)) => b.int(at, x),
            (Fill::Text, EllValue::Char(ch)) => b.text(at, ch.encode_utf8(&mut [0; 4])),
            (Fill::Text, EllValue::Digits(d)) => b.text(at, d),
            (Fill::Bytes, EllValue::Raw(x)) => b.put_bytes(at, x),
            (Fill::Phys | Fill::PhysUnit, EllValue::I(p)) if fd.kind == EllKind::Position => {
                match scale.filter(|(ppu, _)| *ppu > 0.0) {
                    Some((ppu, _)) if c.fill == Fill::Phys => {
                        b.float(at, aptscope_dissector::apt::round_sig(p as f64 / ppu))
                    }
                    Some((_, unit)) => b.word(at, unit),
                    None => {}
                }
            }
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stretch's rows counted by table come as sorting them would put them, stretch after
    /// stretch (the counts start again at zero), whatever tables and how many rows each.
    #[test]
    fn rows_counted_by_table_are_the_rows_sorted() {
        let mut order = ByKind::default();
        let mut x: u64 = 0x2545_f491_4f6c_dd1d;
        for stretch in 0..40 {
            // From one table to every one of 600, rows from none to a few thousand.
            let tables = 1 + stretch * 15;
            let rows = (stretch * 97) % 3000;
            let mut want = Vec::new();
            for i in 0..rows {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                let k = (x % tables as u64) as usize;
                order.push(k, i);
                want.push((k as u32, i as u32));
            }
            want.sort_unstable();
            assert_eq!(order.sorted(), &want[..], "stretch {stretch}");
        }
    }

    /// Text columns are dictionary-encoded also inside lists (the diagnostics' messages, flag
    /// names), raw bytes have no statistics, numbers neither dictionary nor lost statistics.
    #[test]
    fn dictionaries_for_text_also_in_lists() {
        let path = |p: &[&str]| ColumnPath::new(p.iter().map(|s| s.to_string()).collect());
        let rec = schema::records_schema();
        let p = writer_properties(100, &rec);
        for c in [
            &["name"][..],
            &["diagnostics", "list", "item", "msg"],
            &["diagnostics", "list", "item", "kind"],
        ] {
            assert!(p.dictionary_enabled(&path(c)), "{c:?}");
        }
        assert!(!p.dictionary_enabled(&path(&["n"])));
        assert!(!p.dictionary_enabled(&path(&["diagnostics", "list", "item", "offset"])));
        assert_eq!(
            p.statistics_enabled(&path(&["raw"])),
            EnabledStatistics::None
        );
        assert_ne!(p.statistics_enabled(&path(&["n"])), EnabledStatistics::None);
        let k = Kinds::global().get("MOT_GET_DCSTATUSUPDATE").expect("kind");
        let flags = k
            .schema
            .fields()
            .iter()
            .find(|f| f.metadata().contains_key("flags"))
            .expect("a flags column");
        let p = writer_properties(100, &k.schema);
        assert!(p.dictionary_enabled(&path(&[flags.name(), "list", "item"])));
    }

    /// Kinds are numbered by name.
    #[test]
    fn kinds_are_numbered_in_name_order() {
        let all = Kinds::global().all();
        assert_eq!(all.len(), Kinds::global().len());
        for (i, k) in all.iter().enumerate() {
            assert_eq!(k.index, i, "{}", k.name);
        }
        assert!(all.windows(2).all(|w| w[0].name < w[1].name));
    }
}
