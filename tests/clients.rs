//! Public client libraries as acceptance tests of the simulators: thorlabs-apt-device and
//! pylablib (PyPI, pinned in `common::clients`) run their documented calls against
//! `aptscope sim apt --model X` through `aptscope tap`. Checked each time: the client's results,
//! the tap's byte check ("matches what was forwarded") and that `decode` of the capture raises
//! no diagnostic.
//!
//! pylablib cycles RTS when it opens a port (`BasicKinesisDevice._cycle_rts`, for FTDI chips),
//! which a pseudo-terminal refuses: the scripts replace that one call with a no-op.

mod common;

use common::clients::client_python;
use common::host::{start_sim_with, start_tap};
use common::proc::wait_for;
use common::{aptscope, scratch};
use std::path::{Path, PathBuf};
use std::process::Command;

/// What every pylablib script starts with.
const PYLABLIB: &str = r#"
import sys
from pylablib.devices import Thorlabs
# A pseudo-terminal refuses the RTS cycle pylablib does on opening (for FTDI chips).
Thorlabs.kinesis.BasicKinesisDevice._cycle_rts = staticmethod(lambda instr: None)
link = sys.argv[1]
"#;

/// What every thorlabs-apt-device script starts with: `wait(cond)` polls the client's state.
const TAD: &str = r#"
import sys, time
import thorlabs_apt_device as tad
link = sys.argv[1]
def wait(cond, secs=30):
    t0 = time.monotonic()
    while not cond():
        if time.monotonic() - t0 > secs:
            raise SystemExit("timed out")
        time.sleep(0.05)
"#;

/// Run `script` (with `prelude`) against the simulated `model` through the tap; returns the
/// client's standard output after the checks of the module docs.
fn run_client(name: &str, model: &str, prelude: &str, script: &str) -> Option<String> {
    run_client_cap(name, model, prelude, script).map(|(out, _)| out)
}

/// As [`run_client`]; also returns the capture's path.
fn run_client_cap(
    name: &str,
    model: &str,
    prelude: &str,
    script: &str,
) -> Option<(String, PathBuf)> {
    let py = client_python()?;
    let dir = scratch(&format!("client-{name}"));
    let _sim = start_sim_with(&["sim", "apt", "--model", model], &dir.join("dev"));
    let mut tap = start_tap(&dir, &[]);
    let file = dir.join("client.py");
    std::fs::write(&file, format!("{prelude}{script}")).expect("write the script");
    let out = Command::new(&py)
        .arg(&file)
        .arg(dir.join("host"))
        .output()
        .expect("run the client");
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "{name}: the client failed:\n{stdout}\n{}\ntap: {}",
        String::from_utf8_lossy(&out.stderr),
        tap.stderr()
    );
    // A client closes the port without waiting for the answers to its last requests (stops
    // and a status request on close): they are still crossing the tap when it exits.
    let cap = dir.join("cap.pcapng");
    wait_for(
        "the device's last replies in the capture",
        || diagnostics(&cap).join("\n"),
        || diagnostics(&cap).is_empty(),
    );
    tap.interrupt();
    let err = tap.stderr();
    assert!(err.contains("matches what was forwarded"), "{name}: {err}");
    let diags = diagnostics(&cap);
    assert!(diags.is_empty(), "{name}: {}", diags.join("\n"));
    let (all, _, _) = aptscope(&["decode", cap.to_str().expect("utf-8 path")], None);
    assert!(all.lines().count() > 10, "{name}: {all}");
    Some((stdout, cap))
}

/// The records of `decode` of the capture that carry a diagnostic.
fn diagnostics(cap: &Path) -> Vec<String> {
    let cap = cap.to_str().expect("utf-8 path");
    let (out, err, ok) = aptscope(&["decode", "-Y", "diag", cap], None);
    assert!(ok, "decode: {err}");
    out.lines()
        .filter(|l| !l.starts_with('#'))
        .map(str::to_string)
        .collect()
}

/// The value printed after `key ` on a line of the client's output.
fn said<'a>(out: &'a str, key: &str) -> &'a str {
    out.lines()
        .find_map(|l| l.strip_prefix(key).and_then(|r| r.strip_prefix(' ')))
        .unwrap_or_else(|| panic!("no `{key}` in:\n{out}"))
}

