//! The object pool a server evaluates on: split files (`objview pool split` output, JSON arrays
//! of `{"uid", "mesh", "gt_cloud"?, …}`), each served as a split whose id is the file stem, and
//! the cache of prepared scenes — the normalized mesh, the ground-truth cloud and the observable
//! reference of one (object, view space) — shared by every episode on them.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use objview_dataset::ObjectRef;
use objview_episode::{load_scene, EpisodeSettings, Scene, SceneSource};
use objview_geom::normalize::Normalization;
use objview_views::ViewSpace;

use crate::error::ServerError;

/// One split: its objects in file order.
#[derive(Debug, Clone)]
pub struct Split {
    /// The split id (the split file's stem, e.g. `main_hidden_test`).
    pub id: String,
    /// Whether it was named with `--public` (metrics visible while running).
    pub public: bool,
    /// Its objects, in the file's order.
    pub objects: Vec<ObjectRef>,
}

impl Split {
    /// The object at index `i` or with uid `key`.
    pub fn object(&self, key: &ObjectKey) -> Option<&ObjectRef> {
        match key {
            ObjectKey::Index(i) => self.objects.get(*i),
            ObjectKey::Uid(u) => self.objects.iter().find(|o| &o.uid == u),
        }
    }
}

/// How a request names an object: an index into its split or a uid.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ObjectKey {
    /// The object's index in the split.
    Index(usize),
    /// The object's uid.
    Uid(String),
}

/// The splits of a server, in command-line order.
#[derive(Debug, Clone, Default)]
pub struct Pool {
    /// Every split.
    pub splits: Vec<Split>,
}

impl Pool {
    /// Reads the split files; `public` names the splits whose metrics may be shown while an
    /// episode runs (`*`: all of them). Two files with the same stem, or a `--public` id that
    /// names no split, are errors.
    pub fn load(files: &[PathBuf], public: &[String]) -> Result<Pool, ServerError> {
        let mut splits: Vec<Split> = Vec::new();
        for f in files {
            let id = split_id(f)?;
            if splits.iter().any(|s| s.id == id) {
                return Err(ServerError::Pool(format!("{}: a second split with id {id:?}", f.display())));
            }
            let objects = objview_dataset::read_split(f).map_err(|e| ServerError::Pool(e.to_string()))?;
            let mut seen = std::collections::HashSet::new();
            for o in &objects {
                if !seen.insert(o.uid.as_str()) {
                    return Err(ServerError::Pool(format!("{}: uid {:?} appears twice", f.display(), o.uid)));
                }
            }
            splits.push(Split { id, public: false, objects });
        }
        for p in public {
            if p == "*" {
                // A bare `--public`: every split.
                splits.iter_mut().for_each(|s| s.public = true);
                continue;
            }
            let Some(s) = splits.iter_mut().find(|s| &s.id == p) else {
                return Err(ServerError::Config(format!(
                    "--public {p}: no such split (splits: {})",
                    splits.iter().map(|s| s.id.as_str()).collect::<Vec<_>>().join(", ")
                )));
            };
            s.public = true;
        }
        Ok(Pool { splits })
    }

    /// The split called `id`.
    pub fn split(&self, id: &str) -> Option<&Split> {
        self.splits.iter().find(|s| s.id == id)
    }
}

/// A split file's id: its file stem.
pub fn split_id(path: &Path) -> Result<String, ServerError> {
    path.file_stem()
        .and_then(|s| s.to_str())
        .filter(|s| !s.is_empty())
        .map(str::to_string)
        .ok_or_else(|| ServerError::Pool(format!("{}: cannot name a split after this file", path.display())))
}

type SceneKey = (String, PathBuf, Option<PathBuf>, String);

/// One cache entry: filled by the first request that builds it.
type SceneSlot = Arc<Mutex<Option<Arc<Scene>>>>;

/// Prepared scenes per (object, view space), built on first use (that takes seconds: the
/// mesh and ground truth are parsed, and the observable reference renders every reference view
/// unless the on-disk cache has it). A prepared scene also has its metric target sets built
/// ([`Scene::fresh_targets`]), so every episode on it starts from a clone of them. Concurrent
/// requests for the same scene wait for one build. At most `capacity` scenes are kept (tens of
/// MB each for a 100k-triangle object; `objview serve --scene-cache N`): the least recently
/// used one is dropped first; running episodes hold their own reference, so dropping never
/// affects them.
pub struct SceneCache {
    normalize: Normalization,
    cache_dir: Option<PathBuf>,
    settings: EpisodeSettings,
    capacity: usize,
    entries: Mutex<Entries>,
    stats: Counters,
}

/// How often a scene was found ready, and how often one was built.
#[derive(Default)]
struct Counters {
    hits: AtomicU64,
    builds: AtomicU64,
}

/// What a [`SceneCache`] has done so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SceneCacheStats {
    /// Requests answered with a scene already prepared (or prepared meanwhile by another
    /// request they waited for).
    pub hits: u64,
    /// Scenes built (a scene dropped and asked for again is built again).
    pub builds: u64,
    /// Scenes held now (built or being built).
    pub held: usize,
}

/// The cache's map, with a use counter per entry for least-recently-used eviction.
#[derive(Default)]
struct Entries {
    map: HashMap<SceneKey, (SceneSlot, u64)>,
    clock: u64,
}

/// Scenes kept by default (`objview serve --scene-cache`).
pub const DEFAULT_SCENE_CACHE: usize = 16;

impl SceneCache {
    /// A cache that loads meshes with `normalize` and keeps observable references in
    /// `cache_dir` (none: not on disk).
    pub fn new(normalize: Normalization, cache_dir: Option<PathBuf>) -> SceneCache {
        SceneCache {
            normalize,
            cache_dir,
            settings: EpisodeSettings::default(),
            capacity: DEFAULT_SCENE_CACHE,
            entries: Mutex::default(),
            stats: Counters::default(),
        }
    }

