//! Benchmark of the `oracle` planner's set-up: for every tammes-128 candidate, render the view,
//! fuse it at the oracle's voxel (`frame_centroids`) and mark the observable-reference points
//! within τ of it (`Targets::mark_within`) — the per-candidate coverage bitsets that the
//! oracle's greedy choice reads. This set-up is most of an oracle episode's planning time
//! (the demo's slow-saturation diagnostic runs it on every object).
//!
//! A built-in object at the default detail (default: ball-in-shell) with its sampled ground
//! truth and observable reference (view space `whole`) is prepared once; then the three stages
//! are timed per candidate on one thread, `reps` rounds, and their medians (per candidate,
//! summed over the candidates) are printed with a checksum of the bitsets, which a change of
//! `mark_within` must keep.
//!
//! Usage: `cargo run --release -p objview-planners --example oracle_bench -- [object] [reps]`
//! (defaults: ball-in-shell, 3 rounds).

use std::time::Instant;

use objview_episode::fusion::frame_centroids;
use objview_episode::{scene_domain, scene_from_parts, EpisodeSettings};
use objview_geom::normalize::{normalize, Normalization};
use objview_geom::stats::median;
use objview_geom::synth;
use objview_render::{Camera, Frame, Intrinsics, Renderer};
use objview_views::{ViewSet, ViewSpace};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let object = args.first().map_or("ball-in-shell", |s| s.as_str());
    let reps: usize = args.get(1).map_or(Ok(3), |s| s.parse())?.max(1);
    let (tau, voxel) = (0.01, 0.005);

    let mesh =
        synth::build(object, synth::Detail::DEFAULT).ok_or_else(|| format!("unknown object {object}"))?;
    let (mesh, transform) = normalize(mesh, Normalization::Unit, std::path::Path::new(object))?;
    let gt = objview_geom::cloud::ground_truth(&mesh, &transform, None)?;
    let space = ViewSpace::builtin("whole").ok_or("no view space whole")?;
    let settings = EpisodeSettings::default();
    let t = Instant::now();
    let scene = scene_from_parts(object, mesh, gt.points, gt.source, &space, "whole", &settings, None)?;
    let targets = scene.reference_targets()?;
    println!(
        "{object}: {} triangles, {} GT points, {} reference points (scene {:.2} s)",
        scene.mesh.triangles.len(),
        scene.gt.len(),
        targets.len(),
        t.elapsed().as_secs_f64()
    );
    let domain = scene_domain(&scene.mesh, &scene.reference.points, voxel);
    let cameras: Vec<Camera> = ViewSet::resolve("tammes-128")?
        .poses(settings.view_radius)
        .iter()
        .map(|p| Camera::new(*p, Intrinsics::default()))
        .collect();
    let words = targets.len().div_ceil(64);
    let mut renderer = Renderer::new();
    let (mut render, mut fuse, mut mark) = (Vec::new(), Vec::new(), Vec::new());
    let mut checksum = 0u64;
    let mut marked = 0u64;
    for round in 0..reps {
        let (mut r_s, mut f_s, mut m_s) = (0.0, 0.0, 0.0);
        let mut sum = 0xcbf2_9ce4_8422_2325u64;
        let mut count = 0u64;
        for cam in &cameras {
            let t = Instant::now();
            let mut frame = Frame::empty(*cam);
            renderer.render_into(&scene.mesh, cam, &mut frame);
            let pts = frame.observed_points();
            r_s += t.elapsed().as_secs_f64();
            let t = Instant::now();
            let fused = frame_centroids(&domain, &pts);
            f_s += t.elapsed().as_secs_f64();
            let t = Instant::now();
            let mut bits = vec![0u64; words];
            targets.mark_within(&fused, tau, &mut bits);
            m_s += t.elapsed().as_secs_f64();
            for &w in &bits {
                sum = (sum ^ w).wrapping_mul(0x0000_0100_0000_01b3);
                count += w.count_ones() as u64;
            }
        }
        if round == 0 {
            (checksum, marked) = (sum, count);
        } else {
            assert_eq!((sum, count), (checksum, marked), "the bitsets changed between rounds");
        }
        render.push(r_s);
        fuse.push(f_s);
        mark.push(m_s);
    }
    let n = cameras.len() as f64;
    let (r, f, m) = (median(&mut render), median(&mut fuse), median(&mut mark));
    println!(
        "{} candidates, one thread, median of {reps} rounds: render {:.2} ms, fuse {:.2} ms, mark_within {:.2} ms per candidate; set-up {:.2} s in all",
        cameras.len(),
        1e3 * r / n,
        1e3 * f / n,
        1e3 * m / n,
        r + f + m
    );
    println!("bitsets: {marked} marks, checksum {checksum:016x}");
    Ok(())
}
