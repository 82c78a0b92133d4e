//! MA-SCVP end to end: training determinism on a small synthetic set-cover dataset (same seed
//! → bit-identical weights, resumed or not; another seed → other weights), the saved weights
//! reproduce the trained network's evaluation, and the `ma-scvp` planner's stop rules in real
//! episodes with a scripted network output.

use std::path::Path;
use std::sync::{Arc, Mutex};

use objview_episode::{run_episode, scene_from_parts, Budget, EpisodeSettings, Planner};
use objview_geom::cloud::sample_surface;
use objview_learn::input_grid::InputGrid;
use objview_learn::mascvp::MascvpShape;
use objview_learn::mascvp_planner::{bootstrap_view, nearest_view, MascvpPlanner, SetScorer};
use objview_learn::mascvp_train::{
    evaluate_scvp, load_scvp_cases, load_scvp_weights_bytes, train_scvp, QuietScvp, ScvpTrainSettings,
};
use objview_learn::npz::{Dtype, NpzWriter};
use objview_planners::random::same_pose;
use objview_planners::tsp::TspSettings;
use objview_views::{start_pose, ViewSet, ViewSpace};

/// Random grids whose blob position encodes a small label set; visited flags and covers as
/// `learn dataset --method ma-scvp` writes them.
fn synthetic_dataset(dir: &Path, objects: usize, per_object: usize, seed: u64) {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    std::fs::create_dir_all(dir.join("cases")).unwrap();
    let mut files = vec![];
    for o in 0..objects {
        let f = format!("cases/obj-{o}.npz");
        let mut w = NpzWriter::create(&dir.join(&f)).unwrap();
        w.begin("grid", Dtype::F32, &[per_object, 64, 64, 64]).unwrap();
        let (mut visited, mut cover) = (vec![0u8; per_object * 128], vec![0u8; per_object * 128]);
        for i in 0..per_object {
            let k = rng.gen_range(0..8usize);
            let g: Vec<f32> = (0..64 * 64 * 64)
                .map(|c| if c / 4096 / 8 == k { 0.9 } else { 0.5 + rng.gen_range(-0.05..0.05) })
                .collect();
            w.write_f32(&g).unwrap();
            visited[i * 128 + rng.gen_range(0..128)] = 1;
            for v in [k * 16, k * 16 + 3, k * 16 + 7] {
                cover[i * 128 + v] = 1;
            }
        }
        w.array_u8("visited", &[per_object, 128], &visited).unwrap();
        w.array_u8("cover", &[per_object, 128], &cover).unwrap();
        w.array_i8("cover_status", &[per_object], &vec![0i8; per_object]).unwrap();
        w.finish().unwrap();
        files.push(f);
    }
    let manifest = serde_json::json!({"format": "objview-learn-dataset", "format_version": 1, "method": "ma-scvp",
        "views": 128, "grid": 64, "objects": objects, "cases": objects * per_object, "files": files,
        "settings": {}, "command": "synthetic", "version": "test"});
    std::fs::write(dir.join("manifest.json"), manifest.to_string()).unwrap();
}

/// Burn's Flex device RNG is process-global: trainings in one process must not overlap.
static TRAINING: Mutex<()> = Mutex::new(());

fn small() -> ScvpTrainSettings {
    ScvpTrainSettings {
        shape: MascvpShape { grid: 16, conv1: 4, blocks: [4, 4, 8], fc: vec![32], dropout: 0.35 },
        epochs: 3,
        batch: 4,
        lr: 1e-3,
        seed: 7,
        val_fraction: 0.0,
        ..Default::default()
    }
}

fn run(data: &Path, out: &Path, s: &ScvpTrainSettings, threads: usize, resume: bool) -> Vec<f64> {
    let _one = TRAINING.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    let o = pool.install(|| train_scvp(data, out, s, resume, &QuietScvp)).unwrap();
    o.history.iter().map(|h| h.train_loss).collect()
}

