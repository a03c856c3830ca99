//! `aptscope stats`: counts and bytes per message, per address, per direction; pair latency
//! (min/median/p99/max) per request; diagnostics by kind; a time-binned rate; per stream when
//! a capture has several. Read from the typed records through [`Fields`] (NDJSON objects read
//! alike), so what a filter selects is what is counted.

use crate::fields::{Fields, Key, Num, Role, Val};
use std::collections::BTreeMap;
use std::fmt::Write;

/// Count and bytes.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Tally {
    /// Records.
    pub count: u64,
    /// Bytes.
    pub bytes: u64,
}

/// Per message: count, bytes, and the latencies of its requests' replies (ms).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MsgStat {
    /// Count and bytes.
    pub tally: Tally,
    /// Latencies of the replies to this message (when it is a request), in ms.
    pub latencies: Latencies,
}

/// Latencies kept in bounded memory: exact count, minimum and maximum; quantiles from every
/// value up to [`LATENCY_SAMPLE`] of them, then from a uniform sample of that size (reservoir
/// sampling with a fixed seed, so the same capture gives the same figures).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Latencies {
    n: u64,
    min: f64,
    max: f64,
    sample: Vec<f64>,
    rng: u64,
}

/// Latencies kept per message for quantiles.
pub const LATENCY_SAMPLE: usize = 1 << 16;

