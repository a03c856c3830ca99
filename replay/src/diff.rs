//! Comparing captured replies with observed ones: field by field for replies to the same
//! request, missing and extra replies, latency, and unsolicited messages by name.

use crate::decoded::{Decoded, FieldVal};
use crate::script::{Msg, Script, Side};
use serde_json::{json, Map, Value};
use std::collections::BTreeMap;
use std::fmt::Write;

/// One request sent during the replay, and what is known of it.
#[derive(Debug, Clone)]
pub struct Exchange {
    /// Index of the captured request in [`Script::msgs`].
    pub idx: usize,
    /// Pass of `--loop`.
    pub lap: u32,
    /// Index of the request as observed (in the observer's messages).
    pub observed: Option<usize>,
}

/// What kind of difference.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A reply came with a different value in a field.
    Field,
    /// A captured reply did not come.
    Missing,
    /// A reply came that the capture does not have.
    Extra,
    /// A kind of unsolicited message (status updates, errors) came in one and not the other.
    Unsolicited,
}

impl Kind {
    fn as_str(self) -> &'static str {
        match self {
            Kind::Field => "field",
            Kind::Missing => "missing",
            Kind::Extra => "extra",
            Kind::Unsolicited => "unsolicited",
        }
    }
}

/// One difference between the capture and what was observed.
#[derive(Debug, Clone)]
pub struct Difference {
    /// Kind.
    pub kind: Kind,
    /// The request (captured record number and label) the reply answers.
    pub request: Option<(u64, String)>,
    /// Pass of `--loop`.
    pub lap: u32,
    /// The reply's label (`MOT_GET_DCSTATUSUPDATE ch1`).
    pub reply: String,
    /// The field that differs (`position`, `status_bits`, `src`).
    pub field: Option<String>,
    /// Captured value (or count, for unsolicited messages).
    pub captured: Value,
    /// Observed value.
    pub observed: Value,
}

/// A reply's time after its request, captured and observed.
#[derive(Debug, Clone)]
pub struct Latency {
    /// The request's label.
    pub request: String,
    /// The reply's label.
    pub reply: String,
    /// Captured latency, ns.
    pub captured_ns: u64,
    /// Observed latency, ns.
    pub observed_ns: u64,
}

/// The comparison of a replay.
#[derive(Debug, Clone, Default)]
pub struct Report {
    /// Replies that came with the captured values.
    pub matched: usize,
    /// Replies that came with different values.
    pub differing: usize,
    /// Captured replies that did not come.
    pub missing: usize,
    /// Replies that are not in the capture.
    pub extra: usize,
    /// Every difference, in the order of the requests.
    pub diffs: Vec<Difference>,
    /// Latency of every matched reply with times on both sides.
    pub latency: Vec<Latency>,
    /// Unsolicited messages by name: captured and observed counts.
    pub unsolicited: BTreeMap<String, (usize, usize)>,
}

/// Where two messages' meanings differ: their fields by name (a name on one side only reads as
/// null on the other), then the sender's address, the Elliptec address and the sub-message,
/// each as a whole. Names in `ignore` are skipped. The differing values come out as the JSON
/// of `decode --json`, for the report.
fn field_diffs(a: &Decoded, b: &Decoded, ignore: &[String], out: &mut Vec<(String, Value, Value)>) {
    let ignored = |k: &str| ignore.iter().any(|i| i == k);
    // By name, in name order; a repeated name keeps its last value (as in a JSON object).
    fn by_name(d: &Decoded) -> BTreeMap<&str, &FieldVal> {
        d.fields.iter().map(|(k, v)| (k.as_ref(), v)).collect()
    }
    // The whole of `fields` is ignored by an empty name (the path of the `fields` object).
    if !ignored("") {
        let (x, y) = (by_name(a), by_name(b));
        let only_b = y.iter().filter(|(k, _)| !x.contains_key(*k));
        for (k, va, vb) in x
            .iter()
            .map(|(k, va)| (*k, *va, y.get(k).copied().unwrap_or(&FieldVal::Null)))
            .chain(only_b.map(|(k, vb)| (*k, &FieldVal::Null, *vb)))
        {
            if va != vb && !ignored(k) {
                out.push((k.to_string(), va.to_json(), vb.to_json()));
            }
        }
    }
    for (k, x, y) in [
        ("src", &a.src, &b.src),
        ("addr", &a.addr, &b.addr),
        ("sub", &a.sub, &b.sub),
    ] {
        if x != y && !ignored(k) {
            let json = |v: &Option<FieldVal>| v.as_ref().map_or(Value::Null, FieldVal::to_json);
            out.push((k.to_string(), json(x), json(y)));
        }
    }
}

