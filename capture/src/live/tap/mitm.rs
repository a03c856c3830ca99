//! The tap proper: a pseudo-terminal man-in-the-middle between a host program and a serial
//! device, forwarding both ways and recording what crossed.

use super::port::{open_device, DevicePair, FdPort, HostPty, Port};
use super::record::{
    forward, run_recorded, stop_signals, supervise, FwdEnd, Recording, Run, Shared,
};
use super::sink::FileSink;
use super::{clock_time, StopHandle, TapOptions, TapStats, READ_BUF, RETRY_EVERY};
use crate::live::error::LiveError;
use crate::live::serial::LineSettings;
use crate::live::signals::Signals;
use crate::model::{Direction, StreamInfo};
use crate::open::Format;
use crate::Say;
use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;
use std::time::{Duration, Instant};

/// Run a tap: create the pseudo-terminal (symlinked at `opts.link`), open the device, forward
/// both ways until stopped (signal, [`StopHandle`], duration) or the device disappears (unless
/// `reconnect`), write the capture, show the timeline; print and return the statistics.
pub fn tap_main(opts: TapOptions) -> Result<TapStats, LiveError> {
    // Handled before the host link appears: a SIGTERM sent as soon as it does (Wireshark
    // stopping an extcap capture) ends the tap cleanly instead of killing it.
    let signals = stop_signals(opts.live.signals)?;
    Tap::new(opts)?.run_installed(None, signals)
}

/// A tap set up (device open, pseudo-terminal and file created) and ready to run.
pub(super) struct Tap {
    pub(super) opts: TapOptions,
    settings: LineSettings,
    device: Option<DevicePair>,
    pub(super) host: HostPty,
    rec: Recording,
}

impl Tap {
    pub(super) fn new(opts: TapOptions) -> Result<Tap, LiveError> {
        let settings = LineSettings::for_proto(opts.live.proto, opts.live.baud, opts.live.flow);
        let format = match (&opts.live.write, opts.stream) {
            // A pipe's name says nothing about what goes through it.
            (Some(_), true) => Some(opts.live.write_format.unwrap_or(Format::PcapNg)),
            (p, _) => p
                .as_deref()
                .map(|p| FileSink::format(p, opts.live.write_format))
                .transpose()?,
        };
        let device = match open_device(&opts.device, &settings) {
            Ok(d) => Some(d),
            Err(e) if opts.live.reconnect => {
                opts.live
                    .say
                    .line(format_args!("aptscope tap: {e}; waiting for it"));
                None
            }
            Err(e) => return Err(e),
        };
        let host = HostPty::create(opts.link.as_deref())?;
        let info = StreamInfo {
            id: 0,
            name: opts.device.clone(),
            settings: Some(settings.to_string()),
        };
        let format = format.unwrap_or(Format::PcapNg);
        let sink = match &opts.live.write {
            Some(p) => Some(FileSink::for_opts(
                p,
                format,
                (opts.stream, opts.live.force, opts.live.followed),
                &info,
            )?),
            None => None,
        };
        opts.live.say.line(format_args!(
            "aptscope tap: host side {}{} ⇄ device {} ({settings}){}",
            host.slave_path.display(),
            host.link
                .as_ref()
                .map(|l| format!(" (link {})", l.path().display()))
                .unwrap_or_default(),
            opts.device,
            opts.live
                .write
                .as_ref()
                .map(|w| format!(", writing {w}"))
                .unwrap_or_default()
        ));
        let rec = Recording::new(opts.live.stop.clone(), opts.live.quiet, sink);
        Ok(Tap {
            opts,
            settings,
            device,
            host,
            rec,
        })
    }
}

