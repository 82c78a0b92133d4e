//! Axis ranges, tick positions and tick labels, computed here rather than left to plotters so
//! that both scales behave the same way and the choice is testable: linear axes get 1-2-5 steps,
//! log axes get 1-2-5 multiples of powers of ten (thinned to whole decades when the range is
//! wide), and labels are the shortest decimal that tells neighbouring ticks apart.

use serde::Serialize;

/// Axis scale.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Scale {
    /// Linear, with 1-2-5 tick steps.
    Linear,
    /// Base-10 logarithmic; non-positive values are drawn at the axis minimum.
    Log,
}

/// The target number of ticks on an axis.
const TARGET_TICKS: f64 = 6.0;

/// Relative padding added on each side of a linear data range.
const LINEAR_PAD: f64 = 0.05;

/// Factor added on each side of a log data range (×/÷).
const LOG_PAD: f64 = 1.15;

/// The drawn range of an axis holding the finite values `lo..=hi` (for a log axis, positive
/// values). A range starting at exactly 0 keeps 0 as its lower end; a degenerate range is
/// widened so that the data stays visible.
pub fn padded_range(scale: Scale, lo: f64, hi: f64) -> (f64, f64) {
    match scale {
        Scale::Linear => {
            let span = hi - lo;
            if lo == 0.0 && span > 0.0 {
                // Counts and fractions start at 0: keep the axis there.
                (0.0, hi + LINEAR_PAD * span)
            } else if span <= 0.0 {
                let half = if lo == 0.0 { 1.0 } else { 0.5 * lo.abs() };
                (lo - half, hi + half)
            } else {
                (lo - LINEAR_PAD * span, hi + LINEAR_PAD * span)
            }
        }
        Scale::Log => {
            if hi <= lo {
                (lo / 2.0, hi * 2.0)
            } else {
                (lo / LOG_PAD, hi * LOG_PAD)
            }
        }
    }
}

/// A "nice" step (1, 2 or 5 times a power of ten) near `raw`, as (mantissa, exponent).
fn nice_step(raw: f64) -> (f64, i32) {
    let exp = raw.log10().floor() as i32;
    let frac = raw / 10f64.powi(exp);
    let m = if frac <= 1.5 {
        1.0
    } else if frac <= 3.5 {
        2.0
    } else if frac <= 7.5 {
        5.0
    } else {
        return (1.0, exp + 1);
    };
    (m, exp)
}

/// `m · 10^e` as the double closest to the decimal (no accumulated rounding).
fn decimal(m: f64, e: i32) -> f64 {
    format!("{m}e{e}").parse().unwrap_or(m * 10f64.powi(e))
}

/// Tick positions inside `lo..=hi`; `integer`: only whole numbers (counts, view numbers).
pub fn ticks(scale: Scale, lo: f64, hi: f64, integer: bool) -> Vec<f64> {
    let t = match scale {
        Scale::Linear => linear_ticks(lo, hi, integer),
        Scale::Log => log_ticks(lo, hi),
    };
    if integer {
        let whole: Vec<f64> = t.iter().copied().filter(|v| v.fract() == 0.0).collect();
        if !whole.is_empty() {
            return whole;
        }
    }
    t
}

fn linear_ticks(lo: f64, hi: f64, integer: bool) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return vec![lo];
    }
    let (m, e) = nice_step((hi - lo) / TARGET_TICKS);
    let (m, e) = if integer && e < 0 { (1.0, 0) } else { (m, e) };
    let step = decimal(m, e);
    let first = (lo / step).ceil() as i64;
    let last = (hi / step).floor() as i64;
    (first..=last)
        .map(|k| {
            // k·step as a decimal: k·m·10^e, exact for the integers involved.
            decimal(k as f64 * m, e)
        })
        .collect()
}

fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo || lo <= 0.0 {
        return vec![lo];
    }
    let e_lo = lo.log10().floor() as i32;
    let e_hi = hi.log10().ceil() as i32;
    let decades = (hi / lo).log10();
    // Multiples per decade: 1-2-5 for short ranges, only powers of ten for wide ones (thinned
    // further to every k-th decade when even those are too many).
    let mantissas: &[f64] = if decades <= 3.5 { &[1.0, 2.0, 5.0] } else { &[1.0] };
    let every = if decades > 2.0 * TARGET_TICKS { (decades / TARGET_TICKS).ceil() as i32 } else { 1 };
    let mut out = Vec::new();
    for e in e_lo..=e_hi {
        if mantissas.len() == 1 && e.rem_euclid(every) != 0 {
            continue;
        }
        for &m in mantissas {
            let v = decimal(m, e);
            if v >= lo * (1.0 - 1e-12) && v <= hi * (1.0 + 1e-12) {
                out.push(v);
            }
        }
    }
    if out.len() < 2 {
        // Less than one 1-2-5 step inside: label both ends instead.
        out = vec![lo, hi];
    }
    out
}

/// The label of tick value `v`: scientific notation (`2e-4`) for very small or large magnitudes,
/// otherwise the fewest decimals that still give `v` back (`0.25`, `20`).
pub fn label(v: f64) -> String {
    if v == 0.0 {
        return "0".to_string();
    }
    let a = v.abs();
    if !(1e-3..1e6).contains(&a) {
        return format!("{v:e}");
    }
    for decimals in 0..=6 {
        let s = format!("{v:.decimals$}");
        if (s.parse::<f64>().unwrap_or(f64::NAN) - v).abs() <= 1e-9 * a.max(1.0) {
            return s;
        }
    }
    format!("{v}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_ticks_are_1_2_5_steps_inside_the_range() {
        assert_eq!(linear_ticks(0.0, 1.0, false), vec![0.0, 0.2, 0.4, 0.6, 0.8, 1.0]);
        assert_eq!(linear_ticks(0.0, 2.1, true), vec![0.0, 1.0, 2.0]);
        assert_eq!(ticks(Scale::Linear, 0.0, 2.1, true), vec![0.0, 1.0, 2.0]);
        assert_eq!(ticks(Scale::Log, 0.5, 30.0, true), vec![1.0, 2.0, 5.0, 10.0, 20.0]);
        assert_eq!(linear_ticks(-3.0, 131.0, false), vec![0.0, 20.0, 40.0, 60.0, 80.0, 100.0, 120.0]);
        assert_eq!(linear_ticks(0.5, 5.5, false), vec![1.0, 2.0, 3.0, 4.0, 5.0]);
    }

    #[test]
    fn log_ticks_use_1_2_5_on_short_ranges_and_decades_on_wide_ones() {
        assert_eq!(log_ticks(5.0, 500.0), vec![5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0]);
        assert_eq!(log_ticks(1e-7, 1.0), vec![1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0]);
        assert_eq!(log_ticks(3.0, 4.0), vec![3.0, 4.0]);
    }

    #[test]
    fn labels_are_short_and_exact() {
        let l: Vec<String> = [0.0, 0.2, 0.4, 0.6, 0.8, 1.0].iter().map(|&v| label(v)).collect();
        assert_eq!(l, ["0", "0.2", "0.4", "0.6", "0.8", "1"]);
        let l: Vec<String> = [1e-5, 2e-4, 1e-3, 0.01, 0.25].iter().map(|&v| label(v)).collect();
        assert_eq!(l, ["1e-5", "2e-4", "0.001", "0.01", "0.25"]);
        assert_eq!(label(20.0), "20");
        assert_eq!(label(2_500_000.0), "2.5e6");
        assert_eq!(label(-1.5), "-1.5");
    }

    #[test]
    fn padded_ranges_widen_degenerate_data() {
        assert_eq!(padded_range(Scale::Linear, 0.0, 10.0), (0.0, 10.5));
        assert_eq!(padded_range(Scale::Linear, -10.0, 10.0), (-11.0, 11.0));
        assert_eq!(padded_range(Scale::Linear, 4.0, 4.0), (2.0, 6.0));
        assert_eq!(padded_range(Scale::Linear, 0.0, 0.0), (-1.0, 1.0));
        let (a, b) = padded_range(Scale::Log, 6.0, 492.0);
        assert!((a - 6.0 / 1.15).abs() < 1e-12 && (b - 492.0 * 1.15).abs() < 1e-9);
    }
}
