//! What the subcommands share: protocol and units options, opening captures, filters, the
//! progress line, and the error for a bad argument.

use crate::error::{CliError, Result};
use aptscope_capture::open::{Format, OpenOptions, Progress};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::filter::Filter;
use aptscope_dissector::units::UnitsOpts;
use std::io;

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum ProtoArg {
    Auto,
    Apt,
    Elliptec,
}

/// Physical units of APT motion values (spec section 8), for the commands that decode.
#[derive(clap::Args)]
pub(crate) struct UnitsArgs {
    /// The stage the APT controller drives (`MTS25-Z8`, `Z825`, `DDS220`, `LTS150`…): positions,
    /// velocities and accelerations are also shown in mm (or deg) and mm/s, mm/s2.
    #[arg(long, value_name = "NAME")]
    stage: Option<String>,
    /// Counts (or microsteps) per unit for a stage section 8 does not list: `34554.96/mm`,
    /// `1919.64/deg` (unit mm when left out).
    #[arg(long, value_name = "X[/UNIT]", conflicts_with = "stage")]
    scale: Option<String>,
    /// The controller (a model, `KDC101`, or a family, `dc_servo`, `brushless`, `stepper`,
    /// `stepper_trinamic`), when the capture has no HW_GET_INFO to tell it.
    #[arg(long, value_name = "MODEL")]
    controller: Option<String>,
}

impl UnitsArgs {
    pub(crate) fn opts(&self) -> Result<UnitsOpts> {
        UnitsOpts::from_args(
            self.stage.as_deref(),
            self.scale.as_deref(),
            self.controller.as_deref(),
        )
        .map_err(bad)
    }
}

pub(crate) fn proto_of(p: ProtoArg) -> Option<Proto> {
    match p {
        ProtoArg::Auto => None,
        ProtoArg::Apt => Some(Proto::Apt),
        ProtoArg::Elliptec => Some(Proto::Elliptec),
    }
}

pub(crate) fn open_opts(format: Option<&str>, hex: bool, usb: Option<&str>) -> Result<OpenOptions> {
    let format = match (format, hex) {
        (Some(f), _) => Some(Format::parse(f).ok_or_else(|| {
            bad(format!(
                "unknown format {f} (one of {})",
                Format::NAMES.join(", ")
            ))
        })?),
        (None, true) => Some(Format::Hex),
        (None, false) => None,
    };
    let usb_device = match usb {
        None => None,
        Some(s) => {
            let (b, a) = s
                .split_once(':')
                .ok_or_else(|| bad(format!("--usb-device takes BUS:ADDR, not {s}")))?;
            Some((
                b.parse().map_err(|_| bad(format!("bad bus {b}")))?,
                a.parse().map_err(|_| bad(format!("bad address {a}")))?,
            ))
        }
    };
    Ok(OpenOptions {
        format,
        usb_device,
        follow: None,
    })
}

/// A reader's diagnostic that makes the command fail: the input has nothing of what was asked
/// for (`--usb-device` naming no device of the capture).
pub(crate) fn fatal(d: &aptscope_capture::ReadDiag) -> Result<()> {
    if d.kind() == aptscope_capture::usb::NOT_FOUND {
        return Err(bad(d.msg()));
    }
    Ok(())
}

pub(crate) fn compile_filter(src: &str) -> Result<Filter> {
    Filter::parse(src).map_err(|e| bad(format!("bad filter: {e}\n{}", e.caret(src))))
}

pub(crate) fn bad(msg: String) -> CliError {
    CliError::Usage(msg)
}

/// A progress line on stderr for long jobs, only when stderr is a terminal.
pub(crate) struct Ticker {
    progress: Progress,
    on: bool,
    last: std::time::Instant,
    count: u32,
    shown: bool,
}

impl Ticker {
    pub(crate) fn new(progress: Progress) -> Self {
        use std::io::IsTerminal;
        Ticker {
            progress,
            on: io::stderr().is_terminal(),
            last: std::time::Instant::now(),
            count: 0,
            shown: false,
        }
    }

    pub(crate) fn tick(&mut self) {
        self.count = self.count.wrapping_add(1);
        if !self.on
            || !self.count.is_multiple_of(4096)
            || self.last.elapsed() < std::time::Duration::from_millis(250)
        {
            return;
        }
        self.last = std::time::Instant::now();
        let mb = self
            .progress
            .read
            .load(std::sync::atomic::Ordering::Relaxed) as f64
            / 1e6;
        match self.progress.fraction() {
            Some(f) => eprint!("\r{:5.1}%  {mb:.1} MB ", f * 100.0),
            None => eprint!("\r{mb:.1} MB "),
        }
        self.shown = true;
    }

    pub(crate) fn done(&mut self) {
        if self.shown {
            eprint!("\r{:30}\r", "");
        }
    }
}
