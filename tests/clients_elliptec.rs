//! Client libraries as the acceptance test of the Elliptec simulator: the PyPI packages
//! `elliptec`, `thorlabs-elliptec` and pylablib run their documented calls — info, every
//! getter, homing, moves, jogs, status, close — against `aptscope sim elliptec` through
//! `aptscope tap --proto elliptec` on pseudo-terminals. Checked: what the client reports, the
//! tap's own byte check ("matches what was forwarded"), and that the capture decodes without a
//! diagnostic. pylablib's Elliptec class opens the port without cycling RTS (only its Kinesis
//! class does), so nothing is stubbed here.

mod common;

use common::clients::client_python;
use common::host::{start_sim_with, start_tap};
use common::proc::Proc;
use common::{aptscope, Scratch};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A simulated bus behind the tap, its capture in the scratch directory.
struct Rig {
    dir: Scratch,
    sim: Proc,
    tap: Proc,
}

impl Rig {
    /// `sim elliptec --modules MODULES` ⇄ `tap --proto elliptec` ⇄ `DIR/host`.
    fn start(name: &str, modules: &str) -> Rig {
        let dir = Scratch::new(name);
        let sim = start_sim_with(&["sim", "elliptec", "--modules", modules], &dir.join("dev"));
        let tap = start_tap(dir.path(), &["--proto", "elliptec"]);
        Rig { dir, sim, tap }
    }

    fn host(&self) -> PathBuf {
        self.dir.join("host")
    }

    /// Run `script` with the host's port as its argument: the JSON object it prints last.
    fn client(&self, py: &Path, script: &str) -> Value {
        let file = self.dir.join("client.py");
        std::fs::write(&file, script).expect("write the client script");
        let out = Command::new(py)
            .arg(&file)
            .arg(self.host())
            .output()
            .expect("run the client");
        let (stdout, stderr) = (
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr),
        );
        assert!(
            out.status.success(),
            "the client failed:\n{stderr}\n{stdout}\ntap: {}\nsim: {}",
            self.tap.stderr(),
            self.sim.both()
        );
        let last = stdout.lines().last().unwrap_or_default();
        serde_json::from_str(last).unwrap_or_else(|e| panic!("{e}: {stdout}\n{stderr}"))
    }

    /// Stop the tap and the simulator; check the tap's byte check and that the capture decodes
    /// without a diagnostic. Returns the decoded frames' text lines.
    fn finish(mut self) -> Vec<String> {
        self.tap.interrupt();
        let err = self.tap.stderr();
        assert!(err.contains("matches what was forwarded"), "{err}");
        self.sim.interrupt();
        let cap = self.dir.join("cap.pcapng");
        let cap = cap.to_str().expect("utf-8 path");
        let (out, err, ok) = aptscope(&["stats", "--json", "--proto", "elliptec", cap], None);
        assert!(ok, "{err}");
        let s: Value = serde_json::from_str(out.trim()).expect("stats JSON");
        // The one note allowed: pylablib's `i3` is a command the manual does not list.
        let diags = s["diags"].as_object().expect("diags");
        assert!(diags.keys().all(|k| k == "unknown_command"), "{out}");
        let (out, err, ok) = aptscope(&["decode", "--json", "--proto", "elliptec", cap], None);
        assert!(ok, "{err}");
        let mut lines = vec![];
        for l in out.lines() {
            let r: Value = serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}"));
            assert_ne!(r["type"], "diag", "{l}");
            if r["type"] == "frame" {
                let text = r["text"].as_str().unwrap_or_default().to_string();
                let unlisted = serde_json::json!([{"kind": "unknown_command"}]);
                let ok = r["diag"] == serde_json::json!([])
                    || (text.trim_end().ends_with("i3") && kinds(&r["diag"]) == unlisted);
                assert!(ok, "{l}");
                lines.push(text);
            }
        }
        lines
    }
}

/// A frame's diagnostics reduced to their kinds.
fn kinds(diag: &Value) -> Value {
    let ks = diag.as_array().map_or(vec![], |a| {
        a.iter()
            .map(|d| serde_json::json!({"kind": d["kind"]}))
            .collect()
    });
    Value::Array(ks)
}

fn near(v: &Value, want: f64, tol: f64) -> bool {
    v.as_f64().is_some_and(|x| (x - want).abs() <= tol)
}