impl Latencies {
    /// Add one latency (ms).
    pub fn push(&mut self, x: f64) {
        if self.n == 0 {
            self.min = x;
            self.max = x;
        } else {
            self.min = self.min.min(x);
            self.max = self.max.max(x);
        }
        self.n += 1;
        if self.sample.len() < LATENCY_SAMPLE {
            self.sample.push(x);
            return;
        }
        // Algorithm R: keep the new value with probability LATENCY_SAMPLE / n.
        let mut r = self.rng.wrapping_add(0x9E37_79B9_7F4A_7C15);
        self.rng = r;
        r = (r ^ (r >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        r = (r ^ (r >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        r ^= r >> 31;
        let j = r % self.n;
        if let Some(slot) = self.sample.get_mut(j as usize) {
            *slot = x;
        }
    }

    /// How many latencies were added.
    pub fn len(&self) -> u64 {
        self.n
    }

    /// Whether none was.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }
}

/// Count and bytes of one stream, with its name when the capture gives one.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StreamStat {
    /// The stream's name (port, device), from its `stream` record.
    pub name: Option<String>,
    /// Frames and their bytes.
    pub tally: Tally,
}

/// Statistics over decoded records.
#[derive(Debug, Clone)]
pub struct Stats {
    /// Frames.
    pub frames: Tally,
    /// Garbage records.
    pub garbage: Tally,
    /// Per message (`apt NAME` / `ell cmd NAME`).
    pub messages: BTreeMap<String, MsgStat>,
    /// Per address (`src → dst` for APT, the bus address for Elliptec).
    pub addresses: BTreeMap<String, Tally>,
    /// Per direction.
    pub directions: BTreeMap<String, Tally>,
    /// Diagnostics by kind.
    pub diags: BTreeMap<String, u64>,
    /// Problems of the capture file itself (damaged or cut records, unknown link types), by
    /// kind: what `decode` and `info` report before any frame.
    pub file_problems: BTreeMap<String, u64>,
    /// The first [`FILE_EXAMPLES`] of them: (file offset, kind, text).
    pub file_examples: Vec<(u64, String, String)>,
    /// Frames per time bin (bin start in ns since the first frame).
    pub bins: BTreeMap<u64, u64>,
    /// Bin width in ns.
    pub bin_ns: u64,
    /// Per stream (port, device): frames, and the name the capture gives it.
    pub streams: BTreeMap<u64, StreamStat>,
    /// Per stream and address, shown instead of `addresses` when there are several streams.
    pub stream_addresses: BTreeMap<(u64, String), Tally>,
    first_ts: Option<u64>,
    /// Recent request (stream, record number) → message key (to attribute reply latency to
    /// the request); bounded, so a long capture keeps flat memory.
    requests: BTreeMap<(u64, u64), String>,
    /// Reused to build keys without an allocation per record.
    scratch: String,
    /// Reused for the direction of the record being counted.
    dir_scratch: String,
    /// Paths read below keys, built once.
    p_kind: Vec<String>,
}

/// File problems listed one by one (all are counted).
pub const FILE_EXAMPLES: usize = 20;

/// At most this many rate bins are shown (text and JSON): a longer capture gets wider bins.
pub const MAX_RATE_BINS: u64 = 200;

/// Requests remembered for their replies' latency: far more than the pairer can have waiting.
const MAX_REQUESTS: usize = 1 << 16;

/// Append the text at `key`/`rest` of `rec` to `out`; false when there is none.
fn push_str<F: Fields + ?Sized>(rec: &F, key: Key, rest: &[String], out: &mut String) -> bool {
    if let Some(w) = rest.is_empty().then(|| rec.word(key)).flatten() {
        out.push_str(w);
        return true;
    }
    let mut found = false;
    rec.visit(key, rest, &mut |v, r| {
        if let (Val::Str(s), false, Role::Plain) = (v, found, r) {
            out.push_str(&s);
            found = true;
        }
    });
    found
}

/// Append the key a frame is counted under in [`Stats::messages`] to `out`: `apt NAME` (its
/// `msgid_hex` when the table does not know it), `ell CMD NAME`. The one spelling of these
/// keys: every view that counts frames (the TUI's statistics too) builds them here.
pub fn message_key<F: Fields + ?Sized>(rec: &F, out: &mut String) {
    if rec.proto() == Some("ell") {
        out.push_str("ell ");
        if !push_str(rec, Key::Cmd, &[], out) {
            out.push('?');
        }
        out.push(' ');
        if !push_str(rec, Key::Name, &[], out) {
            out.push_str("UNKNOWN");
        }
    } else {
        out.push_str("apt ");
        if !push_str(rec, Key::Name, &[], out) && !push_str(rec, Key::MsgidHex, &[], out) {
            out.push('?');
        }
    }
}

/// Append the key a frame is counted under in [`Stats::addresses`] (and
/// [`Stats::stream_addresses`]) to `out`: `apt SRC → DST` (the addresses' names), `ell ADDR`.
/// The one spelling, as for [`message_key`].
pub fn address_key<F: Fields + ?Sized>(rec: &F, out: &mut String) {
    static NAME: std::sync::OnceLock<[String; 1]> = std::sync::OnceLock::new();
    let name = NAME.get_or_init(|| ["name".to_string()]);
    if rec.proto() == Some("ell") {
        out.push_str("ell ");
        if !push_str(rec, Key::Addr, &[], out) {
            out.push('?');
        }
    } else {
        out.push_str("apt ");
        if !push_str(rec, Key::Src, name, out) {
            out.push('?');
        }
        out.push_str(" → ");
        if !push_str(rec, Key::Dst, name, out) {
            out.push('?');
        }
    }
}

/// The number at `key` of `rec`.
fn number<F: Fields + ?Sized>(rec: &F, key: Key) -> Option<Num> {
    if let Some(x) = rec.number(key) {
        return Some(Num::I(i128::from(x)));
    }
    let mut n = None;
    rec.visit(key, &[], &mut |v, _| {
        if let Val::Num(x) = v {
            n.get_or_insert(x);
        }
    });
    n
}

/// Whether the text at `key` of `rec` is `want`.
fn text_is<F: Fields + ?Sized>(rec: &F, key: Key, want: &str) -> bool {
    if let Some(w) = rec.word(key) {
        return w == want;
    }
    let mut yes = false;
    rec.visit(key, &[], &mut |v, _| {
        if let Val::Str(s) = v {
            yes |= s == want;
        }
    });
    yes
}

/// Update the entry of `k` in `map` with `f`, creating it when missing: one lookup for a
/// known key, and no key allocation.
fn bump<T: Default>(map: &mut BTreeMap<String, T>, k: &str, f: impl FnOnce(&mut T)) {
    if let Some(v) = map.get_mut(k) {
        return f(v);
    }
    let mut v = T::default();
    f(&mut v);
    map.insert(k.to_string(), v);
}

/// The value at fraction `q` of sorted data (nearest rank).
fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1;
    sorted[i]
}

impl Stats {
    /// Empty statistics with time bins of `bin_ns`.
    pub fn new(bin_ns: u64) -> Self {
        Stats {
            frames: Tally::default(),
            garbage: Tally::default(),
            messages: BTreeMap::new(),
            addresses: BTreeMap::new(),
            directions: BTreeMap::new(),
            diags: BTreeMap::new(),
            file_problems: BTreeMap::new(),
            file_examples: vec![],
            bins: BTreeMap::new(),
            bin_ns: bin_ns.max(1),
            streams: BTreeMap::new(),
            stream_addresses: BTreeMap::new(),
            first_ts: None,
            requests: BTreeMap::new(),
            scratch: String::new(),
            dir_scratch: String::new(),
            p_kind: vec!["kind".to_string()],
        }
    }

    /// Count a problem of the capture file itself at file `offset`.
    pub fn add_file_problem(&mut self, offset: u64, kind: &str, msg: &str) {
        bump(&mut self.file_problems, kind, |c| *c += 1);
        if self.file_examples.len() < FILE_EXAMPLES {
            self.file_examples
                .push((offset, kind.to_string(), msg.to_string()));
        }
    }

    /// Count one record: a typed [`crate::record::Record`], or its NDJSON object (both read
    /// through [`Fields`]). Frames and garbage are counted, diagnostics by kind; a `stream`
    /// record names its stream.
    pub fn add<F: Fields + ?Sized>(&mut self, rec: &F) {
        let diags = &mut self.diags;
        rec.visit(Key::Diag, &self.p_kind, &mut |v, _| {
            let k = match &v {
                Val::Str(s) => s.as_ref(),
                _ => "?",
            };
            bump(diags, k, |c| *c += 1);
        });
        let len = number(rec, Key::Len).and_then(Num::u64).unwrap_or(0);
        let stream = number(rec, Key::Stream).and_then(Num::u64);
        if text_is(rec, Key::Type, "garbage") {
            self.garbage.count += 1;
            self.garbage.bytes += len;
            return;
        }
        if text_is(rec, Key::Type, "stream") {
            self.scratch.clear();
            if let (Some(id), true) = (
                stream,
                push_str(rec, Key::StreamName, &[], &mut self.scratch),
            ) {
                self.streams.entry(id).or_default().name = Some(self.scratch.clone());
            }
            return;
        }
        if !text_is(rec, Key::Type, "frame") {
            return;
        }
        self.frames.count += 1;
        self.frames.bytes += len;
        self.scratch.clear();
        message_key(rec, &mut self.scratch);
        bump(&mut self.messages, &self.scratch, |m| {
            m.tally.count += 1;
            m.tally.bytes += len;
        });
        let pair = number(rec, Key::Pair).and_then(Num::u64);
        // The direction, read once: it decides what can be a request and keys `directions`.
        let mut dir = std::mem::take(&mut self.dir_scratch);
        dir.clear();
        let has_dir = push_str(rec, Key::Dir, &[], &mut dir);
        let from_device = if has_dir {
            dir == "d2h"
        } else {
            text_is(rec, Key::MsgDir, "d2h")
        };
        let s = stream.unwrap_or(0);
        // Only what can be a request is remembered (a reply names its request in `pair`).
        if let (Some(n), None, false) = (number(rec, Key::N).and_then(Num::u64), pair, from_device)
        {
            self.requests.insert((s, n), self.scratch.clone());
            if self.requests.len() > MAX_REQUESTS {
                self.requests.pop_first();
            }
        }
        if let (Some(p), Some(l)) = (pair, number(rec, Key::LatencyMs)) {
            if let Some(req) = self.requests.get(&(s, p)) {
                if let Some(m) = self.messages.get_mut(req) {
                    m.latencies.push(l.f());
                }
            }
        }
        self.scratch.clear();
        address_key(rec, &mut self.scratch);
        bump(&mut self.addresses, &self.scratch, |a| {
            a.count += 1;
            a.bytes += len;
        });
        if let Some(id) = stream {
            let st = &mut self.streams.entry(id).or_default().tally;
            st.count += 1;
            st.bytes += len;
            let key = (id, std::mem::take(&mut self.scratch));
            let a = self.stream_addresses.entry(key).or_default();
            a.count += 1;
            a.bytes += len;
        }
        if !has_dir {
            dir.push_str("unknown");
        }
        bump(&mut self.directions, &dir, |d| {
            d.count += 1;
            d.bytes += len;
        });
        self.dir_scratch = dir;
        if let Some(ts) = number(rec, Key::TsNs).and_then(Num::u64) {
            let first = *self.first_ts.get_or_insert(ts);
            let bin = ts.saturating_sub(first) / self.bin_ns * self.bin_ns;
            *self.bins.entry(bin).or_default() += 1;
        }
    }

    /// Whether the statistics break down per stream: more than one stream carried frames.
    pub fn per_stream(&self) -> bool {
        self.streams.values().filter(|s| s.tally.count > 0).count() > 1
    }

    /// The rate histogram as shown: every bin from the first frame's to the last one's, the
    /// empty ones included, as (bin start in ns since the first frame, frames). Bins are
    /// widened by a round factor (2, 5, 10, 20 …) when there would be more than
    /// [`MAX_RATE_BINS`]. Returns the width used too.
    pub fn rate(&self) -> (u64, Vec<(u64, u64)>) {
        let Some((&last, _)) = self.bins.last_key_value() else {
            return (self.bin_ns, vec![]);
        };
        let n = last / self.bin_ns + 1;
        // The smallest round factor (1, 2 or 5 × 10^e) that brings the bins under the cap.
        let need = n.div_ceil(MAX_RATE_BINS);
        let k = (0..19)
            .flat_map(|e| [1, 2, 5].map(|m| m * 10u64.pow(e)))
            .find(|k| *k >= need)
            .unwrap_or(need);
        let width = self.bin_ns.saturating_mul(k);
        let rows = n.div_ceil(k);
        let mut v: Vec<(u64, u64)> = (0..rows).map(|i| (i.saturating_mul(width), 0)).collect();
        for (b, c) in &self.bins {
            if let Some(r) = v.get_mut((b / width) as usize) {
                r.1 += c;
            }
        }
        (width, v)
    }

    /// Latency summary of a message: (n, min, median, p99, max) in ms.
    pub fn latency(&self, key: &str) -> Option<(usize, f64, f64, f64, f64)> {
        let l = &self.messages.get(key)?.latencies;
        if l.is_empty() {
            return None;
        }
        let mut v = l.sample.clone();
        v.sort_by(f64::total_cmp);
        Some((
            l.n as usize,
            l.min,
            quantile(&v, 0.5),
            quantile(&v, 0.99),
            l.max,
        ))
    }

    /// Text tables, like Wireshark's Statistics menu.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "Frames: {} ({} bytes); garbage: {} records ({} bytes)",
            self.frames.count, self.frames.bytes, self.garbage.count, self.garbage.bytes
        );
        if !self.file_problems.is_empty() {
            let _ = writeln!(s, "\nFile problems{:>39}", "count");
            for (k, n) in &self.file_problems {
                let _ = writeln!(s, "  {k:<48}{n:>6}");
            }
            for (offset, _, msg) in &self.file_examples {
                let _ = writeln!(s, "  at byte {offset}: {msg}");
            }
        }
        let _ = writeln!(
            s,
            "\nMessages{:>44}{:>10}   latency ms (n, min / median / p99 / max)",
            "count", "bytes"
        );
        for (k, m) in &self.messages {
            let _ = write!(s, "  {k:<48}{:>6}{:>10}", m.tally.count, m.tally.bytes);
            if let Some((n, a, b, c, d)) = self.latency(k) {
                let _ = write!(s, "   {n}, {a:.3} / {b:.3} / {c:.3} / {d:.3}");
            }
            s.push('\n');
        }
        if self.per_stream() {
            let _ = writeln!(s, "\nStreams{:>45}{:>10}", "count", "bytes");
            for (id, st) in &self.streams {
                let k = format!("s{id} {}", st.name.as_deref().unwrap_or(""));
                let _ = writeln!(s, "  {k:<48}{:>6}{:>10}", st.tally.count, st.tally.bytes);
            }
            let _ = writeln!(s, "\nAddresses per stream{:>32}{:>10}", "count", "bytes");
            for ((id, k), t) in &self.stream_addresses {
                let k = format!("s{id} {k}");
                let _ = writeln!(s, "  {k:<48}{:>6}{:>10}", t.count, t.bytes);
            }
        } else {
            let _ = writeln!(s, "\nAddresses{:>43}{:>10}", "count", "bytes");
            for (k, t) in &self.addresses {
                let _ = writeln!(s, "  {k:<48}{:>6}{:>10}", t.count, t.bytes);
            }
        }
        let _ = writeln!(s, "\nDirections{:>42}{:>10}", "count", "bytes");
        for (k, t) in &self.directions {
            let _ = writeln!(s, "  {k:<48}{:>6}{:>10}", t.count, t.bytes);
        }
        let _ = writeln!(s, "\nDiagnostics{:>41}", "count");
        if self.diags.is_empty() {
            let _ = writeln!(s, "  none");
        }
        for (k, n) in &self.diags {
            let _ = writeln!(s, "  {k:<48}{n:>6}");
        }
        let (width, rate) = self.rate();
        if !rate.is_empty() {
            let _ = write!(s, "\nRate (frames per {} s", width as f64 / 1e9);
            if width != self.bin_ns {
                let _ = write!(
                    s,
                    "; bins of {} s widened to show at most {MAX_RATE_BINS}",
                    self.bin_ns as f64 / 1e9
                );
            }
            s.push_str(")\n");
            let max = rate.iter().map(|r| r.1).max().unwrap_or(1).max(1);
            // Enough decimals to tell bins apart (3 at least).
            let dec = (3..9u32)
                .find(|d| width.is_multiple_of(10u64.pow(9 - d)))
                .unwrap_or(9) as usize;
            for (b, n) in &rate {
                let bar = "#".repeat(((*n * 40).div_ceil(max)) as usize);
                let row = format!("  {:>10.dec$} s {n:>6} {bar}", *b as f64 / 1e9);
                let _ = writeln!(s, "{}", row.trim_end());
            }
        }
        s
    }

