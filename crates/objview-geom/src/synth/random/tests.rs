//! Tests of the random pool: determinism (same settings, same bytes; pools grow by appending),
//! distinct objects, valid closed normalized meshes of bounded size in every family, and the
//! manifest.

use super::*;
use crate::hash::Fnv;
use crate::synth::tests::{check_closed, check_normalized_clean, signed_volume};
use std::collections::{BTreeMap, HashSet};

fn mesh_hash(m: &Mesh) -> u64 {
    let mut h = Fnv::default();
    for p in &m.positions {
        h.eat_f64s(p);
    }
    for t in &m.triangles {
        for i in t {
            h.eat(&i.to_le_bytes());
        }
    }
    h.0
}

/// Validity of one object: closed and outward, normalized, non-degenerate, bounded size.
fn check_object(o: &RandomObject) {
    let m = &o.mesh;
    m.validate(Path::new(&o.name)).unwrap();
    check_closed(m).unwrap_or_else(|e| panic!("{}: {e} ({})", o.name, o.params));
    let v = signed_volume(m);
    assert!(v > 0.0 && v < 4.0 / 3.0 * std::f64::consts::PI, "{}: signed volume {v}", o.name);
    let n = m.num_triangles();
    assert!((MIN_TRIANGLES..=MAX_TRIANGLES).contains(&n), "{}: {n} triangles", o.name);
    check_normalized_clean(&o.name, m);
    assert!(o.params.is_object());
    assert_eq!(o.name, object_name(o.object_seed_pool(), o.index, o.family));
}

impl RandomObject {
    /// The pool seed from the name `p{seed}-…` (tests only).
    fn object_seed_pool(&self) -> u64 {
        self.name[1..].split('-').next().unwrap().parse().unwrap()
    }
}

#[test]
fn family_names_are_unique_kebab_case() {
    let mut names: Vec<&str> = families().iter().map(|f| f.name).collect();
    for f in families() {
        assert!(f.name.chars().all(|c| c.is_ascii_lowercase() || c == '-'), "{}", f.name);
        assert!(!f.description.is_empty() && f.weight > 0);
    }
    names.sort();
    names.dedup();
    assert_eq!(names.len(), families().len());
}

