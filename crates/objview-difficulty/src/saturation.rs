//! Observation saturation (SPEC §4, paper §3.2): from the raw curve Y(N) to N*, d_sat and r_vis.
//!
//! Tammes sets of different sizes are not nested, so the raw curve Y(N) need not be monotone. SPEC
//! §4 therefore (1) takes its running maximum Y_m, (2) fits a lognormal CDF
//! Ŷ(N) = y_max·Φ((ln N − μ)/σ) with y_max = Y_m(N_max) by least squares of ln N on
//! z = Φ⁻¹(clamped Y_m/y_max), and (3) defines the saturation point N* as the smallest N from which
//! the fitted curve gains at most `plateau_tol·|S_gt|` voxels per `plateau_step` views at every probe
//! N, N + 5, …, N + 20 (capped at N_max). d_sat = round(N*), r_vis = Ŷ(N*)/|S_gt|.
//!
//! Choices where SPEC §4 is silent (all documented on the items below):
//! - y_max = 0 (nothing observed) is an error: the normalization Y_m/y_max is undefined.
//! - var(z) = 0 happens exactly when every p_i clamps to 1 − p_clamp, i.e. the curve is already at
//!   its maximum at N_min. The fit then takes σ = min_sigma and places the step so that the fitted
//!   curve passes through the first point (μ = ln N_min − σ·z), which makes N* = N_min.
//! - N* search: if the plateau predicate holds at N_min, N* = N_min (literally the smallest N); if
//!   it fails at N_max, N* = N_max (no plateau inside the grid: the object saturates at or beyond
//!   the largest view set). Otherwise bisection keeps "fails at lo, holds at hi" and returns hi.

use serde::{Deserialize, Serialize};

use crate::error::DifficultyError;
use crate::grid::SATURATION_GRID;
use crate::normal::{norm_cdf, norm_inv_cdf};

/// Curve fractions are clamped to [P_CLAMP, 1 − P_CLAMP] before Φ⁻¹.
pub const P_CLAMP: f64 = 1e-4;
/// Lower bound on the fitted σ.
pub const MIN_SIGMA: f64 = 1e-6;
/// Number of bisection halvings of [N_min, N_max] in the search for N*.
pub const BISECTION_STEPS: u32 = 80;
/// The plateau gain is measured over N' → N' + PLATEAU_STEP views.
pub const PLATEAU_STEP: f64 = 10.0;
/// Probe points N' = N, N + PROBE_STRIDE, … .
pub const PROBE_STRIDE: f64 = 5.0;
/// Probe points go up to N + PROBE_SPAN (and never beyond N_max).
pub const PROBE_SPAN: f64 = 20.0;
/// Maximum gain per plateau step, as a fraction of |S_gt|.
pub const PLATEAU_TOL: f64 = 2e-4;
/// An object is slow-saturating when d_sat exceeds this many views.
pub const SLOW_SATURATION_THRESHOLD: usize = 128;

/// All constants of the saturation analysis, recorded with every result.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SaturationSettings {
    /// Clamp of the fractions p_i before Φ⁻¹, to [p_clamp, 1 − p_clamp]; in (0, ½].
    pub p_clamp: f64,
    /// Lower bound on the fitted σ; > 0.
    pub min_sigma: f64,
    /// Bisection halvings in the search for N*.
    pub bisection_steps: u32,
    /// Width (in views) of the gain measured at each probe; > 0.
    pub plateau_step: f64,
    /// Spacing of the probes; > 0.
    pub probe_stride: f64,
    /// Probes cover [N, N + probe_span] ∩ [N, N_max]; ≥ 0.
    pub probe_span: f64,
    /// Allowed gain per plateau step as a fraction of |S_gt|; ≥ 0.
    pub plateau_tol: f64,
    /// d_sat above this marks a slow-saturation object.
    pub slow_saturation_threshold: usize,
}

impl Default for SaturationSettings {
    fn default() -> Self {
        Self {
            p_clamp: P_CLAMP,
            min_sigma: MIN_SIGMA,
            bisection_steps: BISECTION_STEPS,
            plateau_step: PLATEAU_STEP,
            probe_stride: PROBE_STRIDE,
            probe_span: PROBE_SPAN,
            plateau_tol: PLATEAU_TOL,
            slow_saturation_threshold: SLOW_SATURATION_THRESHOLD,
        }
    }
}

