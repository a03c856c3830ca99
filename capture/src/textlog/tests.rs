//! Tests of the text-log readers.

use super::*;
use crate::model::OwnedChunk;
use std::io::BufReader;

fn samples() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../samples")
}

fn sample(name: &str) -> Vec<u8> {
    std::fs::read(samples().join(name)).unwrap()
}

struct Got {
    chunks: Vec<OwnedChunk>,
    diags: Vec<ReadDiag>,
    streams: Vec<StreamInfo>,
}

impl Got {
    fn bytes(&self) -> Vec<u8> {
        self.chunks
            .iter()
            .flat_map(|c| c.bytes.iter().copied())
            .collect()
    }
    fn kinds(&self) -> Vec<(&'static str, u64)> {
        self.diags.iter().map(|d| (d.kind(), d.offset)).collect()
    }
}

fn read_all(mut r: Box<dyn Reader>) -> Got {
    let mut g = Got {
        chunks: vec![],
        diags: vec![],
        streams: vec![],
    };
    while let Some(ev) = r.next_event() {
        match ev {
            Event::Chunk(c) => {
                assert!(!c.bytes.is_empty() && c.bytes.len() <= MAX_CHUNK);
                g.chunks.push(c.to_owned());
            }
            Event::Diag(d) => g.diags.push(d),
            Event::Stream(s) => g.streams.push(s),
        }
    }
    g
}

/// Offset of the line holding `needle` in `text`.
fn at(text: &str, needle: &str) -> u64 {
    let i = text.find(needle).unwrap();
    text[..i].rfind('\n').map_or(0, |j| j as u64 + 1)
}

fn read_str(kind: TextFormat, text: &str) -> Got {
    read_all(open(kind, Cursor::new(text.as_bytes().to_vec())))
}

fn read_sample(kind: TextFormat, name: &str) -> Got {
    let f = std::fs::File::open(samples().join(name)).unwrap();
    read_all(open(kind, BufReader::new(f)))
}

/// The direction of each byte of the session, from its frames (one per line of the .hex).
fn session_dirs() -> Vec<Direction> {
    let text = String::from_utf8(sample("kdc101-session.hex")).unwrap();
    let mut dirs = vec![];
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let bytes: Vec<u8> = line
            .split_whitespace()
            .map(|h| u8::from_str_radix(h, 16).unwrap())
            .collect();
        let id = u16::from_le_bytes([bytes[0], bytes[1]]);
        // HW_GET_INFO, MOD_GET_CHANENABLESTATE, MOT_MOVE_HOMED, MOT_MOVE_COMPLETED,
        // MOT_GET_DCSTATUSUPDATE come from the controller; the rest from the host.
        let d2h = [0x0006, 0x0212, 0x0444, 0x0464, 0x0491].contains(&id);
        let d = if d2h {
            Direction::DeviceToHost
        } else {
            Direction::HostToDevice
        };
        dirs.extend(std::iter::repeat_n(d, bytes.len()));
    }
    dirs
}

fn check_session(g: &Got, directed: bool, timed: bool) {
    assert_eq!(g.diags, vec![], "no diagnostics");
    assert_eq!(g.bytes(), sample("kdc101-session.bin"));
    let dirs = session_dirs();
    let mut pos = 0;
    let mut last_ts = None;
    for c in &g.chunks {
        for (i, _) in c.bytes.iter().enumerate() {
            let want = if directed {
                dirs[pos + i]
            } else {
                Direction::Unknown
            };
            assert_eq!(c.dir, want, "direction of byte {}", pos + i);
        }
        pos += c.bytes.len();
        if timed {
            let ts = c.ts_ns.expect("timestamp");
            if let Some(l) = last_ts {
                assert!(ts > l, "timestamps increase: {l} then {ts}");
            }
            last_ts = Some(ts);
        } else {
            assert_eq!(c.ts_ns, None);
        }
    }
}

