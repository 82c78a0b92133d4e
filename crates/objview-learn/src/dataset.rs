//! `objview learn dataset`: oracle training data for the learned planners, one NPZ file per
//! object plus a JSON manifest, resumable and shardable like `annotate`. `--method completion`
//! writes the completion network's pairs instead ([`crate::completion_data`], same layout);
//! what follows is the data of `nbv-net` and `ma-scvp`.
//!
//! Per object (timed by stage):
//! 1. `load`: the normalized mesh and its ground-truth cloud, exactly as `annotate` reads them;
//! 2. `visibility`: S_gt at r = 0.02 and the tammes-128 per-view visible voxel sets O(v) of
//!    SPEC §4 (the sets d_plan is computed from);
//! 3. `rollouts`: the greedy oracle rollout from each of the 128 start views
//!    ([`crate::rollout`]);
//! 4. `sampling`: the method's case protocol ([`crate::sampling`]): NBV-Net whole rollouts,
//!    MA-SCVP long-tail, seeded by (seed, uid);
//! 5. `covers` (MA-SCVP only): the exact residual set cover of every kept case, with its status;
//! 6. `grids`: each kept case's input grid ([`crate::input_grid`]) built **as the planner sees
//!    it at deployment**: the rendered depth frames (SPEC camera) of the case's visited views,
//!    inserted in visiting order from the camera positions. The reference instead inserts the
//!    visible *voxel centres* of each view (one point per 0.02 voxel), which differs from what
//!    its planners get at deployment (one point per pixel, more free space carved): a
//!    train/deploy gap this generator closes. `--input voxel-centres` keeps the reference's
//!    variant. Grids of one rollout are built incrementally (one scan per visited view);
//! 7. `write`: `cases/<uid>.npz` (temp file, then rename) and one line in the objects file.
//!
//! The NPZ arrays of an object with n cases (the contract of `python/objview/learn.py`):
//! `grid` f32 `[n, G, G, G]` (C order, `[x][y][z]`), `visited` u8 `[n, 128]`, `label` i64 `[n]` (oracle
//! NBV), `gains` i32 `[n, 128]`, `cover` u8 `[n, 128]` (multi-hot residual cover; zeros when not
//! computed), `cover_status` i8 `[n]` (−1 not computed, 0 optimal, 1 time limit, 2 error),
//! `start` i32 `[n]`, `step` i32 `[n]`, `covered` i32 `[n]`, `universe` i32 `[]` (|U|).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use objview_dataset::annotate::{ground_truth_points, AnnotateSettings, GridViews};
use objview_dataset::{
    drive, resolve_inputs, to_line, BatchSummary, ItemOutcome, ObjectRef, Progress, ResumableJsonl, Shard,
};
use objview_difficulty::{CoverSettings, CoverStatus};
use objview_geom::hash::{splitmix64, Fnv};
use objview_geom::normalize::load_normalized;
use objview_render::{render, Camera};
use objview_voxel::{bitset_to_indices, center_of, Visibility, VoxelSet};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::input_grid::{InputGrid, GRID};
use crate::npz::{Dtype, NpzWriter};
use crate::rollout::Coverage;
use crate::sampling::{sample, Protocol, NEED_CASE_1};
use crate::LearnError;

/// The number of views of the learned planners' action space (tammes-128).
pub const VIEWS: usize = 128;
/// The manifest's format name.
pub const FORMAT: &str = "objview-learn-dataset";
/// The manifest's format version.
pub const FORMAT_VERSION: u32 = 1;

/// Which learned method the data is for (decides the case protocol and the labels computed).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Method {
    /// NBV-Net: NBV protocol, oracle NBV labels.
    #[serde(rename = "nbv-net")]
    NbvNet,
    /// MA-SCVP: long-tail protocol, residual set-cover labels.
    #[serde(rename = "ma-scvp")]
    MaScvp,
    /// The completion network of the hybrids' `net` backend: partial clouds of 1–3 views and
    /// the ground-truth cloud ([`crate::completion_data`]).
    #[serde(rename = "completion")]
    Completion,
}

