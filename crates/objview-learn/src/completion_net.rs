//! The learned point-cloud completion network of the hybrid planners' `net` backend (issue 19):
//! a small PCN / FoldingNet-style encoder–decoder standing in for the reference's PoinTr
//! (learned-baselines.md §5.1, 42.1 M parameters, CUDA kernels, weights not retrievable; §10–§11:
//! not trainable on 2 CPU cores). The widths are settings ([`CompletionShape`]); the default
//! ([`CompletionShape::small`]) trains on 2 CPU cores and answers a completion call within the
//! 100 ms budget on one core — a stated deviation recorded in every sidecar and result.
//!
//! Topology (B clouds of N = 2048 normalized points, widths e₁, e₂, e₃, G):
//! 1. **encoder stage 1** (PointNet shared MLP, Linear over the point axis): 3 → e₁ (ReLU) → e₂;
//!    max over the points → a stage-1 global feature g₁ (e₂);
//! 2. **encoder stage 2** (PCN): every point's feature concatenated with g₁ (2·e₂) → e₃ (ReLU)
//!    → G; max over the points → the global feature g (G);
//! 3. **coarse decoder** (FC): g → hidden widths (ReLU each) → M·3: M coarse points;
//! 4. **folding decoder** (FoldingNet / PCN): every coarse point c_m is paired with each point
//!    u_k of a fixed s × s grid on [−r, r]² (r = `grid_scale`); the MLP
//!    [g, u_k, c_m] → h (ReLU) → h (ReLU) → 3 gives an offset, fine point = c_m + offset.
//!    The first layer is split by input (`[g]` once per cloud, `[u_k]` once per grid point, `[c_m]`
//!    once per coarse point, then broadcast-added) — the same function as one Linear over the
//!    concatenation, without materializing it. M·s² = 6144 fine points
//!    ([`objview_planners::hybrid::completion::NET_PREDICTED_POINTS`]), in the input's
//!    normalized frame.
//!
//! The loss ([`chamfer_loss`]) is PoinTr's/PCN's Chamfer-L1 (`ChamferDistanceL1`: the mean
//! nearest-neighbour Euclidean distance from prediction to ground truth and from ground truth
//! to prediction, averaged) on the coarse and the fine output. Nearest neighbours are found
//! exactly outside the autodiff graph ([`KdTree`]); the distances to them are computed inside it,
//! so the gradient is the gradient of the minimum (almost everywhere). [`chamfer_l1`] is the
//! same figure in f64 for evaluation.

use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Int, Tensor, TensorData};
use objview_planners::hybrid::completion::NET_PREDICTED_POINTS;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::LearnError;

/// The completion network's shape.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CompletionShape {
    /// Encoder widths [e₁, e₂, e₃, G] (stage 1: 3 → e₁ → e₂; stage 2: 2·e₂ → e₃ → G).
    pub encoder: [usize; 4],
    /// Hidden widths of the coarse decoder (each followed by ReLU), then Linear → M·3.
    pub coarse_fc: Vec<usize>,
    /// Coarse points M.
    pub coarse: usize,
    /// Folding grid side s (s² fine points per coarse point; M·s² = 6144).
    pub fold_grid: usize,
    /// Hidden width h of the folding MLP.
    pub fold_width: usize,
    /// Half side r of the folding grid [−r, r]² (normalized units).
    pub grid_scale: f64,
}

impl CompletionShape {
    /// The default trained here: encoder 64/128/256/512, coarse FC 512/512 → 96 points, folding
    /// 8 × 8 per coarse point (PoinTr's 96 × 64 layout) with width 64, grid half side 0.05.
    pub fn small() -> CompletionShape {
        CompletionShape {
            encoder: [64, 128, 256, 512],
            coarse_fc: vec![512, 512],
            coarse: 96,
            fold_grid: 8,
            fold_width: 64,
            grid_scale: 0.05,
        }
    }

