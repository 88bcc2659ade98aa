//! Wavefront OBJ (+ .mtl) loading with `tobj`.
//!
//! Colours: `Kd` (linear) times the `map_Kd` texture times vertex colours (`v x y z r g b`,
//! linear). A texture that is missing or cannot be decoded is reported with `log::warn!` once
//! per distinct texture path (per load; materials sharing it are not reported again) and the
//! material falls back to `Kd` (a `Kd` of zero next to a `map_Kd` counts as 1:
//! the exporters' "texture only" convention). OBJ texture coordinates have v = 0 at the
//! bottom of the image; they are flipped to the image convention of [`Mesh::uvs`].

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use super::mesh::{Material, Mesh, Wrap};
use super::{guard, load_texture, texture_from_bytes, AssetRoots, ImportOptions, SceneError};

/// Loads `path` as an OBJ mesh; `mtllib` and `map_Kd` files must lie under `roots` (else one
/// warning each and the base colour).
pub(crate) fn load_obj(
    path: &Path,
    opts: &ImportOptions,
    roots: &AssetRoots,
) -> Result<Mesh, SceneError> {
    // A missing file is an io error (as for every format), not a parse error.
    std::fs::metadata(path).map_err(|e| SceneError::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    let bytes = super::read_bounded(path, "OBJ file").map_err(|e| SceneError::Parse {
        path: path.to_path_buf(),
        format: "obj",
        message: e,
    })?;
    let load_opts = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    // Material libraries are opened only inside the asset roots.
    let load_mtl = |lib: &Path| -> tobj::MTLLoadResult {
        let name = lib.to_string_lossy().replace('\\', "/");
        match roots.read(&name, "material library") {
            Ok(text) => tobj::load_mtl_buf(&mut std::io::Cursor::new(text)),
            Err(e) => {
                log::warn!(
                    "{}: material library {name:?} not opened: {e}; using the base colour",
                    path.display()
                );
                Err(tobj::LoadError::OpenFileFailed)
            }
        }
    };
    let (models, materials) = guard(path, "obj", || {
        tobj::load_obj_buf(&mut std::io::Cursor::new(&bytes), &load_opts, load_mtl).map_err(|e| {
            SceneError::Parse {
                path: path.to_path_buf(),
                format: "obj",
                message: e.to_string(),
            }
        })
    })?;
    let mut mesh = Mesh {
        source: path.to_path_buf(),
        ..Mesh::default()
    };

    // Materials.
    let obj_materials = match materials {
        Ok(m) => m,
        Err(e) => {
            if !matches!(e, tobj::LoadError::OpenFileFailed) {
                log::warn!(
                    "{}: material library unusable ({e}); no materials",
                    path.display()
                );
            }
            Vec::new()
        }
    };
    let mut texture_cache: HashMap<PathBuf, Option<u32>> = HashMap::new();
    // `Ok`: a file named on the command line (trusted); `Err`: a reference from the model.
    let mut get_texture = |mesh: &mut Mesh, file: Result<&Path, &str>| -> Option<u32> {
        let key = match file {
            Ok(p) => p.to_path_buf(),
            Err(r) => PathBuf::from(r),
        };
        if let Some(&t) = texture_cache.get(&key) {
            return t;
        }
        let loaded = match file {
            Ok(p) => load_texture(p),
            Err(r) => roots
                .read(r, "texture")
                .and_then(|bytes| texture_from_bytes(&bytes)),
        };
        let file = key.as_path();
        let t = match loaded {
            Ok(tex) => {
                mesh.textures.push(tex);
                Some(mesh.textures.len() as u32 - 1)
            }
            Err(e) => {
                log::warn!(
                    "{}: texture {} unusable ({e}); using the material's Kd",
                    path.display(),
                    file.display()
                );
                None
            }
        };
        texture_cache.insert(key.clone(), t);
        t
    };
    let override_material = match &opts.texture_override {
        Some(file) => {
            let t = get_texture(&mut mesh, Ok(file));
            if t.is_none() {
                return Err(SceneError::Io {
                    path: file.clone(),
                    source: std::io::Error::other("texture override could not be loaded"),
                });
            }
            Some(Material {
                base_color: [1.0; 4],
                texture: t,
                wrap: [Wrap::Repeat; 2],
            })
        }
        None => None,
    };
    if let Some(m) = override_material {
        mesh.materials.push(m);
    } else {
        for m in &obj_materials {
            let mut kd = m.diffuse.unwrap_or([1.0; 3]);
            // Exporters such as Maya write `Kd 0 0 0` next to `map_Kd` meaning "the texture
            // alone"; read that as Kd = 1 so that a textured (or texture-less) material is not black.
            if m.diffuse_texture.is_some() && kd == [0.0; 3] {
                kd = [1.0; 3];
            }
            let alpha = m.dissolve.unwrap_or(1.0);
            let texture = m.diffuse_texture.as_ref().and_then(|name| {
                let name = name.replace('\\', "/");
                // `map_Kd` may carry options before the file name; the file is the last token.
                let file = name.split_whitespace().last().unwrap_or("");
                if file.is_empty() {
                    None
                } else {
                    get_texture(&mut mesh, Err(file))
                }
            });
            mesh.materials.push(Material {
                base_color: [kd[0], kd[1], kd[2], alpha],
                texture,
                wrap: [Wrap::Repeat; 2],
            });
        }
    }
    let default_material = mesh.materials.len() as u32;
    let mut need_default = false;

    // Geometry.
    let any_vertex_colors = models.iter().any(|m| !m.mesh.vertex_color.is_empty());
    let any_uvs = models.iter().any(|m| !m.mesh.texcoords.is_empty());
    for model in &models {
        let m = &model.mesh;
        let first = mesh.positions.len() as u64;
        let nv = m.positions.len() / 3;
        if first + nv as u64 >= u32::MAX as u64 {
            return Err(SceneError::TooLarge {
                path: path.to_path_buf(),
                reason: "more than 2^32 vertices".into(),
            });
        }
        mesh.positions
            .extend(m.positions.chunks_exact(3).map(|p| [p[0], p[1], p[2]]));
        if any_uvs {
            if m.texcoords.len() == nv * 2 {
                mesh.uvs
                    .extend(m.texcoords.chunks_exact(2).map(|t| [t[0], 1.0 - t[1]]));
            } else {
                mesh.uvs.extend(std::iter::repeat_n([0.0, 0.0], nv));
            }
        }
        if any_vertex_colors {
            if m.vertex_color.len() == nv * 3 {
                mesh.colors.extend(
                    m.vertex_color
                        .chunks_exact(3)
                        .map(|c| [c[0], c[1], c[2], 1.0]),
                );
            } else {
                mesh.colors.extend(std::iter::repeat_n([1.0; 4], nv));
            }
        }
        let material = if opts.texture_override.is_some() {
            0
        } else {
            match m.material_id {
                Some(id) if id < obj_materials.len() => id as u32,
                _ => {
                    need_default = true;
                    default_material
                }
            }
        };
        for t in m.indices.chunks_exact(3) {
            if t.iter().any(|&i| i as usize >= nv) {
                return Err(SceneError::Parse {
                    path: path.to_path_buf(),
                    format: "obj",
                    message: format!("face index {t:?} out of range ({nv} vertices)"),
                });
            }
            mesh.triangles.push([
                t[0] + first as u32,
                t[1] + first as u32,
                t[2] + first as u32,
            ]);
            mesh.tri_materials.push(material);
        }
    }
    if need_default {
        mesh.materials.push(Material::default());
    }
    mesh.has_colors =
        !obj_materials.is_empty() || opts.texture_override.is_some() || any_vertex_colors;
    if !mesh.has_colors {
        mesh.materials.clear();
        mesh.tri_materials.clear();
    }
    if mesh.triangles.is_empty() {
        return Err(SceneError::InvalidMesh {
            path: path.to_path_buf(),
            reason: "no triangles".into(),
        });
    }
    Ok(mesh)
}
