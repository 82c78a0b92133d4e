//! Regenerates the shipped `data/viewsets/tammes-N.txt` files with the Tammes optimizer:
//! `RAYON_NUM_THREADS=1 cargo run --release -p objview-views --example gen_viewsets -- OUTDIR [N ...]`
//! (without N: the saturation grid of SPEC §4 minus the two official sizes 128 and 360).

use std::path::PathBuf;
use std::time::Instant;

use objview_views::tammes::{best_known_deg, file_header, generate, DEFAULT_SEED};

/// The saturation grid of SPEC §4 without the two official sizes (128, 360).
const GRID: &[usize] =
    &[6, 8, 10, 12, 14, 16, 20, 24, 28, 32, 40, 48, 56, 64, 80, 96, 112, 144, 160, 180, 200, 270, 432, 492];

fn main() {
    let mut args = std::env::args().skip(1);
    let out = PathBuf::from(args.next().expect("usage: gen_viewsets OUTDIR [N ...]"));
    let ns: Vec<usize> = args.map(|a| a.parse().expect("N must be an integer")).collect();
    let ns = if ns.is_empty() { GRID.to_vec() } else { ns };
    for n in ns {
        let t0 = Instant::now();
        let vs = generate(n, DEFAULT_SEED);
        let secs = t0.elapsed().as_secs_f64();
        let a = vs.min_angle_deg().expect("n >= 2");
        let bk = best_known_deg(n);
        vs.write(&out.join(format!("tammes-{n}.txt")), &file_header(&vs, DEFAULT_SEED)).expect("write");
        println!(
            "n={n} min_angle_deg={a:.6} best_known={} ratio={} secs={secs:.1}",
            bk.map_or("-".into(), |b| format!("{b:.6}")),
            bk.map_or("-".into(), |b| format!("{:.5}", a / b))
        );
    }
}