/// 2024-05-01 12:00:00 as nanoseconds since the epoch (UTC).
const T0: u64 = 1_714_564_800 * NS;

#[test]
fn socat_sample() {
    let g = read_sample(TextFormat::Socat, "kdc101-session.socat.log");
    check_session(&g, true, true);
    assert_eq!(g.chunks[0].ts_ns, Some(T0));
    assert_eq!(
        g.chunks.len(),
        21,
        "one chunk per read (the 90-byte reply comes in two)"
    );
    assert!(g.streams.is_empty());
}

#[test]
fn jpnevulator_sample() {
    let g = read_sample(TextFormat::Jpnevulator, "kdc101-session.jpnevulator.txt");
    check_session(&g, true, true);
    // The pty and the tty are the two directions of one line: one stream.
    let names: Vec<_> = g.streams.iter().map(|s| (s.id, s.name.as_str())).collect();
    assert_eq!(names, vec![(0, "/dev/pts/3")]);
    assert!(g.chunks.iter().all(|c| c.stream == 0));
}

#[test]
fn interceptty_sample() {
    let g = read_sample(TextFormat::Interceptty, "kdc101-session.interceptty.log");
    check_session(&g, true, true);
    // interceptty -T prints the time of day only: 12:00:00 after midnight.
    assert_eq!(g.chunks[0].ts_ns, Some(12 * 3600 * NS));
}

#[test]
fn xxd_sample() {
    let g = read_sample(TextFormat::Xxd, "kdc101-session.xxd.txt");
    check_session(&g, false, false);
}

#[test]
fn sniff_samples() {
    let head = |n: &str| {
        let mut b = sample(n);
        b.truncate(8192);
        b
    };
    assert_eq!(
        sniff(&head("kdc101-session.socat.log")),
        Some(TextFormat::Socat)
    );
    assert_eq!(
        sniff(&head("kdc101-session.jpnevulator.txt")),
        Some(TextFormat::Jpnevulator)
    );
    assert_eq!(
        sniff(&head("kdc101-session.interceptty.log")),
        Some(TextFormat::Interceptty)
    );
    assert_eq!(
        sniff(&head("kdc101-session.xxd.txt")),
        Some(TextFormat::Xxd)
    );
    assert_eq!(sniff(HEXDUMP_C.as_bytes()), Some(TextFormat::HexdumpC));
    assert_eq!(
        sniff(b"0000  05 00 00 00 50 01\n0006  06 00 54 00\n"),
        Some(TextFormat::HexColumns)
    );
    assert_eq!(
        sniff(b"12:00:00.000 05 00 00 00 50 01\n12:00:00.011 06 00 54 00 81 50\n"),
        Some(TextFormat::HexColumns)
    );
    // Not ours: binary, pcap, an Elliptec ASCII stream, plain hex, prose, empty.
    assert_eq!(sniff(&head("kdc101-session.bin")), None);
    assert_eq!(sniff(&head("elliptec-bus.txt")), None);
    assert_eq!(
        sniff(b"0in0IN0E1140028420200117016800023000\r\n0gs0GS00\r\n"),
        None
    );
    assert_eq!(sniff(&head("kdc101-session.hex")), None);
    assert_eq!(sniff(&head("damaged.bin")), None);
    assert_eq!(
        sniff(&[0xd4, 0xc3, 0xb2, 0xa1, 2, 0, 4, 0, 0, 0, 0, 0]),
        None
    );
    assert_eq!(
        sniff(&[0x0a, 0x0d, 0x0d, 0x0a, 0x1c, 0, 0, 0, 0x4d, 0x3c, 0x2b, 0x1a]),
        None
    );
    assert_eq!(sniff(b"Hello, this is a README.\nNothing to see.\n"), None);
    assert_eq!(
        sniff(b"2ca5\n0ca1\n"),
        None,
        "Elliptec commands made of hex letters"
    );
    assert_eq!(
        sniff(b"> 2024/05/01 12:00:00.000000  length=3 from=0 to=2\n012\n"),
        None,
        "socat -v"
    );
    assert_eq!(sniff(b""), None);
}

