//! Import of OBJ / glTF / .vox files: shared data (when present), bundled files, bad input.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

mod common;

use indicatif::ProgressBar;
use voxdag::scene::{import, load_mesh, load_vox, morton, ImportOptions, SceneError, Voxels};

fn bundled(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

fn with_res(r: u32) -> ImportOptions {
    ImportOptions {
        resolution: Some(r),
        ..ImportOptions::default()
    }
}

fn check(v: &Voxels) {
    assert!(!v.is_empty());
    assert!(v.codes.windows(2).all(|w| w[0] < w[1]));
    assert!(v.colors.is_empty() || v.colors.len() == v.codes.len());
    let n = v.resolution;
    assert!(v
        .codes
        .iter()
        .all(|&c| morton::decode(c).iter().all(|&x| x < n)));
}

fn files_with_ext(dir: &Path, exts: &[&str], out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .expect("read_dir")
        .map(|e| e.expect("entry").path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            files_with_ext(&p, exts, out);
        } else if let Some(e) = p.extension().and_then(|e| e.to_str()) {
            if exts.contains(&e.to_ascii_lowercase().as_str()) {
                out.push(p);
            }
        }
    }
}

#[test]
fn shared_meshes_import() {
    let Some(data) = common::shared_data() else {
        return;
    };
    let mut files = Vec::new();
    files_with_ext(&data.join("meshes"), &["obj"], &mut files);
    assert!(files.len() >= 7, "{files:?}");
    for f in &files {
        let v = import(f, &with_res(64), &ProgressBar::hidden()).expect("import");
        check(&v);
        assert_eq!(v.resolution, 64);
        let name = f.file_name().unwrap().to_str().unwrap();
        // Only the Crytek Sponza has materials (its textures are absent: Kd fallback).
        assert_eq!(v.has_colors(), name.contains("crytek"), "{name}");
        assert!(v.len() > 1000, "{name}: {} voxels", v.len());
    }
}

#[test]
fn shared_textured_models_import_with_colours() {
    let Some(data) = common::shared_data() else {
        return;
    };
    let mut files = Vec::new();
    files_with_ext(&data.join("textured"), &["gltf", "glb"], &mut files);
    assert!(files.len() >= 5, "{files:?}");
    for f in &files {
        let v = import(f, &with_res(32), &ProgressBar::hidden()).expect("import");
        check(&v);
        assert!(v.has_colors(), "{f:?}");
        // Textured: more than a handful of distinct colours.
        let mut distinct: Vec<u32> = v.colors.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert!(distinct.len() > 8, "{f:?}: {} colours", distinct.len());
    }
    // spot: OBJ without a .mtl plus an override texture.
    let spot = data.join("textured/spot");
    let opts = ImportOptions {
        resolution: Some(32),
        texture_override: Some(spot.join("spot_texture.png")),
        ..ImportOptions::default()
    };
    let v = import(
        &spot.join("spot_triangulated.obj"),
        &opts,
        &ProgressBar::hidden(),
    )
    .unwrap();
    check(&v);
    assert!(v.has_colors());
    let plain = import(
        &spot.join("spot_triangulated.obj"),
        &with_res(32),
        &ProgressBar::hidden(),
    )
    .unwrap();
    assert!(!plain.has_colors());
    assert_eq!(plain.codes, v.codes);
}

#[test]
fn gltf_node_transforms_are_applied() {
    let Some(data) = common::shared_data() else {
        return;
    };
    // Fox is skinned and its mesh node sits under a scaled/rotated hierarchy; the rest pose
    // must still be a sane, non-degenerate shape (longest side along the body).
    let m = load_mesh(
        &data.join("textured/fox/Fox.gltf"),
        &ImportOptions::default(),
    )
    .unwrap();
    assert_eq!(m.triangle_count(), 576);
    assert!(m.has_colors && !m.textures.is_empty() && m.uvs.len() == m.positions.len());
}

