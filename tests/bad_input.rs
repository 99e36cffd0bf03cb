//! Malformed and unsupported input (issue: foundation, "bad input"; docs/cli.md, "Exit status").
//!
//! Every case runs the `surfcache` binary on a file built here from `assets/cornell.gltf`
//! (or written by hand) and checks what a user sees: a non-zero exit status with exactly one
//! stderr line `error: …` naming the file and the cause, and never a panic or backtrace.
//! Inputs that are only doubtful (points/lines primitives, degenerate triangles, negative
//! radiance) load with exactly one `warning: …` line and exit 0. Bake options given with a
//! method they do not apply to are errors of the same kind.

mod common;

use common::{ASSETS, cornell_bin, cornell_json, mesh_index, pack_glb, stderr_of, temp_dir};
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use surfcache::core::glam::Vec3;

const SURFCACHE: &str = env!("CARGO_BIN_EXE_surfcache");

/// A points CSV with one point on the Cornell floor (both the built-in and the glTF box).
fn points_csv(dir: &Path) -> PathBuf {
    let path = dir.join("points.csv");
    std::fs::write(&path, "x,y,z,nx,ny,nz\n0.3,0,0.3,0,1,0\n").unwrap();
    path
}

/// `surfcache reference SCENE --samples 1 POINTS.csv EXTRA…`, with backtraces enabled so a
/// panic could not hide behind a short message.
fn reference(scene: impl AsRef<std::ffi::OsStr>, points: &Path, extra: &[&str]) -> Output {
    Command::new(SURFCACHE)
        .arg("reference")
        .arg(scene)
        .args(["--samples", "1", "--threads", "1"])
        .arg(points)
        .args(extra)
        .env("RUST_BACKTRACE", "1")
        .output()
        .expect("the surfcache binary runs")
}

fn assert_no_panic(out: &Output) {
    let stderr = stderr_of(out);
    for bad in ["panicked", "backtrace", "RUST_BACKTRACE"] {
        assert!(!stderr.contains(bad), "stderr shows a panic:\n{stderr}");
    }
    assert!(
        out.status.code().is_some(),
        "killed by a signal: {:?}\n{stderr}",
        out.status
    );
}

/// Non-zero exit, nothing on stdout, exactly one stderr line `error: …` containing every
/// needle. Returns the line.
#[track_caller]
fn expect_error(out: &Output, needles: &[&str]) -> String {
    assert_no_panic(out);
    let stderr = stderr_of(out);
    assert!(
        !out.status.success(),
        "expected failure, got success; stderr:\n{stderr}"
    );
    assert!(
        out.stdout.is_empty(),
        "stdout not empty on error: {}",
        String::from_utf8_lossy(&out.stdout)
    );
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 1, "expected one stderr line, got:\n{stderr}");
    let line = lines[0];
    assert!(line.starts_with("error: "), "not an error line: {line}");
    for needle in needles {
        assert!(line.contains(needle), "'{needle}' missing from: {line}");
    }
    line.to_string()
}

/// Exit 0, the result CSV on stdout (one row), exactly one stderr line `warning: …`
/// containing every needle. Returns the line.
#[track_caller]
fn expect_warning(out: &Output, needles: &[&str]) -> String {
    assert_no_panic(out);
    let stderr = stderr_of(out);
    assert!(out.status.success(), "expected success; stderr:\n{stderr}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let rows: Vec<&str> = stdout.lines().collect();
    assert_eq!(rows.len(), 2, "stdout:\n{stdout}");
    assert_eq!(rows[0], "x,y,z,r,g,b,rel_std");
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 1, "expected one stderr line, got:\n{stderr}");
    let line = lines[0];
    assert!(line.starts_with("warning: "), "not a warning line: {line}");
    for needle in needles {
        assert!(line.contains(needle), "'{needle}' missing from: {line}");
    }
    line.to_string()
}

#[track_caller]
fn expect_clean_success(out: &Output) {
    assert_no_panic(out);
    assert!(
        out.status.success() && out.stderr.is_empty(),
        "expected a silent success: {:?}\n{}",
        out.status,
        stderr_of(out)
    );
}

// --- the Cornell box glTF, taken apart and put back together ---------------------------

/// Triangles of the unmodified Cornell glTF, and of the named meshes in it.
fn cornell_triangles() -> usize {
    let loaded = surfcache::io::load_gltf(&Path::new(ASSETS).join("cornell.gltf")).unwrap();
    assert_eq!(loaded.report, Default::default());
    loaded.scene.triangle_count()
}

/// Writes `NAME.gltf` (and `NAME.bin` holding `bin`, referenced by buffer 0) into `dir`.
fn write_gltf(dir: &Path, name: &str, doc: &Value, bin: &[u8]) -> PathBuf {
    let mut doc = doc.clone();
    doc["buffers"][0]["uri"] = json!(format!("{name}.bin"));
    std::fs::write(dir.join(format!("{name}.bin")), bin).unwrap();
    let path = dir.join(format!("{name}.gltf"));
    std::fs::write(&path, serde_json::to_vec_pretty(&doc).unwrap()).unwrap();
    path
}