#[test]
fn training_is_deterministic_resumable_and_seed_dependent() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    synthetic_dataset(&data, 2, 6, 1);
    let s = small();
    let w = |n: &str| dir.path().join(format!("{n}.safetensors"));
    let h = |p: &Path| objview_geom::hash::fnv1a64(&std::fs::read(p).unwrap());
    let losses = run(&data, &w("a"), &s, 1, false);
    assert!(losses[2] < losses[0], "loss decreases: {losses:?}");
    run(&data, &w("b"), &s, 2, false);
    assert_eq!(h(&w("a")), h(&w("b")), "same seed, 1 vs 2 threads: bit-identical weights");
    run(&data, &w("c"), &ScvpTrainSettings { epochs: 1, ..s.clone() }, 1, false);
    run(&data, &w("c"), &s, 1, true);
    assert_eq!(h(&w("a")), h(&w("c")), "resumed after epoch 1");
    run(&data, &w("d"), &ScvpTrainSettings { seed: 8, ..s.clone() }, 1, false);
    assert_ne!(h(&w("a")), h(&w("d")), "another seed, other weights");

    // The saved weights (BatchNorm running statistics included) give the evaluation recorded
    // for the kept epoch.
    let device = burn::tensor::Device::flex();
    let net = load_scvp_weights_bytes(&std::fs::read(w("a")).unwrap(), &s.shape, &device).unwrap();
    let (cases, skipped) = load_scvp_cases(&data, 16).unwrap();
    assert_eq!((cases.len(), skipped), (12, 0));
    let (l1, m1) = evaluate_scvp(&net, &cases, 0.3, 1.5, &device);
    let (l2, m2) = evaluate_scvp(&net, &cases, 0.3, 1.5, &device);
    assert_eq!((l1, m1), (l2, m2));
    assert!(l1.is_finite() && (0.0..=1.0).contains(&m1.f1));
    assert_eq!(m1.label_size, 3.0);
}

#[test]
fn nbv_net_data_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    synthetic_dataset(&data, 1, 2, 1);
    let m = data.join("manifest.json");
    let text = std::fs::read_to_string(&m).unwrap().replace("\"ma-scvp\"", "\"nbv-net\"");
    std::fs::write(&m, text).unwrap();
    let e = load_scvp_cases(&data, 16).unwrap_err().to_string();
    assert!(e.contains("manifest.json") && e.contains("ma-scvp"), "{e}");
}

/// Per network call: the visited view ids and the number of known grid cells.
type Calls = Vec<(Vec<usize>, usize)>;

/// Logits that decode to `set` (everything else far below γ), recording each call's view
/// state and how many grid cells were known.
struct Script {
    set: Vec<usize>,
    calls: Arc<Mutex<Calls>>,
}

impl SetScorer for Script {
    fn logits(&mut self, grid: &InputGrid, visited: &[bool]) -> Vec<f32> {
        let known = grid.probabilities().iter().filter(|&&p| p != 0.5).count();
        let vs: Vec<usize> = (0..visited.len()).filter(|&v| visited[v]).collect();
        self.calls.lock().unwrap().push((vs, known));
        let mut s = vec![-6.0f32; 128];
        for &v in &self.set {
            s[v] = 2.0;
        }
        s
    }
    fn describe(&self) -> serde_json::Value {
        serde_json::json!("scripted")
    }
}

fn episode(space: &str, set: Vec<usize>) -> (objview_episode::EpisodeResult, Calls) {
    let mesh = objview_render::bench::icosphere(2);
    let gt = sample_surface(&mesh, 5_000, 1);
    let settings = EpisodeSettings { record_timings: false, ..Default::default() };
    let vs = ViewSpace::builtin(space).unwrap();
    let scene = Arc::new(
        scene_from_parts("sphere", mesh, gt, "sampled".into(), &vs, space, &settings, None).unwrap(),
    );
    let calls = Arc::new(Mutex::new(vec![]));
    let mut p = MascvpPlanner::with_scorer(
        Box::new(Script { set, calls: calls.clone() }),
        0.3,
        TspSettings::default(),
    );
    assert_eq!(p.name(), "ma-scvp");
    let cands = Arc::new(ViewSet::resolve("tammes-128").unwrap().poses(3.0));
    let r =
        run_episode(scene, &mut p, &settings, Budget::Auto, 0, start_pose(3.0), cands, serde_json::json!({}))
            .unwrap();
    let c = calls.lock().unwrap().clone();
    (r, c)
}

