//! The compiled form of a filter: expressions, tests, field references and literals.

use crate::fields::{Key, Num};
use regex::Regex;
use std::cmp::Ordering;

#[derive(Clone, Debug)]
pub(super) enum Expr {
    All,
    Or(Vec<Expr>),
    And(Vec<Expr>),
    Not(Box<Expr>),
    Test(Test),
}

#[derive(Clone, Debug)]
pub(super) enum Test {
    /// `apt` / `ell` alone.
    Proto(&'static str),
    /// `diag`: diagnostics, or a garbage/input/diag record.
    Diag(Option<&'static str>),
    /// `unpaired`: a request without reply or a reply without request.
    Unpaired(Option<&'static str>),
    /// `paired`: the record has a `pair`.
    Paired(Option<&'static str>),
    Exists(FieldRef),
    Cmp(FieldRef, CmpOp, Lit),
    Contains(FieldRef, Lit),
    Matches(FieldRef, Regex),
    In(FieldRef, Vec<Lit>),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum CmpOp {
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
}

impl CmpOp {
    /// Whether the ordering of a value against the literal satisfies the comparison.
    pub(super) fn holds(self, o: Ordering) -> bool {
        match self {
            CmpOp::Eq => o == Ordering::Equal,
            CmpOp::Ne => o != Ordering::Equal,
            CmpOp::Lt => o == Ordering::Less,
            CmpOp::Le => o != Ordering::Greater,
            CmpOp::Gt => o == Ordering::Greater,
            CmpOp::Ge => o != Ordering::Less,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Op {
    Cmp(CmpOp),
    Contains,
    Matches,
    In,
}

/// A field reference resolved, once, to a record key and the path below it.
#[derive(Clone, Debug)]
pub(super) struct FieldRef {
    pub(super) proto: Option<&'static str>,
    pub(super) key: Key,
    pub(super) rest: Vec<String>,
    /// `apt.X` where `X` is a record key and a field name too: `fields.X` (this path) is read
    /// when the record has no key `X`.
    pub(super) fallback: Option<Vec<String>>,
    /// `ts`: `ts_ns` converted to seconds.
    pub(super) ts_seconds: bool,
    /// Nanoseconds per unit of the field's value, for comparisons with durations.
    pub(super) unit_ns: Option<f64>,
    /// `dir` / `msg_dir`: `host`, `tx`, `device`, `rx` … are read as `h2d` / `d2h`.
    pub(super) dir_like: bool,
    /// Text compares with case (`cmd`).
    pub(super) case_sensitive: bool,
}

#[derive(Clone, Debug)]
pub(super) struct Lit {
    pub(super) kind: LitKind,
    /// The value as written (strings: their content, unescaped).
    pub(super) text: String,
}

#[derive(Clone, Copy, Debug)]
pub(super) enum LitKind {
    Num(N),
    /// A duration, in nanoseconds.
    Dur(f64),
    Str,
    Word,
    Bool(bool),
}

impl Lit {
    pub(super) fn numeric(&self) -> bool {
        matches!(self.kind, LitKind::Num(_) | LitKind::Dur(_))
    }
}

pub(super) type N = Num;