#[test]
fn shared_vox_files_import() {
    let Some(data) = common::shared_data() else {
        return;
    };
    let mut files = Vec::new();
    files_with_ext(&data.join("vox"), &["vox"], &mut files);
    assert!(files.len() >= 40, "{} files", files.len());
    for f in &files {
        let v = load_vox(f, &ImportOptions::default()).expect("load_vox");
        check(&v);
        assert!(v.has_colors());
        let bytes = std::fs::read(f).unwrap();
        let raw = dot_vox::load_bytes(&bytes).unwrap();
        if raw.models.len() == 1 {
            let mut unique: Vec<(u8, u8, u8)> = raw.models[0]
                .voxels
                .iter()
                .map(|v| (v.x, v.y, v.z))
                .collect();
            unique.sort_unstable();
            unique.dedup();
            assert_eq!(v.len(), unique.len(), "{f:?}");
            // Extent of the occupied voxels (the grid is the smallest power of two >= it).
            let span = |f: fn(&dot_vox::Voxel) -> u8| {
                let it = raw.models[0].voxels.iter().map(f);
                (it.clone().max().unwrap() - it.min().unwrap()) as u32 + 1
            };
            let ext = span(|v| v.x).max(span(|v| v.y)).max(span(|v| v.z));
            assert!(v.resolution >= ext && v.resolution >= 8 && v.resolution / 2 < ext.max(8));
        }
    }
    // The scene-graph file combines its models.
    let f = data.join("vox/opengametools/test_multiple_model_scene.vox");
    let raw = dot_vox::load_bytes(&std::fs::read(&f).unwrap()).unwrap();
    assert!(raw.models.len() > 1);
    let v = load_vox(&f, &ImportOptions::default()).unwrap();
    let largest = raw.models.iter().map(|m| m.voxels.len()).max().unwrap();
    assert!(v.len() > largest, "{} <= {}", v.len(), largest);
}

#[test]
fn bundled_vox_scale_and_orientation() {
    let f = bundled("ff3.vox");
    let raw = dot_vox::load_bytes(&std::fs::read(&f).unwrap()).unwrap();
    let model = &raw.models[0];
    let v1 = load_vox(&f, &ImportOptions::default()).unwrap();
    check(&v1);
    assert_eq!(v1.len(), model.voxels.len());
    // z-up -> y-up: (x, y, z) -> (x - xmin, z - zmin, ymax - y).
    let (xmin, ymax, zmin) = (
        model.voxels.iter().map(|v| v.x).min().unwrap() as u32,
        model.voxels.iter().map(|v| v.y).max().unwrap() as u32,
        model.voxels.iter().map(|v| v.z).min().unwrap() as u32,
    );
    let got: BTreeMap<u64, u32> = v1
        .codes
        .iter()
        .copied()
        .zip(v1.colors.iter().copied())
        .collect();
    for vx in &model.voxels {
        let code = morton::encode(vx.x as u32 - xmin, vx.z as u32 - zmin, ymax - vx.y as u32);
        let c = raw.palette[vx.i as usize];
        let want = c.r as u32 | (c.g as u32) << 8 | (c.b as u32) << 16 | (c.a as u32) << 24;
        assert_eq!(got.get(&code), Some(&want));
    }
    let opts = ImportOptions {
        vox_scale: 3,
        ..ImportOptions::default()
    };
    let v3 = load_vox(&f, &opts).unwrap();
    check(&v3);
    assert_eq!(v3.len(), 27 * v1.len());
    // Resolution that is too small for the model, and invalid options.
    assert!(matches!(
        load_vox(&f, &with_res(8)),
        Err(SceneError::TooLarge { .. })
    ));
    assert!(matches!(
        load_vox(&f, &with_res(100)),
        Err(SceneError::BadResolution { .. })
    ));
    let zero = ImportOptions {
        vox_scale: 0,
        ..ImportOptions::default()
    };
    assert!(matches!(
        load_vox(&f, &zero),
        Err(SceneError::BadOption { .. })
    ));
}

