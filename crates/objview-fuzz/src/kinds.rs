//! The kinds of input the fuzzer feeds, and for each one the loader call it exercises and the
//! check that a loaded object is valid.
//!
//! A kind is a loader entry point plus the file extension it dispatches on: the mesh formats
//! through `objview_geom::io::load_mesh`, the cloud formats through
//! `objview_geom::cloud::read_cloud` (NPY also through `objview_geom::npy::read_npy_f64`), view
//! sets, rule files, split files (and the meshes and clouds they name inside the case folder),
//! annotation results (`read_annotations` and the resumable writer's reader) and episode result
//! lines (`objview_report::load::load_results`).
//!
//! The `test-*` kinds are fake loaders that misbehave on purpose (panic, abort, hang, allocate
//! without bound, or one of those chosen by the first byte). They exist so the tests can prove
//! the harness classifies each failure; they are never part of a normal run.

use std::path::{Component, Path};

use objview_geom::mesh::Appearance;
use objview_geom::Mesh;

/// An input kind (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Kind {
    /// Wavefront OBJ mesh (`.obj`), through `load_mesh`.
    Obj,
    /// PLY mesh, ascii or binary (`.ply`), through `load_mesh`.
    Ply,
    /// STL mesh, ascii or binary (`.stl`), through `load_mesh`.
    Stl,
    /// OFF mesh (`.off`), through `load_mesh`.
    Off,
    /// glTF JSON mesh (`.gltf`), through `load_mesh`.
    Gltf,
    /// Binary glTF mesh (`.glb`), through `load_mesh`.
    Glb,
    /// PCD point cloud, ascii or binary (`.pcd`), through `read_cloud`.
    Pcd,
    /// PLY point cloud (`.ply`), through `read_cloud`.
    CloudPly,
    /// NumPy array cloud (`.npy`), through `read_cloud` and `read_npy_f64`.
    Npy,
    /// NumPy zip archive cloud (`.npz`), through `read_cloud`.
    Npz,
    /// View-set file, one `x y z` direction per line (`.txt`), through `ViewSet::load`.
    ViewSet,
    /// Feasibility rule file of a view space (`.json`), through `ViewSpace::load`.
    Rules,
    /// Split file (`.json`), through `resolve_inputs`, plus the meshes and clouds it names.
    Split,
    /// Annotation results (`.jsonl`), through `read_annotations`.
    Annotations,
    /// A results file reopened for resuming (`.jsonl`), through `ResumableJsonl::open`.
    Resume,
    /// Episode result lines (`.jsonl`), through `objview_report::load::load_results`.
    Results,
    /// Test kind: always panics.
    TestPanic,
    /// Test kind: always aborts the process.
    TestAbort,
    /// Test kind: never returns.
    TestHang,
    /// Test kind: allocates memory without bound.
    TestOom,
    /// Test kind: the behaviour is chosen by the file's first byte (ok, error, caught panic,
    /// panic, abort, unbounded memory, hang, or a failed 1 TiB reservation).
    TestMixed,
}

/// What loading one file gave.
#[derive(Debug, Clone, PartialEq)]
pub enum Loaded {
    /// A valid object; a short description.
    Ok(String),
    /// The loader's error message.
    Error(String),
    /// The loader returned an object that breaks an invariant its consumers rely on.
    Invalid(String),
}

