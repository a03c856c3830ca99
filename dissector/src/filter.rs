//! Display filters: a small Wireshark-like language over decoded records.
//!
//! One language is used by `aptscope decode -Y`, `stats -Y` and the TUI filter bar. A filter is
//! compiled once with [`Filter::parse`] (names resolved to [`crate::fields::Key`]s there) and
//! tested with [`Filter::matches`] against a typed [`crate::record::Record`] — read through
//! [`crate::fields::Fields`], nothing rendered — or against the NDJSON object `decode --json`
//! writes for it; both read alike (`dissector/tests/fields.rs` holds them equal).
//!
//! ```text
//! expr    := and ( ("||" | "or") and )*
//! and     := not ( ("&&" | "and") not )*
//! not     := ("!" | "not") not | "(" expr ")" | test
//! test    := field                                  exists and is truthy
//!          | field ("=="|"!="|"<"|"<="|">"|">="|"eq"|"ne"|"lt"|"le"|"gt"|"ge") value
//!          | field "contains" value                 substring, or membership for lists
//!          | field ("~" | "matches") value           regular expression (`regex` crate)
//!          | field "in" "{" value* "}"              set membership (spaces or commas)
//! field   := [proto "."] name ("." name)*           proto: apt, ell (or elliptec)
//! value   := "string" | 123 | 0x1F | -5 | 1.5 | 50ms | true | false | bare_word
//! ```
//!
//! Fields name NDJSON keys (the list is [`crate::fields::KEYS`]), with a few aliases: `apt.chan` is `channel`, `ts` is `ts_ns` in
//! seconds (capture time, not relative to the first record), `latency` is `latency_ms`;
//! durations (`50ms`, `1.5s`, `200us`, `2min`) convert to the unit of `ts`, `ts_ns` and
//! `latency`, plain numbers are in that unit. `len` (also `apt.len`) is the record's length in
//! bytes; `apt.data_len` is the data packet's. Direction values `host`/`tx` mean `h2d` and
//! `device`/`rx` mean `d2h`. Without `apt.`/`ell.` only record-level keys are accepted (`dir`,
//! `n`, `offset`, `len`, `ts`, `stream`, `latency`, `pair`, `proto`, `type`, `diag` …). `apt.src`/`apt.dst`/`apt.sub`/`ell.module` are objects,
//! compared through their `name` (or `model`, `kind`) with text and their `addr` (or `id`,
//! `value`) with numbers. A protocol-prefixed name that is not a key of the record is looked up
//! in its `fields` too (`apt.position` is `apt.fields.position`). A field that holds a list
//! (`status_bits`, `diag.kind`) matches when any element does; `!=` when none is equal. An enum
//! or flag field is also its number (`codes.X`) in comparisons: `ell.status == 12` and
//! `ell.status == OUT_OF_RANGE` both match; `~`, `contains` and existence read the names only. A number
//! compares with a number, and with text as written (`ell.addr == 5`, `ell.fields.year > 2021`);
//! other mixes of types are simply false, as is any comparison with a missing field. Text equality, `contains` and `~` ignore case (labels;
//! `(?-i)` in a regex turns that off), except for `cmd`, where case is the Elliptec direction
//! (`gs` request, `GS` reply); `<`, `>` … on text compare bytes. Special bare words:
//! `diag`, `unpaired`, `paired`, and `apt`/`ell` alone for "this protocol".
//!
//! An empty filter matches every record.

use crate::table::Table;
use std::cmp::Ordering;
use std::fmt;

use nom::branch::alt;
use nom::bytes::complete::{tag, tag_no_case, take_while, take_while1};
use nom::character::complete::{char as nchar, digit1, hex_digit1, multispace0};
use nom::combinator::{map, opt, recognize};
use nom::error::{ErrorKind, ParseError};
use nom::sequence::pair;
use nom::{Err as NomErr, IResult};
use regex::{Regex, RegexBuilder};
use std::borrow::Cow;

use crate::fields::{Fields, Key, Num, Role, Val, APT, ELL, KEYS, TOP};

/// Deepest nesting of parentheses and `!` accepted (keeps recursion bounded on any input).
const MAX_DEPTH: usize = 64;

/// A compiled display filter.
#[derive(Clone, Debug)]
pub struct Filter {
    expr: Expr,
    text: String,
}

/// A filter compiled into closures for scans over millions of records: each comparison of a
/// record-level value with a literal becomes a closure specialised for its operator and
/// literal, so a record costs a few calls instead of a walk of the expression tree. Gives the
/// same answers as [`Filter::matches`] (anything it does not specialise, it asks that of).
pub struct Matcher {
    root: Node,
}

type Node = Box<dyn Fn(&dyn Fields) -> bool + Send + Sync>;

impl fmt::Debug for Matcher {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Matcher")
    }
}

impl Matcher {
    /// Does `rec` pass the filter?
    pub fn matches(&self, rec: &dyn Fields) -> bool {
        (self.root)(rec)
    }
}

/// The closure of one expression.
fn node(e: &Expr) -> Node {
    match e {
        Expr::All => Box::new(|_| true),
        // Two terms (the common case) without a loop.
        Expr::Or(xs) => match &xs[..] {
            [a, b] => {
                let (a, b) = (node(a), node(b));
                Box::new(move |r| a(r) || b(r))
            }
            _ => {
                let xs: Vec<Node> = xs.iter().map(node).collect();
                Box::new(move |r| xs.iter().any(|x| x(r)))
            }
        },
        Expr::And(xs) => match &xs[..] {
            [a, b] => {
                let (a, b) = (node(a), node(b));
                Box::new(move |r| a(r) && b(r))
            }
            _ => {
                let xs: Vec<Node> = xs.iter().map(node).collect();
                Box::new(move |r| xs.iter().all(|x| x(r)))
            }
        },
        Expr::Not(x) => {
            let x = node(x);
            Box::new(move |r| !x(r))
        }
        Expr::Test(Test::Cmp(f, op, lit)) => cmp_node(f, *op, lit),
        Expr::Test(t) => {
            let t = t.clone();
            Box::new(move |r| t.eval(r))
        }
    }
}

/// A comparison: specialised when it is of a record-level number with an integer, or a
/// record-level word with a text (`==`/`!=`, ignoring case); when the record does not have the
/// value at hand, [`Test::cmp`] decides.
fn cmp_node(f: &FieldRef, op: CmpOp, lit: &Lit) -> Node {
    let (key, proto) = (f.key, f.proto);
    // Out of line (boxed): the specialised closures stay small.
    let general: Node = {
        let (f, lit) = (f.clone(), lit.clone());
        Box::new(move |r: &dyn Fields| Test::cmp(r, &f, op, &lit))
    };
    if f.ts_seconds || !f.rest.is_empty() {
        return general;
    }
    match lit.kind {
        LitKind::Num(N::I(l)) => match op {
            CmpOp::Eq => num_node(key, proto, general, move |x| i128::from(x) == l),
            CmpOp::Ne => num_node(key, proto, general, move |x| i128::from(x) != l),
            CmpOp::Lt => num_node(key, proto, general, move |x| i128::from(x) < l),
            CmpOp::Le => num_node(key, proto, general, move |x| i128::from(x) <= l),
            CmpOp::Gt => num_node(key, proto, general, move |x| i128::from(x) > l),
            CmpOp::Ge => num_node(key, proto, general, move |x| i128::from(x) >= l),
        },
        LitKind::Str | LitKind::Word
            if matches!(op, CmpOp::Eq | CmpOp::Ne) && !f.case_sensitive =>
        {
            let (text, ne) = (lit.text.clone(), op == CmpOp::Ne);
            Box::new(move |r| match r.word(key).filter(|_| proto_is(r, proto)) {
                Some(w) => w.eq_ignore_ascii_case(&text) != ne,
                None => general(r),
            })
        }
        _ => general,
    }
}

/// A comparison of a record-level number: `test` on the number the record has at hand,
/// else `general`.
fn num_node(
    key: Key,
    proto: Option<&'static str>,
    general: Node,
    test: impl Fn(i64) -> bool + Send + Sync + 'static,
) -> Node {
    Box::new(
        move |r| match r.number(key).filter(|_| proto_is(r, proto)) {
            Some(x) => test(x),
            None => general(r),
        },
    )
}

/// Why a filter does not compile, and where.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FilterError {
    /// 1-based column (in characters) of the offending place in the filter.
    pub column: usize,
    /// What is wrong there.
    pub msg: String,
}

impl fmt::Display for FilterError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "column {}: {}", self.column, self.msg)
    }
}

impl std::error::Error for FilterError {}

impl FilterError {
    /// Two lines: the filter `src`, then a `^` under the error's column (tabs kept so the caret
    /// lines up).
    pub fn caret(&self, src: &str) -> String {
        let line = src.lines().next().unwrap_or("");
        let pad: String = line
            .chars()
            .take(self.column.saturating_sub(1))
            .map(|c| if c == '\t' { '\t' } else { ' ' })
            .collect();
        let missing = self
            .column
            .saturating_sub(1)
            .saturating_sub(pad.chars().count());
        format!("{line}\n{pad}{}^", " ".repeat(missing))
    }
}

impl Filter {
    /// Compiles a filter. An empty (or all-blank) filter matches everything.
    pub fn parse(src: &str) -> Result<Filter, FilterError> {
        let text = src.to_string();
        if src.trim().is_empty() {
            return Ok(Filter {
                expr: Expr::All,
                text,
            });
        }
        let err = |rest: &str, msg: String| FilterError {
            column: column(src, rest),
            msg,
        };
        match expr_or(src, 0) {
            Ok((rest, expr)) => {
                let rest = skip_ws(rest);
                if rest.is_empty() {
                    Ok(Filter { expr, text })
                } else {
                    Err(err(rest, unexpected(rest)))
                }
            }
            Err(NomErr::Error(e)) => {
                let at = skip_ws(e.at);
                Err(err(
                    at,
                    format!("expected a field name, `!` or `(`, found `{}`", token(at)),
                ))
            }
            Err(NomErr::Failure(e)) => Err(err(
                e.at,
                e.msg.unwrap_or_else(|| "syntax error".to_string()),
            )),
            Err(NomErr::Incomplete(_)) => Err(err("", "incomplete filter".to_string())),
        }
    }

    /// Does the record pass the filter? `rec` is a typed [`crate::record::Record`] (or an
    /// [`crate::fields::InFile`]), or one NDJSON object of `decode --json`: both read alike.
    pub fn matches<F: Fields + ?Sized>(&self, rec: &F) -> bool {
        self.expr.eval(rec)
    }

    /// The filter compiled for scans ([`Matcher`]).
    pub fn matcher(&self) -> Matcher {
        Matcher {
            root: node(&self.expr),
        }
    }

    /// The APT message ids whose frames can match, worked out from the table before a scan:
    /// a term on a field (`apt.position > 1000`, `apt.chan == 1`) needs a message that has
    /// it, so a scan skips every other frame by its id without decoding it. `None` when every
    /// id can match. Says nothing about records other than APT frames.
    pub fn apt_ids(&self, table: &Table) -> Option<IdSet> {
        let mut set = IdSet(vec![0u64; 1024].into_boxed_slice());
        // Unknown ids have no fields: one answer for all of them.
        let unknown = self.expr.can_match(&|_| false);
        let mut all = unknown;
        for id in 0..=u16::MAX {
            let yes = match table.msg(id) {
                Some(_) => self.expr.can_match(&|name| table.may_have_field(id, name)),
                None => unknown,
            };
            all &= yes;
            if yes {
                set.0[usize::from(id >> 6)] |= 1 << (id & 63);
            }
        }
        (!all).then_some(set)
    }

    /// The filter as it was written.
    pub fn as_str(&self) -> &str {
        &self.text
    }

    /// The top-level record keys [`Filter::matches`] can read (sorted, without duplicates): a
    /// record reduced to these keys, each with its whole value, matches exactly when the full
    /// record does. Empty for the empty filter.
    pub fn record_keys(&self) -> Vec<&str> {
        let (mut keys, fallback) = self.record_keys_split();
        if !fallback.is_empty() {
            keys.push("fields");
            keys.sort_unstable();
            keys.dedup();
        }
        keys
    }

    /// [`Filter::record_keys`] in two parts (each sorted, without duplicates): the keys read
    /// directly, and the protocol-prefixed names that are looked up in `fields` only when the
    /// record has no such key. When a record has every key of the second list, `fields` is
    /// read only if the first list has it.
    pub fn record_keys_split(&self) -> (Vec<&str>, Vec<&str>) {
        let (mut keys, mut fallback) = (vec![], vec![]);
        self.expr.record_keys(&mut keys, &mut fallback);
        for v in [&mut keys, &mut fallback] {
            v.sort_unstable();
            v.dedup();
        }
        (keys, fallback)
    }
}

impl std::str::FromStr for Filter {
    type Err = FilterError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Filter::parse(s)
    }
}

impl fmt::Display for Filter {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}

/// A set of APT message ids (see [`Filter::apt_ids`]).
#[derive(Clone, Debug)]
pub struct IdSet(Box<[u64]>);

impl IdSet {
    /// Whether `id` is in the set.
    #[inline]
    pub fn contains(&self, id: u16) -> bool {
        self.0
            .get(usize::from(id >> 6))
            .is_some_and(|w| w & (1 << (id & 63)) != 0)
    }
}

// ---------------------------------------------------------------------------------------------
// The compiled form.

