//! Unit tests of the visibility internals: mode names, the floor-free pixel lookup, bitset
//! helpers, `next_up`, the per-axis cell search both ways, and the distance field.

use super::axis::{cell_at, next_up, start_cell, up_cell};
use super::field::{distance_field, FIELD_CAP};
use super::project::pixel_of;
use super::*;

#[test]
fn mode_parse_and_display() {
    assert_eq!("inverse".parse::<VisibilityMode>().unwrap(), VisibilityMode::Inverse);
    assert_eq!("mesh".parse::<VisibilityMode>().unwrap(), VisibilityMode::Mesh);
    assert!("Mesh".parse::<VisibilityMode>().is_err());
    assert_eq!(VisibilityMode::default().to_string(), "inverse");
}

#[test]
fn fast_pixel_of_matches_intrinsics() {
    use rand::{Rng, SeedableRng};
    let k = objview_render::Intrinsics::default();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let mut cases: Vec<[f64; 3]> = (0..200_000)
        .map(|_| [rng.gen_range(-1.5..1.5), rng.gen_range(-1.5..1.5), rng.gen_range(-0.5..3.0)])
        .collect();
    // Exactly on the image border and on pixel edges.
    for (u, v) in [(0.0, 0.0), (512.0, 3.0), (511.999_999, 0.0), (-1e-12, 5.0), (256.0, 512.0)] {
        cases.push([(u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0]);
    }
    cases.push([0.0, 0.0, 1e-9]);
    cases.push([0.0, 0.0, 1.1e-9]);
    for p in cases {
        assert_eq!(pixel_of(&k, p), k.pixel_of(p), "{p:?}");
    }
}

#[test]
fn bitset_helpers_roundtrip() {
    let a = vec![0u32, 5, 63, 64, 130];
    let b = to_bitset(&a, 131);
    assert_eq!(b.len(), 3);
    assert_eq!(bitset_to_indices(&b), a);
    assert_eq!(bitset_count(&b), 5);
    let c = to_bitset(&[1, 64, 129], 131);
    let u = union_bitsets(&[b, c], 131);
    assert_eq!(bitset_to_indices(&u), vec![0, 1, 5, 63, 64, 129, 130]);
    assert_eq!(union(&[vec![3, 1], vec![2, 3]]), vec![1, 2, 3]);
    let cov = coverage_counts(&[to_bitset(&[0, 2], 4), to_bitset(&[2, 3], 4), to_bitset(&[2], 4)], 4);
    assert_eq!(cov, vec![1, 0, 3, 1]);
}

#[test]
fn next_up_is_the_next_float() {
    assert_eq!(next_up(1.0), 1.0 + f64::EPSILON);
    assert_eq!(next_up(0.0), f64::from_bits(1));
    assert_eq!(next_up(-0.0), f64::from_bits(1));
    assert_eq!(next_up(-1.0), -1.0 + f64::EPSILON / 2.0);
    assert_eq!(next_up(f64::MAX), f64::INFINITY);
    assert_eq!(next_up(f64::INFINITY), f64::INFINITY);
    assert_eq!(next_up(f64::NEG_INFINITY), -f64::MAX);
    assert!(next_up(f64::NAN).is_nan());
    for x in [2.5f64, -3.75, 1e-300, -1e-300, 6.0] {
        let y = next_up(x);
        assert!(y > x && (x + y) / 2.0 == x || (x + y) / 2.0 == y, "{x}");
    }
}

/// `up_cell` on mirrored planes finds the same cell as `cell_at` walking down, and on the
/// planes themselves the same as `cell_at` walking up, for times on and around crossings.
#[test]
fn up_cell_matches_cell_at_both_ways() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let r = 0.02;
    for _ in 0..2000 {
        let n = rng.gen_range(3..40usize);
        let o: f64 = rng.gen_range(-1.0..1.0);
        let g0 = rng.gen_range(-30..10) as f64;
        let p: Vec<f64> = (0..=n).map(|g| (g0 + g as f64) * r - o).collect();
        let m: Vec<f64> = p.iter().rev().map(|&x| -x).collect();
        let d: f64 = rng.gen_range(0.01..1.0);
        let s = 1.0 / d;
        let mut times: Vec<f64> = p.iter().map(|&x| x * s).collect();
        times.extend((0..10).map(|_| rng.gen_range(-3.0..3.0)));
        for t in times.clone() {
            times.push(next_up(t));
        }
        for &t in &times {
            let (lo, hi) = (0, n - 1);
            let up = cell_at::<false>(&p, s, 1, d, r, t, lo, hi);
            assert_eq!(up_cell(&p, s, d, 1.0 / r, t, lo, hi), up, "up t {t}");
            let down = cell_at::<false>(&p, -s, -1, -d, r, t, lo, hi);
            assert_eq!(n - 1 - up_cell(&m, s, d, 1.0 / r, t, lo, hi), down, "down t {t}");
            let incl = cell_at::<true>(&p, s, 1, d, r, t, lo, hi);
            assert_eq!(up_cell(&p, s, d, 1.0 / r, next_up(t), lo, hi), incl, "inclusive t {t}");
            assert_eq!(start_cell(&p, s, d, 1.0 / r, t), (up, p[up + 1] * s), "start t {t}");
        }
    }
}

