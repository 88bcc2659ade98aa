//! The renderer and the path tracers traverse the live GPU hash DAG in place
//! (`GpuRenderer::bind_hash_dag`, `render/dag_hash.glsl`): for every table variant, after load,
//! sphere / cube add / remove edits and undo, the first hits (hit, voxel, normal, `t` bits) and
//! the image equal svdag32's of the same voxels; the path tracers' accumulations equal svdag32's
//! bit for bit; a scene with materials shows its palette colours. On any Vulkan device
//! (lavapipe in CI), validation on.

mod common;

use std::collections::HashMap;
use std::sync::Arc;

use common::{build_scene, gpu, repo};
use voxdag::dag::Svdag;
use voxdag::edit::cpu::HashDag;
use voxdag::edit::gpu::{EditTool, GpuHashDag, GpuHashDagConfig, ToolShape};
use voxdag::edit::item::{InnerNode, NodePtr, Root};
use voxdag::edit::tool::{Shape, Tool};
use voxdag::gpu::GpuContext;
use voxdag::hash::HashVariant;
use voxdag::render::gpu::{GpuRenderer, GpuScene, Palette};
use voxdag::render::hash_scene::HashDagScene;
use voxdag::render::pathtrace::{PtImage, PtSettings, Sun};
use voxdag::render::pathtrace_gpu::{GpuPathTracer, PtMode};
use voxdag::render::{Camera, FirstHit, RenderSettings, TraversalFormat};
use voxdag::scene::{morton, Voxels};

/// Cameras: the default framing, a close one looking down, an axis-aligned one from inside.
fn cameras(n: u32) -> Vec<RenderSettings> {
    let n_f = n as f32;
    let frame = Camera::orbit_default(n);
    let mut close = frame;
    close.eye = [0.9 * n_f, 0.8 * n_f, 0.15 * n_f];
    close.target = [0.4 * n_f, 0.1 * n_f, 0.6 * n_f];
    let mut inside = frame;
    inside.eye = [0.5 * n_f + 0.25, 0.5 * n_f, 0.5 * n_f];
    inside.target = [0.5 * n_f + 0.25, 0.5 * n_f, -n_f];
    [frame, close, inside]
        .into_iter()
        .map(|c| RenderSettings::new(64, 48, c))
        .collect()
}

/// The traversal fields of a first hit (the colour index is a Morton rank in svdag32 and the
/// material in the hash DAG).
fn geometry(h: &FirstHit) -> (u32, u32, [u32; 3], [i32; 3]) {
    (h.hit, h.t_bits, h.voxel, h.normal)
}

/// Renders `reference` (svdag32) and `scene` (hash DAG) from every camera; asserts equal first
/// hits and images, and that the hash DAG's colour index is 0 (geometry only). Returns the
/// number of pixels that hit.
fn assert_same(
    what: &str,
    renderer: &GpuRenderer,
    reference: &Svdag,
    scene: &GpuScene,
    n: u32,
) -> usize {
    let svdag = renderer.upload(reference).unwrap();
    let mut hits = 0;
    for (k, settings) in cameras(n).iter().enumerate() {
        let (ref_image, ref_hits) = renderer.render_first_hits(&svdag, settings).unwrap();
        let (image, got) = renderer.render_first_hits(scene, settings).unwrap();
        let bad: Vec<usize> = (0..got.len())
            .filter(|&i| geometry(&got[i]) != geometry(&ref_hits[i]) || got[i].color_index != 0)
            .collect();
        assert!(
            bad.is_empty(),
            "{what} camera {k}: {} of {} first hits differ from svdag32; pixel {}: got {:?} \
             expected {:?}",
            bad.len(),
            got.len(),
            bad[0],
            got[bad[0]],
            ref_hits[bad[0]]
        );
        assert!(
            image.rgba == ref_image.rgba && image.hits == ref_image.hits,
            "{what} camera {k}: the image differs from svdag32's"
        );
        hits += got.iter().filter(|h| h.hit == 1).count();
    }
    hits
}

fn geometry_only(mut dag: Svdag) -> Svdag {
    dag.colors.clear();
    dag
}