#[test]
fn scene_graph_transforms_place_models() {
    use dot_vox::{DotVoxData, Frame, Model, SceneNode, ShapeModel, Size, Voxel};
    type HashMap = dot_vox::Dict;
    // Two 2x1x1 models: model 0 plain, model 1 rotated 90 degrees about z and translated.
    let model = |i: u8| Model {
        size: Size { x: 2, y: 1, z: 1 },
        voxels: vec![
            Voxel {
                x: 0,
                y: 0,
                z: 0,
                i,
            },
            Voxel {
                x: 1,
                y: 0,
                z: 0,
                i,
            },
        ],
    };
    let frame = |r: Option<&str>, t: &str| {
        let mut a = HashMap::default();
        if let Some(r) = r {
            a.insert("_r".to_string(), r.to_string());
        }
        a.insert("_t".to_string(), t.to_string());
        Frame::new(a)
    };
    // Rotation about z by +90 degrees: rows [0,-1,0],[1,0,0],[0,0,1]:
    // row0 -> col 1 (neg), row1 -> col 0: byte = 1 | 0 << 2 | 1 << 4.
    let rz = (1 | (1 << 4)).to_string();
    let scenes = vec![
        SceneNode::Transform {
            attributes: HashMap::default(),
            frames: vec![Frame::new(HashMap::default())],
            child: 1,
            layer_id: u32::MAX,
        },
        SceneNode::Group {
            attributes: HashMap::default(),
            children: vec![2, 4],
        },
        SceneNode::Transform {
            attributes: HashMap::default(),
            frames: vec![frame(None, "0 0 0")],
            child: 3,
            layer_id: 0,
        },
        SceneNode::Shape {
            attributes: HashMap::default(),
            models: vec![ShapeModel {
                model_id: 0,
                attributes: HashMap::default(),
            }],
        },
        SceneNode::Transform {
            attributes: HashMap::default(),
            frames: vec![frame(Some(&rz), "10 0 5")],
            child: 5,
            layer_id: 0,
        },
        SceneNode::Shape {
            attributes: HashMap::default(),
            models: vec![ShapeModel {
                model_id: 1,
                attributes: HashMap::default(),
            }],
        },
    ];
    let mut data = DotVoxData {
        version: 150,
        index_map: Vec::new(),
        models: vec![model(1), model(2)],
        palette: dot_vox::DEFAULT_PALETTE.to_vec(),
        materials: Vec::new(),
        scenes,
        layers: Vec::new(),
    };
    data.index_map = (0..=255).collect();
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("scene.vox");
    let mut out = std::fs::File::create(&f).unwrap();
    data.write_vox(&mut out).unwrap();
    drop(out);
    let v = load_vox(&f, &ImportOptions::default()).unwrap();
    // Model 0 (pivot floor(2/2) = 1): centres x + 0.5 - 1 -> voxels x = -1, 0 at y = z = 0.
    // Model 1: centres (-0.5, 0.5, 0.5), (0.5, 0.5, 0.5) rotated -> (-0.5, -0.5), (-0.5, 0.5)
    // in (x, y), + (10, 0, 5) -> voxels (9, -1, 5), (9, 0, 5).
    // World z-up: {(-1,0,0), (0,0,0), (9,-1,5), (9,0,5)}; y-up (x, z, -y), min corner to 0:
    // (x + 1, z, 0 - y) over y in {-1, 0} -> max(-y) = 1: (x+1, z, -y).
    let want: Vec<[u32; 3]> = vec![[0, 0, 0], [1, 0, 0], [10, 5, 1], [10, 5, 0]];
    let mut want_codes: Vec<u64> = want
        .iter()
        .map(|p| morton::encode(p[0], p[1], p[2]))
        .collect();
    want_codes.sort_unstable();
    assert_eq!(v.codes, want_codes);
    assert_eq!(v.resolution, 16);
}

