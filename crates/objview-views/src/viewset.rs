//! View sets (SPEC §3): lists of unit view directions, their file format and the built-in
//! `tammes-N` sets.
//!
//! A view-set file holds one `x y z` per line; `#` starts a comment (whole-line or trailing) and
//! blank lines are ignored. Every direction is normalized on load, so files written with a few
//! decimals (as the official ones are) are accepted as they are; a direction that is already
//! unit to round-off (|d|² within 8 ulp of 1) is kept bit for bit. Files are written with Rust's
//! shortest round-trip float formatting, so `write` → `load` gives back bit-identical unit
//! vectors and the output is deterministic.

use std::fmt::Write as _;
use std::path::Path;

use objview_geom::Pose;

use crate::builtin;
use crate::error::ViewsError;

/// The start view direction of every episode (SPEC §3): normalize(1, 1, 1), feasible in every
/// built-in view space.
pub const START_DIRECTION: [f64; 3] =
    [0.577_350_269_189_625_8, 0.577_350_269_189_625_8, 0.577_350_269_189_625_8];

/// A named list of unit view directions.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewSet {
    /// Name: `tammes-N` for built-in sets, the file path for loaded files.
    pub name: String,
    /// Unit directions.
    pub dirs: Vec<[f64; 3]>,
}

/// Normalizes `d`, or `None` when it is zero or not finite.
pub(crate) fn normalize(d: [f64; 3]) -> Option<[f64; 3]> {
    if !d.iter().all(|v| v.is_finite()) {
        return None;
    }
    // Scale first so that huge or tiny (but finite, non-zero) inputs do not overflow/underflow.
    let m = d.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
    if m == 0.0 {
        return None;
    }
    let s = [d[0] / m, d[1] / m, d[2] / m];
    let n = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
    Some([s[0] / n, s[1] / n, s[2] / n])
}

/// Minimum pairwise angle (degrees) of a list of unit vectors; `None` with fewer than 2.
///
/// Exact O(N²): the closest pair is selected by squared chord length (well conditioned for small
/// angles) and its angle is `2·asin(chord/2)`.
pub fn min_pairwise_angle_deg(dirs: &[[f64; 3]]) -> Option<f64> {
    if dirs.len() < 2 {
        return None;
    }
    let mut best = f64::INFINITY;
    for (i, a) in dirs.iter().enumerate() {
        for b in &dirs[i + 1..] {
            let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
            let c2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
            if c2 < best {
                best = c2;
            }
        }
    }
    let half = (best.sqrt() / 2.0).min(1.0);
    Some((2.0 * half.asin()).to_degrees())
}

impl ViewSet {
    /// Builds a set from directions, normalizing each one; `None` if one is zero or not finite.
    pub fn from_dirs(name: impl Into<String>, dirs: &[[f64; 3]]) -> Option<ViewSet> {
        let dirs = dirs.iter().map(|d| normalize(*d)).collect::<Option<Vec<_>>>()?;
        Some(ViewSet { name: name.into(), dirs })
    }

    /// Number of directions.
    pub fn len(&self) -> usize {
        self.dirs.len()
    }

    /// True when the set has no direction.
    pub fn is_empty(&self) -> bool {
        self.dirs.is_empty()
    }

    /// Parses view-set text; `origin` names the source in error messages.
    pub fn parse(origin: &str, text: &str) -> Result<ViewSet, ViewsError> {
        let mut dirs = Vec::new();
        for (idx, raw) in text.lines().enumerate() {
            let line_no = idx + 1;
            let content = raw.split('#').next().unwrap_or("").trim();
            if content.is_empty() {
                continue;
            }
            let bad =
                |reason: String| ViewsError::ViewSetLine { path: origin.to_string(), line: line_no, reason };
            let parts: Vec<&str> =
                content.split(|c: char| c.is_whitespace() || c == ',').filter(|p| !p.is_empty()).collect();
            if parts.len() != 3 {
                return Err(bad(format!("expected 3 numbers `x y z`, found {} in {content:?}", parts.len())));
            }
            let mut v = [0.0; 3];
            for (k, p) in parts.iter().enumerate() {
                let x: f64 =
                    p.parse().map_err(|_| bad(format!("{} is not a number: {p:?}", ["x", "y", "z"][k])))?;
                if !x.is_finite() {
                    return Err(bad(format!("{} is not finite: {p:?}", ["x", "y", "z"][k])));
                }
                v[k] = x;
            }
            let r2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            if (r2 - 1.0).abs() <= 8.0 * f64::EPSILON {
                // Already unit to round-off: kept bit for bit, so write → load is exact.
                dirs.push(v);
            } else {
                let n = normalize(v).ok_or_else(|| bad("zero vector cannot be normalized".into()))?;
                dirs.push(n);
            }
        }
        if dirs.is_empty() {
            return Err(ViewsError::EmptyViewSet { path: origin.to_string() });
        }
        Ok(ViewSet { name: origin.to_string(), dirs })
    }

    /// Loads a view-set file.
    pub fn load(path: &Path) -> Result<ViewSet, ViewsError> {
        let text = objview_geom::fsutil::read_text(path).map_err(|source| ViewsError::Io {
            path: path.to_path_buf(),
            op: "read",
            source,
        })?;
        ViewSet::parse(&path.display().to_string(), &text)
    }

    /// Resolves `tammes-N` (a shipped set, built into the binary) or a view-set file path.
    pub fn resolve(spec: &str) -> Result<ViewSet, ViewsError> {
        if let Some(text) = builtin::tammes_text(spec) {
            let mut vs = ViewSet::parse(&format!("builtin:{spec}"), text)?;
            vs.name = spec.to_string();
            return Ok(vs);
        }
        let path = Path::new(spec);
        if path.is_file() {
            return ViewSet::load(path);
        }
        Err(ViewsError::UnknownViewSet {
            spec: spec.to_string(),
            shipped: builtin::SHIPPED_TAMMES
                .iter()
                .map(|(n, _)| n.to_string())
                .collect::<Vec<_>>()
                .join(", "),
        })
    }

    /// The file text: optional `#` header lines, then one `x y z` per line, each number in
    /// shortest round-trip form (deterministic, reloads bit-identically).
    pub fn to_text(&self, header: &[String]) -> String {
        let mut s = String::new();
        for h in header {
            for line in h.lines() {
                let _ = writeln!(s, "# {line}");
            }
        }
        for d in &self.dirs {
            let _ = writeln!(s, "{:?} {:?} {:?}", d[0], d[1], d[2]);
        }
        s
    }

    /// Writes the set to `path` (see [`ViewSet::to_text`]).
    pub fn write(&self, path: &Path, header: &[String]) -> Result<(), ViewsError> {
        std::fs::write(path, self.to_text(header)).map_err(|source| ViewsError::Io {
            path: path.to_path_buf(),
            op: "write",
            source,
        })
    }

    /// Minimum pairwise angle in degrees (exact, O(N²)); `None` with fewer than 2 directions.
    pub fn min_angle_deg(&self) -> Option<f64> {
        min_pairwise_angle_deg(&self.dirs)
    }

    /// The poses `[radius·d, 0, 0, 0, 0]` looking at the origin (SPEC §2).
    pub fn poses(&self, radius: f64) -> Vec<Pose> {
        self.dirs.iter().map(|d| Pose::from_direction(*d, radius)).collect()
    }
}

/// The start pose: [`START_DIRECTION`] at `radius`, looking at the origin, roll 0.
pub fn start_pose(radius: f64) -> Pose {
    Pose::from_direction(START_DIRECTION, radius)
}
