//! Every constant of SPEC §5 in one place, as a setting: each is recorded in every result line.

use serde::{Deserialize, Serialize};

/// Episode settings (defaults = SPEC §5).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeSettings {
    /// Fusion voxel size (0.005).
    pub fusion_voxel: f64,
    /// Coverage thresholds τ (0.01, 0.02, 0.03).
    pub taus: Vec<f64>,
    /// MS@δ resolutions (0.01, 0.02, 0.03).
    pub ms_deltas: Vec<f64>,
    /// MS growth threshold (0.01).
    pub ms_growth: f64,
    /// MS stable steps in a row (3).
    pub ms_stable_steps: usize,
    /// MS resolution of the automatic budget for iterative planners (0.02).
    pub auto_delta: f64,
    /// Budget checkpoints K (5, 10, 30, 50).
    pub checkpoint_ks: Vec<usize>,
    /// Maximum views, start included (129).
    pub cap: usize,
    /// Stop iterative runs once every checkpoint exists (`enough_info`).
    pub enough_info: bool,
    /// View radius R of view-set poses (3.0).
    pub view_radius: f64,
    /// Reference view set for NSC (`tammes-360`).
    pub reference_view_set: String,
    /// Candidate view set handed to planners (`tammes-360`).
    pub candidates: String,
    /// Render RGB for planners.
    pub render_rgb: bool,
    /// Record wall-clock timings (PR, per-step times); off gives byte-identical files.
    pub record_timings: bool,
}

impl Default for EpisodeSettings {
    fn default() -> Self {
        EpisodeSettings {
            fusion_voxel: 0.005,
            taus: vec![0.01, 0.02, 0.03],
            ms_deltas: vec![0.01, 0.02, 0.03],
            ms_growth: 0.01,
            ms_stable_steps: 3,
            auto_delta: 0.02,
            checkpoint_ks: vec![5, 10, 30, 50],
            cap: 129,
            enough_info: true,
            view_radius: objview_geom::pose::VIEW_RADIUS,
            reference_view_set: "tammes-360".into(),
            candidates: "tammes-360".into(),
            render_rgb: false,
            record_timings: true,
        }
    }
}

impl EpisodeSettings {
    /// Checks ranges; the error names the setting.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.fusion_voxel > 0.0 && self.fusion_voxel.is_finite()) {
            return Err(format!("fusion_voxel must be > 0, got {}", self.fusion_voxel));
        }
        if self.taus.is_empty() || self.taus.iter().any(|t| !(*t > 0.0 && t.is_finite())) {
            return Err(format!("taus must be positive numbers, got {:?}", self.taus));
        }
        if self.ms_deltas.iter().any(|t| !(*t > 0.0 && t.is_finite())) {
            return Err(format!("ms_deltas must be positive numbers, got {:?}", self.ms_deltas));
        }
        if !self.ms_deltas.contains(&self.auto_delta) {
            return Err(format!(
                "auto_delta {} must be one of ms_deltas {:?}",
                self.auto_delta, self.ms_deltas
            ));
        }
        if self.cap < 1 {
            return Err("cap must be at least 1 (the start view)".into());
        }
        if self.ms_stable_steps < 1 {
            return Err("ms_stable_steps must be at least 1".into());
        }
        Ok(())
    }
}