    /// Checks the sizes (an error names the setting).
    pub fn validate(&self) -> Result<(), LearnError> {
        let bad = |m: String| Err(LearnError::Invalid(m));
        if self.encoder.contains(&0) || self.coarse_fc.contains(&0) || self.fold_width == 0 {
            return bad(format!(
                "completion widths must be positive: encoder {:?}, coarse_fc {:?}, fold_width {}",
                self.encoder, self.coarse_fc, self.fold_width
            ));
        }
        if self.coarse == 0
            || self.fold_grid == 0
            || self.coarse * self.fold_grid.pow(2) != NET_PREDICTED_POINTS
        {
            return bad(format!(
                "completion coarse points × fold_grid² must be {NET_PREDICTED_POINTS}, got {} × {}²",
                self.coarse, self.fold_grid
            ));
        }
        if !(self.grid_scale.is_finite() && self.grid_scale > 0.0) {
            return bad(format!("completion grid_scale must be a positive number, got {}", self.grid_scale));
        }
        Ok(())
    }

    /// The parameter count of a network of this shape (weights and biases of every Linear).
    pub fn params(&self) -> usize {
        let lin = |i: usize, o: usize| i * o + o;
        let [e1, e2, e3, g] = self.encoder;
        let mut n = lin(3, e1) + lin(e1, e2) + lin(2 * e2, e3) + lin(e3, g);
        let mut w = g;
        for &h in &self.coarse_fc {
            n += lin(w, h);
            w = h;
        }
        n += lin(w, self.coarse * 3);
        let h = self.fold_width;
        // First folding layer split by input: [g] with the bias, [u] and [c] without.
        n += lin(g, h) + 2 * h + 3 * h + lin(h, h) + lin(h, 3);
        n
    }

    /// How this network differs from the reference's PoinTr (recorded in sidecars and results).
    pub fn deviation(&self) -> String {
        format!(
            "a PCN/FoldingNet-style encoder-decoder of {} parameters instead of the reference's PoinTr \
             (ShapeNet-55 config, ~42.1 M parameters: DGCNN grouper, 6 encoder and 8 decoder transformer \
             blocks, 96 queries, FoldingNet head of 64 points per query; weights behind Git LFS and CUDA-only): \
             PointNet encoder {:?} with max-pooling (PCN two-stage), coarse FC {:?} -> {} points, folding of a \
             {}x{} grid per coarse point with width {}; same contract (2048 input points, 6144 predicted, \
             centroid/max-radius normalization) and the same Chamfer-L1 loss on coarse and fine outputs; \
             trained here on partial clouds of procedural Main-Train-Public objects",
            self.params(),
            self.encoder,
            self.coarse_fc,
            self.coarse,
            self.fold_grid,
            self.fold_grid,
            self.fold_width
        )
    }

    /// The s × s folding grid on [−r, r]², row-major, as [s², 2] values.
    pub fn grid_points(&self) -> Vec<f32> {
        folding_grid(self.fold_grid, self.grid_scale)
    }
}

/// The s × s grid on [−r, r]² (linearly spaced, row-major), as [s², 2] values.
pub fn folding_grid(s: usize, r: f64) -> Vec<f32> {
    let at = |i: usize| if s == 1 { 0.0 } else { -r + 2.0 * r * i as f64 / (s - 1) as f64 };
    (0..s * s).flat_map(|k| [at(k / s) as f32, at(k % s) as f32]).collect()
}

/// The network (see the module docs).
#[derive(Module, Debug)]
pub struct CompletionNet {
    enc1: Linear,
    enc2: Linear,
    enc3: Linear,
    enc4: Linear,
    coarse_fc: Vec<Linear>,
    coarse_out: Linear,
    fold_g: Linear,
    fold_u: Linear,
    fold_c: Linear,
    fold2: Linear,
    fold3: Linear,
    coarse: usize,
    fold_grid: usize,
    grid_scale: f64,
}

