//! HashDAG replay files: real files parse unmodified and write back byte for byte, the
//! format's quirks, every class of bad line, scaling, and a replay applied by the CPU editor.

mod common;

use std::path::Path;

use voxdag::edit::cpu::{CpuEditor, HashDag};
use voxdag::edit::item::Root;
use voxdag::edit::replay::{Action, Replay, ReplayError, Step};
use voxdag::edit::tool::{Shape, Tool, VoxelMap};

fn data(name: &str) -> std::path::PathBuf {
    common::repo().join("tests/data/hashdag_replays").join(name)
}

#[test]
fn real_files_parse_and_write_back_unmodified() {
    let files = [
        "epiccitadel_large_edits.csv",
        "epiccitadel_edits_short.csv",
        "sanmiguel_tree_copy.csv",
        "epiccitadel_video_large_carving_undo.csv",
        "replay_edits_add_head400.csv",
    ];
    for name in files {
        let path = data(name);
        let replay = Replay::load(&path).unwrap_or_else(|e| panic!("{e}"));
        assert!(!replay.lines.is_empty(), "{name}");
        let text = std::fs::read_to_string(&path).unwrap();
        if !text.contains(",,") && !text.contains("TRUE") {
            // Written by HashDAG's write_csv: our writer gives the same bytes.
            let ours = replay.to_csv();
            for (i, (a, b)) in ours.lines().zip(text.lines()).enumerate() {
                assert_eq!(a, b, "{name}:{}", i + 1);
            }
            // (Some files lack the final newline, which our writer always ends with.)
            assert_eq!(
                ours.trim_end_matches('\n'),
                text.trim_end_matches('\n'),
                "{name}"
            );
        }
        // Whatever the quirks, writing and reading again gives the same actions.
        let again = Replay::parse(&replay.to_csv(), "again").unwrap();
        let actions = |r: &Replay| r.lines.iter().map(|l| l.action).collect::<Vec<_>>();
        assert_eq!(actions(&again), actions(&replay), "{name}");
    }
    let copy = Replay::load(&data("sanmiguel_tree_copy.csv")).unwrap();
    let copies: Vec<_> = copy
        .lines
        .iter()
        .filter(|l| matches!(l.action, Action::EditCopy { .. }))
        .collect();
    assert_eq!(copies.len(), 1);
    match copies[0].action {
        Action::EditCopy {
            radius,
            transform: Some((m, swirl, period)),
            ..
        } => {
            assert_eq!(radius, 503.0);
            assert_eq!(m, [1.1, 0.0, 0.0, 0.0, 1.1, 0.0, 0.0, 0.0, 1.1]);
            assert!(!swirl);
            assert_eq!(period, 110.0);
        }
        other => panic!("{other:?}"),
    }
    let undo = Replay::load(&data("epiccitadel_video_large_carving_undo.csv")).unwrap();
    let count = |a: Action| undo.lines.iter().filter(|l| l.action == a).count();
    assert_eq!((count(Action::Undo), count(Action::Redo)), (28, 32));
}

#[test]
fn quirks_are_accepted() {
    let text = "SetLocation,-951.243605,667.199855,-27.706481,,,,,,\r\n\
                EditSphere,2775,1328,2063,10,TRUE,,,,\n\
                EditCube,1.5,2,3.25,4,FALSE\n\
                \n\
                EditFill,23364.000000,65253.000000,39508.000000,124.000000\n\
                EditPaint,1,2,3,4\n\
                SetToolParameters,20157,64817,41532,0,0,0,0,0,0,280.000000,1\n\
                Undo\nRedo,,\nEndFrame,,,,,,,,,";
    let replay = Replay::parse(text, "quirks.csv").unwrap();
    let actions: Vec<Action> = replay.lines.iter().map(|l| l.action).collect();
    assert_eq!(
        actions[1],
        Action::EditSphere {
            location: [2775.0, 1328.0, 2063.0],
            radius: 10.0,
            add: true
        }
    );
    assert_eq!(
        actions[2],
        Action::EditCube {
            location: [1.5, 2.0, 3.25],
            radius: 4.0,
            add: false
        }
    );
    assert_eq!(
        &actions[6..],
        &[Action::Undo, Action::Redo, Action::EndFrame]
    );
    // Line numbers count the blank line.
    assert_eq!(replay.lines[3].line, 5);
    assert_eq!(
        Action::EditSphere {
            location: [1.0, 2.5, 3.0],
            radius: 4.0,
            add: true
        }
        .to_csv(),
        "EditSphere,1.000000,2.500000,3.000000,4.000000,true"
    );
}

