//! View-set file format, angles, poses, resolution of names, and the shipped `tammes-N` data
//! checked against the best-known table and the official files.

use std::path::PathBuf;

use objview_views::tammes::{best_known_deg, file_header, DEFAULT_SEED};
use objview_views::viewset::min_pairwise_angle_deg;
use objview_views::{start_pose, ViewSet, ViewsError, START_DIRECTION};

fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data/viewsets")
}

/// The saturation grid of SPEC §4.
const GRID: &[usize] = &[
    6, 8, 10, 12, 14, 16, 20, 24, 28, 32, 40, 48, 56, 64, 80, 96, 112, 128, 144, 160, 180, 200, 270, 360,
    432, 492,
];

#[test]
fn parse_comments_blanks_and_normalization() {
    let text = "# header\n\n2 0 0\n  0 -3 0   # trailing comment\n0,0,0.5\n";
    let vs = ViewSet::parse("mem.txt", text).unwrap();
    assert_eq!(vs.dirs, vec![[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]);
    assert_eq!(vs.len(), 3);
    // (3, 4, 0) normalizes to (0.6, 0.8, 0).
    let vs = ViewSet::parse("mem.txt", "3 4 0\n").unwrap();
    assert!((vs.dirs[0][0] - 0.6).abs() < 1e-16 && (vs.dirs[0][1] - 0.8).abs() < 1e-16);
}

#[test]
fn parse_errors_name_file_and_line() {
    let cases: &[(&str, usize, &str)] = &[
        ("1 0 0\n1 2\n", 2, "expected 3 numbers"),
        ("# c\n1 0 0\n\n0 0 0\n", 4, "zero vector"),
        ("1 0 0\n1 x 0\n", 2, "y is not a number"),
        ("nan 0 1\n", 1, "x is not finite"),
        ("1 0 0\n0 1 inf\n", 2, "z is not finite"),
        ("1 0 0 4\n", 1, "expected 3 numbers"),
    ];
    for (text, line, reason) in cases {
        let e = ViewSet::parse("views.txt", text).unwrap_err();
        match &e {
            ViewsError::ViewSetLine { path, line: l, reason: r } => {
                assert_eq!(path, "views.txt");
                assert_eq!(l, line, "{text:?}");
                assert!(r.contains(reason), "{r} should contain {reason}");
            }
            other => panic!("unexpected error {other:?}"),
        }
        let msg = e.to_string();
        assert!(msg.starts_with(&format!("views.txt line {line}: ")), "{msg}");
    }
    let e = ViewSet::parse("empty.txt", "# only a comment\n\n").unwrap_err();
    assert!(matches!(e, ViewsError::EmptyViewSet { .. }));
    assert!(e.to_string().contains("empty.txt") && e.to_string().contains("empty"));
}

#[test]
fn write_load_roundtrip_is_bit_identical_and_deterministic() {
    let vs = ViewSet::from_dirs("x", &[[1.0, 2.0, 3.0], [-0.1, 1e-20, 7.0], [0.3, -0.7, 0.2]]).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("v.txt");
    vs.write(&p, &["a header".to_string()]).unwrap();
    let back = ViewSet::load(&p).unwrap();
    assert_eq!(back.dirs, vs.dirs, "bit-identical after write/load");
    let text = std::fs::read_to_string(&p).unwrap();
    assert!(text.starts_with("# a header\n"));
    assert_eq!(text, vs.to_text(&["a header".to_string()]));
    let p2 = dir.path().join("v2.txt");
    back.write(&p2, &["a header".to_string()]).unwrap();
    assert_eq!(std::fs::read(&p).unwrap(), std::fs::read(&p2).unwrap());
    // Loading a missing file names it.
    let e = ViewSet::load(&dir.path().join("missing.txt")).unwrap_err();
    assert!(e.to_string().contains("missing.txt"), "{e}");
}

#[test]
fn min_angle_of_known_configurations() {
    // Two directions 1 degree apart in the xy plane.
    let t = 1f64.to_radians();
    assert!(
        (min_pairwise_angle_deg(&[[1.0, 0.0, 0.0], [t.cos(), t.sin(), 0.0]]).unwrap() - 1.0).abs() < 1e-12
    );
    // Octahedron: 90 degrees; a cube's vertex directions: acos(1/3) = 70.5288 degrees.
    let oct = ViewSet::parse("oct", "1 0 0\n-1 0 0\n0 1 0\n0 -1 0\n0 0 1\n0 0 -1\n").unwrap();
    assert!((oct.min_angle_deg().unwrap() - 90.0).abs() < 1e-12);
    let mut cube = String::new();
    for x in [-1, 1] {
        for y in [-1, 1] {
            for z in [-1, 1] {
                cube.push_str(&format!("{x} {y} {z}\n"));
            }
        }
    }
    let cube = ViewSet::parse("cube", &cube).unwrap();
    assert!((cube.min_angle_deg().unwrap() - (1.0f64 / 3.0).acos().to_degrees()).abs() < 1e-10);
    assert_eq!(ViewSet::parse("one", "0 0 1\n").unwrap().min_angle_deg(), None);
}

#[test]
fn poses_and_start_view() {
    let vs = ViewSet::parse("p", "0 0 2\n1 1 0\n").unwrap();
    let poses = vs.poses(3.0);
    assert_eq!(poses[0].to_array(), [0.0, 0.0, 3.0, 0.0, 0.0, 0.0, 0.0]);
    let s = 3.0 / 2f64.sqrt();
    assert!((poses[1].center[0] - s).abs() < 1e-15 && (poses[1].center[1] - s).abs() < 1e-15);
    let inv = 1.0 / 3f64.sqrt();
    for c in START_DIRECTION {
        assert!((c - inv).abs() < 1e-16);
    }
    let p = start_pose(3.0);
    assert!((p.radius() - 3.0).abs() < 1e-15);
    assert!(p.center.iter().all(|&c| (c - 3.0 * inv).abs() < 1e-15));
}

#[test]
fn resolve_names_and_paths() {
    let vs = ViewSet::resolve("tammes-128").unwrap();
    assert_eq!(vs.name, "tammes-128");
    assert_eq!(vs.len(), 128);
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("mine.txt");
    std::fs::write(&p, "0 0 1\n0 1 0\n").unwrap();
    let mine = ViewSet::resolve(p.to_str().unwrap()).unwrap();
    assert_eq!(mine.len(), 2);
    for bad in ["tammes-129", "tammes-abc", "no/such/file.txt"] {
        let e = ViewSet::resolve(bad).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains(bad) && msg.contains("128") && msg.contains("492"), "{msg}");
    }
}

