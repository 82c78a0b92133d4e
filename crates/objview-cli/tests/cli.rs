//! End-to-end tests of the `objview` command-line contract (README "Commands", SPEC §1–§4).
//!
//! Every expected value here is derived independently of the program: the scenes are written by
//! the tests themselves (an icosphere, planar rectangles, an axis-aligned cube, point clouds on a
//! plane), the camera is rebuilt from the SPEC §2 formulas, and the outputs (NPY, PLY, PNG, JSON)
//! are parsed by hand-written readers in `common/`. No library code of the workspace is used.

mod common;

use common::*;
use std::collections::HashSet;
use std::path::Path;

// ---------------------------------------------------------------------------------------------
// render: the analytic sphere
// ---------------------------------------------------------------------------------------------

/// A level-5 icosphere (20480 triangles, vertices on the unit sphere) seen from (3,0,0).
///
/// The mesh is convex (checked), so it contains the ball of radius `d_min` (the smallest distance
/// of a face plane from the origin) and lies inside the ball of radius `r_max` (largest vertex
/// norm, 1 up to f32 rounding). Hence for every pixel, with camera distance D = 3:
/// - a pixel whose centre ray misses B(r_max) has depth 0; one whose ray hits B(d_min) is a hit,
///   i.e. the hit region is a disc of radius between fx·tan(asin(d_min/3)) and
///   fx·tan(asin(r_max/3)) pixels (≈ 218.5);
/// - a hit's depth lies between the first-intersection depths with B(r_max) and B(d_min).
#[test]
fn render_sphere_depth_points_preview_match_analytic_geometry() {
    let dir = tempdir();
    let sphere = Icosphere::new(5);
    let mesh = dir.path().join("sphere.obj");
    sphere.write_obj(&mesh);
    assert_eq!(sphere.faces.len(), 20480);
    let (d_min, r_max) = (sphere.inradius(), sphere.circumradius());
    assert!(d_min > 0.9995 && d_min < 1.0 && (r_max - 1.0).abs() < 1e-6, "d_min {d_min} r_max {r_max}");

    let depth_path = dir.path().join("d.npy");
    let ply_path = dir.path().join("p.ply");
    let png_path = dir.path().join("p.png");
    let pose = "3,0,0,0,0,0,0";
    objview_ok(&[
        "render",
        s(&mesh),
        "--pose",
        pose,
        "--normalize",
        "none",
        "--depth",
        s(&depth_path),
        "--points",
        s(&ply_path),
        "--preview",
        s(&png_path),
    ]);

    let depth = read_depth(&depth_path);
    let cam = SpecCamera::from_pose([3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    const D: f64 = 3.0;

    // Centre pixel: tessellation bounds, and the exact first hit on our own triangles.
    let centre = depth.at(256, 256) as f64;
    let (xn, yn) = normalized_coords(256, 256);
    let lo = first_sphere_hit_depth(xn, yn, D, r_max).unwrap();
    let hi = first_sphere_hit_depth(xn, yn, D, d_min).unwrap();
    // The centre ray is 0.5·√2/fx ≈ 1.1e-3 rad off axis: the unit sphere is met at 2 + ~6e-6.
    assert!((lo - 2.0).abs() < 1e-5 && hi - lo < 1.0 - d_min + 1e-6, "[{lo}, {hi}]");
    assert!(centre >= lo - 5e-5 && centre <= hi + 5e-5, "centre depth {centre} outside [{lo}, {hi}]");
    let exact = sphere.raycast(cam.center, cam.ray(256, 256)).expect("centre ray hits our mesh");
    assert!((centre - exact).abs() < 2e-5, "centre depth {centre}, ray-cast on the OBJ gives {exact}");
    for (u, v) in [(0, 0), (511, 0), (0, 511), (511, 511), (256, 0), (0, 256)] {
        assert_eq!(depth.at(u, v), 0.0, "pixel ({u},{v}) must see nothing");
    }

    // Every pixel: the disc and the depth bounds. Pixels within 0.05 px of either bounding radius
    // are not classified (floating-point ties at the silhouette).
    let fx = fx();
    let r_in_px = fx * (d_min / D).asin().tan();
    let r_out_px = fx * (r_max / D).asin().tan();
    let analytic_px = fx * (1.0f64 / 3.0).asin().tan();
    assert!((analytic_px - 218.5).abs() < 0.1 && r_out_px - r_in_px < 0.5, "{r_in_px} {r_out_px}");
    let (mut hits, mut disc_in, mut disc_out) = (0usize, 0usize, 0usize);
    let mut max_hit_radius: f64 = 0.0;
    for v in 0..512 {
        for u in 0..512 {
            let z = depth.at(u, v) as f64;
            let (xn, yn) = normalized_coords(u, v);
            let rho = fx * (xn * xn + yn * yn).sqrt();
            if rho < r_in_px {
                disc_in += 1;
            }
            if rho <= r_out_px {
                disc_out += 1;
            }
            if z != 0.0 {
                hits += 1;
                max_hit_radius = max_hit_radius.max(rho);
                let near = first_sphere_hit_depth(xn, yn, D, r_max);
                let near = near.unwrap_or_else(|| panic!("pixel ({u},{v}) at {rho:.3} px hit, z={z}"));
                assert!(z >= near - 5e-5, "pixel ({u},{v}): depth {z} nearer than the unit sphere {near}");
                if let Some(far) = first_sphere_hit_depth(xn, yn, D, d_min) {
                    assert!(z <= far + 5e-5, "pixel ({u},{v}): depth {z} behind the inscribed ball {far}");
                }
            } else {
                assert!(rho > r_in_px - 0.05, "pixel ({u},{v}) at {rho:.3} px < {r_in_px:.3} px missed");
            }
        }
    }
    assert!(max_hit_radius <= r_out_px + 0.05, "hit at {max_hit_radius} px > {r_out_px} px");
    assert!(hits >= disc_in && hits <= disc_out, "{hits} hits, disc counts [{disc_in}, {disc_out}]");
    // The silhouette radius estimated from the hit area: within a pixel of fx·tan(asin(1/3)).
    let area_radius = (hits as f64 / std::f64::consts::PI).sqrt();
    assert!((area_radius - analytic_px).abs() < 1.0, "area radius {area_radius} vs {analytic_px}");

    // Observed cloud: one point per hit pixel, on the sphere, back-projecting to its own pixel.
    let points = read_ply_points(&ply_path);
    assert_eq!(points.len(), hits, "PLY vertex count vs non-zero depth pixels");
    let mut seen = vec![false; 512 * 512];
    for p in &points {
        let n = norm(*p);
        assert!(n >= d_min - 1e-4 && n <= r_max + 1e-4, "point {p:?} at |p| = {n}");
        let (u, v, z) = cam.project(*p);
        let (ui, vi) = (u.round(), v.round());
        assert!((u - ui).abs() < 1e-2 && (v - vi).abs() < 1e-2, "point {p:?} projects to ({u}, {v})");
        let (ui, vi) = (ui as usize, vi as usize);
        assert!(!seen[vi * 512 + ui], "two points on pixel ({ui},{vi})");
        seen[vi * 512 + ui] = true;
        let dz = depth.at(ui, vi) as f64;
        assert!((dz - z).abs() < 1e-4, "point {p:?}: camera z {z} but depth[{vi}][{ui}] = {dz}");
    }

    let png = read_png(&png_path);
    assert_eq!((png.width, png.height), (512, 512));

    // Determinism: a second run gives byte-identical files.
    let again = dir.path().join("again");
    std::fs::create_dir(&again).unwrap();
    let (d2, p2, i2) = (again.join("d.npy"), again.join("p.ply"), again.join("p.png"));
    objview_ok(&[
        "render",
        s(&mesh),
        "--pose",
        pose,
        "--normalize",
        "none",
        "--depth",
        s(&d2),
        "--points",
        s(&p2),
        "--preview",
        s(&i2),
    ]);
    for (a, b) in [(&depth_path, &d2), (&ply_path, &p2), (&png_path, &i2)] {
        assert!(read(a) == read(b), "{} differs between two identical runs", a.display());
    }
}

// ---------------------------------------------------------------------------------------------
// render: planar rectangles (constant depth, orientation, negative pose, roll)
// ---------------------------------------------------------------------------------------------

/// An axis-aligned rectangle in the plane `p[normal] = 0`, spanning `a` along axis
/// (normal + 1) % 3 and `b` along axis (normal + 2) % 3. Off-centre, so that every mirror or
/// rotation of the image shows.
struct Rect {
    normal: usize,
    a: [f64; 2],
    b: [f64; 2],
}

/// In the plane x = 0: y ∈ [0.1, 0.6], z ∈ [0.2, 0.5].
const RECT_X: Rect = Rect { normal: 0, a: [0.1, 0.6], b: [0.2, 0.5] };
/// In the plane z = 0: x ∈ [0.1, 0.6], y ∈ [0.2, 0.5] (seen from the poles).
const RECT_Z: Rect = Rect { normal: 2, a: [0.1, 0.6], b: [0.2, 0.5] };

impl Rect {
    fn axes(&self) -> (usize, usize) {
        ((self.normal + 1) % 3, (self.normal + 2) % 3)
    }

    fn write_obj(&self, path: &Path) {
        let (ia, ib) = self.axes();
        let corner = |a: f64, b: f64| {
            let mut p = [0.0; 3];
            (p[ia], p[ib]) = (a, b);
            p
        };
        let ([a0, a1], [b0, b1]) = (self.a, self.b);
        let v = [corner(a0, b0), corner(a1, b0), corner(a1, b1), corner(a0, b1)];
        write_obj(path, &v, &[[0, 1, 2], [0, 2, 3]]);
    }

    /// Expected depth image: for each pixel, `Some(z)` if its centre ray crosses the rectangle
    /// more than `margin` inside its edges, `Some(0)` if more than `margin` outside, `None` (not
    /// classified) near an edge.
    fn expected(&self, cam: &SpecCamera, margin: f64) -> Vec<Option<f64>> {
        let (ia, ib) = self.axes();
        let ([a0, a1], [b0, b1]) = (self.a, self.b);
        let mut out = Vec::with_capacity(512 * 512);
        for v in 0..512 {
            for u in 0..512 {
                let w = cam.ray(u, v);
                // Camera-frame z is the ray parameter t (the ray's forward component is 1).
                let t = -cam.center[self.normal] / w[self.normal];
                if !t.is_finite() || t <= 0.0 {
                    out.push(Some(0.0));
                    continue;
                }
                let (a, b) = (cam.center[ia] + t * w[ia], cam.center[ib] + t * w[ib]);
                let inside = (a - a0).min(a1 - a).min(b - b0).min(b1 - b);
                out.push(if inside > margin {
                    Some(t)
                } else if inside < -margin {
                    Some(0.0)
                } else {
                    None
                });
            }
        }
        out
    }
}

/// Compares a rendered depth image with `Rect::expected`; returns the number of hit pixels.
fn assert_matches_rect(depth: &Depth, expected: &[Option<f64>], what: &str) -> usize {
    let mut hits = 0;
    for v in 0..512 {
        for u in 0..512 {
            let Some(e) = expected[v * 512 + u] else { continue };
            let z = depth.at(u, v) as f64;
            if e == 0.0 {
                assert_eq!(z, 0.0, "{what}: pixel ({u},{v}) should miss the rectangle");
            } else {
                hits += 1;
                // The depth of a plane facing the camera is exactly its distance: allow 2 ulp of f32.
                assert!((z - e).abs() <= 2.0 * f32::EPSILON as f64 * e, "{what}: ({u},{v}) depth {z} != {e}");
            }
        }
    }
    hits
}

#[test]
fn render_plane_orientation_negative_pose_and_roll() {
    let dir = tempdir();
    let mesh = dir.path().join("rect.obj");
    RECT_X.write_obj(&mesh);
    let render = |pose: &str, name: &str| {
        let out = dir.path().join(name);
        objview_ok(&["render", s(&mesh), "--normalize", "none", "--pose", pose, "--depth", s(&out)]);
        read_depth(&out)
    };
    // 1e-4 object units is ≈ 0.02 px at distance 3.
    let margin = 1e-4;
    let pi = std::f64::consts::PI;

    // Front view: constant depth 3, right = +y (u grows with y), down = −z (v grows with −z).
    let d0 = render("3,0,0,0,0,0,0", "d0.npy");
    let e0 = RECT_X.expected(&SpecCamera::from_pose([3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]), margin);
    let hits = assert_matches_rect(&d0, &e0, "pose 3,0,0");
    // The rectangle covers 0.5 × 0.3 at distance 3: (fx/3)² · 0.15 ≈ 6366 pixels.
    let expect_px = (fx() / 3.0).powi(2) * 0.15;
    assert!((hits as f64 - expect_px).abs() < 0.02 * expect_px, "{hits} hits, ≈{expect_px} expected");
    assert!(d0.at(300, 200) != 0.0 && d0.at(200, 300) == 0.0, "image is mirrored or flipped");

    // Negative numbers parse; seen from behind (no back-face culling), the image is mirrored.
    let dn = render("-3,0,0,0,0,0,0", "dn.npy");
    let en = RECT_X.expected(&SpecCamera::from_pose([-3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]), margin);
    assert!(assert_matches_rect(&dn, &en, "pose -3,0,0") > 6000);
    assert!(dn.at(211, 200) != 0.0 && dn.at(300, 200) == 0.0);

    // Roll π rotates the image by 180°: pixel (u, v) ↔ (511 − u, 511 − v).
    let dr = render(&format!("3,0,0,0,0,0,{pi}"), "dr.npy");
    let er = RECT_X.expected(&SpecCamera::from_pose([3.0, 0.0, 0.0, 0.0, 0.0, 0.0, pi]), margin);
    assert_matches_rect(&dr, &er, "roll π");
    assert!(d0.data != dr.data, "roll π gave the same image as roll 0");
    let mut compared = 0;
    for v in 0..512 {
        for u in 0..512 {
            if e0[v * 512 + u].is_none() {
                continue;
            }
            let (a, b) = (d0.at(u, v), dr.at(511 - u, 511 - v));
            assert!((a - b).abs() <= 2.0 * f32::EPSILON * 3.0, "({u},{v}): {a} vs rolled {b}");
            compared += 1;
        }
    }
    assert!(compared > 250_000, "only {compared} pixels away from the edges");
}

/// Straight above and below the object, the SPEC pole rule applies: f = normalize(1e-8, 1e-8,
/// ±1), so right = (1, −1, 0)/√2 and the rectangle's edges run diagonally across the image.
#[test]
fn render_from_the_poles_follows_the_pole_rule() {
    let dir = tempdir();
    let mesh = dir.path().join("rect-z.obj");
    RECT_Z.write_obj(&mesh);
    for (pose, z) in [("0,0,3,0,0,0,0", 3.0), ("0,0,-3,0,0,0,0", -3.0), ("0,0,2.5,0,0,0.5,0", 2.5)] {
        let out = dir.path().join("d.npy");
        objview_ok(&["render", s(&mesh), "--normalize", "none", "--pose", pose, "--depth", s(&out)]);
        let look = if z == 2.5 { 0.5 } else { 0.0 };
        let cam = SpecCamera::from_pose([0.0, 0.0, z, 0.0, 0.0, look, 0.0]);
        assert!((cam.right[0] - 0.5f64.sqrt()).abs() < 1e-9 && (cam.right[1] + 0.5f64.sqrt()).abs() < 1e-9);
        let hits = assert_matches_rect(&read_depth(&out), &RECT_Z.expected(&cam, 1e-4), pose);
        let expect_px = (fx() / z.abs()).powi(2) * 0.15;
        assert!((hits as f64 - expect_px).abs() < 0.03 * expect_px, "{pose}: {hits} hits, ≈{expect_px}");
    }
}

// ---------------------------------------------------------------------------------------------
// render / visibility: errors
// ---------------------------------------------------------------------------------------------

/// Runs a command that must fail on the input file `file`; checks the one-line message.
fn assert_file_error(args: &[&str], file: &Path, reason: &str) {
    let err = objview_err(args);
    let name = file.file_name().unwrap().to_str().unwrap();
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "`{}`: stderr must be one line, got {err:?}", args.join(" "));
    let line = lines[0];
    assert!(line.starts_with("error: "), "{line:?}");
    assert!(line.contains(name), "error does not name the file {name}: {line:?}");
    assert!(line.to_lowercase().contains(reason), "error has no reason '{reason}': {line:?}");
    let after = &line[line.find(name).unwrap() + name.len()..];
    assert!(after.trim_start_matches([':', ' ']).len() >= 5, "no reason after the file name: {line:?}");
}

#[test]
fn render_rejects_bad_meshes_with_one_line_naming_the_file() {
    let dir = tempdir();
    let out = dir.path().join("out.npy");
    let render = |mesh: &Path, normalize: &str| {
        vec![
            "render".to_string(),
            s(mesh).to_string(),
            "--pose".into(),
            "3,0,0,0,0,0,0".into(),
            "--normalize".into(),
            normalize.into(),
            "--depth".into(),
            s(&out).into(),
        ]
    };
    let check = |mesh: &Path, normalize: &str, reason: &str| {
        let args = render(mesh, normalize);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        assert_file_error(&args, mesh, reason);
        assert!(!out.exists(), "a failed render wrote {}", out.display());
    };

    check(&dir.path().join("no-such-mesh.obj"), "unit", "no such file");

    let xyz = dir.path().join("cloud.xyz");
    std::fs::write(&xyz, "0 0 0\n1 0 0\n0 1 0\n").unwrap();
    check(&xyz, "unit", "unsupported");

    let bad = dir.path().join("bad-index.obj");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n").unwrap();
    check(&bad, "unit", "index");

    // Farthest vertex at distance 2 > 1.01: not a pre-normalized asset.
    let big = dir.path().join("radius-two.obj");
    write_obj(&big, &[[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.0]], &[[0, 1, 2]]);
    check(&big, "none", "normalized");
    // ... which `--normalize unit` accepts.
    objview_ok(&render(&big, "unit").iter().map(String::as_str).collect::<Vec<_>>());
    assert!(out.exists());
}

#[test]
fn render_rejects_bad_poses_with_a_clear_message() {
    let dir = tempdir();
    let mesh = dir.path().join("rect.obj");
    RECT_X.write_obj(&mesh);
    let out = dir.path().join("out.npy");
    for (pose, reason) in [
        ("3,0,0,0,0,0", "7 numbers"),
        ("3,0,0,0,0,0,NaN", "finite"),
        ("3,0,0,0,0,0,inf", "finite"),
        ("3,0,0,0,0,zero,0", "not a number"),
    ] {
        let err = objview_err(&["render", s(&mesh), "--pose", pose, "--depth", s(&out)]);
        let first = err.lines().next().unwrap_or("");
        assert!(first.starts_with("error: "), "pose {pose}: {err:?}");
        assert!(first.contains("pose") && first.contains(reason), "pose {pose}: unclear message {first:?}");
        assert_eq!(err.lines().filter(|l| l.starts_with("error")).count(), 1, "{err:?}");
        assert!(!out.exists());
    }
}

// Contract checks added for violations found earlier (multi-line argument errors, repeated
// I/O causes, degenerate poses accepted); they guard against regressions.

/// README: every command "exits non-zero with one line" on bad input. Argument errors detected
/// by clap (bad pose, unknown `--mode`, missing `--depth`) print a blank line and a
/// "For more information, try '--help'." trailer, or a whole usage block, after the error line.
#[test]
fn argument_errors_are_one_line() {
    let dir = tempdir();
    let mesh = dir.path().join("rect.obj");
    RECT_X.write_obj(&mesh);
    let (out, json) = (dir.path().join("d.npy"), dir.path().join("v.json"));
    for args in [
        vec!["render", s(&mesh), "--pose", "3,0,0,0,0,0", "--depth", s(&out)],
        vec!["render", s(&mesh), "--pose", "3,0,0,0,0,0,NaN", "--depth", s(&out)],
        vec!["render", s(&mesh), "--pose", "3,0,0,0,0,0,0", "--normalize", "foo", "--depth", s(&out)],
        vec!["render", s(&mesh), "--pose", "3,0,0,0,0,0,0"],
        vec!["visibility", s(&mesh), "--views", "tammes-128", "--mode", "foo", "--out", s(&json)],
        vec!["viewset", "generate", "twelve"],
    ] {
        let err = objview_err(&args);
        assert_eq!(err.lines().count(), 1, "`objview {}`: {err:?}", args.join(" "));
    }
}

/// A missing file's message repeats the OS error ("…: No such file or directory (os error 2):
/// No such file or directory (os error 2)"): `GeomError::Io` both prints and chains its source.
#[test]
fn io_errors_do_not_repeat_the_cause() {
    let dir = tempdir();
    let missing = dir.path().join("missing.obj");
    let err = objview_err(&["render", s(&missing), "--pose", "3,0,0,0,0,0,0", "--depth", "x.npy"]);
    let parts: Vec<&str> = err.trim_end().split(": ").collect();
    for w in parts.windows(2) {
        assert_ne!(w[0], w[1], "repeated cause in {err:?}");
    }
}

/// A pose whose centre equals its look-at point has no viewing direction (SPEC §2 normalizes
/// look-at − centre); today it renders an empty image and exits 0 instead of failing.
#[test]
fn degenerate_pose_is_rejected() {
    let dir = tempdir();
    let mesh = dir.path().join("rect.obj");
    RECT_X.write_obj(&mesh);
    let out = dir.path().join("d.npy");
    let err = objview_err(&["render", s(&mesh), "--pose", "1,1,1,1,1,1,0", "--depth", s(&out)]);
    assert!(err.contains("pose"), "{err:?}");
    assert!(!out.exists());
}

#[test]
fn every_command_has_help() {
    for cmd in [
        &["render", "--help"][..],
        &["viewset", "generate", "--help"],
        &["viewset", "check", "--help"],
        &["visibility", "--help"],
        &["objects", "synth", "--help"],
    ] {
        let out = objview(cmd);
        assert!(out.status.success(), "{cmd:?}");
        assert!(String::from_utf8_lossy(&out.stdout).contains("Usage:"), "{cmd:?}");
    }
}

// ---------------------------------------------------------------------------------------------
// viewset
// ---------------------------------------------------------------------------------------------

/// Parses `n=<N> min_angle_deg=<x>` (the whole of stdout); returns N, x and x's decimals.
fn parse_check_line(stdout: &str) -> (usize, f64, usize) {
    let line = stdout.strip_suffix('\n').unwrap_or(stdout);
    assert!(!line.contains('\n'), "one line expected: {stdout:?}");
    let (n, x) = line.split_once(' ').unwrap_or_else(|| panic!("{stdout:?}"));
    let n = n.strip_prefix("n=").unwrap_or_else(|| panic!("{stdout:?}")).parse().unwrap();
    let x = x.strip_prefix("min_angle_deg=").unwrap_or_else(|| panic!("{stdout:?}"));
    let decimals = x.split_once('.').map_or(0, |(_, d)| d.len());
    (n, x.parse().unwrap(), decimals)
}

/// Non-comment lines of a view-set text as vectors (3 numbers each, asserted).
fn parse_directions(text: &str) -> Vec<[f64; 3]> {
    text.lines()
        .filter(|l| !l.trim_start().starts_with('#'))
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            assert_eq!(v.len(), 3, "line {l:?}");
            [v[0], v[1], v[2]]
        })
        .collect()
}

