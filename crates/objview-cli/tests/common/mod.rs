//! Helpers of the end-to-end tests, independent of the workspace's library crates: running the
//! binary, the SPEC §2 camera, analytic scenes, and minimal readers/writers of NPY, PLY, PNG, OBJ.

#![allow(dead_code)]

use std::collections::HashMap;
use std::path::Path;
use std::process::{Command, Output};

pub const SIZE: usize = 512;

// ------------------------------------------------------------------------------------ running

pub fn tempdir() -> tempfile::TempDir {
    tempfile::tempdir().expect("temporary directory")
}

pub fn s(p: &Path) -> &str {
    p.to_str().expect("UTF-8 path")
}

pub fn read(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("reading {}: {e}", p.display()))
}

pub fn objview(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_objview")).args(args).output().expect("running objview")
}

/// Runs `objview args`, asserts success, returns stdout.
pub fn objview_ok(args: &[&str]) -> String {
    let out = objview(args);
    assert!(
        out.status.success(),
        "`objview {}` failed ({}): {}",
        args.join(" "),
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("UTF-8 stdout")
}

/// Runs `objview args`, asserts a non-zero exit (not a crash by signal), returns stderr.
pub fn objview_err(args: &[&str]) -> String {
    let out = objview(args);
    let stderr = String::from_utf8(out.stderr).expect("UTF-8 stderr");
    assert!(!out.status.success(), "`objview {}` should fail, it succeeded", args.join(" "));
    assert!(out.status.code().is_some(), "`objview {}` was killed: {}", args.join(" "), out.status);
    assert!(!stderr.contains("panicked"), "`objview {}` panicked: {stderr}", args.join(" "));
    stderr
}

// ----------------------------------------------------------------------------------- vectors

pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

pub fn normalize(a: [f64; 3]) -> [f64; 3] {
    let n = norm(a);
    [a[0] / n, a[1] / n, a[2] / n]
}

// ------------------------------------------------------------------------- SPEC §2 camera

/// fx = fy = 256 / tan(22.5°).
pub fn fx() -> f64 {
    256.0 / (std::f64::consts::PI / 8.0).tan()
}

/// Normalized image coordinates of the centre of pixel (u, v): ((u + ½ − 256)/fx, (v + ½ − 256)/fy).
pub fn normalized_coords(u: usize, v: usize) -> (f64, f64) {
    ((u as f64 + 0.5 - 256.0) / fx(), (v as f64 + 0.5 - 256.0) / fx())
}

/// The camera of SPEC §2: forward f, right x = normalize(f × z), down y = f × x.
pub struct SpecCamera {
    pub center: [f64; 3],
    pub forward: [f64; 3],
    pub right: [f64; 3],
    pub down: [f64; 3],
}

impl SpecCamera {
    /// Only roll 0 and π are supported: the SPEC leaves the sense of the roll rotation to the
    /// implementation, and a half turn is the same in both senses (right, down ↦ −right, −down).
    pub fn from_pose(p: [f64; 7]) -> SpecCamera {
        let center = [p[0], p[1], p[2]];
        let mut f = normalize(sub([p[3], p[4], p[5]], center));
        for sz in [1.0, -1.0] {
            if norm(sub(f, [0.0, 0.0, sz])) < 1e-6 {
                f = normalize([1e-8, 1e-8, sz]);
            }
        }
        let mut right = normalize(cross(f, [0.0, 0.0, 1.0]));
        let mut down = cross(f, right);
        if p[6] == std::f64::consts::PI {
            right = right.map(|c| -c);
            down = down.map(|c| -c);
        } else {
            assert_eq!(p[6], 0.0, "test camera supports roll 0 and π only");
        }
        SpecCamera { center, forward: f, right, down }
    }

    /// World direction of the ray through the centre of pixel (u, v), with forward component 1
    /// (so the ray parameter is the camera-frame z).
    pub fn ray(&self, u: usize, v: usize) -> [f64; 3] {
        let (x, y) = normalized_coords(u, v);
        std::array::from_fn(|k| self.forward[k] + x * self.right[k] + y * self.down[k])
    }

    /// Continuous pixel coordinates (pixel centres at integers) and camera-frame z of `p`.
    pub fn project(&self, p: [f64; 3]) -> (f64, f64, f64) {
        let q = sub(p, self.center);
        let z = dot(q, self.forward);
        let u = fx() * dot(q, self.right) / z + 256.0 - 0.5;
        let v = fx() * dot(q, self.down) / z + 256.0 - 0.5;
        (u, v, z)
    }
}

/// Camera-frame depth of the first intersection of the ray (xn, yn, 1) (camera at the origin of
/// its frame) with the sphere of radius `rho` centred on the optical axis at distance `d`.
pub fn first_sphere_hit_depth(xn: f64, yn: f64, d: f64, rho: f64) -> Option<f64> {
    // |t·(xn, yn, 1) − (0, 0, d)|² = rho²  ⇔  t²·k − 2·t·d + d² − rho² = 0,  k = |(xn, yn, 1)|².
    let k = xn * xn + yn * yn + 1.0;
    let disc = d * d - k * (d * d - rho * rho);
    (disc >= 0.0).then(|| (d - disc.sqrt()) / k)
}

// --------------------------------------------------------------------------------- icosphere

/// An icosphere: the icosahedron's faces subdivided `level` times, midpoints pushed to the unit
/// sphere; vertex coordinates are rounded to f32 (what the OBJ file holds, exactly).
pub struct Icosphere {
    pub verts: Vec<[f64; 3]>,
    pub faces: Vec<[usize; 3]>,
}

impl Icosphere {
    pub fn new(level: u32) -> Icosphere {
        let phi = (1.0 + 5f64.sqrt()) / 2.0;
        let mut verts = Vec::new();
        for a in [-1.0, 1.0] {
            for b in [-phi, phi] {
                verts.push([a, b, 0.0]);
                verts.push([0.0, a, b]);
                verts.push([b, 0.0, a]);
            }
        }
        // Faces: the triples of mutually adjacent vertices (edge length 2).
        let adjacent = |i: usize, j: usize| (norm(sub(verts[i], verts[j])) - 2.0).abs() < 1e-9;
        let mut faces = Vec::new();
        for i in 0..12 {
            for j in i + 1..12 {
                for k in j + 1..12 {
                    if adjacent(i, j) && adjacent(j, k) && adjacent(i, k) {
                        faces.push([i, j, k]);
                    }
                }
            }
        }
        assert_eq!(faces.len(), 20);
        let mut verts: Vec<[f64; 3]> = verts.into_iter().map(normalize).collect();
        for _ in 0..level {
            let mut mid: HashMap<(usize, usize), usize> = HashMap::new();
            let mut midpoint = |a: usize, b: usize, verts: &mut Vec<[f64; 3]>| {
                *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    let (p, q) = (verts[a], verts[b]);
                    verts.push(normalize([p[0] + q[0], p[1] + q[1], p[2] + q[2]]));
                    verts.len() - 1
                })
            };
            let mut next = Vec::with_capacity(faces.len() * 4);
            for [a, b, c] in faces {
                let ab = midpoint(a, b, &mut verts);
                let bc = midpoint(b, c, &mut verts);
                let ca = midpoint(c, a, &mut verts);
                next.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
            }
            faces = next;
        }
        // Closed genus-0 surface: V = F/2 + 2.
        assert_eq!(verts.len(), faces.len() / 2 + 2);
        let verts = verts.into_iter().map(|p| p.map(|c| c as f32 as f64)).collect();
        let sphere = Icosphere { verts, faces };
        sphere.assert_convex();
        sphere
    }

    /// Outward unit normal and offset of face `i`'s plane (n·p = offset, offset > 0).
    fn plane(&self, i: usize) -> ([f64; 3], f64) {
        let [a, b, c] = self.faces[i].map(|k| self.verts[k]);
        let mut n = normalize(cross(sub(b, a), sub(c, a)));
        if dot(n, a) < 0.0 {
            n = n.map(|x| -x);
        }
        (n, dot(n, a))
    }

    /// Every vertex lies on the inner side of every face plane: the mesh bounds a convex body.
    fn assert_convex(&self) {
        for i in 0..self.faces.len() {
            let (n, off) = self.plane(i);
            for p in &self.verts {
                assert!(dot(n, *p) <= off + 1e-9, "icosphere not convex at face {i}");
            }
        }
    }

    /// Smallest distance of a face plane from the origin: the ball of this radius is inside.
    pub fn inradius(&self) -> f64 {
        (0..self.faces.len()).map(|i| self.plane(i).1).fold(f64::INFINITY, f64::min)
    }

    /// Largest vertex norm: the mesh is inside the ball of this radius.
    pub fn circumradius(&self) -> f64 {
        self.verts.iter().map(|p| norm(*p)).fold(0.0, f64::max)
    }

    /// Smallest ray parameter t > 0 at which `origin + t·dir` meets a triangle (Möller–Trumbore).
    pub fn raycast(&self, origin: [f64; 3], dir: [f64; 3]) -> Option<f64> {
        let mut best: Option<f64> = None;
        for f in &self.faces {
            let [a, b, c] = f.map(|k| self.verts[k]);
            let (e1, e2) = (sub(b, a), sub(c, a));
            let pv = cross(dir, e2);
            let det = dot(e1, pv);
            if det.abs() < 1e-15 {
                continue;
            }
            let tv = sub(origin, a);
            let u = dot(tv, pv) / det;
            let qv = cross(tv, e1);
            let v = dot(dir, qv) / det;
            let t = dot(e2, qv) / det;
            if u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0 && best.is_none_or(|b| t < b) {
                best = Some(t);
            }
        }
        best
    }

    pub fn write_obj(&self, path: &Path) {
        write_obj(path, &self.verts, &self.faces);
    }
}

