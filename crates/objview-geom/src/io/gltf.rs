//! glTF 2.0 / GLB loading — the format of Objaverse, the benchmark's main real-world source.
//!
//! The `gltf` crate parses and validates the JSON document and gives typed access to scenes,
//! nodes, meshes and materials. Buffer data is resolved and accessors are decoded here, with
//! explicit bounds checks (the crate's own readers assert on malformed strides and sizes, and
//! a malformed asset must become an error, never a panic). Decoding writes straight into the
//! output vectors: no per-vertex allocation.
//!
//! What is loaded (SPEC §1): every primitive of every node of the default scene (all scenes
//! when none is marked default), with node transforms composed down the hierarchy and applied
//! — a mesh instanced by two nodes appears twice. Triangle lists, strips and fans are read
//! (strips/fans converted to lists), indexed or not; points and lines are skipped. Positions
//! may be float or (KHR_mesh_quantization) integer, normalized or not; sparse accessors are
//! applied. Appearance: each material's baseColorFactor and baseColorTexture (PNG/JPEG, with
//! the texture's own TEXCOORD set) give [`Appearance::Textured`] (the diffuse factor/texture
//! for KHR_materials_pbrSpecularGlossiness materials); KHR_texture_transform and vertex
//! colours are ignored; a document whose textures have no `source` (WebP/Basis images given
//! only by an extension) is loaded without textures. Geometry-compression extensions (Draco, meshopt) are reported
//! as unsupported.
//!
//! Untrusted documents: the node graph must be a forest as glTF 2.0 requires (a node has at
//! most one parent and is listed once in its children array, no cycles, a scene root is no
//! node's child), so expansion is linear in the document; node instances, vertices and
//! triangles are capped by the [`Limits`]. External buffers and images are read only when a
//! primitive or a used material needs them, only from inside the asset's folder
//! ([`crate::fsutil::resolve_inside`]) and only as size-capped regular files.

use crate::limits::{over, Limits, Which};
use crate::mesh::{Appearance, Material, Texture};
use crate::{GeomError, Mesh};
use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::json::validation::Validate;
use ::gltf::mesh::Mode;
use std::borrow::Cow;
use std::cell::OnceCell;
use std::collections::HashMap;
use std::path::Path;

const GLB_MAGIC: &[u8; 4] = b"glTF";
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;

/// Loads a glTF or GLB file. The caller validates the result.
pub(super) fn load(path: &Path, limits: &Limits) -> Result<Mesh, GeomError> {
    let bytes = super::read_input(path, limits)?;
    let (json, blob) = if bytes.starts_with(GLB_MAGIC) {
        split_glb(path, &bytes)?
    } else {
        let is_glb = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("glb"));
        if is_glb {
            return Err(GeomError::parse(path, "invalid GLB: missing 'glTF' magic"));
        }
        (&bytes[..], None)
    };
    let root = match ::gltf::json::Root::from_slice(json) {
        Ok(root) => root,
        Err(e) => without_sourceless_textures(json)
            .ok_or_else(|| GeomError::parse(path, format!("invalid glTF JSON: {e}")))?,
    };
    let root = match validate(path, &root) {
        Ok(()) => root,
        Err(e) => {
            let stripped = without_sourceless_textures(json).ok_or(e)?;
            validate(path, &stripped)?;
            stripped
        }
    };
    let doc = ::gltf::Document::from_json_without_validation(root);
    let buffers = Buffers { blob, data: doc.buffers().map(|_| OnceCell::new()).collect() };
    Loader::new(path, limits, &doc, &buffers).run()
}

/// Splits a GLB container into its JSON chunk and optional BIN chunk.
fn split_glb<'a>(path: &Path, b: &'a [u8]) -> Result<(&'a [u8], Option<&'a [u8]>), GeomError> {
    let bad = |why: String| GeomError::parse(path, format!("invalid GLB: {why}"));
    let u32_at =
        |o: usize| -> Option<u32> { b.get(o..o + 4).map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]])) };
    let (Some(version), Some(length)) = (u32_at(4), u32_at(8)) else {
        return Err(bad(format!("{} bytes, shorter than the 12-byte header", b.len())));
    };
    if version != 2 {
        return Err(bad(format!("container version {version} (only glTF 2.0 is supported)")));
    }
    let length = length as usize;
    if length > b.len() {
        return Err(bad(format!("header declares {length} bytes but the file has {} (truncated)", b.len())));
    }
    let b = &b[..length];
    let (Some(json_len), Some(json_type)) = (u32_at(12), u32_at(16)) else {
        return Err(bad("no JSON chunk".into()));
    };
    if json_type != CHUNK_JSON {
        return Err(bad("first chunk is not JSON".into()));
    }
    let json_end = 20usize.saturating_add(json_len as usize);
    let Some(json) = b.get(20..json_end) else {
        return Err(bad(format!("JSON chunk of {json_len} bytes runs past the end of the file")));
    };
    let bin_start = json_end.div_ceil(4) * 4;
    let mut blob = None;
    if let (Some(bin_len), Some(bin_type)) = (u32_at(bin_start), u32_at(bin_start + 4)) {
        if bin_start + 8 <= b.len() && bin_type == CHUNK_BIN {
            let end = (bin_start + 8).saturating_add(bin_len as usize);
            let Some(bin) = b.get(bin_start + 8..end) else {
                return Err(bad(format!("BIN chunk of {bin_len} bytes runs past the end of the file")));
            };
            blob = Some(bin);
        }
    }
    Ok((json, blob))
}

/// Fallback for documents the `gltf` crate refuses because a texture has no `source` (its
/// image is only given by an extension such as EXT_texture_webp or KHR_texture_basisu, which
/// Objaverse assets use): drop all textures and texture references, keep geometry and base
/// colours. `None` if the document is not such a case (the original error is reported).
fn without_sourceless_textures(json: &[u8]) -> Option<::gltf::json::Root> {
    let mut v: serde_json::Value = serde_json::from_slice(json).ok()?;
    let textures = v.get("textures")?.as_array()?;
    if textures.iter().all(|t| t.get("source").is_some()) {
        return None;
    }
    let obj = v.as_object_mut()?;
    for key in ["textures", "images", "samplers"] {
        obj.remove(key);
    }
    /// Removes every `...Texture` key (a texture reference) below a material.
    fn strip(v: &mut serde_json::Value) {
        match v {
            serde_json::Value::Object(m) => {
                m.retain(|k, _| !k.ends_with("Texture"));
                m.values_mut().for_each(strip);
            }
            serde_json::Value::Array(a) => a.iter_mut().for_each(strip),
            _ => {}
        }
    }
    if let Some(mats) = obj.get_mut("materials") {
        strip(mats);
    }
    ::gltf::json::Root::from_slice(&serde_json::to_vec(&v).ok()?).ok()
}

/// Validates the document's references; `extensionsRequired` entries are tolerated except
/// the geometry-compression ones, whose data this loader cannot decode.
fn validate(path: &Path, root: &::gltf::json::Root) -> Result<(), GeomError> {
    let mut errors: Vec<String> = Vec::new();
    root.validate(root, ::gltf::json::Path::new, &mut |p, e| {
        let p = p();
        let s = p.as_str();
        if s.starts_with("extensionsRequired") && !s.contains("draco") && !s.contains("meshopt") {
            return;
        }
        errors.push(format!("{s}: {e:?}"));
    });
    if let Some(first) = errors.first() {
        let more = if errors.len() > 1 { format!(" (and {} more)", errors.len() - 1) } else { String::new() };
        let what = if first.contains("draco") || first.contains("meshopt") {
            "unsupported compressed geometry"
        } else {
            "invalid glTF"
        };
        return Err(GeomError::parse(path, format!("{what}: {first}{more}")));
    }
    Ok(())
}

