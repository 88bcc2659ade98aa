//! Triangle meshes in model space with materials, textures and colour evaluation.
//!
//! Colour model (see `docs/voxelization.md`): the colour at a surface point is
//! `base_color_factor * texture(uv) * vertex_color`, all in linear space. Textures are stored as
//! sRGB RGBA8 and decoded to linear per texel before bilinear interpolation; the result is
//! encoded back to sRGB RGBA8 (alpha stays linear).

use std::path::PathBuf;
use std::sync::OnceLock;

use super::SceneError;
use crate::color::{linear_to_srgb, srgb_to_linear};

/// Texture coordinate wrap mode (glTF sampler semantics).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Wrap {
    /// Repeat the texture (`fract`).
    #[default]
    Repeat,
    /// Repeat, mirroring every other copy.
    MirroredRepeat,
    /// Clamp to the edge texel.
    ClampToEdge,
}

impl Wrap {
    /// Maps an integer texel index into `0..size` according to the wrap mode.
    #[inline]
    fn apply(self, i: i64, size: i64) -> i64 {
        match self {
            Wrap::Repeat => i.rem_euclid(size),
            Wrap::ClampToEdge => i.clamp(0, size - 1),
            Wrap::MirroredRepeat => {
                let m = i.rem_euclid(2 * size);
                if m < size {
                    m
                } else {
                    2 * size - 1 - m
                }
            }
        }
    }
}

/// An RGBA8 sRGB texture, rows top to bottom (uv (0,0) is the top-left corner of texel (0,0)).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Texture {
    /// Width in texels (> 0).
    pub width: u32,
    /// Height in texels (> 0).
    pub height: u32,
    /// `width * height` texels, row-major, sRGB RGB and linear alpha.
    pub texels: Vec<[u8; 4]>,
}

/// Lookup table from an 8-bit sRGB value to linear [0, 1].
fn srgb_lut() -> &'static [f32; 256] {
    static LUT: OnceLock<[f32; 256]> = OnceLock::new();
    LUT.get_or_init(|| {
        let mut t = [0f32; 256];
        for (i, v) in t.iter_mut().enumerate() {
            *v = srgb_to_linear(i as f32 / 255.0);
        }
        t
    })
}

/// Encodes a linear RGBA colour as packed sRGB RGBA8 (`r | g << 8 | b << 16 | a << 24`).
pub fn encode_rgba8(c: [f32; 4]) -> u32 {
    let q = |v: f32| -> u32 {
        let v = if v.is_finite() {
            v.clamp(0.0, 1.0)
        } else {
            0.0
        };
        (v * 255.0 + 0.5) as u32
    };
    q(linear_to_srgb(c[0].max(0.0)))
        | q(linear_to_srgb(c[1].max(0.0))) << 8
        | q(linear_to_srgb(c[2].max(0.0))) << 16
        | q(c[3]) << 24
}

impl Texture {
    /// Builds a texture, checking that the texel count matches the size.
    pub fn new(width: u32, height: u32, texels: Vec<[u8; 4]>) -> Option<Texture> {
        if width == 0 || height == 0 || texels.len() as u64 != width as u64 * height as u64 {
            return None;
        }
        Some(Texture {
            width,
            height,
            texels,
        })
    }

    /// Linear colour of texel (x, y).
    #[inline]
    fn texel_linear(&self, x: i64, y: i64) -> [f32; 4] {
        let lut = srgb_lut();
        let t = self.texels[(y as usize) * self.width as usize + x as usize];
        [
            lut[t[0] as usize],
            lut[t[1] as usize],
            lut[t[2] as usize],
            t[3] as f32 / 255.0,
        ]
    }