impl SaturationSettings {
    /// Checks every setting's range.
    pub fn validate(&self) -> Result<(), DifficultyError> {
        let check = |name, value: f64, ok: bool, reason| {
            if ok {
                Ok(())
            } else {
                Err(DifficultyError::InvalidSetting { name, value, reason })
            }
        };
        let p = self.p_clamp;
        check("p_clamp", p, p > 0.0 && p <= 0.5, "must be in (0, 0.5]")?;
        let s = self.min_sigma;
        check("min_sigma", s, s > 0.0 && s.is_finite(), "must be positive and finite")?;
        let w = self.plateau_step;
        check("plateau_step", w, w > 0.0 && w.is_finite(), "must be positive and finite")?;
        let d = self.probe_stride;
        check("probe_stride", d, d > 0.0 && d.is_finite(), "must be positive and finite")?;
        let span = self.probe_span;
        check("probe_span", span, span >= 0.0 && span.is_finite(), "must be non-negative and finite")?;
        let tol = self.plateau_tol;
        check("plateau_tol", tol, tol >= 0.0 && tol.is_finite(), "must be non-negative and finite")?;
        Ok(())
    }
}

/// One point of the raw saturation curve: Y = |∪_{v ∈ tammes-N} O(v)|.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CurvePoint {
    /// View-set size N.
    pub n: usize,
    /// Observed voxel count Y(N) (a count; real-valued so that synthetic curves can be fitted).
    pub y: f64,
}

impl CurvePoint {
    /// A curve point.
    pub fn new(n: usize, y: f64) -> Self {
        Self { n, y }
    }
}

/// The raw curve over [`SATURATION_GRID`] from one count per grid size.
pub fn curve_on_grid(counts: &[usize]) -> Result<Vec<CurvePoint>, DifficultyError> {
    if counts.len() != SATURATION_GRID.len() {
        return Err(DifficultyError::GridLength { expected: SATURATION_GRID.len(), got: counts.len() });
    }
    Ok(SATURATION_GRID.iter().zip(counts).map(|(&n, &y)| CurvePoint::new(n, y as f64)).collect())
}

/// Running maximum Y_m(N_i) = max_{j ≤ i} Y(N_j).
pub fn running_max(ys: &[f64]) -> Vec<f64> {
    let mut acc = f64::NEG_INFINITY;
    ys.iter()
        .map(|&y| {
            acc = acc.max(y);
            acc
        })
        .collect()
}

/// The fitted curve Ŷ(N) = y_max·Φ((ln N − μ)/σ).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LognormalFit {
    /// Location μ of ln N.
    pub mu: f64,
    /// Scale σ of ln N (≥ min_sigma).
    pub sigma: f64,
    /// Asymptote y_max = Y_m(N_max).
    pub y_max: f64,
    /// True when var(z) = 0 (every fraction clamped to 1 − p_clamp) and the documented fallback
    /// σ = min_sigma, μ = ln N_min − σ·z was used.
    pub degenerate: bool,
}

impl LognormalFit {
    /// Ŷ(N) for a real N > 0.
    pub fn eval(&self, n: f64) -> f64 {
        self.y_max * norm_cdf((n.ln() - self.mu) / self.sigma)
    }

    /// The plateau predicate of SPEC §4 at N: for every probe N' ∈ {N, N + stride, …} with
    /// N' ≤ min(n_max, N + span), Ŷ(N' + step) − Ŷ(N') ≤ tol·|S_gt|. (N' + step may exceed
    /// n_max: the fitted curve is evaluated beyond the grid.)
    pub fn plateau_holds(&self, n: f64, n_max: f64, s_gt: usize, settings: &SaturationSettings) -> bool {
        let limit = n_max.min(n + settings.probe_span);
        let allowed = settings.plateau_tol * s_gt as f64;
        let mut k = 0u32;
        loop {
            // n + k·stride rather than repeated addition, so that N + 20 is hit exactly.
            let probe = n + f64::from(k) * settings.probe_stride;
            if probe > limit {
                return true;
            }
            if self.eval(probe + settings.plateau_step) - self.eval(probe) > allowed {
                return false;
            }
            k += 1;
        }
    }
}

/// Least-squares fit of SPEC §4 on the running-max curve: p_i = clamp(Y_m(N_i)/y_max),
/// z_i = Φ⁻¹(p_i), σ = max(cov(x, z)/var(z), min_sigma), μ = mean(x) − σ·mean(z), x_i = ln N_i.
///
/// `ns` must be strictly increasing and positive, `ym` non-decreasing (a running maximum) with
/// ym.last() = y_max > 0; `saturation` checks this, this function only requires equal lengths ≥ 1
/// and y_max > 0.
pub fn fit_lognormal(
    ns: &[usize],
    ym: &[f64],
    settings: &SaturationSettings,
) -> Result<LognormalFit, DifficultyError> {
    assert_eq!(ns.len(), ym.len(), "one running-max value per view-set size");
    let y_max = *ym.last().ok_or(DifficultyError::CurveTooShort { len: 0 })?;
    if y_max.is_nan() || y_max <= 0.0 {
        return Err(DifficultyError::NothingObserved);
    }
    let (lo, hi) = (settings.p_clamp, 1.0 - settings.p_clamp);
    let x: Vec<f64> = ns.iter().map(|&n| (n as f64).ln()).collect();
    let z: Vec<f64> = ym.iter().map(|&y| norm_inv_cdf((y / y_max).clamp(lo, hi))).collect();
    let len = x.len() as f64;
    let mean_x = x.iter().sum::<f64>() / len;
    let mean_z = z.iter().sum::<f64>() / len;
    // Exact test on the inputs: with all z equal, the centred sums below would be rounding noise.
    if z.iter().all(|&zi| zi == z[0]) {
        let sigma = settings.min_sigma;
        return Ok(LognormalFit { mu: x[0] - sigma * z[0], sigma, y_max, degenerate: true });
    }
    let (mut sxz, mut szz) = (0.0, 0.0);
    for (xi, zi) in x.iter().zip(&z) {
        sxz += (xi - mean_x) * (zi - mean_z);
        szz += (zi - mean_z) * (zi - mean_z);
    }
    let sigma = (sxz / szz).max(settings.min_sigma);
    Ok(LognormalFit { mu: mean_x - sigma * mean_z, sigma, y_max, degenerate: false })
}