#[derive(Clone, Debug)]
enum Expr {
    All,
    Or(Vec<Expr>),
    And(Vec<Expr>),
    Not(Box<Expr>),
    Test(Test),
}

#[derive(Clone, Debug)]
enum Test {
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
enum CmpOp {
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
}

impl CmpOp {
    /// Whether the ordering of a value against the literal satisfies the comparison.
    fn holds(self, o: Ordering) -> bool {
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
enum Op {
    Cmp(CmpOp),
    Contains,
    Matches,
    In,
}

/// A field reference resolved, once, to a record key and the path below it.
#[derive(Clone, Debug)]
struct FieldRef {
    proto: Option<&'static str>,
    key: Key,
    rest: Vec<String>,
    /// `apt.X` where `X` is a record key and a field name too: `fields.X` (this path) is read
    /// when the record has no key `X`.
    fallback: Option<Vec<String>>,
    /// `ts`: `ts_ns` converted to seconds.
    ts_seconds: bool,
    /// Nanoseconds per unit of the field's value, for comparisons with durations.
    unit_ns: Option<f64>,
    /// `dir` / `msg_dir`: `host`, `tx`, `device`, `rx` … are read as `h2d` / `d2h`.
    dir_like: bool,
    /// Text compares with case (`cmd`).
    case_sensitive: bool,
}

#[derive(Clone, Debug)]
struct Lit {
    kind: LitKind,
    /// The value as written (strings: their content, unescaped).
    text: String,
}

#[derive(Clone, Copy, Debug)]
enum LitKind {
    Num(N),
    /// A duration, in nanoseconds.
    Dur(f64),
    Str,
    Word,
    Bool(bool),
}

impl Lit {
    fn numeric(&self) -> bool {
        matches!(self.kind, LitKind::Num(_) | LitKind::Dur(_))
    }
}

type N = Num;

fn num_cmp(a: N, b: N) -> Option<Ordering> {
    match (a, b) {
        (N::I(a), N::I(b)) => Some(a.cmp(&b)),
        _ => a.f().partial_cmp(&b.f()),
    }
}

fn num_text(n: N) -> String {
    match n {
        N::I(i) => i.to_string(),
        N::F(f) => f.to_string(),
    }
}

/// A value as a comparison sees it: an object stands for one of its members.
#[derive(Clone, Copy, Debug)]
enum Scalar<'a> {
    Num(N),
    Str(&'a str),
    Bool(bool),
}

fn truthy(v: &Val<'_>) -> bool {
    match v {
        Val::Num(_) => true,
        Val::Str(s) => !s.is_empty(),
        Val::Bool(b) => *b,
        Val::Obj(o) => o.nonempty,
    }
}

/// An object stands for one of its members: addresses by `name`/`addr`, sub-messages by
/// `name`/`id`, modules by `model`, diagnostics by `kind`, physical values by `value`.
fn coerce<'a>(v: &'a Val<'_>, numeric: bool) -> Option<Scalar<'a>> {
    match v {
        Val::Num(n) => Some(Scalar::Num(*n)),
        Val::Str(s) => Some(Scalar::Str(s)),
        Val::Bool(b) => Some(Scalar::Bool(*b)),
        Val::Obj(o) if numeric => o.num.map(Scalar::Num),
        Val::Obj(o) => o.text.as_deref().map(Scalar::Str),
    }
}

fn text_of_val<'a>(v: &'a Val<'_>) -> Option<Cow<'a, str>> {
    Some(match coerce(v, false)? {
        Scalar::Num(n) => Cow::Owned(num_text(n)),
        Scalar::Str(s) => Cow::Borrowed(s),
        Scalar::Bool(b) => Cow::Borrowed(if b { "true" } else { "false" }),
    })
}

fn proto_is<F: Fields + ?Sized>(rec: &F, p: Option<&str>) -> bool {
    match p {
        None => true,
        Some(p) => rec.proto() == Some(p),
    }
}

/// Does any value at `key`/`rest` satisfy `pred`?
fn any_at<F: Fields + ?Sized>(
    rec: &F,
    key: Key,
    rest: &[String],
    pred: &mut dyn FnMut(&Val<'_>, Role) -> bool,
) -> bool {
    let mut hit = false;
    rec.visit(key, rest, &mut |v, r| {
        if !hit && pred(&v, r) {
            hit = true;
        }
    });
    hit
}

impl Expr {
    /// The top-level keys [`Expr::eval`] reads (see [`Filter::record_keys`]).
    fn record_keys<'a>(&'a self, out: &mut Vec<&'a str>, fallback: &mut Vec<&'a str>) {
        let f = match self {
            Expr::All => return,
            Expr::Or(xs) | Expr::And(xs) => {
                return xs.iter().for_each(|x| x.record_keys(out, fallback))
            }
            Expr::Not(x) => return x.record_keys(out, fallback),
            Expr::Test(Test::Proto(_)) => return out.push("proto"),
            Expr::Test(Test::Diag(_)) => return out.extend(["proto", "diag", "type"]),
            Expr::Test(Test::Unpaired(_)) => return out.extend(["proto", "unpaired", "diag"]),
            Expr::Test(Test::Paired(_)) => return out.extend(["proto", "pair"]),
            Expr::Test(t) => match t.field() {
                Some(f) => f,
                None => return,
            },
        };
        if f.proto.is_some() {
            out.push("proto");
        }
        out.push(f.key.json_name());
        if f.key == Key::Fields && f.rest.len() == 1 {
            // `codes.X` is read beside `fields.X`.
            out.push("codes");
        }
        if let Some(p) = &f.fallback {
            fallback.push(p[0].as_str());
            if p.len() == 1 {
                fallback.push("codes");
            }
        }
    }

    /// Can an APT frame whose message has exactly the fields `has` accepts pass? (`false`
    /// only when it certainly cannot.)
    fn can_match(&self, has: &dyn Fn(&str) -> bool) -> bool {
        match self {
            Expr::All | Expr::Not(_) => true,
            Expr::Or(xs) => xs.iter().any(|x| x.can_match(has)),
            Expr::And(xs) => xs.iter().all(|x| x.can_match(has)),
            Expr::Test(t) => t.field().is_none_or(|f| f.can_have_value(has)),
        }
    }

    fn eval<F: Fields + ?Sized>(&self, rec: &F) -> bool {
        match self {
            Expr::All => true,
            Expr::Or(xs) => xs.iter().any(|x| x.eval(rec)),
            Expr::And(xs) => xs.iter().all(|x| x.eval(rec)),
            Expr::Not(x) => !x.eval(rec),
            // The commonest test, kept apart from the others: their code would make every
            // test pay for a large frame.
            Expr::Test(Test::Cmp(f, op, lit)) => Test::cmp(rec, f, *op, lit),
            Expr::Test(t) => t.eval(rec),
        }
    }
}

/// `diag.kind`, read by `unpaired`.
fn kind_path() -> &'static [String] {
    use std::sync::OnceLock;
    static P: OnceLock<Vec<String>> = OnceLock::new();
    P.get_or_init(|| vec!["kind".to_string()])
}

impl Test {
    /// A comparison. A record-level value the record has at hand ([`Fields::number`],
    /// [`Fields::word`]) is compared as [`FieldRef::compare`] would, the common literals
    /// without building values; anything else goes through the visitor.
    #[inline]
    fn cmp<F: Fields + ?Sized>(rec: &F, f: &FieldRef, op: CmpOp, lit: &Lit) -> bool {
        if f.ts_seconds || !f.rest.is_empty() || !proto_is(rec, f.proto) {
            return Self::eval_cmp(rec, f, op, lit);
        }
        let eq = matches!(op, CmpOp::Eq | CmpOp::Ne);
        let o = if let Some(x) = rec.number(f.key) {
            match lit.kind {
                LitKind::Num(N::I(l)) => Some(i128::from(x).cmp(&l)),
                _ => f.compare(&Val::Num(N::I(i128::from(x))), lit, eq),
            }
        } else if let Some(w) = rec.word(f.key) {
            match lit.kind {
                LitKind::Str | LitKind::Word => {
                    Some(text_cmp(w, &lit.text, eq && !f.case_sensitive))
                }
                _ => f.compare(&Val::Str(Cow::Borrowed(w)), lit, eq),
            }
        } else {
            return Self::eval_cmp(rec, f, op, lit);
        };
        o.is_some_and(|o| op.holds(o))
    }

    /// A comparison through the visitor: any value satisfies it (`!=`: some value compares
    /// and none is equal).
    #[inline(never)]
    fn eval_cmp<F: Fields + ?Sized>(rec: &F, f: &FieldRef, op: CmpOp, lit: &Lit) -> bool {
        match op {
            CmpOp::Ne => {
                let (mut comparable, mut equal) = (false, false);
                f.each(rec, &mut |v, _| match f.compare(&v, lit, true) {
                    Some(Ordering::Equal) => equal = true,
                    Some(_) => comparable = true,
                    None => {}
                });
                comparable && !equal
            }
            _ => f.any(rec, &mut |v, _| {
                f.compare(v, lit, op == CmpOp::Eq)
                    .is_some_and(|o| op.holds(o))
            }),
        }
    }

    /// The field a test on a field reads (every test but the record-level words).
    fn field(&self) -> Option<&FieldRef> {
        match self {
            Test::Exists(f)
            | Test::Cmp(f, ..)
            | Test::Contains(f, _)
            | Test::Matches(f, _)
            | Test::In(f, _) => Some(f),
            Test::Proto(_) | Test::Diag(_) | Test::Unpaired(_) | Test::Paired(_) => None,
        }
    }

    #[inline(never)]
    fn eval<F: Fields + ?Sized>(&self, rec: &F) -> bool {
        match self {
            Test::Proto(p) => proto_is(rec, Some(p)),
            Test::Diag(p) => {
                proto_is(rec, *p)
                    && (any_at(rec, Key::Diag, &[], &mut |_, _| true)
                        || any_at(
                            rec,
                            Key::Type,
                            &[],
                            &mut |v, _| matches!(v, Val::Str(s) if matches!(s.as_ref(), "input" | "diag" | "garbage")),
                        ))
            }
            Test::Unpaired(p) => {
                proto_is(rec, *p)
                    && (any_at(rec, Key::Unpaired, &[], &mut |v, _| {
                        matches!(v, Val::Bool(true))
                    }) || any_at(
                        rec,
                        Key::Diag,
                        kind_path(),
                        &mut |v, _| matches!(v, Val::Str(s) if matches!(s.as_ref(), "no_reply" | "unsolicited" | "unanswered")),
                    ))
            }
            Test::Paired(p) => proto_is(rec, *p) && any_at(rec, Key::Pair, &[], &mut |_, _| true),
            Test::Exists(f) => f.any(rec, &mut |v, r| r != Role::Code && truthy(v)),
            Test::Cmp(f, op, lit) => Self::cmp(rec, f, *op, lit),
            Test::Contains(f, lit) => f.any(rec, &mut |v, role| match role {
                Role::Member => f.compare(v, lit, true) == Some(Ordering::Equal),
                Role::Code => false,
                Role::Plain => match coerce(v, false) {
                    Some(Scalar::Str(s)) => {
                        if f.case_sensitive {
                            s.contains(lit.text.as_str())
                        } else {
                            s.to_ascii_lowercase()
                                .contains(&lit.text.to_ascii_lowercase())
                        }
                    }
                    _ => false,
                },
            }),
            Test::Matches(f, re) => f.any(rec, &mut |v, role| {
                role != Role::Code && text_of_val(v).is_some_and(|t| re.is_match(&t))
            }),
            Test::In(f, set) => f.any(rec, &mut |v, _| {
                set.iter()
                    .any(|lit| f.compare(v, lit, true) == Some(Ordering::Equal))
            }),
        }
    }
}

impl FieldRef {
    /// Can an APT frame whose message has the fields `has` accepts give this field a value?
    /// Every test on a field needs one.
    fn can_have_value(&self, has: &dyn Fn(&str) -> bool) -> bool {
        if self.proto.is_some_and(|p| p != "apt") {
            return false;
        }
        // A whole object (`apt.fields`) is there whatever the message.
        let named = |path: &[String]| path.first().is_none_or(|n| has(n));
        let direct = match self.key {
            Key::Fields | Key::Codes | Key::Phys if self.proto.is_some() => named(&self.rest),
            // The channel is read from `chan_ident`.
            Key::Channel => has("chan_ident"),
            _ => return true,
        };
        direct || self.fallback.as_deref().is_some_and(named)
    }

