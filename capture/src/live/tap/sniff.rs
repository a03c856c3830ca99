//! A passive sniff of a Y-cable: two receive-only adapters, one per direction, merged by time
//! into one capture.

use super::port::{open_serial, SerialPort};
use super::record::{
    forward, run_recorded, stop_signals, supervise, FwdEnd, Recording, Run, Shared,
};
use super::sink::FileSink;
use super::{clock_time, SniffOptions, StopHandle, TapStats, RETRY_EVERY};
use crate::live::error::LiveError;
use crate::live::serial::LineSettings;
use crate::live::signals::Signals;
use crate::model::{Direction, StreamInfo};
use crate::open::Format;
use crate::Say;
use std::io::Write;
use std::sync::atomic::AtomicBool;
use std::thread;
use std::time::Instant;

/// Run a sniff: read the two receive-only adapters (each in its own thread), merge both
/// directions by time into the capture, show the timeline, until stopped or an adapter
/// disappears (unless `reconnect`); print and return the statistics.
pub fn sniff_main(opts: SniffOptions) -> Result<TapStats, LiveError> {
    // Handled before the set-up, as the tap does.
    let signals = stop_signals(opts.live.signals)?;
    Sniff::new(opts)?.run_installed(None, signals)
}

/// A sniff set up (ports open, file created) and ready to run.
pub(super) struct Sniff {
    pub(super) opts: SniffOptions,
    settings: LineSettings,
    ports: Vec<Option<SerialPort>>,
    pub(super) rec: Recording,
}

impl Sniff {
    pub(super) fn new(opts: SniffOptions) -> Result<Sniff, LiveError> {
        let settings = LineSettings::for_proto(opts.live.proto, opts.live.baud, opts.live.flow);
        let format = opts
            .live
            .write
            .as_deref()
            .map(|p| FileSink::format(p, opts.live.write_format))
            .transpose()?;
        let mut ports = vec![];
        for p in [&opts.host_tx, &opts.device_tx] {
            ports.push(match open_serial(p, &settings) {
                Ok(port) => Some(port),
                Err(e) if opts.live.reconnect => {
                    opts.live
                        .say
                        .line(format_args!("aptscope sniff: {e}; waiting for it"));
                    None
                }
                Err(e) => return Err(e),
            });
        }
        let sink = match &opts.live.write {
            Some(p) => Some(FileSink::for_opts(
                p,
                format.unwrap_or(Format::PcapNg),
                (false, opts.live.force, opts.live.followed),
                &StreamInfo {
                    id: 0,
                    name: format!("{} + {}", opts.host_tx, opts.device_tx),
                    settings: Some(format!("{settings} (receive-only Y-cable)")),
                },
            )?),
            None => None,
        };
        opts.live.say.line(format_args!(
            "aptscope sniff: host TX on {}, device TX on {} ({settings}){}",
            opts.host_tx,
            opts.device_tx,
            opts.live
                .write
                .as_ref()
                .map(|w| format!(", writing {w}"))
                .unwrap_or_default()
        ));
        let rec = Recording::new(opts.live.stop.clone(), opts.live.quiet, sink);
        Ok(Sniff {
            opts,
            settings,
            ports,
            rec,
        })
    }
}

impl Run for Sniff {
    const WHAT: &'static str = "aptscope sniff";

    fn control(&self) -> (bool, StopHandle, Say) {
        (
            self.opts.live.signals,
            self.opts.live.stop.clone(),
            self.opts.live.say,
        )
    }

    fn run_with(
        self,
        display: Option<Box<dyn Write + Send>>,
        signals: Option<&Signals>,
        say: Say,
    ) -> Result<TapStats, LiveError> {
        let Sniff {
            opts,
            settings,
            ports,
            rec,
        } = self;
        let (sh, sink, disp) = rec.start(say, display);
        let sh = &sh;
        let deadline = opts.live.duration.map(|d| Instant::now() + d);
        let never = AtomicBool::new(false);
        let stats = thread::scope(|scope| {
            run_recorded(
                scope,
                sh,
                sink,
                disp,
                (opts.live.proto, opts.live.units.clone()),
                || {
                    thread::scope(|s| {
                        let dirs = [Direction::HostToDevice, Direction::DeviceToHost];
                        let paths = [&opts.host_tx, &opts.device_tx];
                        for ((port, dir), path) in ports.into_iter().zip(dirs).zip(paths) {
                            let (sh, never, settings) = (&sh, &never, &settings);
                            let reconnect = opts.live.reconnect;
                            s.spawn(move || {
                                receive(path, port, dir, settings, reconnect, sh, never)
                            });
                        }
                        supervise(sh, signals, deadline, &never);
                        // The receivers see the stop within a tick.
                        sh.stop.stop();
                    });
                    Ok(())
                },
            )
        })?;
        Ok(stats)
    }
}

/// One receive-only adapter of a sniff: read and record until stopped; when it disappears,
/// report it and either stop the sniff or (with `reconnect`) reopen it.
fn receive(
    path: &str,
    mut port: Option<SerialPort>,
    dir: Direction,
    settings: &LineSettings,
    reconnect: bool,
    sh: &Shared,
    never: &AtomicBool,
) {
    loop {
        let mut p = match port.take() {
            Some(p) => p,
            None => loop {
                if sh.stop.is_stopped() {
                    return;
                }
                match open_serial(path, settings) {
                    Ok(p) => {
                        sh.say.line(format_args!(
                            "aptscope sniff: {path} back at {}",
                            clock_time(sh.clock.now())
                        ));
                        break p;
                    }
                    Err(_) => {
                        if sh.stop.wait(RETRY_EVERY) {
                            return;
                        }
                    }
                }
            },
        };
        match forward(&mut p, None, dir, sh, never) {
            FwdEnd::Stopped => return,
            FwdEnd::SrcGone(t, e) | FwdEnd::DstGone(t, e) => {
                sh.disconnect(t, path, &e);
                if !reconnect {
                    sh.stop.stop();
                    return;
                }
            }
        }
    }
}
