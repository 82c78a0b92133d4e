//! The parametric families of the random pool, one generator per family.
//!
//! A generator draws its parameters from the object's stream (recording them) and builds the
//! object at roughly unit size into the builder; the random scale, orientation and the
//! normalization happen afterwards. No draw may depend on the builder's edge length, so the
//! same object comes out at every tessellation.

use super::super::builder::{pieces, P3};
use super::super::shapes::{spur_gear, DARK, GREY, WHITE};
use super::parts::*;
use super::{round4, Family, Gen};
use std::f64::consts::{FRAC_PI_2, PI, TAU};

macro_rules! family {
    ($name:literal, $gen:path, $weight:literal, $desc:literal) => {
        Family { name: $name, description: $desc, weight: $weight, generate: $gen }
    };
}

static FAMILIES: [Family; 35] = [
    // Simple solids: a few views see everything.
    family!("box", box_, 6, "Box with random sides: convex, flat faces"),
    family!("plate", plate, 6, "Thin plate, sometimes perforated by a grid of square holes"),
    family!("prism", prism, 4, "Regular 3- to 8-gonal prism of random height"),
    family!("pyramid", pyramid, 3, "Regular 3- to 6-gonal pyramid, sometimes truncated"),
    family!("ellipsoid", ellipsoid_, 3, "Triaxial ellipsoid: convex and smooth"),
    family!("frustum", frustum_, 4, "Cylinder, cone, frustum or flat disc of random proportions"),
    family!("capsule", capsule, 2, "Cylinder with hemispherical ends"),
    family!("stairs", stairs, 3, "Staircase of 2 to 7 random steps: concave inner corners"),
    family!("beam", beam, 4, "Extruded L, T, U, I, H or hollow rectangular section"),
    // Moderate self-occlusion.
    family!("torus", torus_, 3, "Ring torus from a thin ring to an almost closed hole"),
    family!("cup", cup_, 3, "Tapered open cup: its inside is seen only from above"),
    family!("bowl", bowl, 3, "Spherical bowl with a foot, its rim below or above the equator"),
    family!("mug", mug, 2, "Mug with one or two torus-segment handles set into the wall"),
    family!("bottle", bottle, 2, "Hollow bottle with a shoulder and a narrow open neck"),
    family!("pot", pot, 2, "Pot with a lid that is on, raised, tilted open or missing, and handles"),
    family!("gear", gear, 3, "Spur gear with 6 to 32 teeth and a bore, sometimes a second gear stacked"),
    family!("table", table, 3, "Table: rectangular or round top on splayed legs, maybe a lower shelf"),
    family!("chair", chair, 3, "Chair: seat on four legs, solid or slatted back, maybe arms"),
    family!("mushroom", mushroom, 1, "Mushroom: stem under an overhanging, drooping cap"),
    family!("ring-stack", ring_stack, 1, "Rings of random sizes stacked on a core: deep grooves"),
    family!("helix", helix, 2, "Tube on a helix, sometimes around a central rod: turns occlude each other"),
    family!("knot", knot, 1, "Tube around a (p, q) torus knot: strands pass in front of each other"),
    family!("blob", blob, 3, "Star-shaped lumpy blob with random bumps and dents"),
    family!("stack", stack, 3, "Stack of boxes, cylinders and prisms, offset, turned and leaning"),
    family!("molecule", molecule, 3, "Balls joined by rods in a random tree"),
    family!("comb", comb, 1, "Comb with 4 to 24 prongs, sometimes double-sided, with a handle"),
    family!("composite", composite, 4, "Union of 2 to 6 random primitives touching each other"),
    // Strong self-occlusion: many views, slow saturation.
    family!("shelf", shelf, 2, "Shelf of rows x columns compartments, maybe a back and items inside"),
    family!("hollow-box", hollow_box, 2, "Hollow box with 1 to 4 holes in its faces, maybe a ball inside"),
    family!("cage", cage, 2, "Lattice of square bars, maybe around a ball"),
    family!("nested", nested, 2, "Nested parts: ball in an open shell, cups in cups, shell in shell"),
    family!("well-ball", well_ball, 3, "Ball with radial closed-bottom wells (chimneys) pointing out"),
    family!("pocket-block", pocket_block, 2, "Block with a grid of blind pockets in its top (and bottom)"),
    family!("tube-bundle", tube_bundle, 2, "Open thick-walled pipes in random directions"),
    family!("spiky-ball", spiky_ball, 2, "Ball with radial cones or rods: the core is seen between spikes"),
];

/// The families of the random pool, in a fixed order (the order and weights are part of the
/// pool's definition: changing them changes the pool, see [`super::POOL_VERSION`]).
pub fn families() -> &'static [Family] {
    &FAMILIES
}

fn box_(g: &mut Gen) {
    let x = g.f("x", 0.25, 1.0);
    let y = g.f("y", 0.25, 1.0);
    let z = g.f("z", 0.1, 1.0);
    cuboid(&mut g.b, [0.0; 3], [x, y, z]);
}

fn plate(g: &mut Gen) {
    let w = g.f("width", 0.3, 1.0);
    let t = g.log_f("thickness", 0.004, 0.06);
    let c = g.b.color;
    let (mut xs, mut ys) = (vec![0.0, 1.0], vec![0.0, w]);
    let mut holes: Vec<([f64; 2], [f64; 2])> = vec![];
    if g.chance("perforated", 0.4) {
        let nx = g.int("holes_x", 1, 6);
        let ny = g.int("holes_y", 1, 4);
        let frac = g.f("hole_fraction", 0.3, 0.7);
        let m = 0.06;
        let (px, py) = ((1.0 - 2.0 * m) / nx as f64, (w - 2.0 * m) / ny as f64);
        for i in 0..nx {
            for j in 0..ny {
                let (cx, cy) = (m + (i as f64 + 0.5) * px, m + (j as f64 + 0.5) * py);
                let (hx, hy) = (0.5 * frac * px, 0.5 * frac * py);
                xs.extend([cx - hx, cx + hx]);
                ys.extend([cy - hy, cy + hy]);
                holes.push(([cx - hx, cx + hx], [cy - hy, cy + hy]));
            }
        }
    }
    cells_where(&mut g.b, xs, ys, vec![0.0, t], |p| {
        let hole = holes.iter().any(|(x, y)| p[0] > x[0] && p[0] < x[1] && p[1] > y[0] && p[1] < y[1]);
        (!hole).then_some(c)
    });
}

fn prism(g: &mut Gen) {
    let n = g.int("sides", 3, 8);
    let h = g.log_f("height", 0.1, 1.8);
    polygonal(&mut g.b, &[[0.0, 0.0], [1.0, 0.0], [1.0, h], [0.0, h]], n, 0.0);
}