/// The edits of the test: large solid additions (full nodes at several levels), removals
/// that cut through them, cubes and spheres.
fn edits(n: f32) -> Vec<EditTool> {
    let tool = |shape, c: [f32; 3], r: f32, remove| EditTool {
        shape,
        center: c.map(|v| v * n),
        radius: r * n,
        remove,
    };
    vec![
        tool(ToolShape::Sphere, [0.4, 0.45, 0.5], 0.3, false),
        tool(ToolShape::Cube, [0.7, 0.3, 0.35], 0.2, false),
        tool(ToolShape::Sphere, [0.55, 0.5, 0.4], 0.17, true),
        tool(ToolShape::Cube, [0.3, 0.6, 0.6], 0.09, true),
        tool(ToolShape::Sphere, [0.2, 0.2, 0.8], 0.13, false),
    ]
}

fn check_variant(ctx: &Arc<GpuContext>, renderer: &GpuRenderer, variant: HashVariant) {
    let file = geometry_only(build_scene(&repo().join("tests/data/teapot.obj"), Some(64)));
    let n = file.resolution;
    let mut loaded = HashDagScene::load(ctx, renderer, &file, variant, None).unwrap();
    assert_eq!(loaded.scene.format(), TraversalFormat::HashDag);
    let name = format!("{variant:?}");
    // After load: the original file, and the tables converted back.
    let hits = assert_same(&format!("{name} load"), renderer, &file, &loaded.scene, n);
    assert!(hits > 500, "{name}: only {hits} pixels hit the teapot");
    let image = loaded.dag.download().unwrap();
    let back = image.to_svdag(loaded.dag.root()).unwrap();
    assert_same(&format!("{name} load"), renderer, &back, &loaded.scene, n);
    // Edits: the binding made before them stays valid; only the root is switched.
    let mut history = vec![back];
    let mut full_nodes = false;
    for (i, tool) in edits(n as f32).iter().enumerate() {
        loaded.dag.edit(tool, None).unwrap();
        let root = loaded.dag.root();
        loaded.scene.set_hash_root(&loaded.dag, root).unwrap();
        let image = loaded.dag.download().unwrap();
        full_nodes |= has_full_child(&image, root);
        let expected = image.to_svdag(root).unwrap();
        assert_same(
            &format!("{name} edit {i}"),
            renderer,
            &expected,
            &loaded.scene,
            n,
        );
        history.push(expected);
    }
    assert!(
        full_nodes,
        "{name}: the edits made no full child: the test would not cover full cubes"
    );
    for step in 1..=2 {
        assert!(loaded.dag.undo());
        let root = loaded.dag.root();
        loaded.scene.set_hash_root(&loaded.dag, root).unwrap();
        let expected = &history[history.len() - 1 - step];
        assert_same(
            &format!("{name} undo {step}"),
            renderer,
            expected,
            &loaded.scene,
            n,
        );
    }
}

/// Whether any inner node under `root` has a full child.
fn has_full_child(image: &voxdag::edit::gpu::HashDagImage, root: Root) -> bool {
    let Root::Node(p) = root else {
        return matches!(root, Root::Full(_));
    };
    let mut stack = vec![(p, image.root_level)];
    while let Some((ptr, level)) = stack.pop() {
        if level == 0 {
            continue;
        }
        let node = InnerNode::decode(&image.item(ptr).unwrap()).unwrap();
        for c in node.children {
            match c {
                voxdag::edit::item::Child::Full(_) => return true,
                voxdag::edit::item::Child::Node(q) => stack.push((q, level - 1)),
                voxdag::edit::item::Child::Empty => {}
            }
        }
    }
    false
}

#[test]
fn first_hits_match_svdag32_after_load_edits_and_undo_every_variant() {
    let ctx = gpu();
    let renderer = GpuRenderer::new(&ctx).unwrap();
    for variant in HashVariant::ALL {
        check_variant(&ctx, &renderer, variant);
    }
    drop(renderer);
    assert_eq!(ctx.validation_errors(), 0, "Vulkan validation errors");
}