#[test]
fn pylablib_kinesis_motor_on_a_kdc101_reads_everything_homes_moves_and_jogs() {
    let script = r#"
d = Thorlabs.KinesisMotor(("serial", link))
info = d.get_full_info()
print("model", info["device_info"].model_no)
print("serial", info["device_info"].serial_no)
print("trigio", info["kcube_trigio_parameters"] is not None)
print("keys", " ".join(sorted(info)))
d.home(sync=True, timeout=30)
print("homed", d.is_homed())
d.move_to(20000); d.wait_move(timeout=30)
print("at", d.get_position())
d.move_by(-5000); d.wait_move(timeout=30)
print("by", d.get_position())
d.jog("-", kind="builtin"); d.wait_move(timeout=30)
print("jog", d.get_position())
print("status", " ".join(d.get_status()))
d.close()
"#;
    let Some(out) = run_client("pll-kdc101", "kdc101", PYLABLIB, script) else {
        return;
    };
    assert_eq!(said(&out, "model"), "KDC101");
    assert_eq!(said(&out, "serial"), "27000123");
    assert_eq!(said(&out, "trigio"), "True");
    assert_eq!(said(&out, "homed"), "True");
    assert_eq!(said(&out, "at"), "20000");
    assert_eq!(said(&out, "by"), "15000");
    // One jog step of 0.1 mm of a Z8 actuator (3455 counts); pylablib's motors have
    // `_forward_positive=False`: its "-" is the controller's forward.
    assert_eq!(said(&out, "jog"), "18455");
    assert!(said(&out, "status").contains("enabled"), "{out}");
}

#[test]
fn pylablib_piezo_controller_on_a_kpz101_sets_and_reads_its_output() {
    let script = r#"
d = Thorlabs.KinesisPiezoController(("serial", link))
print("model", d.get_device_info().model_no)
print("status", d.get_full_info()["status"])
d.enable_channel(True)
d.set_output_voltage(30)
print("volts", round(d.get_output_voltage()))
print("range", d.get_voltage_range())
d.close()
"#;
    let Some(out) = run_client("pll-kpz101", "kpz101", PYLABLIB, script) else {
        return;
    };
    assert_eq!(said(&out, "model"), "KPZ101");
    assert_eq!(said(&out, "volts"), "30");
    assert_eq!(said(&out, "range"), "75");
}

#[test]
fn pylablib_piezo_motor_on_a_kim101_moves_each_channel() {
    let script = r#"
d = Thorlabs.KinesisPiezoMotor(("serial", link))
print("channels", d.get_device_info().nchannels)
print("keys", " ".join(sorted(d.get_full_info())))
d.move_to(300, channel=2); d.wait_move(channel=2, timeout=30)
d.move_by(-120, channel=4); d.wait_move(channel=4, timeout=30)
print("pos", " ".join(str(p) for p in d.get_position(channel="all")))
d.close()
"#;
    let Some(out) = run_client("pll-kim101", "kim101", PYLABLIB, script) else {
        return;
    };
    assert_eq!(said(&out, "channels"), "4");
    assert_eq!(said(&out, "pos"), "0 300 0 -120");
}

#[test]
fn pylablib_mff_flips_between_its_two_states() {
    let script = r#"
d = Thorlabs.MFF(("serial", link))
d.move_to_state(1); d._wait_move(timeout=30)
print("one", d.get_state())
d.move_to_state(0); d._wait_move(timeout=30)
print("zero", d.get_state())
d.close()
"#;
    // A flipper ends MOT_MOVE_JOG without MOT_MOVE_COMPLETED (pylablib's MFF class takes one
    // for an error): the table's `silent` line for the model, which pairing and the simulator
    // both read, so the session has no no-reply either.
    let Some(out) = run_client("pll-mff101", "mff101", PYLABLIB, script) else {
        return;
    };
    assert_eq!((said(&out, "one"), said(&out, "zero")), ("1", "0"));
}

#[test]
fn pylablib_quad_detector_on_a_kpa101_reads_everything() {
    let script = r#"
d = Thorlabs.KinesisQuadDetector(("serial", link))
info = d.get_full_info()
print("mode", info["operation_mode"])
d.set_operation_mode("closed_loop")
print("now", d.get_operation_mode())
d.close()
"#;
    let Some(out) = run_client("pll-kpa101", "kpa101", PYLABLIB, script) else {
        return;
    };
    assert_eq!(said(&out, "mode"), "monitor");
    assert_eq!(said(&out, "now"), "closed_loop");
}

#[test]
fn pylablib_kinesis_motor_on_a_bsc203_bay_and_a_k10cr1() {
    let script = r#"
d = Thorlabs.KinesisMotor(("serial", link), is_rack_system=True, default_channel=2)
print("model", d.get_device_info().model_no)
d.move_by(10000); d.wait_move(timeout=30)
print("pos", d.get_position())
d.close()
"#;
    let Some(out) = run_client("pll-bsc203", "bsc203", PYLABLIB, script) else {
        return;
    };
    assert_eq!(said(&out, "pos"), "10000");
    let script = r#"
d = Thorlabs.KinesisMotor(("serial", link))
print("keys", " ".join(sorted(d.get_full_info())))
d.move_by(136533); d.wait_move(timeout=30)
print("pos", d.get_position())
d.close()
"#;
    let Some(out) = run_client("pll-k10cr1", "k10cr1", PYLABLIB, script) else {
        return;
    };
    // One degree of the rotation mount.
    assert_eq!(said(&out, "pos"), "136533");
}