    /// Hits, builds and scenes held so far.
    pub fn stats(&self) -> SceneCacheStats {
        SceneCacheStats {
            hits: self.stats.hits.load(Ordering::Relaxed),
            builds: self.stats.builds.load(Ordering::Relaxed),
            held: self.len(),
        }
    }

    /// The same cache keeping at most `n` scenes (at least one).
    pub fn with_capacity(mut self, n: usize) -> SceneCache {
        self.capacity = n.max(1);
        self
    }

    /// Scenes currently cached (built or being built).
    pub fn len(&self) -> usize {
        self.entries.lock().unwrap_or_else(|e| e.into_inner()).map.len()
    }

    /// Whether nothing is cached.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// How meshes are normalized.
    pub fn normalize(&self) -> Normalization {
        self.normalize
    }

    /// The slot of `key` (created empty if new), marked as just used; drops the least recently
    /// used other entries beyond the capacity.
    fn touch(&self, key: SceneKey) -> SceneSlot {
        let mut e = self.entries.lock().unwrap_or_else(|e| e.into_inner());
        e.clock += 1;
        let now = e.clock;
        let slot = {
            let item = e.map.entry(key.clone()).or_default();
            item.1 = now;
            item.0.clone()
        };
        while e.map.len() > self.capacity {
            let Some(old) =
                e.map.iter().filter(|(k, _)| **k != key).min_by_key(|(_, v)| v.1).map(|(k, _)| k.clone())
            else {
                break;
            };
            e.map.remove(&old);
        }
        slot
    }

    /// The scene of `obj` in the built-in view space `space` (blocking; call it off the async
    /// executor, and outside the engine queue: a request waiting here for another's build must
    /// not hold an engine lane). The error text may name files: do not send it to clients.
    pub fn get(&self, obj: &ObjectRef, space: &str) -> Result<Arc<Scene>, String> {
        let key = (obj.uid.clone(), obj.mesh.clone(), obj.gt_cloud.clone(), space.to_string());
        let entry = self.touch(key);
        // Held while building: a second request for this scene waits here for the first.
        let mut slot = entry.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(s) = slot.as_ref() {
            self.stats.hits.fetch_add(1, Ordering::Relaxed);
            return Ok(s.clone());
        }
        let vs = ViewSpace::builtin(space).ok_or_else(|| format!("unknown view space {space:?}"))?;
        let src = SceneSource {
            uid: &obj.uid,
            mesh: &obj.mesh,
            gt_cloud: obj.gt_cloud.as_deref(),
            normalization: self.normalize,
        };
        let scene = load_scene(&src, &vs, space, &self.settings, self.cache_dir.as_deref())
            .map_err(|e| format!("{}: {e}", obj.uid))?;
        // The target sets' spatial indexes, built once here rather than by the first episode
        // (episodes use the default τ list; another list builds its own on first use).
        scene.fresh_targets(&self.settings.taus).map_err(|e| format!("{}: {e}", obj.uid))?;
        // Every episode here has the server's settings and start pose: the first one's state
        // after its start view is kept and copied by the later creates.
        scene.keep_start_states(1);
        let scene = Arc::new(scene);
        self.stats.builds.fetch_add(1, Ordering::Relaxed);
        *slot = Some(scene.clone());
        Ok(scene)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scene_cache_drops_the_least_recently_used() {
        let cache = SceneCache::new(Normalization::Unit, None).with_capacity(2);
        let key = |u: &str| (u.to_string(), PathBuf::from(format!("{u}.obj")), None, "whole".to_string());
        let a = cache.touch(key("a"));
        cache.touch(key("b"));
        // `a` is used again, so `b` is the oldest when `c` arrives.
        assert!(Arc::ptr_eq(&a, &cache.touch(key("a"))));
        cache.touch(key("c"));
        assert_eq!(cache.len(), 2);
        let keys: std::collections::BTreeSet<String> =
            cache.entries.lock().unwrap().map.keys().map(|k| k.0.clone()).collect();
        assert_eq!(keys, ["a", "c"].iter().map(|s| s.to_string()).collect());
        // A dropped entry comes back empty (it is rebuilt on use).
        assert!(cache.touch(key("b")).lock().unwrap().is_none());
        assert_eq!(SceneCache::new(Normalization::Unit, None).with_capacity(0).capacity, 1);
    }

    #[test]
    fn public_marks_named_splits_or_all() {
        let dir = tempfile::tempdir().unwrap();
        let mut files = Vec::new();
        for name in ["alpha", "beta"] {
            let f = dir.path().join(format!("{name}.json"));
            std::fs::write(&f, format!(r#"[{{"uid": "{name}-obj", "mesh": "{name}.obj"}}]"#)).unwrap();
            files.push(f);
        }
        let flags = |p: &Pool| p.splits.iter().map(|s| (s.id.clone(), s.public)).collect::<Vec<_>>();
        let none = Pool::load(&files, &[]).unwrap();
        assert_eq!(flags(&none), vec![("alpha".into(), false), ("beta".into(), false)]);
        let one = Pool::load(&files, &["beta".into()]).unwrap();
        assert_eq!(flags(&one), vec![("alpha".into(), false), ("beta".into(), true)]);
        let all = Pool::load(&files, &["*".into()]).unwrap();
        assert_eq!(flags(&all), vec![("alpha".into(), true), ("beta".into(), true)]);
        let err = Pool::load(&files, &["gamma".into()]).unwrap_err().to_string();
        assert!(err.contains("--public gamma: no such split"), "{err}");
    }
}
