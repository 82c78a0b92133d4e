//! Fixed, platform-independent hashes (std's hasher is randomly seeded): FNV-1a 64 for content
//! keys and partitions, SplitMix64 for deriving seeds. Used wherever a hash must give the same
//! value on every machine and run (shards, cache keys, per-episode seeds, plot jitter).

/// Streaming 64-bit FNV-1a; the current value is `.0`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fnv(pub u64);

impl Default for Fnv {
    fn default() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv {
    /// Feeds bytes.
    pub fn eat(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }

    /// Feeds the little-endian bit patterns of `xs`.
    pub fn eat_f64s(&mut self, xs: &[f64]) {
        for x in xs {
            self.eat(&x.to_bits().to_le_bytes());
        }
    }
}

/// 64-bit FNV-1a of `bytes`.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h = Fnv::default();
    h.eat(bytes);
    h.0
}

/// The SplitMix64 finalizer.
pub fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_values() {
        // FNV-1a 64 test vectors.
        assert_eq!(fnv1a64(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a64(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(fnv1a64(b"foobar"), 0x8594_4171_f739_67e8);
        let mut h = Fnv::default();
        h.eat(b"foo");
        h.eat(b"bar");
        assert_eq!(h.0, fnv1a64(b"foobar"));
        // SplitMix64 of 0 (first output of the generator seeded with 0).
        assert_eq!(splitmix64(0), 0xe220_a839_7b1d_cdaf);
    }
}