#[test]
fn bundled_textured_obj_samples_texels_exactly() {
    // Unit quad z = 0 with uv = (x, y), 8x8 texture, resolution 8: the quad maps to z = 4, and
    // voxel (i, j, 3|4) has its closest point at uv ((i+.5)/8, (j+.5)/8) = centre of texel
    // (i, 7 - j) (OBJ v points up, image rows down).
    let v = import(&bundled("quad.obj"), &with_res(8), &ProgressBar::hidden()).unwrap();
    check(&v);
    assert_eq!(v.len(), 8 * 8 * 2);
    for (code, col) in v.codes.iter().zip(&v.colors) {
        let [i, j, k] = morton::decode(*code);
        assert!(k == 3 || k == 4);
        let (tx, ty) = (i, 7 - j);
        let want = (32 * tx + 7) | (32 * ty + 3) << 8 | 100 << 16 | 255 << 24;
        assert_eq!(*col, want, "voxel {i} {j} {k}");
    }
}

#[test]
fn bad_input_is_an_error() {
    let hidden = ProgressBar::hidden();
    let opts = with_res(16);
    assert!(matches!(
        import(Path::new("/nonexistent/x.obj"), &opts, &hidden),
        Err(SceneError::Io { .. })
    ));
    assert!(matches!(
        import(Path::new("/nonexistent/x.vox"), &opts, &hidden),
        Err(SceneError::Io { .. })
    ));
    assert!(matches!(
        import(Path::new("/nonexistent/x.gltf"), &opts, &hidden),
        Err(SceneError::Io { .. })
    ));
    assert!(matches!(
        import(Path::new("model.stl"), &opts, &hidden),
        Err(SceneError::Unsupported { .. })
    ));
    assert!(matches!(
        import(&bundled("teapot.obj"), &with_res(48), &hidden),
        Err(SceneError::BadResolution { .. })
    ));
    let dir = tempfile::tempdir().unwrap();
    // Truncated / corrupt copies of each format.
    let cases: Vec<(&str, Vec<u8>)> = vec![
        (
            "trunc.vox",
            std::fs::read(bundled("ff3.vox")).unwrap()[..700].to_vec(),
        ),
        ("garbage.vox", b"VOX \x96\0\0\0MAIN garbage".to_vec()),
        ("empty.vox", Vec::new()),
        ("garbage.gltf", b"{ \"asset\": { \"version\": ".to_vec()),
        ("garbage.glb", b"glTF\x02\0\0\0\xff\xff\xff\xff".to_vec()),
        (
            "nobuf.gltf",
            br#"{"asset":{"version":"2.0"},"buffers":[{"uri":"missing.bin","byteLength":12}]}"#
                .to_vec(),
        ),
        (
            "bad_index.obj",
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n".to_vec(),
        ),
        ("empty.obj", Vec::new()),
        ("text.obj", b"this is not an obj file\n\x00\x01".to_vec()),
        (
            "trunc.obj",
            std::fs::read(bundled("teapot.obj")).unwrap()[..5000].to_vec(),
        ),
    ];
    for (name, bytes) in cases {
        let f = dir.path().join(name);
        std::fs::write(&f, &bytes).unwrap();
        let r = import(&f, &opts, &hidden);
        // A truncated OBJ may still hold valid faces; everything else must fail.
        if name == "trunc.obj" {
            if let Ok(v) = r {
                check(&v);
            }
        } else {
            let e = r.expect_err(name);
            assert!(e.to_string().contains(name), "{name}: {e}");
        }
    }
}

