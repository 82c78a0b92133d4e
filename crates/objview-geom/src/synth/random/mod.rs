//! Random procedural objects: a seeded training pool of any size (`objview objects synth
//! --count N --seed S`), drawn from parametric [`families`] with random parameters — the
//! built-in shapes with their dimensions drawn instead of fixed, and assemblies of several
//! parts (handles, legs, shelves, lids, bottles with narrow necks, containers with apertures,
//! nested parts, thin plates, holes, tori, gears, stacked and leaning parts, wells) — under a
//! random non-uniform scale and orientation, so that the pool spans easy convex solids
//! (d_plan of a few views) up to objects that need tens of views and saturate slowly.
//!
//! Determinism: object `index` of pool `seed` depends on `(seed, index)` only, through its own
//! ChaCha8 stream seeded with [`object_seed`], so the same settings give byte-identical files
//! and the first k objects of a pool of N > k are the pool of k (pools can grow). Parameters
//! are rounded to 4 decimals when drawn (the rounded value is the one used), and every object
//! records its family and parameters in the manifest `synth.json` written next to the meshes.
//!
//! Meshes are solids like the built-ins: every part is a closed, consistently outward-oriented
//! surface (assemblies are unions of closed components that may interpenetrate), normalized to
//! the unit ball (vertex bounding-box centre at the origin, farthest vertex at distance 1), with
//! per-face colours and [`MIN_TRIANGLES`]..=[`MAX_TRIANGLES`] triangles (the tessellation is
//! coarsened or refined until the count fits; parameters do not depend on it).

mod families;
mod parts;

use super::builder::{Builder, Rgb, P3};
use super::Detail;
use crate::hash::splitmix64;
use crate::{GeomError, Mesh};
use rand_chacha::rand_core::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use serde_json::{Map, Value};
use std::path::{Path, PathBuf};

pub use families::families;

/// Version of the random pool's generators. It is bumped whenever a change alters the object
/// drawn for some `(seed, index)`; it is recorded in `synth.json`.
pub const POOL_VERSION: u32 = 1;

/// File name of the manifest written by [`write_random_pool`].
pub const MANIFEST: &str = "synth.json";

/// Fewest triangles of a random object (the tessellation is refined below it).
pub const MIN_TRIANGLES: usize = 2_000;
/// Most triangles of a random object (the tessellation is coarsened above it).
pub const MAX_TRIANGLES: usize = 30_000;

/// One parametric family of random objects.
#[derive(Debug, Clone, Copy)]
pub struct Family {
    /// Stable kebab-case name (part of the object names).
    pub name: &'static str,
    /// One line on what the family draws and which visibility challenge it poses.
    pub description: &'static str,
    /// Relative frequency in the pool.
    pub weight: u32,
    pub(crate) generate: fn(&mut Gen),
}

/// One object of a random pool.
#[derive(Debug, Clone, PartialEq)]
pub struct RandomObject {
    /// `p{seed}-{index:05}-{family}`: the file stem (and uid) of the object.
    pub name: String,
    /// Its position in the pool (0-based): object i of pool S is the same for every N > i.
    pub index: usize,
    /// Seed of the object's own random stream ([`object_seed`]).
    pub object_seed: u64,
    /// The parametric family it was drawn from (`objects list --families`).
    pub family: &'static str,
    /// The family's parameters as drawn (a JSON object; nested parts are arrays of objects).
    pub params: Value,
    /// Non-uniform scale applied in the object's construction frame, before the rotation.
    pub scale: [f64; 3],
    /// Orientation as a unit quaternion `[w, x, y, z]`.
    pub rotation: [f64; 4],
    /// The normalized mesh.
    pub mesh: Mesh,
}

/// Seed of object `index` of the pool with seed `seed` (independent of the pool's size).
pub fn object_seed(seed: u64, index: usize) -> u64 {
    splitmix64(splitmix64(seed) ^ splitmix64(index as u64))
}

/// Name of object `index` of family `family` in the pool with seed `seed`.
pub fn object_name(seed: u64, index: usize, family: &str) -> String {
    format!("p{seed}-{index:05}-{family}")
}

/// The random stream of one object, the parameters recorded so far and the mesh builder.
pub(crate) struct Gen {
    rng: ChaCha8Rng,
    params: Map<String, Value>,
    pub b: Builder,
}

/// `x` rounded to 4 decimals.
pub(crate) fn round4(x: f64) -> f64 {
    (x * 1e4).round() / 1e4
}

const PALETTE: [Rgb; 11] = {
    use super::shapes::*;
    [GREY, RED, ORANGE, YELLOW, GREEN, TEAL, BLUE, PURPLE, WHITE, BROWN, DARK]
};

impl Gen {
    fn new(object_seed: u64, h: f64) -> Gen {
        Gen { rng: ChaCha8Rng::seed_from_u64(object_seed), params: Map::new(), b: Builder::new(h) }
    }

    /// Uniform in [0, 1) from the top 53 bits of the next 64-bit output (independent of the
    /// `rand` crate's distribution code, so streams stay stable across its versions).
    pub fn unit(&mut self) -> f64 {
        (self.rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi], rounded to 4 decimals; not recorded.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        round4(lo + (hi - lo) * self.unit())
    }

