//! glTF 2.0 (.gltf, .glb) loading with the `gltf` crate.
//!
//! The default scene (or scene 0, or all root nodes when there is no scene) is flattened with
//! the node hierarchy transforms; skins and morph targets are ignored (rest pose). Colours:
//! `baseColorFactor` times the base-colour texture (`TEXCOORD_n` of the texture info, sampler
//! wrap modes) times `COLOR_0`. Only the base-colour images are decoded. The nodes must form
//! a tree (glTF 2.0 rule): a node reached twice (two parents, a cycle) is a parse error.

use std::collections::HashMap;
use std::path::Path;

use gltf::mesh::Mode;
use gltf::texture::WrappingMode;

use super::mesh::{Material, Mesh, Texture, Wrap};
use super::{guard, percent_decode, texture_from_bytes, AssetRoots, SceneError};
use crate::safety::check_memory;

type Mat4 = [[f64; 4]; 4];

/// Column-major 4x4 product `a * b`.
fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut r = [[0.0; 4]; 4];
    for (c, col) in r.iter_mut().enumerate() {
        for (row, v) in col.iter_mut().enumerate() {
            *v = (0..4).map(|k| a[k][row] * b[c][k]).sum();
        }
    }
    r
}

/// Identity matrix.
const IDENTITY: Mat4 = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
];

/// Maps a glTF wrapping mode.
fn wrap(m: WrappingMode) -> Wrap {
    match m {
        WrappingMode::Repeat => Wrap::Repeat,
        WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
        WrappingMode::ClampToEdge => Wrap::ClampToEdge,
    }
}

/// The bytes of a URI that is not a data URI, read under the asset roots (percent-decoded
/// first; any scheme, `file:` included, is refused).
fn read_uri(uri: &str, roots: &AssetRoots, what: &str) -> Result<Vec<u8>, String> {
    let path_part = uri.split(['?', '#']).next().unwrap_or("");
    if let Some(colon) = path_part.find(':') {
        if !path_part[..colon].contains('/') {
            return Err(format!(
                "URI {uri:?}: the {:?} scheme is not allowed (only data: URIs and relative \
                 paths inside the model's folder or --asset-root)",
                &path_part[..colon]
            ));
        }
    }
    roots.read(&percent_decode(path_part)?, what)
}

/// Loads every buffer: GLB chunk, data URI or a file under the asset roots, each at least
/// its declared length.
fn load_buffers(
    document: &gltf::Document,
    mut blob: Option<Vec<u8>>,
    roots: &AssetRoots,
) -> Result<Vec<gltf::buffer::Data>, String> {
    let mut buffers = Vec::new();
    for buffer in document.buffers() {
        let i = buffer.index();
        check_memory(format!("glTF buffer {i}"), buffer.length() as u64)
            .map_err(|e| e.to_string())?;
        let data = match buffer.source() {
            gltf::buffer::Source::Uri(uri) if !uri.starts_with("data:") => gltf::buffer::Data(
                read_uri(uri, roots, "glTF buffer")
                    .map_err(|e| format!("buffer {i} ({uri:?}) not opened: {e}"))?,
            ),
            source => gltf::buffer::Data::from_source_and_blob(source, None, &mut blob)
                .map_err(|e| format!("buffer {i}: {e}"))?,
        };
        if data.len() < buffer.length() {
            return Err(format!(
                "buffer {i} holds {} bytes, shorter than its byteLength {}",
                data.len(),
                buffer.length()
            ));
        }
        buffers.push(data);
    }
    Ok(buffers)
}

