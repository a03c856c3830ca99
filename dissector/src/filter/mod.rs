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
//! Fields name NDJSON keys (the list is [`crate::shape::KEYS`]), with a few aliases: `apt.chan` is `channel`, `ts` is `ts_ns` in
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

mod ast;
mod eval;
mod keys;
mod lexer;
mod matcher;
mod parser;
#[cfg(test)]
mod tests;

pub use matcher::Matcher;

use crate::fields::Fields;
use crate::table::Table;
use ast::Expr;
use lexer::{column, skip_ws, token, unexpected};
use nom::Err as NomErr;
use parser::expr_or;
use std::fmt;

/// A compiled display filter.
#[derive(Clone, Debug)]
pub struct Filter {
    expr: Expr,
    text: String,
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
        Matcher::new(&self.expr)
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
