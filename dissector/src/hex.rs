//! Streaming decoder of hex text (`53 04 06 00 …`, any whitespace, commas or colons between
//! bytes), like `xxd -r -p`, with a diagnostic for every character that is not a hex digit.

use crate::diag::{Diag, DiagKind};

/// Turns hex text, pushed in any chunking, into bytes.
#[derive(Debug, Default)]
pub struct HexDecoder {
    /// High nibble waiting for its low nibble.
    pending: Option<(u8, u64)>,
    /// Text offset of the next character.
    offset: u64,
    /// Bad characters met after the pending nibble: reported once it is resolved, so
    /// diagnostics stay in offset order.
    held: Vec<Diag>,
}

fn nibble(c: u8) -> Option<u8> {
    match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'a'..=b'f' => Some(c - b'a' + 10),
        b'A'..=b'F' => Some(c - b'A' + 10),
        _ => None,
    }
}

impl HexDecoder {
    /// A decoder at text offset 0.
    pub fn new() -> Self {
        Self::default()
    }

    /// Decode a chunk of text: bytes are appended to `out`, problems to `diags` (with text
    /// offsets). Separators (whitespace, `,`, `:`, `;`) end a byte; anything else that is not a
    /// hex digit gets a `bad_hex` diagnostic and is skipped.
    pub fn push(&mut self, text: &[u8], out: &mut Vec<u8>, diags: &mut Vec<Diag>) {
        for &c in text {
            let at = self.offset;
            self.offset += 1;
            match nibble(c) {
                Some(n) => match self.pending.take() {
                    Some((hi, _)) => {
                        out.push(hi << 4 | n);
                        diags.append(&mut self.held);
                    }
                    None => self.pending = Some((n, at)),
                },
                // A separator ends a byte: a lone digit before it is reported and dropped, so one
                // typo does not shift every later byte by a nibble.
                None if c.is_ascii_whitespace() || matches!(c, b',' | b':' | b';') => {
                    self.resolve_lone(diags);
                }
                None => {
                    let d = Diag {
                        offset: at,
                        kind: DiagKind::BadHex { ch: c as char },
                    };
                    if self.pending.is_some() {
                        self.held.push(d);
                    } else {
                        diags.push(d);
                    }
                }
            }
        }
    }

    /// End of text: a lone last digit is reported.
    pub fn finish(&mut self, diags: &mut Vec<Diag>) {
        self.resolve_lone(diags);
    }

    /// A pending digit with no partner is reported, then what was held behind it.
    fn resolve_lone(&mut self, diags: &mut Vec<Diag>) {
        if let Some((_, at)) = self.pending.take() {
            diags.push(Diag {
                offset: at,
                kind: DiagKind::OddHexDigit,
            });
        }
        diags.append(&mut self.held);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_with_separators_and_reports_bad_chars() {
        let mut d = HexDecoder::new();
        let (mut out, mut diags) = (vec![], vec![]);
        d.push(b"23 02,0", &mut out, &mut diags);
        d.push(b"1 5O 50\n0102f", &mut out, &mut diags);
        d.finish(&mut diags);
        assert_eq!(out, [0x23, 0x02, 0x01, 0x50, 0x01, 0x02]);
        let got: Vec<(u64, DiagKind)> = diags.iter().map(|d| (d.offset, d.kind)).collect();
        assert_eq!(
            got,
            [
                (9, DiagKind::OddHexDigit),
                (10, DiagKind::BadHex { ch: 'O' }),
                (19, DiagKind::OddHexDigit)
            ]
        );
    }

    #[test]
    fn diagnostics_stay_in_offset_order() {
        let mut d = HexDecoder::new();
        let (mut out, mut diags) = (vec![], vec![]);
        d.push(b"5O 5Oa 7", &mut out, &mut diags);
        d.finish(&mut diags);
        let offs: Vec<u64> = diags.iter().map(|x| x.offset).collect();
        assert_eq!(offs, [0, 1, 4, 7], "{diags:?}");
        assert_eq!(out, [0x5a]);
    }
}
