//! The live timeline: what the display channel brings, decoded and printed as it comes; a
//! slow terminal makes it skip (and say so), never the file.

use super::queue::Rec;
use super::record::Shared;
use super::TICK;
use aptscope_dissector::detect::Proto;
use aptscope_dissector::pipeline::{Ctx, Format as OutFormat, Pipeline};
use aptscope_dissector::table::Dir;
use aptscope_dissector::units::UnitsOpts;
use std::io::{self, Write};
use std::sync::atomic::Ordering;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::sync::Arc;

/// The live timeline: decodes what the display channel brings, writes lines to `out`.
pub(super) fn display_loop(
    rx: Receiver<Arc<Rec>>,
    (proto, units): (Proto, UnitsOpts),
    out: &mut dyn Write,
    sh: &Shared,
) {
    let mut p = Pipeline::new(Some(proto), OutFormat::Text);
    p.set_units(units);
    let mut broken = false;
    let mut reported = 0u64;
    let mut emit = |line: &str| -> io::Result<()> { writeln!(out, "{line}") };
    let mut show = |r: &Rec, p: &mut Pipeline, broken: &mut bool, reported: &mut u64| {
        if *broken {
            return;
        }
        let skipped = sh.display_skipped.load(Ordering::Relaxed);
        if skipped > *reported {
            let n = skipped - *reported;
            *reported = skipped;
            if emit(&format!(
                "# display skipped {n} bytes (terminal too slow); the capture file has them"
            ))
            .is_err()
            {
                *broken = true;
                return;
            }
        }
        let ctx = Ctx {
            stream: 0,
            dir: r.dir.dir(),
            ts_ns: Some(r.ts),
        };
        if p.push_chunk(ctx, &r.bytes, &mut emit).is_err() {
            *broken = true;
        }
        // Live, a host's read is its write: show an Elliptec command sent without terminator
        // now, not when the host next writes (a module that never answers would hide it).
        if ctx.dir == Some(Dir::HostToDevice) && p.cut(0, Dir::HostToDevice, &mut emit).is_err() {
            *broken = true;
        }
    };
    loop {
        match rx.recv_timeout(TICK) {
            Ok(r) => show(&r, &mut p, &mut broken, &mut reported),
            Err(RecvTimeoutError::Timeout) => {
                if sh.display_done.load(Ordering::SeqCst) {
                    while let Ok(r) = rx.try_recv() {
                        show(&r, &mut p, &mut broken, &mut reported);
                    }
                    break;
                }
            }
            Err(RecvTimeoutError::Disconnected) => break,
        }
    }
    if !broken {
        let _ = p.finish(&mut emit);
    }
    let _ = out.flush();
}

/// Standard output, flushed line by line (a live display).
pub(super) struct LineOut(pub(super) io::Stdout);

impl Write for LineOut {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let mut l = self.0.lock();
        l.write_all(buf)?;
        if buf.ends_with(b"\n") {
            l.flush()?;
        }
        Ok(buf.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        self.0.flush()
    }
}
