//! Point-cloud completion behind one interface, for the hybrid planners (issue 19; reference
//! behaviour in `shared/research/learned-baselines.md` §5).
//!
//! Why a trait: the hybrid planners (completion + NBV / set cover / max coverage) must not care
//! where the completed shape comes from. The learned network (`net`, in `objview-learn`:
//! `objview_learn::completion_backend::NetCompletion`, which needs Burn and so cannot live in
//! this crate) implements [`Completion`] like the two backends here:
//!
//! - [`IdentityCompletion`] (`identity`): predicts nothing, so the "completion" is the input
//!   alone — a **lower bound** (what the planning steps do with no shape prior at all);
//! - [`OracleCompletion`] (`oracle`): predicts the observable reference cloud of the episode
//!   (ground truth) — an **upper bound** on what any completion can give the planner. It reads
//!   the object, so like the `oracle` planner it is a diagnostic only: planners using it say so
//!   in their method name (`completion-scp[oracle]`) and ask for ground truth.
//!
//! The service contract ([`complete`]) is the reference's: a partial cloud of any size is
//! resampled to [`INPUT_POINTS`] = 2048 points with a seeded RNG ([`resample`]), normalized
//! (centroid subtracted, divided by the largest distance to it; [`Normalization`]), handed to
//! the backend, and the backend's prediction is mapped back; the output is the prediction
//! followed by the 2048 resampled input points (8192 in all for the net's 6144 predicted).
//! The input points are appended as they were before normalization (not round-tripped), so
//! they are exactly points of the partial cloud.

use objview_episode::EpisodeContext;
use rand::Rng;

/// Points the backend receives (the reference's PoinTr input size).
pub const INPUT_POINTS: usize = 2048;
/// Points the reference network predicts (its output is these plus the input: 8192).
pub const NET_PREDICTED_POINTS: usize = 6144;

/// A completion failure.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CompletionError {
    /// The partial cloud is empty (nothing to complete).
    #[error("the partial cloud is empty: nothing to complete")]
    EmptyInput,
    /// A non-finite input coordinate.
    #[error("partial-cloud point {index} is not finite: {point:?}")]
    NonFinite {
        /// Its index.
        index: usize,
        /// The point.
        point: [f64; 3],
    },
    /// A backend name that is not known.
    #[error("unknown completion backend {0:?} (known: net, oracle, identity)")]
    UnknownBackend(String),
    /// The learned backend is requested where it is not linked (this crate's own rows; the
    /// learned-planner crate provides the rows that build it).
    #[error(
        "the net completion backend is not linked into these planner rows (it comes with objview-learn's \
         hybrid rows, as in the objview CLI; here use completion=oracle or completion=identity)"
    )]
    NetUnavailable,
    /// The oracle backend was used without ground-truth access.
    #[error("the oracle completion backend needs ground-truth access (the episode did not grant it)")]
    NoGroundTruth,
    /// A backend's own failure.
    #[error("completion backend {backend}: {message}")]
    Backend {
        /// The backend's name.
        backend: String,
        /// What went wrong.
        message: String,
    },
}

/// What a backend's output means for the results it leads to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CompletionBound {
    /// The real method (a learned completion network).
    Method,
    /// A lower bound: no completion at all.
    LowerBound,
    /// An upper bound that reads the ground truth (diagnostics only).
    UpperBound,
}

/// The reference's normalization: `q = (p − centroid) / scale`, scale = the largest distance
/// of an input point to the centroid (1 when all points coincide).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Normalization {
    /// Centroid of the (resampled) input.
    pub centroid: [f64; 3],
    /// Max distance to the centroid (> 0).
    pub scale: f64,
}

impl Normalization {
    /// The normalization of `points` (not empty).
    pub fn of(points: &[[f64; 3]]) -> Normalization {
        let n = points.len().max(1) as f64;
        let mut c = [0.0; 3];
        for p in points {
            for k in 0..3 {
                c[k] += p[k];
            }
        }
        let centroid = c.map(|x| x / n);
        let scale = points
            .iter()
            .map(|p| {
                ((p[0] - centroid[0]).powi(2) + (p[1] - centroid[1]).powi(2) + (p[2] - centroid[2]).powi(2))
                    .sqrt()
            })
            .fold(0.0f64, f64::max);
        Normalization { centroid, scale: if scale > 0.0 { scale } else { 1.0 } }
    }

    /// `(p − centroid) / scale`.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|k| (p[k] - self.centroid[k]) / self.scale)
    }

    /// `q · scale + centroid` (the inverse of [`Normalization::apply`]).
    pub fn invert(&self, q: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|k| q[k] * self.scale + self.centroid[k])
    }
}