fn pyramid(g: &mut Gen) {
    let n = g.int("sides", 3, 6);
    let h = g.f("height", 0.3, 1.6);
    let top = if g.chance("truncated", 0.4) { g.f("top_ratio", 0.15, 0.7) } else { 0.0 };
    if top > 0.0 {
        polygonal(&mut g.b, &[[0.0, 0.0], [1.0, 0.0], [top, h], [0.0, h]], n, 0.0);
    } else {
        polygonal(&mut g.b, &[[0.0, 0.0], [1.0, 0.0], [0.0, h]], n, 0.0);
    }
}

fn ellipsoid_(g: &mut Gen) {
    let b = g.f("b", 0.3, 1.0);
    let c = g.f("c", 0.15, 1.0);
    ellipsoid(&mut g.b, [0.0; 3], [1.0, b, c], &IDENTITY);
}

fn frustum_(g: &mut Gen) {
    let top = if g.chance("cone", 0.3) { 0.0 } else { g.f("top_radius", 0.2, 1.0) };
    let h = g.log_f("height", 0.03, 2.0);
    frustum(&mut g.b, 1.0, top, 0.0, h);
}

fn capsule(g: &mut Gen) {
    let r = g.f("radius", 0.15, 0.6);
    let mut p = g.b.profile([0.0, -r]);
    p.arc([0.0, 0.0], r, r, -FRAC_PI_2, 0.0).line_to([r, 1.0]).arc([0.0, 1.0], r, r, 0.0, FRAC_PI_2);
    g.b.revolve(&p);
}

fn stairs(g: &mut Gen) {
    let n = g.int("steps", 2, 7);
    let width = g.f("width", 0.3, 1.0);
    let (mut xs, mut zs) = (vec![0.0], vec![0.0]);
    let (mut runs, mut rises) = (vec![], vec![]);
    for _ in 0..n {
        let run = g.uniform(0.1, 0.3);
        let rise = g.uniform(0.05, 0.25);
        xs.push(xs.last().copied().unwrap_or(0.0) + run);
        zs.push(zs.last().copied().unwrap_or(0.0) + rise);
        runs.push(run);
        rises.push(rise);
    }
    g.record("runs", runs);
    g.record("rises", rises);
    // Column i (from x = xs[i]) is n − i steps high.
    let c = g.b.color;
    let (xs2, zs2) = (xs.clone(), zs.clone());
    cells_where(&mut g.b, xs, vec![0.0, width], zs, |p| {
        let i = xs2.iter().filter(|&&x| x < p[0]).count() - 1;
        (p[2] < zs2[n - i]).then_some(c)
    });
}

fn beam(g: &mut Gen) {
    let kind = g.choose("section", &["l", "t", "u", "i", "h", "hollow"]);
    let w = g.f("width", 0.3, 1.0);
    let h = g.f("height", 0.3, 1.0);
    let t = g.f("wall", 0.05, 0.3) * w.min(h);
    let len = g.f("length", 0.5, 1.6);
    let c = g.b.color;
    let xs = vec![0.0, t, 0.5 * (w - t), 0.5 * (w + t), w - t, w];
    let zs = vec![0.0, t, 0.5 * (h - t), 0.5 * (h + t), h - t, h];
    cells_where(&mut g.b, xs, vec![0.0, len], zs, |p| {
        let (x, z) = (p[0], p[2]);
        let (left, right, bottom, top) = (x < t, x > w - t, z < t, z > h - t);
        let (mid_x, mid_z) = ((x - 0.5 * w).abs() < 0.5 * t, (z - 0.5 * h).abs() < 0.5 * t);
        let solid = match kind {
            "l" => left || bottom,
            "t" => top || mid_x,
            "u" => bottom || left || right,
            "i" => bottom || top || mid_x,
            "h" => left || right || mid_z,
            _ => left || right || bottom || top,
        };
        solid.then_some(c)
    });
}

fn torus_(g: &mut Gen) {
    let r = g.log_f("tube_radius", 0.06, 0.7);
    torus(&mut g.b, 1.0, r);
}

fn cup_(g: &mut Gen) {
    let rb = g.f("bottom_radius", 0.25, 0.6);
    let rt = rb * g.f("flare", 0.8, 1.6);
    let h = g.f("height", 0.3, 1.6);
    let w = g.f("wall", 0.02, 0.06);
    let f = g.f("floor", 0.03, 0.08);
    cup(&mut g.b, rb, rt, h, w, f, WHITE);
}

fn bowl(g: &mut Gen) {
    let t = g.f("wall", 0.03, 0.1);
    let zb = g.f("foot_height", -0.92, -0.5);
    let rim = g.f("rim_latitude", -0.35, 0.45);
    let tb = t;
    let ri = 1.0 - t;
    let foot = zb.asin();
    let inner_end = ((zb + tb) / ri).asin();
    let outer = g.b.color;
    let mut p = g.b.profile([0.0, zb]);
    p.line_to([foot.cos(), zb]).arc([0.0, 0.0], 1.0, 1.0, foot, rim);
    p.color = GREY;
    let mid = 1.0 - 0.5 * t;
    p.arc([mid * rim.cos(), mid * rim.sin()], 0.5 * t, 0.5 * t, rim, rim + PI);
    p.color = WHITE;
    p.arc([0.0, 0.0], ri, ri, rim, inner_end).line_to([0.0, zb + tb]);
    g.b.revolve(&p);
    g.b.color = outer;
}

/// A torus-segment handle in the xz plane whose ends sit in the middle of a wall of radius
/// `r` and thickness `w` around the z axis, turned by `yaw` about z.
#[allow(clippy::too_many_arguments)]
fn handle(g: &mut Gen, r: f64, w: f64, zc: f64, rho: f64, out: f64, tube: f64, yaw: f64) {
    let mark = g.b.mark();
    let cx = r + out - rho;
    let end = ((r - 0.5 * w - cx) / rho).clamp(-1.0, 1.0).acos();
    let n = pieces(2.0 * end * rho, g.b.h).max(4);
    let path: Vec<P3> = (0..=n)
        .map(|i| {
            let a = -end + 2.0 * end * i as f64 / n as f64;
            [cx + rho * a.cos(), 0.0, zc + rho * a.sin()]
        })
        .collect();
    g.b.tube(&path, false, tube);
    place(&mut g.b, mark, &rot_axis([0.0, 0.0, 1.0], yaw), [0.0; 3]);
}

