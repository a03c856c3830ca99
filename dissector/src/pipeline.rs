//! From captured chunks to rendered records: protocol detection, one framer per (stream,
//! direction) lane, decoding, Elliptec bus state and pairing, text or NDJSON lines. Pure: the
//! caller feeds chunks and writes the lines out.
//!
//! Frames come out in the order they complete, which for a capture read in time order is time
//! order: the lanes are merged by time.

use crate::apt::{AptFrame, AptFramer, Item as AptItem};
use crate::detect::{detect, Detection, Proto, SAMPLE};
use crate::diag::{Diag, DiagKind};
use crate::ell::{Bus, EllFrame, EllFramer, Expired, Item as EllItem};
use crate::pair::AptPairer;
use crate::table::Dir;
use crate::units::{Tracker, UnitsOpts};
use crate::{json, text, Table};
use std::fmt::Write;

/// Output format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// One tshark-like line per record.
    Text,
    /// One JSON object per line.
    Json,
}

/// A chunk's context: where and when its bytes were captured.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Ctx {
    /// Stream (port/device) index.
    pub stream: u32,
    /// Direction, when the capture records it.
    pub dir: Option<Dir>,
    /// Capture time in ns, when recorded.
    pub ts_ns: Option<u64>,
}

struct Lane {
    stream: u32,
    dir: Option<Dir>,
    apt: AptFramer<'static>,
    ell: EllFramer,
    /// Time of the latest chunk: the time a frame completing now gets.
    ts: Option<u64>,
    /// Bytes pushed so far, and the (first offset, time) of each timed chunk not yet behind
    /// the records emitted: garbage gets the time its first byte arrived.
    pushed: u64,
    times: std::collections::VecDeque<(u64, u64)>,
}

impl Lane {
    /// Time of the byte at stream offset `at` from a lane's `times` (else `latest`). Records
    /// come in offset order: what is before `at` is forgotten.
    fn time_at(
        times: &mut std::collections::VecDeque<(u64, u64)>,
        latest: Option<u64>,
        at: u64,
    ) -> Option<u64> {
        while times.get(1).is_some_and(|(o, _)| *o <= at) {
            times.pop_front();
        }
        times
            .front()
            .filter(|(o, _)| *o <= at)
            .map(|(_, t)| *t)
            .or(latest)
    }
}

/// The decoding pipeline for one capture.
pub struct Pipeline {
    fmt: Format,
    proto: Option<Proto>,
    /// Chunks held back until the protocol is known.
    sample: Vec<(Ctx, Vec<u8>)>,
    sample_len: usize,
    /// Input and file diagnostics met while the sample is held, with the number of sample
    /// chunks before them: emitted in their place among the sample's records.
    held: Vec<(usize, String)>,
    lanes: Vec<Lane>,
    buses: Vec<(u32, Bus)>,
    pairers: Vec<(u32, AptPairer)>,
    first_ts: Option<u64>,
    n: u64,
    line: String,
    jline: String,
    filter: Option<RecordFilter>,
    reply_timeout: Option<u64>,
    /// `{"file":NAME,` when records name their input (several inputs), else empty.
    file_prefix: String,
    /// Models seen per device and the stage conversion of motion values.
    units: Tracker,
}

/// Decides, from its NDJSON object, whether a record is emitted.
type RecordFilter = Box<dyn FnMut(&serde_json::Value) -> bool>;

impl Pipeline {
    /// A pipeline for `proto`, or auto-detection from the first 4 KiB when `None`.
    pub fn new(proto: Option<Proto>, fmt: Format) -> Self {
        Pipeline {
            fmt,
            proto,
            sample: vec![],
            sample_len: 0,
            held: vec![],
            lanes: vec![],
            buses: vec![],
            pairers: vec![],
            first_ts: None,
            n: 0,
            line: String::with_capacity(512),
            jline: String::with_capacity(512),
            filter: None,
            reply_timeout: None,
            file_prefix: String::new(),
            units: Tracker::new(UnitsOpts::default()),
        }
    }

    /// Convert APT motion values (positions, velocities, accelerations) to physical units
    /// with this stage or scale, beside their raw values. Without it only devices with a
    /// built-in stage (HW_GET_INFO model K10CR1, LTS150 …) convert.
    pub fn set_units(&mut self, opts: UnitsOpts) {
        self.units = Tracker::new(opts);
    }

    /// Name the input in every NDJSON record (`"file": name`, first key), for runs over several
    /// files: numbers, offsets and pairs count within a file.
    pub fn set_file(&mut self, name: &str) {
        self.file_prefix.clear();
        self.file_prefix.push_str("{\"file\":");
        json::string(&mut self.file_prefix, name);
        self.file_prefix.push(',');
    }