/// Checks the glTF 2.0 rules the reader relies on: views inside their buffers, accessors
/// (and sparse parts) inside their views, and every accessor's size within the memory limit.
fn validate_layout(document: &gltf::Document) -> Result<(), String> {
    for view in document.views() {
        let end = view.offset() as u64 + view.length() as u64;
        let buffer = view.buffer();
        if end > buffer.length() as u64 {
            return Err(format!(
                "buffer view {} ends at byte {end}, past buffer {} ({} bytes)",
                view.index(),
                buffer.index(),
                buffer.length()
            ));
        }
        if let Some(stride) = view.stride() {
            if !(4..=252).contains(&stride) || stride % 4 != 0 {
                return Err(format!(
                    "buffer view {} has byteStride {stride} (glTF: 4..=252, a multiple of 4)",
                    view.index()
                ));
            }
        }
    }
    for accessor in document.accessors() {
        let i = accessor.index();
        let (count, elem) = (accessor.count() as u64, accessor.size() as u64);
        check_memory(format!("glTF accessor {i}"), count.saturating_mul(elem))
            .map_err(|e| e.to_string())?;
        if let Some(view) = accessor.view() {
            let stride = view.stride().map_or(elem, |s| s as u64);
            if count > 0 {
                let end = accessor.offset() as u64 + stride * (count - 1) + elem;
                if end > view.length() as u64 {
                    return Err(format!(
                        "accessor {i} ({count} elements of {elem} bytes) runs to byte {end} of \
                         buffer view {} ({} bytes)",
                        view.index(),
                        view.length()
                    ));
                }
            }
        }
        if let Some(sparse) = accessor.sparse() {
            let n = sparse.count() as u64;
            if n > count {
                return Err(format!(
                    "accessor {i}: {n} sparse values for {count} elements"
                ));
            }
            let (iv, vv) = (sparse.indices().view(), sparse.values().view());
            let index_size = sparse.indices().index_type().size() as u64;
            let ends = [
                (sparse.indices().offset() as u64 + n * index_size, iv),
                (sparse.values().offset() as u64 + n * elem, vv),
            ];
            for (end, view) in ends {
                if end > view.length() as u64 {
                    return Err(format!(
                        "accessor {i}: sparse data runs to byte {end} of buffer view {} ({} \
                         bytes)",
                        view.index(),
                        view.length()
                    ));
                }
            }
        }
    }
    Ok(())
}

/// Decodes image `img` (base colour): a buffer view, a data URI, or a file under the roots.
fn load_image(
    img: &gltf::Image,
    buffers: &[gltf::buffer::Data],
    roots: &AssetRoots,
) -> Result<Texture, String> {
    let bytes: Vec<u8> = match img.source() {
        gltf::image::Source::View { view, .. } => {
            let data = &buffers[view.buffer().index()].0;
            data[view.offset()..view.offset() + view.length()].to_vec()
        }
        gltf::image::Source::Uri { uri, .. } if uri.starts_with("data:") => {
            gltf::buffer::Data::from_source(gltf::buffer::Source::Uri(uri), None)
                .map_err(|e| e.to_string())?
                .0
        }
        gltf::image::Source::Uri { uri, .. } => read_uri(uri, roots, "texture")?,
    };
    texture_from_bytes(&bytes)
}

