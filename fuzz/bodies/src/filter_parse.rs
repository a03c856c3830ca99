//! Display-filter parser (`Filter::parse`) on any text, and matching of what compiles against
//! real records (`records.ndjson`: APT and Elliptec frames, garbage, late diagnostics).
//!
//! Checks: parsing ends without panic; an error's column lies within the filter (1-based, in
//! characters, one past the end at most) and its caret rendering works; a filter that compiles
//! gives back its text, compiles again from it, and evaluates on every record without panic,
//! the same way twice; `!(f)` matches exactly the records `f` does not.

use aptscope_dissector::filter::Filter;
use std::sync::OnceLock;

fn records() -> &'static [serde_json::Value] {
    static R: OnceLock<Vec<serde_json::Value>> = OnceLock::new();
    R.get_or_init(|| {
        include_str!("../../records.ndjson")
            .lines()
            .map(|l| serde_json::from_str(l).expect("records.ndjson"))
            .collect()
    })
}

/// The target's body: panics when a check fails.
pub fn fuzz(data: &[u8]) {
    let Ok(src) = std::str::from_utf8(data) else {
        return;
    };
    match Filter::parse(src) {
        Err(e) => {
            let chars = src.chars().count();
            assert!(
                e.column >= 1 && e.column <= chars + 1,
                "column {} outside a filter of {chars} characters: {src:?}",
                e.column
            );
            let _ = e.caret(src);
            let _ = e.to_string();
        }
        Ok(f) => {
            assert_eq!(f.as_str(), src);
            let again = Filter::parse(f.as_str()).expect("a filter that compiled compiles again");
            let neg = Filter::parse(&format!("!({src}\n)"));
            for r in records() {
                let m = f.matches(r);
                assert_eq!(
                    m,
                    again.matches(r),
                    "same filter, same record, other answer"
                );
                if let Ok(neg) = &neg {
                    if !src.trim().is_empty() {
                        assert_eq!(neg.matches(r), !m, "!({src}) vs {src} on {r}");
                    }
                }
            }
        }
    }
}