    /// Bilinear sample at `uv` in linear space with the given wrap modes (u, v).
    pub fn sample(&self, uv: [f64; 2], wrap: [Wrap; 2]) -> [f32; 4] {
        let (w, h) = (self.width as i64, self.height as i64);
        let fu = if uv[0].is_finite() { uv[0] } else { 0.0 };
        let fv = if uv[1].is_finite() { uv[1] } else { 0.0 };
        // Keep the coordinate in a range where i64 conversion is exact; wrap modes are periodic
        // (period 2 covers mirrored repeat), clamp saturates anyway.
        let reduce = |t: f64, m: Wrap| match m {
            Wrap::ClampToEdge => t.clamp(-1.0, 2.0),
            _ => t.rem_euclid(2.0),
        };
        let x = reduce(fu, wrap[0]) * w as f64 - 0.5;
        let y = reduce(fv, wrap[1]) * h as f64 - 0.5;
        let x0 = x.floor();
        let y0 = y.floor();
        let fx = (x - x0) as f32;
        let fy = (y - y0) as f32;
        let (x0, y0) = (x0 as i64, y0 as i64);
        let xa = wrap[0].apply(x0, w);
        let xb = wrap[0].apply(x0 + 1, w);
        let ya = wrap[1].apply(y0, h);
        let yb = wrap[1].apply(y0 + 1, h);
        let c00 = self.texel_linear(xa, ya);
        let c10 = self.texel_linear(xb, ya);
        let c01 = self.texel_linear(xa, yb);
        let c11 = self.texel_linear(xb, yb);
        let mut out = [0f32; 4];
        for i in 0..4 {
            let top = c00[i] + (c10[i] - c00[i]) * fx;
            let bot = c01[i] + (c11[i] - c01[i]) * fx;
            out[i] = top + (bot - top) * fy;
        }
        out
    }
}

/// A surface material: base colour factor (linear RGBA) and an optional base-colour texture.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Linear RGBA base-colour factor.
    pub base_color: [f32; 4],
    /// Index into [`Mesh::textures`].
    pub texture: Option<u32>,
    /// Wrap modes for u and v.
    pub wrap: [Wrap; 2],
}

impl Default for Material {
    fn default() -> Self {
        Material {
            base_color: [1.0; 4],
            texture: None,
            wrap: [Wrap::Repeat; 2],
        }
    }
}

/// An indexed triangle mesh in model space with per-triangle materials and per-vertex uv/colour.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    /// File the mesh came from (used in error messages); empty for meshes built in code.
    pub source: PathBuf,
    /// Vertex positions in model space.
    pub positions: Vec<[f32; 3]>,
    /// Per-vertex texture coordinates (image convention: v = 0 is the top row); empty or one per vertex.
    pub uvs: Vec<[f32; 2]>,
    /// Per-vertex linear RGBA colours; empty or one per vertex.
    pub colors: Vec<[f32; 4]>,
    /// Triangles as vertex index triples.
    pub triangles: Vec<[u32; 3]>,
    /// Material index of each triangle (into `materials`); empty means material 0 for all.
    pub tri_materials: Vec<u32>,
    /// Materials; may be empty when the mesh has no colour information.
    pub materials: Vec<Material>,
    /// Base-colour textures referenced by materials.
    pub textures: Vec<Texture>,
    /// True when the mesh carries any colour information (materials, textures or vertex colours);
    /// false gives voxels without colours.
    pub has_colors: bool,
}

