//! The built-in seed corpus: small valid inputs of every kind, generated in code so that they
//! are the same bytes on every machine (no data files to ship or keep in sync).
//!
//! A [`Case`] is a set of files in one folder: the main file `case.<ext>` that the loader is
//! given, and the files it names (an OBJ's .mtl and texture, a glTF's external buffer and
//! image, a split file's mesh and cloud). Every seed loads as a valid object (a unit test
//! checks this), so the mutations start from inputs that reach deep into each parser.

use objview_geom::npy::npy_header;
use serde_json::{json, Value};

use crate::kinds::Kind;

/// One input: `files[0]` is the main file, the others sit beside it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Case {
    /// (file name, bytes); names are plain file names (no folders).
    pub files: Vec<(String, Vec<u8>)>,
}

impl Case {
    /// A case of one main file.
    pub fn single(kind: Kind, bytes: Vec<u8>) -> Case {
        Case { files: vec![(main_name(kind), bytes)] }
    }

    /// A case with files beside the main one.
    pub fn with(kind: Kind, bytes: Vec<u8>, side: Vec<(&str, Vec<u8>)>) -> Case {
        let mut files = vec![(main_name(kind), bytes)];
        files.extend(side.into_iter().map(|(n, b)| (n.to_string(), b)));
        Case { files }
    }

    /// The main file's bytes.
    pub fn main(&self) -> &[u8] {
        &self.files[0].1
    }

    /// Total size in bytes.
    pub fn len(&self) -> usize {
        self.files.iter().map(|(_, b)| b.len()).sum()
    }