/// Uniform roots: an empty scene and a completely full one (`Root::Full`).
#[test]
fn empty_and_full_roots_match_svdag32() {
    let ctx = gpu();
    let renderer = GpuRenderer::new(&ctx).unwrap();
    let full = Svdag::from_voxels(&Voxels::from_coords(16, (0..4096).map(morton::decode))).unwrap();
    let empty = Svdag::from_voxels(&Voxels::from_coords(16, [])).unwrap();
    for (dag, root_full) in [(full, true), (empty, false)] {
        let loaded =
            HashDagScene::load(&ctx, &renderer, &dag, HashVariant::TicketBoard, None).unwrap();
        let expected_root = if root_full {
            Root::Full(0)
        } else {
            Root::Empty
        };
        assert_eq!(loaded.dag.root(), expected_root);
        let hits = assert_same("uniform", &renderer, &dag, &loaded.scene, 16);
        assert_eq!(hits > 0, root_full);
    }
    drop(renderer);
    assert_eq!(ctx.validation_errors(), 0, "Vulkan validation errors");
}

/// A solid ball with a bite taken out, on a floor: full nodes and concave paths.
fn ball_scene(n: u32) -> Svdag {
    let c = n as f32 / 2.0;
    let coords = (0..(n as u64).pow(3))
        .map(morton::decode)
        .filter(|&[x, y, z]| {
            let d2 = |cx: f32, cy: f32, cz: f32| {
                (x as f32 + 0.5 - cx).powi(2)
                    + (y as f32 + 0.5 - cy).powi(2)
                    + (z as f32 + 0.5 - cz).powi(2)
            };
            let ball = d2(c, c, c) < (0.35 * n as f32).powi(2);
            let bite = d2(0.75 * n as f32, 0.7 * n as f32, c) < (0.25 * n as f32).powi(2);
            (ball && !bite) || y < n / 8
        });
    Svdag::from_voxels(&Voxels::from_coords(n, coords.collect::<Vec<_>>())).unwrap()
}

fn pt_settings(n: u32) -> PtSettings {
    let mut s = PtSettings::new(RenderSettings::new(40, 40, Camera::orbit_default(n)));
    s.spp = 2;
    s.seed = 5;
    s.bounces = 4;
    s.sun = Some(Sun {
        dir: [0.4, 1.0, 0.3],
        intensity: 2.0,
    });
    s
}

fn accum_bits(img: &PtImage) -> Vec<[u32; 4]> {
    img.accum.iter().map(|a| a.map(f32::to_bits)).collect()
}

/// Megakernel and wavefront over the hash DAG (after an edit) give svdag32's accumulation of
/// the same voxels bit for bit, for every table variant.
#[test]
fn path_tracers_match_svdag32_every_variant() {
    let dag = ball_scene(32);
    let ctx = gpu();
    let renderer = GpuRenderer::new(&ctx).unwrap();
    let tracer = GpuPathTracer::new(&ctx).unwrap();
    let s = pt_settings(32);
    for variant in HashVariant::ALL {
        let mut loaded = HashDagScene::load(&ctx, &renderer, &dag, variant, None).unwrap();
        loaded
            .dag
            .edit(
                &EditTool {
                    shape: ToolShape::Cube,
                    center: [10.0, 20.0, 12.0],
                    radius: 5.0,
                    remove: false,
                },
                None,
            )
            .unwrap();
        let root = loaded.dag.root();
        loaded.scene.set_hash_root(&loaded.dag, root).unwrap();
        let edited = loaded.dag.download().unwrap().to_svdag(root).unwrap();
        let svdag = renderer.upload(&edited).unwrap();
        let reference = tracer.render(&svdag, &s, PtMode::Megakernel, None).unwrap();
        let hits = reference.first_hits.iter().filter(|h| h.hit != 0).count();
        assert!(
            hits > 40 * 40 / 8,
            "the scene should fill the view ({hits})"
        );
        for mode in [PtMode::Megakernel, PtMode::Wavefront] {
            let image = tracer.render(&loaded.scene, &s, mode, None).unwrap();
            let bad = image
                .first_hits
                .iter()
                .zip(&reference.first_hits)
                .filter(|(a, b)| geometry(a) != geometry(b))
                .count();
            assert_eq!(
                bad, 0,
                "{variant:?} {mode:?}: first hits differ from svdag32"
            );
            assert!(
                accum_bits(&image) == accum_bits(&reference),
                "{variant:?} {mode:?}: accumulation differs from svdag32"
            );
        }
    }
    drop(tracer);
    drop(renderer);
    assert_eq!(ctx.validation_errors(), 0, "Vulkan validation errors");
}

