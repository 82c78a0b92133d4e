//! Normalization of a loaded mesh to the unit ball (SPEC §1).
//!
//! Views are placed on a sphere of radius 3 around the origin, so every object must fit the
//! unit ball centred there. Raw assets are normalized (`unit`); the benchmark pool's own files
//! are already normalized and are only checked (`none`), so that their frame — and therefore
//! the difficulty annotations computed in it — is untouched. The [`Transform`] returned is
//! what was applied, so that a ground-truth cloud read from a file can be mapped the same way.

use crate::io::load_mesh;
use crate::{GeomError, Mesh};
use std::fmt;
use std::path::Path;
use std::str::FromStr;

/// Largest farthest-vertex distance accepted for an asset declared pre-normalized. The pool's
/// own files reach 1.0015 (Blender export rounding), so the check leaves 1 % of slack.
pub const MAX_PRENORMALIZED_RADIUS: f64 = 1.01;

/// How a mesh is brought to the unit ball.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Normalization {
    /// Centre of the vertex AABB to the origin, farthest vertex at distance 1.
    #[default]
    Unit,
    /// Already normalized: checked against [`MAX_PRENORMALIZED_RADIUS`], used as is.
    None,
}

impl FromStr for Normalization {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "unit" => Ok(Normalization::Unit),
            "none" => Ok(Normalization::None),
            other => Err(format!("unknown normalization '{other}' (expected 'unit' or 'none')")),
        }
    }
}

impl fmt::Display for Normalization {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Normalization::Unit => "unit",
            Normalization::None => "none",
        })
    }
}

/// The similarity applied by [`normalize`]: `p' = (p − center) · scale`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    /// The point moved to the origin (centre of the vertex AABB for `unit`), file frame.
    pub center: [f64; 3],
    /// Uniform scale factor applied after centring (normalized units per file unit).
    pub scale: f64,
}

impl Transform {
    /// The identity transform.
    pub const IDENTITY: Transform = Transform { center: [0.0; 3], scale: 1.0 };

    /// Maps a point of the file frame to the normalized frame.
    #[inline]
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|k| (p[k] - self.center[k]) * self.scale)
    }
}