fn same_kind(a: &Msg, b: &Msg) -> bool {
    a.name == b.name && a.channel() == b.channel()
}

/// Compare the captured replies of every exchange with the observed ones, and the unsolicited
/// messages of the replayed range (`in_range` of each captured message, `laps` passes) with the
/// observed unsolicited ones. Fields named in `ignore` (`serial_number`, `status_bits`, or
/// `src`, `addr`, `sub` as a whole) are not compared.
pub fn compare(
    script: &Script,
    exchanges: &[Exchange],
    observed: &[Msg],
    in_range: &dyn Fn(&Msg) -> bool,
    laps: u32,
    ignore: &[String],
) -> Report {
    let mut r = Report::default();
    // Observed replies by the observed request they answer.
    let mut by_req: BTreeMap<u64, Vec<usize>> = BTreeMap::new();
    let mut unsolicited_obs: Vec<usize> = vec![];
    let mut paired_to_sent: Vec<bool> = vec![false; observed.len()];
    let sent_n: BTreeMap<u64, ()> = exchanges
        .iter()
        .filter_map(|e| e.observed.map(|o| (observed[o].n, ())))
        .collect();
    for (i, m) in observed.iter().enumerate() {
        if m.side != Side::Device {
            continue;
        }
        match m.pair {
            Some(p) if sent_n.contains_key(&p) => {
                by_req.entry(p).or_default().push(i);
                paired_to_sent[i] = true;
            }
            _ => unsolicited_obs.push(i),
        }
    }
    for ex in exchanges {
        let req = &script.msgs[ex.idx];
        let req_label = req.label();
        let obs_req = ex.observed.map(|o| &observed[o]);
        let mut obs: Vec<usize> = obs_req
            .and_then(|o| by_req.get(&o.n).cloned())
            .unwrap_or_default();
        for &c in script.replies_to(ex.idx) {
            let cm = &script.msgs[c];
            let found = obs.iter().position(|&o| same_kind(cm, &observed[o]));
            let Some(pos) = found else {
                r.missing += 1;
                r.diffs.push(Difference {
                    kind: Kind::Missing,
                    request: Some((req.n, req_label.clone())),
                    lap: ex.lap,
                    reply: cm.label(),
                    field: None,
                    captured: cm.ts_ns.zip(req.ts_ns).map_or(
                        Value::Null,
                        |(a, b)| json!({ "latency_ms": a.saturating_sub(b) as f64 / 1e6 }),
                    ),
                    observed: Value::Null,
                });
                continue;
            };
            let o = obs.remove(pos);
            let om = &observed[o];
            let mut fd = vec![];
            field_diffs(&cm.decoded, &om.decoded, ignore, &mut fd);
            if fd.is_empty() {
                r.matched += 1;
            } else {
                r.differing += 1;
            }
            for (field, a, b) in fd {
                r.diffs.push(Difference {
                    kind: Kind::Field,
                    request: Some((req.n, req_label.clone())),
                    lap: ex.lap,
                    reply: cm.label(),
                    field: Some(field),
                    captured: a,
                    observed: b,
                });
            }
            if let (Some(ct), Some(rt), Some(ot), Some(qt)) =
                (cm.ts_ns, req.ts_ns, om.ts_ns, obs_req.and_then(|q| q.ts_ns))
            {
                r.latency.push(Latency {
                    request: req_label.clone(),
                    reply: cm.label(),
                    captured_ns: ct.saturating_sub(rt),
                    observed_ns: ot.saturating_sub(qt),
                });
            }
        }
        for o in obs {
            r.extra += 1;
            r.diffs.push(Difference {
                kind: Kind::Extra,
                request: Some((req.n, req_label.clone())),
                lap: ex.lap,
                reply: observed[o].label(),
                field: None,
                captured: Value::Null,
                observed: observed[o].decoded.fields_json(),
            });
        }
    }
    // Unsolicited messages: compared by name and count (their number depends on timing).
    for m in &script.msgs {
        if m.side == Side::Device && m.pair.is_none() && in_range(m) {
            r.unsolicited.entry(m.name.clone()).or_default().0 += laps.max(1) as usize;
        }
    }
    for &o in &unsolicited_obs {
        r.unsolicited.entry(observed[o].name.clone()).or_default().1 += 1;
    }
    for (name, (c, o)) in &r.unsolicited {
        if (*c == 0) != (*o == 0) {
            r.diffs.push(Difference {
                kind: Kind::Unsolicited,
                request: None,
                lap: 0,
                reply: name.clone(),
                field: None,
                captured: json!(c),
                observed: json!(o),
            });
        }
    }
    r
}

