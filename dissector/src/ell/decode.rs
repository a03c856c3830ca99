//! Decoding an Elliptec frame: address, command, typed fields, and what is off about it.

use super::frame::head_of_frame;
use super::table::{status_name, Cmd, Field, Kind, CURVE_POINT_BYTES, CURVE_SHORT_BYTES};
use crate::diag::{Diag, DiagKind};
use crate::table::Dir;

/// A field's value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EllValue<'a> {
    /// Unsigned number.
    U(u64),
    /// Signed number (positions).
    I(i64),
    /// An address character.
    Char(char),
    /// Decimal digits kept as written (serial number).
    Digits(&'a str),
    /// Binary data.
    Raw(&'a [u8]),
}

impl EllValue<'_> {
    /// As an integer, for numbers.
    pub fn as_i64(&self) -> Option<i64> {
        match *self {
            EllValue::U(v) => i64::try_from(v).ok(),
            EllValue::I(v) => Some(v),
            EllValue::Digits(d) => d.parse().ok(),
            EllValue::Char(c) => c.to_digit(16).map(i64::from),
            EllValue::Raw(_) => None,
        }
    }
}

/// A decoded Elliptec frame. Borrows the bytes; up to 8 fields, no allocation.
#[derive(Debug, Clone)]
pub struct EllFrame<'a> {
    /// Stream offset.
    pub offset: u64,
    /// The bytes, terminator included.
    pub bytes: &'a [u8],
    /// Bus address 0–15 as written in the frame.
    pub addr: u8,
    /// The two-character command as written.
    pub code: [u8; 2],
    /// The command, when the manual defines it.
    pub cmd: Option<&'static Cmd>,
    /// Data characters with separators (spaces, commas) removed, terminator excluded.
    data: [u8; 64],
    data_len: usize,
    /// The data slice when it is binary or longer than 64 characters.
    data_raw: &'a [u8],
    /// Whether a CR/LF terminator was present.
    pub terminated: bool,
    /// Where the terminator starts in `bytes` (their length without one).
    term_at: usize,
    diags: Vec<Diag>,
}

fn hex_val(s: &[u8]) -> Option<u64> {
    if s.is_empty() || s.len() > 16 {
        return None;
    }
    let mut v = 0u64;
    for &c in s {
        v = v << 4 | (c as char).to_digit(16)? as u64;
    }
    Some(v)
}

