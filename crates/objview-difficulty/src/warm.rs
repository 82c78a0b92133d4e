//! HiGHS integer solves from a warm start, with the returned solution checked against the
//! objective HiGHS reports — shared by every exact solver of the workspace that hands HiGHS a
//! start (the set cover of d_plan and of `completion-scp`, the max coverage of
//! `completion-mcp`, the exact open path).
//!
//! Why: HiGHS (the version `highs-sys` 1.16 builds) can report `Optimal` with the objective of
//! its optimum while the solution it returns is still the warm start. On a 15-view, 14-element
//! set cover that presolve settles (the test below, taken from a `completion-scp` plan) it
//! reports objective 6 and returns the 7-view start, and the caller took those 7 views for a
//! proven minimum. [`solve_from`] compares the returned solution's objective, computed from the
//! caller's column costs, with the reported one. When they disagree on an `Optimal` run it
//! solves again without the start (presolve-settled runs are instant); a solution that still
//! disagrees, or one from a run stopped otherwise, is withheld, so no caller can take it for
//! the solver's.

use highs::{HighsModelStatus, HighsSolutionStatus, Model, SolvedModel};

/// Relative tolerance of the objective check (HiGHS's own feasibility tolerances are ~1e-7
/// absolute on 0/1 values; costs here are view counts, voxel weights and path lengths).
const OBJECTIVE_TOLERANCE: f64 = 1e-6;

/// A MIP solved by [`solve_from`].
pub struct WarmSolve {
    /// The solved model (status, objective, bounds).
    pub solved: SolvedModel,
    /// The column values of HiGHS's solution, when it has a feasible one whose objective is the
    /// objective HiGHS reports.
    pub columns: Option<Vec<f64>>,
    /// Whether the first solution disagreed with its reported objective, so the model was
    /// solved again without the warm start.
    pub restarted: bool,
}

impl WarmSolve {
    /// The columns at 1 (value > 0.5) among the first `among` columns of the checked solution
    /// (the 0/1 decision columns of a model that lists them first), when there is one.
    pub fn chosen(&self, among: usize) -> Option<Vec<usize>> {
        let values = self.columns.as_ref()?;
        Some(values[..among].iter().enumerate().filter(|(_, &x)| x > 0.5).map(|(c, _)| c).collect())
    }
}

/// The columns of `solved`'s solution, when feasible and consistent with its objective
/// (Σ `costs` · x within [`OBJECTIVE_TOLERANCE`]).
fn consistent_columns(solved: &SolvedModel, costs: &[f64]) -> Option<Vec<f64>> {
    if solved.primal_solution_status() != HighsSolutionStatus::Feasible {
        return None;
    }
    let columns = solved.get_solution().columns().to_vec();
    let value: f64 = columns.iter().zip(costs).map(|(x, c)| x * c).sum();
    let reported = solved.objective_value();
    ((value - reported).abs() <= OBJECTIVE_TOLERANCE * reported.abs().max(1.0)).then_some(columns)
}

/// Solves the model `build` makes (an integer program whose objective is Σ `costs[j]` ·
/// x_j, no offset) from the warm start `start` (column values; a start HiGHS rejects is
/// harmless), checking the returned solution as the module docs say. `build` is called again
/// for the second solve, so it must make the same model.
pub fn solve_from(
    build: impl Fn() -> Result<Model, String>,
    start: &[f64],
    costs: &[f64],
) -> Result<WarmSolve, String> {
    let mut model = build()?;
    let _ = model.try_set_solution(Some(start), None, None, None);
    let solved = model.try_solve().map_err(|s| format!("HiGHS run failed: {s:?}"))?;
    let columns = consistent_columns(&solved, costs);
    let feasible = solved.primal_solution_status() == HighsSolutionStatus::Feasible;
    if columns.is_some() || !feasible || solved.status() != HighsModelStatus::Optimal {
        return Ok(WarmSolve { solved, columns, restarted: false });
    }
    let solved = build()?.try_solve().map_err(|s| format!("HiGHS run failed: {s:?}"))?;
    let columns = consistent_columns(&solved, costs);
    Ok(WarmSolve { solved, columns, restarted: true })
}