#[test]
fn every_grid_size_is_built_in_and_within_half_percent_of_best_known() {
    for &n in GRID {
        let name = format!("tammes-{n}");
        let vs = ViewSet::resolve(&name).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(vs.len(), n, "{name}");
        // The shipped file on disk is what is built in.
        let disk = ViewSet::load(&data_dir().join(format!("{name}.txt"))).unwrap();
        assert_eq!(disk.dirs, vs.dirs, "{name}");
        for d in &vs.dirs {
            let r = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            assert!((r - 1.0).abs() < 1e-15, "{name}: |d| = {r}");
        }
        let a = vs.min_angle_deg().unwrap();
        let best = best_known_deg(n).unwrap_or_else(|| panic!("no best-known angle for {n}"));
        assert!(a >= 0.995 * best, "{name}: min angle {a} < 0.995 * best-known {best}");
        // Sanity bound against a broken angle computation: tammes-144, -200 and -492 do exceed
        // the table (17.5928469 vs 17.5923906, 14.9963766 vs 14.9963567, 9.5565446 vs
        // 9.5559128; recomputed independently).
        assert!(a <= best * 1.0001, "{name}: min angle {a} far above best-known {best}");
    }
}

#[test]
fn generated_files_have_headers_matching_their_content() {
    for &n in GRID.iter().filter(|&&n| n != 128 && n != 360) {
        let path = data_dir().join(format!("tammes-{n}.txt"));
        let text = std::fs::read_to_string(&path).unwrap();
        let vs = ViewSet::parse("x", &text).unwrap();
        let header: Vec<String> = text
            .lines()
            .take_while(|l| l.starts_with('#'))
            .map(|l| l.trim_start_matches("# ").to_string())
            .collect();
        // The header is exactly what the generator writes for this content.
        assert_eq!(header, file_header(&vs, DEFAULT_SEED), "{}", path.display());
        assert!(header[1].contains("generator: objview-tammes 1") && header[1].contains("seed 20260523"));
        let stated: f64 = header[2]["min_angle_deg: ".len()..].trim().parse().unwrap();
        assert!((stated - vs.min_angle_deg().unwrap()).abs() < 1e-8, "tammes-{n}");
    }
}

fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3))
}

#[test]
fn official_sets_are_verbatim_copies() {
    // Length and FNV-1a hash of the official files (github.com/Hoooozier/objview_bench,
    // benchmark/Tammes_sphere/), recorded when they were copied.
    let expected: &[(usize, usize, u64)] =
        &[(128, 5952, 0xa93b_3505_14da_8015), (360, 16737, 0x81b7_1c23_09e4_4ea4)];
    for &(n, len, hash) in expected {
        let shipped = std::fs::read(data_dir().join(format!("tammes-{n}.txt"))).unwrap();
        assert_eq!(shipped.len(), len, "tammes-{n}");
        assert_eq!(fnv1a(&shipped), hash, "tammes-{n}");
        // Where the shared official copy is present, compare byte for byte too.
        let official = PathBuf::from(format!("/work/shared/official/Tammes_sphere/{n}_xyz.txt"));
        if let Ok(bytes) = std::fs::read(&official) {
            assert_eq!(bytes, shipped, "tammes-{n} differs from {}", official.display());
        }
    }
    let notice = std::fs::read_to_string(data_dir().join("NOTICE-official.md")).unwrap();
    assert!(notice.contains("MIT License") && notice.contains("Hoooozier"));
    // The official angles equal the best-known values (to the files' 12 decimals).
    for n in [128, 360] {
        let a = ViewSet::resolve(&format!("tammes-{n}")).unwrap().min_angle_deg().unwrap();
        assert!((a - best_known_deg(n).unwrap()).abs() < 1e-5, "tammes-{n}: {a}");
    }
}