impl<'a> EllFrame<'a> {
    /// Decode a frame from the framer. `None` only when the bytes are not a frame at all.
    pub fn decode(offset: u64, bytes: &'a [u8], truncated: bool) -> Option<Self> {
        let h = head_of_frame(bytes)?;
        let code = [bytes[h.cmd_at], bytes[h.cmd_at + 1]];
        let binary = h.cmd.filter(|c| c.is_binary());
        let mut end = bytes.len();
        match binary {
            // Binary data may hold CR and LF bytes of its own (a curve's last current ending in
            // 0x0D lost those bytes to the terminator): only what follows its fixed length is
            // the terminator, as the framer cuts it, or a CR LF after the manual's shorter
            // length; a truncated curve has none.
            Some(c) => {
                let full = h.data_at + c.data_len();
                let short = h.data_at + CURVE_SHORT_BYTES;
                if end > full {
                    end = full;
                } else if !truncated && end == short + 2 && bytes[short..].starts_with(b"\r\n") {
                    end = short;
                }
            }
            None => {
                while end > h.data_at && matches!(bytes[end - 1], b'\r' | b'\n') {
                    end -= 1;
                }
            }
        }
        let terminated = end < bytes.len();
        let body = &bytes[h.data_at.min(end)..end];
        let mut f = EllFrame {
            offset,
            bytes,
            addr: h.addr,
            code,
            cmd: h.cmd,
            data: [0; 64],
            data_len: 0,
            data_raw: body,
            terminated,
            term_at: end,
            diags: vec![],
        };
        if h.letter_o {
            f.diag(0, DiagKind::LetterO);
        }
        let raw = binary.is_some();
        let mut separators = h.spaced;
        if !raw {
            for (i, &c) in body.iter().enumerate() {
                match c {
                    b' ' | b',' => separators = true,
                    _ => {
                        let c = if c == b'O' {
                            f.diag(h.data_at + i, DiagKind::LetterO);
                            b'0'
                        } else {
                            c
                        };
                        if f.data_len < f.data.len() {
                            f.data[f.data_len] = c;
                        }
                        f.data_len += 1;
                    }
                }
            }
        } else {
            f.data_len = body.len();
        }
        if separators {
            let at = bytes[..end]
                .iter()
                .position(|&c| c == b' ' || c == b',')
                .unwrap_or(h.cmd_at);
            f.diag(at, DiagKind::Separators);
        }
        if truncated {
            f.diag(
                bytes.len(),
                DiagKind::Truncated {
                    expected: (h.data_at + h.cmd.map_or(0, |c| c.data_len())) as u32,
                    got: bytes.len() as u32,
                },
            );
        }
        match h.cmd {
            None => f.diag(h.cmd_at, DiagKind::UnknownCommand),
            Some(c) => {
                if !truncated && f.data_len == 0 && c.data_len() > 0 {
                    f.diag(
                        h.data_at,
                        DiagKind::MissingData {
                            expected: c.data_len() as u32,
                        },
                    );
                } else if !truncated && f.data_len != c.data_len() {
                    f.diag(
                        h.data_at,
                        DiagKind::DataLength {
                            expected: c.data_len() as u32,
                            got: f.data_len as u32,
                        },
                    );
                }
                if c.dir == Dir::DeviceToHost && !terminated && !truncated {
                    f.diag(bytes.len(), DiagKind::MissingTerminator);
                }
                if !raw {
                    let kinds = c
                        .fields
                        .iter()
                        .flat_map(|x| std::iter::repeat_n(x.kind, x.width as usize));
                    let mut bad = None;
                    for (ch, kind) in f.data().iter().zip(kinds) {
                        let ok = match kind {
                            Kind::Addr => addr_char(*ch).is_some(),
                            Kind::Dec => ch.is_ascii_digit(),
                            _ => ch.is_ascii_hexdigit(),
                        };
                        if !ok && bad.is_none() {
                            bad = Some(*ch);
                        }
                    }
                    if let Some(ch) = bad {
                        let at = body
                            .iter()
                            .position(|&b| b == ch)
                            .map_or(h.data_at, |p| h.data_at + p);
                        f.diag(at, DiagKind::BadDataChar { ch: ch as char });
                    }
                }
            }
        }
        Some(f)
    }

    fn diag(&mut self, at: usize, kind: DiagKind) {
        self.diags.push(Diag {
            offset: self.offset + at as u64,
            kind,
        });
    }

    /// The data characters (separators removed).
    pub fn data(&self) -> &[u8] {
        &self.data[..self.data_len.min(self.data.len())]
    }

    /// Where the terminator starts in [`Self::bytes`] (their length when there is none): after
    /// the last data byte, which in binary data may itself be a CR or LF.
    pub fn terminator_at(&self) -> usize {
        self.term_at
    }

    /// The command as text (`ma`).
    pub fn code_str(&self) -> &str {
        std::str::from_utf8(&self.code).unwrap_or("??")
    }

    /// The address character (`0`–`F`).
    pub fn addr_char(&self) -> char {
        char::from_digit(self.addr as u32, 16).map_or('?', |c| c.to_ascii_uppercase())
    }

    /// Host → module for lower-case commands, module → host for upper case.
    pub fn dir(&self) -> Dir {
        if self.code[0].is_ascii_lowercase() {
            Dir::HostToDevice
        } else {
            Dir::DeviceToHost
        }
    }

    /// Problems found.
    pub fn diags(&self) -> &[Diag] {
        &self.diags
    }

    /// Add a diagnostic found by a later stage (pairing).
    pub fn push_diag(&mut self, d: Diag) {
        self.diags.push(d);
    }

