//! The observed cloud's back-projection ([`Frame::observed_points_into`]) on its own, against
//! its definition — every hit pixel through [`Camera::unproject`] — in the same run:
//! `cargo run --release -p objview-render --example prof_unproject [-- TRIANGLES REPEATS]`.
//!
//! Renders the built-in mug at ~TRIANGLES (default 100 000) from 16 spiral poses at radius 3
//! (512×512), checks that both give the same points bit for bit, and prints the median time per
//! frame of each and their ratio.

use objview_render::bench::spiral_poses;
use objview_render::frame::NO_HIT;
use objview_render::{Camera, Frame, Intrinsics, Renderer};
use std::time::Instant;

/// Every hit pixel through [`Camera::unproject`], in row-major order (the definition).
fn per_pixel(frame: &Frame, out: &mut Vec<[f64; 3]>) {
    out.clear();
    let w = frame.width();
    for (i, (&z, &t)) in frame.depth.iter().zip(&frame.triangle).enumerate() {
        if t != NO_HIT {
            let (u, v) = (i as u32 % w, i as u32 / w);
            out.push(frame.camera.unproject(u, v, z as f64));
        }
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let a: Vec<usize> = std::env::args().skip(1).map(|s| s.parse().expect("a number")).collect();
    let triangles = a.first().copied().unwrap_or(100_000);
    let repeats = a.get(1).copied().unwrap_or(20);
    let mesh = objview_geom::synth::build_with_triangles("mug", triangles);
    let (mesh, _) = objview_geom::normalize::normalize(
        mesh,
        objview_geom::normalize::Normalization::Unit,
        std::path::Path::new("mug"),
    )
    .expect("normalize");
    let mut renderer = Renderer::new();
    let frames: Vec<Frame> = spiral_poses(16, 3.0)
        .into_iter()
        .map(|p| {
            let cam = Camera::new(p, Intrinsics::default());
            let mut f = Frame::empty(cam);
            renderer.render_into(&mesh, &cam, &mut f);
            f
        })
        .collect();
    let (mut a_out, mut b_out) = (Vec::new(), Vec::new());
    for f in &frames {
        f.observed_points_into(&mut a_out);
        per_pixel(f, &mut b_out);
        let bits = |v: &[[f64; 3]]| v.iter().map(|p| p.map(f64::to_bits)).collect::<Vec<_>>();
        assert_eq!(bits(&a_out), bits(&b_out), "the row scan differs from unproject");
    }
    let hits: usize = frames.iter().map(Frame::num_hits).sum::<usize>() / frames.len();
    let (mut rows, mut pixels) = (Vec::new(), Vec::new());
    for _ in 0..repeats {
        for f in &frames {
            let t = Instant::now();
            f.observed_points_into(&mut a_out);
            rows.push(t.elapsed().as_secs_f64() * 1e3);
            std::hint::black_box(&a_out);
            let t = Instant::now();
            per_pixel(f, &mut b_out);
            pixels.push(t.elapsed().as_secs_f64() * 1e3);
            std::hint::black_box(&b_out);
        }
    }
    let (r, p) = (median(rows), median(pixels));
    println!(
        "prof_unproject: mug {} triangles, 16 views of 512×512, {hits} hits per view: observed_points_into median {r:.3} ms/frame, per-pixel unproject {p:.3} ms/frame ({:.2}× faster)",
        mesh.triangles.len(),
        p / r
    );
}