#[test]
fn names_round_trip() {
    for f in TextFormat::ALL {
        assert_eq!(TextFormat::parse(f.name()), Some(f));
    }
    assert_eq!(TextFormat::parse("pcap"), None);
}

// --- socat ---

const SOCAT_OK: &str = "> 2024/05/01 12:00:00.000100  length=6 from=0 to=5\n \
05 00 00 00 50 01                                ....P.\n--\n";

#[test]
fn socat_without_timestamps_and_hex_only() {
    // socat -x without -v: all bytes on one line, no ASCII column, no "--".
    let g = read_str(
        TextFormat::Socat,
        "> length=6 from=0 to=5\n 05 00 00 00 50 01\n< length=2 from=0 to=1\n 0a 0b\n",
    );
    assert_eq!(g.diags, vec![]);
    assert_eq!(g.chunks.len(), 2);
    assert_eq!(g.chunks[0].dir, Direction::HostToDevice);
    assert_eq!(g.chunks[1].dir, Direction::DeviceToHost);
    assert_eq!(g.chunks[1].bytes, vec![0x0a, 0x0b]);
    assert_eq!(g.chunks[0].ts_ns, None);
}

#[test]
fn socat_bad_hex() {
    let text = format!(
        "{SOCAT_OK}< 2024/05/01 12:00:00.000200  length=4 from=0 to=3\n 12 0g 00 50\n--\n{}",
        SOCAT_OK.replace("from=0 to=5", "from=6 to=11")
    );
    let g = read_str(TextFormat::Socat, &text);
    let bad_line = at(&text, " 12 0g");
    assert_eq!(
        g.kinds(),
        vec![
            ("bad_hex", bad_line),
            ("length_mismatch", SOCAT_OK.len() as u64)
        ]
    );
    assert!(
        g.diags[0].msg().contains("column 5"),
        "{}",
        g.diags[0].msg()
    );
    // What is readable is kept: the block before, the byte before the bad one, the block after.
    assert_eq!(
        g.bytes(),
        [&[5, 0, 0, 0, 0x50, 1][..], &[0x12], &[5, 0, 0, 0, 0x50, 1]].concat()
    );
    assert_eq!(g.chunks[1].dir, Direction::DeviceToHost);
}

#[test]
fn socat_truncated_last_line() {
    let text = format!("{SOCAT_OK}< 2024/05/01 12:00:01.5  length=6 from=0 to=5\n 06 00 00 00 50");
    let g = read_str(TextFormat::Socat, &text);
    let hdr = SOCAT_OK.len() as u64;
    assert_eq!(
        g.kinds(),
        vec![
            ("truncated_line", at(&text, " 06 00")),
            ("length_mismatch", hdr)
        ]
    );
    assert_eq!(g.bytes(), vec![5, 0, 0, 0, 0x50, 1, 6, 0, 0, 0, 0x50]);
    assert_eq!(g.chunks[1].ts_ns, Some(T0 + 1_500_000_000));
}

#[test]
fn socat_garbage_gap_and_headerless_data() {
    let text = format!(
        " 01 02\n2024/05/01 11:59:59 socat[42] N starting data transfer loop\n{SOCAT_OK}hello there\n{}",
        SOCAT_OK.replace("from=0 to=5", "from=10 to=15")
    );
    let g = read_str(TextFormat::Socat, &text);
    assert_eq!(
        g.kinds(),
        vec![
            ("missing_header", 0),
            ("garbage_line", at(&text, "hello")),
            (
                "sequence_gap",
                at(&text, "> 2024/05/01 12:00:00.000100  length=6 from=10")
            )
        ]
    );
    assert_eq!(g.chunks[0].dir, Direction::Unknown);
    assert_eq!(g.bytes().len(), 2 + 6 + 6);
}