    /// Pass each value at this field to `g` (nothing when the record is of another protocol).
    fn each<F: Fields + ?Sized>(&self, rec: &F, g: &mut dyn FnMut(Val<'_>, Role)) {
        if !proto_is(rec, self.proto) {
            return;
        }
        if self.ts_seconds {
            rec.visit(Key::TsNs, &[], &mut |v, _| {
                if let Val::Num(n) = v {
                    g(Val::Num(N::F(n.f() / 1e9)), Role::Plain);
                }
            });
            return;
        }
        let present = rec.visit(self.key, &self.rest, g);
        if let (false, Some(p)) = (present, &self.fallback) {
            rec.visit(Key::Fields, p, g);
        }
    }

    /// Does any value at this field satisfy `pred`?
    fn any<F: Fields + ?Sized>(
        &self,
        rec: &F,
        pred: &mut dyn FnMut(&Val<'_>, Role) -> bool,
    ) -> bool {
        let mut hit = false;
        self.each(rec, &mut |v, r| {
            if !hit && pred(&v, r) {
                hit = true;
            }
        });
        hit
    }

    /// Compares one value with a literal; `None` when the types do not compare.
    /// `equality`: text ignores case (unless the field is case-sensitive).
    fn compare(&self, v: &Val<'_>, lit: &Lit, equality: bool) -> Option<Ordering> {
        let v = coerce(v, lit.numeric())?;
        let fold = equality && !self.case_sensitive;
        match (v, lit.kind) {
            (Scalar::Num(a), LitKind::Num(b)) => num_cmp(a, b),
            (Scalar::Num(a), LitKind::Dur(ns)) => {
                let unit = self.unit_ns?;
                a.f().partial_cmp(&(ns / unit))
            }
            (Scalar::Str(s), LitKind::Num(b)) => match parse_num(s) {
                Some(a) => num_cmp(a, b),
                None if equality => Some(text_cmp(s, &lit.text, fold)),
                None => None,
            },
            (Scalar::Str(s), LitKind::Str | LitKind::Word | LitKind::Bool(_)) => {
                Some(text_cmp(s, &lit.text, fold))
            }
            (Scalar::Bool(a), LitKind::Bool(b)) => Some(a.cmp(&b)),
            (Scalar::Bool(a), LitKind::Str | LitKind::Word) => {
                match lit.text.to_ascii_lowercase().as_str() {
                    "true" => Some(a.cmp(&true)),
                    "false" => Some(a.cmp(&false)),
                    _ => None,
                }
            }
            _ => None,
        }
    }
}

fn text_cmp(a: &str, b: &str, fold: bool) -> Ordering {
    if fold {
        a.bytes()
            .map(|c| c.to_ascii_lowercase())
            .cmp(b.bytes().map(|c| c.to_ascii_lowercase()))
    } else {
        a.cmp(b)
    }
}

fn parse_num(s: &str) -> Option<N> {
    if let Ok(i) = s.parse::<i128>() {
        return Some(N::I(i));
    }
    s.parse::<f64>().ok().filter(|f| f.is_finite()).map(N::F)
}

// ---------------------------------------------------------------------------------------------
// Field names: the keys come from [`crate::fields::KEYS`], the field names from the tables.

/// Names usable without a protocol prefix.
fn top_level() -> impl Iterator<Item = &'static str> + Clone {
    KEYS.iter().filter(|d| d.scope & TOP != 0).map(|d| d.name)
}

fn scope_of(proto: &str) -> u8 {
    if proto == "ell" {
        ELL
    } else {
        APT
    }
}

/// The field names a protocol's records can hold in `fields` (from the message tables, plus
/// the keys the NDJSON derives beside a field).
fn field_names(proto: &str) -> &'static [&'static str] {
    use std::sync::OnceLock;
    static APT: OnceLock<Vec<&'static str>> = OnceLock::new();
    static ELL: OnceLock<Vec<&'static str>> = OnceLock::new();
    let build = |v: Vec<&'static str>| {
        let mut v = v;
        v.sort_unstable();
        v.dedup();
        v
    };
    if proto == "ell" {
        ELL.get_or_init(|| {
            let mut v: Vec<&'static str> = vec![];
            for c in crate::ell::table::COMMANDS {
                for f in c.fields {
                    v.push(f.name);
                    match f.kind {
                        crate::ell::table::Kind::Model => {
                            v.push(Box::leak(format!("{}_name", f.name).into_boxed_str()))
                        }
                        crate::ell::table::Kind::Firmware => {
                            v.push(Box::leak(format!("{}_version", f.name).into_boxed_str()))
                        }
                        crate::ell::table::Kind::ThreadHw => v.extend(["thread", "hw_release"]),
                        crate::ell::table::Kind::Raw => v.push("curve_points"),
                        _ => {}
                    }
                }
            }
            build(v)
        })
    } else {
        APT.get_or_init(|| {
            let t = crate::Table::global();
            let forms = t
                .msgs()
                .iter()
                .flat_map(|m| m.forms.iter())
                .chain(t.subs().iter().flat_map(|s| s.forms.iter()));
            build(
                forms
                    .flat_map(|f| f.fields.iter().map(|x| x.name))
                    .collect(),
            )
        })
    }
}

/// Check that `rest` (the name after `apt.`/`ell.`) names something records of `proto` hold;
/// if not, say so with the nearest names.
fn check_name(proto: &str, rest: &[&str]) -> Result<(), String> {
    let scope = scope_of(proto);
    let keys = || {
        KEYS.iter()
            .filter(move |d| d.scope & scope != 0)
            .map(|d| d.name)
    };
    let fields = field_names(proto);
    let first = rest.first().copied().unwrap_or("");
    let (ok, bad, cands): (bool, &str, Vec<&str>) = match (first, rest.get(1)) {
        ("fields" | "phys" | "codes", Some(f)) => (fields.contains(f), f, fields.to_vec()),
        _ => (
            Key::lookup(first, scope).is_some() || fields.contains(&first),
            first,
            keys().chain(fields.iter().copied()).collect(),
        ),
    };
    if ok {
        return Ok(());
    }
    let near = crate::suggest::nearest(bad, cands, 4);
    let name = format!("{proto}.{}", rest.join("."));
    Err(if near.is_empty() {
        format!("unknown field `{name}`: no {proto} record has `{bad}`")
    } else {
        let prefix = match (first, rest.get(1)) {
            ("fields" | "phys" | "codes", Some(_)) => format!("{proto}.{first}."),
            _ => format!("{proto}."),
        };
        let list: Vec<String> = near.iter().map(|n| format!("`{prefix}{n}`")).collect();
        format!("unknown field `{name}`; did you mean {}?", list.join(", "))
    })
}

/// What a dotted name refers to.
enum Ref {
    Proto(&'static str),
    Field(FieldRef),
}

fn resolve(segs: &[&str]) -> Result<Ref, String> {
    let (proto, rest) = match segs.split_first() {
        Some((&"apt", rest)) => (Some("apt"), rest),
        Some((&("ell" | "elliptec"), rest)) => (Some("ell"), rest),
        _ => (None, segs),
    };
    let Some(first) = rest.first() else {
        return Ok(Ref::Proto(proto.unwrap_or("apt")));
    };
    let top = Key::lookup(first, TOP).filter(|_| proto.is_none());
    if proto.is_none() && top.is_none() {
        let name = segs.join(".");
        // Suggest only names that exist: a protocol field of that name, or a record key.
        let mut near: Vec<String> = vec![];
        for p in ["apt", "ell"] {
            if check_name(p, rest).is_ok() {
                near.push(format!("`{p}.{name}`"));
            }
        }
        let last = rest.last().copied().unwrap_or(first);
        for t in crate::suggest::nearest(last, top_level(), 3) {
            near.push(format!("`{t}`"));
        }
        return Err(if near.is_empty() {
            format!("unknown field `{name}`: protocol fields need a prefix (`apt.` or `ell.`)")
        } else {
            format!(
                "unknown field `{name}`: protocol fields need a prefix; did you mean {}?",
                near.join(", ")
            )
        });
    }
    let owned = |s: &[&str]| s.iter().map(|x| x.to_string()).collect::<Vec<String>>();
    let (key, path, fallback) = match proto {
        None => (top.map_or(Key::Fields, |d| d.key), owned(&rest[1..]), None),
        Some(p) => {
            check_name(p, rest)?;
            let is_field = field_names(p).contains(first);
            match Key::lookup(first, scope_of(p)) {
                Some(d) => (d.key, owned(&rest[1..]), is_field.then(|| owned(rest))),
                // A field name alone: `apt.position` is `apt.fields.position`.
                None => (Key::Fields, owned(rest), None),
            }
        }
    };
    let mut ts_seconds = false;
    let mut unit_ns = None;
    if rest.len() == 1 {
        match *first {
            "ts" => {
                ts_seconds = true;
                unit_ns = Some(1e9);
            }
            "ts_ns" => unit_ns = Some(1.0),
            "latency" | "latency_ms" => unit_ns = Some(1e6),
            _ => {}
        }
    }
    let last = rest.last().copied().unwrap_or("");
    Ok(Ref::Field(FieldRef {
        proto,
        key,
        rest: path,
        fallback,
        ts_seconds,
        unit_ns,
        dir_like: matches!(last, "dir" | "msg_dir"),
        case_sensitive: last == "cmd",
    }))
}

// ---------------------------------------------------------------------------------------------
// The parser (nom).

/// A parse error: where, and (for hard errors) what.
#[derive(Debug)]
struct PErr<'a> {
    at: &'a str,
    msg: Option<String>,
}

impl<'a> ParseError<&'a str> for PErr<'a> {
    fn from_error_kind(input: &'a str, _: ErrorKind) -> Self {
        PErr {
            at: input,
            msg: None,
        }
    }
    fn append(_: &'a str, _: ErrorKind, other: Self) -> Self {
        other
    }
}

type Res<'a, T> = IResult<&'a str, T, PErr<'a>>;

fn failure<'a, T>(at: &'a str, msg: impl Into<String>) -> Res<'a, T> {
    Err(NomErr::Failure(PErr {
        at,
        msg: Some(msg.into()),
    }))
}

fn soft<T>(at: &str) -> Res<'_, T> {
    Err(NomErr::Error(PErr { at, msg: None }))
}

fn column(src: &str, rest: &str) -> usize {
    let off = src.len().saturating_sub(rest.len());
    src.get(..off).map_or(1, |p| p.chars().count() + 1)
}

fn skip_ws(i: &str) -> &str {
    i.trim_start()
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// The token at `i`, for messages.
fn token(i: &str) -> String {
    let word: String = i
        .chars()
        .take_while(|c| is_ident(*c) || *c == '.')
        .collect();
    if !word.is_empty() {
        return word;
    }
    let punct: String = i
        .chars()
        .take_while(|c| !c.is_whitespace() && !is_ident(*c) && *c != '"' && *c != '(')
        .collect();
    if punct.is_empty() {
        i.chars().take(1).collect()
    } else {
        punct
    }
}

/// The message for input left after a complete expression.
fn unexpected(rest: &str) -> String {
    if rest.starts_with(')') {
        "unbalanced parentheses: `)` without a matching `(`".to_string()
    } else if rest.starts_with('&') || rest.starts_with('|') {
        let t: String = rest.chars().take(1).collect();
        format!("unknown operator `{t}` (use `{t}{t}`)")
    } else {
        format!(
            "unexpected `{}`: expected `&&`, `||` or the end of the filter",
            token(rest)
        )
    }
}

/// A keyword: `kw` not followed by a name character.
fn keyword<'a>(kw: &'static str) -> impl FnMut(&'a str) -> Res<'a, &'a str> {
    move |i: &'a str| {
        let (rest, m) = tag(kw)(i)?;
        if rest.starts_with(is_ident) {
            soft(i)
        } else {
            Ok((rest, m))
        }
    }
}

/// Runs a sub-parser that must find a test, after `what` (`&&`, `!`, `(` …).
fn need<'a, T>(r: Res<'a, T>, at: &'a str, what: &str) -> Res<'a, T> {
    match r {
        Err(NomErr::Error(_)) => failure(skip_ws(at), format!("expected a test after `{what}`")),
        r => r,
    }
}

fn expr_or(i: &str, depth: usize) -> Res<'_, Expr> {
    let (mut i, first) = expr_and(i, depth)?;
    let mut xs = vec![first];
    loop {
        let (j, _) = multispace0(i)?;
        match alt((tag("||"), keyword("or")))(j) {
            Ok((k, op)) => {
                let (k, x) = need(expr_and(k, depth), k, op)?;
                xs.push(x);
                i = k;
            }
            Err(NomErr::Error(_)) => break,
            Err(e) => return Err(e),
        }
    }
    Ok((
        i,
        if xs.len() == 1 {
            xs.remove(0)
        } else {
            Expr::Or(xs)
        },
    ))
}

fn expr_and(i: &str, depth: usize) -> Res<'_, Expr> {
    let (mut i, first) = expr_not(i, depth)?;
    let mut xs = vec![first];
    loop {
        let (j, _) = multispace0(i)?;
        match alt((tag("&&"), keyword("and")))(j) {
            Ok((k, op)) => {
                let (k, x) = need(expr_not(k, depth), k, op)?;
                xs.push(x);
                i = k;
            }
            Err(NomErr::Error(_)) => break,
            Err(e) => return Err(e),
        }
    }
    Ok((
        i,
        if xs.len() == 1 {
            xs.remove(0)
        } else {
            Expr::And(xs)
        },
    ))
}

fn expr_not(i: &str, depth: usize) -> Res<'_, Expr> {
    let (i, _) = multispace0(i)?;
    if depth >= MAX_DEPTH {
        return failure(
            i,
            format!("filter nested too deeply (over {MAX_DEPTH} levels)"),
        );
    }
    if let Ok((j, op)) = alt((tag::<_, _, PErr>("!"), keyword("not")))(i) {
        let (j, x) = need(expr_not(j, depth + 1), j, op)?;
        return Ok((j, Expr::Not(Box::new(x))));
    }
    if let Ok((j, _)) = nchar::<_, PErr>('(')(i) {
        let (j, x) = need(expr_or(j, depth + 1), j, "(")?;
        let (j, _) = multispace0(j)?;
        return match nchar::<_, PErr>(')')(j) {
            Ok((k, _)) => Ok((k, x)),
            Err(_) if j.is_empty() => {
                failure(i, "unbalanced parentheses: this `(` is never closed")
            }
            Err(_) => failure(
                j,
                format!("expected `)`, `&&` or `||`, found `{}`", token(j)),
            ),
        };
    }
    test(i)
}

