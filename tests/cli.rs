//! The `voxdag` CLI end to end: good input gives the documented outputs, bad input gives one-line
//! errors naming the path or the reason, a non-zero exit, no panic and no partial output file.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn voxdag(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_voxdag"))
        .args(args)
        .env("RUST_LOG", "warn")
        .output()
        .expect("run voxdag")
}

/// Runs voxdag and asserts it succeeded (stderr in the message otherwise).
fn voxdag_ok(args: &[&str]) -> Output {
    common::assert_cli_ok(args, voxdag(args))
}

/// Asserts a clean failure: non-zero exit, one `error:` line containing every `needle`, no panic.
fn assert_clean_error(out: &Output, needles: &[&str]) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "expected failure, got success; stderr: {stderr}"
    );
    assert_eq!(out.status.code(), Some(1), "stderr: {stderr}");
    assert!(!stderr.contains("panicked"), "panic: {stderr}");
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(
        errors.len(),
        1,
        "want exactly one error line, got: {stderr}"
    );
    for needle in needles {
        assert!(
            errors[0].contains(needle),
            "error line {:?} lacks {needle:?}",
            errors[0]
        );
    }
}

/// A closed tetrahedron as OBJ text.
const TETRAHEDRON: &str =
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn build_stats_export_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let obj = write(dir.path(), "tetra.obj", TETRAHEDRON.as_bytes());
    let vdag = dir.path().join("tetra.vdag");
    voxdag_ok(&[
        "build",
        s(&obj),
        "--resolution",
        "64",
        "-o",
        s(&vdag),
        "--quiet",
    ]);

    let out = voxdag_ok(&["stats", s(&vdag), "--json"]);
    let json: serde_json::Value =
        serde_json::from_slice(&out.stdout).expect("stats --json is JSON");
    assert_eq!(json["resolution"], 64);
    let voxels = json["voxels"].as_u64().unwrap();
    assert!(
        voxels > 64 * 64,
        "a tetrahedron's surface at 64^3 has thousands of voxels, got {voxels}"
    );
    assert!(json["bytes"]["svo"].as_u64().unwrap() >= json["bytes"]["svdag32"].as_u64().unwrap());
    let levels = json["levels"].as_array().unwrap();
    assert_eq!(levels.len(), 5, "levels 0 (4^3) .. 4 (root of 64^3)");
    for (i, level) in levels.iter().enumerate() {
        assert_eq!(level["level"], i as u64);
        assert!(level["svdag"].as_u64().unwrap() <= level["svo"].as_u64().unwrap());
    }
    assert_eq!(levels[4]["svo"], 1);
    assert_eq!(levels[4]["svdag"], 1);

    for key in ["ssvdag", "s", "a", "sa", "sat"] {
        assert!(
            levels[0][key].as_u64().unwrap() <= levels[0]["svdag"].as_u64().unwrap(),
            "{key}"
        );
    }
    // --quick: the same SVO/SVDAG numbers without the transform searches and encodings.
    let out = voxdag_ok(&["stats", s(&vdag), "--json", "--quick"]);
    let quick: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(quick["voxels"], json["voxels"]);
    assert_eq!(quick["bytes"]["svdag32"], json["bytes"]["svdag32"]);
    assert!(quick["bytes"].get("tsvdag").is_none() && quick["levels"][0].get("sa").is_none());
    for (q, full) in quick["levels"].as_array().unwrap().iter().zip(levels) {
        assert_eq!((&q["svo"], &q["svdag"]), (&full["svo"], &full["svdag"]));
    }

    let xyz = dir.path().join("tetra.xyz");
    voxdag_ok(&[
        "export-voxels",
        s(&vdag),
        "--format",
        "xyz-u32",
        "-o",
        s(&xyz),
    ]);
    let bytes = std::fs::read(&xyz).unwrap();
    assert_eq!(bytes.len() as u64, voxels * 12);
    assert!(bytes
        .chunks_exact(4)
        .all(|c| u32::from_le_bytes(c.try_into().unwrap()) < 64));

    let vox = dir.path().join("tetra.vox");
    voxdag_ok(&["export-voxels", s(&vdag), "--format", "vox", "-o", s(&vox)]);
    let reimported = dot_vox_count(&vox);
    assert_eq!(reimported, voxels);
}

