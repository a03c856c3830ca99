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

/// What `aptscope` exits with, and when: `aptscope --help` and every man page list them.
const EXIT_STATUS: &[(&str, &str)] = &[
    (
        "0",
        "It did what was asked. A capture read to its end is a success however damaged it is: \
         garbage, truncated frames, unknown ids and a file cut short are diagnostics in the \
         output, with their byte offsets, not failures. A reader that goes away (`| head`) \
         ends it quietly, with 0.",
    ),
    (
        "1",
        "An error, said on standard error: a file or port that cannot be opened, read or \
         written; input that is not APT or Elliptec traffic in any format aptscope reads; \
         `replay --check` or `probe --check` finding differences; a tap or sniff whose \
         capture file does not hold every byte it forwarded; `decode --to parquet` stopped \
         by a signal before the end of its input.",
    ),
    (
        "2",
        "The command line is wrong: an unknown command or option, or a value an option does \
         not take.",
    ),
];

/// [`EXIT_STATUS`] as the end of `aptscope --help`: each status, its text wrapped beside it
/// at 80 columns.
pub fn exit_status_help() -> String {
    let mut s = String::from("Exit status:");
    for (code, what) in EXIT_STATUS {
        s.push_str(&format!("\n  {code} "));
        let mut col = 4;
        for word in what.split(' ') {
            if col + 1 + word.chars().count() > 80 {
                s.push_str("\n    ");
                col = 4;
            }
            s.push(' ');
            s.push_str(word);
            col += 1 + word.chars().count();
        }
    }
    s
}

/// [`EXIT_STATUS`] as a man page's EXIT STATUS section (roff).
fn exit_status_roff() -> String {
    let mut s = String::from(".SH \"EXIT STATUS\"\n");
    for (code, what) in EXIT_STATUS {
        // Roff: a hyphen is `\-`, a backslash `\e`; no line of this text starts with a dot.
        let what = what.replace('\\', "\\e").replace('-', "\\-");
        s.push_str(&format!(".TP\n\\fB{code}\\fR\n{what}\n"));
    }
    s
}

/// Print the man page (roff) of the command at `path` under `aptscope` (`[]`: aptscope itself,
/// `["sim", "apt"]`), named `aptscope-sim-apt` as `man` expects of a subcommand's page.
pub fn man(path: &[String]) -> io::Result<()> {
    // No `help` subcommand on the pages: it is not a command with a page of its own.
    // Nor `--help`'s closing text: the EXIT STATUS section below says it.
    let mut cmd = crate::Cli::command()
        .disable_help_subcommand(true)
        .after_long_help(None::<&str>);
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
    // Before the VERSION section (its place in man-pages(7)'s order), else at the end.
    let page = String::from_utf8_lossy(&buf);
    let at = page.find("\n.SH VERSION").map_or(page.len(), |i| i + 1);
    let page = format!("{}{}{}", &page[..at], exit_status_roff(), &page[at..]);
    io::stdout().lock().write_all(page.as_bytes())
}
