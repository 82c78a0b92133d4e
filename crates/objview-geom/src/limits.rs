//! Resource limits of the file loaders: the contract that an untrusted asset can make objview
//! read at most so many bytes and build at most so many triangles, vertices, points and glTF
//! node instances, whatever its headers claim.
//!
//! The defaults ([`Limits::default`]) accept every real asset of Objaverse scale (GLBs of
//! hundreds of MB, tens of millions of triangles) and stop bombs (a 1 KB header claiming 2^40
//! vertices, a 2 MB archive that inflates to gigabytes, a node graph that instances a mesh 2^40
//! times). Each limit can be changed with an environment variable ([`Limits::from_env`]), read
//! once per process by [`Limits::global`], which is what [`crate::io::load_mesh`],
//! [`crate::cloud::read_cloud`] and [`crate::npy::read_npy_f64`] use; the `*_with` variants of
//! those functions take explicit limits instead.
//!
//! | field | default | environment variable |
//! | --- | ---: | --- |
//! | [`max_file_bytes`](Limits::max_file_bytes) | 2 GiB | `OBJVIEW_MAX_FILE_BYTES` |
//! | [`max_referenced_bytes`](Limits::max_referenced_bytes) | 1 GiB | `OBJVIEW_MAX_REFERENCED_BYTES` |
//! | [`max_decompressed_bytes`](Limits::max_decompressed_bytes) | 1 GiB | `OBJVIEW_MAX_DECOMPRESSED_BYTES` |
//! | [`max_texture_bytes`](Limits::max_texture_bytes) | 4 GiB | `OBJVIEW_MAX_TEXTURE_BYTES` |
//! | [`max_triangles`](Limits::max_triangles) | 50 000 000 | `OBJVIEW_MAX_TRIANGLES` |
//! | [`max_vertices`](Limits::max_vertices) | 150 000 000 | `OBJVIEW_MAX_VERTICES` |
//! | [`max_gltf_nodes`](Limits::max_gltf_nodes) | 1 000 000 | `OBJVIEW_MAX_GLTF_NODES` |
//! | [`max_points`](Limits::max_points) | 100 000 000 | `OBJVIEW_MAX_POINTS` |
//!
//! A value is a positive decimal integer; byte limits also accept a `K`, `M` or `G` suffix
//! (powers of 1024, e.g. `OBJVIEW_MAX_FILE_BYTES=4G`). An unset or empty variable means the
//! default; any other value that is not of this form is an error that every load reports
//! (naming the variable), rather than a silently ignored setting.

use std::sync::OnceLock;

const KIB: u64 = 1024;
const MIB: u64 = 1024 * KIB;
const GIB: u64 = 1024 * MIB;

/// Limits on what one load may read and build. See the module documentation for the
/// defaults and environment variables.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Largest file given directly (a mesh, cloud or `.npy` file), in bytes. Checked from the
    /// file's metadata before anything is read.
    pub max_file_bytes: u64,
    /// Largest file an asset refers to (a glTF `.bin` buffer or image, an OBJ `.mtl` or
    /// texture), in bytes.
    pub max_referenced_bytes: u64,
    /// Largest decompressed member of an archive (an `.npz` entry) or compressed block (PCD
    /// `binary_compressed`), in bytes.
    pub max_decompressed_bytes: u64,
    /// Most bytes of decoded texture images (RGB, 3 bytes per pixel) one mesh may hold.
    pub max_texture_bytes: u64,
    /// Most triangles of one mesh (after triangulation and glTF instancing).
    pub max_triangles: u64,
    /// Most vertices of one mesh (after glTF instancing). Three per triangle, so that
    /// non-indexed meshes within [`Limits::max_triangles`] always fit.
    pub max_vertices: u64,
    /// Most glTF node instances one scene graph may expand to.
    pub max_gltf_nodes: u64,
    /// Most points of one ground-truth point cloud.
    pub max_points: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_file_bytes: 2 * GIB,
            max_referenced_bytes: GIB,
            max_decompressed_bytes: GIB,
            max_texture_bytes: 4 * GIB,
            max_triangles: 50_000_000,
            max_vertices: 150_000_000,
            max_gltf_nodes: 1_000_000,
            max_points: 100_000_000,
        }
    }
}