    /// Use one reply timeout for every request instead of the per-message defaults.
    pub fn set_reply_timeout(&mut self, ns: u64) {
        self.reply_timeout = Some(ns);
    }

    /// Emit only the records `keep` accepts (it sees each record as its NDJSON object, whatever
    /// the output format). Records are still numbered, so a kept record keeps its number.
    pub fn set_filter(&mut self, keep: impl FnMut(&serde_json::Value) -> bool + 'static) {
        self.filter = Some(Box::new(keep));
    }

    /// The protocol in use (after detection).
    pub fn proto(&self) -> Option<Proto> {
        self.proto
    }

    /// Records emitted so far.
    pub fn records(&self) -> u64 {
        self.n
    }

    /// Feed bytes of a single unknown-direction stream without times.
    pub fn push<E>(
        &mut self,
        chunk: &[u8],
        ts: Option<u64>,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        self.push_chunk(
            Ctx {
                ts_ns: ts,
                ..Ctx::default()
            },
            chunk,
            emit,
        )
    }

    /// Feed one captured chunk. Each rendered record is passed to `emit` (without newline).
    pub fn push_chunk<E>(
        &mut self,
        ctx: Ctx,
        chunk: &[u8],
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        if self.proto.is_none() {
            self.sample.push((ctx, chunk.to_vec()));
            self.sample_len += chunk.len();
            if self.sample_len < SAMPLE {
                return Ok(());
            }
            self.choose(emit)?;
            return self.replay_sample(emit);
        }
        self.feed(ctx, chunk, emit)
    }

    /// Say that the sender of `dir` on `stream` has paused (a live source knows: its write is
    /// over): an Elliptec host command complete but for its optional terminator is framed now
    /// instead of when the next byte comes. APT frames need no such hint.
    pub fn cut<E>(
        &mut self,
        stream: u32,
        dir: Dir,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        if self.proto != Some(Proto::Elliptec) {
            return Ok(());
        }
        for j in 0..self.lanes.len() {
            if self.lanes[j].stream == stream && self.lanes[j].dir == Some(dir) {
                self.lanes[j].ell.cut();
                self.drain(j, emit)?;
            }
        }
        Ok(())
    }

    /// Report a problem of the input itself (a bad character in hex text, a corrupt capture
    /// record), with its offset in the file.
    pub fn input_diag<E>(
        &mut self,
        d: &Diag,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        self.line.clear();
        match self.fmt {
            Format::Json => {
                self.line.push_str("{\"type\":\"input\",\"diag\":");
                json::diags(&mut self.line, std::iter::once(*d));
                self.line.push('}');
            }
            Format::Text => text::input_diag_line(&mut self.line, d),
        }
        self.emit_or_hold(emit)
    }

    /// Report a stream (port, device) the capture names: its index, name and line settings.
    pub fn stream_info<E>(
        &mut self,
        id: u32,
        name: &str,
        settings: Option<&str>,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        self.line.clear();
        match self.fmt {
            Format::Json => {
                let _ = write!(
                    self.line,
                    "{{\"type\":\"stream\",\"stream\":{id},\"stream_name\":"
                );
                json::string(&mut self.line, name);
                if let Some(x) = settings {
                    self.line.push_str(",\"settings\":");
                    json::string(&mut self.line, x);
                }
                self.line.push('}');
            }
            Format::Text => {
                let _ = write!(self.line, "# stream {id}: {name}");
                if let Some(x) = settings {
                    let _ = write!(self.line, " ({x})");
                }
            }
        }
        self.tag_line();
        emit(&self.line)
    }

    /// Report a capture-file problem given as text (kind and message) at a file offset.
    pub fn file_diag<E>(
        &mut self,
        offset: u64,
        kind: &str,
        msg: &str,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        self.line.clear();
        match self.fmt {
            Format::Json => {
                let _ = write!(self.line, "{{\"type\":\"input\",\"diag\":[{{\"kind\":");
                json::string(&mut self.line, kind);
                let _ = write!(self.line, ",\"offset\":{offset},\"msg\":");
                json::string(&mut self.line, msg);
                self.line.push_str("}]}");
            }
            Format::Text => {
                let _ = write!(self.line, "     - {offset:>#10x}  !! file: {kind}: {msg}");
            }
        }
        self.emit_or_hold(emit)
    }

