//! Record bytes read back by position: the cache directory, scratch files, a window per
//! thread.

use std::sync::atomic::{AtomicU64, Ordering};

/// Where the viewer keeps its files: `$XDG_CACHE_HOME/aptscope`, else `~/.cache/aptscope`,
/// else the temporary directory (whichever can be made).
pub fn cache_dir() -> std::path::PathBuf {
    let home = std::env::var_os("HOME").map(|h| std::path::PathBuf::from(h).join(".cache"));
    let xdg = std::env::var_os("XDG_CACHE_HOME")
        .map(std::path::PathBuf::from)
        .filter(|p| p.is_absolute());
    xdg.or(home)
        .map(|d| d.join("aptscope"))
        .filter(|d| std::fs::create_dir_all(d).is_ok())
        .unwrap_or_else(std::env::temp_dir)
}

/// A new file of the viewer's own, already unlinked (it goes when the process does, however it
/// ends), opened for reading and writing: in [`cache_dir`], else the temporary directory.
pub(crate) fn scratch_file(what: &str) -> Option<std::fs::File> {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    let name = format!("{what}-{}-{n}.tmp", std::process::id());
    [cache_dir(), std::env::temp_dir()].iter().find_map(|d| {
        let p = d.join(&name);
        let f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&p)
            .ok()?;
        let _ = std::fs::remove_file(&p);
        Some(f)
    })
}

/// A file for the arena: the indexer's handle to write it, and the index's to read it back.
pub(super) fn arena_file_pair() -> Option<(std::fs::File, ReadBack)> {
    let f = scratch_file("arena")?;
    let back = f.try_clone().ok()?;
    Some((f, ReadBack::of(back)))
}

/// A capture file records' bytes are read back from ([`Index::file`](super::Index::file)).
#[derive(Debug)]
pub struct ReadBack {
    pub(super) file: std::fs::File,
    /// Tells this file's [`WINDOW`] from another index's.
    pub(super) id: u64,
    /// Where position 0 is in the file (a section of a cached index's file).
    pub(super) base: u64,
}

/// Bytes read back at once: records read in order (a filter's scan, a screen of rows) cost one
/// read of the file per window, not one each.
pub(super) const WINDOW_LEN: usize = 64 << 10;

thread_local! {
    /// The part of a file this thread read back last: ([`ReadBack::id`], its file position,
    /// its bytes).
    static WINDOW: std::cell::RefCell<(u64, u64, Vec<u8>)> =
        const { std::cell::RefCell::new((0, 0, Vec::new())) };
}

impl ReadBack {
    /// Read records' bytes back from the file at `path`.
    pub fn open(path: &str) -> std::io::Result<Self> {
        Ok(Self::of(std::fs::File::open(path)?))
    }

    /// Read back from an open file.
    pub(super) fn of(file: std::fs::File) -> Self {
        Self::at(file, 0)
    }

    /// Read back from an open file whose position 0 is at `base`.
    pub(super) fn at(file: std::fs::File, base: u64) -> Self {
        static NEXT: AtomicU64 = AtomicU64::new(1);
        ReadBack {
            file,
            id: NEXT.fetch_add(1, Ordering::Relaxed),
            base,
        }
    }

    /// The `len` bytes at `at`, when the file has them.
    pub(super) fn read(&self, at: u64, len: usize) -> Option<Vec<u8>> {
        use std::os::unix::fs::FileExt;
        let at = at.checked_add(self.base)?;
        if len > WINDOW_LEN {
            let mut buf = vec![0; len];
            return self.file.read_exact_at(&mut buf, at).ok().map(|()| buf);
        }
        WINDOW.with_borrow_mut(|(id, start, buf)| {
            let end = at.checked_add(len as u64)?;
            let inside = *id == self.id && at >= *start && end <= *start + buf.len() as u64;
            if !inside {
                buf.resize(WINDOW_LEN, 0);
                let mut got = 0;
                while got < WINDOW_LEN {
                    match self.file.read_at(&mut buf[got..], at + got as u64) {
                        Ok(0) => break,
                        Ok(n) => got += n,
                        Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                        Err(_) => break,
                    }
                }
                buf.truncate(got);
                (*id, *start) = (self.id, at);
            }
            let from = usize::try_from(at - *start).ok()?;
            buf.get(from..from + len).map(<[u8]>::to_vec)
        })
    }
}
