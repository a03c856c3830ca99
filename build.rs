//! Names the commit the binary was built from in `aptscope --version` (`0.1.0 (a94ef7b
//! 2026-12-02)`), read with git when the crate is built in its own repository; a build without
//! git or without `.git` (a crates.io tarball) says the version alone. `tests/version.rs` runs
//! these functions too.

use std::path::Path;
use std::process::Command;

fn main() {
    let dir = std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR");
    let version = std::env::var("CARGO_PKG_VERSION").expect("cargo sets CARGO_PKG_VERSION");
    let dir = Path::new(&dir);
    let git = |args: &[&str]| git(dir, args);
    let (long, date) = describe(&version, &git);
    println!("cargo:rustc-env=APTSCOPE_VERSION={long}");
    println!(
        "cargo:rustc-env=APTSCOPE_COMMIT_DATE={}",
        date.unwrap_or_default()
    );
    println!("cargo:rerun-if-changed=build.rs");
    for p in watched(dir, &git) {
        println!("cargo:rerun-if-changed={p}");
    }
}

/// The output of `git ARGS` run in `dir`, trimmed; `None` when git is missing, fails or prints
/// nothing, or when `dir` is not the top of a repository (a tarball unpacked inside another
/// project's repository must not take that project's commit).
pub(crate) fn git(dir: &Path, args: &[&str]) -> Option<String> {
    if !dir.join(".git").exists() {
        return None;
    }
    let o = Command::new("git")
        .arg("-C")
        .arg(dir)
        .args(args)
        .output()
        .ok()?;
    let s = String::from_utf8(o.stdout).ok()?.trim().to_owned();
    (o.status.success() && !s.is_empty()).then_some(s)
}

/// The version as `--version` shows it, and the commit's date: `0.1.0 (a94ef7b 2026-12-02)`,
/// or `0.1.0` and no date when `git` answers nothing.
pub(crate) fn describe(
    version: &str,
    git: &dyn Fn(&[&str]) -> Option<String>,
) -> (String, Option<String>) {
    match (
        git(&["rev-parse", "--short", "HEAD"]),
        git(&["log", "-1", "--format=%cs"]),
    ) {
        (Some(commit), Some(date)) => (format!("{version} ({commit} {date})"), Some(date)),
        _ => (version.to_owned(), None),
    }
}

/// The files that change when HEAD moves to another commit: HEAD itself (a checkout) and the
/// branch it points at (a commit): its loose ref, or the folder where git writes it when it is
/// only in packed-refs, and packed-refs. git gives the paths, as a worktree keeps its HEAD apart
/// from the shared refs. Only existing paths: cargo reruns a build script whose watched path is
/// missing on every build.
pub(crate) fn watched(dir: &Path, git: &dyn Fn(&[&str]) -> Option<String>) -> Vec<String> {
    let path = |p: &str| git(&["rev-parse", "--git-path", p]).map(|g| dir.join(g));
    let mut v = vec![];
    v.extend(path("HEAD"));
    // None on a detached HEAD, which HEAD's own file holds.
    if let Some(branch) = git(&["symbolic-ref", "-q", "HEAD"]) {
        if let Some(r) = path(&branch) {
            match r.exists() {
                true => v.push(r),
                false => v.extend(r.parent().map(Path::to_path_buf)),
            }
        }
        v.extend(path("packed-refs"));
    }
    v.into_iter()
        .filter(|p| p.exists())
        .map(|p| p.display().to_string())
        .collect()
}
