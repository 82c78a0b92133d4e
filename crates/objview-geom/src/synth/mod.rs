//! The built-in object pool: about thirty deterministic procedural meshes that span the kinds
//! of self-occlusion view planning has to deal with — convex solids, tori, open containers
//! (cups, bowls, a vase with a narrow neck), internal surfaces seen only through a hole,
//! nested shells, sealed cavities that are never observable, thin plates, deep slots, gears,
//! tubes, assemblies with overhangs and many thin prongs.
//!
//! It is the default pool of the benchmark's main job, of tests and of benchmarks, so it has to
//! be available without downloading anything and be bit-for-bit reproducible. Every object has
//! a stable kebab-case name, a one-line description, and a generator whose tessellation is set
//! by a [`Detail`]; [`build_with_triangles`] picks the detail that gives a requested triangle
//! count (for scaling benchmarks up to millions of triangles). Meshes come out normalized like
//! SPEC §1 `unit`: the vertex bounding-box centre at the origin and the farthest vertex at
//! distance exactly 1. All objects carry per-face colours for RGB rendering.
//!
//! Objects are modelled as solids: every catalog entry is a closed, consistently outward-oriented
//! triangle surface (each edge shared by exactly two triangles, in opposite directions); surfaces
//! bounding a cavity face into the cavity. Thin things have real thickness.

mod builder;
pub mod random;
mod shapes;

use crate::{GeomError, Mesh};
use builder::Builder;
use std::path::{Path, PathBuf};

/// Tessellation level of a procedural object: the number of edge segments a full circle of
/// radius 1 (in the object's unit-sized construction frame) is divided into. Every generator
/// aims at edge length `2π / segments`, so the triangle count grows like `segments²`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Detail {
    /// Edge segments per full circle of radius 1 (at least [`Detail::MIN_SEGMENTS`] in effect).
    pub segments: u32,
}

impl Detail {
    /// The pool's default: a few thousand to about twenty thousand triangles per object.
    pub const DEFAULT: Detail = Detail { segments: 96 };
    /// The coarsest detail generators accept; lower values are raised to it.
    pub const MIN_SEGMENTS: u32 = 8;

    /// Target edge length in the construction frame.
    pub fn edge_length(self) -> f64 {
        std::f64::consts::TAU / self.segments.max(Self::MIN_SEGMENTS) as f64
    }
}

impl Default for Detail {
    fn default() -> Self {
        Detail::DEFAULT
    }
}

/// One entry of the built-in pool.
#[derive(Debug, Clone, Copy)]
pub struct SynthObject {
    /// Stable kebab-case name (also the file stem written by [`write_pool`]).
    pub name: &'static str,
    /// One line on what the object is and which visibility challenge it poses.
    pub description: &'static str,
    /// Every edge is shared by exactly two triangles with opposite directions (a watertight,
    /// consistently oriented surface, possibly of several components).
    pub closed: bool,
    /// Some closed components interpenetrate (an assembly that would need a boolean union),
    /// so a few of its triangles lie inside the solid and are never observable.
    pub overlapping: bool,
    generate: fn(&mut Builder),
    /// Tessellation multiplier for objects made of small features (prongs, thin slabs), so that
    /// every object gets a comparable triangle budget at the same [`Detail`].
    fineness: f64,
}

impl SynthObject {
    /// Builds the object at `detail`, normalized to the unit ball.
    pub fn build(&self, detail: Detail) -> Mesh {
        let mut b = Builder::new(detail.edge_length() / self.fineness);
        (self.generate)(&mut b);
        b.finish()
    }

    /// Builds the object with a tessellation chosen so that its triangle count is close to
    /// `target` (within ±20% for targets from a few thousand triangles up; small targets are
    /// bounded below by the coarsest detail).
    pub fn build_with_triangles(&self, target: usize) -> Mesh {
        let target = target.max(1) as f64;
        let mut segments = 32u32;
        let mut mesh = self.build(Detail { segments });
        // The count grows like segments²: a few secant steps on sqrt(count) converge fast.
        for _ in 0..6 {
            let ratio = target / mesh.num_triangles() as f64;
            if (ratio - 1.0).abs() < 0.05 {
                break;
            }
            let next =
                (segments as f64 * ratio.sqrt()).round().clamp(Detail::MIN_SEGMENTS as f64, 1e6) as u32;
            if next == segments {
                break;
            }
            segments = next;
            mesh = self.build(Detail { segments });
        }
        mesh
    }
}

impl SynthObject {
    fn finer(self, fineness: f64) -> Self {
        SynthObject { fineness, ..self }
    }
}

macro_rules! object {
    ($name:literal, $gen:path, $desc:literal) => {
        SynthObject {
            name: $name,
            description: $desc,
            closed: true,
            overlapping: false,
            generate: $gen,
            fineness: 1.0,
        }
    };
    ($name:literal, $gen:path, $desc:literal, overlapping) => {
        SynthObject {
            name: $name,
            description: $desc,
            closed: true,
            overlapping: true,
            generate: $gen,
            fineness: 1.0,
        }
    };
}

