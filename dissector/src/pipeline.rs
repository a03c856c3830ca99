//! From captured chunks to rendered lines: the [`Decoder`]'s records as text or NDJSON. Pure:
//! the caller feeds chunks and writes the lines out.

use crate::detect::Proto;
use crate::diag::Diag;
use crate::fields::InFile;
use crate::filter::{Filter, IdSet};
use crate::record::{Decoder, Record};
use crate::table::Dir;
use crate::units::UnitsOpts;
use crate::{json, text};
use std::fmt::Write;

pub use crate::record::Ctx;

/// Output format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// One tshark-like line per record.
    Text,
    /// One JSON object per line.
    Json,
}

/// The decoding pipeline for one capture: a [`Decoder`] and a renderer.
pub struct Pipeline {
    fmt: Format,
    dec: Decoder,
    r: Renderer,
}

/// Renders [`Record`]s as text or NDJSON lines: the one place records become lines (the
/// pipeline, MCAP's decoded channels and the live views all use it).
pub struct Renderer {
    fmt: Format,
    line: String,
    filter: Option<Filter>,
    /// The APT message ids whose frames can pass the filter (`None`: any).
    ids: Option<IdSet>,
    /// The input's name when records name it (several inputs).
    file: Option<String>,
    /// Streams seen (announced or carrying records): the timeline names a record's stream
    /// once there are two.
    streams: Vec<u32>,
}

impl Pipeline {
    /// A pipeline for `proto`, or auto-detection from the first 4 KiB when `None`.
    pub fn new(proto: Option<Proto>, fmt: Format) -> Self {
        Pipeline {
            fmt,
            dec: Decoder::new(proto),
            r: Renderer::new(fmt),
        }
    }

    /// Convert APT motion values (positions, velocities, accelerations) to physical units
    /// with this stage or scale, beside their raw values. Without it only devices with a
    /// built-in stage (HW_GET_INFO model K10CR1, LTS150 …) convert.
    pub fn set_units(&mut self, opts: UnitsOpts) {
        self.dec.set_units(opts);
    }

    /// Name the input in every NDJSON record (`"file": name`, first key), for runs over several
    /// files: numbers, offsets and pairs count within a file.
    pub fn set_file(&mut self, name: &str) {
        self.r.file = Some(name.to_string());
    }

    /// Use one reply timeout for every request instead of the per-message defaults.
    pub fn set_reply_timeout(&mut self, ns: u64) {
        self.dec.set_reply_timeout(ns);
    }

    /// Emit only the frames, garbage and no-reply records `filter` accepts (read from the typed
    /// records; only what is emitted is rendered). Records are still numbered, so a kept record
    /// keeps its number. Detection, stream, input and units records always pass.
    pub fn set_filter(&mut self, filter: Filter) {
        self.r.ids = filter.apt_ids(crate::Table::global());
        self.r.filter = Some(filter);
    }

    /// The protocol in use (after detection).
    pub fn proto(&self) -> Option<Proto> {
        self.dec.proto()
    }

    /// The detector's verdict (see [`Decoder::detection`]).
    pub fn detection(&self) -> Option<&crate::detect::Detection> {
        self.dec.detection()
    }

    /// Records numbered so far (frames and garbage runs).
    pub fn records(&self) -> u64 {
        self.dec.records()
    }

    /// The decoder under the pipeline (frames and bytes so far, detection).
    pub fn decoder(&self) -> &Decoder {
        &self.dec
    }

    /// The output format.
    pub fn format(&self) -> Format {
        self.fmt
    }

    /// Feed bytes of a single unknown-direction stream without times.
    pub fn push<E>(
        &mut self,
        chunk: &[u8],
        ts: Option<u64>,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        let ctx = Ctx {
            ts_ns: ts,
            ..Ctx::default()
        };
        self.push_chunk(ctx, chunk, emit)
    }

    /// Feed one captured chunk. Each rendered record is passed to `emit` (without newline).
    pub fn push_chunk<E>(
        &mut self,
        ctx: Ctx,
        chunk: &[u8],
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        let r = &mut self.r;
        self.dec.push(ctx, chunk, &mut |rec| r.render(rec, emit))
    }