/// Brute-force Chebyshev distances on a small grid.
#[test]
fn distance_field_is_exact_chebyshev() {
    let keys = [[0, 0, 0], [7, 1, -3], [2, 9, 4], [-5, 3, 70]];
    let set = VoxelSet::from_keys(&keys, 0.1).unwrap();
    let f = distance_field(&set);
    let [nx, ny, nz] = set.grid_dims();
    let o = set.grid_origin();
    for x in 0..nx {
        for y in 0..ny {
            for z in 0..nz {
                let k = [o[0] + x as i32, o[1] + y as i32, o[2] + z as i32];
                let d =
                    keys.iter().map(|q| (0..3).map(|a| (q[a] - k[a]).abs()).max().unwrap()).min().unwrap();
                let want = d.min(FIELD_CAP as i32 + 1) as u8;
                assert_eq!(f[(x * ny + y) * nz + z], want, "cell {k:?}");
            }
        }
    }
}

/// A closed 5×5×5 shell of voxels (keys 0..5 on every axis, the 3×3×3 inside empty) with one
/// voxel in the cavity, and optionally a hole in the shell's +z face.
fn shell_with_ball(hole: bool) -> VoxelSet {
    let mut keys = Vec::new();
    for x in 0..5 {
        for y in 0..5 {
            for z in 0..5 {
                let on_shell = [x, y, z].iter().any(|&c| c == 0 || c == 4);
                if on_shell && !(hole && [x, y, z] == [2, 2, 4]) {
                    keys.push([x, y, z]);
                }
            }
        }
    }
    keys.push([2, 2, 2]);
    VoxelSet::from_keys(&keys, 0.1).unwrap()
}

#[test]
fn open_faces_are_the_exterior_face_neighbours() {
    use super::prune::open_faces;
    // Bits: +x 0, −x 1, +y 2, −y 3, +z 4, −z 5.
    let set = shell_with_ball(false);
    let open = open_faces(&set);
    let of = |k: [i32; 3]| open[set.index_of(k).unwrap()];
    // Sealed inside: the cavity's ball and the shell's inner faces are never exterior.
    assert_eq!(of([2, 2, 2]), 0);
    assert_eq!(of([4, 2, 2]), 0b000001, "+x face centre: only its outer face");
    assert_eq!(of([0, 2, 2]), 0b000010);
    assert_eq!(of([2, 4, 2]), 0b000100);
    assert_eq!(of([2, 2, 0]), 0b100000);
    assert_eq!(of([4, 4, 2]), 0b000101, "edge: two outer faces");
    assert_eq!(of([0, 0, 0]), 0b101010, "corner: three outer faces");
    // Brute force on every voxel: a face is open exactly when its neighbour is outside the
    // 5×5×5 block (the cavity is sealed).
    for (i, k) in set.keys().iter().enumerate() {
        let mut want = 0u8;
        for a in 0..3 {
            for (s, step) in [1, -1].into_iter().enumerate() {
                let mut n = *k;
                n[a] += step;
                if n.iter().any(|&c| !(0..5).contains(&c)) {
                    want |= 1 << (2 * a + s);
                }
            }
        }
        assert_eq!(open[i], want, "{k:?}");
    }
    // A hole in the +z face opens the cavity: the ball and the inner faces become exterior.
    let set = shell_with_ball(true);
    let open = open_faces(&set);
    let of = |k: [i32; 3]| open[set.index_of(k).unwrap()];
    assert_eq!(of([2, 2, 2]), 0b111111);
    assert_eq!(of([2, 2, 0]), 0b110000, "floor centre: outer face and the cavity side");
    assert_eq!(of([4, 2, 2]), 0b000011);
    assert_eq!(of([2, 3, 4]), 0b111000, "next to the hole: −y (the hole), +z, −z (the cavity)");
}