    /// Whether every file is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Writes the files into `dir`, a folder reused from case to case: files of an earlier
    /// case that this one does not have are removed, the others overwritten (much cheaper than
    /// a fresh folder per case on a journaling file system). Returns the main file's path.
    pub fn write_into_slot(&self, dir: &std::path::Path) -> std::io::Result<std::path::PathBuf> {
        match std::fs::read_dir(dir) {
            Ok(entries) => {
                for e in entries {
                    let e = e?;
                    let keep = e.file_name().to_str().is_some_and(|n| self.files.iter().any(|(f, _)| f == n));
                    if !keep {
                        let p = e.path();
                        if e.file_type()?.is_dir() {
                            std::fs::remove_dir_all(p)?;
                        } else {
                            std::fs::remove_file(p)?;
                        }
                    }
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => std::fs::create_dir_all(dir)?,
            Err(e) => return Err(e),
        }
        for (name, bytes) in &self.files {
            std::fs::write(dir.join(name), bytes)?;
        }
        Ok(dir.join(&self.files[0].0))
    }

    /// Writes the files into `dir` (created if needed); returns the main file's path.
    pub fn write_to(&self, dir: &std::path::Path) -> std::io::Result<std::path::PathBuf> {
        std::fs::create_dir_all(dir)?;
        for (name, bytes) in &self.files {
            std::fs::write(dir.join(name), bytes)?;
        }
        Ok(dir.join(&self.files[0].0))
    }
}

/// The main file's name in a case folder: `case.<ext>`.
pub fn main_name(kind: Kind) -> String {
    format!("case.{}", kind.ext())
}

/// The seeds of `kind` (never empty).
pub fn seeds(kind: Kind) -> Vec<Case> {
    let one = |b: Vec<u8>| Case::single(kind, b);
    match kind {
        Kind::Obj => obj_seeds(),
        Kind::Ply => vec![one(ply_ascii_mesh()), one(ply_binary_mesh(true)), one(ply_binary_mesh(false))],
        Kind::Stl => {
            vec![one(stl_ascii()), one(stl_binary(b"binary stl")), one(stl_binary(b"solid but binary"))]
        }
        Kind::Off => OFF_SEEDS.iter().map(|s| one(s.as_bytes().to_vec())).collect(),
        Kind::Gltf => gltf_seeds(),
        Kind::Glb => vec![one(glb())],
        Kind::Pcd => vec![one(pcd_ascii()), one(pcd_binary()), one(pcd_compressed())],
        Kind::CloudPly => vec![one(ply_points_binary()), one(ply_ascii_mesh())],
        Kind::Npy => vec![one(npy_f8()), one(npy_f4_v2())],
        Kind::Npz => vec![one(npz(false)), one(npz(true))],
        Kind::ViewSet => vec![
            one(VIEWSET.as_bytes().to_vec()),
            one(objview_views::builtin::SHIPPED_TAMMES[0].1.as_bytes().to_vec()),
        ],
        Kind::Rules => {
            let mut v: Vec<Case> = objview_views::feasibility::BUILTIN_SPACES
                .iter()
                .map(|(_, text)| one(text.as_bytes().to_vec()))
                .collect();
            v.push(one(RULES.as_bytes().to_vec()));
            v
        }
        Kind::Split => split_seeds(),
        Kind::Annotations => vec![one(annotations())],
        Kind::Resume => vec![one(RESUME.as_bytes().to_vec())],
        Kind::Results => vec![one(results())],
        Kind::TestPanic | Kind::TestAbort | Kind::TestHang | Kind::TestOom | Kind::TestMixed => {
            (0u8..6).map(|b| one(vec![b, b'x', b'y'])).collect()
        }
    }
}

/// Kind-specific tokens the text mutations insert (keywords and statements of the format).
pub fn dictionary(kind: Kind) -> &'static [&'static str] {
    match kind {
        Kind::Obj => &[
            "v 1 2 3\n", "f 1 2 3\n", "f -1 -2 -3\n", "f 1/1/1 2/2/2 3/3/3\n", "vt 0.5 0.5\n", "vn 0 0 1\n",
            "mtllib m.mtl\n", "usemtl skin\n", "map_Kd tex.png\n", "newmtl x\n", "Kd 1 1 1\n", "o a\n", "g b\n",
            "f 0 0 0\n", "l 1 2\n", "s off\n", "\\\n", "#",
        ],
        Kind::Ply | Kind::CloudPly => &[
            "element vertex 3\n", "element face 1\n", "property float x\n", "property double y\n",
            "property list uchar int vertex_indices\n", "property list uint uint vertex_index\n",
            "property uchar red\n", "format ascii 1.0\n", "format binary_little_endian 1.0\n",
            "format binary_big_endian 1.0\n", "end_header\n", "comment c\n", "obj_info i\n", " 255 ", " -1 ",
        ],
        Kind::Stl => &[
            "solid\n", "solid s\n", "endsolid\n", "facet normal 0 0 1\n", "outer loop\n", "vertex 0 0 0\n",
            "vertex 1 0 0\n", "endloop\n", "endfacet\n",
        ],
        Kind::Off => &["OFF\n", "COFF\n", "NOFF\n", "CNOFF\n", "3 0 1 2\n", "4 0 1 2 3 255 0 0\n", "0 0 0\n", "#", " 1.0 "],
        Kind::Gltf | Kind::Glb => &[
            "\"children\":[0,0],", "\"nodes\":[0],", "\"mesh\":0,", "\"uri\":\"b.bin\",", "\"byteStride\":4,",
            "\"count\":4294967295,", "\"byteOffset\":4294967295,", "\"mode\":5,", "\"mode\":6,", "\"normalized\":true,",
            "\"componentType\":5121,", "\"type\":\"SCALAR\",", "\"sparse\":{\"count\":1,\"indices\":{\"bufferView\":0,\"componentType\":5125},\"values\":{\"bufferView\":0}},",
            "\"matrix\":[1e38,0,0,0,0,1e38,0,0,0,0,1e38,0,0,0,0,1],", "\"scene\":0,", "\"extensionsRequired\":[\"KHR_draco_mesh_compression\"],",
            "[", "{", "\"", ",", "null",
        ],
        Kind::Pcd => &[
            "COUNT 0 1 1\n", "POINTS 4294967295\n", "WIDTH 0\n", "HEIGHT 0\n", "SIZE 8 8 8\n", "TYPE I F F\n",
            "DATA ascii\n", "DATA binary\n", "DATA binary_compressed\n", "FIELDS x y z x\n", "VERSION .7\n",
        ],
        Kind::Npy | Kind::Npz => &[
            "'shape': (), ", "'shape': (0, 3), ", "'shape': (18446744073709551615, 3), ", "'descr': '<f4', ",
            "'fortran_order': True, ", "'descr': '|u1', ", "(", ")", ",", "'",
        ],
        Kind::ViewSet => &["1 0 0\n", "0 0 0\n", "nan 1 2\n", "# c\n", "1,2,3\n", "1e308 1e308 1e308\n", "5e-324 0 0\n"],
        Kind::Rules => &[
            "{\"logic\":\"or\",\"rules\":[]}", "{\"field\":\"camera_z\",\"op\":\"==\",\"value\":0}", "\"blocklist\":{\"poses\":[[0,0,0,0,0,0,0]]},",
            "\"atol\":-1,", "[", "{", "\"", ",", "null", "1e400",
        ],
        Kind::Split => &[
            "{\"mesh\":\"mesh.off\"},", "{\"mesh\":\"tri.obj\",\"uid\":\"a\"},", "\"gt_cloud\":\"c.pcd\",", "\"annotation\":{},",
            "\"sub/mesh.off\"", "[", "{", "\"", ",", "null",
        ],
        Kind::Annotations | Kind::Resume | Kind::Results => &[
            "{\"uid\":\"a\"}\n", "{\"uid\":\"a\",\"error\":\"e\"}\n", "\"terminal\"", "\"iterative\"", "\"budget\":\"0\",",
            "\"budget\":\"auto\",", "\"d_sat\":1,", "\n", "[", "{", "\"", ",", "null", "1e400",
        ],
        _ => &["x"],
    }
}

// ---------------------------------------------------------------------------------------------
// Meshes.

/// A 2×2 RGB PNG (a texture for the OBJ and glTF seeds).
pub fn png_2x2() -> Vec<u8> {
    let img = image::RgbImage::from_raw(2, 2, vec![255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255])
        .expect("2x2 RGB");
    let mut buf = std::io::Cursor::new(Vec::new());
    img.write_to(&mut buf, image::ImageFormat::Png).expect("PNG encoding in memory");
    buf.into_inner()
}

fn obj_seeds() -> Vec<Case> {
    let cube = "# textured cube\nmtllib m.mtl\no cube\n\
        v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
        vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 -1\nvn 0 0 1\n\
        usemtl skin\nf 1/1/1 4/4/1 3/3/1 2/2/1\nf 5/1/2 6/2/2 7/3/2 8/4/2\n\
        usemtl plain\nf 1 2 6 5\nf 2 3 7 6\ng top\nf 3 4 8 7\nf 4 1 5 8\n";
    let mtl = "newmtl skin\nKa 0 0 0\nKd 0.8 0.5 0.2\nmap_Kd tex.png\n\nnewmtl plain\nKd 0.1 0.2 0.3\nd 1\n";
    let plain = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\ng a\nf -4 -3 -2\nf 1 2 4\nl 1 2\np 3\ns 1\nf 2 3 4\n";
    let poly =
        "o pentagon\nv 1 0 0\nv 0.309 0.951 0\nv -0.809 0.588 0\nv -0.809 -0.588 0\nv 0.309 -0.951 0\n\
        v 0 0 1\nvt 0 0\nvt 1 1\nf 1/1 2/2 3/1 4/2 5/1\nf 1//1 2//1 6//1\n";
    vec![
        Case::with(Kind::Obj, cube.into(), vec![("m.mtl", mtl.into()), ("tex.png", png_2x2())]),
        Case::single(Kind::Obj, plain.into()),
        Case::single(Kind::Obj, poly.into()),
    ]
}

fn ply_ascii_mesh() -> Vec<u8> {
    "ply\nformat ascii 1.0\ncomment seed\nelement vertex 4\nproperty float x\nproperty float y\n\
     property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
     element face 2\nproperty list uchar int vertex_indices\nelement edge 1\nproperty int vertex1\n\
     property int vertex2\nend_header\n0 0 0 255 0 0\n1 0 0 0 255 0\n1 1 0 0 0 255\n0 1 0.25 51 102 153\n\
     4 0 1 2 3\n3 3 2 1\n0 1\n"
        .into()
}

fn ply_binary_mesh(le: bool) -> Vec<u8> {
    let fmt = if le { "binary_little_endian" } else { "binary_big_endian" };
    let (idx_t, coord_t) = if le { ("int", "double") } else { ("uint", "float") };
    let verts = [[0.0f64, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.25]];
    let faces: [&[u32]; 2] = [&[0, 1, 2, 3], &[3, 2, 1]];
    let mut b = format!(
        "ply\nformat {fmt} 1.0\nelement vertex 4\nproperty {coord_t} x\nproperty float quality\n\
         property {coord_t} y\nproperty {coord_t} z\nelement face 2\nproperty list uchar {idx_t} vertex_indices\n\
         end_header\n"
    )
    .into_bytes();
    let put = |b: &mut Vec<u8>, x: f64| {
        if le {
            b.extend(x.to_le_bytes())
        } else {
            b.extend((x as f32).to_be_bytes())
        }
    };
    for v in verts {
        put(&mut b, v[0]);
        b.extend(if le { 0.5f32.to_le_bytes() } else { 0.5f32.to_be_bytes() });
        put(&mut b, v[1]);
        put(&mut b, v[2]);
    }
    for f in faces {
        b.push(f.len() as u8);
        for &i in f {
            b.extend(if le { i.to_le_bytes() } else { i.to_be_bytes() });
        }
    }
    b
}

const TRIS: [[[f32; 3]; 3]; 3] = [
    [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
    [[1.0, 0.0, 0.0], [1.0, 1.0, 0.5], [0.0, 1.0, 0.0]],
    [[0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
];

fn stl_ascii() -> Vec<u8> {
    let mut s = String::from("solid seed\n");
    for t in TRIS {
        s.push_str("  facet normal 0 0 1\n    outer loop\n");
        for v in t {
            s.push_str(&format!("      vertex {} {} {}\n", v[0], v[1], v[2]));
        }
        s.push_str("    endloop\n  endfacet\n");
    }
    s.push_str("endsolid seed\n");
    s.into_bytes()
}

fn stl_binary(header: &[u8]) -> Vec<u8> {
    let mut b = header.to_vec();
    b.resize(80, b' ');
    b.extend((TRIS.len() as u32).to_le_bytes());
    for t in TRIS {
        b.extend([0u8; 12]);
        for v in t {
            for c in v {
                b.extend(c.to_le_bytes());
            }
        }
        b.extend([0u8; 2]);
    }
    b
}

const OFF_SEEDS: &[&str] = &[
    "OFF\n# a comment\n4 2 0\n0 0 0\n1 0 0\n1 1 0  # trailing\n\n0 1 1\n4 0 1 2 3\n3 3 2 1 255 0 51\n",
    "OFF4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 1\n4 0 1 2 3\n",
    "COFF\n3 1 0\n0 0 0 1 0 0 1\n1 0 0 0 1 0 1\n0 1 0 0 0 0.5 1\n3 0 1 2\n",
    "NOFF 3 1 0\n0 0 0 0 0 1\n2 0 0 0 0 1\n0 2 0 0 0 1\n3 0 1 2 0.5 0.5 0.5\n",
];

/// Standard base64 with padding.
pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16 | (*c.get(1).unwrap_or(&0) as u32) << 8 | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

/// The glTF seeds' buffer: a tetrahedron's positions (48 bytes), UVs (32) and u16 indices (24).
fn tetra_buffer() -> Vec<u8> {
    let pos = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let uv = [[0.0f32, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]];
    let idx: [u16; 12] = [0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3];
    let mut b = Vec::new();
    pos.iter().flatten().for_each(|x| b.extend(x.to_le_bytes()));
    uv.iter().flatten().for_each(|x| b.extend(x.to_le_bytes()));
    idx.iter().for_each(|x| b.extend(x.to_le_bytes()));
    b
}

/// A glTF document over [`tetra_buffer`]; `buffer` is the buffer object (uri or none),
/// `nodes`/`scene_nodes` the node graph; with `texture`, a material with a texture.
fn gltf_doc(buffer: Value, nodes: Value, scene_nodes: Value, texture: Option<Value>) -> Value {
    let mut doc = json!({
        "asset": {"version": "2.0", "generator": "objview-fuzz seed"},
        "scene": 0,
        "scenes": [{"nodes": scene_nodes}],
        "nodes": nodes,
        "meshes": [{"primitives": [{
            "attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0, "mode": 4
        }]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.4, 0.2, 1.0]}}],
        "buffers": [buffer],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48, "target": 34962},
            {"buffer": 0, "byteOffset": 48, "byteLength": 32, "target": 34962},
            {"buffer": 0, "byteOffset": 80, "byteLength": 24, "target": 34963}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [0.0, 0.0, 0.0], "max": [1.0, 1.0, 1.0]},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 2, "componentType": 5123, "count": 12, "type": "SCALAR"}
        ]
    });
    if let Some(image) = texture {
        doc["images"] = json!([image]);
        doc["samplers"] = json!([{}]);
        doc["textures"] = json!([{"source": 0, "sampler": 0}]);
        doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0, "texCoord": 0});
    }
    doc
}

