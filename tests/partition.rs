//! The partitioned build (docs/scaling.md): `voxdag build --part i/K` for every part, then
//! `voxdag merge`, writes the bytes of the one-machine build; a missing, duplicated, foreign or
//! corrupt part is refused with one error line naming it, and no output is left.

mod common;

use std::path::{Path, PathBuf};

use common::{repo, voxdag_cli};

/// A scratch folder for this test binary's outputs.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxdag-part-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    dir
}

fn s(p: &Path) -> &str {
    p.to_str().expect("UTF-8 path")
}

/// Runs the CLI, asserting success.
fn ok(args: &[&str]) -> String {
    let out = common::assert_cli_ok(args, voxdag_cli(args));
    String::from_utf8_lossy(&out.stdout).to_string()
}

/// Runs the CLI, asserting exit 1 with one `error:` line that contains every needle.
fn refused(args: &[&str], needles: &[&str]) {
    let out = voxdag_cli(args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "voxdag {args:?}: {stderr}");
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(errors.len(), 1, "want one error line: {stderr}");
    for n in needles {
        assert!(stderr.contains(n), "stderr lacks {n:?}: {stderr}");
    }
}

/// Builds the `k` parts of `input` with `args` into `dir`; returns their paths.
fn build_parts(dir: &Path, input: &Path, args: &[&str], k: u32) -> Vec<PathBuf> {
    (0..k)
        .map(|i| {
            let part = dir.join(format!("part_{i}.vdagp"));
            let spec = format!("{i}/{k}");
            let mut all = vec!["-q", "build", s(input), "--part", &spec, "-o", s(&part)];
            all.extend(args);
            ok(&all);
            part
        })
        .collect()
}

/// Merges `parts` into `out`.
fn merge(parts: &[PathBuf], out: &Path) {
    let mut all = vec!["-q", "merge"];
    all.extend(parts.iter().map(|p| s(p)));
    all.extend(["-o", s(out)]);
    ok(&all);
}

/// K = 1, 2, 7, 64 parts merged equal the one-machine build byte for byte.
fn assert_partitioned_equal(name: &str, input: &Path, args: &[&str]) {
    let dir = scratch(name);
    let whole = dir.join("whole.vdag");
    let mut all = vec!["-q", "build", s(input), "-o", s(&whole)];
    all.extend(args);
    ok(&all);
    let expected = std::fs::read(&whole).expect("read whole build");
    for k in [1, 2, 7, 64] {
        let parts = build_parts(&dir, input, args, k);
        let merged = dir.join(format!("merged_{k}.vdag"));
        // Any order: the merge sorts by part index.
        let mut shuffled = parts.clone();
        shuffled.reverse();
        merge(&shuffled, &merged);
        let got = std::fs::read(&merged).expect("read merged build");
        assert!(
            got == expected,
            "{name} {args:?}: {k} parts merged differ from the one-machine build ({} vs {} bytes)",
            got.len(),
            expected.len()
        );
        for p in parts {
            std::fs::remove_file(p).expect("remove part");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn merged_parts_equal_the_one_machine_build() {
    let avocado = repo().join("assets/avocado/Avocado.gltf");
    let teapot = repo().join("tests/data/teapot.obj");
    // With lossless colours (the default), a lossy codec with small chunks, and none.
    assert_partitioned_equal("avocado", &avocado, &["-r", "64"]);
    assert_partitioned_equal(
        "avocado-lossy",
        &avocado,
        &["-r", "128", "--colors", "lossy", "--chunk-depth", "3"],
    );
    assert_partitioned_equal("teapot", &teapot, &["-r", "64"]);
    assert_partitioned_equal("vox", &repo().join("tests/data/ff3.vox"), &[]);
}

#[test]
fn bad_part_sets_are_refused_naming_the_part() {
    let dir = scratch("bad");
    let avocado = repo().join("assets/avocado/Avocado.gltf");
    let parts = build_parts(&dir, &avocado, &["-r", "64"], 4);
    let out = dir.join("out.vdag");
    let o = s(&out);

    // Missing part 2.
    let given = [&parts[0], &parts[1], &parts[3]].map(|p| s(p));
    refused(
        &[&["merge"], &given[..], &["-o", o]].concat(),
        &["part 2/4 is missing"],
    );
    // Part 1 twice (once under another name).
    let copy = dir.join("copy.vdagp");
    std::fs::copy(&parts[1], &copy).expect("copy part");
    let all: Vec<&str> = parts.iter().map(|p| s(p)).collect();
    refused(
        &[&["merge"], &all[..], &[s(&copy), "-o", o]].concat(),
        &["part_1.vdagp", "copy.vdagp", "both part 1/4"],
    );
    // A part of another build (other K).
    let other = dir.join("other");
    std::fs::create_dir_all(&other).expect("folder");
    let foreign = build_parts(&other, &avocado, &["-r", "64"], 2);
    refused(
        &[&["merge"], &all[..3], &[s(&foreign[1]), "-o", o]].concat(),
        &["part_1.vdagp", "not one build"],
    );
    // Corrupt: one flipped bit in the node words (CRC), a truncated file, a bad magic.
    let bytes = std::fs::read(&parts[2]).expect("read part");
    let corrupt = dir.join("corrupt.vdagp");
    let mut flipped = bytes.clone();
    flipped[100] ^= 0x10;
    std::fs::write(&corrupt, &flipped).expect("write");
    let with = |bad: &Path| -> Vec<String> {
        let mut v: Vec<String> = vec!["merge".into()];
        v.extend([&parts[0], &parts[1]].map(|p| p.display().to_string()));
        v.push(bad.display().to_string());
        v.push(parts[3].display().to_string());
        v.extend(["-o".into(), o.to_string()]);
        v
    };
    let run = |bad: &Path, needles: &[&str]| {
        let args = with(bad);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        refused(&args, needles);
    };
    run(&corrupt, &["corrupt.vdagp", "CRC-32"]);
    let truncated = dir.join("truncated.vdagp");
    std::fs::write(&truncated, &bytes[..bytes.len() - 7]).expect("write");
    run(&truncated, &["truncated.vdagp", "do not add up"]);
    let magic = dir.join("magic.vdagp");
    let mut m = bytes.clone();
    m[0] = b'X';
    std::fs::write(&magic, &m).expect("write");
    run(&magic, &["magic.vdagp", "bad magic"]);
    let missing_file = dir.join("nowhere.vdagp");
    run(&missing_file, &["nowhere.vdagp"]);
    // A header whose counts claim more than the file: refused before reading the body.
    let mut huge = bytes.clone();
    huge[72..80].copy_from_slice(&(1u64 << 60).to_le_bytes());
    let lying = dir.join("lying.vdagp");
    std::fs::write(&lying, &huge).expect("write");
    run(&lying, &["lying.vdagp"]);
    assert!(!out.exists(), "a refused merge left {}", out.display());
    // The good set still merges.
    merge(&parts, &out);
    let _ = std::fs::remove_dir_all(&dir);
}