/// The backend's input: [`INPUT_POINTS`] normalized points and the normalization used.
#[derive(Debug, Clone, PartialEq)]
pub struct NormalizedInput {
    /// The resampled input, normalized.
    pub points: Vec<[f64; 3]>,
    /// How it was normalized (backends that produce object-frame points, like the oracle, map
    /// them with [`Normalization::apply`]).
    pub normalization: Normalization,
}

/// A completion backend. One instance serves one planner; [`Completion::reset`] is called at
/// every episode start, [`Completion::predict`] once per completion request.
pub trait Completion: Send {
    /// The backend's name (`net`, `oracle`, `identity`), shown in the planner's method name.
    fn name(&self) -> &'static str;
    /// What its results mean (real method, lower or upper bound).
    fn bound(&self) -> CompletionBound;
    /// Whether it reads the ground truth (then the planner asks the environment for it).
    fn needs_ground_truth(&self) -> bool {
        false
    }
    /// What to record about the backend in results (the net: its weights, shape, hash), or
    /// null for nothing beyond its name and bound.
    fn describe(&self) -> serde_json::Value {
        serde_json::Value::Null
    }
    /// Starts an episode (the oracle takes the ground truth from `ctx.oracle` here).
    fn reset(&mut self, _ctx: &EpisodeContext) -> Result<(), CompletionError> {
        Ok(())
    }
    /// The predicted points for `input`, in the normalized frame of `input.normalization`
    /// (the net: 6144 points). The input points themselves are not part of the answer.
    fn predict(&mut self, input: &NormalizedInput) -> Result<Vec<[f64; 3]>, CompletionError>;
}

/// The partial cloud resampled to exactly `n` points (the reference's rule): more than `n`
/// points → the first `n` of a random permutation; fewer → the cloud is doubled by tiling
/// while twice its size still fits in `n`, then a random subset (without replacement) of the
/// tiled cloud fills the remainder; exactly `n` → unchanged. Deterministic for a given `rng`.
pub fn resample<R: Rng>(
    points: &[[f64; 3]],
    n: usize,
    rng: &mut R,
) -> Result<Vec<[f64; 3]>, CompletionError> {
    if points.is_empty() {
        return Err(CompletionError::EmptyInput);
    }
    if let Some((index, p)) = points.iter().enumerate().find(|(_, p)| !p.iter().all(|x| x.is_finite())) {
        return Err(CompletionError::NonFinite { index, point: *p });
    }
    use std::cmp::Ordering;
    match points.len().cmp(&n) {
        Ordering::Equal => Ok(points.to_vec()),
        Ordering::Greater => {
            let idx = permutation_prefix(points.len(), n, rng);
            Ok(idx.into_iter().map(|i| points[i]).collect())
        }
        Ordering::Less => {
            let mut tiled = points.to_vec();
            while tiled.len() * 2 <= n {
                tiled.extend_from_within(..);
            }
            let rest = n - tiled.len();
            let idx = permutation_prefix(tiled.len(), rest, rng);
            let extra: Vec<[f64; 3]> = idx.into_iter().map(|i| tiled[i]).collect();
            tiled.extend(extra);
            Ok(tiled)
        }
    }
}

/// The first `k` entries of a uniformly random permutation of `0..n` (partial Fisher–Yates).
fn permutation_prefix<R: Rng>(n: usize, k: usize, rng: &mut R) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..n).collect();
    for i in 0..k.min(n) {
        let j = rng.gen_range(i..n);
        idx.swap(i, j);
    }
    idx.truncate(k.min(n));
    idx
}

/// A completed cloud (object frame): `points[..predicted]` are the backend's prediction,
/// `points[predicted..]` the [`INPUT_POINTS`] resampled input points.
#[derive(Debug, Clone, PartialEq)]
pub struct Completed {
    /// Prediction followed by the resampled input.
    pub points: Vec<[f64; 3]>,
    /// How many of `points` are predicted.
    pub predicted: usize,
    /// The normalization used.
    pub normalization: Normalization,
}

/// The full service contract (see the module docs): resample `partial` to 2048 points with
/// `rng`, normalize, predict with `backend`, map back, append the input.
pub fn complete<R: Rng>(
    backend: &mut dyn Completion,
    partial: &[[f64; 3]],
    rng: &mut R,
) -> Result<Completed, CompletionError> {
    let input = resample(partial, INPUT_POINTS, rng)?;
    let normalization = Normalization::of(&input);
    let normalized =
        NormalizedInput { points: input.iter().map(|p| normalization.apply(*p)).collect(), normalization };
    let predicted = backend.predict(&normalized)?;
    let mut points: Vec<[f64; 3]> = predicted.iter().map(|q| normalization.invert(*q)).collect();
    let n_pred = points.len();
    points.extend_from_slice(&input);
    Ok(Completed { points, predicted: n_pred, normalization })
}