impl Method {
    /// The CLI name.
    pub fn name(self) -> &'static str {
        match self {
            Method::NbvNet => "nbv-net",
            Method::MaScvp => "ma-scvp",
            Method::Completion => "completion",
        }
    }
    /// Its case protocol (`None` for completion data, which has no rollouts).
    pub fn protocol(self) -> Option<Protocol> {
        match self {
            Method::NbvNet => Some(Protocol::Nbv),
            Method::MaScvp => Some(Protocol::LongTail),
            Method::Completion => None,
        }
    }
}

impl std::str::FromStr for Method {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "nbv-net" => Ok(Method::NbvNet),
            "ma-scvp" => Ok(Method::MaScvp),
            "completion" => Ok(Method::Completion),
            o => Err(format!("unknown method '{o}' (expected nbv-net, ma-scvp or completion)")),
        }
    }
}

/// How case grids are built.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum InputSource {
    /// Rendered depth frames of the visited views (what the planner sees at deployment).
    #[default]
    Depth,
    /// The visible voxel centres of each visited view (the reference's training variant).
    VoxelCentres,
}

impl InputSource {
    /// The CLI name.
    pub fn name(self) -> &'static str {
        match self {
            InputSource::Depth => "depth",
            InputSource::VoxelCentres => "voxel-centres",
        }
    }
}

impl std::str::FromStr for InputSource {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "depth" => Ok(InputSource::Depth),
            "voxel-centres" => Ok(InputSource::VoxelCentres),
            o => Err(format!("unknown input '{o}' (expected depth or voxel-centres)")),
        }
    }
}

/// Every setting of a dataset run; recorded in the manifest and every object line.
#[derive(Debug, Clone)]
pub struct DatasetSettings {
    /// The method the cases are for.
    pub method: Method,
    /// How meshes, ground truth and visibility are read (the annotation's settings; the cover
    /// settings are those of the residual covers).
    pub annotate: AnnotateSettings,
    /// How grids are built.
    pub input: InputSource,
    /// Grid cells per axis (64).
    pub grid: usize,
    /// The long-tail `need_case_1` (64).
    pub need_case_1: usize,
    /// Seed of the case sampling.
    pub seed: u64,
    /// Completion data: partial clouds per object, views per partial, ground-truth size.
    pub completion: crate::completion_data::CompletionDataSettings,
}

impl Default for DatasetSettings {
    fn default() -> Self {
        let mut annotate = AnnotateSettings::default();
        annotate.cover.time_limit_s = 10.0;
        DatasetSettings {
            method: Method::NbvNet,
            annotate,
            input: InputSource::Depth,
            grid: GRID,
            need_case_1: NEED_CASE_1,
            seed: 0,
            completion: Default::default(),
        }
    }
}

impl DatasetSettings {
    /// The settings as recorded.
    pub fn to_json(&self) -> Value {
        if self.method == Method::Completion {
            return crate::completion_data::settings_json(self);
        }
        json!({
            "method": self.method.name(),
            "protocol": match self.method.protocol() { Some(Protocol::Nbv) => "nbv (whole rollouts)", _ => "long-tail" },
            "views": format!("tammes-{VIEWS}"),
            "input": self.input.name(),
            "grid": self.grid,
            "grid_box": [-1.0, 1.0],
            "need_case_1": self.need_case_1,
            "seed": self.seed,
            "labels": {"nbv": "greedy largest new-voxel gain, ties to the lowest id",
                       "cover": if self.method == Method::MaScvp { "exact residual set cover (objview_difficulty::solve_min_cover)" } else { "not computed" }},
            "rng": "ChaCha8(splitmix64(fnv1a(seed, uid)))",
            "annotate": self.annotate.to_json(),
        })
    }

    /// Checks ranges.
    pub fn validate(&self) -> Result<(), LearnError> {
        self.annotate.validate()?;
        if !(1..=256).contains(&self.grid) {
            return Err(LearnError::Invalid(format!("--grid must be 1..=256, got {}", self.grid)));
        }
        if self.need_case_1 == 0 {
            return Err(LearnError::Invalid("--need-case-1 must be at least 1".into()));
        }
        if self.method == Method::Completion {
            self.completion.validate()?;
        }
        Ok(())
    }
}