#[test]
fn socat_problems_are_typed_and_say_what_was_expected_and_found() {
    let text = format!(
        " 01 02\n{SOCAT_OK}hello there\n{}{}",
        SOCAT_OK.replace("from=0 to=5", "from=10 to=15"),
        SOCAT_OK.replace("from=0 to=5", "from=16 to=30")
    );
    let g = read_str(TextFormat::Socat, &text);
    let log = ReadProblem::Log;
    let problems: Vec<ReadProblem> = g.diags.iter().map(|d| d.problem.clone()).collect();
    assert_eq!(
        problems,
        [
            log(LogProblem::MissingHeader),
            log(LogProblem::GarbageLine {
                expected: "a socat dump".into(),
                line: "hello there".into()
            }),
            log(LogProblem::SequenceGap {
                expected: 6,
                found: 10
            }),
            log(LogProblem::SpanMismatch {
                from: 16,
                to: 30,
                length: 6
            }),
        ]
    );
    let texts: Vec<String> = g.diags.iter().map(ReadDiag::msg).collect();
    assert_eq!(
        texts[1..],
        [
            "not part of a socat dump: \"hello there\"",
            "from=10 but 6 bytes were logged before in this direction: blocks are missing",
            "from=16 to=30 do not span length=6"
        ]
    );
    assert_eq!(g.diags[3].kind(), "length_mismatch");
}

#[test]
fn socat_ascii_mismatch() {
    let g = read_str(TextFormat::Socat, &SOCAT_OK.replace("....P.", "....Q."));
    assert_eq!(g.kinds(), vec![("ascii_mismatch", 51)]);
    assert_eq!(g.bytes(), vec![5, 0, 0, 0, 0x50, 1]);
}

// --- jpnevulator ---

#[test]
fn jpnevulator_one_tty_byte_count_and_garbage() {
    let text = "2024-05-01 12:00:00.000000:\n00000000\t05 00 00 00 50 01\n\
                2024-05-01 12:00:00.250000:\n00000006\t06 00\nthis is not hex\n00000009\t54 00\n";
    let g = read_str(TextFormat::Jpnevulator, text);
    assert_eq!(
        g.kinds(),
        vec![
            ("garbage_line", at(text, "this")),
            ("byte_count_gap", at(text, "00000009"))
        ]
    );
    assert!(g.streams.is_empty());
    assert_eq!(g.chunks.len(), 2);
    assert!(g
        .chunks
        .iter()
        .all(|c| c.dir == Direction::Unknown && c.stream == 0));
    assert_eq!(g.chunks[1].ts_ns, Some(T0 + 250_000_000));
    assert_eq!(g.bytes(), vec![5, 0, 0, 0, 0x50, 1, 6, 0, 0x54, 0]);
}

#[test]
fn jpnevulator_aliases_and_bad_hex() {
    let text = "2024-05-01 12:00:00.000000: host\n05 00 00 00 50 01\n\
                2024-05-01 12:00:00.010000: kcube\n06 00 5X 00\n";
    let g = read_str(TextFormat::Jpnevulator, text);
    assert_eq!(g.kinds(), vec![("bad_hex", at(text, "06 00 5X"))]);
    assert_eq!(g.chunks[0].dir, Direction::HostToDevice);
    // The other of two interfaces carries the other direction.
    assert_eq!(g.chunks[1].dir, Direction::DeviceToHost);
    assert_eq!(g.chunks[1].bytes, vec![6, 0]);
}

#[test]
fn jpnevulator_two_ttys_unknown() {
    let text = "2024-05-01 12:00:00.000000: /dev/ttyS0\n05 00\n2024-05-01 12:00:00.000100: /dev/ttyUSB0\n06 00\n";
    let g = read_str(TextFormat::Jpnevulator, text);
    assert_eq!(g.diags, vec![]);
    assert!(g.chunks.iter().all(|c| c.dir == Direction::Unknown));
    assert_eq!(g.chunks[1].stream, 1);
}