fn ident(i: &str) -> Res<'_, &str> {
    recognize(pair(
        take_while1(|c: char| c.is_ascii_alphabetic() || c == '_'),
        take_while(is_ident),
    ))(i)
}

fn field_path(i: &str) -> Res<'_, Vec<&str>> {
    let (mut i, first) = ident(i)?;
    if matches!(first, "and" | "or" | "not" | "in" | "contains" | "matches") {
        return soft(i);
    }
    let mut segs = vec![first];
    while let Ok((j, _)) = nchar::<_, PErr>('.')(i) {
        match take_while1::<_, _, PErr>(is_ident)(j) {
            Ok((k, s)) => {
                segs.push(s);
                i = k;
            }
            Err(_) => return failure(j, "expected a field name after `.`"),
        }
    }
    Ok((i, segs))
}

fn sym<'a>(t: &'static str, op: Op) -> impl FnMut(&'a str) -> Res<'a, (Op, &'a str)> {
    map(tag(t), move |s| (op, s))
}

fn word_op<'a>(t: &'static str, op: Op) -> impl FnMut(&'a str) -> Res<'a, (Op, &'a str)> {
    map(keyword(t), move |s| (op, s))
}

fn operator(i: &str) -> Res<'_, (Op, &str)> {
    use CmpOp::*;
    alt((
        alt((
            sym("==", Op::Cmp(Eq)),
            sym("!=", Op::Cmp(Ne)),
            sym("<=", Op::Cmp(Le)),
            sym(">=", Op::Cmp(Ge)),
            sym("<", Op::Cmp(Lt)),
            sym(">", Op::Cmp(Gt)),
            sym("~", Op::Matches),
        )),
        alt((
            word_op("contains", Op::Contains),
            word_op("matches", Op::Matches),
            word_op("in", Op::In),
            word_op("eq", Op::Cmp(Eq)),
            word_op("ne", Op::Cmp(Ne)),
            word_op("lt", Op::Cmp(Lt)),
            word_op("le", Op::Cmp(Le)),
            word_op("gt", Op::Cmp(Gt)),
            word_op("ge", Op::Cmp(Ge)),
        )),
    ))(i)
}

/// Where a bare field reference may end.
fn at_boundary(i: &str) -> bool {
    i.is_empty()
        || i.starts_with(')')
        || i.starts_with("&&")
        || i.starts_with("||")
        || keyword("and")(i).is_ok()
        || keyword("or")(i).is_ok()
}

fn test(i: &str) -> Res<'_, Expr> {
    let start = i;
    let (i, segs) = field_path(i)?;
    let field = match resolve(&segs) {
        Ok(r) => r,
        Err(msg) => return failure(start, msg),
    };
    let (j, _) = multispace0(i)?;
    let (k, (op, op_text)) = match operator(j) {
        Ok(r) => r,
        Err(NomErr::Error(_)) => {
            if at_boundary(j) {
                return Ok((i, Expr::Test(bare(field))));
            }
            if token(j) == "=" {
                return failure(j, "unknown operator `=` (did you mean `==`?)");
            }
            return failure(
                j,
                format!(
                    "unknown operator `{}` (use ==, !=, <, <=, >, >=, contains, ~, matches or in)",
                    token(j)
                ),
            );
        }
        Err(e) => return Err(e),
    };
    let f = match field {
        Ref::Field(f) => f,
        Ref::Proto(p) => {
            return failure(
                start,
                format!("`{p}` is a protocol; compare one of its fields, e.g. `{p}.name`"),
            )
        }
    };
    match op {
        Op::In => {
            let (k, set) = set(k)?;
            let set = set.into_iter().map(|l| normalize(&f, l)).collect();
            Ok((k, Expr::Test(Test::In(f, set))))
        }
        Op::Matches => {
            let at = skip_ws(k);
            let (k, lit) = value(k, op_text)?;
            // Case-insensitive like Wireshark's `matches` and like `==` here (`(?-i)` turns
            // that off), except where case carries meaning (`cmd`).
            let built = RegexBuilder::new(&lit.text)
                .case_insensitive(!f.case_sensitive)
                .build();
            match built {
                Ok(re) => Ok((k, Expr::Test(Test::Matches(f, re)))),
                Err(e) => failure(at, format!("invalid regular expression: {}", regex_msg(&e))),
            }
        }
        Op::Contains => {
            let (k, lit) = value(k, op_text)?;
            Ok((k, Expr::Test(Test::Contains(f, lit))))
        }
        Op::Cmp(c) => {
            let (k, lit) = value(k, op_text)?;
            let lit = normalize(&f, lit);
            Ok((k, Expr::Test(Test::Cmp(f, c, lit))))
        }
    }
}

fn regex_msg(e: &regex::Error) -> String {
    match e {
        regex::Error::Syntax(s) => s
            .lines()
            .rev()
            .find(|l| !l.trim().is_empty())
            .map(|l| l.trim().trim_start_matches("error: ").to_string())
            .unwrap_or_else(|| s.clone()),
        other => other.to_string(),
    }
}

fn bare(r: Ref) -> Test {
    match r {
        Ref::Proto(p) => Test::Proto(p),
        Ref::Field(f) if f.rest.is_empty() && !f.ts_seconds => match f.key {
            Key::Diag => Test::Diag(f.proto),
            Key::Unpaired => Test::Unpaired(f.proto),
            Key::Paired => Test::Paired(f.proto),
            _ => Test::Exists(f),
        },
        Ref::Field(f) => Test::Exists(f),
    }
}

/// Direction synonyms for `dir` / `msg_dir`.
fn normalize(f: &FieldRef, mut lit: Lit) -> Lit {
    if f.dir_like && matches!(lit.kind, LitKind::Str | LitKind::Word) {
        match lit.text.to_ascii_lowercase().as_str() {
            "host" | "h2d" | "tx" => lit.text = "h2d".to_string(),
            "device" | "d2h" | "rx" => lit.text = "d2h".to_string(),
            _ => {}
        }
    }
    lit
}

fn value<'a>(i: &'a str, after: &str) -> Res<'a, Lit> {
    let (i, _) = multispace0(i)?;
    match alt((string_lit, number_lit, word_lit))(i) {
        Err(NomErr::Error(_)) => failure(i, format!("expected a value after `{after}`")),
        r => r,
    }
}

fn set(i: &str) -> Res<'_, Vec<Lit>> {
    let (i, _) = multispace0(i)?;
    let brace = i;
    let Ok((mut i, _)) = nchar::<_, PErr>('{')(i) else {
        return failure(i, "expected `{` after `in`");
    };
    let mut out = Vec::new();
    loop {
        let (j, _) = take_while(|c: char| c.is_whitespace() || c == ',')(i)?;
        if let Ok((k, _)) = nchar::<_, PErr>('}')(j) {
            return Ok((k, out));
        }
        if j.is_empty() {
            return failure(brace, "unbalanced braces: this `{` is never closed");
        }
        match alt((string_lit, number_lit, word_lit))(j) {
            Ok((k, lit)) => {
                out.push(lit);
                i = k;
            }
            Err(NomErr::Error(_)) => {
                return failure(j, format!("expected a value or `}}`, found `{}`", token(j)))
            }
            Err(e) => return Err(e),
        }
    }
}

fn string_lit(i: &str) -> Res<'_, Lit> {
    let (body, _) = nchar('"')(i)?;
    let mut out = String::new();
    let mut chars = body.char_indices();
    while let Some((at, c)) = chars.next() {
        match c {
            '"' => {
                let rest = body.get(at + 1..).unwrap_or("");
                return Ok((
                    rest,
                    Lit {
                        kind: LitKind::Str,
                        text: out,
                    },
                ));
            }
            '\\' => match chars.next() {
                Some((_, '"')) => out.push('"'),
                Some((_, '\\')) => out.push('\\'),
                Some((_, 'n')) => out.push('\n'),
                Some((_, 't')) => out.push('\t'),
                Some((_, 'r')) => out.push('\r'),
                // Anything else stays as written, so regexes read naturally: "\d+".
                Some((_, other)) => {
                    out.push('\\');
                    out.push(other);
                }
                None => break,
            },
            c => out.push(c),
        }
    }
    failure(i, "unterminated string: missing closing `\"`")
}

/// Nanoseconds per duration unit.
fn unit_ns(u: &str) -> Option<f64> {
    Some(match u {
        "ns" => 1.0,
        "us" | "µs" => 1e3,
        "ms" => 1e6,
        "s" => 1e9,
        "min" => 60e9,
        "h" => 3600e9,
        _ => return None,
    })
}

fn number_lit(i: &str) -> Res<'_, Lit> {
    let start = i;
    let (j, neg) = opt(nchar('-'))(i)?;
    let sign: i128 = if neg.is_some() { -1 } else { 1 };
    let (rest, n, hex) = if let Ok((k, _)) = tag_no_case::<_, _, PErr>("0x")(j) {
        let Ok((k, digits)) = hex_digit1::<_, PErr>(k) else {
            return failure(k, "expected hex digits after `0x`");
        };
        match i128::from_str_radix(digits, 16) {
            Ok(v) => (k, N::I(sign * v), true),
            Err(_) => return failure(start, "number out of range"),
        }
    } else {
        let (k, txt) = recognize(pair(digit1, opt(pair(nchar('.'), digit1))))(j)?;
        let n = if txt.contains('.') {
            match txt.parse::<f64>() {
                Ok(v) => N::F(sign as f64 * v),
                Err(_) => return failure(start, "bad number"),
            }
        } else {
            match txt.parse::<i128>() {
                Ok(v) => N::I(sign * v),
                Err(_) => return failure(start, "number out of range"),
            }
        };
        (k, n, false)
    };
    let (after, unit) = take_while(|c: char| c.is_alphanumeric() || c == '_')(rest)?;
    let text = start
        .get(..start.len() - after.len())
        .unwrap_or_default()
        .to_string();
    if unit.is_empty() {
        return Ok((
            after,
            Lit {
                kind: LitKind::Num(n),
                text,
            },
        ));
    }
    if hex {
        return failure(start, format!("bad hex number `{text}`"));
    }
    match unit_ns(unit) {
        Some(u) => Ok((
            after,
            Lit {
                kind: LitKind::Dur(n.f() * u),
                text,
            },
        )),
        None => failure(
            rest,
            format!("unknown duration unit `{unit}` (use ns, us, ms, s, min or h)"),
        ),
    }
}