impl CompletionNet {
    /// A freshly initialized network of `shape` on `device` (seed the device first for
    /// reproducible weights). The shape must be valid ([`CompletionShape::validate`]).
    pub fn new(shape: &CompletionShape, device: &Device) -> CompletionNet {
        shape.validate().expect("a valid completion shape");
        let [e1, e2, e3, g] = shape.encoder;
        let h = shape.fold_width;
        let mut coarse_fc = Vec::new();
        let mut w = g;
        for &c in &shape.coarse_fc {
            coarse_fc.push(LinearConfig::new(w, c).init(device));
            w = c;
        }
        CompletionNet {
            enc1: LinearConfig::new(3, e1).init(device),
            enc2: LinearConfig::new(e1, e2).init(device),
            enc3: LinearConfig::new(2 * e2, e3).init(device),
            enc4: LinearConfig::new(e3, g).init(device),
            coarse_fc,
            coarse_out: LinearConfig::new(w, shape.coarse * 3).init(device),
            fold_g: LinearConfig::new(g, h).init(device),
            fold_u: LinearConfig::new(2, h).with_bias(false).init(device),
            fold_c: LinearConfig::new(3, h).with_bias(false).init(device),
            fold2: LinearConfig::new(h, h).init(device),
            fold3: LinearConfig::new(h, 3).init(device),
            coarse: shape.coarse,
            fold_grid: shape.fold_grid,
            grid_scale: shape.grid_scale,
        }
    }

    /// (coarse [B, M, 3], fine [B, M·s², 3]) for normalized clouds `x` [B, N, 3] (any N ≥ 1).
    pub fn forward(&self, x: Tensor<3>) -> (Tensor<3>, Tensor<3>) {
        let device = x.device();
        let [b, n, _] = x.dims();
        let f = self.enc2.forward(relu(self.enc1.forward(x)));
        let g1 = f.clone().max_dim(1).repeat_dim(1, n);
        let f = self.enc4.forward(relu(self.enc3.forward(Tensor::cat(vec![f, g1], 2))));
        let [_, _, gw] = f.dims();
        let g = f.max_dim(1).reshape([b, gw]);
        let mut y = g.clone();
        for l in &self.coarse_fc {
            y = relu(l.forward(y));
        }
        let m = self.coarse;
        let coarse = self.coarse_out.forward(y).reshape([b, m, 3]);
        let s2 = self.fold_grid * self.fold_grid;
        let u = Tensor::<2>::from_data(
            TensorData::new(folding_grid(self.fold_grid, self.grid_scale), [s2, 2]),
            &device,
        );
        let hu = self.fold_u.forward(u); // [s², h]
        let [_, h] = hu.dims();
        let hg = self.fold_g.forward(g).reshape([b, 1, 1, h]);
        let hc = self.fold_c.forward(coarse.clone()).reshape([b, m, 1, h]);
        let pre = hc + hu.reshape([1, 1, s2, h]) + hg; // [B, M, s², h]
        let z = relu(self.fold2.forward(relu(pre)));
        let offset = self.fold3.forward(z); // [B, M, s², 3]
        let fine = (offset + coarse.clone().reshape([b, m, 1, 3])).reshape([b, m * s2, 3]);
        (coarse, fine)
    }

    /// The fine prediction for one normalized cloud (inference; `points` of any size ≥ 1).
    pub fn predict(&self, points: &[[f32; 3]], device: &Device) -> Vec<[f32; 3]> {
        let flat: Vec<f32> = points.iter().flatten().copied().collect();
        let x = Tensor::<3>::from_data(TensorData::new(flat, [1, points.len(), 3]), device);
        let (_, fine) = self.forward(x);
        let v: Vec<f32> = fine.into_data().try_to_vec::<f32>().expect("f32 points");
        v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
    }
}

