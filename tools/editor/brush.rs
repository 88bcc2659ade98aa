//! The editor's tools: which edit a click makes (sphere / cube add and remove, paint, fill, copy
//! from a picked source with a quarter-turn rotation) and the brush preview the renderer draws
//! at the hit (the voxels in the tool's region tinted).

use clap::ValueEnum;
use glam::Vec3;
use serde::Serialize;
use voxdag::color::srgb_to_linear;
use voxdag::edit::tool::{CopyParams, Shape, Tool};
use voxdag::render::params::BrushPreview;
use voxdag::render::Camera;

/// The tools of the editor.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ToolKind {
    /// Add a ball of voxels.
    SphereAdd,
    /// Remove a ball of voxels.
    SphereRemove,
    /// Add an axis-aligned cube of voxels.
    CubeAdd,
    /// Remove an axis-aligned cube of voxels.
    CubeRemove,
    /// Set the material of the solid voxels in a ball (geometry unchanged).
    Paint,
    /// Flood the empty voxels reachable from the cursor inside a cube.
    Fill,
    /// Stamp the picked source cube (Shift+click) at the cursor.
    Copy,
}

impl ToolKind {
    /// Every tool, in the order of the number keys 1..7.
    pub const ALL: [ToolKind; 7] = [
        ToolKind::SphereAdd,
        ToolKind::SphereRemove,
        ToolKind::CubeAdd,
        ToolKind::CubeRemove,
        ToolKind::Paint,
        ToolKind::Fill,
        ToolKind::Copy,
    ];

    /// Name in the Tools panel.
    pub fn label(self) -> &'static str {
        match self {
            ToolKind::SphereAdd => "sphere add",
            ToolKind::SphereRemove => "sphere remove",
            ToolKind::CubeAdd => "cube add",
            ToolKind::CubeRemove => "cube remove",
            ToolKind::Paint => "paint",
            ToolKind::Fill => "fill",
            ToolKind::Copy => "copy (Shift+click: source)",
        }
    }

    /// Whether the tool is centred on the empty voxel in front of the hit face (it puts voxels
    /// there) rather than on the hit voxel itself.
    pub fn in_front(self) -> bool {
        matches!(
            self,
            ToolKind::SphereAdd | ToolKind::CubeAdd | ToolKind::Fill | ToolKind::Copy
        )
    }

    /// Whether the tool's region is a cube (else a ball).
    fn cube(self) -> bool {
        matches!(
            self,
            ToolKind::CubeAdd | ToolKind::CubeRemove | ToolKind::Fill | ToolKind::Copy
        )
    }
}

/// The copy tool's state: the picked source centre and the stamp's rotation about +y.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct CopyState {
    /// Centre of the source cube (Shift+click with the copy tool); `None` until picked.
    pub source: Option<[f32; 3]>,
    /// Quarter turns about +y applied to the stamp (0..4).
    pub quarter_turns: u8,
}