/// Packs a one-buffer glTF document into GLB, its buffer pointing at the BIN chunk.
fn glb_of(doc: &Value, bin: &[u8]) -> Vec<u8> {
    let mut doc = doc.clone();
    doc["buffers"] = json!([{ "byteLength": bin.len() }]);
    pack_glb(&serde_json::to_vec(&doc).unwrap(), bin)
}

fn primitive(doc: &Value, mesh: &str) -> Value {
    doc["meshes"][mesh_index(doc, mesh)]["primitives"][0].clone()
}

fn as_usize(v: &Value) -> usize {
    v.as_u64().map_or(0, |x| x as usize)
}

/// Byte offset in the buffer of element `element` of accessor `accessor`, and its stride.
fn element_offset(doc: &Value, accessor: usize, element: usize, size: usize) -> usize {
    let acc = &doc["accessors"][accessor];
    let view = &doc["bufferViews"][as_usize(&acc["bufferView"])];
    assert_eq!(as_usize(&view["buffer"]), 0);
    let stride = view["byteStride"].as_u64().map_or(size, |s| s as usize);
    as_usize(&view["byteOffset"]) + as_usize(&acc["byteOffset"]) + element * stride
}

/// Position `vertex` of mesh `mesh` in `bin` (float VEC3).
fn position_offset(doc: &Value, mesh: &str, vertex: usize) -> usize {
    let acc = as_usize(&primitive(doc, mesh)["attributes"]["POSITION"]);
    assert_eq!(doc["accessors"][acc]["componentType"], 5126);
    element_offset(doc, acc, vertex, 12)
}

fn read_vec3(bin: &[u8], at: usize) -> Vec3 {
    let f = |k: usize| f32::from_le_bytes(bin[at + 4 * k..at + 4 * k + 4].try_into().unwrap());
    Vec3::new(f(0), f(1), f(2))
}

fn write_vec3(bin: &mut [u8], at: usize, v: Vec3) {
    for k in 0..3 {
        bin[at + 4 * k..at + 4 * k + 4].copy_from_slice(&v[k].to_le_bytes());
    }
}

/// The first triangle's indices of mesh `mesh` and where they are (u32 indices).
fn first_triangle(doc: &Value, bin: &[u8], mesh: &str) -> ([u32; 3], usize) {
    let acc = as_usize(&primitive(doc, mesh)["indices"]);
    assert_eq!(doc["accessors"][acc]["componentType"], 5125, "u32 indices");
    let at = element_offset(doc, acc, 0, 4);
    let idx = |k: usize| u32::from_le_bytes(bin[at + 4 * k..at + 4 * k + 4].try_into().unwrap());
    ([idx(0), idx(1), idx(2)], at)
}

fn triangles_of(doc: &Value, mesh: &str) -> usize {
    let acc = as_usize(&primitive(doc, mesh)["indices"]);
    as_usize(&doc["accessors"][acc]["count"]) / 3
}

// --- containers ---------------------------------------------------------------------------

#[test]
fn truncated_glb() {
    let dir = temp_dir("truncated_glb");
    let points = points_csv(&dir);
    let glb = glb_of(&cornell_json(), &cornell_bin());
    // The whole file loads, so what fails below is the truncation alone.
    let whole = dir.join("cornell.glb");
    std::fs::write(&whole, &glb).unwrap();
    expect_clean_success(&reference(&whole, &points, &[]));
    let loaded = surfcache::io::load_gltf(&whole).unwrap();
    assert_eq!(loaded.scene.triangle_count(), cornell_triangles());

    for len in [100, 8, 30, glb.len() / 2, glb.len() - 1] {
        let cut = dir.join(format!("cut{len}.glb"));
        std::fs::write(&cut, &glb[..len]).unwrap();
        expect_error(
            &reference(&cut, &points, &[]),
            &[&format!("cut{len}.glb"), "truncated"],
        );
    }
}

#[test]
fn garbage_named_glb() {
    let dir = temp_dir("garbage_named_glb");
    let points = points_csv(&dir);
    // Deterministic noise (a 64-bit LCG), never starting with "glTF" or '{'.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut noise: Vec<u8> = (0..600)
        .map(|_| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 56) as u8
        })
        .collect();
    noise[0] = 0x89;
    let path = dir.join("noise.glb");
    std::fs::write(&path, &noise).unwrap();
    expect_error(
        &reference(&path, &points, &[]),
        &["noise.glb", "not a GLB file"],
    );

    // The magic and a consistent length, then noise: the chunk headers are nonsense.
    let mut fake = b"glTF".to_vec();
    fake.extend_from_slice(&2u32.to_le_bytes());
    fake.extend_from_slice(&(noise.len() as u32 + 12).to_le_bytes());
    fake.extend_from_slice(&noise);
    let path = dir.join("fake.glb");
    std::fs::write(&path, &fake).unwrap();
    expect_error(&reference(&path, &points, &[]), &["fake.glb"]);

    let empty = dir.join("empty.glb");
    std::fs::write(&empty, b"").unwrap();
    expect_error(&reference(&empty, &points, &[]), &["empty.glb", "empty"]);
}

