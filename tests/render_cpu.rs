//! CPU ray cast vs a brute-force DDA, camera framing and the CPU reference renderer.
//!
//! Tolerance: the DAG ray cast (f32) and the DDA (f64) may disagree only when one of their hit
//! points lies within `EDGE_TOL` (1e-4 grid units) of a voxel edge or corner (two coordinates
//! within 1e-4 of an integer), or when a hit `t` lies within 1e-4 (relative) of `t_max`.
//! Otherwise voxel, normal and colour index must be equal and `t` equal within 1e-4 relative.

use proptest::prelude::*;
use voxdag::dag::raycast::{raycast_reference, Hit, Ray, T_UNBOUNDED};
use voxdag::dag::{Svdag, VoxelIndex};
use voxdag::render::cpu::{linear_to_srgb, quantize, srgb_to_linear, AMBIENT, DIFFUSE, GREY};
use voxdag::render::{render_cpu, Camera, RenderOutput, RenderParams, RenderSettings};
use voxdag::scene::{morton, Voxels};

const EDGE_TOL: f64 = 1e-4;

fn voxels_from(resolution: u32, mut coords: Vec<[u32; 3]>, colored: bool) -> Voxels {
    coords.sort_by_key(|c| morton::encode(c[0], c[1], c[2]));
    coords.dedup();
    let codes: Vec<u64> = coords
        .iter()
        .map(|c| morton::encode(c[0], c[1], c[2]))
        .collect();
    let colors = if colored {
        codes
            .iter()
            .map(|&c| 0xff00_0000 | (c as u32).wrapping_mul(2_654_435_761) & 0x00ff_ffff)
            .collect()
    } else {
        Vec::new()
    };
    Voxels {
        resolution,
        codes,
        colors,
    }
}

/// True when the point `origin + t dir` lies within `EDGE_TOL` of a voxel edge or corner.
fn near_edge(ray: &Ray, t: f32) -> bool {
    let near = (0..3)
        .filter(|&k| {
            let p = ray.origin[k] as f64 + t as f64 * ray.dir[k] as f64;
            (p - p.round()).abs() <= EDGE_TOL
        })
        .count();
    near >= 2
}

fn ambiguous(ray: &Ray, t_max: f32, hit: &Option<Hit>) -> bool {
    match hit {
        None => false,
        Some(h) => {
            near_edge(ray, h.t) || (h.t as f64 - t_max as f64).abs() <= 1e-4 * (1.0 + t_max as f64)
        }
    }
}

/// Compares the DAG ray cast with the reference; returns whether they differ (allowed only
/// when ambiguous, asserted here).
fn check_ray(dag: &Svdag, index: &VoxelIndex, voxels: &Voxels, ray: &Ray, t_max: f32) -> bool {
    let got = dag.raycast(index, ray, t_max);
    let want = raycast_reference(voxels, ray, t_max);
    let same = match (&got, &want) {
        (None, None) => true,
        (Some(a), Some(b)) => {
            a.voxel == b.voxel
                && a.normal == b.normal
                && a.color_index == b.color_index
                && (a.t as f64 - b.t as f64).abs() <= 1e-4 * (1.0 + b.t.abs() as f64)
        }
        _ => false,
    };
    if !same {
        assert!(
            ambiguous(ray, t_max, &got) || ambiguous(ray, t_max, &want),
            "ray {ray:?} t_max {t_max}: dag {got:?} vs reference {want:?}"
        );
    }
    !same
}

fn arb_scene() -> impl Strategy<Value = Voxels> {
    (
        prop_oneof![Just(8u32), Just(16), Just(32)],
        0.0f64..0.4,
        any::<u64>(),
    )
        .prop_map(|(n, density, seed)| {
            // Small xorshift so that dense scenes stay cheap to generate.
            let mut s = seed | 1;
            let mut coords = Vec::new();
            for z in 0..n {
                for y in 0..n {
                    for x in 0..n {
                        s ^= s << 13;
                        s ^= s >> 7;
                        s ^= s << 17;
                        if ((s >> 11) as f64 / (1u64 << 53) as f64) < density {
                            coords.push([x, y, z]);
                        }
                    }
                }
            }
            voxels_from(n, coords, true)
        })
}

