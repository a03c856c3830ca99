//! Records the scripted host sessions against the simulators (`capture::live::session`) on a
//! virtual clock and writes them as `samples/sessions/<session>.{pcapng,pcap,mcap,bin}`. The
//! output is byte-identical on every run. From the repository root:
//! `cargo run -p aptscope-capture --example record_sessions -- samples/sessions`

use aptscope_capture::live::session::{record, write_recording, NAMES};
use std::path::PathBuf;
use std::process::ExitCode;

fn main() -> ExitCode {
    let dir = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "samples/sessions".into()),
    );
    if let Err(e) = std::fs::create_dir_all(&dir) {
        eprintln!("{}: {e}", dir.display());
        return ExitCode::FAILURE;
    }
    for name in NAMES {
        let rec = match record(name) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("{name}: {e}");
                return ExitCode::FAILURE;
            }
        };
        match write_recording(&rec, &dir) {
            Ok(paths) => {
                for p in paths {
                    eprintln!("wrote {}", p.display());
                }
            }
            Err(e) => {
                eprintln!("{name}: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    ExitCode::SUCCESS
}
