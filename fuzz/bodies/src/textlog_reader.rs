//! Text-log readers (socat, jpnevulator, interceptty, xxd, hexdump -C, hex columns) and the
//! format sniffer on any bytes.
//!
//! Input: `[kind, max_read, seed, file...]`: `kind % 6` picks the reader (whatever the sniffer
//! says: every reader must cope with any text), the file is handed out in reads of at most
//! `max_read` bytes. Checks (see `drain_reader`): the reader ends, diagnostics have snake_case
//! kinds and offsets within the file, streams are announced once before their chunks.

use crate::util::{drain_reader, split_ctl, ShortReads};
use aptscope_capture::open::sniff;
use aptscope_capture::textlog::{self, TextFormat};
use std::io::BufReader;

const KINDS: [TextFormat; 6] = TextFormat::ALL;

/// The target's body: panics when a check fails.
pub fn fuzz(data: &[u8]) {
    let (ctl, file) = split_ctl::<3>(data);
    let _ = sniff(file);
    let sniffed = textlog::sniff(file);
    let kind = KINDS[ctl[0] as usize % KINDS.len()];
    // Small BufReader capacities too, so lines straddle buffer refills.
    let cap = 1 + ctl[1] as usize * 8;
    for k in std::iter::once(kind).chain(sniffed.filter(|s| *s != kind)) {
        let src = BufReader::with_capacity(cap, ShortReads::new(file.to_vec(), ctl[1], ctl[2]));
        let mut r = textlog::open(k, src);
        drain_reader(r.as_mut(), file.len(), true);
    }
}