// --- interceptty ---

#[test]
fn interceptty_classic_and_eol_mode() {
    // interceptty without -T: one byte per line; '<' to the device, '>' from it.
    let g = read_str(
        TextFormat::Interceptty,
        "< 0x30 (0)\n< 0x67 (g)\n> \t0x30 (0)\n> \t0x47 (G)\n> \t0x0d\n< 0x31 (1)\n",
    );
    assert_eq!(g.diags, vec![]);
    let got: Vec<_> = g
        .chunks
        .iter()
        .map(|c| (c.dir, c.bytes.clone(), c.ts_ns))
        .collect();
    assert_eq!(
        got,
        vec![
            (Direction::HostToDevice, b"0g".to_vec(), None),
            (Direction::DeviceToHost, b"0G\r".to_vec(), None),
            (Direction::HostToDevice, b"1".to_vec(), None),
        ]
    );
    // -e 0x0a: several bytes a line.
    let g = read_str(TextFormat::Interceptty, "# Using '[LF]' as end of line char\n< 30(0):67(g):73(s):0a([LF])\n> \t30(0):3a(:):29()):20(' ')\n");
    assert_eq!(g.diags, vec![]);
    assert_eq!(g.bytes(), b"0gs\n0:) ".to_vec());
}

#[test]
fn interceptty_bad_lines() {
    let text = "[12:00 00.000000]< 0x05 ([ENQ])\n                 < 0xzz (?)\nwhat is this\n[12:00 0x.000000]> \t0x06 ([ACK])\n[12:00 00.100000]> \t0x07 ([BEL])\n> \t0x08";
    let g = read_str(TextFormat::Interceptty, text);
    assert_eq!(
        g.kinds(),
        vec![
            ("bad_hex", 32),
            ("garbage_line", 60),
            ("bad_timestamp", 73),
            ("truncated_line", 139)
        ]
    );
    assert_eq!(g.bytes(), vec![5, 7, 8]);
    assert_eq!(g.chunks[1].ts_ns, Some(12 * 3600 * NS + 100_000_000));
}

// --- xxd / hexdump ---

/// `hexdump -C samples/kdc101-session.bin`, as hexdump printed it (a `*` for 3 zero lines).
const HEXDUMP_C: &str = "\
00000000  05 00 00 00 50 01 06 00  54 00 81 50 3b fd 9b 01  |....P...T..P;...|
00000010  4b 44 43 31 30 31 00 00  2c 00 0b 00 03 00 00 00  |KDC101..,.......|
00000020  00 00 00 00 00 00 00 00  00 00 00 00 00 00 00 00  |................|
*
00000050  00 00 00 00 00 00 00 00  00 00 01 00 00 00 01 00  |................|
00000060  10 02 01 01 50 01 11 02  01 00 50 01 12 02 01 01  |....P.....P.....|
00000070  01 50 11 00 00 00 50 01  43 04 01 00 50 01 91 04  |.P....P.C...P...|
00000080  0e 00 81 50 01 00 00 00  00 00 78 00 00 00 20 03  |...P......x... .|
00000090  00 80 91 04 0e 00 81 50  01 00 50 fb ff ff 78 00  |.......P..P...x.|
000000a0  00 00 20 03 00 80 91 04  0e 00 81 50 01 00 e8 ea  |.. ........P....|
000000b0  ff ff 78 00 00 00 20 03  00 80 91 04 0e 00 81 50  |..x... ........P|
000000c0  01 00 b8 d9 ff ff 78 00  00 00 20 03 00 80 44 04  |......x... ...D.|
000000d0  01 00 01 50 53 04 06 00  d0 01 01 00 00 9e 02 00  |...PS...........|
000000e0  91 04 0e 00 81 50 01 00  00 50 00 00 2c 01 00 00  |.....P...P..,...|
000000f0  10 05 00 80 91 04 0e 00  81 50 01 00 00 0c 01 00  |.........P......|
00000100  2c 01 00 00 10 05 00 80  91 04 0e 00 81 50 01 00  |,............P..|
00000110  00 dc 01 00 2c 01 00 00  10 05 00 80 91 04 0e 00  |....,...........|
00000120  81 50 01 00 00 86 02 00  2c 01 00 00 10 05 00 80  |.P......,.......|
00000130  91 04 0e 00 81 50 01 00  00 9e 02 00 2c 01 00 00  |.....P......,...|
00000140  10 05 00 80 64 04 0e 00  81 50 01 00 00 9e 02 00  |....d....P......|
00000150  00 00 00 00 00 25 00 80  12 00 00 00 50 01        |.....%......P.|
0000015e
";

