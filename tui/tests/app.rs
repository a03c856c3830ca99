//! App state and key handling, without a terminal.

use aptscope_capture::open::OpenOptions;
use aptscope_tui::app::{App, Input, Pane, TimeMode, View};
use aptscope_tui::index::{load, F_IS_REPLY};
use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};

/// Record `n` as `decode --json` writes it, parsed.
fn json_value(ix: &aptscope_tui::index::Index, n: u64) -> Option<serde_json::Value> {
    serde_json::from_str(&aptscope_tui::decode::json_of(ix, n)?).ok()
}

fn sample(name: &str) -> String {
    format!("{}/../samples/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn app(name: &str) -> App {
    let shared = load(&sample(name), OpenOptions::default()).expect("sample opens");
    App::new(shared, name, false)
}

fn key(app: &mut App, c: KeyCode) {
    app.on_key(KeyEvent::new(c, KeyModifiers::NONE));
}

fn typed(app: &mut App, s: &str) {
    for c in s.chars() {
        key(app, KeyCode::Char(c));
    }
}

#[test]
fn moves_with_vim_keys_and_arrows() {
    let mut a = app("kdc101-session.pcapng");
    assert_eq!(a.len(), 20);
    assert_eq!(a.selected(), Some(1));
    key(&mut a, KeyCode::Char('j'));
    key(&mut a, KeyCode::Down);
    assert_eq!(a.selected(), Some(3));
    key(&mut a, KeyCode::Char('k'));
    assert_eq!(a.selected(), Some(2));
    key(&mut a, KeyCode::Char('G'));
    assert_eq!(a.selected(), Some(20));
    key(&mut a, KeyCode::Char('g'));
    assert_eq!(a.selected(), Some(1));
    // An 80×18 screen shows five rows of the timeline.
    a.update(ratatui::layout::Rect::new(0, 0, 80, 18));
    assert_eq!(a.rows_on_screen(), 5);
    key(&mut a, KeyCode::PageDown);
    assert_eq!(a.selected(), Some(6));
    assert!(a.top() <= a.position() && a.position() < a.top() + 5);
    key(&mut a, KeyCode::PageUp);
    assert_eq!(a.selected(), Some(1));
    key(&mut a, KeyCode::Up);
    assert_eq!(a.selected(), Some(1));
}

#[test]
fn filter_goto_pair_search() {
    let mut a = app("kdc101-session.pcapng");
    key(&mut a, KeyCode::Char('/'));
    typed(&mut a, "apt.name ==");
    let e = a
        .filter_error()
        .cloned()
        .expect("incomplete filter is an error");
    assert_eq!(e.column, 12);
    key(&mut a, KeyCode::Enter);
    assert!(
        matches!(a.input(), Input::Filter(_)),
        "a bad filter stays open"
    );
    typed(&mut a, " MOT_GET_DCSTATUSUPDATE");
    assert!(a.filter_error().is_none());
    key(&mut a, KeyCode::Enter);
    assert_eq!(*a.input(), Input::None);
    let n = a.len();
    assert!(n > 0 && n < 20, "filter selects status updates: {n}");
    let shown = a.rows(0, n);
    assert!(shown.iter().all(|x| *x >= 8));
    // Clearing the filter keeps the selected record.
    key(&mut a, KeyCode::Char('j'));
    let sel = a.selected();
    key(&mut a, KeyCode::Char('/'));
    key(&mut a, KeyCode::Char('u'));
    a.on_key(KeyEvent::new(KeyCode::Char('u'), KeyModifiers::CONTROL));
    key(&mut a, KeyCode::Enter);
    assert_eq!(a.len(), 20);
    assert_eq!(a.selected(), sel);

    // Go to a record, jump to its pair and back.
    key(&mut a, KeyCode::Char(':'));
    typed(&mut a, "2");
    key(&mut a, KeyCode::Enter);
    assert_eq!(a.selected(), Some(2));
    key(&mut a, KeyCode::Char('p'));
    assert_eq!(a.selected(), Some(1));
    key(&mut a, KeyCode::Char('p'));
    assert_eq!(a.selected(), Some(2));
    let ix = a.shared().index.read().expect("lock");
    assert!(ix.rec(2).expect("rec").has(F_IS_REPLY));
    drop(ix);

    // Search.
    key(&mut a, KeyCode::Char('g'));
    key(&mut a, KeyCode::Char('s'));
    typed(&mut a, "apt.name ~ MOVE_HOMED");
    key(&mut a, KeyCode::Enter);
    let hit = a.selected().expect("a hit");
    let ix = a.shared().index.read().expect("lock");
    let v = json_value(&ix, hit).expect("json");
    drop(ix);
    assert_eq!(v["name"], "MOT_MOVE_HOMED");
    key(&mut a, KeyCode::Char('n'));
    assert!(a.message().is_some(), "only one homed message");
    key(&mut a, KeyCode::Char('N'));
    assert_eq!(a.selected(), Some(hit));
}

#[test]
fn panes_tree_collapse_and_views() {
    let mut a = app("kdc101-session.pcapng");
    key(&mut a, KeyCode::Char(':'));
    typed(&mut a, "8");
    key(&mut a, KeyCode::Enter);
    let lines = a.detail_lines();
    assert!(
        lines.iter().any(|l| l.text.contains("[x]")),
        "flags expanded"
    );
    assert!(lines.iter().any(|l| l.text.starts_with("status_bits")));
    key(&mut a, KeyCode::Tab);
    assert_eq!(a.focus(), Pane::Detail);
    // Select the header section and collapse it.
    key(&mut a, KeyCode::Char('j'));
    assert!(a.detail_lines()[1].text.starts_with("Header"));
    assert_eq!(a.highlight(), Some((0, 6)));
    key(&mut a, KeyCode::Enter);
    assert_eq!(a.detail_lines().len(), lines.len() - 5);
    key(&mut a, KeyCode::Char('l'));
    assert_eq!(a.detail_lines().len(), lines.len());
    key(&mut a, KeyCode::Tab);
    assert_eq!(a.focus(), Pane::Hex);
    key(&mut a, KeyCode::BackTab);
    key(&mut a, KeyCode::BackTab);
    assert_eq!(a.focus(), Pane::List);
    key(&mut a, KeyCode::Char('t'));
    assert_eq!(a.time_mode(), TimeMode::Delta);
    key(&mut a, KeyCode::Char('2'));
    assert_eq!(a.view(), View::Stats);
    key(&mut a, KeyCode::Char('q'));
    assert_eq!(a.view(), View::Timeline);
    assert!(!a.should_quit());
    key(&mut a, KeyCode::Char('?'));
    assert!(a.help_shown());
    key(&mut a, KeyCode::Esc);
    assert!(!a.help_shown());
    a.on_key(KeyEvent::new(KeyCode::Char('c'), KeyModifiers::CONTROL));
    assert!(a.should_quit());
}

#[test]
fn indexes_like_decode() {
    // Record numbers, pairs and diagnostics agree with the NDJSON of `decode --json`.
    for name in ["damaged.bin", "elliptec-bus.txt", "bsc203-rack.hex"] {
        let a = app(name);
        let ix = a.shared().index.read().expect("lock");
        assert!(ix.done);
        for n in 1..=ix.recs.len() as u64 {
            let v = json_value(&ix, n).expect("json");
            assert_eq!(v["n"], n, "{name} #{n}");
            assert!(aptscope_tui::decode::row(&ix, n).is_some());
            assert!(!aptscope_tui::decode::tree(&ix, n).is_empty());
        }
    }
    let a = app("damaged.bin");
    let st = a.scan().state.lock().expect("lock");
    assert!(st.done);
    assert!(st.stats.garbage.count > 0);
    assert!(!st.stats.diags.is_empty());
}

#[test]
fn background_index_and_follow() {
    let shared = aptscope_tui::index::spawn(&sample("elliptec-bus.txt"), OpenOptions::default())
        .expect("opens");
    let mut a = App::new(shared, "bus", true);
    for _ in 0..200 {
        if a.shared().index.read().is_ok_and(|ix| ix.done)
            && a.scan().state.lock().is_ok_and(|s| s.done)
        {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    key(&mut a, KeyCode::Char('f'));
    a.tick();
    assert_eq!(a.position(), a.len() - 1);
    assert!(!a.shared().index.read().expect("lock").series.is_empty());
}

#[test]
fn records_equal_the_pipeline_ndjson() {
    use aptscope_capture::model::Event;
    use aptscope_dissector::pipeline::{Format, Pipeline};
    for name in [
        "kdc101-session.pcapng",
        "damaged.bin",
        "damaged.hex",
        "elliptec-bus.txt",
        "bsc203-rack.hex",
        "kdc101-session.socat.log",
    ] {
        let (mut r, _) =
            aptscope_capture::open::open(&sample(name), OpenOptions::default()).expect("opens");
        let mut p = Pipeline::new(None, Format::Json);
        let mut out: Vec<serde_json::Value> = vec![];
        let mut emit = |l: &str| -> Result<(), ()> {
            out.push(serde_json::from_str(l).expect("json"));
            Ok(())
        };
        while let Some(ev) = r.next_event() {
            if let Event::Chunk(c) = ev {
                let ctx = c.ctx();
                p.push_chunk(ctx, c.bytes, &mut emit).expect("push");
            }
        }
        p.finish(&mut emit).expect("finish");
        let a = app(name);
        let ix = a.shared().index.read().expect("lock");
        let mut count = 0;
        for want in out.iter().filter(|v| v.get("n").is_some()) {
            let n = want["n"].as_u64().expect("n");
            let mut got = json_value(&ix, n).expect("record");
            if let Some(d) = got["diag"].as_array_mut() {
                d.retain(|x| x["kind"] != "no_reply");
            }
            assert_eq!(&got, want, "{name} #{n}");
            count += 1;
        }
        assert_eq!(count, ix.recs.len(), "{name}");
        let late: Vec<u64> = out
            .iter()
            .filter(|v| v["type"] == "diag")
            .filter_map(|v| v["ref"].as_u64())
            .collect();
        for n in late {
            assert!(
                ix.rec(n).expect("ref").has(aptscope_tui::index::F_NO_REPLY),
                "{name} #{n}"
            );
        }
    }
}

#[test]
fn mouse_wheel_and_click() {
    use ratatui::crossterm::event::{MouseButton, MouseEvent, MouseEventKind};
    use ratatui::layout::Rect;
    let mut a = app("kdc101-session.pcapng");
    // The panes of an 80×24 screen: the timeline's rows start at line 3, the detail's at 12.
    a.update(Rect::new(0, 0, 80, 24));
    let areas = a.areas();
    assert_eq!(
        (areas.list.y, areas.detail.y, a.rows_on_screen()),
        (3, 12, 8)
    );
    let ev = |kind, row| MouseEvent {
        kind,
        column: 5,
        row,
        modifiers: KeyModifiers::NONE,
    };
    a.on_mouse(ev(MouseEventKind::ScrollDown, 4));
    assert_eq!(a.selected(), Some(4));
    a.on_mouse(ev(MouseEventKind::Down(MouseButton::Left), 3));
    assert_eq!(a.selected(), Some(a.top() as u64 + 1));
    a.on_mouse(ev(MouseEventKind::Down(MouseButton::Left), 14));
    assert_eq!(a.focus(), Pane::Detail);
    assert_eq!(a.detail_selected(), 2);
}

#[test]
fn a_forced_protocol_is_used_without_detection() {
    use aptscope_dissector::detect::Proto;
    let shared = aptscope_tui::index::spawn_as(
        &sample("kdc101-session.bin"),
        OpenOptions::default(),
        Some(Proto::Elliptec),
    )
    .expect("opens");
    let give_up = std::time::Instant::now() + std::time::Duration::from_secs(60);
    while !shared.index.read().is_ok_and(|ix| ix.done) {
        assert!(std::time::Instant::now() < give_up, "indexing never ended");
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let ix = shared.index.read().expect("lock");
    assert_eq!(ix.proto, Some(Proto::Elliptec));
    assert!(ix.proto_certain);
}

/// With a stage, the viewer shows what `decode --stage` shows: rows and the detail tree give
/// motion values raw and in mm, the NDJSON records (for filters) carry the same `phys`, and
/// the position plot is in mm.
#[test]
fn a_stage_shows_motion_values_in_mm_everywhere() {
    use aptscope_capture::model::Event;
    use aptscope_dissector::pipeline::{Format, Pipeline};
    use aptscope_dissector::units::UnitsOpts;
    let path = sample("sessions/kdc101.pcapng");
    let units = UnitsOpts::from_args(Some("MTS25-Z8"), None, None).expect("stage");
    let shared = aptscope_tui::index::load_with(&path, OpenOptions::default(), units.clone())
        .expect("opens");
    let ix = shared.index.read().expect("lock");
    // Record 6 is MOT_SET_VELPARAMS: 2.5 mm/s and 4 mm/s² on a Z8 stage.
    let row = aptscope_tui::decode::row(&ix, 6).expect("row");
    assert!(
        row.fields.contains("max_vel=1932478 (2.50003 mm/s)"),
        "{}",
        row.fields
    );
    assert!(
        row.fields.contains("acceleration=1055 (3.99857 mm/s2)"),
        "{}",
        row.fields
    );
    let tree = aptscope_tui::decode::tree(&ix, 6);
    let texts: Vec<&str> = tree.iter().map(|n| n.text.as_str()).collect();
    assert!(
        texts
            .iter()
            .any(|t| t.starts_with("units: MTS25-Z8: 34554.96 counts/mm")),
        "{texts:?}"
    );
    assert!(
        texts.contains(&"max_vel = 1932478 (2.50003 mm/s)  [i32 @16]"),
        "{texts:?}"
    );
    assert!(
        ix.units_notes
            .iter()
            .any(|n| n.contains("(KDC101): MTS25-Z8")),
        "{:?}",
        ix.units_notes
    );
    assert!(
        ix.series.contains_key("position usb ch1 (mm)"),
        "{:?}",
        ix.series.keys()
    );
    // The last position of the session: 1 mm (34555 counts).
    let last = ix.series["position usb ch1 (mm)"]
        .last()
        .map_or(0.0, |p| p.1);
    assert!((last - 1.0).abs() < 1e-4, "{last}");
    // Without the stage: raw, honestly labelled.
    let plain = load(&path, OpenOptions::default()).expect("opens");
    let plain = plain.index.read().expect("lock");
    let row = aptscope_tui::decode::row(&plain, 6).expect("row");
    assert!(
        row.fields.contains("max_vel=1932478 vel_units"),
        "{}",
        row.fields
    );
    assert!(plain.series.contains_key("position usb ch1"));
    // The records equal the pipeline's with the same stage.
    let (mut r, _) = aptscope_capture::open::open(&path, OpenOptions::default()).expect("opens");
    let mut p = Pipeline::new(None, Format::Json);
    p.set_units(units);
    let mut out: Vec<serde_json::Value> = vec![];
    let mut emit = |l: &str| -> Result<(), ()> {
        out.push(serde_json::from_str(l).expect("json"));
        Ok(())
    };
    while let Some(ev) = r.next_event() {
        if let Event::Chunk(c) = ev {
            p.push_chunk(c.ctx(), c.bytes, &mut emit).expect("push");
        }
    }
    p.finish(&mut emit).expect("finish");
    let mut with_phys = 0;
    for want in out.iter().filter(|v| v.get("n").is_some()) {
        let n = want["n"].as_u64().expect("n");
        let mut got = json_value(&ix, n).expect("record");
        if let Some(d) = got["diag"].as_array_mut() {
            d.retain(|x| x["kind"] != "no_reply");
        }
        assert_eq!(&got, want, "#{n}");
        with_phys += usize::from(got.get("phys").is_some());
    }
    assert!(with_phys > 30, "{with_phys}");
}

/// Select detail line `id` of the selected record (focus on the detail pane).
fn select_line(a: &mut App, id: &str) {
    a.set_focus(Pane::Detail);
    let i = a
        .detail_lines()
        .iter()
        .position(|l| l.id == id)
        .expect("line shown");
    a.select_detail(i);
}

#[test]
fn apply_prepare_and_narrow_as_filter() {
    let mut a = app("kdc101-session.pcapng");
    key(&mut a, KeyCode::Char(':'));
    typed(&mut a, "8");
    key(&mut a, KeyCode::Enter);
    // Apply: the filter runs, the record stays selected.
    select_line(&mut a, "f.status_bits.HOMING");
    key(&mut a, KeyCode::Char('a'));
    assert_eq!(a.filter_text(), "apt.status_bits contains HOMING");
    assert_eq!(a.rows(0, 100), [8, 9, 10, 11]);
    assert_eq!(a.selected(), Some(8));
    assert_eq!(*a.input(), Input::None);
    // … and Selected: narrowed by another line of the record.
    select_line(&mut a, "f.position");
    key(&mut a, KeyCode::Char('&'));
    assert_eq!(
        a.filter_text(),
        "(apt.status_bits contains HOMING) && (apt.position == 0)"
    );
    assert_eq!(a.rows(0, 100), [8]);
    // Prepare: into the filter bar to edit, not applied yet.
    select_line(&mut a, "hdr.src");
    key(&mut a, KeyCode::Char('A'));
    assert_eq!(*a.input(), Input::Filter("apt.src == usb".into()));
    assert_eq!(a.rows(0, 100), [8], "not applied before Enter");
    typed(&mut a, " && apt.position < 0");
    key(&mut a, KeyCode::Enter);
    assert_eq!(a.filter_text(), "apt.src == usb && apt.position < 0");
    assert_eq!(a.rows(0, 100), [9, 10, 11]);
    // A heading has no value: nothing changes, the status line says why.
    let before = a.filter_text().to_string();
    select_line(&mut a, "fields");
    key(&mut a, KeyCode::Char('a'));
    assert_eq!(a.filter_text(), before);
    assert!(a.message().is_some_and(|m| m.starts_with("no filter")));
    // In the timeline the action takes the row's message.
    a.set_focus(Pane::List);
    key(&mut a, KeyCode::Char('a'));
    assert_eq!(a.filter_text(), "apt.name == MOT_GET_DCSTATUSUPDATE");
    assert_eq!(a.len(), 9);
}

#[test]
fn detail_scrolls_sideways_and_resets_on_another_record() {
    let mut a = app("kdc101-session.pcapng");
    key(&mut a, KeyCode::Char(':'));
    typed(&mut a, "2");
    key(&mut a, KeyCode::Enter);
    key(&mut a, KeyCode::Tab);
    key(&mut a, KeyCode::Char('>'));
    key(&mut a, KeyCode::Char('>'));
    assert_eq!(a.detail_left(), 16);
    key(&mut a, KeyCode::Char('<'));
    assert_eq!(a.detail_left(), 8);
    a.set_focus(Pane::List);
    key(&mut a, KeyCode::Char('j'));
    assert_eq!(a.detail_left(), 0, "a new record starts at the left");
}

#[test]
fn help_scrolls_and_closes() {
    let mut a = app("kdc101-session.pcapng");
    key(&mut a, KeyCode::Char('?'));
    assert!(a.help_shown());
    key(&mut a, KeyCode::Char('j'));
    key(&mut a, KeyCode::Down);
    assert_eq!(a.help_scroll(), 2);
    key(&mut a, KeyCode::Char('k'));
    assert_eq!(a.help_scroll(), 1);
    // Keys do not reach the panes while the help is open.
    assert_eq!(a.selected(), Some(1));
    key(&mut a, KeyCode::Char('g'));
    assert_eq!(a.help_scroll(), 0);
    key(&mut a, KeyCode::Char('q'));
    assert!(!a.help_shown());
    assert!(!a.should_quit(), "q closes the help only");
}

/// Shrinking the window (120×32 → 80×24) keeps the selected row on screen at the next frame,
/// without a key press.
#[test]
fn the_selected_row_stays_visible_when_the_window_shrinks() {
    use ratatui::backend::TestBackend;
    use ratatui::Terminal;
    let mut a = app("kdc101-session.pcapng");
    let mut big = Terminal::new(TestBackend::new(120, 32)).expect("terminal");
    big.draw(|f| aptscope_tui::ui::draw(f, &mut a))
        .expect("draw");
    // The last row that fits the big window.
    let last = a.top() + a.rows_on_screen() - 1;
    a.select(last);
    big.draw(|f| aptscope_tui::ui::draw(f, &mut a))
        .expect("draw");
    let mut small = Terminal::new(TestBackend::new(80, 24)).expect("terminal");
    small
        .draw(|f| aptscope_tui::ui::draw(f, &mut a))
        .expect("draw");
    assert!(
        a.rows_on_screen() < last + 1,
        "the small window shows fewer rows"
    );
    assert!(
        a.top() <= a.position() && a.position() < a.top() + a.rows_on_screen(),
        "row {} visible in {}..{}",
        a.position(),
        a.top(),
        a.top() + a.rows_on_screen()
    );
    let screen = format!("{}", small.backend());
    assert!(screen.contains("2:stats 3:plot"), "{screen}");
}

/// What the first screen says of inputs that are not what they seem: a capture of another link
/// type lists its file problem where the records would be (it showed only "(no records)"), and
/// random bytes are a guess that says how little framed (the title said "apt").
#[test]
fn the_first_screen_says_what_is_wrong_with_the_input() {
    use ratatui::backend::TestBackend;
    use ratatui::Terminal;
    let screen = |path: &str| {
        let shared = load(path, OpenOptions::default()).expect("opens");
        let mut a = App::new(shared, "x", false);
        let mut t = Terminal::new(TestBackend::new(100, 30)).expect("terminal");
        t.draw(|f| aptscope_tui::ui::draw(f, &mut a)).expect("draw");
        format!("{}", t.backend())
    };
    let root = env!("CARGO_MANIFEST_DIR");
    let eth = screen(&format!("{root}/../tests/bad-input/unknown-linktype.pcap"));
    assert!(eth.contains("1 file problem (2: stats)"), "{eth}");
    assert!(
        eth.contains("file problem at byte 24: unknown_linktype"),
        "{eth}"
    );
    let rand = screen(&format!("{root}/../tests/bad-input/random.bin"));
    let title = rand.lines().next().unwrap_or("");
    assert!(
        title.contains("apt? (") && title.contains("% frames)"),
        "{title}"
    );
    let ok = screen(&sample("kdc101-session.pcapng"));
    let title = ok.lines().next().unwrap_or("");
    assert!(
        title.contains("· apt ·") && !title.contains("file problem"),
        "{title}"
    );
}

/// The detail tree of a current curve whose last bytes equal CR and LF: the curve is 522 bytes
/// and the terminator only the CR LF after it (it took the curve's last bytes too).
#[test]
fn a_curve_ending_in_cr_lf_bytes_is_data_in_the_detail_tree() {
    let mut curve: Vec<u8> = (0..522u32).map(|i| (i * 7 % 251) as u8).collect();
    curve[518..].copy_from_slice(b"\n\r\r\n");
    let bytes = [
        b"0gs\r\n0GS00\r\n0c1\r\n0C1".as_slice(),
        &curve,
        b"\r\n0gs\r\n0GS00\r\n",
    ]
    .concat();
    let path = std::env::temp_dir().join(format!("aptscope-tui-curve-{}.bin", std::process::id()));
    std::fs::write(&path, &bytes).expect("write");
    let shared = load(path.to_str().expect("utf-8"), OpenOptions::default()).expect("opens");
    let _ = std::fs::remove_file(&path);
    let ix = shared.index.read().expect("lock");
    let tree = aptscope_tui::decode::tree(&ix, 4);
    let node = |id: &str| tree.iter().find(|x| x.id == id).map(|x| x.range);
    assert_eq!(node("f.curve"), Some(Some((3, 522))), "{tree:?}");
    assert_eq!(node("term"), Some(Some((525, 2))), "{tree:?}");
}

/// A duplicate reply names the request it repeats the answer to, and has no latency: as
/// `decode` prints it (the pairing gives it none), in its JSON, its row and the display filter.
/// Found by the `tui_view` fuzz target: the viewer worked the latency out from the pair.
#[test]
fn a_duplicate_reply_has_its_pair_and_no_latency() {
    use aptscope_dissector::filter::Filter;
    use aptscope_tui::fields::matches;
    let completed = " 64 04 0e 00 81 50 01 00 00 9e 02 00 00 00 00 00\n 00 25 00 80\n--\n";
    let log = format!(
        "> 2024/05/01 12:00:00.000000  length=12 from=0 to=11\n \
         53 04 06 00 d0 01 01 00 00 9e 02 00\n--\n\
         < 2024/05/01 12:00:00.500000  length=20 from=0 to=19\n{completed}\
         < 2024/05/01 12:00:00.600000  length=20 from=20 to=39\n{completed}"
    );
    let path = std::env::temp_dir().join(format!("aptscope-dup-{}.socat.log", std::process::id()));
    std::fs::write(&path, log).expect("write");
    let shared = load(path.to_str().expect("path"), OpenOptions::default()).expect("opens");
    std::fs::remove_file(&path).expect("remove");
    let ix = shared.index.read().expect("lock");
    assert_eq!(ix.recs.len(), 3);
    let (first, dup) = (
        json_value(&ix, 2).expect("2"),
        json_value(&ix, 3).expect("3"),
    );
    assert_eq!(
        (&first["pair"], &first["latency_ms"]),
        (&1.into(), &500.into())
    );
    assert_eq!(dup["pair"], 1);
    assert_eq!(dup["diag"][0]["kind"], "duplicate_reply");
    assert!(dup.get("latency_ms").is_none(), "{dup}");
    let row = aptscope_tui::decode::row(&ix, 3).expect("row");
    assert_eq!((row.pair, row.latency_ns), (Some(1), None));
    let f = Filter::parse("latency > 0").expect("filter");
    assert!(matches(&f, &ix, 2) && !matches(&f, &ix, 3));
}