/// Exact nearest neighbours among a fixed point set: a k-d tree (median splits on the widest
/// axis, leaves of up to 8 points). Ties between equally distant points go to the **lowest
/// index**, so the answer is exactly brute force's first minimum.
#[derive(Debug, Clone)]
pub struct KdTree {
    pts: Vec<[f64; 3]>,
    idx: Vec<u32>,
    /// Split axis and value of the internal node whose range has its middle at this position
    /// (the value is kept: building the children reorders the range).
    split: Vec<(u8, f64)>,
}

const LEAF: usize = 8;

#[inline]
fn d2(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let (x, y, z) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    x * x + y * y + z * z
}

impl KdTree {
    /// The tree of `points` (may be empty: then every query answers `None`).
    pub fn new(points: &[[f64; 3]]) -> KdTree {
        let mut t = KdTree {
            pts: points.to_vec(),
            idx: (0..points.len() as u32).collect(),
            split: vec![(0, 0.0); points.len()],
        };
        t.build(0, points.len());
        t
    }

    fn build(&mut self, lo: usize, hi: usize) {
        if hi - lo <= LEAF {
            return;
        }
        let mut min = [f64::INFINITY; 3];
        let mut max = [f64::NEG_INFINITY; 3];
        for &i in &self.idx[lo..hi] {
            let p = self.pts[i as usize];
            for a in 0..3 {
                min[a] = min[a].min(p[a]);
                max[a] = max[a].max(p[a]);
            }
        }
        let ax =
            (0..3).max_by(|&a, &b| (max[a] - min[a]).total_cmp(&(max[b] - min[b])).then(b.cmp(&a))).unwrap();
        let mid = (lo + hi) / 2;
        let pts = &self.pts;
        self.idx[lo..hi].select_nth_unstable_by(mid - lo, |&i, &j| {
            pts[i as usize][ax].total_cmp(&pts[j as usize][ax]).then(i.cmp(&j))
        });
        self.split[mid] = (ax as u8, self.pts[self.idx[mid] as usize][ax]);
        self.build(lo, mid);
        self.build(mid, hi);
    }

    /// The index of the point nearest to `q` and the squared distance (`None` when empty).
    pub fn nearest(&self, q: &[f64; 3]) -> Option<(usize, f64)> {
        if self.pts.is_empty() {
            return None;
        }
        let mut best = (f64::INFINITY, u32::MAX);
        self.search(0, self.pts.len(), q, &mut best);
        Some((best.1 as usize, best.0))
    }

    fn search(&self, lo: usize, hi: usize, q: &[f64; 3], best: &mut (f64, u32)) {
        if hi - lo <= LEAF {
            for &i in &self.idx[lo..hi] {
                let d = d2(q, &self.pts[i as usize]);
                if d < best.0 || (d == best.0 && i < best.1) {
                    *best = (d, i);
                }
            }
            return;
        }
        let mid = (lo + hi) / 2;
        let (ax, value) = self.split[mid];
        let diff = q[ax as usize] - value;
        // Left holds coordinates ≤ the split value, right ≥ it.
        let (first, second) = if diff < 0.0 { ((lo, mid), (mid, hi)) } else { ((mid, hi), (lo, mid)) };
        self.search(first.0, first.1, q, best);
        // `<=`: an equally distant point of lower index may lie on the other side.
        if diff * diff <= best.0 {
            self.search(second.0, second.1, q, best);
        }
    }
}

/// The two halves of a Chamfer-L1 distance and their average.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Chamfer {
    /// Mean distance from each point of the first cloud (the prediction) to the second.
    pub accuracy: f64,
    /// Mean distance from each point of the second cloud (the ground truth) to the first.
    pub completeness: f64,
    /// (accuracy + completeness) / 2: PoinTr's `ChamferDistanceL1`.
    pub l1: f64,
}

/// For every point of `from`, the index of its nearest point of `to` (exact, ties to the lowest
/// index) and the distance.
pub fn nearest_all(from: &[[f64; 3]], to: &[[f64; 3]]) -> Vec<(usize, f64)> {
    let tree = KdTree::new(to);
    from.iter().map(|p| tree.nearest(p).map(|(i, d)| (i, d.sqrt())).unwrap_or((0, f64::INFINITY))).collect()
}

