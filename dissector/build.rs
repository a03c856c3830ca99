//! Collects the message table files (`msgs/*.apt`) into `OUT_DIR/sources.rs` so the library
//! embeds them all, and warns about table errors early (the library's tests refuse them).

#[allow(dead_code)]
#[path = "src/table/model.rs"]
mod model;
#[allow(dead_code)]
#[path = "src/table/parse.rs"]
mod parse;

use std::{env, fs, path::PathBuf};

fn main() {
    let dir = PathBuf::from(env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"))
        .join("msgs");
    println!("cargo:rerun-if-changed={}", dir.display());
    let mut files: Vec<PathBuf> = fs::read_dir(&dir)
        .expect("dissector/msgs exists")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "apt"))
        .collect();
    files.sort();
    let mut out = String::from("/// The table files, in order: (file name, text).\npub const SOURCES: &[(&str, &str)] = &[\n");
    let mut texts: Vec<(&'static str, &'static str)> = vec![];
    for f in &files {
        println!("cargo:rerun-if-changed={}", f.display());
        let name = f
            .file_name()
            .and_then(|n| n.to_str())
            .expect("utf-8 file name")
            .to_string();
        out.push_str(&format!(
            "    ({name:?}, include_str!({:?})),\n",
            f.display().to_string()
        ));
        let text = fs::read_to_string(f).expect("table file is UTF-8");
        texts.push((
            Box::leak(name.into_boxed_str()),
            Box::leak(text.into_boxed_str()),
        ));
    }
    out.push_str("];\n");
    let dest = PathBuf::from(env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("sources.rs");
    fs::write(dest, out).expect("write sources.rs");
    match parse::parse_sources(&texts) {
        Ok(data) => write_ids(&data),
        Err(errs) => {
            for e in errs.iter().take(20) {
                println!("cargo:warning=message table: {e}");
            }
        }
    }
}

/// `OUT_DIR/msg_ids.rs`: each message's id as a constant named as the table names it
/// (`HW_GET_INFO`), and each sub-message's id in a module per group (`la::SETPOINT`), so code
/// that names a message is checked by the compiler rather than by a lookup at run time.
fn write_ids(data: &model::TableData) {
    let mut out = String::new();
    let mut seen = std::collections::BTreeMap::new();
    for m in &data.msgs {
        if let Some(old) = seen.insert(m.name, m.id) {
            assert_eq!(old, m.id, "{} names two ids", m.name);
            continue;
        }
        out.push_str(&format!(
            "/// `MGMSG_{}` (0x{:04X}): {}\npub const {}: u16 = 0x{:04X};\n",
            m.name,
            m.id,
            m.doc.replace('\n', " "),
            m.name,
            m.id
        ));
    }
    let mut groups: Vec<&str> = data.subs.iter().map(|s| s.group).collect();
    groups.dedup();
    for g in groups {
        out.push_str(&format!(
            "/// Sub-message ids of the `{g}` group.\npub mod {g} {{\n"
        ));
        for s in data.subs.iter().filter(|s| s.group == g) {
            out.push_str(&format!(
                "    /// {} (sub-message {}): {}\n    pub const {}: u16 = {};\n",
                s.name,
                s.id,
                s.doc.replace('\n', " "),
                s.name.to_ascii_uppercase(),
                s.id
            ));
        }
        out.push_str("}\n");
    }
    let dest = PathBuf::from(env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("msg_ids.rs");
    fs::write(dest, out).expect("write msg_ids.rs");
}