/// The per-object RNG seed of the case sampling.
pub fn object_seed(seed: u64, uid: &str) -> u64 {
    let mut h = Fnv::default();
    h.eat(&seed.to_le_bytes());
    h.eat(&[0xff]);
    h.eat(uid.as_bytes());
    splitmix64(h.0)
}

/// What one object produced (its line in the objects file).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ObjectRecord {
    /// The object.
    pub uid: String,
    /// The NPZ file, relative to the dataset folder.
    pub file: String,
    /// Number of cases.
    pub cases: usize,
    /// |U|, the voxels seen by some tammes-128 view.
    pub universe: usize,
    /// |S_gt|.
    pub surface_voxels: usize,
    /// Valid rollout steps over all 128 rollouts (before sampling).
    pub valid_steps: usize,
    /// Mean number of views of a rollout until everything is covered.
    pub mean_rollout_views: f64,
    /// Residual-cover statuses of the kept cases (`optimal`, `time_limit`, `error`), when computed.
    pub cover_status: BTreeMap<String, usize>,
    /// Seconds per stage.
    pub timings: BTreeMap<String, f64>,
    /// Total seconds.
    pub seconds: f64,
    /// The settings.
    pub settings: Value,
    /// objview version.
    pub version: String,
}

/// The normalized mesh of `obj` and its surface voxels S_gt, read exactly as `annotate` reads
/// them.
pub fn load_object(
    obj: &ObjectRef,
    a: &AnnotateSettings,
) -> Result<(objview_geom::mesh::Mesh, VoxelSet), LearnError> {
    let path = obj.mesh.as_path();
    let (mesh, transform) =
        load_normalized(path, a.normalize).map_err(objview_dataset::DatasetError::from)?;
    let (points, _) = ground_truth_points(obj, a, &mesh, transform)?;
    let set = VoxelSet::from_points(&points, a.resolution)
        .map_err(|source| objview_dataset::DatasetError::Voxel { path: path.to_path_buf(), source })?;
    Ok((mesh, set))
}

/// The per-view visible voxel sets O(v) of SPEC §4 over `set` for `cameras` (the sets d_plan is
/// computed from).
pub fn view_coverage(
    mesh: &objview_geom::mesh::Mesh,
    set: &VoxelSet,
    a: &AnnotateSettings,
    cameras: &[Camera],
) -> Coverage {
    let vis = Visibility::with_max_range(set, mesh, a.visibility, a.max_range);
    Coverage::new(vis.observe_all_bitsets(cameras))
}

