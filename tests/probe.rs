//! `aptscope probe` end to end: against every simulated APT model (each on a pseudo-terminal,
//! as a controller on a port), against a simulator made to deviate from the spec (a missing
//! reply, a wrong length, another revision's layout), on a port that is not APT, and the
//! `--dry-run`, `-w` and `--compare` outputs.

mod common;

use aptscope_capture::live::sim::{serve_pty, stop_pair, AptModel, AptSim, Pty, Simulator};
use aptscope_dissector::msg;
use common::host::start_sim_with;
use common::{aptscope, Scratch};
use serde_json::Value;
use std::thread;

/// Known differences of the simulators that the probe finds (each a simulator defect to mend,
/// not the probe's): model → the requests left unanswered.
const KNOWN: &[(&str, &[&str])] = &[
    // The inertia motor controllers answer MOT_REQ_STATUSUPDATE for channels 3 and 4 (idents
    // 4 and 8) with the channel number (3, 4) in chan_ident instead of the ident.
    (
        "TIM101",
        &[
            "0x50 MOT_REQ_STATUSUPDATE ch3",
            "0x50 MOT_REQ_STATUSUPDATE ch4",
        ],
    ),
    (
        "KIM101",
        &[
            "0x50 MOT_REQ_STATUSUPDATE ch3",
            "0x50 MOT_REQ_STATUSUPDATE ch4",
        ],
    ),
];

/// Models whose simulator does not answer HW_REQ_INFO (its device list lacks it), which the
/// probe refuses as "not answering APT".
const SILENT: &[&str] = &["KLS1550"];

/// `sim apt --list`: (model, bays).
fn models() -> Vec<(String, usize)> {
    let (out, err, ok) = aptscope(&["sim", "apt", "--list"], None);
    assert!(ok, "{err}");
    out.lines()
        .skip(1)
        .filter_map(|l| {
            let w: Vec<&str> = l.split_whitespace().collect();
            // Rows are MODEL FAMILY BAYS CHANNELS SERIAL; the notes after them are not.
            let bays = w.get(2)?;
            if w.len() < 5 || !w[0].chars().all(|c| c.is_ascii_alphanumeric()) {
                return None;
            }
            Some((w[0].to_string(), bays.parse().unwrap_or(1).max(1)))
        })
        .collect()
}

/// Probe the simulator of `model` with `args` added: (stdout, stderr, success).
fn probe_sim(model: &str, dir: &Scratch, args: &[&str]) -> (String, String, bool) {
    let link = dir.join(&format!("{model}.pty"));
    let sim = start_sim_with(&["sim", "apt", "--model", model, "--once"], &link);
    let mut a = vec!["probe", "--port", link.to_str().expect("utf-8")];
    a.extend_from_slice(args);
    let r = aptscope(&a, None);
    drop(sim);
    r
}

fn parse(out: &str, ctx: &str) -> Value {
    serde_json::from_str(out).unwrap_or_else(|e| panic!("{ctx}: {e}\n{out}"))
}

fn keys_where(v: &Value, pred: impl Fn(&Value) -> bool) -> Vec<String> {
    v["outcomes"]
        .as_array()
        .expect("outcomes")
        .iter()
        .filter(|o| pred(o))
        .map(|o| o["key"].as_str().expect("key").to_string())
        .collect()
}