#[test]
fn hexdump_c_with_repeats() {
    let g = read_str(TextFormat::HexdumpC, HEXDUMP_C);
    check_session(&g, false, false);
}

#[test]
fn hexdump_huge_repeat_is_streamed() {
    let text = "00000000  00 00 00 00 00 00 00 00  00 00 00 00 00 00 00 00  |................|\n*\n01000000\n";
    let mut r = open(TextFormat::HexdumpC, Cursor::new(text.as_bytes().to_vec()));
    let mut total = 0u64;
    while let Some(ev) = r.next_event() {
        match ev {
            Event::Chunk(c) => {
                assert!(c.bytes.len() <= MAX_CHUNK && c.bytes.iter().all(|&b| b == 0));
                total += c.bytes.len() as u64;
            }
            other => panic!("{other:?}"),
        }
    }
    assert_eq!(total, 0x0100_0000);
}

#[test]
fn hexdump_bad_lines() {
    let text = "00000000  05 00 00 00 50 01 06 00  54 00 81 50 3b fd 9b 01  |....P...T..P;...|\n\
00000010  4b 44 43 31 30 31 00 00  2c 00 0b 00 03 00 00 00  |KDC101..,.......|\n\
00000030  00 00 00 00 00 00 00 00  00 00 00 00 00 00 00 00  |................|\n\
*\n";
    let g = read_str(TextFormat::HexdumpC, text);
    assert_eq!(
        g.kinds(),
        vec![("offset_gap", 158), ("truncated_repeat", 237)]
    );
    assert_eq!(g.bytes().len(), 48);
}

#[test]
fn xxd_bad_hex_truncated_and_gap() {
    let xxd = String::from_utf8(sample("kdc101-session.xxd.txt")).unwrap();
    let lines: Vec<&str> = xxd.lines().collect();
    // Line 2 with a bad digit; line 4 missing; the last line cut in the middle.
    let bad = lines[1].replacen("4331", "43z1", 1);
    let cut = &lines[21][..20];
    let text = format!("{}\n{bad}\n{}\n{}\n{cut}", lines[0], lines[2], lines[4]);
    let g = read_str(TextFormat::Xxd, &text);
    let l = lines[0].len() as u64 + 1;
    assert_eq!(
        g.kinds(),
        vec![
            ("bad_hex", l),
            ("offset_gap", 3 * l),
            ("truncated_line", 4 * l)
        ]
    );
    assert!(
        g.diags[0].msg().contains("column 18"),
        "{}",
        g.diags[0].msg()
    );
    let bin = sample("kdc101-session.bin");
    let want = [&bin[..19], &bin[32..48], &bin[64..80], &bin[336..340]].concat();
    assert_eq!(g.bytes(), want);
}