    /// End of capture: flush what is left and report commands that got no reply.
    pub fn finish<E>(&mut self, emit: &mut impl FnMut(&str) -> Result<(), E>) -> Result<(), E> {
        if self.proto.is_none() {
            if self.sample.is_empty() {
                // Nothing to detect from: only the diagnostics.
                for (_, line) in std::mem::take(&mut self.held) {
                    emit(&line)?;
                }
                return Ok(());
            }
            self.choose(emit)?;
            self.replay_sample(emit)?;
        }
        for i in 0..self.lanes.len() {
            self.lanes[i].apt.finish();
            self.lanes[i].ell.finish();
            self.drain(i, emit)?;
        }
        let mut left = vec![];
        for (_, bus) in self.buses.iter_mut() {
            left.extend(bus.finish());
        }
        left.sort_by_key(|e| e.n);
        self.render_expired("ell", &left, emit)?;
        let mut left: Vec<Expired> = vec![];
        for (_, p) in self.pairers.iter_mut() {
            left.extend(p.finish().into_iter().map(|u| Expired {
                n: u.n,
                offset: u.offset,
                code: u.name,
            }));
        }
        left.sort_by_key(|e| e.n);
        self.render_expired("apt", &left, emit)
    }

    /// Emit the diagnostic line in `self.line`, or hold it while the protocol is not known (its
    /// place is after the sample chunks held so far).
    fn emit_or_hold<E>(&mut self, emit: &mut impl FnMut(&str) -> Result<(), E>) -> Result<(), E> {
        self.tag_line();
        if self.proto.is_none() {
            self.held.push((self.sample.len(), self.line.clone()));
            return Ok(());
        }
        emit(&self.line)
    }

    /// Put the input's name into the JSON record in `self.line` (see [`Pipeline::set_file`]).
    fn tag_line(&mut self) {
        if self.fmt == Format::Json && !self.file_prefix.is_empty() && self.line.starts_with('{') {
            self.line.replace_range(..1, &self.file_prefix);
        }
    }

    fn replay_sample<E>(&mut self, emit: &mut impl FnMut(&str) -> Result<(), E>) -> Result<(), E> {
        let mut held = std::mem::take(&mut self.held).into_iter().peekable();
        for (i, (ctx, bytes)) in std::mem::take(&mut self.sample).into_iter().enumerate() {
            while let Some((_, line)) = held.next_if(|(at, _)| *at <= i) {
                emit(&line)?;
            }
            self.feed(ctx, &bytes, emit)?;
        }
        for (_, line) in held {
            emit(&line)?;
        }
        self.sample_len = 0;
        Ok(())
    }

    fn choose<E>(&mut self, emit: &mut impl FnMut(&str) -> Result<(), E>) -> Result<(), E> {
        let mut bytes = Vec::with_capacity(SAMPLE);
        // Judge the busiest lane of the sample: interleaved lanes would confuse both framers.
        let lane_of = |c: &Ctx| (c.stream, c.dir.map(|d| d.as_str()));
        let mut best: Option<((u32, Option<&str>), usize)> = None;
        for (c, b) in &self.sample {
            let k = lane_of(c);
            let total: usize = self
                .sample
                .iter()
                .filter(|(x, _)| lane_of(x) == k)
                .map(|(_, y)| y.len())
                .sum();
            if best.is_none_or(|(_, t)| total > t) {
                best = Some((k, total));
            }
            let _ = b;
        }
        if let Some((k, _)) = best {
            for (c, b) in &self.sample {
                if lane_of(c) == k && bytes.len() < SAMPLE {
                    bytes.extend_from_slice(b);
                }
            }
        }
        let d: Detection = detect(&bytes);
        let proto = d.proto.unwrap_or(if d.elliptec > d.apt {
            Proto::Elliptec
        } else {
            Proto::Apt
        });
        self.proto = Some(proto);
        self.line.clear();
        let verdict = if d.proto.is_some() {
            "detected"
        } else {
            "mixed or unknown stream; best guess"
        };
        match self.fmt {
            Format::Json => {
                let _ = write!(
                    self.line,
                    "{{\"type\":\"detect\",\"proto\":\"{}\",\"certain\":{},\"apt\":{:.3},\"ell\":{:.3}}}",
                    proto.code(),
                    d.proto.is_some(),
                    d.apt,
                    d.elliptec
                );
            }
            Format::Text => {
                let _ = write!(
                    self.line,
                    "# protocol {}: {verdict} ({:.0}% of the first {} bytes frame as APT, {:.0}% as Elliptec; --proto to choose)",
                    proto.name(),
                    d.apt * 100.0,
                    bytes.len().min(SAMPLE),
                    d.elliptec * 100.0
                );
            }
        }
        self.tag_line();
        emit(&self.line)
    }