impl Kind {
    /// Every real kind, in run order.
    pub const ALL: &'static [Kind] = &[
        Kind::Obj,
        Kind::Ply,
        Kind::Stl,
        Kind::Off,
        Kind::Gltf,
        Kind::Glb,
        Kind::Pcd,
        Kind::CloudPly,
        Kind::Npy,
        Kind::Npz,
        Kind::ViewSet,
        Kind::Rules,
        Kind::Split,
        Kind::Annotations,
        Kind::Resume,
        Kind::Results,
    ];

    /// The fake kinds that prove the harness can fail.
    pub const TEST: &'static [Kind] =
        &[Kind::TestPanic, Kind::TestAbort, Kind::TestHang, Kind::TestOom, Kind::TestMixed];

    /// The name used on the command line and as the regression folder.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Obj => "obj",
            Kind::Ply => "ply",
            Kind::Stl => "stl",
            Kind::Off => "off",
            Kind::Gltf => "gltf",
            Kind::Glb => "glb",
            Kind::Pcd => "pcd",
            Kind::CloudPly => "cloud-ply",
            Kind::Npy => "npy",
            Kind::Npz => "npz",
            Kind::ViewSet => "viewset",
            Kind::Rules => "rules",
            Kind::Split => "split",
            Kind::Annotations => "annotations",
            Kind::Resume => "resume",
            Kind::Results => "results",
            Kind::TestPanic => "test-panic",
            Kind::TestAbort => "test-abort",
            Kind::TestHang => "test-hang",
            Kind::TestOom => "test-oom",
            Kind::TestMixed => "test-mixed",
        }
    }

    /// The kind of a name (test kinds included).
    pub fn from_name(name: &str) -> Option<Kind> {
        Kind::ALL.iter().chain(Kind::TEST).copied().find(|k| k.name() == name)
    }

    /// Whether this is one of the fake [`Kind::TEST`] kinds.
    pub fn is_test(self) -> bool {
        Kind::TEST.contains(&self)
    }

    /// The extension of the case's main file (the loaders dispatch on it).
    pub fn ext(self) -> &'static str {
        match self {
            Kind::Obj => "obj",
            Kind::Ply | Kind::CloudPly => "ply",
            Kind::Stl => "stl",
            Kind::Off => "off",
            Kind::Gltf => "gltf",
            Kind::Glb => "glb",
            Kind::Pcd => "pcd",
            Kind::Npy => "npy",
            Kind::Npz => "npz",
            Kind::ViewSet => "txt",
            Kind::Rules | Kind::Split => "json",
            Kind::Annotations | Kind::Resume | Kind::Results => "jsonl",
            _ => "bin",
        }
    }

    /// The crate whose loader this kind exercises (where a finding is to be fixed).
    pub fn owner(self) -> &'static str {
        match self {
            Kind::Obj
            | Kind::Ply
            | Kind::Stl
            | Kind::Off
            | Kind::Gltf
            | Kind::Glb
            | Kind::Pcd
            | Kind::CloudPly
            | Kind::Npy
            | Kind::Npz => "objview-geom",
            Kind::ViewSet | Kind::Rules => "objview-views",
            Kind::Split => "objview-dataset (objview-geom for the files it names)",
            Kind::Annotations | Kind::Resume => "objview-dataset",
            Kind::Results => "objview-report",
            _ => "objview-fuzz (test kind)",
        }
    }

    /// Loads `path` (the main file of a case) with this kind's loader. Runs in the child
    /// process: may panic, abort, hang or exhaust memory — that is what is being tested.
    pub fn load(self, path: &Path) -> Loaded {
        match self {
            Kind::Obj | Kind::Ply | Kind::Stl | Kind::Off | Kind::Gltf | Kind::Glb => {
                match objview_geom::io::load_mesh(path) {
                    Ok(m) => check_mesh(&m),
                    Err(e) => Loaded::Error(e.to_string()),
                }
            }
            Kind::Pcd | Kind::CloudPly | Kind::Npz => cloud(path),
            Kind::Npy => match cloud(path) {
                Loaded::Ok(s) => match objview_geom::npy::read_npy_f64(path) {
                    Ok((shape, v)) if shape.iter().product::<usize>() == v.len() => Loaded::Ok(s),
                    Ok((shape, v)) => Loaded::Invalid(format!("npy shape {shape:?} with {} values", v.len())),
                    Err(e) => Loaded::Invalid(format!("read_cloud accepted it, read_npy_f64 did not: {e}")),
                },
                other => other,
            },
            Kind::ViewSet => match objview_views::ViewSet::load(path) {
                Ok(vs) => check_viewset(&vs),
                Err(e) => Loaded::Error(e.to_string()),
            },
            Kind::Rules => match objview_views::ViewSpace::load(path) {
                Ok(vs) => check_space(&vs),
                Err(e) => Loaded::Error(e.to_string()),
            },
            Kind::Split => split(path),
            Kind::Annotations => match objview_dataset::read_annotations(&[path.to_path_buf()]) {
                Ok(set) => Loaded::Ok(format!(
                    "{} annotations, {} failures",
                    set.annotations.len(),
                    set.failures.len()
                )),
                Err(e) => Loaded::Error(e.to_string()),
            },
            Kind::Resume => resume(path),
            Kind::Results => match objview_report::load::load_results(&[path.to_path_buf()], "0.02") {
                Ok(l) => Loaded::Ok(format!("{} episodes, {} failures", l.episodes.len(), l.failures.len())),
                Err(e) => Loaded::Error(e.to_string()),
            },
            Kind::TestPanic | Kind::TestAbort | Kind::TestHang | Kind::TestOom | Kind::TestMixed => {
                test_kind(self, path)
            }
        }
    }
}