fn word_lit(i: &str) -> Res<'_, Lit> {
    let (rest, w) = recognize(pair(
        take_while1(|c: char| c.is_ascii_alphabetic() || c == '_'),
        take_while(|c: char| is_ident(c) || c == '.'),
    ))(i)?;
    let kind = match w {
        "and" | "or" | "not" => return soft(i),
        "true" => LitKind::Bool(true),
        "false" => LitKind::Bool(false),
        _ => LitKind::Word,
    };
    Ok((
        rest,
        Lit {
            kind,
            text: w.to_string(),
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::{json, Value};

    /// `aptscope decode --json samples/kdc101-session.pcapng`
    const KDC101: &str = r##"{"type":"stream","stream":0,"stream_name":"/dev/ttyUSB0","settings":"115200 8N1 RTS/CTS"}
{"type":"detect","proto":"apt","certain":true,"apt":1.000,"ell":0.000}
{"n":1,"proto":"apt","type":"frame","offset":0,"len":6,"raw":"050000005001","msgid":5,"msgid_hex":"0x0005","name":"HW_REQ_INFO","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":false,"data_len":0,"fields":{},"diag":[],"dir":"h2d","ts_ns":1764000000050000000,"stream":0}
{"n":2,"proto":"apt","type":"frame","offset":0,"len":90,"raw":"0600540081503bfd9b014b444331303100002c000b000300000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000010000000100","msgid":6,"msgid_hex":"0x0006","name":"HW_GET_INFO","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":84,"fields":{"serial_number":27000123,"model_number":"KDC101","hw_type":"BRUSHLESS_DC_CONTROLLER","fw_minor":11,"fw_interim":0,"fw_major":3,"internal":"000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000","hw_version":1,"mod_state":0,"nchs":1},"pair":1,"latency_ms":2,"diag":[],"dir":"d2h","ts_ns":1764000000052000000,"stream":0}
{"n":3,"proto":"apt","type":"frame","offset":6,"len":6,"raw":"100201015001","msgid":528,"msgid_hex":"0x0210","name":"MOD_SET_CHANENABLESTATE","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":false,"data_len":0,"channel":1,"fields":{"chan_ident":"CH1","enable_state":"ENABLE"},"diag":[],"dir":"h2d","ts_ns":1764000000102000000,"stream":0}
{"n":4,"proto":"apt","type":"frame","offset":12,"len":6,"raw":"110201005001","msgid":529,"msgid_hex":"0x0211","name":"MOD_REQ_CHANENABLESTATE","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":false,"data_len":0,"channel":1,"fields":{"chan_ident":"CH1"},"diag":[],"dir":"h2d","ts_ns":1764000000152000000,"stream":0}
{"n":5,"proto":"apt","type":"frame","offset":90,"len":6,"raw":"120201010150","msgid":530,"msgid_hex":"0x0212","name":"MOD_GET_CHANENABLESTATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":false,"data_len":0,"channel":1,"fields":{"chan_ident":"CH1","enable_state":"ENABLE"},"pair":4,"latency_ms":2,"diag":[],"dir":"d2h","ts_ns":1764000000154000000,"stream":0}
{"n":6,"proto":"apt","type":"frame","offset":18,"len":6,"raw":"110000005001","msgid":17,"msgid_hex":"0x0011","name":"HW_START_UPDATEMSGS","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":false,"data_len":0,"fields":{},"diag":[],"dir":"h2d","ts_ns":1764000000204000000,"stream":0}
{"n":7,"proto":"apt","type":"frame","offset":24,"len":6,"raw":"430401005001","msgid":1091,"msgid_hex":"0x0443","name":"MOT_MOVE_HOME","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":false,"data_len":0,"channel":1,"fields":{"chan_ident":"CH1"},"diag":[],"dir":"h2d","ts_ns":1764000000254000000,"stream":0}
{"n":8,"proto":"apt","type":"frame","offset":96,"len":20,"raw":"91040e0081500100000000007800000020030080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":0,"velocity":120,"status_bits":["MOVING_CCW","MOTOR_CONNECTED","HOMING","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000000354000000,"stream":0}
{"n":9,"proto":"apt","type":"frame","offset":116,"len":20,"raw":"91040e008150010050fbffff7800000020030080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":-1200,"velocity":120,"status_bits":["MOVING_CCW","MOTOR_CONNECTED","HOMING","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000000454000000,"stream":0}
{"n":10,"proto":"apt","type":"frame","offset":136,"len":20,"raw":"91040e0081500100e8eaffff7800000020030080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":-5400,"velocity":120,"status_bits":["MOVING_CCW","MOTOR_CONNECTED","HOMING","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000000554000000,"stream":0}
{"n":11,"proto":"apt","type":"frame","offset":156,"len":20,"raw":"91040e0081500100b8d9ffff7800000020030080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":-9800,"velocity":120,"status_bits":["MOVING_CCW","MOTOR_CONNECTED","HOMING","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000000654000000,"stream":0}
{"n":12,"proto":"apt","type":"frame","offset":176,"len":6,"raw":"440401000150","msgid":1092,"msgid_hex":"0x0444","name":"MOT_MOVE_HOMED","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":false,"data_len":0,"channel":1,"fields":{"chan_ident":"CH1"},"pair":7,"latency_ms":2000,"diag":[],"dir":"d2h","ts_ns":1764000002254000000,"stream":0}
{"n":13,"proto":"apt","type":"frame","offset":30,"len":12,"raw":"53040600d0010100009e0200","msgid":1107,"msgid_hex":"0x0453","name":"MOT_MOVE_ABSOLUTE","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":true,"data_len":6,"form_note":"long version: position in the data packet","channel":1,"fields":{"chan_ident":"CH1","absolute_position":171520},"diag":[],"dir":"h2d","ts_ns":1764000002304000000,"stream":0}
{"n":14,"proto":"apt","type":"frame","offset":182,"len":20,"raw":"91040e0081500100005000002c01000010050080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":20480,"velocity":300,"status_bits":["MOVING_CW","MOTOR_CONNECTED","HOMED","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000002404000000,"stream":0}
{"n":15,"proto":"apt","type":"frame","offset":202,"len":20,"raw":"91040e0081500100000c01002c01000010050080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":68608,"velocity":300,"status_bits":["MOVING_CW","MOTOR_CONNECTED","HOMED","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000002504000000,"stream":0}
{"n":16,"proto":"apt","type":"frame","offset":222,"len":20,"raw":"91040e008150010000dc01002c01000010050080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":121856,"velocity":300,"status_bits":["MOVING_CW","MOTOR_CONNECTED","HOMED","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000002604000000,"stream":0}
{"n":17,"proto":"apt","type":"frame","offset":242,"len":20,"raw":"91040e0081500100008602002c01000010050080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":165376,"velocity":300,"status_bits":["MOVING_CW","MOTOR_CONNECTED","HOMED","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000002704000000,"stream":0}
{"n":18,"proto":"apt","type":"frame","offset":262,"len":20,"raw":"91040e0081500100009e02002c01000010050080","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1","position":171520,"velocity":300,"status_bits":["MOVING_CW","MOTOR_CONNECTED","HOMED","ENABLED"]},"diag":[],"dir":"d2h","ts_ns":1764000002804000000,"stream":0}
{"n":19,"proto":"apt","type":"frame","offset":282,"len":20,"raw":"64040e0081500100009e02000000000000250080","msgid":1124,"msgid_hex":"0x0464","name":"MOT_MOVE_COMPLETED","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"form_note":"with status (MOTDCSTATUS structure)","channel":1,"fields":{"chan_ident":"CH1","position":171520,"velocity":0,"status_bits":["MOTOR_CONNECTED","HOMED","SETTLED","ENABLED"]},"pair":13,"latency_ms":502,"diag":[],"dir":"d2h","ts_ns":1764000002806000000,"stream":0}
{"n":20,"proto":"apt","type":"frame","offset":42,"len":6,"raw":"120000005001","msgid":18,"msgid_hex":"0x0012","name":"HW_STOP_UPDATEMSGS","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":false,"data_len":0,"fields":{},"diag":[],"dir":"h2d","ts_ns":1764000002856000000,"stream":0}
"##;

    /// `aptscope decode --json samples/elliptec-bus.txt`
    const ELL_BUS: &str = r##"{"type":"detect","proto":"ell","certain":true,"apt":0.000,"ell":1.000}
{"n":1,"proto":"ell","type":"frame","offset":0,"len":3,"raw":"30696e","text":"0in","addr":"0","dir":"h2d","cmd":"in","name":"REQ_INFORMATION","fields":{},"diag":[],"stream":0}
{"n":2,"proto":"ell","type":"frame","offset":3,"len":35,"raw":"30494e3045313134303032383432303230303131373031363830303032333030300d0a","text":"0IN0E1140028420200117016800023000\r\n","addr":"0","dir":"d2h","cmd":"IN","name":"GET_INFORMATION","fields":{"model":14,"serial":"11400284","year":"2020","firmware":1,"thread_hw":23,"thread":"metric","hw_release":23,"travel":360,"pulses_per_unit":143360},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"pair":1,"diag":[],"stream":0}
{"n":3,"proto":"ell","type":"frame","offset":38,"len":3,"raw":"31696e","text":"1in","addr":"1","dir":"h2d","cmd":"in","name":"REQ_INFORMATION","fields":{},"diag":[],"stream":0}
{"n":4,"proto":"ell","type":"frame","offset":41,"len":35,"raw":"31494e3039313133303031323332303233313530313030313330303030303032300d0a","text":"1IN091130012320231501001300000020\r\n","addr":"1","dir":"d2h","cmd":"IN","name":"GET_INFORMATION","fields":{"model":9,"serial":"11300123","year":"2023","firmware":21,"thread_hw":1,"thread":"metric","hw_release":1,"travel":19,"pulses_per_unit":32},"module":{"first_addr":1,"model":"ELL9","serial":"11300123"},"pair":3,"diag":[],"stream":0}
{"n":5,"proto":"ell","type":"frame","offset":76,"len":3,"raw":"32696e","text":"2in","addr":"2","dir":"h2d","cmd":"in","name":"REQ_INFORMATION","fields":{},"diag":[],"stream":0}
{"n":6,"proto":"ell","type":"frame","offset":79,"len":35,"raw":"32494e3131313137303034353632303232313730313030314330303030303830300d0a","text":"2IN111170045620221701001C00000800\r\n","addr":"2","dir":"d2h","cmd":"IN","name":"GET_INFORMATION","fields":{"model":17,"serial":"11700456","year":"2022","firmware":23,"thread_hw":1,"thread":"metric","hw_release":1,"travel":28,"pulses_per_unit":2048},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"pair":5,"diag":[],"stream":0}
{"n":7,"proto":"ell","type":"frame","offset":114,"len":3,"raw":"306773","text":"0gs","addr":"0","dir":"h2d","cmd":"gs","name":"REQ_STATUS","fields":{},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"diag":[],"stream":0}
{"n":8,"proto":"ell","type":"frame","offset":117,"len":7,"raw":"30475330300d0a","text":"0GS00\r\n","addr":"0","dir":"d2h","cmd":"GS","name":"GET_STATUS","fields":{"status":"OK"},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"pair":7,"diag":[],"stream":0}
{"n":9,"proto":"ell","type":"frame","offset":124,"len":4,"raw":"30686f30","text":"0ho0","addr":"0","dir":"h2d","cmd":"ho","name":"HOME","fields":{"direction":0},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"diag":[],"stream":0}
{"n":10,"proto":"ell","type":"frame","offset":128,"len":7,"raw":"30475330390d0a","text":"0GS09\r\n","addr":"0","dir":"d2h","cmd":"GS","name":"GET_STATUS","fields":{"status":"BUSY"},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"pair":9,"interim":true,"diag":[],"stream":0}
{"n":11,"proto":"ell","type":"frame","offset":135,"len":13,"raw":"30504f30303030303030300d0a","text":"0PO00000000\r\n","addr":"0","dir":"d2h","cmd":"PO","name":"POSITION","fields":{"position":0},"phys":{"position":{"value":0,"unit":"deg"}},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"pair":9,"diag":[],"stream":0}
{"n":12,"proto":"ell","type":"frame","offset":148,"len":11,"raw":"306d613030303038433030","text":"0ma00008C00","addr":"0","dir":"h2d","cmd":"ma","name":"MOVE_ABSOLUTE","fields":{"position":35840},"phys":{"position":{"value":90,"unit":"deg"}},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"diag":[],"stream":0}
{"n":13,"proto":"ell","type":"frame","offset":159,"len":7,"raw":"30475330390d0a","text":"0GS09\r\n","addr":"0","dir":"d2h","cmd":"GS","name":"GET_STATUS","fields":{"status":"BUSY"},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"pair":12,"interim":true,"diag":[],"stream":0}
{"n":14,"proto":"ell","type":"frame","offset":166,"len":13,"raw":"30504f30303030384330300d0a","text":"0PO00008C00\r\n","addr":"0","dir":"d2h","cmd":"PO","name":"POSITION","fields":{"position":35840},"phys":{"position":{"value":90,"unit":"deg"}},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"pair":12,"diag":[],"stream":0}
{"n":15,"proto":"ell","type":"frame","offset":179,"len":3,"raw":"316677","text":"1fw","addr":"1","dir":"h2d","cmd":"fw","name":"FORWARD","fields":{},"module":{"first_addr":1,"model":"ELL9","serial":"11300123"},"diag":[],"stream":0}
{"n":16,"proto":"ell","type":"frame","offset":182,"len":13,"raw":"31504f30303030303032300d0a","text":"1PO00000020\r\n","addr":"1","dir":"d2h","cmd":"PO","name":"POSITION","fields":{"position":32},"module":{"first_addr":1,"model":"ELL9","serial":"11300123"},"pair":15,"diag":[],"stream":0}
{"n":17,"proto":"ell","type":"frame","offset":195,"len":11,"raw":"326d613030303032303030","text":"2ma00002000","addr":"2","dir":"h2d","cmd":"ma","name":"MOVE_ABSOLUTE","fields":{"position":8192},"phys":{"position":{"value":4,"unit":"mm"}},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"diag":[],"stream":0}
{"n":18,"proto":"ell","type":"frame","offset":206,"len":13,"raw":"32504f30303030323030300d0a","text":"2PO00002000\r\n","addr":"2","dir":"d2h","cmd":"PO","name":"POSITION","fields":{"position":8192},"phys":{"position":{"value":4,"unit":"mm"}},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"pair":17,"diag":[],"stream":0}
{"n":19,"proto":"ell","type":"frame","offset":219,"len":11,"raw":"326d723030303031303030","text":"2mr00001000","addr":"2","dir":"h2d","cmd":"mr","name":"MOVE_RELATIVE","fields":{"position":4096},"phys":{"position":{"value":2,"unit":"mm"}},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"diag":[],"stream":0}
{"n":20,"proto":"ell","type":"frame","offset":230,"len":13,"raw":"32504f30303030333030300d0a","text":"2PO00003000\r\n","addr":"2","dir":"d2h","cmd":"PO","name":"POSITION","fields":{"position":12288},"phys":{"position":{"value":6,"unit":"mm"}},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"pair":19,"diag":[],"stream":0}
{"n":21,"proto":"ell","type":"frame","offset":243,"len":4,"raw":"32636135","text":"2ca5","addr":"2","dir":"h2d","cmd":"ca","name":"CHANGE_ADDRESS","fields":{"new_address":"5"},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"diag":[],"stream":0}
{"n":22,"proto":"ell","type":"frame","offset":247,"len":7,"raw":"35475330300d0a","text":"5GS00\r\n","addr":"5","dir":"d2h","cmd":"GS","name":"GET_STATUS","fields":{"status":"OK"},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"pair":21,"diag":[],"stream":0}
{"n":23,"proto":"ell","type":"frame","offset":254,"len":3,"raw":"356770","text":"5gp","addr":"5","dir":"h2d","cmd":"gp","name":"GET_POSITION","fields":{},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"diag":[],"stream":0}
{"n":24,"proto":"ell","type":"frame","offset":257,"len":13,"raw":"35504f30303030333030300d0a","text":"5PO00003000\r\n","addr":"5","dir":"d2h","cmd":"PO","name":"POSITION","fields":{"position":12288},"phys":{"position":{"value":6,"unit":"mm"}},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"pair":23,"diag":[],"stream":0}
{"n":25,"proto":"ell","type":"frame","offset":270,"len":11,"raw":"356d613030303046303030","text":"5ma0000F000","addr":"5","dir":"h2d","cmd":"ma","name":"MOVE_ABSOLUTE","fields":{"position":61440},"phys":{"position":{"value":30,"unit":"mm"}},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"diag":[],"stream":0}
{"n":26,"proto":"ell","type":"frame","offset":281,"len":7,"raw":"35475330430d0a","text":"5GS0C\r\n","addr":"5","dir":"d2h","cmd":"GS","name":"GET_STATUS","fields":{"status":"OUT_OF_RANGE"},"module":{"first_addr":2,"model":"ELL17","serial":"11700456"},"pair":25,"diag":[],"stream":0}
{"n":27,"proto":"ell","type":"frame","offset":288,"len":3,"raw":"306776","text":"0gv","addr":"0","dir":"h2d","cmd":"gv","name":"REQ_VELOCITY","fields":{},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"diag":[],"stream":0}
{"n":28,"proto":"ell","type":"frame","offset":291,"len":7,"raw":"30475636340d0a","text":"0GV64\r\n","addr":"0","dir":"d2h","cmd":"GV","name":"GET_VELOCITY","fields":{"velocity":100},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"pair":27,"diag":[],"stream":0}
{"n":29,"proto":"ell","type":"frame","offset":298,"len":5,"raw":"3073763332","text":"0sv32","addr":"0","dir":"h2d","cmd":"sv","name":"SET_VELOCITY","fields":{"velocity":50},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"diag":[],"stream":0}
{"n":30,"proto":"ell","type":"frame","offset":303,"len":7,"raw":"30475330300d0a","text":"0GS00\r\n","addr":"0","dir":"d2h","cmd":"GS","name":"GET_STATUS","fields":{"status":"OK"},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"pair":29,"diag":[],"stream":0}
{"n":31,"proto":"ell","type":"frame","offset":310,"len":7,"raw":"30425330390d0a","text":"0BS09\r\n","addr":"0","dir":"d2h","cmd":"BS","name":"BUTTON_STATUS","fields":{"status":"BUSY"},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"diag":[],"stream":0}
{"n":32,"proto":"ell","type":"frame","offset":317,"len":13,"raw":"30424f30303030343630300d0a","text":"0BO00004600\r\n","addr":"0","dir":"d2h","cmd":"BO","name":"BUTTON_POSITION","fields":{"position":17920},"phys":{"position":{"value":45,"unit":"deg"}},"module":{"first_addr":0,"model":"ELL14","serial":"11400284"},"diag":[],"stream":0}
{"n":33,"proto":"ell","type":"frame","offset":330,"len":4,"raw":"31676130","text":"1ga0","addr":"1","dir":"h2d","cmd":"ga","name":"GROUP_ADDRESS","fields":{"new_address":"0"},"module":{"first_addr":1,"model":"ELL9","serial":"11300123"},"diag":[],"stream":0}
{"n":34,"proto":"ell","type":"frame","offset":334,"len":7,"raw":"30475330300d0a","text":"0GS00\r\n","addr":"0","dir":"d2h","cmd":"GS","name":"GET_STATUS","fields":{"status":"OK"},"module":{"first_addr":1,"model":"ELL9","serial":"11300123"},"pair":33,"diag":[],"stream":0}
{"n":35,"proto":"ell","type":"frame","offset":341,"len":3,"raw":"31676a","text":"1gj","addr":"1","dir":"h2d","cmd":"gj","name":"REQ_JOG_STEP_SIZE","fields":{},"module":{"first_addr":1,"model":"ELL9","serial":"11300123"},"diag":[],"stream":0}
{"proto":"ell","type":"diag","ref":35,"diag":[{"kind":"no_reply","offset":341,"msg":"no reply to record 35"}]}
"##;

    /// `aptscope decode --json samples/damaged.bin`
    const DAMAGED: &str = r##"{"type":"detect","proto":"apt","certain":false,"apt":0.369,"ell":0.000}
{"n":1,"proto":"apt","type":"garbage","offset":0,"len":4,"raw":"ff0055aa","diag":[{"kind":"garbage","offset":0,"msg":"4 byte(s) that start no frame"}],"dir":"unknown","stream":0}
{"n":2,"proto":"apt","type":"frame","offset":4,"len":6,"raw":"050000005001","msgid":5,"msgid_hex":"0x0005","name":"HW_REQ_INFO","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":false,"data_len":0,"fields":{},"diag":[],"dir":"h2d","stream":0}
{"n":3,"proto":"apt","type":"garbage","offset":10,"len":3,"raw":"133700","diag":[{"kind":"garbage","offset":10,"msg":"3 byte(s) that start no frame"}],"dir":"unknown","stream":0}
{"n":4,"proto":"apt","type":"frame","offset":13,"len":8,"raw":"eeee0200d0011234","msgid":61166,"msgid_hex":"0xEEEE","name":null,"src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":true,"data_len":2,"fields":{},"diag":[{"kind":"unknown_id","offset":13,"msg":"unknown message id 0xEEEE"}],"dir":"unknown","stream":0}
{"n":5,"proto":"apt","type":"frame","offset":21,"len":6,"raw":"230201005001","msgid":547,"msgid_hex":"0x0223","name":"MOD_IDENTIFY","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":80,"name":"usb"},"data_flag":false,"data_len":0,"channel":1,"fields":{"chan_ident":"CH1"},"diag":[],"dir":"h2d","stream":0}
{"n":6,"proto":"apt","type":"frame","offset":27,"len":10,"raw":"53040400a2010100400d","msgid":1107,"msgid_hex":"0x0453","name":"MOT_MOVE_ABSOLUTE","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":34,"name":"bay1","bay":1},"data_flag":true,"data_len":4,"fields":{},"diag":[{"kind":"length_mismatch","offset":29,"msg":"data length 4 matches no form of this message"}],"dir":"h2d","stream":0}
{"n":7,"proto":"apt","type":"garbage","offset":37,"len":6,"raw":"5304ffffa201","diag":[{"kind":"absurd_length","offset":37,"msg":"header of 0x0453 claims a 65535-byte data packet (max 255); header skipped"}],"dir":"unknown","stream":0}
{"n":8,"proto":"apt","type":"frame","offset":43,"len":12,"raw":"53040600a2010100400d0300","msgid":1107,"msgid_hex":"0x0453","name":"MOT_MOVE_ABSOLUTE","msg_dir":"h2d","src":{"addr":1,"name":"host"},"dst":{"addr":34,"name":"bay1","bay":1},"data_flag":true,"data_len":6,"form_note":"long version: position in the data packet","channel":1,"fields":{"chan_ident":"CH1","absolute_position":200000},"diag":[],"dir":"h2d","stream":0}
{"n":9,"proto":"apt","type":"frame","offset":55,"len":10,"raw":"91040e00815001000050","msgid":1169,"msgid_hex":"0x0491","name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h","src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},"data_flag":true,"data_len":14,"channel":1,"fields":{"chan_ident":"CH1"},"diag":[{"kind":"truncated","offset":65,"msg":"truncated: header announces 20 bytes, stream ends after 10"}],"dir":"d2h","stream":0}
{"proto":"apt","type":"diag","ref":2,"diag":[{"kind":"no_reply","offset":4,"msg":"no reply to record 2"}]}
{"proto":"apt","type":"diag","ref":6,"diag":[{"kind":"no_reply","offset":27,"msg":"no reply to record 6"}]}
{"proto":"apt","type":"diag","ref":8,"diag":[{"kind":"no_reply","offset":43,"msg":"no reply to record 8"}]}
"##;

    fn records(ndjson: &str) -> Vec<Value> {
        ndjson
            .lines()
            .map(|l| serde_json::from_str(l).expect("golden line is JSON"))
            .collect()
    }

    fn f(src: &str) -> Filter {
        Filter::parse(src).unwrap_or_else(|e| panic!("{src}: {e}\n{}", e.caret(src)))
    }

    fn count(recs: &[Value], src: &str) -> usize {
        let flt = f(src);
        recs.iter().filter(|r| flt.matches(r)).count()
    }

    /// Record numbers (`n`) of the matching records.
    fn ns(recs: &[Value], src: &str) -> Vec<u64> {
        let flt = f(src);
        recs.iter()
            .filter(|r| flt.matches(r))
            .filter_map(|r| r.get("n").and_then(Value::as_u64))
            .collect()
    }

    fn err(src: &str) -> FilterError {
        match Filter::parse(src) {
            Ok(x) => panic!("{src}: parsed as {x:?}"),
            Err(e) => e,
        }
    }

    fn status_rec() -> Value {
        json!({"n":14,"proto":"apt","type":"frame","offset":182,"len":20,
            "raw":"91040e0081500100005000002c01000010050080","msgid":1169,"msgid_hex":"0x0491",
            "name":"MOT_GET_DCSTATUSUPDATE","msg_dir":"d2h",
            "src":{"addr":80,"name":"usb"},"dst":{"addr":1,"name":"host"},
            "data_flag":true,"data_len":14,"channel":1,
            "fields":{"chan_ident":"CH1","position":20480,"velocity":300,
                "status_bits":["MOVING_CW","MOTOR_CONNECTED","HOMED","ENABLED"]},
            "diag":[],"dir":"d2h","ts_ns":1764000002404000000_u64,"stream":0})
    }

    fn rack_rec() -> Value {
        json!({"n":8,"proto":"apt","type":"frame","offset":43,"len":12,
            "raw":"53040600a2010100400d0300","msgid":1107,"msgid_hex":"0x0453",
            "name":"MOT_MOVE_ABSOLUTE","msg_dir":"h2d",
            "src":{"addr":1,"name":"host"},"dst":{"addr":35,"name":"bay2","bay":2},
            "data_flag":true,"data_len":6,"channel":1,
            "fields":{"chan_ident":"CH1","absolute_position":200000},"diag":[],"dir":"h2d"})
    }

    fn ell_reply() -> Value {
        json!({"n":14,"proto":"ell","type":"frame","offset":166,"len":13,
            "raw":"30504f30303030384330300d0a","text":"0PO00008C00\r\n","addr":"0","dir":"d2h",
            "cmd":"PO","name":"POSITION","fields":{"position":35840},
            "phys":{"position":{"value":90,"unit":"deg"}},
            "module":{"first_addr":0,"model":"ELL14","serial":"11400284"},
            "pair":12,"latency_ms":12.5,"ts_ns":2_500_000_000_u64,"diag":[]})
    }

    fn sub_rec() -> Value {
        json!({"n":3,"proto":"apt","type":"frame","offset":0,"len":10,"msgid":2048,
            "name":"LA_SET_PARAMS","msg_dir":"h2d","src":{"addr":1,"name":"host"},
            "dst":{"addr":80,"name":"usb"},"data_flag":true,"data_len":4,
            "sub":{"id":1,"name":"SETPOINT"},"fields":{"setpoint":1638},
            "phys":{"setpoint":{"value":5.0,"unit":"%"}},"diag":[],"dir":"h2d"})
    }

    fn yes(rec: &Value, src: &str) -> bool {
        f(src).matches(rec)
    }

    /// A term on a field narrows a scan to the messages that have it; anything that can
    /// match without the field (negation, `||` with a record-level term) does not.
    #[test]
    fn apt_ids_follow_the_fields_a_filter_needs() {
        let t = Table::global();
        let id = |n: &str| t.msg_by_name(n).map(|m| m.id).expect(n);
        let ids = |f: &str| Filter::parse(f).expect(f).apt_ids(t);
        let pos = ids("apt.position > 1000 && dir == d2h").expect("narrowed");
        assert!(
            pos.contains(id("MOT_GET_DCSTATUSUPDATE")) && pos.contains(id("MOT_MOVE_COMPLETED"))
        );
        assert!(!pos.contains(id("MOT_MOVE_HOME")) && !pos.contains(0x7FFF));
        let chan = ids("apt.chan == 1").expect("narrowed");
        assert!(chan.contains(id("MOT_MOVE_HOME")) && !chan.contains(id("HW_REQ_INFO")));
        let sub = ids("apt.codes.status_bits").expect("narrowed");
        assert!(sub.contains(id("MOT_GET_DCSTATUSUPDATE")));
        let ell = ids("ell.position > 0").expect("no APT frame");
        assert!(!ell.contains(id("MOT_GET_DCSTATUSUPDATE")));
        for any in [
            "!apt.position",
            "apt.position > 1 || n > 5",
            "apt.fields",
            "dir == h2d",
            "",
        ] {
            assert!(ids(any).is_none(), "{any}");
        }
    }

    #[test]
    fn kdc101_counts() {
        let recs = records(KDC101);
        assert_eq!(recs.len(), 22);
        assert_eq!(count(&recs, r#"apt.name == "MOT_GET_DCSTATUSUPDATE""#), 9);
        assert_eq!(count(&recs, "dir == device"), 13);
        assert_eq!(count(&recs, "dir == host"), 7);
        assert_eq!(count(&recs, "dir == d2h || dir == h2d"), 20);
        assert_eq!(ns(&recs, "apt.fields.position > 100000"), [16, 17, 18, 19]);
        assert_eq!(ns(&recs, "apt.fields.position < 0"), [9, 10, 11]);
        assert_eq!(count(&recs, "apt.fields.position"), 10);
        assert_eq!(count(&recs, "apt.position >= 0"), 7);
        assert_eq!(
            ns(&recs, "apt.fields.status_bits contains HOMED"),
            [14, 15, 16, 17, 18, 19]
        );
        assert_eq!(
            count(&recs, r#"apt.fields.status_bits contains "HOMING""#),
            4
        );
        assert_eq!(ns(&recs, r#"apt.name ~ "^MOT_MOVE""#), [7, 12, 13, 19]);
        assert_eq!(ns(&recs, "apt.name in {HW_REQ_INFO HW_GET_INFO}"), [1, 2]);
        assert_eq!(count(&recs, "apt.fields.velocity >= 300"), 5);
        assert_eq!(count(&recs, "apt.msgid == 0x0491"), 9);
        assert_eq!(count(&recs, "apt.msgid == 1169"), 9);
        assert_eq!(count(&recs, "apt.chan == 1"), 16);
        assert_eq!(count(&recs, "apt.fields.chan_ident == ch1"), 16);
        assert_eq!(count(&recs, "apt.src == usb"), 13);
        assert_eq!(count(&recs, "apt.dst == 0x50"), 7);
        assert_eq!(count(&recs, "apt.data_flag"), 12);
        assert_eq!(count(&recs, "apt.data_flag == false"), 8);
        assert_eq!(count(&recs, "apt.len == 20"), 10);
        assert_eq!(count(&recs, "apt.data_len == 14"), 10);
        assert_eq!(count(&recs, "apt.fields.model_number == kdc101"), 1);
        assert_eq!(count(&recs, r#"apt.form_note contains "long""#), 1);
        assert_eq!(count(&recs, "apt.msg_dir == host"), 7);
        // The detect record is `"proto":"apt"` too; the stream record has no protocol.
        assert_eq!(count(&recs, "apt"), 21);
        assert_eq!(count(&recs, "type == frame"), 20);
        assert_eq!(count(&recs, "stream == 0"), 21);
        assert_eq!(count(&recs, "offset == 0"), 2);
        assert_eq!(count(&recs, "n <= 5"), 5);
        assert_eq!(ns(&recs, "ts > 1764000002.5"), [15, 16, 17, 18, 19, 20]);
        assert_eq!(count(&recs, "ts_ns < 1764000000100000000"), 2);
        assert_eq!(count(&recs, "diag || unpaired || ell"), 0);
        // Request/reply pairs: HW_GET_INFO ↩ 1, MOD_GET_CHANENABLESTATE ↩ 4,
        // MOT_MOVE_HOMED ↩ 7 (2 s later), MOT_MOVE_COMPLETED ↩ 13 (502 ms).
        assert_eq!(ns(&recs, "paired"), [2, 5, 12, 19]);
        assert_eq!(ns(&recs, "apt.pair == 13"), [19]);
        assert_eq!(ns(&recs, "latency > 1s"), [12]);
        assert_eq!(ns(&recs, "latency >= 0.5s && latency < 2000"), [19]);
        assert_eq!(ns(&recs, "latency < 10ms"), [2, 5]);
        assert_eq!(ns(&recs, "apt.latency == 2s"), [12]);
        assert_eq!(
            ns(&recs, "dir == host && !(apt.name ~ MOT) && apt.chan"),
            [3, 4]
        );
    }

    #[test]
    fn elliptec_counts() {
        let recs = records(ELL_BUS);
        assert_eq!(
            count(&recs, "ell"),
            37,
            "the frames and the detection record"
        );
        assert_eq!(count(&recs, "ell.addr == 0"), 17);
        assert_eq!(ns(&recs, "ell.addr == 5"), [22, 23, 24, 25, 26]);
        assert_eq!(count(&recs, "ell.module == ELL14"), 15);
        assert_eq!(ns(&recs, "ell.module == ell9"), [4, 15, 16, 33, 34, 35]);
        assert_eq!(ns(&recs, "ell.phys.position > 45"), [12, 14]);
        assert_eq!(count(&recs, "ell.phys.position >= 45"), 3);
        assert_eq!(ns(&recs, "ell.fields.status == BUSY"), [10, 13, 31]);
        assert_eq!(count(&recs, "ell.cmd == GS"), 7);
        assert_eq!(ns(&recs, "ell.cmd == gs"), [7]);
        assert_eq!(count(&recs, "ell.cmd in {PO BO}"), 7);
        assert_eq!(count(&recs, "ell.name == POSITION"), 6);
        assert_eq!(ns(&recs, "ell.fields.serial == 11400284"), [2]);
        assert_eq!(ns(&recs, "ell.fields.year >= 2022"), [4, 6]);
        assert_eq!(count(&recs, "ell.fields.thread == metric"), 3);
        assert_eq!(count(&recs, "ell.interim"), 2);
        assert_eq!(count(&recs, "paired"), 17);
        assert_eq!(count(&recs, "unpaired"), 1);
        assert_eq!(count(&recs, "diag"), 1);
        assert_eq!(count(&recs, "ell.diag"), 1);
        assert_eq!(count(&recs, "apt.diag"), 0);
        assert_eq!(count(&recs, r#"diag.kind == "no_reply""#), 1);
        assert_eq!(count(&recs, "ref == 35"), 1);
        assert_eq!(count(&recs, "apt.name == POSITION"), 0);
        assert_eq!(count(&recs, "ell.fields.new_address == 5"), 1);
        assert_eq!(count(&recs, r#"ell.text ~ "^0PO""#), 2);
        assert_eq!(ns(&recs, r#"ell.cmd ~ "^g""#), [7, 23, 27, 33, 35]);
        assert_eq!(count(&recs, r#"ell.cmd matches "^G""#), 8);
        assert_eq!(
            ns(&recs, "dir == tx && ell.module.model == ELL17"),
            [17, 19, 21, 23, 25]
        );
    }

    #[test]
    fn damaged_counts() {
        let recs = records(DAMAGED);
        assert_eq!(ns(&recs, "diag"), [1, 3, 4, 6, 7, 9]);
        assert_eq!(ns(&recs, r#"diag.kind == "truncated""#), [9]);
        assert_eq!(ns(&recs, "diag.kind == truncated"), [9]);
        assert_eq!(ns(&recs, "diag contains truncated"), [9]);
        assert_eq!(ns(&recs, "diag.offset == 65"), [9]);
        assert_eq!(ns(&recs, "diag.msg contains \"65535\""), [7]);
        assert_eq!(ns(&recs, "diag.kind in {garbage absurd_length}"), [1, 3, 7]);
        assert_eq!(count(&recs, "type == garbage"), 3);
        assert_eq!(ns(&recs, "apt.msgid && !apt.name"), [4]);
        assert_eq!(ns(&recs, "apt.dst == bay1"), [6, 8]);
        assert_eq!(
            ns(&recs, "apt.dst.bay == 1 && apt.fields.absolute_position"),
            [8]
        );
        assert_eq!(count(&recs, "dir == unknown"), 4);
        assert_eq!(count(&recs, "!diag && type == frame"), 3);
        // Requests never answered: one `diag` record each, about its request.
        assert_eq!(count(&recs, "unpaired"), 3);
        assert_eq!(count(&recs, "type == diag && ref in {2 6 8}"), 3);
        assert_eq!(count(&recs, "diag"), 9);
        assert_eq!(
            count(&recs, "diag.kind == no_reply && diag.offset >= 27"),
            2
        );
    }

    #[test]
    fn comparison_operators() {
        let r = status_rec();
        for (src, want) in [
            ("apt.fields.position == 20480", true),
            ("apt.fields.position eq 20480", true),
            ("apt.fields.position != 20480", false),
            ("apt.fields.position ne 1", true),
            ("apt.fields.position < 20481", true),
            ("apt.fields.position lt 20480", false),
            ("apt.fields.position <= 20480", true),
            ("apt.fields.position le 20479", false),
            ("apt.fields.position > 20479", true),
            ("apt.fields.position gt 20480", false),
            ("apt.fields.position >= 20480", true),
            ("apt.fields.position ge 20481", false),
            ("apt.fields.position > -5", true),
            ("apt.fields.position == 20480.0", true),
            ("apt.fields.position < 20480.5", true),
            ("apt.fields.position == 0x5000", true),
            ("apt.msgid == 0X491", true),
            ("apt.msgid_hex == 0x0491", true),
            ("apt.msgid_hex == \"0X0491\"", true),
            // Strings: equality ignores case; ordering is lexical.
            ("apt.name == mot_get_dcstatusupdate", true),
            ("apt.name != MOT_GET_DCSTATUSUPDATE", false),
            ("apt.name != MOT_MOVE_HOME", true),
            ("apt.name > MOT_A", true),
            ("apt.name < \"MOT_H\"", true),
            ("apt.name >= MOT_GET_DCSTATUSUPDATE", true),
            ("apt.name <= MOT_GET", false),
            // Incompatible types are false, never an error.
            // A number against text compares as written: "MOT_…" is not 5.
            ("apt.name == 5", false),
            ("apt.name != 5", true),
            ("apt.name > 5", false),
            ("apt.fields.position == HOMED", false),
            ("apt.fields.position != HOMED", false),
            ("apt.fields.position < 1s", false),
            ("apt.data_flag == true", true),
            ("apt.data_flag != true", false),
            ("apt.data_flag == \"TRUE\"", true),
            ("apt.data_flag == 1", false),
            // Missing fields: every comparison is false.
            ("apt.fields.max_vel == 1", false),
            ("apt.fields.max_vel != 1", false),
            ("!(apt.fields.max_vel == 1)", true),
        ] {
            assert_eq!(yes(&r, src), want, "{src}");
        }
    }

    #[test]
    fn contains_matches_in() {
        let r = status_rec();
        for (src, want) in [
            ("apt.fields.status_bits contains HOMED", true),
            ("apt.fields.status_bits contains \"homed\"", true),
            // Lists: membership, not substring.
            ("apt.fields.status_bits contains HOME", false),
            ("apt.fields.status_bits == ENABLED", true),
            ("apt.fields.status_bits != ENABLED", false),
            ("apt.fields.status_bits != SETTLED", true),
            ("apt.fields.status_bits in {SETTLED HOMED}", true),
            ("apt.name contains DCSTATUS", true),
            ("apt.name contains dcstatus", true),
            ("apt.name contains MOVE", false),
            ("apt.raw contains \"9104\"", true),
            ("apt.dst contains hos", true),
            ("apt.fields.position contains 2", false),
            ("apt.name ~ \"^MOT_GET\"", true),
            ("apt.name matches \"STATUS.*UPDATE$\"", true),
            ("apt.name ~ \"^mot\"", true),
            ("apt.name ~ \"(?-i)^mot\"", false),
            ("apt.name ~ \"(?-i)^MOT\"", true),
            ("apt.name ~ DCSTATUS", true),
            ("apt.fields.status_bits ~ \"^MOVING_\"", true),
            ("apt.fields.position ~ \"^204\"", true),
            ("apt.dst ~ \"^ho\"", true),
            ("apt.raw ~ \"\\d{4}\"", true),
            ("apt.name in {MOT_MOVE_HOME, MOT_GET_DCSTATUSUPDATE}", true),
            ("apt.name in {\"MOT_MOVE_HOME\"}", false),
            ("apt.name in {}", false),
            ("apt.fields.position in {1 2 20480}", true),
            ("apt.fields.position in {0x5000}", true),
            ("apt.msgid in {5 6}", false),
            ("n in {13,14,15}", true),
        ] {
            assert_eq!(yes(&r, src), want, "{src}");
        }
    }

    #[test]
    fn logic_and_precedence() {
        let r = status_rec();
        for (src, want) in [
            ("apt && ell", false),
            ("apt and not ell", true),
            ("apt || ell", true),
            ("ell or apt", true),
            ("!apt", false),
            ("not not apt", true),
            ("!!apt", true),
            // && binds tighter than ||: true || (false && false)
            ("apt || ell && ell", true),
            // (true || false) && false
            ("(apt || ell) && ell", false),
            // ! binds tighter than &&: (!ell) && apt
            ("!ell && apt", true),
            // !(ell && apt)
            ("!(ell && apt)", true),
            // ! binds tighter than ||: (!apt) || ell
            ("!apt || ell", false),
            ("ell || ell || ell || apt", true),
            ("apt && apt && apt && ell", false),
            ("((apt))", true),
            (
                "(apt.name == X || apt.fields.position > 0) and dir == rx",
                true,
            ),
            ("apt.sub||apt.fields.position", true),
            ("apt.fields.position&&!apt.sub", true),
        ] {
            assert_eq!(yes(&r, src), want, "{src}");
        }
    }

    #[test]
    fn addresses_and_directions() {
        let r = rack_rec();
        for (src, want) in [
            ("apt.dst == bay2", true),
            ("apt.dst == BAY2", true),
            ("apt.dst == bay3", false),
            ("apt.dst == 0x23", true),
            ("apt.dst == 35", true),
            ("apt.dst == 34", false),
            ("apt.dst > 0x21", true),
            ("apt.src == host", true),
            ("apt.src == 1", true),
            ("apt.dst in {bay1 bay2}", true),
            ("apt.dst.bay == 2", true),
            ("dir == host", true),
            ("dir == h2d", true),
            ("dir == tx", true),
            ("dir == device", false),
            ("dir == rx", false),
            ("dir != d2h", true),
            ("dir in {host}", true),
            ("apt.msg_dir == host", true),
            ("apt.dir == tx", true),
            ("ell.dir == tx", false),
        ] {
            assert_eq!(yes(&r, src), want, "{src}");
        }
    }

    #[test]
    fn elliptec_fields_and_durations() {
        let r = ell_reply();
        for (src, want) in [
            ("ell.addr == 0", true),
            ("ell.addr == \"0\"", true),
            ("ell.cmd == PO", true),
            ("ell.cmd == po", false),
            ("ell.name == position", true),
            ("ell.module == ELL14", true),
            ("ell.module == ell14", true),
            ("ell.module.serial == 11400284", true),
            ("ell.fields.position == 35840", true),
            ("ell.position == 35840", true),
            ("ell.phys.position == 90", true),
            ("ell.phys.position.unit == deg", true),
            ("ell.pair == 12", true),
            ("pair == 12", true),
            ("paired", true),
            ("unpaired", false),
            ("apt.fields.position", false),
            ("apt.pair == 12", false),
            // latency is in ms: numbers are ms, durations convert.
            ("latency == 12.5", true),
            ("latency < 50ms", true),
            ("latency > 0.01s", true),
            ("latency > 12ms", true),
            ("latency <= 12500us", true),
            ("latency < 12500us", false),
            ("latency < 12500000ns", false),
            ("latency < 200us", false),
            ("latency < 2min", true),
            ("latency < 1h", true),
            ("latency > -1s", true),
            ("latency_ms == 12.5", true),
            ("ell.latency > 10ms", true),
            ("latency == 12.5ms", true),
            // ts is in seconds.
            ("ts == 2.5", true),
            ("ts > 2s", true),
            ("ts >= 2500ms", true),
            ("ts < 1.5s", false),
            ("ts < 1min", true),
            ("ts_ns == 2.5s", true),
            ("ts_ns == 2500000000", true),
            ("ell.fields.position < 1s", false),
        ] {
            assert_eq!(yes(&r, src), want, "{src}");
        }
    }

    #[test]
    fn truthiness_and_specials() {
        let s = sub_rec();
        assert!(yes(&s, "apt.sub"));
        assert!(yes(&s, "apt.sub == SETPOINT"));
        assert!(yes(&s, "apt.sub == setpoint"));
        assert!(yes(&s, "apt.sub == 1"));
        assert!(yes(&s, "apt.sub.id == 1"));
        assert!(yes(&s, "apt.phys.setpoint == 5"));
        assert!(yes(&s, "apt.setpoint == 1638"));
        assert!(!yes(&status_rec(), "apt.sub"));
        assert!(!yes(&status_rec(), "apt.sub == SETPOINT"));
        assert!(!yes(&status_rec(), "apt.sub != SETPOINT"));

        let r = json!({"proto":"apt","n":1,"diag":[],"fields":{"position":0,"velocity":false,"model_number":"",
            "status_bits":[],"notes":"x","chan_ident":[1],"serial_number":null,"internal":{}}});
        assert!(yes(&r, "apt.fields.position"), "0 exists and is not false");
        assert!(!yes(&r, "apt.fields.velocity"));
        assert!(!yes(&r, "apt.fields.model_number"));
        assert!(!yes(&r, "apt.fields.status_bits"));
        assert!(yes(&r, "apt.fields.notes"));
        assert!(yes(&r, "apt.fields.chan_ident"));
        assert!(!yes(&r, "apt.fields.serial_number"));
        assert!(!yes(&r, "apt.fields.internal"));
        assert!(!yes(&r, "apt.fields.max_vel"));
        assert!(!yes(&r, "diag"));
        assert!(!yes(&r, "apt.fields.serial_number == null"));

        let input = json!({"type":"input","diag":[]});
        assert!(yes(&input, "diag"));
        assert!(!yes(&input, "apt.diag"), "an input record has no protocol");
        let garbage = json!({"proto":"apt","type":"garbage","diag":[]});
        assert!(yes(&garbage, "diag"));
        assert!(yes(&garbage, "apt.diag"));

        assert!(yes(&json!({"proto":"ell","unpaired":true}), "unpaired"));
        assert!(yes(
            &json!({"proto":"ell","unpaired":true}),
            "unpaired == true"
        ));
        assert!(!yes(&json!({"proto":"ell","unpaired":false}), "unpaired"));
        let unsol = json!({"proto":"ell","diag":[{"kind":"unsolicited","offset":3,"msg":"x"}]});
        assert!(yes(&unsol, "unpaired && diag"));
        assert!(yes(&unsol, "ell.unpaired"));
        assert!(!yes(&unsol, "apt.unpaired"));
        let unans = json!({"type":"diag","ref":3,"diag":[{"kind":"unanswered"}]});
        assert!(yes(&unans, "unpaired"));
        assert!(!yes(&json!({"pair":null}), "paired"));
        assert!(yes(&json!({"pair":0}), "paired"));
    }

    #[test]
    fn values() {
        let r = json!({"proto":"apt","n":-3,"fields":{"model_number":"a \"quoted\" \\ word",
            "serial_number":18446744073709551615_u64,"position":-2147483648,"velocity":0.25,"notes":"x\ty"}});
        for (src, want) in [
            ("n == -3", true),
            ("n < -2", true),
            ("n == -0x3", true),
            (
                "apt.fields.model_number == \"a \\\"quoted\\\" \\\\ word\"",
                true,
            ),
            ("apt.fields.model_number contains \"\\\"quoted\\\"\"", true),
            ("apt.fields.notes == \"x\\ty\"", true),
            ("apt.fields.serial_number == 0xFFFFFFFFFFFFFFFF", true),
            ("apt.fields.serial_number == 18446744073709551615", true),
            ("apt.fields.serial_number > 18446744073709551614", true),
            ("apt.fields.position == -2147483648", true),
            ("apt.fields.velocity == 0.25", true),
            ("apt.fields.velocity < 1", true),
            ("apt.fields.velocity > 0", true),
            ("apt.fields.model_number ~ \"\\\"q\"", true),
        ] {
            assert_eq!(yes(&r, src), want, "{src}");
        }
        assert!(
            yes(&json!({"type":"frame"}), "   "),
            "blank filter matches all"
        );
        assert!(yes(&json!(null), ""));
        assert!(!yes(&json!(null), "apt"));
        assert!(!yes(&json!([1, 2]), "n == 1"));
        assert!(yes(&json!({"x": 1}), "!(n == 1)"));
    }

    #[test]
    fn errors_point_at_their_column() {
        for (src, col, msg) in [
            ("apt.name ==", 12, "expected a value after `==`"),
            ("apt.name ==   && n", 15, "expected a value after `==`"),
            ("apt.name contains", 18, "expected a value after `contains`"),
            ("(apt.name == X", 1, "unbalanced parentheses: this `(` is never closed"),
            ("n == 1 && ((n == 2)", 11, "unbalanced parentheses: this `(` is never closed"),
            ("apt.name == X)", 14, "unbalanced parentheses: `)` without a matching `(`"),
            ("(n == 1 n)", 9, "expected `)`, `&&` or `||`, found `n`"),
            ("()", 2, "expected a test after `(`"),
            (
                "apt.name like X",
                10,
                "unknown operator `like` (use ==, !=, <, <=, >, >=, contains, ~, matches or in)",
            ),
            (
                "apt.name =~ X",
                10,
                "unknown operator `=~` (use ==, !=, <, <=, >, >=, contains, ~, matches or in)",
            ),
            ("apt.name = X", 10, "unknown operator `=` (did you mean `==`?)"),
            ("n == 1 & n == 2", 8, "unknown operator `&` (use `&&`)"),
            ("apt.sub | n == 2", 9, "unknown operator `|` (use ==, !=, <, <=, >, >=, contains, ~, matches or in)"),
            ("apt.name == \"MOT", 13, "unterminated string: missing closing `\"`"),
            ("apt.name == \"MOT\\\"", 13, "unterminated string: missing closing `\"`"),
            ("apt.name == X Y", 15, "unexpected `Y`: expected `&&`, `||` or the end of the filter"),
            ("apt.name ~ \"MOT_(\"", 12, "invalid regular expression: unclosed group"),
            ("apt.name matches \"[\"", 18, "invalid regular expression: unclosed character class"),
            ("latency < 50xs", 13, "unknown duration unit `xs` (use ns, us, ms, s, min or h)"),
            ("latency < 1.5sec", 14, "unknown duration unit `sec` (use ns, us, ms, s, min or h)"),
            ("n == 0x", 8, "expected hex digits after `0x`"),
            ("n == 0x1fz", 6, "bad hex number `0x1fz`"),
            ("n == 999999999999999999999999999999999999999999", 6, "number out of range"),
            (
                "name == MOT_MOVE_HOME",
                1,
                "unknown field `name`: protocol fields need a prefix; did you mean `apt.name`, `ell.name`?",
            ),
            (
                "dir == h2d && fields.position > 3",
                15,
                "unknown field `fields.position`: protocol fields need a prefix; did you mean `apt.fields.position`, `ell.fields.position`?",
            ),
            ("apt.nmae == X", 1, "unknown field `apt.nmae`; did you mean `apt.name`?"),
            (
                "frame.len > 3",
                1,
                "unknown field `frame.len`: protocol fields need a prefix; did you mean `len`?",
            ),
            (
                "ell.fields.postion > 3",
                1,
                "unknown field `ell.fields.postion`; did you mean `ell.fields.position`?",
            ),
            ("apt == 5", 1, "`apt` is a protocol; compare one of its fields, e.g. `apt.name`"),
            ("apt.fields.", 12, "expected a field name after `.`"),
            ("n == 1 &&", 10, "expected a test after `&&`"),
            ("n == 1 ||   ", 13, "expected a test after `||`"),
            ("n == 1 and or", 12, "expected a test after `and`"),
            ("!", 2, "expected a test after `!`"),
            ("not", 4, "expected a test after `not`"),
            ("== 5", 1, "expected a field name, `!` or `(`, found `==`"),
            ("  \"x\"", 3, "expected a field name, `!` or `(`, found `\"`"),
            ("n in 5", 6, "expected `{` after `in`"),
            ("n in {1 2", 6, "unbalanced braces: this `{` is never closed"),
            ("n in {1 == }", 9, "expected a value or `}`, found `==`"),
            ("n == and", 6, "expected a value after `==`"),
        ] {
            let e = err(src);
            assert_eq!((e.column, e.msg.as_str()), (col, msg), "{src}");
        }
    }

    #[test]
    fn error_display_and_caret() {
        let src = "apt.name ==";
        let e = err(src);
        assert_eq!(e.to_string(), "column 12: expected a value after `==`");
        assert_eq!(e.caret(src), "apt.name ==\n           ^");
        let src = "(dir == host";
        assert_eq!(err(src).caret(src), "(dir == host\n^");
        let src = "\tn == \"µs";
        let e = err(src);
        assert_eq!(e.column, 7);
        assert_eq!(e.caret(src), "\tn == \"µs\n\t     ^");
        let src = "n == 1 && µ";
        let e = err(src);
        assert_eq!(e.column, 11);
        assert_eq!(e.msg, "expected a test after `&&`");
    }

    #[test]
    fn api_shape() {
        let flt: Filter = "apt.name == X".parse().expect("parses");
        assert_eq!(flt.as_str(), "apt.name == X");
        assert_eq!(flt.to_string(), "apt.name == X");
        let copy = flt.clone();
        assert!(format!("{copy:?}").contains("Cmp"));
        let e: Box<dyn std::error::Error> = Box::new(err("("));
        assert!(e.to_string().starts_with("column "));
    }

    #[test]
    fn nesting_is_bounded() {
        let deep = format!("{}n == 1{}", "(".repeat(60), ")".repeat(60));
        assert!(f(&deep).matches(&json!({"n":1})));
        let too_deep = format!("{}n == 1{}", "(".repeat(500), ")".repeat(500));
        assert!(err(&too_deep).msg.contains("nested too deeply"));
        let nots = "!".repeat(10_000) + "n";
        assert!(err(&nots).msg.contains("nested too deeply"));
        let long = vec!["n == 1"; 20_000].join(" || ");
        assert!(f(&long).matches(&json!({"n":1})));
    }

    proptest::proptest! {
        #[test]
        fn never_panics(src in "\\PC{0,40}") {
            if let Ok(flt) = Filter::parse(&src) {
                for r in records(KDC101).iter().chain(records(DAMAGED).iter()) {
                    let _ = flt.matches(r);
                }
            } else if let Err(e) = Filter::parse(&src) {
                proptest::prop_assert!(e.column >= 1 && e.column <= src.chars().count() + 1);
                let _ = e.caret(&src);
            }
        }

        #[test]
        fn never_panics_on_filter_like_text(
            parts in proptest::collection::vec(proptest::sample::select(vec![
                "apt.name", "n", "dir", "(", ")", "!", "&&", "||", "==", "<", "~", "in", "{", "}",
                "\"x", "\"a\"", "0x", "12ms", "-", "contains", "HOMED", " ", ".", "ell.", "diag",
            ]), 0..12)
        ) {
            let src: String = parts.concat();
            match Filter::parse(&src) {
                Ok(flt) => {
                    for r in records(ELL_BUS) {
                        let _ = flt.matches(&r);
                    }
                }
                Err(e) => {
                    proptest::prop_assert!(e.column >= 1 && e.column <= src.chars().count() + 1);
                }
            }
        }
    }
}
