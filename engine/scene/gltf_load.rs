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
use super::{guard, SceneError};

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

/// Converts an image decoded by the gltf crate into an RGBA8 texture.
fn to_texture(data: &gltf::image::Data) -> Option<Texture> {
    use gltf::image::Format as F;
    let px = &data.pixels;
    let n = data.width as usize * data.height as usize;
    let (stride, bytes): (usize, usize) = match data.format {
        F::R8 => (1, 1),
        F::R8G8 => (2, 1),
        F::R8G8B8 => (3, 1),
        F::R8G8B8A8 => (4, 1),
        F::R16 => (1, 2),
        F::R16G16 => (2, 2),
        F::R16G16B16 => (3, 2),
        F::R16G16B16A16 => (4, 2),
        _ => return None,
    };
    if px.len() < n * stride * bytes {
        return None;
    }
    let ch = |i: usize, c: usize| -> u8 {
        // 16-bit: little-endian, take the high byte.
        px[(i * stride + c) * bytes + bytes - 1]
    };
    let texels = (0..n)
        .map(|i| match stride {
            1 => {
                let v = ch(i, 0);
                [v, v, v, 255]
            }
            2 => {
                let v = ch(i, 0);
                [v, v, v, ch(i, 1)]
            }
            3 => [ch(i, 0), ch(i, 1), ch(i, 2), 255],
            _ => [ch(i, 0), ch(i, 1), ch(i, 2), ch(i, 3)],
        })
        .collect();
    Texture::new(data.width, data.height, texels)
}

/// Maps a glTF wrapping mode.
fn wrap(m: WrappingMode) -> Wrap {
    match m {
        WrappingMode::Repeat => Wrap::Repeat,
        WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
        WrappingMode::ClampToEdge => Wrap::ClampToEdge,
    }
}

/// Loads a .gltf or .glb file as a mesh.
pub(crate) fn load_gltf(path: &Path) -> Result<Mesh, SceneError> {
    let parse_err = |message: String| SceneError::Parse {
        path: path.to_path_buf(),
        format: "gltf",
        message,
    };
    let bytes = std::fs::read(path).map_err(|e| SceneError::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    let base = path.parent().unwrap_or(Path::new("."));
    guard(path, "gltf", || {
        let gltf::Gltf { document, blob } =
            gltf::Gltf::from_slice(&bytes).map_err(|e| parse_err(e.to_string()))?;
        let buffers = gltf::import_buffers(&document, Some(base), blob)
            .map_err(|e| parse_err(format!("buffers: {e}")))?;
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
                                    let t = match gltf::image::Data::from_source(
                                        img.source(),
                                        Some(base),
                                        &buffers,
                                    ) {
                                        Ok(data) => match to_texture(&data) {
                                            Some(t) => {
                                                mesh.textures.push(t);
                                                Some(mesh.textures.len() as u32 - 1)
                                            }
                                            None => {
                                                log::warn!(
                                                    "{}: image {} has an unsupported pixel \
                                                     format; using the base colour factor",
                                                    path.display(),
                                                    img.index()
                                                );
                                                None
                                            }
                                        },
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
                let indices: Vec<u32> = match reader.read_indices() {
                    Some(ix) => ix.into_u32().collect(),
                    None => (0..nv as u32).collect(),
                };
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
