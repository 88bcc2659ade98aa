//! Materials (docs/materials.md): palette quantization, the `.vdag` material section through
//! every encoding and `verify`, renders in palette colours (golden, and CPU / GPU / path traced
//! renders equal to those of the same scene stored with colours `palette[id]`), the GPU hash
//! DAG's material load against the CPU `HashDag::insert_svdag` for every table variant, the
//! GPU save round trip, and `voxdag edit --cpu` keeping materials.

mod common;

use std::path::Path;
use std::sync::Arc;

use common::{assert_renders_match, check_golden, voxdag_cli};
use voxdag::attr::Materials;
use voxdag::dag::encode::{EncodedDag, SsvdagEncoding, VoxelDigest};
use voxdag::dag::{Svdag, VdagFile, VoxelIndex};
use voxdag::edit::cpu::{CpuEditor, HashDag};
use voxdag::edit::gpu::{GpuHashDag, GpuHashDagConfig};
use voxdag::edit::item::Root;
use voxdag::edit::replay::{Replay, Step};
use voxdag::gpu::GpuContext;
use voxdag::hash::HashVariant;
use voxdag::render::cpu::{render_cpu_with, ColorSource};
use voxdag::render::gpu::GpuRenderer;
use voxdag::render::{Camera, RenderSettings};
use voxdag::scene::{morton, Voxels};

fn avocado(resolution: u32) -> Svdag {
    common::build_scene(
        &common::repo().join("assets/avocado/Avocado.gltf"),
        Some(resolution),
    )
}

