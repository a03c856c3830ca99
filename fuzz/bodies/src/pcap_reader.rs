//! pcap/pcapng reader (serial link types, usbmon and USBPcap captures) on any bytes.
//!
//! Input: `[max_read, seed, flags, file...]`: the file is handed out in reads of at most
//! `max_read` bytes (0: as much as asked), `flags & 1` restricts USB captures to device
//! `1:(flags >> 1)`. Checks (see `drain_reader`): the reader ends, diagnostics have snake_case
//! kinds and offsets within the file, streams are announced once before their chunks, and the
//! events do not depend on how the file is read (they once did after a corrupt block:
//! `fuzz/artifacts-found/pcap_reader/pcap-resync-short-reads.fuzz`;
//! `APTSCOPE_FUZZ_LENIENT=1` skips this).

use crate::util::{drain_reader, event_keys, split_ctl, strict, ShortReads};
use aptscope_capture::pcap::PcapReader;

/// The target's body: panics when a check fails.
pub fn fuzz(data: &[u8]) {
    let (ctl, file) = split_ctl::<3>(data);
    let usb = (ctl[2] & 1 != 0).then_some((1u16, ctl[2] >> 1));
    let mut r = PcapReader::new(ShortReads::new(file.to_vec(), ctl[0], ctl[1]), usb);
    drain_reader(&mut r, file.len(), true);
    if ctl[0] != 0 && strict() {
        let limit = 64 + 8 * file.len();
        let mut short = PcapReader::new(ShortReads::new(file.to_vec(), ctl[0], ctl[1]), usb);
        let mut whole = PcapReader::new(ShortReads::new(file.to_vec(), 0, 0), usb);
        assert_eq!(
            event_keys(&mut short, limit),
            event_keys(&mut whole, limit),
            "short reads changed what the reader makes of the file"
        );
    }
}
