//! `objview bench annotate` and `objview bench stability`: the cost of the difficulty annotation
//! per stage, and how much its results depend on the ground-truth sampling seed.

use std::path::Path;

use anyhow::{Context, Result};
use objview_dataset::annotate::{annotate_object, AnnotateSettings, Annotation, GridViews, StageTimings};
use objview_dataset::ObjectRef;
use objview_geom::synth;
use rayon::prelude::*;
use serde_json::json;

use crate::bench::{AnnotateBenchArgs, StabilityArgs};

/// Peak resident memory of this process (VmHWM, bytes), if the OS reports it.
fn peak_rss() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Resets the peak (Linux `clear_refs` 5); false where unsupported.
fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

fn median(mut v: Vec<f64>) -> f64 {
    objview_geom::stats::median(&mut v)
}

/// Writes built-in object `name` with about `triangles` triangles (0: its default detail) as OBJ.
fn write_object(name: &str, triangles: usize, dir: &Path) -> Result<ObjectRef> {
    let obj = synth::find(name)
        .with_context(|| format!("no built-in object named {name:?} (see `objview objects list`)"))?;
    let mesh = if triangles == 0 {
        obj.build(synth::Detail::default())
    } else {
        obj.build_with_triangles(triangles)
    };
    let path = dir.join(format!("{name}.obj"));
    objview_geom::write::write_obj(&path, &mesh)?;
    Ok(ObjectRef::from_mesh(&path))
}

fn stage_medians(runs: &[Annotation]) -> StageTimings {
    let m = |f: fn(&StageTimings) -> f64| median(runs.iter().map(|r| f(&r.timings)).collect());
    StageTimings {
        load: m(|t| t.load),
        ground_truth: m(|t| t.ground_truth),
        voxelize: m(|t| t.voxelize),
        visibility: m(|t| t.visibility),
        fit: m(|t| t.fit),
        cover: m(|t| t.cover),
        cover_lock_wait: m(|t| t.cover_lock_wait),
    }
}

pub fn bench_annotate(a: AnnotateBenchArgs) -> Result<()> {
    let settings = AnnotateSettings::default();
    let views = GridViews::new(settings.view_radius)?;
    let settings_json = objview_runs::provenance::settings("bench annotate", settings.to_json());
    let all = std::thread::available_parallelism().map_or(1, |n| n.get());
    let dir = tempfile::tempdir()?;
    let repeats = a.repeats.max(1);
    println!(
        "objview bench annotate: {} views per object (26 tammes-N sets), exact d_plan; median of {repeats} runs; \
         seconds per stage",
        views.total_views()
    );
    println!(
        "{:<8} {:>8} {:>7} {:>7} {:>6} {:>6} {:>7} {:>10} {:>6} {:>7} {:>8} {:>7} {:>9}",
        "object",
        "tris",
        "|S_gt|",
        "threads",
        "load",
        "gt",
        "voxel",
        "visibility",
        "fit",
        "cover",
        "total",
        "d_plan",
        "peak MiB"
    );
    let mut rows = Vec::new();
    for name in &a.objects {
        for &size in &a.sizes {
            let obj = write_object(name, size, dir.path())?;
            for threads in [1, all] {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
                let reset = reset_peak_rss();
                let mut runs = Vec::with_capacity(repeats);
                for _ in 0..repeats {
                    runs.push(pool.install(|| annotate_object(&obj, &settings, &views, &settings_json))?);
                }
                let peak = peak_rss();
                let st = stage_medians(&runs);
                let total = median(runs.iter().map(|r| r.seconds).collect());
                let r = &runs[0];
                println!(
                    "{:<8} {:>8} {:>7} {:>7} {:>6.3} {:>6.3} {:>7.3} {:>10.3} {:>6.4} {:>7.3} {:>8.3} {:>7} {:>9}",
                    name,
                    r.faces,
                    r.surface_voxels,
                    threads,
                    st.load,
                    st.ground_truth,
                    st.voxelize,
                    st.visibility,
                    st.fit,
                    st.cover,
                    total,
                    r.d_plan.map_or_else(|| r.d_plan_status.clone(), |d| d.to_string()),
                    peak.map_or("-".into(), |p| format!("{:.0}{}", p as f64 / 1048576.0, if reset { "" } else { "*" })),
                );
                rows.push(json!({
                    "object": name, "triangles": r.faces, "surface_voxels": r.surface_voxels,
                    "threads": threads, "median_stage_seconds": st, "median_total_seconds": total,
                    "d_plan": r.d_plan, "d_plan_status": r.d_plan_status, "proven_by": r.d_plan_proven_by, "search_nodes": r.search_nodes,
                    "peak_rss_bytes": peak, "peak_is_per_configuration": reset,
                }));
            }
        }
    }
    println!(
        "stages: load = read + normalize mesh; gt = sample cloud; voxel = S_gt; visibility = O(v) of all {} views \
         and the 26 unions; fit = lognormal fit + N*; cover = reductions + LP + exact d_plan",
        views.total_views()
    );
    if let Some(p) = &a.json {
        crate::common::write_json(p, &json!({"settings": settings_json, "rows": rows}))?;
        println!("figures -> {}", p.display());
    }
    Ok(())
}