/// The `elliptec` package (0.1.0): a rotator, a four-position slider, a linear stage, a
/// bi-positional shutter and an iris on one bus, each through its class.
const ELLIPTEC: &str = r#"
import json, sys, elliptec
c = elliptec.Controller(sys.argv[1], debug=False)
r = {}
ro = elliptec.Rotator(c, address="0", debug=False)
r["ro_info"] = [ro.info["Motor Type"], ro.info["Range"], ro.info["Pulse/Rev"], ro.info["Serial No."]]
ro.home()
r["ro_set"] = ro.set_angle(90)
r["ro_get"] = ro.get_angle()
r["ro_shift"] = ro.shift_angle(-30)
ro.set_jog_step(5)
r["ro_jog_step"] = ro.get_jog_step()
r["ro_jog"] = ro.jog("forward")
r["ro_home_offset"] = ro.get_home_offset()
r["ro_status"] = list(ro.get("status"))
r["ro_m1"] = ro.get("motor_1_info")["Forward frequency"]
r["ro_m2"] = ro.get("motor_2_info")["Backward period"]
ro.save_user_data()
sl = elliptec.Slider(c, address="1", debug=False)
sl.home()
r["sl_set"] = sl.set_slot(3)
r["sl_get"] = sl.get_slot()
r["sl_jog"] = sl.jog("backward")
li = elliptec.Linear(c, address="2", debug=False)
li.home()
r["li_set"] = li.set_distance(10.0)
r["li_shift"] = li.shift_distance(-2.5)
r["li_get"] = li.get_distance()
sh = elliptec.Shutter(c, address="3", debug=False)
r["sh_open"] = sh.open()
r["sh_is_open"] = sh.is_open()
r["sh_close"] = sh.close()
ir = elliptec.Iris(c, address="4", debug=False)
ir.home()
r["ir_set"] = ir.set_aperture(5.0)
r["ir_get"] = ir.get_aperture()
ir.change_address("7")
r["ir_moved"] = [ir.address, ir.get_aperture()]
r["scan"] = [d["info"]["Motor Type"] for d in elliptec.scan_for_devices(c, 0, 3, debug=False)]
r["status_after"] = list(ro.get("status"))
c.close_connection()
print(json.dumps(r))
"#;

#[test]
fn the_elliptec_package_drives_every_kind_of_module() {
    let Some(py) = client_python() else { return };
    let rig = Rig::start("ell-pkg", "0:ELL14,1:ELL9,2:ELL20,3:ELL6,4:ELL15");
    let r = rig.client(&py, ELLIPTEC);
    assert_eq!(r["ro_info"][0], 14, "{r}");
    assert_eq!(r["ro_info"][1], 360, "{r}");
    assert_eq!(r["ro_info"][2], 0x23000, "{r}");
    assert!(near(&r["ro_set"], 90.0, 0.01), "{r}");
    assert!(near(&r["ro_get"], 90.0, 0.01), "{r}");
    assert!(near(&r["ro_shift"], 60.0, 0.01), "{r}");
    assert!(near(&r["ro_jog_step"], 5.0, 0.01), "{r}");
    assert!(near(&r["ro_jog"], 65.0, 0.01), "{r}");
    assert!(near(&r["ro_home_offset"], 0.0, 0.0), "{r}");
    assert_eq!(r["ro_status"], serde_json::json!(["0", "GS", "0"]), "{r}");
    assert!(near(&r["ro_m1"], 14_740_000.0 / 189.0, 1.0), "{r}");
    assert_eq!(r["ro_m2"], 0x8B, "{r}");
    assert_eq!(
        (&r["sl_set"], &r["sl_get"], &r["sl_jog"]),
        (&3.into(), &3.into(), &2.into())
    );
    assert!(near(&r["li_set"], 10.0, 0.001), "{r}");
    assert!(near(&r["li_shift"], 7.5, 0.001), "{r}");
    assert!(near(&r["li_get"], 7.5, 0.001), "{r}");
    assert_eq!(r["sh_open"], 2, "{r}");
    assert_eq!(r["sh_is_open"], true, "{r}");
    assert_eq!(r["sh_close"], 1, "{r}");
    assert!(near(&r["ir_set"], 5.0, 0.001), "{r}");
    assert!(near(&r["ir_get"], 5.0, 0.001), "{r}");
    assert_eq!(r["ir_moved"][0], "7", "{r}");
    assert!(near(&r["ir_moved"][1], 5.0, 0.001), "{r}");
    assert_eq!(r["scan"], serde_json::json!([14, 9, 20, 6]), "{r}");
    assert_eq!(
        r["status_after"],
        serde_json::json!(["0", "GS", "0"]),
        "{r}"
    );
    let lines = rig.finish();
    assert!(lines.iter().any(|l| l.starts_with("1ma")), "{lines:?}");
    assert!(lines.iter().any(|l| l.starts_with("3fw")), "{lines:?}");
}