/// Generates the cases of one object and writes `out_dir/cases/<uid>.npz`.
pub fn generate_object(
    obj: &ObjectRef,
    settings: &DatasetSettings,
    cameras: &[Camera],
    out_dir: &Path,
    settings_json: &Value,
) -> Result<ObjectRecord, LearnError> {
    let t_all = Instant::now();
    let mut timings = BTreeMap::new();
    let mut lap = |name: &str, t: &mut Instant| {
        timings.insert(name.to_string(), t.elapsed().as_secs_f64());
        *t = Instant::now();
    };
    let mut t = Instant::now();
    let a = &settings.annotate;
    let (mesh, set) = load_object(obj, a)?;
    lap("load", &mut t);
    let coverage = view_coverage(&mesh, &set, a, cameras);
    lap("visibility", &mut t);

    let rollouts: Vec<_> = (0..cameras.len()).map(|s| coverage.rollout(s, None)).collect();
    let valid_steps = rollouts.iter().map(|r| r.steps.iter().filter(|s| s.is_valid()).count()).sum();
    let complete: Vec<usize> = rollouts
        .iter()
        .filter(|r| r.steps.last().is_some_and(|s| s.covered == coverage.universe_size()))
        .map(|r| r.steps.len())
        .collect();
    let mean_rollout_views =
        if complete.is_empty() { 0.0 } else { complete.iter().sum::<usize>() as f64 / complete.len() as f64 };
    lap("rollouts", &mut t);

    let protocol = settings.method.protocol().ok_or_else(|| {
        LearnError::Invalid(format!("method {} has no case protocol", settings.method.name()))
    })?;
    let kept = sample(&rollouts, protocol, settings.need_case_1, object_seed(settings.seed, &obj.uid));
    lap("sampling", &mut t);

    let n = kept.len();
    let mut cover = vec![0u8; n * VIEWS];
    let mut cover_status = vec![-1i8; n];
    let mut status_counts = BTreeMap::new();
    if settings.method == Method::MaScvp {
        let cs: &CoverSettings = &a.cover;
        for (i, &(r, s)) in kept.iter().enumerate() {
            let (ids, status) = coverage.residual_cover(&rollouts[r].steps[s].visited, cs)?;
            for v in ids {
                cover[i * VIEWS + v] = 1;
            }
            let (code, name) = match status {
                CoverStatus::Optimal => (0, "optimal"),
                CoverStatus::TimeLimit => (1, "time_limit"),
                _ => (2, "error"),
            };
            cover_status[i] = code;
            *status_counts.entry(name.to_string()).or_insert(0) += 1;
        }
    }
    lap("covers", &mut t);

    let cases_dir = out_dir.join("cases");
    std::fs::create_dir_all(&cases_dir).map_err(|e| LearnError::io(&cases_dir, e))?;
    let file = format!("cases/{}.npz", obj.uid);
    let final_path = out_dir.join(&file);
    let tmp = out_dir.join(format!("cases/{}.npz.tmp", obj.uid));
    let g = settings.grid;
    let mut w = NpzWriter::create(&tmp)?;
    w.begin("grid", Dtype::F32, &[n, g, g, g])?;
    // Each view's depth frame (or visible voxel centres) is made once and reused by every
    // rollout that visits it.
    let mut frames: BTreeMap<usize, Vec<f32>> = BTreeMap::new();
    let mut centres: BTreeMap<usize, Vec<[f64; 3]>> = BTreeMap::new();
    let mut grid = InputGrid::new(g);
    let mut buf = Vec::with_capacity(g * g * g);
    let mut current: Option<(usize, usize)> = None; // (rollout, views inserted)
    for &(r, s) in &kept {
        let visited = &rollouts[r].steps[s].visited;
        let done = match current {
            Some((cr, k)) if cr == r => k,
            _ => {
                grid.clear();
                0
            }
        };
        for &v in &visited[done..] {
            match settings.input {
                InputSource::Depth => {
                    let depth = frames.entry(v).or_insert_with(|| render(&mesh, &cameras[v]).depth);
                    grid.insert_depth(&cameras[v], depth);
                }
                InputSource::VoxelCentres => {
                    let pts = centres.entry(v).or_insert_with(|| {
                        bitset_to_indices(&coverage.sets[v])
                            .into_iter()
                            .map(|i| center_of(set.key(i as usize), a.resolution))
                            .collect()
                    });
                    grid.insert_points(cameras[v].center, pts);
                }
            }
        }
        current = Some((r, visited.len()));
        buf.clear();
        grid.write_probabilities(&mut buf);
        w.write_f32(&buf)?;
    }
    lap("grids", &mut t);

    let mut visited = vec![0u8; n * VIEWS];
    let mut gains = vec![0i32; n * VIEWS];
    let (mut label, mut start, mut step, mut covered) = (vec![], vec![], vec![], vec![]);
    for (i, &(r, s)) in kept.iter().enumerate() {
        let st = &rollouts[r].steps[s];
        for &v in &st.visited {
            visited[i * VIEWS + v] = 1;
        }
        for (v, &gv) in st.gains.iter().enumerate() {
            gains[i * VIEWS + v] = gv as i32;
        }
        label.push(st.nbv.expect("a valid case has an oracle view") as i64);
        start.push(rollouts[r].start as i32);
        step.push(s as i32);
        covered.push(st.covered as i32);
    }
    w.array_u8("visited", &[n, VIEWS], &visited)?;
    w.array_i64("label", &[n], &label)?;
    w.array_i32("gains", &[n, VIEWS], &gains)?;
    w.array_u8("cover", &[n, VIEWS], &cover)?;
    w.array_i8("cover_status", &[n], &cover_status)?;
    w.array_i32("start", &[n], &start)?;
    w.array_i32("step", &[n], &step)?;
    w.array_i32("covered", &[n], &covered)?;
    w.array_i32("universe", &[], &[coverage.universe_size() as i32])?;
    w.finish()?;
    std::fs::rename(&tmp, &final_path).map_err(|e| LearnError::io(&final_path, e))?;
    lap("write", &mut t);

    Ok(ObjectRecord {
        uid: obj.uid.clone(),
        file,
        cases: n,
        universe: coverage.universe_size(),
        surface_voxels: set.len(),
        valid_steps,
        mean_rollout_views,
        cover_status: status_counts,
        timings,
        seconds: t_all.elapsed().as_secs_f64(),
        settings: settings_json.clone(),
        version: crate::VERSION.to_string(),
    })
}

