//! Loading the hidden object of an episode: the normalized mesh (SPEC §1), its ground-truth
//! cloud (read and mapped into the normalized frame, or sampled), the view space, and the
//! observable reference (cached). One [`Scene`] serves every episode on that (object, space).

use std::path::Path;
use std::sync::Arc;

use objview_geom::normalize::{load_normalized, Normalization};
use objview_render::Intrinsics;
use objview_views::{ViewSet, ViewSpace};

use crate::engine::{scene_domain, Scene};
use crate::reference::observable_reference;
use crate::settings::EpisodeSettings;
use crate::EpisodeError;

/// Where an object comes from.
#[derive(Debug, Clone)]
pub struct SceneSource<'a> {
    /// The object's id (results' `uid`).
    pub uid: &'a str,
    /// The mesh file.
    pub mesh: &'a Path,
    /// Ground-truth cloud file (mesh file frame), or `None` to sample one (SPEC §1).
    pub gt_cloud: Option<&'a Path>,
    /// How the mesh is normalized (SPEC §1 `unit`, or `none` for pre-normalized assets).
    pub normalization: Normalization,
}

/// Loads the object and prepares its scene in `space` (`space_name` is what results record).
pub fn load_scene(
    src: &SceneSource<'_>,
    space: &ViewSpace,
    space_name: &str,
    settings: &EpisodeSettings,
    cache_dir: Option<&Path>,
) -> Result<Scene, EpisodeError> {
    let (mesh, transform) =
        load_normalized(src.mesh, src.normalization).map_err(|e| EpisodeError::Setup(e.to_string()))?;
    let gt = objview_geom::cloud::ground_truth(&mesh, &transform, src.gt_cloud)
        .map_err(|e| EpisodeError::Setup(e.to_string()))?;
    // Results name a ground-truth file by its name only: no paths of the machine that ran the
    // episode (the server must not reveal them; local and remote results stay identical).
    let source = match src.gt_cloud {
        Some(p) => format!("file:{}", p.file_name().map_or_else(|| "?".into(), |n| n.to_string_lossy())),
        None => gt.source,
    };
    scene_from_parts(src.uid, mesh, gt.points, source, space, space_name, settings, cache_dir)
}

/// A scene from an already normalized mesh and ground truth.
#[allow(clippy::too_many_arguments)]
pub fn scene_from_parts(
    uid: &str,
    mesh: objview_geom::Mesh,
    gt: Vec<[f64; 3]>,
    gt_source: String,
    space: &ViewSpace,
    space_name: &str,
    settings: &EpisodeSettings,
    cache_dir: Option<&Path>,
) -> Result<Scene, EpisodeError> {
    settings.validate().map_err(EpisodeError::Settings)?;
    if gt.is_empty() {
        return Err(EpisodeError::Setup(format!("{uid}: the ground-truth cloud is empty")));
    }
    let intrinsics = Intrinsics::default();
    let domain = scene_domain(&mesh, &gt, settings.fusion_voxel);
    let views = ViewSet::resolve(&settings.reference_view_set)
        .map_err(|e| EpisodeError::Settings(format!("reference view set: {e}")))?;
    let reference =
        observable_reference(&mesh, &gt, &domain, space, &views, &intrinsics, settings, cache_dir)?;
    Ok(Scene {
        uid: uid.to_string(),
        mesh: Arc::new(mesh),
        gt: Arc::new(gt),
        gt_source,
        space: space.clone(),
        space_name: space_name.to_string(),
        reference: Arc::new(reference),
        domain,
        intrinsics,
        targets: std::sync::OnceLock::new(),
        reference_targets: std::sync::OnceLock::new(),
        starts: Default::default(),
    })
}
