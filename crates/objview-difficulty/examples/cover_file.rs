//! Solves a cover instance dumped by `objview-dataset`'s `dump_cover` example (first line
//! `views elements`, then one line of element ids per view) with both exact methods and prints
//! what each did. For solver investigations.
//!
//! Usage: `cargo run --release -p objview-difficulty --example cover_file -- FILE [time_limit_s]`

use objview_difficulty::{solve_min_cover, CoverMethod, CoverSettings};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let text = std::fs::read_to_string(&args[0]).expect("readable instance file");
    let limit: f64 = args.get(1).map_or(300.0, |s| s.parse().expect("numeric time limit"));
    let mut lines = text.lines();
    let n_elements: usize =
        lines.next().and_then(|l| l.split(' ').nth(1)).and_then(|s| s.parse().ok()).unwrap();
    let views: Vec<Vec<u64>> = lines
        .map(|l| {
            let mut bits = vec![0u64; n_elements.div_ceil(64)];
            for id in l.split(' ').filter(|s| !s.is_empty()) {
                let i: usize = id.parse().unwrap();
                bits[i / 64] |= 1 << (i % 64);
            }
            bits
        })
        .collect();
    for method in [CoverMethod::Auto, CoverMethod::Ilp] {
        let s = CoverSettings { method, time_limit_s: limit, ..Default::default() };
        let r = solve_min_cover(&views, &s).unwrap();
        println!(
            "{method}: status {:?} d_plan {:?} best {} bound {} LP {:.3} greedy {} reduced {}x{} forced {} \
             proven_by {} search {} nodes {:.2} s, total {:.2} s",
            r.status,
            r.d_plan,
            r.best_size,
            r.lower_bound,
            r.lp_bound,
            r.greedy_size,
            r.reduction.reduced_views,
            r.reduction.reduced_elements,
            r.reduction.forced_views.len(),
            r.proven_by,
            r.search_nodes,
            r.search_seconds,
            r.seconds
        );
    }
}
