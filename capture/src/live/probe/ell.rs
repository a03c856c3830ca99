//! The Elliptec probe: scan bus addresses 0–F with `in`, then send each module found the
//! read-only commands (class `query` in the command table) its model supports.

use super::{Layout, Outcome, Reply, Step};
use aptscope_dissector::ell::table::{self, Class, Cmd};

/// How long the address scan waits for each `in` (a 9600-baud `IN` reply takes about 35 ms;
/// the command table's 2 s for each of 16 addresses would make a scan of a one-module bus last
/// half a minute).
pub const SCAN_MS: u32 = 250;

/// The `in` request to bus address `addr` (0–15).
pub fn scan_step(addr: u8) -> Step {
    step(addr, cmd("in"), SCAN_MS)
}

fn cmd(code: &str) -> &'static Cmd {
    table::lookup(code.as_bytes()).unwrap_or(&table::UNKNOWN_COMMAND)
}

/// A bus address as the protocol writes it (`0`–`9`, `A`–`F`).
pub fn addr_char(addr: u8) -> char {
    char::from_digit(u32::from(addr & 0x0F), 16).map_or('0', |c| c.to_ascii_uppercase())
}

fn step(addr: u8, c: &'static Cmd, timeout_ms: u32) -> Step {
    let mut bytes = vec![addr_char(addr) as u8];
    bytes.extend_from_slice(c.code.as_bytes());
    Step {
        name: c.name,
        sub: None,
        dst: addr,
        chan: None,
        bytes,
        timeout_ms,
        listed: true,
    }
}

/// Whether the probe may send `c`: a query (it asks for data and changes nothing), as the
/// command table classes it; settings, motions, scans, drives, address changes, groups and
/// reboots never.
pub fn read_only(c: &Cmd) -> bool {
    c.class == Class::Query && c.dir == aptscope_dissector::table::Dir::HostToDevice
}

/// The ELL model number an `IN` reply line names (`0IN0E…`: 14).
pub fn model_of(line: &[u8]) -> Option<u8> {
    let t = std::str::from_utf8(line.get(3..5)?).ok()?;
    u8::from_str_radix(t, 16).ok()
}

/// The plan for a module of model `number` at `addr`: every query its model supports but `in`
/// (asked by the scan). An unknown model gets every query.
pub fn plan(addr: u8, number: u8) -> Vec<Step> {
    let m = table::model(number);
    table::COMMANDS
        .iter()
        .filter(|c| read_only(c) && c.code != "in")
        .filter(|c| m.is_none_or(|m| m.supports(c.code)))
        .map(|c| step(addr, c, c.timeout_ms))
        .collect()
}

/// Whether `line` (a reply line without its CR LF) answers `s`: from its address, with one of
/// its replies or a `GS` status.
pub fn answers(s: &Step, line: &[u8]) -> bool {
    let c = table::by_name(s.name).unwrap_or(&table::UNKNOWN_COMMAND);
    let code = line.get(1..3).and_then(|b| std::str::from_utf8(b).ok());
    line.first() == Some(&(addr_char(s.dst) as u8))
        && code.is_some_and(|k| c.replies.contains(&k) || k == "GS")
}

/// Judge the reply `line` to `s`.
pub fn check(s: &Step, line: &[u8], latency_us: u64) -> Reply {
    let c = table::by_name(s.name).unwrap_or(&table::UNKNOWN_COMMAND);
    let code = line
        .get(1..3)
        .and_then(|b| std::str::from_utf8(b).ok())
        .unwrap_or("?");
    let data = line.get(3..).unwrap_or(&[]);
    let r = cmd(code);
    let mut notes = vec![];
    if code == "GS" && !c.replies.contains(&"GS") {
        let st = std::str::from_utf8(data)
            .ok()
            .and_then(|d| u32::from_str_radix(d.trim(), 16).ok());
        notes.push(match st {
            Some(n) => format!("answered GS {} instead", table::status_name(n)),
            None => "answered GS instead".into(),
        });
    } else if data.len() != r.data_len() {
        notes.push(format!(
            "wrong length: {} data characters, {} has {}",
            data.len(),
            code,
            r.data_len()
        ));
    }
    let fits = notes.is_empty();
    Reply {
        name: r.name.to_string(),
        len: data.len(),
        layout: Layout {
            form: if fits {
                r.data_len().to_string()
            } else {
                "none".into()
            },
            note: String::new(),
            revs: vec![],
        },
        latency_us,
        notes,
    }
}

/// The outcome of a scan step nothing answered: not a deviation (an empty address).
pub fn empty_address(s: Step) -> Outcome {
    let mut step = s;
    step.listed = false;
    Outcome { step, reply: None }
}
