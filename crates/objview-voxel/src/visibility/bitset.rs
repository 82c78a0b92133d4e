//! Bitsets over set indices (one bit per S_gt voxel) and the helpers the annotations and set
//! cover use on them: conversion to and from sorted index lists, unions, per-voxel view counts.

/// A bitset of `len` bits (`len.div_ceil(64)` words) with the given indices set.
/// Panics on an index ≥ `len`.
pub fn to_bitset(indices: &[u32], len: usize) -> Vec<u64> {
    let mut bits = vec![0u64; len.div_ceil(64)];
    for &i in indices {
        assert!((i as usize) < len, "index {i} out of range {len}");
        bits[i as usize >> 6] |= 1u64 << (i & 63);
    }
    bits
}

/// The set indices of a bitset, ascending.
pub fn bitset_to_indices(bits: &[u64]) -> Vec<u32> {
    let n: u32 = bits.iter().map(|w| w.count_ones()).sum();
    let mut out = Vec::with_capacity(n as usize);
    for (wi, &w) in bits.iter().enumerate() {
        let mut w = w;
        while w != 0 {
            out.push((wi * 64) as u32 + w.trailing_zeros());
            w &= w - 1;
        }
    }
    out
}

/// `acc |= other`, word by word (`other` may be shorter).
pub fn union_into(acc: &mut [u64], other: &[u64]) {
    for (a, b) in acc.iter_mut().zip(other) {
        *a |= *b;
    }
}

/// Union of sorted index lists, sorted unique.
pub fn union(lists: &[Vec<u32>]) -> Vec<u32> {
    let mut all: Vec<u32> = lists.iter().flatten().copied().collect();
    all.sort_unstable();
    all.dedup();
    all
}

/// Union of bitsets of `len` bits.
pub fn union_bitsets(sets: &[Vec<u64>], len: usize) -> Vec<u64> {
    let mut acc = vec![0u64; len.div_ceil(64)];
    for s in sets {
        union_into(&mut acc, s);
    }
    acc
}

/// For each of `len` voxels, the number of bitsets (views) containing it — for the SPEC §4
/// option of keeping only voxels seen by at least k views.
pub fn coverage_counts(sets: &[Vec<u64>], len: usize) -> Vec<u32> {
    let mut counts = vec![0u32; len];
    for s in sets {
        for i in bitset_to_indices(s) {
            counts[i as usize] += 1;
        }
    }
    counts
}

/// Number of set bits.
pub fn bitset_count(bits: &[u64]) -> usize {
    bits.iter().map(|w| w.count_ones() as usize).sum()
}
