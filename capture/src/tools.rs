//! External tools the tests run (tshark, tmux): one rule for when one is missing, so that a
//! bare machine cannot pass a test by skipping it.

use std::process::Command;

/// What a test does when the tool it needs is missing.
#[derive(Debug, PartialEq, Eq)]
pub enum Missing {
    /// Fail, saying how to install the tool.
    Fail,
    /// Skip, saying so.
    Skip,
}

/// In CI (`CI` set to anything but empty, `0` or `false`) a missing tool fails the test;
/// elsewhere too, unless `APTSCOPE_SKIP_MISSING_TOOLS=1` asks to skip (cargo would show a
/// silent skip as "ok").
pub fn on_missing(ci: Option<&str>, skip: Option<&str>) -> Missing {
    let ci = ci.is_some_and(|v| !matches!(v, "" | "0" | "false"));
    if !ci && skip == Some("1") {
        Missing::Skip
    } else {
        Missing::Fail
    }
}

/// Whether `tool` runs (`tool version_arg` succeeds). When it does not: `false` if the rule of
/// [`on_missing`] says skip, else a panic with how to install it (Debian package `package`).
pub fn require(tool: &str, version_arg: &str, package: &str) -> bool {
    let ok = Command::new(tool)
        .arg(version_arg)
        .output()
        .is_ok_and(|o| o.status.success());
    ok || missing(
        &format!("{tool} is not installed"),
        &format!("install it (Debian/Ubuntu: `apt-get install {package}`; `.ci/run` does)"),
    )
}

/// What a test does when something it needs (`what`, how to get it: `how`) is missing, by the
/// rule of [`on_missing`]: `false` (skip, saying so), or a panic saying how to get it.
pub fn missing(what: &str, how: &str) -> bool {
    let env = |k| std::env::var(k).ok();
    match on_missing(
        env("CI").as_deref(),
        env("APTSCOPE_SKIP_MISSING_TOOLS").as_deref(),
    ) {
        Missing::Skip => {
            eprintln!("{what}: skipped (APTSCOPE_SKIP_MISSING_TOOLS=1)");
            false
        }
        Missing::Fail => panic!(
            "{what}: {how}, or outside CI set APTSCOPE_SKIP_MISSING_TOOLS=1 to skip this test"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_tool_fails_in_ci_and_skips_only_when_asked() {
        assert_eq!(on_missing(None, None), Missing::Fail);
        assert_eq!(on_missing(Some("true"), None), Missing::Fail);
        assert_eq!(on_missing(Some("1"), Some("1")), Missing::Fail);
        assert_eq!(on_missing(None, Some("0")), Missing::Fail);
        assert_eq!(on_missing(None, Some("1")), Missing::Skip);
        assert_eq!(on_missing(Some("false"), Some("1")), Missing::Skip);
        assert_eq!(on_missing(Some(""), Some("1")), Missing::Skip);
    }
}