/// The built-in pool, in a fixed order.
pub fn catalog() -> Vec<SynthObject> {
    use shapes::*;
    vec![
        object!("sphere", sphere, "UV sphere: convex, fully visible from a handful of views"),
        object!("cube", cube, "Cube: convex with sharp edges and flat faces"),
        object!("cylinder", cylinder, "Closed cylinder, height 4/3 of its diameter: convex"),
        object!("cone", cone, "Closed cone standing on its base: convex with an apex"),
        object!("octahedron", octahedron, "Regular octahedron: convex, eight flat faces"),
        object!("ellipsoid", ellipsoid, "Triaxial ellipsoid (1 : 0.65 : 0.45) lying flat: convex, flattened"),
        object!("torus", torus, "Ring torus, tube/centre radius 0.35/0.65: a hole and an inner rim"),
        object!("thin-torus", thin_torus, "Thin ring torus, tube/centre radius 0.12/0.88: a large hole"),
        object!("cup", cup, "Tapered cup, open top, 0.04 wall: its inside is seen only from above"),
        object!(
            "mug",
            mug,
            "Straight mug with a torus-segment handle whose ends sit inside the wall",
            overlapping
        ),
        object!("bowl", bowl, "Spherical bowl with a flat foot and a thick rounded rim"),
        object!("vase", vase, "Vase with a bulb, a narrow neck and a flared lip: inside nearly unobservable"),
        object!("pipe", pipe, "Thick-walled open tube lying along x: inside visible only near the axis"),
        object!(
            "box-with-hole",
            box_with_hole,
            "Hollow box with a small square hole in its top: internal surfaces seen only through it"
        ),
        object!(
            "sealed-box",
            sealed_box,
            "Hollow box with a sealed cavity: the inner surface is never observable"
        ),
        object!(
            "hollow-sphere",
            hollow_sphere,
            "Sphere with a sealed concentric spherical cavity (radius 0.75): inside never observable"
        ),
        object!(
            "ball-in-shell",
            ball_in_shell,
            "Ball resting inside a thick spherical shell cut open at the top: nested surfaces"
        ),
        object!(
            "ball-in-cage",
            ball_in_cage,
            "Ball inside a cubic cage of square bars: nested, seen through windows"
        ),
        object!("thin-plate", thin_plate, "Thin slab 1.6 x 1.0 x 0.03 lying flat: edges nearly invisible")
            .finer(1.3),
        object!("l-shape", l_shape, "Upright extruded L: a concave inner corner").finer(1.3),
        object!("u-shape", u_shape, "Extruded U with a deep 0.3-wide channel"),
        object!(
            "l-bracket",
            l_bracket,
            "Cube with one corner pocket cut out: three walls of an inside corner"
        ),
        object!("gear", gear, "Spur gear with 14 trapezoidal teeth and a bore: many small concave gaps"),
        object!(
            "slot-block",
            slot_block,
            "Block with a blind slit 0.04 wide and 0.65 deep, open only at the top"
        ),
        object!("chair", chair, "Chair of boxes: four legs, a seat, a slatted back").finer(1.3),
        object!("table", table, "Table whose top overhangs four inset legs: underside seen only from below")
            .finer(1.3),
        object!("comb", comb, "Comb with twelve thin prongs separated by narrow gaps, and a handle")
            .finer(1.7),
        object!("mushroom", mushroom, "Mushroom: flared stem under an overhanging, drooping cap"),
        object!(
            "ring-tower",
            ring_tower,
            "Stacking toy: five rings of decreasing size on a core, deep grooves"
        ),
        object!("helix", helix, "Three turns of a tube on a helix: turns occlude each other"),
        object!(
            "trefoil-knot",
            trefoil_knot,
            "Tube around a trefoil knot: strands pass in front of each other"
        ),
        object!("blob", blob, "Lumpy star-shaped blob with a head, ears, a tail and a dent (bunny-like)"),
        object!(
            "washer",
            capsule_ring,
            "Thick washer with rounded edges standing on its rim: a hole seen edge-on"
        ),
    ]
}

/// The catalog entry called `name`.
pub fn find(name: &str) -> Option<SynthObject> {
    catalog().into_iter().find(|o| o.name == name)
}

/// Builds the catalog object `name` at `detail`; `None` for an unknown name.
pub fn build(name: &str, detail: Detail) -> Option<Mesh> {
    find(name).map(|o| o.build(detail))
}

/// Builds the catalog object `name` with about `target_triangles` triangles (see
/// [`SynthObject::build_with_triangles`]).
///
/// # Panics
/// If `name` is not in the [`catalog`] (use [`find`] first for user input).
pub fn build_with_triangles(name: &str, target_triangles: usize) -> Mesh {
    find(name)
        .unwrap_or_else(|| panic!("no built-in object named {name:?}"))
        .build_with_triangles(target_triangles)
}

/// Writes every catalog object at the default detail as `<dir>/<name>.obj` (plus its
/// `<name>.mtl` with the face colours), creating `dir` if needed. Returns the OBJ paths in
/// catalog order. Output is deterministic: re-running overwrites the files with identical bytes.
pub fn write_pool(dir: &Path) -> Result<Vec<PathBuf>, GeomError> {
    std::fs::create_dir_all(dir).map_err(|e| GeomError::io(dir, e))?;
    catalog()
        .iter()
        .map(|o| {
            let path = dir.join(format!("{}.obj", o.name));
            crate::write::write_obj(&path, &o.build(Detail::DEFAULT))?;
            Ok(path)
        })
        .collect()
}

#[cfg(test)]
mod tests;