    /// Decide the protocol now when the bytes held so far make it certain (see
    /// [`Decoder::detect_if_certain`]): a live input shows its records at once instead of after
    /// the 4 KiB detection sample. Returns whether the protocol is known.
    pub fn detect_if_certain<E>(
        &mut self,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<bool, E> {
        let r = &mut self.r;
        self.dec.detect_if_certain(&mut |rec| r.render(rec, emit))
    }

    /// Say that the sender of `dir` on `stream` has paused (see [`Decoder::cut`]).
    pub fn cut<E>(
        &mut self,
        stream: u32,
        dir: Dir,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        let r = &mut self.r;
        self.dec.cut(stream, dir, &mut |rec| r.render(rec, emit))
    }

    /// Report a problem of the input itself (a bad character in hex text, a corrupt capture
    /// record), with its offset in the file.
    pub fn input_diag<E>(
        &mut self,
        d: &Diag,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        let r = &mut self.r;
        self.dec.input_diag(d, &mut |rec| r.render(rec, emit))
    }

    /// Report a stream (port, device) the capture names: its index, name and line settings.
    pub fn stream_info<E>(
        &mut self,
        id: u32,
        name: &str,
        settings: Option<&str>,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        let r = &mut self.r;
        self.dec
            .stream_info(id, name, settings, &mut |rec| r.render(rec, emit))
    }

    /// Report a capture-file problem given as text (kind and message) at a file offset.
    pub fn file_diag<E>(
        &mut self,
        offset: u64,
        kind: &str,
        msg: &str,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        let r = &mut self.r;
        self.dec
            .file_diag(offset, kind, msg, &mut |rec| r.render(rec, emit))
    }

    /// End of capture: flush what is left and report commands that got no reply.
    pub fn finish<E>(&mut self, emit: &mut impl FnMut(&str) -> Result<(), E>) -> Result<(), E> {
        let r = &mut self.r;
        self.dec.finish(&mut |rec| r.render(rec, emit))
    }
}

impl Renderer {
    /// A renderer writing `fmt`.
    pub fn new(fmt: Format) -> Self {
        Renderer {
            fmt,
            line: String::with_capacity(512),
            filter: None,
            ids: None,
            file: None,
            streams: vec![],
        }
    }

    /// Name the input in every NDJSON record, and to the filter (see [`Pipeline::set_file`]).
    pub fn set_file(&mut self, name: &str) {
        self.file = Some(name.to_string());
    }

    /// Render only what `filter` accepts (see [`Pipeline::set_filter`]).
    pub fn set_filter(&mut self, filter: Filter) {
        self.ids = filter.apt_ids(crate::Table::global());
        self.filter = Some(filter);
    }

    /// The streams seen so far (what decides whether text lines name their stream).
    pub fn streams(&self) -> &[u32] {
        &self.streams
    }

    /// Start from these streams seen: a renderer taking over the records of a capture from
    /// the middle renders them as the one that saw the start would.
    pub fn set_streams(&mut self, streams: &[u32]) {
        self.streams.clear();
        self.streams.extend_from_slice(streams);
    }

    /// Note the stream a record names, as rendering it would (without rendering it): a
    /// thread that hands records to other renderers keeps the streams seen with this.
    pub fn note_streams(&mut self, rec: &Record<'_>) {
        if let Some(m) = rec.meta() {
            self.saw_stream(m.stream);
        }
        if let Record::Stream { id, .. } = rec {
            self.saw_stream(*id);
        }
    }

    /// Whether a record passes the filter (every record when there is none).
    fn keep(&self, rec: &Record<'_>) -> bool {
        if let (Some(ids), Record::Apt(a)) = (&self.ids, rec) {
            if !ids.contains(a.frame.header().msg_id()) {
                return false;
            }
        }
        self.filter.as_ref().is_none_or(|f| {
            f.matches(&InFile {
                file: self.file.as_deref(),
                rec,
            })
        })
    }

    /// Note a stream; true when the timeline should name streams (two or more seen).
    fn saw_stream(&mut self, id: u32) -> bool {
        if !self.streams.contains(&id) {
            self.streams.push(id);
        }
        self.streams.len() > 1
    }

    /// The line of one record, as [`Pipeline`] would emit it (file name and filter aside).
    pub fn line(&mut self, rec: &Record<'_>) -> &str {
        let _ = self.render(rec, &mut |_: &str| Ok::<(), ()>(()));
        &self.line
    }

