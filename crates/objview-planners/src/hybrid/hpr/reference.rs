//! The first implementation of [`super::hull_faces`] (HashMap edges, one `Vec` per outside
//! set), kept for the tests only: the faster hull must return exactly the same faces (same
//! order) or the same error on every input, since the step's HPR gains, hence the chosen views,
//! must not change.

use std::collections::HashMap;

use super::{cross, dot, norm, sub, HullError};

#[derive(Debug, Clone)]
struct Face {
    v: [usize; 3],
    n: [f64; 3],
    d: f64,
    outside: Vec<usize>,
    alive: bool,
}

/// The face through `v` (counter-clockwise seen from outside): unit normal and offset, or
/// `None` when its area is (numerically) zero.
fn make_face(p: &[[f64; 3]], v: [usize; 3]) -> Option<Face> {
    let n = cross(sub(p[v[1]], p[v[0]]), sub(p[v[2]], p[v[0]]));
    let l = norm(n);
    if l.is_nan() || l <= 0.0 || !l.is_finite() {
        return None;
    }
    let n = n.map(|x| x / l);
    Some(Face { v, n, d: dot(n, p[v[0]]), outside: Vec::new(), alive: true })
}

fn dist(f: &Face, q: [f64; 3]) -> f64 {
    dot(f.n, q) - f.d
}

/// The indices of the vertices of the convex hull of `points`, ascending. Points closer than a
/// relative tolerance (1e-11 of the coordinate scale) to the hull's surface are not vertices.
pub fn hull_vertices(points: &[[f64; 3]]) -> Result<Vec<usize>, HullError> {
    let mut verts: Vec<usize> = hull_faces(points)?.into_iter().flatten().collect();
    verts.sort_unstable();
    verts.dedup();
    Ok(verts)
}

