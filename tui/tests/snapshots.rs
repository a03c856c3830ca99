//! Rendering snapshots (`insta`) at 80×24 and 160×48 with ratatui's `TestBackend`.

use aptscope_capture::open::OpenOptions;
use aptscope_tui::app::App;
use aptscope_tui::index::load;
use aptscope_tui::ui::draw;
use ratatui::backend::TestBackend;
use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use ratatui::Terminal;

fn app(name: &str) -> App {
    let path = format!("{}/../samples/{name}", env!("CARGO_MANIFEST_DIR"));
    let shared = load(&path, OpenOptions::default()).expect("sample opens");
    App::new(shared, name, false)
}

fn keys(app: &mut App, s: &str) {
    for c in s.chars() {
        let code = match c {
            '\n' => KeyCode::Enter,
            '\t' => KeyCode::Tab,
            c => KeyCode::Char(c),
        };
        app.on_key(KeyEvent::new(code, KeyModifiers::NONE));
    }
}

fn screen(app: &mut App, w: u16, h: u16) -> String {
    let mut t = Terminal::new(TestBackend::new(w, h)).expect("terminal");
    // Twice: the first draw learns the pane sizes (as in the real loop).
    t.draw(|f| draw(f, app)).expect("draw");
    t.draw(|f| draw(f, app)).expect("draw");
    format!("{}", t.backend())
}

fn both(name: &str, prep: &str, snap: &str) {
    for (w, h) in [(80, 24), (160, 48)] {
        let mut a = app(name);
        // Learn the sizes before moving (page keys depend on them).
        let _ = screen(&mut a, w, h);
        keys(&mut a, prep);
        insta::assert_snapshot!(format!("{snap}_{w}x{h}"), screen(&mut a, w, h));
    }
}

#[test]
fn timeline_first_screen() {
    both("kdc101-session.pcapng", "", "kdc_first");
}

#[test]
fn status_update_detail_with_flags_and_field_highlight() {
    // Record 8, detail pane, down to the status bits field.
    both(
        "kdc101-session.pcapng",
        ":8\n\tjjjjjjjjjjjj",
        "kdc_status_detail",
    );
}

#[test]
fn reply_with_pair_and_delta_time() {
    both("kdc101-session.pcapng", ":12\nt", "kdc_pair_delta");
}

#[test]
fn damaged_capture_diagnostics() {
    both("damaged.bin", "G", "damaged_end");
}

#[test]
fn elliptec_bus() {
    both("elliptec-bus.txt", "jjjjjjj", "ell_bus");
}

#[test]
fn rack_bays() {
    both("bsc203-rack.hex", "jjj\tjjjjj", "rack_bays");
}

#[test]
fn filter_error_column() {
    both("kdc101-session.pcapng", "/apt.name == ", "filter_error");
}

#[test]
fn filter_applied() {
    both(
        "kdc101-session.pcapng",
        "/apt.name ~ MOVE\n",
        "filter_applied",
    );
}

#[test]
fn statistics_view() {
    both("kdc101-session.pcapng", "2", "stats");
}

#[test]
fn plot_view() {
    both("kdc101-session.pcapng", "3", "plot");
}

#[test]
fn help_overlay() {
    both("kdc101-session.pcapng", "?", "help");
}
