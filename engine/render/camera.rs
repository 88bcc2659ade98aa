//! Pinhole camera in grid coordinates (y up) and primary-ray generation.

// Per-axis index loops mirror the GLSL vector code one to one.
#![allow(clippy::needless_range_loop)]

use crate::dag::raycast::Ray;
use crate::dag::Svdag;

/// A look-at pinhole camera in grid coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position.
    pub eye: [f32; 3],
    /// Point looked at.
    pub target: [f32; 3],
    /// Approximate up vector (y up by default).
    pub up: [f32; 3],
    /// Vertical field of view in degrees.
    pub fov_y_deg: f32,
}

/// Orthonormal camera frame: `right`, `up` and `forward` unit vectors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraBasis {
    /// Image x axis (to the right).
    pub right: [f32; 3],
    /// Image y axis (up).
    pub up: [f32; 3],
    /// Viewing direction.
    pub forward: [f32; 3],
}

/// Azimuth of the default camera, degrees around +y from +z.
pub const DEFAULT_AZIMUTH_DEG: f32 = 35.0;
/// Elevation of the default camera above the horizontal plane, degrees.
pub const DEFAULT_ELEVATION_DEG: f32 = 25.0;
/// Vertical field of view of the default camera, degrees.
pub const DEFAULT_FOV_Y_DEG: f32 = 45.0;

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn length(a: [f32; 3]) -> f32 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

/// `a / |a|`, or `None` when `a` is (nearly) zero or not finite.
pub(crate) fn normalize(a: [f32; 3]) -> Option<[f32; 3]> {
    let l = length(a);
    if l > 1e-20 && l.is_finite() {
        Some([a[0] / l, a[1] / l, a[2] / l])
    } else {
        None
    }
}

impl Camera {
    /// [`Camera::orbit`] around the whole `resolution^3` grid.
    pub fn orbit_default(resolution: u32) -> Camera {
        Camera::orbit([0.0; 3], [resolution as f32; 3])
    }

    /// The default view of a scene: [`Camera::orbit`] around its occupied bounds, or the whole
    /// grid when it is empty.
    pub fn frame(dag: &Svdag) -> Camera {
        match dag.occupied_bounds() {
            Some((min, max)) => Camera::orbit(min.map(|v| v as f32), max.map(|v| v as f32)),
            None => Camera::orbit_default(dag.resolution),
        }
    }

    /// Looks at the centre of the box `min..max` from azimuth 35°, elevation 25°, far enough that
    /// the box's bounding sphere fits the vertical field of view (so the whole box is visible at
    /// any aspect ratio >= 1).
    pub fn orbit(min: [f32; 3], max: [f32; 3]) -> Camera {
        let centre = [0, 1, 2].map(|a| 0.5 * (min[a] + max[a]));
        let radius = 0.5 * length(sub(max, min));
        let half_fov = (0.5 * DEFAULT_FOV_Y_DEG).to_radians();
        let distance = 1.1 * radius / half_fov.sin();
        let (az, el) = (
            DEFAULT_AZIMUTH_DEG.to_radians(),
            DEFAULT_ELEVATION_DEG.to_radians(),
        );
        let offset = [
            distance * el.cos() * az.sin(),
            distance * el.sin(),
            distance * el.cos() * az.cos(),
        ];
        Camera {
            eye: [
                centre[0] + offset[0],
                centre[1] + offset[1],
                centre[2] + offset[2],
            ],
            target: centre,
            up: [0.0, 1.0, 0.0],
            fov_y_deg: DEFAULT_FOV_Y_DEG,
        }
    }

    /// The orthonormal frame of the camera. Degenerate inputs fall back to sane axes: eye ==
    /// target looks along -z, and an `up` parallel to the view direction is replaced by +z or +x.
    pub fn basis(&self) -> CameraBasis {
        let forward = normalize(sub(self.target, self.eye)).unwrap_or([0.0, 0.0, -1.0]);
        let right = [self.up, [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]
            .iter()
            .find_map(|&up| {
                let r = cross(forward, up);
                if length(r) > 1e-4 * length(up).max(1e-30) {
                    normalize(r)
                } else {
                    None
                }
            })
            .unwrap_or([1.0, 0.0, 0.0]);
        let up = cross(right, forward);
        CameraBasis { right, up, forward }
    }

    /// `tan(fov_y / 2)`, with the field of view clamped to `[1e-3, 179]` degrees.
    pub fn tan_half_fov(&self) -> f32 {
        let fov = if self.fov_y_deg.is_finite() {
            self.fov_y_deg.clamp(1e-3, 179.0)
        } else {
            DEFAULT_FOV_Y_DEG
        };
        (0.5 * fov).to_radians().tan()
    }

    /// Primary ray through the centre of `pixel` (x right, y down from the top-left corner) of
    /// a `width x height` image; built exactly like the GPU does from `RenderParams`.
    pub fn primary_ray(&self, pixel: [u32; 2], width: u32, height: u32) -> Ray {
        let b = self.basis();
        let scale = pixel_scale(self.tan_half_fov(), height);
        generate_ray(self.eye, &b, scale, pixel, width, height)
    }

    /// Projects a point to continuous pixel coordinates (`None` when behind the eye).
    pub fn project(&self, point: [f32; 3], width: u32, height: u32) -> Option<[f32; 2]> {
        let b = self.basis();
        let d = sub(point, self.eye);
        let z = dot(d, b.forward);
        if z <= 0.0 {
            return None;
        }
        let scale = pixel_scale(self.tan_half_fov(), height);
        let u = dot(d, b.right) / z / scale;
        let v = dot(d, b.up) / z / scale;
        Some([u + 0.5 * width as f32, 0.5 * height as f32 - v])
    }
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Size of one pixel on the image plane at distance 1: `2 tan(fov_y / 2) / height`.
pub(crate) fn pixel_scale(tan_half_fov: f32, height: u32) -> f32 {
    2.0 * tan_half_fov / height.max(1) as f32
}

/// The primary-ray formula shared with `shade.glsl` (same f32 operations, same order):
/// `u = (x + 0.5 - width/2) * scale`, `v = (height/2 - y - 0.5) * scale`,
/// `dir = (forward + u * right) + v * up` (not normalised).
pub(crate) fn generate_ray(
    eye: [f32; 3],
    b: &CameraBasis,
    scale: f32,
    pixel: [u32; 2],
    width: u32,
    height: u32,
) -> Ray {
    let u = (pixel[0] as f32 + 0.5 - 0.5 * width as f32) * scale;
    let v = (0.5 * height as f32 - pixel[1] as f32 - 0.5) * scale;
    let mut dir = [0.0f32; 3];
    for k in 0..3 {
        dir[k] = b.forward[k] + u * b.right[k] + v * b.up[k];
    }
    Ray { origin: eye, dir }
}