/// Loads a .gltf or .glb file as a mesh; external files must lie under `roots`.
pub(crate) fn load_gltf(path: &Path, assets: &AssetRoots) -> Result<Mesh, SceneError> {
    let parse_err = |message: String| SceneError::Parse {
        path: path.to_path_buf(),
        format: "gltf",
        message,
    };
    std::fs::metadata(path).map_err(|e| SceneError::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    let bytes = super::read_bounded(path, "glTF file").map_err(parse_err)?;
    guard(path, "gltf", || {
        let gltf::Gltf { document, blob } =
            gltf::Gltf::from_slice(&bytes).map_err(|e| parse_err(e.to_string()))?;
        validate_layout(&document).map_err(parse_err)?;
        let buffers = load_buffers(&document, blob, assets).map_err(parse_err)?;
        let get = |b: gltf::Buffer| buffers.get(b.index()).map(|d| &d.0[..]);

        let mut mesh = Mesh {
            source: path.to_path_buf(),
            has_colors: true,
            ..Mesh::default()
        };
        // Base-colour images only, decoded once each.
        let mut image_tex: HashMap<usize, Option<u32>> = HashMap::new();
        let mut material_index: HashMap<Option<usize>, u32> = HashMap::new();
        let mut material_texcoord: Vec<u32> = Vec::new();
        let mut any_uv = false;
        let mut any_color = false;

        // Collect (node mesh, world matrix) from the scene graph. glTF requires the nodes to
        // form a strict forest (one parent at most, no cycles): a node reached twice is an
        // error, so that shared children cannot expand into exponentially many instances.
        let node_count = document.nodes().len();
        let roots: Vec<gltf::Node> = match document
            .default_scene()
            .or_else(|| document.scenes().next())
        {
            Some(s) => s.nodes().collect(),
            None => {
                // No scene: every node that is no other node's child.
                let mut is_child = vec![false; node_count];
                for n in document.nodes() {
                    for c in n.children() {
                        if let Some(f) = is_child.get_mut(c.index()) {
                            *f = true;
                        }
                    }
                }
                document.nodes().filter(|n| !is_child[n.index()]).collect()
            }
        };
        let mut visited = vec![false; node_count];
        let mut stack: Vec<(gltf::Node, Mat4)> = roots.into_iter().map(|n| (n, IDENTITY)).collect();
        let mut instances: Vec<(gltf::Mesh, Mat4)> = Vec::new();
        while let Some((node, parent)) = stack.pop() {
            let seen = visited
                .get_mut(node.index())
                .ok_or_else(|| parse_err(format!("node {} does not exist", node.index())))?;
            if std::mem::replace(seen, true) {
                return Err(parse_err(format!(
                    "node {} is reached twice in the scene (several parents, a cycle or a \
                     repeated root); glTF requires a node tree",
                    node.index()
                )));
            }
            let local = node.transform().matrix().map(|c| c.map(|v| v as f64));
            let world = mul(&parent, &local);
            if let Some(m) = node.mesh() {
                instances.push((m, world));
            }
            for child in node.children() {
                stack.push((child, world));
            }
        }
        // Deterministic order: by depth-first discovery reversed is fine but sort by mesh index
        // and matrix to be independent of the stack order.
        instances.sort_by(|a, b| {
            a.0.index()
                .cmp(&b.0.index())
                .then(a.1.partial_cmp(&b.1).unwrap_or(std::cmp::Ordering::Equal))
        });

        struct Vert {
            p: [f32; 3],
            uv: [f32; 2],
            c: [f32; 4],
        }
        let mut verts: Vec<Vert> = Vec::new();
        for (gmesh, world) in &instances {
            for prim in gmesh.primitives() {
                let mode = prim.mode();
                if !matches!(
                    mode,
                    Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
                ) {
                    log::warn!(
                        "{}: skipping a non-triangle primitive ({mode:?})",
                        path.display()
                    );
                    continue;
                }
                // Material.
                let gmat = prim.material();
                let mat_id = match material_index.get(&gmat.index()) {
                    Some(&id) => id,
                    None => {
                        let pbr = gmat.pbr_metallic_roughness();
                        let mut material = Material {
                            base_color: pbr.base_color_factor(),
                            texture: None,
                            wrap: [Wrap::Repeat; 2],
                        };
                        let mut texcoord = 0;
                        if let Some(info) = pbr.base_color_texture() {
                            texcoord = info.tex_coord();
                            let tex = info.texture();
                            let sampler = tex.sampler();
                            material.wrap = [wrap(sampler.wrap_s()), wrap(sampler.wrap_t())];
                            let img = tex.source();
                            let t = match image_tex.get(&img.index()) {
                                Some(&t) => t,
                                None => {
                                    let t = match load_image(&img, &buffers, assets) {
                                        Ok(t) => {
                                            mesh.textures.push(t);
                                            Some(mesh.textures.len() as u32 - 1)
                                        }
                                        Err(e) => {
                                            log::warn!(
                                                "{}: image {} unusable ({e}); using the base \
                                                 colour factor",
                                                path.display(),
                                                img.index()
                                            );
                                            None
                                        }
                                    };
                                    image_tex.insert(img.index(), t);
                                    t
                                }
                            };
                            material.texture = t;
                        }
                        mesh.materials.push(material);
                        material_texcoord.push(texcoord);
                        let id = mesh.materials.len() as u32 - 1;
                        material_index.insert(gmat.index(), id);
                        id
                    }
                };
                let reader = prim.reader(get);
                let Some(positions) = reader.read_positions() else {
                    continue;
                };
                let first = verts.len();
                // Every attribute has the vertex count (glTF rule); all of them must fit.
                let count = prim
                    .get(&gltf::Semantic::Positions)
                    .map_or(0, |a| a.count());
                for (semantic, accessor) in prim.attributes() {
                    if accessor.count() != count {
                        return Err(parse_err(format!(
                            "mesh {}: attribute {semantic:?} has {} elements, POSITION has \
                             {count}",
                            gmesh.index(),
                            accessor.count()
                        )));
                    }
                }
                if (first + count) as u64 >= u32::MAX as u64 {
                    return Err(SceneError::TooLarge {
                        path: path.to_path_buf(),
                        reason: "more than 2^32 vertices".into(),
                    });
                }
                let need = crate::safety::bytes_of::<Vert>((first + count) as u64);
                check_memory(format!("the vertices of mesh {}", gmesh.index()), need)
                    .map_err(|e| parse_err(e.to_string()))?;
                verts
                    .try_reserve(count)
                    .map_err(|e| parse_err(format!("vertices: {e}")))?;
                let uv_set = material_texcoord[mat_id as usize];
                let mut uvs = reader.read_tex_coords(uv_set).map(|t| t.into_f32());
                let mut colors = reader.read_colors(0).map(|c| c.into_rgba_f32());
                any_uv |= uvs.is_some();
                any_color |= colors.is_some();
                for p in positions {
                    let p = p.map(|v| v as f64);
                    let mut q = [0f32; 3];
                    for (r, qr) in q.iter_mut().enumerate() {
                        *qr = (world[0][r] * p[0]
                            + world[1][r] * p[1]
                            + world[2][r] * p[2]
                            + world[3][r]) as f32;
                    }
                    let uv = uvs.as_mut().and_then(|it| it.next()).unwrap_or([0.0; 2]);
                    let c = colors.as_mut().and_then(|it| it.next()).unwrap_or([1.0; 4]);
                    verts.push(Vert { p: q, uv, c });
                }
                let nv = verts.len() - first;
                let index_count = prim.indices().map_or(nv, |a| a.count());
                let need = crate::safety::bytes_of::<[u32; 4]>(
                    (mesh.triangles.len() + index_count) as u64,
                );
                check_memory(format!("the triangles of mesh {}", gmesh.index()), need)
                    .map_err(|e| parse_err(e.to_string()))?;
                let indices: Vec<u32> = match reader.read_indices() {
                    Some(ix) => ix.into_u32().collect(),
                    None => (0..nv as u32).collect(),
                };
                if indices.len() != index_count {
                    return Err(parse_err(format!(
                        "mesh {}: {} of {index_count} indices readable",
                        gmesh.index(),
                        indices.len()
                    )));
                }
                if let Some(&bad) = indices.iter().find(|&&i| i as usize >= nv) {
                    return Err(parse_err(format!(
                        "mesh {} index {bad} out of range ({nv} vertices)",
                        gmesh.index()
                    )));
                }
                let f = first as u32;
                let mut push = |a: u32, b: u32, c: u32| {
                    mesh.triangles.push([a + f, b + f, c + f]);
                    mesh.tri_materials.push(mat_id);
                };
                match mode {
                    Mode::Triangles => {
                        for t in indices.chunks_exact(3) {
                            push(t[0], t[1], t[2]);
                        }
                    }
                    Mode::TriangleStrip => {
                        for i in 2..indices.len() {
                            if i % 2 == 0 {
                                push(indices[i - 2], indices[i - 1], indices[i]);
                            } else {
                                push(indices[i - 1], indices[i - 2], indices[i]);
                            }
                        }
                    }
                    _ => {
                        for i in 2..indices.len() {
                            push(indices[0], indices[i - 1], indices[i]);
                        }
                    }
                }
                if verts.len() >= u32::MAX as usize {
                    return Err(SceneError::TooLarge {
                        path: path.to_path_buf(),
                        reason: "more than 2^32 vertices".into(),
                    });
                }
            }
        }
        mesh.positions = verts.iter().map(|v| v.p).collect();
        if any_uv {
            mesh.uvs = verts.iter().map(|v| v.uv).collect();
        }
        if any_color {
            mesh.colors = verts.iter().map(|v| v.c).collect();
        }
        if mesh.triangles.is_empty() {
            return Err(SceneError::InvalidMesh {
                path: path.to_path_buf(),
                reason: "no triangles in the default scene".into(),
            });
        }
        Ok(mesh)
    })
}