// ------------------------------------------------------------------------------------ writers

/// Writes a triangle mesh as OBJ (1-based indices). Coordinates are written as f32 (shortest
/// round-trip form), so readers parsing f32 or f64 see the same values for f32-exact inputs.
pub fn write_obj(path: &Path, verts: &[[f64; 3]], faces: &[[usize; 3]]) {
    let mut s = String::from("# objview test mesh\n");
    for v in verts {
        s += &format!("v {} {} {}\n", v[0] as f32, v[1] as f32, v[2] as f32);
    }
    for f in faces {
        s += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
    }
    std::fs::write(path, s).unwrap();
}

pub fn write_ply_ascii(path: &Path, pts: &[[f64; 3]]) {
    let mut s = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
        pts.len()
    );
    for p in pts {
        s += &format!("{} {} {}\n", p[0] as f32, p[1] as f32, p[2] as f32);
    }
    std::fs::write(path, s).unwrap();
}

/// NPY v1.0, little-endian float64, shape (n, 3), C order; header padded to 64 bytes.
pub fn write_npy_f64(path: &Path, pts: &[[f64; 3]]) {
    let mut header = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': ({}, 3), }}", pts.len());
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    for p in pts {
        for c in p {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
    }
    std::fs::write(path, bytes).unwrap();
}

// ------------------------------------------------------------------------------------ readers

/// A 512×512 depth image, row-major (row = image v).
pub struct Depth {
    pub data: Vec<f32>,
}

impl Depth {
    pub fn at(&self, u: usize, v: usize) -> f32 {
        self.data[v * SIZE + u]
    }
}

/// Reads a depth NPY, asserting the contract: float32 little-endian, C order, shape (512, 512),
/// nothing after the data; every value finite and ≥ 0.
pub fn read_depth(path: &Path) -> Depth {
    let bytes = read(path);
    assert!(bytes.len() > 10 && &bytes[..6] == b"\x93NUMPY", "{}: not an NPY file", path.display());
    let (hlen, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 => (u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize, 12),
        v => panic!("{}: NPY version {v}", path.display()),
    };
    let header = std::str::from_utf8(&bytes[start..start + hlen]).unwrap();
    assert_eq!((start + hlen) % 16, 0, "NPY data must be aligned: {header:?}");
    let compact: String = header.chars().filter(|c| !c.is_whitespace()).collect();
    assert!(compact.contains("'descr':'<f4'"), "dtype: {header:?}");
    assert!(compact.contains("'fortran_order':False"), "order: {header:?}");
    assert!(compact.contains("'shape':(512,512)"), "shape: {header:?}");
    let data = &bytes[start + hlen..];
    assert_eq!(data.len(), SIZE * SIZE * 4, "{}: data size", path.display());
    let data: Vec<f32> = data.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
    assert!(
        data.iter().all(|z| z.is_finite() && *z >= 0.0),
        "{}: negative or non-finite depth",
        path.display()
    );
    Depth { data }
}

/// Reads the `vertex` element's x, y, z of a PLY file (ascii or binary little-endian; the vertex
/// element must come first). The count is the header's `element vertex N`.
pub fn read_ply_points(path: &Path) -> Vec<[f64; 3]> {
    let bytes = read(path);
    let end = b"end_header\n";
    let hend = bytes.windows(end.len()).position(|w| w == end).expect("PLY end_header") + end.len();
    let header = std::str::from_utf8(&bytes[..hend]).unwrap();
    let mut lines = header.lines();
    assert_eq!(lines.next(), Some("ply"), "PLY magic");
    let (mut format, mut count, mut props) = (String::new(), None, Vec::<(String, String)>::new());
    let mut in_vertex = false;
    for l in lines {
        let t: Vec<&str> = l.split_whitespace().collect();
        match t.as_slice() {
            ["format", f, "1.0"] => format = f.to_string(),
            ["element", "vertex", n] => {
                assert!(count.is_none(), "two vertex elements");
                count = Some(n.parse::<usize>().unwrap());
                in_vertex = true;
            }
            ["element", ..] => {
                assert!(count.is_some(), "vertex element must come first");
                in_vertex = false;
            }
            ["property", ty, name] if in_vertex => props.push((ty.to_string(), name.to_string())),
            ["property", "list", ..] if in_vertex => panic!("list property in vertex element"),
            _ => {}
        }
    }
    let n = count.expect("element vertex");
    let idx = |axis: &str| props.iter().position(|(_, p)| p == axis).unwrap_or_else(|| panic!("no {axis}"));
    let (ix, iy, iz) = (idx("x"), idx("y"), idx("z"));
    let body = &bytes[hend..];
    let mut out = Vec::with_capacity(n);
    match format.as_str() {
        "ascii" => {
            let text = std::str::from_utf8(body).unwrap();
            let mut rows = text.lines();
            for _ in 0..n {
                let v: Vec<f64> =
                    rows.next().unwrap().split_whitespace().map(|x| x.parse().unwrap()).collect();
                out.push([v[ix], v[iy], v[iz]]);
            }
        }
        "binary_little_endian" => {
            let size = |ty: &str| match ty {
                "char" | "uchar" | "int8" | "uint8" => 1,
                "short" | "ushort" | "int16" | "uint16" => 2,
                "int" | "uint" | "int32" | "uint32" | "float" | "float32" => 4,
                "double" | "float64" => 8,
                t => panic!("PLY type {t}"),
            };
            let offsets: Vec<usize> =
                props.iter().scan(0, |o, (ty, _)| Some(std::mem::replace(o, *o + size(ty)))).collect();
            let stride: usize = props.iter().map(|(ty, _)| size(ty)).sum();
            assert!(body.len() >= n * stride, "PLY body truncated: {} < {}", body.len(), n * stride);
            let get = |rec: &[u8], i: usize| -> f64 {
                let o = offsets[i];
                match props[i].0.as_str() {
                    "float" | "float32" => f32::from_le_bytes(rec[o..o + 4].try_into().unwrap()) as f64,
                    "double" | "float64" => f64::from_le_bytes(rec[o..o + 8].try_into().unwrap()),
                    t => panic!("coordinate of type {t}"),
                }
            };
            for rec in body.chunks_exact(stride).take(n) {
                out.push([get(rec, ix), get(rec, iy), get(rec, iz)]);
            }
        }
        f => panic!("PLY format {f:?}"),
    }
    out
}

pub struct Png {
    pub width: u32,
    pub height: u32,
    pub bit_depth: u8,
    pub colour_type: u8,
}

fn crc32(data: &[u8]) -> u32 {
    let mut crc = 0xFFFF_FFFFu32;
    for &b in data {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

/// Checks a PNG's structure: signature, IHDR first (13 bytes, valid fields), every chunk's CRC,
/// at least one IDAT, IEND last with nothing after it.
pub fn read_png(path: &Path) -> Png {
    let b = read(path);
    assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n", "{}: PNG signature", path.display());
    let mut pos = 8;
    let mut chunks = Vec::new();
    while pos < b.len() {
        assert!(pos + 12 <= b.len(), "truncated chunk");
        let len = u32::from_be_bytes(b[pos..pos + 4].try_into().unwrap()) as usize;
        let ty = &b[pos + 4..pos + 8];
        assert!(pos + 12 + len <= b.len(), "chunk overruns the file");
        let data = &b[pos + 8..pos + 8 + len];
        let crc = u32::from_be_bytes(b[pos + 8 + len..pos + 12 + len].try_into().unwrap());
        assert_eq!(crc, crc32(&b[pos + 4..pos + 8 + len]), "CRC of chunk {}", String::from_utf8_lossy(ty));
        chunks.push((ty.to_vec(), data.to_vec()));
        pos += 12 + len;
    }
    assert_eq!(chunks.first().map(|c| c.0.as_slice()), Some(&b"IHDR"[..]), "IHDR first");
    assert_eq!(chunks.last().map(|c| c.0.as_slice()), Some(&b"IEND"[..]), "IEND last");
    assert!(chunks.iter().any(|c| c.0 == b"IDAT"), "no IDAT");
    let ihdr = &chunks[0].1;
    assert_eq!(ihdr.len(), 13);
    let png = Png {
        width: u32::from_be_bytes(ihdr[0..4].try_into().unwrap()),
        height: u32::from_be_bytes(ihdr[4..8].try_into().unwrap()),
        bit_depth: ihdr[8],
        colour_type: ihdr[9],
    };
    assert!(matches!(png.colour_type, 0 | 2 | 3 | 4 | 6), "colour type {}", png.colour_type);
    assert!(matches!(png.bit_depth, 1 | 2 | 4 | 8 | 16), "bit depth {}", png.bit_depth);
    assert_eq!(&ihdr[10..12], &[0, 0], "compression/filter method");
    assert!(ihdr[12] <= 1, "interlace method");
    png
}