fn vox() -> Svdag {
    common::build_scene(&common::repo().join("tests/data/ff3.vox"), None)
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn cli_ok(args: &[&str]) -> String {
    let out = common::assert_cli_ok(args, voxdag_cli(args));
    String::from_utf8_lossy(&out.stdout).into()
}

#[test]
fn quantization_is_deterministic_bounded_and_keeps_few_colours() {
    // A .vox model with few colours keeps them exactly.
    let dag = vox();
    let m = Materials::quantize(&dag.colors, 16).unwrap();
    let opaque: Vec<u32> = dag.colors.iter().map(|c| c | 0xff00_0000).collect();
    assert_eq!(m.to_colors(), opaque, "ff3.vox colours kept exactly");
    let mut distinct = opaque.clone();
    distinct.sort_unstable();
    distinct.dedup();
    assert_eq!(m.palette, distinct);
    // Exactly 16 colours are kept, 17 are quantized to at most 16.
    let sixteen: Vec<u32> = (0..1000u32)
        .map(|i| 0xff00_0000 | ((i % 16) * 0x0f0b07))
        .collect();
    assert_eq!(
        Materials::quantize(&sixteen, 16).unwrap().to_colors(),
        sixteen
    );
    let seventeen: Vec<u32> = (0..1000u32)
        .map(|i| 0xff00_0000 | ((i % 17) * 0x0f0b07))
        .collect();
    let q = Materials::quantize(&seventeen, 16).unwrap();
    assert!(q.palette.len() <= 16 && q.palette.len() >= 15);
    // A textured scene: bounded, deterministic, and better with more entries.
    let dag = avocado(64);
    let error = |m: &Materials| voxdag::attr::rmse(&dag.colors, &m.to_colors());
    let mut last = f64::INFINITY;
    for k in [1, 2, 4, 8, 16] {
        let a = Materials::quantize(&dag.colors, k).unwrap();
        assert_eq!(a, Materials::quantize(&dag.colors, k).unwrap(), "k = {k}");
        assert!(
            a.palette.len() <= k as usize,
            "k = {k}: {}",
            a.palette.len()
        );
        assert_eq!(a.ids.len(), dag.colors.len());
        a.validate().unwrap();
        let e = error(&a);
        assert!(e < last, "k = {k}: RMSE {e} not below {last}");
        last = e;
    }
    assert!(last < 0.05, "16 materials: RMSE {last}");
    assert!(Materials::quantize(&dag.colors, 0).is_err());
    assert!(Materials::quantize(&dag.colors, 17).is_err());
}

/// A material file of `dag` in memory (svdag32).
fn material_file(dag: &Svdag, m: &Materials) -> VdagFile {
    let mut geometry = dag.clone();
    geometry.colors.clear();
    VdagFile {
        encoded: EncodedDag::Svdag32(geometry),
        colors: Vec::new(),
        digest: Some(VoxelDigest::of_codes(&dag.to_voxels().codes)),
        stored_colors: None,
        materials: Some(m.clone()),
    }
}

#[test]
fn material_files_round_trip_in_every_encoding_and_verify() {
    let dag = avocado(32);
    let m = Materials::quantize(&dag.colors, 6).unwrap();
    let file = material_file(&dag, &m);
    let bytes = file.to_bytes().unwrap();
    let back = VdagFile::from_bytes(&bytes, "m.vdag").unwrap();
    assert_eq!(back, file);
    // SSVDAG keeps the section alongside its payload (the voxel order is the same).
    let mut ss = file.clone();
    ss.encoded = EncodedDag::Ssvdag(SsvdagEncoding::build(&file_geometry(&file)).unwrap());
    let back = VdagFile::from_bytes(&ss.to_bytes().unwrap(), "s.vdag").unwrap();
    assert_eq!(back.materials.as_ref(), Some(&m));
    let decoded = back.into_svdag(Path::new("s.vdag")).unwrap();
    assert_eq!(decoded, file_geometry(&file));
    // Colours and materials together are refused by the writer.
    let mut both = file.clone();
    both.colors = m.to_colors();
    assert!(both.to_bytes().is_err());
    // The CLI: every encoding builds, verifies and keeps the palette.
    let dir = tempfile::tempdir().unwrap();
    let input = common::repo().join("assets/avocado/Avocado.gltf");
    for encoding in ["svdag32", "ssvdag", "tsvdag"] {
        let out = dir.path().join(format!("{encoding}.vdag"));
        cli_ok(&[
            "build",
            s(&input),
            "-r",
            "32",
            "--materials",
            "6",
            "--encoding",
            encoding,
            "-o",
            s(&out),
        ]);
        let stdout = cli_ok(&["verify", s(&out)]);
        assert!(
            stdout.contains("material ids of a 6-entry palette"),
            "{stdout}"
        );
        let loaded = VdagFile::load(&out).unwrap();
        assert_eq!(loaded.materials.as_ref(), Some(&m), "{encoding}");
        assert!(loaded.colors.is_empty() && loaded.stored_colors.is_none());
    }
    // Geometry-only and colour builds have no material section.
    let plain = dir.path().join("plain.vdag");
    cli_ok(&["build", s(&input), "-r", "32", "-o", s(&plain)]);
    let loaded = VdagFile::load(&plain).unwrap();
    assert!(loaded.materials.is_none() && loaded.stored_colors.is_some());
    // --materials replaces colours: asking for both is a usage error.
    let out = voxdag_cli(&[
        "build",
        s(&input),
        "--materials",
        "4",
        "--colors",
        "raw",
        "-o",
        s(&plain),
    ]);
    assert!(!out.status.success());
    let out = voxdag_cli(&["build", s(&input), "--materials", "17", "-o", s(&plain)]);
    assert!(!out.status.success());
}

fn file_geometry(file: &VdagFile) -> Svdag {
    match &file.encoded {
        EncodedDag::Svdag32(d) => d.clone(),
        _ => unreachable!("svdag32 file"),
    }
}

/// Renders of a material file equal those of the same scene stored with colours
/// `palette[id]`, for the CPU and GPU renderers, primary and path traced; and a golden.
#[test]
fn renders_show_palette_colours() {
    let dag = avocado(64);
    let m = Materials::quantize(&dag.colors, 8).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let materials = dir.path().join("m.vdag");
    material_file(&dag, &m).save(&materials).unwrap();
    let mut coloured = dag.clone();
    coloured.colors = m.to_colors();
    let colours = dir.path().join("c.vdag");
    coloured.save(&colours).unwrap();
    let modes: [&[&str]; 4] = [
        &[],
        &["--cpu"],
        &["--pt", "--spp", "2"],
        &["--cpu", "--pt", "--spp", "2"],
    ];
    for mode in modes {
        let render = |file: &Path, name: &str| {
            let out = dir.path().join(name);
            let mut args = vec!["render", s(file), "--size", "96x64", "--out", s(&out)];
            args.extend_from_slice(mode);
            cli_ok(&args);
            image::open(&out).unwrap().to_rgba8().into_raw()
        };
        let a = render(&materials, "m.png");
        let b = render(&colours, "c.png");
        assert_eq!(a, b, "render {mode:?}: material file vs palette colours");
        assert!(
            a.chunks(4).collect::<std::collections::HashSet<_>>().len() > 8,
            "{mode:?}: the scene is visible"
        );
    }
    // Golden of the GPU render, matched by the CPU reference.
    let colors = m.to_colors();
    let settings = RenderSettings::new(128, 128, Camera::frame(&dag));
    let context = common::gpu();
    let renderer = GpuRenderer::new(&context).unwrap();
    let scene = renderer
        .upload_with(&dag, ColorSource::Raw(&colors))
        .unwrap();
    let gpu_image = renderer.render(&scene, &settings, None).unwrap();
    drop(scene);
    drop(renderer);
    assert_eq!(context.validation_errors(), 0);
    let index = VoxelIndex::new(&dag);
    let cpu_image = render_cpu_with(&dag, &index, ColorSource::Raw(&colors), &settings).unwrap();
    assert_renders_match("materials avocado", &gpu_image, &cpu_image);
    check_golden("materials-avocado", &gpu_image, 8, 0.005);
}

/// Deterministic material scenes: noise with random materials, a solid slab of one material
/// (full leaves and nodes), a ball with materials by position (solid but mixed).
fn synthetic(resolution: u32, seed: u64) -> (Svdag, Materials) {
    let mut rng = common::Rng(seed);
    let n = resolution;
    let mut voxels = Vec::new();
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let m = if x < n / 4 && rng.below(3) == 0 {
                    Some(rng.below(5) as u8)
                } else if (n / 2..n / 2 + n / 4).contains(&x) && y < n / 2 + 3 {
                    Some(4)
                } else {
                    let d = |v: u32, c: f64| v as f64 - c * n as f64;
                    let r2 = d(x, 0.7).powi(2) + d(y, 0.6).powi(2) + d(z, 0.5).powi(2);
                    (r2 < (0.2 * n as f64).powi(2)).then_some(((x / 2 + y) % 3) as u8)
                };
                if let Some(m) = m {
                    voxels.push((morton::encode(x, y, z), m));
                }
            }
        }
    }
    voxels.sort_unstable();
    let v = Voxels {
        resolution,
        codes: voxels.iter().map(|p| p.0).collect(),
        colors: Vec::new(),
    };
    let ids = voxels.iter().map(|p| p.1).collect();
    let palette = vec![
        0xff00_00ff,
        0xff00_ff00,
        0xffff_0000,
        0xff80_8080,
        0xffff_ffff,
    ];
    (
        Svdag::from_voxels(&v).unwrap(),
        Materials::new(palette, ids).unwrap(),
    )
}

