//! Per-axis arithmetic of the walks: which cell a ray is in at a given time, the next plane
//! crossing, and float helpers that avoid libm calls and NaN handling in hot loops. Small pure
//! functions whose exact agreement (tested) is what lets the fast walk reproduce the plain one.

/// The cell `g ∈ [0, n)` with `p[g] ≤ 0 < p[g+1]`, clamped (callers ensure it exists).
#[inline]
pub(super) fn camera_cell(p: &[f64], r: f64, n: usize) -> usize {
    // A guess (truncation is a floor for the non-negative values that matter), then exact
    // fix-up against the planes.
    let mut g = ((-p[0] / r) as i64).clamp(0, n as i64 - 1) as usize;
    while g > 0 && p[g] > 0.0 {
        g -= 1;
    }
    while g + 1 < n && p[g + 1] <= 0.0 {
        g += 1;
    }
    g
}

/// Time of the next plane crossing out of cell `g` along an axis.
#[inline]
pub(super) fn next_crossing(p: &[f64], inv: f64, step: i8, g: usize) -> f64 {
    match step {
        1 => p[g + 1] * inv,
        -1 => p[g] * inv,
        _ => f64::INFINITY,
    }
}

/// The walk's cell along one axis at time `t`: the state after every crossing at time ≤ t
/// (`INCLUSIVE`) or < t, searched in `[lo, hi]`. The crossing into cell g is at `p[g]·inv`
/// moving up and at `p[g+1]·inv` moving down; crossing times are monotone in g.
#[allow(clippy::too_many_arguments)]
#[inline]
pub(super) fn cell_at<const INCLUSIVE: bool>(
    p: &[f64],
    inv: f64,
    step: i8,
    d: f64,
    r: f64,
    t: f64,
    lo: usize,
    hi: usize,
) -> usize {
    let done = |c: f64| if INCLUSIVE { c <= t } else { c < t };
    // Guess from the position (truncation; the fix-up below makes it exact).
    let mut g = (((t * d - p[0]) / r) as i64).clamp(lo as i64, hi as i64) as usize;
    if step > 0 {
        while g > lo && !done(p[g] * inv) {
            g -= 1;
        }
        while g < hi && done(p[g + 1] * inv) {
            g += 1;
        }
    } else {
        while g < hi && !done(p[g + 1] * inv) {
            g += 1;
        }
        while g > lo && done(p[g] * inv) {
            g -= 1;
        }
    }
    g
}

/// [`cell_at`] for an axis walked upwards (`p` increasing, crossing into cell g at `p[g]·s`,
/// `s` > 0; `ad` = |d|): the cell after every crossing at time < t, searched in `[lo, hi]`.
/// The crossing times are non-decreasing in g, so "crossed before t" holds for a prefix of
/// cells and the answer — the last crossed cell, clamped to `[lo, hi]` — is unique, whatever
/// the guess the fix-up loops start from. `t` and the plane times are never NaN.
#[inline(always)]
pub(super) fn up_cell(p: &[f64], s: f64, ad: f64, inv_r: f64, t: f64, lo: usize, hi: usize) -> usize {
    let mut g = (((t * ad - p[0]) * inv_r) as i64).clamp(lo as i64, hi as i64) as usize;
    while g > lo && p[g] * s >= t {
        g -= 1;
    }
    while g < hi && p[g + 1] * s < t {
        g += 1;
    }
    g
}

/// [`up_cell`] over the whole axis (`p` holds the n + 1 planes of n cells) and the time of the
/// next crossing out of that cell, `p[g + 1]·s`: the same cell, with the common case — the
/// guess is right — checked by one pair of comparisons.
#[inline(always)]
pub(super) fn start_cell(p: &[f64], s: f64, ad: f64, inv_r: f64, t: f64) -> (usize, f64) {
    let hi = p.len() - 2;
    let g = (((t * ad - p[0]) * inv_r) as i64).clamp(0, hi as i64) as usize;
    let w = &p[g..g + 2];
    let next = w[1] * s;
    if (g == 0 || w[0] * s < t) && (g == hi || next >= t) {
        return (g, next);
    }
    let g = up_cell(p, s, ad, inv_r, t, 0, hi);
    (g, p[g + 1] * s)
}

/// The smallest f64 above `x` (`f64::next_up`, newer than the MSRV); NaN and +∞ map to
/// themselves.
#[inline]
pub(super) fn next_up(x: f64) -> f64 {
    if x.is_nan() || x == f64::INFINITY {
        x
    } else if x == 0.0 {
        f64::from_bits(1)
    } else if x > 0.0 {
        f64::from_bits(x.to_bits() + 1)
    } else {
        f64::from_bits(x.to_bits() - 1)
    }
}

/// `a.max(b)` for non-NaN operands without the NaN handling (`maxsd` alone). Which zero it
/// returns for ±0 may differ; callers only compare the result.
#[inline(always)]
pub(super) fn fmax(a: f64, b: f64) -> f64 {
    if a > b {
        a
    } else {
        b
    }
}

/// `a.min(b)` for non-NaN operands, as [`fmax`].
#[inline(always)]
pub(super) fn fmin(a: f64, b: f64) -> f64 {
    if a < b {
        a
    } else {
        b
    }
}