#[test]
fn xxd_options_and_garbage() {
    // xxd -g1 -c8 -u, then a line that is not xxd.
    let g = read_str(
        TextFormat::Xxd,
        "00000000: 05 00 00 00 50 01 06 00  ....P...\n00000008: 54 00        T.\nnot xxd\n",
    );
    assert_eq!(g.kinds(), vec![("garbage_line", 70)]);
    assert_eq!(g.bytes(), vec![5, 0, 0, 0, 0x50, 1, 6, 0, 0x54, 0]);
    // A long run of lines is cut into chunks of MAX_CHUNK.
    let mut big = String::new();
    for i in 0..5000u32 {
        big += &format!(
            "{:08x}: 4142 4344 4546 4748 494a 4b4c 4d4e 4f50  ABCDEFGHIJKLMNOP\n",
            i * 16
        );
    }
    let g = read_str(TextFormat::Xxd, &big);
    assert_eq!(g.diags, vec![]);
    assert_eq!(
        g.chunks.iter().map(|c| c.bytes.len()).collect::<Vec<_>>(),
        vec![MAX_CHUNK, 80_000 - MAX_CHUNK]
    );
}

// --- hex columns ---

#[test]
fn hex_columns() {
    let text = "# a capture\n2024-05-01 12:00:00.000 05 00 00 00 50 01\n\
                [2024-05-01T12:00:00.011Z] 0x06, 0x00\n\
                12:00:00.262 0010: 12 02 01 01 01 50  ....P.\n\
                0.5 000020 aa bb  |..|\n\
                000030  cc dd ee\n";
    let g = read_str(TextFormat::HexColumns, text);
    assert_eq!(g.diags, vec![]);
    let got: Vec<_> = g
        .chunks
        .iter()
        .map(|c| (c.ts_ns, c.bytes.clone()))
        .collect();
    assert_eq!(
        got,
        vec![
            (Some(T0), vec![5, 0, 0, 0, 0x50, 1]),
            (Some(T0 + 11_000_000), vec![6, 0]),
            (
                Some(12 * 3600 * NS + 262_000_000),
                vec![0x12, 2, 1, 1, 1, 0x50]
            ),
            (Some(500_000_000), vec![0xaa, 0xbb]),
            (None, vec![0xcc, 0xdd, 0xee]),
        ]
    );
    // od -A x -t x1z
    let g = read_str(
        TextFormat::HexColumns,
        "000000 05 00 00 00 50 01  >....P.<\n000006\n",
    );
    assert_eq!(g.diags, vec![]);
    assert_eq!(g.bytes(), vec![5, 0, 0, 0, 0x50, 1]);
}

#[test]
fn hex_columns_bad_lines() {
    let text = "0000  05 00 0q 00\nnonsense here\n[12:61:00.0] 01\n0004  50 01\n0006  06 0";
    let g = read_str(TextFormat::HexColumns, text);
    assert_eq!(
        g.kinds(),
        vec![
            ("bad_hex", 0),
            ("garbage_line", 18),
            ("bad_timestamp", 32),
            ("truncated_line", 60)
        ]
    );
    assert_eq!(g.bytes(), vec![5, 0, 0x50, 1, 6]);
}

#[test]
fn line_too_long_is_skipped() {
    let text = format!(
        "0000  05 00\n{}\n0002  06 00\n",
        "ab ".repeat(MAX_LINE / 3 + 10)
    );
    let g = read_str(TextFormat::HexColumns, &text);
    assert_eq!(g.kinds(), vec![("line_too_long", 12)]);
    assert_eq!(g.bytes(), vec![5, 0, 6, 0]);
}

#[test]
fn io_error_is_reported() {
    struct Failing(usize);
    impl Read for Failing {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            if self.0 == 0 {
                return Err(io::Error::other("disk on fire"));
            }
            self.0 = 0;
            let line = b"00000000: 0500 0000 5001  ....P.\n";
            buf[..line.len()].copy_from_slice(line);
            Ok(line.len())
        }
    }
    let g = read_all(open(TextFormat::Xxd, BufReader::new(Failing(1))));
    assert_eq!(g.kinds(), vec![("io_error", 33)]);
    assert_eq!(g.bytes(), vec![5, 0, 0, 0, 0x50, 1]);
}