/// Copies the items reachable from `root` of a CPU hash DAG into the GPU tables (child
/// pointers rewritten bottom-up) and returns the GPU root.
fn copy_to_gpu(cpu: &HashDag, root: Root, gpu_dag: &mut GpuHashDag) -> Root {
    let Root::Node(p) = root else {
        return root;
    };
    let levels = cpu.root_level() as usize + 1;
    // Reachable (cpu pointer) per level, children before parents.
    let mut per_level: Vec<Vec<NodePtr>> = vec![Vec::new(); levels];
    let mut seen = std::collections::HashSet::new();
    let mut stack = vec![(p, cpu.root_level())];
    while let Some((ptr, level)) = stack.pop() {
        if !seen.insert((ptr, level)) {
            continue;
        }
        per_level[level as usize].push(ptr);
        if level > 0 {
            for c in cpu.node(ptr).unwrap().children {
                if let voxdag::edit::item::Child::Node(q) = c {
                    stack.push((q, level - 1));
                }
            }
        }
    }
    let mut map: HashMap<(NodePtr, usize), NodePtr> = HashMap::new();
    for (level, ptrs) in per_level.iter().enumerate() {
        let mut by_size: HashMap<u32, (Vec<NodePtr>, Vec<u32>)> = HashMap::new();
        for &ptr in ptrs {
            let mut words = cpu.item(ptr).to_vec();
            if level > 0 {
                let header = words[0];
                let mut at = 1;
                for o in 0..8 {
                    if header >> o & 1 == 0 {
                        continue;
                    }
                    if header >> (8 + o) & 1 == 0 {
                        words[at] = map[&(NodePtr(words[at]), level - 1)].0;
                    }
                    at += 1;
                }
            }
            let entry = by_size.entry(words.len() as u32).or_default();
            entry.0.push(ptr);
            entry.1.extend(words);
        }
        for (words, (ptrs, items)) in by_size {
            let table = gpu_dag.table_mut(words).unwrap();
            let (handles, _) = table.find_or_insert(&items, None).unwrap();
            for (ptr, h) in ptrs.iter().zip(handles) {
                map.insert((*ptr, level), NodePtr::new(words, h.0));
            }
        }
    }
    Root::Node(map[&(p, levels - 1)])
}

