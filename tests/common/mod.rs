//! What the end-to-end tests share: running the `aptscope` binary, scratch directories, and for
//! the live tests the processes, the host's port and the terminal ([`proc`], [`host`], [`term`]).
#![allow(dead_code)]

pub mod clients;
pub mod host;
pub mod proc;
mod scratch;
pub mod term;

#[allow(unused_imports)] // Not every test file makes directories.
pub use scratch::scratch;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// Run the binary in the repository with `stdin` (empty when `None`): stdout, stderr, success.
pub fn aptscope(args: &[&str], stdin: Option<&[u8]>) -> (String, String, bool) {
    aptscope_env(args, stdin, &[])
}

/// [`aptscope`] with these environment variables set.
pub fn aptscope_env(
    args: &[&str],
    stdin: Option<&[u8]>,
    env: &[(&str, &str)],
) -> (String, String, bool) {
    let mut c = Command::new(env!("CARGO_BIN_EXE_aptscope"))
        .args(args)
        .envs(env.iter().copied())
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

/// A [`scratch`] directory removed when the test ends (also when it fails).
pub struct Scratch(PathBuf);

impl Scratch {
    /// A new, empty one named after `name`.
    pub fn new(name: &str) -> Self {
        Scratch(scratch(name))
    }

    /// A path inside it.
    pub fn join(&self, p: &str) -> PathBuf {
        self.0.join(p)
    }

    /// The directory.
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The whole APT frames at the start of `bytes`, as the dissector's framer cuts them; an
/// incomplete frame at the end (still arriving) is left out. Panics on bytes that start no
/// frame, with their offset.
pub fn apt_frames(bytes: &[u8]) -> Vec<Vec<u8>> {
    use aptscope_dissector::apt::{AptFramer, GarbageKind, Item};
    let mut f = AptFramer::new(aptscope_dissector::Table::global());
    f.push(bytes);
    f.finish();
    let mut out = vec![];
    while let Some(it) = f.next_item() {
        match it {
            Item::Frame {
                bytes,
                truncated: false,
                ..
            } => out.push(bytes.to_vec()),
            Item::Frame { .. }
            | Item::Garbage {
                kind: GarbageKind::TrailingBytes,
                ..
            } => break,
            Item::Garbage { offset, bytes, .. } => {
                panic!(
                    "not APT at {offset}: {:02x?}",
                    &bytes[..bytes.len().min(32)]
                )
            }
        }
    }
    out
}

/// `n` bytes of deterministic noise (a linear congruential generator from `seed`): input that
/// frames as neither protocol.
pub fn noise(n: usize, seed: u32) -> Vec<u8> {
    let mut x = seed;
    (0..n)
        .map(|_| {
            x = x.wrapping_mul(1_103_515_245).wrapping_add(12_345);
            (x >> 16) as u8
        })
        .collect()
}