/// The structural invariants of a mesh and its appearance that the renderer and the metrics
/// index by (beyond `Mesh::validate`, which `load_mesh` already ran).
pub fn check_mesh(m: &Mesh) -> Loaded {
    if let Err(e) = m.validate(Path::new("mesh")) {
        return Loaded::Invalid(format!("load_mesh returned a mesh that fails validate: {e}"));
    }
    let (nv, nt) = (m.positions.len(), m.triangles.len());
    let bad = match &m.appearance {
        Appearance::None => None,
        Appearance::VertexColors(c) if c.len() != nv => {
            Some(format!("{} vertex colours for {nv} vertices", c.len()))
        }
        Appearance::FaceColors(c) if c.len() != nt => {
            Some(format!("{} face colours for {nt} triangles", c.len()))
        }
        // Colour values themselves are not checked: the renderer clamps them to 0..255.
        Appearance::VertexColors(_) | Appearance::FaceColors(_) => None,
        Appearance::Textured { corner_uvs, face_material, materials, textures } => {
            if corner_uvs.len() != nt || face_material.len() != nt {
                Some(format!(
                    "{} corner UVs, {} face materials for {nt} triangles",
                    corner_uvs.len(),
                    face_material.len()
                ))
            } else if let Some(f) = face_material.iter().find(|&&f| f as usize >= materials.len()) {
                Some(format!("face material {f} of {} materials", materials.len()))
            } else {
                textures
                    .iter()
                    .find(|t| {
                        t.width == 0 || t.height == 0 || t.rgb.len() != t.width as usize * t.height as usize
                    })
                    .map(|t| format!("texture {}x{} with {} texels", t.width, t.height, t.rgb.len()))
            }
        }
    };
    match bad {
        Some(why) => Loaded::Invalid(why),
        None => Loaded::Ok(format!("{nv} vertices, {nt} triangles")),
    }
}

fn cloud(path: &Path) -> Loaded {
    match objview_geom::cloud::read_cloud(path) {
        Ok(pts) if pts.is_empty() => Loaded::Invalid("empty cloud".into()),
        Ok(pts) if pts.iter().flatten().any(|x| !x.is_finite()) => Loaded::Invalid("non-finite point".into()),
        Ok(pts) => Loaded::Ok(format!("{} points", pts.len())),
        Err(e) => Loaded::Error(e.to_string()),
    }
}

fn check_viewset(vs: &objview_views::ViewSet) -> Loaded {
    if vs.dirs.is_empty() {
        return Loaded::Invalid("empty view set".into());
    }
    for d in &vs.dirs {
        let n2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        if !n2.is_finite() || (n2 - 1.0).abs() > 1e-9 {
            return Loaded::Invalid(format!("direction {d:?} is not unit"));
        }
    }
    Loaded::Ok(format!("{} directions", vs.dirs.len()))
}

fn check_space(vs: &objview_views::ViewSpace) -> Loaded {
    use objview_views::feasibility::Rule;
    if !vs.atol.is_finite() || vs.atol < 0.0 {
        return Loaded::Invalid(format!("atol {}", vs.atol));
    }
    fn ok(r: &Rule) -> bool {
        match r {
            Rule::Cmp { value, .. } => value.is_finite(),
            Rule::Group { rules, .. } => !rules.is_empty() && rules.iter().all(ok),
        }
    }
    if !vs.rule.as_ref().is_none_or(ok) {
        return Loaded::Invalid("empty group or non-finite threshold".into());
    }
    // Evaluate a few poses (the consumers do): must not panic.
    let feasible = objview_views::ViewSet::resolve("tammes-32")
        .map(|set| set.poses(3.0).iter().filter(|p| vs.is_feasible(p)).count())
        .unwrap_or(0);
    for p in &vs.blocklist {
        let _ = vs.explain(p);
    }
    Loaded::Ok(format!("{} blocked poses, {feasible}/32 feasible", vs.blocklist.len()))
}