/// Standard base64 decoding (padding optional, whitespace ignored); `None` on a bad symbol.
fn base64_decode(s: &str) -> Option<Vec<u8>> {
    let mut out = Vec::with_capacity(s.len() / 4 * 3);
    let (mut acc, mut bits) = (0u32, 0u32);
    for c in s.bytes() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            b'=' => break,
            b' ' | b'\n' | b'\r' | b'\t' => continue,
            _ => return None,
        } as u32;
        acc = (acc << 6) | v;
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    Some(out)
}

/// The reason of an error about a referenced file, without the asset's name (the caller's
/// error names it).
fn reason(e: GeomError) -> String {
    match e {
        GeomError::Parse { reason, .. } | GeomError::Invalid { reason, .. } => reason,
        e => e.to_string(),
    }
}

/// Reads the bytes a URI points to: a `data:` URI, or a file inside the glTF file's folder
/// (a size-capped regular file, see [`crate::fsutil`]).
fn read_uri(path: &Path, uri: &str, limits: &Limits) -> Result<Vec<u8>, String> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let Some((_, data)) = rest.split_once(";base64,") else {
            return Err("data URI is not base64".into());
        };
        return base64_decode(data).ok_or_else(|| "bad base64 in data URI".to_string());
    }
    if uri.contains("://") {
        return Err(format!("unsupported URI scheme in '{uri}'"));
    }
    let file = crate::fsutil::resolve_inside(path, uri).map_err(reason)?;
    super::read_referenced(&file, limits).map_err(reason)
}

/// The document's buffers, each read on first use: a buffer that no primitive or used image
/// needs is never read.
struct Buffers<'b> {
    /// The GLB BIN chunk.
    blob: Option<&'b [u8]>,
    /// Per buffer: its data, or why it is unavailable (reported only if geometry needs it).
    data: Vec<OnceCell<Result<Cow<'b, [u8]>, String>>>,
}

impl<'b> Buffers<'b> {
    /// The data of `buffer`, read now if it has not been yet.
    fn get(&self, path: &Path, limits: &Limits, buffer: &::gltf::Buffer) -> Result<&[u8], &str> {
        let Some(cell) = self.data.get(buffer.index()) else {
            return Err("buffer index out of range");
        };
        let data = cell.get_or_init(|| {
            let data: Cow<'b, [u8]> = match buffer.source() {
                ::gltf::buffer::Source::Bin => {
                    Cow::Borrowed(self.blob.ok_or_else(|| "GLB has no BIN chunk".to_string())?)
                }
                ::gltf::buffer::Source::Uri(uri) => Cow::Owned(
                    read_uri(path, uri, limits).map_err(|e| format!("buffer {}: {e}", buffer.index()))?,
                ),
            };
            if data.len() < buffer.length() {
                return Err(format!(
                    "buffer {} has {} bytes, declares {}",
                    buffer.index(),
                    data.len(),
                    buffer.length()
                ));
            }
            Ok(data)
        });
        match data {
            Ok(d) => Ok(d.as_ref()),
            Err(e) => Err(e.as_str()),
        }
    }
}

/// A column-major 4×4 affine transform in f64.
type Mat4 = [[f64; 4]; 4];

const IDENTITY: Mat4 =
    [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

fn mat_mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut r = [[0.0; 4]; 4];
    for (c, col) in r.iter_mut().enumerate() {
        for (row, v) in col.iter_mut().enumerate() {
            *v = (0..4).map(|k| a[k][row] * b[c][k]).sum();
        }
    }
    r
}

#[inline]
fn transform_point(m: &Mat4, p: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| m[0][r] * p[0] + m[1][r] * p[1] + m[2][r] * p[2] + m[3][r])
}

/// Size in bytes of one component.
fn component_size(t: DataType) -> usize {
    match t {
        DataType::I8 | DataType::U8 => 1,
        DataType::I16 | DataType::U16 => 2,
        DataType::U32 | DataType::F32 => 4,
    }
}

/// Reads component `c` of type `t` at the start of `s` as f64 (normalized integers mapped
/// to [0, 1] or [-1, 1] as glTF defines).
#[inline]
fn read_component(s: &[u8], t: DataType, normalized: bool) -> f64 {
    match t {
        DataType::F32 => f32::from_le_bytes([s[0], s[1], s[2], s[3]]) as f64,
        DataType::U32 => {
            let v = u32::from_le_bytes([s[0], s[1], s[2], s[3]]) as f64;
            if normalized {
                v / u32::MAX as f64
            } else {
                v
            }
        }
        DataType::U16 => {
            let v = u16::from_le_bytes([s[0], s[1]]) as f64;
            if normalized {
                v / 65535.0
            } else {
                v
            }
        }
        DataType::I16 => {
            let v = i16::from_le_bytes([s[0], s[1]]) as f64;
            if normalized {
                (v / 32767.0).max(-1.0)
            } else {
                v
            }
        }
        DataType::U8 => {
            let v = s[0] as f64;
            if normalized {
                v / 255.0
            } else {
                v
            }
        }
        DataType::I8 => {
            let v = s[0] as i8 as f64;
            if normalized {
                (v / 127.0).max(-1.0)
            } else {
                v
            }
        }
    }
}

/// Where an image's bytes come from, to decode each source once.
#[derive(PartialEq, Eq, Hash)]
enum ImageKey {
    /// (buffer index, byte offset, byte length) of a buffer view.
    View(usize, usize, usize),
    Uri(String),
}

struct Loader<'a, 'b> {
    path: &'a Path,
    limits: &'a Limits,
    doc: &'a ::gltf::Document,
    buffers: &'a Buffers<'b>,
    positions: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
    corner_uvs: Vec<[[f32; 2]; 3]>,
    face_material: Vec<u32>,
    materials: Vec<Material>,
    textures: Vec<Texture>,
    /// Bytes of the decoded textures so far (against [`Limits::max_texture_bytes`]).
    texture_bytes: u64,
    /// (glTF material index or None for the default material, textured?) -> our index.
    material_index: HashMap<(Option<usize>, bool), u32>,
    /// glTF image index -> decoded texture index (None: not decodable).
    image_cache: HashMap<usize, Option<usize>>,
    /// Image source -> decoded texture index, so that images sharing a source decode once.
    source_cache: HashMap<ImageKey, Option<usize>>,
    /// Scratch buffers reused across primitives.
    prim_pos: Vec<[f64; 3]>,
    prim_uv: Vec<[f64; 2]>,
    prim_idx: Vec<u32>,
}

impl<'a, 'b> Loader<'a, 'b> {
    fn new(path: &'a Path, limits: &'a Limits, doc: &'a ::gltf::Document, buffers: &'a Buffers<'b>) -> Self {
        Loader {
            path,
            limits,
            doc,
            buffers,
            positions: Vec::new(),
            triangles: Vec::new(),
            corner_uvs: Vec::new(),
            face_material: Vec::new(),
            materials: Vec::new(),
            textures: Vec::new(),
            texture_bytes: 0,
            material_index: HashMap::new(),
            image_cache: HashMap::new(),
            source_cache: HashMap::new(),
            prim_pos: Vec::new(),
            prim_uv: Vec::new(),
            prim_idx: Vec::new(),
        }
    }