/// thorlabs-elliptec (1.3.0): an ELL14, an ELL9 and an ELL20 sharing the port (multi-drop),
/// polled in the background every 0.1 s while blocking homes and moves run.
const THORLABS_ELLIPTEC: &str = r#"
import json, sys, time
from thorlabs_elliptec import ELLx, ELLStatus
ro = ELLx(serial_port=sys.argv[1], x=14, device_id=0)
li = ELLx(serial_port=ro, x=20, device_id=2)
sl = ELLx(serial_port=ro, x=9, device_id=1)
r = {}
r["info"] = [ro.model_number, ro.serial_number, ro.travel, ro.units, ro.firmware_version,
             ro.thread_type, li.model_number, li.travel, li.units]
ro.home(blocking=True)
li.home(blocking=True)
ro.move_absolute(45, blocking=True)
r["ro_abs"] = ro.get_position()
ro.move_relative(-15, blocking=True)
r["ro_rel"] = ro.get_position()
li.move_absolute(12.5, blocking=True)
r["li_abs"] = li.get_position()
li.move_relative_raw(-1024, blocking=True)
r["li_rel_raw"] = li.get_position_raw()
sl.home(blocking=True)
sl.move_absolute_raw(64, blocking=True)
r["sl"] = [sl.model_number, sl.get_position_raw(), sl.get_position()]
ro.move_absolute(90)
r["moving"] = ro.is_moving()
ro.wait(raise_errors=True)
r["moved"] = ro.get_position()
time.sleep(0.3)
r["status"] = [int(ro.status), int(li.status), int(sl.status)]
sl.close()
li.close()
ro.close()
time.sleep(0.3)
print(json.dumps(r))
"#;

#[test]
fn thorlabs_elliptec_homes_moves_and_polls_three_modules() {
    let Some(py) = client_python() else { return };
    let rig = Rig::start("ell-thorlabs", "0:ELL14,1:ELL9,2:ELL20");
    let r = rig.client(&py, THORLABS_ELLIPTEC);
    let info = r["info"].as_array().expect("info");
    assert_eq!(info[0], "ELL14/M", "{r}");
    assert_eq!(info[2], 360, "{r}");
    assert_eq!(info[3], "°", "{r}");
    assert_eq!(info[6], "ELL20/M", "{r}");
    assert_eq!((&info[7], &info[8]), (&60.into(), &"mm".into()), "{r}");
    assert!(near(&r["ro_abs"], 45.0, 0.01), "{r}");
    assert!(near(&r["ro_rel"], 30.0, 0.01), "{r}");
    assert!(near(&r["li_abs"], 12.5, 0.001), "{r}");
    assert_eq!(r["li_rel_raw"], 12_800 - 1024, "{r}");
    assert_eq!(r["moving"], true, "{r}");
    assert!(near(&r["moved"], 90.0, 0.01), "{r}");
    // An ELL9: positions in pulses, 31 per slot; asked for 64, it rests on the third at 62.
    assert_eq!(r["sl"], serde_json::json!(["ELL9/M", 62, 2.0]), "{r}");
    assert_eq!(r["status"], serde_json::json!([0, 0, 0]), "{r}");
    let lines = rig.finish();
    // The background polling went on throughout.
    let polls = lines.iter().filter(|l| l.ends_with("gs\r\n")).count();
    assert!(polls >= 4, "{polls} status polls: {lines:?}");
}

