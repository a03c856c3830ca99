//! `aptscope info`: what a capture holds, like capinfos.

use crate::model::{Direction, Event, ReadDiag, Reader, StreamInfo};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::record::{Decoder, Record};
use aptscope_dissector::table::Dir;
use std::fmt::Write;

/// Counts for one (stream, direction).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LaneStats {
    /// Stream index.
    pub stream: u32,
    /// Direction.
    pub dir: Option<Direction>,
    /// Chunks read.
    pub chunks: u64,
    /// Bytes read.
    pub bytes: u64,
    /// Frames decoded.
    pub frames: u64,
    /// Frames with a diagnostic.
    pub frames_with_diags: u64,
    /// Bytes in garbage records.
    pub garbage_bytes: u64,
}

/// What a capture holds.
#[derive(Debug, Clone, Default)]
pub struct Info {
    /// Format description.
    pub format: String,
    /// Protocol and whether it was detected with certainty.
    pub proto: Option<(Proto, bool)>,
    /// Streams announced.
    pub streams: Vec<StreamInfo>,
    /// Per lane counts.
    pub lanes: Vec<LaneStats>,
    /// First and last chunk times (ns).
    pub first_ts: Option<u64>,
    /// Last chunk time (ns).
    pub last_ts: Option<u64>,
    /// File diagnostics (all counted, the first 20 kept).
    pub file_diags: Vec<ReadDiag>,
    /// Number of file diagnostics.
    pub file_diag_count: u64,
}

/// The lane of a (stream, direction), made on first use.
fn lane(lanes: &mut Vec<LaneStats>, stream: u32, dir: Option<Direction>) -> &mut LaneStats {
    let i = match lanes
        .iter()
        .position(|l| l.stream == stream && l.dir == dir)
    {
        Some(i) => i,
        None => {
            lanes.push(LaneStats {
                stream,
                dir,
                ..LaneStats::default()
            });
            lanes.len() - 1
        }
    };
    &mut lanes[i]
}

/// The capture's direction as the decoder keeps it.
fn direction(d: Option<Dir>) -> Option<Direction> {
    match d {
        Some(Dir::HostToDevice) => Some(Direction::HostToDevice),
        Some(Dir::DeviceToHost) => Some(Direction::DeviceToHost),
        _ => None,
    }
}

/// Count one record of the decoder in its lane (frames, frames with a diagnostic as `decode`
/// shows them, garbage bytes) and note the protocol it chose.
fn count(info: &mut Info, rec: &Record<'_>) {
    let (meta, diags) = match rec {
        Record::Detect {
            proto, detection, ..
        } => {
            info.proto = Some((*proto, detection.proto.is_some()));
            return;
        }
        Record::Apt(a) => {
            let p = a.pair;
            let paired =
                p.unsolicited || (p.duplicate && p.pair.is_some()) || p.not_for_model.is_some();
            (&a.meta, a.frame.has_diags() || paired)
        }
        Record::Ell(e) => (&e.meta, !e.frame.diags().is_empty()),
        Record::Garbage(g) => {
            lane(&mut info.lanes, g.meta.stream, direction(g.meta.cap_dir)).garbage_bytes +=
                g.bytes.len() as u64;
            return;
        }
        _ => return,
    };
    let l = lane(&mut info.lanes, meta.stream, direction(meta.cap_dir));
    l.frames += 1;
    l.frames_with_diags += u64::from(diags);
}