impl CopyState {
    /// The rotation as the copy tool's row-major matrix; `None` for no rotation.
    fn transform(&self) -> Option<[[f32; 3]; 3]> {
        // A quarter turn maps +x to -z and +z to +x (right-handed, about +y).
        match self.quarter_turns % 4 {
            0 => None,
            1 => Some([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]),
            2 => Some([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]),
            _ => Some([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
        }
    }
}

/// The edit `kind` makes at `center`; `None` for the copy tool without a source.
pub fn tool(
    kind: ToolKind,
    center: [f32; 3],
    radius: f32,
    material: u8,
    copy: &CopyState,
) -> Option<Tool> {
    let shape = if kind.cube() {
        Shape::Cube
    } else {
        Shape::Sphere
    };
    Some(match kind {
        ToolKind::SphereAdd | ToolKind::CubeAdd => Tool::Add {
            shape,
            center,
            radius,
            material,
        },
        ToolKind::SphereRemove | ToolKind::CubeRemove => Tool::Remove {
            shape,
            center,
            radius,
        },
        ToolKind::Paint => Tool::Paint {
            center,
            radius,
            material,
        },
        ToolKind::Fill => Tool::Fill {
            center,
            radius,
            material,
        },
        ToolKind::Copy => {
            let source = copy.source?;
            Tool::Copy(CopyParams {
                source,
                dest: center,
                center: source,
                radius,
                transform: copy.transform(),
            })
        }
    })
}

/// One edit of every kind the brush makes (parameters arbitrary): what
/// `GpuHashDag::prepare_tools` needs to make every edit pipeline the editor can use.
pub fn one_of_each() -> Vec<Tool> {
    let copy = CopyState {
        source: Some([0.0; 3]),
        quarter_turns: 0,
    };
    ToolKind::ALL
        .iter()
        .filter_map(|&kind| tool(kind, [0.0; 3], 1.0, 0, &copy))
        .collect()
}

/// How much of the shaded colour the preview tint replaces.
const PREVIEW_STRENGTH: f32 = 0.45;

/// The renderer's brush preview of `kind` at `center`: the tool's region (its own shape and
/// inclusion rule) tinted green for adding, red for removing, the material's colour (`material`,
/// sRGB) for paint.
pub fn preview(kind: ToolKind, center: [f32; 3], radius: f32, material: [u8; 3]) -> BrushPreview {
    let srgb = match kind {
        ToolKind::SphereRemove | ToolKind::CubeRemove => [240, 90, 80],
        ToolKind::Paint => material,
        _ => [80, 220, 120],
    };
    BrushPreview {
        shape: if kind.cube() {
            Shape::Cube
        } else {
            Shape::Sphere
        },
        center,
        radius,
        color: srgb.map(|c| srgb_to_linear(c as f32 / 255.0)),
        strength: PREVIEW_STRENGTH,
    }
}

/// Outlines the copy tool's source cube (`radius` voxels around `source`) on the overlay in
/// yellow: the renderer tints one region, the stamp's destination under the cursor.
pub fn draw_copy_source(
    ctx: &egui::Context,
    camera: &Camera,
    extent: [u32; 2],
    source: [f32; 3],
    radius: f32,
) {
    let [w, h] = extent;
    let Some(c) = camera.project(source, w, h) else {
        return;
    };
    let up = Vec3::from(camera.basis().up);
    let edge = (Vec3::from(source) + up * radius).to_array();
    let Some(e) = camera.project(edge, w, h) else {
        return;
    };
    let painter = ctx.layer_painter(egui::LayerId::background());
    let ppp = ctx.pixels_per_point();
    let to_points = |q: [f32; 2]| egui::pos2(q[0] / ppp, q[1] / ppp);
    let (c, e) = (to_points(c), to_points(e));
    // Dark under light: visible on bright and dark voxels.
    let half = c.distance(e).max(2.0);
    for (width, col) in [(3.0, egui::Color32::BLACK), (1.5, egui::Color32::YELLOW)] {
        painter.rect_stroke(
            egui::Rect::from_center_size(c, egui::vec2(2.0 * half, 2.0 * half)),
            0.0,
            egui::Stroke::new(width, col),
            egui::StrokeKind::Middle,
        );
    }
    painter.circle_filled(c, 2.0, egui::Color32::YELLOW);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn copy_needs_a_source_and_rotates_in_quarter_turns() {
        let mut copy = CopyState::default();
        assert_eq!(tool(ToolKind::Copy, [1.0; 3], 4.0, 0, &copy), None);
        copy.source = Some([8.0, 8.0, 8.0]);
        for turns in 0..4u8 {
            copy.quarter_turns = turns;
            let Some(Tool::Copy(p)) = tool(ToolKind::Copy, [20.0, 8.0, 8.0], 4.0, 0, &copy) else {
                panic!("a copy");
            };
            assert_eq!(
                (p.source, p.dest, p.center),
                ([8.0; 3], [20.0, 8.0, 8.0], [8.0; 3])
            );
            // Four quarter turns of +x come back to +x; each is a proper rotation.
            let m = p
                .transform
                .unwrap_or([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
            let mut v = [1.0f32, 0.0, 0.0];
            for _ in 0..4 {
                v = [0, 1, 2].map(|r| m[r][0] * v[0] + m[r][1] * v[1] + m[r][2] * v[2]);
            }
            assert_eq!(v, [1.0, 0.0, 0.0]);
            assert_eq!(m[1], [0.0, 1.0, 0.0], "turns about +y");
        }
    }

    #[test]
    fn paint_keeps_its_material_and_remove_has_none() {
        let copy = CopyState::default();
        assert!(matches!(
            tool(ToolKind::Paint, [1.0; 3], 3.0, 5, &copy),
            Some(Tool::Paint { material: 5, .. })
        ));
        assert!(matches!(
            tool(ToolKind::CubeRemove, [1.0; 3], 3.0, 5, &copy),
            Some(Tool::Remove {
                shape: Shape::Cube,
                ..
            })
        ));
    }

    #[test]
    fn the_preview_has_the_tools_shape_and_colour() {
        let material = [10, 200, 30];
        let p = preview(ToolKind::CubeRemove, [4.5; 3], 2.0, material);
        assert_eq!((p.shape, p.center, p.radius), (Shape::Cube, [4.5; 3], 2.0));
        assert!(p.color[0] > p.color[1], "remove is red");
        let p = preview(ToolKind::SphereAdd, [4.5; 3], 2.0, material);
        assert_eq!(p.shape, Shape::Sphere);
        assert!(p.color[1] > p.color[0], "add is green");
        let paint = preview(ToolKind::Paint, [4.5; 3], 2.0, material);
        assert_eq!(paint.shape, Shape::Sphere);
        assert_eq!(
            paint.color,
            material.map(|c| srgb_to_linear(c as f32 / 255.0))
        );
        for kind in [ToolKind::Fill, ToolKind::Copy] {
            assert_eq!(preview(kind, [0.5; 3], 1.0, material).shape, Shape::Cube);
        }
        // The region is the tool's: the voxels the edit would touch.
        let ball = preview(ToolKind::SphereAdd, [4.5; 3], 2.0, material);
        assert!(ball.contains([4, 4, 4]) && ball.contains([6, 4, 4]));
        assert!(
            !ball.contains([6, 6, 4]),
            "corner of the cube, outside the ball"
        );
        let cube = preview(ToolKind::CubeAdd, [4.5; 3], 2.0, material);
        assert!(cube.contains([6, 6, 6]) && !cube.contains([7, 4, 4]));
    }
}
