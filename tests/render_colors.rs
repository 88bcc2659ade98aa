//! Colours on screen from encoded chunks: the GPU renderer decodes every format during traversal
//! (binary search of the chunk, then the format's GLSL decoder) and matches the CPU reference,
//! which decodes through `ChunkedColors::color`; golden renders of the textured scenes per codec.

mod common;

use common::{assert_renders_match, check_golden, gpu, shared_data};
use indicatif::ProgressBar;
use voxdag::attr::{ColorCodec, ColorFormat, StoredColors};
use voxdag::dag::{Svdag, VoxelIndex};
use voxdag::render::cpu::{render_cpu_with, ColorSource};
use voxdag::render::gpu::{colors_for_allocation, GpuRenderer};
use voxdag::render::{render_cpu, Camera, RenderOutput, RenderSettings};
use voxdag::scene::{self, morton, ImportOptions, Voxels};

/// Every `--colors` codec the renderer must display.
const CODECS: &[&str] = &[
    "raw",
    "lossless",
    "lossless565",
    "lossy",
    "dolonius",
    "dado",
];

fn encode(dag: &Svdag, codec: &str, depth: Option<u32>) -> StoredColors {
    let codec = ColorCodec::parse(codec).unwrap();
    StoredColors::encode(dag, codec, depth, &ProgressBar::hidden()).unwrap()
}

/// GPU and CPU renders of `dag` with its colours taken from `stored`.
fn render_both(
    dag: &Svdag,
    stored: &StoredColors,
    settings: &RenderSettings,
) -> (RenderOutput, RenderOutput) {
    let context = gpu();
    let renderer = GpuRenderer::new(&context).unwrap();
    let scene = renderer
        .upload_with(dag, ColorSource::Chunked(&stored.chunks))
        .unwrap();
    assert_eq!(scene.color_format(), stored.chunks.format);
    let gpu_image = renderer.render(&scene, settings, None).unwrap();
    drop(scene);
    drop(renderer);
    assert_eq!(context.validation_errors(), 0, "Vulkan validation errors");
    let index = VoxelIndex::new(dag);
    let cpu_image =
        render_cpu_with(dag, &index, ColorSource::Chunked(&stored.chunks), settings).unwrap();
    (gpu_image, cpu_image)
}

/// A 64^3 sphere shell painted by position, with speckles, so every chunk has distinct colours.
fn painted_sphere() -> Svdag {
    let n = 64i32;
    let mut voxels = Vec::new();
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let d = ((x - 32).pow(2) + (y - 32).pow(2) + (z - 32).pow(2)) as f32;
                if (d.sqrt() - 26.0).abs() < 1.5 {
                    let (ux, uy, uz) = (x as u32, y as u32, z as u32);
                    let speckle = (ux * 7 + uy * 3 + uz * 5) % 13 == 0;
                    let c = if speckle {
                        ux.wrapping_mul(2654435761) ^ uz.wrapping_mul(40503)
                    } else {
                        (ux * 4) | ((uy * 4) << 8) | ((uz * 4) << 16)
                    };
                    voxels.push((morton::encode(ux, uy, uz), c | 0xff00_0000));
                }
            }
        }
    }
    voxels.sort_unstable();
    Svdag::from_voxels(&Voxels {
        resolution: n as u32,
        codes: voxels.iter().map(|v| v.0).collect(),
        colors: voxels.iter().map(|v| v.1).collect(),
    })
    .unwrap()
}

#[test]
fn chunked_colours_render_like_their_decoded_values() {
    let dag = painted_sphere();
    let settings = RenderSettings::new(96, 96, Camera::frame(&dag));
    for codec in CODECS {
        // Depth 3 at 64^3: 8^3-voxel nodes, a few hundred chunks for the binary search.
        let stored = encode(&dag, codec, Some(3));
        assert!(stored.chunks.chunk_count() > 100);
        let (gpu_image, cpu_image) = render_both(&dag, &stored, &settings);
        assert_renders_match(codec, &gpu_image, &cpu_image);
        // The CPU per-hit decode equals rendering the fully decoded colours.
        let mut decoded = dag.clone();
        decoded.colors = stored.chunks.decode_all().unwrap();
        let reference = render_cpu(&decoded, &VoxelIndex::new(&decoded), &settings).unwrap();
        assert_eq!(cpu_image, reference, "{codec}");
    }
}

#[test]
fn raw_colours_beyond_one_allocation_render_exactly_as_raw() {
    let dag = painted_sphere();
    let raw_bytes = dag.colors.len() as u64 * 4;
    assert!(colors_for_allocation(&dag.colors, raw_bytes)
        .unwrap()
        .is_none());
    // One byte over the limit: the upload's fallback, lossless chunks in colour order.
    let fitted = colors_for_allocation(&dag.colors, raw_bytes - 1)
        .unwrap()
        .expect("re-encoded");
    assert_eq!(fitted.decode_all().unwrap(), dag.colors);
    assert!(fitted.byte_size() < raw_bytes);
    let settings = RenderSettings::new(96, 96, Camera::frame(&dag));
    let context = gpu();
    let renderer = GpuRenderer::new(&context).unwrap();
    let raw = renderer.upload(&dag).unwrap();
    assert_eq!(raw.color_format(), ColorFormat::Raw);
    let chunked = renderer
        .upload_with(&dag, ColorSource::Chunked(&fitted))
        .unwrap();
    assert_eq!(chunked.color_format(), ColorFormat::Lossless888);
    let raw_image = renderer.render(&raw, &settings, None).unwrap();
    let chunked_image = renderer.render(&chunked, &settings, None).unwrap();
    assert_eq!(raw_image, chunked_image);
    drop((raw, chunked, renderer));
    assert_eq!(context.validation_errors(), 0, "Vulkan validation errors");
}

/// Voxelizes a textured scene from `../shared/data/textured` at 256^3.
fn textured(data: &std::path::Path, scene_name: &str) -> Svdag {
    let dir = data.join("textured").join(scene_name);
    let (path, texture) = match scene_name {
        "spot" => (
            dir.join("spot_triangulated.obj"),
            Some(dir.join("spot_texture.png")),
        ),
        other => (dir.join(format!("{other}.gltf")), None),
    };
    let options = ImportOptions {
        resolution: Some(256),
        texture_override: texture,
        ..Default::default()
    };
    let voxels = scene::import(&path, &options, &ProgressBar::hidden()).unwrap();
    Svdag::from_voxels(&voxels).unwrap()
}

#[test]
fn golden_textured_scenes_per_codec() {
    let Some(data) = shared_data() else { return };
    for scene_name in ["spot", "Avocado", "BoomBox"] {
        let dag = textured(&data, scene_name);
        assert!(!dag.colors.is_empty(), "{scene_name} is textured");
        let settings = RenderSettings::new(128, 128, Camera::frame(&dag));
        let mut raw_image = None;
        for codec in CODECS {
            let stored = encode(&dag, codec, None);
            let (gpu_image, cpu_image) = render_both(&dag, &stored, &settings);
            let name = format!("{scene_name}/{codec}");
            assert_renders_match(&name, &gpu_image, &cpu_image);
            match *codec {
                "raw" => raw_image = Some(gpu_image.clone()),
                "lossless" => assert_eq!(
                    Some(&gpu_image),
                    raw_image.as_ref(),
                    "{name}: lossless must render exactly like raw"
                ),
                _ => {}
            }
            let golden = format!("colors-{}-{codec}", scene_name.to_lowercase());
            check_golden(&golden, &gpu_image, 8, 0.005);
        }
    }
}
