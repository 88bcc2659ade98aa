//! Hostile input and faults (docs/security.md): crafted models and `.vdag` files, generated
//! here, for every class of the threat model. Each CLI case must end within seconds with one
//! `error:` line (exit 1), a "not proven" line (exit 2) or a correct result; never a signal or
//! panic text, never a file left behind or replaced, never a file opened outside the asset root.

use std::io::Read;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use proptest::prelude::*;
use voxdag::dag::encode::{EncodedDag, TsvdagEncoding, TsvdagOptions, VoxelDigest};
use voxdag::dag::{Svdag, TransformSet, VdagFile};
use voxdag::scene::{self, ImportOptions, Voxels};

/// Runs the CLI with a deadline; `limit_as`: an RLIMIT_AS for the child.
fn run_with(args: &[&str], limit_as: Option<u64>, seconds: u64) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_voxdag"));
    cmd.args(args)
        .env("RUST_LOG", "warn")
        .env(
            "VK_ICD_FILENAMES",
            "/usr/share/vulkan/icd.d/lvp_icd.x86_64.json",
        )
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    if let Some(bytes) = limit_as {
        // SAFETY: setrlimit is async-signal-safe; nothing else runs between fork and exec.
        unsafe {
            cmd.pre_exec(move || {
                let l = libc::rlimit {
                    rlim_cur: bytes,
                    rlim_max: bytes,
                };
                if libc::setrlimit(libc::RLIMIT_AS, &l) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
    }
    let mut child = cmd.spawn().expect("run voxdag");
    let (mut out, mut err) = (child.stdout.take().unwrap(), child.stderr.take().unwrap());
    let t_out = std::thread::spawn(move || {
        let mut b = Vec::new();
        out.read_to_end(&mut b).unwrap();
        b
    });
    let t_err = std::thread::spawn(move || {
        let mut b = Vec::new();
        err.read_to_end(&mut b).unwrap();
        b
    });
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if start.elapsed() > Duration::from_secs(seconds) {
            child.kill().unwrap();
            panic!("voxdag {args:?} ran longer than {seconds} s");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Output {
        status,
        stdout: t_out.join().unwrap(),
        stderr: t_err.join().unwrap(),
    }
}

fn run(args: &[&str]) -> Output {
    run_with(args, None, 60)
}

/// Asserts exit `code` (1: one `error:` line containing every needle; 2: the not-proven line),
/// no signal, no panic text.
fn expect(out: &Output, code: i32, needles: &[&str]) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert_eq!(out.status.code(), Some(code), "stderr: {stderr}");
    assert!(
        !stderr.contains("panicked") && !stderr.contains("thread '"),
        "panic text: {stderr}"
    );
    if code == 1 {
        let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
        assert_eq!(errors.len(), 1, "want one error line: {stderr}");
    }
    for n in needles {
        assert!(stderr.contains(n), "stderr lacks {n:?}: {stderr}");
    }
    stderr
}

/// The names in a folder, sorted.
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    v.sort();
    v
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A tetrahedron's buffer: 4 f32 positions then 12 u16 indices (72 bytes).
fn tetra_buffer() -> Vec<u8> {
    let mut b = Vec::new();
    for v in [0f32, 0., 0., 1., 0., 0., 0., 1., 0., 0., 0., 1.] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for i in [0u16, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    b
}

/// glTF JSON of the tetrahedron with its buffer at `uri`; `patch` edits the JSON value.
fn tetra_gltf(uri: &str, patch: impl FnOnce(&mut serde_json::Value)) -> String {
    let mut v = serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"uri": uri, "byteLength": 72}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 24}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [0, 0, 0], "max": [1, 1, 1]},
            {"bufferView": 1, "componentType": 5123, "count": 12, "type": "SCALAR"}
        ]
    });
    patch(&mut v);
    v.to_string()
}