fn dot_vox_count(path: &Path) -> u64 {
    // Re-import through voxdag itself: build from the .vox at native size and read the voxel count.
    let vdag = path.with_extension("back.vdag");
    voxdag_ok(&["build", s(path), "-o", s(&vdag), "--quiet"]);
    let out = voxdag(&["stats", s(&vdag), "--json"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    json["voxels"].as_u64().unwrap()
}

#[test]
fn bad_inputs_fail_cleanly_without_output() {
    let dir = tempfile::tempdir().unwrap();
    let out_path = dir.path().join("out.vdag");
    let out = s(&out_path);
    let obj = write(dir.path(), "tetra.obj", TETRAHEDRON.as_bytes());

    let missing = dir.path().join("missing.obj");
    assert_clean_error(
        &voxdag(&["build", s(&missing), "-r", "64", "-o", out, "-q"]),
        &["missing.obj"],
    );

    let txt = write(dir.path(), "notes.txt", b"hello");
    assert_clean_error(
        &voxdag(&["build", s(&txt), "-r", "64", "-o", out, "-q"]),
        &["notes.txt"],
    );

    let bad_obj = write(
        dir.path(),
        "bad.obj",
        b"v 0 0 0\nf 1 2 3\nthis is not obj \xff\xfe\n",
    );
    assert_clean_error(
        &voxdag(&["build", s(&bad_obj), "-r", "64", "-o", out, "-q"]),
        &["bad.obj"],
    );

    let bad_vox = write(dir.path(), "bad.vox", b"VOX \x96\x00\x00\x00MAIN\xff\xff");
    assert_clean_error(
        &voxdag(&["build", s(&bad_vox), "-o", out, "-q"]),
        &["bad.vox"],
    );

    let bad_glb = write(
        dir.path(),
        "bad.glb",
        b"glTF\x02\x00\x00\x00\x10\x00\x00\x00",
    );
    assert_clean_error(
        &voxdag(&["build", s(&bad_glb), "-r", "64", "-o", out, "-q"]),
        &["bad.glb"],
    );

    assert_clean_error(
        &voxdag(&["build", s(&obj), "-r", "100", "-o", out, "-q"]),
        &["power of two"],
    );
    assert_clean_error(
        &voxdag(&["build", s(&obj), "-r", "4", "-o", out, "-q"]),
        &["4"],
    );
    assert_clean_error(
        &voxdag(&["build", s(&obj), "-r", "1048576", "-o", out, "-q"]),
        &["1048576"],
    );
    // 65536^3 is a valid resolution, but 64 stacked full-size planes there need ~2 TiB of voxels:
    // the in-memory build refuses up front, before any allocation (the streaming build, the
    // default, would run it in bounded memory for hours).
    let mut planes = String::new();
    for i in 0..64 {
        let y = i as f32 / 63.0;
        planes += &format!("v 0 {y} 0\nv 1 {y} 0\nv 1 {y} 1\nv 0 {y} 1\n");
        let v = 4 * i + 1;
        planes += &format!("f {} {} {}\nf {} {} {}\n", v, v + 1, v + 2, v, v + 2, v + 3);
    }
    let planes = write(dir.path(), "planes.obj", planes.as_bytes());
    assert_clean_error(
        &voxdag(&[
            "build",
            s(&planes),
            "-r",
            "65536",
            "--in-memory",
            "-o",
            out,
            "-q",
        ]),
        &["planes.obj", "memory"],
    );
    assert!(
        !out_path.exists(),
        "a failed build must not leave an output file"
    );

    let garbage = write(dir.path(), "garbage.vdag", &[7u8; 300]);
    assert_clean_error(&voxdag(&["stats", s(&garbage)]), &["garbage.vdag"]);
    let png = dir.path().join("img.png");
    assert_clean_error(
        &voxdag(&["render", s(&garbage), "--out", s(&png)]),
        &["garbage.vdag"],
    );
    assert_clean_error(
        &voxdag(&["render", s(&missing), "--out", s(&png)]),
        &["missing"],
    );
    assert!(!png.exists());

    let nowhere = dir.path().join("no/such/dir/out.vdag");
    assert_clean_error(
        &voxdag(&["build", s(&obj), "-r", "64", "-o", s(&nowhere), "-q"]),
        &["no/such/dir"],
    );
}

#[test]
fn render_writes_png_profile_and_trace() {
    let dir = tempfile::tempdir().unwrap();
    let obj = write(dir.path(), "tetra.obj", TETRAHEDRON.as_bytes());
    let vdag = dir.path().join("tetra.vdag");
    assert!(
        voxdag(&["build", s(&obj), "-r", "64", "-o", s(&vdag), "-q"])
            .status
            .success()
    );
    let png = dir.path().join("tetra.png");
    let trace = dir.path().join("trace.json");
    let out = voxdag(&[
        "render",
        s(&vdag),
        "--size",
        "96x64",
        "--out",
        s(&png),
        "--profile",
        "--trace",
        s(&trace),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("primary rays"),
        "the profile table names the pass: {stdout}"
    );
    let image = image::open(&png).unwrap().to_rgba8();
    assert_eq!((image.width(), image.height()), (96, 64));
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&trace).unwrap()).unwrap();
    let events = json["traceEvents"].as_array().unwrap();
    assert!(events.iter().any(|e| e["name"] == "primary rays"
        && e["ph"] == "X"
        && e["dur"].as_f64().unwrap() > 0.0));

    // The CPU reference renderer gives the same hit pixels as the GPU (within the edge tolerance).
    let cpu_png = dir.path().join("tetra-cpu.png");
    voxdag_ok(&[
        "render",
        s(&vdag),
        "--size",
        "96x64",
        "--out",
        s(&cpu_png),
        "--cpu",
    ]);
    let cpu = image::open(&cpu_png).unwrap().to_rgba8();
    let differing = image
        .pixels()
        .zip(cpu.pixels())
        .filter(|(a, b)| a.0.iter().zip(b.0).any(|(x, y)| x.abs_diff(y) > 4))
        .count();
    assert!(
        differing <= 96 * 64 / 200,
        "{differing} pixels differ between GPU and CPU renders"
    );
}

#[test]
fn bench_compress_writes_consistent_tables() {
    let dir = tempfile::tempdir().unwrap();
    let teapot = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/teapot.obj");
    let (json, md, png, cache) = (
        dir.path().join("c.json"),
        dir.path().join("c.md"),
        dir.path().join("c.png"),
        dir.path().join("cache"),
    );
    let run = |extra: &[&str]| {
        let mut args = vec![
            "bench",
            "compress",
            "--scenes",
            teapot,
            "--resolutions",
            "64",
            "--json",
            s(&json),
            "--markdown",
            s(&md),
            "--chart",
            s(&png),
            "--cache",
            s(&cache),
        ];
        args.extend(extra);
        voxdag(&args)
    };
    let bench = |extra: &[&str]| {
        let out = run(extra);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let rows: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
        rows[0].clone()
    };
    let row = bench(&[]);
    let e = |row: &serde_json::Value, k: &str| row["elements"][k].as_u64().unwrap();
    assert!(e(&row, "svdag") <= e(&row, "svo") && e(&row, "s") <= e(&row, "svdag"));
    assert!(e(&row, "a") <= e(&row, "svdag") && e(&row, "s") <= e(&row, "ssvdag"));
    assert!(e(&row, "sa") <= e(&row, "s").min(e(&row, "a")) && e(&row, "sat") <= e(&row, "sa"));
    let b = |k: &str| row["bytes"][k].as_u64().unwrap();
    assert!(b("ssvdag") < b("svdag32") && b("tsvdag") > 0 && b("tsvdag_base") > 0);
    assert!(std::fs::read_to_string(&md).unwrap().contains("S+A+T"));
    let chart = image::open(&png).unwrap();
    assert_eq!(
        (chart.width(), chart.height()),
        (18 + 5 * 14 + 18, 260),
        "one bar group"
    );
    // The svdag32 build is kept in --cache and reused; without the translation search the
    // other counts are the same and the S+A+T column says so.
    let cached = cache.join("teapot-64-svdag32.vdag");
    let built = std::fs::metadata(&cached).unwrap().modified().unwrap();
    let ablation = row["ablation"].as_array().unwrap();
    assert_eq!(ablation.len(), 5);
    // The last ablation step has every heuristic on: the sizes of the bytes table.
    assert_eq!(ablation[4]["huffman"], row["bytes"]["tsvdag"]);
    assert_eq!(ablation[4]["base"], row["bytes"]["tsvdag_base"]);
    let off = bench(&["--translations", "off", "--heuristics", "off"]);
    assert_eq!(
        std::fs::metadata(&cached).unwrap().modified().unwrap(),
        built
    );
    for k in ["svo", "svdag", "ssvdag", "s", "a", "sa"] {
        assert_eq!(e(&off, k), e(&row, k), "{k}");
    }
    assert!(off["elements"]["sat"].is_null() && off["seconds"]["sat"].is_null());
    assert!(off["ablation"].as_array().unwrap().is_empty());
    assert!(off["seconds"]["encode_tsvdag_v1"].is_null());
    let text = std::fs::read_to_string(&md).unwrap();
    assert!(text.contains("not run") && !text.contains("per encoder heuristic"));
    // A cached report of another resolution is refused, naming the file.
    let report = cache.join("teapot-64-svdag32.json");
    let text = std::fs::read_to_string(&report).unwrap();
    std::fs::write(
        &report,
        text.replacen("\"resolution\": 64", "\"resolution\": 128", 1),
    )
    .unwrap();
    let out = run(&[]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("teapot-64-svdag32.json"),
        "{stderr}"
    );
}

/// `build --colors`: every codec stores its colours, `stats --json` reports their size and error,
/// `verify` decodes them, `render` shows them; bad values are refused by the argument parser.
#[test]
fn build_colors_flags() {
    let dir = tempfile::tempdir().unwrap();
    let avocado = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/avocado/Avocado.gltf");
    let mut sizes = Vec::new();
    for codec in [
        None,
        Some("none"),
        Some("raw"),
        Some("lossless"),
        Some("lossless565"),
        Some("lossy=0.1"),
        Some("dolonius"),
        Some("dado"),
    ] {
        let vdag = dir
            .path()
            .join(format!("avocado-{}.vdag", codec.unwrap_or("default")));
        let mut args = vec!["build", s(&avocado), "-r", "64", "-o", s(&vdag), "-q"];
        if let Some(c) = codec {
            args.extend(["--colors", c]);
        }
        let out = voxdag(&args);
        assert!(
            out.status.success(),
            "{codec:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let out = voxdag_ok(&["stats", s(&vdag), "--json", "--quick"]);
        let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let voxels = json["voxels"].as_u64().unwrap();
        let (bytes, raw) = (
            json["color_bytes"].as_u64().unwrap(),
            json["raw_color_bytes"].as_u64().unwrap(),
        );
        let rmse = json["color_rmse"].as_f64().unwrap();
        let name = json["color_codec"].as_str().unwrap().to_string();
        match codec {
            Some("none") => assert_eq!((bytes, raw, name.as_str()), (0, 0, "none")),
            _ => {
                assert_eq!(raw, 3 * voxels, "{codec:?}");
                assert!(bytes > 0);
                // The default is the exact lossless codec.
                let exact = matches!(codec, None | Some("raw" | "lossless" | "dado"));
                assert_eq!(rmse == 0.0, exact, "{codec:?}: rmse {rmse}");
                assert!(rmse < 0.05, "{codec:?}: rmse {rmse}");
                assert_eq!(
                    name,
                    codec
                        .unwrap_or("lossless")
                        .replace("dolonius", "dolonius=0.06")
                );
            }
        }
        sizes.push((codec, bytes));
        voxdag_ok(&["verify", s(&vdag)]);
        let png = dir.path().join("img.png");
        voxdag_ok(&[
            "render",
            s(&vdag),
            "--cpu",
            "--size",
            "32x32",
            "--out",
            s(&png),
        ]);
    }
    // Lossy is smaller than lossless, which is smaller than raw RGBA8 words.
    let size = |c: &str| sizes.iter().find(|(k, _)| *k == Some(c)).unwrap().1;
    assert!(
        size("lossy=0.1") < size("lossless") && size("lossless") < size("raw"),
        "{sizes:?}"
    );

    let out_path = dir.path().join("bad.vdag");
    for bad in [
        "foo",
        "lossy=0",
        "lossy=abc",
        "lossy=1.5",
        "raw=0.1",
        "lossless=1",
    ] {
        let out = voxdag(&[
            "build",
            s(&avocado),
            "-r",
            "64",
            "-o",
            s(&out_path),
            "-q",
            "--colors",
            bad,
        ]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && !stderr.contains("panicked"),
            "{bad}: {stderr}"
        );
        assert!(stderr.contains("--colors"), "{bad}: {stderr}");
        assert!(!out_path.exists());
    }
    // --no-colors and --colors exclude each other.
    let out = voxdag(&[
        "build",
        s(&avocado),
        "-o",
        s(&out_path),
        "--no-colors",
        "--colors",
        "raw",
    ]);
    assert!(!out.status.success());
}

/// `voxdag build SCENE.vdag` re-encodes a built scene: the same voxels and colours (verify
/// checks them against the stored digest, export gives the same bytes), no voxelization, and
/// the options that only apply to a model are refused.
#[test]
fn build_from_a_vdag_re_encodes_the_same_voxels() {
    let dir = tempfile::tempdir().unwrap();
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/avocado/Avocado.gltf");
    let svdag = dir.path().join("a.vdag");
    voxdag_ok(&["-q", "build", s(&model), "-r", "64", "-o", s(&svdag)]);
    let export = |vdag: &Path, name: &str| {
        let path = dir.path().join(name);
        voxdag_ok(&[
            "export-voxels",
            s(vdag),
            "--format",
            "xyz-u32",
            "-o",
            s(&path),
        ]);
        std::fs::read(path).unwrap()
    };
    let original = export(&svdag, "a.xyz");
    for (name, extra) in [
        (
            "sat.vdag",
            &["--encoding", "tsvdag", "--transforms", "sat"][..],
        ),
        ("ssvdag.vdag", &["--encoding", "ssvdag"][..]),
    ] {
        let out_path = dir.path().join(name);
        let mut args = vec!["-q", "build", s(&svdag), "-o", s(&out_path)];
        args.extend_from_slice(extra);
        let out = voxdag_ok(&args);
        assert!(
            String::from_utf8_lossy(&out.stdout).contains("loaded and decoded"),
            "{}",
            String::from_utf8_lossy(&out.stdout)
        );
        let verify = voxdag_ok(&["verify", s(&out_path)]);
        assert!(
            String::from_utf8_lossy(&verify.stdout).contains("matching the content digest"),
            "{name}: {}",
            String::from_utf8_lossy(&verify.stdout)
        );
        assert_eq!(
            export(&out_path, &format!("{name}.xyz")),
            original,
            "{name}"
        );
    }
    let refused = dir.path().join("refused.vdag");
    assert_clean_error(
        &voxdag(&["-q", "build", s(&svdag), "-r", "128", "-o", s(&refused)]),
        &["--resolution 128", "64^3"],
    );
    assert_clean_error(
        &voxdag(&["-q", "build", s(&svdag), "--part", "1/2", "-o", s(&refused)]),
        &["--part", "already a built scene"],
    );
    assert!(!refused.exists());
}

/// A scene saved without the voxel digest (`Svdag::save`, which `voxdag edit -o` uses)
/// re-encodes to the compact encodings: they store the digest taken from its voxels, and
/// `verify` proves the new file against it.
#[test]
fn build_from_a_vdag_without_voxel_digest() {
    let dir = tempfile::tempdir().unwrap();
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/avocado/Avocado.gltf");
    let built = dir.path().join("built.vdag");
    voxdag_ok(&[
        "-q",
        "build",
        s(&model),
        "-r",
        "32",
        "--no-colors",
        "-o",
        s(&built),
    ]);
    let plain = dir.path().join("plain.vdag");
    voxdag::dag::Svdag::load(&built)
        .unwrap()
        .save(&plain)
        .unwrap();
    assert!(
        voxdag::dag::VdagFile::load(&plain)
            .unwrap()
            .digest
            .is_none(),
        "the test needs a file without the voxel digest"
    );
    let original = voxdag::dag::VdagFile::load(&built).unwrap().digest;
    for encoding in ["ssvdag", "tsvdag"] {
        let out_path = dir.path().join(format!("{encoding}.vdag"));
        voxdag_ok(&[
            "-q",
            "build",
            s(&plain),
            "--encoding",
            encoding,
            "-o",
            s(&out_path),
        ]);
        let stored = voxdag::dag::VdagFile::load(&out_path).unwrap().digest;
        assert_eq!(stored, original, "{encoding}: the digest of the voxels");
        voxdag_ok(&["verify", s(&out_path)]);
    }
}

#[test]
fn bench_pathtrace_keeps_colours_in_the_svdag32_cache_only() {
    let dir = tempfile::tempdir().unwrap();
    let vox = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/ff3.vox");
    let (json, md, cache) = (
        dir.path().join("p.json"),
        dir.path().join("p.md"),
        dir.path().join("cache"),
    );
    voxdag_ok(&[
        "bench",
        "pathtrace",
        "--scenes",
        vox,
        "--resolutions",
        "64",
        "--size",
        "32x18",
        "--spp",
        "1",
        "--rounds",
        "2",
        "--formats",
        "svdag32,tsvdag-sa-huffman",
        "--cache",
        s(&cache),
        "--json",
        s(&json),
        "--markdown",
        s(&md),
    ]);
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let rows = report["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    let floats = |v: &serde_json::Value| -> Vec<f64> {
        let values = v.as_array().unwrap().iter();
        values.map(|x| x.as_f64().unwrap()).collect()
    };
    for row in rows {
        assert_eq!(row["gpu_colors"], "raw");
        assert_eq!(row["first_hit_mismatches"], 0);
        // Two rounds of one sample per tracer: each round's ratio, the median among them; the
        // CPU reference timed in each round too.
        assert_eq!(row["rounds"], 2);
        let cpu = floats(&row["cpu_rounds_ms"]);
        assert_eq!(cpu.len(), 2);
        assert!(cpu.contains(&row["cpu_ms_per_sample"].as_f64().unwrap()));
        for tracer in ["mega", "wave"] {
            let samples = row[format!("{tracer}_samples_ms")].as_array().unwrap();
            assert_eq!(samples.len(), 2);
            let ratios = floats(&row[format!("{tracer}_vs_svdag32_rounds")]);
            assert_eq!(ratios.len(), 2);
            let ratio = row[format!("{tracer}_vs_svdag32")].as_f64().unwrap();
            assert!(ratios.contains(&ratio), "{ratio} is one of {ratios:?}");
            if row["format"] == "svdag32" {
                assert_eq!(ratios, [1.0, 1.0]);
            }
        }
    }
    assert_clean_error(
        &voxdag(&[
            "bench",
            "pathtrace",
            "--scenes",
            vox,
            "--rounds",
            "0",
            "--json",
            s(&json),
            "--markdown",
            s(&md),
        ]),
        &["--rounds"],
    );
    let colors = |format: &str| {
        let file = voxdag::dag::VdagFile::load(&cache.join(format!("ff3-64-{format}.vdag")));
        file.unwrap().colors.len()
    };
    assert!(colors("svdag32") > 0);
    assert_eq!(colors("tsvdag-sa-huffman"), 0);
}

/// The largest mesh resolution, 2^17 (issue 12: "131072 where the scene's DAG fits"): a zero-area
/// sliver along the main diagonal touches 7 N - 6 voxels (every coordinate m or m + 1); the
/// streaming build, the file, `stats`, `verify` and the GPU render take its 17 levels.
#[test]
fn build_verify_and_render_at_131072() {
    let dir = tempfile::tempdir().unwrap();
    let obj = write(
        dir.path(),
        "diagonal.obj",
        b"v 0 0 0\nv 1 1 1\nv 0.5 0.5 0.5\nf 1 2 3\n",
    );
    let vdag = dir.path().join("diagonal.vdag");
    voxdag_ok(&["build", s(&obj), "-r", "131072", "-o", s(&vdag), "-q"]);
    let out = voxdag_ok(&["stats", s(&vdag), "--json", "--quick"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["resolution"], 131072);
    assert_eq!(json["voxels"], 7 * 131072 - 6);
    let out = voxdag_ok(&["verify", s(&vdag)]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("matching the content digest"));
    let png = dir.path().join("diagonal.png");
    voxdag_ok(&["render", s(&vdag), "--size", "64x48", "--out", s(&png)]);
    assert!(png.exists());
    let refused = voxdag(&["build", s(&obj), "-r", "262144", "-o", s(&vdag), "-q"]);
    assert_clean_error(&refused, &["262144", "above the maximum 131072"]);
}
