//! Camera model (SPEC §2) and the exact first-hit renderer of objview.
//!
//! - [`camera`]: intrinsics, the pose → camera-axes rule (pole rule, roll), projection and
//!   pixel-centre rays.
//! - [`reference`](mod@reference): brute-force per-pixel ray–triangle casting. Slow, obviously
//!   correct; the oracle the fast renderer is tested against.
//! - [`frame`]: a rendered view (depth, triangle ids) and what is derived from it
//!   (observed point cloud, RGB).

pub mod camera;
pub mod frame;
pub mod reference;

pub use camera::{Camera, Intrinsics};
pub use frame::{Frame, NO_HIT};

pub mod preview;
pub mod raster;
pub mod rgb;

pub mod bench;
pub use raster::{render_parallel, Renderer};

/// Renders `mesh` from `camera`: first hit through every pixel centre (SPEC §2).
/// Poses are in the object frame (see [`camera`]); depth is camera-frame z, 0 = no hit.
pub fn render(mesh: &objview_geom::Mesh, camera: &Camera) -> Frame {
    raster::render(mesh, camera)
}
