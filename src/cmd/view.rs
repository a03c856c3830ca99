//! `aptscope view`: a capture in the terminal UI.

use crate::common::{open_opts, proto_of, ProtoArg, UnitsArgs};
use crate::error::Result;
use aptscope_capture::follow::FollowStop;

// The options of `view`.
#[derive(clap::Args)]
pub(crate) struct ViewArgs {
    /// Capture file.
    pub(crate) file: String,
    /// Input format instead of detecting it.
    #[arg(long, short = 'F')]
    pub(crate) format: Option<String>,
    /// Protocol (default: detected from the first 4 KiB).
    #[arg(long, value_enum, default_value_t = ProtoArg::Auto)]
    pub(crate) proto: ProtoArg,
    /// USB captures: only the device at BUS:ADDR.
    #[arg(long)]
    pub(crate) usb_device: Option<String>,
    /// Follow a capture another program (a tap) is still writing, like `tail -f`: new
    /// records appear as the file grows; a cut last block is waited for. `-` (a pipe:
    /// `dumpcap -w - | aptscope view --follow -`) is followed until its writer ends.
    #[arg(long)]
    pub(crate) follow: bool,
    #[command(flatten)]
    pub(crate) units: UnitsArgs,
    /// Memory the index of the records may take (`512M`, `2G`; default 512M, or a quarter of
    /// the machine's memory when that is less); beyond it, older records are kept in a scratch file in
    /// `$XDG_CACHE_HOME/aptscope` (or the temporary directory) and read back when shown.
    #[arg(long, value_name = "SIZE", value_parser = parse_size)]
    pub(crate) index_memory: Option<u64>,
    /// Neither read nor write the index cache (`$XDG_CACHE_HOME/aptscope/index`: a capture
    /// indexed completely before and unchanged since opens at once from there);
    /// `APTSCOPE_NO_INDEX_CACHE=1` does the same.
    #[arg(long)]
    pub(crate) no_cache: bool,
}

fn parse_size(s: &str) -> std::result::Result<u64, String> {
    aptscope_tui::index::parse_size(s)
        .ok_or_else(|| format!("`{s}` is not a size (bytes, or with K, M, G or T: `512M`, `2G`)"))
}

/// Browse the capture `a` names in the terminal UI.
pub(crate) fn run(a: ViewArgs) -> Result<()> {
    if let Some(bytes) = a.index_memory {
        aptscope_tui::index::set_index_memory(bytes);
    }
    if a.no_cache {
        aptscope_tui::index::set_index_cache(false);
    }
    let mut o = open_opts(a.format.as_deref(), false, a.usb_device.as_deref())?;
    // Standard input is followed as it comes, with or without --follow (a pipe ends when its
    // writer does: `dumpcap -w - | aptscope view --follow -`).
    if a.follow && a.file != "-" {
        // Nothing says when another program's writing ends: followed until `q`.
        o.follow = Some(FollowStop::new());
    }
    let source = aptscope_tui::Source::File {
        path: &a.file,
        opts: o,
        proto: proto_of(a.proto),
        units: a.units.opts()?,
    };
    Ok(aptscope_tui::run(source, Default::default())?)
}