    fn lane(&mut self, ctx: &Ctx) -> usize {
        if let Some(i) = self
            .lanes
            .iter()
            .position(|l| l.stream == ctx.stream && l.dir == ctx.dir)
        {
            return i;
        }
        self.lanes.push(Lane {
            stream: ctx.stream,
            dir: ctx.dir,
            apt: AptFramer::new(Table::global()),
            ell: EllFramer::new(),
            ts: None,
            pushed: 0,
            times: Default::default(),
        });
        self.lanes.len() - 1
    }

    fn feed<E>(
        &mut self,
        ctx: Ctx,
        chunk: &[u8],
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        if self.first_ts.is_none() {
            self.first_ts = ctx.ts_ns;
        }
        let i = self.lane(&ctx);
        if self.proto == Some(Proto::Elliptec) && ctx.dir.is_some() {
            // The other direction speaks: the host's last command is over, terminator or not.
            for j in 0..self.lanes.len() {
                let l = &self.lanes[j];
                if j != i && l.stream == ctx.stream && l.dir.is_some() && l.dir != ctx.dir {
                    self.lanes[j].ell.cut();
                    self.drain(j, emit)?;
                }
            }
        }
        let lane = &mut self.lanes[i];
        if let Some(t) = ctx.ts_ns {
            lane.ts = Some(t);
            lane.times.push_back((lane.pushed, t));
        }
        lane.pushed += chunk.len() as u64;
        match self.proto {
            Some(Proto::Apt) => lane.apt.push(chunk),
            _ => lane.ell.push(chunk),
        }
        self.drain(i, emit)
    }

    /// Append the capture context to a JSON object (before its closing brace).
    fn close_json(line: &mut String, ts: Option<u64>, stream: u32, dir: Option<&str>) {
        if line.ends_with('}') {
            line.pop();
            if let Some(d) = dir {
                let _ = write!(line, ",\"dir\":\"{d}\"");
            }
            if let Some(t) = ts {
                let _ = write!(line, ",\"ts_ns\":{t}");
            }
            let _ = write!(line, ",\"stream\":{stream}}}");
        }
    }

    /// Emit the record rendered in `self.jline` (JSON, when wanted) and `self.line` (text, when
    /// wanted), if the filter lets it through.
    fn emit_record<E>(&mut self, emit: &mut impl FnMut(&str) -> Result<(), E>) -> Result<(), E> {
        if !self.file_prefix.is_empty() && self.jline.starts_with('{') {
            self.jline.replace_range(..1, &self.file_prefix);
        }
        if let Some(f) = self.filter.as_mut() {
            let keep = serde_json::from_str::<serde_json::Value>(&self.jline).is_ok_and(|v| f(&v));
            if !keep {
                return Ok(());
            }
        }
        match self.fmt {
            Format::Json => emit(&self.jline),
            Format::Text => emit(&self.line),
        }
    }

    fn want_json(&self) -> bool {
        self.fmt == Format::Json || self.filter.is_some()
    }