fn check_gpu_load(
    ctx: &Arc<GpuContext>,
    config: &GpuHashDagConfig,
    name: &str,
    dag: &Svdag,
    m: &Materials,
) {
    let variant = config.variant;
    let mut cpu = HashDag::new(dag.resolution, true).unwrap();
    let cpu_root = cpu.insert_svdag(dag, Some(&m.ids)).unwrap();
    let gpu = GpuHashDag::load_materials(ctx, config, dag, m, None).unwrap();
    assert!(gpu.with_materials());
    assert_eq!(gpu.palette(), Some(m.palette16()), "{name} {variant:?}");
    let image = gpu.download().unwrap();
    let voxels = image.voxels(gpu.root()).unwrap();
    assert_eq!(
        voxels,
        cpu.voxels(cpu_root).unwrap(),
        "{name} {variant:?}: voxels and materials"
    );
    assert_eq!(
        image.level_counts(gpu.root()).unwrap(),
        cpu.unique_nodes_per_level(cpu_root).unwrap(),
        "{name} {variant:?}: unique items per level"
    );
    match (cpu_root, gpu.root()) {
        (Root::Node(_), Root::Node(_)) => {}
        (a, b) => assert_eq!(a, b, "{name} {variant:?}: uniform root"),
    }
    let file = gpu.to_file().unwrap();
    assert_eq!(
        file.materials.as_ref(),
        Some(m),
        "{name} {variant:?}: saved"
    );
    let mut geometry = dag.clone();
    geometry.colors.clear();
    assert_eq!(
        file_geometry(&file),
        geometry,
        "{name} {variant:?}: saved geometry"
    );
}