/// Whether `p` lies inside `dir` without going up (`..`) — the split loader follows only
/// such paths, so a mutated split file never reads outside its case folder.
fn inside(dir: &Path, p: &Path) -> bool {
    p.strip_prefix(dir).is_ok_and(|rel| rel.components().all(|c| matches!(c, Component::Normal(_))))
}

fn split(path: &Path) -> Loaded {
    let objects = match objview_dataset::resolve_inputs(&[path.to_path_buf()]) {
        Ok(o) => o,
        Err(e) => return Loaded::Error(e.to_string()),
    };
    let dir = path.parent().unwrap_or(Path::new(""));
    let mut loaded = 0;
    // As `objview annotate` does: every object's mesh, and its cloud if named (only files
    // inside the case folder, and a bounded number of them).
    for o in objects.iter().take(8) {
        if inside(dir, &o.mesh) {
            match objview_geom::io::load_mesh(&o.mesh) {
                Ok(m) => match check_mesh(&m) {
                    Loaded::Ok(_) => loaded += 1,
                    other => return other,
                },
                Err(e) => return Loaded::Error(e.to_string()),
            }
        }
        if let Some(c) = o.gt_cloud.as_deref().filter(|c| inside(dir, c)) {
            match cloud(c) {
                Loaded::Ok(_) => {}
                other => return other,
            }
        }
    }
    Loaded::Ok(format!("{} objects, {loaded} meshes loaded", objects.len()))
}

fn resume(path: &Path) -> Loaded {
    // First as a plain resume (may cut a torn last line), then asking to retry failures
    // (rewrites the file without them).
    for retry in [false, true] {
        match objview_dataset::ResumableJsonl::open(path, "uid", retry) {
            Ok((_, ex)) if retry => {
                return Loaded::Ok(format!("{} lines kept, {} retried", ex.lines, ex.retried))
            }
            Ok(_) => {}
            Err(e) => return Loaded::Error(e.to_string()),
        }
    }
    unreachable!("the loop returns on its second pass")
}

fn test_kind(kind: Kind, path: &Path) -> Loaded {
    let bytes = std::fs::read(path).unwrap_or_default();
    let which = match kind {
        // 'H' hangs, 'R' asks for 1 TiB and recovers; otherwise the first byte mod 6 picks the
        // behaviour (0: no bytes).
        Kind::TestMixed => match bytes.first() {
            None => 0,
            Some(b'H') => 6,
            Some(b'R') => 7,
            Some(b) => b % 6,
        },
        Kind::TestPanic => 3,
        Kind::TestAbort => 4,
        Kind::TestOom => 5,
        _ => 6,
    };
    match which {
        0 => Loaded::Ok(format!("{} bytes", bytes.len())),
        1 => Loaded::Error(format!("test kind: rejected {} bytes", bytes.len())),
        2 => {
            // A panic that the loader catches and turns into an error (as the mesh loaders'
            // last line of defence does): still a finding.
            match std::panic::catch_unwind(|| -> usize { panic!("test kind: caught panic") }) {
                Ok(n) => Loaded::Ok(format!("{n}")),
                Err(_) => Loaded::Error("test kind: parser failed".into()),
            }
        }
        3 => panic!("test kind: deliberate panic"),
        4 => std::process::abort(),
        5 => {
            // Allocate memory without bound (zeroed blocks: mapped lazily, so the limit is
            // reached fast).
            let mut hoard: Vec<Vec<u8>> = Vec::new();
            loop {
                hoard.push(vec![0u8; 64 << 20]);
                std::hint::black_box(&hoard);
            }
        }
        7 => {
            // An allocation far beyond the limit, failure handled: unbounded memory all the same.
            let mut v: Vec<u8> = Vec::new();
            match v.try_reserve(1 << 40) {
                Ok(()) => Loaded::Ok("reserved 1 TiB".into()),
                Err(e) => Loaded::Error(format!("test kind: {e}")),
            }
        }
        _ => loop {
            std::thread::sleep(std::time::Duration::from_millis(50));
        },
    }
}