    /// The fields with their values (as many as the data holds).
    pub fn fields(&self) -> impl Iterator<Item = (&'static Field, EllValue<'_>)> + '_ {
        let fields: &'static [Field] = self.cmd.map_or(&[], |c| c.fields);
        let mut at = 0usize;
        fields.iter().filter_map(move |f| {
            let w = f.width as usize;
            if f.kind.is_binary() {
                return Some((f, EllValue::Raw(self.data_raw)));
            }
            let s = self.data().get(at..at + w)?;
            at += w;
            let v = match f.kind {
                Kind::Addr => EllValue::Char(addr_char(s[0])?),
                Kind::Dec => EllValue::Digits(std::str::from_utf8(s).ok()?),
                Kind::Signed | Kind::Position => {
                    let u = hex_val(s)?;
                    let bits = 4 * w as u32;
                    let v = if bits < 64 && u >> (bits - 1) & 1 == 1 {
                        u as i64 - (1i64 << bits)
                    } else {
                        u as i64
                    };
                    EllValue::I(v)
                }
                _ => EllValue::U(hex_val(s)?),
            };
            Some((f, v))
        })
    }

    /// A field by name.
    pub fn field(&self, name: &str) -> Option<EllValue<'_>> {
        self.fields().find(|(f, _)| f.name == name).map(|(_, v)| v)
    }

    /// The points of a `C1`/`C2` current curve (empty for other frames).
    pub fn curve(&self) -> impl Iterator<Item = CurvePoint> + '_ {
        let data: &[u8] = if self.cmd.is_some_and(|c| c.is_binary()) {
            self.data_raw
        } else {
            &[]
        };
        curve_points(data)
    }
}

/// One point of a `C1`/`C2` current curve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CurvePoint {
    /// Drive period (frequency = 14 740 000 / period Hz).
    pub period: u16,
    /// Current in points (1866 per ampere).
    pub current: u32,
}

impl CurvePoint {
    /// Drive frequency in Hz (0 for a zero period).
    pub fn hz(&self) -> f64 {
        if self.period == 0 {
            0.0
        } else {
            PERIOD_CLOCK_HZ / self.period as f64
        }
    }

    /// Current in amperes.
    pub fn amps(&self) -> f64 {
        self.current as f64 / CURRENT_PER_AMP
    }
}

/// The clock of drive periods: frequency = this / period (p.13).
pub const PERIOD_CLOCK_HZ: f64 = 14_740_000.0;
/// Current points per ampere (p.13).
pub const CURRENT_PER_AMP: f64 = 1866.0;

/// The whole points of current-curve bytes: period u16 then current u32, little endian (the
/// layout chosen in [`CURVE_POINTS`](super::table::CURVE_POINTS)); trailing bytes of a partial
/// point are left out.
pub fn curve_points(data: &[u8]) -> impl Iterator<Item = CurvePoint> + '_ {
    data.chunks_exact(CURVE_POINT_BYTES).map(|p| CurvePoint {
        period: u16::from_le_bytes([p[0], p[1]]),
        current: u32::from_le_bytes([p[2], p[3], p[4], p[5]]),
    })
}

/// The current-curve bytes of these points (the inverse of [`curve_points`]).
pub fn curve_bytes(points: &[CurvePoint]) -> Vec<u8> {
    let mut out = Vec::with_capacity(points.len() * CURVE_POINT_BYTES);
    for p in points {
        out.extend_from_slice(&p.period.to_le_bytes());
        out.extend_from_slice(&p.current.to_le_bytes());
    }
    out
}

fn addr_char(c: u8) -> Option<char> {
    match c {
        b'0'..=b'9' | b'A'..=b'F' => Some(c as char),
        b'a'..=b'f' => Some(c.to_ascii_uppercase() as char),
        _ => None,
    }
}

