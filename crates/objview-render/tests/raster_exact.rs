//! Exactness of the rasterizer: against closed-form answers (sphere, planes, look-at, roll)
//! and against the brute-force ray-casting oracle (`reference::render`) on random and closed
//! meshes from generic, near (camera inside the unit ball: near-plane clipping) and polar poses;
//! plus determinism of the parallel renderer.

use objview_geom::{Mesh, Pose};
use objview_render::bench::{icosphere, spiral_poses, torus};
use objview_render::{reference, render_parallel, Camera, Frame, Intrinsics, Renderer, NO_HIT};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn small() -> Intrinsics {
    Intrinsics::from_fov(128, 128, 45.0, 45.0)
}

fn in_ball(rng: &mut ChaCha8Rng, r: f64) -> [f64; 3] {
    loop {
        let p: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-1.0..1.0));
        if p.iter().map(|x| x * x).sum::<f64>() <= 1.0 {
            return p.map(|x| x * r);
        }
    }
}

/// `n` independent triangles with corners uniform in the unit ball (large, interpenetrating).
fn big_random_triangles(n: usize, seed: u64) -> Mesh {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let pos: Vec<[f64; 3]> = (0..3 * n).map(|_| in_ball(&mut rng, 1.0)).collect();
    Mesh::new(pos, (0..n as u32).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect())
}

/// A soup of `n` small triangles (edges up to ~0.2) around random centres in the ball, with
/// some shared vertices (fans) so that shared edges are exercised too.
fn soup(n: usize, seed: u64) -> Mesh {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut pos = Vec::new();
    let mut tris = Vec::new();
    while tris.len() < n {
        let c = in_ball(&mut rng, 0.9);
        let base = pos.len() as u32;
        pos.push(c);
        let k = rng.gen_range(3..7);
        for _ in 0..k {
            let d = in_ball(&mut rng, 0.2);
            pos.push([c[0] + d[0], c[1] + d[1], c[2] + d[2]]);
        }
        for j in 0..k as u32 {
            tris.push([base, base + 1 + j, base + 1 + (j + 1) % k as u32]);
        }
    }
    Mesh::new(pos, tris)
}

/// Poses: generic at radius 3 with rolls, the two poles, radius-1 cameras (geometry right at
/// the near plane), and cameras inside the ball (triangles with corners behind the camera).
fn poses() -> Vec<Pose> {
    let mut p = spiral_poses(4, 3.0);
    p[1].roll = 0.7;
    p[3].roll = -2.0;
    p.push(Pose { center: [0.0, 0.0, 3.0], look_at: [0.0; 3], roll: 0.0 });
    p.push(Pose { center: [0.0, 0.0, -3.0], look_at: [0.0; 3], roll: 1.0 });
    p.push(Pose { center: [0.0, 0.0, 1.0], look_at: [0.0; 3], roll: 0.0 });
    p.push(Pose::from_direction([1.0, -0.4, 0.3], 1.0));
    p.push(Pose { center: [0.6, 0.3, -0.2], look_at: [-0.2, 0.1, 0.1], roll: 0.3 });
    p.push(Pose { center: [0.0, 0.05, 0.1], look_at: [1.0, 0.0, 0.0], roll: 0.0 });
    p
}

struct Cmp {
    total: usize,
    agree: usize,
    hits: usize,
    non_silhouette: usize,
    max_rel: f64,
}