/// The Chamfer-L1 distance of `pred` and `truth` (exact, f64); both must be non-empty.
pub fn chamfer_l1(pred: &[[f64; 3]], truth: &[[f64; 3]]) -> Chamfer {
    let mean = |v: Vec<(usize, f64)>| v.iter().map(|x| x.1).sum::<f64>() / v.len().max(1) as f64;
    let accuracy = mean(nearest_all(pred, truth));
    let completeness = mean(nearest_all(truth, pred));
    Chamfer { accuracy, completeness, l1: (accuracy + completeness) / 2.0 }
}

/// Points of a flat f32 slice (x, y, z triples) as f64.
pub fn to_f64(flat: &[f32]) -> Vec<[f64; 3]> {
    flat.chunks_exact(3).map(|c| [c[0] as f64, c[1] as f64, c[2] as f64]).collect()
}

/// The Chamfer-L1 loss of a batch, differentiable in `pred` [B, P, 3]: `truth` holds B clouds
/// of Q points each (flat x, y, z f32). Nearest neighbours (both ways) are exact and found
/// outside the graph; the distances `sqrt(|p − q|² + 1e-12)` to them are inside it. Returns a
/// one-element tensor: the mean over the batch of PoinTr's `ChamferDistanceL1`.
pub fn chamfer_loss(pred: Tensor<3>, truth: &[Vec<f32>]) -> Tensor<1> {
    let device = pred.device();
    let [b, p, _] = pred.dims();
    assert_eq!(truth.len(), b, "one ground-truth cloud per prediction");
    let q = truth[0].len() / 3;
    assert!(truth.iter().all(|t| t.len() == q * 3) && q > 0, "ground-truth clouds of one size");
    let values: Vec<f32> = pred.clone().inner().into_data().try_to_vec::<f32>().expect("f32 points");
    // Per sample: (truth point nearest to each prediction, prediction nearest to each truth point).
    let nn: Vec<(Vec<usize>, Vec<usize>)> = (0..b)
        .into_par_iter()
        .map(|s| {
            let pr = to_f64(&values[s * p * 3..(s + 1) * p * 3]);
            let tr = to_f64(&truth[s]);
            let a: Vec<usize> = nearest_all(&pr, &tr).into_iter().map(|x| x.0).collect();
            let c: Vec<usize> = nearest_all(&tr, &pr).into_iter().map(|x| x.0).collect();
            (a, c)
        })
        .collect();
    let mut matched = Vec::with_capacity(b * p * 3);
    let mut index = Vec::with_capacity(b * q);
    let mut flat_truth = Vec::with_capacity(b * q * 3);
    for (s, (a, c)) in nn.iter().enumerate() {
        for &j in a {
            matched.extend_from_slice(&truth[s][j * 3..j * 3 + 3]);
        }
        index.extend(c.iter().map(|&i| (s * p + i) as i64));
        flat_truth.extend_from_slice(&truth[s]);
    }
    let matched = Tensor::<3>::from_data(TensorData::new(matched, [b, p, 3]), &device);
    let index = Tensor::<1, Int>::from_data(TensorData::new(index, [b * q]), &device);
    let flat_truth = Tensor::<2>::from_data(TensorData::new(flat_truth, [b * q, 3]), &device);
    let acc = ((pred.clone() - matched).powi_scalar(2).sum_dim(2) + 1e-12).sqrt().mean();
    let nearest = pred.reshape([b * p, 3]).select(0, index);
    let comp = ((nearest - flat_truth).powi_scalar(2).sum_dim(1) + 1e-12).sqrt().mean();
    (acc + comp) / 2.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn cloud(n: usize, seed: u64) -> Vec<[f64; 3]> {
        let mut r = ChaCha8Rng::seed_from_u64(seed);
        (0..n).map(|_| [r.gen_range(-1.0..1.0), r.gen_range(-1.0..1.0), r.gen_range(-0.5..0.5)]).collect()
    }

    #[test]
    fn kd_tree_matches_brute_force_with_ties_to_the_lowest_index() {
        for (n, m, seed) in [(1usize, 5usize, 1u64), (7, 50, 2), (500, 400, 3), (3000, 1000, 4)] {
            let pts = cloud(n, seed);
            let tree = KdTree::new(&pts);
            for q in cloud(m, seed + 100).iter().chain(&pts[..n.min(20)]) {
                let mut best = (0, f64::INFINITY);
                for (i, p) in pts.iter().enumerate() {
                    let d = d2(q, p);
                    if d < best.1 {
                        best = (i, d);
                    }
                }
                assert_eq!(tree.nearest(q), Some(best), "n {n}");
            }
        }
        // Duplicates and a grid of equal distances: the lowest index wins.
        let mut pts: Vec<[f64; 3]> = (0..40).map(|i| [(i % 4) as f64, ((i / 4) % 5) as f64, 0.0]).collect();
        pts.extend(pts.clone());
        let tree = KdTree::new(&pts);
        assert_eq!(tree.nearest(&[1.5, 2.0, 0.0]), Some((9, 0.25)), "points 9 and 10 tie, as do 49 and 50");
        assert_eq!(tree.nearest(&[3.0, 4.0, 0.0]), Some((19, 0.0)));
        assert_eq!(KdTree::new(&[]).nearest(&[0.0; 3]), None);
    }

    #[test]
    fn chamfer_of_a_hand_computed_case() {
        // pred {(0,0,0), (2,0,0)}, truth {(0,0,1), (0,3,0), (2,0,0)}:
        // pred → truth: 1 (to (0,0,1)), 0 → accuracy 0.5;
        // truth → pred: 1, 3, 0 → completeness 4/3; l1 = (0.5 + 4/3) / 2 = 11/12.
        let pred = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
        let truth = [[0.0, 0.0, 1.0], [0.0, 3.0, 0.0], [2.0, 0.0, 0.0]];
        let c = chamfer_l1(&pred, &truth);
        assert_eq!(c.accuracy, 0.5);
        assert!((c.completeness - 4.0 / 3.0).abs() < 1e-15);
        assert!((c.l1 - 11.0 / 12.0).abs() < 1e-15);
        assert_eq!(chamfer_l1(&truth, &truth).l1, 0.0);
    }

    #[test]
    fn chamfer_and_the_loss_agree_with_brute_force() {
        let (a, b) = (cloud(300, 7), cloud(200, 8));
        let brute = |x: &[[f64; 3]], y: &[[f64; 3]]| {
            x.iter().map(|p| y.iter().map(|q| d2(p, q)).fold(f64::INFINITY, f64::min).sqrt()).sum::<f64>()
                / x.len() as f64
        };
        let c = chamfer_l1(&a, &b);
        assert!((c.accuracy - brute(&a, &b)).abs() < 1e-12);
        assert!((c.completeness - brute(&b, &a)).abs() < 1e-12);
        // The loss on two samples (f32) is the mean of the samples' Chamfer-L1.
        let device = Device::flex();
        let (a2, b2) = (cloud(300, 9), cloud(200, 10));
        let f32s = |v: &[[f64; 3]]| v.iter().flat_map(|p| p.map(|x| x as f32)).collect::<Vec<f32>>();
        let back = |v: &[[f64; 3]]| to_f64(&f32s(v));
        let pred: Vec<f32> = [f32s(&a), f32s(&a2)].concat();
        let pred = Tensor::<3>::from_data(TensorData::new(pred, [2, 300, 3]), &device.clone().autodiff());
        let l: f32 = chamfer_loss(pred, &[f32s(&b), f32s(&b2)]).into_scalar();
        let want = (chamfer_l1(&back(&a), &back(&b)).l1 + chamfer_l1(&back(&a2), &back(&b2)).l1) / 2.0;
        assert!((l as f64 - want).abs() < 1e-5, "{l} vs {want}");
    }

    /// The gradient of the loss moves a prediction towards the truth: one point at (1, 0, 0)
    /// and truth at the origin → d loss / dx = 1 (half from each direction, each a mean over
    /// one point).
    #[test]
    fn loss_gradient_of_a_single_point() {
        let device = Device::flex().autodiff();
        let p = Tensor::<3>::from_data(TensorData::new(vec![1.0f32, 0.0, 0.0], [1, 1, 3]), &device)
            .require_grad();
        let loss = chamfer_loss(p.clone(), &[vec![0.0, 0.0, 0.0]]);
        let grads = loss.backward();
        let g: Vec<f32> = p.grad(&grads).unwrap().into_data().try_to_vec::<f32>().unwrap();
        assert!((g[0] - 1.0).abs() < 1e-5 && g[1].abs() < 1e-7 && g[2].abs() < 1e-7, "{g:?}");
    }

    #[test]
    fn forward_shapes_parameter_count_and_grid() {
        let device = Device::flex();
        device.seed(1);
        let s = CompletionShape::small();
        s.validate().unwrap();
        let net = CompletionNet::new(&s, &device);
        assert_eq!(net.num_params(), s.params());
        // Hand count of the default: encoder 3·64+64 + 64·128+128 + 256·256+256 + 256·512+512,
        // coarse 512·512+512 + 512·512+512 + 512·288+288, folding 512·64+64 + 2·64 + 3·64 +
        // 64·64+64 + 64·3+3.
        let enc = 256 + 8320 + 65_792 + 131_584;
        let coarse = 262_656 + 262_656 + 147_744;
        let fold = 32_832 + 128 + 192 + 4160 + 195;
        assert_eq!(s.params(), enc + coarse + fold);
        let x = Tensor::<3>::from_data(
            TensorData::new(
                cloud(2 * 2048, 3).iter().flat_map(|p| p.map(|x| x as f32)).collect::<Vec<_>>(),
                [2, 2048, 3],
            ),
            &device,
        );
        let (coarse_pts, fine) = net.forward(x);
        assert_eq!(coarse_pts.dims(), [2, 96, 3]);
        assert_eq!(fine.dims(), [2, NET_PREDICTED_POINTS, 3]);
        let c: Vec<f32> = coarse_pts.into_data().try_to_vec().unwrap();
        let f: Vec<f32> = fine.into_data().try_to_vec().unwrap();
        assert!(f.iter().all(|x| x.is_finite()));
        // Fine point k of coarse point m is within the folding MLP's reach of c_m: here, at
        // initialization, every fine point of coarse point m stays nearer to c_m than 10 units.
        assert_eq!(net.predict(&[[0.1, 0.2, 0.3]], &device).len(), NET_PREDICTED_POINTS);
        assert!(c.iter().all(|x| x.is_finite()));
        let g = s.grid_points();
        assert_eq!(g.len(), 2 * 64);
        assert_eq!((g[0], g[1], g[126], g[127]), (-0.05, -0.05, 0.05, 0.05));
        let mut bad = s.clone();
        bad.coarse = 100;
        assert!(bad.validate().unwrap_err().to_string().contains("6144"));
        assert!(s.deviation().contains("42.1 M"));
    }

    /// The forward pass is a function of the cloud as a set: permuting the input points does
    /// not change the output (max-pooling over points), up to float summation order (exact
    /// here: per-point layers do not mix points).
    #[test]
    fn output_is_invariant_to_the_input_order() {
        let device = Device::flex();
        device.seed(5);
        let net = CompletionNet::new(&CompletionShape::small(), &device);
        let pts: Vec<[f32; 3]> = cloud(512, 11).iter().map(|p| p.map(|x| x as f32)).collect();
        let mut rev = pts.clone();
        rev.reverse();
        assert_eq!(net.predict(&pts, &device), net.predict(&rev, &device));
    }
}
