//! The parameters of RSE and RSE-Mov ([`RseSettings`]): which variant, the ray stride, the
//! movement weight γ and the occupancy grid. They are their own module because they are also the
//! planners' registry settings: `--param` overrides are applied to their JSON form and the
//! result is deserialized back into them.

use objview_episode::PlannerError;
use serde::{Deserialize, Serialize};

use crate::occupancy::OccupancySettings;

/// Which of the two planners.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RseVariant {
    /// `rse`: the candidate with the largest rear-side entropy gain.
    Rse,
    /// `rse-mov`: gain traded against travel distance (weight γ).
    RseMov,
}

/// All parameters of the RSE planners.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RseSettings {
    /// `rse` or `rse-mov`.
    pub variant: RseVariant,
    /// Pixel stride of the scoring rays in u and v (rays through pixel centres u + 0.5 for
    /// u = 0, stride, 2·stride, …; same in v). Default 4 (16 384 rays for 512×512).
    pub stride: u32,
    /// RSE-Mov's movement weight γ ∈ [0, 1] (default 0.7); unused by RSE.
    pub gamma: f64,
    /// The occupancy grid.
    pub occupancy: OccupancySettings,
}

impl RseSettings {
    /// RSE with its defaults.
    pub fn rse() -> RseSettings {
        RseSettings {
            variant: RseVariant::Rse,
            stride: 4,
            gamma: 0.7,
            occupancy: OccupancySettings::default(),
        }
    }

    /// RSE-Mov with its defaults (γ = 0.7).
    pub fn rse_mov() -> RseSettings {
        RseSettings { variant: RseVariant::RseMov, ..RseSettings::rse() }
    }

    /// The method name: `rse` or `rse-mov`.
    pub fn name(&self) -> &'static str {
        match self.variant {
            RseVariant::Rse => "rse",
            RseVariant::RseMov => "rse-mov",
        }
    }

    /// Checks the parameters: stride ≥ 1, γ ∈ [0, 1], valid occupancy settings.
    pub fn validate(&self) -> Result<(), PlannerError> {
        if self.stride == 0 {
            return Err(PlannerError(format!("{}: stride must be at least 1", self.name())));
        }
        if !(0.0..=1.0).contains(&self.gamma) {
            return Err(PlannerError(format!(
                "{}: gamma must be in [0, 1], got {}",
                self.name(),
                self.gamma
            )));
        }
        self.occupancy.validate().map_err(|e| PlannerError(format!("{}: {e}", self.name())))
    }
}
