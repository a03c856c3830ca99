//! The scripted session samples (`samples/sessions/`): regenerated, they are byte-identical to
//! the committed files; they decode with no diagnostics but the intended ones of `damaged`;
//! and the kdc101 and elliptec scripts, run in real time through a simulator on a
//! pseudo-terminal, the real tap and a host program, give the capture the virtual recording
//! predicts.

#[path = "../../tests/common/scratch.rs"]
mod scratch;

use aptscope_capture::live::session::{
    formats, frame_names, read_capture, record, run_real, session, write_recording, Recording,
    NAMES, STATUS_UPDATES,
};
use aptscope_capture::{Direction, OwnedChunk};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::pipeline::{Format as OutFormat, Pipeline};
use aptscope_dissector::Table;
use scratch::scratch;
use std::path::{Path, PathBuf};

fn samples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../samples/sessions")
}

fn recording(name: &str) -> Recording {
    record(name).unwrap_or_else(|e| panic!("{name}: {e}"))
}

#[test]
fn regenerated_samples_are_byte_identical_to_the_committed_ones() {
    let dir = scratch("regen");
    let mut expected: Vec<String> = vec!["README.md".into()];
    for name in NAMES {
        let rec = recording(name);
        for p in write_recording(&rec, &dir).expect("write") {
            let file = p
                .file_name()
                .and_then(|f| f.to_str())
                .expect("file name")
                .to_string();
            let new = std::fs::read(&p).expect("read new");
            let old = std::fs::read(samples().join(&file)).unwrap_or_else(|e| {
                panic!("samples/sessions/{file}: {e} (run samples/make-samples.sh)")
            });
            assert!(
                new == old,
                "samples/sessions/{file} differs from what the scripts record now: run \
                 `cargo run -p aptscope-capture --example record_sessions -- samples/sessions`"
            );
            // A few KB each (MCAP carries a JSON schema per message type).
            let limit = if file.ends_with(".mcap") { 128 } else { 8 } << 10;
            assert!(new.len() < limit, "{file}: {} bytes", new.len());
            expected.push(file);
        }
    }
    let mut committed: Vec<String> = std::fs::read_dir(samples())
        .expect("samples/sessions")
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .collect();
    committed.sort();
    expected.sort();
    assert_eq!(committed, expected, "files in samples/sessions");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn recording_twice_gives_the_same_chunks() {
    for name in NAMES {
        assert_eq!(recording(name), recording(name), "{name}");
    }
}

/// The diagnostic kinds of decoding a capture file, in order (file problems included).
fn diag_kinds(path: &Path) -> (Vec<String>, Vec<OwnedChunk>) {
    let (chunks, file_diags) = read_capture(path).expect("read");
    let mut kinds: Vec<String> = file_diags;
    let mut p = Pipeline::new(None, OutFormat::Json);
    let mut lines: Vec<String> = vec![];
    let mut emit = |l: &str| -> Result<(), ()> {
        lines.push(l.to_string());
        Ok(())
    };
    for c in &chunks {
        p.push_chunk(c.as_chunk().ctx(), &c.bytes, &mut emit)
            .expect("push");
    }
    p.finish(&mut emit).expect("finish");
    for l in &lines {
        for part in l.split("\"kind\":\"").skip(1) {
            kinds.push(part.split('"').next().unwrap_or("").to_string());
        }
    }
    (kinds, chunks)
}

#[test]
fn every_sample_decodes_without_diagnostics_but_the_intended_ones() {
    for name in NAMES {
        let rec = recording(name);
        for (ext, _) in formats(&rec) {
            let path = samples().join(format!("{name}.{ext}"));
            let (kinds, chunks) = diag_kinds(&path);
            let want: &[&str] = if *name == "damaged" {
                // Noise before the first reply and between two status updates, the last
                // status update cut after 9 bytes, and the move it was part of never completes.
                &["garbage", "garbage", "truncated", "no_reply"]
            } else {
                &[]
            };
            assert_eq!(kinds, want, "{name}.{ext}");
            let bytes: Vec<u8> = chunks.iter().flat_map(|c| c.bytes.clone()).collect();
            let rec_bytes: Vec<u8> = rec.chunks.iter().flat_map(|c| c.bytes.clone()).collect();
            assert!(bytes == rec_bytes, "{name}.{ext}: other bytes");
            if ext != "bin" {
                assert_eq!(chunks, rec.chunks, "{name}.{ext}: chunks");
            }
        }
    }
}

#[test]
fn sessions_show_what_their_readme_says() {
    let names = |n: &str| -> Vec<String> {
        let rec = recording(n);
        frame_names(rec.proto, &rec.chunks)
            .into_iter()
            .map(|(_, n)| n)
            .collect()
    };
    let kdc = names("kdc101");
    for m in [
        "HW_GET_INFO",
        "MOT_GET_VELPARAMS",
        "MOT_MOVE_HOMED",
        "MOT_GET_DCSTATUSUPDATE",
        "MOT_GET_POSCOUNTER",
    ] {
        assert!(kdc.iter().any(|n| n == m), "kdc101 lacks {m}");
    }
    assert_eq!(kdc.iter().filter(|n| *n == "MOT_MOVE_COMPLETED").count(), 2);
    let bsc = recording("bsc203");
    let bays: std::collections::BTreeSet<u8> = bsc
        .chunks
        .iter()
        .filter(|c| c.dir == Direction::DeviceToHost && c.bytes.len() >= 6)
        .map(|c| c.bytes[5])
        .collect();
    assert_eq!(
        bays.into_iter().collect::<Vec<_>>(),
        [0x11, 0x21, 0x22, 0x23]
    );
    let ltq = recording("laser-tec-quad");
    assert_eq!(ltq.streams.len(), 3);
    let ltq_names = names("laser-tec-quad");
    for m in ["LA_GET_PARAMS", "TEC_GET_PARAMS", "QUAD_GET_PARAMS"] {
        assert!(ltq_names.iter().filter(|n| *n == m).count() >= 3, "{m}");
    }
    let ell = names("elliptec");
    assert!(ell.iter().any(|n| n == "2ca"));
    assert!(ell.iter().any(|n| n == "5PO"));
}

// ------------------------------------------------------------------------------------ real time

/// Request/reply names without the periodic status updates.
fn exchange(proto: Proto, chunks: &[OwnedChunk]) -> Vec<(Direction, String)> {
    frame_names(proto, chunks)
        .into_iter()
        .filter(|(_, n)| {
            !STATUS_UPDATES
                .iter()
                .any(|&id| Table::global().msg(id).is_some_and(|m| m.name == n))
        })
        .collect()
}

fn real_matches_virtual(name: &str) {
    let s = session(name).expect("session");
    let part = &s.parts[0];
    let dir = scratch(name);
    let run = run_real(&part.device, &part.steps, &dir).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert!(run.stats.file_matches(), "{}", run.stats.summary(name));
    assert!(
        run.stats.disconnects.is_empty(),
        "{:?}",
        run.stats.disconnects
    );
    let (chunks, diags) = read_capture(&run.capture).expect("capture");
    assert!(diags.is_empty(), "{diags:?}");
    assert!(chunks.iter().all(|c| c.ts_ns.is_some()));
    let side = |d: Direction| -> Vec<u8> {
        chunks
            .iter()
            .filter(|c| {
                assert_ne!(c.dir, Direction::Unknown, "chunk without direction");
                c.dir == d
            })
            .flat_map(|c| c.bytes.clone())
            .collect()
    };
    assert!(
        side(Direction::HostToDevice) == run.sent,
        "{name}: host → device bytes differ from what the script wrote"
    );
    assert!(
        side(Direction::DeviceToHost) == run.read,
        "{name}: device → host bytes differ from what the host read"
    );
    let proto = part.device.proto();
    let virt = recording(name);
    assert_eq!(
        exchange(proto, &chunks),
        exchange(proto, &virt.chunks),
        "{name}: request/reply sequence"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn kdc101_in_real_time_through_the_tap_matches_the_virtual_recording() {
    real_matches_virtual("kdc101");
}

#[test]
fn elliptec_in_real_time_through_the_tap_matches_the_virtual_recording() {
    real_matches_virtual("elliptec");
}
