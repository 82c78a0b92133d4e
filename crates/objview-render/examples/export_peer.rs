//! Writes the inputs of `bench/peer_open3d.py` for a built-in benchmark mesh, and objview's
//! own depth of the first pose for comparison:
//! `export_peer N OUTDIR` → OUTDIR/mesh.obj, OUTDIR/poses.txt (16 spiral poses, radius 3),
//! OUTDIR/objview_depth.npy (512×512 f32, first pose).

use objview_render::bench::{bench_mesh, spiral_poses};
use objview_render::{Camera, Intrinsics};
use std::io::Write;
use std::path::PathBuf;

fn main() -> std::io::Result<()> {
    let mut args = std::env::args().skip(1);
    let n: usize = args.next().and_then(|s| s.parse().ok()).expect("usage: export_peer N OUTDIR");
    let dir = PathBuf::from(args.next().expect("usage: export_peer N OUTDIR"));
    std::fs::create_dir_all(&dir)?;
    let mesh = bench_mesh(n);
    let mut obj = std::io::BufWriter::new(std::fs::File::create(dir.join("mesh.obj"))?);
    // `{}` prints the shortest decimal that round-trips the f64.
    for p in &mesh.positions {
        writeln!(obj, "v {} {} {}", p[0], p[1], p[2])?;
    }
    for t in &mesh.triangles {
        writeln!(obj, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1)?;
    }
    obj.flush()?;
    let poses = spiral_poses(16, 3.0);
    let mut pf = std::fs::File::create(dir.join("poses.txt"))?;
    for p in &poses {
        let a = p.to_array();
        writeln!(pf, "{} {} {} {} {} {} {}", a[0], a[1], a[2], a[3], a[4], a[5], a[6])?;
    }
    let f = objview_render::render(&mesh, &Camera::new(poses[0], Intrinsics::default()));
    objview_geom::npy::write_npy_f32(&dir.join("objview_depth.npy"), &[512, 512], &f.depth)
        .expect("writing npy");
    eprintln!("{} triangles, first pose {} hits -> {}", mesh.num_triangles(), f.num_hits(), dir.display());
    Ok(())
}