#[cfg(test)]
mod tests {
    use super::*;
    use highs::{ColProblem, Sense};

    /// The reduced set-cover instance of a `completion-scp` plan (tube-bundle's neighbour in
    /// procedural pool 2): 15 views (rows they cover), 14 elements, minimum cover 6 views
    /// (equal to its LP bound), and the reduced greedy cover of 7 views that was the start.
    const VIEWS: [&[usize]; 15] = [
        &[4, 13],
        &[6, 10, 13],
        &[3, 5],
        &[5, 10],
        &[2, 12],
        &[8, 9],
        &[1, 3, 11],
        &[0, 6, 7],
        &[5, 12],
        &[2, 10],
        &[9, 11],
        &[1, 9],
        &[8, 12],
        &[0, 13],
        &[4, 7],
    ];
    const START: [usize; 7] = [0, 1, 2, 4, 5, 6, 7];

    fn cover_model() -> Result<Model, String> {
        let mut pb = ColProblem::new();
        let rows: Vec<_> = (0..14).map(|_| pb.add_row(1.0..)).collect();
        for v in VIEWS {
            pb.add_integer_column(1.0, 0.0..=1.0, v.iter().map(|&r| (rows[r], 1.0)));
        }
        let mut model = pb.try_optimise(Sense::Minimise).map_err(|s| format!("{s:?}"))?;
        for (name, value) in [("output_flag", false), ("log_to_console", false)] {
            model.try_set_option(name, value).map_err(|e| format!("{e:?}"))?;
        }
        model.try_set_option("threads", 1).map_err(|e| format!("{e:?}"))?;
        model.try_set_option("mip_rel_gap", 0.0).map_err(|e| format!("{e:?}"))?;
        Ok(model)
    }

    fn start() -> Vec<f64> {
        (0..VIEWS.len()).map(|c| if START.contains(&c) { 1.0 } else { 0.0 }).collect()
    }

    /// The minimum cover size by brute force over every subset of the 15 views.
    fn brute_force_minimum() -> usize {
        (0u32..1 << VIEWS.len())
            .filter(|&mask| {
                let mut covered = 0u32;
                for (c, v) in VIEWS.iter().enumerate() {
                    if mask >> c & 1 == 1 {
                        covered |= v.iter().fold(0, |a, &r| a | 1 << r);
                    }
                }
                covered == (1 << 14) - 1
            })
            .map(|mask| mask.count_ones() as usize)
            .min()
            .expect("all views cover everything")
    }

    #[test]
    fn the_returned_solution_is_the_reported_optimum() {
        assert_eq!(brute_force_minimum(), 6);
        let costs = vec![1.0; VIEWS.len()];
        let run = solve_from(cover_model, &start(), &costs).unwrap();
        assert_eq!(run.solved.status(), HighsModelStatus::Optimal);
        assert_eq!(run.solved.objective_value(), 6.0);
        let chosen = run.chosen(VIEWS.len()).expect("a checked solution");
        assert_eq!(chosen.len(), 6, "{chosen:?}");
        let covered = chosen.iter().fold(0u32, |a, &c| VIEWS[c].iter().fold(a, |a, &r| a | 1 << r));
        assert_eq!(covered, (1 << 14) - 1);
    }

    #[test]
    fn consistent_runs_are_not_solved_again() {
        // Without a start (and from the optimum as the start) the first solution is HiGHS's own.
        let costs = vec![1.0; VIEWS.len()];
        let zeros = vec![0.0; VIEWS.len()];
        let run = solve_from(cover_model, &zeros, &costs).unwrap();
        assert!(!run.restarted);
        let best = run.columns.expect("a checked solution");
        let run = solve_from(cover_model, &best, &costs).unwrap();
        assert!(!run.restarted);
        assert_eq!(run.solved.objective_value(), 6.0);
    }

    #[test]
    fn a_solution_whose_objective_disagrees_is_withheld() {
        // Costs that are not the model's: every solution disagrees, so none is handed out.
        let wrong = vec![2.0; VIEWS.len()];
        let run = solve_from(cover_model, &start(), &wrong).unwrap();
        assert!(run.restarted);
        assert!(run.columns.is_none());
    }
}