fn mug(g: &mut Gen) {
    let r = g.f("radius", 0.3, 0.6);
    let h = g.f("height", 0.5, 1.4);
    let w = g.f("wall", 0.03, 0.07);
    let rt = r * g.f("flare", 0.9, 1.15);
    cup(&mut g.b, r, rt, h, w, 0.06, WHITE);
    let handles = if g.chance("two_handles", 0.25) { 2 } else { 1 };
    for k in 0..handles {
        let (rho, out, tube, zc) = g.part("handles", |g| {
            let rho = g.f("radius", 0.12, 0.4 * h);
            let out = rho * g.f("reach", 0.5, 1.6);
            let tube = g.f("tube", 0.025, 0.06);
            let zc = g.f("height", 0.1 + rho, (h - 0.05 - rho).max(0.1 + rho));
            (rho, out, tube, zc)
        });
        g.paint();
        // The wall radius at the handle's height (tapered mugs).
        let rz = r + (rt - r) * zc / h;
        handle(g, rz, w, zc, rho, out, tube, PI * k as f64);
    }
}

fn bottle(g: &mut Gen) {
    let rb = g.f("body_radius", 0.25, 0.5);
    let hb = g.f("body_height", 0.4, 1.2);
    let s = g.f("shoulder", 0.08, 0.4);
    let w = g.f("wall", 0.02, 0.04);
    let rn = (rb * g.f("neck_ratio", 0.15, 0.8)).max(w + 0.04);
    let ln = g.f("neck_length", 0.05, 0.45);
    let lip = if g.chance("lip", 0.4) { g.f("lip", 0.01, 0.06) } else { 0.0 };
    let top = hb + s + ln;
    let radius = move |z: f64| -> f64 {
        if z <= hb {
            rb
        } else if z <= hb + s {
            let u = (z - hb) / s;
            let u = u * u * (3.0 - 2.0 * u);
            rb + (rn - rb) * u
        } else {
            let u = ((z - (top - 0.06)) / 0.06).clamp(0.0, 1.0);
            rn + lip * u * u * (3.0 - 2.0 * u)
        }
    };
    let tb = 0.05;
    let outer = g.b.color;
    let mut p = g.b.profile([0.0, 0.0]);
    p.line_to([radius(0.0), 0.0]).curve(|t| [radius(top * t), top * t]);
    p.color = GREY;
    p.line_to([radius(top) - w, top]);
    p.color = DARK;
    p.curve(|t| {
        let z = top - (top - tb) * t;
        [radius(z) - w, z]
    })
    .line_to([0.0, tb]);
    g.b.revolve(&p);
    g.b.color = outer;
}

fn pot(g: &mut Gen) {
    let r = g.f("radius", 0.4, 0.9);
    let h = g.f("height", 0.25, 0.9);
    let w = g.f("wall", 0.03, 0.07);
    let rt = r * g.f("flare", 0.9, 1.1);
    cup(&mut g.b, r, rt, h, w, 0.05, DARK);
    let lid = g.choose("lid", &["on", "raised", "tilted", "none"]);
    if lid != "none" {
        let over = g.f("lid_overhang", 0.0, 0.05);
        let lt = g.f("lid_thickness", 0.025, 0.08);
        let knob = g.f("knob", 0.04, 0.12);
        let lift = if lid == "raised" { g.f("gap", 0.03, 0.2) } else { -0.005 };
        let tilt = if lid == "tilted" { g.f("tilt_deg", 8.0, 60.0).to_radians() } else { 0.0 };
        g.paint();
        let mark = g.b.mark();
        let rl = rt + over;
        frustum(&mut g.b, rl, rl, 0.0, lt);
        ball(&mut g.b, [0.0, 0.0, lt + 0.6 * knob], knob);
        // Hinge on the rim at +x: the far side rises by the tilt.
        let m = rot_axis([0.0, 1.0, 0.0], tilt);
        let hinge = [rl, 0.0, 0.0];
        g.b.map_from(mark, |p| add(mul(&m, sub(p, hinge)), [hinge[0], 0.0, h + lift]));
    }
    if g.chance("handles", 0.5) {
        let hr = g.f("handle_radius", 0.05, 0.12);
        let ht = g.f("handle_tube", 0.015, 0.035);
        g.paint();
        for k in 0..2 {
            let mark = g.b.mark();
            torus(&mut g.b, hr, ht);
            // Upright loop in the xz plane, half inside the wall.
            let rz = r + (rt - r) * 0.7;
            place(&mut g.b, mark, &rot_axis([1.0, 0.0, 0.0], FRAC_PI_2), [rz + hr - 0.5 * w, 0.0, 0.7 * h]);
            place(&mut g.b, mark, &rot_axis([0.0, 0.0, 1.0], PI * k as f64), [0.0; 3]);
        }
    }
}

fn gear(g: &mut Gen) {
    let teeth = g.int("teeth", 6, 32);
    let root = g.f("root_radius", 0.6, 0.9);
    let bore = g.f("bore_radius", 0.08, 0.5 * root);
    let thick = g.log_f("thickness", 0.08, 0.6);
    let a = g.f("root_arc", 0.3, 0.55);
    let b = a + g.f("flank", 0.04, 0.15);
    let c = (b + g.f("tip_arc", 0.08, 0.3)).min(0.96);
    let side = g.paint();
    g.b.color = GREY;
    let top = g.b.color;
    spur_gear(&mut g.b, teeth, root, 1.0, bore, 0.0, thick, [a, b, c], top, side);
    if g.chance("second_gear", 0.35) {
        let s = g.f("second_scale", 0.35, 0.8);
        let teeth2 = g.int("second_teeth", 6, 24);
        let thick2 = g.log_f("second_thickness", 0.08, 0.5);
        let side = g.paint();
        // Its bore matches the first one's so the pair shares one axle hole.
        let root2 = (root * s).max(bore + 0.06);
        let top = g.b.color;
        spur_gear(
            &mut g.b,
            teeth2,
            root2,
            s.max(root2 + 0.04),
            bore,
            thick - 0.01,
            thick2,
            [a, b, c],
            top,
            side,
        );
    }
}