/// Read a whole capture (streaming) and count what it holds. `proto` forces the protocol.
pub fn summarize(r: &mut dyn Reader, proto: Option<Proto>) -> Info {
    let mut info = Info {
        proto: proto.map(|p| (p, true)),
        ..Info::default()
    };
    let mut dec = Decoder::new(proto);
    while let Some(ev) = r.next_event() {
        match ev {
            Event::Stream(s) => info.streams.push(s),
            Event::Diag(d) => {
                info.file_diag_count += 1;
                if info.file_diags.len() < 20 {
                    info.file_diags.push(d);
                }
            }
            Event::Chunk(c) => {
                let dir = Some(c.dir).filter(|d| *d != Direction::Unknown);
                let l = lane(&mut info.lanes, c.stream, dir);
                l.chunks += 1;
                l.bytes += c.bytes.len() as u64;
                if let Some(t) = c.ts_ns {
                    info.first_ts = Some(info.first_ts.map_or(t, |f| f.min(t)));
                    info.last_ts = Some(info.last_ts.map_or(t, |f| f.max(t)));
                }
                let _ = dec.push(c.ctx(), c.bytes, &mut |rec: &Record<'_>| {
                    count(&mut info, rec);
                    Ok::<(), ()>(())
                });
            }
        }
    }
    let _ = dec.finish(&mut |rec: &Record<'_>| {
        count(&mut info, rec);
        Ok::<(), ()>(())
    });
    info.format = r.format();
    info
}

/// A UTC time as `YYYY-MM-DD hh:mm:ss.nnnnnnnnn`.
pub fn utc(ns: u64) -> String {
    let secs = ns / 1_000_000_000;
    let (days, rem) = (secs / 86_400, secs % 86_400);
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02}:{:02}.{:09}",
        rem / 3600,
        rem / 60 % 60,
        rem % 60,
        ns % 1_000_000_000
    )
}