#[test]
fn thorlabs_apt_device_tdc001_talks_to_bay_0x21() {
    let script = r#"
d = tad.TDC001(serial_port=link, home=False)
wait(lambda: d.velparams_[0][0].get("msg") == "mot_get_velparams")
print("from", d.velparams_[0][0]["source"])
d.home(); wait(lambda: d.status["homed"])
d.move_absolute(20000); time.sleep(0.3)
wait(lambda: d.status["position"] == 20000 and not d.status["moving_forward"])
print("pos", d.status["position"])
d.close()
"#;
    let Some(out) = run_client("tad-tdc001", "tdc001", TAD, script) else {
        return;
    };
    // The replies come from the bay address the class sends to (0x21).
    assert_eq!(said(&out, "from"), "33");
    assert_eq!(said(&out, "pos"), "20000");
}

#[test]
fn thorlabs_apt_device_kdc101_homes_and_moves() {
    let script = r#"
d = tad.KDC101(serial_port=link, home=False)
d.home(); wait(lambda: d.status["homed"])
d.move_relative(10000); time.sleep(0.3)
wait(lambda: d.status["position"] == 10000)
d.move_jog(); time.sleep(0.3)
wait(lambda: d.status["position"] == 6545)
print("pos", d.status["position"])
d.close()
"#;
    let Some(out) = run_client("tad-kdc101", "kdc101", TAD, script) else {
        return;
    };
    // One jog step (3455 counts) back: the class inverts the direction logic by default.
    assert_eq!(said(&out, "pos"), "6545");
}

#[test]
fn thorlabs_apt_device_bsc_answers_each_bays_trigger_and_moves_a_bay() {
    let script = r#"
d = tad.BSC(serial_port=link, x=3, home=False)
wait(lambda: all(d.trigger_[b][0].get("msg") == "mot_get_trigger" for b in range(3)))
print("trig", " ".join(str(d.trigger_[b][0]["source"]) for b in range(3)))
d.move_relative(100000, bay=1); time.sleep(0.3)
wait(lambda: d.status_[1][0]["position"] == 100000)
print("pos", " ".join(str(d.status_[b][0]["position"]) for b in range(3)))
d.close()
"#;
    let Some(out) = run_client("tad-bsc203", "bsc203", TAD, script) else {
        return;
    };
    assert_eq!(said(&out, "trig"), "33 34 35");
    assert_eq!(said(&out, "pos"), "0 100000 0");
}

#[test]
fn pylablib_laser_diode_driver_on_a_kld101_follows_its_setpoint() {
    let script = r#"
d = Thorlabs.kinesis.KinesisLaserDiodeDriver(("serial", link))
print("setpoint", round(d.set_laser_power_setpoint(50)))
print("off", d.get_complete_status().output)
print("on", d.enable_output(True))
print("current", round(d.get_complete_status().laser_current))
d.enable_output(False)
d.close()
"#;
    let Some(out) = run_client("pll-kld101", "kld101", PYLABLIB, script) else {
        return;
    };
    assert_eq!(said(&out, "setpoint"), "50");
    assert_eq!((said(&out, "off"), said(&out, "on")), ("False", "True"));
    // The simulated diode draws 0.6 of full scale per unit of power setpoint.
    assert_eq!(said(&out, "current"), "30");
}

#[test]
fn thorlabs_apt_device_bbd203_moves_a_bay_with_status_updates_kept_alive() {
    let script = r#"
from thorlabs_apt_device.devices.bbd import BBD203
d = BBD203(serial_port=link, home=False)
wait(lambda: all(d.velparams_[b][0].get("msg") == "mot_get_velparams" for b in range(3)))
d.move_relative(20000, bay=2)
# The class asks for status updates and keeps them alive with MOT_ACK_DCSTATUSUPDATE (its first
# comes about 5 s in, after the 50th update: the updates resume with it).
time.sleep(6)
wait(lambda: d.status_[2][0]["position"] == 20000)
print("pos", " ".join(str(d.status_[b][0]["position"]) for b in range(3)))
print("source", d.status_[2][0]["source"])
d.close()
"#;
    let Some((out, cap)) = run_client_cap("tad-bbd203", "bbd203", TAD, script) else {
        return;
    };
    assert_eq!(said(&out, "pos"), "0 0 20000");
    assert_eq!(said(&out, "source"), "35");
    // More than the 50 updates a bay sends without the host's ACK: the ACKs kept them going.
    let cap = cap.to_str().expect("utf-8 path");
    let filter = "apt.name == MOT_GET_DCSTATUSUPDATE && apt.src == 0x23";
    let (ups, err, ok) = aptscope(&["decode", "-Y", filter, cap], None);
    assert!(ok, "{err}");
    let n = ups.lines().filter(|l| !l.starts_with('#')).count();
    assert!(n > 50, "{n} status updates from bay 0x23");
}
