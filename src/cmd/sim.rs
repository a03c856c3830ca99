//! `aptscope sim`: a simulated controller on a pseudo-terminal or a serial port, or in the
//! terminal UI behind a tap (`--view`).

use crate::cmd::live::{end_abandoned, live_view, return_view, viewed_file};
use crate::error::Result;
use aptscope_capture::live::sim::{
    apt_sim, ell_model_list, ell_sim, model_list, sim_apt_main, sim_elliptec_main, SimLine,
};
use aptscope_capture::live::tap::{sim_with_view, TapOptions};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::units::UnitsOpts;

#[derive(clap::Subcommand)]
pub(crate) enum SimCmd {
    /// An APT controller.
    Apt {
        /// The controller model, any the spec names (`--list` shows them): kdc101, tdc001,
        /// bsc203 (three bays), kpz101, k10cr1, kim101, tls001 …
        #[arg(long, default_value = "kdc101")]
        model: String,
        /// List the models with their family, bays and channels, and exit.
        #[arg(long)]
        list: bool,
        /// Symlink to the pseudo-terminal.
        #[arg(long, conflicts_with = "port")]
        pty: Option<std::path::PathBuf>,
        /// Serve on this serial port instead (a null-modem cable to the host's port).
        #[arg(long)]
        port: Option<std::path::PathBuf>,
        /// Baud rate on --port.
        #[arg(long, default_value_t = 115_200)]
        baud: u32,
        /// End when the first host program closes the port (by default the simulator serves
        /// one program after another until stopped, as a controller stays on).
        #[arg(long, conflicts_with = "port")]
        once: bool,
        #[command(flatten)]
        view: SimView,
    },
    /// An Elliptec bus.
    Elliptec {
        /// Modules by address: `0:ELL14,1:ELL9`.
        #[arg(long, default_value = "0:ELL14")]
        modules: String,
        /// List the simulated models (travel, pulses, slots, motors, commands) and exit.
        #[arg(long, conflicts_with_all = ["pty", "port", "once"])]
        list: bool,
        /// Symlink to the pseudo-terminal.
        #[arg(long, conflicts_with = "port")]
        pty: Option<std::path::PathBuf>,
        /// Serve on this serial port instead.
        #[arg(long)]
        port: Option<std::path::PathBuf>,
        /// Baud rate on --port.
        #[arg(long, default_value_t = 9_600)]
        baud: u32,
        /// End when the first host program closes the port.
        #[arg(long, conflicts_with = "port")]
        once: bool,
        #[command(flatten)]
        view: SimView,
    },
}

/// `sim … --view`: the simulator's own traffic in the terminal UI.
#[derive(clap::Args)]
pub(crate) struct SimView {
    /// Show the simulator's traffic live in the terminal UI (recorded by a tap in front of
    /// it, to -w or a temporary pcapng whose path is printed on exit); `q` ends both.
    #[arg(long, conflicts_with_all = ["port", "once"])]
    pub(crate) view: bool,
    /// With --view: write the capture here (pcapng, or pcap by the .pcap extension).
    #[arg(short = 'w', long, requires = "view")]
    pub(crate) write: Option<String>,
    /// With --view: overwrite the -w file if it exists.
    #[arg(long, requires = "write")]
    pub(crate) force: bool,
}

/// Run the simulator `what` names.
pub(crate) fn run(what: SimCmd) -> Result<()> {
    match what {
        SimCmd::Apt { list: true, .. } => {
            print!("{}", model_list());
            Ok(())
        }
        SimCmd::Elliptec { list: true, .. } => {
            print!("{}", ell_model_list());
            Ok(())
        }
        SimCmd::Apt {
            model, pty, view, ..
        } if view.view => sim_view(Box::new(apt_sim(&model)?), Proto::Apt, pty, view),
        SimCmd::Elliptec {
            modules, pty, view, ..
        } if view.view => sim_view(Box::new(ell_sim(&modules)?), Proto::Elliptec, pty, view),
        SimCmd::Apt {
            model,
            pty,
            port,
            baud,
            once,
            ..
        } => Ok(sim_apt_main(
            &model,
            sim_line(pty.as_deref(), port.as_deref(), baud, once),
        )?),
        SimCmd::Elliptec {
            modules,
            pty,
            port,
            baud,
            once,
            ..
        } => Ok(sim_elliptec_main(
            &modules,
            sim_line(pty.as_deref(), port.as_deref(), baud, once),
        )?),
    }
}

fn sim_line<'a>(
    pty: Option<&'a std::path::Path>,
    port: Option<&'a std::path::Path>,
    baud: u32,
    once: bool,
) -> SimLine<'a> {
    match port {
        Some(p) => SimLine::Port(p, baud),
        None if once => SimLine::PtyOnce(pty),
        None => SimLine::Pty(pty),
    }
}

/// `sim … --view`: the simulator behind a tap whose host side is `pty` (or the printed
/// pseudo-terminal), the tap's file in the terminal UI.
fn sim_view(
    sim: Box<dyn aptscope_capture::live::sim::Simulator + Send>,
    proto: Proto,
    pty: Option<std::path::PathBuf>,
    view: SimView,
) -> Result<()> {
    let link = pty.map(|p| p.to_string_lossy().into_owned());
    let mut o = TapOptions::new(String::new(), link);
    o.live.proto = proto;
    o.live.write = view.write;
    o.live.force = view.force;
    let path = viewed_file(&mut o.live.write, "sim");
    let r = sim_with_view(
        sim,
        o,
        |v| live_view(v, proto, UnitsOpts::default()),
        end_abandoned,
    );
    return_view(r, &path, "aptscope sim")
}
