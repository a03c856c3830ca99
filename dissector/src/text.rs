//! One-line text rendering of records, like tshark's default output.

use crate::apt::{summary_in, AptFrame, GarbageKind};
use crate::diag::Diag;
use std::fmt::Write;

/// Record number, time (seconds since the first record, when the capture has times) and
/// stream offset: the start of every line.
fn prefix(out: &mut String, n: u64, time: Option<f64>, offset: u64) {
    let _ = write!(out, "{n:>6} ");
    if let Some(t) = time {
        let _ = write!(out, "{t:>11.6} ");
    }
    let _ = write!(out, "{offset:>#10x}  ");
}

/// Append the timeline line of a decoded APT frame (no newline):
/// `N  offset  src → dst  NAME  chN  key fields  [diagnostics]`.
pub fn apt_line(out: &mut String, n: u64, f: &AptFrame<'_, '_>, time: Option<f64>) {
    apt_line_in(out, n, f, time, None)
}

/// [`apt_line`] with motion values also in physical units (`max_vel=1932478 (2.5 mm/s)`).
pub fn apt_line_in(
    out: &mut String,
    n: u64,
    f: &AptFrame<'_, '_>,
    time: Option<f64>,
    scale: Option<&crate::units::Scale>,
) {
    let h = f.header();
    prefix(out, n, time, f.offset);
    let _ = write!(out, "{:>5} → {:<5} ", h.src().name(), h.dst().name());
    match f.name() {
        Some(name) => {
            let _ = write!(out, "{name:<32}");
        }
        None => {
            let _ = write!(out, "{:<32}", format!("UNKNOWN_0x{:04X}", h.msg_id()));
        }
    }
    match f.channel() {
        Some(c) => {
            let _ = write!(out, " ch{c:<2}");
        }
        None => out.push_str("     "),
    }
    if let Some(s) = f.sub {
        let _ = write!(out, " [{}]", s.name);
    }
    out.push(' ');
    let before = out.len();
    summary_in(f, 6, scale, out);
    if out.len() == before && f.form.is_none() && f.bytes.len() > 6 {
        out.push_str("data=");
        for b in &f.bytes[6..f.bytes.len().min(6 + 32)] {
            let _ = write!(out, "{b:02x}");
        }
    }
    for d in f.diags() {
        let _ = write!(out, "  !! {d}");
    }
}

/// Append the line of a garbage record.
pub fn garbage_line(
    out: &mut String,
    n: u64,
    offset: u64,
    bytes: &[u8],
    kind: GarbageKind,
    time: Option<f64>,
) {
    let d = crate::json::garbage_diag(offset, bytes.len(), kind);
    prefix(out, n, time, offset);
    let _ = write!(out, "!! {}: ", d.kind);
    for b in bytes.iter().take(24) {
        let _ = write!(out, "{b:02x}");
    }
    if bytes.len() > 24 {
        out.push('…');
    }
}

/// Append the line of an input diagnostic (e.g. a bad character in hex text).
pub fn input_diag_line(out: &mut String, d: &Diag) {
    let _ = write!(out, "     - {:>#10x}  !! input: {}", d.offset, d.kind);
}

/// Append the timeline line of an Elliptec frame with what the bus made of it.
pub fn ell_line(
    out: &mut String,
    n: u64,
    f: &crate::ell::EllFrame<'_>,
    o: &crate::ell::Observation,
    time: Option<f64>,
) {
    let arrow = if f.dir() == crate::table::Dir::HostToDevice {
        "host → "
    } else {
        "   ← "
    };
    prefix(out, n, time, f.offset);
    let _ = write!(out, "{arrow}{}  {} ", f.addr_char(), f.code_str());
    let name = f.cmd.map_or("UNKNOWN", |c| c.name);
    let _ = write!(out, "{name:<28}");
    let scale = o.module.as_ref().and_then(|m| m.scale());
    for (fd, v) in f.fields() {
        out.push(' ');
        out.push_str(fd.name);
        out.push('=');
        crate::ell::fmt_value(fd, &v, scale, out);
    }
    if let Some(m) = o.module.as_ref().and_then(|m| m.model) {
        let _ = write!(out, "  [ELL{m}]");
    }
    if let Some(p) = o.pair {
        let _ = write!(out, "  ↩ #{p}");
        if let Some(l) = o.latency_ns {
            let _ = write!(out, " {:.1} ms", l as f64 / 1e6);
        }
        if o.interim {
            out.push_str(" (interim)");
        }
    }
    for d in f.diags() {
        let _ = write!(out, "  !! {d}");
    }
}

/// Append the line of an Elliptec garbage record: its first bytes in hex and as printable
/// ASCII (`.` for the others), like a hex dump.
pub fn ell_garbage_line(out: &mut String, n: u64, offset: u64, bytes: &[u8], time: Option<f64>) {
    prefix(out, n, time, offset);
    let _ = write!(out, "!! {} byte(s) that start no frame: ", bytes.len());
    let head = &bytes[..bytes.len().min(24)];
    for (i, b) in head.iter().enumerate() {
        let _ = write!(out, "{}{b:02x}", if i > 0 { " " } else { "" });
    }
    if bytes.len() > head.len() {
        out.push_str(" …");
    }
    out.push_str("  |");
    out.extend(head.iter().map(|&b| {
        if b.is_ascii_graphic() || b == b' ' {
            b as char
        } else {
            '.'
        }
    }));
    out.push('|');
}

/// Append a line for a diagnostic that refers to an earlier record.
pub fn late_diag_line(out: &mut String, refers_to: u64, d: &Diag) {
    let _ = write!(
        out,
        "     - {:>#10x}  !! #{refers_to}: {}",
        d.offset, d.kind
    );
}

/// Append what pairing found to an APT line: the request a reply answers, its latency, and
/// unsolicited or duplicate replies.
pub fn pair_suffix(out: &mut String, p: &crate::pair::PairInfo) {
    if let Some(n) = p.pair {
        let _ = write!(out, "  ↩ #{n}");
        if let Some(l) = p.latency_ns {
            let _ = write!(out, " {:.1} ms", l as f64 / 1e6);
        }
        if p.other_address {
            out.push_str(" (from another address)");
        }
    }
    if p.duplicate {
        out.push_str("  !! duplicate reply");
    }
    if p.unsolicited {
        out.push_str("  !! unsolicited reply");
    }
    if let Some(model) = p.not_for_model {
        let _ = write!(out, "  !! {}", crate::DiagKind::NotForModel { model });
    }
}

/// Append the line of a units notice: `# units: stream 0 usb (KDC101): MTS25-Z8: 34554.96
/// counts/mm, brushed DC servo rules`.
pub fn units_notice_line(out: &mut String, n: &crate::units::Notice) {
    out.push_str("# ");
    out.push_str(&n.text());
}
