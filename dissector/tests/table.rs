//! The message table against the spec: coverage of every id, every spec example, and
//! encode/decode round trips over every form.

use aptscope_dissector::apt::{AptFrame, FieldValue, Value};
use aptscope_dissector::spec_examples::{self, Owner};
use aptscope_dissector::synth::{all_forms, random_frame, Rng};
use aptscope_dissector::table::FormKind;
use aptscope_dissector::Table;

/// The ids of a fixture of spec index lines that the table lacks, and how many lines it has.
fn missing_ids(fixture: &str) -> (Vec<String>, usize) {
    let t = Table::global();
    let mut missing = vec![];
    let mut n = 0;
    for line in fixture.lines().filter(|l| !l.starts_with('#')) {
        let (id, name) = line.split_once(' ').expect("id name");
        let id = u16::from_str_radix(id.trim_start_matches("0x"), 16).expect("hex id");
        n += 1;
        if t.msg(id).is_none() {
            missing.push(format!("0x{id:04X} {name}"));
        }
    }
    (missing, n)
}

#[test]
fn every_id_in_the_spec_indexes_is_in_the_table() {
    let t = Table::global();
    let (missing, n) = missing_ids(include_str!("spec_ids.txt"));
    assert!(n > 400, "the fixture lists the spec's index lines");
    assert!(
        missing.is_empty(),
        "ids in the spec's indexes but not in the table: {missing:#?}"
    );
    assert!(t.msgs().len() >= 320, "{} messages", t.msgs().len());
}

#[test]
fn every_id_of_the_2025_revision_is_in_the_table_and_marked() {
    let t = Table::global();
    let (missing, n) = missing_ids(include_str!("spec_ids_2025.txt"));
    assert!(n > 390, "the fixture lists the 2025 spec's index lines");
    assert!(
        missing.is_empty(),
        "ids in the 2025 spec's indexes but not in the table: {missing:#?}"
    );
    // Ids the 2025 revision lists and Issue 23 does not are marked as 2025 only.
    let old: std::collections::HashSet<&str> = include_str!("spec_ids.txt")
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    let mut unmarked = vec![];
    for line in include_str!("spec_ids_2025.txt")
        .lines()
        .filter(|l| !l.starts_with('#'))
    {
        let Some(id) = line.split_whitespace().next() else {
            continue;
        };
        let Ok(v) = u16::from_str_radix(id.trim_start_matches("0x"), 16) else {
            continue;
        };
        // In Issue 23's body though not in its indexes (lines 6550 and 13295).
        if old.contains(id) || ["0x07D4", "0x08E2"].contains(&id) {
            continue;
        }
        if let Some(m) = t.msg(v) {
            if m.revs != aptscope_dissector::table::Revs::REV_2025 {
                unmarked.push(m.name);
            }
        }
    }
    unmarked.dedup();
    assert!(
        unmarked.is_empty(),
        "new in 2025 but not rev=2025: {unmarked:?}"
    );
}

#[test]
fn every_spec_example_decodes_as_the_spec_states() {
    let t = Table::global();
    let all = spec_examples::all(t);
    let mut failures = vec![];
    for (owner, ex) in &all {
        if let Err(e) = spec_examples::check(t, *owner, ex) {
            let who = match owner {
                Owner::Msg(m) => m.name.to_string(),
                Owner::Sub(s) => format!("sub {} {}", s.group, s.name),
            };
            failures.push(format!("{}:{}: {who}: {e}", ex.file, ex.line));
        }
    }
    assert!(all.len() >= 200, "only {} examples", all.len());
    assert!(
        failures.is_empty(),
        "{} of {} examples fail:\n{}",
        failures.len(),
        all.len(),
        failures.join("\n")
    );
}

#[test]
fn spec_examples_known_wrong_are_recorded_with_a_reason() {
    let t = Table::global();
    let bad: Vec<_> = spec_examples::all(t)
        .into_iter()
        .filter(|(_, e)| e.bad_reason.is_some())
        .collect();
    assert!(!bad.is_empty());
    for (_, e) in bad {
        assert!(
            e.bad_reason.is_some_and(|r| r.len() > 10),
            "{}:{} needs a real reason",
            e.file,
            e.line
        );
    }
}

fn same(v: &Value<'_>, want: &FieldValue) -> bool {
    match (v, want) {
        (Value::U(_) | Value::I(_), FieldValue::Int(w)) => v.as_i64() == Some(*w),
        (Value::F(x), FieldValue::Float(w)) => x == w,
        (Value::Str(b), FieldValue::Text(w)) => aptscope_dissector::apt::text_of(b) == w.as_str(),
        (Value::Bytes(b), FieldValue::Bytes(w)) => b == &w.as_slice(),
        (Value::Array(..), FieldValue::List(w)) => v
            .elements()
            .map(|e| e.as_f64())
            .eq(w.iter().map(|x| Some(*x))),
        _ => false,
    }
}

#[test]
fn decode_of_encode_is_identity_for_every_form() {
    let t = Table::global();
    let forms = all_forms(t);
    assert!(forms.len() > 330, "{} forms", forms.len());
    let mut r = Rng(0xA9_7500);
    for (m, form, sub) in forms {
        for _ in 0..20 {
            let (bytes, vals) = random_frame(t, &mut r, m, form, sub);
            let f = AptFrame::decode(t, 0, &bytes, false).expect("a frame");
            assert_eq!(f.msg.map(|x| x.id), Some(m.id), "{}", m.name);
            assert!(
                f.form.is_some_and(|x| std::ptr::eq(x, form)),
                "{} {:?}: decoded another form",
                m.name,
                form.kind
            );
            assert!(
                !f.has_diags(),
                "{}: {:?}",
                m.name,
                f.diags().collect::<Vec<_>>()
            );
            for (k, want) in &vals {
                let (_, got) = f
                    .field(k)
                    .unwrap_or_else(|| panic!("{}: field {k} missing", m.name));
                assert!(
                    same(&got, want),
                    "{} {k}: encoded {want:?}, decoded {got:?}",
                    m.name
                );
            }
            if form.kind != FormKind::Header {
                assert_eq!(f.bytes.len(), 6 + f.header().data_len());
            }
        }
    }
}
