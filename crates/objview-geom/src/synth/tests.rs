//! Tests of the built-in pool against independently derived values: normalization, topology
//! (watertight and consistently oriented), orientation (signed volume), analytic areas and
//! volumes, enclosure of sealed cavities, determinism and triangle-count targeting.

use super::*;
use crate::Appearance;
use std::collections::HashMap;
use std::f64::consts::PI;

fn default_meshes() -> Vec<(SynthObject, Mesh)> {
    catalog().into_iter().map(|o| (o, o.build(Detail::DEFAULT))).collect()
}

pub(super) fn signed_volume(m: &Mesh) -> f64 {
    (0..m.num_triangles())
        .map(|t| {
            let [a, b, c] = m.triangle(t);
            (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                + a[2] * (b[0] * c[1] - b[1] * c[0]))
                / 6.0
        })
        .sum()
}

/// `Err` describing the first edge that is not shared by exactly two oppositely directed
/// triangle sides.
pub(super) fn check_closed(m: &Mesh) -> Result<(), String> {
    let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
    for tri in &m.triangles {
        for k in 0..3 {
            *directed.entry((tri[k], tri[(k + 1) % 3])).or_default() += 1;
        }
    }
    for (&(a, b), &n) in &directed {
        if n != 1 {
            return Err(format!("directed edge {a}->{b} used {n} times"));
        }
        if !directed.contains_key(&(b, a)) {
            return Err(format!("edge {a}-{b} has only one triangle"));
        }
    }
    Ok(())
}

/// Connected components (by shared vertices) as lists of triangle indices.
fn components(m: &Mesh) -> Vec<Vec<usize>> {
    let mut parent: Vec<usize> = (0..m.positions.len()).collect();
    fn root(p: &mut [usize], mut i: usize) -> usize {
        while p[i] != i {
            p[i] = p[p[i]];
            i = p[i];
        }
        i
    }
    for tri in &m.triangles {
        for k in 1..3 {
            let (a, b) = (root(&mut parent, tri[0] as usize), root(&mut parent, tri[k] as usize));
            parent[a] = b;
        }
    }
    let mut groups: HashMap<usize, Vec<usize>> = HashMap::new();
    for (t, tri) in m.triangles.iter().enumerate() {
        groups.entry(root(&mut parent, tri[0] as usize)).or_default().push(t);
    }
    let mut v: Vec<Vec<usize>> = groups.into_values().collect();
    v.sort();
    v
}

fn sub_mesh(m: &Mesh, tris: &[usize]) -> Mesh {
    Mesh::new(m.positions.clone(), tris.iter().map(|&t| m.triangles[t]).collect())
}

