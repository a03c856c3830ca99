//! Filters read typed records exactly as they read the NDJSON `decode --json` writes: the
//! `Fields` implementation on `Record` and the one on `serde_json::Value` agree, on every
//! sample, for every key, operator and kind of value.

use aptscope_dissector::detect::Proto;
use aptscope_dissector::fields::{Fields, Num, Role, Val, KEYS};
use aptscope_dissector::filter::Filter;
use aptscope_dissector::pipeline::{Format, Renderer};
use aptscope_dissector::record::{Ctx, Decoder, Record};
use aptscope_dissector::table::Dir;
use std::path::Path;

const FILTERS: &[&str] = &[
    "apt",
    "ell",
    "diag",
    "unpaired",
    "paired",
    "apt.diag",
    "ell.unpaired",
    "apt.paired",
    "n > 3",
    "n in {1 2 3}",
    "offset == 0",
    "offset > 0x20",
    "cap_offset > 10",
    "len == 6",
    "len >= 20",
    "raw contains \"05\"",
    "raw ~ \"^9\"",
    "type == frame",
    "type == garbage",
    "type == diag",
    "proto == apt",
    "proto == ell",
    "dir == host",
    "dir == device",
    "dir == unknown",
    "dir != h2d",
    "ts > 0.001",
    "ts < 1s",
    "ts_ns > 1000",
    "stream == 1",
    "stream != 0",
    "latency > 0",
    "latency < 5ms",
    "latency_ms >= 1",
    "pair",
    "pair > 2",
    "ref > 0",
    "ref",
    "interim",
    "diag.kind == garbage",
    "diag.kind in {no_reply truncated unknown_id length_mismatch}",
    "diag.offset > 3",
    "diag.msg contains byte",
    "diag == no_reply",
    "diag.kind ~ \"^un\"",
    "apt.msgid == 0x0491",
    "apt.msgid_hex == 0x0491",
    "apt.msgid_hex ~ \"^0x04\"",
    "apt.name ~ MOT_",
    "apt.name",
    "!apt.name",
    "apt.name != MOT_MOVE_HOME",
    "apt.name > M",
    "apt.msg_dir == d2h",
    "apt.msg_dir == host",
    "apt.src == usb",
    "apt.src == 0x50",
    "apt.src.bay == 1",
    "apt.src.name ~ bay",
    "apt.dst == bay1",
    "apt.dst > 0x21",
    "apt.dst contains ba",
    "apt.dst ~ \"^h\"",
    "apt.dst in {host usb}",
    "apt.data_flag",
    "apt.data_flag == false",
    "apt.data_len > 10",
    "apt.form_note contains long",
    "apt.form_note",
    "apt.chan == 1",
    "apt.channel > 1",
    "apt.sub",
    "apt.sub == 1",
    "apt.sub.name ~ \"^S\"",
    "apt.sub.id > 3",
    "apt.fields",
    "apt.fields.position > 0",
    "apt.position < 0",
    "apt.position",
    "apt.fields.status_bits contains HOMED",
    "apt.fields.status_bits ~ MOVING",
    "apt.fields.status_bits != ENABLED",
    "apt.fields.status_bits > 1024",
    "apt.fields.status_bits",
    "apt.fields.chan_ident == CH1",
    "apt.fields.chan_ident == 1",
    "apt.fields.enable_state == 1",
    "apt.fields.enable_state == ENABLE",
    "apt.fields.enable_state != 2",
    "apt.fields.hw_type ~ DC",
    "apt.fields.hw_type in {16 44}",
    "apt.fields.serial_number > 1000",
    "apt.fields.model_number contains 1",
    "apt.fields.internal contains 00",
    "apt.phys",
    "apt.phys.setpoint > 1",
    "apt.phys.setpoint.unit == \"%\"",
    "apt.phys.position",
    "apt.codes",
    "apt.codes.status_bits > 0",
    "apt.codes.hw_type",
    "apt.codes.enable_state == 1",
    "apt.pair_other_address",
    "apt.latency > 1ms",
    "apt.ts > 0",
    "apt.stream == 0",
    "apt.dir == tx",
    "ell.addr == 0",
    "ell.addr == 2",
    "ell.cmd == GS",
    "ell.cmd ~ \"^g\"",
    "ell.cmd contains S",
    "ell.name == POSITION",
    "ell.name",
    "ell.text ~ PO",
    "ell.fields.status == 12",
    "ell.status == OUT_OF_RANGE",
    "ell.status != 0",
    "ell.status != OK",
    "ell.status > 5",
    "ell.status ~ OUT",
    "ell.fields.status in {9 12}",
    "ell.codes.status > 0",
    "ell.codes",
    "ell.module == ELL14",
    "ell.module.serial contains 11",
    "ell.module.first_addr == 0",
    "ell.module.model",
    "ell.phys.position > 10",
    "ell.phys.position.unit == deg",
    "ell.phys",
    "ell.fields",
    "ell.fields.model_name == ELL9",
    "ell.fields.firmware_version ~ \"\\\\.\"",
    "ell.fields.thread == metric",
    "ell.fields.hw_release > 0",
    "ell.fields.serial > 1",
    "ell.fields.year >= 2022",
    "ell.fields.new_address == 5",
    "ell.fields.velocity > 50",
    "ell.position > 100",
    "ell.interim",
    "ell.latency > 1ms",
    "ell.dir == rx",
    "ell.raw ~ \"0d0a$\"",
    "!(n < 5) && dir == d2h",
    "apt.name ~ GET && (apt.chan == 1 || apt.src == bay1)",
];

