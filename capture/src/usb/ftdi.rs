//! FTDI specifics: the status bytes of IN packets and the line settings of vendor requests.

/// The first byte of an FTDI IN packet: modem status, bit 0 set ("reserved, must be 1"), bits 2
/// and 3 clear (bit 1 is seen set on some H chips).
pub(super) fn ftdi_status_ok(b: u8) -> bool {
    b & 0x0c == 0 && b & 0x03 != 0
}

/// Whether every `mps` piece of `data` starts with a plausible FTDI status pair.
pub(super) fn pieces_look_ftdi(data: &[u8], mps: usize) -> bool {
    data.chunks(mps)
        .all(|p| p.len() >= 2 && ftdi_status_ok(p[0]))
}

/// Bulk IN data without the two status bytes that start every `mps`-byte piece.
pub(super) fn strip_ftdi_status(data: &[u8], mps: usize) -> Vec<u8> {
    let mps = mps.max(3);
    let mut v = Vec::with_capacity(data.len());
    for piece in data.chunks(mps) {
        if let Some(rest) = piece.get(2..) {
            v.extend_from_slice(rest);
        }
    }
    v
}

/// Inverse of the Linux driver's `divfrac` (fraction code → eighths).
pub(super) const FRAC_INV: [u32; 8] = [0, 4, 2, 1, 3, 5, 6, 7];

/// Common baud rates: a decoded rate within 3 % of one (the FTDI tolerance) is reported as it.
pub(super) const STANDARD_BAUDS: [u32; 26] = [
    300, 600, 1200, 2400, 4800, 9600, 14400, 19200, 28800, 38400, 57600, 76800, 115200, 128000,
    153600, 230400, 250000, 256000, 460800, 500000, 921600, 1000000, 1500000, 2000000, 3000000,
    12000000,
];

/// The baud rate of an FTDI (AM/BM/R/X/H) SET_BAUDRATE: `wValue` and the divisor's high bits
/// (bit 16: last fraction bit; bit 17: 120 MHz clock of H chips).
pub(super) fn decode_baud(wvalue: u16, hi: u16) -> String {
    let raw = (u32::from(hi) << 16) | u32::from(wvalue);
    let h_clock = raw & 0x2_0000 != 0;
    let div = match raw & 0x1_ffff {
        0 => 1,
        1 => 0x4001,
        d => d,
    };
    let eighths = ((div & 0x3fff) << 3) | FRAC_INV[((div >> 14) & 7) as usize];
    if eighths == 0 {
        return format!("baud divisor 0x{raw:05x}");
    }
    let base: u64 = if h_clock { 96_000_000 } else { 24_000_000 };
    let baud = (base + u64::from(eighths) / 2) / u64::from(eighths);
    let nominal = STANDARD_BAUDS
        .iter()
        .copied()
        .find(|&s| baud.abs_diff(u64::from(s)) * 100 <= u64::from(s) * 3);
    match nominal {
        Some(s) => s.to_string(),
        None => baud.to_string(),
    }
}

/// The baud rate of the original FT8U100AX (SIO), which takes a code.
pub(super) fn sio_baud(wvalue: u16) -> String {
    const RATES: [u32; 10] = [
        300, 600, 1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200,
    ];
    match RATES.get(usize::from(wvalue)) {
        Some(r) => r.to_string(),
        None => format!("baud code {wvalue}"),
    }
}

/// SET_DATA `wValue`: bits 0–7 data bits, 8–10 parity, 11–13 stop bits → `8N1`.
pub(super) fn format_data_bits(v: u16) -> String {
    let bits = v & 0xff;
    let parity = ['N', 'O', 'E', 'M', 'S']
        .get(usize::from((v >> 8) & 7))
        .copied()
        .unwrap_or('?');
    let stop = match (v >> 11) & 7 {
        0 => "1",
        1 => "1.5",
        2 => "2",
        _ => "?",
    };
    let mut s = format!("{bits}{parity}{stop}");
    if v & 0x4000 != 0 {
        s.push_str(" break");
    }
    s
}

/// SET_FLOW_CTRL protocol (high byte of `wIndex`).
pub(super) fn format_flow(p: u16) -> String {
    let names: Vec<&str> = [(1, "RTS/CTS"), (2, "DTR/DSR"), (4, "XON/XOFF")]
        .iter()
        .filter(|(bit, _)| p & bit != 0)
        .map(|(_, n)| *n)
        .collect();
    if names.is_empty() {
        format!("flow 0x{p:02x}")
    } else {
        names.join("+")
    }
}