fn gltf_seeds() -> Vec<Case> {
    let buf = tetra_buffer();
    let data_uri = json!({"byteLength": buf.len(), "uri": format!("data:application/octet-stream;base64,{}", base64(&buf))});
    let hierarchy = json!([
        {"children": [1], "translation": [0.5, 0.0, 0.0], "rotation": [0.0, 0.0, 0.3826834, 0.9238795]},
        {"mesh": 0, "scale": [2.0, 1.0, 1.0]},
        {"mesh": 0, "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 3, 0, 0, 1]}
    ]);
    let a = gltf_doc(data_uri, hierarchy, json!([0, 2]), None);
    let external = json!({"byteLength": buf.len(), "uri": "b.bin"});
    let b = gltf_doc(external.clone(), json!([{"mesh": 0}]), json!([0]), Some(json!({"uri": "tex.png"})));
    // Shared subtrees (two parents of one node): the loader refuses them (glTF requires a tree;
    // a DAG can instance a mesh exponentially often), so this seed's mutations probe that check.
    let dag = json!([{"children": [1, 2]}, {"children": [3]}, {"children": [3]}, {"mesh": 0}]);
    let c = gltf_doc(external, dag, json!([0]), None);
    let text = |v: &Value| serde_json::to_vec_pretty(v).expect("JSON");
    vec![
        Case::single(Kind::Gltf, text(&a)),
        Case::with(Kind::Gltf, text(&b), vec![("b.bin", buf.clone()), ("tex.png", png_2x2())]),
        Case::with(Kind::Gltf, text(&c), vec![("b.bin", buf)]),
    ]
}

fn glb() -> Vec<u8> {
    let buf = tetra_buffer();
    let doc = gltf_doc(
        json!({"byteLength": buf.len()}),
        json!([{"children": [1]}, {"mesh": 0, "translation": [0, 0, 1]}]),
        json!([0]),
        None,
    );
    let mut json = serde_json::to_vec(&doc).expect("JSON");
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let mut bin = buf;
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut b = b"glTF".to_vec();
    b.extend(2u32.to_le_bytes());
    b.extend((total as u32).to_le_bytes());
    b.extend((json.len() as u32).to_le_bytes());
    b.extend(0x4E4F_534Au32.to_le_bytes());
    b.extend(json);
    b.extend((bin.len() as u32).to_le_bytes());
    b.extend(0x004E_4942u32.to_le_bytes());
    b.extend(bin);
    b
}

// ---------------------------------------------------------------------------------------------
// Clouds.

const CLOUD: [[f32; 3]; 5] =
    [[0.0, 0.0, 0.0], [1.0, 0.5, -0.25], [-2.0, 3.0, 0.125], [0.5, 0.5, 0.5], [4.0, -1.0, 2.0]];

fn pcd_ascii() -> Vec<u8> {
    let mut s = String::from(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\n\
         TYPE F F F F\nCOUNT 1 1 1 1\nWIDTH 5\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 5\nDATA ascii\n",
    );
    for p in CLOUD {
        s.push_str(&format!("{} {} {} 4.2e6\n", p[0], p[1], p[2]));
    }
    s.into_bytes()
}

fn pcd_binary() -> Vec<u8> {
    let mut b = b"VERSION .7\nFIELDS intensity x y z normal\nSIZE 1 8 8 8 4\nTYPE U F F F F\n\
        COUNT 1 1 1 1 3\nWIDTH 5\nHEIGHT 1\nPOINTS 5\nDATA binary\n"
        .to_vec();
    for (i, p) in CLOUD.iter().enumerate() {
        b.push(i as u8);
        p.iter().for_each(|&c| b.extend((c as f64).to_le_bytes()));
        [0.0f32, 0.0, 1.0].iter().for_each(|c| b.extend(c.to_le_bytes()));
    }
    b
}

fn pcd_compressed() -> Vec<u8> {
    let mut raw = Vec::new();
    for k in 0..3 {
        CLOUD.iter().for_each(|p| raw.extend(p[k].to_le_bytes()));
    }
    // LZF literal runs of at most 32 bytes (valid LZF; mutations create back-references).
    let mut comp = Vec::new();
    for chunk in raw.chunks(32) {
        comp.push((chunk.len() - 1) as u8);
        comp.extend(chunk);
    }
    let mut b = b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 5\nHEIGHT 1\nPOINTS 5\n\
        DATA binary_compressed\n"
        .to_vec();
    b.extend((comp.len() as u32).to_le_bytes());
    b.extend((raw.len() as u32).to_le_bytes());
    b.extend(comp);
    b
}

fn ply_points_binary() -> Vec<u8> {
    let mut b = format!(
        "ply\nformat binary_little_endian 1.0\ncomment objview point cloud\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\nend_header\n",
        CLOUD.len()
    )
    .into_bytes();
    CLOUD.iter().flatten().for_each(|c| b.extend(c.to_le_bytes()));
    b
}

fn npy_f8() -> Vec<u8> {
    let mut b = npy_header("<f8", &[CLOUD.len(), 3]);
    CLOUD.iter().flatten().for_each(|&c| b.extend((c as f64).to_le_bytes()));
    b
}

/// A float32 (n, 4) array with a version 2.0 header (4-byte header length).
fn npy_f4_v2() -> Vec<u8> {
    let v1 = npy_header("<f4", &[CLOUD.len(), 4]);
    let dict = &v1[10..];
    let mut b = b"\x93NUMPY\x02\x00".to_vec();
    b.extend((dict.len() as u32).to_le_bytes());
    b.extend(dict);
    for p in CLOUD {
        p.iter().chain([1.0f32].iter()).for_each(|c| b.extend(c.to_le_bytes()));
    }
    b
}

fn npz(deflate: bool) -> Vec<u8> {
    use std::io::Write;
    let method = if deflate { zip::CompressionMethod::Deflated } else { zip::CompressionMethod::Stored };
    let opt = zip::write::SimpleFileOptions::default()
        .compression_method(method)
        .last_modified_time(zip::DateTime::default());
    let mut z = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let mut other = npy_header("<f8", &[1, 3]);
    other.extend([0u8; 24]);
    z.start_file("normals.npy", opt).expect("zip in memory");
    z.write_all(&other).expect("zip in memory");
    z.start_file(if deflate { "arr_0.npy" } else { "points.npy" }, opt).expect("zip in memory");
    z.write_all(&npy_f8()).expect("zip in memory");
    z.finish().expect("zip in memory").into_inner()
}

// ---------------------------------------------------------------------------------------------
// View sets, rules, splits, results.

const VIEWSET: &str = "# seed view set\n# x y z\n1 0 0\n0,1,0\n0 0 1 # trailing\n\n-1 -1 -1\n\
    0.5773502691896258 0.5773502691896258 0.5773502691896258\n3, -4, 12\n";

const RULES: &str = r#"{
  "name": "seed", "description": "nested groups and a blocklist", "pose_format": "camera_lookat_roll",
  "atol": 0.001,
  "structured_rule": {"logic": "and", "rules": [
    {"field": "camera_radius", "op": ">=", "value": 1.0},
    {"logic": "or", "rules": [
      {"field": "camera_z", "op": ">", "value": 0.0},
      {"field": "camera_x", "op": "<=", "value": -0.5},
      {"field": "roll_rad", "op": "==", "value": 0.0},
      {"field": "lookat_y", "op": "!=", "value": 1.0}
    ]},
    {"field": "lookat_z", "op": "<", "value": 10}
  ]},
  "blocklist": {"poses": [[0, 0, 3, 0, 0, 0, 0], [1.5, 1.5, 1.5, 0, 0, 0, 0.25]]}
}
"#;