    fn err(&self, reason: String) -> GeomError {
        GeomError::parse(self.path, reason)
    }

    /// The parent of each node, after checking that the nodes form a forest as glTF 2.0
    /// requires: a node has at most one parent, a parent lists a child once, and there is no
    /// cycle. A shared child would be expanded once per path to it (exponentially many).
    fn parents(&self) -> Result<Vec<Option<usize>>, GeomError> {
        let n = self.doc.nodes().len();
        let mut parent: Vec<Option<usize>> = vec![None; n];
        for node in self.doc.nodes() {
            let p = node.index();
            for child in node.children() {
                let c = child.index();
                match parent[c] {
                    Some(q) if q == p => {
                        return Err(self.err(format!("invalid glTF: node {p} lists child {c} twice")));
                    }
                    Some(q) => {
                        return Err(self.err(format!(
                            "invalid glTF: node {c} has more than one parent (nodes {q} and {p}); \
                             the node hierarchy must be a tree"
                        )));
                    }
                    None => parent[c] = Some(p),
                }
            }
        }
        // Cycles: walk up from every node; 1 = on the current walk, 2 = known to reach a root.
        let mut state = vec![0u8; n];
        let mut walk = Vec::new();
        for start in 0..n {
            let mut v = start;
            walk.clear();
            loop {
                match state[v] {
                    1 => {
                        return Err(self
                            .err(format!("invalid glTF: node hierarchy contains a cycle through node {v}")));
                    }
                    2 => break,
                    _ => {}
                }
                state[v] = 1;
                walk.push(v);
                match parent[v] {
                    Some(p) => v = p,
                    None => break,
                }
            }
            for &w in &walk {
                state[w] = 2;
            }
        }
        Ok(parent)
    }

    fn run(mut self) -> Result<Mesh, GeomError> {
        let doc = self.doc;
        let parent = self.parents()?;
        // Root nodes: of the default scene, else of every scene, else every node that is no
        // other node's child (a document without scenes).
        let scenes: Vec<::gltf::Scene> = match doc.default_scene() {
            Some(s) => vec![s],
            None => doc.scenes().collect(),
        };
        let mut roots: Vec<::gltf::Node> = Vec::new();
        for scene in &scenes {
            let mut listed = std::collections::HashSet::new();
            for node in scene.nodes() {
                let r = node.index();
                if let Some(p) = parent[r] {
                    return Err(self.err(format!(
                        "invalid glTF: node {r} is a root of scene {} and also a child of node {p}",
                        scene.index()
                    )));
                }
                if !listed.insert(r) {
                    return Err(
                        self.err(format!("invalid glTF: scene {} lists node {r} twice", scene.index()))
                    );
                }
                roots.push(node);
            }
        }
        if doc.scenes().len() == 0 {
            roots = doc.nodes().filter(|n| parent[n.index()].is_none()).collect();
        }
        let mut instances: u64 = 0;
        let mut stack: Vec<(::gltf::Node, Mat4)> = roots.into_iter().rev().map(|n| (n, IDENTITY)).collect();
        while let Some((node, parent)) = stack.pop() {
            instances += 1;
            if instances > self.limits.max_gltf_nodes {
                let o = over(Which::GltfNodes, self.limits.max_gltf_nodes);
                return Err(GeomError::invalid(
                    self.path,
                    format!("the scene graph has too many node instances, {o}"),
                ));
            }
            let local = node.transform().matrix().map(|c| c.map(|v| v as f64));
            let world = mat_mul(&parent, &local);
            if let Some(mesh) = node.mesh() {
                for prim in mesh.primitives() {
                    self.primitive(&mesh, &prim, &world)?;
                }
            }
            for child in node.children().collect::<Vec<_>>().into_iter().rev() {
                stack.push((child, world));
            }
        }
        let appearance = if doc.materials().len() == 0 {
            Appearance::None
        } else {
            Appearance::Textured {
                corner_uvs: self.corner_uvs,
                face_material: self.face_material,
                materials: self.materials,
                textures: self.textures,
            }
        };
        Ok(Mesh { positions: self.positions, triangles: self.triangles, appearance })
    }

    /// Bytes of an accessor's elements: (data starting at element 0, stride, element size).
    fn accessor_bytes(
        &self,
        what: &str,
        view: &::gltf::buffer::View,
        offset: usize,
        count: usize,
        elem: usize,
    ) -> Result<(&'a [u8], usize), GeomError> {
        let buffers: &'a Buffers<'b> = self.buffers;
        let data = match buffers.get(self.path, self.limits, &view.buffer()) {
            Ok(d) => d,
            Err(why) => return Err(self.err(format!("{what}: {why}"))),
        };
        let stride = view.stride().unwrap_or(elem);
        if stride < elem {
            return Err(self.err(format!("{what}: byteStride {stride} < element size {elem}")));
        }
        let view_end = view.offset().saturating_add(view.length());
        let Some(view_bytes) = data.get(view.offset()..view_end) else {
            return Err(self.err(format!("{what}: buffer view outside its buffer")));
        };
        let need = if count == 0 {
            0
        } else {
            offset.saturating_add(stride.saturating_mul(count - 1)).saturating_add(elem)
        };
        if need > view_bytes.len() {
            return Err(self.err(format!(
                "{what}: {count} elements need {need} bytes, buffer view has {}",
                view_bytes.len()
            )));
        }
        Ok((&view_bytes[offset.min(view_bytes.len())..], stride))
    }

    /// Decodes an accessor of `N` components per element into `out` (cleared first), applying
    /// sparse substitution.
    fn read_vec<const N: usize>(
        &self,
        what: &str,
        acc: &::gltf::Accessor,
        out: &mut Vec<[f64; N]>,
    ) -> Result<(), GeomError> {
        let dims = match acc.dimensions() {
            Dimensions::Scalar => 1,
            Dimensions::Vec2 => 2,
            Dimensions::Vec3 => 3,
            Dimensions::Vec4 => 4,
            _ => 0,
        };
        if dims != N {
            return Err(
                self.err(format!("{what}: expected {N} components, accessor has {:?}", acc.dimensions()))
            );
        }
        let t = acc.data_type();
        let cs = component_size(t);
        let elem = cs * N;
        let norm = acc.normalized();
        let count = acc.count();
        out.clear();
        match acc.view() {
            Some(view) => {
                let (bytes, stride) = self.accessor_bytes(what, &view, acc.offset(), count, elem)?;
                out.reserve(count);
                for i in 0..count {
                    let e = &bytes[i * stride..];
                    out.push(std::array::from_fn(|c| read_component(&e[c * cs..], t, norm)));
                }
            }
            None => {
                // Zero-initialized (sparse-only) accessor: refuse counts no buffer could back,
                // so a lying header cannot exhaust memory.
                let bytes = self.doc.buffers().fold(0usize, |a, b| a.saturating_add(b.length()));
                if count > bytes.saturating_add(1) || count as u64 > self.limits.max_vertices {
                    return Err(
                        self.err(format!("{what}: accessor without a buffer view claims {count} elements"))
                    );
                }
                out.resize(count, [0.0; N]);
            }
        }
        if let Some(sparse) = acc.sparse() {
            let n = sparse.count();
            let iv = sparse.indices();
            let it = match iv.index_type() {
                ::gltf::accessor::sparse::IndexType::U8 => DataType::U8,
                ::gltf::accessor::sparse::IndexType::U16 => DataType::U16,
                ::gltf::accessor::sparse::IndexType::U32 => DataType::U32,
            };
            let ics = component_size(it);
            let (ib, istride) = self.accessor_bytes(what, &iv.view(), iv.offset(), n, ics)?;
            let vv = sparse.values();
            let (vb, vstride) = self.accessor_bytes(what, &vv.view(), vv.offset(), n, elem)?;
            for k in 0..n {
                let target = read_component(&ib[k * istride..], it, false) as usize;
                let Some(slot) = out.get_mut(target) else {
                    return Err(self.err(format!("{what}: sparse index {target} >= count {count}")));
                };
                let e = &vb[k * vstride..];
                *slot = std::array::from_fn(|c| read_component(&e[c * cs..], t, norm));
            }
        }
        Ok(())
    }

