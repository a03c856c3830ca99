//! `aptscope convert`: a capture rewritten in another format, losslessly where it can be.

use crate::common::{bad, fatal, open_opts, Ticker};
use crate::error::Result;
use aptscope_capture::open::{create, open_with_progress, Format};
use aptscope_capture::Event;
use std::io;

// The options of `convert`.
#[derive(clap::Args)]
pub(crate) struct ConvertArgs {
    /// Input capture.
    pub(crate) input: String,
    /// Output file, or `-` for standard output (with --to).
    pub(crate) output: String,
    /// Input format instead of detecting it.
    #[arg(long, short = 'F')]
    pub(crate) format: Option<String>,
    /// Output format: pcapng, pcap, mcap, raw, hex.
    #[arg(long)]
    pub(crate) to: Option<String>,
    /// Overwrite OUT if it exists.
    #[arg(long)]
    pub(crate) force: bool,
    /// USB captures: only the device at BUS:ADDR.
    #[arg(long)]
    pub(crate) usb_device: Option<String>,
}

/// Convert the capture `a` names.
pub(crate) fn run(a: ConvertArgs) -> Result<()> {
    let opts = open_opts(a.format.as_deref(), false, a.usb_device.as_deref())?;
    let (input, output, to, force) = (
        a.input.as_str(),
        a.output.as_str(),
        a.to.as_deref(),
        a.force,
    );
    let target = match to {
        Some(t) => Format::parse(t).ok_or_else(|| bad(format!("unknown output format {t}")))?,
        None => Format::from_extension(output).ok_or_else(|| {
            bad(format!(
                "cannot tell the output format from {output}: use --to pcapng|pcap|mcap|raw|hex"
            ))
        })?,
    };
    if output == "-"
        && matches!(target, Format::PcapNg | Format::Pcap | Format::Raw)
        && std::io::IsTerminal::is_terminal(&io::stdout())
    {
        return Err(bad(format!(
            "{} is binary and standard output is a terminal: redirect it (> FILE, | …) or \
             name a file",
            target.name()
        )));
    }
    let (mut reader, from, progress) = open_with_progress(input, opts)?;
    let mut ticker = Ticker::new(progress);
    let mut w = create(output, target, force)?;
    let (mut chunks, mut bytes, mut diags) = (0u64, 0u64, 0u64);
    while let Some(ev) = reader.next_event() {
        ticker.tick();
        match ev {
            Event::Stream(s) => w.stream(&s)?,
            Event::Chunk(c) => {
                chunks += 1;
                bytes += c.bytes.len() as u64;
                w.chunk(&c)?;
            }
            Event::Diag(d) => {
                fatal(&d)?;
                diags += 1;
                eprintln!("aptscope: {input}: {d}");
                w.diag(&d)?;
            }
        }
    }
    w.finish()?;
    ticker.done();
    eprintln!(
        "{input} ({}) -> {output} ({}): {chunks} chunks, {bytes} bytes, {diags} input diagnostics",
        from.name(),
        target.name()
    );
    // Only what this input had that the target dropped.
    for l in w.lost() {
        eprintln!("  {} cannot carry: {l}", target.name());
    }
    Ok(())
}
