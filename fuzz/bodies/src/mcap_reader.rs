//! MCAP reader on any bytes.
//!
//! Input: `[max_read, seed, flags, file...]`: the file is handed out in reads of at most
//! `max_read` bytes (0: as much as asked); `flags & 1` tells the reader the file's length (as
//! `McapReader::open` does). Checks (see `drain_reader`): the reader ends, diagnostics have
//! snake_case kinds and offsets within the file, streams are announced once before their
//! chunks; and the events (chunks, streams, diagnostics' kinds and offsets) do not depend on how
//! the file is read.

use crate::util::{drain_reader, event_keys, split_ctl, ShortReads};
use aptscope_capture::mcap::McapReader;

fn reader(file: &[u8], max: u8, seed: u8, with_len: bool) -> McapReader {
    let r = McapReader::new(ShortReads::new(file.to_vec(), max, seed));
    if with_len {
        r.with_file_len(file.len() as u64)
    } else {
        r
    }
}

/// The target's body: panics when a check fails.
pub fn fuzz(data: &[u8]) {
    let (ctl, file) = split_ctl::<3>(data);
    let with_len = ctl[2] & 1 != 0;
    let mut r = reader(file, ctl[0], ctl[1], with_len);
    drain_reader(&mut r, file.len(), true);
    if ctl[0] != 0 {
        let limit = 64 + 8 * file.len();
        assert_eq!(
            event_keys(&mut reader(file, ctl[0], ctl[1], with_len), limit),
            event_keys(&mut reader(file, 0, 0, with_len), limit),
            "short reads changed what the reader makes of the file"
        );
    }
}
