//! The generators of the built-in objects, one function per catalog entry.
//!
//! Each generator draws its object at roughly unit size into a [`Builder`] whose edge length
//! sets the tessellation; normalization to the unit ball happens afterwards, in
//! [`Builder::finish`]. Shapes are modelled as solids with real thickness: a cup is one closed
//! surface (outside, rim, inside), a pipe is a closed ring-shaped solid, a hollow box is the
//! boundary of its walls. Where an object is an assembly of parts that would need a boolean
//! union to merge (the mug's handle), each part is a closed surface and the overlap is
//! documented in the catalog.

use super::builder::{pieces, Builder, Rgb, P2, P3};
use std::f64::consts::{FRAC_PI_2, PI, TAU};

pub(super) const GREY: Rgb = [0.72, 0.72, 0.72];
pub(super) const RED: Rgb = [0.80, 0.18, 0.15];
pub(super) const ORANGE: Rgb = [0.92, 0.55, 0.15];
pub(super) const YELLOW: Rgb = [0.93, 0.82, 0.25];
pub(super) const GREEN: Rgb = [0.25, 0.62, 0.30];
pub(super) const TEAL: Rgb = [0.15, 0.55, 0.60];
pub(super) const BLUE: Rgb = [0.20, 0.35, 0.75];
pub(super) const PURPLE: Rgb = [0.52, 0.30, 0.65];
pub(super) const WHITE: Rgb = [0.93, 0.92, 0.88];
pub(super) const BROWN: Rgb = [0.50, 0.33, 0.18];
pub(super) const DARK: Rgb = [0.22, 0.22, 0.25];

/// Sphere of radius `r` centred at `c`, faces outward (or into the ball's cavity when
/// `inward`, for the inner surface of a hollow solid).
pub(super) fn ball(b: &mut Builder, c: P3, r: f64, inward: bool) {
    let mark = b.mark();
    let (a0, a1) = if inward { (FRAC_PI_2, -FRAC_PI_2) } else { (-FRAC_PI_2, FRAC_PI_2) };
    let mut p = b.profile([0.0, r * a0.sin()]);
    p.arc([0.0, 0.0], r, r, a0, a1);
    b.revolve(&p);
    b.map_from(mark, |q| [q[0] + c[0], q[1] + c[1], q[2] + c[2]]);
}

pub(super) fn sphere(b: &mut Builder) {
    b.color = BLUE;
    ball(b, [0.0; 3], 1.0, false);
}

pub(super) fn cube(b: &mut Builder) {
    let s: &[f64] = &[-0.6, 0.6];
    b.cells([s, s, s], |_, _, _| Some(ORANGE));
}

pub(super) fn cylinder(b: &mut Builder) {
    b.color = GREEN;
    let mut p = b.profile([0.0, -0.8]);
    p.line_to([0.6, -0.8]).line_to([0.6, 0.8]).line_to([0.0, 0.8]);
    b.revolve(&p);
}

pub(super) fn cone(b: &mut Builder) {
    b.color = YELLOW;
    let mut p = b.profile([0.0, -0.6]);
    p.line_to([0.75, -0.6]).line_to([0.0, 0.9]);
    b.revolve(&p);
}

pub(super) fn octahedron(b: &mut Builder) {
    b.color = PURPLE;
    // Rings are diamonds |x| + |y| = 1, so every quad lies in one of the eight face planes.
    let k = pieces(2f64.sqrt(), b.h);
    let corners: [P2; 5] = [[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0], [1.0, 0.0]];
    let ring: Vec<P2> = (0..4)
        .flat_map(|s| {
            let (u, v) = (corners[s], corners[s + 1]);
            (0..k).map(move |i| {
                let t = i as f64 / k as f64;
                [u[0] + t * (v[0] - u[0]), u[1] + t * (v[1] - u[1])]
            })
        })
        .collect();
    let mut p = b.profile([0.0, -1.0]);
    p.line_to([1.0, 0.0]).line_to([0.0, 1.0]);
    b.revolve_ring(&p, false, &ring);
}

pub(super) fn ellipsoid(b: &mut Builder) {
    b.color = TEAL;
    ball(b, [0.0; 3], 1.0, false);
    b.map_from(0, |q| [q[0], 0.65 * q[1], 0.45 * q[2]]);
}

