//! Renderer benchmark on the built-in torus meshes: `cargo run --release -p objview-render
//! --example bench_render -- [triangles...] [--poses N] [--repeats R] [--only-single]`.
//! Prints one JSON line per mesh (see `objview_render::bench::RenderBenchResult`).

use objview_render::bench::{bench_mesh, bench_render, spiral_poses};

fn main() {
    let mut sizes = Vec::new();
    let (mut poses, mut repeats) = (16, 5);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--poses" => poses = args.next().and_then(|s| s.parse().ok()).expect("--poses N"),
            "--repeats" => repeats = args.next().and_then(|s| s.parse().ok()).expect("--repeats R"),
            s => sizes.push(s.parse::<usize>().expect("triangle count")),
        }
    }
    if sizes.is_empty() {
        sizes = vec![10_000, 100_000, 1_000_000];
    }
    for n in sizes {
        let mesh = bench_mesh(n);
        let r = bench_render(&mesh, &spiral_poses(poses, 3.0), repeats);
        println!("{}", serde_json::to_string(&r).expect("serializable"));
    }
}