/// Writes a .vox file whose scene graph `scenes` places one 1^3 model (palette index 1).
fn write_one_voxel_scene(dir: &Path, name: &str, scenes: Vec<dot_vox::SceneNode>) -> PathBuf {
    use dot_vox::{DotVoxData, Model, Size, Voxel};
    let data = DotVoxData {
        version: 150,
        index_map: (0..=255).collect(),
        models: vec![Model {
            size: Size { x: 1, y: 1, z: 1 },
            voxels: vec![Voxel {
                x: 0,
                y: 0,
                z: 0,
                i: 1,
            }],
        }],
        palette: dot_vox::DEFAULT_PALETTE.to_vec(),
        materials: Vec::new(),
        scenes,
        layers: Vec::new(),
    };
    let f = dir.join(name);
    let mut out = std::fs::File::create(&f).unwrap();
    data.write_vox(&mut out).unwrap();
    f
}

#[test]
fn huge_vox_scales_are_errors() {
    // Scaled voxel counts and extents are checked products: no panic, no wrap-around.
    let f = bundled("ff3.vox");
    for scale in [u32::MAX, 1 << 22, 65537, 40_000] {
        let opts = ImportOptions {
            vox_scale: scale,
            ..ImportOptions::default()
        };
        let e = load_vox(&f, &opts).expect_err("scale too large");
        assert!(matches!(e, SceneError::TooLarge { .. }), "{scale}: {e}");
        assert!(e.to_string().contains("ff3.vox"), "{scale}: {e}");
    }
    // Two one-voxel shapes 2^33 apart (nested i32 translations) at scale 2^31: the scaled
    // extent 2^64 and the voxel count 2 * 2^93 wrap to 0 in unchecked u64 arithmetic.
    use dot_vox::{Frame, SceneNode, ShapeModel};
    type Dict = dot_vox::Dict;
    let translate = |t: &str, child: u32| {
        let mut a = Dict::default();
        a.insert("_t".to_string(), t.to_string());
        SceneNode::Transform {
            attributes: Dict::default(),
            frames: vec![Frame::new(a)],
            child,
            layer_id: u32::MAX,
        }
    };
    let shape = || SceneNode::Shape {
        attributes: Dict::default(),
        models: vec![ShapeModel {
            model_id: 0,
            attributes: Dict::default(),
        }],
    };
    let scenes = vec![
        translate("0 0 0", 1),
        SceneNode::Group {
            attributes: Dict::default(),
            children: vec![2, 6],
        },
        translate("2147483647 0 0", 3),
        translate("2147483647 0 0", 4),
        translate("1 0 0", 5),
        shape(),
        translate("-2147483648 0 0", 7),
        translate("-2147483648 0 0", 8),
        shape(),
    ];
    let dir = tempfile::tempdir().unwrap();
    let f = write_one_voxel_scene(dir.path(), "far.vox", scenes);
    for scale in [1, 1 << 31] {
        let opts = ImportOptions {
            vox_scale: scale,
            ..ImportOptions::default()
        };
        let e = load_vox(&f, &opts).expect_err("extent 2^33");
        assert!(matches!(e, SceneError::TooLarge { .. }), "{scale}: {e}");
        assert!(e.to_string().contains("far.vox"), "{scale}: {e}");
    }
}

#[test]
fn exponentially_branching_vox_scene_graph_is_rejected_quickly() {
    use dot_vox::{Frame, SceneNode, ShapeModel};
    type Dict = dot_vox::Dict;
    // Node 0: transform -> group 1; group i (1..=40) lists group i + 1 twice; node 41 is a
    // shape: 2^40 paths to one shape in a file of a few hundred bytes.
    let mut scenes = vec![SceneNode::Transform {
        attributes: Dict::default(),
        frames: vec![Frame::new(Dict::default())],
        child: 1,
        layer_id: u32::MAX,
    }];
    for i in 1..=40u32 {
        scenes.push(SceneNode::Group {
            attributes: Dict::default(),
            children: vec![i + 1, i + 1],
        });
    }
    scenes.push(SceneNode::Shape {
        attributes: Dict::default(),
        models: vec![ShapeModel {
            model_id: 0,
            attributes: Dict::default(),
        }],
    });
    let dir = tempfile::tempdir().unwrap();
    let f = write_one_voxel_scene(dir.path(), "branching.vox", scenes);
    let start = std::time::Instant::now();
    let e = load_vox(&f, &ImportOptions::default()).expect_err("2^40 placements");
    assert!(matches!(e, SceneError::Parse { .. }), "{e}");
    assert!(e.to_string().contains("branching.vox"), "{e}");
    assert!(start.elapsed().as_secs() < 10, "took {:?}", start.elapsed());
}

