//! GPU renderer vs the CPU reference (hit masks, images) and golden regression renders, on any
//! Vulkan device (lavapipe in CI). These tests fail when no device exists.

mod common;

use common::{build_scene, check_golden, gpu, repo, shared_data};
use voxdag::dag::{Svdag, VoxelIndex};
use voxdag::render::gpu::GpuRenderer;
use voxdag::render::{render_cpu, Camera, RenderOutput, RenderSettings};
use voxdag::scene::{morton, Voxels};

/// A procedural scene: a hollow sphere with a window cut out and a solid floor slab, with colours.
fn sphere_scene(n: u32) -> Svdag {
    let c = n as f32 / 2.0;
    let mut codes = Vec::new();
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let d = ((x as f32 + 0.5 - c).powi(2)
                    + (y as f32 + 0.5 - c).powi(2)
                    + (z as f32 + 0.5 - c).powi(2))
                .sqrt();
                let shell = (d - n as f32 * 0.35).abs() < 1.5 && !(x > n / 2 && y > n / 2);
                let floor = y < n / 8;
                if shell || floor {
                    codes.push(morton::encode(x, y, z));
                }
            }
        }
    }
    codes.sort_unstable();
    let colors = codes
        .iter()
        .map(|&code| {
            let [x, y, z] = morton::decode(code);
            (x * 255 / n) | ((y * 255 / n) << 8) | ((z * 255 / n) << 16) | 0xff00_0000
        })
        .collect();
    Svdag::from_voxels(&Voxels {
        resolution: n,
        codes,
        colors,
    })
    .unwrap()
}

fn render_both(dag: &Svdag, settings: &RenderSettings) -> (RenderOutput, RenderOutput) {
    let context = gpu();
    let renderer = GpuRenderer::new(&context).unwrap();
    let scene = renderer.upload(dag).unwrap();
    let gpu_image = renderer.render(&scene, settings, None).unwrap();
    drop(scene);
    drop(renderer);
    assert_eq!(
        context.validation_errors(),
        0,
        "Vulkan validation reported problems"
    );
    let cpu_image = render_cpu(dag, &VoxelIndex::new(dag), settings).unwrap();
    (gpu_image, cpu_image)
}

/// Renders `dag` at 128x128 from the default camera on both paths and compares them
/// (`common::assert_renders_match`).
fn assert_gpu_matches_cpu(name: &str, dag: &Svdag) {
    let settings = RenderSettings::new(128, 128, Camera::frame(dag));
    let (gpu_image, cpu_image) = render_both(dag, &settings);
    common::assert_renders_match(name, &gpu_image, &cpu_image);
}

#[test]
fn gpu_matches_cpu_on_procedural_sphere() {
    assert_gpu_matches_cpu("sphere", &sphere_scene(64));
}

#[test]
fn gpu_matches_cpu_on_avocado() {
    let dag = build_scene(&repo().join("assets/avocado/Avocado.gltf"), Some(128));
    assert!(!dag.colors.is_empty(), "the avocado is textured");
    assert_gpu_matches_cpu("avocado", &dag);
}

#[test]
fn gpu_matches_cpu_on_vox_model() {
    let dag = build_scene(&repo().join("tests/data/ff3.vox"), None);
    assert_gpu_matches_cpu("vox", &dag);
}

#[test]
fn gpu_matches_cpu_on_bunny() {
    let Some(data) = shared_data() else { return };
    let dag = build_scene(&data.join("meshes/bunny.obj"), Some(256));
    assert_gpu_matches_cpu("bunny", &dag);
}

/// Golden renders: at most 0.5% of pixels may differ by more than 8/255 in a channel (lavapipe vs
/// other drivers round a few edge rays differently).
fn golden(name: &str, dag: &Svdag) {
    golden_with_settings(name, dag, RenderSettings::new(256, 256, Camera::frame(dag)));
}

fn golden_with_settings(name: &str, dag: &Svdag, settings: RenderSettings) {
    let context = gpu();
    let renderer = GpuRenderer::new(&context).unwrap();
    let scene = renderer.upload(dag).unwrap();
    let image = renderer.render(&scene, &settings, None).unwrap();
    check_golden(name, &image, 8, 0.005);
}

#[test]
fn golden_avocado() {
    golden(
        "avocado",
        &build_scene(&repo().join("assets/avocado/Avocado.gltf"), Some(256)),
    );
}

#[test]
fn golden_vox() {
    golden(
        "vox",
        &build_scene(&repo().join("tests/data/ff3.vox"), None),
    );
}

#[test]
fn golden_bunny() {
    let Some(data) = shared_data() else { return };
    golden(
        "bunny",
        &build_scene(&data.join("meshes/bunny.obj"), Some(512)),
    );
}

