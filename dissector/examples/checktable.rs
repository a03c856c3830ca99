//! Check message table files: `checktable [FILE.apt]`.
//!
//! Parses every `*.apt` file beside FILE (or in `dissector/msgs`), prints errors, then checks
//! every spec example of FILE (or of all files) against the framer and decoder.

use aptscope_dissector::spec_examples::{self, Owner};
use aptscope_dissector::Table;
use std::path::{Path, PathBuf};

fn main() {
    let arg = std::env::args().nth(1);
    let dir = match &arg {
        Some(f) => Path::new(f)
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from(".")),
        None => PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/msgs")),
    };
    let target = arg
        .as_ref()
        .and_then(|f| Path::new(f).file_name())
        .and_then(|n| n.to_str())
        .map(str::to_string);
    let mut files: Vec<PathBuf> = match std::fs::read_dir(&dir) {
        Ok(rd) => rd
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "apt"))
            .collect(),
        Err(e) => {
            eprintln!("cannot read {}: {e}", dir.display());
            std::process::exit(2);
        }
    };
    files.sort();
    let mut sources: Vec<(&'static str, &'static str)> = vec![];
    for f in &files {
        let name = f
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or("?")
            .to_string();
        let text = std::fs::read_to_string(f).unwrap_or_else(|e| {
            eprintln!("{}: {e}", f.display());
            String::new()
        });
        sources.push((
            Box::leak(name.into_boxed_str()),
            Box::leak(text.into_boxed_str()),
        ));
    }
    let mine = |file: &str| target.as_deref().is_none_or(|t| t == file);
    let table = match Table::from_sources(&sources) {
        Ok(t) => t,
        Err(errs) => {
            let (own, other): (Vec<_>, Vec<_>) = errs.iter().partition(|e| mine(&e.file));
            for e in &own {
                println!("ERROR {e}");
            }
            if !other.is_empty() {
                println!(
                    "({} error(s) in other files, not shown; those files are left out below)",
                    other.len()
                );
            }
            let bad: Vec<&str> = other.iter().map(|e| e.file.as_str()).collect();
            let kept: Vec<_> = sources
                .iter()
                .copied()
                .filter(|(n, _)| !bad.contains(n))
                .collect();
            match Table::from_sources(&kept) {
                Ok(t) if own.is_empty() => t,
                Ok(_) | Err(_) => {
                    println!(
                        "{} error(s) in {}",
                        own.len(),
                        target.as_deref().unwrap_or("the table")
                    );
                    std::process::exit(1);
                }
            }
        }
    };
    let (mut ok, mut bad) = (0, 0);
    for (owner, ex) in spec_examples::all(&table) {
        if !mine(ex.file) {
            continue;
        }
        let who = match owner {
            Owner::Msg(m) => m.name.to_string(),
            Owner::Sub(s) => format!("sub {} {}", s.group, s.name),
        };
        match spec_examples::check(&table, owner, ex) {
            Ok(()) => ok += 1,
            Err(e) => {
                bad += 1;
                println!("EXAMPLE {}:{}: {who}: {e}", ex.file, ex.line);
            }
        }
    }
    let msgs = table.msgs().iter().filter(|m| mine(m.file)).count();
    let subs = table.subs().iter().filter(|s| mine(s.file)).count();
    let forms: usize = table
        .msgs()
        .iter()
        .filter(|m| mine(m.file))
        .map(|m| m.forms.len())
        .sum();
    println!("{msgs} messages, {subs} sub-messages, {forms} message forms; examples: {ok} ok, {bad} failing");
    if bad > 0 {
        std::process::exit(1);
    }
}