    fn drain<E>(
        &mut self,
        i: usize,
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        let t = Table::global();
        let first = self.first_ts;
        let (ts, stream, cap_dir) = (self.lanes[i].ts, self.lanes[i].stream, self.lanes[i].dir);
        let rel = |ts: Option<u64>| match (ts, first) {
            (Some(a), Some(b)) => Some(a.saturating_sub(b) as f64 / 1e9),
            _ => None,
        };
        let time = rel(ts);
        let (want_json, want_text) = (self.want_json(), self.fmt == Format::Text);
        if self.proto == Some(Proto::Apt) {
            let pi_idx = match self.pairers.iter().position(|(s, _)| *s == stream) {
                Some(p) => p,
                None => {
                    let mut p = AptPairer::new();
                    p.timeout_ns = self.reply_timeout;
                    self.pairers.push((stream, p));
                    self.pairers.len() - 1
                }
            };
            loop {
                let lane = &mut self.lanes[i];
                let Some(item) = lane.apt.next_item() else {
                    break;
                };
                let (AptItem::Frame { offset: at, .. } | AptItem::Garbage { offset: at, .. }) =
                    item;
                let first_ts = Lane::time_at(&mut lane.times, ts, at);
                let mut rec_ts = ts;
                self.n += 1;
                self.line.clear();
                self.jline.clear();
                let mut dir = cap_dir.map(|d| d.as_str());
                let mut expired = vec![];
                match item {
                    AptItem::Frame {
                        offset,
                        bytes,
                        truncated,
                    } => {
                        if let Some(f) = AptFrame::decode(t, offset, bytes, truncated) {
                            if dir.is_none() {
                                dir = f
                                    .msg
                                    .map(|m| m.dir)
                                    .filter(|d| *d != Dir::Both)
                                    .map(|d| d.as_str());
                            }
                            let pinfo = self.pairers[pi_idx].1.observe(t, self.n, &f, cap_dir, ts);
                            expired = pinfo
                                .expired
                                .iter()
                                .map(|u| Expired {
                                    n: u.n,
                                    offset: u.offset,
                                    code: u.name,
                                })
                                .collect();
                            let (scale, notice) = self.units.observe(stream, &f);
                            if let Some(nt) = notice {
                                // Before the frame: what its values are converted with.
                                let mut l = String::new();
                                match self.fmt {
                                    Format::Json => json::units_notice(&mut l, &nt),
                                    Format::Text => text::units_notice_line(&mut l, &nt),
                                }
                                emit(&l)?;
                            }
                            if want_json {
                                json::apt_frame_in(&mut self.jline, self.n, &f, &pinfo, scale);
                            }
                            if want_text {
                                text::apt_line_in(&mut self.line, self.n, &f, time, scale);
                                text::pair_suffix(&mut self.line, &pinfo);
                            }
                        }
                    }
                    AptItem::Garbage {
                        offset,
                        bytes,
                        kind,
                    } => {
                        rec_ts = first_ts;
                        if want_json {
                            json::apt_garbage(&mut self.jline, self.n, offset, bytes, kind);
                        }
                        if want_text {
                            let t = rel(first_ts);
                            text::garbage_line(&mut self.line, self.n, offset, bytes, kind, t);
                        }
                    }
                }
                Self::close_json(
                    &mut self.jline,
                    rec_ts,
                    stream,
                    Some(dir.unwrap_or("unknown")),
                );
                self.emit_record(emit)?;
                self.render_expired("apt", &expired, emit)?;
            }
            return Ok(());
        }
        let bus_idx = match self.buses.iter().position(|(s, _)| *s == stream) {
            Some(b) => b,
            None => {
                let mut b = Bus::new();
                b.timeout_ns = self.reply_timeout;
                self.buses.push((stream, b));
                self.buses.len() - 1
            }
        };
        loop {
            let lane = &mut self.lanes[i];
            let Some(item) = lane.ell.next_item() else {
                break;
            };
            let (EllItem::Frame { offset: at, .. } | EllItem::Garbage { offset: at, .. }) = item;
            let first_ts = Lane::time_at(&mut lane.times, ts, at);
            let mut rec_ts = ts;
            self.n += 1;
            self.line.clear();
            self.jline.clear();
            let mut expired: Vec<Expired> = vec![];
            match item {
                EllItem::Frame {
                    offset,
                    bytes,
                    truncated,
                } => {
                    let Some(mut f) = EllFrame::decode(offset, bytes, truncated) else {
                        continue;
                    };
                    let o = self.buses[bus_idx].1.observe(self.n, &f, ts);
                    if o.unsolicited {
                        f.push_diag(Diag {
                            offset,
                            kind: DiagKind::Unsolicited,
                        });
                    }
                    expired.extend(o.expired.iter().copied());
                    if want_json {
                        json::ell_frame(&mut self.jline, self.n, &f, &o);
                    }
                    if want_text {
                        text::ell_line(&mut self.line, self.n, &f, &o, time);
                    }
                }
                EllItem::Garbage { offset, bytes, .. } => {
                    rec_ts = first_ts;
                    if want_json {
                        json::ell_garbage(&mut self.jline, self.n, offset, bytes);
                    }
                    if want_text {
                        let t = rel(first_ts);
                        text::ell_garbage_line(&mut self.line, self.n, offset, bytes, t);
                    }
                }
            }
            Self::close_json(&mut self.jline, rec_ts, stream, None);
            self.emit_record(emit)?;
            self.render_expired("ell", &expired, emit)?;
        }
        Ok(())
    }

    fn render_expired<E>(
        &mut self,
        proto: &str,
        list: &[Expired],
        emit: &mut impl FnMut(&str) -> Result<(), E>,
    ) -> Result<(), E> {
        for e in list {
            let d = Diag {
                offset: e.offset,
                kind: DiagKind::NoReply { cmd: e.n },
            };
            self.line.clear();
            self.jline.clear();
            if self.want_json() {
                json::late_diag(&mut self.jline, proto, e.n, d);
            }
            if self.fmt == Format::Text {
                text::late_diag_line(&mut self.line, e.n, &d);
            }
            self.emit_record(emit)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
