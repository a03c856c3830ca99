//! The schemas of the dataset, derived from the message tables: the common `records` table and
//! one table per message kind whose columns are the kind's fields, typed from the table.

use aptscope_dissector::ell::table::{Cmd, Kind as EllKind, COMMANDS};
use aptscope_dissector::table::{Field, FormKind, MsgDef, Prim, SubDef, Ty};
use aptscope_dissector::Table;
use arrow_schema::{DataType, Field as AField, Fields, Schema, SchemaRef, TimeUnit};
use std::collections::HashMap;
use std::sync::{Arc, OnceLock};

/// Name of the table of common columns (and of its directory).
pub const RECORDS: &str = "records";

/// Prefix of Elliptec kind tables (`ELL_POSITION`): APT and Elliptec names stay apart.
pub const ELL_PREFIX: &str = "ELL_";

/// The element type of the `diagnostics` list.
pub fn diag_struct() -> Fields {
    Fields::from(vec![
        AField::new("kind", DataType::Utf8, false),
        AField::new("offset", DataType::UInt64, false),
        AField::new("msg", DataType::Utf8, false),
    ])
}

fn list_of(dt: DataType) -> DataType {
    DataType::List(Arc::new(AField::new("item", dt, true)))
}

fn utc_ns() -> DataType {
    DataType::Timestamp(TimeUnit::Nanosecond, Some("UTC".into()))
}

/// The `records` table: one row per record of every capture (frames, garbage runs, requests
/// without reply, input diagnostics, detection, streams, units notices).
pub fn records_schema() -> SchemaRef {
    static S: OnceLock<SchemaRef> = OnceLock::new();
    S.get_or_init(|| {
        let f = |n: &str, dt: DataType, null: bool| AField::new(n, dt, null);
        Arc::new(Schema::new(vec![
            f("file", DataType::Utf8, false),
            f("stream", DataType::UInt32, true),
            f("n", DataType::UInt64, true),
            f("ts_ns", DataType::UInt64, true),
            f("time", utc_ns(), true),
            f("rel_s", DataType::Float64, true),
            f("dir", DataType::Utf8, true),
            f("proto", DataType::Utf8, true),
            f("type", DataType::Utf8, false),
            f("offset", DataType::UInt64, true),
            f("msgid", DataType::UInt16, true),
            f("name", DataType::Utf8, true),
            f("sub", DataType::Utf8, true),
            f("code", DataType::Utf8, true),
            f("kind", DataType::Utf8, true),
            f("src", DataType::UInt8, true),
            f("dst", DataType::UInt8, true),
            f("channel", DataType::Int64, true),
            f("len", DataType::UInt32, true),
            f("raw", DataType::Binary, true),
            f(
                "diagnostics",
                list_of(DataType::Struct(diag_struct())),
                false,
            ),
            f("pair", DataType::UInt64, true),
            f("latency_ms", DataType::Float64, true),
            f("ref", DataType::UInt64, true),
            f("detail", DataType::Utf8, true),
        ]))
    })
    .clone()
}

/// How a column of a kind table is filled from a field value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fill {
    /// The field's integer value, in the column's integer type.
    Int,
    /// The field's float value.
    Float,
    /// An enumeration's label (null when the value has none).
    EnumLabel,
    /// The names of the flags set.
    FlagNames,
    /// Text (`str[N]`, Elliptec digits and address characters).
    Text,
    /// Bytes.
    Bytes,
    /// Array elements.
    List,
    /// The physical value: the stage's or device's conversion, else the table's scale.
    Phys,
    /// The unit of [`Fill::Phys`] (it depends on the stage or device).
    PhysUnit,
    /// Elliptec status: the code's name.
    StatusName,
}

/// One field-derived column of a kind table.
#[derive(Debug, Clone)]
pub struct Col {
    /// Field name in the table.
    pub field: &'static str,
    /// What the column name adds to the field name (`_code`, `_bits`, `_phys`, `_phys_unit`).
    pub suffix: &'static str,
    /// How its value is derived.
    pub fill: Fill,
    /// Arrow type.
    pub dt: DataType,
}