#[test]
fn needed_pixels_cover_every_pixel_centre_in_a_live_footprint() {
    use super::project::TILE;
    use super::prune::open_faces;
    use crate::key::center_of;
    use objview_geom::Pose;
    use objview_render::{Camera, Intrinsics};
    use rand::{Rng, SeedableRng};
    // A shell of r = 0.1 voxels; the union holds all but a scattered few, so pruning marks the
    // footprints of those that are live. Images whose size is no multiple of the 8-pixel tiles,
    // off-centre principal points, one mirrored.
    let r = 0.1;
    let mut keys = Vec::new();
    for x in -8..8 {
        for y in -8..8 {
            for z in -8..8 {
                let d2 = (x * x + y * y + z * z) as f64;
                if (36.0..64.0).contains(&d2) {
                    keys.push([x, y, z]);
                }
            }
        }
    }
    let set = VoxelSet::from_keys(&keys, r).unwrap();
    let caster = InverseCaster::new(&set);
    let open = open_faces(&set);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let mut marked_total = 0;
    for trial in 0..12 {
        let k = Intrinsics {
            width: 517 - 37 * (trial % 3),
            height: 389 + 13 * (trial % 4),
            fx: if trial % 5 == 4 { -500.0 } else { 480.0 },
            fy: 470.0,
            cx: 240.3 + 3.0 * trial as f64,
            cy: 190.7,
            ..Intrinsics::default()
        };
        let dir: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-1.0..1.0));
        let n = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
        let rad = rng.gen_range(2.5..4.0);
        let cam = Camera::new(
            Pose { center: std::array::from_fn(|a| rad * dir[a] / n), look_at: [0.0; 3], roll: 0.3 },
            k,
        );
        let mut acc = vec![u64::MAX; set.len().div_ceil(64)];
        for _ in 0..set.len() / 40 {
            let i = rng.gen_range(0..set.len());
            acc[i >> 6] &= !(1 << (i & 63));
        }
        let (w, h) = (k.width as usize, k.height as usize);
        let mtw = w.div_ceil(TILE);
        let mut need = vec![0u64; mtw * h.div_ceil(TILE)];
        assert!(caster.needed_pixels(&cam, &acc, &mut need), "trial {trial}: pruning gave up");
        let mut want = vec![false; w * h];
        // Brute force: the live voxels (not in acc, an exterior face turned to the camera),
        // then every pixel centre within each one's footprint, pixel by pixel.
        let o = cam.center;
        let camc: [f64; 3] = std::array::from_fn(|a| (o[a] / r).floor());
        let rho = 0.5 * 3f64.sqrt() * r;
        let (afx, afy) = (k.fx.abs() * (1.0 + 1e-9), k.fy.abs() * (1.0 + 1e-9));
        for (i, key) in set.keys().iter().enumerate() {
            let facing = (0..3).fold(0u8, |m, a| {
                let ka = key[a] as f64;
                m | ((ka <= camc[a]) as u8) << (2 * a) | ((ka >= camc[a]) as u8) << (2 * a + 1)
            });
            if acc[i >> 6] >> (i & 63) & 1 == 1 || open[i] & facing == 0 {
                continue;
            }
            let pc = cam.to_camera(center_of(*key, r));
            let z = pc[2];
            let (uc, vc) = (k.fx * pc[0] / z + k.cx, k.fy * pc[1] / z + k.cy);
            let dist = (pc[0] * pc[0] + pc[1] * pc[1] + z * z).sqrt();
            let hr = rho * dist / (z * (z - rho));
            let (hu, hv) = (afx * hr + 1.0, afy * hr + 1.0);
            for v in 0..h {
                for u in 0..w {
                    if (u as f64 + 0.5 - uc).abs() <= hu && (v as f64 + 0.5 - vc).abs() <= hv {
                        let bit = need[(v / TILE) * mtw + u / TILE] >> ((v % TILE) * TILE + u % TILE) & 1;
                        assert_eq!(bit, 1, "trial {trial}: pixel ({u}, {v}) of voxel {key:?}");
                        want[v * w + u] = true;
                    }
                }
            }
        }
        // And nothing far from them: a marked pixel is in a footprint or just before one (the
        // marked range starts up to one pixel early on each axis).
        for v in 0..h {
            for u in 0..w {
                if need[(v / TILE) * mtw + u / TILE] >> ((v % TILE) * TILE + u % TILE) & 1 == 1 {
                    let near = [(0, 0), (1, 0), (0, 1), (1, 1)]
                        .iter()
                        .any(|&(du, dv)| u + du < w && v + dv < h && want[(v + dv) * w + u + du]);
                    assert!(near, "trial {trial}: pixel ({u}, {v}) marked outside every footprint");
                    marked_total += 1;
                }
            }
        }
    }
    assert!(marked_total > 1000, "{marked_total}");
}
