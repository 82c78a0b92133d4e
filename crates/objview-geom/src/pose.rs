//! Camera poses (SPEC §2): seven numbers `[cx, cy, cz, lx, ly, lz, roll]` — the camera centre,
//! the look-at point (both in the object frame, unit-ball units) and the roll in radians about
//! the viewing axis.

use serde::{Deserialize, Serialize};

/// Default view radius R: a view direction `d` means the pose `[R·d, 0, 0, 0, 0]`.
pub const VIEW_RADIUS: f64 = 3.0;

/// A camera pose in the object frame (units: normalized object units; roll: radians).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Camera centre.
    pub center: [f64; 3],
    /// Point the optical axis passes through.
    pub look_at: [f64; 3],
    /// Rotation about the viewing axis, radians (right-hand rule about the forward axis).
    pub roll: f64,
}

impl Pose {
    /// The pose looking at the origin from `radius · d` (d need not be unit; it is normalized).
    pub fn from_direction(d: [f64; 3], radius: f64) -> Pose {
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        Pose {
            center: [radius * d[0] / n, radius * d[1] / n, radius * d[2] / n],
            look_at: [0.0; 3],
            roll: 0.0,
        }
    }

    /// The 7-number form `[cx, cy, cz, lx, ly, lz, roll]`.
    pub fn to_array(&self) -> [f64; 7] {
        let (c, l) = (self.center, self.look_at);
        [c[0], c[1], c[2], l[0], l[1], l[2], self.roll]
    }

    /// From the 7-number form; `None` unless all seven numbers are finite.
    pub fn from_array(a: [f64; 7]) -> Option<Pose> {
        if a.iter().all(|x| x.is_finite()) {
            Some(Pose { center: [a[0], a[1], a[2]], look_at: [a[3], a[4], a[5]], roll: a[6] })
        } else {
            None
        }
    }

    /// Parses `cx,cy,cz,lx,ly,lz,roll` (commas and/or whitespace).
    pub fn parse(s: &str) -> Result<Pose, String> {
        let parts: Vec<&str> =
            s.split(|c: char| c == ',' || c.is_whitespace()).filter(|p| !p.is_empty()).collect();
        if parts.len() != 7 {
            return Err(format!("a pose needs 7 numbers cx,cy,cz,lx,ly,lz,roll; got {}", parts.len()));
        }
        let mut a = [0.0; 7];
        for (i, p) in parts.iter().enumerate() {
            a[i] = p.parse::<f64>().map_err(|_| format!("pose number {} is not a number: {p:?}", i + 1))?;
        }
        let p = Pose::from_array(a).ok_or_else(|| "pose numbers must be finite".to_string())?;
        if p.center == p.look_at {
            return Err(
                "the camera centre equals the look-at point: the pose has no viewing direction".into()
            );
        }
        Ok(p)
    }

    /// Distance of the camera centre from the origin.
    pub fn radius(&self) -> f64 {
        let c = self.center;
        (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_roundtrip_and_errors() {
        let p = Pose::parse("3,0,0, 0,0,0, 0.5").unwrap();
        assert_eq!(p.to_array(), [3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5]);
        assert!(Pose::parse("1,2,3").unwrap_err().contains("7 numbers"));
        assert!(Pose::parse("1,2,3,4,5,6,x").unwrap_err().contains("number 7"));
        assert!(Pose::parse("1,2,3,4,5,6,NaN").is_err());
        assert!(Pose::parse("1,1,1,1,1,1,0").unwrap_err().contains("no viewing direction"));
        let d = Pose::from_direction([0.0, 0.0, 2.0], VIEW_RADIUS);
        assert_eq!(d.center, [0.0, 0.0, 3.0]);
        assert!((d.radius() - 3.0).abs() < 1e-15);
    }
}
