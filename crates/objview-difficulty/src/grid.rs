//! The saturation grid of SPEC §4: the view-set sizes N at which Y(N) = |∪ O(v)| is measured.
//!
//! The grid is part of the protocol (it fixes where the curve is sampled, hence the fit and the
//! grid-based r_vis), so it is defined once here.

/// View-set sizes N of the saturation curve, strictly increasing (SPEC §4).
pub const SATURATION_GRID: [usize; 26] = [
    6, 8, 10, 12, 14, 16, 20, 24, 28, 32, 40, 48, 56, 64, 80, 96, 112, 128, 144, 160, 180, 200, 270, 360,
    432, 492,
];

/// Smallest grid size N_min.
pub const SATURATION_N_MIN: usize = SATURATION_GRID[0];

/// Largest grid size N_max.
pub const SATURATION_N_MAX: usize = SATURATION_GRID[SATURATION_GRID.len() - 1];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_matches_spec_and_is_strictly_increasing() {
        // Transcribed independently from SPEC §4.
        let spec = "6, 8, 10, 12, 14, 16, 20, 24, 28, 32, 40, 48, 56, 64, 80, 96, 112, 128, 144, \
                    160, 180, 200, 270, 360, 432, 492";
        let parsed: Vec<usize> = spec.split(',').map(|s| s.trim().parse().unwrap()).collect();
        assert_eq!(parsed, SATURATION_GRID.to_vec());
        assert!(SATURATION_GRID.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(SATURATION_N_MIN, 6);
        assert_eq!(SATURATION_N_MAX, 492);
        // The planning view set (tammes-128) and the slow-saturation threshold are grid points.
        assert!(SATURATION_GRID.contains(&128));
    }
}