    /// The same as one JSON object.
    pub fn to_json(&self) -> String {
        let mut s = String::new();
        let tally = |s: &mut String, t: &Tally| {
            let _ = write!(s, "{{\"count\":{},\"bytes\":{}}}", t.count, t.bytes);
        };
        s.push_str("{\"frames\":");
        tally(&mut s, &self.frames);
        s.push_str(",\"garbage\":");
        tally(&mut s, &self.garbage);
        s.push_str(",\"messages\":{");
        for (i, (k, m)) in self.messages.iter().enumerate() {
            if i > 0 {
                s.push(',');
            }
            crate::json::string(&mut s, k);
            let _ = write!(
                s,
                ":{{\"count\":{},\"bytes\":{}",
                m.tally.count, m.tally.bytes
            );
            if let Some((n, a, b, c, d)) = self.latency(k) {
                let _ = write!(s, ",\"latency_ms\":{{\"n\":{n},\"min\":{a},\"median\":{b},\"p99\":{c},\"max\":{d}}}");
            }
            s.push('}');
        }
        for (name, map) in [
            ("addresses", &self.addresses),
            ("directions", &self.directions),
        ] {
            let _ = write!(s, "}},\"{name}\":{{");
            for (i, (k, t)) in map.iter().enumerate() {
                if i > 0 {
                    s.push(',');
                }
                crate::json::string(&mut s, k);
                s.push(':');
                tally(&mut s, t);
            }
        }
        s.push_str("},\"streams\":{");
        for (i, (id, st)) in self.streams.iter().enumerate() {
            let _ = write!(s, "{}\"{id}\":{{", if i > 0 { "," } else { "" });
            if let Some(n) = &st.name {
                s.push_str("\"name\":");
                crate::json::string(&mut s, n);
                s.push(',');
            }
            let _ = write!(
                s,
                "\"count\":{},\"bytes\":{},\"addresses\":{{",
                st.tally.count, st.tally.bytes
            );
            let of_stream = self.stream_addresses.range((*id, String::new())..);
            for (j, ((_, k), t)) in of_stream.take_while(|((x, _), _)| x == id).enumerate() {
                if j > 0 {
                    s.push(',');
                }
                crate::json::string(&mut s, k);
                s.push(':');
                tally(&mut s, t);
            }
            s.push_str("}}");
        }
        s.push_str("},\"diags\":{");
        for (i, (k, n)) in self.diags.iter().enumerate() {
            let _ = write!(s, "{}\"{k}\":{n}", if i > 0 { "," } else { "" });
        }
        s.push_str("},\"file_problems\":{");
        for (i, (k, n)) in self.file_problems.iter().enumerate() {
            let _ = write!(s, "{}\"{k}\":{n}", if i > 0 { "," } else { "" });
        }
        s.push_str("},\"file_examples\":[");
        for (i, (offset, kind, msg)) in self.file_examples.iter().enumerate() {
            let _ = write!(
                s,
                "{}{{\"offset\":{offset},\"kind\":\"{kind}\",\"msg\":",
                if i > 0 { "," } else { "" }
            );
            crate::json::string(&mut s, msg);
            s.push('}');
        }
        s.push(']');
        let (width, rate) = self.rate();
        let _ = write!(s, ",\"bin_s\":{}", width as f64 / 1e9);
        if width != self.bin_ns {
            let _ = write!(s, ",\"bin_s_asked\":{}", self.bin_ns as f64 / 1e9);
        }
        s.push_str(",\"rate\":[");
        for (i, (b, n)) in rate.iter().enumerate() {
            let _ = write!(
                s,
                "{}[{},{n}]",
                if i > 0 { "," } else { "" },
                *b as f64 / 1e9
            );
        }
        s.push_str("]}");
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::{json, Value};

    #[test]
    fn counts_latencies_and_bins() {
        let mut st = Stats::new(1_000_000_000);
        let recs = [
            json!({"n":1,"type":"frame","proto":"apt","name":"HW_REQ_INFO","len":6,"src":{"name":"host"},"dst":{"name":"usb"},"dir":"h2d","ts_ns":1_000,"diag":[]}),
            json!({"n":2,"type":"frame","proto":"apt","name":"HW_GET_INFO","len":90,"src":{"name":"usb"},"dst":{"name":"host"},"dir":"d2h","ts_ns":2_001_000,"pair":1,"latency_ms":2.0,"diag":[]}),
            json!({"n":3,"type":"frame","proto":"apt","name":"HW_REQ_INFO","len":6,"src":{"name":"host"},"dst":{"name":"usb"},"dir":"h2d","ts_ns":1_500_000_000,"diag":[]}),
            json!({"n":4,"type":"frame","proto":"apt","name":"HW_GET_INFO","len":90,"src":{"name":"usb"},"dst":{"name":"host"},"dir":"d2h","ts_ns":1_504_000_000,"pair":3,"latency_ms":4.0,"diag":[]}),
            json!({"n":5,"type":"garbage","proto":"apt","len":3,"diag":[{"kind":"garbage"}]}),
            json!({"proto":"apt","type":"diag","ref":3,"diag":[{"kind":"no_reply"}]}),
        ];
        for r in &recs {
            st.add(r);
        }
        assert_eq!(
            st.frames,
            Tally {
                count: 4,
                bytes: 192
            }
        );
        assert_eq!(st.garbage, Tally { count: 1, bytes: 3 });
        assert_eq!(st.messages["apt HW_REQ_INFO"].tally.count, 2);
        assert_eq!(st.latency("apt HW_REQ_INFO"), Some((2, 2.0, 2.0, 4.0, 4.0)));
        assert_eq!(
            st.addresses["apt usb → host"],
            Tally {
                count: 2,
                bytes: 180
            }
        );
        assert_eq!(st.directions["h2d"].count, 2);
        assert_eq!(st.diags["garbage"], 1);
        assert_eq!(st.diags["no_reply"], 1);
        assert_eq!(st.bins.get(&0), Some(&2));
        assert_eq!(st.bins.get(&1_000_000_000), Some(&2));
        let j: Value = serde_json::from_str(&st.to_json()).expect("valid JSON");
        assert_eq!(j["messages"]["apt HW_REQ_INFO"]["latency_ms"]["p99"], 4.0);
        assert!(st.to_text().contains("apt HW_REQ_INFO"));
    }

    fn frame_at(ts_ns: u64) -> Value {
        json!({"n":1,"type":"frame","proto":"apt","name":"HW_REQ_INFO","len":6,"dir":"h2d","ts_ns":ts_ns,"diag":[]})
    }

    /// Empty bins are shown (a pause is visible), and a long capture gets wider bins, at most
    /// MAX_RATE_BINS of them.
    #[test]
    fn rate_shows_empty_bins_and_caps_their_number() {
        let mut st = Stats::new(1_000_000_000);
        for t in [0, 100_000_000, 3_500_000_000] {
            st.add(&frame_at(t));
        }
        assert_eq!(
            st.rate(),
            (
                1_000_000_000,
                vec![
                    (0, 2),
                    (1_000_000_000, 0),
                    (2_000_000_000, 0),
                    (3_000_000_000, 1)
                ]
            )
        );
        let text = st.to_text();
        assert!(text.contains("Rate (frames per 1 s)\n"), "{text}");
        assert!(text.contains("       2.000 s      0\n"), "{text}");
        let j: Value = serde_json::from_str(&st.to_json()).expect("valid JSON");
        assert_eq!(j["rate"], json!([[0, 2], [1, 0], [2, 0], [3, 1]]));
        assert!(j.get("bin_s_asked").is_none());

        // 1000 s in 1 ms bins: a million bins asked; 10 s wide ones, 101 of them.
        let mut st = Stats::new(1_000_000);
        for t in [0, 1_000_000_000_000] {
            st.add(&frame_at(t));
        }
        let (width, rows) = st.rate();
        assert_eq!((width, rows.len()), (10_000_000_000, 101));
        assert_eq!(rows.iter().map(|r| r.1).sum::<u64>(), 2);
        assert!(st
            .to_text()
            .contains("Rate (frames per 10 s; bins of 0.001 s widened to show at most 200)"));
        let j: Value = serde_json::from_str(&st.to_json()).expect("valid JSON");
        assert_eq!(
            (j["bin_s"].as_f64(), j["bin_s_asked"].as_f64()),
            (Some(10.0), Some(0.001))
        );
    }
}

#[cfg(test)]
mod typed {
    use super::*;
    use crate::pipeline::{Format, Renderer};
    use crate::record::{Ctx, Decoder, Record};
    use crate::table::Dir;
    use crate::Table;

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