fn table(g: &mut Gen) {
    let round = g.chance("round", 0.3);
    let w = g.f("width", 0.6, 1.2);
    let d = if round { w } else { g.f("depth", 0.4, 1.0) };
    let t = g.f("top_thickness", 0.03, 0.1);
    let ht = g.f("height", 0.4, 1.0);
    let lt = g.f("leg_thickness", 0.03, 0.1);
    let inset = g.f("leg_inset", 0.0, 0.15);
    let splay = if g.chance("splayed", 0.3) { g.f("splay", 0.03, 0.2) } else { 0.0 };
    let square = !round && g.chance("square_legs", 0.6);
    let top_color = g.b.color;
    if round {
        frustum(&mut g.b, 0.5 * w, 0.5 * w, ht - t, ht);
    } else {
        cuboid(&mut g.b, [-0.5 * w, -0.5 * d, ht - t], [0.5 * w, 0.5 * d, ht]);
    }
    let legs: Vec<[f64; 2]> = if round {
        let n = g.int("legs", 3, 4);
        let rr = 0.5 * w - inset - lt;
        (0..n)
            .map(|k| [rr * (TAU * k as f64 / n as f64).cos(), rr * (TAU * k as f64 / n as f64).sin()])
            .collect()
    } else {
        let (x, y) = (0.5 * w - inset - lt, 0.5 * d - inset - lt);
        vec![[x, y], [-x, y], [-x, -y], [x, -y]]
    };
    let leg_color = g.paint();
    let mut feet = vec![];
    for l in &legs {
        let n = (l[0] * l[0] + l[1] * l[1]).sqrt().max(1e-9);
        let foot = [l[0] + splay * l[0] / n, l[1] + splay * l[1] / n, 0.0];
        let top = [l[0], l[1], ht - 0.5 * t];
        if square {
            let len = norm(sub(top, foot));
            oriented_box(&mut g.b, scale(add(top, foot), 0.5), [lt, lt, len], &rot_z_to(sub(top, foot)));
        } else {
            rod(&mut g.b, foot, top, 0.5 * lt);
        }
        feet.push(foot);
    }
    if g.chance("shelf", 0.4) {
        let z = ht * g.f("shelf_height", 0.15, 0.5);
        let st = g.f("shelf_thickness", 0.02, 0.05);
        g.b.color = top_color;
        // Spans the legs at that height.
        let k = z / (ht - 0.5 * t);
        let at: Vec<[f64; 2]> = legs
            .iter()
            .zip(&feet)
            .map(|(l, f)| [f[0] + k * (l[0] - f[0]), f[1] + k * (l[1] - f[1])])
            .collect();
        let rx = at.iter().map(|p| p[0].abs()).fold(0.0, f64::max);
        let ry = at.iter().map(|p| p[1].abs()).fold(0.0, f64::max);
        if round {
            frustum(&mut g.b, rx.max(ry), rx.max(ry), z - st, z);
        } else {
            cuboid(&mut g.b, [-rx, -ry, z - st], [rx, ry, z]);
        }
    }
    g.b.color = leg_color;
}

fn chair(g: &mut Gen) {
    let w = g.f("width", 0.4, 0.7);
    let d = g.f("depth", 0.4, 0.7);
    let hs = g.f("seat_height", 0.35, 0.6);
    let t = g.f("seat_thickness", 0.03, 0.08);
    let lt = g.f("leg_thickness", 0.03, 0.08);
    let hb = g.f("back_height", 0.25, 0.7);
    let back = g.choose("back", &["solid", "vertical_slats", "horizontal_slats"]);
    let seat = g.b.color;
    cuboid(&mut g.b, [0.0, 0.0, hs - t], [w, d, hs]);
    let legc = g.paint();
    for (x, y) in [(0.0, 0.0), (w - lt, 0.0), (0.0, d - lt), (w - lt, d - lt)] {
        cuboid(&mut g.b, [x, y, 0.0], [x + lt, y + lt, hs - 0.5 * t]);
    }
    // Back: two posts at the rear (y = d) and a solid panel or slats between them.
    let top = hs + hb;
    for x in [0.0, w - lt] {
        cuboid(&mut g.b, [x, d - lt, hs - 0.5 * t], [x + lt, d, top]);
    }
    g.b.color = seat;
    match back {
        "solid" => {
            cuboid(&mut g.b, [0.5 * lt, d - 0.8 * lt, hs + 0.1 * hb], [w - 0.5 * lt, d - 0.2 * lt, top])
        }
        "vertical_slats" => {
            let n = g.int("slats", 2, 7);
            let sw = (w - 2.0 * lt) / (2 * n + 1) as f64;
            cuboid(&mut g.b, [0.5 * lt, d - 0.8 * lt, top - 0.15 * hb], [w - 0.5 * lt, d - 0.2 * lt, top]);
            for k in 0..n {
                let x = lt + sw * (2 * k + 1) as f64;
                cuboid(&mut g.b, [x, d - 0.7 * lt, hs - 0.5 * t], [x + sw, d - 0.3 * lt, top - 0.1 * hb]);
            }
        }
        _ => {
            let n = g.int("slats", 2, 6);
            let sh = hb / (2 * n) as f64;
            for k in 0..n {
                let z = top - sh * (2 * k + 1) as f64;
                cuboid(&mut g.b, [0.5 * lt, d - 0.8 * lt, z], [w - 0.5 * lt, d - 0.2 * lt, z + sh]);
            }
        }
    }
    if g.chance("arms", 0.3) {
        let ah = g.f("arm_height", 0.15, 0.3).min(0.9 * hb);
        g.b.color = legc;
        for x in [0.0, w - lt] {
            cuboid(&mut g.b, [x, 0.1 * d, hs + ah - lt], [x + lt, d - 0.5 * lt, hs + ah]);
            cuboid(
                &mut g.b,
                [x + 0.1 * lt, 0.1 * d, hs - 0.5 * t],
                [x + 0.9 * lt, 0.1 * d + lt, hs + ah - 0.5 * lt],
            );
        }
    }
}

fn mushroom(g: &mut Gen) {
    let rs = g.f("stem_radius", 0.06, 0.3);
    let hs = g.f("stem_height", 0.2, 1.0);
    let rc = g.f("cap_radius", rs + 0.15, 1.0);
    let hc = g.f("cap_height", 0.1, 0.6);
    let droop = g.f("droop", 0.0, 0.3).min(0.8 * hs);
    let stem = g.b.color;
    let mut p = g.b.profile([0.0, 0.0]);
    p.line_to([rs * 1.4, 0.0]).line_to([rs, 0.1 * hs]).line_to([rs, hs]);
    p.color = WHITE;
    p.line_to([rc, hs - droop]);
    p.color = g.paint();
    p.arc([0.0, hs - droop], rc, hc + droop, 0.0, FRAC_PI_2);
    g.b.revolve(&p);
    g.b.color = stem;
}

fn ring_stack(g: &mut Gen) {
    let n = g.int("rings", 2, 8);
    let neck = g.f("core_radius", 0.05, 0.2);
    let base = g.f("base_radius", 0.2, 0.6);
    let shrink = g.chance("decreasing", 0.6);
    let mut radii: Vec<f64> = (0..n).map(|_| g.uniform(0.04, 0.3)).collect();
    if shrink {
        radii.sort_by(|a, b| b.total_cmp(a));
    }
    let gap = g.f("gap", 0.01, 0.1);
    g.record("ring_radii", radii.clone());
    let mut colors = vec![];
    for _ in 0..n {
        colors.push(g.paint());
    }
    let mut p = g.b.profile([0.0, 0.0]);
    p.color = DARK;
    p.line_to([base, 0.0]).line_to([base, 0.06]).line_to([neck, 0.06]).line_to([neck, 0.06 + gap]);
    let mut z = 0.06 + gap;
    for (k, rho) in radii.iter().enumerate() {
        p.color = colors[k];
        p.arc([neck, z + rho], *rho, *rho, -FRAC_PI_2, FRAC_PI_2);
        z += 2.0 * rho;
        p.color = DARK;
        p.line_to([neck, z + gap]);
        z += gap;
    }
    p.arc([0.0, z], neck, neck, 0.0, FRAC_PI_2);
    g.b.revolve(&p);
}