#[test]
fn every_simulated_model_answers_what_the_spec_lists() {
    let dir = Scratch::new("probe-all");
    let all = models();
    assert!(all.len() > 60, "{all:?}");
    let mut failures = vec![];
    for (model, bays) in &all {
        let (out, err, ok) = probe_sim(model, &dir, &["--json", "--timeout", "300ms"]);
        if SILENT.contains(&model.as_str()) {
            assert!(!ok && err.contains("does not answer APT"), "{model}: {err}");
            continue;
        }
        if !ok {
            failures.push(format!("{model}: failed: {err}"));
            continue;
        }
        let v = parse(&out, model);
        if v["model"] != model.as_str() || v["units"].as_array().map(Vec::len) != Some(*bays) {
            failures.push(format!(
                "{model}: identified as {} {}",
                v["model"], v["units"]
            ));
        }
        if v["sent"].as_u64().unwrap_or(0) == 0 || v["interrupted"] != false {
            failures.push(format!("{model}: incomplete: {v}"));
        }
        let known: &[&str] = KNOWN
            .iter()
            .find(|(m, _)| m == model)
            .map_or(&[], |(_, k)| k);
        let deviating = keys_where(&v, |o| o["deviates"] == true);
        if deviating != known {
            failures.push(format!(
                "{model}: deviations {deviating:?}, known {known:?}"
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A KDC101 that deviates: no MOT_GET_VELPARAMS, a MOT_GET_JOGPARAMS two bytes short, and
/// MOT_GET_KCUBEMMIPARAMS in the 2025 revision's 36-byte layout (the simulator's is Issue 23's).
struct Deviating(AptSim);

impl Deviating {
    /// `frame` as this device sends it (`None`: not at all).
    fn alter(frame: Vec<u8>) -> Option<Vec<u8>> {
        let id = u16::from_le_bytes([frame[0], frame[1]]);
        let set_len = |mut f: Vec<u8>, n: usize| {
            f.resize(6 + n, 0);
            f[2..4].copy_from_slice(&(n as u16).to_le_bytes());
            f
        };
        match id {
            msg::MOT_GET_VELPARAMS => None,
            msg::MOT_GET_JOGPARAMS => {
                let n = frame.len() - 6 - 2;
                Some(set_len(frame, n))
            }
            msg::MOT_GET_KCUBEMMIPARAMS => Some(set_len(frame, 36)),
            _ => Some(frame),
        }
    }
}

impl Simulator for Deviating {
    fn input(&mut self, bytes: &[u8], now_ns: u64) {
        self.0.input(bytes, now_ns);
    }

    fn poll(&mut self, now_ns: u64) -> Option<Vec<u8>> {
        let out = self.0.poll(now_ns)?;
        // Whole frames by their headers (the simulator's output is well formed).
        let mut rest = &out[..];
        let mut sent = vec![];
        while rest.len() >= 6 {
            let len = if rest[4] & 0x80 != 0 {
                usize::from(u16::from_le_bytes([rest[2], rest[3]]))
            } else {
                0
            };
            let (f, r) = rest.split_at((6 + len).min(rest.len()));
            sent.extend(Deviating::alter(f.to_vec()).unwrap_or_default());
            rest = r;
        }
        Some(sent)
    }

    fn next_deadline(&self) -> Option<u64> {
        self.0.next_deadline()
    }
}

/// Probe a [`Deviating`] KDC101 served in this process with `args`.
fn probe_deviating(args: &[&str]) -> (String, String, bool) {
    probe_served(
        |sim| Box::new(Deviating(sim)) as Box<dyn Simulator + Send>,
        args,
    )
}

/// Probe a KDC101 simulator wrapped by `wrap`, served in this process, with `args`.
fn probe_served(
    wrap: impl FnOnce(AptSim) -> Box<dyn Simulator + Send> + Send + 'static,
    args: &[&str],
) -> (String, String, bool) {
    let pty = Pty::open().expect("pty");
    let path = pty.path().to_str().expect("utf-8").to_string();
    let (stop, signal) = stop_pair().expect("stop");
    let server = thread::spawn(move || {
        let mut sim = wrap(AptSim::new(AptModel::parse("kdc101").expect("kdc101")));
        serve_pty(sim.as_mut(), pty, Some(&signal), &[])
    });
    let mut a = vec!["probe", "--port", path.as_str()];
    a.extend_from_slice(args);
    let r = aptscope(&a, None);
    stop.stop();
    server.join().expect("server").expect("serve");
    r
}

#[test]
fn a_deviating_controller_has_each_deviation_named() {
    let (out, err, ok) = probe_deviating(&["--timeout", "300ms"]);
    assert!(ok, "{err}");
    assert!(out.contains("2 deviation(s)"), "{out}");
    assert!(
        out.contains("MOT_REQ_VELPARAMS ch1") && out.contains("no reply within 300 ms"),
        "{out}"
    );
    assert!(
        out.contains("MOT_GET_JOGPARAMS (20 bytes): wrong length: 20 data bytes fit no form"),
        "{out}"
    );
    assert!(
        out.contains("MOT_GET_KCUBEMMIPARAMS (36 bytes): 2025 revision layout"),
        "{out}"
    );
    // --check makes deviations the exit status.
    let (_, err, ok) = probe_deviating(&["--timeout", "300ms", "--check"]);
    assert!(!ok && err.contains("differences found"), "{err}");
}

#[test]
fn compare_puts_two_reports_side_by_side() {
    let dir = Scratch::new("probe-compare");
    let (lab, err, ok) = probe_sim("kdc101", &dir, &["--json"]);
    assert!(ok, "{err}");
    let (theirs, err, ok) = probe_deviating(&["--json", "--timeout", "300ms"]);
    assert!(ok, "{err}");
    // The simulator answers MMI parameters in the older (Issue 23) layout.
    let v = parse(&lab, "lab");
    let mmi = &v["outcomes"]
        .as_array()
        .expect("outcomes")
        .iter()
        .find(|o| o["request"] == "MOT_REQ_KCUBEMMIPARAMS")
        .expect("MMI")["reply"];
    assert_eq!(mmi["revs"], serde_json::json!(["23"]), "{mmi}");
    let (a, b) = (dir.join("lab.json"), dir.join("theirs.json"));
    std::fs::write(&a, lab).expect("write");
    std::fs::write(&b, theirs).expect("write");
    let (out, err, ok) = aptscope(
        &[
            "probe",
            "--compare",
            a.to_str().expect("utf-8"),
            b.to_str().expect("utf-8"),
        ],
        None,
    );
    assert!(ok, "{err}");
    assert!(
        out.contains("17 request(s) answered alike, 3 differ"),
        "{out}"
    );
    for l in [
        "MOT_REQ_VELPARAMS ch1",
        "A MOT_GET_VELPARAMS len 14 form 14",
        "A MOT_GET_JOGPARAMS len 22 form 22",
        "B MOT_GET_JOGPARAMS len 20 form none",
        "A MOT_GET_KCUBEMMIPARAMS len 28 form 28",
        "B MOT_GET_KCUBEMMIPARAMS len 36 form 36",
    ] {
        assert!(out.contains(l), "{l}: {out}");
    }
}

#[test]
fn dry_run_prints_the_plan_and_sends_only_the_identification() {
    let dir = Scratch::new("probe-dry");
    let cap = dir.join("dry.pcapng");
    let (out, err, ok) = probe_sim(
        "bsc203",
        &dir,
        &["--dry-run", "-w", cap.to_str().expect("utf-8")],
    );
    assert!(ok, "{err}");
    assert!(out.contains("model     BSC203"), "{out}");
    assert!(out.contains("unit      0x23 BSC203"), "{out}");
    assert!(out.contains("read-only request(s), one at a time"), "{out}");
    assert!(out.contains("0x21 MOT_REQ_VELPARAMS ch1"), "{out}");
    for bad in ["_SET_", "_MOVE_", "IDENTIFY"] {
        assert!(!out.contains(bad), "{bad} in the plan: {out}");
    }
    // What went out: HW_REQ_INFO, RACK_REQ_BAYUSED per bay, HW_REQ_INFO per bay.
    let (dec, err, ok) = aptscope(&["decode", cap.to_str().expect("utf-8")], None);
    assert!(ok, "{err}");
    let sent: Vec<&str> = dec.lines().filter(|l| l.contains("host →")).collect();
    assert_eq!(sent.len(), 7, "{dec}");
    assert!(
        sent.iter()
            .all(|l| l.contains("HW_REQ_INFO") || l.contains("RACK_REQ_BAYUSED")),
        "{dec}"
    );
}

#[test]
fn a_port_that_does_not_answer_apt_is_refused() {
    let dir = Scratch::new("probe-refuse");
    let link = dir.join("ell.pty");
    let sim = start_sim_with(&["sim", "elliptec", "--once"], &link);
    let (out, err, ok) = aptscope(&["probe", "--port", link.to_str().expect("utf-8")], None);
    drop(sim);
    assert!(!ok, "{out}");
    assert!(err.contains("does not answer APT"), "{err}");
    assert!(err.contains("ell.pty"), "the port is named: {err}");
}

#[test]
fn an_elliptec_bus_is_scanned_and_each_module_asked_its_queries() {
    let dir = Scratch::new("probe-ell");
    let link = dir.join("bus.pty");
    let sim = start_sim_with(
        &["sim", "elliptec", "--modules", "0:ELL14,3:ELL9", "--once"],
        &link,
    );
    let (out, err, ok) = aptscope(
        &[
            "probe",
            "--proto",
            "elliptec",
            "--port",
            link.to_str().expect("utf-8"),
            "--json",
        ],
        None,
    );
    drop(sim);
    assert!(ok, "{err}");
    let v = parse(&out, "elliptec");
    let units: Vec<&str> = v["units"]
        .as_array()
        .expect("units")
        .iter()
        .map(|u| u["model"].as_str().expect("model"))
        .collect();
    assert_eq!(units, ["ELL14", "ELL9"], "{v}");
    assert_eq!(v["deviations"], 0, "{v}");
    // 16 scanned addresses, then the queries of each module's model (an ELL9 has one motor
    // and no velocity: fewer).
    let asked = keys_where(&v, |o| o["reply"].is_object());
    assert!(
        asked.contains(&"0x00 GET_POSITION".to_string()),
        "{asked:?}"
    );
    assert!(
        asked.contains(&"0x00 REQ_MOTOR2_INFO".to_string()),
        "{asked:?}"
    );
    assert!(
        asked.contains(&"0x03 REQ_MOTOR1_INFO".to_string()),
        "{asked:?}"
    );
    assert!(
        !asked.contains(&"0x03 REQ_MOTOR2_INFO".to_string()),
        "{asked:?}"
    );
    let sent = keys_where(&v, |_| true);
    assert!(
        sent.iter()
            .all(|k| k.contains("REQ_") || k.contains("GET_")),
        "only queries: {sent:?}"
    );
}

/// A KDC101 that answers its identification, then nothing; counting the bytes it was sent.
struct Mute(AptSim, std::sync::Arc<std::sync::atomic::AtomicUsize>);

impl Simulator for Mute {
    fn input(&mut self, bytes: &[u8], now_ns: u64) {
        use std::sync::atomic::Ordering;
        self.1.fetch_add(bytes.len(), Ordering::SeqCst);
        self.0.input(bytes, now_ns);
    }

    fn poll(&mut self, now_ns: u64) -> Option<Vec<u8>> {
        use std::sync::atomic::Ordering;
        let out = self.0.poll(now_ns)?;
        // HW_REQ_INFO is 6 bytes: what answers anything after it is kept back.
        Some(if self.1.load(Ordering::SeqCst) > 6 {
            vec![]
        } else {
            out
        })
    }

    fn next_deadline(&self) -> Option<u64> {
        self.0.next_deadline()
    }
}

#[test]
fn ctrl_c_stops_the_probe_at_once() {
    use common::proc::{wait_for, Proc};
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Arc;
    let pty = Pty::open().expect("pty");
    let path = pty.path().to_str().expect("utf-8").to_string();
    let (stop, signal) = stop_pair().expect("stop");
    let seen = Arc::new(AtomicUsize::new(0));
    let counter = seen.clone();
    let server = thread::spawn(move || {
        let mut sim = Mute(
            AptSim::new(AptModel::parse("kdc101").expect("kdc101")),
            counter,
        );
        serve_pty(&mut sim, pty, Some(&signal), &[])
    });
    let mut p = Proc::aptscope(&["probe", "--port", path.as_str()]);
    // HW_REQ_INFO, then the plan's first request, which waits 2 s for its reply.
    wait_for(
        "the first request of the plan",
        || p.both(),
        || seen.load(Ordering::SeqCst) >= 12,
    );
    p.interrupt();
    stop.stop();
    server.join().expect("server").expect("serve");
    let out = p.stdout();
    assert!(
        out.contains("requests  0 sent, 0 answered, 0 deviation(s) (interrupted)"),
        "{out}"
    );
    assert!(p.stderr().contains("interrupted"), "{}", p.both());
    // Nothing was sent after the signal (no second request of the plan).
    assert_eq!(seen.load(Ordering::SeqCst), 12, "{}", p.both());
}

/// A KDC101 that also answers PZ_REQ_OUTPUTVOLTS, which the spec does not list for it.
struct Generous(AptSim, Vec<Vec<u8>>);

impl Simulator for Generous {
    fn input(&mut self, bytes: &[u8], now_ns: u64) {
        // The probe sends one request at a time: a chunk starts with its header.
        if bytes.len() >= 6 && u16::from_le_bytes([bytes[0], bytes[1]]) == msg::PZ_REQ_OUTPUTVOLTS {
            let named = aptscope_dissector::apt::Named {
                name: "PZ_GET_OUTPUTVOLTS",
                sub: None,
                values: &[("chan_ident", "1")],
                form: None,
                dst: 0x01,
                src: 0x50,
            };
            let t = aptscope_dissector::Table::global();
            self.1
                .push(aptscope_dissector::apt::encode_named(t, &named).expect("encode"));
        }
        self.0.input(bytes, now_ns);
    }

    fn poll(&mut self, now_ns: u64) -> Option<Vec<u8>> {
        self.1.pop().or_else(|| self.0.poll(now_ns))
    }

    fn next_deadline(&self) -> Option<u64> {
        if self.1.is_empty() {
            self.0.next_deadline()
        } else {
            Some(0)
        }
    }
}

#[test]
fn unlisted_finds_what_a_device_does_beyond_its_list() {
    let (out, err, ok) = probe_served(
        |sim| Box::new(Generous(sim, vec![])) as Box<dyn Simulator + Send>,
        &["--unlisted", "--timeout", "30ms"],
    );
    assert!(ok, "{err}");
    assert!(out.contains("answered beyond the model's list"), "{out}");
    assert!(
        out.contains("PZ_REQ_OUTPUTVOLTS ch1") && out.contains("PZ_GET_OUTPUTVOLTS (4 bytes)"),
        "{out}"
    );
    assert!(
        out.contains("PZ_GET_OUTPUTVOLTS is not in the KDC101 list"),
        "{out}"
    );
    // What it does not answer beyond its list is no deviation.
    assert!(out.contains("1 deviation(s)"), "{out}");
}
