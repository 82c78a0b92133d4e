//! Where objview caches what it can rebuild: observable references (NSC's denominator, SPEC
//! §5), keyed by mesh, view space, settings and version, so a second run of an object skips
//! the most expensive part of its set-up.

use std::path::PathBuf;

/// The default observable-reference cache folder: `$XDG_CACHE_HOME/objview/reference`, else
/// `~/.cache/objview/reference`, else one under the temporary folder.
pub fn default_reference_cache() -> PathBuf {
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(std::env::temp_dir);
    base.join("objview").join("reference")
}

/// The cache folder of a run: none with `no_cache`, `dir` if given, else the default.
pub fn reference_cache(dir: Option<PathBuf>, no_cache: bool) -> Option<PathBuf> {
    if no_cache {
        None
    } else {
        Some(dir.unwrap_or_else(default_reference_cache))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_cache_wins_and_a_given_folder_beats_the_default() {
        assert_eq!(reference_cache(Some("x".into()), true), None);
        assert_eq!(reference_cache(Some("x".into()), false), Some(PathBuf::from("x")));
        assert!(reference_cache(None, false).unwrap().ends_with("objview/reference"));
    }
}