/// A data: URI of the tetrahedron buffer.
fn data_uri() -> String {
    const ALPHABET: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let b = tetra_buffer();
    let mut out = String::from("data:application/octet-stream;base64,");
    for c in b.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for i in 0..4 {
            if i <= c.len() {
                out.push(ALPHABET[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

fn mkfifo(path: &Path) {
    let c = std::ffi::CString::new(s(path)).unwrap();
    // SAFETY: a valid C string.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
}

/// Class 1: References outside the model's folder are never opened (the outside file is a FIFO: an
/// open would block until the deadline); `--asset-root` widens the root; subfolders,
/// percent-encoded names, data URIs and symlinked folders inside keep working.
#[test]
fn asset_references_stay_inside_the_root() {
    let dir = tempfile::tempdir().unwrap();
    let model_dir = dir.path().join("model");
    std::fs::create_dir_all(model_dir.join("sub dir")).unwrap();
    let outside = dir.path().join("secret.bin");
    mkfifo(&outside);
    let out = dir.path().join("out.vdag");
    let absolute = s(&outside).to_string();
    for uri in [
        "../secret.bin".to_string(),
        "%2E%2E/secret.bin".to_string(),
        "sub%20dir/../../secret.bin".to_string(),
        absolute.clone(),
        format!("file://{absolute}"),
        format!("file:{absolute}"),
    ] {
        let gltf = model_dir.join("m.gltf");
        std::fs::write(&gltf, tetra_gltf(&uri, |_| {})).unwrap();
        let o = run_with(
            &["-q", "build", s(&gltf), "-r", "16", "-o", s(&out)],
            None,
            20,
        );
        expect(&o, 1, &["buffer 0", "not opened"]);
        assert!(!out.exists());
    }
    // A FIFO inside the folder is not a regular file: refused, not opened.
    mkfifo(&model_dir.join("fifo.bin"));
    let gltf = model_dir.join("m.gltf");
    std::fs::write(&gltf, tetra_gltf("fifo.bin", |_| {})).unwrap();
    let o = run_with(
        &["-q", "build", s(&gltf), "-r", "16", "-o", s(&out)],
        None,
        20,
    );
    expect(&o, 1, &["not a regular file"]);

    // Legitimate: a subfolder with percent-encoded names, a data URI, a symlinked folder.
    std::fs::write(model_dir.join("sub dir/base colour.bin"), tetra_buffer()).unwrap();
    let shared = dir.path().join("shared");
    std::fs::create_dir(&shared).unwrap();
    std::fs::write(shared.join("t.bin"), tetra_buffer()).unwrap();
    std::os::unix::fs::symlink(&shared, model_dir.join("linked")).unwrap();
    for uri in [
        "sub%20dir/base%20colour.bin".to_string(),
        "./sub dir/../sub%20dir/base%20colour.bin".to_string(),
        data_uri(),
        "linked/t.bin".to_string(),
    ] {
        std::fs::write(&gltf, tetra_gltf(&uri, |_| {})).unwrap();
        let o = run(&["-q", "build", s(&gltf), "-r", "16", "-o", s(&out)]);
        assert!(
            o.status.success(),
            "{uri}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    // --asset-root widens the root to the parent folder.
    std::fs::write(dir.path().join("buffer.bin"), tetra_buffer()).unwrap();
    std::fs::write(&gltf, tetra_gltf("../buffer.bin", |_| {})).unwrap();
    let o = run(&["-q", "build", s(&gltf), "-r", "16", "-o", s(&out)]);
    expect(&o, 1, &["outside the asset root"]);
    let o = run(&[
        "-q",
        "build",
        s(&gltf),
        "-r",
        "16",
        "-o",
        s(&out),
        "--asset-root",
        s(dir.path()),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// Class 1: OBJ `mtllib` and `map_Kd` outside the folder: one warning each, base colour, a result.
#[test]
fn obj_references_outside_are_warnings() {
    let dir = tempfile::tempdir().unwrap();
    let model_dir = dir.path().join("model");
    std::fs::create_dir(&model_dir).unwrap();
    mkfifo(&dir.path().join("evil.mtl"));
    mkfifo(&dir.path().join("evil.png"));
    let obj = model_dir.join("t.obj");
    let tetra = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
    let out = dir.path().join("t.vdag");
    std::fs::write(&obj, format!("mtllib ../evil.mtl\nusemtl a\n{tetra}")).unwrap();
    let o = run_with(&["build", s(&obj), "-r", "16", "-o", s(&out)], None, 20);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr).contains("not opened"));
    let evil = s(&dir.path().join("evil.png")).to_string();
    std::fs::write(
        model_dir.join("m.mtl"),
        format!("newmtl a\nKd 1 0 0\nmap_Kd {evil}\n"),
    )
    .unwrap();
    std::fs::write(&obj, format!("mtllib m.mtl\nusemtl a\n{tetra}")).unwrap();
    let o = run_with(&["build", s(&obj), "-r", "16", "-o", s(&out)], None, 20);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("absolute path"), "{stderr}");
}

/// Class 2: Requests sized by the input fail before allocating: a 2^32-1 vertex accessor, a `.vdag`
/// header announcing 2^60 bytes, `/dev/zero`, and a build under an address-space limit.
#[test]
fn unbounded_requests_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let gltf = dir.path().join("huge.gltf");
    std::fs::write(
        &gltf,
        tetra_gltf(&data_uri(), |v| {
            // Sparse, no buffer view: zeros plus one stored value.
            v["accessors"][0] = serde_json::json!({"componentType": 5126,
                "count": 4294967295u64, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 1],
                "sparse": {"count": 1, "indices": {"bufferView": 1, "componentType": 5123},
                           "values": {"bufferView": 0}}});
            v["meshes"][0]["primitives"][0]
                .as_object_mut()
                .unwrap()
                .remove("indices");
        }),
    )
    .unwrap();
    let out = dir.path().join("o.vdag");
    let o = run(&["--memory-limit", "1536M", "build", s(&gltf), "-o", s(&out)]);
    expect(
        &o,
        1,
        &["glTF accessor 0 needs 48.0 GiB, the memory limit is 1.5 GiB (--memory-limit)"],
    );
    // Without the flag the default limit (at most physical RAM) still refuses it.
    expect(
        &run(&["build", s(&gltf), "-o", s(&out)]),
        1,
        &["memory limit"],
    );

    let mut header = voxdag::dag::MAGIC.to_vec();
    header.extend_from_slice(&1u32.to_le_bytes());
    header.resize(32, 0);
    header.extend_from_slice(&(1u64 << 60).to_le_bytes());
    header.resize(64, 0);
    let big = dir.path().join("big.vdag");
    std::fs::write(&big, &header).unwrap();
    expect(&run(&["verify", s(&big)]), 1, &["memory limit"]);
    expect(&run(&["verify", "/dev/zero"]), 1, &["bad magic"]);
    // Models that are devices: refused, not read without end.
    for name in ["z.vox", "z.obj", "z.gltf"] {
        let link = dir.path().join(name);
        std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
        let o = run(&["build", s(&link), "-r", "16", "-o", s(&out)]);
        expect(&o, 1, &["not a regular file"]);
    }
    // A FIFO that never ends: the header is all that is read.
    let fifo = dir.path().join("in.vdag");
    mkfifo(&fifo);
    let writer = {
        let fifo = fifo.clone();
        std::thread::spawn(move || {
            let mut f = std::fs::OpenOptions::new().write(true).open(fifo).unwrap();
            let zeros = vec![0u8; 1 << 16];
            while std::io::Write::write_all(&mut f, &zeros).is_ok() {}
        })
    };
    expect(&run(&["verify", s(&fifo)]), 1, &["bad magic"]);
    writer.join().unwrap();

    // Under a small address space: one out-of-memory line, exit 1, no temporary file left.
    let work = dir.path().join("work");
    std::fs::create_dir(&work).unwrap();
    let obj = dir.path().join("t.obj");
    std::fs::write(
        &obj,
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
    )
    .unwrap();
    let out = work.join("t.vdag");
    // The in-memory build holds every voxel (59 M at 4096: 470 MiB).
    let o = run_with(
        &[
            "-q",
            "build",
            s(&obj),
            "-r",
            "4096",
            "--in-memory",
            "-o",
            s(&out),
        ],
        Some(384 << 20),
        60,
    );
    expect(&o, 1, &["memory"]);
    assert!(names(&work).is_empty(), "{:?}", names(&work));
    // The streaming build (the default) holds the DAG and a working set: it fits.
    let o = run_with(
        &["-q", "build", s(&obj), "-r", "1024", "-o", s(&out)],
        Some(384 << 20),
        60,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(names(&work), ["t.vdag"]);
}

/// A solid grid of side `n` as an SVDAG (one node per level: 2^63 voxels for n = 2^21).
fn solid(n: u32) -> Svdag {
    let root_level = n.trailing_zeros() - 2;
    let mut words = Vec::new();
    let mut level_starts = vec![0u64; root_level as usize + 1];
    for level in (1..=root_level).rev() {
        level_starts[level as usize] = words.len() as u64;
        let child = words.len() as u32 + 9;
        words.push(0xff);
        words.extend(std::iter::repeat_n(child, 8));
    }
    level_starts[0] = words.len() as u64;
    words.extend([u32::MAX, u32::MAX]);
    let dag = Svdag {
        resolution: n,
        words,
        level_starts,
        colors: Vec::new(),
    };
    dag.validate().unwrap();
    dag
}

/// Class 3: A 1 KB file of 2^63 voxels (svdag32 and tsvdag): verify in seconds, export refused
/// before writing; it and a solid 65536^3 grid (2^48 voxels) render on the CPU and the GPU.
#[test]
fn huge_valid_scene() {
    let dir = tempfile::tempdir().unwrap();
    let dag = solid(1 << 21);
    assert_eq!(dag.voxel_count(), 1 << 63);
    let file = dir.path().join("solid.vdag");
    dag.save(&file).unwrap();
    assert!(std::fs::metadata(&file).unwrap().len() < 2048);
    let o = run_with(&["verify", s(&file)], None, 20);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("9223372036854775808 voxels"));
    let o = run_with(&["stats", s(&file), "--quick"], None, 20);
    assert!(o.status.success());
    // The same voxels as a tsvdag (S+A transforms): its digest is O(stored nodes) too, when
    // written (in this process) and when verified.
    let tsv = dir.path().join("solid-tsvdag.vdag");
    let encoded = TsvdagEncoding::build(&dag, TransformSet::All, TsvdagOptions::default()).unwrap();
    VdagFile {
        encoded: EncodedDag::Tsvdag(encoded),
        colors: Vec::new(),
        // The v1 voxel digest a tsvdag file must carry: its CRC of 2^63 codes is never computed
        // (verify checks the count and the content digest).
        digest: Some(VoxelDigest {
            voxels: 1 << 63,
            crc32: 0,
        }),
        stored_colors: None,
        materials: None,
    }
    .save(&tsv)
    .unwrap();
    assert!(std::fs::metadata(&tsv).unwrap().len() < 2048);
    let o = run_with(&["verify", s(&tsv)], None, 20);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("9223372036854775808 voxels"));
    std::fs::remove_file(&tsv).unwrap();
    let before = names(dir.path());
    let xyz = dir.path().join("all.xyz");
    let o = run_with(
        &[
            "export-voxels",
            s(&file),
            "--format",
            "xyz-u32",
            "-o",
            s(&xyz),
        ],
        None,
        20,
    );
    expect(&o, 1, &["free on its filesystem"]);
    let o = run_with(
        &[
            "export-voxels",
            s(&file),
            "--format",
            "xyz-u32",
            "-o",
            "-",
            "--max-output",
            "1G",
        ],
        None,
        20,
    );
    expect(&o, 1, &["more than --max-output 1.0 GiB"]);
    assert!(o.stdout.is_empty());
    assert_eq!(names(dir.path()), before, "nothing written");
    // Every valid file renders on both renderers: a solid 65536^3 grid (2^48 voxels, more than
    // any u32 count; without colours none is needed) and the solid 2^21 one (2^63 voxels, the
    // largest resolution of the format, the full 21-frame GPU stack), both the same image.
    let file64k = dir.path().join("solid64k.vdag");
    solid(1 << 16).save(&file64k).unwrap();
    for scene in [&file64k, &file] {
        let mut images = Vec::new();
        for extra in [&["--cpu"][..], &[][..]] {
            let png = dir.path().join("solid.png");
            let mut args = vec!["render", s(scene), "--size", "16x16", "--out", s(&png)];
            args.extend(extra);
            let o = run_with(&args, None, 60);
            assert!(
                o.status.success(),
                "{scene:?} {extra:?}: {}",
                String::from_utf8_lossy(&o.stderr)
            );
            images.push(std::fs::read(&png).unwrap());
            std::fs::remove_file(&png).unwrap();
        }
        assert_eq!(images[0], images[1], "{scene:?}: GPU == CPU");
    }
    std::fs::remove_file(&file64k).unwrap();
    // The same scene without the content digest: checked, but not proven.
    let old = dir.path().join("old.vdag");
    std::fs::write(&old, dag.to_bytes()).unwrap();
    let o = run_with(&["verify", s(&old)], None, 20);
    expect(&o, 2, &["no digest: the voxels are not proven"]);
}

/// A coloured 16^3 scene.
fn colored() -> Svdag {
    let mut coords = Vec::new();
    for x in 0..16u32 {
        for y in 0..16u32 {
            if (x * 7 + y * 3) % 5 < 2 {
                coords.push([x, y, (x + y) % 16]);
            }
        }
    }
    let mut v = Voxels::from_coords(16, coords);
    v.colors = (0..v.codes.len() as u32)
        .map(|i| 0xff00_0000 | i.wrapping_mul(2654435761) & 0xffffff)
        .collect();
    Svdag::from_voxels(&v).unwrap()
}

/// `verify --against` compares colours and materials too (raw and chunked, a chunk at a time):
/// equal files pass, the first differing colour or material id is named with its voxel, and a
/// file without the other's attributes is refused.
#[test]
fn verify_against_compares_colours_and_materials() {
    let dir = tempfile::tempdir().unwrap();
    let path = |name: &str| dir.path().join(name);
    let save = |name: &str,
                dag: &Svdag,
                stored: Option<voxdag::attr::StoredColors>,
                materials: Option<voxdag::attr::Materials>| {
        VdagFile {
            colors: if stored.is_some() || materials.is_some() {
                Vec::new()
            } else {
                dag.colors.clone()
            },
            digest: None,
            encoded: EncodedDag::Svdag32(dag.clone()),
            stored_colors: stored,
            materials,
        }
        .save(&path(name))
        .unwrap();
    };
    let dag = colored();
    let n = dag.colors.len();
    let k = n / 2 + 3;
    let mut changed = dag.clone();
    changed.colors[k] ^= 0x00ff_0000;
    let hidden = indicatif::ProgressBar::hidden();
    let chunks = |d: &Svdag| {
        voxdag::attr::StoredColors::encode(d, voxdag::attr::ColorCodec::Raw, Some(1), &hidden)
            .unwrap()
    };
    save("raw.vdag", &dag, None, None);
    save("chunked.vdag", &dag, Some(chunks(&dag)), None);
    save("changed.vdag", &changed, None, None);
    let mut bare = dag.clone();
    bare.colors.clear();
    save("bare.vdag", &bare, None, None);
    let p = |name: &str| path(name).to_str().unwrap().to_string();
    for (a, b) in [("raw.vdag", "chunked.vdag"), ("chunked.vdag", "raw.vdag")] {
        let o = run(&["verify", &p(a), "--against", &p(b)]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let stdout = String::from_utf8_lossy(&o.stdout);
        let same = format!("; the same voxels and colours as {}", p(b));
        assert!(stdout.contains(&same), "{stdout}");
    }
    let ours = format!("{:08x}", dag.colors[k]);
    let theirs = format!("{:08x}", changed.colors[k]);
    for a in ["raw.vdag", "chunked.vdag"] {
        let o = run(&["verify", &p(a), "--against", &p("changed.vdag")]);
        let at = format!("first differing colour: voxel {k} (");
        expect(&o, 1, &[&at, &ours, &theirs]);
    }
    expect(
        &run(&["verify", &p("bare.vdag"), "--against", &p("raw.vdag")]),
        1,
        &["same voxels", "has no colours", "has colours"],
    );
    // Materials: a changed id is named; a changed palette is reported as such.
    let ids: Vec<u8> = (0..n).map(|i| (i % 3) as u8).collect();
    let palette = vec![0xff00_00ff, 0xff00_ff00, 0xffff_0000];
    let materials =
        |ids: Vec<u8>, palette: Vec<u32>| Some(voxdag::attr::Materials { palette, ids });
    save(
        "m.vdag",
        &bare,
        None,
        materials(ids.clone(), palette.clone()),
    );
    let mut other_ids = ids.clone();
    other_ids[k] = (other_ids[k] + 1) % 3;
    save(
        "m-ids.vdag",
        &bare,
        None,
        materials(other_ids, palette.clone()),
    );
    let mut other_palette = palette.clone();
    other_palette[1] = 0xff80_8080;
    save("m-palette.vdag", &bare, None, materials(ids, other_palette));
    let o = run(&["verify", &p("m.vdag"), "--against", &p("m.vdag")]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let at = format!("first differing material: voxel {k} (");
    expect(
        &run(&["verify", &p("m.vdag"), "--against", &p("m-ids.vdag")]),
        1,
        &[&at],
    );
    expect(
        &run(&["verify", &p("m.vdag"), "--against", &p("m-palette.vdag")]),
        1,
        &["different palettes"],
    );
    expect(
        &run(&["verify", &p("m.vdag"), "--against", &p("raw.vdag")]),
        1,
        &["has materials", "has colours"],
    );
}

fn fix_crc(b: &mut [u8]) {
    let n = b.len();
    let crc = crc32fast::hash(&b[..n - 4]);
    b[n - 4..].copy_from_slice(&crc.to_le_bytes());
}

/// Class 4: `verify` proves colours too: a colour changed under a repaired checksum fails; a file
/// without the digest section exits 2.
#[test]
fn verify_is_honest() {
    let dir = tempfile::tempdir().unwrap();
    let dag = colored();
    let good = dir.path().join("good.vdag");
    dag.save(&good).unwrap();
    let o = run(&["verify", s(&good)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The colour section is section 3; change its first colour and repair the checksum.
    let mut b = std::fs::read(&good).unwrap();
    let colors_at = u64::from_le_bytes(b[64 + 2 * 24 + 8..64 + 2 * 24 + 16].try_into().unwrap());
    b[colors_at as usize] ^= 0x5a;
    fix_crc(&mut b);
    let bad = dir.path().join("bad.vdag");
    std::fs::write(&bad, &b).unwrap();
    expect(&run(&["verify", s(&bad)]), 1, &["colours", "differ"]);
    // The same with chunked colours (section 6), which verify hashes chunk by chunk without
    // decoding them all at once: raw chunks, so a changed word still decodes.
    let codec = voxdag::attr::ColorCodec::Raw;
    let hidden = indicatif::ProgressBar::hidden();
    let stored = voxdag::attr::StoredColors::encode(&dag, codec, Some(1), &hidden).unwrap();
    let chunks = stored.chunks.chunk_count();
    let chunked = dir.path().join("chunked.vdag");
    VdagFile {
        colors: dag.colors.clone(),
        digest: None,
        encoded: EncodedDag::Svdag32(dag.clone()),
        stored_colors: Some(stored),
        materials: None,
    }
    .save(&chunked)
    .unwrap();
    let o = run(&["verify", s(&chunked)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    let count = format!("{} colours in {chunks} raw chunks", dag.colors.len());
    assert!(stdout.contains(&count), "{stdout}");
    let mut b = std::fs::read(&chunked).unwrap();
    let (_, at, _) = section(&b, 6);
    let last_word = at + 40 + 16 * (chunks + 1) + 4 * (dag.colors.len() - 1);
    b[last_word] ^= 0x5a;
    fix_crc(&mut b);
    std::fs::write(&bad, &b).unwrap();
    expect(&run(&["verify", s(&bad)]), 1, &["colours", "differ"]);
    // No digest section (the bare to_bytes form).
    let bare = dir.path().join("bare.vdag");
    std::fs::write(&bare, dag.to_bytes()).unwrap();
    expect(
        &run(&["verify", s(&bare)]),
        2,
        &["no digest: the voxels are not proven"],
    );
}

/// Offset and length of section `id` in a `.vdag` file's table.
fn section(b: &[u8], id: u32) -> (usize, usize, usize) {
    let count = u32::from_le_bytes(b[28..32].try_into().unwrap()) as usize;
    let u64_at = |at: usize| u64::from_le_bytes(b[at..at + 8].try_into().unwrap()) as usize;
    (0..count)
        .map(|i| 64 + 24 * i)
        .find(|&e| u32::from_le_bytes(b[e..e + 4].try_into().unwrap()) == id)
        .map(|e| (e, u64_at(e + 8), u64_at(e + 16)))
        .expect("section listed")
}

/// Class 2 and 4: a corrupt or truncated material section (palette size, ids, counts, padding,
/// colours alongside) is one error line naming the problem; a changed id under a repaired
/// checksum fails `verify`'s content digest.
#[test]
fn material_sections_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let dag = colored();
    let m = voxdag::attr::Materials::quantize(&dag.colors, 4).unwrap();
    let voxels = m.ids.len();
    let mut geometry = dag.clone();
    geometry.colors.clear();
    let good = dir.path().join("good.vdag");
    VdagFile {
        encoded: EncodedDag::Svdag32(geometry),
        colors: Vec::new(),
        digest: None,
        stored_colors: None,
        materials: Some(m.clone()),
    }
    .save(&good)
    .unwrap();
    let o = run(&["verify", s(&good)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let bytes = std::fs::read(&good).unwrap();
    let (entry, at, len) = section(&bytes, 8);
    type Patch = Box<dyn Fn(&mut Vec<u8>)>;
    fn put32(b: &mut [u8], at: usize, v: u32) {
        b[at..at + 4].copy_from_slice(&v.to_le_bytes());
    }
    let mut cases: Vec<(&str, Patch, Vec<String>)> = vec![
        (
            "palette0",
            Box::new(move |b| put32(b, at, 0)),
            vec!["palette of 0 entries".into()],
        ),
        (
            "palette17",
            Box::new(move |b| put32(b, at, 17)),
            vec!["palette of 17 entries".into()],
        ),
        (
            "reserved",
            Box::new(move |b| put32(b, at + 4, 1)),
            vec!["reserved material field".into()],
        ),
        (
            "unused entry",
            Box::new(move |b| put32(b, at + 16 + 4 * 15, 7)),
            vec!["palette entry 15".into()],
        ),
        (
            "id past the palette",
            Box::new(move |b| b[at + 80] = 0xff),
            vec!["material 15 of a".into(), "-entry palette".into()],
        ),
        (
            "count beyond the section",
            Box::new(move |b| b[at + 8..at + 16].copy_from_slice(&u64::MAX.to_le_bytes())),
            vec!["material ids do not fill".into()],
        ),
        (
            // Two ids fewer, the section one byte shorter: consistent, but not the voxel count.
            "count below the voxels",
            Box::new(move |b| {
                b[at + 8..at + 16].copy_from_slice(&(voxels as u64 - 2).to_le_bytes());
                b[entry + 16..entry + 24].copy_from_slice(&(len as u64 - 1).to_le_bytes());
                if voxels % 2 == 1 {
                    b[at + 80 + (voxels - 2) / 2] &= 0x0f; // now the padding nibble
                }
            }),
            vec![format!("{} material ids for {voxels} voxels", voxels - 2)],
        ),
        (
            "with colours",
            Box::new(|b| put32(b, 24, 1)),
            vec!["material section 8 in a file with colours".into()],
        ),
        (
            // A different id, checksum repaired: the content digest tells.
            "changed id",
            Box::new(move |b| b[at + 80] ^= 0x01),
            vec!["colours".into(), "differ".into()],
        ),
    ];
    if voxels % 2 == 1 {
        cases.push((
            "padding nibble",
            Box::new(move |b| b[at + len - 1] |= 0x10),
            vec!["unused high nibble".into()],
        ));
    }
    for (name, patch, needles) in &cases {
        let mut b = bytes.clone();
        patch(&mut b);
        fix_crc(&mut b);
        let path = dir.path().join(format!("{name}.vdag"));
        std::fs::write(&path, &b).unwrap();
        let needles: Vec<&str> = needles.iter().map(String::as_str).collect();
        let stderr = expect(&run(&["verify", s(&path)]), 1, &needles);
        assert!(!stderr.is_empty(), "{name}");
        // Loading for a render fails the same way (before any GPU work).
        if *name != "changed id" {
            expect(
                &run(&[
                    "render",
                    "--cpu",
                    s(&path),
                    "--out",
                    s(&dir.path().join("x.png")),
                ]),
                1,
                &needles,
            );
        }
    }
    // Truncated inside the section.
    let cut = dir.path().join("cut.vdag");
    std::fs::write(&cut, &bytes[..at + 40]).unwrap();
    expect(&run(&["verify", s(&cut)]), 1, &["truncated"]);
}

/// Class 5: Output files: SIGTERM mid-export leaves nothing; FIFOs are written in place; `-o -`;
/// a symlink at the output is replaced, not followed; bad `--report` fails before the build.
#[test]
fn output_files_are_clean() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("solid512.vdag");
    solid(512).save(&scene).unwrap();
    let work = dir.path().join("work");
    std::fs::create_dir(&work).unwrap();
    let out = work.join("all.xyz");
    let mut child = Command::new(env!("CARGO_BIN_EXE_voxdag"))
        .args([
            "export-voxels",
            s(&scene),
            "--format",
            "xyz-u32",
            "-o",
            s(&out),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while names(&work).is_empty() {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "no temporary file"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    // SAFETY: signalling our own child.
    unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    let status = child.wait().unwrap();
    use std::os::unix::process::ExitStatusExt;
    assert!(
        status.signal() == Some(libc::SIGTERM) || status.success(),
        "{status:?}"
    );
    if status.signal().is_some() {
        assert!(names(&work).is_empty(), "left behind: {:?}", names(&work));
    }

    // A small scene for the rest.
    let small = dir.path().join("small.vdag");
    colored().save(&small).unwrap();
    let voxels = colored().voxel_count() as usize;
    let o = run(&["export-voxels", s(&small), "--format", "xyz-u32", "-o", "-"]);
    assert!(o.status.success());
    assert_eq!(o.stdout.len(), 12 * voxels);

    let fifo = work.join("pipe");
    mkfifo(&fifo);
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read(fifo).unwrap().len())
    };
    let o = run(&[
        "export-voxels",
        s(&small),
        "--format",
        "xyz-u32",
        "-o",
        s(&fifo),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(reader.join().unwrap(), 12 * voxels);
    use std::os::unix::fs::FileTypeExt;
    assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());

    let victim = dir.path().join("victim");
    std::fs::write(&victim, b"precious").unwrap();
    let link = work.join("link.xyz");
    std::os::unix::fs::symlink(&victim, &link).unwrap();
    let o = run(&[
        "export-voxels",
        s(&small),
        "--format",
        "xyz-u32",
        "-o",
        s(&link),
    ]);
    assert!(o.status.success());
    assert_eq!(std::fs::read(&victim).unwrap(), b"precious");

    let obj = dir.path().join("t.obj");
    std::fs::write(
        &obj,
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
    )
    .unwrap();
    let vdag = work.join("t.vdag");
    let o = run(&[
        "-q",
        "build",
        s(&obj),
        "-r",
        "16",
        "-o",
        s(&vdag),
        "--report",
        s(&work),
    ]);
    expect(&o, 1, &["is a directory"]);
    assert!(
        !vdag.exists(),
        "nothing built before the report path is checked"
    );
    let o = run(&[
        "render",
        s(&small),
        "--cpu",
        "--out",
        s(&work.join("x.png")),
        "--trace",
        s(&dir.path().join("missing/t.json")),
    ]);
    expect(&o, 1, &["does not exist"]);
    // Benchmarks check every output (JSON, Markdown, chart, row) before the work starts.
    let json = work.join("b.json");
    let md = work.join("b.md");
    let o = run(&[
        "bench",
        "compress",
        "--json",
        s(&json),
        "--markdown",
        s(&md),
        "--chart",
        s(&work),
    ]);
    expect(&o, 1, &["is a directory"]);
    let o = run(&[
        "bench",
        "primitives",
        "--log2",
        "1",
        "--json",
        s(&json),
        "--markdown",
        s(&scene.join("b.md")),
    ]);
    expect(&o, 1, &["creating"]);
    assert!(
        !json.exists() && !md.exists(),
        "no benchmark ran before its outputs were checked"
    );
}

/// An edit of the glTF JSON.
type Patch = Box<dyn FnOnce(&mut serde_json::Value)>;

/// Class 6: Messages: malformed glTF is one error line without panic text; OS errors print once.
#[test]
fn malformed_models_give_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o.vdag");
    let o = run(&["-q", "build", "/no/such/model.obj", "-o", s(&out)]);
    let stderr = expect(&o, 1, &["os error 2"]);
    assert_eq!(stderr.matches("os error 2").count(), 1, "{stderr}");
    let cases: Vec<(&str, Patch)> = vec![
        (
            "",
            Box::new(|v| v["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = 99.into()),
        ),
        (
            "runs to byte",
            Box::new(|v| v["accessors"][1]["count"] = 15.into()),
        ),
        (
            "past buffer",
            Box::new(|v| v["bufferViews"][1]["byteLength"] = 64.into()),
        ),
        (
            "out of range",
            Box::new(|v| v["accessors"][0]["count"] = 2.into()),
        ),
        (
            "reached twice",
            Box::new(|v| {
                v["nodes"] = serde_json::json!([{"mesh": 0, "children": [1]}, {"children": [0]}])
            }),
        ),
    ];
    for (needle, patch) in cases {
        let gltf = dir.path().join("bad.gltf");
        std::fs::write(&gltf, tetra_gltf(&data_uri(), patch)).unwrap();
        let o = run(&["-q", "build", s(&gltf), "-r", "16", "-o", s(&out)]);
        expect(&o, 1, &[needle]);
        assert!(!out.exists());
    }
}

/// Panics raised in this crate's own code (not a third-party parser) while fuzzing.
static OWN_PANICS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

fn count_own_panics() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let default = std::panic::take_hook();
        // Only third-party parsers' panics (absolute registry paths) are silenced: a failing
        // assertion in a test running beside the fuzzers must still print its message.
        std::panic::set_hook(Box::new(move |info| {
            let file = info.location().map_or("", |l| l.file());
            if file.starts_with("engine/") {
                OWN_PANICS.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            }
            if !Path::new(file).is_absolute() {
                default(info);
            }
        }));
    });
}

/// Loads a mutated model: an error or a mesh that validates; no panic from our code.
fn load_mutated(dir: &Path, name: &str, bytes: &[u8]) -> Result<(), TestCaseError> {
    count_own_panics();
    voxdag::safety::set_memory_limit(256 << 20);
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    let before = OWN_PANICS.load(std::sync::atomic::Ordering::SeqCst);
    if let Ok(mesh) = scene::load_mesh(&path, &ImportOptions::default()) {
        prop_assert!(mesh.validate().is_ok());
        let _ = voxdag::scene::voxelize(&mesh, 16, &indicatif::ProgressBar::hidden());
    }
    prop_assert_eq!(OWN_PANICS.load(std::sync::atomic::Ordering::SeqCst), before);
    Ok(())
}

fn fuzz_dir() -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxdag-hostile-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Mutated glTF (bytes flipped, digits replaced): an error or a valid mesh.
    #[test]
    fn mutated_gltf_never_panics(
        flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..4),
        digits in prop::collection::vec((any::<prop::sample::Index>(), 0u8..10), 0..3),
    ) {
        let mut b = tetra_gltf(&data_uri(), |_| {}).into_bytes();
        for (at, v) in &flips {
            let i = at.index(b.len());
            b[i] ^= v;
        }
        for (at, d) in &digits {
            let i = at.index(b.len());
            if b[i].is_ascii_digit() {
                b[i] = b'0' + d;
            }
        }
        load_mutated(&fuzz_dir(), "f.gltf", &b)?;
    }

    /// Mutated OBJ text: an error or a valid mesh.
    #[test]
    fn mutated_obj_never_panics(
        flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..4),
    ) {
        let mut b = b"mtllib m.mtl\nusemtl a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvt 0 0\nvt 1 0\n\
            f 1/1 3/2 2/1\nf 1 2 4\nf 1 4 3\nf -1 -2 -3\n".to_vec();
        for (at, v) in &flips {
            let i = at.index(b.len());
            b[i] ^= v;
        }
        load_mutated(&fuzz_dir(), "f.obj", &b)?;
    }
}