/// Writes a .gltf with one triangle (0,0,0), (1,0,0), (0,1,0) as mesh 0 and the given
/// `nodes` / `scenes` JSON (`scenes` may be empty: no scene).
fn write_gltf(dir: &Path, name: &str, nodes: &str, scenes: &str) -> PathBuf {
    let tri: Vec<u8> = [0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    std::fs::write(dir.join("tri.bin"), tri).unwrap();
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},
        "buffers":[{{"uri":"tri.bin","byteLength":36}}],
        "bufferViews":[{{"buffer":0,"byteLength":36}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3",
                       "min":[0,0,0],"max":[1,1,0]}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],
        "nodes":[{nodes}]{scenes}}}"#
    );
    let f = dir.join(name);
    std::fs::write(&f, json).unwrap();
    f
}

#[test]
fn gltf_nodes_must_form_a_tree() {
    let dir = tempfile::tempdir().unwrap();
    // A ladder of 40 layers of two nodes, each listing both nodes of the next layer: 2^40
    // paths to the meshes of the last layer.
    let layers = 40;
    let nodes: Vec<String> = (0..2 * layers)
        .map(|i| {
            let layer = i / 2;
            if layer + 1 < layers {
                format!(r#"{{"children":[{},{}]}}"#, 2 * layer + 2, 2 * layer + 3)
            } else {
                r#"{"mesh":0}"#.to_string()
            }
        })
        .collect();
    let f = write_gltf(
        dir.path(),
        "ladder.gltf",
        &nodes.join(","),
        r#","scenes":[{"nodes":[0,1]}],"scene":0"#,
    );
    let start = std::time::Instant::now();
    let e = load_mesh(&f, &ImportOptions::default()).expect_err("shared children");
    assert!(matches!(e, SceneError::Parse { .. }), "{e}");
    assert!(e.to_string().contains("ladder.gltf"), "{e}");
    assert!(start.elapsed().as_secs() < 10, "took {:?}", start.elapsed());
    // A cycle and a root listed twice are rejected the same way.
    for (name, nodes, scenes) in [
        (
            "cycle.gltf",
            r#"{"mesh":0,"children":[1]},{"children":[0]}"#,
            r#","scenes":[{"nodes":[0]}]"#,
        ),
        (
            "twice.gltf",
            r#"{"mesh":0}"#,
            r#","scenes":[{"nodes":[0,0]}]"#,
        ),
    ] {
        let f = write_gltf(dir.path(), name, nodes, scenes);
        let e = load_mesh(&f, &ImportOptions::default()).expect_err(name);
        assert!(e.to_string().contains(name), "{e}");
    }
    // Without a scene, the roots are the nodes without a parent: the child is instanced once,
    // with its parent's transform (translate 10 after scale 2).
    let f = write_gltf(
        dir.path(),
        "noscene.gltf",
        r#"{"translation":[10,0,0],"children":[1]},{"mesh":0,"scale":[2,2,2]}"#,
        "",
    );
    let m = load_mesh(&f, &ImportOptions::default()).unwrap();
    assert_eq!(m.triangle_count(), 1);
    assert_eq!(
        m.positions,
        vec![[10.0, 0.0, 0.0], [12.0, 0.0, 0.0], [10.0, 2.0, 0.0]]
    );
}