/// (nearest view of the start pose, bootstrap view) in `space`, computed independently.
fn first_two(space: &str) -> (usize, Option<usize>) {
    let t = ViewSet::resolve("tammes-128").unwrap().poses(3.0);
    let s = start_pose(3.0);
    let near = nearest_view(&t, s.center).unwrap();
    let vs = ViewSpace::builtin(space).unwrap();
    let allowed: Vec<bool> =
        (0..128).map(|v| v != near && vs.is_feasible(&t[v]) && !same_pose(&t[v], &s)).collect();
    (near, bootstrap_view(&t, &allowed, &s))
}

#[test]
fn one_call_plan_executes_the_decoded_set_and_ends_with_plan_end() {
    let t = ViewSet::resolve("tammes-128").unwrap().poses(3.0);
    let (near, boot) = first_two("whole");
    let boot = boot.unwrap();
    let set: Vec<usize> = [5usize, 40, 90, near, boot].to_vec();
    let (r, calls) = episode("whole", set);
    assert_eq!(r.terminal_reason, "plan_end");
    assert_eq!(calls.len(), 1, "the network is called once");
    let mut want_vs = vec![near, boot];
    want_vs.sort_unstable();
    assert_eq!(calls[0].0, want_vs, "view state = nearest + bootstrap");
    assert!(calls[0].1 > 0);
    let moved: Vec<[f64; 7]> = r.visited_poses.iter().skip(1).copied().collect();
    assert_eq!(moved.len(), 4, "bootstrap + three decoded unvisited views");
    assert_eq!(moved[0], t[boot].to_array(), "the first move is the bootstrap view");
    let mut rest: Vec<usize> =
        moved[1..].iter().map(|m| (0..128).find(|&v| t[v].to_array() == *m).unwrap()).collect();
    rest.sort_unstable();
    assert_eq!(rest, vec![5, 40, 90], "visited and bootstrap views are not repeated");
    // The result line records the decision: nearest, bootstrap, decoded set, executed order
    // and its proven-shortest open path (no seconds).
    let plan = &r.planner_notes.as_ref().expect("planner notes")["plan"];
    assert_eq!(plan["nearest"], near);
    assert_eq!(plan["bootstrap"], boot);
    let mut decoded = vec![5usize, 40, 90, near, boot];
    decoded.sort_unstable();
    assert_eq!(plan["decoded"], serde_json::json!(decoded));
    let order: Vec<usize> =
        moved[1..].iter().map(|m| (0..128).find(|&v| t[v].to_array() == *m).unwrap()).collect();
    assert_eq!(plan["planned"], serde_json::json!(order));
    assert_eq!(plan["tsp"]["optimal"], true);
    assert!(plan["tsp"].get("seconds").is_none() && plan["stop"].is_null() && plan["tsp_error"].is_null());
}

#[test]
fn empty_decoded_set_ends_after_the_bootstrap() {
    let (r, calls) = episode("whole", vec![]);
    assert_eq!(r.terminal_reason, "plan_end");
    assert_eq!(calls.len(), 1);
    assert_eq!(r.visited_poses.len(), 2, "start + bootstrap");
    let plan = &r.planner_notes.as_ref().expect("planner notes")["plan"];
    assert_eq!(
        (plan["stop"].as_str(), plan["planned"].as_array().map(Vec::len)),
        (Some("plan_end"), Some(0))
    );
}

#[test]
fn all_infeasible_decoded_views_stop_with_candidate_exhausted() {
    let t = ViewSet::resolve("tammes-128").unwrap().poses(3.0);
    let quarter = ViewSpace::builtin("quarter").unwrap();
    let bad: Vec<usize> = (0..128).filter(|&v| !quarter.is_feasible(&t[v])).take(3).collect();
    let (_, boot) = first_two("quarter");
    let boot = boot.expect("the quarter has feasible tammes-128 views");
    let (r, calls) = episode("quarter", bad);
    assert_eq!(r.terminal_reason, "candidate_exhausted");
    assert_eq!(calls.len(), 1);
    assert_eq!(r.visited_poses.len(), 2);
    assert_eq!(r.visited_poses[1], t[boot].to_array());
    let plan = &r.planner_notes.as_ref().expect("planner notes")["plan"];
    assert_eq!(plan["stop"], "candidate_exhausted");
}