fn line_error(text: &str) -> (usize, String) {
    match Replay::parse(text, "bad.csv").and_then(|r| r.steps(256, 8, 1).map(|_| ())) {
        Err(ReplayError::Line { path, line, reason }) => {
            assert_eq!(path, Path::new("bad.csv"));
            (line, reason)
        }
        other => panic!("{text:?}: expected a line error, got {other:?}"),
    }
}

#[test]
fn every_class_of_bad_line_names_the_line() {
    let good = "EditSphere,10,10,10,4,true\nEndFrame\n";
    let cases = [
        ("Explode,1,2,3", "unknown action"),
        ("EditSphere,1,2,3,4", "takes 5 fields"),
        ("EditSphere,1,2,3,4,true,5", "takes 5 fields"),
        ("EditCopy,1,2,3,4,5,6,7,8,9,10,11", "takes 10 or 21 fields"),
        ("EditSphere,1,x,3,4,true", "not a number"),
        ("EditSphere,1,,3,4,true", "not a number"),
        ("EditSphere,1,2,3,4,yes", "true/false"),
        ("EditSphere,1,2,NaN,4,true", "not a finite number"),
        ("EditFill,1,2,inf,4", "not a finite number"),
        ("EditSphere,300,2,3,4,true", "outside the 256^3 scene"),
        ("EditPaint,-1,2,3,4", "outside the 256^3 scene"),
        ("EditSphere,1,2,3,0,true", "radius"),
        ("EditSphere,1,2,3,-2,false", "radius"),
        ("EditCube,1,2,3,100000,true", "radius"),
        ("Undo,1", "takes 0 fields"),
        ("SetToolParameters,-1,0,0,0,0,0,0,0,0,1,0", "unsigned"),
        (
            "EditCopy,1,2,3,4,5,6,7,8,9,10,0,0,0,0,0,0,0,0,0,false,1",
            "singular",
        ),
        (
            "EditCopy,1,2,3,4,5,6,7,8,9,10,1,0,0,0,1,0,0,0,1,true,1",
            "swirl",
        ),
    ];
    for (bad, expected) in cases {
        let text = format!("{good}{bad}\n{good}");
        let (line, reason) = line_error(&text);
        assert_eq!(line, 3, "{bad}");
        assert!(reason.contains(expected), "{bad}: {reason}");
    }
}

#[test]
fn positions_scale_with_the_depths() {
    let replay = Replay::parse("EditSphere,100,50,25.5,8,true\nUndo\n", "s.csv").unwrap();
    // Scene 2^9 = 512, replay depth 8: everything doubles.
    let steps = replay.steps(512, 8, 3).unwrap();
    assert_eq!(
        steps,
        vec![
            (
                1,
                Step::Edit(Tool::Add {
                    shape: Shape::Sphere,
                    center: [200.0, 100.0, 51.0],
                    radius: 16.0,
                    material: 3
                })
            ),
            (2, Step::Undo)
        ]
    );
    // Replay depth 10 on a 2^8 scene: a quarter.
    let steps = replay.steps(256, 10, 0).unwrap();
    match steps[0].1 {
        Step::Edit(Tool::Add { center, radius, .. }) => {
            assert_eq!((center, radius), ([25.0, 12.5, 6.375], 2.0));
        }
        ref other => panic!("{other:?}"),
    }
    assert!(matches!(
        replay.steps(256, 31, 0),
        Err(ReplayError::Depth(31))
    ));
}