/// Torus around the z axis: tube radius `r` around a centre circle of radius `big_r`.
pub(super) fn torus_at(b: &mut Builder, big_r: f64, r: f64) {
    let mut p = b.profile([big_r + r, 0.0]);
    p.arc([big_r, 0.0], r, r, 0.0, TAU);
    b.revolve_closed(&p.close());
}

/// Major radius of the `torus` object before normalization (minor radius 1 − this).
pub(super) const TORUS_R: f64 = 0.65;
/// Major radius of the `thin-torus` object before normalization (minor radius 1 − this).
pub(super) const THIN_TORUS_R: f64 = 0.88;

pub(super) fn torus(b: &mut Builder) {
    b.color = RED;
    torus_at(b, TORUS_R, 1.0 - TORUS_R);
}

pub(super) fn thin_torus(b: &mut Builder) {
    b.color = ORANGE;
    torus_at(b, THIN_TORUS_R, 1.0 - THIN_TORUS_R);
}

pub(super) fn cup(b: &mut Builder) {
    // Tapered paper-cup shape: bottom 0.05 thick, wall 0.04.
    b.color = WHITE;
    let mut p = b.profile([0.0, 0.0]);
    p.line_to([0.32, 0.0]).line_to([0.45, 0.9]);
    p.color = GREY;
    p.line_to([0.41, 0.9]);
    p.color = TEAL;
    p.line_to([0.28, 0.05]).line_to([0.0, 0.05]);
    b.revolve(&p);
}

/// Mug dimensions: outer radius, height, wall, bottom thickness.
const MUG: (f64, f64, f64, f64) = (0.5, 1.0, 0.05, 0.06);

pub(super) fn mug(b: &mut Builder) {
    let (r, h, w, tb) = MUG;
    b.color = BLUE;
    let mut p = b.profile([0.0, 0.0]);
    p.line_to([r, 0.0]).line_to([r, h]);
    p.color = WHITE;
    p.line_to([r - w, h]).line_to([r - w, tb]).line_to([0.0, tb]);
    b.revolve(&p);
    // Handle: an arc of a torus in the xz plane whose flat end caps sit in the middle of the
    // wall (so the ends are hidden inside the wall, and the caps never reach the inside).
    b.color = RED;
    let (rho, tube, zc) = (0.3, 0.045, 0.55);
    let cx = r + 0.32 - rho;
    let end = ((r - 0.5 * w - cx) / rho).acos();
    let n = pieces(2.0 * end * rho, b.h).max(4);
    let path: Vec<P3> = (0..=n)
        .map(|i| {
            let a = -end + 2.0 * end * i as f64 / n as f64;
            [cx + rho * a.cos(), 0.0, zc + rho * a.sin()]
        })
        .collect();
    b.tube(&path, false, tube);
}

pub(super) fn bowl(b: &mut Builder) {
    // Spherical bowl (outer radius 1, wall 0.08) with a flat foot and a rounded rim.
    let (t, zb, tb): (f64, f64, f64) = (0.08, -0.8, 0.08);
    let ri = 1.0 - t;
    let foot = zb.asin();
    let inner_end = ((zb + tb) / ri).asin();
    b.color = GREEN;
    let mut p = b.profile([0.0, zb]);
    p.line_to([foot.cos(), zb]).arc([0.0, 0.0], 1.0, 1.0, foot, 0.0);
    p.color = WHITE;
    p.arc([1.0 - 0.5 * t, 0.0], 0.5 * t, 0.5 * t, 0.0, PI);
    p.color = YELLOW;
    p.arc([0.0, 0.0], ri, ri, 0.0, inner_end).line_to([0.0, zb + tb]);
    b.revolve(&p);
}

/// Outer radius of the vase at height `z` (0..1.4): a bulb, a narrow neck, a flared lip.
fn vase_radius(z: f64) -> f64 {
    let s = ((z - 1.15) / 0.25).clamp(0.0, 1.0);
    0.1 + 0.3 * (-((z - 0.45) / 0.32).powi(2)).exp() + 0.12 * s * s * (3.0 - 2.0 * s)
}

pub(super) fn vase(b: &mut Builder) {
    let (h, w, tb) = (1.4, 0.025, 0.06);
    b.color = PURPLE;
    let mut p = b.profile([0.0, 0.0]);
    p.line_to([vase_radius(0.0), 0.0]).curve(|t| [vase_radius(h * t), h * t]);
    p.color = GREY;
    p.line_to([vase_radius(h) - w, h]);
    p.color = DARK;
    p.curve(|t| {
        let z = h - (h - tb) * t;
        [vase_radius(z) - w, z]
    })
    .line_to([0.0, tb]);
    b.revolve(&p);
}

