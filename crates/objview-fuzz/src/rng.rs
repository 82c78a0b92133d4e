//! The fuzzer's random numbers: SplitMix64, a tiny generator with a fixed, platform-independent
//! output, so that a seed names the same sequence of cases on every machine and in every
//! version of the dependencies (no `rand` algorithm changes can move it).

use objview_geom::hash::{fnv1a64, splitmix64};

/// A SplitMix64 stream.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// A stream from a seed.
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }

    /// The stream of case `index` of `kind` under the run seed `seed`: independent of every
    /// other case, so the cases can be generated in any order and by any number of workers.
    pub fn for_case(seed: u64, kind: &str, index: u64) -> Rng {
        let k = fnv1a64(kind.as_bytes());
        Rng(splitmix64(splitmix64(seed ^ k).wrapping_add(index)))
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in `0..n` (0 when `n` is 0).
    pub fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            return 0;
        }
        ((self.next_u64() as u128 * n as u128) >> 64) as usize
    }

    /// Uniform in `lo..=hi`.
    pub fn range(&mut self, lo: usize, hi: usize) -> usize {
        lo + self.below(hi - lo + 1)
    }

    /// True with probability `num / den`.
    pub fn chance(&mut self, num: usize, den: usize) -> bool {
        self.below(den) < num
    }

    /// A random element of a non-empty slice.
    pub fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }

    /// A length biased towards small values: `1..=max`, each halving of the range about as
    /// likely as the next.
    pub fn small_len(&mut self, max: usize) -> usize {
        let max = max.max(1);
        let bits = usize::BITS - max.leading_zeros();
        let cap = (1usize << self.below(bits as usize + 1)).min(max);
        self.range(1, cap)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_fixed_and_independent() {
        // SplitMix64 of state 0: published first output.
        assert_eq!(Rng::new(0).next_u64(), 0xe220_a839_7b1d_cdaf);
        let a: Vec<u64> = (0..4).map(|i| Rng::for_case(1, "obj", i).next_u64()).collect();
        let b: Vec<u64> = (0..4).map(|i| Rng::for_case(1, "obj", i).next_u64()).collect();
        assert_eq!(a, b);
        assert_ne!(Rng::for_case(1, "obj", 0).next_u64(), Rng::for_case(1, "ply", 0).next_u64());
        assert_ne!(Rng::for_case(1, "obj", 0).next_u64(), Rng::for_case(2, "obj", 0).next_u64());
        let mut r = Rng::new(5);
        for _ in 0..1000 {
            assert!(r.below(7) < 7);
            let l = r.small_len(100);
            assert!((1..=100).contains(&l));
        }
    }
}