fn helix(g: &mut Gen) {
    let turns = g.f("turns", 1.2, 5.0);
    let r = g.f("tube_radius", 0.04, 0.25);
    let pitch = 2.0 * r + g.f("gap", 0.04, 0.8);
    let coil = g.f("coil_radius", 2.0 * r + 0.1, 1.0);
    tube_along(
        &mut g.b,
        |t| {
            let a = TAU * turns * t;
            [coil * a.cos(), coil * a.sin(), pitch * turns * t]
        },
        false,
        r,
    );
    if g.chance("rod", 0.4) {
        let rr = g.f("rod_radius", 0.04, (coil - r - 0.02).max(0.05));
        g.paint();
        rod(&mut g.b, [0.0, 0.0, -0.1], [0.0, 0.0, pitch * turns + 0.1], rr);
    }
}

fn knot(g: &mut Gen) {
    let pq = [(2, 3), (2, 5), (3, 4), (3, 5), (2, 7), (3, 2), (5, 2)];
    let (p, q) = pq[g.below(0, pq.len() - 1)];
    g.record("p", p);
    g.record("q", q);
    let a = g.f("minor", 0.3, 0.6);
    let r = g.f("tube_radius", 0.05, 0.16);
    tube_along(
        &mut g.b,
        |t| {
            let phi = TAU * t;
            let rr = 1.0 + a * (q as f64 * phi).cos();
            [rr * (p as f64 * phi).cos(), rr * (p as f64 * phi).sin(), a * (q as f64 * phi).sin()]
        },
        true,
        r,
    );
}

fn blob(g: &mut Gen) {
    let n = g.int("lumps", 2, 10);
    let lumps: Vec<(P3, f64, f64)> = (0..n)
        .map(|_| {
            g.part("lump", |g| {
                let d = g.direction();
                g.record("direction", d.to_vec());
                let amp = g.f("amplitude", -0.3, 0.6);
                let w = g.log_f("width", 0.02, 0.4);
                (d, amp, w)
            })
        })
        .collect();
    let waves: [f64; 6] = std::array::from_fn(|_| g.uniform(0.0, TAU));
    let wamp = g.f("wave_amplitude", 0.0, 0.1);
    g.record("wave_phases", waves.to_vec());
    let mark = g.b.mark();
    ball(&mut g.b, [0.0; 3], 1.0);
    g.b.map_from(mark, |q| {
        let lump: f64 = lumps.iter().map(|&(c, amp, w)| amp * (-(1.0 - dot(q, c)) / w).exp()).sum();
        let wave = wamp
            * (3.0 * q[0] + waves[0]).sin()
            * (2.0 * q[1] + waves[1]).sin()
            * (2.5 * q[2] + waves[2]).sin()
            + 0.5 * wamp * (5.0 * q[0] - 4.0 * q[2] + waves[3]).sin() * (3.0 * q[1] + waves[4]).cos();
        scale(q, (1.0 + lump + wave).max(0.25))
    });
}

/// One random primitive of size about `s` around the origin (its axis along z), recorded in
/// the current parameter record.
fn primitive(g: &mut Gen, s: f64) {
    let kind = g.choose(
        "kind",
        &["box", "cylinder", "cone", "ball", "ellipsoid", "torus", "cup", "rod", "prism", "pipe"],
    );
    let a = g.f("aspect", 0.3, 1.0);
    let b = &mut g.b;
    match kind {
        "box" => cuboid(b, [-0.5 * s, -0.5 * s * a, -0.5 * s], [0.5 * s, 0.5 * s * a, 0.5 * s]),
        "cylinder" => frustum(b, 0.5 * s * a, 0.5 * s * a, -0.5 * s, 0.5 * s),
        "cone" => frustum(b, 0.5 * s, 0.0, -0.5 * s * a, 0.5 * s * a),
        "ball" => ball(b, [0.0; 3], 0.5 * s),
        "ellipsoid" => ellipsoid(b, [0.0; 3], [0.5 * s, 0.5 * s * a, 0.3 * s], &IDENTITY),
        "torus" => torus(b, 0.5 * s, 0.5 * s * (0.1 + 0.4 * a)),
        "cup" => {
            let (r, h) = (0.5 * s * a.max(0.4), s);
            let mark = b.mark();
            cup(b, r, r * 1.1, h, 0.03, 0.04, DARK);
            place(b, mark, &IDENTITY, [0.0, 0.0, -0.5 * h]);
        }
        "rod" => rod(b, [0.0, 0.0, -0.5 * s], [0.0, 0.0, 0.5 * s], 0.06 + 0.1 * s * a),
        "prism" => {
            let mark = b.mark();
            polygonal(
                b,
                &[[0.0, 0.0], [0.5 * s, 0.0], [0.5 * s, s * a], [0.0, s * a]],
                3 + (a * 4.0) as usize,
                0.0,
            );
            place(b, mark, &IDENTITY, [0.0, 0.0, -0.5 * s * a]);
        }
        _ => {
            let ro = (0.5 * s * a).max(0.08);
            pipe(b, ro - 0.03, ro, s)
        }
    }
}

fn composite(g: &mut Gen) {
    let n = g.int("parts", 2, 6);
    let mut prev: Option<(P3, f64)> = None;
    for _ in 0..n {
        g.part("parts", |g| {
            let s = g.f("size", 0.25, 0.8);
            let axis = g.direction();
            let spin = g.f("spin", 0.0, TAU);
            let c = match prev {
                None => [0.0; 3],
                Some((c0, s0)) => {
                    let d = g.direction();
                    let reach = g.f("reach", 0.25, 0.55);
                    add(c0, scale(d, reach * (s0 + s))).map(round4)
                }
            };
            g.record("axis", axis.to_vec());
            g.record("centre", c.to_vec());
            g.paint();
            let mark = g.b.mark();
            primitive(g, s);
            let m = mat_mul(&rot_z_to(axis), &rot_axis([0.0, 0.0, 1.0], spin));
            place(&mut g.b, mark, &m, c);
            prev = Some((c, s));
        });
    }
}