/// A kind table: its name (directory), schema and the columns after the keys.
#[derive(Debug)]
pub struct KindSchema {
    /// Directory name: the APT message name (`MOT_MOVE_ABSOLUTE`), `MSG.SUB` for a sub-message,
    /// or `ELL_NAME` for an Elliptec command.
    pub name: String,
    /// The Arrow schema (keys first).
    pub schema: SchemaRef,
    /// The schema of the batches the writer makes: [`Self::schema`] with its columns of words
    /// (the key `file`, enum labels, flag names, units, status names: text from the tables) as
    /// dictionaries ([`crate::words`]).
    pub batch: SchemaRef,
    /// Field columns, in schema order after [`KEYS`].
    pub cols: Vec<Col>,
    /// Its place in [`Kinds::all`] (kinds sorted by name): writers keep their tables in a
    /// vector by this number rather than in a map by name.
    pub index: usize,
}

/// The key columns every kind table starts with (joins `records` on `file`, `n`).
pub const KEYS: [&str; 4] = ["file", "n", "stream", "ts_ns"];

fn key_fields() -> Vec<AField> {
    vec![
        AField::new("file", DataType::Utf8, false),
        AField::new("n", DataType::UInt64, false),
        AField::new("stream", DataType::UInt32, false),
        AField::new("ts_ns", DataType::UInt64, true),
    ]
}

fn prim_type(p: Prim) -> DataType {
    match p {
        Prim::U8 => DataType::UInt8,
        Prim::I8 => DataType::Int8,
        Prim::U16 => DataType::UInt16,
        Prim::I16 => DataType::Int16,
        Prim::U32 => DataType::UInt32,
        Prim::I32 => DataType::Int32,
        Prim::F32 => DataType::Float32,
    }
}

/// The value column of an APT field type.
fn apt_value(ty: Ty) -> Option<(Fill, DataType)> {
    Some(match ty {
        Ty::Prim(Prim::F32) => (Fill::Float, DataType::Float32),
        Ty::Prim(p) => (Fill::Int, prim_type(p)),
        Ty::Array(Prim::F32, _) => (Fill::List, list_of(DataType::Float64)),
        Ty::Array(_, _) => (Fill::List, list_of(DataType::Int64)),
        Ty::Str(_) => (Fill::Text, DataType::Utf8),
        Ty::Bytes(_) => (Fill::Bytes, DataType::Binary),
        Ty::Pad(_) => return None,
    })
}

/// Builds a schema from field columns, widening a field that two forms type differently.
struct Builder {
    cols: Vec<Col>,
    meta: Vec<HashMap<String, String>>,
}

impl Builder {
    fn new() -> Self {
        Builder {
            cols: vec![],
            meta: vec![],
        }
    }

    fn push(
        &mut self,
        field: &'static str,
        suffix: &'static str,
        fill: Fill,
        dt: DataType,
        meta: HashMap<String, String>,
    ) {
        if let Some(i) = self
            .cols
            .iter()
            .position(|c| c.field == field && c.suffix == suffix)
        {
            let c = &mut self.cols[i];
            if c.dt != dt {
                // Two forms disagree (u16 in one, i32 in another): a type that holds both.
                c.dt = match (&c.dt, &dt) {
                    (a, b) if a.is_integer() && b.is_integer() => DataType::Int64,
                    (a, b) if a.is_numeric() && b.is_numeric() => DataType::Float64,
                    _ => DataType::Utf8,
                };
            }
            return;
        }
        self.cols.push(Col {
            field,
            suffix,
            fill,
            dt,
        });
        self.meta.push(meta);
    }

