//! Synthetic APT traffic from the table, for tests, benchmarks and demos: a small deterministic
//! RNG and random valid frames of any message form.

use crate::apt::{encode, FieldValue};
use crate::table::{Form, FormKind, MsgDef, Prim, Table, Ty};

/// SplitMix64: deterministic, seedable, good enough for test data.
#[derive(Debug, Clone)]
pub struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// A value in `0..n` (0 when `n` is 0).
    pub fn below(&mut self, n: u64) -> u64 {
        if n == 0 {
            0
        } else {
            self.next_u64() % n
        }
    }
}

/// A random value of a scalar type (floats exactly representable in f32).
pub fn prim_value(r: &mut Rng, p: Prim) -> f64 {
    match p {
        Prim::U8 => r.below(256) as f64,
        Prim::I8 => (r.below(256) as i64 - 128) as f64,
        Prim::U16 => r.below(65536) as f64,
        Prim::I16 => (r.below(65536) as i64 - 32768) as f64,
        Prim::U32 => r.below(1 << 32) as f64,
        Prim::I32 => ((r.below(1 << 32) as i64) - (1 << 31)) as f64,
        // Values exactly representable in f32.
        Prim::F32 => (r.below(1 << 20) as f64 - (1 << 19) as f64) / 64.0,
    }
}

/// Random values for every non-pad field of `form`.
pub fn random_values(table: &Table, r: &mut Rng, form: &Form) -> Vec<(&'static str, FieldValue)> {
    let mut v = vec![];
    for f in &form.fields {
        let val = match f.ty {
            Ty::Pad(_) => continue,
            Ty::Prim(p) => {
                if let (Some(e), true) = (f.enumeration, r.below(2) == 0) {
                    let items = &table.enum_def(e).items;
                    let (x, _) = items[r.below(items.len() as u64) as usize];
                    // An enum value outside the field's range cannot be sent; fall back.
                    if fits(p, x) {
                        FieldValue::Int(x)
                    } else {
                        FieldValue::Int(prim_value(r, p) as i64)
                    }
                } else if p == Prim::F32 {
                    FieldValue::Float(prim_value(r, p))
                } else {
                    FieldValue::Int(prim_value(r, p) as i64)
                }
            }
            // An open array: a few whole rows' worth of elements.
            Ty::Array(p, 0) => {
                FieldValue::List((0..r.below(13) * 3).map(|_| prim_value(r, p)).collect())
            }
            Ty::Array(p, n) => FieldValue::List((0..n).map(|_| prim_value(r, p)).collect()),
            Ty::Str(n) => {
                let len = r.below(n as u64 + 1) as usize;
                FieldValue::Text(
                    (0..len)
                        .map(|_| (b'A' + r.below(26) as u8) as char)
                        .collect(),
                )
            }
            Ty::Bytes(n) => FieldValue::Bytes((0..n).map(|_| r.below(256) as u8).collect()),
        };
        v.push((f.name, val));
    }
    v
}

/// Whether `x` fits the scalar type.
pub fn fits(p: Prim, x: i64) -> bool {
    match p {
        Prim::U8 => (0..=255).contains(&x),
        Prim::I8 => (-128..=127).contains(&x),
        Prim::U16 => (0..=65535).contains(&x),
        Prim::I16 => (-32768..=32767).contains(&x),
        Prim::U32 => (0..=u32::MAX as i64).contains(&x),
        Prim::I32 => (i32::MIN as i64..=i32::MAX as i64).contains(&x),
        Prim::F32 => true,
    }
}

/// Every encodable (message, form, sub-id) of the table: header and data forms of messages,
/// and for messages with `form sub`, every data form of every sub of the group.
pub fn all_forms(table: &Table) -> Vec<(&MsgDef, &Form, Option<u16>)> {
    let mut out = vec![];
    for m in table.msgs() {
        for f in &m.forms {
            match f.kind {
                FormKind::Sub => {
                    for s in table.subs().iter().filter(|s| Some(s.group) == m.subs) {
                        for sf in s
                            .forms
                            .iter()
                            .filter(|sf| matches!(sf.kind, FormKind::Data(_)))
                        {
                            out.push((m, sf, Some(s.id)));
                        }
                    }
                }
                _ => out.push((m, f, None)),
            }
        }
    }
    out
}

/// Random addresses from the spec's address space.
pub fn random_addr(r: &mut Rng) -> u8 {
    const A: [u8; 13] = [
        0x01, 0x11, 0x21, 0x22, 0x23, 0x24, 0x25, 0x26, 0x27, 0x28, 0x29, 0x2A, 0x50,
    ];
    A[r.below(A.len() as u64) as usize]
}

/// Encode one random frame of the given form.
pub fn random_frame(
    table: &Table,
    r: &mut Rng,
    m: &MsgDef,
    form: &Form,
    sub: Option<u16>,
) -> (Vec<u8>, Vec<(&'static str, FieldValue)>) {
    let mut vals = random_values(table, r, form);
    if let Some(id) = sub {
        for (k, v) in vals.iter_mut() {
            if *k == "sub_id" {
                *v = FieldValue::Int(id as i64);
            }
        }
    } else if m.subs.is_some() && form.kind == FormKind::Header {
        // A header-only request of a sub group carries a sub id the table knows.
        let subs: Vec<u16> = table
            .subs()
            .iter()
            .filter(|s| Some(s.group) == m.subs && s.id < 256)
            .map(|s| s.id)
            .collect();
        if let Some(&id) = subs.get(r.below(subs.len() as u64) as usize) {
            for (k, v) in vals.iter_mut() {
                if *k == "sub_id" {
                    *v = FieldValue::Int(id as i64);
                }
            }
        }
    }
    // Values are drawn within each field's range, so encoding cannot fail; an empty frame would
    // show up in every test that uses this.
    let bytes = encode(form, &vals, m.id, random_addr(r), random_addr(r)).unwrap_or_default();
    (bytes, vals)
}

/// A stream of `n` random frames of every form, with garbage between some when `garbage`.
pub fn stream(table: &Table, seed: u64, n: usize, garbage: bool) -> Vec<u8> {
    let forms = all_forms(table);
    let mut r = Rng(seed);
    let mut out = vec![];
    for _ in 0..n {
        if garbage && r.below(4) == 0 {
            for _ in 0..r.below(12) {
                out.push(r.below(256) as u8);
            }
        }
        let (m, form, sub) = forms[r.below(forms.len() as u64) as usize];
        out.extend(random_frame(table, &mut r, m, form, sub).0);
    }
    out
}