fn stack(g: &mut Gen) {
    let n = g.int("parts", 2, 6);
    let mut z = 0.0;
    for _ in 0..n {
        g.part("parts", |g| {
            let kind = g.choose("kind", &["box", "cylinder", "prism"]);
            let w = g.f("width", 0.2, 1.0);
            let d = g.f("depth", 0.2, 1.0);
            let h = g.log_f("height", 0.06, 0.5);
            let off = [g.f("offset_x", -0.3, 0.3) * w, g.f("offset_y", -0.3, 0.3) * w];
            let yaw = g.f("yaw", 0.0, TAU);
            let tilt = if g.chance("leaning", 0.3) { g.f("tilt_deg", 5.0, 30.0).to_radians() } else { 0.0 };
            let tilt_dir = g.f("tilt_direction", 0.0, TAU);
            g.paint();
            let mark = g.b.mark();
            match kind {
                "box" => cuboid(&mut g.b, [-0.5 * w, -0.5 * d, -0.5 * h], [0.5 * w, 0.5 * d, 0.5 * h]),
                "cylinder" => frustum(&mut g.b, 0.5 * w, 0.5 * w, -0.5 * h, 0.5 * h),
                _ => polygonal(
                    &mut g.b,
                    &[[0.0, -0.5 * h], [0.5 * w, -0.5 * h], [0.5 * w, 0.5 * h], [0.0, 0.5 * h]],
                    6,
                    0.0,
                ),
            }
            let m = mat_mul(
                &rot_axis([tilt_dir.cos(), tilt_dir.sin(), 0.0], tilt),
                &rot_axis([0.0, 0.0, 1.0], yaw),
            );
            let lift = 0.5 * h * tilt.cos() + 0.5 * w.max(d) * tilt.sin();
            place(&mut g.b, mark, &m, [off[0], off[1], z + lift]);
            z += 2.0 * lift - 0.005;
        });
    }
}

fn molecule(g: &mut Gen) {
    let n = g.int("atoms", 3, 14);
    let rod_r = g.f("bond_radius", 0.02, 0.06);
    let mut atoms: Vec<(P3, f64)> = vec![];
    for i in 0..n {
        g.part("atoms", |g| {
            let r = g.f("radius", 0.08, 0.3);
            let (c, parent) = if i == 0 {
                ([0.0; 3], None)
            } else {
                let p = g.below(0, i - 1);
                let d = g.direction();
                let len = atoms[p].1 + r + g.f("bond", 0.05, 0.5);
                (add(atoms[p].0, scale(d, len)).map(round4), Some(p))
            };
            g.record("centre", c.to_vec());
            if let Some(p) = parent {
                g.record("parent", p);
                g.b.color = GREY;
                rod(&mut g.b, atoms[p].0, c, rod_r);
            }
            g.paint();
            ball(&mut g.b, c, r);
            atoms.push((c, r));
        });
    }
}

fn comb(g: &mut Gen) {
    let n = g.int("prongs", 4, 24);
    let pw = g.f("prong_width", 0.02, 0.07);
    let gap = g.f("gap", 0.03, 0.15);
    let pl = g.f("prong_length", 0.2, 1.0);
    let sh = g.f("spine_height", 0.05, 0.25);
    let t = g.f("thickness", 0.03, 0.15);
    let hl = if g.chance("handle", 0.5) { g.f("handle_length", 0.1, 0.6) } else { 0.0 };
    let double = g.chance("double_sided", 0.3);
    let mut xs = vec![0.0];
    for i in 0..2 * n - 1 {
        xs.push(xs[i] + if i % 2 == 0 { pw } else { gap });
    }
    let end = *xs.last().expect("non-empty");
    if hl > 0.0 {
        xs.push(end + hl);
    }
    let zs = if double { vec![0.0, pl, pl + sh, 2.0 * pl + sh] } else { vec![0.0, pl, pl + sh] };
    let (spine, prong) = (g.b.color, g.paint());
    let xs2 = xs.clone();
    cells_where(&mut g.b, xs, vec![0.0, t], zs, |p| {
        let in_spine = p[2] > pl && p[2] < pl + sh;
        if p[0] > end {
            return in_spine.then_some(DARK);
        }
        let i = xs2.iter().filter(|&&x| x < p[0]).count() - 1;
        if in_spine {
            Some(spine)
        } else {
            (i % 2 == 0).then_some(prong)
        }
    });
}

fn shelf(g: &mut Gen) {
    let w = g.f("width", 0.5, 1.2);
    let h = g.f("height", 0.5, 1.4);
    let d = g.f("depth", 0.2, 0.6);
    let t = g.f("board", 0.02, 0.06);
    let rows = g.int("rows", 1, 5);
    let cols = g.int("columns", 1, 4);
    let back = g.chance("back", 0.7);
    let boards =
        |size: f64, n: usize| -> Vec<f64> { (0..=n).map(|k| k as f64 * (size - t) / n as f64).collect() };
    let (bx, bz) = (boards(w, cols), boards(h, rows));
    let in_board = |v: f64, bs: &[f64]| bs.iter().any(|&b| v > b && v < b + t);
    let xs: Vec<f64> = bx.iter().flat_map(|&b| [b, b + t]).collect();
    let zs: Vec<f64> = bz.iter().flat_map(|&b| [b, b + t]).collect();
    let ys = if back { vec![0.0, d - t, d] } else { vec![0.0, d] };
    let c = g.b.color;
    let (bx2, bz2) = (bx.clone(), bz.clone());
    cells_where(&mut g.b, xs, ys, zs, |p| {
        (in_board(p[0], &bx2) || in_board(p[2], &bz2) || (back && p[1] > d - t)).then_some(c)
    });
    if g.chance("items", 0.5) {
        for i in 0..cols {
            for k in 0..rows {
                let (x0, x1) = (bx[i] + t, bx[i + 1]);
                let (z0, z1) = (bz[k] + t, bz[k + 1]);
                let depth = if back { d - t } else { d };
                let room = (x1 - x0).min(z1 - z0).min(depth);
                if g.unit() < 0.5 {
                    continue;
                }
                g.part("items", |g| {
                    g.record("compartment", vec![i, k]);
                    let kind = g.choose("kind", &["ball", "box"]);
                    let s = room * g.f("size", 0.3, 0.85);
                    let fx = g.f("x", 0.0, 1.0);
                    let fy = g.f("y", 0.0, 1.0);
                    let cx = x0 + 0.5 * s + fx * (x1 - x0 - s);
                    let cy = 0.5 * s + fy * (depth - s);
                    g.paint();
                    if kind == "ball" {
                        ball(&mut g.b, [cx, cy, z0 + 0.5 * s + 0.002], 0.5 * s);
                    } else {
                        cuboid(
                            &mut g.b,
                            [cx - 0.5 * s, cy - 0.5 * s, z0],
                            [cx + 0.5 * s, cy + 0.5 * s, z0 + s],
                        );
                    }
                });
            }
        }
    }
}

