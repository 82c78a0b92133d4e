//! Human-viewable images of rendered views: a colour-mapped depth preview (viridis, near =
//! yellow, far = purple, misses black) and PNG writers for it and for RGB renders. For
//! inspection only; the benchmark's data are the depth arrays themselves.

use crate::{Frame, NO_HIT};
use image::{Rgb, RgbImage};
use std::path::{Path, PathBuf};

/// Failure to write a preview image.
#[derive(Debug, thiserror::Error)]
pub enum PreviewError {
    /// Encoding or writing the PNG file failed.
    #[error("cannot write PNG {path}: {source}")]
    Write {
        /// The PNG file being written.
        path: PathBuf,
        /// The encoder's or the file system's error.
        source: image::ImageError,
    },
    /// The pixel buffer does not hold `width × height` pixels.
    #[error("cannot write PNG {path}: {len} pixels given for a {width}×{height} image")]
    Size {
        /// The PNG file that was to be written.
        path: PathBuf,
        /// Requested image width, pixels.
        width: u32,
        /// Requested image height, pixels.
        height: u32,
        /// Number of pixels actually given.
        len: usize,
    },
}

/// Viridis (matplotlib) at t = 0, ¼, ½, ¾, 1; linearly interpolated in between.
const VIRIDIS: [[f64; 3]; 5] =
    [[68.0, 1.0, 84.0], [59.0, 82.0, 139.0], [33.0, 145.0, 140.0], [94.0, 201.0, 98.0], [253.0, 231.0, 37.0]];

/// Viridis colour of `t` in [0, 1] (clamped): 0 = dark purple, 1 = yellow.
pub fn viridis(t: f64) -> [u8; 3] {
    let x = t.clamp(0.0, 1.0) * 4.0;
    let i = (x.floor() as usize).min(3);
    let f = x - i as f64;
    std::array::from_fn(|k| (VIRIDIS[i][k] + f * (VIRIDIS[i + 1][k] - VIRIDIS[i][k])).round() as u8)
}

/// Colour-mapped depth of `frame`: depth normalized between the smallest and largest depth of
/// the hit pixels, nearest = yellow (warm), farthest = purple; misses black. A frame whose hits
/// all have one depth is yellow where hit.
pub fn depth_preview(frame: &Frame) -> RgbImage {
    let (w, h) = (frame.width(), frame.height());
    let hits =
        || frame.depth.iter().zip(&frame.triangle).filter(|(_, &t)| t != NO_HIT).map(|(&z, _)| z as f64);
    let lo = hits().fold(f64::INFINITY, f64::min);
    let hi = hits().fold(f64::NEG_INFINITY, f64::max);
    let span = if hi > lo { hi - lo } else { 1.0 };
    let mut img = RgbImage::new(w, h);
    for (i, (&z, &t)) in frame.depth.iter().zip(&frame.triangle).enumerate() {
        if t != NO_HIT {
            let c = viridis(1.0 - (z as f64 - lo) / span);
            img.put_pixel(i as u32 % w, i as u32 / w, Rgb(c));
        }
    }
    img
}

/// Writes `img` as a PNG to `path`.
pub fn save_png(img: &RgbImage, path: impl AsRef<Path>) -> Result<(), PreviewError> {
    let path = path.as_ref();
    img.save_with_format(path, image::ImageFormat::Png)
        .map_err(|source| PreviewError::Write { path: path.to_path_buf(), source })
}

/// Writes a row-major `width × height` RGB buffer (e.g. from [`crate::rgb::render_rgb`]) as a
/// PNG to `path`.
pub fn save_rgb_png(
    width: u32,
    height: u32,
    rgb: &[[u8; 3]],
    path: impl AsRef<Path>,
) -> Result<(), PreviewError> {
    let path = path.as_ref();
    if rgb.len() != width as usize * height as usize {
        return Err(PreviewError::Size { path: path.to_path_buf(), width, height, len: rgb.len() });
    }
    let img = RgbImage::from_raw(width, height, rgb.iter().flatten().copied().collect())
        .expect("size checked above");
    save_png(&img, path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Camera, Intrinsics};
    use objview_geom::{Mesh, Pose};

    #[test]
    fn viridis_endpoints_and_midpoint() {
        assert_eq!(viridis(0.0), [68, 1, 84]);
        assert_eq!(viridis(1.0), [253, 231, 37]);
        assert_eq!(viridis(0.5), [33, 145, 140]);
        assert_eq!(viridis(-3.0), viridis(0.0));
        assert_eq!(viridis(0.125), [64, 42, 112]); // halfway between the first two anchors
    }

    #[test]
    fn preview_maps_near_to_yellow_and_misses_to_black_and_round_trips() {
        // A square tilted about the vertical axis: depth varies left to right.
        let mesh = Mesh::new(
            vec![[0.3, -0.5, -0.5], [-0.3, 0.5, -0.5], [-0.3, 0.5, 0.5], [0.3, -0.5, 0.5]],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let cam =
            Camera::new(Pose::from_direction([1.0, 0.0, 0.0], 3.0), Intrinsics::from_fov(64, 64, 45.0, 45.0));
        let f = crate::render(&mesh, &cam);
        let img = depth_preview(&f);
        assert_eq!(img.get_pixel(0, 0).0, [0, 0, 0]);
        // Image left = −y = the near side (x = +0.3).
        let (mut near, mut far) = ((0, 0.0f32), (0, 0.0f32));
        for (i, &z) in f.depth.iter().enumerate() {
            if f.triangle[i] != NO_HIT && (near.1 == 0.0 || z < near.1) {
                near = (i, z);
            }
            if f.triangle[i] != NO_HIT && z > far.1 {
                far = (i, z);
            }
        }
        let px = |i: usize| img.get_pixel(i as u32 % 64, i as u32 / 64).0;
        assert_eq!(px(near.0), [253, 231, 37]);
        assert_eq!(px(far.0), [68, 1, 84]);
        assert!((near.0 % 64) < 32 && (far.0 % 64) > 32);

        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("d.png");
        save_png(&img, &p).unwrap();
        let back = image::open(&p).unwrap().to_rgb8();
        assert_eq!(back, img);
        let rgb: Vec<[u8; 3]> = (0..6).map(|i| [i, 2 * i, 3 * i]).collect();
        save_rgb_png(3, 2, &rgb, dir.path().join("c.png")).unwrap();
        let back = image::open(dir.path().join("c.png")).unwrap().to_rgb8();
        assert_eq!(back.get_pixel(2, 1).0, [5, 10, 15]);
        let e = save_rgb_png(4, 2, &rgb, dir.path().join("x.png")).unwrap_err().to_string();
        assert!(e.contains("6 pixels") && e.contains("x.png"), "{e}");
        let e = save_png(&img, dir.path().join("no/such/dir.png")).unwrap_err().to_string();
        assert!(e.contains("dir.png"), "{e}");
    }
}
