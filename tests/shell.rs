//! `aptscope completions` and `aptscope man`, end to end: the bash script loads in a bash and
//! completes commands and options; every command's man page renders with `man -l` and says what
//! the command does. Needs bash and man (`apt-get install man-db`, which `.ci/run` does).

mod common;

use aptscope_capture::tools::require;
use common::{aptscope, Scratch};
use std::process::Command;

/// `PATH` with the binary under test first, so that a shell finds it as `aptscope`.
fn path_with_aptscope() -> String {
    let bin = std::path::Path::new(env!("CARGO_BIN_EXE_aptscope"));
    let dir = bin
        .parent()
        .expect("the binary's folder")
        .display()
        .to_string();
    match std::env::var("PATH") {
        Ok(p) => format!("{dir}:{p}"),
        Err(_) => dir,
    }
}

/// Run `script` in a bash without start-up files: stdout, stderr, success.
fn bash(script: &str) -> (String, String, bool) {
    let o = Command::new("bash")
        .args(["--norc", "--noprofile", "-c", script])
        .env("PATH", path_with_aptscope())
        .output()
        .expect("run bash");
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
        o.status.success(),
    )
}

/// The names in `aptscope --help`'s command list (not `help`).
fn commands() -> Vec<String> {
    let (out, err, ok) = aptscope(&["--help"], None);
    assert!(ok, "{err}");
    let list = out.split("Commands:\n").nth(1).expect("a command list");
    let names: Vec<String> = list
        .lines()
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|n| *n != "help")
        .map(str::to_owned)
        .collect();
    assert!(
        names.len() >= 13 && names.iter().any(|n| n == "man"),
        "{out}"
    );
    names
}

/// What bash's completion of `line` (the words so far, the last one being completed) offers.
fn complete(line: &str) -> Vec<String> {
    let words: Vec<&str> = line.split(' ').collect();
    let script = format!(
        "source <(aptscope completions bash) || exit 1\n\
         COMP_WORDS=({words}); COMP_CWORD={cword}; COMP_LINE='{line}'; COMP_POINT={point}\n\
         _aptscope aptscope '{cur}' '{prev}' && printf '%s\\n' \"${{COMPREPLY[@]}}\"",
        words = words
            .iter()
            .map(|w| format!("'{w}'"))
            .collect::<Vec<_>>()
            .join(" "),
        cword = words.len() - 1,
        point = line.len(),
        cur = words[words.len() - 1],
        prev = words[words.len() - 2],
    );
    let (out, err, ok) = bash(&script);
    assert!(ok && err.is_empty(), "completing `{line}`: {err}");
    out.lines().map(str::to_owned).collect()
}

#[test]
fn the_bash_completion_script_loads_without_error() {
    if !require("bash", "--version", "bash") {
        return;
    }
    let (out, err, ok) = bash("source <(aptscope completions bash) && complete -p aptscope");
    assert!(ok, "{err}");
    assert!(err.is_empty(), "the script complained while loading: {err}");
    let spec = out.trim_end();
    assert!(
        spec.starts_with("complete ")
            && spec.contains(" -F _aptscope ")
            && spec.ends_with(" aptscope"),
        "{out}"
    );
}

#[test]
fn bash_completes_commands_options_and_values() {
    if !require("bash", "--version", "bash") {
        return;
    }
    assert_eq!(complete("aptscope dec"), ["decode"]);
    let mut opts = complete("aptscope decode --fo");
    opts.sort();
    assert_eq!(opts, ["--follow", "--force", "--format"]);
    let mut shells = complete("aptscope completions ");
    shells.retain(|w| !w.starts_with('-'));
    shells.sort();
    assert_eq!(shells, ["bash", "elvish", "fish", "powershell", "zsh"]);
    assert_eq!(complete("aptscope sim ap"), ["apt"]);
}

#[test]
fn every_shell_gets_a_script_naming_every_command() {
    let names = commands();
    for shell in ["bash", "zsh", "fish", "powershell", "elvish"] {
        let (out, err, ok) = aptscope(&["completions", shell], None);
        assert!(ok, "{shell}: {err}");
        for n in &names {
            assert!(out.contains(n.as_str()), "{shell}: no `{n}` in\n{out}");
        }
        assert!(out.contains("usb-device"), "{shell}: an option is missing");
    }
    let (_, err, ok) = aptscope(&["completions", "tcsh"], None);
    assert!(!ok && err.contains("possible values: bash"), "{err}");
}

/// `man -l` of `page` as plain text, its words one space apart and words hyphenated at the end
/// of a line joined again (how wide a terminal man assumes decides where it breaks lines).
fn rendered(dir: &Scratch, name: &str, page: &str) -> String {
    let f = dir.join(&format!("{name}.1"));
    std::fs::write(&f, page).expect("write the page");
    let o = Command::new("man")
        .arg("-l")
        .arg(&f)
        .env("LC_ALL", "C.UTF-8")
        .env("MANWIDTH", "80")
        .env("MANPAGER", "cat")
        .env("PAGER", "cat")
        .output()
        .expect("run man");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        o.status.success() && err.is_empty(),
        "man -l {name}.1: {err}"
    );
    let text = String::from_utf8_lossy(&o.stdout);
    // Like `col -b`: overstrikes (bold, underline) when man keeps them.
    let mut plain = String::new();
    for c in text.chars() {
        match c {
            '\u{8}' => {
                plain.pop();
            }
            c => plain.push(c),
        }
    }
    // groff's hyphenation ends a line with U+2010; the page's own hyphens are `\-`, shown as
    // `-` (or U+2212 where groff is not configured to show them as `-`).
    let mut joined = String::new();
    for line in plain.lines() {
        match joined.strip_suffix('\u{2010}') {
            Some(head) => joined = format!("{head}{}", line.trim_start()),
            None => {
                joined.push('\n');
                joined.push_str(line);
            }
        }
    }
    let joined = joined.replace('\u{2212}', "-");
    joined.split_whitespace().collect::<Vec<_>>().join(" ")
}

