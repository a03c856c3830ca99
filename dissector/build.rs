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
    if let Err(errs) = parse::parse_sources(&texts) {
        for e in errs.iter().take(20) {
            println!("cargo:warning=message table: {e}");
        }
    }
}