#[test]
fn gpu_load_of_material_scenes_matches_the_cpu_hash_dag() {
    let ctx = common::gpu();
    let mut scenes: Vec<(String, Svdag, Materials)> = Vec::new();
    let (dag, m) = synthetic(32, 7);
    scenes.push(("synthetic 32".into(), dag, m));
    let empty = Svdag::from_voxels(&Voxels::from_coords(16, [])).unwrap();
    scenes.push((
        "empty 16".into(),
        empty,
        Materials::new(vec![1], vec![]).unwrap(),
    ));
    let full = Svdag::from_voxels(&Voxels::from_coords(8, (0..512).map(morton::decode))).unwrap();
    let one = Materials::new(vec![1, 2, 3], vec![2; 512]).unwrap();
    scenes.push(("full 8, one material".into(), full.clone(), one));
    let two = Materials::new(vec![1, 2], (0..512).map(|i| (i >= 448) as u8).collect()).unwrap();
    scenes.push(("full 8, two materials".into(), full, two));
    for (name, dag, k) in [("ff3.vox", vox(), 16), ("avocado 64", avocado(64), 16)] {
        let m = Materials::quantize(&dag.colors, k).unwrap();
        scenes.push((name.into(), dag, m));
    }
    // Every layout with 1024 buckets per table, and tables sized by what the load puts in them.
    let configs = HashVariant::ALL
        .map(|variant| GpuHashDagConfig::new(variant, 1024))
        .into_iter()
        .chain([GpuHashDagConfig::sized_by_load(HashVariant::AccelHash8)]);
    for config in configs {
        for (name, dag, m) in &scenes {
            check_gpu_load(&ctx, &config, name, dag, m);
        }
    }
    // Materials that do not fit the voxels are an error, not a panic.
    let (dag, m) = (&scenes[0].1, &scenes[0].2);
    let mut short = m.clone();
    short.ids.pop();
    let config = GpuHashDagConfig::new(HashVariant::Atomic64, 64);
    assert!(GpuHashDag::load_materials(&ctx, &config, dag, &short, None).is_err());
    ctx.wait_idle().unwrap();
    assert_eq!(ctx.live_allocations(), 0, "leaked GPU allocations");
    assert_eq!(ctx.validation_errors(), 0, "validation messages");
}

/// `voxdag build` -> GPU load -> save gives the same bytes, with materials and without.
#[test]
fn gpu_save_round_trips_built_files_byte_for_byte() {
    let ctx = common::gpu();
    let dir = tempfile::tempdir().unwrap();
    let input = common::repo().join("assets/avocado/Avocado.gltf");
    let config = GpuHashDagConfig::new(HashVariant::AccelHash32, 1024);
    for (name, extra) in [
        ("m.vdag", ["--materials", "16"]),
        ("g.vdag", ["--colors", "none"]),
    ] {
        let built = dir.path().join(name);
        let mut args = vec!["build", s(&input), "-r", "64", "-o", s(&built)];
        args.extend_from_slice(&extra);
        cli_ok(&args);
        let file = VdagFile::load(&built).unwrap();
        let dag = file_geometry(&file);
        let gpu = match &file.materials {
            Some(m) => GpuHashDag::load_materials(&ctx, &config, &dag, m, None).unwrap(),
            None => GpuHashDag::load(&ctx, &config, &dag, None).unwrap(),
        };
        let saved = dir.path().join(format!("saved-{name}"));
        gpu.save(&saved).unwrap();
        assert_eq!(
            std::fs::read(&saved).unwrap(),
            std::fs::read(&built).unwrap(),
            "{name}: load -> save"
        );
        cli_ok(&["verify", s(&saved)]);
    }
}

