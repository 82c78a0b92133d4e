//! `inverse` visibility against an independent brute force: for each ray, a slab test against
//! every voxel of the set, keeping the voxel with the smallest entry distance within range.
//! Random small sets (clustered blobs, sparse sets with large empty regions that exercise the
//! distance-field leaps, sphere shells), random cameras at radius 1.5–3 including the poles and
//! rolls, and random rays from inside the grid.

mod common;
use common::shell_keys;
use objview_geom::Pose;
use objview_render::{Camera, Intrinsics};
use objview_voxel::{center_of, pixel_ray_direction, InverseCaster, VoxelKey, VoxelSet};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Brute force: index (into `keys`, sorted) of the first voxel entered by `o + t·d`,
/// 0 ≤ t ≤ tmax, by the slab method: the voxel with the smallest entry `t` among those whose
/// closed box the ray meets. Where the ray passes exactly through a cell edge or corner, the
/// boxes touched only there (zero-length intersection) count only if the walk's documented tie
/// order (z, then y, then x) enters them: the axes on which the ray enters such a box at that
/// instant must be crossed before the axes on which it leaves it; among boxes entered at the
/// same instant, fewer entering axes come first. The voxel containing `o` (half-open cells, the
/// walk's start) wins outright. `Err` if two voxels still tie (never expected).
fn brute_first(keys: &[VoxelKey], r: f64, o: [f64; 3], d: [f64; 3], tmax: f64) -> Result<Option<usize>, ()> {
    let mut best: Option<((f64, u32), usize)> = None;
    let mut tie = false;
    for (i, k) in keys.iter().enumerate() {
        let mut slab = [(f64::NEG_INFINITY, f64::INFINITY); 3];
        let mut miss = false;
        let mut contains = true;
        for a in 0..3 {
            let lo = k[a] as f64 * r;
            let hi = (k[a] + 1) as f64 * r;
            contains &= lo <= o[a] && o[a] < hi;
            if d[a] == 0.0 {
                // Parallel: inside the half-open slab or never.
                miss |= !(lo <= o[a] && o[a] < hi);
                continue;
            }
            let inv = 1.0 / d[a];
            let (t0, t1) = ((lo - o[a]) * inv, (hi - o[a]) * inv);
            slab[a] = (t0.min(t1), t0.max(t1));
        }
        let t_in = slab.iter().map(|s| s.0).fold(f64::NEG_INFINITY, f64::max);
        let t_out = slab.iter().map(|s| s.1).fold(f64::INFINITY, f64::min);
        if miss {
            continue;
        }
        if contains {
            // The half-open cell of the camera centre: where the walk starts.
            best = Some(((0.0, 0), i));
            tie = false;
            break;
        }
        if t_in > t_out || t_out <= 0.0 {
            continue;
        }
        let entering: Vec<usize> = (0..3).filter(|&a| d[a] != 0.0 && slab[a].0 == t_in).collect();
        if t_in == t_out {
            // Touched at a single instant: entered only if every entering axis comes before
            // (has a higher index than) every leaving axis.
            let leaving: Vec<usize> = (0..3).filter(|&a| d[a] != 0.0 && slab[a].1 == t_out).collect();
            if entering.iter().any(|&e| leaving.iter().any(|&l| l > e)) {
                continue;
            }
        }
        let rank = (t_in, entering.len() as u32);
        if rank.0 > tmax {
            continue;
        }
        match best {
            Some((b, _)) if rank > b => {}
            Some((b, _)) if rank == b => tie = true,
            _ => {
                best = Some((rank, i));
                tie = false;
            }
        }
    }
    if tie {
        Err(())
    } else {
        Ok(best.map(|(_, i)| i))
    }
}

/// Brute-force O(v) following SPEC §4 literally; `None` if a tie made it ambiguous.
fn brute_observed(keys: &[VoxelKey], r: f64, cam: &Camera, tmax: f64) -> Option<Vec<u32>> {
    let mut out = Vec::new();
    for k in keys {
        let pc = cam.to_camera(center_of(*k, r));
        let Some((u, v)) = cam.intrinsics.pixel_of(pc) else { continue };
        let d = pixel_ray_direction(cam, u, v);
        if let Some(i) = brute_first(keys, r, cam.center, d, tmax).ok()? {
            out.push(i as u32);
        }
    }
    out.sort_unstable();
    out.dedup();
    Some(out)
}

fn random_unit(rng: &mut ChaCha8Rng) -> [f64; 3] {
    loop {
        let v: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-1.0..1.0));
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if n > 0.1 && n <= 1.0 {
            return [v[0] / n, v[1] / n, v[2] / n];
        }
    }
}

/// Random cameras: radius 1.5–3, random look-at near the origin, random roll; plus both poles
/// (which trigger the pole rule) and axis views.
fn cameras(rng: &mut ChaCha8Rng, n: usize) -> Vec<Camera> {
    let mut poses = vec![
        Pose::from_direction([0.0, 0.0, 1.0], 2.0),
        Pose { roll: 0.7, ..Pose::from_direction([0.0, 0.0, -1.0], 2.5) },
        Pose::from_direction([1.0, 0.0, 0.0], 1.5),
    ];
    while poses.len() < n {
        let d = random_unit(rng);
        let rad = rng.gen_range(1.5..3.0);
        let look: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-0.15..0.15));
        poses.push(Pose {
            center: [rad * d[0], rad * d[1], rad * d[2]],
            look_at: look,
            roll: rng.gen_range(-3.2..3.2),
        });
    }
    poses.into_iter().map(|p| Camera::new(p, Intrinsics::default())).collect()
}

