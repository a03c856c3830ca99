//! A terminal for the live views: `aptscope` in a tmux session of its own.

use super::proc::wait_for;
use nix::unistd::Pid;
use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};

/// A terminal running `aptscope ARGS`: a tmux session on a server of its own (never the
/// user's), the program's standard error in a file and its exit status written when it ends.
/// The server is killed on drop (a failing test leaves nothing running).
pub struct Term {
    sock: String,
    err: PathBuf,
    status: PathBuf,
}

fn tmux(sock: &str, args: &[&str]) -> String {
    let o = Command::new("tmux")
        .args(["-L", sock])
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("run tmux");
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Quoted for the shell tmux runs the command with.
fn sh_quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

impl Term {
    /// `aptscope ARGS` in a 160×40 terminal (room for the scratch paths in the title), its
    /// files in `dir`; `None` when tmux is missing and the rule of
    /// [`aptscope_capture::tools::require`] says skip (in CI it fails instead).
    pub fn start<S: AsRef<str>>(dir: &Path, args: &[S]) -> Option<Term> {
        if !aptscope_capture::tools::require("tmux", "-V", "tmux") {
            return None;
        }
        static N: AtomicUsize = AtomicUsize::new(0);
        let sock = format!(
            "aptscope-{}-{}-{}",
            env!("CARGO_CRATE_NAME"),
            std::process::id(),
            N.fetch_add(1, Ordering::SeqCst)
        );
        let (err, status) = (dir.join("term.err"), dir.join("term.status"));
        let mut line = sh_quote(env!("CARGO_BIN_EXE_aptscope"));
        for a in args {
            line.push(' ');
            line.push_str(&sh_quote(a.as_ref()));
        }
        let path = |p: &Path| sh_quote(p.to_str().expect("utf-8 path"));
        let cmd = format!("{line} 2>{}; echo $? >{}", path(&err), path(&status));
        let new = ["new-session", "-d", "-s", "t", "-x", "160", "-y", "40"];
        tmux(&sock, &[&new[..], &[cmd.as_str()]].concat());
        Some(Term { sock, err, status })
    }

    /// `aptscope ARGS` that makes `link` (a simulator's `--pty`, a tap's `--link`) and shows
    /// its view: the terminal once both are there.
    pub fn start_view<S: AsRef<str>>(dir: &Path, args: &[S], link: &Path) -> Option<Term> {
        let term = Term::start(dir, args)?;
        wait_for(
            "the link",
            || term.stderr(),
            || std::fs::read_link(link).is_ok(),
        );
        term.wait("the view", |s| s.contains("Timeline"));
        Some(term)
    }

    /// What the terminal shows.
    pub fn screen(&self) -> String {
        tmux(&self.sock, &["capture-pane", "-p", "-t", "t"])
    }

    /// Type `keys` (tmux's names: `Enter`, `C-c` …).
    pub fn keys(&self, keys: &[&str]) {
        let mut a = vec!["send-keys", "-t", "t"];
        a.extend_from_slice(keys);
        tmux(&self.sock, &a);
    }

    /// The program's standard error so far.
    pub fn stderr(&self) -> String {
        std::fs::read_to_string(&self.err).unwrap_or_default()
    }

    /// The screen once `cond` holds of it (panics at the deadline, showing it).
    pub fn wait(&self, what: &str, cond: impl Fn(&str) -> bool) -> String {
        let last = RefCell::new(String::new());
        wait_for(
            what,
            || format!("{}\n{}", last.borrow(), self.stderr()),
            || {
                *last.borrow_mut() = self.screen();
                cond(&last.borrow())
            },
        );
        last.into_inner()
    }

    /// Wait for `aptscope` to end: its exit code and standard error.
    pub fn exit(&self) -> (i32, String) {
        wait_for(
            "the program in the terminal to end",
            || format!("{}\n{}", self.screen(), self.stderr()),
            || std::fs::read_to_string(&self.status).is_ok_and(|s| s.ends_with('\n')),
        );
        let code = std::fs::read_to_string(&self.status).unwrap_or_default();
        (code.trim().parse().unwrap_or(-1), self.stderr())
    }

    /// The `aptscope` process (the child of the pane's shell).
    pub fn pid(&self) -> Pid {
        let shell = tmux(&self.sock, &["display", "-p", "-t", "t", "#{pane_pid}"]);
        let shell = shell.trim();
        let children = std::fs::read_to_string(format!("/proc/{shell}/task/{shell}/children"))
            .unwrap_or_default();
        let pid = children
            .split_whitespace()
            .next()
            .and_then(|p| p.parse().ok())
            .expect("the program in the terminal");
        Pid::from_raw(pid)
    }
}

impl Drop for Term {
    fn drop(&mut self) {
        tmux(&self.sock, &["kill-server"]);
    }
}
