//! `aptscope --version` names the commit it was built from; build.rs, whose functions are
//! included here, says the version alone when git answers nothing (a crates.io tarball).

mod common;

#[allow(dead_code)] // Its `main` is the build script's.
#[path = "../build.rs"]
mod build;

use common::aptscope;
use std::path::Path;
use std::process::Command;

/// `git ARGS` in the repository, trimmed; panics when it fails (the tests run in a clone).
fn git(args: &[&str]) -> String {
    let o = Command::new("git")
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run git");
    assert!(
        o.status.success(),
        "git {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout)
        .expect("UTF-8")
        .trim()
        .to_owned()
}

#[test]
fn version_names_the_commit_and_its_date() {
    let (out, err, ok) = aptscope(&["--version"], None);
    assert!(ok, "{err}");
    let commit = git(&["rev-parse", "--short", "HEAD"]);
    let date = git(&["log", "-1", "--format=%cs"]);
    assert_eq!(
        out,
        format!("aptscope {} ({commit} {date})\n", env!("CARGO_PKG_VERSION"))
    );
}

#[test]
fn without_git_the_version_stands_alone() {
    let nothing = |_: &[&str]| None;
    assert_eq!(
        build::describe("0.1.0", &nothing),
        ("0.1.0".to_owned(), None)
    );
    // A commit without a date (a git that cannot read the log) is not half shown either.
    let commit_only = |a: &[&str]| (a[0] == "rev-parse").then(|| "a94ef7b".to_owned());
    assert_eq!(build::describe("0.1.0", &commit_only).0, "0.1.0");
    let both = |a: &[&str]| {
        Some(
            if a[0] == "rev-parse" {
                "a94ef7b"
            } else {
                "2026-12-02"
            }
            .to_owned(),
        )
    };
    assert_eq!(
        build::describe("0.1.0", &both),
        (
            "0.1.0 (a94ef7b 2026-12-02)".to_owned(),
            Some("2026-12-02".to_owned())
        )
    );
}

#[test]
fn a_folder_without_dot_git_asks_git_nothing() {
    // A tarball unpacked inside another repository: git would answer with that one's commit.
    let dir = common::Scratch::new("no-git");
    assert_eq!(
        build::git(dir.path(), &["rev-parse", "--short", "HEAD"]),
        None
    );
    assert!(build::watched(dir.path(), &|a| build::git(dir.path(), a)).is_empty());
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    assert_eq!(
        build::git(root, &["rev-parse", "--short", "HEAD"]),
        Some(git(&["rev-parse", "--short", "HEAD"]))
    );
}

#[test]
fn the_build_reruns_when_head_or_its_branch_moves() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let watched = build::watched(root, &|a| build::git(root, a));
    let abs = |p: &str| {
        let p = Path::new(p);
        let p = if p.is_absolute() {
            p.to_path_buf()
        } else {
            root.join(p)
        };
        std::fs::canonicalize(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
    };
    let head = abs(&git(&["rev-parse", "--git-path", "HEAD"]));
    assert!(watched.iter().any(|w| abs(w) == head), "{watched:?}");
    let o = Command::new("git")
        .args(["symbolic-ref", "-q", "HEAD"])
        .current_dir(root)
        .output()
        .expect("run git");
    // Empty on a detached HEAD: then HEAD's own file holds the commit.
    let branch = String::from_utf8_lossy(&o.stdout).trim().to_owned();
    if !branch.is_empty() {
        let r = root.join(git(&["rev-parse", "--git-path", &branch]));
        // A branch only in packed-refs: its loose file appears in this folder on a commit.
        let r = if r.exists() {
            r
        } else {
            r.parent().expect("refs folder").to_path_buf()
        };
        let r = std::fs::canonicalize(r).expect("the ref's path");
        assert!(watched.iter().any(|w| abs(w) == r), "{watched:?}");
    }
}