    fn apt_field(&mut self, t: &Table, f: &Field) {
        let Some((fill, dt)) = apt_value(f.ty) else {
            return;
        };
        let mut meta = HashMap::new();
        meta.insert("aptscope.type".to_string(), f.ty.name());
        if let Some(u) = f.unit {
            meta.insert("unit".into(), u.into());
        }
        if let Some(s) = f.scale {
            meta.insert("scale".into(), s.to_string());
        }
        if let Some(q) = f.q {
            meta.insert("quantity".into(), q.as_str().into());
        }
        if let Some(m) = f.pct_of {
            meta.insert("pct_of".into(), m.as_str().into());
        }
        if let Some(e) = f.enumeration {
            let d = t.enum_def(e);
            let vals: Vec<String> = d.items.iter().map(|(v, l)| format!("{v}={l}")).collect();
            meta.insert("enum".into(), d.name.into());
            meta.insert("enum.values".into(), vals.join(","));
            self.push(f.name, "", Fill::EnumLabel, DataType::Utf8, meta.clone());
            self.push(f.name, "_code", Fill::Int, dt, meta);
        } else if let Some(fl) = f.flags {
            let d = t.flags_def(fl);
            let bits: Vec<String> = d
                .items
                .iter()
                .map(|(m, l)| format!("0x{m:X}={l}"))
                .collect();
            meta.insert("flags".into(), d.name.into());
            meta.insert("flags.bits".into(), bits.join(","));
            self.push(
                f.name,
                "",
                Fill::FlagNames,
                list_of(DataType::Utf8),
                meta.clone(),
            );
            self.push(f.name, "_bits", Fill::Int, dt, meta);
        } else {
            self.push(f.name, "", fill, dt, meta.clone());
        }
        if f.scale.is_some() || f.q.is_some() || f.pct_of.is_some() {
            let mut pm = HashMap::new();
            // A fixed scale has a fixed unit; a stage's or device's conversion names its own.
            if f.q.is_none() && f.pct_of.is_none() {
                if let Some(u) = f.unit {
                    pm.insert("unit".into(), u.into());
                }
            } else {
                pm.insert("unit".into(), format!("see {}_phys_unit", f.name));
            }
            self.push(f.name, "_phys", Fill::Phys, DataType::Float64, pm);
            if f.q.is_some() || f.pct_of.is_some() {
                self.push(
                    f.name,
                    "_phys_unit",
                    Fill::PhysUnit,
                    DataType::Utf8,
                    HashMap::new(),
                );
            }
        }
    }

    fn ell_field(&mut self, f: &aptscope_dissector::ell::table::Field) {
        let mut meta = HashMap::new();
        meta.insert("aptscope.type".to_string(), f.kind.name().to_string());
        if !f.kind.unit().is_empty() {
            meta.insert("unit".into(), f.kind.unit().into());
        }
        match f.kind {
            EllKind::Status => {
                self.push(f.name, "", Fill::StatusName, DataType::Utf8, meta.clone());
                self.push(f.name, "_code", Fill::Int, DataType::UInt8, meta);
            }
            EllKind::Addr | EllKind::Dec => self.push(f.name, "", Fill::Text, DataType::Utf8, meta),
            EllKind::Raw => self.push(f.name, "", Fill::Bytes, DataType::Binary, meta),
            EllKind::Signed => self.push(f.name, "", Fill::Int, DataType::Int64, meta),
            EllKind::Position => {
                self.push(f.name, "", Fill::Int, DataType::Int64, meta);
                let mut pm = HashMap::new();
                pm.insert("unit".into(), format!("see {}_phys_unit", f.name));
                self.push(f.name, "_phys", Fill::Phys, DataType::Float64, pm);
                self.push(
                    f.name,
                    "_phys_unit",
                    Fill::PhysUnit,
                    DataType::Utf8,
                    HashMap::new(),
                );
            }
            _ => self.push(f.name, "", Fill::Int, DataType::UInt64, meta),
        }
    }

    fn finish(self, name: String) -> KindSchema {
        let mut fields = key_fields();
        let mut taken: Vec<String> = KEYS.iter().map(|s| s.to_string()).collect();
        let mut words = vec!["file".to_string()];
        for (c, m) in self.cols.iter().zip(self.meta) {
            let mut n = format!("{}{}", c.field, c.suffix);
            // A field named like a key column (or a derived column) keeps its data apart.
            while taken.contains(&n) {
                n.push_str("_field");
            }
            taken.push(n.clone());
            if matches!(
                c.fill,
                Fill::EnumLabel | Fill::FlagNames | Fill::PhysUnit | Fill::StatusName
            ) {
                words.push(n.clone());
            }
            fields.push(AField::new(n, c.dt.clone(), true).with_metadata(m));
        }
        let schema = Schema::new(fields);
        let words: Vec<&str> = words.iter().map(String::as_str).collect();
        KindSchema {
            name,
            batch: Arc::new(crate::words::words_schema(&schema, &words)),
            schema: Arc::new(schema),
            cols: self.cols,
            index: 0,
        }
    }
}