pub(super) fn pipe(b: &mut Builder) {
    // Thick-walled open tube lying along x: its inside is visible only from near the axis.
    b.color = GREY;
    let mut p = b.profile([0.32, -0.9]);
    p.line_to([0.42, -0.9]).line_to([0.42, 0.9]).line_to([0.32, 0.9]);
    p.color = DARK;
    b.revolve_closed(&p.close());
    b.map_from(0, |q| [q[2], q[1], -q[0]]);
}

/// Cell boundaries `[0, t, …inner…, 1 − t, 1]`-style axes for hollow boxes.
fn shell_axis(size: f64, t: f64, inner: &[f64]) -> Vec<f64> {
    let mut v = vec![0.0, t];
    v.extend_from_slice(inner);
    v.extend_from_slice(&[size - t, size]);
    v
}

pub(super) fn box_with_hole(b: &mut Builder) {
    // Hollow box (walls 0.06) with a 0.16 × 0.16 hole in the middle of its top: the inner
    // surfaces are visible only through the hole.
    let (s, t, hw) = (1.0, 0.06, 0.08);
    let x = shell_axis(s, t, &[0.5 - hw, 0.5 + hw]);
    let z = shell_axis(0.8, t, &[0.4 - hw, 0.4 + hw]);
    b.cells([&x, &x, &z], |i, j, k| {
        let wall = i == 0 || i == 4 || j == 0 || j == 4 || k == 0 || k == 4;
        let hole = k == 4 && i == 2 && j == 2;
        (wall && !hole).then_some(if k == 0 || k == 4 { BROWN } else { ORANGE })
    });
}

pub(super) fn sealed_box(b: &mut Builder) {
    // Hollow box with a sealed cavity: the inner surface is never observable.
    let x = shell_axis(1.0, 0.08, &[]);
    let z = shell_axis(0.7, 0.08, &[]);
    b.cells([&x, &x, &z], |i, j, k| (i != 1 || j != 1 || k != 1).then_some(BROWN));
}

pub(super) fn hollow_sphere(b: &mut Builder) {
    // Outer sphere of radius 1 with a sealed spherical cavity of radius HOLLOW_INNER.
    b.color = TEAL;
    ball(b, [0.0; 3], 1.0, false);
    b.color = RED;
    ball(b, [0.0; 3], HOLLOW_INNER, true);
}

/// Cavity radius of `hollow-sphere` (outer radius 1).
pub(super) const HOLLOW_INNER: f64 = 0.75;

pub(super) fn ball_in_shell(b: &mut Builder) {
    // Thick spherical shell (radius 1, wall 0.08) cut open above 60° latitude, with a ball
    // resting a hair above its inner bottom: the ball is seen only through the opening.
    let (t, cut) = (0.08, 60f64.to_radians());
    let ri = 1.0 - t;
    b.color = GREY;
    let mut p = b.profile([0.0, -1.0]);
    p.arc([0.0, 0.0], 1.0, 1.0, -FRAC_PI_2, cut);
    p.color = WHITE;
    p.line_to([ri * cut.cos(), ri * cut.sin()]);
    p.color = DARK;
    p.arc([0.0, 0.0], ri, ri, cut, -FRAC_PI_2);
    b.revolve(&p);
    b.color = RED;
    ball(b, [0.0, 0.0, -ri + 0.5 + 0.02], 0.5, false);
}

pub(super) fn ball_in_cage(b: &mut Builder) {
    // Cubic cage of square bars (12 edges plus a cross on every face) around a ball.
    let bar = 0.06;
    let a = shell_axis(1.0, bar, &[0.5 - 0.5 * bar, 0.5 + 0.5 * bar]);
    b.cells([&a, &a, &a], |i, j, k| {
        let on = [i, j, k].iter().filter(|&&c| c == 0 || c == 4).count();
        let mid = [i, j, k].contains(&2);
        (on >= 2 || (on == 1 && mid)).then_some(DARK)
    });
    b.color = YELLOW;
    ball(b, [0.5, 0.5, bar + 0.3 + 0.01], 0.3, false);
}

