//! What the end-to-end tests share: running the `aptscope` binary.
#![allow(dead_code)]

mod scratch;

#[allow(unused_imports)] // Not every test file makes directories.
pub use scratch::scratch;
use std::io::Write;
use std::process::{Command, Stdio};

/// Run the binary in the repository with `stdin` (empty when `None`): stdout, stderr, success.
pub fn aptscope(args: &[&str], stdin: Option<&[u8]>) -> (String, String, bool) {
    let mut c = Command::new(env!("CARGO_BIN_EXE_aptscope"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run aptscope");
    let mut si = c.stdin.take().expect("stdin");
    if let Some(b) = stdin {
        si.write_all(b).expect("write stdin");
    }
    drop(si);
    let o = c.wait_with_output().expect("wait");
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
        o.status.success(),
    )
}