    /// Two controllers on two ports: counted per stream, named by their `stream` records, each
    /// reply's latency attributed to its request on its own stream; the typed records and their
    /// NDJSON give the same statistics.
    #[test]
    fn typed_records_count_per_stream_like_their_ndjson() {
        let req = frame("HW_REQ_INFO", &[], 0x50, 0x01);
        let info = frame("HW_GET_INFO", &[("model_number", "KDC101")], 0x01, 0x50);
        let mut dec = Decoder::new(Some(crate::detect::Proto::Apt));
        let (mut typed, mut json) = (Stats::new(1_000_000_000), Stats::new(1_000_000_000));
        let mut r = Renderer::new(Format::Json);
        let mut each = |rec: &Record<'_>| -> Result<(), String> {
            typed.add(rec);
            let v: serde_json::Value =
                serde_json::from_str(r.line(rec)).map_err(|e| e.to_string())?;
            json.add(&v);
            Ok(())
        };
        let mut run = || -> Result<(), String> {
            dec.stream_info(0, "/dev/ttyUSB0", None, &mut each)?;
            dec.stream_info(1, "/dev/ttyUSB1", None, &mut each)?;
            for (i, (stream, dir, b, ms)) in [
                (0, Dir::HostToDevice, &req, 0),
                (1, Dir::HostToDevice, &req, 1),
                (1, Dir::DeviceToHost, &info, 5),
                (0, Dir::DeviceToHost, &info, 9),
                (1, Dir::HostToDevice, &req, 20),
            ]
            .into_iter()
            .enumerate()
            {
                let ctx = Ctx {
                    stream,
                    dir: Some(dir),
                    ts_ns: Some(ms * 1_000_000 + i as u64),
                };
                dec.push(ctx, b, &mut each)?;
            }
            dec.finish(&mut each)
        };
        run().expect("decodes");
        assert_eq!(typed.to_json(), json.to_json());
        assert!(typed.per_stream());
        assert_eq!(typed.streams[&0].name.as_deref(), Some("/dev/ttyUSB0"));
        assert_eq!(
            (typed.streams[&0].tally.count, typed.streams[&1].tally.count),
            (2, 3)
        );
        let (n, min, _, _, max) = typed.latency("apt HW_REQ_INFO").expect("latencies");
        assert_eq!(n, 2);
        assert!(
            (min - 4.0).abs() < 0.01 && (max - 9.0).abs() < 0.01,
            "{min} {max}"
        );
        assert_eq!(typed.diags.get("no_reply"), Some(&1));
        let text = typed.to_text();
        assert!(text.contains("s1 /dev/ttyUSB1"), "{text}");
        assert!(text.contains("s0 apt usb → host"), "{text}");
        let j: serde_json::Value = serde_json::from_str(&typed.to_json()).expect("JSON");
        assert_eq!(j["streams"]["1"]["addresses"]["apt host → usb"]["count"], 2);
    }
}