fn radius(p: [f64; 3]) -> f64 {
    (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
}

#[test]
fn catalog_names_are_unique_kebab_case() {
    let cat = catalog();
    assert!(cat.len() >= 30, "{} objects", cat.len());
    let mut names: Vec<&str> = cat.iter().map(|o| o.name).collect();
    for n in &names {
        assert!(
            !n.is_empty() && n.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-'),
            "{n}"
        );
        assert!(!n.starts_with('-') && !n.ends_with('-') && !n.contains("--"), "{n}");
    }
    for o in &cat {
        assert!(!o.description.is_empty() && !o.description.contains('\n'));
    }
    names.sort();
    names.dedup();
    assert_eq!(names.len(), cat.len());
    assert!(build("no-such-object", Detail::DEFAULT).is_none());
    assert_eq!(find("gear").map(|o| o.name), Some("gear"));
}

#[test]
fn every_object_is_valid_normalized_and_non_degenerate() {
    for (o, m) in default_meshes() {
        m.validate(Path::new(o.name)).unwrap();
        let n = m.num_triangles();
        assert!((2_000..=20_000).contains(&n), "{}: {n} triangles at default detail", o.name);
        check_normalized_clean(o.name, &m);
        if let Appearance::FaceColors(c) = &m.appearance {
            assert!(c.iter().flatten().all(|x| (0.0..=1.0).contains(x)));
        }
    }
}

/// A generated object's mesh is normalized (max radius 1, AABB centred), has no degenerate
/// triangle and no unreferenced vertex, and carries one colour per face. Shared by the tests of
/// the built-in and the random pools.
pub(super) fn check_normalized_clean(name: &str, m: &Mesh) {
    let n = m.num_triangles();
    assert!((m.max_radius() - 1.0).abs() <= 1e-12, "{name}: max radius {}", m.max_radius());
    let (lo, hi) = m.bounds().unwrap();
    for k in 0..3 {
        assert!((lo[k] + hi[k]).abs() <= 1e-12, "{name}: AABB centre off on axis {k}");
    }
    let min_area = (0..n).map(|t| m.triangle_area(t)).fold(f64::INFINITY, f64::min);
    assert!(min_area > 1e-12, "{name}: degenerate triangle, area {min_area}");
    // Every vertex is used (no stray points that would disturb bounds-based consumers).
    let mut used = vec![false; m.positions.len()];
    m.triangles.iter().flatten().for_each(|&i| used[i as usize] = true);
    assert!(used.iter().all(|&u| u), "{name}: unreferenced vertex");
    match &m.appearance {
        Appearance::FaceColors(c) => assert_eq!(c.len(), n, "{name}"),
        other => panic!("{name}: expected face colours, got {other:?}"),
    }
}

#[test]
fn closed_objects_are_watertight_and_outward() {
    for (o, m) in default_meshes() {
        if o.closed {
            check_closed(&m).unwrap_or_else(|e| panic!("{}: {e}", o.name));
            // Outward orientation: the enclosed volume is positive, and below that of the ball.
            let v = signed_volume(&m);
            assert!(v > 0.0 && v < 4.0 / 3.0 * PI, "{}: signed volume {v}", o.name);
        }
    }
}

#[test]
fn closed_check_detects_holes_and_flips() {
    let mut m = build("cube", Detail { segments: 8 }).unwrap();
    assert!(check_closed(&m).is_ok());
    m.triangles[0].swap(0, 1);
    assert!(check_closed(&m).is_err());
    m.triangles.remove(0);
    assert!(check_closed(&m).is_err());
}

#[test]
fn analytic_areas_and_volumes() {
    let sphere = build("sphere", Detail::DEFAULT).unwrap();
    let area = sphere.surface_area();
    assert!((area / (4.0 * PI) - 1.0).abs() < 0.01, "sphere area {area}");
    let vol = signed_volume(&sphere);
    assert!((vol / (4.0 / 3.0 * PI) - 1.0).abs() < 0.01, "sphere volume {vol}");
    // Tori: centre radius R and tube radius r with R + r = 1 before normalization, so the
    // normalized torus keeps them; area 4π²Rr, volume 2π²Rr².
    for (name, big_r) in [("torus", shapes::TORUS_R), ("thin-torus", shapes::THIN_TORUS_R)] {
        let m = build(name, Detail::DEFAULT).unwrap();
        let r = 1.0 - big_r;
        let (a, v) = (m.surface_area(), signed_volume(&m));
        assert!((a / (4.0 * PI * PI * big_r * r) - 1.0).abs() < 0.01, "{name} area {a}");
        // A polygonal tube cross-section loses area faster than perimeter: 2% for volumes.
        assert!((v / (2.0 * PI * PI * big_r * r * r) - 1.0).abs() < 0.02, "{name} volume {v}");
    }
    // Flat-faced solids are exact up to rounding. Cube of side 1.2 → half-diagonal 1.
    let cube = build("cube", Detail::DEFAULT).unwrap();
    let side = 2.0 / 3f64.sqrt();
    assert!((signed_volume(&cube) - side.powi(3)).abs() < 1e-12);
    assert!((cube.surface_area() - 6.0 * side * side).abs() < 1e-12);
    // Octahedron |x| + |y| + |z| ≤ 1: volume 4/3, area 8 · (√3/4) · 2.
    let oct = build("octahedron", Detail::DEFAULT).unwrap();
    assert!((signed_volume(&oct) - 4.0 / 3.0).abs() < 1e-12);
    assert!((oct.surface_area() - 4.0 * 3f64.sqrt()).abs() < 1e-11);
    // Sealed box 1 × 1 × 0.7 with 0.08 walls, scaled by 1 / half-diagonal.
    let sb = build("sealed-box", Detail::DEFAULT).unwrap();
    let s = 1.0 / (0.5f64 * 0.5 + 0.5 * 0.5 + 0.35 * 0.35).sqrt();
    let expected = (0.7 - 0.84 * 0.84 * 0.54) * s.powi(3);
    assert!((signed_volume(&sb) - expected).abs() < 1e-12, "{} vs {expected}", signed_volume(&sb));
}

#[test]
fn sealed_cavities_are_enclosed_and_face_inward() {
    // hollow-sphere: two components; the inner one lies strictly inside the outer one's
    // inscribed radius and has negative signed volume (faces into the cavity).
    let m = build("hollow-sphere", Detail::DEFAULT).unwrap();
    let comps = components(&m);
    assert_eq!(comps.len(), 2);
    let max_r = |c: &[usize]| {
        c.iter().flat_map(|&t| m.triangles[t]).map(|i| radius(m.positions[i as usize])).fold(0.0, f64::max)
    };
    let (outer, inner) =
        if max_r(&comps[0]) > max_r(&comps[1]) { (&comps[0], &comps[1]) } else { (&comps[1], &comps[0]) };
    let inner_max = max_r(inner);
    assert!((inner_max - shapes::HOLLOW_INNER).abs() < 1e-12, "{inner_max}");
    // Smallest distance from the origin to the outer polyhedron's face planes.
    let outer_min = outer
        .iter()
        .map(|&t| {
            let [a, b, c] = m.triangle(t);
            let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
            let n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
            (n[0] * a[0] + n[1] * a[1] + n[2] * a[2]).abs() / radius(n)
        })
        .fold(f64::INFINITY, f64::min);
    assert!(inner_max < outer_min - 0.2, "inner {inner_max} vs outer {outer_min}");
    assert!(signed_volume(&sub_mesh(&m, inner)) < 0.0);
    assert!(signed_volume(&sub_mesh(&m, outer)) > 0.0);
    let expected = 4.0 / 3.0 * PI * (1.0 - shapes::HOLLOW_INNER.powi(3));
    assert!((signed_volume(&m) / expected - 1.0).abs() < 0.01);

    // sealed-box: the inner component's vertices are all strictly inside the outer box.
    let m = build("sealed-box", Detail::DEFAULT).unwrap();
    let comps = components(&m);
    assert_eq!(comps.len(), 2);
    let (lo, hi) = m.bounds().unwrap();
    for c in &comps {
        let sub = sub_mesh(&m, c);
        let (clo, chi) = sub.bounds().unwrap();
        if clo != lo {
            assert!(signed_volume(&sub) < 0.0);
            for k in 0..3 {
                assert!(clo[k] > lo[k] + 0.05 && chi[k] < hi[k] - 0.05);
            }
        }
    }
}

#[test]
fn builds_are_deterministic() {
    for o in catalog() {
        let (a, b) = (o.build(Detail { segments: 40 }), o.build(Detail { segments: 40 }));
        assert_eq!(a, b, "{}", o.name);
        assert_eq!(crate::write::obj_text(&a, "x.mtl"), crate::write::obj_text(&b, "x.mtl"));
    }
}

#[test]
fn write_pool_is_byte_identical_on_rerun() {
    let dir = tempfile::tempdir().unwrap();
    let paths = write_pool(dir.path()).unwrap();
    assert_eq!(paths.len(), catalog().len());
    let first: Vec<Vec<u8>> = paths.iter().map(|p| std::fs::read(p).unwrap()).collect();
    let mtl = std::fs::read(dir.path().join("mug.mtl")).unwrap();
    assert!(String::from_utf8_lossy(&mtl).matches("newmtl").count() >= 2);
    let again = write_pool(dir.path()).unwrap();
    assert_eq!(again, paths);
    for (p, bytes) in paths.iter().zip(&first) {
        assert_eq!(&std::fs::read(p).unwrap(), bytes, "{}", p.display());
    }
    // The OBJ carries the default-detail mesh exactly (vertex count and face count).
    let text = String::from_utf8(first[0].clone()).unwrap();
    let sphere = build("sphere", Detail::DEFAULT).unwrap();
    assert_eq!(text.lines().filter(|l| l.starts_with("v ")).count(), sphere.positions.len());
    assert_eq!(text.lines().filter(|l| l.starts_with("f ")).count(), sphere.num_triangles());
}

fn assert_near_target(name: &str, target: usize) {
    let m = build_with_triangles(name, target);
    let ratio = m.num_triangles() as f64 / target as f64;
    assert!((0.8..=1.2).contains(&ratio), "{name}: {} triangles for target {target}", m.num_triangles());
    assert!((m.max_radius() - 1.0).abs() <= 1e-12);
    let min_area = (0..m.num_triangles()).map(|t| m.triangle_area(t)).fold(f64::INFINITY, f64::min);
    assert!(min_area > 1e-12, "{name}: degenerate triangle at target {target}");
}

#[test]
fn triangle_targets_10k_and_100k_for_every_object() {
    for o in catalog() {
        assert_near_target(o.name, 10_000);
        assert_near_target(o.name, 100_000);
    }
}

#[test]
fn triangle_targets_1m() {
    for name in ["sphere", "torus", "mug", "gear"] {
        let t = std::time::Instant::now();
        assert_near_target(name, 1_000_000);
        eprintln!("{name}: 1M triangles in {:?}", t.elapsed());
    }
}

#[test]
#[should_panic(expected = "no built-in object")]
fn build_with_triangles_rejects_unknown_names() {
    build_with_triangles("teapot", 1000);
}

#[test]
fn pool_files_load_back_exactly() {
    // The written pool is what the benchmark's main job loads: every triangle's corners and
    // colour must come back from the OBJ/MTL loader bit for bit.
    let dir = tempfile::tempdir().unwrap();
    for (o, path) in catalog().iter().zip(write_pool(dir.path()).unwrap()) {
        let built = o.build(Detail::DEFAULT);
        let loaded = crate::io::load_mesh(&path).unwrap();
        assert_eq!(loaded.num_triangles(), built.num_triangles(), "{}", o.name);
        for t in 0..built.num_triangles() {
            assert_eq!(loaded.triangle(t), built.triangle(t), "{} triangle {t}", o.name);
        }
        assert_eq!(loaded.appearance, built.appearance, "{}", o.name);
    }
}

#[test]
fn other_details_stay_closed_normalized_and_non_degenerate() {
    for segments in [8, 21, 150] {
        for o in catalog() {
            let m = o.build(Detail { segments });
            m.validate(Path::new(o.name)).unwrap();
            check_closed(&m).unwrap_or_else(|e| panic!("{} at {segments}: {e}", o.name));
            assert!(signed_volume(&m) > 0.0, "{} at {segments}", o.name);
            assert!((m.max_radius() - 1.0).abs() <= 1e-12, "{} at {segments}", o.name);
            let min_area = (0..m.num_triangles()).map(|t| m.triangle_area(t)).fold(f64::INFINITY, f64::min);
            assert!(min_area > 1e-12, "{} at {segments}: area {min_area}", o.name);
        }
    }
}

#[test]
fn mug_handle_ends_stay_inside_the_wall() {
    // Body = the component holding the lowest-x vertex (the side away from the handle).
    let m = build("mug", Detail::DEFAULT).unwrap();
    let comps = components(&m);
    assert_eq!(comps.len(), 2);
    let verts = |c: &[usize]| -> Vec<[f64; 3]> {
        let mut ids: Vec<u32> = c.iter().flat_map(|&t| m.triangles[t]).collect();
        ids.sort_unstable();
        ids.dedup();
        ids.iter().map(|&i| m.positions[i as usize]).collect()
    };
    let (a, b) = (verts(&comps[0]), verts(&comps[1]));
    let min_x = |v: &[[f64; 3]]| v.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min);
    let (body, handle) = if min_x(&a) < min_x(&b) { (a, b) } else { (b, a) };
    let lo = |k: usize| body.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
    let hi = |k: usize| body.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max);
    let axis = [0.5 * (lo(0) + hi(0)), 0.5 * (lo(1) + hi(1))];
    let radial = |p: &[f64; 3]| (p[0] - axis[0]).hypot(p[1] - axis[1]);
    let r_out = body.iter().map(radial).fold(0.0, f64::max);
    // Inner wall: the largest radius below the outer one among vertices above the floor.
    let floor = lo(2) + 0.1;
    let r_in =
        body.iter().filter(|p| p[2] > floor).map(radial).filter(|&r| r < r_out - 1e-9).fold(0.0, f64::max);
    assert!(r_in > 0.8 * r_out && r_in < r_out, "{r_in} {r_out}");
    let embedded: Vec<&[f64; 3]> = handle.iter().filter(|p| radial(p) < r_out).collect();
    assert!(!embedded.is_empty(), "handle ends should reach into the wall");
    for p in embedded {
        assert!(radial(p) > r_in + 0.01, "handle vertex {p:?} pokes into the cup");
        assert!(p[2] > floor && p[2] < hi(2));
    }
}
