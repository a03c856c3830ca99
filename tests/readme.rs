//! The README's and docs/'s example outputs are the binary's: a fenced block after
//! `<!-- output: COMMAND -->` is what COMMAND prints, and in a block after `<!-- output -->`
//! each `$ COMMAND` line is followed by what it prints. Each COMMAND runs in `sh` from the
//! repository root with this build's `aptscope` first on PATH; trailing blanks are not compared
//! (editors strip them). A difference fails with the new text;
//! `APTSCOPE_UPDATE_README=1 cargo test --test readme` writes it into README.md instead.

use std::path::Path;
use std::process::Command;

/// One marked block: where its content lines are in the README, and the commands with what the
/// README says they print.
struct Block {
    /// Index of the first content line (after the opening fence).
    start: usize,
    /// Index of the closing fence.
    end: usize,
    /// `$ COMMAND` lines in the block (else the marker names the one command).
    transcript: bool,
    /// Each command with the lines it prints (as the README has them).
    runs: Vec<(String, Vec<String>)>,
}

/// The marked blocks of `lines`.
fn blocks(lines: &[&str]) -> Vec<Block> {
    let mut out = vec![];
    for (i, l) in lines.iter().enumerate() {
        let Some(marker) = l
            .trim()
            .strip_prefix("<!-- output")
            .and_then(|m| m.strip_suffix("-->"))
        else {
            continue;
        };
        assert!(
            lines.get(i + 1).is_some_and(|f| f.starts_with("```")),
            "line {}: a fenced block must follow the output marker",
            i + 1
        );
        let start = i + 2;
        let end = start
            + lines[start..]
                .iter()
                .position(|f| f.starts_with("```"))
                .unwrap_or_else(|| panic!("line {}: the block is not closed", i + 2));
        let content = &lines[start..end];
        let cmd = marker.trim().strip_prefix(':');
        let runs = match cmd {
            // The whole block is one command's output.
            Some(cmd) => vec![(
                cmd.trim().to_owned(),
                content.iter().map(|s| s.to_string()).collect(),
            )],
            // `$ COMMAND` lines, each followed by its output.
            None => {
                assert!(
                    marker.trim().is_empty()
                        && content.first().is_some_and(|c| c.starts_with("$ ")),
                    "line {}: `<!-- output -->` blocks start with a `$ COMMAND` line",
                    i + 1
                );
                let mut runs: Vec<(String, Vec<String>)> = vec![];
                for c in content {
                    match c.strip_prefix("$ ") {
                        Some(cmd) => runs.push((cmd.to_owned(), vec![])),
                        None => runs
                            .last_mut()
                            .expect("a command first")
                            .1
                            .push(c.to_string()),
                    }
                }
                runs
            }
        };
        out.push(Block {
            start,
            end,
            transcript: cmd.is_none(),
            runs,
        });
    }
    out
}

/// What `cmd` prints (stdout; a command shows stderr with `2>&1`), line by line. Its exit
/// status is not looked at: the README shows error messages too.
fn run(root: &Path, cmd: &str) -> Vec<String> {
    let bin = Path::new(env!("CARGO_BIN_EXE_aptscope"))
        .parent()
        .expect("the binary's folder")
        .display()
        .to_string();
    let path = match std::env::var("PATH") {
        Ok(p) => format!("{bin}:{p}"),
        Err(_) => bin,
    };
    let o = Command::new("sh")
        .args(["-c", cmd])
        .current_dir(root)
        .env("PATH", path)
        .output()
        .unwrap_or_else(|e| panic!("sh -c {cmd}: {e}"));
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .map(str::to_owned)
        .collect()
}

fn trimmed(lines: &[String]) -> Vec<&str> {
    lines.iter().map(|l| l.trim_end()).collect()
}

/// README.md and the chapters of docs/: the pages whose marked outputs are checked.
fn pages(root: &Path) -> Vec<String> {
    let mut v = vec!["README.md".to_string()];
    let mut docs: Vec<String> = std::fs::read_dir(root.join("docs"))
        .expect("docs/")
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.ends_with(".md"))
        .map(|n| format!("docs/{n}"))
        .collect();
    docs.sort();
    v.extend(docs);
    v
}

#[test]
fn the_readme_shows_what_the_binary_prints() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut failures = vec![];
    let mut marked = 0;
    for page in pages(root) {
        let text = std::fs::read_to_string(root.join(&page)).expect("page");
        let lines: Vec<&str> = text.lines().collect();
        let blocks = blocks(&lines);
        marked += blocks.len();
        let mut page_failures = vec![];
        let mut updated: Vec<String> = lines.iter().map(|s| s.to_string()).collect();
        // From the end, so that a block that changes length moves none still to do.
        for b in blocks.iter().rev() {
            let mut new = vec![];
            for (cmd, want) in &b.runs {
                let got = run(root, cmd);
                if trimmed(&got) != trimmed(want) {
                    page_failures.push(format!(
                        "{page}:{}: `{cmd}` now prints:\n{}\n",
                        b.start + 1,
                        got.join("\n")
                    ));
                }
                if b.transcript {
                    new.push(format!("$ {cmd}"));
                }
                new.extend(got.iter().map(|l| l.trim_end().to_owned()));
            }
            updated.splice(b.start..b.end, new);
        }
        if page_failures.is_empty() {
            continue;
        }
        page_failures.reverse();
        if std::env::var("APTSCOPE_UPDATE_README").as_deref() == Ok("1") {
            let mut text = updated.join("\n");
            text.push('\n');
            std::fs::write(root.join(&page), text).expect("write the page");
            eprintln!("{page} updated:\n{}", page_failures.join("\n"));
            continue;
        }
        failures.extend(page_failures);
    }
    assert!(marked >= 4, "the marked outputs are gone");
    assert!(
        failures.is_empty(),
        "the example outputs differ from the binary's (APTSCOPE_UPDATE_README=1 writes these \
         into the pages):\n\n{}",
        failures.join("\n")
    );
}

#[test]
fn marked_blocks_are_found_in_both_forms() {
    let text =
        "a\n<!-- output: echo x -->\n```\nx\n```\n<!-- output -->\n```\n$ echo y\ny\n$ true\n```\n";
    let lines: Vec<&str> = text.lines().collect();
    let b = blocks(&lines);
    assert_eq!(b.len(), 2);
    assert_eq!((b[0].start, b[0].end), (3, 4));
    assert_eq!(b[0].runs, [("echo x".to_owned(), vec!["x".to_owned()])]);
    assert!(!b[0].transcript && b[1].transcript);
    assert_eq!(
        b[1].runs,
        [
            ("echo y".to_owned(), vec!["y".to_owned()]),
            ("true".to_owned(), vec![])
        ]
    );
}