/// One dataset run, fully resolved.
#[derive(Debug, Clone)]
pub struct DatasetPlan {
    /// Pool folders, split files or meshes.
    pub inputs: Vec<PathBuf>,
    /// The dataset folder.
    pub out: PathBuf,
    /// Every setting.
    pub settings: DatasetSettings,
    /// Worker threads (`None`: every core).
    pub threads: Option<usize>,
    /// The part of the inputs to do.
    pub shard: Shard,
    /// Redo objects whose earlier line is a failure.
    pub retry_failed: bool,
    /// The command line, recorded in the manifest.
    pub command: String,
}

impl DatasetPlan {
    /// The objects file of this plan's shard.
    pub fn objects_file(&self) -> PathBuf {
        objects_file(&self.out, self.shard)
    }

    /// Generates every object of the shard not yet in its objects file, then rewrites the
    /// manifest from every objects file in the folder.
    pub fn run(&self, progress: &dyn Progress) -> Result<(BatchSummary, Value), LearnError> {
        self.settings.validate()?;
        let objects = self.shard.select(resolve_inputs(&self.inputs)?);
        let views = GridViews::new(self.settings.annotate.view_radius)?;
        let cameras = views.planning().to_vec();
        let mut settings_json = objview_runs::provenance::settings("learn dataset", self.settings.to_json());
        settings_json["shard"] = json!(self.shard.to_string());
        settings_json["inputs"] =
            json!(self.inputs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>());
        settings_json["pool"] = pool_provenance(&objects);
        std::fs::create_dir_all(&self.out).map_err(|e| LearnError::io(&self.out, e))?;
        let (out, existing) = ResumableJsonl::open(&self.objects_file(), "uid", self.retry_failed)?;
        let summary = drive(
            "learn dataset",
            Some(format!("shard {}", self.shard)),
            Some(if self.settings.method == Method::Completion {
                format!(
                    "completion pairs, {} partial clouds of 1-{} views per object",
                    self.settings.completion.partials, self.settings.completion.max_views
                )
            } else {
                format!("{} cases, {}³ grids", self.settings.method.name(), self.settings.grid)
            }),
            &objects,
            out,
            &existing,
            self.threads,
            |obj| match self.generate(obj, &cameras, &settings_json) {
                Ok((line, note)) => ItemOutcome { note, line, failed: false },
                Err(e) => {
                    let msg = objview_geom::error::one_line(&e.to_string()).into_owned();
                    ItemOutcome {
                        line: to_line(
                            &json!({"uid": obj.uid, "mesh": obj.mesh.display().to_string(), "error": msg, "settings": settings_json}),
                        ),
                        failed: true,
                        note: msg,
                    }
                }
            },
            progress,
        )?;
        let manifest = write_manifest(&self.out, &settings_json, &self.command)?;
        Ok((summary, manifest))
    }
}

impl DatasetPlan {
    /// One object of the method: its objects-file line and a progress note.
    fn generate(
        &self,
        obj: &ObjectRef,
        cameras: &[Camera],
        settings_json: &Value,
    ) -> Result<(String, String), LearnError> {
        if self.settings.method == Method::Completion {
            let rec = crate::completion_data::generate_completion_object(
                obj,
                &self.settings,
                cameras,
                &self.out,
                settings_json,
            )?;
            let note = format!(
                "{} partial clouds (mean {:.0} points), {:.2} s",
                rec.cases, rec.mean_partial_points, rec.seconds
            );
            return Ok((to_line(&rec), note));
        }
        let rec = generate_object(obj, &self.settings, cameras, &self.out, settings_json)?;
        let note = format!("{} cases, |U|={}, {:.2} s", rec.cases, rec.universe, rec.seconds);
        Ok((to_line(&rec), note))
    }
}

