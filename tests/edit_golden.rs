//! Golden of an edited scene on lavapipe: the teapot (64^3, geometry only: paint changes
//! nothing there) after a replay with sphere add / remove, a cube, paint, copy and undo, edited
//! on the GPU hash DAG and rendered from it in place (`edit-gpu-teapot`). The GPU-edited voxels
//! equal the CPU reference editor's on the same replay, and its svdag32 renders the same.

mod common;

use voxdag::edit::cpu::{CpuEditor, HashDag};
use voxdag::edit::gpu::{GpuHashDag, GpuHashDagConfig};
use voxdag::edit::replay::{Replay, Step};
use voxdag::hash::HashVariant;
use voxdag::render::gpu::GpuRenderer;
use voxdag::render::{Camera, RenderSettings};

const REPLAY: &str = "\
EditSphere,40,40,36,12,true
EndFrame
EditSphere,20,30,32,9,false
EditCube,48,22,40,7,false
EditPaint,32,32,32,14
EditCopy,20,30,32,20,30,32,44,30,14,9
EditSphere,12,12,12,6,true
Undo
EndFrame
";

fn settings() -> RenderSettings {
    RenderSettings::new(160, 120, Camera::orbit_default(64))
}

#[test]
fn replay_goldens_on_the_teapot() {
    let ctx = common::gpu();
    let svdag = common::build_scene(&common::repo().join("tests/data/teapot.obj"), Some(64));
    let steps = Replay::parse(REPLAY, "golden.csv")
        .unwrap()
        .steps(64, 6, 0)
        .unwrap();
    let renderer = GpuRenderer::new(&ctx).unwrap();

    let mut hd = GpuHashDag::load(
        &ctx,
        &GpuHashDagConfig::new(HashVariant::AccelHash32, 1024),
        &svdag,
        None,
    )
    .unwrap();
    let mut dag = HashDag::new(64, false).unwrap();
    let root = dag.insert_svdag(&svdag, None).unwrap();
    let mut cpu = CpuEditor::new(dag, root, 64);
    for (_, step) in &steps {
        match step {
            Step::Edit(tool) => {
                hd.edit(tool, None).unwrap();
                cpu.edit(tool).unwrap();
            }
            Step::Undo => assert_eq!(hd.undo(), cpu.undo()),
            Step::Redo => assert_eq!(hd.redo(), cpu.redo()),
            Step::EndFrame => {}
        }
    }
    hd.gc(None).unwrap();
    let image = hd.download().unwrap();
    assert_eq!(
        image.voxels(hd.root()).unwrap(),
        cpu.dag().voxels(cpu.root()).unwrap(),
        "GPU edit = CPU editor"
    );
    let scene = renderer.bind_hash_dag(&hd, None).unwrap();
    let gpu_image = renderer.render(&scene, &settings(), None).unwrap();
    common::check_golden("edit-gpu-teapot", &gpu_image, 8, 0.005);
    drop(scene);

    let out = cpu.dag().to_svdag(cpu.root()).unwrap();
    let scene = renderer.upload(&out).unwrap();
    let cpu_image = renderer.render(&scene, &settings(), None).unwrap();
    common::assert_renders_match("edit-teapot", &gpu_image, &cpu_image);
    // The replay changed the scene (the goldens are not of the unedited teapot).
    let plain = renderer.upload(&svdag).unwrap();
    let before = renderer.render(&plain, &settings(), None).unwrap();
    assert!(common::compare(&before.rgba, &gpu_image.rgba, 8).differing > 100);
    drop((scene, plain, hd, renderer));
    ctx.wait_idle().unwrap();
    assert_eq!(ctx.live_allocations(), 0, "leaked GPU allocations");
    assert_eq!(ctx.validation_errors(), 0, "validation messages (see log)");
}