    /// Render one record and emit it (frames and diagnostics through the filter).
    pub fn render<E>(
        &mut self,
        rec: &Record<'_>,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        if let Some(m) = rec.meta() {
            self.saw_stream(m.stream);
        }
        if matches!(
            rec,
            Record::Apt(_) | Record::Ell(_) | Record::Garbage(_) | Record::NoReply(_)
        ) && !self.keep(rec)
        {
            return Ok(());
        }
        if self.fmt == Format::Json {
            self.line.clear();
            json::record(&mut self.line, rec, self.file.as_deref());
            return emit(&self.line);
        }
        let stream_col = self.streams.len() > 1;
        let line = &mut self.line;
        line.clear();
        match rec {
            Record::Detect {
                proto,
                detection: d,
                sample,
            } => {
                let verdict = if d.proto.is_some() {
                    "detected"
                } else {
                    "mixed or unknown stream; best guess"
                };
                let _ = write!(
                    line,
                    "# protocol {}: {verdict} ({:.0}% of the first {sample} bytes frame as APT, {:.0}% as Elliptec; --proto to choose)",
                    proto.name(),
                    d.apt * 100.0,
                    d.elliptec * 100.0
                );
                return emit(line);
            }
            Record::Stream { id, name, settings } => {
                if !self.streams.contains(id) {
                    self.streams.push(*id);
                }
                let _ = write!(line, "# stream {id}: {name}");
                if let Some(x) = settings {
                    let _ = write!(line, " ({x})");
                }
                return emit(line);
            }
            Record::Input(d) => {
                text::input_diag_line(line, d);
                return emit(line);
            }
            Record::FileDiag { offset, kind, msg } => {
                let _ = write!(line, "     - {offset:>#10x}  !! file: {kind}: {msg}");
                return emit(line);
            }
            // Not filtered: it explains what follows.
            Record::Units(nt) => {
                text::units_notice_line(line, nt);
                return emit(line);
            }
            Record::Apt(a) => {
                let m = &a.meta;
                text::apt_line_in(line, m.n, a.frame, m.rel_s, a.scale);
                text::pair_suffix(line, a.pair);
            }
            Record::Ell(e) => {
                let m = &e.meta;
                text::ell_line(line, m.n, e.frame, e.obs, m.rel_s);
            }
            Record::Garbage(g) => {
                let m = &g.meta;
                match g.kind {
                    Some(kind) => text::garbage_line(line, m.n, g.offset, g.bytes, kind, m.rel_s),
                    None => text::ell_garbage_line(line, m.n, g.offset, g.bytes, m.rel_s),
                }
            }
            Record::NoReply(e) => text::late_diag_line(line, e.n, &e.diag()),
        }
        if stream_col {
            // Several streams: each line says which (`# stream N: NAME` names them).
            let stream = rec.meta().map_or_else(
                || match rec {
                    Record::NoReply(e) => e.stream,
                    _ => 0,
                },
                |m| m.stream,
            );
            line.insert_str(0, &format!("s{stream} "));
        }
        emit(line)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Table;

    /// Diagnostics met while the protocol is being detected keep their place among the frames.
    #[test]
    fn file_diagnostics_during_detection_keep_their_place() {
        let mut p = Pipeline::new(None, Format::Json);
        let mut out: Vec<String> = vec![];
        let mut emit = |l: &str| -> Result<(), ()> {
            out.push(l.to_string());
            Ok(())
        };
        let identify = [0x23, 0x02, 0x01, 0x00, 0x50, 0x01];
        p.push(&identify, None, &mut emit).unwrap();
        p.file_diag(40, "truncated_record", "cut", &mut emit)
            .unwrap();
        p.push(&identify, None, &mut emit).unwrap();
        p.finish(&mut emit).unwrap();
        let kinds: Vec<&str> = out
            .iter()
            .map(|l| {
                if l.contains("\"type\":\"input\"") {
                    "diag"
                } else if l.contains("\"type\":\"frame\"") {
                    "frame"
                } else {
                    "other"
                }
            })
            .collect();
        assert_eq!(kinds, ["other", "frame", "diag", "frame"], "{out:?}");
    }

    fn frame(name: &str, values: &[(&str, &str)], dst: u8, src: u8) -> Vec<u8> {
        let n = crate::apt::Named {
            name,
            sub: None,
            values,
            form: None,
            dst,
            src,
        };
        crate::apt::encode_named(Table::global(), &n).expect("valid frame")
    }