#[cfg(test)]
mod bounded {
    use super::*;
    use serde_json::json;

    /// A long capture of requests (a one-direction capture, say) keeps flat memory, and a
    /// reply still finds a recent request for its latency.
    #[test]
    fn remembered_requests_are_bounded() {
        let mut s = Stats::new(1_000_000_000);
        let n = 3 * MAX_REQUESTS as u64;
        for i in 1..=n {
            s.add(&json!({"type": "frame", "n": i, "len": 6, "proto": "apt",
                "name": "HW_REQ_INFO", "msg_dir": "h2d"}));
        }
        assert_eq!(s.requests.len(), MAX_REQUESTS);
        s.add(
            &json!({"type": "frame", "n": n + 1, "len": 90, "proto": "apt",
            "name": "HW_GET_INFO", "msg_dir": "d2h", "pair": n, "latency_ms": 2.5}),
        );
        assert_eq!(s.requests.len(), MAX_REQUESTS, "a reply is not a request");
        assert_eq!(s.latency("apt HW_REQ_INFO").map(|l| l.0), Some(1));
    }

    #[test]
    fn latencies_beyond_the_sample_keep_exact_extremes_and_close_quantiles() {
        let mut l = Latencies::default();
        let n = 4 * LATENCY_SAMPLE as u64;
        // 0.0 … n-1 in a scrambled order.
        for i in 0..n {
            l.push(((i * 7919) % n) as f64);
        }
        assert_eq!(l.len(), n);
        assert_eq!((l.min, l.max), (0.0, (n - 1) as f64));
        assert_eq!(l.sample.len(), LATENCY_SAMPLE);
        let mut v = l.sample.clone();
        v.sort_by(f64::total_cmp);
        let med = quantile(&v, 0.5) / n as f64;
        assert!((0.48..0.52).contains(&med), "median at {med}");
    }
}