/// How a field reads for people. `scale` comes from the bus state ([`Module::scale`]) when the
/// module's `IN` reply has been seen: pulses per unit and the unit (`mm`, `deg`, or `slot` for
/// an indexed slider, whose positions show as slot numbers).
///
/// [`Module::scale`]: super::Module::scale
pub fn fmt_value(f: &Field, v: &EllValue<'_>, scale: Option<(f64, &str)>, out: &mut String) {
    use std::fmt::Write;
    let _ = match (f.kind, v) {
        (Kind::Status, EllValue::U(c)) => write!(out, "{} ({c})", status_name(*c as u32)),
        (Kind::Model, EllValue::U(m)) => write!(out, "ELL{m}"),
        (Kind::Firmware, EllValue::U(x)) => write!(out, "{}.{}", x >> 4, x & 15),
        (Kind::ThreadHw, EllValue::U(x)) => write!(
            out,
            "{} hw{}",
            if x & 0x80 != 0 { "imperial" } else { "metric" },
            x & 0x7F
        ),
        (Kind::Period, EllValue::U(p)) if *p > 0 => {
            write!(out, "{p} ({:.1} kHz)", PERIOD_CLOCK_HZ / *p as f64 / 1000.0)
        }
        (Kind::Current, EllValue::U(c)) => {
            write!(out, "{c} ({:.3} A)", *c as f64 / CURRENT_PER_AMP)
        }
        (Kind::Percent, EllValue::U(p)) => write!(out, "{p}%"),
        (Kind::Minutes, EllValue::U(m)) => write!(out, "{m} min"),
        (Kind::HomeDir, EllValue::U(d)) => write!(out, "{}", if *d == 0 { "CW" } else { "CCW" }),
        (Kind::Bool, EllValue::U(b)) => write!(out, "{}", if *b != 0 { "ON" } else { "OFF" }),
        (Kind::Position, EllValue::I(p)) => match scale {
            Some((ppp, "slot")) if ppp > 0.0 => {
                let _ = write!(out, "{p} (");
                fmt_slot(*p as f64 / ppp, out);
                write!(out, ")")
            }
            Some((ppu, unit)) if ppu > 0.0 => write!(
                out,
                "{p} ({} {unit})",
                crate::apt::round_sig(*p as f64 / ppu)
            ),
            _ => write!(out, "{p} pulses"),
        },
        (Kind::Raw, EllValue::Raw(b)) => {
            fmt_curve(b, out);
            Ok(())
        }
        (_, EllValue::U(x)) => write!(out, "{x}"),
        (_, EllValue::I(x)) => write!(out, "{x}"),
        (_, EllValue::Char(c)) => write!(out, "{c}"),
        (_, EllValue::Digits(d)) => write!(out, "{d}"),
        (_, EllValue::Raw(b)) => write!(out, "<{} bytes>", b.len()),
    };
}

/// `slot 2`, or `≈slot 3` within a tenth of the spacing, or `2.5 slots` in between.
fn fmt_slot(x: f64, out: &mut String) {
    use std::fmt::Write;
    let r = x.round();
    let _ = if x == r {
        write!(out, "slot {r}")
    } else if (x - r).abs() <= 0.1 {
        write!(out, "≈slot {r}")
    } else {
        write!(out, "{} slots", crate::apt::round_sig(x))
    };
}

/// A current curve in one line: points, frequency range, peak current.
fn fmt_curve(b: &[u8], out: &mut String) {
    use std::fmt::Write;
    let pts: Vec<CurvePoint> = curve_points(b).collect();
    let _ = write!(out, "{} points", pts.len());
    let freqs = pts.iter().map(CurvePoint::hz).filter(|f| *f > 0.0);
    let lo = freqs.clone().fold(f64::INFINITY, f64::min);
    let hi = freqs.fold(0.0, f64::max);
    if hi > 0.0 {
        let _ = write!(out, " {:.1}-{:.1} kHz", lo / 1000.0, hi / 1000.0);
    }
    if let Some(peak) = pts.iter().max_by_key(|p| p.current) {
        let _ = write!(
            out,
            ", peak {:.3} A at {:.1} kHz",
            peak.amps(),
            peak.hz() / 1000.0
        );
    }
    let rest = b.len() % CURVE_POINT_BYTES;
    if rest > 0 {
        let _ = write!(out, " (+{rest} bytes)");
    }
}
