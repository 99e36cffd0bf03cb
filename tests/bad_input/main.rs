//! Malformed and unsupported input (issue: foundation, "bad input"; docs/cli.md, "Exit status").
//!
//! Every case runs the `surfcache` binary on a file built here from `assets/cornell.gltf`
//! (or written by hand) and checks what a user sees: a non-zero exit status with exactly one
//! stderr line `error: …` naming the file and the cause, and never a panic or backtrace.
//! Inputs that are only doubtful (points/lines primitives, degenerate triangles, negative
//! radiance) load with exactly one `warning: …` line and exit 0. Bake options given with a
//! method they do not apply to are errors of the same kind.

mod arguments;
#[path = "../common/mod.rs"]
mod common;
mod environment;
mod escaping;
mod gltf_files;

use common::{
    ASSETS, assert_no_panic, expect_error, mesh_index, one_stderr_line, pack_glb, stderr_of,
};
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
    one_stderr_line(&stderr, "warning", needles)
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