impl Run for Tap {
    const WHAT: &'static str = "aptscope tap";

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
        let Tap {
            opts,
            settings,
            mut device,
            host,
            rec,
        } = self;
        let (sh, sink, disp) = rec.start(say, display);
        let sh = &sh;
        let deadline = opts.live.duration.map(|d| Instant::now() + d);
        let mut host_r = host.master.try_clone()?;
        let mut host_w = host.master.try_clone()?;
        let stats = thread::scope(|scope| {
            run_recorded(
                scope,
                sh,
                sink,
                disp,
                (opts.live.proto, opts.live.units.clone()),
                || loop {
                    let (mut dev_r, mut dev_w) = match device.take() {
                        Some(d) => d,
                        None => match wait_for_device(
                            &opts.device,
                            &settings,
                            &mut host_r,
                            sh,
                            signals,
                            deadline,
                        ) {
                            Some(d) => d,
                            None => return Ok(()),
                        },
                    };
                    let end = AtomicBool::new(false);
                    let (h2d, d2h) = thread::scope(|s| {
                        let (sh, end) = (&sh, &end);
                        let finish = move |r: FwdEnd| {
                            end.store(true, Ordering::SeqCst);
                            sh.stop.wake();
                            r
                        };
                        let (host_r, host_w) = (&mut host_r, &mut host_w);
                        let (dev_r, dev_w): (&mut dyn Port, &mut dyn Port) =
                            (&mut *dev_r, &mut *dev_w);
                        let h = s.spawn(move || {
                            let to = Some(dev_w);
                            finish(forward(host_r, to, Direction::HostToDevice, sh, end))
                        });
                        let d = s.spawn(move || {
                            let to: Option<&mut dyn Port> = Some(host_w);
                            finish(forward(dev_r, to, Direction::DeviceToHost, sh, end))
                        });
                        supervise(sh, signals, deadline, end);
                        end.store(true, Ordering::SeqCst);
                        (
                            h.join().unwrap_or(FwdEnd::Stopped),
                            d.join().unwrap_or(FwdEnd::Stopped),
                        )
                    });
                    let (dev_gone, host_gone) = match (h2d, d2h) {
                        (FwdEnd::SrcGone(t, e), _) | (_, FwdEnd::DstGone(t, e)) => {
                            (None, Some((t, e)))
                        }
                        (FwdEnd::DstGone(t, e), _) | (_, FwdEnd::SrcGone(t, e)) => {
                            (Some((t, e)), None)
                        }
                        (FwdEnd::Stopped, FwdEnd::Stopped) => (None, None),
                    };
                    if let Some((_, e)) = host_gone {
                        return Err(LiveError::HostSide(e));
                    }
                    if let Some((t, e)) = dev_gone {
                        sh.disconnect(t, &opts.device, &e);
                        if opts.live.reconnect && !sh.stop.is_stopped() {
                            sh.say.line(format_args!(
                                "aptscope tap: waiting for {} to come back",
                                opts.device
                            ));
                            continue;
                        }
                    }
                    return Ok(());
                },
            )
        })?;
        drop(host);
        Ok(stats)
    }
}

/// With the device away: keep draining (and discarding) what the host writes, and try to
/// reopen the device every [`RETRY_EVERY`], until it is back or the tap is stopped.
fn wait_for_device(
    path: &str,
    settings: &LineSettings,
    host_r: &mut FdPort,
    sh: &Shared,
    signals: Option<&Signals>,
    deadline: Option<Instant>,
) -> Option<DevicePair> {
    let mut buf = vec![0u8; READ_BUF];
    let mut last_try: Option<Instant> = None;
    loop {
        if sh.stop.is_stopped() {
            return None;
        }
        if deadline.is_some_and(|d| Instant::now() >= d) {
            sh.stop.stop();
            return None;
        }
        if let Some(sig) = signals.and_then(|s| s.wait(Duration::ZERO)) {
            sh.stop.stop();
            sh.say.line(format_args!("aptscope: {sig}: stopping"));
            return None;
        }
        if last_try.is_none_or(|t| t.elapsed() >= RETRY_EVERY) {
            last_try = Some(Instant::now());
            if let Ok(d) = open_device(path, settings) {
                sh.say.line(format_args!(
                    "aptscope tap: {path} back at {}",
                    clock_time(sh.clock.now())
                ));
                return Some(d);
            }
        }
        match host_r.read_tick(&mut buf) {
            Ok(n) => {
                sh.discarded_h2d.fetch_add(n as u64, Ordering::Relaxed);
            }
            Err(e) => {
                sh.say.line(format_args!("aptscope tap: host side: {e}"));
                sh.stop.stop();
                return None;
            }
        }
    }
}