fn sample(name: &str) -> Vec<u8> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../samples")
        .join(name);
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// A number or word a record has at hand ([`Fields::number`], [`Fields::word`]) is exactly
/// the one plain value its visit gives.
fn at_hand_is_what_visit_gives(rec: &Record<'_>) -> Result<(), String> {
    for def in KEYS {
        let want = match (rec.number(def.key), rec.word(def.key)) {
            (Some(x), _) => format!("{:?}", Val::Num(Num::I(i128::from(x)))),
            (None, Some(w)) => format!("{:?}", Val::Str(w.into())),
            (None, None) => continue,
        };
        let mut got = vec![];
        let there = rec.visit(def.key, &[], &mut |v, r| got.push(format!("{v:?} {r:?}")));
        if !there || got != [format!("{want} {:?}", Role::Plain)] {
            return Err(format!(
                "{}: at hand {want}, visit {there} {got:?}",
                def.name
            ));
        }
    }
    Ok(())
}

/// Every key of a decoded record holds a value of the type the shape gives it
/// ([`Key::ty`](aptscope_dissector::shape::Key::ty)), which filters check literals against.
fn types_are_the_shapes(v: &serde_json::Value) -> Result<(), String> {
    use aptscope_dissector::shape::{Key, Ty};
    use serde_json::Value as J;
    let Some(obj) = v.as_object() else {
        return Err("not an object".into());
    };
    for (name, val) in obj {
        // Keys of the other record types (detect, input …) are not the shape's.
        let Some(def) = KEYS.iter().find(|d| d.name == name) else {
            continue;
        };
        let ok = match (def.key.ty(), val) {
            (_, J::Null) => def.key == Key::Name,
            (Ty::UInt, J::Number(n)) => n.is_u64(),
            (Ty::Int, J::Number(n)) => n.is_i64() || n.is_u64(),
            (Ty::Float, J::Number(_)) | (Ty::Bool, J::Bool(_)) => true,
            (Ty::Word | Ty::Text, J::String(_)) => true,
            (Ty::Hex, J::String(s)) => s.len() % 2 == 0 && s.bytes().all(|c| c.is_ascii_hexdigit()),
            (Ty::Address, J::Object(o)) => o.get("addr").is_some_and(J::is_u64),
            (Ty::Object, J::Object(_)) | (Ty::List, J::Array(_)) => true,
            _ => false,
        };
        if !ok {
            return Err(format!("`{name}` is not {:?}: {val}", def.key.ty()));
        }
    }
    Ok(())
}

