//! `objview bench annotate` and `objview bench stability`: settings from the arguments and
//! printing; the measurements are [`objview_runs::bench::annotate`].

use anyhow::Result;
use objview_runs::bench::annotate::{
    AnnotateBench, AnnotateBenchSettings, StabilityBench, StabilitySettings,
};

use crate::bench::{AnnotateBenchArgs, StabilityArgs};

pub fn bench_annotate(a: AnnotateBenchArgs) -> Result<()> {
    let host = crate::bench::announce_host();
    let bench = AnnotateBench::new(AnnotateBenchSettings {
        objects: a.objects.clone(),
        sizes: a.sizes.clone(),
        repeats: a.repeats,
    })?;
    println!(
        "objview bench annotate: {} views per object (26 tammes-N sets), exact d_plan; median of {} runs; \
         seconds per stage",
        bench.total_views(),
        bench.repeats()
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
    let report = bench.run(&mut |r| {
        let st = &r.stages;
        println!(
            "{:<8} {:>8} {:>7} {:>7} {:>6.3} {:>6.3} {:>7.3} {:>10.3} {:>6.4} {:>7.3} {:>8.3} {:>7} {:>9}",
            r.object,
            r.triangles,
            r.surface_voxels,
            r.threads,
            st.load,
            st.ground_truth,
            st.voxelize,
            st.visibility,
            st.fit,
            st.cover,
            r.total_seconds,
            r.d_plan.map_or_else(|| r.d_plan_status.clone(), |d| d.to_string()),
            r.peak_rss_bytes.map_or("-".into(), |p| format!(
                "{:.0}{}",
                p as f64 / 1048576.0,
                if r.peak_is_per_configuration { "" } else { "*" }
            )),
        );
    })?;
    println!(
        "stages: load = read + normalize mesh; gt = sample cloud; voxel = S_gt; visibility = O(v) of all {} views \
         and the 26 unions; fit = lognormal fit + N*; cover = reductions + LP + exact d_plan",
        bench.total_views()
    );
    if let Some(p) = &a.json {
        crate::bench::write_figures(p, report.to_json(), &host)?;
        println!("figures -> {}", p.display());
    }
    Ok(())
}

pub fn bench_stability(a: StabilityArgs) -> Result<()> {
    let bench = StabilityBench::new(StabilitySettings {
        seeds: a.seeds.clone(),
        objects: a.objects.clone(),
        threads: a.threads,
        time_limit: a.time_limit,
    })?;
    eprintln!(
        "bench stability: {} objects x {} seeds ({} annotations)",
        bench.objects().len(),
        a.seeds.len(),
        bench.annotations()
    );
    let bar = crate::common::progress(bench.annotations() as u64);
    let report = bench.run(&|| bar.inc(1));
    bar.finish_and_clear();

    println!(
        "objview bench stability: seeds {:?}, sampled ground-truth clouds (SPEC §1 count rule)",
        a.seeds
    );
    println!(
        "{:<16} {:>20} {:>8} {:>20} {:>7} {:>13} {:>8}",
        "object", "d_plan per seed", "spread", "d_sat per seed", "spread", "r_vis range", "buckets"
    );
    for row in &report.rows {
        let name = &row.object;
        let f = match &row.figures {
            Ok(f) => f,
            Err(e) => {
                println!("{name:<16} failed: {e}");
                continue;
            }
        };
        let fmt = |v: Vec<String>| v.join(",");
        println!(
            "{:<16} {:>20} {:>8} {:>20} {:>7} {:>6.3}-{:<6.3} {:>8}",
            name,
            fmt(f.d_plan.iter().map(|d| d.map_or("?".into(), |d| d.to_string())).collect()),
            f.d_plan_spread,
            fmt(f.d_sat.iter().map(|d| d.to_string()).collect()),
            f.d_sat_spread,
            f.r_vis_min,
            f.r_vis_max,
            f.d_plan_buckets
        );
    }
    let s = &report.summary;
    println!(
        "summary: {} objects; d_plan differs across seeds for {}, changes d_plan bucket (width 5) for \
         {}; d_sat differs for {} (median spread {:.0}, max {:.0}); {} failed",
        s.objects,
        s.d_plan_moved,
        s.d_plan_bucket_changed,
        s.d_sat_moved,
        s.d_sat_spread_median,
        s.d_sat_spread_max,
        s.failed
    );
    if let Some(p) = &a.json {
        crate::common::write_json(p, &report.to_json())?;
        println!("figures -> {}", p.display());
    }
    Ok(())
}