fn min_angle_deg(dirs: &[[f64; 3]]) -> f64 {
    let mut best = f64::INFINITY;
    for (i, a) in dirs.iter().enumerate() {
        for b in &dirs[i + 1..] {
            let c = (dot(*a, *b) / (norm(*a) * norm(*b))).clamp(-1.0, 1.0);
            best = best.min(c.acos().to_degrees());
        }
    }
    best
}

#[test]
fn viewset_generate_12_is_an_icosahedron() {
    let dir = tempdir();
    let file = dir.path().join("v12.txt");
    objview_ok(&["viewset", "generate", "12", "--out", s(&file)]);
    let (n, x, decimals) = parse_check_line(&objview_ok(&["viewset", "check", s(&file)]));
    // Icosahedron: angle between neighbouring vertices = arccos(1/√5) = 63.4349°.
    let ico = (1.0 / 5f64.sqrt()).acos().to_degrees();
    assert_eq!(n, 12);
    assert!((x - ico).abs() <= 0.005 * ico, "min angle {x} vs icosahedron {ico}");
    // The printed angle is the file's own minimum angle.
    let text = String::from_utf8(read(&file)).unwrap();
    let dirs = parse_directions(&text);
    assert_eq!(dirs.len(), 12);
    assert!((min_angle_deg(&dirs) - x).abs() <= 0.5 * 10f64.powi(-(decimals as i32)) + 1e-9);

    // To standard output: the same 12 unit vectors, nothing else but comments.
    let stdout = objview_ok(&["viewset", "generate", "12"]);
    let dirs_out = parse_directions(&stdout);
    assert_eq!(dirs_out.len(), 12);
    for d in &dirs_out {
        assert!((norm(*d) - 1.0).abs() < 1e-9, "{d:?} is not unit");
    }
    assert_eq!(dirs_out, dirs, "stdout and --out give different sets");
}