fn blob_keys(rng: &mut ChaCha8Rng, half: i32, count: usize) -> Vec<VoxelKey> {
    (0..count).map(|_| std::array::from_fn(|_| rng.gen_range(-half..half))).collect()
}

fn check_views(keys: &[VoxelKey], r: f64, cams: &[Camera]) -> (usize, usize) {
    let set = VoxelSet::from_keys(keys, r).unwrap();
    let caster = InverseCaster::new(&set);
    let (mut checked, mut total) = (0, 0);
    for cam in cams {
        let fast = caster.observe(cam);
        let walk = caster.observe_walk(cam);
        let Some(slow) = brute_observed(set.keys(), r, cam, 6.0) else { continue };
        assert_eq!(walk, slow, "walk, camera {:?}", cam.pose);
        assert_eq!(fast, slow, "z-buffer, camera {:?}", cam.pose);
        checked += 1;
        total += fast.len();
    }
    (checked, total)
}

#[test]
fn dense_blobs_match_brute_force() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut seen = 0;
    for trial in 0..6 {
        let keys = blob_keys(&mut rng, 6 + trial, 300);
        let cams = cameras(&mut rng, 12);
        let (checked, total) = check_views(&keys, 0.05, &cams);
        assert_eq!(checked, cams.len());
        seen += total;
    }
    assert!(seen > 500, "too few observed voxels to be a meaningful test: {seen}");
}

#[test]
fn sparse_sets_exercise_leaps_and_match() {
    // A few hundred voxels spread over a 60³ box at r = 0.02: large empty regions, so rays
    // leap with distance values up to the cap.
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    for _ in 0..4 {
        let mut keys = blob_keys(&mut rng, 30, 250);
        keys.extend(blob_keys(&mut rng, 4, 60)); // a dense core behind the sparse cloud
        let cams = cameras(&mut rng, 10);
        let (checked, total) = check_views(&keys, 0.02, &cams);
        assert_eq!(checked, cams.len());
        assert!(total > 100, "{total}");
    }
}

#[test]
fn sphere_shells_match_brute_force() {
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    for (r, radius) in [(0.05, 0.45), (0.04, 0.3)] {
        let keys = shell_keys(r, radius, r * 1.2);
        assert!(keys.len() > 300, "{}", keys.len());
        let cams = cameras(&mut rng, 6);
        let set = VoxelSet::from_keys(&keys, r).unwrap();
        let (checked, total) = check_views(&keys, r, &cams);
        assert_eq!(checked, cams.len());
        // A closed shell: each view sees roughly the facing half, never everything.
        let mean = total as f64 / checked as f64;
        assert!(mean > 0.2 * set.len() as f64 && mean < 0.7 * set.len() as f64, "{mean} of {}", set.len());
    }
}

#[test]
fn random_rays_from_anywhere_match_brute_force() {
    // Origins inside the grid (often inside empty cells near voxels, sometimes inside voxels),
    // arbitrary unit directions, short and long ranges.
    let mut rng = ChaCha8Rng::seed_from_u64(14);
    let r = 0.05;
    let mut keys = blob_keys(&mut rng, 8, 200);
    keys.extend(shell_keys(r, 0.3, r));
    let set = VoxelSet::from_keys(&keys, r).unwrap();
    let (mut hits, mut rays) = (0, 0);
    for range in [6.0, 0.25] {
        let caster = InverseCaster::with_max_range(&set, range);
        for _ in 0..3000 {
            let o: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-0.7..0.7));
            let d = random_unit(&mut rng);
            let Ok(want) = brute_first(set.keys(), r, o, d, range) else { continue };
            let got = caster.first_hit(o, d).map(|i| i as usize);
            assert_eq!(got, want, "o {o:?} d {d:?} range {range}");
            rays += 1;
            hits += got.is_some() as usize;
        }
    }
    assert!(rays > 5900 && hits > 500 && hits < rays - 1000, "{hits}/{rays}");
}

#[test]
fn tile_bounded_walk_equals_plain_walk_on_larger_sets_and_close_cameras() {
    // A thin sphere shell at r = 0.02 plus a blob inside (~9k voxels): too big for the brute
    // force, but the two walks (with and without the per-view depth bound) must agree, also for
    // cameras close to or inside the object (boxes reaching the camera plane, camera in the
    // grid box, camera inside a voxel).
    let mut rng = ChaCha8Rng::seed_from_u64(15);
    let r = 0.02;
    let mut keys = shell_keys(r, 0.55, r);
    keys.extend(blob_keys(&mut rng, 12, 800));
    let set = VoxelSet::from_keys(&keys, r).unwrap();
    let caster = InverseCaster::new(&set);
    let mut cams = cameras(&mut rng, 8);
    for _ in 0..6 {
        let d = random_unit(&mut rng);
        let rad = rng.gen_range(0.2..1.0);
        cams.push(Camera::new(
            Pose { center: [rad * d[0], rad * d[1], rad * d[2]], look_at: [0.0; 3], roll: 0.3 },
            Intrinsics::default(),
        ));
    }
    let inside = center_of(keys[0], r);
    cams.push(Camera::new(Pose { center: inside, look_at: [0.0; 3], roll: 0.0 }, Intrinsics::default()));
    for cam in &cams {
        let fast = caster.observe(cam);
        assert_eq!(fast, caster.observe_walk(cam), "camera {:?}", cam.pose);
        assert!(!fast.is_empty());
    }
}