fn hollow_box(g: &mut Gen) {
    let size = [g.f("x", 0.5, 1.0), g.f("y", 0.5, 1.0), g.f("z", 0.4, 1.0)];
    let t = g.f("wall", 0.03, 0.08);
    let nh = g.int("holes", 1, 4);
    // A random choice of distinct faces (partial Fisher–Yates).
    let mut faces: Vec<usize> = (0..6).collect();
    for i in 0..nh {
        let j = g.below(i, 5);
        faces.swap(i, j);
    }
    let mut axes: [Vec<f64>; 3] = std::array::from_fn(|a| vec![0.0, t, size[a] - t, size[a]]);
    // (axis, high side, rect lo/hi along axes (a+1)%3 and (a+2)%3)
    let mut holes: Vec<(usize, bool, [f64; 2], [f64; 2])> = vec![];
    for &f in &faces[..nh] {
        let (a, hi) = (f / 2, f % 2 == 1);
        let (u, v) = ((a + 1) % 3, (a + 2) % 3);
        let rect = g.part("hole_list", |g| {
            g.record("face", f);
            let mut rect = [[0.0; 2]; 2];
            for (k, ax) in [u, v].into_iter().enumerate() {
                let inner = size[ax] - 2.0 * t;
                let wdt = inner * g.f(if k == 0 { "size_u" } else { "size_v" }, 0.1, 0.7);
                let free = (inner - wdt - 0.04).max(0.0);
                let c = t + 0.02 + 0.5 * wdt + free * g.f(if k == 0 { "pos_u" } else { "pos_v" }, 0.0, 1.0);
                rect[k] = [c - 0.5 * wdt, c + 0.5 * wdt];
            }
            rect
        });
        axes[u].extend(rect[0]);
        axes[v].extend(rect[1]);
        holes.push((a, hi, rect[0], rect[1]));
    }
    let c = g.b.color;
    let [xs, ys, zs] = axes;
    cells_where(&mut g.b, xs, ys, zs, |p| {
        let wall = (0..3).any(|a| p[a] < t || p[a] > size[a] - t);
        let hole = holes.iter().any(|&(a, hi, ru, rv)| {
            let (u, v) = ((a + 1) % 3, (a + 2) % 3);
            let layer = if hi { p[a] > size[a] - t } else { p[a] < t };
            layer && p[u] > ru[0] && p[u] < ru[1] && p[v] > rv[0] && p[v] < rv[1]
        });
        (wall && !hole).then_some(c)
    });
    if g.chance("ball_inside", 0.6) {
        let inner = (0..3).map(|a| size[a] - 2.0 * t).fold(f64::INFINITY, f64::min);
        let r = 0.5 * inner * g.f("ball_size", 0.3, 0.9);
        let fx = g.f("ball_x", 0.0, 1.0);
        let fy = g.f("ball_y", 0.0, 1.0);
        let cx = t + r + 0.01 + fx * (size[0] - 2.0 * t - 2.0 * r - 0.02).max(0.0);
        let cy = t + r + 0.01 + fy * (size[1] - 2.0 * t - 2.0 * r - 0.02).max(0.0);
        g.paint();
        ball(&mut g.b, [cx, cy, t + r + 0.01], r);
    }
}

fn cage(g: &mut Gen) {
    let size = [g.f("x", 0.5, 1.0), g.f("y", 0.5, 1.0), g.f("z", 0.5, 1.0)];
    let n = [g.int("gaps_x", 1, 4), g.int("gaps_y", 1, 4), g.int("gaps_z", 1, 4)];
    let bt = g.f("bar", 0.02, 0.07);
    let bars: Vec<Vec<f64>> =
        (0..3).map(|a| (0..=n[a]).map(|k| k as f64 * (size[a] - bt) / n[a] as f64).collect()).collect();
    let axes: Vec<Vec<f64>> = bars.iter().map(|bs| bs.iter().flat_map(|&b| [b, b + bt]).collect()).collect();
    let c = g.b.color;
    let bars2 = bars.clone();
    cells_where(&mut g.b, axes[0].clone(), axes[1].clone(), axes[2].clone(), |p| {
        let on = (0..3).filter(|&a| bars2[a].iter().any(|&b| p[a] > b && p[a] < b + bt)).count();
        (on >= 2).then_some(c)
    });
    if g.chance("ball_inside", 0.5) {
        let r = 0.5 * size.iter().fold(f64::INFINITY, |m, &s| m.min(s)) * g.f("ball_size", 0.2, 0.8);
        g.paint();
        ball(&mut g.b, [0.5 * size[0], 0.5 * size[1], 0.5 * size[2]], r);
    }
}

/// Spherical shell of outer radius `r`, wall `t`, open above latitude `cut` (radians).
fn open_shell(g: &mut Gen, r: f64, t: f64, cut: f64) {
    let ri = r - t;
    let outer = g.b.color;
    let mut p = g.b.profile([0.0, -r]);
    p.arc([0.0, 0.0], r, r, -FRAC_PI_2, cut);
    p.color = WHITE;
    p.line_to([ri * cut.cos(), ri * cut.sin()]);
    p.color = DARK;
    p.arc([0.0, 0.0], ri, ri, cut, -FRAC_PI_2);
    g.b.revolve(&p);
    g.b.color = outer;
}

fn nested(g: &mut Gen) {
    match g.choose("kind", &["ball_in_shell", "cups", "shell_in_shell"]) {
        "ball_in_shell" => {
            let t = g.f("wall", 0.04, 0.12);
            let cut = g.f("opening_latitude_deg", -10.0, 75.0).to_radians();
            let rb = (1.0 - t) * g.f("ball_size", 0.2, 0.6);
            open_shell(g, 1.0, t, cut);
            g.paint();
            ball(&mut g.b, [0.0, 0.0, -(1.0 - t) + rb + 0.02], rb);
        }
        "cups" => {
            let n = g.int("cups", 2, 4);
            let h = g.f("height", 0.4, 1.2);
            let flare = g.f("flare", 1.0, 1.5);
            let w = g.f("wall", 0.02, 0.05);
            let mut rb = 0.5;
            let mut z = 0.0;
            for _ in 0..n {
                g.paint();
                let mark = g.b.mark();
                cup(&mut g.b, rb, rb * flare, h, w, 0.04, DARK);
                place(&mut g.b, mark, &IDENTITY, [0.0, 0.0, z]);
                // The next cup stands on this one's floor.
                z += 0.045;
                rb = rb - w - 0.03;
                if rb < 0.08 {
                    break;
                }
            }
        }
        _ => {
            let t = g.f("wall", 0.04, 0.1);
            let cut = g.f("opening_latitude_deg", 0.0, 70.0).to_radians();
            let s = g.f("inner_size", 0.4, 0.75);
            let turn = g.f("inner_turn_deg", 30.0, 180.0).to_radians();
            open_shell(g, 1.0, t, cut);
            g.paint();
            let mark = g.b.mark();
            open_shell(g, s, t, cut);
            place(&mut g.b, mark, &rot_axis([1.0, 0.0, 0.0], turn), [0.0; 3]);
        }
    }
}