pub fn bench_stability(a: StabilityArgs) -> Result<()> {
    anyhow::ensure!(!a.seeds.is_empty(), "--seeds: give at least one seed");
    let names: Vec<String> = if a.objects.is_empty() {
        synth::catalog().iter().map(|o| o.name.to_string()).collect()
    } else {
        a.objects.clone()
    };
    let dir = tempfile::tempdir()?;
    let objects: Vec<ObjectRef> =
        names.iter().map(|n| write_object(n, 0, dir.path())).collect::<Result<_>>()?;
    let mut base = AnnotateSettings::default();
    base.cover.time_limit_s = a.time_limit;
    base.validate()?;
    let views = GridViews::new(base.view_radius)?;
    let threads = a.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads.max(1)).build()?;
    let jobs: Vec<(usize, u64)> =
        (0..objects.len()).flat_map(|i| a.seeds.iter().map(move |&s| (i, s))).collect();
    eprintln!(
        "bench stability: {} objects x {} seeds ({} annotations)",
        objects.len(),
        a.seeds.len(),
        jobs.len()
    );
    let bar = crate::common::progress(jobs.len() as u64);
    let results: Vec<Result<Annotation, String>> = pool.install(|| {
        jobs.par_iter()
            .map(|&(i, seed)| {
                let s = AnnotateSettings { gt_seed: seed, ..base.clone() };
                let sj = objview_runs::provenance::settings("bench stability", s.to_json());
                let r = annotate_object(&objects[i], &s, &views, &sj).map_err(|e| e.to_string());
                bar.inc(1);
                r
            })
            .collect()
    });
    bar.finish_and_clear();

    println!(
        "objview bench stability: seeds {:?}, sampled ground-truth clouds (SPEC §1 count rule)",
        a.seeds
    );
    println!(
        "{:<16} {:>20} {:>8} {:>20} {:>7} {:>13} {:>8}",
        "object", "d_plan per seed", "spread", "d_sat per seed", "spread", "r_vis range", "buckets"
    );
    let (mut moved, mut bucket_changed, mut dsat_moved, mut failed) = (0, 0, 0, 0);
    let mut dsat_spreads = Vec::new();
    let mut rows = Vec::new();
    let k = a.seeds.len();
    for (i, name) in names.iter().enumerate() {
        let rs = &results[i * k..(i + 1) * k];
        if let Some(Err(e)) = rs.iter().find(|r| r.is_err()) {
            println!("{name:<16} failed: {e}");
            failed += 1;
            continue;
        }
        let rs: Vec<&Annotation> = rs.iter().map(|r| r.as_ref().expect("checked")).collect();
        let dp: Vec<Option<usize>> = rs.iter().map(|r| r.d_plan).collect();
        let ds: Vec<usize> = rs.iter().map(|r| r.d_sat).collect();
        let rv: Vec<f64> = rs.iter().map(|r| r.r_vis).collect();
        let solved: Vec<usize> = dp.iter().flatten().copied().collect();
        let dp_spread = solved.iter().max().zip(solved.iter().min()).map_or(0, |(x, y)| x - y);
        let buckets: std::collections::BTreeSet<usize> =
            solved.iter().filter_map(|&d| objview_pool::split::bucket_of(d)).collect();
        let ds_spread = ds.iter().max().unwrap() - ds.iter().min().unwrap();
        let (rv_min, rv_max) = rv.iter().fold((f64::MAX, f64::MIN), |(lo, hi), &x| (lo.min(x), hi.max(x)));
        moved += usize::from(dp_spread > 0);
        bucket_changed += usize::from(buckets.len() > 1);
        dsat_moved += usize::from(ds_spread > 0);
        dsat_spreads.push(ds_spread as f64);
        let fmt = |v: Vec<String>| v.join(",");
        println!(
            "{:<16} {:>20} {:>8} {:>20} {:>7} {:>6.3}-{:<6.3} {:>8}",
            name,
            fmt(dp.iter().map(|d| d.map_or("?".into(), |d| d.to_string())).collect()),
            dp_spread,
            fmt(ds.iter().map(|d| d.to_string()).collect()),
            ds_spread,
            rv_min,
            rv_max,
            buckets.len()
        );
        rows.push(json!({"object": name, "d_plan": dp, "d_sat": ds, "r_vis": rv,
            "d_plan_spread": dp_spread, "d_sat_spread": ds_spread, "d_plan_buckets": buckets.len()}));
    }
    let n = names.len() - failed;
    println!(
        "summary: {n} objects; d_plan differs across seeds for {moved}, changes d_plan bucket (width 5) for \
         {bucket_changed}; d_sat differs for {dsat_moved} (median spread {:.0}, max {:.0}); {failed} failed",
        median(dsat_spreads.clone()),
        dsat_spreads.iter().cloned().fold(0.0, f64::max)
    );
    if let Some(p) = &a.json {
        let settings = objview_runs::provenance::settings(
            "bench stability",
            json!({"seeds": a.seeds, "annotate": base.to_json()}),
        );
        crate::common::write_json(
            p,
            &json!({"settings": settings, "objects": rows,
            "summary": {"objects": n, "d_plan_moved": moved, "d_plan_bucket_changed": bucket_changed,
                        "d_sat_moved": dsat_moved, "failed": failed}}),
        )?;
        println!("figures -> {}", p.display());
    }
    Ok(())
}