#[test]
fn malformed_json_gltf() {
    let dir = temp_dir("malformed_json_gltf");
    let points = points_csv(&dir);
    std::fs::write(dir.join("cornell.bin"), cornell_bin()).unwrap();
    let text = std::fs::read_to_string(Path::new(ASSETS).join("cornell.gltf")).unwrap();
    let cut = dir.join("cut.gltf");
    std::fs::write(&cut, &text[..text.len() / 2]).unwrap();
    expect_error(
        &reference(&cut, &points, &[]),
        &["cut.gltf", "malformed glTF JSON"],
    );

    // Valid JSON that is not a glTF document.
    let wrong = dir.join("wrong.gltf");
    std::fs::write(&wrong, r#"{"asset": 3, "meshes": "none"}"#).unwrap();
    expect_error(&reference(&wrong, &points, &[]), &["wrong.gltf"]);
}

// --- referenced files ---------------------------------------------------------------------

#[test]
fn missing_buffer_file() {
    let dir = temp_dir("missing_buffer_file");
    let points = points_csv(&dir);
    let mut doc = cornell_json();
    doc["buffers"][0]["uri"] = json!("gone.bin");
    let path = dir.join("nobuf.gltf");
    std::fs::write(&path, serde_json::to_vec(&doc).unwrap()).unwrap();
    expect_error(
        &reference(&path, &points, &[]),
        &["nobuf.gltf", "buffer 0", "gone.bin", "not found"],
    );
}

#[test]
fn missing_image_file() {
    let dir = temp_dir("missing_image_file");
    let points = points_csv(&dir);
    let mut doc = cornell_json();
    doc["images"] = json!([{ "uri": "gone.png" }]);
    doc["textures"] = json!([{ "source": 0 }]);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({ "index": 0 });
    let path = write_gltf(&dir, "noimage", &doc, &cornell_bin());
    expect_error(
        &reference(&path, &points, &[]),
        &["noimage.gltf", "image 0", "gone.png", "not found"],
    );
}

// --- accessors and primitives ---------------------------------------------------------------

#[test]
fn accessor_out_of_range() {
    let dir = temp_dir("accessor_out_of_range");
    let points = points_csv(&dir);
    let bin = cornell_bin();
    let floor_positions = as_usize(&primitive(&cornell_json(), "floor")["attributes"]["POSITION"]);
    let floor_indices = as_usize(&primitive(&cornell_json(), "floor")["indices"]);

    // Count beyond the buffer view.
    let mut doc = cornell_json();
    doc["accessors"][floor_positions]["count"] = json!(400);
    let path = write_gltf(&dir, "count", &doc, &bin);
    expect_error(
        &reference(&path, &points, &[]),
        &[
            "count.gltf",
            "floor",
            &format!("accessor {floor_positions}"),
            "400 elements",
        ],
    );

    // Offset pushing the last element past the view.
    let mut doc = cornell_json();
    doc["accessors"][floor_indices]["byteOffset"] = json!(8);
    let path = write_gltf(&dir, "offset", &doc, &bin);
    expect_error(
        &reference(&path, &points, &[]),
        &[
            "offset.gltf",
            "floor",
            &format!("accessor {floor_indices}"),
            "byte 8",
        ],
    );

    // A buffer view beyond the buffer.
    let mut doc = cornell_json();
    let view = as_usize(&doc["accessors"][floor_positions]["bufferView"]);
    doc["bufferViews"][view]["byteOffset"] = json!(bin.len() - 8);
    let path = write_gltf(&dir, "view", &doc, &bin);
    expect_error(
        &reference(&path, &points, &[]),
        &[
            "view.gltf",
            &format!("buffer view {view}"),
            "beyond buffer 0",
        ],
    );

    // An index naming a vertex that does not exist.
    let mut bad = bin.clone();
    let (_, at) = first_triangle(&cornell_json(), &bin, "floor");
    bad[at..at + 4].copy_from_slice(&77u32.to_le_bytes());
    let path = write_gltf(&dir, "index", &cornell_json(), &bad);
    expect_error(
        &reference(&path, &points, &[]),
        &["index.gltf", "floor", "77"],
    );
}

#[test]
fn points_and_lines_primitives_are_skipped() {
    let dir = temp_dir("points_and_lines_primitives_are_skipped");
    let points = points_csv(&dir);
    let mut doc = cornell_json();
    let back = mesh_index(&doc, "back_wall");
    let red = mesh_index(&doc, "red_wall");
    doc["meshes"][back]["primitives"][0]["mode"] = json!(0); // POINTS
    doc["meshes"][red]["primitives"][0]["mode"] = json!(1); // LINES
    let path = write_gltf(&dir, "mixed", &doc, &cornell_bin());
    expect_warning(
        &reference(&path, &points, &[]),
        &["skipped 2 primitive(s)", "points or lines"],
    );
    let loaded = surfcache::io::load_gltf(&path).unwrap();
    assert_eq!(loaded.report.skipped_primitives, 2);
    assert_eq!(loaded.report.degenerate_triangles, 0);
    assert_eq!(
        loaded.scene.triangle_count(),
        cornell_triangles() - triangles_of(&doc, "back_wall") - triangles_of(&doc, "red_wall")
    );
}

#[test]
fn only_points_and_lines_is_an_error() {
    let dir = temp_dir("only_points_and_lines_is_an_error");
    let points = points_csv(&dir);
    let mut doc = cornell_json();
    let meshes = doc["meshes"].as_array().unwrap().len();
    for m in 0..meshes {
        doc["meshes"][m]["primitives"][0]["mode"] = json!(if m % 2 == 0 { 3 } else { 0 });
    }
    let path = write_gltf(&dir, "lines", &doc, &cornell_bin());
    expect_error(
        &reference(&path, &points, &[]),
        &[
            "lines.gltf",
            "the scene has no triangles",
            &format!("{meshes} point/line primitive(s) skipped"),
        ],
    );
}

#[test]
fn nan_vertex_position() {
    let dir = temp_dir("nan_vertex_position");
    let points = points_csv(&dir);
    let doc = cornell_json();
    let mut bin = cornell_bin();
    let at = position_offset(&doc, "back_wall", 2);
    let mut p = read_vec3(&bin, at);
    p.y = f32::NAN;
    write_vec3(&mut bin, at, p);
    let path = write_gltf(&dir, "nan", &doc, &bin);
    expect_error(
        &reference(&path, &points, &[]),
        &["nan.gltf", "mesh 'back_wall'", "vertex 2", "NaN"],
    );
}

#[test]
fn infinite_vertex_position() {
    let dir = temp_dir("infinite_vertex_position");
    let points = points_csv(&dir);
    let doc = cornell_json();
    let mut bin = cornell_bin();
    let at = position_offset(&doc, "short_block", 5);
    let mut p = read_vec3(&bin, at);
    p.z = f32::NEG_INFINITY;
    write_vec3(&mut bin, at, p);
    let path = write_gltf(&dir, "inf", &doc, &bin);
    expect_error(
        &reference(&path, &points, &[]),
        &["inf.gltf", "mesh 'short_block'", "vertex 5", "inf"],
    );
}

#[test]
fn degenerate_triangles_are_dropped() {
    let dir = temp_dir("degenerate_triangles_are_dropped");
    let points = points_csv(&dir);
    let doc = cornell_json();
    let mut bin = cornell_bin();
    // Floor: the first triangle repeats an index.
    let ([a, _, c], at) = first_triangle(&doc, &bin, "floor");
    for (k, i) in [a, a, c].into_iter().enumerate() {
        bin[at + 4 * k..at + 4 * k + 4].copy_from_slice(&i.to_le_bytes());
    }
    // Back wall: the first triangle's third corner moves onto the middle of its first edge,
    // so its indices differ but its area is zero.
    let ([a, b, c], _) = first_triangle(&doc, &bin, "back_wall");
    let pa = read_vec3(&bin, position_offset(&doc, "back_wall", a as usize));
    let pb = read_vec3(&bin, position_offset(&doc, "back_wall", b as usize));
    write_vec3(
        &mut bin,
        position_offset(&doc, "back_wall", c as usize),
        0.5 * (pa + pb),
    );
    let path = write_gltf(&dir, "degenerate", &doc, &bin);
    expect_warning(
        &reference(&path, &points, &[]),
        &["dropped 2 degenerate or zero-area triangle(s)"],
    );
    let loaded = surfcache::io::load_gltf(&path).unwrap();
    assert_eq!(loaded.report.degenerate_triangles, 2);
    assert_eq!(loaded.report.skipped_primitives, 0);
    assert_eq!(loaded.scene.triangle_count(), cornell_triangles() - 2);
    // The other halves of both quads remain.
    for name in ["floor", "back_wall"] {
        let inst = loaded
            .scene
            .instances
            .iter()
            .find(|i| i.name == name)
            .unwrap();
        assert_eq!(inst.mesh.indices.len(), triangles_of(&doc, name) - 1);
    }
}

// --- environment maps -----------------------------------------------------------------------

const ENV_W: usize = 8;
const ENV_H: usize = 4;

/// Writes an 8×4 RGB f32 EXR directly with the exr crate (write_rgb_exr refuses
/// non-finite values), uniform 1 except `special` at pixel `at` in channel `channel`.
fn write_env(path: &Path, at: (usize, usize), channel: usize, special: f32) {
    exr::prelude::write_rgb_file(path, ENV_W, ENV_H, |x, y| {
        let mut v = [1.0f32; 3];
        if (x, y) == at {
            v[channel] = special;
        }
        (v[0], v[1], v[2])
    })
    .unwrap();
}

#[test]
fn environment_map_with_nan() {
    let dir = temp_dir("environment_map_with_nan");
    let points = points_csv(&dir);
    let env = dir.join("nan.exr");
    write_env(&env, (5, 2), 1, f32::NAN);
    expect_error(
        &reference("cornell", &points, &["--env", env.to_str().unwrap()]),
        &["nan.exr", "pixel (5, 2)", "channel G", "NaN"],
    );
}

#[test]
fn environment_map_with_infinity() {
    let dir = temp_dir("environment_map_with_infinity");
    let points = points_csv(&dir);
    let env = dir.join("inf.exr");
    write_env(&env, (0, 3), 2, f32::INFINITY);
    expect_error(
        &reference("cornell", &points, &["--env", env.to_str().unwrap()]),
        &["inf.exr", "pixel (0, 3)", "channel B", "infinity"],
    );
}

#[test]
fn environment_map_with_negative_values_is_clamped() {
    let dir = temp_dir("environment_map_with_negative_values_is_clamped");
    let points = points_csv(&dir);
    let env = dir.join("negative.exr");
    write_env(&env, (6, 1), 0, -3.0);
    expect_warning(
        &reference("cornell", &points, &["--env", env.to_str().unwrap()]),
        &["negative.exr", "1 pixels had negative values, clamped to 0"],
    );
    let (map, warnings) = surfcache::io::read_environment_map(&env).unwrap();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert_eq!((map.width, map.height), (ENV_W as u32, ENV_H as u32));
    for j in 0..ENV_H as u32 {
        for i in 0..ENV_W as u32 {
            let expected = if (i, j) == (6, 1) {
                Vec3::new(0.0, 1.0, 1.0)
            } else {
                Vec3::ONE
            };
            assert_eq!(map.texel(i, j), expected, "pixel ({i}, {j})");
        }
    }
}

#[test]
fn environment_map_without_rgb_channels() {
    let dir = temp_dir("environment_map_without_rgb_channels");
    let points = points_csv(&dir);
    use exr::prelude::WritableImage;
    let env = dir.join("luminance.exr");
    let channels = exr::prelude::SpecificChannels::build()
        .with_channel("Y")
        .with_pixel_fn(|_| (1.0f32,));
    exr::prelude::Image::from_channels((ENV_W, ENV_H), channels)
        .write()
        .to_file(&env)
        .unwrap();
    expect_error(
        &reference("cornell", &points, &["--env", env.to_str().unwrap()]),
        &["luminance.exr", "no R, G, B channels", "found: Y"],
    );
}

#[test]
fn environment_map_that_is_not_exr() {
    let dir = temp_dir("environment_map_that_is_not_exr");
    let points = points_csv(&dir);
    let env = dir.join("text.exr");
    std::fs::write(&env, "this is not an image\n").unwrap();
    expect_error(
        &reference("cornell", &points, &["--env", env.to_str().unwrap()]),
        &["text.exr"],
    );
    // A real EXR cut short.
    let whole = dir.join("whole.exr");
    write_env(&whole, (0, 0), 0, 1.0);
    let bytes = std::fs::read(&whole).unwrap();
    let cut = dir.join("cut.exr");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    expect_error(
        &reference("cornell", &points, &["--env", cut.to_str().unwrap()]),
        &["cut.exr"],
    );
}

// --- command-line arguments -----------------------------------------------------------------

#[test]
fn unknown_builtin_scene() {
    let dir = temp_dir("unknown_builtin_scene");
    let points = points_csv(&dir);
    expect_error(
        &reference("cornel", &points, &[]),
        &["unknown built-in scene 'cornel'", "cornell"],
    );
}

#[test]
fn missing_files() {
    let dir = temp_dir("missing_files");
    let points = points_csv(&dir);
    let scene = dir.join("absent.gltf");
    expect_error(&reference(&scene, &points, &[]), &["absent.gltf"]);
    let scene = dir.join("absent.glb");
    expect_error(&reference(&scene, &points, &[]), &["absent.glb"]);
    let env = dir.join("absent.exr");
    expect_error(
        &reference("cornell", &points, &["--env", env.to_str().unwrap()]),
        &["absent.exr"],
    );
    expect_error(
        &reference("cornell", &dir.join("absent.csv"), &[]),
        &["points file", "absent.csv"],
    );
}

#[test]
fn points_csv_with_bad_header() {
    let dir = temp_dir("points_csv_with_bad_header");
    let path = dir.join("bad_header.csv");
    std::fs::write(&path, "x,y,z,r,g,b\n0.3,0,0.3,0,1,0\n").unwrap();
    expect_error(
        &reference("cornell", &path, &[]),
        &["bad_header.csv", "header must be 'x,y,z,nx,ny,nz'"],
    );
    // And a good file for contrast: the same row under the right header runs.
    expect_clean_success(&reference("cornell", &points_csv(&dir), &[]));
}

// --- bake options that do not apply to the chosen method ----------------------------------

/// `surfcache bake cornell ARGS… -o OUT`, with backtraces enabled.
fn bake(out: &Path, args: &[&str]) -> Output {
    Command::new(SURFCACHE)
        .args(["bake", "cornell"])
        .args(args)
        .arg("-o")
        .arg(out)
        .env("RUST_BACKTRACE", "1")
        .output()
        .expect("the surfcache binary runs")
}

/// An option of one method given with another is an error, not silently ignored
/// (docs/cli.md, `surfcache bake`), and nothing is written.
#[test]
fn bake_options_that_do_not_apply_to_the_method() {
    let dir = temp_dir("bake_options_that_do_not_apply_to_the_method");
    let out = dir.join("out");
    let density = "--density applies to --method irradiance-map and lightmap only";
    let interpolation = "--interpolation-error applies to --method irradiance-map only";
    let share = "--no-share-corners applies to --method irradiance-map only";
    let filter = "--filter-passes applies to --method lightmap only";
    let guiding = "--no-guiding applies to --method lightmap only";
    let cases: [(&[&str], &str); 9] = [
        (&["--method", "vertex", "--density", "8"], density),
        // Checked before the value: the option is wrong whatever its value.
        (&["--method", "vertex", "--density", "0"], density),
        (
            &["--method", "vertex", "--interpolation-error", "0.1"],
            interpolation,
        ),
        // The default method, lightmaps.
        (&["--interpolation-error", "0.1"], interpolation),
        (&["--method", "vertex", "--no-share-corners"], share),
        (&["--method", "lightmap", "--no-share-corners"], share),
        (
            &["--method", "irradiance-map", "--filter-passes", "2"],
            filter,
        ),
        (&["--method", "vertex", "--no-guiding"], guiding),
        (&["--method", "irradiance-map", "--no-guiding"], guiding),
    ];
    for (args, message) in cases {
        let line = expect_error(&bake(&out, args), &[message]);
        assert_eq!(line, format!("error: {message}"), "{args:?}");
        assert!(
            std::fs::read_dir(&dir).unwrap().next().is_none(),
            "{args:?} wrote into {}",
            dir.display()
        );
    }
}

// --- text from files that a message quotes --------------------------------------------------

/// A name no terminal should receive raw: line breaks, a colour and a screen-clearing escape
/// sequence, an OSC title sequence ended by BEL, a C1 CSI, a right-to-left override, a line
/// separator and a long tail that a message must cut.
fn hostile_name() -> String {
    format!(
        "evil\nline\r\u{1b}[31mred\u{1b}[2J\u{1b}]0;title\u{7}\u{9b}1m\u{202e}rtl\u{2028}{}",
        "x".repeat(600)
    )
}

/// The characters a message line may not hold: controls (C0, DEL, C1) and the invisible
/// format characters that reorder or hide text.
fn unprintable(c: char) -> bool {
    c.is_control()
        || matches!(c, '\u{200b}'..='\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2028}' | '\u{2029}'
            | '\u{2066}'..='\u{2069}' | '\u{feff}' | '\u{61c}')
}

/// Like [`expect_error`], and the line is UTF-8, holds nothing [`unprintable`] and is not
/// long: a name the message quotes is cut, and so is a cause quoting a long excerpt.
#[track_caller]
fn expect_printable_error(out: &Output, needles: &[&str]) -> String {
    assert!(
        std::str::from_utf8(&out.stderr).is_ok(),
        "stderr is not UTF-8: {:?}",
        out.stderr
    );
    let line = expect_error(out, needles);
    if let Some(c) = line.chars().find(|&c| unprintable(c)) {
        panic!("unprintable {c:?} in: {line:?}");
    }
    assert!(line.chars().count() < 800, "not cut: {line}");
    line
}

/// What the line shows of [`hostile_name`] is cut short.
#[track_caller]
fn assert_name_cut(line: &str) {
    assert!(!line.contains(&"x".repeat(100)), "name not cut: {line}");
}

/// glTF names (mesh, material, node, image, URIs, extensions) through `.gltf` and `.glb`.
#[test]
fn gltf_names_are_escaped() {
    let dir = temp_dir("gltf_names_are_escaped");
    let points = points_csv(&dir);
    let name = hostile_name();
    let bin = cornell_bin();
    // What each message must show of the name: its start, escaped, and cut.
    let shown =
        r"evil\nline\r\u{1b}[31mred\u{1b}[2J\u{1b}]0;title\u{7}\u{9b}1m\u{202e}rtl\u{2028}…";

    // A mesh name, in an accessor error, a scene validation error (NaN), as .gltf and .glb.
    let mut doc = cornell_json();
    let floor = mesh_index(&doc, "floor");
    doc["meshes"][floor]["name"] = json!(name);
    let positions = as_usize(&doc["meshes"][floor]["primitives"][0]["attributes"]["POSITION"]);
    let mut count = doc.clone();
    count["accessors"][positions]["count"] = json!(400);
    let path = write_gltf(&dir, "mesh_count", &count, &bin);
    expect_printable_error(&reference(&path, &points, &[]), &["mesh_count.gltf", shown]);
    let glb = dir.join("mesh_count.glb");
    std::fs::write(&glb, glb_of(&count, &bin)).unwrap();
    expect_printable_error(&reference(&glb, &points, &[]), &["mesh_count.glb", shown]);
    let mut nan = bin.clone();
    let at = element_offset(&doc, positions, 1, 12);
    nan[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    let path = write_gltf(&dir, "mesh_nan", &doc, &nan);
    expect_printable_error(
        &reference(&path, &points, &[]),
        &["mesh_nan.gltf", shown, "NaN"],
    );

    // A material name.
    let mut doc = cornell_json();
    doc["materials"][0]["name"] = json!(name);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = json!([1e39, 1, 1, 1]);
    let path = write_gltf(&dir, "material", &doc, &bin);
    expect_printable_error(
        &reference(&path, &points, &[]),
        &["material.gltf", shown, "not finite"],
    );

    // A node name, on a node whose transform is not finite.
    let mut doc = cornell_json();
    let node = doc["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .position(|n| n.get("mesh").is_some())
        .unwrap();
    doc["nodes"][node]["name"] = json!(name);
    doc["nodes"][node]["scale"] = json!([1e39, 1, 1]);
    let path = write_gltf(&dir, "node", &doc, &bin);
    expect_printable_error(&reference(&path, &points, &[]), &["node.gltf", shown]);

    // An image URI and an image name.
    let mut doc = cornell_json();
    doc["images"] = json!([{ "uri": format!("{name}.png") }]);
    doc["textures"] = json!([{ "source": 0 }]);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({ "index": 0 });
    let path = write_gltf(&dir, "image_uri", &doc, &bin);
    expect_printable_error(
        &reference(&path, &points, &[]),
        &["image_uri.gltf", "image 0", shown, "not found"],
    );
    let mut doc = cornell_json();
    doc["images"] = json!([{ "name": name, "uri": "data:image/png;base64,AAAA" }]);
    doc["textures"] = json!([{ "source": 0 }]);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({ "index": 0 });
    let path = write_gltf(&dir, "image_name", &doc, &bin);
    expect_printable_error(
        &reference(&path, &points, &[]),
        &["image_name.gltf", "image 0", shown],
    );

    // Buffer URIs: a missing file, a bad %-escape, a scheme, one decoding to invalid UTF-8.
    for (file, uri, needle) in [
        ("buffer_missing", format!("{name}.bin"), shown),
        ("buffer_escape", format!("{name}%zz.bin"), "bad %-escape"),
        (
            "buffer_scheme",
            format!("\u{1b}[2J{name}:x"),
            "unsupported URI scheme",
        ),
        (
            "buffer_utf8",
            format!("a%ff%9b\u{1b}[2J{name}"),
            "does not decode to UTF-8",
        ),
    ] {
        let mut doc = cornell_json();
        doc["buffers"][0]["uri"] = json!(uri);
        let path = dir.join(format!("{file}.gltf"));
        std::fs::write(&path, serde_json::to_vec(&doc).unwrap()).unwrap();
        expect_printable_error(
            &reference(&path, &points, &[]),
            &[&format!("{file}.gltf"), "buffer 0", needle],
        );
    }

    // A required extension: gltf's validation quotes it (and the cause is cut).
    let mut doc = cornell_json();
    doc["extensionsRequired"] = json!([name]);
    doc["extensionsUsed"] = json!([name]);
    let path = write_gltf(&dir, "extension", &doc, &bin);
    expect_printable_error(
        &reference(&path, &points, &[]),
        &[
            "extension.gltf",
            "extensionsRequired",
            r"evil\nline\r\u{1b}[31m",
        ],
    );

    // JSON that does not parse: raw control characters and invalid UTF-8 inside strings, and
    // a value of the wrong type (serde quotes it).
    let text = std::fs::read(Path::new(ASSETS).join("cornell.gltf")).unwrap();
    let mut raw = b"{\"asset\":{\"version\":\"2.0\"},\"scene\":\"\x1b[2J\n\xff\x9b\"".to_vec();
    raw.extend_from_slice(&text[1..]);
    let path = dir.join("raw.gltf");
    std::fs::write(&path, &raw).unwrap();
    expect_printable_error(&reference(&path, &points, &[]), &["raw.gltf"]);
    let mut doc = cornell_json();
    doc["scene"] = json!("\u{1b}[2J\nevil\u{202e}");
    let path = write_gltf(&dir, "wrong_type", &doc, &bin);
    expect_printable_error(&reference(&path, &points, &[]), &["wrong_type.gltf"]);
    // serde quotes the whole string: the cause is cut.
    let mut doc = cornell_json();
    doc["scene"] = json!(name);
    let path = write_gltf(&dir, "long", &doc, &bin);
    expect_printable_error(&reference(&path, &points, &[]), &["long.gltf", "evil"]);
}

/// A mesh name in a warning (the file still loads): one printable warning line.
#[test]
fn gltf_names_in_warnings_are_escaped() {
    let dir = temp_dir("gltf_names_in_warnings_are_escaped");
    let points = points_csv(&dir);
    let mut doc = cornell_json();
    let wall = mesh_index(&doc, "back_wall");
    doc["meshes"][wall]["name"] = json!(hostile_name());
    let indices = as_usize(&doc["meshes"][wall]["primitives"][0]["indices"]);
    let count = as_usize(&doc["accessors"][indices]["count"]);
    doc["accessors"][indices]["count"] = json!(count - 1);
    let path = write_gltf(&dir, "warn", &doc, &cornell_bin());
    let out = reference(&path, &points, &[]);
    let line = expect_warning(&out, &[r"evil\nline\r\u{1b}[31m", "not a multiple of 3"]);
    assert!(!line.chars().any(unprintable), "{line:?}");
    assert_name_cut(&line);
}

/// An EXR whose channel names hold a line break, an escape sequence and bytes that are not
/// UTF-8 (the fuzz failure of `SURFCACHE_FUZZ_SEED=1796197522859263124`, by hand).
#[test]
fn exr_channel_names_are_escaped() {
    use exr::prelude::*;
    let dir = temp_dir("exr_channel_names_are_escaped");
    let points = points_csv(&dir);
    let env = dir.join("channels.exr");
    let samples = || FlatSamples::F32(vec![1.0; ENV_W * ENV_H]);
    let names: [&[u8]; 4] = [b"\n", b"G", b"R\x1b[31m\r", b"\xff\x9b"];
    let channels = AnyChannels::sort(
        names
            .iter()
            .map(|n| AnyChannel::new(Text::from_slice_unchecked(n), samples()))
            .collect::<SmallVec<_>>(),
    );
    Image::from_channels((ENV_W, ENV_H), channels)
        .write()
        .to_file(&env)
        .unwrap();
    let line = expect_printable_error(
        &reference("cornell", &points, &["--env", env.to_str().unwrap()]),
        &["channels.exr", "no R, G, B channels"],
    );
    assert!(
        line.contains(r"found: \n, G, R\u{1b}[31m\r, \xff\x9b)"),
        "{line}"
    );
}

/// Paths with control characters and bytes that are not UTF-8, the CSV points header and a
/// built-in scene name.
#[test]
fn paths_csv_headers_and_scene_names_are_escaped() {
    use std::os::unix::ffi::OsStrExt;
    let dir = temp_dir("paths_csv_headers_and_scene_names_are_escaped");
    let points = points_csv(&dir);
    let bad = std::ffi::OsStr::from_bytes(b"bad\n\x1b[2J\xff\x9b");
    let mut missing_exr = dir.join(bad).into_os_string();
    missing_exr.push(".exr");
    let out = Command::new(SURFCACHE)
        .args(["reference", "cornell", "--samples", "1", "--env"])
        .arg(&missing_exr)
        .arg(&points)
        .output()
        .unwrap();
    expect_printable_error(&out, &[r"bad\n\u{1b}[2J\xff\x9b.exr"]);
    // A scene argument is text, so its path has no invalid UTF-8.
    let missing_gltf = dir.join("bad\n\u{1b}[2J.gltf");
    expect_printable_error(
        &reference(&missing_gltf, &points, &[]),
        &[r"bad\n\u{1b}[2J.gltf"],
    );
    let mut missing_csv = dir.join(bad).into_os_string();
    missing_csv.push(".csv");
    expect_printable_error(
        &reference("cornell", Path::new(&missing_csv), &[]),
        &["points file", r"bad\n\u{1b}[2J\xff\x9b.csv"],
    );

    let csv = dir.join("header.csv");
    std::fs::write(
        &csv,
        format!("x,y,z,\u{1b}[2J\r{}\n0,0,0,0,1,0\n", hostile_name()),
    )
    .unwrap();
    expect_printable_error(
        &reference("cornell", &csv, &[]),
        &["header.csv", r"found 'x,y,z,\u{1b}[2J\revil'"],
    );
    let csv = dir.join("not_utf8.csv");
    std::fs::write(&csv, b"x,y,z,nx,ny,nz\n0,0,\xff\x1b[2J,0,1,0\n").unwrap();
    expect_printable_error(&reference("cornell", &csv, &[]), &["not_utf8.csv"]);
    let csv = dir.join("value.csv");
    std::fs::write(&csv, "x,y,z,nx,ny,nz\n0,0,\u{1b}[2J\u{9b}1m,0,1,0\n").unwrap();
    expect_printable_error(&reference("cornell", &csv, &[]), &["value.csv", "line 2"]);

    expect_printable_error(
        &reference("cornell\u{1b}[2J\n", &points, &[]),
        &[r"unknown built-in scene 'cornell\u{1b}[2J\n'"],
    );
}