/// pylablib (1.4.5) `Thorlabs.ElliptecMotor` on the bus's two addresses (its default probes all
/// 16 with `gs`, and the 14 unanswered probes would show as `no_reply` in the capture, as on
/// hardware): `get_full_info()` (which asks `i3`, answered `GS03`), every getter, settings, a frequency
/// search, homing, moves and an address change.
const PYLABLIB: &str = r#"
import json, sys
from pylablib.devices import Thorlabs
m = Thorlabs.ElliptecMotor(sys.argv[1], addrs=[0, 1])
r = {}
r["addrs"] = m.get_connected_addrs()
full = m.get_full_info()
r["full_keys"] = sorted(full)
r["full_motors"] = {str(a): len(v) for a, v in full["motor_info"].items()}
r["full_models"] = {str(a): v.model_no for a, v in full["device_info"].items()}
r["status"] = m.get_status(addr=0)
r["velocity"] = m.set_velocity(50, addr=0)
r["home_offset"] = m.get_home_offset(addr=0)
r["freq"] = m.set_frequency(fw_freq=80000, motor=1, addr=0)[0]
r["searched"] = m.search_frequency(motor=2, addr=0)
r["stored"] = m.store_parameters(addr=0)
r["homed"] = m.home(addr=0)
r["moved"] = m.move_to(45, addr=0)
r["pos"] = m.get_position(addr=0)
r["moved_by"] = m.move_by(-15, addr=0)
r["pos2"] = m.get_position(addr=0)
r["lin_home"] = m.home(addr=1)
r["lin_moved"] = m.move_to(10, addr=1)
r["lin_pos"] = m.get_position(addr=1)
r["readdressed"] = m.change_addr(5, addr=1)
r["addrs2"] = m.get_connected_addrs()
r["lin_pos2"] = m.get_position(addr=5)
r["status_all"] = {str(a): s for a, s in m.get_status(addr="all").items()}
m.close()
print(json.dumps(r))
"#;

#[test]
fn pylablib_gets_full_info_and_drives_a_rotation_mount_and_a_linear_stage() {
    let Some(py) = client_python() else { return };
    let rig = Rig::start("ell-pylablib", "0:ELL14,1:ELL17");
    let r = rig.client(&py, PYLABLIB);
    assert_eq!(r["addrs"], serde_json::json!([0, 1]), "{r}");
    for k in [
        "device_info",
        "motor_info",
        "position",
        "status",
        "velocity",
    ] {
        assert!(
            r["full_keys"]
                .as_array()
                .is_some_and(|a| a.contains(&k.into())),
            "{k}: {r}"
        );
    }
    // Motors 1 and 2 answer, motor 3 is refused with GS03.
    assert_eq!(r["full_motors"], serde_json::json!({"0": 2, "1": 2}), "{r}");
    assert_eq!(
        r["full_models"],
        serde_json::json!({"0": 14, "1": 17}),
        "{r}"
    );
    assert_eq!(r["status"], "ok", "{r}");
    assert_eq!(r["velocity"], 50, "{r}");
    assert!(near(&r["home_offset"], 0.0, 0.0), "{r}");
    assert!(near(&r["freq"], 14_740_000.0 / 184.0, 1.0), "{r}");
    assert!(near(&r["searched"][0], 14_740_000.0 / 189.0, 1.0), "{r}");
    assert_eq!(r["stored"], "ok", "{r}");
    for k in ["homed", "moved", "moved_by", "lin_home", "lin_moved"] {
        assert_eq!(r[k], true, "{k}: {r}");
    }
    assert!(near(&r["pos"], 45.0, 0.01), "{r}");
    assert!(near(&r["pos2"], 30.0, 0.01), "{r}");
    // pylablib reads IN's pulses as per travel (2048 / 28 per "unit"): its own units round
    // trip.
    assert!(near(&r["lin_pos"], 10.0, 0.02), "{r}");
    assert!(near(&r["lin_pos2"], 10.0, 0.02), "{r}");
    assert_eq!(r["readdressed"], "ok", "{r}");
    assert_eq!(r["addrs2"], serde_json::json!([0, 5]), "{r}");
    // The module keeps the GS03 of `i3` for the next `gs` (pylablib: "otherwise it is returned
    // as the next status result"); pylablib clears it at its default address only (its
    // `_parse_status` sends `gs` without an address), so the linear stage still reports it.
    assert_eq!(
        r["status_all"],
        serde_json::json!({"0": "ok", "5": "not_supported"}),
        "{r}"
    );
    let lines = rig.finish();
    for want in ["0i3", "0GS03", "1ca5", "5GS00"] {
        assert!(
            lines.iter().any(|l| l.trim_end() == want),
            "{want}: {lines:?}"
        );
    }
}