#[test]
fn replay_on_the_cpu_editor_matches_brute_force() {
    let text = "EditSphere,32,32,32,12,true\nEndFrame\n\
                EditCube,40,30,30,6,false\n\
                EditPaint,30,30,30,8\n\
                EditCopy,32,32,32,32,32,32,50,50,50,6\n\
                Undo\nRedo\nUndo\n\
                EditFill,10,10,10,5\nEndFrame,,,\n";
    let replay = Replay::parse(text, "session.csv").unwrap();
    let steps = replay.steps(64, 6, 7).unwrap();
    let mut editor = CpuEditor::new(HashDag::new(64, true).unwrap(), Root::Empty, 16);
    let mut history = vec![VoxelMap {
        resolution: 64,
        ..Default::default()
    }];
    let mut current = 0;
    for (_, step) in steps {
        match step {
            Step::Edit(tool) => {
                editor.edit(&tool).unwrap();
                let mut next = history[current].clone();
                next.apply(&tool, true).unwrap();
                history.truncate(current + 1);
                history.push(next);
                current += 1;
            }
            Step::Undo => {
                editor.undo();
                current -= 1;
            }
            Step::Redo => {
                editor.redo();
                current += 1;
            }
            Step::EndFrame => {}
        }
        assert_eq!(
            editor.dag().voxels(editor.root()).unwrap(),
            history[current].sorted()
        );
    }
    assert!(!history[current].voxels.is_empty());
}

#[test]
fn edit_command_replays_on_the_cpu_and_the_gpu() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("teapot.vdag");
    let svdag = common::build_scene(&common::repo().join("tests/data/teapot.obj"), Some(64));
    svdag.save(&scene).unwrap();
    let replay = dir.path().join("r.csv");
    std::fs::write(
        &replay,
        "EditSphere,16,16,16,4,true\nEndFrame\nEditSphere,32,32,32,8,FALSE,,\nUndo\nRedo\n",
    )
    .unwrap();
    let out = dir.path().join("out.vdag");
    let report = dir.path().join("report.json");
    let (scene_s, replay_s, out_s, report_s) = (
        scene.to_str().unwrap(),
        replay.to_str().unwrap(),
        out.to_str().unwrap(),
        report.to_str().unwrap(),
    );
    // The GPU editor (the default) writes what the CPU editor writes.
    let gpu_out = dir.path().join("gpu.vdag");
    let gpu_s = gpu_out.to_str().unwrap();
    let gpu = common::voxdag_cli(&["edit", scene_s, "--replay", replay_s, "-o", gpu_s]);
    assert!(
        gpu.status.success(),
        "{}",
        String::from_utf8_lossy(&gpu.stderr)
    );
    let run = common::voxdag_cli(&[
        "edit", scene_s, "--replay", replay_s, "-o", out_s, "--cpu", "--report", report_s,
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    // The saved scene equals the brute-force edit of the teapot.
    let mut map = VoxelMap {
        resolution: 64,
        ..Default::default()
    };
    for code in svdag.to_voxels().codes {
        map.voxels.insert(voxdag::scene::morton::decode(code), 0);
    }
    for (_, step) in Replay::load(&replay).unwrap().steps(64, 6, 0).unwrap() {
        if let Step::Edit(tool) = step {
            map.apply(&tool, false).unwrap();
        }
    }
    let saved = voxdag::dag::Svdag::load(&out).unwrap();
    let codes: Vec<u64> = map.sorted().iter().map(|e| e.0).collect();
    assert_eq!(saved.to_voxels().codes, codes);
    assert!(std::fs::read(&gpu_out).unwrap() == std::fs::read(&out).unwrap());
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(json["edits"].as_array().unwrap().len(), 2);
    assert_eq!(json["unique_nodes_per_level"].as_array().unwrap().len(), 5);
    // A bad line: an error naming the line, no output written.
    std::fs::write(&replay, "EditSphere,16,16,16,4,true\nEditSphere,1,2,3\n").unwrap();
    std::fs::remove_file(&out).unwrap();
    let bad = common::voxdag_cli(&["edit", scene_s, "--replay", replay_s, "-o", out_s, "--cpu"]);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("r.csv:2"));
    assert!(!out.exists());
}