#[test]
fn truncated_line_keeps_earlier_diagnostics() {
    // A short block without "--", then a cut header: the short block is still reported,
    // the cut line only as truncated (not also as an unreadable header).
    let block = SOCAT_OK
        .replace("length=6 from=0 to=5", "length=7 from=0 to=6")
        .replace("--\n", "");
    let text = format!("{block}> 2024/05/01 12:0");
    let g = read_str(TextFormat::Socat, &text);
    assert_eq!(
        g.kinds(),
        vec![
            ("truncated_line", block.len() as u64),
            ("length_mismatch", 0)
        ]
    );
    assert_eq!(g.bytes(), vec![5, 0, 0, 0, 0x50, 1]);
}

/// Every sample through read buffers of a few bytes gives the same events.
#[test]
fn small_read_buffers() {
    let cases = [
        (TextFormat::Socat, "kdc101-session.socat.log"),
        (TextFormat::Jpnevulator, "kdc101-session.jpnevulator.txt"),
        (TextFormat::Interceptty, "kdc101-session.interceptty.log"),
        (TextFormat::Xxd, "kdc101-session.xxd.txt"),
    ];
    for (kind, name) in cases {
        let whole = read_sample(kind, name);
        for cap in [1, 2, 7, 61] {
            let r = BufReader::with_capacity(cap, Cursor::new(sample(name)));
            let g = read_all(open(kind, r));
            assert_eq!(g.chunks, whole.chunks, "{name} with {cap}-byte reads");
            assert_eq!(g.streams, whole.streams);
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

    /// Damaged samples and noise never panic, and every byte a reader gives is bounded.
    #[test]
    fn damaged_input_never_panics(
        which in 0usize..4,
        edits in proptest::collection::vec((0usize..20_000, 0u8..=255, 0u8..3), 0..40),
        noise in proptest::collection::vec(proptest::sample::select(b" 0123456789abcdefABCDEF<>:.-/|*[]()x\t\n\r".to_vec()), 0..3000),
    ) {
        let names = [
            "kdc101-session.socat.log",
            "kdc101-session.jpnevulator.txt",
            "kdc101-session.interceptty.log",
            "kdc101-session.xxd.txt",
        ];
        let mut text = sample(names[which]);
        for (pos, b, op) in edits {
            let pos = pos % (text.len() + 1);
            match op {
                0 => text.insert(pos, b),
                1 if pos < text.len() => { text.remove(pos); }
                _ if pos < text.len() => text[pos] = b,
                _ => {}
            }
        }
        for input in [text, noise] {
            let _ = sniff(&input);
            for kind in TextFormat::ALL {
                let g = read_all(open(kind, Cursor::new(input.clone())));
                proptest::prop_assert!(g.bytes().len() <= input.len());
                for d in &g.diags {
                    proptest::prop_assert!(d.offset <= input.len() as u64);
                }
            }
        }
    }
}

#[test]
fn timestamps() {
    assert_eq!(parse_datetime(b"1970-01-01 00:00:00"), Some((0, 19)));
    assert_eq!(
        parse_datetime(b"2024/05/01 12:00:00.123456 "),
        Some((T0 + 123_456_000, 26))
    );
    assert_eq!(
        parse_datetime(b"2024-02-30 00:00:00").map(|t| t.0),
        parse_datetime(b"2024-03-01 00:00:00").map(|t| t.0)
    );
    assert_eq!(parse_datetime(b"2024-13-01 00:00:00"), None);
    assert_eq!(
        parse_tod(b"23:59:59.999999999999", false),
        Some((DAY_NS - 1, 21))
    );
    assert_eq!(
        parse_tod(b"12:00 01.5", true),
        Some((43_201_500_000_000, 10))
    );
    assert_eq!(parse_tod(b"12:00 01.5", false), None);
    let mut c = TodClock::default();
    assert_eq!(c.at(DAY_NS - NS), DAY_NS - NS);
    assert_eq!(c.at(NS), DAY_NS + NS);
}
