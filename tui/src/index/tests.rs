//! The index's unit tests: read-back windows, record storage and spilling.

use super::*;

/// Two files read back in turn on one thread give their own bytes (each read misses the
/// other's window), across windows and up to their ends.
#[test]
fn files_read_back_give_their_own_bytes() {
    let dir = std::env::temp_dir().join(format!("aptscope-readback-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let data: Vec<Vec<u8>> = (0..2u8)
        .map(|k| {
            (0..WINDOW_LEN * 2 + 100)
                .map(|i| (i % 251) as u8 ^ k)
                .collect()
        })
        .collect();
    let files: Vec<ReadBack> = data
        .iter()
        .enumerate()
        .map(|(k, d)| {
            let p = dir.join(format!("{k}.bin"));
            std::fs::write(&p, d).expect("write");
            ReadBack::open(&p.to_string_lossy()).expect("open")
        })
        .collect();
    let _ = std::fs::remove_dir_all(&dir);
    let end = data[0].len();
    for (at, len) in [
        (0, 10),
        (WINDOW_LEN - 3, 6),
        (5, WINDOW_LEN + 7),
        (end - 4, 4),
    ] {
        for (f, d) in files.iter().zip(&data) {
            assert_eq!(f.read(at as u64, len).as_deref(), d.get(at..at + len));
        }
    }
    assert_eq!(files[0].read(end as u64 - 2, 4), None);
}

/// Records of every shape (offsets and times going back and far ahead, no time, old and
/// new module entries, values too wide for their slot, offsets apart from the capture's
/// from some record on) come back from the packed store as they went in, by index, by
/// iteration from any record, and after their pair link and flags are patched.
#[test]
fn packed_records_read_back_as_pushed() {
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let (mut cap, mut ts) = (0u64, 1_000u64);
    let mut recs = vec![];
    for i in 0..(CHUNK as u64 * 2 + 777) {
        let r = next();
        cap = match r % 50 {
            0 => cap.saturating_sub(r >> 40),
            1 => cap + (r >> 20),
            _ => cap + r % 300,
        };
        ts = match (r >> 8) % 40 {
            0 => ts.saturating_sub((r >> 30) % 5_000_000_000),
            1 => ts + (r >> 16),
            _ => ts + (r >> 12) % 100_000,
        };
        let apart = i > CHUNK as u64 + 5;
        recs.push(Rec {
            start: if apart { cap / 2 } else { cap },
            offset: if apart && r % 3 == 0 { cap + 1 } else { cap },
            cap_offset: cap,
            ts: if (r >> 20) % 9 == 0 { u64::MAX } else { ts },
            pair: (r >> 24) as u32,
            len: if (r >> 4) % 500 == 0 {
                70_000 + (r % 9) as u32
            } else {
                (r % 300) as u32
            },
            module: match (r >> 6) % 5 {
                0 => 0,
                1 => 1,
                2 => (r >> 40) as u32,
                _ => (i / 100) as u32,
            },
            stream: if (r >> 9) % 300 == 0 {
                300
            } else {
                ((r >> 9) % 4) as u16
            },
            flags: (r >> 32) as u16 & ((1 << DIR_SHIFT) - 1),
            dir: ((r >> 50) % 3) as u8,
            src: (r >> 13) as u8,
            dst: (r >> 21) as u8,
            id: (r >> 29) as u16,
            diags: if (r >> 3) % 700 == 0 {
                999
            } else {
                ((r >> 3) % 5) as u16
            },
            chan: (r >> 45) as u8,
        });
    }
    // Arena starts at the capture offsets, then apart; one after the other (an arena
    // written in order); one after the other, then out of line.
    let in_line = |recs: &[Rec], upto: usize| {
        let mut at = 1000;
        let mut out = recs.to_vec();
        for r in out.iter_mut().take(upto) {
            r.start = at;
            at += u64::from(r.len);
        }
        out
    };
    let variants = [
        recs.clone(),
        in_line(&recs, recs.len()),
        in_line(&recs, CHUNK + 100),
    ];
    // In memory, and over a budget of about one chunk (the older ones in a scratch file).
    let cases = variants
        .iter()
        .flat_map(|v| [(v, None), (v, Some(CHUNK_BYTES))]);
    let mut whole = 0;
    for (pristine, budget) in cases {
        let mut recs = pristine.clone();
        let mut packed = Recs::default();
        if let Some(b) = budget {
            packed.set_budget(b);
        }
        packed.extend(recs.iter().copied());
        check_packed(&mut packed, &mut recs);
        let spilled = packed.spilled_chunks();
        assert_eq!(spilled > 0, budget.is_some(), "{spilled}");
        // Of the three chunks, the first is spilled: the budget holds the second, and the
        // third is being filled.
        match budget {
            None => whole = packed.memory(),
            Some(_) => assert_eq!(packed.memory() + CHUNK_BYTES, whole),
        }
    }
}

fn check_packed(packed: &mut Recs, recs: &mut [Rec]) {
    assert_eq!(packed.len(), recs.len());
    for (i, r) in recs.iter().enumerate() {
        assert_eq!(packed.get(i).as_ref(), Some(r), "#{i}");
    }
    for from in [
        0,
        1,
        CHUNK - 1,
        CHUNK,
        CHUNK + 6,
        recs.len() - 1,
        recs.len(),
    ] {
        assert!(
            packed.iter_from(from).eq(recs[from..].iter().copied()),
            "from {from}"
        );
    }
    assert_eq!(packed.last(), recs.last().copied());
    for i in [0, 5, CHUNK + 3, recs.len() - 1, 7] {
        let was = packed.patch(i, 42, F_NO_REPLY);
        assert_eq!(was, Some(recs[i].flags));
        recs[i].flags |= F_NO_REPLY;
        if recs[i].pair == 0 {
            recs[i].pair = 42;
        }
        assert_eq!(packed.get(i), Some(recs[i]), "patched #{i}");
    }
    assert_eq!(packed.get(recs.len()), None);
    // Patches to spilled records are seen by reads after them, not the chunks kept before.
    assert!(packed.iter().eq(recs.iter().copied()));
}

/// A directory of this test's own, removed on drop.
struct TestDir(std::path::PathBuf);

impl TestDir {
    fn new(tag: &str) -> TestDir {
        let p = std::env::temp_dir().join(format!("aptscope-ix-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).expect("dir");
        TestDir(p)
    }
}

impl Drop for TestDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Records of every shape over several chunks (the last partly filled), in memory or spilled
/// over a budget, with their arena in memory or in a file, come back from a cache file as they
/// went in: by index, by iteration, with their bytes; a cache of another aptscope version or
/// another layout's key is not read.
#[test]
fn records_of_every_shape_come_back_from_the_cache() {
    let dir = TestDir::new("cache-shapes");
    let capture = dir.0.join("capture.bin");
    std::fs::write(&capture, b"a capture").expect("write");
    let capture = capture.to_string_lossy().to_string();
    let mut x = 0x2545_F491_4F6C_DD1Du64;
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let n = CHUNK * 2 + 777;
    let (mut cap, mut recs) = (0u64, vec![]);
    let mut arena_len = 0u64;
    for i in 0..n {
        let r = next();
        let len = if r % 900 == 0 {
            70_000
        } else {
            (r % 40) as u32
        };
        cap += r % 300;
        recs.push(Rec {
            start: arena_len,
            offset: if i > CHUNK && r % 3 == 0 {
                cap + 9
            } else {
                cap
            },
            cap_offset: cap,
            ts: if r % 11 == 0 { u64::MAX } else { cap * 1000 },
            pair: (r >> 24) as u32,
            len,
            module: (r >> 40) as u32 % 3,
            stream: if r % 1000 == 1 { 300 } else { (r % 3) as u16 },
            flags: (r >> 32) as u16 & ((1 << DIR_SHIFT) - 1),
            dir: ((r >> 50) % 3) as u8,
            src: (r >> 13) as u8,
            dst: (r >> 21) as u8,
            id: (r >> 29) as u16,
            diags: (r % 3) as u16,
            chan: (r >> 45) as u8,
        });
        arena_len += u64::from(len);
    }
    let arena: Vec<u8> = (0..arena_len).map(|i| (i * 31 % 253) as u8).collect();
    let key = |proto| {
        cache::Key::new(
            &capture,
            &OpenOptions::default(),
            proto,
            &UnitsOpts::default(),
            &dir.0,
        )
        .expect("key")
    };
    for (budget, arena_in_file) in [(None, false), (Some(CHUNK_BYTES), true)] {
        let mut ix = Index {
            format: "pcapng".into(),
            done: true,
            diag_sets: vec![vec!["truncated"], vec!["no_reply", "unknown_id"]],
            ..Index::default()
        };
        if let Some(b) = budget {
            ix.recs.set_budget(b);
        }
        ix.recs.extend(recs.iter().copied());
        assert_eq!(ix.recs.spilled_chunks() > 0, budget.is_some());
        if arena_in_file {
            let (out, back) = arena_file_pair().expect("scratch file");
            use std::os::unix::fs::FileExt;
            out.write_all_at(&arena, 0).expect("arena");
            ix.arena_file = Some(back);
        } else {
            ix.arena = arena.clone();
        }
        let k = key(None);
        cache::write(&ix, &k, cache::VERSION).expect("written");
        let back = cache::read(&k).expect("read back");
        assert!(back.from_cache);
        assert_eq!(back.recs.spilled_chunks(), 3);
        assert_eq!(back.recs.len(), n);
        assert_eq!(back.diag_sets, ix.diag_sets);
        for i in [0, 1, CHUNK - 1, CHUNK, n - 1, 17, CHUNK * 2 + 5] {
            assert_eq!(back.recs.get(i), Some(recs[i]), "#{i}");
        }
        assert!(back.recs.iter().eq(recs.iter().copied()));
        assert!(back
            .recs
            .iter_from(CHUNK + 3)
            .eq(recs[CHUNK + 3..].iter().copied()));
        for r in recs.iter().step_by(97).chain(recs.last()) {
            let s = r.start as usize;
            assert_eq!(back.bytes(r).as_ref(), &arena[s..s + r.len as usize]);
        }
        // Another version's cache, and the cache of other options, are not read.
        cache::write(&ix, &k, "0.0.0-another").expect("written");
        assert!(cache::read(&k).is_none());
        assert!(cache::read_with_version(&k, "0.0.0-another").is_some());
        assert!(cache::read(&key(Some(Proto::Elliptec))).is_none());
    }
    // A diagnostic kind this build does not know: not read.
    let ix = Index {
        format: "pcapng".into(),
        done: true,
        diag_sets: vec![vec!["a kind from elsewhere"]],
        ..Index::default()
    };
    let k = key(None);
    cache::write(&ix, &k, cache::VERSION).expect("written");
    assert!(cache::read(&k).is_none());
}

/// The cache directory is kept under its size: the least recently used files go first, the
/// one just written stays even when it alone is over; unfinished writes go once stale.
#[test]
fn the_cache_evicts_the_least_recently_used() {
    let dir = TestDir::new("cache-evict");
    let now = std::time::SystemTime::now();
    let file = |name: &str, len: usize, age_s: u64| {
        let p = dir.0.join(name);
        std::fs::write(&p, vec![0u8; len]).expect("write");
        let f = std::fs::File::options().write(true).open(&p).expect("open");
        f.set_modified(now - std::time::Duration::from_secs(age_s))
            .expect("time");
        p
    };
    let old = file("old.idx", 100, 300);
    let mid = file("mid.idx", 100, 200);
    let new = file("new.idx", 100, 100);
    let just = file("just.idx", 100, 0);
    let other = file("notes.txt", 1000, 1000);
    let fresh_tmp = file("x.idx.tmp-1-0", 50, 10);
    let stale_tmp = file("y.idx.tmp-1-1", 50, 7200);
    cache::evict(&dir.0, &just, 250);
    let there = |p: &std::path::Path| p.exists();
    assert_eq!(
        [&old, &mid, &new, &just, &other, &fresh_tmp, &stale_tmp].map(|p| there(p)),
        [false, false, true, true, true, true, false]
    );
    cache::evict(&dir.0, &just, 10);
    assert_eq!([there(&new), there(&just)], [false, true]);
}
