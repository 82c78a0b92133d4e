//! Load/sampling timings of the geometry I/O paths (ignored by default; run with
//! `cargo test -p objview-geom --release --test io_timing -- --ignored --nocapture`).
//! Each timing also checks its result, so a fast wrong answer fails.

use objview_geom::cloud::{read_cloud, sample_surface, write_pcd_binary, write_ply_points};
use objview_geom::io::load_mesh;
use objview_geom::normalize::{load_normalized, Normalization};
use std::path::Path;
use std::time::Instant;

/// A GLB holding an `n`×`n` grid (2·(n−1)² triangles, u32 indices), built by hand.
fn grid_glb(n: usize) -> Vec<u8> {
    let mut bin = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (x, y) = (i as f32 / (n - 1) as f32, j as f32 / (n - 1) as f32);
            for c in [x, y, (x * 7.0).sin() * 0.1] {
                bin.extend(c.to_le_bytes());
            }
        }
    }
    let pos_len = bin.len();
    let mut ntri = 0;
    for i in 0..n - 1 {
        for j in 0..n - 1 {
            let v = (i * n + j) as u32;
            for t in [[v, v + 1, v + n as u32], [v + 1, v + n as u32 + 1, v + n as u32]] {
                for k in t {
                    bin.extend(k.to_le_bytes());
                }
                ntri += 1;
            }
        }
    }
    let doc = serde_json::json!({
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "scale": [2, 2, 2]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": bin.len()}],
        "bufferViews": [{"buffer": 0, "byteLength": pos_len},
                        {"buffer": 0, "byteOffset": pos_len, "byteLength": bin.len() - pos_len}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": n * n, "type": "VEC3",
             "min": [0, 0, -0.1], "max": [1, 1, 0.1]},
            {"bufferView": 1, "componentType": 5125, "count": 3 * ntri, "type": "SCALAR"}]
    });
    let mut j = serde_json::to_vec(&doc).unwrap();
    while j.len() & 3 != 0 {
        j.push(b' ');
    }
    let total = 12 + 8 + j.len() + 8 + bin.len();
    let mut out = b"glTF".to_vec();
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((j.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(&j);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(&bin);
    out
}

#[test]
#[ignore]
fn timings() {
    let samples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/official/samples");
    if let Ok(entries) = std::fs::read_dir(&samples) {
        for e in entries {
            let p = e.unwrap().path();
            let t = Instant::now();
            let (m, _) = load_normalized(&p, Normalization::None).unwrap();
            println!(
                "load {}: {} tris, {:.1} ms",
                p.file_name().unwrap().to_string_lossy(),
                m.triangles.len(),
                t.elapsed().as_secs_f64() * 1e3
            );
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let glb = dir.path().join("grid.glb");
    std::fs::write(&glb, grid_glb(708)).unwrap();
    let t = Instant::now();
    let m = load_mesh(&glb).unwrap();
    println!(
        "load GLB grid: {} vertices, {} tris, {:.1} ms",
        m.positions.len(),
        m.triangles.len(),
        t.elapsed().as_secs_f64() * 1e3
    );
    assert_eq!(m.triangles.len(), 2 * 707 * 707);
    assert_eq!(m.positions[708 * 708 - 1][0], 2.0);

    let t = Instant::now();
    let pts = sample_surface(&m, 2_000_000, 0);
    println!("sample_surface 2M points: {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
    assert_eq!(pts.len(), 2_000_000);

    for name in ["c.pcd", "c.ply"] {
        let p = dir.path().join(name);
        let t = Instant::now();
        if name.ends_with("pcd") {
            write_pcd_binary(&p, &pts).unwrap();
        } else {
            write_ply_points(&p, &pts).unwrap();
        }
        let w = t.elapsed().as_secs_f64() * 1e3;
        let t = Instant::now();
        let back = read_cloud(&p).unwrap();
        println!("{name} 2M points: write {w:.1} ms, read {:.1} ms", t.elapsed().as_secs_f64() * 1e3);
        assert_eq!(back.len(), pts.len());
    }
}