#[test]
fn objects_are_deterministic_and_independent_of_pool_size() {
    for i in [0, 1, 17] {
        assert_eq!(random_object(3, i), random_object(3, i));
    }
    assert_ne!(object_seed(3, 1), object_seed(4, 1));
    assert_ne!(object_seed(3, 1), object_seed(3, 2));
    // Written pools: the same settings give the same bytes; a larger pool starts with the
    // smaller one's files.
    let (a, b, c) =
        (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let pa = write_random_pool(a.path(), 11, 4).unwrap();
    let pb = write_random_pool(b.path(), 11, 4).unwrap();
    let pc = write_random_pool(c.path(), 11, 7).unwrap();
    assert_eq!(pa.len(), 4);
    assert_eq!(pc.len(), 7);
    let read = |p: &Path| std::fs::read(p).unwrap();
    for (x, y) in pa.iter().zip(&pb) {
        assert_eq!(x.file_name(), y.file_name());
        assert_eq!(read(x), read(y));
        assert_eq!(read(&x.with_extension("mtl")), read(&y.with_extension("mtl")));
    }
    assert_eq!(read(&a.path().join(MANIFEST)), read(&b.path().join(MANIFEST)));
    for (x, z) in pa.iter().zip(&pc) {
        assert_eq!(x.file_name(), z.file_name());
        assert_eq!(read(x), read(z));
    }
    // The manifest lists the objects with their families and parameters.
    let m: Value = serde_json::from_slice(&read(&c.path().join(MANIFEST))).unwrap();
    assert_eq!(m["version"], POOL_VERSION);
    assert_eq!(m["seed"], 11);
    assert_eq!(m["count"], 7);
    assert_eq!(m["families"].as_array().unwrap().len(), families().len());
    let objs = m["objects"].as_array().unwrap();
    assert_eq!(objs.len(), 7);
    for (i, o) in objs.iter().enumerate() {
        let r = random_object(11, i);
        assert_eq!(o["name"], r.name.as_str());
        assert_eq!(o["family"], r.family);
        assert_eq!(o["params"], r.params);
        assert_eq!(o["triangles"], r.mesh.num_triangles());
        assert!(pc[i].ends_with(format!("{}.obj", r.name)));
    }
    // The OBJ loads back to the same triangles.
    let loaded = crate::io::load_mesh(&pc[5]).unwrap();
    let r = random_object(11, 5);
    assert_eq!(loaded.num_triangles(), r.mesh.num_triangles());
    assert_eq!(loaded.triangle(0), r.mesh.triangle(0));
}

#[test]
fn two_hundred_objects_are_distinct_valid_and_normalized() {
    let mut hashes = HashSet::new();
    let mut names = HashSet::new();
    let mut per_family: BTreeMap<&str, usize> = BTreeMap::new();
    for o in random_pool(1, 200) {
        check_object(&o);
        assert_eq!(o.family, family_of(1, o.index).name);
        assert!(hashes.insert(mesh_hash(&o.mesh)), "{}: same mesh as an earlier object", o.name);
        assert!(names.insert(o.name.clone()));
        *per_family.entry(o.family).or_default() += 1;
    }
    eprintln!("families in the first 200 of seed 1: {per_family:?}");
    assert!(per_family.len() >= 25, "{} families", per_family.len());
}

#[test]
fn every_family_is_reached_and_valid() {
    // Every family appears among the first 600 objects of seed 0; the first three objects of
    // each family (from seeds 0 and 2) are valid.
    for seed in [0, 2] {
        let mut found: BTreeMap<&str, Vec<usize>> = BTreeMap::new();
        for i in 0..600 {
            found.entry(family_of(seed, i).name).or_default().push(i);
        }
        let missing: Vec<&str> =
            families().iter().map(|f| f.name).filter(|n| !found.contains_key(n)).collect();
        assert!(missing.is_empty(), "seed {seed}: families never drawn: {missing:?}");
        for (fam, idx) in found {
            for &i in idx.iter().take(if seed == 0 { 3 } else { 1 }) {
                let o = random_object(seed, i);
                assert_eq!(o.family, fam);
                check_object(&o);
            }
        }
    }
}

#[test]
fn built_in_pool_bytes_are_unchanged() {
    // FNV-1a 64 over the OBJ (without its first line, which names the tool's version) and MTL
    // texts of the 33 built-in objects at the default detail, in catalog order: the demo's
    // default pool must not move when the random pool changes.
    let mut h = Fnv::default();
    for o in super::super::catalog() {
        let text = crate::write::obj_text(&o.build(Detail::DEFAULT), &format!("{}.mtl", o.name));
        let (first, rest) = text.obj.split_once('\n').unwrap();
        assert!(first.starts_with("# objview "), "{first}");
        h.eat(rest.as_bytes());
        h.eat(text.mtl.as_deref().unwrap_or("").as_bytes());
    }
    assert_eq!(h.0, BUILT_IN_HASH, "built-in pool hash {:#018x}", h.0);
}

/// See [`built_in_pool_bytes_are_unchanged`].
const BUILT_IN_HASH: u64 = 0x5013_57cb_a947_80c7;

/// A wider sweep than the default tests (5,000 objects of three seeds, a few seconds in an
/// optimized build): `cargo test --profile ci -p objview-geom -- --ignored many_objects`.
#[test]
#[ignore]
fn many_objects_are_valid() {
    let mut tris: Vec<usize> = vec![];
    for seed in [5, 6, 7] {
        for o in random_pool(seed, 5_000 / 3) {
            check_object(&o);
            tris.push(o.mesh.num_triangles());
        }
    }
    tris.sort_unstable();
    eprintln!("triangles: min {} median {} max {}", tris[0], tris[tris.len() / 2], tris[tris.len() - 1]);
}