#[test]
fn viewset_check_octahedron_and_bad_files() {
    let dir = tempdir();
    // The six axis directions, some not unit length (normalized on load), with comments.
    let oct = dir.path().join("octahedron.txt");
    std::fs::write(
        &oct,
        "# octahedron\n2 0 0\n-1 0 0\n# middle comment\n0 0.5 0\n0 -3 0\n0 0 1\n0 0 -1e-3\n",
    )
    .unwrap();
    let (n, x, decimals) = parse_check_line(&objview_ok(&["viewset", "check", s(&oct)]));
    assert_eq!(n, 6);
    assert!((x - 90.0).abs() <= 0.5 * 10f64.powi(-(decimals as i32)), "octahedron min angle {x}");

    let bad_number = dir.path().join("bad-number.txt");
    std::fs::write(&bad_number, "# header\n1 0 0\n0 x 1\n").unwrap();
    assert_file_error(&["viewset", "check", s(&bad_number)], &bad_number, "line 3");
    let zero = dir.path().join("zero-vector.txt");
    std::fs::write(&zero, "1 0 0\n0 0 0\n0 1 0\n").unwrap();
    assert_file_error(&["viewset", "check", s(&zero)], &zero, "line 2");
    let short = dir.path().join("two-numbers.txt");
    std::fs::write(&short, "1 0 0\n0 1 0\n0 1\n").unwrap();
    assert_file_error(&["viewset", "check", s(&short)], &short, "line 3");
    let empty = dir.path().join("empty.txt");
    std::fs::write(&empty, "").unwrap();
    assert_file_error(&["viewset", "check", s(&empty)], &empty, "empty");
    let missing = dir.path().join("missing-views.txt");
    assert_file_error(&["viewset", "check", s(&missing)], &missing, "readable");
}