/// Pixel-by-pixel comparison with the oracle: agreement = same hit/miss and relative depth
/// difference ≤ 1e-5. A disagreeing pixel counts as a silhouette pixel when one of its
/// 8 neighbours sees (in the oracle) a different triangle or nothing.
fn compare(fast: &Frame, oracle: &Frame) -> Cmp {
    let (w, h) = (fast.width() as i64, fast.height() as i64);
    let mut c = Cmp { total: fast.depth.len(), agree: 0, hits: 0, non_silhouette: 0, max_rel: 0.0 };
    for v in 0..h {
        for u in 0..w {
            let i = (v * w + u) as usize;
            let (ta, tb) = (fast.triangle[i], oracle.triangle[i]);
            let (za, zb) = (fast.depth[i] as f64, oracle.depth[i] as f64);
            assert_eq!(ta == NO_HIT, za == 0.0, "depth/triangle disagree at {u},{v}");
            let same = match (ta == NO_HIT, tb == NO_HIT) {
                (true, true) => true,
                (false, false) => {
                    let rel = (za - zb).abs() / zb;
                    c.max_rel = c.max_rel.max(rel);
                    rel <= 1e-5
                }
                _ => false,
            };
            c.hits += (tb != NO_HIT) as usize;
            if same {
                c.agree += 1;
                continue;
            }
            let silhouette = (-1..=1).any(|dv| {
                (-1..=1).any(|du| {
                    let (x, y) = (u + du, v + dv);
                    x >= 0 && y >= 0 && x < w && y < h && oracle.triangle[(y * w + x) as usize] != tb
                })
            });
            if !silhouette {
                eprintln!("non-silhouette mismatch at ({u},{v}): fast ({ta}, {za}) oracle ({tb}, {zb})");
                c.non_silhouette += 1;
            }
        }
    }
    c
}

fn check_against_oracle(name: &str, mesh: &Mesh, intr: Intrinsics, poses: &[Pose]) {
    let mut r = Renderer::new();
    let mut f = Frame::empty(Camera::new(poses[0], intr));
    let mut hits = 0;
    for (k, &p) in poses.iter().enumerate() {
        let cam = Camera::new(p, intr);
        r.render_into(mesh, &cam, &mut f);
        let o = reference::render(mesh, &cam);
        let c = compare(&f, &o);
        let frac = c.agree as f64 / c.total as f64;
        eprintln!(
            "{name} pose {k}: {} hits, {} disagreeing pixels ({:.4}%), max rel depth diff {:.2e}",
            c.hits,
            c.total - c.agree,
            100.0 * (1.0 - frac),
            c.max_rel
        );
        assert!(frac >= 0.999, "{name} pose {k}: agreement {frac}");
        assert_eq!(c.non_silhouette, 0, "{name} pose {k}");
        hits += c.hits;
    }
    assert!(hits > 0, "{name}: nothing visible from any pose");
}

#[test]
fn matches_oracle_on_big_random_triangles() {
    check_against_oracle("big", &big_random_triangles(60, 1), small(), &poses());
}

#[test]
fn matches_oracle_on_soup() {
    check_against_oracle("soup", &soup(400, 2), small(), &poses());
}

#[test]
fn matches_oracle_on_closed_meshes() {
    check_against_oracle("icosphere", &icosphere(3), small(), &poses());
    check_against_oracle("torus", &torus(24, 12, 0.7, 0.3), small(), &poses());
}

#[test]
fn matches_oracle_at_full_resolution() {
    let intr = Intrinsics::default();
    let p = [
        Pose::from_direction([0.3, -1.0, 0.6], 3.0),
        Pose { center: [0.9, 0.5, 0.1], look_at: [0.0, 0.0, 0.0], roll: 0.4 },
    ];
    check_against_oracle("icosphere-512", &icosphere(2), intr, &p);
    check_against_oracle("soup-512", &soup(250, 7), intr, &p[1..]);
}

/// Smallest t > 0 with |c + t·d| = 1 (the exact unit sphere), if any.
fn sphere_hit(c: [f64; 3], d: [f64; 3]) -> Option<f64> {
    let a: f64 = d.iter().map(|x| x * x).sum();
    let b: f64 = 2.0 * (0..3).map(|k| c[k] * d[k]).sum::<f64>();
    let cc: f64 = c.iter().map(|x| x * x).sum::<f64>() - 1.0;
    let disc = b * b - 4.0 * a * cc;
    (disc >= 0.0).then(|| (-b - disc.sqrt()) / (2.0 * a))
}