/// `identity`: no completion (predicts nothing) — the lower bound.
#[derive(Debug, Clone, Copy, Default)]
pub struct IdentityCompletion;

impl Completion for IdentityCompletion {
    fn name(&self) -> &'static str {
        "identity"
    }
    fn bound(&self) -> CompletionBound {
        CompletionBound::LowerBound
    }
    fn predict(&mut self, _input: &NormalizedInput) -> Result<Vec<[f64; 3]>, CompletionError> {
        Ok(Vec::new())
    }
}

/// `oracle`: predicts the episode's observable reference cloud (ground truth), voxel-filtered
/// at [`super::steps::PARTIAL_VOXEL`] (centroids), so every planning voxel the object occupies
/// is represented without sending hundreds of thousands of points through outlier removal. It
/// is not cut to 6144 points: the upper bound is on the completion's *shape*, not on the
/// network's output density. Diagnostics only (it reads the object).
#[derive(Debug, Clone, Default)]
pub struct OracleCompletion {
    truth: Vec<[f64; 3]>,
}

impl Completion for OracleCompletion {
    fn name(&self) -> &'static str {
        "oracle"
    }
    fn bound(&self) -> CompletionBound {
        CompletionBound::UpperBound
    }
    fn needs_ground_truth(&self) -> bool {
        true
    }
    fn reset(&mut self, ctx: &EpisodeContext) -> Result<(), CompletionError> {
        let oracle = ctx.oracle.as_ref().ok_or(CompletionError::NoGroundTruth)?;
        self.truth = super::steps::voxel_filter(&oracle.reference, super::steps::PARTIAL_VOXEL);
        Ok(())
    }
    fn predict(&mut self, input: &NormalizedInput) -> Result<Vec<[f64; 3]>, CompletionError> {
        if self.truth.is_empty() {
            return Err(CompletionError::NoGroundTruth);
        }
        Ok(self.truth.iter().map(|p| input.normalization.apply(*p)).collect())
    }
}