// ---------------------------------------------------------------------------------------------
// visibility
// ---------------------------------------------------------------------------------------------

/// The six axis directions, in this order: +x −x +y −y +z −z.
const AXES: &str = "1 0 0\n-1 0 0\n0 1 0\n0 -1 0\n0 0 1\n0 0 -1\n";

/// Cube half-size: faces at ±0.51 = ±25.5 r lie in the middle of voxel layers 25 and −26, so
/// the voxelization is robust to rounding and symmetric under all 48 symmetries of the grid
/// (x ↦ −x maps key k to −1 − k, and layer 25 to −26).
const CUBE_H: f64 = 0.51;

fn write_cube(path: &Path, h: f64) {
    let v: Vec<[f64; 3]> =
        (0..8).map(|i| [(i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64]).collect();
    let v: Vec<[f64; 3]> = v.iter().map(|p| p.map(|c| (2.0 * c - 1.0) * h)).collect();
    let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    let tris: Vec<[usize; 3]> = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
    write_obj(path, &v, &tris);
}

struct VisResult {
    surface: u64,
    per_view: Vec<u64>,
    union: u64,
    json: serde_json::Value,
    bytes: Vec<u8>,
}

fn visibility(mesh: &Path, views: &Path, extra: &[&str], out: &Path) -> VisResult {
    let mut args = vec!["visibility", s(mesh), "--normalize", "none", "--views", s(views), "--out", s(out)];
    args.extend_from_slice(extra);
    objview_ok(&args);
    let bytes = read(out);
    let json: serde_json::Value = serde_json::from_slice(&bytes).expect("visibility writes JSON");
    let int = |v: &serde_json::Value| v.as_u64().unwrap_or_else(|| panic!("not an integer: {v}"));
    VisResult {
        surface: int(&json["surface_voxels"]),
        per_view: json["per_view"].as_array().expect("per_view array").iter().map(int).collect(),
        union: int(&json["union"]),
        json,
        bytes,
    }
}

/// Axis-aligned cube with faces at ±0.51 seen from the six axis directions at radius 3.
///
/// S_gt (sampled on the faces, ≥ 18 expected samples in even the corner voxels) is the shell of
/// keys in [−26, 25]³ with some coordinate at −26 or 25: 52³ − 50³ = 15608 voxels. From the +x
/// camera every ray towards the cube crosses the plane x = 0.52 (the outer side of layer 25)
/// within |y|, |z| < 0.52, so the first S_gt voxel of every ray lies in the front layer; and a
/// front-layer voxel's own ray (through a pixel centre ≤ 0.71 px ≈ 0.003 from its centre, plus a
/// perspective shift ≤ 0.003 over the 0.01 to the layer's face) enters that very voxel, 0.01 from
/// its sides. So O(v) = the 52² = 2704 front-layer voxels in `inverse` mode; in `mesh` mode the
/// rendered cloud covers exactly the front face, ≥ 2 pixels per (half) voxel at 0.004 per pixel.
/// The rotated pixel grid of the ±z cameras (pole rule) changes none of these bounds, so all six
/// views are equal, and their union is the whole shell: union / surface_voxels = 1 exactly.
#[test]
fn visibility_cube_from_six_axes_is_exact_in_both_modes() {
    let dir = tempdir();
    let mesh = dir.path().join("cube.obj");
    write_cube(&mesh, CUBE_H);
    let views = dir.path().join("axes.txt");
    std::fs::write(&views, AXES).unwrap();
    let shell = 52u64.pow(3) - 50u64.pow(3);
    for mode in ["inverse", "mesh"] {
        let out = dir.path().join(format!("{mode}.json"));
        let r = visibility(&mesh, &views, &["--mode", mode, "--resolution", "0.02"], &out);
        assert_eq!(r.surface, shell, "{mode}: surface_voxels");
        assert_eq!(r.per_view, vec![52 * 52; 6], "{mode}: per_view");
        assert_eq!(r.union, r.surface, "{mode}: union");
        assert_eq!(r.json["settings"]["mode"], mode, "settings record the mode");
        assert_eq!(r.json["settings"]["resolution"], 0.02, "settings record the resolution");

        // Determinism: a second run writes the same bytes.
        let out2 = dir.path().join(format!("{mode}-again.json"));
        let r2 = visibility(&mesh, &views, &["--mode", mode], &out2);
        assert!(r.bytes == r2.bytes, "{mode}: two runs differ");
    }
}

/// Points on the plane z = 0.011 (voxel layer 0), coordinates exactly representable in f32 and
/// never within 1e-6 voxel of a cell boundary, so floor(p / r) is unambiguous.
fn plane_points() -> Vec<[f64; 3]> {
    let r = 0.02;
    let clean = |c: f64| ((c / r) - (c / r).round()).abs() > 1e-6;
    let mut pts = Vec::new();
    for i in 0..83 {
        for j in 0..71 {
            let x = (-0.45 + 0.0117 * i as f64) as f32 as f64;
            let y = (-0.4 + 0.0131 * j as f64 + 0.002 * (i % 3) as f64) as f32 as f64;
            let p = [x, y, 0.011f32 as f64];
            if p.iter().all(|&c| clean(c)) {
                pts.push(p);
            }
        }
    }
    pts
}

#[test]
fn visibility_gt_cloud_voxels_are_the_distinct_keys() {
    let dir = tempdir();
    let mesh = dir.path().join("cube.obj");
    write_cube(&mesh, CUBE_H);
    let views = dir.path().join("axes.txt");
    std::fs::write(&views, AXES).unwrap();
    let pts = plane_points();
    let keys: HashSet<[i64; 3]> = pts.iter().map(|p| p.map(|c| (c / 0.02).floor() as i64)).collect();
    assert!(keys.len() > 1500 && keys.iter().all(|k| k[2] == 0));

    let ply = dir.path().join("plane.ply");
    write_ply_ascii(&ply, &pts);
    let npy = dir.path().join("plane.npy");
    write_npy_f64(&npy, &pts);
    for cloud in [&ply, &npy] {
        let out = dir.path().join("plane.json");
        let r = visibility(&mesh, &views, &["--gt-cloud", s(cloud)], &out);
        assert_eq!(r.surface, keys.len() as u64, "{}: surface_voxels vs distinct keys", cloud.display());
        assert_eq!(r.per_view.len(), 6);
        // Seen face-on from ±z, a single layer of voxels is entirely visible (inverse mode: each
        // voxel's ray enters the layer ≤ 0.5 px ≈ 0.003 from the voxel's centre).
        assert_eq!(r.per_view[4], r.surface, "{}: +z view", cloud.display());
        assert_eq!(r.per_view[5], r.surface, "{}: −z view", cloud.display());
        assert_eq!(r.union, r.surface);
        assert!(r.per_view.iter().all(|&n| n <= r.surface));
    }

    // A bad view file fails with one line naming it.
    let bad = dir.path().join("bad-views.txt");
    std::fs::write(&bad, "1 0 0\n0 0 zero\n").unwrap();
    let out = dir.path().join("bad.json");
    assert_file_error(
        &["visibility", s(&mesh), "--normalize", "none", "--views", s(&bad), "--out", s(&out)],
        &bad,
        "line 2",
    );
    assert!(!out.exists());
}

// ---------------------------------------------------------------------------------------------
// objects synth
// ---------------------------------------------------------------------------------------------

#[test]
fn objects_synth_is_deterministic_and_renderable() {
    let dir = tempdir();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    objview_ok(&["objects", "synth", "--out", s(&a)]);
    objview_ok(&["objects", "synth", "--out", s(&b)]);
    let list = |d: &Path| {
        let mut v: Vec<String> =
            std::fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
        v.sort();
        v
    };
    let files = list(&a);
    assert_eq!(files, list(&b));
    let objs: Vec<&String> = files.iter().filter(|f| f.ends_with(".obj")).collect();
    assert!(objs.len() >= 30, "only {} objects", objs.len());
    for f in &files {
        assert!(read(&a.join(f)) == read(&b.join(f)), "{f} differs between two runs");
    }

    // Three of them render from (3,0,0) after unit normalization: hits, and every depth lies in
    // [2, 4] because a unit-normalized object lies in the unit ball (z = 3 − x).
    for f in [objs[0], objs[objs.len() / 2], objs[objs.len() - 1]] {
        let out = dir.path().join(format!("{f}.npy"));
        objview_ok(&[
            "render",
            s(&a.join(f)),
            "--pose",
            "3,0,0,0,0,0,0",
            "--normalize",
            "unit",
            "--depth",
            s(&out),
        ]);
        let d = read_depth(&out);
        let hits: Vec<f32> = d.data.iter().copied().filter(|&z| z != 0.0).collect();
        assert!(hits.len() > 100, "{f}: only {} hit pixels", hits.len());
        assert!(hits.iter().all(|&z| (2.0 - 1e-4..=4.0 + 1e-4).contains(&z)), "{f}: depth outside [2, 4]");
    }
}

/// `feasibility`: a custom rule file (OR of two half-spaces) on hand-picked poses, and the
/// built-in `hemi` on the 6 axis directions (exactly those with z ≥ 0: +x, −x, +y, −y, +z).
#[test]
fn feasibility_custom_rules_and_builtin_space() {
    let dir = tempdir();
    let rules = dir.path().join("front_or_top.json");
    std::fs::write(
        &rules,
        r#"{"name": "front_or_top", "atol": 0.0001, "structured_rule": {"logic": "and", "rules": [
            {"field": "camera_radius", "op": ">=", "value": 1.0},
            {"logic": "or", "rules": [
                {"field": "camera_x", "op": ">", "value": 0.5},
                {"field": "camera_z", "op": ">", "value": 0.5}]}]}}"#,
    )
    .unwrap();
    let out = objview_ok(&[
        "feasibility",
        s(&rules),
        "--pose",
        "3,0,0,0,0,0,0",
        "--pose",
        "-3,0,0,0,0,0,0",
        "--pose",
        "0,0,3,0,0,0,1.0",
        "--pose",
        "0.6,0,0.6,0,0,0,0",
    ]);
    let verdicts: Vec<&str> = out
        .lines()
        .filter(|l| !l.starts_with("space="))
        .map(|l| l.split_whitespace().nth(2).unwrap())
        .collect();
    assert_eq!(verdicts, ["feasible", "infeasible:", "feasible", "infeasible:"], "{out}");
    assert!(out.contains("camera_radius"), "the radius rule is named for the inner pose: {out}");
    assert!(out.ends_with("space=front_or_top feasible=2 of 4\n"), "{out}");

    let views = dir.path().join("axes.txt");
    std::fs::write(&views, "1 0 0\n-1 0 0\n0 1 0\n0 -1 0\n0 0 1\n0 0 -1\n").unwrap();
    let out = objview_ok(&["feasibility", "hemi", "--views", s(&views), "--quiet"]);
    assert_eq!(out, "space=hemi feasible=5 of 6\n");

    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, r#"{"name": "x", "structured_rule": {"logic": "xor", "rules": []}}"#).unwrap();
    let err = objview_err(&["feasibility", s(&bad), "--views", s(&views)]);
    assert!(err.contains("bad.json"), "{err}");
}