/// The faces of the convex hull of `points` (vertex indices, counter-clockwise seen from
/// outside); see [`hull_vertices`].
pub fn hull_faces(points: &[[f64; 3]]) -> Result<Vec<[usize; 3]>, HullError> {
    let n = points.len();
    if points.iter().any(|p| p.iter().any(|x| !x.is_finite())) {
        return Err(HullError::NonFinite);
    }
    if n < 4 {
        return Err(HullError::Degenerate);
    }
    let scale = points.iter().flat_map(|p| p.iter()).fold(0.0f64, |m, x| m.max(x.abs())).max(1e-300);
    let eps = 1e-11 * scale;
    // Initial simplex, made of hull vertices only (ties → the lexicographically largest
    // point, which is a vertex of the tied face or edge): the lexicographic minimum, the point
    // farthest from it, the point farthest from their line, the point farthest from their plane.
    let lex = |a: &[f64; 3], b: &[f64; 3]| {
        a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])).then(a[2].total_cmp(&b[2]))
    };
    let farthest = |key: &dyn Fn(&[f64; 3]) -> f64| -> (usize, f64) {
        let mut best = (0usize, f64::NEG_INFINITY);
        for (i, p) in points.iter().enumerate() {
            let d = key(p);
            if d > best.1 || (d == best.1 && lex(p, &points[best.0]).is_gt()) {
                best = (i, d);
            }
        }
        best
    };
    let i0 = (0..n).min_by(|&a, &b| lex(&points[a], &points[b])).expect("n >= 4");
    let (i1, best) = farthest(&|p| norm(sub(*p, points[i0])));
    if best <= eps {
        return Err(HullError::Degenerate);
    }
    let u = sub(points[i1], points[i0]).map(|x| x / best);
    let (i2, best) = farthest(&|p| norm(cross(sub(*p, points[i0]), u)));
    if best <= eps {
        return Err(HullError::Degenerate);
    }
    let base = make_face(points, [i0, i1, i2]).ok_or(HullError::Degenerate)?;
    let (i3, best) = farthest(&|p| dist(&base, *p).abs());
    if best <= eps {
        return Err(HullError::Degenerate);
    }
    // Orient the tetrahedron's faces outwards (i3 below the base after the flip, if needed).
    let (a, b, c, d) = if dist(&base, points[i3]) > 0.0 { (i0, i2, i1, i3) } else { (i0, i1, i2, i3) };
    let mut faces: Vec<Face> = Vec::new();
    for v in [[a, b, c], [a, d, b], [b, d, c], [c, d, a]] {
        faces.push(make_face(points, v).ok_or(HullError::Degenerate)?);
    }
    // Directed edge (u, v) → the face that has it counter-clockwise.
    let mut edges: HashMap<(usize, usize), usize> = HashMap::new();
    let add_edges = |edges: &mut HashMap<(usize, usize), usize>, f: usize, v: [usize; 3]| -> bool {
        (0..3).all(|k| edges.insert((v[k], v[(k + 1) % 3]), f).is_none())
    };
    for (f, face) in faces.iter().enumerate() {
        if !add_edges(&mut edges, f, face.v) {
            return Err(HullError::Inconsistent);
        }
    }
    let simplex = [a, b, c, d];
    for (i, p) in points.iter().enumerate() {
        if simplex.contains(&i) {
            continue;
        }
        if let Some(f) = faces.iter().position(|f| dist(f, *p) > eps) {
            faces[f].outside.push(i);
        }
    }
    let mut stack: Vec<usize> = (0..faces.len()).collect();
    while let Some(f) = stack.pop() {
        if !faces[f].alive || faces[f].outside.is_empty() {
            continue;
        }
        // The outside point farthest from the face (lowest index on ties): a hull vertex.
        let apex = *faces[f]
            .outside
            .iter()
            .max_by(|&&x, &&y| {
                dist(&faces[f], points[x]).total_cmp(&dist(&faces[f], points[y])).then(y.cmp(&x))
            })
            .expect("non-empty");
        let q = points[apex];
        // The faces that see the apex (connected to f), by breadth-first search.
        let mut visible = vec![f];
        let mut seen: HashMap<usize, bool> = HashMap::from([(f, true)]);
        let mut horizon: Vec<(usize, usize)> = Vec::new();
        let mut at = 0;
        while at < visible.len() {
            let g = visible[at];
            at += 1;
            let v = faces[g].v;
            for k in 0..3 {
                let (s, t) = (v[k], v[(k + 1) % 3]);
                let h = *edges.get(&(t, s)).ok_or(HullError::Inconsistent)?;
                let sees = *seen.entry(h).or_insert_with(|| dist(&faces[h], q) > eps);
                if sees {
                    if !visible.contains(&h) {
                        visible.push(h);
                    }
                } else {
                    horizon.push((s, t));
                }
            }
        }
        let mut orphans: Vec<usize> = Vec::new();
        for &g in &visible {
            faces[g].alive = false;
            let v = faces[g].v;
            for k in 0..3 {
                edges.remove(&(v[k], v[(k + 1) % 3]));
            }
            orphans.extend(std::mem::take(&mut faces[g].outside).into_iter().filter(|&i| i != apex));
        }
        let first_new = faces.len();
        for &(s, t) in &horizon {
            let face = make_face(points, [s, t, apex]).ok_or(HullError::Inconsistent)?;
            let id = faces.len();
            if !add_edges(&mut edges, id, face.v) {
                return Err(HullError::Inconsistent);
            }
            faces.push(face);
        }
        for i in orphans {
            if let Some(g) = (first_new..faces.len()).find(|&g| dist(&faces[g], points[i]) > eps) {
                faces[g].outside.push(i);
            }
        }
        stack.extend(first_new..faces.len());
    }
    // A closed triangulated sphere: every directed edge has its twin, and V − E + F = 2.
    let alive: Vec<&Face> = faces.iter().filter(|f| f.alive).collect();
    if edges.len() != 3 * alive.len() || edges.keys().any(|&(s, t)| !edges.contains_key(&(t, s))) {
        return Err(HullError::Inconsistent);
    }
    let mut verts: Vec<usize> = alive.iter().flat_map(|f| f.v).collect();
    verts.sort_unstable();
    verts.dedup();
    if verts.len() as i64 - (edges.len() / 2) as i64 + alive.len() as i64 != 2 {
        return Err(HullError::Inconsistent);
    }
    Ok(alive.iter().map(|f| f.v).collect())
}

/// The first [`super::hpr_visible`], on the reference hull.
pub fn hpr_visible(points: &[[f64; 3]], camera: [f64; 3]) -> Vec<bool> {
    let n = points.len();
    if n <= 4 {
        return vec![true; n];
    }
    let r = super::hpr_radius(points, camera);
    let mut flipped: Vec<[f64; 3]> = points
        .iter()
        .map(|p| {
            let q = sub(*p, camera);
            let l = norm(q);
            if l > 0.0 {
                let s = 1.0 + 2.0 * (r - l) / l;
                q.map(|x| x * s)
            } else {
                q
            }
        })
        .collect();
    flipped.push([0.0; 3]); // the camera
    match hull_vertices(&flipped) {
        Ok(verts) => {
            let mut vis = vec![false; n];
            for v in verts.into_iter().filter(|&v| v < n) {
                vis[v] = true;
            }
            for (i, p) in points.iter().enumerate() {
                if *p == camera {
                    vis[i] = true;
                }
            }
            vis
        }
        Err(_) => vec![true; n],
    }
}

/// The first [`super::hpr_count`].
pub fn hpr_count(points: &[[f64; 3]], camera: [f64; 3]) -> usize {
    hpr_visible(points, camera).into_iter().filter(|&v| v).count()
}