pub(super) fn thin_plate(b: &mut Builder) {
    b.cells([&[0.0, 1.6], &[0.0, 1.0], &[0.0, 0.03]], |_, _, _| Some(GREY));
}

pub(super) fn l_shape(b: &mut Builder) {
    // An upright L extruded along y.
    b.cells([&[0.0, 0.35, 1.2], &[0.0, 0.5], &[0.0, 0.35, 1.2]], |i, _, k| {
        (i == 0 || k == 0).then_some(GREEN)
    });
}

pub(super) fn u_shape(b: &mut Builder) {
    // A U with a deep channel (0.3 wide, 0.9 deep) extruded along y.
    b.cells([&[0.0, 0.3, 0.6, 0.9], &[0.0, 0.6], &[0.0, 0.3, 1.2]], |i, _, k| {
        (k == 0 || i != 1).then_some(BLUE)
    });
}

pub(super) fn slot_block(b: &mut Builder) {
    // Block with a blind slit 0.04 wide and 0.65 deep, open only at the top.
    let x = [0.0, 0.48, 0.52, 1.0];
    let y = [0.0, 0.1, 0.5, 0.6];
    let z = [0.0, 0.15, 0.8];
    b.cells([&x, &y, &z], |i, j, k| {
        (!(i == 1 && j == 1 && k == 1)).then_some(if i == 1 && j == 1 { RED } else { GREY })
    });
}

pub(super) fn gear(b: &mut Builder) {
    // Spur gear: 14 trapezoidal teeth (root radius 0.78, tip 1), a bore of radius 0.22, 0.25
    // thick.
    spur_gear(b, 14, 0.78, 1.0, 0.22, -0.125, 0.25, [0.5, 0.6, 0.9], ORANGE, YELLOW);
}

/// A spur gear around z between z0 and z0 + thickness: `teeth` trapezoidal teeth from `root`
/// to `tip` radius, a bore of radius `bore`; `fr` are the tooth outline's fractions of a pitch
/// (root arc end, tip start, tip end); the caps and the bottom have colour `top`, the
/// outer wall `side`, the bore grey. The tooth outline has strictly increasing polar angle, so
/// pairing every outline point with the bore point at the same angle gives non-crossing radial
/// cap strips.
#[allow(clippy::too_many_arguments)]
pub(crate) fn spur_gear(
    b: &mut Builder,
    teeth: usize,
    root: f64,
    tip: f64,
    bore: f64,
    z0: f64,
    thick: f64,
    fr: [f64; 3],
    top: Rgb,
    side: Rgb,
) {
    let h = b.h;
    let pitch = TAU / teeth as f64;
    let polar = |r: f64, a: f64| [r * a.cos(), r * a.sin()];
    let arc = |out: &mut Vec<P2>, r: f64, a0: f64, a1: f64| {
        let n = pieces(r * (a1 - a0), h);
        out.extend((0..n).map(|i| polar(r, a0 + (a1 - a0) * i as f64 / n as f64)));
    };
    let line = |out: &mut Vec<P2>, p: P2, q: P2| {
        let n = pieces((q[0] - p[0]).hypot(q[1] - p[1]), h);
        out.extend((0..n).map(|i| {
            let t = i as f64 / n as f64;
            [p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]
        }));
    };
    let mut outline: Vec<P2> = Vec::new();
    for k in 0..teeth {
        let f = [0.0, fr[0], fr[1], fr[2], 1.0].map(|s| (k as f64 + s) * pitch);
        arc(&mut outline, root, f[0], f[1]);
        line(&mut outline, polar(root, f[1]), polar(tip, f[2]));
        arc(&mut outline, tip, f[2], f[3]);
        line(&mut outline, polar(tip, f[3]), polar(root, f[4]));
    }
    let m = pieces(tip - bore, h);
    let q = pieces(thick, h);
    let mut section: Vec<(f64, f64, Rgb)> = Vec::new();
    (0..m).for_each(|i| section.push((i as f64 / m as f64, z0, top)));
    (0..q).for_each(|i| section.push((1.0, z0 + thick * i as f64 / q as f64, side)));
    (0..m).for_each(|i| section.push((1.0 - i as f64 / m as f64, z0 + thick, top)));
    (0..q).for_each(|i| section.push((0.0, z0 + thick - thick * i as f64 / q as f64, GREY)));
    let rows: Vec<Vec<P3>> = section
        .iter()
        .map(|&(t, z, _)| {
            outline
                .iter()
                .map(|o| {
                    let r_o = o[0].hypot(o[1]);
                    let s = bore + t * (r_o - bore);
                    [o[0] * s / r_o, o[1] * s / r_o, z]
                })
                .collect()
        })
        .collect();
    let colors: Vec<Rgb> = section.iter().map(|s| s.2).collect();
    b.sheet(&rows, &colors, true);
}

