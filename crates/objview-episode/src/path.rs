//! Path cost (SPEC §5 "PC"): the travel length of the camera centre between two poses under the
//! *shell distance* — the straight segment when it does not enter the open unit ball (the
//! object's bounding ball), otherwise tangent + great-circle arc on the unit sphere + tangent,
//! the shortest path that stays outside the ball. When an endpoint is inside the ball the
//! straight length is used (no collision-free path is defined there).
//!
//! Units: normalized object units (the object fits in the unit ball). Only camera centres
//! matter; look-at points and roll do not move the camera.

use objview_geom::Pose;

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// Shell distance between camera centres `a` and `b` around the unit ball (radius 1, centred at
/// the origin): |a − b| if the segment stays outside the open unit ball or an endpoint is inside
/// it; otherwise √(|a|²−1) + arc + √(|b|²−1), where arc = ∠(a, b) − acos(1/|a|) − acos(1/|b|).
pub fn shell_distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    shell_distance_radius(a, b, 1.0)
}

/// [`shell_distance`] around a ball of radius `r` (> 0) centred at the origin.
pub fn shell_distance_radius(a: [f64; 3], b: [f64; 3], r: f64) -> f64 {
    let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let straight = norm(d);
    let (na, nb) = (norm(a), norm(b));
    if na <= r || nb <= r || straight == 0.0 {
        return straight;
    }
    // Closest point of the segment to the origin: a + t·d, t = −a·d/|d|², clamped to [0, 1].
    let t = (-dot(a, d) / (straight * straight)).clamp(0.0, 1.0);
    let c = [a[0] + t * d[0], a[1] + t * d[1], a[2] + t * d[2]];
    if norm(c) >= r {
        return straight;
    }
    let cos_ab = (dot(a, b) / (na * nb)).clamp(-1.0, 1.0);
    let angle = cos_ab.acos();
    let alpha = (r / na).clamp(-1.0, 1.0).acos();
    let beta = (r / nb).clamp(-1.0, 1.0).acos();
    let arc = (angle - alpha - beta).max(0.0);
    (na * na - r * r).sqrt() + r * arc + (nb * nb - r * r).sqrt()
}

/// Shell distance between the camera centres of two poses.
pub fn pose_distance(a: &Pose, b: &Pose) -> f64 {
    shell_distance(a.center, b.center)
}

/// Total shell length of a pose sequence (segment by segment, in order).
pub fn path_length(poses: &[Pose]) -> f64 {
    poses.windows(2).map(|w| pose_distance(&w[0], &w[1])).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn straight_when_outside() {
        // Both at x = 2, segment along y: closest point (2, 0, 0), distance 2 > 1.
        assert!(close(shell_distance([2.0, -1.0, 0.0], [2.0, 1.0, 0.0]), 2.0));
        // Zero-length segment.
        assert_eq!(shell_distance([3.0, 0.0, 0.0], [3.0, 0.0, 0.0]), 0.0);
        // Segment pointing away: closest point is an endpoint.
        assert!(close(shell_distance([2.0, 0.0, 0.0], [4.0, 0.0, 0.0]), 2.0));
    }

    #[test]
    fn tangent_segment_is_straight() {
        // The segment y = 1 touches the unit ball at (0,1,0): not inside the open ball.
        assert!(close(shell_distance([-2.0, 1.0, 0.0], [2.0, 1.0, 0.0]), 4.0));
    }

    #[test]
    fn through_the_ball_antipodal() {
        // a = (3,0,0), b = (−3,0,0): tangents √8 each, angle π, alpha = beta = acos(1/3).
        let alpha = (1.0f64 / 3.0).acos();
        let want = 2.0 * 8f64.sqrt() + (std::f64::consts::PI - 2.0 * alpha);
        assert!(close(shell_distance([3.0, 0.0, 0.0], [-3.0, 0.0, 0.0]), want));
        // Longer than the straight segment, symmetric.
        assert!(want > 6.0);
        assert!(close(shell_distance([-3.0, 0.0, 0.0], [3.0, 0.0, 0.0]), want));
    }

    #[test]
    fn through_the_ball_at_right_angle() {
        // a = (3,0,0), b = (0,3,0): segment's closest point (1.5,1.5,0), |.| = 2.12 > 1: straight.
        assert!(close(shell_distance([3.0, 0.0, 0.0], [0.0, 3.0, 0.0]), 18f64.sqrt()));
        // a = (1.2,0,0), b = (0,1.2,0): closest point (0.6,0.6,0), |.| = 0.85 < 1: shell path.
        let (na, alpha) = (1.2f64, (1.0f64 / 1.2).acos());
        let want = 2.0 * (na * na - 1.0).sqrt() + (std::f64::consts::FRAC_PI_2 - 2.0 * alpha);
        let got = shell_distance([1.2, 0.0, 0.0], [0.0, 1.2, 0.0]);
        assert!(close(got, want), "{got} vs {want}");
        assert!(got > (2.0f64 * 1.44).sqrt());
    }

    #[test]
    fn endpoint_inside_is_straight() {
        assert!(close(shell_distance([0.5, 0.0, 0.0], [-3.0, 0.0, 0.0]), 3.5));
        assert!(close(shell_distance([3.0, 0.0, 0.0], [0.0, 0.0, 0.0]), 3.0));
    }

    #[test]
    fn path_sums_segments() {
        let p = |x: f64, y: f64| Pose { center: [x, y, 0.0], look_at: [0.0; 3], roll: 0.0 };
        let poses = [p(2.0, -1.0), p(2.0, 1.0), p(2.0, 1.0), p(-2.0, 1.0)];
        assert!(close(path_length(&poses), 2.0 + 0.0 + 4.0));
        assert_eq!(path_length(&poses[..1]), 0.0);
    }

    #[test]
    fn shell_is_never_shorter_than_straight() {
        for i in 0..50 {
            let t = i as f64 * 0.37;
            let a = [3.0 * t.cos(), 3.0 * t.sin(), 0.4];
            let b = [-2.5 * (t * 1.3).sin(), 0.2, 2.5 * (t * 1.3).cos()];
            let s = shell_distance(a, b);
            let d = norm([a[0] - b[0], a[1] - b[1], a[2] - b[2]]);
            assert!(s >= d - 1e-12);
        }
    }
}