    /// Decode `chunks` (host/device direction each) with `opts`, as NDJSON objects.
    fn decode_json(opts: UnitsOpts, chunks: &[(Dir, Vec<u8>)]) -> Vec<serde_json::Value> {
        let mut p = Pipeline::new(Some(Proto::Apt), Format::Json);
        p.set_units(opts);
        let mut out: Vec<String> = vec![];
        let mut emit = |l: &str| -> Result<(), ()> {
            out.push(l.to_string());
            Ok(())
        };
        for (dir, b) in chunks {
            let ctx = Ctx {
                stream: 0,
                dir: Some(*dir),
                ts_ns: None,
            };
            p.push_chunk(ctx, b, &mut emit).unwrap();
        }
        p.finish(&mut emit).unwrap();
        out.iter()
            .map(|l| serde_json::from_str(l).expect("JSON"))
            .collect()
    }

    /// Two streams: text lines name theirs, every record carries it and a capture-wide
    /// offset, a filter reads the typed records (what it drops is not emitted), and a
    /// record's file comes first when the pipeline names one.
    #[test]
    fn streams_offsets_files_and_filters() {
        let req = frame("HW_REQ_INFO", &[], 0x50, 0x01);
        let info = frame("HW_GET_INFO", &[("model_number", "KDC101")], 0x01, 0x50);
        let run = |fmt: Format, filter: Option<&str>| -> Vec<String> {
            let mut p = Pipeline::new(Some(Proto::Apt), fmt);
            p.set_file("a.bin");
            if let Some(f) = filter {
                p.set_filter(crate::filter::Filter::parse(f).expect("filter"));
            }
            let mut out: Vec<String> = vec![];
            let mut emit = |l: &str| -> Result<(), ()> {
                out.push(l.to_string());
                Ok(())
            };
            p.stream_info(0, "/dev/ttyUSB0", None, &mut emit).unwrap();
            p.stream_info(1, "/dev/ttyUSB1", None, &mut emit).unwrap();
            for (stream, dir, b) in [
                (0, Dir::HostToDevice, &req),
                (1, Dir::HostToDevice, &req),
                (1, Dir::DeviceToHost, &info),
            ] {
                let ctx = Ctx {
                    stream,
                    dir: Some(dir),
                    ts_ns: None,
                };
                p.push_chunk(ctx, b, &mut emit).unwrap();
            }
            p.finish(&mut emit).unwrap();
            out
        };
        let text = run(Format::Text, None);
        let frames: Vec<&String> = text.iter().filter(|l| l.contains("HW_")).collect();
        assert_eq!(frames.len(), 3, "{text:?}");
        assert!(
            frames[0].starts_with("s0 ") && frames[1].starts_with("s1 "),
            "{text:?}"
        );
        assert!(text
            .iter()
            .any(|l| l.starts_with("s0 ") && l.contains("!! #1")));
        let json = run(Format::Json, None);
        let recs: Vec<serde_json::Value> = json
            .iter()
            .map(|l| serde_json::from_str(l).expect("JSON"))
            .collect();
        assert!(recs.iter().all(|r| r["file"] == "a.bin"), "{json:?}");
        let frames: Vec<&serde_json::Value> =
            recs.iter().filter(|r| r["type"] == "frame").collect();
        // Requests #1 and #2 are both at offset 0 of their lanes; not in the capture.
        let offs: Vec<(u64, u64)> = frames
            .iter()
            .filter_map(|r| Some((r["offset"].as_u64()?, r["cap_offset"].as_u64()?)))
            .collect();
        assert_eq!(offs, [(0, 0), (0, 6), (0, 12)]);
        let late = recs.iter().find(|r| r["type"] == "diag").expect("no_reply");
        assert_eq!((&late["ref"], &late["stream"]), (&1.into(), &0.into()));
        let only = run(Format::Json, Some("stream == 1 && apt.name ~ GET"));
        let kept: Vec<&String> = only.iter().filter(|l| l.contains("\"n\"")).collect();
        assert_eq!(kept.len(), 1, "{only:?}");
        assert!(kept[0].contains("\"n\":3") && kept[0].contains("\"pair\":2"));
        let none = run(Format::Text, Some("file contains b.bin"));
        assert!(none.iter().all(|l| l.starts_with('#')), "{none:?}");
    }

