//! The parser: filter text to the compiled form (nom).

use super::ast::{CmpOp, Expr, FieldRef, Lit, LitKind, Op, Test};
use super::keys::{resolve, Ref};
use super::lexer::{
    failure, ident, is_ident, keyword, need, number_lit, skip_ws, soft, string_lit, token,
    word_lit, PErr, Res,
};
use crate::fields::Key;
use crate::shape::Ty;
use nom::branch::alt;
use nom::bytes::complete::{tag, take_while, take_while1};
use nom::character::complete::{char as nchar, multispace0};
use nom::combinator::map;
use nom::Err as NomErr;
use regex::RegexBuilder;

/// Deepest nesting of parentheses and `!` accepted (keeps recursion bounded on any input).
const MAX_DEPTH: usize = 64;

pub(super) fn expr_or(i: &str, depth: usize) -> Res<'_, Expr> {
    chain(i, depth, ("||", "or"), expr_and, Expr::Or)
}

fn expr_and(i: &str, depth: usize) -> Res<'_, Expr> {
    chain(i, depth, ("&&", "and"), expr_not, Expr::And)
}

/// `sub (op sub)*`, `op` the symbol or the keyword of `ops`: one operand alone, or all of them
/// joined by `join`.
fn chain<'a>(
    i: &'a str,
    depth: usize,
    ops: (&'static str, &'static str),
    sub: fn(&'a str, usize) -> Res<'a, Expr>,
    join: fn(Vec<Expr>) -> Expr,
) -> Res<'a, Expr> {
    let (mut i, first) = sub(i, depth)?;
    let mut xs = vec![first];
    loop {
        let (j, _) = multispace0(i)?;
        match alt((tag(ops.0), keyword(ops.1)))(j) {
            Ok((k, op)) => {
                let (k, x) = need(sub(k, depth), k, op)?;
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
            join(xs)
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
    let name = segs.join(".");
    match op {
        Op::In => {
            let at = skip_ws(k);
            let (k, set) = set(k)?;
            if let Err(msg) = set.iter().try_for_each(|l| fits(&f, &name, op_text, l)) {
                return failure(at, msg);
            }
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
            let at = skip_ws(k);
            if matches!(c, CmpOp::Lt | CmpOp::Le | CmpOp::Gt | CmpOp::Ge) {
                if let Some(ty) = top_ty(&f).filter(|t| !t.is_ordered()) {
                    return failure(
                        start,
                        format!(
                            "`{name}` is {}: `{op_text}` does not apply (use == or !=)",
                            ty.describe()
                        ),
                    );
                }
            }
            let (k, lit) = value(k, op_text)?;
            if let Err(msg) = fits(&f, &name, op_text, &lit) {
                return failure(at, msg);
            }
            let lit = normalize(&f, lit);
            Ok((k, Expr::Test(Test::Cmp(f, c, lit))))
        }
    }
}

/// The type of what `f` reads, when it is a record-level key as such (not a path below one, nor
/// a name that may be a field's too).
fn top_ty(f: &FieldRef) -> Option<Ty> {
    (f.rest.is_empty() && f.fallback.is_none()).then(|| f.key.ty())
}

/// A literal of the wrong kind is a mistake, said at once rather than matching nothing or
/// anything: text compared with a number key (`n == abc` never holds), a number with the hex
/// text of bytes (`raw > 5` would read the hex digits as a decimal number).
fn fits(f: &FieldRef, name: &str, op: &str, lit: &Lit) -> Result<(), String> {
    let text = matches!(lit.kind, LitKind::Str | LitKind::Word | LitKind::Bool(_));
    match top_ty(f) {
        Some(ty) if ty.is_number() && text => Err(format!(
            "`{name}` is {}: `{name} {op} {}` can never hold",
            ty.describe(),
            lit.text
        )),
        Some(Ty::Hex) if lit.numeric() => Err(format!(
            "`{name}` is {}: compare it with hex text in quotes (`{name} contains \"0500\"`)",
            Ty::Hex.describe()
        )),
        _ => Ok(()),
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
