//! `voxdag edit` on the GPU (the default) against `--cpu`: the saved files are equal byte for
//! byte on the HashDAG replay files of tests/data, for every table layout; the report holds
//! per-edit times, kernel times with `--profile`, GC statistics and the per-level unique node
//! counts; `--trace` and `--render-after` write their files.

mod common;

use std::path::Path;

fn replay(name: &str) -> std::path::PathBuf {
    common::repo().join("tests/data/hashdag_replays").join(name)
}

fn run(args: &[&str]) {
    let out = common::voxdag_cli(args);
    assert!(
        out.status.success(),
        "voxdag {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn gpu_edit_saves_the_same_bytes_as_the_cpu_editor_on_the_hashdag_replays() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("teapot.vdag");
    common::build_scene(&common::repo().join("tests/data/teapot.obj"), Some(256))
        .save(&scene)
        .unwrap();
    // (file, the depth it was recorded at).
    let replays = [
        ("sanmiguel_tree_copy.csv", "16"),
        ("epiccitadel_edits_short.csv", "16"),
        ("epiccitadel_large_edits.csv", "16"),
        ("replay_edits_add_head400.csv", "12"),
    ];
    for (i, (name, depth)) in replays.iter().enumerate() {
        let r = replay(name);
        let cpu = dir.path().join(format!("{name}.cpu.vdag"));
        run(&[
            "edit",
            path(&scene),
            "--replay",
            path(&r),
            "--replay-depth",
            depth,
            "-o",
            path(&cpu),
            "--cpu",
        ]);
        let tables = if i == 0 {
            vec!["atomic64", "ticket_board", "accel32", "accel8"]
        } else {
            vec!["accel8"]
        };
        let mut engines: Vec<[&str; 2]> = tables.iter().map(|t| [*t, "single-lane"]).collect();
        if i == 0 {
            // The dissertation's subgroup teams give the file of the default single lanes.
            engines.push(["accel32", "subgroup"]);
        }
        for [table, team] in engines {
            let gpu = dir.path().join(format!("{name}.{table}.{team}.vdag"));
            run(&[
                "edit",
                path(&scene),
                "--replay",
                path(&r),
                "--replay-depth",
                depth,
                "-o",
                path(&gpu),
                "--table",
                table,
                "--team",
                team,
                "--undo-depth",
                "2",
            ]);
            assert!(
                std::fs::read(&gpu).unwrap() == std::fs::read(&cpu).unwrap(),
                "{name} on {table} ({team}): the GPU's file differs from the CPU editor's"
            );
        }
    }
}

#[test]
fn gpu_edit_report_profile_trace_and_render() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("teapot.vdag");
    common::build_scene(&common::repo().join("tests/data/teapot.obj"), Some(64))
        .save(&scene)
        .unwrap();
    let r = dir.path().join("r.csv");
    std::fs::write(
        &r,
        "EditSphere,16,16,16,4,true\nEndFrame\nEditCube,32,32,32,8,FALSE,,\nUndo\nRedo\nEditSphere,40,20,30,6,false\n",
    )
    .unwrap();
    let (out, report, trace, png) = (
        dir.path().join("out.vdag"),
        dir.path().join("report.json"),
        dir.path().join("trace.json"),
        dir.path().join("after.png"),
    );
    run(&[
        "edit",
        path(&scene),
        "--replay",
        path(&r),
        "-o",
        path(&out),
        "--report",
        path(&report),
        "--profile",
        "--trace",
        path(&trace),
        "--render-after",
        path(&png),
        "--undo-depth",
        "1",
    ]);
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(json["editor"], "gpu");
    assert_eq!(json["table"], "accel32");
    // The replay's tools' pipelines are made after the load, before the first edit.
    assert!(json["pipelines_ms"].as_f64().unwrap() > 0.0, "{json}");
    let edits = json["edits"].as_array().unwrap();
    assert_eq!(edits.len(), 3);
    assert!(edits[0]["kernels_ms"]
        .as_object()
        .unwrap()
        .contains_key("edit traverse small levels"));
    // Per edit the temporary SVO's entries and items per level (5 levels at 64^3), no more
    // items than entries; the first sphere builds leaves.
    for edit in edits {
        let nodes = edit["temporary_nodes"].as_array().unwrap();
        let items = edit["items"].as_array().unwrap();
        assert_eq!((nodes.len(), items.len()), (5, 5));
        assert!(nodes
            .iter()
            .zip(items)
            .all(|(n, i)| i.as_u64() <= n.as_u64()));
    }
    assert!(edits[0]["temporary_nodes"][0].as_u64().unwrap() > 0);
    assert_eq!(json["unique_nodes_per_level"].as_array().unwrap().len(), 5);
    // Undo depth 1: two live roots; the final GC freed what the dropped roots held.
    assert!(json["gc"]["freed_items"].as_u64().unwrap() > 0);
    let live = json["gc"]["live_per_table"].as_array().unwrap();
    assert_eq!(live.len(), 9);
    assert!(std::fs::read_to_string(&trace)
        .unwrap()
        .contains("traceEvents"));
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (1024, 768));
    // The CPU editor's file is the same.
    let cpu = dir.path().join("cpu.vdag");
    run(&[
        "edit",
        path(&scene),
        "--replay",
        path(&r),
        "-o",
        path(&cpu),
        "--cpu",
    ]);
    assert!(std::fs::read(&cpu).unwrap() == std::fs::read(&out).unwrap());
}

