//! View selection from the scores: RSE takes the largest gain, RSE-Mov trades normalized gain
//! against normalized travel cost. Pure functions over the per-candidate numbers, separate from
//! the scoring so that the rules can be read and tested on their own.

/// The index (into `gains`) RSE chooses: the largest gain, ties to the lowest index; `None` when
/// `gains` is empty.
pub fn select_rse(gains: &[f64]) -> Option<usize> {
    argmax(gains.iter().copied())
}

/// The index RSE-Mov chooses: the largest (1 − γ)·gain/Σgain − γ·cost/Σcost (a zero sum drops
/// its term), ties to the lowest index; `None` when empty. `gains` and `costs` have the same
/// length.
pub fn select_rse_mov(gains: &[f64], costs: &[f64], gamma: f64) -> Option<usize> {
    let sg: f64 = gains.iter().sum();
    let sc: f64 = costs.iter().sum();
    let norm = |x: f64, s: f64| if s > 0.0 { x / s } else { 0.0 };
    argmax(gains.iter().zip(costs).map(|(&g, &c)| (1.0 - gamma) * norm(g, sg) - gamma * norm(c, sc)))
}

fn argmax(values: impl Iterator<Item = f64>) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (i, v) in values.enumerate() {
        let better = match best {
            None => true,
            Some((_, b)) => v > b,
        };
        if better {
            best = Some((i, v));
        }
    }
    best.map(|(i, _)| i)
}

/// Euclidean distance between two points.
pub(super) fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

/// Camera centres closer than this (per coordinate, object units) are the same position.
const SAME_POSITION: f64 = 1e-9;

pub(super) fn same_position(a: [f64; 3], b: [f64; 3]) -> bool {
    (0..3).all(|k| (a[k] - b[k]).abs() <= SAME_POSITION)
}