/// A scene with materials (imported with per-voxel materials, then added to with other
/// materials, cut and painted on the CPU editor, copied into a `GpuHashDag` with materials)
/// shows `palette[material]`: the same image as svdag32 with each voxel coloured by its
/// material, and every hit's colour index is that voxel's material; the megakernel agrees bit
/// for bit too.
#[test]
fn materials_show_palette_colours() {
    let ctx = gpu();
    let renderer = GpuRenderer::new(&ctx).unwrap();
    let tracer = GpuPathTracer::new(&ctx).unwrap();
    let file = geometry_only(build_scene(&repo().join("tests/data/teapot.obj"), Some(64)));
    let n = file.resolution;
    let mut cpu = HashDag::new(n, true).unwrap();
    let voxels = file.to_voxels();
    let materials: Vec<u8> = voxels
        .codes
        .iter()
        .map(|&c| {
            let [x, y, z] = morton::decode(c);
            ((x / 8 + y / 4 + z / 16) % 16) as u8
        })
        .collect();
    let mut root = cpu.insert_svdag(&file, Some(&materials)).unwrap();
    let tools = [
        Tool::Add {
            shape: Shape::Sphere,
            center: [26.0, 30.0, 32.0],
            radius: 17.0,
            material: 3,
        },
        Tool::Add {
            shape: Shape::Cube,
            center: [44.0, 20.0, 22.0],
            radius: 11.0,
            material: 12,
        },
        Tool::Remove {
            shape: Shape::Sphere,
            center: [34.0, 32.0, 26.0],
            radius: 9.0,
        },
        Tool::Paint {
            center: [30.0, 40.0, 36.0],
            radius: 10.0,
            material: 7,
        },
    ];
    for tool in &tools {
        root = cpu.edit(root, tool).unwrap();
    }
    let config = GpuHashDagConfig::new(HashVariant::AccelHash32, 1024);
    let mut gpu_dag = GpuHashDag::new(&ctx, &config, cpu.root_level(), true).unwrap();
    let gpu_root = copy_to_gpu(&cpu, root, &mut gpu_dag);
    let palette: Palette = std::array::from_fn(|m| {
        let m = m as u32;
        [
            (m * 53 % 256) as u8,
            (m * 97 % 256) as u8,
            (255 - m * 13) as u8,
        ]
    });
    let mut scene = renderer.bind_hash_dag(&gpu_dag, Some(&palette)).unwrap();
    scene.set_hash_root(&gpu_dag, gpu_root).unwrap();
    // The CPU computation: every voxel coloured by its material, as svdag32 colours.
    let image = gpu_dag.download().unwrap();
    let expected_voxels = image.voxels(gpu_root).unwrap();
    assert_eq!(
        expected_voxels,
        cpu.voxels(root).unwrap(),
        "the copy to the GPU tables changed the voxels"
    );
    let distinct: std::collections::HashSet<u8> = expected_voxels.iter().map(|v| v.1).collect();
    assert!(distinct.len() >= 8, "too few materials: {distinct:?}");
    let material_of: HashMap<u64, u8> = expected_voxels.iter().copied().collect();
    let colored = Svdag::from_voxels(&Voxels {
        resolution: n,
        codes: expected_voxels.iter().map(|v| v.0).collect(),
        colors: expected_voxels
            .iter()
            .map(|v| {
                let [r, g, b] = palette[v.1 as usize];
                r as u32 | (g as u32) << 8 | (b as u32) << 16 | 0xff00_0000
            })
            .collect(),
    })
    .unwrap();
    let svdag = renderer.upload(&colored).unwrap();
    for (k, settings) in cameras(n).iter().enumerate() {
        let (ref_image, ref_hits) = renderer.render_first_hits(&svdag, settings).unwrap();
        let (got_image, got) = renderer.render_first_hits(&scene, settings).unwrap();
        for (i, (a, b)) in got.iter().zip(&ref_hits).enumerate() {
            assert_eq!(geometry(a), geometry(b), "camera {k} pixel {i}: first hit");
            if a.hit == 1 {
                let code = morton::encode(a.voxel[0], a.voxel[1], a.voxel[2]);
                assert_eq!(
                    a.color_index, material_of[&code] as u64,
                    "camera {k} pixel {i}: colour index is not the voxel's material"
                );
            }
        }
        assert!(
            got_image.rgba == ref_image.rgba,
            "camera {k}: the palette image differs from svdag32 coloured by material"
        );
    }
    let s = pt_settings(n);
    let reference = tracer.render(&svdag, &s, PtMode::Megakernel, None).unwrap();
    let got = tracer.render(&scene, &s, PtMode::Megakernel, None).unwrap();
    assert!(
        accum_bits(&got) == accum_bits(&reference),
        "megakernel: palette accumulation differs from svdag32's"
    );
    // A palette needs materials.
    let plain = HashDagScene::load(&ctx, &renderer, &file, HashVariant::Atomic64, None).unwrap();
    assert!(renderer.bind_hash_dag(&plain.dag, Some(&palette)).is_err());
    // A root from another DAG's tables is refused.
    assert!(scene.set_hash_root(&plain.dag, plain.dag.root()).is_err());
    drop(plain);
    drop(scene);
    drop(tracer);
    drop(renderer);
    assert_eq!(ctx.validation_errors(), 0, "Vulkan validation errors");
}
