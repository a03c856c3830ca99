//! `completions` and `man`: shell completion scripts and man pages made from the clap
//! definitions, so they list the same commands and options as `--help`.

use clap::CommandFactory;
use std::io::{self, Write};

/// Print the completion script of `shell` for `aptscope`.
pub fn completions(shell: clap_complete::Shell) -> io::Result<()> {
    // Into a buffer first: `generate` panics when a write fails (a closed pipe).
    let mut buf = vec![];
    clap_complete::generate(shell, &mut crate::Cli::command(), "aptscope", &mut buf);
    io::stdout().lock().write_all(&buf)
}

/// Print the man page (roff) of the command at `path` under `aptscope` (`[]`: aptscope itself,
/// `["sim", "apt"]`), named `aptscope-sim-apt` as `man` expects of a subcommand's page.
pub fn man(path: &[String]) -> io::Result<()> {
    // No `help` subcommand on the pages: it is not a command with a page of its own.
    let mut cmd = crate::Cli::command().disable_help_subcommand(true);
    // Building sets each subcommand's page name (`aptscope-decode`) and usage (`aptscope decode`).
    cmd.build();
    for name in path {
        let sub = cmd.find_subcommand(name).cloned().ok_or_else(|| {
            let names: Vec<&str> = cmd.get_subcommands().map(|c| c.get_name()).collect();
            let what = match names.is_empty() {
                true => format!("`{}` has no subcommands", cmd.get_bin_name().unwrap_or("")),
                false => format!("the commands are {}", names.join(", ")),
            };
            crate::common::bad(format!("man: no command `{name}`: {what}"))
        })?;
        cmd = sub;
    }
    let mut buf = vec![];
    // The footer: the version short (the commit would run into the date at 80 columns; the
    // VERSION section has it), and the commit's date as the page's.
    clap_mangen::Man::new(cmd)
        .source(concat!("aptscope ", env!("CARGO_PKG_VERSION")))
        .date(env!("APTSCOPE_COMMIT_DATE"))
        .manual("aptscope manual")
        .render(&mut buf)?;
    io::stdout().lock().write_all(&buf)
}