/// N* in [n_min, n_max]: n_min if the plateau predicate holds there, n_max if it fails there,
/// otherwise `bisection_steps` halvings keeping "fails at lo, holds at hi", returning hi.
///
/// Bisection finds the smallest N exactly when the predicate is monotone on [n_min, n_max]
/// (fails, then holds). For the fitted lognormal the gain g(N) = Ŷ(N + 10) − Ŷ(N) is a sliding
/// window integral of a unimodal density, hence unimodal: {g ≤ tol} = (0, a] ∪ [b, ∞). The
/// predicate is then monotone on [n_min, n_max] unless (i) n_min lies in the pre-rise part (0, a]
/// with the whole first probe window there — handled by the N* = n_min rule, which is the
/// literal "smallest N" — or (ii) the high-gain interval (a, b) is shorter than the probe stride,
/// so that probes can straddle it; then bisection returns a point where the predicate switches
/// from failing to holding, not necessarily the first one.
pub fn saturation_point(
    fit: &LognormalFit,
    n_min: f64,
    n_max: f64,
    s_gt: usize,
    settings: &SaturationSettings,
) -> f64 {
    let holds = |n: f64| fit.plateau_holds(n, n_max, s_gt, settings);
    if holds(n_min) {
        return n_min;
    }
    if !holds(n_max) {
        return n_max;
    }
    let (mut lo, mut hi) = (n_min, n_max);
    for _ in 0..settings.bisection_steps {
        let mid = lo + 0.5 * (hi - lo);
        if holds(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    hi
}

/// The saturation analysis of one object (SPEC §4).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Saturation {
    /// The raw curve Y(N) as measured.
    pub curve: Vec<CurvePoint>,
    /// Running maximum Y_m at the curve's sizes.
    pub running_max: Vec<f64>,
    /// Fitted location μ of ln N.
    pub mu: f64,
    /// Fitted scale σ of ln N.
    pub sigma: f64,
    /// y_max = Y_m(N_max).
    pub y_max: f64,
    /// Saturation point N* (real-valued).
    pub n_star: f64,
    /// d_sat = round(N*).
    pub d_sat: usize,
    /// r_vis = Ŷ(N*)/|S_gt|.
    pub r_vis: f64,
    /// Smallest curve size N ≥ N*.
    pub grid_n: usize,
    /// Y_m(grid_n)/|S_gt|.
    pub grid_r_vis: f64,
    /// d_sat > slow_saturation_threshold.
    pub slow_saturation: bool,
    /// The fit used the var(z) = 0 fallback (curve already at its maximum at N_min).
    pub degenerate_fit: bool,
    /// |S_gt|.
    pub s_gt: usize,
    /// The settings used.
    pub settings: SaturationSettings,
}

/// Runs the saturation analysis on a raw curve (normally over [`SATURATION_GRID`], any strictly
/// increasing positive sizes are accepted) for an object with |S_gt| = `s_gt` voxels.
pub fn saturation(
    curve: &[CurvePoint],
    s_gt: usize,
    settings: &SaturationSettings,
) -> Result<Saturation, DifficultyError> {
    settings.validate()?;
    if s_gt == 0 {
        return Err(DifficultyError::EmptyGroundTruth);
    }
    if curve.len() < 2 {
        return Err(DifficultyError::CurveTooShort { len: curve.len() });
    }
    for (index, point) in curve.iter().enumerate() {
        if point.n == 0 {
            return Err(DifficultyError::ZeroViewCount { index });
        }
        if index > 0 && point.n <= curve[index - 1].n {
            return Err(DifficultyError::NonIncreasingN { index, prev: curve[index - 1].n, n: point.n });
        }
        if !point.y.is_finite() || point.y < 0.0 {
            return Err(DifficultyError::InvalidY { index, y: point.y });
        }
        if point.y > s_gt as f64 {
            return Err(DifficultyError::YExceedsGroundTruth { index, y: point.y, s_gt });
        }
    }
    let ns: Vec<usize> = curve.iter().map(|p| p.n).collect();
    let ym = running_max(&curve.iter().map(|p| p.y).collect::<Vec<_>>());
    let fit = fit_lognormal(&ns, &ym, settings)?;
    let (n_min, n_max) = (ns[0] as f64, ns[ns.len() - 1] as f64);
    let n_star = saturation_point(&fit, n_min, n_max, s_gt, settings);
    let d_sat = n_star.round() as usize;
    // N* ≤ N_max, so a grid size ≥ N* always exists.
    let grid_index = ns.iter().position(|&n| n as f64 >= n_star).unwrap_or(ns.len() - 1);
    let s = s_gt as f64;
    Ok(Saturation {
        curve: curve.to_vec(),
        running_max: ym.clone(),
        mu: fit.mu,
        sigma: fit.sigma,
        y_max: fit.y_max,
        n_star,
        d_sat,
        r_vis: fit.eval(n_star) / s,
        grid_n: ns[grid_index],
        grid_r_vis: ym[grid_index] / s,
        slow_saturation: d_sat > settings.slow_saturation_threshold,
        degenerate_fit: fit.degenerate,
        s_gt,
        settings: *settings,
    })
}

// Reference values keep the 18 digits printed from 50-digit arithmetic; the compiler rounds them
// to the nearest f64, which is the point of quoting them in full.
#[allow(clippy::excessive_precision)]
#[cfg(test)]
mod tests {
    use super::*;

    /// Φ⁻¹(0.9999) for the f64 0.9999 = 1 − 1e-4, at 60 digits (mpmath): the z of a clamped top.
    const Z_TOP: f64 = 3.71901648545570839;
    /// −Φ⁻¹(1e-4) for the f64 1e-4 (mpmath): the |z| of a clamped bottom.
    const Z_BOTTOM: f64 = 3.71901648545568055;

    fn settings() -> SaturationSettings {
        SaturationSettings::default()
    }

    fn grid_f64() -> Vec<f64> {
        SATURATION_GRID.iter().map(|&n| n as f64).collect()
    }

    /// A curve over the grid from a function of N.
    fn grid_curve(f: impl Fn(f64) -> f64) -> Vec<CurvePoint> {
        SATURATION_GRID.iter().map(|&n| CurvePoint::new(n, f(n as f64))).collect()
    }

    /// The curve whose fit is exactly (μ, σ): Y_i = y_max·Φ((ln N_i − μ)/σ) below N_max and
    /// y_max at N_max, with μ = ln N_max − σ·Z_TOP, so that the clamped top point lies on the line.
    fn exact_lognormal_curve(sigma: f64, y_max: f64) -> (f64, Vec<CurvePoint>) {
        let mu = 492f64.ln() - sigma * Z_TOP;
        let mut curve = grid_curve(|n| y_max * norm_cdf((n.ln() - mu) / sigma));
        curve.last_mut().unwrap().y = y_max;
        (mu, curve)
    }

    /// Scans N = n_min + k·step over [n_min, n_max]: the first N where the plateau predicate
    /// holds, and whether it keeps holding at every later scan point (monotone predicate).
    fn scan_first_plateau(fit: &LognormalFit, n_max: f64, s_gt: usize, step: f64) -> (f64, bool) {
        let st = settings();
        let n_min = 6.0;
        let count = ((n_max - n_min) / step).round() as usize;
        let mut first = None;
        let mut monotone = true;
        for k in 0..=count {
            let n = n_min + k as f64 * step;
            let holds = fit.plateau_holds(n, n_max, s_gt, &st);
            match (first, holds) {
                (None, true) => first = Some(n),
                (Some(_), false) => monotone = false,
                _ => {}
            }
        }
        (first.unwrap_or(n_max), monotone)
    }

    #[test]
    fn settings_defaults_are_the_spec_constants() {
        let st = SaturationSettings::default();
        assert_eq!(st.p_clamp, 1e-4);
        assert_eq!(st.min_sigma, 1e-6);
        assert_eq!(st.bisection_steps, 80);
        assert_eq!(st.plateau_step, 10.0);
        assert_eq!(st.probe_stride, 5.0);
        assert_eq!(st.probe_span, 20.0);
        assert_eq!(st.plateau_tol, 2e-4);
        assert_eq!(st.slow_saturation_threshold, 128);
        assert!(st.validate().is_ok());
        for bad in [
            SaturationSettings { p_clamp: 0.0, ..st },
            SaturationSettings { p_clamp: 0.6, ..st },
            SaturationSettings { min_sigma: 0.0, ..st },
            SaturationSettings { plateau_step: -1.0, ..st },
            SaturationSettings { probe_stride: 0.0, ..st },
            SaturationSettings { probe_span: f64::NAN, ..st },
            SaturationSettings { plateau_tol: -1e-4, ..st },
        ] {
            assert!(matches!(bad.validate(), Err(DifficultyError::InvalidSetting { .. })), "{bad:?}");
        }
    }

    #[test]
    fn settings_serialize_and_partial_configs_take_defaults() {
        let json = serde_json::to_value(SaturationSettings::default()).unwrap();
        assert_eq!(json["plateau_tol"], 2e-4);
        assert_eq!(json["bisection_steps"], 80);
        let partial: SaturationSettings = serde_json::from_str(r#"{"plateau_tol": 1e-3}"#).unwrap();
        assert_eq!(partial, SaturationSettings { plateau_tol: 1e-3, ..Default::default() });
        assert!(serde_json::from_str::<SaturationSettings>(r#"{"plateau_tl": 1e-3}"#).is_err());
    }

    #[test]
    fn running_max_of_non_monotone_curve() {
        let ys = [10.0, 30.0, 25.0, 40.0, 35.0, 50.0, 45.0];
        assert_eq!(running_max(&ys), vec![10.0, 30.0, 30.0, 40.0, 40.0, 50.0, 50.0]);
        assert!(running_max(&[]).is_empty());
        // End to end: y_max is the global maximum even when the last raw value is lower, and the
        // fit only sees the running maximum (dips change nothing).
        let ns = [6, 8, 10, 12, 14, 16, 20];
        let raw: Vec<CurvePoint> = ns.iter().zip(ys).map(|(&n, y)| CurvePoint::new(n, y)).collect();
        let monotone: Vec<CurvePoint> =
            ns.iter().zip(running_max(&ys)).map(|(&n, y)| CurvePoint::new(n, y)).collect();
        let a = saturation(&raw, 100, &settings()).unwrap();
        let b = saturation(&monotone, 100, &settings()).unwrap();
        assert_eq!(a.y_max, 50.0);
        assert_eq!(a.running_max, vec![10.0, 30.0, 30.0, 40.0, 40.0, 50.0, 50.0]);
        assert_eq!(a.curve, raw);
        assert_eq!((a.mu, a.sigma, a.n_star), (b.mu, b.sigma, b.n_star));
    }

    #[test]
    fn fit_recovers_the_parameters_of_an_exact_lognormal_curve() {
        assert_eq!(1.0 - P_CLAMP, 0.9999);
        // σ ≥ 0.6 keeps Φ at N = 6 above the 1e-4 clamp: (ln 6 − ln 492)/σ + Z_TOP > −Z_BOTTOM.
        for sigma in [0.6, 0.8, 1.0, 1.5, 3.0] {
            let (mu, curve) = exact_lognormal_curve(sigma, 70_000.0);
            let sat = saturation(&curve, 100_000, &settings()).unwrap();
            assert!(!sat.degenerate_fit);
            assert!((sat.sigma - sigma).abs() < 1e-11 * sigma, "σ = {sigma}: fitted {}", sat.sigma);
            assert!((sat.mu - mu).abs() < 1e-11 * mu.abs().max(1.0), "σ = {sigma}: μ {} vs {mu}", sat.mu);
            assert_eq!(sat.y_max, 70_000.0);
        }
    }

    #[test]
    fn two_point_fit_through_both_clamps() {
        // Y = (0, 50): p = (1e-4, 1 − 1e-4) → z = (−Z_BOTTOM, Z_TOP); the line through two points.
        let curve = [CurvePoint::new(10, 0.0), CurvePoint::new(100, 50.0)];
        let sat = saturation(&curve, 80, &settings()).unwrap();
        let sigma = std::f64::consts::LN_10 / (Z_TOP + Z_BOTTOM);
        let mu = 10f64.ln() + sigma * Z_BOTTOM;
        assert!((sat.sigma - sigma).abs() < 1e-14, "{} vs {sigma}", sat.sigma);
        assert!((sat.mu - mu).abs() < 1e-14, "{} vs {mu}", sat.mu);
    }

    #[test]
    fn fit_minimizes_the_squared_residuals() {
        // An irregular, partly clamped curve: the fitted (μ, σ) must beat every perturbation.
        let ys = [0.0, 0.0, 3.0, 40.0, 41.0, 90.0, 300.0, 280.0, 500.0, 800.0, 810.0, 990.0, 1000.0];
        let ns = [6, 8, 10, 12, 14, 16, 20, 24, 28, 32, 40, 48, 56];
        let ym = running_max(&ys);
        let fit = fit_lognormal(&ns, &ym, &settings()).unwrap();
        let x: Vec<f64> = ns.iter().map(|&n| (n as f64).ln()).collect();
        let z: Vec<f64> = ym.iter().map(|&y| norm_inv_cdf((y / 1000.0).clamp(1e-4, 1.0 - 1e-4))).collect();
        assert_eq!(z[0], -Z_BOTTOM);
        assert_eq!(z[12], Z_TOP);
        let sse = |mu: f64, sigma: f64| -> f64 {
            x.iter().zip(&z).map(|(xi, zi)| (xi - mu - sigma * zi).powi(2)).sum()
        };
        let best = sse(fit.mu, fit.sigma);
        for (dm, ds) in [(1e-4, 0.0), (-1e-4, 0.0), (0.0, 1e-4), (0.0, -1e-4), (1e-4, -1e-4), (-1e-4, 1e-4)] {
            assert!(sse(fit.mu + dm, fit.sigma + ds) > best, "({dm}, {ds})");
        }
    }

    #[test]
    fn flat_curve_is_the_degenerate_fit_saturated_at_n_min() {
        // Everything visible already with 6 views: all p clamp to 1 − 1e-4, var(z) = 0.
        let curve = grid_curve(|_| 5_000.0);
        let sat = saturation(&curve, 8_000, &settings()).unwrap();
        assert!(sat.degenerate_fit);
        assert_eq!(sat.sigma, MIN_SIGMA);
        assert!((sat.mu - (6f64.ln() - MIN_SIGMA * Z_TOP)).abs() < 1e-15);
        assert_eq!(sat.n_star, 6.0);
        assert_eq!(sat.d_sat, 6);
        // Ŷ(6) = y_max·Φ(Z_TOP) = y_max·0.9999 (hand-derived).
        assert!((sat.r_vis - 5_000.0 * 0.9999 / 8_000.0).abs() < 1e-12, "{}", sat.r_vis);
        assert_eq!(sat.grid_n, 6);
        assert_eq!(sat.grid_r_vis, 5_000.0 / 8_000.0);
        assert!(!sat.slow_saturation);
        // Within the clamp of the top is still degenerate; just outside is not.
        let mut curve = grid_curve(|_| 10_000.0);
        curve[0].y = 9_999.5;
        assert!(saturation(&curve, 10_000, &settings()).unwrap().degenerate_fit);
        curve[0].y = 9_990.0;
        let sat = saturation(&curve, 10_000, &settings()).unwrap();
        assert!(!sat.degenerate_fit);
        // z takes two values (z₁ = Φ⁻¹(0.999) at N = 6, Z_TOP elsewhere): the least-squares slope is
        // the difference of the group means of x over the difference of the z values.
        let z1 = 3.09023230616781354; // −Φ⁻¹(0.001), equal to Φ⁻¹(0.999) to ~1e-14
        let rest: f64 = SATURATION_GRID[1..].iter().map(|&n| (n as f64).ln()).sum::<f64>() / 25.0;
        let sigma = (rest - 6f64.ln()) / (Z_TOP - z1);
        let mean_x = (rest * 25.0 + 6f64.ln()) / 26.0;
        let mu = mean_x - sigma * (Z_TOP * 25.0 + z1) / 26.0;
        assert!((sat.sigma - sigma).abs() < 1e-11 * sigma, "{} vs {sigma}", sat.sigma);
        assert!((sat.mu - mu).abs() < 1e-11 * mu.abs(), "{} vs {mu}", sat.mu);
    }

    #[test]
    fn invalid_curves_are_errors() {
        let st = settings();
        let ok = [CurvePoint::new(6, 1.0), CurvePoint::new(8, 2.0)];
        assert!(saturation(&ok, 10, &st).is_ok());
        assert_eq!(saturation(&ok, 0, &st), Err(DifficultyError::EmptyGroundTruth));
        assert_eq!(saturation(&ok[..1], 10, &st), Err(DifficultyError::CurveTooShort { len: 1 }));
        let zero = [CurvePoint::new(6, 0.0), CurvePoint::new(8, 0.0)];
        assert_eq!(saturation(&zero, 10, &st), Err(DifficultyError::NothingObserved));
        let unsorted = [CurvePoint::new(8, 1.0), CurvePoint::new(8, 2.0)];
        assert!(matches!(
            saturation(&unsorted, 10, &st),
            Err(DifficultyError::NonIncreasingN { index: 1, .. })
        ));
        let n0 = [CurvePoint::new(0, 1.0), CurvePoint::new(8, 2.0)];
        assert_eq!(saturation(&n0, 10, &st), Err(DifficultyError::ZeroViewCount { index: 0 }));
        for y in [f64::NAN, -1.0, f64::INFINITY] {
            let bad = [CurvePoint::new(6, 1.0), CurvePoint::new(8, y)];
            assert!(matches!(saturation(&bad, 10, &st), Err(DifficultyError::InvalidY { index: 1, .. })));
        }
        let over = [CurvePoint::new(6, 1.0), CurvePoint::new(8, 11.0)];
        assert!(matches!(saturation(&over, 10, &st), Err(DifficultyError::YExceedsGroundTruth { .. })));
        let bad_settings = SaturationSettings { probe_stride: 0.0, ..st };
        assert!(matches!(saturation(&ok, 10, &bad_settings), Err(DifficultyError::InvalidSetting { .. })));
        assert_eq!(curve_on_grid(&[1, 2, 3]), Err(DifficultyError::GridLength { expected: 26, got: 3 }));
        let counts: Vec<usize> = (0..26).map(|i| 100 + i).collect();
        let curve = curve_on_grid(&counts).unwrap();
        assert_eq!((curve[0], curve[25]), (CurvePoint::new(6, 100.0), CurvePoint::new(492, 125.0)));
    }

    #[test]
    fn n_star_of_a_sharp_step_is_derived_by_hand() {
        // σ = 1e-3, e^μ = 20: Ŷ jumps from 0 to y_max within N ∈ 20·(1 ± 0.005), so Ŷ(N + 10) = y_max
        // past the jump and the binding probe is N' = N: y_max·(1 − Φ(t)) ≤ 2e-4·|S_gt|, i.e.
        // N* = 20·exp(σ·t*) with 1 − Φ(t*) = 2e-4·|S_gt|/y_max. (At N = 6 the window [16, 26] holds
        // the jump, so the plateau does not hold at N_min.)
        let st = settings();
        for (y_max, s_gt, t_star) in
            [(10_000.0, 10_000, 3.5400837992061451159f64), (5_000.0, 10_000, 3.35279478050482874)]
        {
            let fit = LognormalFit { mu: 20f64.ln(), sigma: 1e-3, y_max, degenerate: false };
            let n_star = saturation_point(&fit, 6.0, 492.0, s_gt, &st);
            let want = 20.0 * (1e-3 * t_star).exp();
            assert!((n_star - want).abs() < 1e-9, "{n_star} vs {want}");
        }
    }

    #[test]
    fn n_star_boundary_rules() {
        let st = settings();
        // Still rising at N_max: t(492) = −0.5, gain over 492 → 502 ≈ φ(0.5)·ln(502/492)/3·|S_gt|
        // ≈ 2.4e-3·|S_gt| > 2e-4·|S_gt|; at N_min (t = −1.97) the gains are larger still. Never
        // holds → N* = N_max.
        let rising = LognormalFit { mu: 492f64.ln() + 1.5, sigma: 3.0, y_max: 1_000.0, degenerate: false };
        assert!(!rising.plateau_holds(492.0, 492.0, 1_000, &st));
        assert!(!rising.plateau_holds(6.0, 492.0, 1_000, &st));
        assert_eq!(saturation_point(&rising, 6.0, 492.0, 1_000, &st), 492.0);
        // A step at N = 100 is invisible from N_min's probe windows [6, 36]: the plateau holds at
        // N_min and N* = N_min, the literal "smallest N" (documented pre-rise behaviour).
        let late = LognormalFit { mu: 100f64.ln(), sigma: 1e-3, y_max: 1_000.0, degenerate: false };
        assert!(late.plateau_holds(6.0, 492.0, 1_000, &st));
        assert_eq!(saturation_point(&late, 6.0, 492.0, 1_000, &st), 6.0);
        // Probes are capped at N_max: at N = 490 only N' = 490 is checked, N' + 10 = 500 > N_max is
        // still evaluated. A jump at 495 is seen from 490 (window [490, 500]) …
        let jump = LognormalFit { mu: 495f64.ln(), sigma: 1e-3, y_max: 1_000.0, degenerate: false };
        assert!(!jump.plateau_holds(490.0, 492.0, 1_000, &st));
        // … and from 470 through the probe 485 ([485, 495.5] reaches into the jump) but not from
        // 460, whose probes stop at 480 ([480, 490]).
        assert!(!jump.plateau_holds(470.0, 492.0, 1_000, &st));
        assert!(jump.plateau_holds(460.0, 492.0, 1_000, &st));
        // The cap itself: a jump at 503 (σ = 1e-4: Ŷ(500) and Ŷ(502) are ~0) is only reachable from
        // the probes 495 and 500, which lie beyond N_max = 492 when N = 480.
        let beyond = LognormalFit { mu: 503f64.ln(), sigma: 1e-4, y_max: 1_000.0, degenerate: false };
        assert!(beyond.plateau_holds(480.0, 492.0, 1_000, &st));
        assert!(beyond.plateau_holds(492.0, 492.0, 1_000, &st));
        assert!(!beyond.plateau_holds(480.0, 600.0, 1_000, &st), "uncapped, probe 495 sees the jump");
        // With plateau_tol = 0 a strictly increasing fit never plateaus.
        let exact = exact_lognormal_curve(1.0, 1_000.0).1;
        let strict = SaturationSettings { plateau_tol: 0.0, ..st };
        let sat = saturation(&exact, 1_000, &strict).unwrap();
        assert_eq!((sat.n_star, sat.d_sat, sat.grid_n), (492.0, 492, 492));
        assert_eq!(sat.grid_r_vis, 1.0);
        assert!(sat.slow_saturation);
    }

    #[test]
    fn bisection_agrees_with_a_brute_force_scan() {
        let step = 0.01;
        let mut cases: Vec<(String, Vec<CurvePoint>, usize)> = Vec::new();
        for sigma in [0.6, 1.0, 1.5, 2.5] {
            cases.push((format!("exact σ={sigma}"), exact_lognormal_curve(sigma, 60_000.0).1, 80_000));
        }
        // Power-law saturation Y = y(1 − a·N^−b) and a curve with dips, as real objects give.
        cases.push(("power".into(), grid_curve(|n| 50_000.0 * (1.0 - 0.8 * n.powf(-0.7))), 60_000));
        cases.push(("slow power".into(), grid_curve(|n| 50_000.0 * (1.0 - 0.9 * n.powf(-0.3))), 60_000));
        let mut dips = grid_curve(|n| 40_000.0 * (1.0 - (-n / 40.0).exp()));
        for (i, p) in dips.iter_mut().enumerate() {
            if i % 3 == 2 {
                p.y *= 0.97;
            }
        }
        cases.push(("dips".into(), dips, 45_000));
        for (name, curve, s_gt) in cases {
            let sat = saturation(&curve, s_gt, &settings()).unwrap();
            let fit = LognormalFit { mu: sat.mu, sigma: sat.sigma, y_max: sat.y_max, degenerate: false };
            let (scan, monotone) = scan_first_plateau(&fit, 492.0, s_gt, step);
            assert!(monotone, "{name}: predicate not monotone on the scan");
            assert!(
                sat.n_star <= scan + 1e-9 && sat.n_star > scan - step - 1e-9,
                "{name}: {} vs {scan}",
                sat.n_star
            );
            // Bisection converged to the switch: holds at N*, fails just below.
            if sat.n_star > 6.0 && sat.n_star < 492.0 {
                assert!(fit.plateau_holds(sat.n_star, 492.0, s_gt, &settings()), "{name}");
                assert!(!fit.plateau_holds(sat.n_star * (1.0 - 1e-12), 492.0, s_gt, &settings()), "{name}");
            }
            // Derived quantities.
            assert_eq!(sat.d_sat, sat.n_star.round() as usize, "{name}");
            assert!((sat.r_vis - fit.eval(sat.n_star) / s_gt as f64).abs() < 1e-15, "{name}");
            let grid = grid_f64();
            let gi = grid.iter().position(|&g| g >= sat.n_star).unwrap();
            assert_eq!(sat.grid_n, SATURATION_GRID[gi], "{name}");
            assert_eq!(sat.grid_r_vis, sat.running_max[gi] / s_gt as f64, "{name}");
            assert!(gi == 0 || grid[gi - 1] < sat.n_star, "{name}");
            assert_eq!(sat.slow_saturation, sat.d_sat > 128, "{name}");
        }
    }

    #[test]
    fn slow_saturation_flag_is_strictly_above_the_threshold() {
        let (_, curve) = exact_lognormal_curve(1.5, 60_000.0);
        let sat = saturation(&curve, 80_000, &settings()).unwrap();
        let d = sat.d_sat;
        assert!(d > 6 && d < 492, "an interior saturation point: {d}");
        let at = SaturationSettings { slow_saturation_threshold: d, ..settings() };
        let below = SaturationSettings { slow_saturation_threshold: d - 1, ..settings() };
        assert!(!saturation(&curve, 80_000, &at).unwrap().slow_saturation);
        assert!(saturation(&curve, 80_000, &below).unwrap().slow_saturation);
        // With the default threshold 128: a slow (power-law) and a fast curve.
        let power = grid_curve(|n| 50_000.0 * (1.0 - 0.8 * n.powf(-0.7)));
        let slow = saturation(&power, 60_000, &settings()).unwrap();
        let fast = saturation(&exact_lognormal_curve(2.5, 60_000.0).1, 80_000, &settings()).unwrap();
        assert!(slow.d_sat > 128 && slow.slow_saturation, "{}", slow.d_sat);
        assert!(fast.d_sat <= 128 && !fast.slow_saturation, "{}", fast.d_sat);
    }

    #[test]
    fn result_serializes_with_its_settings() {
        let (_, curve) = exact_lognormal_curve(1.0, 600.0);
        let sat = saturation(&curve, 1_000, &settings()).unwrap();
        let json = serde_json::to_value(&sat).unwrap();
        for key in [
            "curve",
            "running_max",
            "mu",
            "sigma",
            "y_max",
            "n_star",
            "d_sat",
            "r_vis",
            "grid_n",
            "grid_r_vis",
            "slow_saturation",
            "degenerate_fit",
            "s_gt",
            "settings",
        ] {
            assert!(json.get(key).is_some(), "missing {key}");
        }
        assert_eq!(json["curve"][0]["n"], 6);
        assert_eq!(json["settings"]["probe_stride"], 5.0);
        let back: Saturation = serde_json::from_value(json).unwrap();
        assert_eq!(back, sat);
    }
}