#[test]
fn tessellated_sphere_matches_the_analytic_sphere() {
    // Icosphere(4): every face lies between the unit sphere and the sphere of radius 1 − δ,
    // δ = 1 − (smallest distance of a face plane from the centre), computed from the mesh.
    let mesh = icosphere(4);
    let delta = (0..mesh.num_triangles())
        .map(|t| {
            let [a, b, c] = mesh.triangle(t);
            let e1: [f64; 3] = std::array::from_fn(|k| b[k] - a[k]);
            let e2: [f64; 3] = std::array::from_fn(|k| c[k] - a[k]);
            let n =
                [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
            let nn = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            1.0 - (n[0] * a[0] + n[1] * a[1] + n[2] * a[2]).abs() / nn
        })
        .fold(0.0, f64::max);
    assert!(delta > 1e-4 && delta < 2e-3, "{delta}");
    let cam = Camera::with_default_intrinsics(Pose::from_direction([0.2, 1.0, -0.3], 3.0));
    let f = objview_render::render(&mesh, &cam);
    let (w, h) = (512u32, 512u32);
    let mut inside = 0;
    for v in 0..h {
        for u in 0..w {
            let i = (v * w + u) as usize;
            let d = cam.pixel_ray_object(u, v);
            // Distance of the ray (line) from the origin.
            let dn: f64 = d.iter().map(|x| x * x).sum::<f64>().sqrt();
            let t0 = -(0..3).map(|k| cam.center[k] * d[k]).sum::<f64>() / (dn * dn);
            let q: [f64; 3] = std::array::from_fn(|k| cam.center[k] + t0 * d[k]);
            let miss_dist = q.iter().map(|x| x * x).sum::<f64>().sqrt();
            if miss_dist > 1.0 {
                assert_eq!(f.triangle[i], NO_HIT, "({u},{v}) outside the sphere is hit");
            } else if miss_dist < 0.99 {
                assert_ne!(f.triangle[i], NO_HIT, "({u},{v}) well inside is missed");
            }
            if miss_dist < 0.9 {
                // Inscribed polygon: hit at or behind the sphere, at most by the ray's path
                // length between the two spheres (in depth units: × depth / distance).
                let z = sphere_hit(cam.center, d).unwrap();
                let m2 = miss_dist * miss_dist;
                let gap = ((1.0 - m2).sqrt() - ((1.0 - delta).powi(2) - m2).sqrt()) / dn;
                let diff = f.depth[i] as f64 - z;
                assert!(diff > -1e-6 && diff <= gap + 1e-6, "({u},{v}): {} vs {z}, gap {gap}", f.depth[i]);
                inside += 1;
            }
        }
    }
    assert!(inside > 100_000);
    // Fine tessellation: the centre pixel sees depth 2 within 1e-4 (icosphere(6) deviates from
    // the sphere by ≤ 4.6e-5), consistently with the oracle's ray cast.
    let mesh = icosphere(6);
    for dir in [[1.0, 0.0, 0.0], [0.3, -0.2, 0.9], [0.0, 0.0, -1.0]] {
        let cam = Camera::with_default_intrinsics(Pose::from_direction(dir, 3.0));
        let f = objview_render::render(&mesh, &cam);
        let z = f.depth[256 * 512 + 256] as f64;
        assert!((z - 2.0).abs() < 1e-4, "{dir:?}: {z}");
        let (zr, _) = reference::cast_pixel(&mesh, &cam, 256, 256).unwrap();
        assert!((z - zr).abs() <= 1e-5 * zr, "{z} vs oracle {zr}");
    }
}

/// The square |y|, |z| ≤ 0.5 in the plane x = 0 (two triangles).
fn square() -> Mesh {
    Mesh::new(
        vec![[0.0, -0.5, -0.5], [0.0, 0.5, -0.5], [0.0, 0.5, 0.5], [0.0, -0.5, 0.5]],
        vec![[0, 1, 2], [0, 2, 3]],
    )
}

#[test]
fn facing_square_has_exact_depth_and_footprint() {
    let cam = Camera::with_default_intrinsics(Pose::from_direction([1.0, 0.0, 0.0], 3.0));
    let f = objview_render::render(&square(), &cam);
    let k = cam.intrinsics;
    for v in 0..512u32 {
        for u in 0..512u32 {
            let i = (v * 512 + u) as usize;
            // Camera right = +y, down = −z: the ray meets x = 0 at y = 3·px, z = −3·py.
            let q = k.pixel_ray(u, v);
            let inside = (3.0 * q[0]).abs() <= 0.5 && (3.0 * q[1]).abs() <= 0.5;
            assert_eq!(f.triangle[i] != NO_HIT, inside, "({u},{v})");
            if inside {
                assert_eq!(f.depth[i], 3.0);
            }
        }
    }
    // ±0.5 at distance 3 → ±103.0 px: pixels 153..=358 each way.
    assert_eq!(f.num_hits(), 206 * 206);
}

#[test]
fn tilted_plane_depth_is_the_ray_plane_intersection() {
    // Two triangles spanning the plane 0.9·x + 0.2·y − 0.3·z = 0.1 across the whole view;
    // their far corners lie behind the camera (near-plane clipping of the bounding box).
    let plane = |y: f64, z: f64| [(0.1 - 0.2 * y + 0.3 * z) / 0.9, y, z];
    let mesh = Mesh::new(
        vec![plane(-20.0, -20.0), plane(20.0, -20.0), plane(20.0, 20.0), plane(-20.0, 20.0)],
        vec![[0, 1, 2], [2, 3, 0]],
    );
    let cam = Camera::with_default_intrinsics(Pose { center: [3.0, 0.2, 0.1], look_at: [0.0; 3], roll: 0.3 });
    let f = objview_render::render(&mesh, &cam);
    let n = [0.9, 0.2, -0.3];
    let mut max_rel: f64 = 0.0;
    for v in 0..512u32 {
        for u in 0..512u32 {
            let d = cam.pixel_ray_object(u, v);
            let dn: f64 = (0..3).map(|k| n[k] * d[k]).sum();
            let t = (0.1 - (0..3).map(|k| n[k] * cam.center[k]).sum::<f64>()) / dn;
            let z = f.depth[(v * 512 + u) as usize] as f64;
            assert!(z > 0.0, "({u},{v}) missed");
            max_rel = max_rel.max((z - t).abs() / t);
        }
    }
    assert!(max_rel < 1e-6, "{max_rel}");
}

#[test]
fn look_at_point_lands_between_the_four_centre_pixels() {
    for (c, l, roll) in [
        ([3.0, 0.0, 0.0], [0.0, 0.0, 0.0], 0.0),
        ([1.0, 2.0, -0.5], [0.3, -0.2, 0.1], 0.7),
        ([0.0, 0.0, 3.0], [0.0, 0.0, 0.0], 1.3),
    ] {
        let cam = Camera::with_default_intrinsics(Pose { center: c, look_at: l, roll });
        // A square of half-width 0.9 px centred on the look-at point, facing the camera.
        let dist: f64 = (0..3).map(|k| (l[k] - c[k]).powi(2)).sum::<f64>().sqrt();
        let s = 0.9 * dist / cam.intrinsics.fx;
        let corner = |a: f64, b: f64| -> [f64; 3] {
            std::array::from_fn(|k| l[k] + a * s * cam.right[k] + b * s * cam.down[k])
        };
        let mesh = Mesh::new(
            vec![corner(-1.0, -1.0), corner(1.0, -1.0), corner(1.0, 1.0), corner(-1.0, 1.0)],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let f = objview_render::render(&mesh, &cam);
        let mut hit: Vec<(usize, usize)> =
            (0..512 * 512).filter(|&i| f.triangle[i] != NO_HIT).map(|i| (i % 512, i / 512)).collect();
        hit.sort();
        assert_eq!(hit, vec![(255, 255), (255, 256), (256, 255), (256, 256)], "{c:?}");
    }
}

#[test]
fn roll_pi_rotates_the_image_by_180_degrees() {
    let mesh = soup(300, 11);
    let p = Pose::from_direction([1.0, 1.0, 0.5], 3.0);
    let a = objview_render::render(&mesh, &Camera::with_default_intrinsics(p));
    let b = objview_render::render(
        &mesh,
        &Camera::with_default_intrinsics(Pose { roll: std::f64::consts::PI, ..p }),
    );
    // Pixel (u, v) of the rolled camera sees what pixel (511 − u, 511 − v) sees.
    let mut flipped = Frame::empty(b.camera);
    for i in 0..512 * 512 {
        flipped.depth[i] = a.depth[512 * 512 - 1 - i];
        flipped.triangle[i] = a.triangle[512 * 512 - 1 - i];
    }
    let c = compare(&b, &flipped);
    assert!(c.hits > 10_000);
    assert!(c.agree as f64 / c.total as f64 >= 0.9999);
    assert_eq!(c.non_silhouette, 0);
}

#[test]
fn parallel_is_bit_identical_for_any_thread_count() {
    let meshes = [soup(20_000, 3), icosphere(5), big_random_triangles(5000, 4)];
    let poses = [Pose::from_direction([0.5, 0.2, 0.8], 3.0), Pose::from_direction([-1.0, 0.1, 0.0], 1.0)];
    for mesh in &meshes {
        for &p in &poses {
            let cam = Camera::with_default_intrinsics(p);
            let single = objview_render::render(mesh, &cam);
            assert!(single.num_hits() > 1000);
            for threads in [1, 2, 3, 5] {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                let par = pool.install(|| render_parallel(mesh, &cam));
                assert!(single.depth.iter().map(|x| x.to_bits()).eq(par.depth.iter().map(|x| x.to_bits())));
                assert_eq!(single.triangle, par.triangle, "{threads} threads");
            }
        }
    }
}

#[test]
fn renderer_reuse_matches_fresh_renders_and_handles_degenerate_input() {
    let mut r = Renderer::new();
    let mut f = Frame::empty(Camera::with_default_intrinsics(Pose::from_direction([1.0, 0.0, 0.0], 3.0)));
    let a = icosphere(3);
    let b = soup(500, 5);
    for (mesh, intr, dir) in [
        (&a, Intrinsics::default(), [1.0, 0.0, 0.0]),
        (&b, small(), [0.0, 1.0, 0.2]),
        (&a, small(), [0.0, 0.0, 1.0]),
    ] {
        let cam = Camera::new(Pose::from_direction(dir, 2.5), intr);
        r.render_into(mesh, &cam, &mut f);
        assert_eq!(f, objview_render::render(mesh, &cam));
        r.render_parallel_into(mesh, &cam, &mut f);
        assert_eq!(f, objview_render::render(mesh, &cam));
    }
    // Zero-area triangles (repeated corner, collinear corners) and an edge-on triangle hit nothing.
    let m = Mesh::new(
        vec![[0.0, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        vec![[0, 1, 1], [0, 1, 2], [0, 3, 4]],
    );
    let cam = Camera::with_default_intrinsics(Pose { center: [3.0, 0.0, 0.0], look_at: [0.0; 3], roll: 0.0 });
    // Triangle [0, 3, 4] lies in the plane y = 0, which contains the camera centre.
    assert_eq!(objview_render::render(&m, &cam).num_hits(), 0);
    assert_eq!(reference::render(&m, &cam).num_hits(), 0);
    // An empty mesh renders an empty frame.
    assert_eq!(objview_render::render(&Mesh::default(), &cam).num_hits(), 0);
}

#[test]
fn geometry_beyond_zfar_or_behind_the_camera_is_not_seen() {
    let cam = Camera::with_default_intrinsics(Pose::from_direction([1.0, 0.0, 0.0], 3.0));
    let shifted = |dx: f64| {
        let mut m = square();
        for p in &mut m.positions {
            p[0] += dx;
        }
        m
    };
    // Square at x = −7.5: depth 10.5 > zfar; at x = 4: behind the camera.
    assert_eq!(objview_render::render(&shifted(-7.5), &cam).num_hits(), 0);
    assert_eq!(objview_render::render(&shifted(4.0), &cam).num_hits(), 0);
    let f = objview_render::render(&shifted(-6.5), &cam);
    assert!(f.num_hits() > 0 && f.depth.iter().all(|&z| z == 0.0 || z == 9.5));
}

#[test]
fn portable_and_simd_paths_are_bit_identical() {
    let meshes = [soup(3000, 21), icosphere(4), big_random_triangles(300, 22)];
    let poses = [Pose::from_direction([0.2, -0.7, 0.4], 3.0), Pose::from_direction([0.0, 0.3, 1.0], 1.0)];
    let (mut simd, mut portable) = (Renderer::new(), Renderer::new());
    portable.set_portable(true);
    for mesh in &meshes {
        for &p in &poses {
            let cam = Camera::with_default_intrinsics(p);
            let mut a = Frame::empty(cam);
            let mut b = Frame::empty(cam);
            simd.render_into(mesh, &cam, &mut a);
            portable.render_into(mesh, &cam, &mut b);
            assert!(a.num_hits() > 1000);
            assert!(a.depth.iter().map(|x| x.to_bits()).eq(b.depth.iter().map(|x| x.to_bits())));
            assert_eq!(a.triangle, b.triangle);
        }
    }
}

/// Images narrower than a vector: the AVX2 kernels' full-width stores of neighbouring rows
/// overlap (a row of 1–7 pixels is shorter than the 4 or 8 lanes written back), and the last
/// row pair of a box may be one row twice; every pixel must still keep its nearest hit.
#[test]
fn tiny_images_agree_across_paths() {
    let meshes = [soup(400, 31), icosphere(3), big_random_triangles(40, 32)];
    let poses = [Pose::from_direction([0.2, -0.7, 0.4], 3.0), Pose::from_direction([-0.5, 0.1, 0.3], 1.5)];
    let (mut simd, mut portable) = (Renderer::new(), Renderer::new());
    portable.set_portable(true);
    let mut hits = 0;
    for w in 1..=9u32 {
        for h in [1u32, 2, 3, 5, 8, 13] {
            let intr = Intrinsics::from_fov(w, h, 45.0, 45.0);
            for mesh in &meshes {
                for &p in &poses {
                    let cam = Camera::new(p, intr);
                    let (mut a, mut b) = (Frame::empty(cam), Frame::empty(cam));
                    simd.render_into(mesh, &cam, &mut a);
                    portable.render_into(mesh, &cam, &mut b);
                    hits += b.num_hits();
                    assert!(
                        a.depth.iter().map(|x| x.to_bits()).eq(b.depth.iter().map(|x| x.to_bits())),
                        "{w}x{h}"
                    );
                    assert_eq!(a.triangle, b.triangle, "{w}x{h}");
                }
            }
        }
    }
    assert!(hits > 1000, "{hits}");
}

#[test]
fn near_and_far_planes_cut_triangles_like_the_oracle() {
    // Camera-frame planes z = z0 + s·(x + y) through the view whose depth crosses
    // znear = 0.01 (z0 = 0.008, s = 2) and zfar = 10 (z0 = 8, s = 2) along a diagonal of
    // the image, so that screen bounding boxes cannot do the cutting.
    let cam = Camera::new(Pose { center: [0.3, -2.0, 0.5], look_at: [0.0, 0.1, 0.0], roll: 0.2 }, small());
    for (z0, slope, zs) in [(0.008, 2.0, [0.001, 5.0]), (8.0, 2.0, [1.0, 30.0])] {
        let p = |x: f64, z: f64| cam.to_object([x, (z - z0) / slope - x, z]);
        let mesh = Mesh::new(
            vec![p(-30.0, zs[0]), p(30.0, zs[0]), p(-40.0, zs[1]), p(40.0, zs[1])],
            vec![[0, 1, 3], [0, 3, 2]],
        );
        let f = objview_render::render(&mesh, &cam);
        let o = reference::render(&mesh, &cam);
        let c = compare(&f, &o);
        eprintln!("z0 {z0}: {} hits, {} disagreeing", c.hits, c.total - c.agree);
        // The cut runs across the image: both hits and misses, nothing lost or added.
        assert!(c.hits > 2000 && c.hits < 14000, "{}", c.hits);
        assert!(c.agree as f64 / c.total as f64 >= 0.999);
        assert_eq!(c.non_silhouette, 0);
        assert!(f.depth.iter().all(|&z| z == 0.0 || (0.01..=10.0).contains(&z)));
    }
}