/// The objects file of a shard: `objects.jsonl`, or `objects.shard-I-of-N.jsonl`.
pub fn objects_file(dir: &Path, shard: Shard) -> PathBuf {
    if shard == Shard::ALL {
        dir.join("objects.jsonl")
    } else {
        dir.join(format!("objects.shard-{}-of-{}.jsonl", shard.index, shard.count))
    }
}

/// Rewrites `dir/manifest.json` from every `objects*.jsonl` of the folder (so shards written
/// into one folder merge): counts, the NPZ files in order, the settings and versions.
pub fn write_manifest(dir: &Path, settings_json: &Value, command: &str) -> Result<Value, LearnError> {
    let mut names: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| LearnError::io(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("objects") && n.ends_with(".jsonl"))
        })
        .collect();
    names.sort();
    let (mut files, mut cases, mut failed, mut objects) = (Vec::new(), 0usize, 0usize, 0usize);
    for p in &names {
        let text = std::fs::read_to_string(p).map_err(|e| LearnError::io(p, e))?;
        for line in text.lines().filter(|l| !l.trim().is_empty()) {
            let Ok(v) = serde_json::from_str::<Value>(line) else { continue };
            if v.get("error").is_some() {
                failed += 1;
            } else if let (Some(f), Some(c)) = (v["file"].as_str(), v["cases"].as_u64()) {
                files.push(f.to_string());
                cases += c as usize;
                objects += 1;
            }
        }
    }
    let manifest = json!({
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "method": settings_json["method"],
        "views": VIEWS,
        "grid": settings_json["grid"],
        "objects": objects,
        "failed": failed,
        "cases": cases,
        "files": files,
        "objects_files": names.iter().filter_map(|p| p.file_name().map(|n| n.to_string_lossy().to_string())).collect::<Vec<_>>(),
        "arrays": if settings_json["method"] == "completion" {
            crate::completion_data::arrays_json()
        } else {
            json!({
                "grid": "float32 [n, G, G, G], occupancy probability, C order [x][y][z], box [-1,1]^3, 0.5 unknown",
                "visited": "uint8 [n, 128]", "label": "int64 [n] oracle next-best view",
                "gains": "int32 [n, 128]", "cover": "uint8 [n, 128] residual set cover (multi-hot)",
                "cover_status": "int8 [n]: -1 not computed, 0 optimal, 1 time limit, 2 error",
                "start": "int32 [n]", "step": "int32 [n]", "covered": "int32 [n]", "universe": "int32 []"
            })
        },
        "command": command,
        "settings": settings_json,
        "version": crate::VERSION,
    });
    let path = dir.join("manifest.json");
    let tmp = dir.join("manifest.json.tmp");
    std::fs::write(&tmp, serde_json::to_string_pretty(&manifest).expect("json") + "\n")
        .map_err(|e| LearnError::io(&tmp, e))?;
    std::fs::rename(&tmp, &path).map_err(|e| LearnError::io(&path, e))?;
    Ok(manifest)
}

/// The path of a data file named in the manifest (`cases/<uid>.npz`), which must lie inside the
/// dataset folder (no absolute paths, no `..`, no symlinks out of it).
pub fn resolve_data_file(dir: &Path, name: &str) -> Result<PathBuf, LearnError> {
    objview_geom::fsutil::resolve_inside(&dir.join("manifest.json"), name)
        .map_err(|e| LearnError::Invalid(objview_geom::error::one_line(&e.to_string()).into_owned()))
}

/// The `synth.json` of the folder of the first object (how a procedural pool was made: seed,
/// count, generator version), or null for other pools.
pub fn pool_provenance(objects: &[ObjectRef]) -> Value {
    objects
        .first()
        .and_then(|o| o.mesh.parent())
        .map(|d| d.join("synth.json"))
        .and_then(|p| std::fs::read_to_string(p).ok())
        .and_then(|t| serde_json::from_str::<Value>(&t).ok())
        .map(|v| json!({"generator": v["generator"], "version": v["version"], "seed": v["seed"], "count": v["count"]}))
        .unwrap_or(Value::Null)
}
