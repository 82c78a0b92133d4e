//! `objview feasibility`: evaluates a view space (built-in `whole|hemi|quarter|eighth` or a
//! custom rule file, SPEC §5) on explicit poses and/or every direction of a view set, and says
//! which rule each infeasible pose violates.

use anyhow::{ensure, Result};
use clap::Parser;
use objview_geom::pose::VIEW_RADIUS;
use objview_geom::Pose;
use objview_views::{ViewSet, ViewSpace};

#[derive(Parser)]
pub struct Args {
    /// View space: `whole`, `hemi`, `quarter`, `eighth`, or a rule-file path.
    pub space: String,
    /// A pose `cx,cy,cz,lx,ly,lz,roll` (object frame, radians); repeatable.
    #[arg(long, allow_hyphen_values = true, value_parser = crate::render::parse_pose)]
    pub pose: Vec<Pose>,
    /// A view set (file or built-in `tammes-N`); each direction d is the pose [3d, 0,0,0, 0].
    #[arg(long)]
    pub views: Option<String>,
    /// Print only the summary line, not one line per pose.
    #[arg(long)]
    pub quiet: bool,
}

pub fn run(a: Args) -> Result<()> {
    let space = ViewSpace::resolve(&a.space)?;
    let mut poses = a.pose.clone();
    if let Some(v) = &a.views {
        poses.extend(ViewSet::resolve(v)?.poses(VIEW_RADIUS));
    }
    ensure!(!poses.is_empty(), "nothing to evaluate: give --pose and/or --views");
    let mask = space.feasible_mask(&poses);
    if !a.quiet {
        for (i, (p, ok)) in poses.iter().zip(&mask).enumerate() {
            let c = p.to_array();
            let text = c.iter().map(|x| format!("{x:.6}")).collect::<Vec<_>>().join(",");
            match (ok, space.explain(p)) {
                (true, _) => println!("{i} {text} feasible"),
                (false, why) => println!("{i} {text} infeasible: {}", why.unwrap_or_default()),
            }
        }
    }
    println!("space={} feasible={} of {}", space.name, mask.iter().filter(|&&b| b).count(), mask.len());
    Ok(())
}