    /// Decodes an index accessor into `self.prim_idx`.
    fn read_indices(&mut self, what: &str, acc: &::gltf::Accessor) -> Result<(), GeomError> {
        let t = acc.data_type();
        if !matches!(t, DataType::U8 | DataType::U16 | DataType::U32)
            || acc.dimensions() != Dimensions::Scalar
        {
            return Err(self.err(format!("{what}: indices must be unsigned integer scalars")));
        }
        // Indices are exact in f64 (< 2^32), so the generic decoder serves.
        let mut tmp: Vec<[f64; 1]> = Vec::new();
        self.read_vec::<1>(what, acc, &mut tmp)?;
        self.prim_idx.clear();
        self.prim_idx.extend(tmp.iter().map(|v| v[0] as u32));
        Ok(())
    }

    fn primitive(
        &mut self,
        mesh: &::gltf::Mesh,
        prim: &::gltf::Primitive,
        world: &Mat4,
    ) -> Result<(), GeomError> {
        let mode = prim.mode();
        if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
            return Ok(());
        }
        let what = format!("mesh {} primitive {}", mesh.index(), prim.index());
        let Some(pos_acc) = prim.get(&::gltf::Semantic::Positions) else {
            return Err(self.err(format!("{what}: no POSITION attribute")));
        };
        let mut pos = std::mem::take(&mut self.prim_pos);
        self.read_vec::<3>(&format!("{what} POSITION"), &pos_acc, &mut pos)?;
        let nv = pos.len();
        match prim.indices() {
            Some(acc) => self.read_indices(&format!("{what} indices"), &acc)?,
            None => {
                self.prim_idx.clear();
                self.prim_idx.extend(0..nv as u32);
            }
        }
        if let Some(&bad) = self.prim_idx.iter().find(|&&i| i as usize >= nv) {
            return Err(GeomError::invalid(
                self.path,
                format!("{what}: index {bad} out of range ({nv} vertices)"),
            ));
        }
        let base = self.positions.len();
        if base + nv > u32::MAX as usize {
            return Err(GeomError::invalid(self.path, "more than 2^32 vertices"));
        }
        let added = match mode {
            Mode::Triangles => self.prim_idx.len() / 3,
            _ => self.prim_idx.len().saturating_sub(2),
        };
        // The limits, before the instance is materialized.
        super::check_counts(self.path, base + nv, self.triangles.len() + added, self.limits)?;
        self.positions.extend(pos.iter().map(|&p| transform_point(world, p)));
        self.prim_pos = pos;

        // Material and UVs.
        let material = prim.material();
        // Base colour: metallic-roughness, or the diffuse of the specular-glossiness
        // extension when the material uses it (its metallic-roughness part is then absent).
        let (factor, tex_info) = match material.pbr_specular_glossiness() {
            Some(sg) => (sg.diffuse_factor(), sg.diffuse_texture()),
            None => {
                let mr = material.pbr_metallic_roughness();
                (mr.base_color_factor(), mr.base_color_texture())
            }
        };
        let mut textured = false;
        let mut uv = std::mem::take(&mut self.prim_uv);
        uv.clear();
        let mut texture = None;
        if let Some(info) = &tex_info {
            if let Some(acc) = prim.get(&::gltf::Semantic::TexCoords(info.tex_coord())) {
                if acc.count() == nv {
                    self.read_vec::<2>(&format!("{what} TEXCOORD_{}", info.tex_coord()), &acc, &mut uv)?;
                    texture = self.texture(info.texture().source())?;
                    textured = texture.is_some();
                }
            }
        }
        let key = (material.index(), textured);
        let mat_id = match self.material_index.get(&key) {
            Some(&m) => m,
            None => {
                let f = factor;
                self.materials.push(Material { base_color: [f[0], f[1], f[2]], texture });
                let m = (self.materials.len() - 1) as u32;
                self.material_index.insert(key, m);
                m
            }
        };

        // Triangles of this primitive (local indices), converted from strips/fans.
        let idx = &self.prim_idx;
        let before = self.triangles.len();
        let b = base as u32;
        match mode {
            Mode::Triangles => {
                self.triangles.extend(idx.chunks_exact(3).map(|t| [t[0] + b, t[1] + b, t[2] + b]));
            }
            Mode::TriangleStrip => {
                for i in 2..idx.len() {
                    let (p, q) = if i % 2 == 0 { (idx[i - 2], idx[i - 1]) } else { (idx[i - 1], idx[i - 2]) };
                    self.triangles.push([p + b, q + b, idx[i] + b]);
                }
            }
            _ => {
                for i in 2..idx.len() {
                    self.triangles.push([idx[0] + b, idx[i - 1] + b, idx[i] + b]);
                }
            }
        }
        let added = self.triangles.len() - before;
        self.face_material.extend(std::iter::repeat_n(mat_id, added));
        if textured {
            let tris = &self.triangles[before..];
            self.corner_uvs.extend(tris.iter().map(|t| {
                t.map(|i| {
                    let u = uv[(i - b) as usize];
                    [u[0] as f32, u[1] as f32]
                })
            }));
        } else {
            self.corner_uvs.extend(std::iter::repeat_n([[0.0f32; 2]; 3], added));
        }
        self.prim_uv = uv;
        Ok(())
    }

    /// Decodes an image once; `None` when its data is unavailable (missing, outside the
    /// asset's folder, not a regular file, over the size limit) or not PNG/JPEG. Errors only
    /// when the decoded textures would exceed [`Limits::max_texture_bytes`].
    fn texture(&mut self, image: ::gltf::Image) -> Result<Option<usize>, GeomError> {
        if let Some(&t) = self.image_cache.get(&image.index()) {
            return Ok(t);
        }
        let key = match image.source() {
            ::gltf::image::Source::View { view, .. } => {
                ImageKey::View(view.buffer().index(), view.offset(), view.length())
            }
            ::gltf::image::Source::Uri { uri, .. } => ImageKey::Uri(uri.to_string()),
        };
        if let Some(&t) = self.source_cache.get(&key) {
            self.image_cache.insert(image.index(), t);
            return Ok(t);
        }
        let bytes: Option<Cow<[u8]>> = match image.source() {
            ::gltf::image::Source::View { view, .. } => {
                let data = self.buffers.get(self.path, self.limits, &view.buffer()).ok();
                data.and_then(|d| d.get(view.offset()..view.offset().saturating_add(view.length())))
                    .map(Cow::Borrowed)
            }
            ::gltf::image::Source::Uri { uri, .. } => {
                read_uri(self.path, uri, self.limits).ok().map(Cow::Owned)
            }
        };
        let decoded = match bytes {
            Some(b) => super::decode_texture(self.path, &b, &mut self.texture_bytes, self.limits)?,
            None => None,
        };
        let tex = decoded.map(|t| {
            self.textures.push(t);
            self.textures.len() - 1
        });
        self.image_cache.insert(image.index(), tex);
        self.source_cache.insert(key, tex);
        Ok(tex)
    }
}