fn show(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        Value::Array(a) => a.iter().map(show).collect::<Vec<_>>().join("|"),
        Value::Null => "(none)".into(),
        _ => v.to_string(),
    }
}

fn ms(ns: u64) -> String {
    format!("{:.1} ms", ns as f64 / 1e6)
}

fn median(mut v: Vec<u64>) -> Option<u64> {
    v.sort_unstable();
    v.get(v.len() / 2).copied()
}

impl Report {
    /// Differences that `--check` fails on: fields, missing and extra replies, and kinds of
    /// unsolicited messages seen on one side only; with `latency_tol_ns`, latencies beyond it.
    pub fn failures(&self, latency_tol_ns: Option<u64>) -> usize {
        self.diffs.len() + latency_tol_ns.map_or(0, |t| self.slow(t).count())
    }

    /// Matched replies whose latency differs by more than `tol_ns`.
    pub fn slow(&self, tol_ns: u64) -> impl Iterator<Item = &Latency> {
        self.latency
            .iter()
            .filter(move |l| l.observed_ns.abs_diff(l.captured_ns) > tol_ns)
    }

    /// The report as text lines.
    pub fn text(&self, latency_tol_ns: Option<u64>) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "# replies: {} matched, {} differing, {} missing, {} extra",
            self.matched, self.differing, self.missing, self.extra
        );
        for d in &self.diffs {
            let req = d
                .request
                .as_ref()
                .map(|(n, l)| format!(" (reply to #{n} {l})"))
                .unwrap_or_default();
            let lap = if d.lap > 0 {
                format!(" [pass {}]", d.lap + 1)
            } else {
                String::new()
            };
            let line = match d.kind {
                Kind::Field => format!(
                    "DIFF     {} {}: captured {}, observed {}{req}{lap}",
                    d.reply,
                    d.field.as_deref().unwrap_or("?"),
                    show(&d.captured),
                    show(&d.observed)
                ),
                Kind::Missing => format!("MISSING  {}{req}{lap}", d.reply),
                Kind::Extra => format!("EXTRA    {}{req}{lap}", d.reply),
                Kind::Unsolicited => format!(
                    "UNSOLICITED {}: captured {}, observed {}",
                    d.reply,
                    show(&d.captured),
                    show(&d.observed)
                ),
            };
            let _ = writeln!(s, "{line}");
        }
        if let Some(t) = latency_tol_ns {
            for l in self.slow(t) {
                let _ = writeln!(
                    s,
                    "LATENCY  {} after {}: captured {}, observed {}",
                    l.reply,
                    l.request,
                    ms(l.captured_ns),
                    ms(l.observed_ns)
                );
            }
        }
        let c = median(self.latency.iter().map(|l| l.captured_ns).collect());
        let o = median(self.latency.iter().map(|l| l.observed_ns).collect());
        if let (Some(c), Some(o)) = (c, o) {
            let worst = self
                .latency
                .iter()
                .max_by_key(|l| l.observed_ns.abs_diff(l.captured_ns));
            let _ = write!(
                s,
                "# latency: median captured {}, observed {}",
                ms(c),
                ms(o)
            );
            if let Some(w) = worst {
                let _ = write!(
                    s,
                    "; largest change {} after {} ({} → {})",
                    w.reply,
                    w.request,
                    ms(w.captured_ns),
                    ms(w.observed_ns)
                );
            }
            s.push('\n');
        }
        if !self.unsolicited.is_empty() {
            let parts: Vec<String> = self
                .unsolicited
                .iter()
                .map(|(n, (c, o))| format!("{n} {c}/{o}"))
                .collect();
            let _ = writeln!(s, "# unsolicited (captured/observed): {}", parts.join(", "));
        }
        s
    }

    /// The report as a JSON object.
    pub fn json(&self, latency_tol_ns: Option<u64>) -> Value {
        let diffs: Vec<Value> = self
            .diffs
            .iter()
            .map(|d| {
                json!({
                    "kind": d.kind.as_str(),
                    "request": d.request.as_ref().map(|(n, l)| json!({"n": n, "label": l})),
                    "pass": d.lap + 1,
                    "reply": d.reply,
                    "field": d.field,
                    "captured": d.captured,
                    "observed": d.observed,
                })
            })
            .collect();
        let latency: Vec<Value> = self
            .latency
            .iter()
            .map(|l| {
                json!({
                    "request": l.request,
                    "reply": l.reply,
                    "captured_ms": l.captured_ns as f64 / 1e6,
                    "observed_ms": l.observed_ns as f64 / 1e6,
                })
            })
            .collect();
        let unsolicited: Map<String, Value> = self
            .unsolicited
            .iter()
            .map(|(n, (c, o))| (n.clone(), json!({"captured": c, "observed": o})))
            .collect();
        json!({
            "matched": self.matched,
            "differing": self.differing,
            "missing": self.missing,
            "extra": self.extra,
            "failures": self.failures(latency_tol_ns),
            "diffs": diffs,
            "latency": latency,
            "unsolicited": unsolicited,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use aptscope_dissector::detect::Proto;

    /// A message on channel 1 with these integer fields.
    fn rec(
        n: u64,
        name: &str,
        side: Side,
        ts: u64,
        pair: Option<u64>,
        fields: &[(&'static str, i128)],
    ) -> Msg {
        let mut m = Msg::fixture(n, name, side, ts, pair);
        m.decoded.fields = fields
            .iter()
            .map(|(k, v)| ((*k).into(), FieldVal::Int(*v)))
            .collect();
        m
    }

    fn run(captured: &[Msg], observed: &[Msg], ignore: &[String]) -> Report {
        let script = Script::new(Proto::Apt, captured.to_vec(), vec![], "t".into());
        let obs = observed;
        let ex: Vec<Exchange> = script
            .msgs
            .iter()
            .enumerate()
            .filter(|(_, m)| m.side == Side::Host)
            .map(|(i, m)| Exchange {
                idx: i,
                lap: 0,
                observed: obs
                    .iter()
                    .position(|x| x.name == m.name && x.side == Side::Host),
            })
            .collect();
        compare(&script, &ex, obs, &|_| true, 1, ignore)
    }

    #[test]
    fn identical_replies_give_an_empty_diff() {
        let c = vec![
            rec(1, "MOT_REQ_DCSTATUSUPDATE", Side::Host, 0, None, &[]),
            rec(
                2,
                "MOT_GET_DCSTATUSUPDATE",
                Side::Device,
                2_000_000,
                Some(1),
                &[("position", 20480)],
            ),
        ];
        let r = run(&c, &c, &[]);
        assert_eq!((r.matched, r.diffs.len()), (1, 0));
        assert_eq!(r.latency.len(), 1);
        assert_eq!(r.failures(None), 0);
    }

    #[test]
    fn a_changed_field_is_named_with_both_values() {
        let c = vec![
            rec(1, "MOT_REQ_DCSTATUSUPDATE", Side::Host, 0, None, &[]),
            rec(
                2,
                "MOT_GET_DCSTATUSUPDATE",
                Side::Device,
                2_000_000,
                Some(1),
                &[("position", 20480), ("velocity", 0)],
            ),
        ];
        let o = vec![
            rec(7, "MOT_REQ_DCSTATUSUPDATE", Side::Host, 0, None, &[]),
            rec(
                8,
                "MOT_GET_DCSTATUSUPDATE",
                Side::Device,
                3_000_000,
                Some(7),
                &[("position", 20512), ("velocity", 0)],
            ),
        ];
        let r = run(&c, &o, &[]);
        assert_eq!((r.matched, r.differing, r.diffs.len()), (0, 1, 1));
        let t = r.text(None);
        assert!(
            t.contains("DIFF     MOT_GET_DCSTATUSUPDATE ch1 position: captured 20480, observed 20512 (reply to #1 MOT_REQ_DCSTATUSUPDATE ch1)"),
            "{t}"
        );
        assert_eq!(r.json(None)["diffs"][0]["field"], "position");
        let r = run(&c, &o, &["position".to_string()]);
        assert_eq!(r.diffs.len(), 0, "ignored field");
    }

    #[test]
    fn missing_extra_and_unsolicited() {
        let c = vec![
            rec(1, "MOT_MOVE_HOME", Side::Host, 0, None, &[]),
            rec(2, "MOT_GET_DCSTATUSUPDATE", Side::Device, 100, None, &[]),
            rec(3, "MOT_MOVE_HOMED", Side::Device, 200, Some(1), &[]),
        ];
        let o = vec![
            rec(1, "MOT_MOVE_HOME", Side::Host, 0, None, &[]),
            rec(2, "HW_RESPONSE", Side::Device, 100, None, &[]),
            rec(3, "MOT_MOVE_STOPPED", Side::Device, 200, Some(1), &[]),
        ];
        let r = run(&c, &o, &[]);
        assert_eq!((r.missing, r.extra), (1, 1));
        let kinds: Vec<Kind> = r.diffs.iter().map(|d| d.kind).collect();
        assert_eq!(
            kinds,
            [
                Kind::Missing,
                Kind::Extra,
                Kind::Unsolicited,
                Kind::Unsolicited
            ]
        );
        assert_eq!(r.failures(None), 4);
    }
}