fn split_seeds() -> Vec<Case> {
    let split = r#"[
  {"uid": "a", "mesh": "mesh.off", "gt_cloud": "c.pcd", "annotation": {"d_plan": 3, "d_sat": 9}},
  {"obj_path": "tri.obj", "pcd_path": null}
]
"#;
    let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    vec![Case::with(
        Kind::Split,
        split.into(),
        vec![("mesh.off", OFF_SEEDS[0].into()), ("tri.obj", tri.into()), ("c.pcd", pcd_ascii())],
    )]
}

fn annotation_line(uid: &str, d_plan: Option<usize>) -> Value {
    json!({
        "uid": uid, "mesh": format!("{uid}.obj"), "gt_cloud": "sampled(seed=0, count=20000)", "vertices": 8,
        "faces": 12, "gt_points": 20000, "surface_voxels": 1000, "curve": [[6, 500], [8, 600]], "mu": 3.0,
        "sigma": 1.0, "n_star": 7.5, "d_sat": 8, "r_vis": 0.8, "grid_n": 8, "grid_r_vis": 0.8,
        "slow_saturation": false, "degenerate_fit": false, "universe": 700, "d_plan": d_plan,
        "d_plan_status": if d_plan.is_some() { "optimal" } else { "time_limit" },
        "d_plan_bound": d_plan.unwrap_or(3), "lp_bound": 2.5, "greedy_cover": 9, "cover_views": [0, 5, 17],
        "d_plan_proven_by": if d_plan.is_some() { "ilp" } else { "none" }, "search_nodes": 12,
        "reduction": {"forced_views": [], "empty_views": 0, "dominated_views": 0,
            "elements_covered_by_forced": 0, "dominated_elements": 0, "rounds": 1,
            "reduced_views": 128, "reduced_elements": 10},
        "solver_seconds": 0.1, "seconds": 1.0,
        "timings": {"load": 0.0, "ground_truth": 0.0, "voxelize": 0.0, "visibility": 0.0, "fit": 0.0,
            "cover": 0.0},
        "settings": {"resolution": 0.02}, "version": "0.1.0"
    })
}

