//! The README is the front door and `docs/` the reference: every link between them (and to
//! files of the repository) leads somewhere, every heading anchor a link names exists, every
//! chapter is reachable from the README, and the README stays short.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// README.md and every Markdown file of docs/.
fn pages() -> Vec<PathBuf> {
    let mut v = vec![root().join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root().join("docs"))
        .expect("docs/")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    docs.sort();
    v.extend(docs);
    v
}

/// The lines of a page outside fenced code blocks.
fn prose(text: &str) -> Vec<&str> {
    let mut fence = false;
    text.lines()
        .filter(|l| {
            if l.starts_with("```") {
                fence = !fence;
                return false;
            }
            !fence
        })
        .collect()
}

/// GitHub's anchor of a heading: lower case, punctuation dropped, spaces as dashes.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || *c == '-' || *c == ' ' || *c == '_')
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

fn anchors(text: &str) -> BTreeSet<String> {
    prose(text)
        .iter()
        .filter_map(|l| {
            l.trim_start_matches('#')
                .strip_prefix(' ')
                .filter(|_| l.starts_with('#'))
        })
        .map(slug)
        .collect()
}

/// `[label](target)` links of a page's prose (inline code spans left out).
fn links(text: &str) -> Vec<String> {
    let mut out = vec![];
    for l in prose(text) {
        // Drop inline code: `[x](y)` there is an example, not a link.
        let mut clean = String::new();
        let mut code = false;
        for c in l.chars() {
            if c == '`' {
                code = !code;
            } else if !code {
                clean.push(c);
            }
        }
        let mut rest = clean.as_str();
        while let Some(i) = rest.find("](") {
            let after = &rest[i + 2..];
            let Some(j) = after.find(')') else { break };
            out.push(after[..j].to_string());
            rest = &after[j..];
        }
    }
    out
}

#[test]
fn every_link_leads_somewhere() {
    let mut broken = vec![];
    for page in pages() {
        let text = std::fs::read_to_string(&page).expect("page");
        let dir = page.parent().expect("dir");
        for target in links(&text) {
            if target.starts_with("http://") || target.starts_with("https://") {
                continue;
            }
            let (file, anchor) = target.split_once('#').unwrap_or((&target, ""));
            let path = if file.is_empty() {
                page.clone()
            } else {
                dir.join(file)
            };
            if !path.exists() {
                broken.push(format!("{}: {target}: no such file", page.display()));
                continue;
            }
            if !anchor.is_empty() && path.extension().is_some_and(|x| x == "md") {
                let t = std::fs::read_to_string(&path).expect("target");
                if !anchors(&t).contains(anchor) {
                    broken.push(format!("{}: {target}: no such heading", page.display()));
                }
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

#[test]
fn every_chapter_is_linked_from_the_readme_and_the_readme_is_short() {
    let readme = std::fs::read_to_string(root().join("README.md")).expect("README");
    let linked: BTreeSet<String> = links(&readme).into_iter().collect();
    for page in pages().iter().skip(1) {
        let name = page.file_name().and_then(|n| n.to_str()).expect("name");
        if name == "SUMMARY.md" || name == "README.md" {
            continue;
        }
        assert!(
            linked
                .iter()
                .any(|l| l.starts_with(&format!("docs/{name}"))),
            "docs/{name} is not linked from the README"
        );
    }
    let n = readme.lines().count();
    assert!(
        n <= 300,
        "the README has {n} lines: the reference belongs in docs/"
    );
}

#[test]
fn anchors_are_read_as_github_makes_them() {
    assert_eq!(
        slug("Live traffic: simulators and taps"),
        "live-traffic-simulators-and-taps"
    );
    assert_eq!(slug("Set-up"), "set-up");
    let t = "# A\n```\n# not a heading\n```\n## B `c`\nsee [x](#a) and `[y](#nowhere)`\n";
    assert_eq!(
        anchors(t),
        BTreeSet::from(["a".to_string(), "b-c".to_string()])
    );
    assert_eq!(links(t), vec!["#a".to_string()]);
}