impl Info {
    /// capinfos-like text.
    pub fn to_text(&self, name: &str) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "File name:            {name}");
        let _ = writeln!(s, "File format:          {}", self.format);
        match self.proto {
            Some((p, certain)) => {
                let _ = writeln!(
                    s,
                    "Protocol:             {}{}",
                    p.name(),
                    if certain {
                        ""
                    } else {
                        " (mixed or unknown; best guess)"
                    }
                );
            }
            None => {
                let _ = writeln!(s, "Protocol:             none (no data)");
            }
        }
        for st in &self.streams {
            let _ = writeln!(
                s,
                "Stream {}:             {}{}",
                st.id,
                st.name,
                st.settings
                    .as_ref()
                    .map(|x| format!(" ({x})"))
                    .unwrap_or_default()
            );
        }
        if let (Some(a), Some(b)) = (self.first_ts, self.last_ts) {
            let _ = writeln!(s, "First chunk time:     {}", utc(a));
            let _ = writeln!(s, "Last chunk time:      {}", utc(b));
            let _ = writeln!(s, "Duration:             {:.6} s", (b - a) as f64 / 1e9);
        } else {
            let _ = writeln!(s, "Times:                not recorded");
        }
        let (mut chunks, mut bytes, mut frames, mut bad, mut garbage) = (0, 0, 0, 0, 0);
        for l in &self.lanes {
            let dir = l.dir.map_or("unknown", |d| d.as_str());
            let _ = writeln!(
                s,
                "Stream {} {dir:<8}     {} chunks, {} bytes, {} frames ({} with diagnostics), {} garbage bytes",
                l.stream, l.chunks, l.bytes, l.frames, l.frames_with_diags, l.garbage_bytes
            );
            chunks += l.chunks;
            bytes += l.bytes;
            frames += l.frames;
            bad += l.frames_with_diags;
            garbage += l.garbage_bytes;
        }
        let _ = writeln!(s, "Total:                {chunks} chunks, {bytes} bytes, {frames} frames ({bad} with diagnostics), {garbage} garbage bytes");
        let _ = writeln!(s, "File diagnostics:     {}", self.file_diag_count);
        for d in &self.file_diags {
            let _ = writeln!(s, "  {d}");
        }
        s
    }

    /// The same as one JSON object.
    pub fn to_json(&self, name: &str) -> String {
        use aptscope_dissector::json::string;
        let mut s = String::from("{\"file\":");
        string(&mut s, name);
        s.push_str(",\"format\":");
        string(&mut s, &self.format);
        match self.proto {
            Some((p, c)) => {
                let _ = write!(s, ",\"proto\":\"{}\",\"proto_certain\":{c}", p.code());
            }
            None => s.push_str(",\"proto\":null"),
        }
        s.push_str(",\"streams\":[");
        for (i, st) in self.streams.iter().enumerate() {
            let _ = write!(
                s,
                "{}{{\"id\":{},\"name\":",
                if i > 0 { "," } else { "" },
                st.id
            );
            string(&mut s, &st.name);
            if let Some(x) = &st.settings {
                s.push_str(",\"settings\":");
                string(&mut s, x);
            }
            s.push('}');
        }
        s.push_str("],\"lanes\":[");
        for (i, l) in self.lanes.iter().enumerate() {
            let _ = write!(
                s,
                "{}{{\"stream\":{},\"dir\":\"{}\",\"chunks\":{},\"bytes\":{},\"frames\":{},\"frames_with_diags\":{},\"garbage_bytes\":{}}}",
                if i > 0 { "," } else { "" },
                l.stream,
                l.dir.map_or("unknown", |d| d.as_str()),
                l.chunks,
                l.bytes,
                l.frames,
                l.frames_with_diags,
                l.garbage_bytes
            );
        }
        s.push(']');
        if let (Some(a), Some(b)) = (self.first_ts, self.last_ts) {
            let _ = write!(
                s,
                ",\"first_ts_ns\":{a},\"last_ts_ns\":{b},\"duration_s\":{}",
                (b - a) as f64 / 1e9
            );
        }
        let _ = write!(s, ",\"file_diags\":{}}}", self.file_diag_count);
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::open::{open, OpenOptions};

    fn sample(name: &str) -> String {
        format!("{}/../samples/{name}", env!("CARGO_MANIFEST_DIR"))
    }

    /// `info` counts what the decode chain yields: per lane, frames (with diagnostics as
    /// `decode` shows them: pairing's included) and garbage bytes.
    #[test]
    fn counts_the_records_of_the_decode_chain() {
        let (mut r, _) =
            open(&sample("sessions/kdc101.pcapng"), OpenOptions::default()).expect("sample opens");
        let i = summarize(r.as_mut(), None);
        assert_eq!(i.proto, Some((Proto::Apt, true)));
        // What the chain yields for the same capture.
        let (mut r, _) =
            open(&sample("sessions/kdc101.pcapng"), OpenOptions::default()).expect("sample opens");
        let mut want: Vec<(u32, Option<Direction>, u64, u64)> = vec![];
        let mut dec = Decoder::new(None);
        let mut tally = |rec: &Record<'_>| {
            if let Record::Apt(a) = rec {
                let d = direction(a.meta.cap_dir);
                let k = match want.iter().position(|w| (w.0, w.1) == (a.meta.stream, d)) {
                    Some(k) => k,
                    None => {
                        want.push((a.meta.stream, d, 0, 0));
                        want.len() - 1
                    }
                };
                want[k].2 += 1;
                want[k].3 += u64::from(a.frame.has_diags() || a.pair.unsolicited);
            }
            Ok::<(), ()>(())
        };
        while let Some(ev) = r.next_event() {
            if let Event::Chunk(c) = ev {
                dec.push(c.ctx(), c.bytes, &mut tally).expect("no error");
            }
        }
        dec.finish(&mut tally).expect("no error");
        let got: Vec<_> = i
            .lanes
            .iter()
            .map(|l| (l.stream, l.dir, l.frames, l.frames_with_diags))
            .collect();
        assert_eq!(got, want);
        assert!(got.iter().map(|g| g.2).sum::<u64>() > 20, "{got:?}");
        let (mut r, _) =
            open(&sample("damaged.bin"), OpenOptions::default()).expect("sample opens");
        let i = summarize(r.as_mut(), Some(Proto::Apt));
        assert!(i.lanes[0].garbage_bytes > 0, "{:?}", i.lanes);
        assert!(i.lanes[0].frames_with_diags > 0, "{:?}", i.lanes);
    }

    #[test]
    fn utc_formats_known_instants() {
        assert_eq!(utc(0), "1970-01-01 00:00:00.000000000");
        assert_eq!(
            utc(1_700_000_000_123_456_789),
            "2023-11-14 22:13:20.123456789"
        );
        assert_eq!(
            utc(951_782_400_000_000_000),
            "2000-02-29 00:00:00.000000000"
        );
    }
}