#[test]
fn man_renders_a_page_for_aptscope_and_each_command() {
    if !require("man", "--version", "man-db") {
        return;
    }
    let dir = Scratch::new("man");
    let (page, err, ok) = aptscope(&["man"], None);
    assert!(ok, "{err}");
    let text = rendered(&dir, "aptscope", &page);
    assert!(
        text.starts_with("aptscope(1) aptscope manual aptscope(1) NAME aptscope - Protocol analyser for Thorlabs APT and Elliptec serial traffic SYNOPSIS aptscope [-h|--help] [-V|--version]"),
        "{text}"
    );
    assert!(
        text.contains(&format!("aptscope {}", env!("CARGO_PKG_VERSION"))),
        "{text}"
    );
    // The exit statuses in a section of their own (not clap's EXTRA of `--help`'s text), before
    // VERSION.
    let status = text.find("EXIT STATUS 0 It did what was asked.");
    assert!(
        status.is_some_and(|at| text.find("VERSION").is_some_and(|v| v > at))
            && !text.contains("EXTRA")
            && text.contains("1 An error, said on standard error")
            && text.contains("2 The command line is wrong"),
        "{text}"
    );
    let mut pages = vec![vec!["sim".to_owned(), "apt".to_owned()]];
    pages.extend(commands().into_iter().map(|c| vec![c]));
    for path in pages {
        let args: Vec<&str> = path.iter().map(String::as_str).collect();
        let (page, err, ok) = aptscope(&[&["man"], &args[..]].concat(), None);
        assert!(ok, "man {path:?}: {err}");
        let name = format!("aptscope-{}", path.join("-"));
        let text = rendered(&dir, &name, &page);
        // What the command does, as its --help says it.
        let (help, err, ok) = aptscope(&[&args[..], &["-h"]].concat(), None);
        assert!(ok, "{err}");
        let about = help.lines().next().expect("a description");
        let usage = format!("SYNOPSIS aptscope {}", path.join(" "));
        assert!(
            text.contains(&format!("NAME {name} - {about}"))
                && text.contains(&format!("DESCRIPTION {about}"))
                && text.contains(&usage)
                && text.contains("EXIT STATUS 0 It did what was asked."),
            "{name}: no `{about}`, `{usage}` or exit status in\n{text}"
        );
    }
}

#[test]
fn man_names_the_commands_when_one_is_unknown() {
    let (out, err, ok) = aptscope(&["man", "decoed"], None);
    assert!(!ok && out.is_empty());
    assert!(
        err.contains("no command `decoed`: the commands are decode, stats, view"),
        "{err}"
    );
    let (_, err, ok) = aptscope(&["man", "sim", "apt", "x"], None);
    assert!(
        !ok && err.contains("`aptscope sim apt` has no subcommands"),
        "{err}"
    );
}

/// The exit statuses `aptscope --help` lists are those it exits with: 0 for a damaged capture
/// (a truncated one too) decoded to its end, its damage in the output; 1 for input that is not
/// traffic and for a file that is not there, saying why; 2 for a wrong command line.
#[test]
fn the_exit_statuses_help_lists_are_those_it_exits_with() {
    let (help, err, ok) = aptscope(&["--help"], None);
    assert!(ok, "{err}");
    let listed: Vec<&str> = help
        .lines()
        .skip_while(|l| *l != "Exit status:")
        // A status's first line; its text's further lines are indented more.
        .filter_map(|l| {
            let rest = l.strip_prefix("  ").filter(|r| !r.starts_with(' '))?;
            rest.split_whitespace().next()
        })
        .collect();
    assert_eq!(listed, ["0", "1", "2"], "{help}");
    let dir = Scratch::new("exit-status");
    let sample = |name: &str| format!("{}/samples/{name}", env!("CARGO_MANIFEST_DIR"));
    let whole = std::fs::read(sample("kdc101-session.pcapng")).expect("sample");
    let cut = dir.join("cut.pcapng");
    std::fs::write(&cut, &whole[..whole.len() - 10]).expect("write");
    let cut = cut.display().to_string();
    let random = format!("{}/tests/bad-input/random.bin", env!("CARGO_MANIFEST_DIR"));
    let cases: [(&[&str], i32, &str); 5] = [
        (
            &["decode", "--json", &sample("damaged.bin")],
            0,
            "\"garbage\"",
        ),
        (&["decode", "--json", &cut], 0, "truncated_record"),
        (&["decode", &random], 1, "aptscope: not a capture"),
        (
            &["decode", "/no/such/capture.bin"],
            1,
            "aptscope: /no/such/capture.bin",
        ),
        (
            &["decode", "--no-such-option", &random],
            2,
            "--no-such-option",
        ),
    ];
    for (args, code, says) in cases {
        let o = Command::new(env!("CARGO_BIN_EXE_aptscope"))
            .args(args)
            .output()
            .expect("run aptscope");
        let both = format!(
            "{}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(
            o.status.code() == Some(code) && both.contains(says),
            "{args:?}: {:?}, expected {code} saying {says}\n{both}",
            o.status
        );
    }
}