pub(super) fn chair(b: &mut Builder) {
    // Four legs, a seat and a back of three slats under a top rail.
    let x = [0.0, 0.08, 0.18, 0.26, 0.36, 0.44, 0.54, 0.62];
    let y = [0.0, 0.08, 0.52, 0.6];
    let z = [0.0, 0.5, 0.58, 1.1, 1.2];
    b.cells([&x, &y, &z], |i, j, k| {
        let post = (i == 0 || i == 6) && (j == 0 || j == 2);
        match k {
            0 => post.then_some(DARK),
            1 => Some(BROWN),
            2 => (j == 2 && i % 2 == 0).then_some(ORANGE),
            _ => (j == 2).then_some(ORANGE),
        }
    });
}

pub(super) fn table(b: &mut Builder) {
    // Table top overhanging four inset legs.
    let x = [0.0, 0.1, 0.17, 1.03, 1.1, 1.2];
    let y = [0.0, 0.1, 0.17, 0.63, 0.7, 0.8];
    b.cells([&x, &y, &[0.0, 0.66, 0.72]], |i, j, k| {
        if k == 1 {
            Some(BROWN)
        } else {
            ((i == 1 || i == 3) && (j == 1 || j == 3)).then_some(DARK)
        }
    });
}

pub(super) fn comb(b: &mut Builder) {
    // 12 prongs 0.04 wide with 0.04 gaps hanging from a spine, plus a handle.
    let prongs = 12;
    let mut x = vec![0.0];
    for i in 0..2 * prongs - 1 {
        x.push(x[i] + 0.04);
    }
    let spine_end = *x.last().expect("non-empty");
    x.push(spine_end + 0.45);
    let last = x.len() - 2;
    b.cells([&x, &[0.0, 0.05], &[0.0, 0.45, 0.6]], |i, _, k| {
        if i == last {
            (k == 1).then_some(DARK)
        } else {
            (k == 1 || i % 2 == 0).then_some(if k == 1 { BLUE } else { TEAL })
        }
    });
}

pub(super) fn l_bracket(b: &mut Builder) {
    // Corner bracket: three orthogonal plates meeting at a corner (an inside corner pocket).
    let a = [0.0, 0.08, 1.0];
    b.cells([&a, &a, &a], |i, j, k| ([i, j, k].contains(&0)).then_some(GREY));
}

pub(super) fn mushroom(b: &mut Builder) {
    // Stem with a flared foot under a domed cap whose rim overhangs and droops.
    b.color = WHITE;
    let mut p = b.profile([0.0, 0.0]);
    p.line_to([0.22, 0.0]).line_to([0.15, 0.12]).line_to([0.15, 0.55]);
    p.color = YELLOW;
    p.line_to([0.7, 0.47]);
    p.color = RED;
    p.arc([0.0, 0.47], 0.7, 0.5, 0.0, FRAC_PI_2);
    b.revolve(&p);
}

pub(super) fn ring_tower(b: &mut Builder) {
    // Base plate, five stacked rings of decreasing size on a core, a knob on top: one solid
    // whose grooves between rings hide part of the surface from most directions.
    let neck = 0.12;
    let mut p = b.profile([0.0, 0.0]);
    p.color = DARK;
    // A short neck above the plate keeps the lowest ring's underside off the plate.
    p.line_to([0.42, 0.0]).line_to([0.42, 0.06]).line_to([neck, 0.06]).line_to([neck, 0.1]);
    let mut z = 0.1;
    for (k, rho) in [0.2, 0.17, 0.14, 0.11, 0.08].into_iter().enumerate() {
        p.color = [RED, ORANGE, YELLOW, GREEN, BLUE][k];
        p.arc([neck, z + rho], rho, rho, -FRAC_PI_2, FRAC_PI_2);
        z += 2.0 * rho;
        p.color = DARK;
        p.line_to([neck, z + 0.04]);
        z += 0.04;
    }
    p.color = PURPLE;
    p.arc([0.0, z], neck, neck, 0.0, FRAC_PI_2);
    b.revolve(&p);
}