fn well_ball(g: &mut Gen) {
    let k = g.log_int("wells", 2, 24);
    let ro = g.f("outer_radius", 0.07, 0.18);
    let w = g.f("wall", 0.02, 0.05);
    let ri = ro - w;
    let len = g.f("length", 0.12, 0.6);
    let jitter = g.f("length_jitter", 0.0, 0.5);
    let min_sep = 2.0 * (1.15 * ro).asin() + 0.04;
    let mut dirs: Vec<P3> = vec![];
    let mut lens: Vec<f64> = vec![];
    for _ in 0..400 {
        if dirs.len() == k {
            break;
        }
        let d = g.direction();
        let l = len * (1.0 - jitter * g.unit());
        if dirs.iter().all(|&e| dot(e, d).clamp(-1.0, 1.0).acos() > min_sep) {
            dirs.push(d);
            lens.push(round4(l));
        }
    }
    g.record("placed", dirs.len());
    g.record("directions", dirs.iter().map(|d| d.to_vec()).collect::<Vec<_>>());
    g.record("lengths", lens.clone());
    ball(&mut g.b, [0.0; 3], 1.0);
    let z0 = (1.0 - ro * ro).sqrt() - 0.05;
    let (outside, inside) = (g.paint(), g.paint());
    for (d, l) in dirs.iter().zip(&lens) {
        g.b.color = outside;
        let mark = g.b.mark();
        let zf = 1.01;
        let top = 1.0 + l;
        let mut p = g.b.profile([0.0, z0]);
        p.line_to([ro, z0]).line_to([ro, top]).line_to([ri, top]);
        p.color = inside;
        p.line_to([ri, zf]).line_to([0.0, zf]);
        g.b.revolve(&p);
        place(&mut g.b, mark, &rot_z_to(*d), [0.0; 3]);
    }
}

fn pocket_block(g: &mut Gen) {
    let w = g.f("width", 0.5, 1.0);
    let d = g.f("depth", 0.5, 1.0);
    let h = g.f("height", 0.3, 0.9);
    let nx = g.int("pockets_x", 1, 6);
    let ny = g.int("pockets_y", 1, 6);
    let pf = g.f("pocket_fraction", 0.4, 0.85);
    let both = g.chance("both_sides", 0.3);
    // Pocket depth relative to the pocket's narrower side, as far as the block allows.
    let aspect = g.log_f("pocket_aspect", 0.15, 2.5);
    let m = 0.05;
    let (px, py) = ((w - 2.0 * m) / nx as f64, (d - 2.0 * m) / ny as f64);
    let pd = (aspect * pf * px.min(py)).min(if both { 0.5 * h - 0.03 } else { h - 0.05 });
    let rx: Vec<[f64; 2]> = (0..nx)
        .map(|i| {
            let c = m + (i as f64 + 0.5) * px;
            [c - 0.5 * pf * px, c + 0.5 * pf * px]
        })
        .collect();
    let ry: Vec<[f64; 2]> = (0..ny)
        .map(|j| {
            let c = m + (j as f64 + 0.5) * py;
            [c - 0.5 * pf * py, c + 0.5 * pf * py]
        })
        .collect();
    let mut xs = vec![0.0, w];
    xs.extend(rx.iter().flatten());
    let mut ys = vec![0.0, d];
    ys.extend(ry.iter().flatten());
    let mut zs = vec![0.0, h - pd, h];
    if both {
        zs.push(pd);
    }
    let (outer, inner) = (g.b.color, g.paint());
    cells_where(&mut g.b, xs, ys, zs, |p| {
        let in_rect =
            rx.iter().any(|r| p[0] > r[0] && p[0] < r[1]) && ry.iter().any(|r| p[1] > r[0] && p[1] < r[1]);
        let pocket = in_rect && (p[2] > h - pd || (both && p[2] < pd));
        (!pocket).then_some(if p[2] > h - pd || p[2] < pd { inner } else { outer })
    });
}

fn tube_bundle(g: &mut Gen) {
    let n = g.int("pipes", 1, 10);
    let parallel = g.chance("parallel", 0.3);
    let axis0 = g.direction();
    g.record("main_axis", axis0.to_vec());
    for _ in 0..n {
        g.part("pipes", |g| {
            let ro = g.f("outer_radius", 0.06, 0.25);
            let wall = g.f("wall", 0.015, 0.05).min(ro - 0.03);
            // Length relative to the bore's diameter.
            let len = (2.0 * (ro - wall) * g.log_f("aspect", 0.8, 6.0)).clamp(0.3, 2.0);
            let axis = if parallel { axis0 } else { g.direction() };
            let c = [g.f("x", -0.5, 0.5), g.f("y", -0.5, 0.5), g.f("z", -0.5, 0.5)];
            g.record("axis", axis.to_vec());
            g.paint();
            let mark = g.b.mark();
            pipe(&mut g.b, ro - wall, ro, len);
            place(&mut g.b, mark, &rot_z_to(axis), c);
        });
    }
}

fn spiky_ball(g: &mut Gen) {
    let k = g.int("spikes", 6, 48);
    let rb = g.f("spike_radius", 0.04, 0.2);
    let len = g.f("length", 0.3, 1.2);
    let jitter = g.f("length_jitter", 0.0, 0.6);
    let cones = g.chance("cones", 0.6);
    let spikes: Vec<(P3, f64)> = (0..k)
        .map(|_| {
            let d = g.direction();
            let l = round4(len * (1.0 - jitter * g.unit()));
            (d, l)
        })
        .collect();
    g.record("directions", spikes.iter().map(|s| s.0.to_vec()).collect::<Vec<_>>());
    g.record("lengths", spikes.iter().map(|s| s.1).collect::<Vec<_>>());
    ball(&mut g.b, [0.0; 3], 1.0);
    g.paint();
    let z0 = (1.0 - rb * rb).sqrt() - 0.03;
    for (d, l) in spikes {
        let mark = g.b.mark();
        frustum(&mut g.b, rb, if cones { 0.0 } else { rb }, z0, 1.0 + l);
        place(&mut g.b, mark, &rot_z_to(d), [0.0; 3]);
    }
}