/// One limit: its environment variable and whether it counts bytes (suffixes allowed).
struct Knob {
    env: &'static str,
    bytes: bool,
    field: fn(&mut Limits) -> &mut u64,
}

const KNOBS: [Knob; 8] = [
    Knob { env: "OBJVIEW_MAX_FILE_BYTES", bytes: true, field: |l| &mut l.max_file_bytes },
    Knob { env: "OBJVIEW_MAX_REFERENCED_BYTES", bytes: true, field: |l| &mut l.max_referenced_bytes },
    Knob { env: "OBJVIEW_MAX_DECOMPRESSED_BYTES", bytes: true, field: |l| &mut l.max_decompressed_bytes },
    Knob { env: "OBJVIEW_MAX_TEXTURE_BYTES", bytes: true, field: |l| &mut l.max_texture_bytes },
    Knob { env: "OBJVIEW_MAX_TRIANGLES", bytes: false, field: |l| &mut l.max_triangles },
    Knob { env: "OBJVIEW_MAX_VERTICES", bytes: false, field: |l| &mut l.max_vertices },
    Knob { env: "OBJVIEW_MAX_GLTF_NODES", bytes: false, field: |l| &mut l.max_gltf_nodes },
    Knob { env: "OBJVIEW_MAX_POINTS", bytes: false, field: |l| &mut l.max_points },
];

/// Parses one limit value: a positive decimal integer, with a `K`/`M`/`G` suffix (×1024ⁿ,
/// optionally followed by `iB` or `B`) when `bytes`.
fn parse_value(s: &str, bytes: bool) -> Option<u64> {
    let s = s.trim();
    let (digits, mult) = if bytes {
        let upper = s.to_ascii_uppercase();
        let stem = upper.strip_suffix("IB").or_else(|| upper.strip_suffix('B')).unwrap_or(&upper);
        match stem.chars().last() {
            Some('K') => (&s[..stem.len() - 1], KIB),
            Some('M') => (&s[..stem.len() - 1], MIB),
            Some('G') => (&s[..stem.len() - 1], GIB),
            // A bare "B" suffix is bytes; "iB" needs K, M or G before it.
            _ if !upper.ends_with("IB") => (&s[..stem.len()], 1),
            _ => return None,
        }
    } else {
        (s, 1)
    };
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse::<u64>().ok()?.checked_mul(mult).filter(|&v| v > 0)
}

impl Limits {
    /// The defaults, overridden by the `OBJVIEW_MAX_*` environment variables that are set;
    /// the error names the first variable whose value is not a valid limit.
    pub fn from_env() -> Result<Limits, String> {
        Limits::from_lookup(|name| std::env::var_os(name).map(|v| v.to_string_lossy().into_owned()))
    }

    /// [`Limits::from_env`] with the variables looked up by `get` (for tests).
    fn from_lookup(get: impl Fn(&str) -> Option<String>) -> Result<Limits, String> {
        let mut limits = Limits::default();
        for knob in &KNOBS {
            let Some(raw) = get(knob.env).filter(|v| !v.trim().is_empty()) else {
                continue;
            };
            let Some(v) = parse_value(&raw, knob.bytes) else {
                let form = if knob.bytes {
                    "a positive number of bytes, optionally with a K, M or G suffix"
                } else {
                    "a positive integer"
                };
                return Err(format!("environment variable {}='{raw}' is not {form}", knob.env));
            };
            *(knob.field)(&mut limits) = v;
        }
        Ok(limits)
    }

    /// The process-wide limits: [`Limits::from_env`], read once (the first call) and kept.
    pub fn global() -> Result<&'static Limits, &'static str> {
        static GLOBAL: OnceLock<Result<Limits, String>> = OnceLock::new();
        GLOBAL.get_or_init(Limits::from_env).as_ref().map_err(String::as_str)
    }

    /// [`Limits::global`] as a [`crate::GeomError`] naming `path` (the file being loaded).
    pub(crate) fn for_file(path: &std::path::Path) -> Result<&'static Limits, crate::GeomError> {
        Limits::global()
            .map_err(|e| crate::GeomError::io(path, std::io::Error::new(std::io::ErrorKind::InvalidInput, e)))
    }
}

