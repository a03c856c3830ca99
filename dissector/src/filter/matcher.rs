//! The compiled matcher: a filter turned into closures for scans.

use super::ast::{CmpOp, Expr, FieldRef, Lit, LitKind, Test, N};
use super::eval::proto_is;
use crate::fields::{Fields, Key};
use std::fmt;

/// A filter compiled into closures for scans over millions of records: each comparison of a
/// record-level value with a literal becomes a closure specialised for its operator and
/// literal, so a record costs a few calls instead of a walk of the expression tree. Gives the
/// same answers as [`super::Filter::matches`] (anything it does not specialise, it asks that of).
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
    /// Compiles `expr` into closures.
    pub(super) fn new(expr: &Expr) -> Matcher {
        Matcher { root: node(expr) }
    }

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
