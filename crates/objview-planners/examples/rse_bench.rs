//! Benchmark of the RSE planners' two costs: inserting a depth frame into the 64³ occupancy
//! grid, and one planning step (scoring every remaining tammes-360 candidate with 128×128 rays).
//!
//! A synthetic object from the built-in pool (default: mug) is observed from the start view
//! (direction (1, 1, 1), radius 3) and then from the views RSE itself picks, as in an episode
//! (all threads). Every step is printed. After `views` observations, the planning step and the
//! insertion of the last frame are timed `reps` times each on one thread and on all threads,
//! and the medians are printed. Single-thread runs also report the worker's CPU time (Linux),
//! which on a shared machine separates the work itself from waiting for a core.
//!
//! Usage: `cargo run --profile ci -p objview-planners --example rse_bench -- [object] [views]
//! [reps]` (defaults: mug, 20 views, 5 repetitions).

use std::time::Instant;

use objview_geom::{synth, Pose};
use objview_planners::occupancy::{OccupancyGrid, OccupancySettings};
use objview_planners::rse::{select_rse, GainMap, GainScratch};
use objview_render::{Camera, Intrinsics};
use objview_views::ViewSet;

/// CPU time of the calling thread in seconds (Linux `/proc/thread-self/schedstat`).
fn thread_cpu_s() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: u64 = text.split_whitespace().next()?.parse().ok()?;
    Some(ns as f64 * 1e-9)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        f64::NAN
    } else {
        v[v.len() / 2]
    }
}

/// One planning step: condense the grid, score the remaining candidates, pick RSE's choice.
fn plan(grid: &OccupancyGrid, cameras: &[Camera], remaining: &[usize], stride: u32) -> (usize, f64) {
    let map = GainMap::new(grid);
    let cams: Vec<Camera> = remaining.iter().map(|&i| cameras[i]).collect();
    let gains = map.view_gains(&cams, stride);
    let k = select_rse(&gains).unwrap_or(0);
    (remaining[k], gains[k])
}

/// Runs `f` `reps` times in a pool of `threads` threads: median wall time, and with one thread
/// the median CPU time of the worker.
fn time_in_pool(
    threads: usize,
    reps: usize,
    mut f: impl FnMut() + Send,
) -> Result<(f64, Option<f64>), rayon::ThreadPoolBuildError> {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    for _ in 0..reps {
        let t = Instant::now();
        let c = pool.install(|| {
            let c0 = thread_cpu_s();
            f();
            c0.zip(thread_cpu_s()).map(|(a, b)| b - a)
        });
        wall.push(t.elapsed().as_secs_f64());
        if threads == 1 {
            cpu.extend(c);
        }
    }
    Ok((median(wall), (!cpu.is_empty()).then(|| median(cpu))))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let object = args.first().map_or("mug", |s| s.as_str());
    let views: usize = args.get(1).map_or(Ok(20), |s| s.parse())?;
    let reps: usize = args.get(2).map_or(Ok(5), |s| s.parse())?.max(1);
    let stride = 4;

    let mesh =
        synth::build(object, synth::Detail::DEFAULT).ok_or_else(|| format!("unknown object {object}"))?;
    let intr = Intrinsics::default();
    let candidates = ViewSet::resolve("tammes-360")?.poses(3.0);
    let cameras: Vec<Camera> = candidates.iter().map(|p| Camera::new(*p, intr)).collect();
    let mut visited = vec![false; candidates.len()];
    let mut grid = OccupancyGrid::new(OccupancySettings::default())?;
    let threads = rayon::current_num_threads();
    println!("object {object} ({} triangles), {views} views, {threads} threads", mesh.num_triangles());

    let mut pose = Pose::from_direction([1.0, 1.0, 1.0], 3.0);
    let (mut insert_times, mut step_times) = (Vec::new(), Vec::new());
    let mut last_frame = None;
    for step in 0..views.max(1) {
        let cam = Camera::new(pose, intr);
        let depth = objview_render::render(&mesh, &cam).depth;
        let before = grid.clone();
        let t = Instant::now();
        let stats = grid.insert_depth(&cam, &depth)?;
        insert_times.push(t.elapsed().as_secs_f64());
        last_frame = Some((before, cam, depth));
        for (i, c) in candidates.iter().enumerate() {
            if c.center == pose.center {
                visited[i] = true;
            }
        }
        let remaining: Vec<usize> = (0..candidates.len()).filter(|&i| !visited[i]).collect();
        if remaining.is_empty() {
            break;
        }
        let t = Instant::now();
        let (next, gain) = plan(&grid, &cameras, &remaining, stride);
        step_times.push(t.elapsed().as_secs_f64());
        let (f, u, o) = grid.state_counts();
        println!(
            "view {:3}: {:6} rays inserted in {:6.2} ms; free/unknown/occupied {f:6}/{u:6}/{o:5}; \
             step over {} candidates {:.3} s, best gain {gain:.1}",
            step + 1,
            stats.rays,
            insert_times[step] * 1e3,
            remaining.len(),
            step_times[step]
        );
        if step + 1 == views {
            break;
        }
        visited[next] = true;
        pose = candidates[next];
    }
    println!(
        "episode ({threads} threads): median insertion {:.2} ms/frame, median planning step {:.3} s",
        median(insert_times) * 1e3,
        median(step_times)
    );

    let remaining: Vec<usize> = (0..candidates.len()).filter(|&i| !visited[i]).collect();
    let Some((before, cam, depth)) = last_frame else {
        return Ok(());
    };
    // What the filter leaves to walk (averages over the remaining candidates, not timed).
    let map = GainMap::new(&grid);
    let mut scratch = GainScratch::default();
    let (mut hits, mut walked) = (0usize, 0usize);
    for &i in &remaining {
        map.view_gain_with(&cameras[i], stride, &mut scratch);
        hits += scratch.first_hits();
        walked += scratch.walked();
    }
    let per = |x: usize| x as f64 / remaining.len().max(1) as f64;

    println!(
        "after {views} views: shell {} voxels; per candidate {:.0} rays hit the shell, {:.0} walked",
        map.shell_len(),
        per(hits),
        per(walked)
    );
    for n in [1, threads] {
        let (plan_wall, plan_cpu) = time_in_pool(n, reps, || {
            plan(&grid, &cameras, &remaining, stride);
        })?;
        let (ins_wall, ins_cpu) = time_in_pool(n, reps, || {
            let mut g = before.clone();
            // A frame of the right size cannot fail.
            let _ = g.insert_depth(&cam, &depth);
        })?;
        let cpu = |c: Option<f64>, scale: f64, unit: &str| {
            c.map_or(String::new(), |c| format!(" (CPU {:.3} {unit})", c * scale))
        };
        println!(
            "after {views} views, {n} thread(s): planning step {:.3} s{} over {} candidates; \
             insertion {:.2} ms{} per frame",
            plan_wall,
            cpu(plan_cpu, 1.0, "s"),
            remaining.len(),
            ins_wall * 1e3,
            cpu(ins_cpu, 1e3, "ms")
        );
    }
    Ok(())
}
