//! The one check of a pose that comes from outside the engine: a planner's move (local or
//! remote), a feasibility query of the server, a start pose (`objview run --start-pose`).
//!
//! A pose is 7 finite numbers whose camera centre and look-at point lie within
//! [`MAX_POSE_DISTANCE`] object units of the origin. The bound keeps every derived number
//! (camera radius, path cost, depth) finite: without it `[1e300, 1e300, 1e300, 0, 0, 0, 0]`
//! has an infinite radius, passes `camera_radius >= 1` and poisons the result with `null`s.
//! Objects are normalized into the unit ball and the camera sees at most `zfar` = 10 units
//! far, so nothing useful lies beyond the bound. A pose a camera is placed at must in addition
//! have a viewing direction (centre ≠ look-at): [`check_view_pose`].

use objview_geom::Pose;

/// The largest distance from the origin (normalized object units) of a pose's camera centre and
/// of its look-at point.
pub const MAX_POSE_DISTANCE: f64 = 100.0;

/// The names of a pose's 7 numbers, in order.
pub const POSE_FIELDS: [&str; 7] = ["cx", "cy", "cz", "lx", "ly", "lz", "roll"];

/// Why a pose is refused. The message names the number or point and the reason.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PoseError {
    /// One of the 7 numbers is NaN or infinite.
    #[error("the pose is not 7 finite numbers: `{field}` is {value}")]
    NotFinite {
        /// Which of the 7 numbers (`cx`, …, `roll`).
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// The camera centre or the look-at point is too far from the origin.
    #[error(
        "the {point} is {} object units from the origin; at most {MAX_POSE_DISTANCE} are allowed",
        distance_text(*.distance)
    )]
    TooFar {
        /// `camera centre` or `look-at point`.
        point: &'static str,
        /// Its distance from the origin, normalized object units.
        distance: f64,
    },
    /// Camera centre = look-at point: no viewing direction.
    #[error("pose centre equals its look-at point (no viewing direction)")]
    NoDirection,
}

fn distance_text(d: f64) -> String {
    if d < 1e6 {
        format!("{d:.3}")
    } else {
        format!("{d:.3e}")
    }
}

/// |p| without overflow (the numbers are finite, possibly near `f64::MAX`).
fn length(p: [f64; 3]) -> f64 {
    let m = p.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if m == 0.0 {
        return 0.0;
    }
    let s = p.iter().map(|x| (x / m) * (x / m)).sum::<f64>();
    m * s.sqrt()
}

/// The pose of `a` if its numbers are finite and its centre and look-at point lie within
/// [`MAX_POSE_DISTANCE`] of the origin.
pub fn check_pose(a: &[f64; 7]) -> Result<Pose, PoseError> {
    if let Some(i) = a.iter().position(|x| !x.is_finite()) {
        return Err(PoseError::NotFinite { field: POSE_FIELDS[i], value: a[i] });
    }
    for (point, p) in [("camera centre", [a[0], a[1], a[2]]), ("look-at point", [a[3], a[4], a[5]])] {
        let distance = length(p);
        if distance > MAX_POSE_DISTANCE {
            return Err(PoseError::TooFar { point, distance });
        }
    }
    Ok(Pose { center: [a[0], a[1], a[2]], look_at: [a[3], a[4], a[5]], roll: a[6] })
}

/// [`check_pose`], and the centre must differ from the look-at point: a pose a camera can be
/// placed at (a move, a start pose).
pub fn check_view_pose(a: &[f64; 7]) -> Result<Pose, PoseError> {
    let p = check_pose(a)?;
    if p.center == p.look_at {
        return Err(PoseError::NoDirection);
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn poses_within_the_bound_pass() {
        let p = check_view_pose(&[3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5]).unwrap();
        assert_eq!(p.to_array(), [3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5]);
        // On the bound itself, and a large roll (radians wrap).
        check_view_pose(&[100.0, 0.0, 0.0, 0.0, -100.0, 0.0, 1e6]).unwrap();
        let d = MAX_POSE_DISTANCE / 3f64.sqrt() - 1e-9;
        check_view_pose(&[d, d, d, -d, -d, -d, 0.0]).unwrap();
    }

    #[test]
    fn huge_finite_poses_are_refused_naming_the_point() {
        let e = check_pose(&[1e300, 1e300, 1e300, 0.0, 0.0, 0.0, 0.0]).unwrap_err();
        assert!(matches!(e, PoseError::TooFar { point: "camera centre", .. }), "{e:?}");
        let text = e.to_string();
        assert!(text.contains("camera centre is 1.732e300 object units") && text.contains("100"), "{text}");
        let e = check_pose(&[3.0, 0.0, 0.0, 0.0, 0.0, 100.5, 0.0]).unwrap_err().to_string();
        assert!(e.starts_with("the look-at point is 100.500 object units"), "{e}");
        // f64::MAX in every coordinate: the length does not overflow into a pass.
        let m = f64::MAX;
        assert!(check_pose(&[m, m, m, 0.0, 0.0, 0.0, 0.0]).is_err());
        assert!(check_pose(&[-m, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]).is_err());
    }

    #[test]
    fn non_finite_numbers_are_refused_naming_the_number() {
        let e = check_pose(&[3.0, 0.0, 0.0, 0.0, 0.0, 0.0, f64::INFINITY]).unwrap_err();
        assert_eq!(e.to_string(), "the pose is not 7 finite numbers: `roll` is inf");
        let e = check_pose(&[3.0, f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0]).unwrap_err();
        assert!(matches!(e, PoseError::NotFinite { field: "cy", value } if value.is_nan()), "{e:?}");
    }

    #[test]
    fn a_view_pose_needs_a_direction() {
        assert!(check_pose(&[1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0]).is_ok());
        assert_eq!(check_view_pose(&[1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0]), Err(PoseError::NoDirection));
    }
}