    /// Uniform integer in lo..=hi; not recorded.
    pub fn below(&mut self, lo: usize, hi: usize) -> usize {
        lo + (self.rng.next_u64() % (hi - lo + 1) as u64) as usize
    }

    /// Records `value` under `key`.
    pub fn record(&mut self, key: &str, value: impl Into<Value>) {
        self.params.insert(key.to_string(), value.into());
    }

    /// Uniform in [lo, hi] (4 decimals), recorded under `key`.
    pub fn f(&mut self, key: &str, lo: f64, hi: f64) -> f64 {
        let v = self.uniform(lo, hi);
        self.record(key, v);
        v
    }

    /// Log-uniform in [lo, hi] (4 decimals), recorded under `key`.
    pub fn log_f(&mut self, key: &str, lo: f64, hi: f64) -> f64 {
        let v = round4((lo.ln() + (hi.ln() - lo.ln()) * self.unit()).exp());
        self.record(key, v);
        v
    }

    /// Uniform integer in lo..=hi, recorded under `key`.
    pub fn int(&mut self, key: &str, lo: usize, hi: usize) -> usize {
        let v = self.below(lo, hi);
        self.record(key, v);
        v
    }

    /// Integer in lo..=hi, log-uniformly distributed (small values more often), recorded
    /// under `key`.
    pub fn log_int(&mut self, key: &str, lo: usize, hi: usize) -> usize {
        let (a, b) = ((lo as f64).ln(), ((hi + 1) as f64).ln());
        let v = ((a + (b - a) * self.unit()).exp().floor() as usize).clamp(lo, hi);
        self.record(key, v);
        v
    }

    /// True with probability `p`, recorded under `key`.
    pub fn chance(&mut self, key: &str, p: f64) -> bool {
        let v = self.unit() < p;
        self.record(key, v);
        v
    }

    /// One of `options`, uniformly, recorded under `key`.
    pub fn choose(&mut self, key: &str, options: &[&'static str]) -> &'static str {
        let v = options[self.below(0, options.len() - 1)];
        self.record(key, v);
        v
    }

    /// A uniformly random unit vector, its components rounded to 4 decimals (so it is unit
    /// length only to about 1e-4; users that need an exact unit vector normalize it).
    pub fn direction(&mut self) -> P3 {
        let z = self.unit() * 2.0 - 1.0;
        let a = std::f64::consts::TAU * self.unit();
        let s = (1.0 - z * z).max(0.0).sqrt();
        [s * a.cos(), s * a.sin(), z].map(round4)
    }

    /// Picks a random palette colour as the builder's current colour and returns it.
    pub fn paint(&mut self) -> Rgb {
        self.b.color = PALETTE[self.below(0, PALETTE.len() - 1)];
        self.b.color
    }

    /// Runs `f` with a fresh parameter record, appended as an object to the array `key`.
    pub fn part<R>(&mut self, key: &str, f: impl FnOnce(&mut Gen) -> R) -> R {
        let outer = std::mem::take(&mut self.params);
        let r = f(self);
        let inner = std::mem::replace(&mut self.params, outer);
        match self.params.entry(key.to_string()).or_insert_with(|| Value::Array(vec![])) {
            Value::Array(a) => a.push(Value::Object(inner)),
            other => *other = Value::Array(vec![Value::Object(inner)]),
        }
        r
    }
}

/// The family whose share of the total weight contains `u mod total`.
fn pick_family(u: u64) -> &'static Family {
    let fams = families();
    let total: u64 = fams.iter().map(|f| f.weight as u64).sum();
    let mut pick = u % total;
    for f in fams {
        if pick < f.weight as u64 {
            return f;
        }
        pick -= f.weight as u64;
    }
    unreachable!("pick < total")
}

/// The family of object `index` of pool `seed` (without building it).
pub fn family_of(seed: u64, index: usize) -> &'static Family {
    pick_family(ChaCha8Rng::seed_from_u64(object_seed(seed, index)).next_u64())
}

