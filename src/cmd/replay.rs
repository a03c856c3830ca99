//! `aptscope replay`: a capture sent again with its timing, the replies compared.

use crate::common::{bad, open_opts, proto_of, ProtoArg};
use crate::error::{CliError, Result};
use aptscope_capture::live::serial::Flow;
use aptscope_replay::{replay_main, ReplayArgs, ReplayOptions};

// The options of `replay`: the replay's own, and how the capture is read.
#[derive(clap::Args)]
pub(crate) struct ReplayCmd {
    /// The options the replay takes as given.
    #[command(flatten)]
    pub(crate) args: ReplayArgs,
    /// Protocol (default: detected from the capture).
    #[arg(long, value_enum, default_value_t = ProtoArg::Auto)]
    pub(crate) proto: ProtoArg,
    /// Input format instead of detecting it.
    #[arg(long, short = 'F')]
    pub(crate) format: Option<String>,
    /// Flow control: none, rtscts, xonxoff (default: the protocol's).
    #[arg(long)]
    pub(crate) flow: Option<String>,
}

/// Replay the capture `a` names.
pub(crate) fn run(a: ReplayCmd) -> Result<()> {
    let open = open_opts(a.format.as_deref(), false, None)?;
    let flow = match a.flow {
        None => None,
        Some(f) => Some(
            Flow::parse(&f)
                .ok_or_else(|| bad(format!("unknown flow control {f} (none, rtscts, xonxoff)")))?,
        ),
    };
    let o = ReplayOptions {
        args: a.args,
        open,
        proto: proto_of(a.proto),
        flow,
    };
    match replay_main(o) {
        Ok(true) => Ok(()),
        Ok(false) => Err(CliError::Differences),
        Err(e) => Err(e.into()),
    }
}