/// Every kind table's name, and its schema built from the tables the first time it is asked
/// for: building all of them (400-odd) took 10 ms, twice the parsing of the tables, paid by
/// the first `to_arrow()` of a process and every `decode --to parquet`, when a capture holds
/// a few dozen kinds.
pub struct Kinds {
    table: &'static Table,
    by_name: HashMap<String, usize>,
    /// Sorted by name ([`KindSchema::index`]).
    sorted: Vec<Lazy>,
}

/// A kind of [`Kinds`]: where its schema comes from, and the schema once built.
struct Lazy {
    name: String,
    from: Origin,
    schema: OnceLock<Arc<KindSchema>>,
}

/// The table entry a kind's schema is built from.
#[derive(Clone, Copy)]
enum Origin {
    Apt(&'static MsgDef, Option<&'static SubDef>),
    Ell(&'static Cmd),
}

impl Lazy {
    fn schema(&self, t: &Table, index: usize) -> &Arc<KindSchema> {
        self.schema.get_or_init(|| {
            let mut k = match self.from {
                Origin::Apt(m, s) => apt_kind(t, m, s),
                Origin::Ell(c) => ell_kind(c),
            };
            k.index = index;
            Arc::new(k)
        })
    }
}

impl Kinds {
    /// The schemas of every APT message (and sub-message) and Elliptec command.
    pub fn global() -> &'static Kinds {
        static K: OnceLock<Kinds> = OnceLock::new();
        K.get_or_init(|| Kinds::build(Table::global()))
    }

    fn build(t: &'static Table) -> Kinds {
        // By name: a later entry of a name replaces an earlier one.
        let mut by_name = HashMap::new();
        for m in t.msgs() {
            by_name.insert(apt_kind_name(m, None), Origin::Apt(m, None));
            if let Some(g) = m.subs {
                for s in t.subs().iter().filter(|s| s.group == g) {
                    by_name.insert(apt_kind_name(m, Some(s)), Origin::Apt(m, Some(s)));
                }
            }
        }
        for c in COMMANDS {
            by_name.insert(ell_kind_name(c), Origin::Ell(c));
        }
        let mut sorted: Vec<Lazy> = by_name
            .into_iter()
            .map(|(name, from)| Lazy {
                name,
                from,
                schema: OnceLock::new(),
            })
            .collect();
        sorted.sort_by(|a, b| a.name.cmp(&b.name));
        let by_name = sorted
            .iter()
            .enumerate()
            .map(|(i, k)| (k.name.clone(), i))
            .collect();
        Kinds {
            table: t,
            by_name,
            sorted,
        }
    }

    /// How many kinds there are (one more than the largest [`KindSchema::index`]).
    pub fn len(&self) -> usize {
        self.sorted.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.sorted.is_empty()
    }

    /// A kind's schema.
    pub fn get(&self, name: &str) -> Option<&Arc<KindSchema>> {
        let i = *self.by_name.get(name)?;
        Some(self.sorted[i].schema(self.table, i))
    }

    /// The kind of index `i` ([`KindSchema::index`]).
    pub fn by_index(&self, i: usize) -> Option<&KindSchema> {
        self.sorted.get(i).map(|k| &**k.schema(self.table, i))
    }

    /// Whether a kind of this name exists (its schema not built).
    pub fn contains(&self, name: &str) -> bool {
        self.by_name.contains_key(name)
    }

    /// Every kind, sorted by name.
    pub fn all(&self) -> Vec<&Arc<KindSchema>> {
        self.sorted
            .iter()
            .enumerate()
            .map(|(i, k)| k.schema(self.table, i))
            .collect()
    }
}

/// The kind-table name of an APT message (with its sub-message).
pub fn apt_kind_name(m: &MsgDef, s: Option<&SubDef>) -> String {
    match s {
        Some(s) => format!("{}.{}", m.name, s.name),
        None => m.name.to_string(),
    }
}

/// The kind-table name of an Elliptec command.
pub fn ell_kind_name(c: &Cmd) -> String {
    format!("{ELL_PREFIX}{}", c.name)
}

