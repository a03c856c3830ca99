//! One capture file into a [`CaptureWriter`]: the loop `aptscope decode --to parquet` and the
//! Python package share.

use crate::{CaptureWriter, Sink, Summary};
use aptscope_capture::open::{open_with_progress, OpenOptions, Progress};
use aptscope_capture::Event;
use aptscope_dissector::detect::Proto;
use aptscope_dissector::record::{Decoder, Record};
use aptscope_dissector::units::UnitsOpts;
use std::io;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// How a capture is decoded.
#[derive(Debug, Clone, Default)]
pub struct DecodeOpts {
    /// How to open it (format, USB device).
    pub open: OpenOptions,
    /// Protocol; `None`: detected.
    pub proto: Option<Proto>,
    /// Stage or scale of APT motion values.
    pub units: UnitsOpts,
    /// One reply timeout for every request.
    pub timeout_ns: Option<u64>,
    /// Skip a file that is [`not_a_capture`] (an error instead of rows).
    pub judge: bool,
    /// Stop reading once this is set (looked at every 256 events, after `tick`): the records
    /// decoded until then are written and the files completed, as at the end of the input.
    pub stop: Option<Arc<AtomicBool>>,
}

pub use aptscope_capture::judge::{not_a_capture, not_a_capture_error};

/// Decode capture `path` (`-`: standard input) into `w`. `tick` is called now and then with
/// the reader's progress. A file that is not a capture (with `judge`) fails before any row
/// group is written.
pub fn decode_file<S: Sink>(
    path: &str,
    o: &DecodeOpts,
    mut w: CaptureWriter<S>,
    tick: &mut dyn FnMut(&Progress),
) -> io::Result<(S, Summary)> {
    let (mut reader, format, progress) = open_with_progress(path, o.open)?;
    let mut dec = Decoder::new(o.proto);
    dec.set_units(o.units.clone());
    if let Some(t) = o.timeout_ns {
        dec.set_reply_timeout(t);
    }
    let judge = o.judge;
    let mut emit = |rec: &Record<'_>| -> io::Result<()> {
        if let Record::Detect { detection, .. } = rec {
            if judge && not_a_capture(format, detection) {
                return Err(not_a_capture_error(detection));
            }
        }
        w.record(rec)
    };
    let mut k = 0u32;
    while let Some(ev) = reader.next_event() {
        // A USB capture without the device asked for has nothing to decode.
        if let Event::Diag(d) = &ev {
            if d.kind() == aptscope_capture::usb::NOT_FOUND {
                return Err(io::Error::new(io::ErrorKind::InvalidInput, d.msg()));
            }
        }
        ev.feed(&mut dec, &mut emit)?;
        k = k.wrapping_add(1);
        if k.is_multiple_of(256) {
            tick(&progress);
            if o.stop.as_ref().is_some_and(|s| s.load(Ordering::Relaxed)) {
                break;
            }
        }
    }
    dec.finish(&mut emit)?;
    tick(&progress);
    w.finish()
}