/// The backend called `name`: `identity`, `oracle`; `net` is refused
/// ([`CompletionError::NetUnavailable`]): it is built by the learned-planner crate
/// ([`super::NetBackend`]).
pub fn backend(name: &str) -> Result<Box<dyn Completion>, CompletionError> {
    match name {
        "identity" => Ok(Box::new(IdentityCompletion)),
        "oracle" => Ok(Box::new(OracleCompletion::default())),
        "net" => Err(CompletionError::NetUnavailable),
        other => Err(CompletionError::UnknownBackend(other.to_string())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn cloud(n: usize, seed: u64) -> Vec<[f64; 3]> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| [rng.gen_range(-0.3..0.9), rng.gen_range(-0.5..0.2), rng.gen_range(0.1..0.4)])
            .collect()
    }

    fn key(p: &[f64; 3]) -> [u64; 3] {
        p.map(f64::to_bits)
    }

    #[test]
    fn resampling_sizes_multiplicities_and_determinism() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        // More points: a subset without repetition.
        let big = cloud(5000, 1);
        let r = resample(&big, INPUT_POINTS, &mut rng).unwrap();
        assert_eq!(r.len(), INPUT_POINTS);
        let mut keys: Vec<_> = r.iter().map(key).collect();
        keys.sort_unstable();
        keys.dedup();
        assert_eq!(keys.len(), INPUT_POINTS, "no point drawn twice");
        let all: std::collections::HashSet<_> = big.iter().map(key).collect();
        assert!(r.iter().all(|p| all.contains(&key(p))));
        // Fewer points: 300 → tiled to 1200 (×4), then 848 distinct draws of the tiled cloud,
        // so every input point occurs 4, 5 or 6 times... at most 4 + 4 (copies of the tiled).
        let small = cloud(300, 2);
        let r = resample(&small, INPUT_POINTS, &mut rng).unwrap();
        assert_eq!(r.len(), INPUT_POINTS);
        assert_eq!(&r[..300], &small[..], "the tiled copies come first");
        assert_eq!(&r[300..600], &small[..]);
        assert_eq!(&r[900..1200], &small[..]);
        for p in &small {
            let m = r.iter().filter(|q| key(q) == key(p)).count();
            assert!((4..=8).contains(&m), "{m}");
        }
        // Exactly 2048: unchanged. 1024: exactly doubled, nothing drawn.
        let exact = cloud(INPUT_POINTS, 3);
        assert_eq!(resample(&exact, INPUT_POINTS, &mut rng).unwrap(), exact);
        let half = cloud(1024, 4);
        let r = resample(&half, INPUT_POINTS, &mut rng).unwrap();
        assert_eq!((&r[..1024], &r[1024..]), (&half[..], &half[..]));
        // Seeded: same seed, same draw; another seed, another draw.
        let a = resample(&big, INPUT_POINTS, &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        let b = resample(&big, INPUT_POINTS, &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        let c = resample(&big, INPUT_POINTS, &mut ChaCha8Rng::seed_from_u64(2)).unwrap();
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert_eq!(resample(&[], 4, &mut rng), Err(CompletionError::EmptyInput));
        assert!(matches!(
            resample(&[[0.0, f64::NAN, 0.0]], 4, &mut rng),
            Err(CompletionError::NonFinite { index: 0, .. })
        ));
    }

    #[test]
    fn normalization_round_trip_and_unit_radius() {
        let pts = cloud(777, 5);
        let n = Normalization::of(&pts);
        let q: Vec<_> = pts.iter().map(|p| n.apply(*p)).collect();
        // Centred, max radius exactly 1 (up to rounding).
        let c: [f64; 3] = std::array::from_fn(|k| q.iter().map(|p| p[k]).sum::<f64>() / q.len() as f64);
        assert!(c.iter().all(|x| x.abs() < 1e-12), "{c:?}");
        let rmax = q.iter().map(|p| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()).fold(0.0, f64::max);
        assert!((rmax - 1.0).abs() < 1e-12, "{rmax}");
        for (p, q) in pts.iter().zip(&q) {
            let back = n.invert(*q);
            assert!((0..3).all(|k| (back[k] - p[k]).abs() < 1e-14), "{p:?} {back:?}");
        }
        // All points equal: scale 1, no division by zero.
        let same = Normalization::of(&[[0.5, 0.5, 0.5]; 3]);
        assert_eq!(same.scale, 1.0);
        assert_eq!(same.apply([0.5, 0.5, 0.5]), [0.0; 3]);
    }

    /// A backend that predicts fixed normalized-frame points and records what it got.
    struct Fixed(Vec<[f64; 3]>, Option<NormalizedInput>);

    impl Completion for Fixed {
        fn name(&self) -> &'static str {
            "fixed"
        }
        fn bound(&self) -> CompletionBound {
            CompletionBound::Method
        }
        fn predict(&mut self, input: &NormalizedInput) -> Result<Vec<[f64; 3]>, CompletionError> {
            self.1 = Some(input.clone());
            Ok(self.0.clone())
        }
    }

    #[test]
    fn complete_round_trips_through_the_normalized_frame() {
        let partial = cloud(3000, 6);
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        // The backend predicts the (normalized) input shifted by +0.5 in x, 3× over: 6144 points.
        let mut backend = Fixed(Vec::new(), None);
        let input = resample(&partial, INPUT_POINTS, &mut ChaCha8Rng::seed_from_u64(9)).unwrap();
        let norm = Normalization::of(&input);
        backend.0 = (0..3).flat_map(|_| input.iter().map(|p| norm.apply([p[0], p[1], p[2]]))).collect();
        for q in &mut backend.0 {
            q[0] += 0.5;
        }
        let out = complete(&mut backend, &partial, &mut rng).unwrap();
        assert_eq!(
            (out.points.len(), out.predicted),
            (NET_PREDICTED_POINTS + INPUT_POINTS, NET_PREDICTED_POINTS)
        );
        assert_eq!(&out.points[out.predicted..], &input[..], "the input is appended as it was");
        let got = backend.1.unwrap();
        assert_eq!(got.points.len(), INPUT_POINTS);
        assert_eq!(got.normalization, norm);
        // Predicted point i is input point i mod 2048 shifted by 0.5·scale in x (object frame).
        for (i, p) in out.points[..out.predicted].iter().enumerate() {
            let s = input[i % INPUT_POINTS];
            let want = [s[0] + 0.5 * norm.scale, s[1], s[2]];
            assert!((0..3).all(|k| (p[k] - want[k]).abs() < 1e-12), "{i}: {p:?} vs {want:?}");
        }
        // Identity: the output is the resampled input alone.
        let out = complete(&mut IdentityCompletion, &partial, &mut ChaCha8Rng::seed_from_u64(9)).unwrap();
        assert_eq!((out.predicted, &out.points[..]), (0, &input[..]));
    }

    #[test]
    fn backends_by_name() {
        assert_eq!(backend("identity").unwrap().name(), "identity");
        let o = backend("oracle").unwrap();
        assert!(o.needs_ground_truth() && o.bound() == CompletionBound::UpperBound);
        assert_eq!(
            backend("net").err().unwrap().to_string(),
            "the net completion backend is not linked into these planner rows (it comes with objview-learn's \
             hybrid rows, as in the objview CLI; here use completion=oracle or completion=identity)"
        );
        assert!(matches!(backend("pointr"), Err(CompletionError::UnknownBackend(_))));
    }
}