#[cfg(test)]
mod tests {
    use super::base64_decode;
    use crate::io::{load_mesh, load_mesh_with};
    use crate::limits::Limits;
    use crate::mesh::Appearance;
    use crate::test_support::within;
    use serde_json::{json, Value};
    use std::path::{Path, PathBuf};

    /// A GLB container around `doc` and `bin`, assembled by hand per the GLB spec.
    fn glb(doc: &Value, bin: &[u8]) -> Vec<u8> {
        let mut j = serde_json::to_vec(doc).unwrap();
        while j.len() & 3 != 0 {
            j.push(b' ');
        }
        let mut b = bin.to_vec();
        while b.len() & 3 != 0 {
            b.push(0);
        }
        let total = 12 + 8 + j.len() + if b.is_empty() { 0 } else { 8 + b.len() };
        let mut out = b"glTF".to_vec();
        out.extend(2u32.to_le_bytes());
        out.extend((total as u32).to_le_bytes());
        out.extend((j.len() as u32).to_le_bytes());
        out.extend(b"JSON");
        out.extend(&j);
        if !b.is_empty() {
            out.extend((b.len() as u32).to_le_bytes());
            out.extend(b"BIN\0");
            out.extend(&b);
        }
        out
    }

    fn f32s(v: &[f32]) -> Vec<u8> {
        v.iter().flat_map(|x| x.to_le_bytes()).collect()
    }