/// `voxdag edit --cpu` on a material scene edits with materials and saves them: the result is
/// the CPU editor's, the palette is kept, voxels away from every tool keep their material.
#[test]
fn edit_cpu_keeps_materials() {
    let dir = tempfile::tempdir().unwrap();
    let input = common::repo().join("assets/avocado/Avocado.gltf");
    let scene = dir.path().join("scene.vdag");
    cli_ok(&[
        "build",
        s(&input),
        "-r",
        "64",
        "--materials",
        "8",
        "-o",
        s(&scene),
    ]);
    let text = "EditSphere,20,20,20,6,true\nEditPaint,32,32,32,8\nEditCube,40,44,30,4,false\n\
                EditSphere,28,36,34,5,true\nUndo\nRedo\nEndFrame\n";
    let replay_path = dir.path().join("r.csv");
    std::fs::write(&replay_path, text).unwrap();
    let out = dir.path().join("out.vdag");
    cli_ok(&[
        "edit",
        s(&scene),
        "--replay",
        s(&replay_path),
        "-o",
        s(&out),
        "--cpu",
        "--material",
        "5",
    ]);
    cli_ok(&["verify", s(&out)]);
    let before = VdagFile::load(&scene).unwrap();
    let after = VdagFile::load(&out).unwrap();
    let (m0, m1) = (
        before.materials.clone().unwrap(),
        after.materials.clone().unwrap(),
    );
    assert_eq!(m0.palette, m1.palette);
    // The reference: the CPU editor on the same steps.
    let dag = file_geometry(&VdagFile::load(&scene).unwrap());
    let mut hd = HashDag::new(64, true).unwrap();
    let root = hd.insert_svdag(&dag, Some(&m0.ids)).unwrap();
    let mut editor = CpuEditor::new(hd, root, 64);
    let steps = Replay::parse(text, "r.csv")
        .unwrap()
        .steps(64, 6, 5)
        .unwrap();
    let mut centres = Vec::new();
    for (_, step) in steps {
        match step {
            Step::Edit(tool) => {
                editor.edit(&tool).unwrap();
            }
            Step::Undo => assert!(editor.undo()),
            Step::Redo => assert!(editor.redo()),
            Step::EndFrame => {}
        }
    }
    for line in text.lines().filter(|l| l.starts_with("Edit")) {
        let f: Vec<f32> = line
            .split(',')
            .skip(1)
            .take(4)
            .map(|v| v.parse().unwrap())
            .collect();
        centres.push(f);
    }
    let expected = editor.dag().voxels(editor.root()).unwrap();
    let codes = file_geometry(&after).to_voxels().codes;
    let got: Vec<(u64, u8)> = codes.into_iter().zip(m1.ids.iter().copied()).collect();
    assert_eq!(got, expected, "edit --cpu == CPU editor with materials");
    assert!(got.iter().any(|&(_, m)| m == 5), "painted / added voxels");
    let original: std::collections::HashMap<u64, u8> = file_geometry(&before)
        .to_voxels()
        .codes
        .into_iter()
        .zip(m0.ids.iter().copied())
        .collect();
    let mut kept = 0;
    for (code, m) in &got {
        let p = morton::decode(*code).map(|c| c as f32 + 0.5);
        let far = centres
            .iter()
            .all(|c| (0..3).map(|i| (p[i] - c[i]).powi(2)).sum::<f32>().sqrt() > c[3] * 1.8 + 1.0);
        if far {
            assert_eq!(
                original.get(code),
                Some(m),
                "voxel {code} away from the tools"
            );
            kept += 1;
        }
    }
    assert!(kept > 1000, "{kept} voxels away from the tools");
}