/// Draws object `index` of pool `seed` at edge length `h`.
fn draw(seed: u64, index: usize, h: f64) -> RandomObject {
    let object_seed = object_seed(seed, index);
    let mut g = Gen::new(object_seed, h);
    let fam = pick_family(g.rng.next_u64());
    g.paint();
    (fam.generate)(&mut g);
    // Random non-uniform scale, then a random orientation: axis-aligned (one of the 24
    // rotations of the cube) for a third of the objects, upright (a turn about z) for another
    // third, uniform over all rotations for the rest.
    let scale = [g.uniform(0.6, 1.0), g.uniform(0.6, 1.0), g.uniform(0.6, 1.0)];
    let mode = g.unit();
    let rotation = if mode < 1.0 / 3.0 {
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let up = [
            [1.0, 0.0, 0.0, 0.0],
            [s, s, 0.0, 0.0],
            [s, -s, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [s, 0.0, s, 0.0],
            [s, 0.0, -s, 0.0],
        ];
        let yaw = [[1.0, 0.0, 0.0, 0.0], [s, 0.0, 0.0, s], [0.0, 0.0, 0.0, 1.0], [s, 0.0, 0.0, -s]];
        parts::quat_mul(yaw[g.below(0, 3)], up[g.below(0, 5)])
    } else if mode < 2.0 / 3.0 {
        let yaw = std::f64::consts::PI * g.uniform(-1.0, 1.0);
        [(0.5 * yaw).cos(), 0.0, 0.0, (0.5 * yaw).sin()]
    } else {
        // Shoemake's uniform random unit quaternion.
        let (u1, u2, u3) = (g.unit(), std::f64::consts::TAU * g.unit(), std::f64::consts::TAU * g.unit());
        let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
        [b * u3.cos(), a * u2.sin(), a * u2.cos(), b * u3.sin()]
    };
    let q = rotation.map(round4);
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    let rotation = q.map(|x| x / n);
    let m = parts::quat_matrix(rotation);
    g.b.map_from(0, |p| parts::mul(&m, [p[0] * scale[0], p[1] * scale[1], p[2] * scale[2]]));
    let mesh = std::mem::replace(&mut g.b, Builder::new(h)).finish();
    RandomObject {
        name: object_name(seed, index, fam.name),
        index,
        object_seed,
        family: fam.name,
        params: Value::Object(g.params),
        scale,
        rotation: q,
        mesh,
    }
}

/// Object `index` of the random pool with seed `seed`, with between [`MIN_TRIANGLES`] and
/// [`MAX_TRIANGLES`] triangles (the default [`Detail`], then a few rescaled tessellations if
/// the count is outside that range; the parameters are the same at every tessellation).
pub fn random_object(seed: u64, index: usize) -> RandomObject {
    let mut h = Detail::DEFAULT.edge_length();
    let mut tries = 0;
    loop {
        let o = draw(seed, index, h);
        let n = o.mesh.num_triangles();
        tries += 1;
        if (MIN_TRIANGLES..=MAX_TRIANGLES).contains(&n) || tries == 6 {
            return o;
        }
        let target = if n > MAX_TRIANGLES { 0.6 * MAX_TRIANGLES as f64 } else { 2.0 * MIN_TRIANGLES as f64 };
        h *= (n as f64 / target).sqrt();
    }
}

/// The first `count` objects of the random pool with seed `seed`.
pub fn random_pool(seed: u64, count: usize) -> impl Iterator<Item = RandomObject> {
    (0..count).map(move |i| random_object(seed, i))
}

#[derive(Serialize)]
struct ManifestObject {
    name: String,
    index: usize,
    object_seed: u64,
    family: &'static str,
    vertices: usize,
    triangles: usize,
    scale: [f64; 3],
    rotation: [f64; 4],
    params: Value,
}

#[derive(Serialize)]
struct ManifestFamily {
    name: &'static str,
    weight: u32,
    description: &'static str,
}

#[derive(Serialize)]
struct Manifest {
    generator: &'static str,
    version: u32,
    seed: u64,
    count: usize,
    min_triangles: usize,
    max_triangles: usize,
    families: Vec<ManifestFamily>,
    objects: Vec<ManifestObject>,
}

/// Writes objects `0..count` of the random pool `seed` as `<dir>/<name>.obj` (+ `.mtl`) and
/// the manifest `<dir>/synth.json` (settings, version, families, and per object its family,
/// parameters, scale, rotation and size), creating `dir` if needed. Returns the OBJ paths in
/// index order. Deterministic: the same `seed` and `count` give byte-identical files, and the
/// objects of a smaller `count` are the first ones of a larger one.
pub fn write_random_pool(dir: &Path, seed: u64, count: usize) -> Result<Vec<PathBuf>, GeomError> {
    std::fs::create_dir_all(dir).map_err(|e| GeomError::io(dir, e))?;
    let mut paths = Vec::with_capacity(count);
    let mut objects = Vec::with_capacity(count);
    for o in random_pool(seed, count) {
        let path = dir.join(format!("{}.obj", o.name));
        crate::write::write_obj(&path, &o.mesh)?;
        paths.push(path);
        objects.push(ManifestObject {
            vertices: o.mesh.positions.len(),
            triangles: o.mesh.num_triangles(),
            name: o.name,
            index: o.index,
            object_seed: o.object_seed,
            family: o.family,
            scale: o.scale,
            rotation: o.rotation,
            params: o.params,
        });
    }
    let manifest = Manifest {
        generator: "objview-geom synth::random",
        version: POOL_VERSION,
        seed,
        count,
        min_triangles: MIN_TRIANGLES,
        max_triangles: MAX_TRIANGLES,
        families: families()
            .iter()
            .map(|f| ManifestFamily { name: f.name, weight: f.weight, description: f.description })
            .collect(),
        objects,
    };
    let mut text = serde_json::to_string_pretty(&manifest).expect("manifest serializes");
    text.push('\n');
    let path = dir.join(MANIFEST);
    std::fs::write(&path, text).map_err(|e| GeomError::io(&path, e))?;
    Ok(paths)
}

#[cfg(test)]
mod tests;