/// `n + 1` samples of a curve `f(t)`, `t` in `[0, 1]`, with `n` chosen from its length.
pub(super) fn sample_path(b: &Builder, f: impl Fn(f64) -> P3, closed: bool) -> Vec<P3> {
    let m = 1024;
    let len: f64 = (0..m)
        .map(|i| {
            let (p, q) = (f(i as f64 / m as f64), f((i + 1) as f64 / m as f64));
            ((q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) + (q[2] - p[2]).powi(2)).sqrt()
        })
        .sum();
    let n = pieces(len, b.h).max(8);
    let count = if closed { n } else { n + 1 };
    (0..count).map(|i| f(i as f64 / n as f64)).collect()
}

pub(super) fn helix(b: &mut Builder) {
    // Three turns of a tube (radius 0.12) on a helix of radius 0.6 and pitch 0.5.
    b.color = GREEN;
    let turns = 3.0;
    let path = sample_path(
        b,
        |t| {
            let a = TAU * turns * t;
            [0.6 * a.cos(), 0.6 * a.sin(), 0.5 * turns * t]
        },
        false,
    );
    b.tube(&path, false, 0.12);
}

pub(super) fn trefoil_knot(b: &mut Builder) {
    // Tube around a trefoil knot. The tube radius (0.15) is below the centre line's minimum
    // radius of curvature (0.43) and below half the closest approach of distant strands
    // (0.40 / 2), so the tube does not intersect itself.
    b.color = PURPLE;
    let path = sample_path(
        b,
        |t| {
            let a = TAU * t;
            let s = 1.0 / 3.0;
            [
                s * (a.sin() + 2.0 * (2.0 * a).sin()),
                s * (a.cos() - 2.0 * (2.0 * a).cos()),
                -s * (3.0 * a).sin(),
            ]
        },
        true,
    );
    b.tube(&path, true, 0.15);
}

/// Radius of the `blob` surface in unit direction `d`: low-frequency waves plus Gaussian-like
/// lumps (a head, two ears, a tail) and a dent; deterministic, smooth, star-shaped.
fn blob_radius(d: P3) -> f64 {
    let lumps: [(P3, f64, f64); 6] = [
        ([0.6, 0.0, 0.55], 0.30, 0.10),
        ([0.45, 0.28, 0.85], 0.55, 0.02),
        ([0.45, -0.28, 0.85], 0.50, 0.02),
        ([-0.95, 0.0, 0.2], 0.15, 0.03),
        ([0.1, 0.95, 0.1], -0.18, 0.08),
        ([0.0, 0.0, -1.0], -0.25, 0.25),
    ];
    let waves = 0.06 * (3.0 * d[0] + 1.3).sin() * (2.0 * d[1] + 0.4).sin() * (2.5 * d[2] + 2.1).sin()
        + 0.03 * (7.0 * d[0] - 5.0 * d[2] + 0.7).sin();
    let lump: f64 = lumps
        .iter()
        .map(|&(c, amp, w)| {
            let n = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
            let cos = (d[0] * c[0] + d[1] * c[1] + d[2] * c[2]) / n;
            amp * (-(1.0 - cos) / w).exp()
        })
        .sum();
    1.0 + waves + lump
}

pub(super) fn blob(b: &mut Builder) {
    b.color = BROWN;
    ball(b, [0.0; 3], 1.0, false);
    b.map_from(0, |q| {
        let r = blob_radius(q);
        [0.9 * r * q[0], 0.75 * r * q[1], 0.8 * r * q[2]]
    });
}

pub(super) fn capsule_ring(b: &mut Builder) {
    // A thick washer (flat annulus with rounded edges) standing on its rim: the hole is seen
    // edge-on from most of the upper hemisphere.
    b.color = TEAL;
    let (ri, ro, half) = (0.45, 1.0, 0.12);
    let mut p = b.profile([ri, -half]);
    p.line_to([ro - half, -half])
        .arc([ro - half, 0.0], half, half, -FRAC_PI_2, FRAC_PI_2)
        .line_to([ri, half]);
    b.revolve_closed(&p.close());
    b.map_from(0, |q| [q[0], -q[2], q[1]]);
}