fn arb_ray() -> impl Strategy<Value = ([f32; 3], [f32; 3], u8, f32)> {
    (
        prop::array::uniform3(-0.5f32..1.5),
        prop::array::uniform3(-1.0f32..1.0),
        any::<u8>(),
        0.0f32..2.0,
    )
}

fn make_ray(n: u32, origin: [f32; 3], dir: [f32; 3], zero_mask: u8) -> Ray {
    let n = n as f32;
    let mut d = dir;
    for (k, v) in d.iter_mut().enumerate() {
        // About one component in eight is exactly zero (parallel rays).
        if (zero_mask >> (2 * k)) & 3 == 0 && (zero_mask >> 6) & 1 == 0 {
            *v = 0.0;
        }
    }
    if d == [0.0; 3] {
        d = [0.3, -1.0, 0.2];
    }
    Ray {
        origin: origin.map(|o| o * n),
        dir: d,
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    #[test]
    fn raycast_matches_dda(scene in arb_scene(), rays in prop::collection::vec(arb_ray(), 200)) {
        let dag = Svdag::from_voxels(&scene).unwrap();
        let index = VoxelIndex::new(&dag);
        let mut differ = 0;
        for (i, &(origin, dir, zero_mask, t_rel)) in rays.iter().enumerate() {
            let ray = make_ray(scene.resolution, origin, dir, zero_mask);
            let t_max = if i % 4 == 0 { t_rel * scene.resolution as f32 } else { T_UNBOUNDED };
            differ += check_ray(&dag, &index, &scene, &ray, t_max) as usize;
        }
        prop_assert!(differ <= 2, "{differ} ambiguous differences in 200 rays");
    }
}

#[test]
fn axis_aligned_rays_along_edges_are_exact() {
    // Rays exactly on integer lines and planes: the half-open cell convention decides.
    let n = 16;
    let mut coords = Vec::new();
    for i in 0..n {
        coords.push([i, (i * 7) % n, (i * 5) % n]);
        coords.push([(i * 3) % n, i, (i * 11) % n]);
        coords.push([(i * 13) % n, (i * 9) % n, i]);
    }
    let scene = voxels_from(n, coords, true);
    let dag = Svdag::from_voxels(&scene).unwrap();
    let index = VoxelIndex::new(&dag);
    let mut hits = 0;
    for a in 0..=n {
        for b in 0..=n {
            for axis in 0..3 {
                for sign in [-1.0f32, 1.0] {
                    let mut origin = [a as f32, b as f32, a as f32];
                    origin[(axis + 1) % 3] = b as f32;
                    origin[(axis + 2) % 3] = a as f32;
                    origin[axis] = if sign > 0.0 { -2.5 } else { n as f32 + 2.5 };
                    let mut dir = [0.0; 3];
                    dir[axis] = sign;
                    let ray = Ray { origin, dir };
                    let got = dag.raycast(&index, &ray, T_UNBOUNDED);
                    let want = raycast_reference(&scene, &ray, T_UNBOUNDED);
                    assert_eq!(got, want, "ray {ray:?}");
                    hits += got.is_some() as usize;
                }
            }
        }
    }
    assert!(hits > 100, "only {hits} hits");
}

#[test]
fn rays_starting_inside_voxels_hit_at_zero() {
    let scene = voxels_from(8, vec![[3, 4, 5], [0, 0, 0], [7, 7, 7]], true);
    let dag = Svdag::from_voxels(&scene).unwrap();
    let index = VoxelIndex::new(&dag);
    let ray = Ray {
        origin: [3.5, 4.25, 5.75],
        dir: [0.2, -0.9, 0.1],
    };
    let hit = dag.raycast(&index, &ray, T_UNBOUNDED).expect("hit");
    assert_eq!(hit.t, 0.0);
    assert_eq!(hit.voxel, [3, 4, 5]);
    assert_eq!(hit.normal, [0, 1, 0]);
    assert_eq!(hit.color_index, 1);
    assert_eq!(raycast_reference(&scene, &ray, T_UNBOUNDED), Some(hit));
    // Misses: away from the grid, too short, behind the origin.
    let away = Ray {
        origin: [-1.0, -1.0, -1.0],
        dir: [-1.0, 0.5, 0.5],
    };
    assert_eq!(dag.raycast(&index, &away, T_UNBOUNDED), None);
    let toward = Ray {
        origin: [-1.5, 0.5, 0.5],
        dir: [1.0, 0.0, 0.0],
    };
    let hit = dag.raycast(&index, &toward, T_UNBOUNDED).expect("hit");
    assert_eq!((hit.t, hit.voxel, hit.normal), (1.5, [0, 0, 0], [-1, 0, 0]));
    assert_eq!(dag.raycast(&index, &toward, 1.5), None);
    // Empty scene.
    let empty = Svdag::from_voxels(&voxels_from(8, vec![], false)).unwrap();
    let empty_index = VoxelIndex::new(&empty);
    assert_eq!(empty.raycast(&empty_index, &toward, T_UNBOUNDED), None);
}

#[test]
fn default_camera_frames_the_grid() {
    for resolution in [8u32, 64, 4096, 65536] {
        let cam = Camera::orbit_default(resolution);
        for (w, h) in [(64u32, 64u32), (160, 90), (1920, 1080)] {
            for corner in 0..8u32 {
                let p = [0, 1, 2].map(|k| ((corner >> k) & 1) as f32 * resolution as f32);
                let px = cam.project(p, w, h).expect("corner in front of the camera");
                assert!(
                    px[0] > 0.0 && px[0] < w as f32 && px[1] > 0.0 && px[1] < h as f32,
                    "corner {p:?} projects to {px:?} outside {w}x{h}"
                );
            }
            // The centre of the image looks at the target, and rays come from the eye.
            let centre = cam.project(cam.target, w, h).expect("target visible");
            assert!((centre[0] - w as f32 / 2.0).abs() < 1e-2 * w as f32);
            assert!((centre[1] - h as f32 / 2.0).abs() < 1e-2 * h as f32);
        }
    }
}

#[test]
fn camera_and_params_build_identical_rays() {
    let scene = voxels_from(32, vec![[1, 2, 3]], false);
    let dag = Svdag::from_voxels(&scene).unwrap();
    let mut cam = Camera::orbit_default(32);
    cam.eye[1] += 3.0;
    let settings = RenderSettings::new(37, 23, cam);
    let params = RenderParams::new(&settings, &dag).expect("params");
    for y in 0..23 {
        for x in 0..37 {
            assert_eq!(cam.primary_ray([x, y], 37, 23), params.primary_ray([x, y]));
        }
    }
    // A pixel's ray passes through the point that projects to the pixel centre.
    let ray = params.primary_ray([5, 17]);
    let p = [0, 1, 2].map(|k| ray.origin[k] + 10.0 * ray.dir[k]);
    let px = cam.project(p, 37, 23).expect("in front");
    assert!(
        (px[0] - 5.5).abs() < 1e-3 && (px[1] - 17.5).abs() < 1e-3,
        "{px:?}"
    );
}

/// A floor slab (y < 2) with a 4^3 block standing on it, in a 16^3 grid.
fn floor_and_block(colored: bool) -> Voxels {
    let mut coords = Vec::new();
    for z in 0..16 {
        for x in 0..16 {
            for y in 0..2 {
                coords.push([x, y, z]);
            }
        }
    }
    for z in 6..10 {
        for y in 2..6 {
            for x in 6..10 {
                coords.push([x, y, z]);
            }
        }
    }
    voxels_from(16, coords, colored)
}

#[test]
fn cpu_render_matches_reference_rays() {
    for colored in [false, true] {
        let scene = floor_and_block(colored);
        let dag = Svdag::from_voxels(&scene).unwrap();
        let index = VoxelIndex::new(&dag);
        let mut settings = RenderSettings::new(96, 64, Camera::orbit_default(16));
        // Light from behind the block so that its shadow falls towards the camera.
        settings.light_dir = [-0.5, 0.7, -0.3];
        let out = render_cpu(&dag, &index, &settings).expect("render");
        assert_eq!(out.rgba.len(), 96 * 64 * 4);
        let params = RenderParams::new(&settings, &dag).expect("params");
        let light = [
            params.light_dir[0],
            params.light_dir[1],
            params.light_dir[2],
        ];
        let eps = params.up[3];
        let (mut differ, mut shadowed, mut lit_top, mut off_colour, mut hit_pixels) =
            (0, 0, 0, 0, 0);
        for y in 0..64u32 {
            for x in 0..96u32 {
                let i = (y * 96 + x) as usize;
                let ray = params.primary_ray([x, y]);
                let want = raycast_reference(&scene, &ray, T_UNBOUNDED);
                if (out.hits[i] == 1) != want.is_some() {
                    differ += 1;
                    continue;
                }
                let px = &out.rgba[4 * i..4 * i + 4];
                assert_eq!(px[3], 255);
                let Some(h) = want else { continue };
                // Expected colour from the reference hit, with the shadow decided by the
                // reference too.
                let albedo = if colored {
                    let c = scene.colors[h.color_index as usize];
                    [0, 8, 16].map(|s| srgb_to_linear(((c >> s) & 0xff) as f32 / 255.0))
                } else {
                    [GREY; 3]
                };
                let n = h.normal.map(|v| v as f32);
                let n_dot_l = (n[0] * light[0] + n[1] * light[1] + n[2] * light[2]).max(0.0);
                let p = [0, 1, 2].map(|k| ray.origin[k] + h.t * ray.dir[k] + n[k] * eps);
                let blocked = n_dot_l > 0.0
                    && raycast_reference(
                        &scene,
                        &Ray {
                            origin: p,
                            dir: light,
                        },
                        T_UNBOUNDED,
                    )
                    .is_some();
                let axis_factor = match h.normal {
                    [_, 0, 0] if h.normal[0] != 0 => 0.85,
                    [0, _, 0] if h.normal[1] != 0 => 1.0,
                    _ => 0.7,
                };
                let direct = if blocked { 0.0 } else { DIFFUSE * n_dot_l };
                shadowed += (blocked && h.normal == [0, 1, 0]) as usize;
                lit_top += (!blocked && h.normal == [0, 1, 0]) as usize;
                hit_pixels += 1;
                let close = (0..3).all(|k| {
                    let want =
                        quantize(linear_to_srgb(albedo[k] * (AMBIENT * axis_factor + direct)));
                    (px[k] as i32 - want as i32).abs() <= 1
                });
                off_colour += !close as usize;
            }
        }
        // Tolerances: hit masks differ on at most 0.1% of the pixels (exact edges), colours
        // within 1/255 except on at most 1% of the hit pixels (shadow rays grazing an edge).
        assert!(differ <= 96 * 64 / 1000, "{differ} hit-mask differences");
        assert!(
            off_colour * 100 <= hit_pixels,
            "{off_colour} of {hit_pixels} colours differ"
        );
        assert!(
            shadowed > 20 && lit_top > 200,
            "shadowed {shadowed}, lit {lit_top}"
        );
        // The grid is in the middle of the frame, sky in the corners.
        assert_eq!(out.hits[0], 0);
        assert_eq!(out.hits[96 * 64 - 1], 0);
        let top = settings
            .camera
            .project([8.0, 6.0, 8.0], 96, 64)
            .expect("visible");
        assert_eq!(out.hits[top[1] as usize * 96 + top[0] as usize], 1);
    }
}

#[test]
fn save_png_round_trip() {
    let scene = floor_and_block(true);
    let dag = Svdag::from_voxels(&scene).unwrap();
    let index = VoxelIndex::new(&dag);
    let settings = RenderSettings::new(40, 30, Camera::orbit_default(16));
    let out: RenderOutput = render_cpu(&dag, &index, &settings).expect("render");
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("frame.png");
    out.save_png(&path).expect("save");
    let back = image::open(&path).expect("open").to_rgba8();
    assert_eq!(back.dimensions(), (40, 30));
    assert_eq!(back.into_raw(), out.rgba);
    assert_eq!(std::fs::read_dir(dir.path()).expect("dir").count(), 1);
}

#[test]
fn params_reject_bad_input() {
    let dag = Svdag::from_voxels(&voxels_from(8, vec![[1, 1, 1]], false)).unwrap();
    let index = VoxelIndex::new(&dag);
    let settings = RenderSettings::new(0, 10, Camera::orbit_default(8));
    assert!(render_cpu(&dag, &index, &settings).is_err());
    let mut settings = RenderSettings::new(10, 10, Camera::orbit_default(8));
    settings.light_dir = [0.0; 3];
    assert!(RenderParams::new(&settings, &dag).is_err());
    let other = VoxelIndex::new(&Svdag::from_voxels(&floor_and_block(false)).unwrap());
    settings.light_dir = [0.0, 1.0, 0.0];
    assert!(render_cpu(&dag, &other, &settings).is_err());
}

/// The GLSL twins compile (glslc, as build.rs runs it) inside a minimal includer that defines
/// the four buffer accessors the contract requires.
#[test]
fn glsl_includes_compile() {
    let includer = r#"#version 460
#extension GL_GOOGLE_include_directive : require
layout(local_size_x = 8, local_size_y = 8) in;
layout(std430, binding = 0) readonly buffer Words { uint words[]; };
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
layout(std430, binding = 1) readonly buffer Counts { uint64_t counts[]; };
layout(std430, binding = 2) readonly buffer Colors { uint colors[]; };
uint dag_word(uint i) { return words[i]; }
uint64_t dag_node_voxels(uint i) { return counts[i]; }
uint dag_color(uint64_t i) { return colors[uint(i)]; }
layout(std430, binding = 6) readonly buffer Info { uint info[]; };
uint dag_info(uint i) { return info[i]; }
#include "render/shade.glsl"
layout(std430, binding = 3) readonly buffer Params { RenderParams params; };
layout(std430, binding = 4) writeonly buffer Rgba { uint out_rgba[]; };
layout(std430, binding = 5) writeonly buffer Hits { uint out_hits[]; };
void main() {
    uvec2 px = gl_GlobalInvocationID.xy;
    if (px.x >= params.width || px.y >= params.height) return;
    bool hit;
    Hit h;
    vec4 c = shade_pixel_hit(px, params, true, true, hit, h);
    out_rgba[px.y * params.width + px.x] = packUnorm4x8(c);
    out_hits[px.y * params.width + px.x] = hit ? 1u : 0u;
}
"#;
    let dir = tempfile::tempdir().expect("tempdir");
    let src = dir.path().join("includer.comp");
    std::fs::write(&src, includer).expect("write");
    let include = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders/glsl");
    let out = std::process::Command::new("glslc")
        .args(["--target-env=vulkan1.2", "-O", "-Werror", "-I"])
        .arg(&include)
        // The generated shared-layout headers (build.rs writes them to OUT_DIR/glsl/gen).
        .arg("-I")
        .arg(concat!(env!("OUT_DIR"), "/glsl"))
        .arg(&src)
        .arg("-o")
        .arg(dir.path().join("includer.spv"))
        .output()
        .expect("glslc must be installed (apt-get install glslc)");
    assert!(
        out.status.success(),
        "glslc failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let spv = std::fs::read(dir.path().join("includer.spv")).expect("spv");
    assert_eq!(&spv[..4], &0x0723_0203u32.to_le_bytes());
}
