//! A fast hasher for maps keyed by small numbers and tuples of them (message ids, record
//! numbers, addresses), where SipHash's protection against chosen keys buys nothing and costs
//! a noticeable share of pairing and indexing. The mixing is FxHash's (rustc's own): one
//! rotate, xor and multiply per word.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// The hasher (see the module documentation).
#[derive(Default, Clone, Copy, Debug)]
pub struct NumHasher(u64);

const K: u64 = 0x517c_c1b7_2722_0a95;

impl NumHasher {
    #[inline]
    fn add(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(K);
    }
}

impl Hasher for NumHasher {
    #[inline]
    fn finish(&self) -> u64 {
        self.0
    }
    #[inline]
    fn write(&mut self, bytes: &[u8]) {
        let mut words = bytes.chunks_exact(8);
        for w in &mut words {
            let mut b = [0u8; 8];
            b.copy_from_slice(w);
            self.add(u64::from_le_bytes(b));
        }
        // The last bytes as one word (a short text is then two or three steps, not one a byte).
        let rest = words.remainder();
        if !rest.is_empty() {
            let mut b = [0u8; 8];
            b[..rest.len()].copy_from_slice(rest);
            self.add(u64::from_le_bytes(b));
        }
    }
    #[inline]
    fn write_u8(&mut self, x: u8) {
        self.add(u64::from(x));
    }
    #[inline]
    fn write_u16(&mut self, x: u16) {
        self.add(u64::from(x));
    }
    #[inline]
    fn write_u32(&mut self, x: u32) {
        self.add(u64::from(x));
    }
    #[inline]
    fn write_u64(&mut self, x: u64) {
        self.add(x);
    }
    #[inline]
    fn write_usize(&mut self, x: usize) {
        self.add(x as u64);
    }
}

/// A `HashMap` with [`NumHasher`].
pub type NumMap<K, V> = HashMap<K, V, BuildHasherDefault<NumHasher>>;

#[cfg(test)]
mod tests {
    use super::*;

    /// Distinct small keys spread over the buckets and the tag bits hashbrown reads.
    #[test]
    fn small_keys_spread() {
        let hash = |x: u64| {
            let mut h = NumHasher::default();
            h.write_u64(x);
            h.finish()
        };
        let low: std::collections::HashSet<u64> = (0..4096).map(|x| hash(x) & 4095).collect();
        let top: std::collections::HashSet<u64> = (0..4096).map(|x| hash(x) >> 57).collect();
        assert!(low.len() > 4000, "{}", low.len());
        assert_eq!(top.len(), 128);
        let mut m: NumMap<(u16, u8, Option<i64>), u32> = NumMap::default();
        m.insert((1, 2, Some(3)), 4);
        assert_eq!(m.get(&(1, 2, Some(3))), Some(&4));
        assert_eq!(m.get(&(1, 2, None)), None);
    }
}