/// Names a limit in error messages.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Which {
    FileBytes,
    ReferencedBytes,
    DecompressedBytes,
    TextureBytes,
    Triangles,
    Vertices,
    GltfNodes,
    Points,
}

impl Which {
    /// The environment variable that sets this limit.
    pub(crate) fn env(self) -> &'static str {
        KNOBS[self as usize].env
    }
}

/// "over the limit of N (ENV raises it)": the common tail of limit errors.
pub(crate) fn over(which: Which, limit: u64) -> String {
    format!("over the limit of {limit} ({} raises it)", which.env())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn with(vars: &[(&str, &str)]) -> Result<Limits, String> {
        let map: HashMap<String, String> = vars.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        Limits::from_lookup(|k| map.get(k).cloned())
    }

    #[test]
    fn unset_variables_give_the_documented_defaults() {
        let d = with(&[]).unwrap();
        assert_eq!(d, Limits::default());
        assert_eq!(d.max_file_bytes, 2 << 30);
        assert_eq!(d.max_triangles, 50_000_000);
        assert_eq!(d.max_vertices, 3 * d.max_triangles);
        // An empty value means "unset".
        assert_eq!(with(&[("OBJVIEW_MAX_POINTS", " ")]).unwrap(), d);
    }

    #[test]
    fn each_variable_sets_its_limit_with_byte_suffixes() {
        let l = with(&[
            ("OBJVIEW_MAX_FILE_BYTES", "4G"),
            ("OBJVIEW_MAX_REFERENCED_BYTES", "512MiB"),
            ("OBJVIEW_MAX_DECOMPRESSED_BYTES", "64kb"),
            ("OBJVIEW_MAX_TEXTURE_BYTES", "1000B"),
            ("OBJVIEW_MAX_TRIANGLES", "7"),
            ("OBJVIEW_MAX_VERTICES", "8"),
            ("OBJVIEW_MAX_GLTF_NODES", "9"),
            ("OBJVIEW_MAX_POINTS", " 10 "),
        ])
        .unwrap();
        assert_eq!(
            l,
            Limits {
                max_file_bytes: 4 << 30,
                max_referenced_bytes: 512 << 20,
                max_decompressed_bytes: 64 << 10,
                max_texture_bytes: 1000,
                max_triangles: 7,
                max_vertices: 8,
                max_gltf_nodes: 9,
                max_points: 10,
            }
        );
    }

    #[test]
    fn invalid_values_are_errors_naming_the_variable() {
        for (var, val) in [
            ("OBJVIEW_MAX_FILE_BYTES", "lots"),
            ("OBJVIEW_MAX_FILE_BYTES", "0"),
            ("OBJVIEW_MAX_FILE_BYTES", "-5"),
            ("OBJVIEW_MAX_FILE_BYTES", "1.5G"),
            ("OBJVIEW_MAX_FILE_BYTES", "99999999999G"),
            ("OBJVIEW_MAX_TRIANGLES", "5M"),
            ("OBJVIEW_MAX_POINTS", "1e6"),
        ] {
            let e = with(&[(var, val)]).unwrap_err();
            assert!(e.contains(var) && e.contains(val), "{e}");
        }
    }

    #[test]
    fn error_messages_name_each_limit_by_its_variable() {
        for (w, env) in [
            (Which::FileBytes, "OBJVIEW_MAX_FILE_BYTES"),
            (Which::ReferencedBytes, "OBJVIEW_MAX_REFERENCED_BYTES"),
            (Which::DecompressedBytes, "OBJVIEW_MAX_DECOMPRESSED_BYTES"),
            (Which::TextureBytes, "OBJVIEW_MAX_TEXTURE_BYTES"),
            (Which::Triangles, "OBJVIEW_MAX_TRIANGLES"),
            (Which::Vertices, "OBJVIEW_MAX_VERTICES"),
            (Which::GltfNodes, "OBJVIEW_MAX_GLTF_NODES"),
            (Which::Points, "OBJVIEW_MAX_POINTS"),
        ] {
            assert_eq!(w.env(), env);
        }
        assert_eq!(over(Which::Points, 5), "over the limit of 5 (OBJVIEW_MAX_POINTS raises it)");
        assert_eq!(parse_value("100", true), Some(100));
        assert_eq!(parse_value("5iB", true), None);
        assert_eq!(parse_value("2k", true), Some(2048));
    }
}
