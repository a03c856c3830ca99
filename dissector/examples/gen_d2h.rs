//! Write a stream of device→host APT messages with random field values to stdout, for the
//! side-by-side comparison with the Python package `thorlabs-apt-protocol`
//! (`bench/compare-python.sh`): `gen_d2h MEGABYTES [SEED]`.
//!
//! Only messages (and forms) that its `Unpacker` parses with the same byte layout are used;
//! each frame picks one of them uniformly, goes to the host (0x01) and comes from an address
//! the `Unpacker` accepts (rack, bays, USB unit). The stream is whole frames: it stops at the
//! first frame boundary at or after MEGABYTES × 10⁶ bytes.

use aptscope_dissector::apt::encode;
use aptscope_dissector::synth::{random_values, Rng};
use aptscope_dissector::table::{Form, FormKind, MsgDef};
use aptscope_dissector::Table;
use std::io::Write;

/// (message, form): `0` = header-only, else the data length.
const MSGS: &[(&str, u16)] = &[
    ("HW_GET_INFO", 84),
    ("HW_RESPONSE", 0),
    ("RACK_GET_BAYUSED", 0),
    ("MOD_GET_CHANENABLESTATE", 0),
    ("MOT_GET_DCSTATUSUPDATE", 14),
    ("MOT_GET_STATUSUPDATE", 14),
    ("MOT_GET_STATUSBITS", 6),
    ("MOT_MOVE_COMPLETED", 0),
    ("MOT_MOVE_COMPLETED", 14),
    ("MOT_MOVE_STOPPED", 0),
    ("MOT_MOVE_STOPPED", 14),
    ("MOT_MOVE_HOMED", 0),
    ("MOT_GET_POSCOUNTER", 6),
    ("MOT_GET_ENCCOUNTER", 6),
    ("MOT_GET_VELPARAMS", 14),
    ("MOT_GET_JOGPARAMS", 22),
    ("MOT_GET_HOMEPARAMS", 14),
    ("MOT_GET_LIMSWITCHPARAMS", 16),
    ("MOT_GET_MOVEABSPARAMS", 6),
    ("MOT_GET_MOVERELPARAMS", 6),
    ("MOT_GET_DCPIDPARAMS", 20),
    ("MOT_GET_POWERPARAMS", 6),
    ("MOT_GET_KCUBEMMIPARAMS", 28),
    ("PZ_GET_OUTPUTVOLTS", 4),
    ("PZ_GET_OUTPUTPOS", 4),
    ("PZ_GET_PZSTATUSUPDATE", 10),
    ("PZ_GET_MAXTRAVEL", 4),
];

/// Sources the `Unpacker` accepts (besides 0x00): rack, bays 0–9, USB unit.
const SOURCES: [u8; 12] = [
    0x11, 0x21, 0x22, 0x23, 0x24, 0x25, 0x26, 0x27, 0x28, 0x29, 0x2A, 0x50,
];
const HOST: u8 = 0x01;

fn forms(t: &Table) -> Vec<(&MsgDef, &Form)> {
    MSGS.iter()
        .map(|&(name, len)| {
            let m = t
                .msg_by_name(name)
                .unwrap_or_else(|| panic!("{name}: not in the table"));
            let want = if len == 0 {
                FormKind::Header
            } else {
                FormKind::Data(len)
            };
            let f = m
                .forms
                .iter()
                .find(|f| f.kind == want)
                .unwrap_or_else(|| panic!("{name}: no form of length {len}"));
            (m, f)
        })
        .collect()
}

fn main() -> std::io::Result<()> {
    let mut args = std::env::args().skip(1);
    let mb: f64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(20.0);
    let seed: u64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(1);
    let t = Table::global();
    let forms = forms(t);
    let mut r = Rng(seed);
    let want = (mb * 1e6) as usize;
    let mut out = Vec::with_capacity(want + 128);
    let mut n = 0u64;
    while out.len() < want {
        let (m, form) = forms[r.below(forms.len() as u64) as usize];
        let vals = random_values(t, &mut r, form);
        let src = SOURCES[r.below(SOURCES.len() as u64) as usize];
        match encode(form, &vals, m.id, HOST, src) {
            Ok(b) => out.extend_from_slice(&b),
            Err(e) => panic!("{}: {e}", m.name),
        }
        n += 1;
    }
    eprintln!(
        "gen_d2h: {} bytes, {n} frames of {} forms of {} messages",
        out.len(),
        forms.len(),
        {
            let mut names: Vec<&str> = MSGS.iter().map(|m| m.0).collect();
            names.dedup();
            names.len()
        }
    );
    let mut w = std::io::stdout().lock();
    w.write_all(&out)?;
    w.flush()
}