    const VEL: &[(&str, &str)] = &[
        ("chan_ident", "CH1"),
        ("min_vel", "0"),
        ("acceleration", "1502"),
        ("max_vel", "73291093"),
    ];

    /// A K10CR1 names itself in HW_GET_INFO and its stage is built in: its motion values come
    /// out in degrees with no option (Trinamic rules: 136533.33 µsteps/deg, × 53.68, ÷ 90.9).
    #[test]
    fn a_fixed_stage_model_converts_once_hw_get_info_names_it() {
        let info = frame(
            "HW_GET_INFO",
            &[("serial_number", "55000123"), ("model_number", "K10CR1")],
            0x01,
            0x50,
        );
        let vel = frame("MOT_GET_VELPARAMS", VEL, 0x01, 0x50);
        let recs = decode_json(
            UnitsOpts::default(),
            &[
                (Dir::DeviceToHost, vel.clone()),
                (Dir::DeviceToHost, info),
                (Dir::DeviceToHost, vel),
            ],
        );
        let kinds: Vec<&str> = recs.iter().filter_map(|r| r["type"].as_str()).collect();
        assert_eq!(kinds, ["frame", "units", "frame", "frame"], "{recs:?}");
        // Before the model is known: raw only.
        assert!(recs[0].get("phys").is_none(), "{}", recs[0]);
        assert_eq!(recs[0]["fields"]["max_vel"], 73291093);
        let u = &recs[1];
        assert_eq!(
            (&u["model"], &u["stage"], &u["family"], &u["unit"]),
            (
                &serde_json::json!("K10CR1"),
                &serde_json::json!("K10CR1"),
                &serde_json::json!("stepper_trinamic"),
                &serde_json::json!("deg")
            )
        );
        let v = &recs[3];
        assert_eq!(v["fields"]["max_vel"], 73291093, "raw stays where it was");
        assert_eq!(v["phys"]["max_vel"]["unit"], "deg/s");
        let max_vel = v["phys"]["max_vel"]["value"].as_f64().unwrap_or(0.0);
        assert!((max_vel - 10.0).abs() < 1e-4, "{max_vel}");
        let acc = v["phys"]["acceleration"]["value"].as_f64().unwrap_or(0.0);
        assert!((acc - 1.0).abs() < 1e-3, "{acc}");
        assert_eq!(v["phys"]["acceleration"]["unit"], "deg/s2");
    }

    /// A stage named on the command line: converted from the first motion value on, and a
    /// stage the controller cannot drive leaves the values raw, saying why.
    #[test]
    fn a_named_stage_converts_and_a_mismatch_says_why() {
        let vel = frame("MOT_SET_VELPARAMS", VEL, 0x50, 0x01);
        let named = |n| UnitsOpts {
            stage: Some(crate::units::StageChoice::Named(n)),
            controller: None,
        };
        let recs = decode_json(named("LTS150"), &[(Dir::HostToDevice, vel.clone())]);
        // LTS150 is in both stepper tables: nothing says which controller.
        assert_eq!(recs[0]["type"], "units");
        assert!(recs[0]["raw"]
            .as_str()
            .unwrap_or("")
            .contains("HW_GET_INFO"));
        assert!(recs[1].get("phys").is_none());
        let info = frame("HW_GET_INFO", &[("model_number", "BSC203")], 0x01, 0x21);
        let to_bay = frame("MOT_SET_VELPARAMS", VEL, 0x21, 0x01);
        let recs = decode_json(
            named("LTS150"),
            &[(Dir::DeviceToHost, info), (Dir::HostToDevice, to_bay)],
        );
        assert_eq!(recs[0]["stage"], "LTS150");
        assert_eq!(recs[0]["counts_per_unit"], 409600.0);
        let v = recs[2]["phys"]["max_vel"]["value"].as_f64().unwrap_or(0.0);
        assert!((v - 73291093.0 / 409600.0 / 53.68).abs() < 1e-3, "{v}");
        let info = frame("HW_GET_INFO", &[("model_number", "BSC203")], 0x01, 0x50);
        let recs = decode_json(
            named("MTS25-Z8"),
            &[(Dir::DeviceToHost, info), (Dir::HostToDevice, vel)],
        );
        assert!(recs[0]["raw"].as_str().unwrap_or("").contains("not listed"));
        assert!(recs[2].get("phys").is_none(), "{}", recs[2]);
    }
}
