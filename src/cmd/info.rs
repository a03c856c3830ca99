//! `aptscope info`: what a capture holds (like capinfos).

use crate::common::{fatal, open_opts, proto_of, ProtoArg};
use crate::error::Result;
use aptscope_capture::info::summarize;
use aptscope_capture::open::open;
use std::io::{self, Write};

// The options of `info`.
#[derive(clap::Args)]
pub(crate) struct InfoArgs {
    /// Capture file.
    pub(crate) file: String,
    /// Input format instead of detecting it.
    #[arg(long, short = 'F')]
    pub(crate) format: Option<String>,
    /// One JSON object.
    #[arg(long)]
    pub(crate) json: bool,
    /// Protocol instead of detecting it.
    #[arg(long, value_enum, default_value_t = ProtoArg::Auto)]
    pub(crate) proto: ProtoArg,
    /// USB captures: only the device at BUS:ADDR.
    #[arg(long)]
    pub(crate) usb_device: Option<String>,
}

/// Summarize the capture `a` names.
pub(crate) fn run(a: InfoArgs) -> Result<()> {
    let opts = open_opts(a.format.as_deref(), false, a.usb_device.as_deref())?;
    let (file, as_json, proto) = (a.file.as_str(), a.json, a.proto);
    let (mut reader, _) = open(file, opts)?;
    let i = summarize(reader.as_mut(), proto_of(proto));
    i.file_diags.iter().try_for_each(fatal)?;
    let mut out = io::stdout().lock();
    if as_json {
        Ok(writeln!(out, "{}", i.to_json(file))?)
    } else {
        Ok(write!(out, "{}", i.to_text(file))?)
    }
}