/// Decode `bytes` as one timed stream, and as two streams (the bytes on each, interleaved;
/// the second one captured device→host), checking every filter on every record both ways.
/// Returns the records seen and how many each filter matched.
fn check(bytes: &[u8], proto: Option<Proto>, filters: &[Filter]) -> (usize, Vec<usize>) {
    let mut seen = 0usize;
    let mut hits = vec![0usize; filters.len()];
    let matchers: Vec<_> = filters.iter().map(Filter::matcher).collect();
    for layout in 0..2 {
        let mut dec = Decoder::new(proto);
        let mut r = Renderer::new(Format::Json);
        let mut each = |rec: &Record<'_>| -> Result<(), String> {
            let line = r.line(rec).to_string();
            let v: serde_json::Value =
                serde_json::from_str(&line).map_err(|e| format!("{e}: {line}"))?;
            seen += 1;
            at_hand_is_what_visit_gives(rec).map_err(|e| format!("{e}: {line}"))?;
            types_are_the_shapes(&v).map_err(|e| format!("{e}: {line}"))?;
            for ((f, m), h) in filters.iter().zip(&matchers).zip(hits.iter_mut()) {
                let typed = f.matches(rec);
                if typed != f.matches(&v) {
                    return Err(format!("`{f}`: typed {typed}, JSON {}: {line}", !typed));
                }
                if typed != m.matches(rec) {
                    return Err(format!("`{f}`: typed {typed}, matcher {}: {line}", !typed));
                }
                *h += usize::from(typed);
            }
            Ok(())
        };
        let step = 7 + layout * 50;
        for (i, c) in bytes.chunks(step).enumerate() {
            let ts_ns = Some(1_000_000 * i as u64);
            let mut ctxs = vec![Ctx {
                stream: 0,
                dir: None,
                ts_ns,
            }];
            if layout == 1 {
                ctxs.push(Ctx {
                    stream: 1,
                    dir: Some(Dir::DeviceToHost),
                    ts_ns,
                });
            }
            for ctx in ctxs {
                if let Err(e) = dec.push(ctx, c, &mut each) {
                    panic!("{e}");
                }
            }
        }
        if let Err(e) = dec.finish(&mut each) {
            panic!("{e}");
        }
    }
    (seen, hits)
}

#[test]
fn typed_records_and_their_ndjson_match_the_same_filters() {
    let filters: Vec<Filter> = FILTERS
        .iter()
        .map(|s| Filter::parse(s).unwrap_or_else(|e| panic!("{s}: {e}")))
        .collect();
    let t = aptscope_dissector::Table::global();
    let inputs: Vec<(String, Vec<u8>, Option<Proto>)> = vec![
        ("kdc101".into(), sample("kdc101-session.bin"), None),
        ("damaged".into(), sample("damaged.bin"), None),
        ("bsc203".into(), sample("sessions/bsc203.bin"), None),
        ("kpz101".into(), sample("sessions/kpz101.bin"), None),
        ("session kdc101".into(), sample("sessions/kdc101.bin"), None),
        (
            "elliptec".into(),
            sample("elliptec-bus.txt"),
            Some(Proto::Elliptec),
        ),
        (
            "every form".into(),
            aptscope_dissector::synth::stream(t, 7, 3000, true),
            Some(Proto::Apt),
        ),
    ];
    let (mut seen, mut hits) = (0, 0);
    for (name, bytes, proto) in &inputs {
        let (s, h) = check(bytes, *proto, &filters);
        assert!(s > 10, "{name}: only {s} records");
        seen += s;
        hits += h.iter().sum::<usize>();
    }
    // Not a vacuous agreement: the filters do select records, and not all of them.
    assert!(hits > seen, "{hits} matches over {seen} records");
    assert!(
        hits < seen * filters.len() / 2,
        "{hits} of {}",
        seen * filters.len()
    );
}

/// Every filter in the list selects something somewhere (else it tests nothing).
#[test]
fn every_listed_filter_selects_some_record() {
    let t = aptscope_dissector::Table::global();
    let mut bytes = sample("kdc101-session.bin");
    bytes.extend(sample("sessions/bsc203.bin"));
    bytes.extend(sample("sessions/kpz101.bin"));
    bytes.extend(sample("damaged.bin"));
    bytes.extend(aptscope_dissector::synth::stream(t, 7, 3000, true));
    let ell = sample("elliptec-bus.txt");
    let filters: Vec<Filter> = FILTERS
        .iter()
        .map(|s| Filter::parse(s).unwrap_or_else(|e| panic!("{s}: {e}")))
        .collect();
    let (_, a) = check(&bytes, Some(Proto::Apt), &filters);
    let (_, e) = check(&ell, Some(Proto::Elliptec), &filters);
    let dead: Vec<&str> = FILTERS
        .iter()
        .zip(a.iter().zip(&e))
        .filter(|(_, (a, e))| **a + **e == 0)
        .map(|(s, _)| *s)
        .collect();
    assert!(dead.is_empty(), "filters that select nothing: {dead:?}");
}