/// `render` records what produced its outputs in `<DEPTH>.json` (NPY cannot carry it).
#[test]
fn render_writes_provenance_beside_the_depth() {
    let dir = tempdir();
    let mesh = dir.path().join("tri.obj");
    write_obj(&mesh, &[[0.0, -0.5, -0.5], [0.0, 0.5, -0.5], [0.0, 0.0, 0.5]], &[[0, 1, 2]]);
    let depth = dir.path().join("d.npy");
    objview_ok(&[
        "render",
        s(&mesh),
        "--pose",
        "-3,0,0,0,0,0,0.25",
        "--normalize",
        "none",
        "--depth",
        s(&depth),
    ]);
    let meta: serde_json::Value =
        serde_json::from_slice(&read(&dir.path().join("d.npy.json"))).expect("provenance JSON");
    assert_eq!(meta["tool"], "objview");
    assert_eq!(meta["command"], "render");
    assert_eq!(meta["pose"], serde_json::json!([-3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.25]));
    assert_eq!(meta["normalize"], "none");
    assert_eq!(meta["depth"]["shape"], serde_json::json!([512, 512]));
    let hits = read_depth(&depth).data.iter().filter(|&&z| z != 0.0).count();
    assert!(hits > 0);
    assert_eq!(meta["hits"], serde_json::json!(hits));
}