/// `voxdag bench edit` of the repository's `scene` at 64^3 without the bytes target, plus
/// `extra` arguments: its JSON report and Markdown table.
fn bench_edit(scene: &str, extra: &[&str]) -> (serde_json::Value, String) {
    let dir = tempfile::tempdir().unwrap();
    let scene = common::repo().join(scene);
    let (json, md) = (dir.path().join("e.json"), dir.path().join("e.md"));
    let mut args = vec![
        "--quiet",
        "bench",
        "edit",
        "--scenes",
        path(&scene),
        "--resolution",
        "64",
        "--random-edits",
        "0",
        "--json",
        path(&json),
        "--markdown",
        path(&md),
    ];
    args.extend_from_slice(extra);
    run(&args);
    let report = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    (report, std::fs::read_to_string(&md).unwrap())
}

/// `voxdag bench edit` times every GPU replay without the profiler (whose timestamps cost
/// lavapipe about an edit) and profiles a second run for the kernel groups: each GPU row has
/// both totals, kernel times and a pass count, and its ratio to the CPU editor comes from the
/// unprofiled total.
#[test]
fn bench_edit_times_unprofiled_and_profiles_a_second_run() {
    let (report, md) = bench_edit(
        "tests/data/teapot.obj",
        &[
            "--tables",
            "accel32",
            "--teams",
            "single-lane,subgroup",
            "--long-replay",
            "20",
        ],
    );
    let rows = report["replays"].as_array().unwrap();
    let cpu = |replay: &serde_json::Value, field: &str| {
        rows.iter()
            .find(|r| r["engine"] == "cpu" && r["replay"] == *replay)
            .unwrap()[field]
            .as_f64()
            .unwrap()
    };
    // Paint changes nothing in a geometry-only scene: no paint replay there.
    assert!(rows.iter().all(|r| r["replay"] != "paint"), "{report}");
    let gpu: Vec<_> = rows
        .iter()
        .filter(|r| r["engine"] != "cpu" && r["status"] == "ok")
        .collect();
    assert!(gpu.len() >= 4, "{report}");
    // The long replay: its 20 edits on the CPU editor and both team modes.
    let long: Vec<_> = rows
        .iter()
        .filter(|r| r["replay"] == "long spheres")
        .collect();
    let engines: Vec<_> = long.iter().map(|r| r["engine"].as_str().unwrap()).collect();
    assert_eq!(engines, ["cpu", "accel32", "accel32 subgroup"], "{report}");
    assert!(long.iter().all(|r| r["edits"] == 20), "{report}");
    for r in gpu {
        assert!(r["edits"].as_u64().unwrap() > 0, "{r}");
        let total = r["edit_ms_total"].as_f64().unwrap();
        assert!(total > 0.0, "{r}");
        assert!(r["profiled_ms_total"].as_f64().unwrap() > 0.0, "{r}");
        // Each fresh load makes its tools' pipelines before the timed edits.
        assert!(r["pipelines_ms"].as_f64().unwrap() > 0.0, "{r}");
        let kernels: f64 = r["kernels_ms"]
            .as_object()
            .unwrap()
            .values()
            .map(|v| v.as_f64().unwrap())
            .sum();
        assert!(kernels > 0.0, "{r}");
        assert!(r["per_edit"][2].as_f64().unwrap() >= 1.0, "{r}");
        let ratio = r["vs_cpu"].as_f64().unwrap();
        let expected = total / cpu(&r["replay"], "edit_ms_total").max(1e-9);
        assert!((ratio - expected).abs() <= 1e-9 * expected.max(1.0), "{r}");
        // The median edit: above 0, at most the largest; its ratio is to the CPU row's median.
        let median = r["edit_ms_median"].as_f64().unwrap();
        assert!(
            median > 0.0 && median <= r["edit_ms_max"].as_f64().unwrap(),
            "{r}"
        );
        let ratio = r["median_vs_cpu"].as_f64().unwrap();
        let expected = median / cpu(&r["replay"], "edit_ms_median").max(1e-9);
        assert!((ratio - expected).abs() <= 1e-9 * expected.max(1.0), "{r}");
    }
    assert!(md.contains("profiled ms total") && md.contains("median / CPU's"));
}

/// `voxdag bench edit --materials 4` on the bundled Avocado (colours quantized into 4
/// materials): the paint replay changes the scene, and every GPU replay leaves the same item
/// bytes as the CPU reference editor (the two editors build the same DAG).
#[test]
fn bench_edit_with_materials_paints_and_matches_the_cpu_editor() {
    let (report, md) = bench_edit(
        "assets/avocado/Avocado.gltf",
        &[
            "--tables",
            "atomic64,accel8",
            "--long-replay",
            "10",
            "--materials",
            "4",
        ],
    );
    assert_eq!(report["materials"], 4, "{report}");
    let rows = report["replays"].as_array().unwrap();
    for replay in ["spheres", "copy", "paint", "long spheres"] {
        let of = |engine: &str| {
            rows.iter()
                .find(|r| r["engine"] == engine && r["replay"] == replay)
                .unwrap_or_else(|| panic!("{replay} on {engine}: {report}"))
        };
        let cpu = of("cpu");
        assert_ne!(
            cpu["dag_bytes_after"], cpu["dag_bytes_before"],
            "{replay} changes the scene"
        );
        for table in ["atomic64", "accel8"] {
            let gpu = of(table);
            assert_eq!(gpu["status"], "ok", "{gpu}");
            assert_eq!(gpu["dag_bytes_before"], cpu["dag_bytes_before"], "{gpu}");
            assert_eq!(gpu["dag_bytes_after"], cpu["dag_bytes_after"], "{gpu}");
        }
    }
    assert!(md.contains("materials: colours quantized to at most 4"));
}
