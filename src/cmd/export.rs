//! `aptscope export`: the message tables for other tools.

use crate::error::Result;
use std::io::{self, Write};

#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum ExportArg {
    /// A Wireshark/tshark Lua dissector generated from the tables.
    WiresharkLua,
}

// The options of `export`.
#[derive(clap::Args)]
pub(crate) struct ExportArgs {
    /// What to write.
    #[arg(value_enum)]
    pub(crate) what: ExportArg,
    /// Output file (default: standard output).
    #[arg(short, long)]
    pub(crate) output: Option<String>,
}

/// Write what `a` asks for.
pub(crate) fn run(a: ExportArgs) -> Result<()> {
    match a.what {
        ExportArg::WiresharkLua => {
            let lua = aptscope_dissector::wireshark::lua();
            match a.output.as_deref() {
                None | Some("-") => Ok(io::stdout().lock().write_all(lua.as_bytes())?),
                Some(path) => Ok(std::fs::write(path, lua)
                    .map_err(|e| io::Error::new(e.kind(), format!("{path}: {e}")))?),
            }
        }
    }
}
