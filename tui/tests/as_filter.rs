//! "Apply / prepare as filter": the filter built from a detail-tree line.

use aptscope_capture::open::OpenOptions;
use aptscope_dissector::filter::Filter;
use aptscope_tui::as_filter::{and, for_node, for_record};
use aptscope_tui::decode::tree;
use aptscope_tui::fields::matches;
use aptscope_tui::index::{load, Index};

fn sample(name: &str) -> String {
    format!("{}/../samples/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn with_index<T>(name: &str, f: impl FnOnce(&Index) -> T) -> T {
    let shared = load(&sample(name), OpenOptions::default()).expect("sample opens");
    let ix = shared.index.read().expect("lock");
    f(&ix)
}

/// The filter of the line with id `id` of record `n`.
fn of(ix: &Index, n: u64, id: &str) -> Option<String> {
    let nodes = tree(ix, n);
    let node = nodes.iter().find(|x| x.id == id).expect("line exists");
    for_node(ix, n, node)
}

#[test]
fn every_line_filter_parses_and_matches_its_own_record() {
    let mut built = 0;
    for name in [
        "kdc101-session.pcapng",
        "damaged.bin",
        "elliptec-bus.txt",
        "bsc203-rack.hex",
        "sessions/damaged.pcapng",
        "sessions/laser-tec-quad.pcapng",
        "sessions/elliptec.pcapng",
        "sessions/bsc203.pcapng",
    ] {
        with_index(name, |ix| {
            for n in 1..=ix.recs.len() as u64 {
                for node in tree(ix, n) {
                    let Some(text) = for_node(ix, n, &node) else {
                        continue;
                    };
                    let f = Filter::parse(&text)
                        .unwrap_or_else(|e| panic!("{name} #{n} {}: {text}: {e}", node.id));
                    assert!(
                        matches(&f, ix, n),
                        "{name} #{n} line {} ({}): `{text}` does not match its record",
                        node.id,
                        node.text
                    );
                    built += 1;
                }
                let text = for_record(ix, n).expect("every record has a message filter");
                let f = Filter::parse(&text).expect("parses");
                assert!(matches(&f, ix, n), "{name} #{n}: `{text}`");
            }
        });
    }
    assert!(built > 500, "only {built} filters built");
}

#[test]
fn apt_lines_give_wireshark_like_filters() {
    with_index("kdc101-session.pcapng", |ix| {
        // Record 8: a status update with its flags.
        assert_eq!(
            of(ix, 8, "f.position").as_deref(),
            Some("apt.position == 0")
        );
        assert_eq!(
            of(ix, 8, "f.chan_ident").as_deref(),
            Some("apt.chan_ident == CH1")
        );
        assert_eq!(
            of(ix, 8, "f.status_bits.HOMING").as_deref(),
            Some("apt.status_bits contains HOMING")
        );
        assert_eq!(
            of(ix, 8, "f.status_bits.HOMED").as_deref(),
            Some("apt.name == MOT_GET_DCSTATUSUPDATE && !(apt.status_bits contains HOMED)")
        );
        assert_eq!(
            of(ix, 8, "f.status_bits").as_deref(),
            Some(
                "apt.status_bits contains MOVING_CCW && apt.status_bits contains MOTOR_CONNECTED \
                 && apt.status_bits contains HOMING && apt.status_bits contains ENABLED"
            )
        );
        assert_eq!(
            of(ix, 8, "msg").as_deref(),
            Some("apt.name == MOT_GET_DCSTATUSUPDATE")
        );
        assert_eq!(of(ix, 8, "hdr.id").as_deref(), Some("apt.msgid == 0x0491"));
        assert_eq!(of(ix, 8, "hdr.src").as_deref(), Some("apt.src == usb"));
        assert_eq!(of(ix, 8, "hdr.dst").as_deref(), Some("apt.dst == host"));
        assert_eq!(of(ix, 8, "hdr.len").as_deref(), Some("apt.data_len == 14"));
        assert_eq!(of(ix, 8, "rec").as_deref(), Some("n == 8"));
        // Headings without a value of their own.
        assert_eq!(of(ix, 8, "fields"), None);
        // The exchange of a request and its reply, from either side.
        assert_eq!(of(ix, 7, "pair").as_deref(), Some("n == 7 || pair == 7"));
        assert_eq!(of(ix, 12, "pair").as_deref(), Some("n == 7 || pair == 7"));
        // A text field with characters outside a bare word is quoted.
        let model = of(ix, 2, "f.model_number").expect("model filter");
        assert!(model.starts_with("apt.model_number == "), "{model}");
        // The timeline action: the message.
        assert_eq!(
            for_record(ix, 12).as_deref(),
            Some("apt.name == MOT_MOVE_HOMED")
        );
    });
}

#[test]
fn diagnostics_garbage_and_elliptec_lines() {
    with_index("damaged.bin", |ix| {
        assert_eq!(
            of(ix, 9, "diag.0").as_deref(),
            Some("diag.kind == truncated")
        );
        assert_eq!(of(ix, 9, "diag").as_deref(), Some("diag"));
        assert_eq!(
            of(ix, 2, "pdiag0").as_deref(),
            Some("diag.kind == no_reply")
        );
        assert_eq!(of(ix, 1, "garbage").as_deref(), Some("type == garbage"));
        assert_eq!(of(ix, 4, "hdr.id").as_deref(), Some("apt.msgid == 0xEEEE"));
        // An unknown message: the timeline action falls back to its id.
        assert_eq!(for_record(ix, 4).as_deref(), Some("apt.msgid == 0xEEEE"));
    });
    with_index("elliptec-bus.txt", |ix| {
        // Elliptec commands are case-sensitive (request gs, reply GS).
        assert_eq!(of(ix, 8, "cmd").as_deref(), Some("ell.cmd == GS"));
        assert_eq!(of(ix, 8, "addr").as_deref(), Some("ell.addr == 0"));
        assert_eq!(of(ix, 8, "f.status").as_deref(), Some("ell.status == OK"));
        assert_eq!(
            of(ix, 8, "text").as_deref(),
            Some(r#"ell.text == "0GS00\r\n""#)
        );
        assert_eq!(of(ix, 8, "term"), None);
    });
}

#[test]
fn and_narrows_the_current_filter() {
    assert_eq!(and("", "apt.chan == 1"), "apt.chan == 1");
    assert_eq!(
        and("apt.name ~ MOVE || diag", "n == 7 || pair == 7"),
        "(apt.name ~ MOVE || diag) && (n == 7 || pair == 7)"
    );
}

#[test]
fn the_help_examples_are_valid_filters() {
    for (text, _) in aptscope_tui::ui::FILTER_EXAMPLES {
        assert!(Filter::parse(text).is_ok(), "{text}");
    }
}