impl Mesh {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Checks index ranges and array lengths; every other function may then index freely.
    pub fn validate(&self) -> Result<(), SceneError> {
        let bad = |reason: String| {
            Err(SceneError::InvalidMesh {
                path: self.source.clone(),
                reason,
            })
        };
        let nv = self.positions.len();
        if !self.uvs.is_empty() && self.uvs.len() != nv {
            return bad(format!("{} uvs for {} vertices", self.uvs.len(), nv));
        }
        if !self.colors.is_empty() && self.colors.len() != nv {
            return bad(format!("{} colours for {} vertices", self.colors.len(), nv));
        }
        if self.triangles.len() >= u32::MAX as usize {
            return bad(format!("{} triangles (max 2^32 - 1)", self.triangles.len()));
        }
        if let Some((t, tri)) = self
            .triangles
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&i| i as usize >= nv))
        {
            return bad(format!(
                "triangle {t} has index {tri:?} >= vertex count {nv}"
            ));
        }
        if let Some((i, p)) = self
            .positions
            .iter()
            .enumerate()
            .find(|(_, p)| p.iter().any(|c| !c.is_finite()))
        {
            return bad(format!("vertex {i} has a non-finite position {p:?}"));
        }
        if !self.tri_materials.is_empty() {
            if self.tri_materials.len() != self.triangles.len() {
                return bad(format!(
                    "{} triangle materials for {} triangles",
                    self.tri_materials.len(),
                    self.triangles.len()
                ));
            }
            if let Some(m) = self
                .tri_materials
                .iter()
                .find(|&&m| m as usize >= self.materials.len())
            {
                return bad(format!(
                    "material index {m} >= material count {}",
                    self.materials.len()
                ));
            }
        }
        for (i, m) in self.materials.iter().enumerate() {
            if let Some(t) = m.texture {
                if t as usize >= self.textures.len() {
                    return bad(format!("material {i} references missing texture {t}"));
                }
            }
        }
        for (i, t) in self.textures.iter().enumerate() {
            if t.width == 0
                || t.height == 0
                || t.texels.len() != t.width as usize * t.height as usize
            {
                return bad(format!("texture {i} has inconsistent size"));
            }
        }
        Ok(())
    }

    /// Linear RGBA colour of triangle `tri` at barycentric coordinates `bary` (weights of its
    /// three vertices). Requires a validated mesh.
    pub fn color_at(&self, tri: usize, bary: [f64; 3]) -> [f32; 4] {
        let idx = self.triangles[tri];
        let material = if self.materials.is_empty() {
            None
        } else {
            let m = self.tri_materials.get(tri).copied().unwrap_or(0);
            self.materials.get(m as usize)
        };
        let mut c = material.map(|m| m.base_color).unwrap_or([1.0; 4]);
        if let Some(m) = material {
            if let (Some(t), false) = (m.texture, self.uvs.is_empty()) {
                let mut uv = [0f64; 2];
                for k in 0..3 {
                    let v = self.uvs[idx[k] as usize];
                    uv[0] += bary[k] * v[0] as f64;
                    uv[1] += bary[k] * v[1] as f64;
                }
                let s = self.textures[t as usize].sample(uv, m.wrap);
                for i in 0..4 {
                    c[i] *= s[i];
                }
            }
        }
        if !self.colors.is_empty() {
            let mut vc = [0f64; 4];
            for k in 0..3 {
                let v = self.colors[idx[k] as usize];
                for i in 0..4 {
                    vc[i] += bary[k] * v[i] as f64;
                }
            }
            for i in 0..4 {
                c[i] *= vc[i] as f32;
            }
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trip() {
        for i in 0..=255u32 {
            let lin = srgb_lut()[i as usize];
            assert_eq!(
                encode_rgba8([lin, lin, lin, 1.0]),
                i | i << 8 | i << 16 | 255 << 24
            );
        }
    }

    #[test]
    fn bilinear_in_linear_space_with_wrap() {
        // 2x1 texture: black | white.
        let t = Texture::new(2, 1, vec![[0, 0, 0, 255], [255, 255, 255, 255]]).unwrap();
        // Halfway between texel centres: linear 0.5 -> sRGB 188.
        let c = t.sample([0.5, 0.5], [Wrap::Repeat; 2]);
        assert!((c[0] - 0.5).abs() < 1e-6);
        assert_eq!(encode_rgba8(c) & 0xff, 188);
        // u = 0: halfway between texel 0 and (wrapped) texel 1 with repeat; texel 0 with clamp.
        let r = t.sample([0.0, 0.5], [Wrap::Repeat; 2]);
        assert!((r[0] - 0.5).abs() < 1e-6);
        let c = t.sample([0.0, 0.5], [Wrap::ClampToEdge; 2]);
        assert_eq!(c[0], 0.0);
        // Mirrored: u = -0.25 mirrors to 0.25 = centre of texel 0.
        let m = t.sample([-0.25, 0.5], [Wrap::MirroredRepeat; 2]);
        assert_eq!(m[0], 0.0);
        let m = t.sample([1.25, 0.5], [Wrap::MirroredRepeat; 2]);
        assert_eq!(m[0], 1.0);
        // Repeat: u = 1.25 is the centre of texel 0.
        let r = t.sample([1.25, 0.5], [Wrap::Repeat; 2]);
        assert_eq!(r[0], 0.0);
    }
}