#[test]
fn golden_sponza_crytek() {
    let Some(data) = shared_data() else { return };
    let dag = build_scene(
        &data.join("meshes/sponza-crytek/sponza_crytek_noleaf.obj"),
        Some(512),
    );
    // From the upper gallery down the atrium's long (z) axis; the atrium is open to the sky but
    // narrow, so shadow rays would leave almost all of it in ambient light: render without them.
    let (min, max) = dag.occupied_bounds().unwrap();
    let at = |a: usize, f: f32| min[a] as f32 + f * (max[a] - min[a]) as f32;
    let camera = Camera {
        eye: [at(0, 0.5), at(1, 0.52), at(2, 0.5)],
        target: [at(0, 0.5), at(1, 0.01), at(2, 0.98)],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 80.0,
    };
    let mut settings = RenderSettings::new(256, 256, camera);
    settings.shadows = false;
    golden_with_settings("sponza-crytek", &dag, settings);
}

/// The editor's brush preview (`RenderSettings::preview`): the pixels whose primary ray hits a
/// voxel inside the region are tinted, as the CPU reference tints them; every other pixel is
/// byte for byte the render without the preview.
#[test]
fn brush_preview_tints_the_region_only() {
    use voxdag::edit::tool::Shape;
    use voxdag::render::params::BrushPreview;
    let dag = sphere_scene(64);
    let plain = RenderSettings::new(96, 96, Camera::frame(&dag));
    let context = gpu();
    let renderer = GpuRenderer::new(&context).unwrap();
    let scene = renderer.upload(&dag).unwrap();
    let (before, hits) = renderer.render_first_hits(&scene, &plain).unwrap();
    // Centred on the voxel seen at the middle of the image.
    let centre = &hits[48 * 96 + 48];
    assert_eq!(centre.hit, 1, "the middle pixel sees the sphere");
    for shape in [Shape::Sphere, Shape::Cube] {
        let preview = BrushPreview {
            shape,
            center: centre.voxel.map(|v| v as f32 + 0.5),
            radius: 6.0,
            color: [1.0, 0.0, 1.0],
            strength: 0.5,
        };
        let settings = RenderSettings {
            preview: Some(preview),
            ..plain
        };
        let after = renderer.render(&scene, &settings, None).unwrap();
        assert_eq!(after.hits, before.hits);
        let mut tinted = 0;
        for (i, h) in hits.iter().enumerate() {
            let (a, b) = (
                &after.rgba[4 * i..4 * i + 4],
                &before.rgba[4 * i..4 * i + 4],
            );
            if h.hit == 1 && preview.contains(h.voxel) {
                tinted += 1;
                assert_ne!(a, b, "{shape:?}: pixel {i} in the region is not tinted");
            } else {
                assert_eq!(a, b, "{shape:?}: pixel {i} outside the region changed");
            }
        }
        assert!(tinted > 50, "{shape:?}: only {tinted} pixels in the region");
        let cpu = render_cpu(&dag, &VoxelIndex::new(&dag), &settings).unwrap();
        common::assert_renders_match("brush preview", &after, &cpu);
    }
    drop(scene);
    drop(renderer);
    assert_eq!(context.validation_errors(), 0);
}

/// First hits carry the voxel's colour index (its depth-first Morton rank, as the CPU ray
/// cast gives it) on a scene without colours too: the editor's hover reads it, so the
/// primary-ray variant without the colour index must not serve a render that writes first hits.
#[test]
fn first_hits_carry_colour_indices_without_colours() {
    let mut dag = sphere_scene(64);
    dag.colors.clear();
    let settings = RenderSettings::new(64, 64, Camera::frame(&dag));
    let context = gpu();
    let renderer = GpuRenderer::new(&context).unwrap();
    let scene = renderer.upload(&dag).unwrap();
    let (_, hits) = renderer.render_first_hits(&scene, &settings).unwrap();
    let index = VoxelIndex::new(&dag);
    let mut compared = 0;
    for (i, got) in hits.iter().enumerate() {
        let pixel = [i as u32 % 64, i as u32 / 64];
        let ray = settings.camera.primary_ray(pixel, 64, 64);
        let want = dag.raycast(&index, &ray, voxdag::dag::raycast::T_UNBOUNDED);
        assert_eq!(got.hit == 1, want.is_some(), "pixel {pixel:?}: hit");
        if let Some(want) = want {
            assert_eq!(
                got.color_index, want.color_index,
                "pixel {pixel:?}: colour index"
            );
            compared += usize::from(want.color_index != 0);
        }
    }
    assert!(
        compared > 100,
        "only {compared} hits with a colour index above 0"
    );
}
