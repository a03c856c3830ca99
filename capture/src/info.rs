//! `aptscope info`: what a capture holds, like capinfos.

use crate::model::{Direction, Event, ReadDiag, Reader, StreamInfo};
use aptscope_dissector::apt::{AptFrame, AptFramer, Item as AptItem};
use aptscope_dissector::detect::{detect, Proto, SAMPLE};
use aptscope_dissector::ell::{EllFrame, EllFramer, Item as EllItem};
use aptscope_dissector::Table;
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

enum Framer {
    Apt(AptFramer<'static>),
    Ell(EllFramer),
}

fn count(f: &mut Framer, s: &mut LaneStats) {
    match f {
        Framer::Apt(a) => {
            while let Some(it) = a.next_item() {
                match it {
                    AptItem::Frame {
                        offset,
                        bytes,
                        truncated,
                    } => {
                        s.frames += 1;
                        if AptFrame::decode(Table::global(), offset, bytes, truncated)
                            .is_none_or(|x| x.has_diags())
                        {
                            s.frames_with_diags += 1;
                        }
                    }
                    AptItem::Garbage { bytes, .. } => s.garbage_bytes += bytes.len() as u64,
                }
            }
        }
        Framer::Ell(e) => {
            while let Some(it) = e.next_item() {
                match it {
                    EllItem::Frame {
                        offset,
                        bytes,
                        truncated,
                    } => {
                        s.frames += 1;
                        if EllFrame::decode(offset, bytes, truncated)
                            .is_none_or(|x| !x.diags().is_empty())
                        {
                            s.frames_with_diags += 1;
                        }
                    }
                    EllItem::Garbage { bytes, .. } => s.garbage_bytes += bytes.len() as u64,
                }
            }
        }
    }
}

/// Read a whole capture (streaming) and count what it holds. `proto` forces the protocol.
pub fn summarize(r: &mut dyn Reader, proto: Option<Proto>) -> Info {
    let mut info = Info::default();
    let mut framers: Vec<Framer> = vec![];
    let mut sample: Vec<(usize, Vec<u8>)> = vec![];
    let mut sample_len = 0usize;
    let mut chosen = proto.map(|p| (p, true));
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
                let i = match info
                    .lanes
                    .iter()
                    .position(|l| l.stream == c.stream && l.dir == dir)
                {
                    Some(i) => i,
                    None => {
                        info.lanes.push(LaneStats {
                            stream: c.stream,
                            dir,
                            ..LaneStats::default()
                        });
                        info.lanes.len() - 1
                    }
                };
                let l = &mut info.lanes[i];
                l.chunks += 1;
                l.bytes += c.bytes.len() as u64;
                if let Some(t) = c.ts_ns {
                    info.first_ts = Some(info.first_ts.map_or(t, |f| f.min(t)));
                    info.last_ts = Some(info.last_ts.map_or(t, |f| f.max(t)));
                }
                match chosen {
                    None => {
                        sample_len += c.bytes.len();
                        sample.push((i, c.bytes.to_vec()));
                        if sample_len >= SAMPLE {
                            chosen = Some(decide(&sample));
                        }
                    }
                    Some((p, _)) => {
                        feed(&mut framers, &mut info.lanes, i, p, c.bytes);
                    }
                }
                if let (Some((p, _)), false) = (chosen, sample.is_empty()) {
                    for (li, b) in std::mem::take(&mut sample) {
                        feed(&mut framers, &mut info.lanes, li, p, &b);
                    }
                }
            }
        }
    }
    if chosen.is_none() && !sample.is_empty() {
        chosen = Some(decide(&sample));
        let p = chosen.map_or(Proto::Apt, |c| c.0);
        for (li, b) in std::mem::take(&mut sample) {
            feed(&mut framers, &mut info.lanes, li, p, &b);
        }
    }
    for (i, f) in framers.iter_mut().enumerate() {
        match f {
            Framer::Apt(a) => a.finish(),
            Framer::Ell(e) => e.finish(),
        }
        count(f, &mut info.lanes[i]);
    }
    info.proto = chosen;
    info.format = r.format();
    info
}

/// Frame `b` on lane `i` (creating its framer for protocol `p` on first use) and count what
/// comes out.
fn feed(framers: &mut Vec<Framer>, lanes: &mut [LaneStats], i: usize, p: Proto, b: &[u8]) {
    while framers.len() <= i {
        framers.push(match p {
            Proto::Apt => Framer::Apt(AptFramer::new(Table::global())),
            Proto::Elliptec => Framer::Ell(EllFramer::new()),
        });
    }
    match &mut framers[i] {
        Framer::Apt(a) => a.push(b),
        Framer::Ell(e) => e.push(b),
    }
    count(&mut framers[i], &mut lanes[i]);
}

fn decide(sample: &[(usize, Vec<u8>)]) -> (Proto, bool) {
    let first = sample.first().map_or(0, |s| s.0);
    let bytes: Vec<u8> = sample
        .iter()
        .filter(|s| s.0 == first)
        .flat_map(|s| s.1.iter().copied())
        .take(SAMPLE)
        .collect();
    let d = detect(&bytes);
    match d.proto {
        Some(p) => (p, true),
        None => (
            if d.elliptec > d.apt {
                Proto::Elliptec
            } else {
                Proto::Apt
            },
            false,
        ),
    }
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
    use super::utc;

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
