//! `cargo run -p aptscope-tui --example view -- FILE [FORMAT]`: the viewer without the CLI.

fn main() -> std::io::Result<()> {
    let mut args = std::env::args().skip(1);
    let Some(path) = args.next() else {
        eprintln!("usage: view FILE [FORMAT]");
        std::process::exit(2);
    };
    let format = args
        .next()
        .and_then(|f| aptscope_capture::open::Format::parse(&f));
    aptscope_tui::run(
        aptscope_tui::Source::File {
            path: &path,
            opts: aptscope_capture::open::OpenOptions {
                format,
                ..Default::default()
            },
            proto: None,
            units: Default::default(),
        },
        Default::default(),
    )
}
