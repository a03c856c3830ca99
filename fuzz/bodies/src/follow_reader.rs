//! Following a growing file (`follow::Follow`, and `open` with `OpenOptions::follow`): the file
//! is written in pieces drawn from the input and read as it grows.
//!
//! Input: `[flags, head_limit, then pieces: [len, read_max, bytes...]]`. The pieces are
//! appended one by one; after each, `Follow` reads (in reads of at most `read_max` bytes, after
//! a `head` of up to `head_limit` bytes when `flags & 1`) exactly what has been written, so a
//! read never waits at an end the writer has not stopped at (the target stays deterministic and
//! never sleeps). Checks: the bytes read are the bytes written, in order; once the writer has
//! stopped, a follower reads the whole file and then ends (read returns 0), and `head` returns
//! at once; a capture opened for following after the writer stopped gives the same events as
//! the file opened plainly (formats detected the same way, no read-size dependence).

use crate::util::{event_keys, Lcg};
use aptscope_capture::follow::{Follow, FollowStop};
use aptscope_capture::open::{open, OpenOptions};
use std::fs::{File, OpenOptions as FsOpen};
use std::io::{Read, Write};
use std::path::PathBuf;
use std::sync::OnceLock;

/// One flag never stopped and one stopped, for the whole process: a `FollowStop` lives for
/// the program (it is leaked), so one per input would grow without bound under libFuzzer.
fn flags() -> (FollowStop, FollowStop) {
    static F: OnceLock<(FollowStop, FollowStop)> = OnceLock::new();
    *F.get_or_init(|| {
        let stopped = FollowStop::new();
        stopped.stop();
        (FollowStop::new(), stopped)
    })
}

/// A file of this process and thread (tests run targets on several threads).
fn path() -> PathBuf {
    let t = format!("{:?}", std::thread::current().id());
    let t: String = t.chars().filter(char::is_ascii_alphanumeric).collect();
    std::env::temp_dir().join(format!("aptscope-fuzz-follow-{}-{t}", std::process::id()))
}

/// Read up to `n` bytes (reads of at most `max`), from a follower that has them.
fn read_n(f: &mut Follow, n: usize, rng: &mut Lcg, max: usize, out: &mut Vec<u8>) {
    let mut buf = vec![0u8; max.max(1)];
    let mut left = n;
    while left > 0 {
        let k = rng.size(max.max(1)).min(left);
        let got = f.read(&mut buf[..k]).expect("read");
        assert!(got > 0, "read 0 bytes with {left} written and unread");
        out.extend_from_slice(&buf[..got]);
        left -= got;
    }
}

/// The body of the target: panics when a check fails.
pub fn fuzz(data: &[u8]) {
    let (running, stopped) = flags();
    let flag = data.first().copied().unwrap_or(0);
    let head_limit = usize::from(data.get(1).copied().unwrap_or(0));
    let mut rest = data.get(2..).unwrap_or(&[]);
    let mut pieces: Vec<(&[u8], usize)> = vec![];
    while rest.len() >= 2 {
        let (len, max) = (usize::from(rest[0]) * 4, usize::from(rest[1]));
        let n = len.min(rest.len() - 2);
        pieces.push((&rest[2..2 + n], max));
        rest = &rest[2 + n..];
    }
    let p = path();
    let mut w = File::create(&p).expect("create the file");
    let mut f = Follow::new(File::open(&p).expect("open"), running);
    let mut rng = Lcg::new(data);
    let (mut written, mut got) = (vec![], vec![]);
    for (i, (bytes, max)) in pieces.iter().enumerate() {
        w.write_all(bytes).expect("write");
        w.flush().expect("flush");
        written.extend_from_slice(bytes);
        if i == 0 && flag & 1 != 0 && !written.is_empty() {
            // As `open` sniffs a followed file: the limit is there, so it returns at once.
            let limit = head_limit.clamp(1, written.len());
            let h = f.head(limit, |_| flag & 2 != 0).expect("head");
            assert_eq!(
                h.len(),
                limit,
                "head of {limit} bytes with {} there",
                written.len()
            );
            got.extend_from_slice(&h);
        }
        read_n(&mut f, written.len() - got.len(), &mut rng, *max, &mut got);
    }
    assert_eq!(got, written, "read as written");
    drop(f);

    // The writer has stopped: a follower reads everything, then ends.
    let mut f = Follow::new(File::open(&p).expect("open"), stopped);
    let mut all = vec![];
    if flag & 1 != 0 {
        all = f.head(head_limit.max(1), |_| false).expect("head");
        assert!(all.len() <= head_limit.max(1));
    }
    let mut buf = [0u8; 97];
    loop {
        let n = f.read(&mut buf[..rng.size(97)]).expect("read");
        if n == 0 {
            break;
        }
        all.extend_from_slice(&buf[..n]);
    }
    assert_eq!(all, written, "a stopped follower reads the file");
    // Appended after the stop: still read (what was written before the follower looked).
    let mut a = FsOpen::new().append(true).open(&p).expect("append");
    a.write_all(b"\x01\x02").expect("write");
    assert_eq!(f.read(&mut buf).expect("read"), 2);
    assert_eq!(f.read(&mut buf).expect("read"), 0);
    drop(a);

    // A capture opened for following, after its writer stopped, reads as the file does.
    let ps = p.to_string_lossy().into_owned();
    let limit = 64 + 8 * written.len();
    let plain = open(&ps, OpenOptions::default());
    let followed = open(
        &ps,
        OpenOptions {
            follow: Some(stopped),
            ..OpenOptions::default()
        },
    );
    match (plain, followed) {
        (Ok((mut a, fa)), Ok((mut b, fb))) => {
            assert_eq!(fa, fb, "detected format");
            assert_eq!(
                event_keys(&mut *a, limit),
                event_keys(&mut *b, limit),
                "followed and plain reads differ"
            );
        }
        (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string()),
        (a, b) => panic!("plain {:?}, followed {:?}", a.is_ok(), b.is_ok()),
    }
    let _ = std::fs::remove_file(&p);
}
