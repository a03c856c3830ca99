//! The lexer: parse errors, tokens, keywords and literals (nom).

use super::ast::{Lit, LitKind, N};
use nom::bytes::complete::{tag, tag_no_case, take_while, take_while1};
use nom::character::complete::{char as nchar, digit1, hex_digit1};
use nom::combinator::{opt, recognize};
use nom::error::{ErrorKind, ParseError};
use nom::sequence::pair;
use nom::{Err as NomErr, IResult};

/// A parse error: where, and (for hard errors) what.
#[derive(Debug)]
pub(super) struct PErr<'a> {
    pub(super) at: &'a str,
    pub(super) msg: Option<String>,
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

pub(super) type Res<'a, T> = IResult<&'a str, T, PErr<'a>>;

pub(super) fn failure<'a, T>(at: &'a str, msg: impl Into<String>) -> Res<'a, T> {
    Err(NomErr::Failure(PErr {
        at,
        msg: Some(msg.into()),
    }))
}

pub(super) fn soft<T>(at: &str) -> Res<'_, T> {
    Err(NomErr::Error(PErr { at, msg: None }))
}

pub(super) fn column(src: &str, rest: &str) -> usize {
    let off = src.len().saturating_sub(rest.len());
    src.get(..off).map_or(1, |p| p.chars().count() + 1)
}

pub(super) fn skip_ws(i: &str) -> &str {
    i.trim_start()
}

pub(super) fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// The token at `i`, for messages.
pub(super) fn token(i: &str) -> String {
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
pub(super) fn unexpected(rest: &str) -> String {
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
pub(super) fn keyword<'a>(kw: &'static str) -> impl FnMut(&'a str) -> Res<'a, &'a str> {
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
pub(super) fn need<'a, T>(r: Res<'a, T>, at: &'a str, what: &str) -> Res<'a, T> {
    match r {
        Err(NomErr::Error(_)) => failure(skip_ws(at), format!("expected a test after `{what}`")),
        r => r,
    }
}

pub(super) fn ident(i: &str) -> Res<'_, &str> {
    recognize(pair(
        take_while1(|c: char| c.is_ascii_alphabetic() || c == '_'),
        take_while(is_ident),
    ))(i)
}

pub(super) fn string_lit(i: &str) -> Res<'_, Lit> {
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

pub(super) fn number_lit(i: &str) -> Res<'_, Lit> {
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

pub(super) fn word_lit(i: &str) -> Res<'_, Lit> {
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