fn lines(values: &[Value]) -> Vec<u8> {
    let mut s = String::new();
    for v in values {
        s.push_str(&serde_json::to_string(v).expect("JSON"));
        s.push('\n');
    }
    s.into_bytes()
}

fn annotations() -> Vec<u8> {
    let failure = json!({"uid": "c", "mesh": "c.glb", "error": "c.glb: invalid GLB", "settings": {}, "version": "0.1.0"});
    lines(&[annotation_line("a", Some(4)), annotation_line("b", None), failure])
}

const RESUME: &str = "{\"uid\":\"a\",\"x\":1}\n{\"uid\":\"b\",\"error\":\"e\"}\n\n{\"uid\":\"c\",\"y\":[1,2]}\n{\"uid\":\"d\",\"x\":";

fn metrics(step: usize) -> Value {
    let v = 0.5 + 0.01 * step as f64;
    json!({"views": step + 1, "sc": {"0.01": 0.4 * v, "0.02": 0.8 * v}, "nsc": {"0.01": 0.5 * v, "0.02": v},
           "cd": 1.0 - v, "path_cost": step as f64, "runtime": 0.01 * step as f64})
}

fn episode(uid: &str, method: &str, mode: &str, budget: &str, last: usize) -> Value {
    let pose = json!([3.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    let steps: Vec<Value> = (0..=last)
        .map(|s| {
            let mut m = metrics(s);
            let o = m.as_object_mut().expect("object");
            o.insert("step".into(), json!(s));
            o.insert("pose".into(), pose.clone());
            o.insert("fused_points".into(), json!(100 * (s + 1)));
            o.insert("ms_voxels".into(), json!({"0.02": 10 * s}));
            o.insert("planner_seconds".into(), json!(0.01));
            o.insert("engine_seconds".into(), json!(0.01));
            o.insert("stage_seconds".into(), json!([0.002, 0.002, 0.004, 0.002]));
            m
        })
        .collect();
    let cp = |s: usize| {
        let mut m = metrics(s);
        m.as_object_mut().expect("object").insert("step".into(), json!(s));
        m
    };
    json!({
        "settings": {"seed": 1}, "uid": uid, "method": method, "family": "classical", "execution_mode": mode,
        "view_space": "whole", "budget": budget, "seed": 0, "start_pose": pose, "visited_poses": vec![pose.clone(); last + 1],
        "terminal_source": "algorithm_stop", "terminal_reason": "plan_end", "terminal_detail": "",
        "steps": steps, "checkpoints": {"K=2": cp(2.min(last)), "terminal": cp(last)},
        "reference": {"points": 1000, "views": 360, "view_set": "tammes-360", "observable_sc": {"0.02": 0.9}, "key": "k"},
        "gt_points": 20000, "gt_source": "sampled(seed=0, count=20000)", "wall_seconds": 1.0
    })
}

fn results() -> Vec<u8> {
    let failure = json!({"uid": "z", "mesh": "z.glb", "error": "z.glb: invalid", "settings": {"planner": "nbv", "seed": 0}});
    lines(&[
        episode("a", "nbv", "iterative", "auto", 3),
        episode("a", "nbv", "iterative", "5", 4),
        episode("b", "plan", "budgeted_plan", "5", 4),
        failure,
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_seed_loads_as_a_valid_object() {
        let dir = tempfile::tempdir().unwrap();
        for &kind in Kind::ALL {
            for (i, case) in seeds(kind).iter().enumerate() {
                let sub = dir.path().join(format!("{}-{i}", kind.name()));
                let main = case.write_to(&sub).unwrap();
                let loaded = kind.load(&main);
                if kind == Kind::Gltf && i == 2 {
                    // The shared-subtree seed: one clean error naming the second parent.
                    match loaded {
                        crate::kinds::Loaded::Error(e) => assert!(e.contains("more than one parent"), "{e}"),
                        other => panic!("the shared-subtree glTF seed must be refused: {other:?}"),
                    }
                    continue;
                }
                match loaded {
                    crate::kinds::Loaded::Ok(_) => {}
                    other => panic!("seed {i} of {}: {other:?}", kind.name()),
                }
            }
        }
    }

    #[test]
    fn seeds_are_deterministic() {
        for &kind in Kind::ALL {
            assert_eq!(seeds(kind), seeds(kind), "{}", kind.name());
        }
        assert_eq!(base64(b"any carnal pleas"), "YW55IGNhcm5hbCBwbGVhcw==");
        assert_eq!(base64(b"ab"), "YWI=");
    }
}