/// Normalizes `mesh` (loaded from `path`, named in errors) according to `mode`.
///
/// `Unit`: translate the centre of the AABB of the vertices referenced by triangles to the
/// origin, then scale uniformly so that the farthest referenced vertex is at distance 1.
/// `None`: fail with "is not normalized" if the farthest referenced vertex is farther than
/// [`MAX_PRENORMALIZED_RADIUS`]; otherwise return the mesh unchanged with the identity.
pub fn normalize(mut mesh: Mesh, mode: Normalization, path: &Path) -> Result<(Mesh, Transform), GeomError> {
    let Some((lo, hi)) = mesh.bounds() else {
        return Err(GeomError::invalid(path, "mesh has no triangles"));
    };
    match mode {
        Normalization::None => {
            let r = mesh.max_radius();
            if r.is_nan() || r > MAX_PRENORMALIZED_RADIUS {
                return Err(GeomError::invalid(
                    path,
                    format!(
                        "is not normalized: farthest vertex at distance {r:.6} > \
                         {MAX_PRENORMALIZED_RADIUS} (use --normalize unit)"
                    ),
                ));
            }
            Ok((mesh, Transform::IDENTITY))
        }
        Normalization::Unit => {
            let center: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
            let mut r2: f64 = 0.0;
            for tri in &mesh.triangles {
                for &i in tri {
                    let p = mesh.positions[i as usize];
                    let d: [f64; 3] = std::array::from_fn(|k| p[k] - center[k]);
                    r2 = r2.max(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
                }
            }
            let r = r2.sqrt();
            if r.is_nan() || r <= 0.0 || r.is_infinite() {
                return Err(GeomError::invalid(
                    path,
                    format!("cannot normalize: farthest vertex distance from the centre is {r}"),
                ));
            }
            let t = Transform { center, scale: 1.0 / r };
            for p in &mut mesh.positions {
                *p = t.apply(*p);
            }
            Ok((mesh, t))
        }
    }
}

/// Loads a mesh ([`load_mesh`]) and normalizes it ([`normalize`]).
pub fn load_normalized(path: &Path, mode: Normalization) -> Result<(Mesh, Transform), GeomError> {
    normalize(load_mesh(path)?, mode, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Axis-aligned box [lo, hi] as 12 triangles.
    fn cuboid(lo: [f64; 3], hi: [f64; 3]) -> Mesh {
        let positions = (0..8)
            .map(|i| {
                [
                    if i & 1 == 0 { lo[0] } else { hi[0] },
                    if i & 2 == 0 { lo[1] } else { hi[1] },
                    if i & 4 == 0 { lo[2] } else { hi[2] },
                ]
            })
            .collect();
        let quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
        let triangles = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
        Mesh::new(positions, triangles)
    }

    #[test]
    fn parse_and_display() {
        for m in [Normalization::Unit, Normalization::None] {
            assert_eq!(m.to_string().parse::<Normalization>().unwrap(), m);
        }
        assert!("Unit!".parse::<Normalization>().unwrap_err().contains("Unit!"));
        assert_eq!(Normalization::default(), Normalization::Unit);
    }

    #[test]
    fn unit_centres_and_scales_a_moved_box() {
        // Box of half-extents (1, 2, 2) centred at (10, -5, 3): farthest corner at distance 3.
        let m = cuboid([9.0, -7.0, 1.0], [11.0, -3.0, 5.0]);
        let (n, t) = normalize(m, Normalization::Unit, Path::new("box.obj")).unwrap();
        assert_eq!(t.center, [10.0, -5.0, 3.0]);
        assert!((t.scale - 1.0 / 3.0).abs() < 1e-15);
        assert!((n.max_radius() - 1.0).abs() < 1e-12);
        let (lo, hi) = n.bounds().unwrap();
        for k in 0..3 {
            assert!((lo[k] + hi[k]).abs() < 1e-12);
        }
        assert!((hi[0] - 1.0 / 3.0).abs() < 1e-12 && (hi[1] - 2.0 / 3.0).abs() < 1e-12);
        // Only referenced vertices count: a far unreferenced vertex changes nothing.
        let mut m = cuboid([0.0; 3], [2.0; 3]);
        m.positions.push([100.0, 100.0, 100.0]);
        let (n, t) = normalize(m, Normalization::Unit, Path::new("b.obj")).unwrap();
        assert_eq!(t.center, [1.0; 3]);
        assert!((n.max_radius() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn none_checks_the_radius() {
        let m = cuboid([-0.5; 3], [0.5; 3]); // radius 0.866
        let (n, t) = normalize(m.clone(), Normalization::None, Path::new("ok.obj")).unwrap();
        assert_eq!(n, m);
        assert_eq!(t, Transform::IDENTITY);
        let big = cuboid([-0.6; 3], [0.6; 3]); // radius 1.039
        let e = normalize(big, Normalization::None, Path::new("big.obj")).unwrap_err().to_string();
        assert!(
            e.starts_with("big.obj: is not normalized: farthest vertex at distance 1.039230 > 1.01"),
            "{e}"
        );
        assert!(e.contains("--normalize unit"), "{e}");
    }

    #[test]
    fn official_samples_are_prenormalized() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/samples");
        let entries = std::fs::read_dir(&dir).expect("data/samples ships with the repository");
        let mut n = 0;
        for e in entries {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "obj") {
                let (m, t) = load_normalized(&p, Normalization::None).unwrap();
                assert_eq!(t, Transform::IDENTITY);
                let r = m.max_radius();
                assert!(r > 0.9 && r <= 1.0015 + 1e-9, "{}: {r}", p.display());
                n += 1;
            }
        }
        assert_eq!(n, 3);
    }
}
