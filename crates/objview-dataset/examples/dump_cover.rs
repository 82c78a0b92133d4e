//! Writes the tammes-128 cover instance of a mesh (per view: the S_gt indices of O(v)) as text:
//! `views elements` then one line per view with its element ids. For solver investigations.
//!
//! Usage: `cargo run --release -p objview-dataset --example dump_cover -- MESH OUT.txt`
use objview_dataset::annotate::{GridViews, PLANNING_VIEWS};
use objview_geom::cloud::{cloud_count, sample_surface};
use objview_geom::normalize::{load_normalized, Normalization};
use objview_voxel::{bitset_to_indices, Visibility, VisibilityMode, VoxelSet};
use std::io::Write;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (mesh, _) = load_normalized(std::path::Path::new(&args[0]), Normalization::Unit).unwrap();
    let pts = sample_surface(&mesh, cloud_count(mesh.surface_area()), 0);
    let set = VoxelSet::from_points(&pts, 0.02).unwrap();
    let views = GridViews::new(3.0).unwrap();
    let vis = Visibility::new(&set, &mesh, VisibilityMode::Inverse);
    let bits = vis.observe_all_bitsets(views.planning());
    let mut f = std::io::BufWriter::new(std::fs::File::create(&args[1]).unwrap());
    writeln!(f, "{} {}", PLANNING_VIEWS, set.len()).unwrap();
    for b in &bits {
        let ids: Vec<String> = bitset_to_indices(b).iter().map(|i| i.to_string()).collect();
        writeln!(f, "{}", ids.join(" ")).unwrap();
    }
}