fn apt_kind(t: &Table, m: &MsgDef, s: Option<&SubDef>) -> KindSchema {
    let mut b = Builder::new();
    for form in m.forms.iter().filter(|f| f.kind != FormKind::Sub) {
        for f in &form.fields {
            b.apt_field(t, f);
        }
    }
    if let Some(s) = s {
        for form in &s.forms {
            for f in &form.fields {
                b.apt_field(t, f);
            }
        }
    }
    b.finish(apt_kind_name(m, s))
}

fn ell_kind(c: &Cmd) -> KindSchema {
    let mut b = Builder::new();
    for f in c.fields {
        b.ell_field(f);
    }
    b.finish(ell_kind_name(c))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_has_unique_column_names_and_the_keys_first() {
        let k = Kinds::global();
        assert!(k.all().len() > 100, "{}", k.all().len());
        for ks in k.all() {
            let names: Vec<&str> = ks
                .schema
                .fields()
                .iter()
                .map(|f| f.name().as_str())
                .collect();
            assert_eq!(&names[..4], &KEYS, "{}", ks.name);
            let mut sorted = names.clone();
            sorted.sort();
            sorted.dedup();
            assert_eq!(sorted.len(), names.len(), "{}: {names:?}", ks.name);
            assert_eq!(ks.cols.len() + 4, names.len());
        }
    }

    #[test]
    fn kinds_built_when_asked_are_those_built_all_at_once() {
        // A fresh set, so that the kinds below are built one by one in an order of their own.
        let lazy = Kinds::build(Table::global());
        let some = [
            "PZ_GET_OUTPUTPOS",
            "MOT_MOVE_HOMED",
            "ELL_POSITION",
            "HW_GET_INFO",
        ];
        for name in some {
            assert!(lazy.contains(name), "{name}");
            let k = lazy.get(name).expect("kind");
            assert_eq!(k.name, name);
            assert!(std::ptr::eq(lazy.by_index(k.index).expect("index"), &**k));
        }
        assert!(!lazy.contains("NO_SUCH_KIND") && lazy.get("NO_SUCH_KIND").is_none());
        let all = Kinds::global().all();
        assert_eq!(all.len(), lazy.len());
        for (i, (a, b)) in all.iter().zip(lazy.all()).enumerate() {
            assert_eq!((a.index, b.index), (i, i));
            assert_eq!(
                (&a.name, &a.schema, &a.batch),
                (&b.name, &b.schema, &b.batch)
            );
        }
    }

    #[test]
    fn dcstatus_is_typed_from_the_table() {
        let k = Kinds::global().get("MOT_GET_DCSTATUSUPDATE").expect("kind");
        let s = &k.schema;
        let pos = s.field_with_name("position").expect("position");
        assert_eq!(pos.data_type(), &DataType::Int32);
        assert_eq!(
            pos.metadata().get("quantity").map(String::as_str),
            Some("pos")
        );
        assert!(s.field_with_name("position_phys").is_ok());
        let st = s
            .fields()
            .iter()
            .find(|f| f.metadata().contains_key("flags"))
            .expect("a flags column");
        assert!(matches!(st.data_type(), DataType::List(_)), "{st:?}");
        assert!(s.field_with_name(&format!("{}_bits", st.name())).is_ok());
    }

    #[test]
    fn enums_get_a_label_and_a_code() {
        let k = Kinds::global();
        let with_enum = k
            .all()
            .into_iter()
            .find(|ks| ks.cols.iter().any(|c| c.fill == Fill::EnumLabel))
            .expect("a kind with an enum");
        let label = with_enum
            .cols
            .iter()
            .find(|c| c.fill == Fill::EnumLabel)
            .expect("label");
        let code = format!("{}_code", label.field);
        let s = &with_enum.schema;
        assert_eq!(
            s.field_with_name(label.field)
                .map(|f| f.data_type().clone())
                .ok(),
            Some(DataType::Utf8)
        );
        assert!(
            s.field_with_name(&code)
                .is_ok_and(|f| f.data_type().is_integer()),
            "{code}"
        );
        let ell = k.get("ELL_GET_STATUS").expect("ELL_GET_STATUS");
        assert!(ell.schema.field_with_name("status_code").is_ok());
    }
}