    fn write(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    /// One triangle (0,0,0), (1,0,0), (0,1,0) with u16 indices `idx`; `nodes`/`scenes` given.
    fn triangle_doc(idx: [u16; 3], nodes: Value, scenes: Value) -> (Value, Vec<u8>) {
        let mut bin = f32s(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        bin.extend(idx.iter().flat_map(|i| i.to_le_bytes()));
        let doc = json!({
            "asset": {"version": "2.0"},
            "scene": 0,
            "scenes": scenes,
            "nodes": nodes,
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
            "buffers": [{"byteLength": 42}],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": 36},
                {"buffer": 0, "byteOffset": 36, "byteLength": 6}
            ],
            "accessors": [
                {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                 "min": [0, 0, 0], "max": [1, 1, 0]},
                {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}
            ]
        });
        (doc, bin)
    }

    #[test]
    fn node_hierarchy_and_instancing() {
        let dir = tempfile::tempdir().unwrap();
        let (doc, bin) = triangle_doc(
            [0, 1, 2],
            json!([
                {"mesh": 0, "translation": [10, 0, 0]},
                {"children": [2], "scale": [2, 2, 2]},
                {"mesh": 0, "translation": [0, 0, 1]},
                {"mesh": 0, "translation": [50, 0, 0]}
            ]),
            // Node 3 belongs to a scene that is not the default one: not loaded.
            json!([{"nodes": [0, 1]}, {"nodes": [3]}]),
        );
        let m = load_mesh(&write(&dir, "a.glb", &glb(&doc, &bin))).unwrap();
        assert_eq!(m.triangles.len(), 2);
        assert_eq!(m.triangle(0), [[10.0, 0.0, 0.0], [11.0, 0.0, 0.0], [10.0, 1.0, 0.0]]);
        // Child of a scaled parent: p' = 2 (p + (0, 0, 1)).
        assert_eq!(m.triangle(1), [[0.0, 0.0, 2.0], [2.0, 0.0, 2.0], [0.0, 2.0, 2.0]]);
        assert_eq!(m.appearance, Appearance::None);

        // Without a default scene, every scene is loaded.
        let mut doc2 = doc.clone();
        doc2.as_object_mut().unwrap().remove("scene");
        let m = load_mesh(&write(&dir, "b.glb", &glb(&doc2, &bin))).unwrap();
        assert_eq!(m.triangles.len(), 3);
        assert_eq!(m.triangle(2)[1], [51.0, 0.0, 0.0]);
        // Node given as a matrix (column-major): rotation of 90° about z, then +5 in y.
        let (doc3, bin3) = triangle_doc(
            [0, 1, 2],
            json!([{"mesh": 0, "matrix": [0, 1, 0, 0, -1, 0, 0, 0, 0, 0, 1, 0, 0, 5, 0, 1]}]),
            json!([{"nodes": [0]}]),
        );
        let m = load_mesh(&write(&dir, "c.glb", &glb(&doc3, &bin3))).unwrap();
        assert_eq!(m.triangle(0), [[0.0, 5.0, 0.0], [0.0, 6.0, 0.0], [-1.0, 5.0, 0.0]]);
    }

    #[test]
    fn strips_fans_non_indexed_and_points() {
        let dir = tempfile::tempdir().unwrap();
        // Square corners 0..3 (z varies so that every triangle has area).
        let mut bin = f32s(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 1.0]);
        bin.extend([0u8, 1, 2, 3]); // u8 fan indices
        let doc = json!({
            "asset": {"version": "2.0"},
            "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [
                {"attributes": {"POSITION": 0}, "mode": 5},
                {"attributes": {"POSITION": 0}, "indices": 1, "mode": 6},
                {"attributes": {"POSITION": 0}, "mode": 0},
                {"attributes": {"POSITION": 0}, "mode": 1}
            ]}],
            "buffers": [{"byteLength": 52}],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": 48},
                {"buffer": 0, "byteOffset": 48, "byteLength": 4}
            ],
            "accessors": [
                {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
                 "min": [0, 0, 0], "max": [1, 1, 1]},
                {"bufferView": 1, "componentType": 5121, "count": 4, "type": "SCALAR"}
            ]
        });
        let m = load_mesh(&write(&dir, "s.glb", &glb(&doc, &bin))).unwrap();
        // Strip (v0 v1 v2), (v2 v1 v3) [same winding as the spec's (v1 v3 v2)]; fan (v0 v1 v2),
        // (v0 v2 v3), offset by the 4 vertices of the first primitive. Points/lines skipped.
        assert_eq!(m.triangles, vec![[0, 1, 2], [2, 1, 3], [4, 5, 6], [4, 6, 7]]);
        assert_eq!(m.positions.len(), 8);
    }

    #[test]
    fn base_color_factor_and_texture() {
        let dir = tempfile::tempdir().unwrap();
        // 2x1 PNG: left red, right green.
        let img = image::RgbImage::from_raw(2, 1, vec![255, 0, 0, 0, 255, 0]).unwrap();
        let mut png = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png).unwrap();
        let mut bin = f32s(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        bin.extend(f32s(&[0.25, 0.5, 0.75, 0.5, 0.25, 0.5])); // UVs: left, right, left
        let img_off = bin.len();
        bin.extend(&png);
        let doc = json!({
            "asset": {"version": "2.0"},
            "scenes": [{"nodes": [0]}],
            "scene": 0,
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [
                {"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "material": 0},
                {"attributes": {"POSITION": 0}, "material": 1}
            ]}],
            "materials": [
                {"pbrMetallicRoughness": {"baseColorFactor": [0.5, 1, 1, 1],
                                          "baseColorTexture": {"index": 0}}},
                {"pbrMetallicRoughness": {"baseColorFactor": [0.1, 0.2, 0.3, 1]}}
            ],
            "textures": [{"source": 0}],
            "images": [{"bufferView": 2, "mimeType": "image/png"}],
            "buffers": [{"byteLength": bin.len()}],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": 36},
                {"buffer": 0, "byteOffset": 36, "byteLength": 24},
                {"buffer": 0, "byteOffset": img_off, "byteLength": png.len()}
            ],
            "accessors": [
                {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                 "min": [0, 0, 0], "max": [1, 1, 0]},
                {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}
            ]
        });
        let m = load_mesh(&write(&dir, "t.glb", &glb(&doc, &bin))).unwrap();
        assert_eq!(m.triangles.len(), 2);
        let Appearance::Textured { textures, materials, .. } = &m.appearance else { panic!() };
        assert_eq!(textures.len(), 1);
        assert_eq!((textures[0].width, textures[0].height), (2, 1));
        assert_eq!(materials.len(), 2);
        assert_eq!(m.color_at(0, [1.0, 0.0, 0.0]), Some([0.5, 0.0, 0.0]));
        assert_eq!(m.color_at(0, [0.0, 1.0, 0.0]), Some([0.0, 1.0, 0.0]));
        assert_eq!(m.color_at(1, [0.3, 0.3, 0.4]), Some([0.1, 0.2, 0.3]));

        // Specular-glossiness material: its diffuse factor is the base colour.
        let mut sg = doc.clone();
        sg["materials"][1] = json!({"extensions": {"KHR_materials_pbrSpecularGlossiness":
            {"diffuseFactor": [0.7, 0.6, 0.5, 1]}}});
        sg["extensionsUsed"] = json!(["KHR_materials_pbrSpecularGlossiness"]);
        let m = load_mesh(&write(&dir, "sg.glb", &glb(&sg, &bin))).unwrap();
        assert_eq!(m.color_at(1, [1.0, 0.0, 0.0]), Some([0.7, 0.6, 0.5]));

        // A texture whose image comes only from an extension (no `source`): loaded without
        // textures, base colours kept.
        let mut webp = doc.clone();
        webp["textures"] = json!([{"extensions": {"EXT_texture_webp": {"source": 0}}}]);
        webp["extensionsUsed"] = json!(["EXT_texture_webp"]);
        let m = load_mesh(&write(&dir, "w.glb", &glb(&webp, &bin))).unwrap();
        let Appearance::Textured { textures, .. } = &m.appearance else { panic!() };
        assert!(textures.is_empty());
        assert_eq!(m.color_at(0, [1.0, 0.0, 0.0]), Some([0.5, 1.0, 1.0]));
        assert_eq!(m.color_at(1, [1.0, 0.0, 0.0]), Some([0.1, 0.2, 0.3]));
    }

    #[test]
    fn gltf_with_data_uri_and_external_buffer() {
        assert_eq!(base64_decode("TWFu").unwrap(), b"Man");
        assert_eq!(base64_decode("aGVsbG8=").unwrap(), b"hello");
        assert_eq!(base64_decode("aGVsbG8").unwrap(), b"hello");
        assert!(base64_decode("a*b").is_none());
        let dir = tempfile::tempdir().unwrap();
        let (mut doc, bin) = triangle_doc([0, 1, 2], json!([{"mesh": 0}]), json!([{"nodes": [0]}]));
        // Standard base64 of `bin`, encoded here independently of the decoder under test.
        const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
        let mut b64 = String::new();
        for ch in bin.chunks(3) {
            let v = (ch[0] as u32) << 16
                | (*ch.get(1).unwrap_or(&0) as u32) << 8
                | *ch.get(2).unwrap_or(&0) as u32;
            for k in 0..=ch.len() {
                b64.push(A[(v >> (18 - 6 * k) & 63) as usize] as char);
            }
        }
        doc["buffers"][0]["uri"] = json!(format!("data:application/octet-stream;base64,{b64}"));
        let m = load_mesh(&write(&dir, "d.gltf", &serde_json::to_vec(&doc).unwrap())).unwrap();
        assert_eq!(m.triangle(0)[1], [1.0, 0.0, 0.0]);
        write(&dir, "my buf.bin", &bin);
        doc["buffers"][0]["uri"] = json!("my%20buf.bin");
        let m = load_mesh(&write(&dir, "e.GLTF", &serde_json::to_vec(&doc).unwrap())).unwrap();
        assert_eq!(m.triangle(0)[2], [0.0, 1.0, 0.0]);
        doc["buffers"][0]["uri"] = json!("missing.bin");
        let e = load_mesh(&write(&dir, "f.gltf", &serde_json::to_vec(&doc).unwrap())).unwrap_err();
        assert!(e.to_string().contains("f.gltf") && e.to_string().contains("missing.bin"), "{e}");
    }

    #[test]
    fn sparse_and_quantized_interleaved_positions() {
        let dir = tempfile::tempdir().unwrap();
        let mut bin = vec![1u8, 2, 0, 0]; // sparse indices (u8) + padding
        bin.extend(f32s(&[1.0, 0.0, 0.0, 0.0, 1.0, 0.0])); // sparse values
                                                           // Interleaved: u16 x y z (normalized) + 2 pad bytes, then 4 bytes of another attribute.
        for v in [[65535u16, 0, 0], [0, 65535, 0], [0, 0, 32768]] {
            for c in v {
                bin.extend(c.to_le_bytes());
            }
            bin.extend([0u8; 6]);
        }
        let doc = json!({
            "asset": {"version": "2.0"},
            "extensionsUsed": ["KHR_mesh_quantization"],
            "extensionsRequired": ["KHR_mesh_quantization"],
            "scenes": [{"nodes": [0, 1]}],
            "nodes": [{"mesh": 0}, {"mesh": 1, "translation": [0, 0, 3]}],
            "meshes": [
                {"primitives": [{"attributes": {"POSITION": 0}}]},
                {"primitives": [{"attributes": {"POSITION": 1}}]}
            ],
            "buffers": [{"byteLength": bin.len()}],
            "bufferViews": [
                {"buffer": 0, "byteOffset": 0, "byteLength": 2},
                {"buffer": 0, "byteOffset": 4, "byteLength": 24},
                {"buffer": 0, "byteOffset": 28, "byteLength": 36, "byteStride": 12}
            ],
            "accessors": [
                {"componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0],
                 "sparse": {"count": 2, "indices": {"bufferView": 0, "componentType": 5121},
                            "values": {"bufferView": 1}}},
                {"bufferView": 2, "componentType": 5123, "normalized": true, "count": 3,
                 "type": "VEC3", "min": [0, 0, 0], "max": [65535, 65535, 32768]}
            ]
        });
        let m = load_mesh(&write(&dir, "q.glb", &glb(&doc, &bin))).unwrap();
        assert_eq!(m.triangle(0), [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        assert_eq!(m.triangle(1), [[1.0, 0.0, 3.0], [0.0, 1.0, 3.0], [0.0, 0.0, 3.0 + 32768.0 / 65535.0]]);
    }

    #[test]
    fn malformed_inputs_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let check = |bytes: &[u8], want: &str| {
            let p = write(&dir, "bad.glb", bytes);
            let e = load_mesh(&p).unwrap_err().to_string();
            assert!(e.contains("bad.glb") && e.contains(want), "{e}");
        };
        let one = || triangle_doc([0, 1, 2], json!([{"mesh": 0}]), json!([{"nodes": [0]}]));
        let (doc, bin) = one();
        let good = glb(&doc, &bin);
        check(&good[..good.len() - 8], "truncated");
        check(&good[..10], "shorter than the 12-byte header");
        let mut magic = good.clone();
        magic[3] = b'X';
        check(&magic, "missing 'glTF' magic");
        check(b"\x00\x01garbage garbage garbage", "missing 'glTF' magic");
        let mut bad_json = good.clone();
        bad_json[20] = b'!';
        check(&bad_json, "invalid glTF JSON");
        let mut nan_bin = bin.clone();
        nan_bin[12..16].copy_from_slice(&f32::NAN.to_le_bytes());
        check(&glb(&doc, &nan_bin), "non-finite");
        let (doc_oob, bin_oob) = triangle_doc([0, 1, 5], json!([{"mesh": 0}]), json!([{"nodes": [0]}]));
        check(&glb(&doc_oob, &bin_oob), "index 5 out of range (3 vertices)");
        let mut points = doc.clone();
        points["meshes"][0]["primitives"][0]["mode"] = json!(0);
        check(&glb(&points, &bin), "no triangles");
        let mut draco = doc.clone();
        draco["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
        draco["extensionsUsed"] = json!(["KHR_draco_mesh_compression"]);
        check(&glb(&draco, &bin), "unsupported compressed geometry");
        let mut stride = doc.clone();
        stride["bufferViews"][0]["byteStride"] = json!(4);
        check(&glb(&stride, &bin), "byteStride 4 < element size 12");
        let mut count = doc.clone();
        count["accessors"][0]["count"] = json!(4);
        check(&glb(&count, &bin), "4 elements need 48 bytes");
        let mut cyc = doc.clone();
        cyc["nodes"] = json!([{"mesh": 0, "children": [1]}, {"children": [0]}]);
        check(&glb(&cyc, &bin), "cycle");
        // Tolerated: other required extensions (not geometry compression) still load.
        let mut tt = doc.clone();
        tt["extensionsRequired"] = json!(["KHR_mesh_quantization"]);
        tt["extensionsUsed"] = json!(["KHR_mesh_quantization"]);
        assert!(load_mesh(&write(&dir, "q.glb", &glb(&tt, &bin))).is_ok());
    }

    #[test]
    fn shared_or_repeated_children_are_rejected_before_any_expansion() {
        let dir = tempfile::tempdir().unwrap();
        let check = |nodes: Value, scenes: Value, want: &str| {
            let (doc, bin) = triangle_doc([0, 1, 2], nodes, scenes);
            let p = write(&dir, "bad.glb", &glb(&doc, &bin));
            let e = within(20, move || load_mesh(&p).map(|m| m.triangles.len())).unwrap_err().to_string();
            assert!(e.contains("bad.glb") && e.contains(want), "{e}");
        };
        // Node i lists child i + 1 twice: 2^depth instances. Depth 3 first (the old loader
        // returned 15 triangles), then the reported 40-level bomb (it aborted on allocation).
        for depth in [3, 40] {
            let nodes: Vec<Value> = (0..=depth)
                .map(|i| {
                    if i < depth {
                        json!({"mesh": 0, "children": [i + 1, i + 1]})
                    } else {
                        json!({"mesh": 0})
                    }
                })
                .collect();
            check(json!(nodes), json!([{"nodes": [0]}]), "node 0 lists child 1 twice");
        }
        // Diamond: nodes 1 and 2 both list node 3.
        let diamond = json!([{"children": [1, 2]}, {"children": [3]}, {"children": [3]}, {"mesh": 0}]);
        check(diamond, json!([{"nodes": [0]}]), "node 3 has more than one parent (nodes 1 and 2)");
        // A scene root that is also a child.
        let nodes = json!([{"mesh": 0, "children": [1]}, {"mesh": 0}]);
        check(
            nodes.clone(),
            json!([{"nodes": [0, 1]}]),
            "node 1 is a root of scene 0 and also a child of node 0",
        );
        // A scene that lists its root twice (each listing was an instance).
        check(nodes, json!([{"nodes": [0, 0]}]), "scene 0 lists node 0 twice");
        // A cycle not reachable from the scene is an error too.
        let cyc = json!([{"mesh": 0}, {"children": [2]}, {"children": [1]}]);
        check(cyc, json!([{"nodes": [0]}]), "cycle through node 1");
    }

    #[test]
    fn node_instances_triangles_and_vertices_are_capped_by_the_limits() {
        let dir = tempfile::tempdir().unwrap();
        // A tree of three nodes instancing the one-triangle mesh: 3 instances, 3 triangles,
        // 9 vertices.
        let nodes =
            json!([{"mesh": 0, "children": [1, 2]}, {"mesh": 0}, {"mesh": 0, "translation": [0, 0, 1]}]);
        let (doc, bin) = triangle_doc([0, 1, 2], nodes, json!([{"nodes": [0]}]));
        let p = write(&dir, "tree.glb", &glb(&doc, &bin));
        assert_eq!(load_mesh_with(&p, &Limits::default()).unwrap().triangles.len(), 3);
        let at = |l: Limits| load_mesh_with(&p, &l).unwrap_err().to_string();
        let d = Limits::default();
        let e = at(Limits { max_gltf_nodes: 2, ..d });
        assert!(
            e.contains("tree.glb") && e.contains("node instances") && e.contains("OBJVIEW_MAX_GLTF_NODES"),
            "{e}"
        );
        let e = at(Limits { max_triangles: 2, ..d });
        assert!(e.contains("3 triangles, over the limit of 2 (OBJVIEW_MAX_TRIANGLES raises it)"), "{e}");
        let e = at(Limits { max_vertices: 8, ..d });
        assert!(e.contains("9 vertices, over the limit of 8 (OBJVIEW_MAX_VERTICES"), "{e}");
        assert!(
            load_mesh_with(&p, &Limits { max_gltf_nodes: 3, max_triangles: 3, max_vertices: 9, ..d }).is_ok()
        );
    }

    /// `dir/asset/` holding `a.gltf` whose buffer 0 has `uri`, and `dir/outside/secret.bin`
    /// holding the same valid triangle data; returns the .gltf path.
    fn asset_with_buffer_uri(dir: &Path, uri: &str) -> PathBuf {
        let (mut doc, bin) = triangle_doc([0, 1, 2], json!([{"mesh": 0}]), json!([{"nodes": [0]}]));
        std::fs::create_dir_all(dir.join("asset")).unwrap();
        std::fs::create_dir_all(dir.join("outside")).unwrap();
        std::fs::write(dir.join("outside/secret.bin"), &bin).unwrap();
        std::fs::write(dir.join("asset/inside.bin"), &bin).unwrap();
        doc["buffers"][0]["uri"] = json!(uri);
        let p = dir.join("asset/a.gltf");
        std::fs::write(&p, serde_json::to_vec(&doc).unwrap()).unwrap();
        p
    }

    #[test]
    fn buffer_uris_cannot_leave_the_asset_folder() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let secret = d.join("outside/secret.bin");
        let absolute = secret.display().to_string();
        for (uri, want) in [
            ("../outside/secret.bin", "'..' is not allowed"),
            ("%2e%2e/outside/secret.bin", "'..' is not allowed"),
            ("%2E%2E%2Foutside%2Fsecret.bin", "'..' is not allowed"),
            ("sub/..\\../outside/secret.bin", "'..' is not allowed"),
            (absolute.as_str(), "absolute paths are not allowed"),
            ("/proc/self/environ", "absolute paths are not allowed"),
        ] {
            let p = asset_with_buffer_uri(d, uri);
            let e = load_mesh(&p).unwrap_err().to_string();
            assert!(e.contains("a.gltf") && e.contains(want), "{uri}: {e}");
        }
        // Symlinks: to a file outside, or through a linked folder, refused; inside, followed.
        #[cfg(unix)]
        {
            use crate::test_support::symlink;
            symlink(&secret, &d.join("asset/link.bin"));
            symlink(&d.join("outside"), &d.join("asset/linked"));
            symlink(&d.join("asset/inside.bin"), &d.join("asset/good.bin"));
            for uri in ["link.bin", "linked/secret.bin"] {
                let e = load_mesh(&asset_with_buffer_uri(d, uri)).unwrap_err().to_string();
                assert!(e.contains("a.gltf") && e.contains("outside the asset's folder"), "{uri}: {e}");
            }
            let m = load_mesh(&asset_with_buffer_uri(d, "good.bin")).unwrap();
            assert_eq!(m.triangle(0)[1], [1.0, 0.0, 0.0]);
        }
        // The same file named inside the folder loads.
        assert!(load_mesh(&asset_with_buffer_uri(d, "./inside.bin")).is_ok());
    }

    #[cfg(unix)]
    #[test]
    fn special_files_as_buffers_are_never_opened_unless_used_and_then_refused() {
        use crate::test_support::{mkfifo, symlink};
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().to_path_buf();
        mkfifo(&d.join("fifo.bin"));
        symlink(Path::new("/dev/zero"), &d.join("zero.bin"));
        let (mut doc, bin) = triangle_doc([0, 1, 2], json!([{"mesh": 0}]), json!([{"nodes": [0]}]));
        write(&dir, "tri.bin", &bin);
        // Unused buffers: a FIFO, /dev/zero directly, /dev/zero through a link (each would
        // block or read without end if opened).
        doc["buffers"] = json!([
            {"uri": "tri.bin", "byteLength": 42},
            {"uri": "fifo.bin", "byteLength": 8},
            {"uri": "/dev/zero", "byteLength": 8},
            {"uri": "zero.bin", "byteLength": 8}
        ]);
        let p = write(&dir, "unused.gltf", &serde_json::to_vec(&doc).unwrap());
        let m = within(10, move || load_mesh(&p).map(|m| m.triangles.len()));
        assert_eq!(m.unwrap(), 1);
        // Used: refused with the reason, without blocking.
        for (k, want) in [
            (1, "not a regular file (it is a FIFO"),
            (2, "absolute paths"),
            (3, "outside the asset's folder"),
        ] {
            let mut used = doc.clone();
            used["bufferViews"][0]["buffer"] = json!(k);
            used["buffers"][k]["byteLength"] = json!(42);
            let p = write(&dir, "used.gltf", &serde_json::to_vec(&used).unwrap());
            let e = within(10, move || load_mesh(&p).map(|m| m.triangles.len())).unwrap_err().to_string();
            assert!(e.contains("used.gltf") && e.contains(want), "{e}");
        }
        // An oversized referenced file is refused by its size, before it is read.
        let p = d.join("tri.gltf");
        std::fs::write(&p, serde_json::to_vec(&triangle_doc_with_uri("tri.bin")).unwrap()).unwrap();
        let l = Limits { max_referenced_bytes: 41, ..Limits::default() };
        let e = load_mesh_with(&p, &l).unwrap_err().to_string();
        assert!(e.contains("file of 42 bytes is over the limit of 41 (OBJVIEW_MAX_REFERENCED_BYTES"), "{e}");
    }

    fn triangle_doc_with_uri(uri: &str) -> Value {
        let (mut doc, _) = triangle_doc([0, 1, 2], json!([{"mesh": 0}]), json!([{"nodes": [0]}]));
        doc["buffers"][0]["uri"] = json!(uri);
        doc
    }

    #[test]
    fn images_outside_the_folder_or_special_are_not_read_and_textures_are_capped() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::create_dir_all(d.join("asset")).unwrap();
        std::fs::create_dir_all(d.join("outside")).unwrap();
        let img = image::RgbImage::from_raw(2, 1, vec![255, 0, 0, 0, 255, 0]).unwrap();
        img.save(d.join("outside/tex.png")).unwrap();
        img.save(d.join("asset/tex.png")).unwrap();
        let mut bin = f32s(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        bin.extend(f32s(&[0.25, 0.5, 0.75, 0.5, 0.25, 0.5]));
        std::fs::write(d.join("asset/g.bin"), &bin).unwrap();
        let doc = |image_uri: &str| {
            json!({
                "asset": {"version": "2.0"},
                "scenes": [{"nodes": [0]}],
                "nodes": [{"mesh": 0}],
                "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "material": 0}]}],
                "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
                "textures": [{"source": 0}],
                "images": [{"uri": image_uri}],
                "buffers": [{"uri": "g.bin", "byteLength": 60}],
                "bufferViews": [
                    {"buffer": 0, "byteOffset": 0, "byteLength": 36},
                    {"buffer": 0, "byteOffset": 36, "byteLength": 24}
                ],
                "accessors": [
                    {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                     "min": [0, 0, 0], "max": [1, 1, 0]},
                    {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}
                ]
            })
        };
        let textures = |uri: &str, limits: Limits| {
            let p = d.join("asset/t.gltf");
            std::fs::write(&p, serde_json::to_vec(&doc(uri)).unwrap()).unwrap();
            within(10, move || {
                load_mesh_with(&p, &limits).map(|m| match m.appearance {
                    Appearance::Textured { textures, .. } => textures.len(),
                    _ => usize::MAX,
                })
            })
        };
        let l = Limits::default();
        assert_eq!(textures("tex.png", l).unwrap(), 1);
        assert_eq!(textures("../outside/tex.png", l).unwrap(), 0);
        assert_eq!(textures(&d.join("outside/tex.png").display().to_string(), l).unwrap(), 0);
        #[cfg(unix)]
        {
            crate::test_support::mkfifo(&d.join("asset/fifo.png"));
            assert_eq!(textures("fifo.png", l).unwrap(), 0);
        }
        // The 2x1 texture decodes to 6 bytes.
        assert_eq!(textures("tex.png", Limits { max_texture_bytes: 6, ..l }).unwrap(), 1);
        let e = textures("tex.png", Limits { max_texture_bytes: 5, ..l }).unwrap_err().to_string();
        assert!(
            e.contains("t.gltf") && e.contains("6 bytes, over the limit of 5 (OBJVIEW_MAX_TEXTURE_BYTES"),
            "{e}"
        );
    }
}
