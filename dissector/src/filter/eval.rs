//! Evaluation: a compiled filter tested against a record read through [`Fields`].

use super::ast::{CmpOp, Expr, FieldRef, Lit, LitKind, Test, N};
use crate::fields::{Fields, Key, Role, Val};
use std::borrow::Cow;
use std::cmp::Ordering;

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

pub(super) fn proto_is<F: Fields + ?Sized>(rec: &F, p: Option<&str>) -> bool {
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
    pub(super) fn record_keys<'a>(&'a self, out: &mut Vec<&'a str>, fallback: &mut Vec<&'a str>) {
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
    pub(super) fn can_match(&self, has: &dyn Fn(&str) -> bool) -> bool {
        match self {
            Expr::All | Expr::Not(_) => true,
            Expr::Or(xs) => xs.iter().any(|x| x.can_match(has)),
            Expr::And(xs) => xs.iter().all(|x| x.can_match(has)),
            Expr::Test(t) => t.field().is_none_or(|f| f.can_have_value(has)),
        }
    }

    pub(super) fn eval<F: Fields + ?Sized>(&self, rec: &F) -> bool {
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
    pub(super) fn cmp<F: Fields + ?Sized>(rec: &F, f: &FieldRef, op: CmpOp, lit: &Lit) -> bool {
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
    pub(super) fn eval<F: Fields + ?Sized>(&self, rec: &F) -> bool {
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
