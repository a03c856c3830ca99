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
    // Twice, as the real loop draws: a second frame shows the same (the update step before
    // each draw fits the state to the screen).
    t.draw(|f| draw(f, app)).expect("draw");
    t.draw(|f| draw(f, app)).expect("draw");
    format!("{}", t.backend())
}

fn both(name: &str, prep: &str, snap: &str) {
    sizes(name, prep, snap, &[(80, 24), (160, 48)]);
}

fn sizes(name: &str, prep: &str, snap: &str, sizes: &[(u16, u16)]) {
    for &(w, h) in sizes {
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
        ":8\n\tjjjjjjjjjjjjj",
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
fn several_streams_show_their_port() {
    // Three controllers on three ports: each row says which.
    both("sessions/laser-tec-quad.pcapng", "", "several_streams");
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

#[test]
fn help_overlay_fits_wide_windows_and_scrolls_in_small_ones() {
    // Wide enough for every entry on one line, tall enough for all: no scroll footer.
    sizes(
        "kdc101-session.pcapng",
        "?",
        "help",
        &[(120, 50), (200, 50), (60, 20)],
    );
    // Scrolled to its end in the smallest usual terminal.
    sizes("kdc101-session.pcapng", "?G", "help_end", &[(80, 24)]);
}

#[test]
fn detail_scrolled_sideways() {
    // Record 2 (HW_GET_INFO, long lines), detail pane, three steps right.
    both("kdc101-session.pcapng", ":2\n\t>>>", "detail_right");
}

#[test]
fn tall_window_gives_the_hex_pane_more_rows() {
    // HW_GET_INFO is 90 bytes: six rows of hex when the window has the height.
    sizes("kdc101-session.pcapng", ":2\n", "tall_hex", &[(80, 48)]);
}

#[test]
fn garbage_rows_show_their_direction() {
    // A capture with directions: its garbage came from the device.
    both("sessions/damaged.pcapng", "", "damaged_session");
}

/// An index of `count` HW_REQ_INFO frames (one copy of the bytes), 1 ms apart.
fn synthetic(count: u64) -> App {
    use aptscope_dissector::detect::Proto;
    use aptscope_tui::index::{Rec, Shared};
    use std::sync::atomic::Ordering;
    use std::sync::Arc;
    let shared = Arc::new(Shared::default());
    {
        let mut ix = shared.index.write().expect("index");
        ix.arena = vec![0x05, 0x00, 0x00, 0x00, 0x50, 0x01];
        ix.recs = (0..count)
            .map(|i| Rec {
                start: 0,
                offset: i * 6,
                cap_offset: i * 6,
                ts: i * 1_000_000,
                pair: 0,
                len: 6,
                module: 0,
                stream: 0,
                flags: 0,
                dir: 1,
                src: 0x01,
                dst: 0x50,
                id: 0x0005,
                diags: 0,
                chan: 0,
            })
            .collect();
        ix.first_ts = Some(0);
        ix.proto = Some(Proto::Apt);
        ix.proto_certain = true;
        ix.format = "synthetic".into();
        ix.done = true;
    }
    // The statistics scan of a million records is not what this tests: stop it at once.
    shared.cancel.store(true, Ordering::Relaxed);
    App::new(shared, "million", false)
}

#[test]
fn million_records_keep_the_columns() {
    for (w, h) in [(80, 24), (160, 48)] {
        let mut a = synthetic(1_000_005);
        let _ = screen(&mut a, w, h);
        // Rows 999,99x and 1,000,00x on one screen, under the header.
        keys(&mut a, ":1000003\n");
        let s = screen(&mut a, w, h);
        let at: Vec<usize> = s
            .lines()
            .filter(|l| l.contains("→  host → usb"))
            .map(|l| l.chars().position(|c| c == '→').unwrap_or(0))
            .collect();
        assert!(at.len() >= 8, "{s}");
        assert!(at.iter().all(|x| *x == at[0]), "rows shift: {at:?}\n{s}");
        assert!(
            s.contains("\n\" 999999 ") && s.contains("\n\"1000000 "),
            "{s}"
        );
        insta::assert_snapshot!(format!("million_{w}x{h}"), s);
    }
}

#[test]
fn rows_are_coloured_by_rule() {
    use aptscope_tui::decode::row;
    use aptscope_tui::ui::{colour_rule, COLOURS};
    let rule = |name: &str| COLOURS.iter().position(|c| c.name == name);
    // Which rule each record takes.
    let a = app("damaged.bin");
    let ix = a.shared().index.read().expect("lock");
    let rules: Vec<Option<usize>> = (1..=9)
        .map(|n| {
            let r = row(&ix, n).expect("row");
            colour_rule(&ix.rec(n).expect("rec"), r.way)
        })
        .collect();
    drop(ix);
    let (err, none, req, dev) = (
        rule("Errors"),
        rule("No reply"),
        rule("Requests"),
        rule("Device"),
    );
    assert_eq!(
        rules,
        [err, none, err, err, req, err, err, none, err],
        "damaged.bin: garbage, HW_REQ_INFO without reply, garbage, unknown id, MOD_IDENTIFY, \
         bad length, absurd header, move without reply, truncated"
    );
    let a = app("kdc101-session.pcapng");
    let ix = a.shared().index.read().expect("lock");
    let rules: Vec<Option<usize>> = [1, 2, 8]
        .iter()
        .map(|&n| colour_rule(&ix.rec(n).expect("rec"), row(&ix, n).expect("row").way))
        .collect();
    drop(ix);
    assert_eq!(rules, [req, rule("Replies"), dev]);
    // The rows take the rule's colours (record 2 is a reply; record 1 is selected).
    let mut a = app("kdc101-session.pcapng");
    let mut t = Terminal::new(TestBackend::new(80, 24)).expect("terminal");
    t.draw(|f| draw(f, &mut a)).expect("draw");
    let y = a.areas().list.y + 1;
    let reply = COLOURS[rule("Replies").expect("rule")].style;
    for x in [0, 10, 40, 79] {
        let cell = t.backend().buffer().cell((x, y)).expect("cell");
        assert_eq!(cell.fg, reply.fg.expect("fg"), "column {x}");
    }
    let mut a = app("damaged.bin");
    t.draw(|f| draw(f, &mut a)).expect("draw");
    let bad = COLOURS[err.expect("rule")].style;
    let cell = t
        .backend()
        .buffer()
        .cell((5, a.areas().list.y + 2))
        .expect("cell");
    assert_eq!(
        (cell.fg, cell.bg),
        (bad.fg.expect("fg"), bad.bg.expect("bg"))
    );
}

#[test]
fn tiny_windows_draw_without_panic() {
    let mut a = app("kdc101-session.pcapng");
    for (w, h) in [(1, 1), (10, 3), (20, 4), (30, 6), (40, 8)] {
        for help in [false, true] {
            a.set_help(help);
            let s = screen(&mut a, w, h);
            assert_eq!(s.lines().count(), h as usize, "{w}x{h}");
        }
    }
}
