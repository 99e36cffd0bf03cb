//! Helpers shared by the root test binaries: scenes and meshes, complete bakes as the
//! product runs them, estimator settings, lookups at world points, a reproducible random
//! stream, tolerance checks, closed forms, the fast Cornell settings of the CLI tests, the
//! check that a run of the `surfcache` binary succeeded, a fresh directory per test, and
//! the Cornell glTF asset taken apart and packed as GLB.
#![allow(dead_code)]

use serde_json::Value;
use std::f32::consts::PI;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::Arc;
use surfcache::cache::{
    Cache, CacheSettings, SurfaceCache,
    bake::{BakeJob, BakeSettings},
};
use surfcache::core::{
    Environment, Instance, Light, Material, Mesh, Scene,
    glam::{Affine3A, Vec2, Vec3},
};
use surfcache::trace::{EstimatorSettings, Sampler, TracedScene};

/// A grey Lambertian material.
pub fn grey(albedo: f32) -> Material {
    Material::diffuse("grey", Vec3::splat(albedo))
}

/// An instance of `mesh` with `material` at the identity transform.
pub fn instance(mesh: Mesh, material: Material) -> Instance {
    Instance {
        name: mesh.name.clone(),
        mesh: Arc::new(mesh),
        material: Arc::new(material),
        transform: Affine3A::IDENTITY,
    }
}

/// A traced scene of `instances` under `environment`.
pub fn traced(instances: Vec<Instance>, environment: Environment) -> TracedScene {
    traced_with_lights(instances, environment, Vec::new())
}

/// A traced scene of `instances` and punctual `lights` under `environment`.
pub fn traced_with_lights(
    instances: Vec<Instance>,
    environment: Environment,
    lights: Vec<Light>,
) -> TracedScene {
    TracedScene::new(&Scene {
        name: "test".into(),
        instances,
        lights,
        environment,
    })
    .expect("a valid scene")
}

/// Adaptive `best` estimates with bound `max_rel_error` and the default sample limits
/// (the job fills in the floor).
pub fn estimator(max_rel_error: f32) -> EstimatorSettings {
    let d = EstimatorSettings::default();
    estimator_with(max_rel_error, d.min_samples, d.max_samples, 0.0)
}

/// Adaptive `best` estimates with bound `max_rel_error`, between `min_samples` and
/// `max_samples` samples, and absolute floor `floor` (0: a bake job measures it).
pub fn estimator_with(
    max_rel_error: f32,
    min_samples: u32,
    max_samples: u32,
    floor: f32,
) -> EstimatorSettings {
    EstimatorSettings {
        sampler: Sampler::Best,
        max_rel_error,
        min_samples,
        max_samples,
        floor,
        max_bounces: None,
    }
}

/// xorshift32: reproducible test points.
pub struct Points(pub u32);

impl Points {
    pub fn next_f32(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 17;
        self.0 ^= self.0 << 5;
        (self.0 >> 8) as f32 / 16_777_216.0
    }

    /// Uniform barycentrics (u, v) in the triangle.
    pub fn barycentrics(&mut self) -> Vec2 {
        let (u, v) = (self.next_f32(), self.next_f32());
        if u + v > 1.0 {
            Vec2::new(1.0 - u, 1.0 - v)
        } else {
            Vec2::new(u, v)
        }
    }
}

/// |E − expected| ≤ `sigmas` · se + 1e-4 · expected + 1e-6 in every channel, for an
/// estimate `got` = (E, its standard error se).
#[track_caller]
pub fn assert_within_errors(got: (Vec3, Vec3), expected: Vec3, sigmas: f32, what: &str) {
    let (e, se) = got;
    for c in 0..3 {
        let tol = sigmas * se[c] + 1e-4 * expected[c].abs() + 1e-6;
        assert!(
            (e[c] - expected[c]).abs() <= tol,
            "{what}: channel {c}: got {} ± {}, expected {}",
            e[c],
            se[c],
            expected[c]
        );
    }
}

/// `got` is finite and |got − expected| ≤ 4·rel·(expected + floor) + expected/1024 + 10⁻⁶
/// in every channel: four standard errors of an estimate stopped at relative error `rel`
/// with absolute floor `floor`, plus half-float rounding.
#[track_caller]
pub fn assert_near(got: Vec3, expected: Vec3, rel: f32, floor: f32, what: &str) {
    for c in 0..3 {
        let tol = 4.0 * rel * (expected[c] + floor) + expected[c] / 1024.0 + 1e-6;
        assert!(
            got.is_finite() && (got[c] - expected[c]).abs() <= tol,
            "{what}: got {got}, expected {expected} (channel {c}, tolerance {tol})"
        );
    }
}

/// A complete bake as `surfcache bake` runs it (bounce passes, the default density
/// budget) of `cache` with `estimator`. Returns the final cache and the floor ε.
pub fn bake(
    scene: &TracedScene,
    cache: CacheSettings,
    estimator: EstimatorSettings,
) -> (Arc<Cache>, f32) {
    bake_with(
        scene,
        BakeSettings {
            cache,
            estimator,
            ..Default::default()
        },
    )
}

/// A complete bake with `settings`: the final cache and the floor ε the job measured.
pub fn bake_with(scene: &TracedScene, settings: BakeSettings) -> (Arc<Cache>, f32) {
    let mut job = BakeJob::new(settings);
    while !job.step(scene, 4096) {}
    let floor = job.floor().expect("the job measured the scene");
    let outcome = job.into_outcome().expect("the bake finished");
    (outcome.cache().clone(), floor)
}

/// The surface a world point with normal `n` lies on: (triangle, barycentrics, front).
pub fn locate(scene: &TracedScene, x: Vec3, n: Vec3) -> (u32, Vec2, bool) {
    let p = scene
        .locate(x, n)
        .unwrap_or_else(|| panic!("{x} is on no surface"));
    let front = p
        .geometric_normal
        .dot(scene.geometric_normals()[p.triangle as usize])
        > 0.0;
    (p.triangle, p.uv, front)
}

/// A cache's irradiance at world point `x` on the side `n` looks at.
pub fn lookup(cache: &dyn SurfaceCache, scene: &TracedScene, x: Vec3, n: Vec3) -> Vec3 {
    let (t, uv, front) = locate(scene, x, n);
    cache.lookup(t, uv, front)
}

/// Irradiance at `x` (normal `n`) from a planar polygon of uniform radiance `radiance`
/// lying wholly on the side of `x`'s tangent plane that `n` points to: Lambert's formula
/// (Arvo 1995, "Applications of Irradiance Tensors", eq. 1),
/// `E = L/2 · |Σ_i Θ_i ⟨n, γ̂_i⟩|`, `Θ_i` the angle the edge v_i v_{i+1} subtends at `x`
/// and `γ̂_i` the unit normal of the plane through `x` and that edge.
pub fn polygon_irradiance(x: Vec3, n: Vec3, polygon: &[Vec3], radiance: f32) -> f32 {
    let mut sum = 0.0f64;
    for i in 0..polygon.len() {
        let a = (polygon[i] - x).normalize().as_dvec3();
        let b = (polygon[(i + 1) % polygon.len()] - x)
            .normalize()
            .as_dvec3();
        let theta = a.dot(b).clamp(-1.0, 1.0).acos();
        let Some(gamma) = a.cross(b).try_normalize() else {
            continue;
        };
        sum += theta * n.as_dvec3().dot(gamma);
    }
    (0.5 * radiance as f64 * sum.abs()) as f32
}

/// The part of polygon `p` on the side `n · (y − x) ≥ 0` of the plane through `x`
/// (Sutherland–Hodgman clipping against one plane).
pub fn clip_polygon(p: &[Vec3], x: Vec3, n: Vec3) -> Vec<Vec3> {
    let mut out = Vec::with_capacity(p.len() + 1);
    for i in 0..p.len() {
        let (a, b) = (p[i], p[(i + 1) % p.len()]);
        let (da, db) = (n.dot(a - x), n.dot(b - x));
        if da >= 0.0 {
            out.push(a);
        }
        if (da >= 0.0) != (db >= 0.0) {
            out.push(a + (b - a) * (da / (da - db)));
        }
    }
    out
}

/// Under a uniform sky of radiance `radiance` with black, opaque `blockers` (planar
/// polygons, mutually non-overlapping as seen from `x`): E = πL − Σ polygon irradiance of
/// each blocker's part above `x`'s tangent plane.
pub fn sky_minus_blockers(x: Vec3, n: Vec3, blockers: &[Vec<Vec3>], radiance: f32) -> f32 {
    let blocked: f32 = blockers
        .iter()
        .map(|p| clip_polygon(p, x, n))
        .filter(|p| p.len() >= 3)
        .map(|p| polygon_irradiance(x, n, &p, radiance))
        .sum();
    PI * radiance - blocked
}

/// Small settings that keep a Cornell bake to about a second: no bounce passes (full
/// paths), a 10 % bound, 8 samples per metre, two threads.
pub const CORNELL_FAST: [&str; 12] = [
    "--max-rel-error",
    "0.1",
    "--density",
    "8",
    "--gather",
    "0",
    "--min-samples",
    "64",
    "--max-samples",
    "4096",
    "--threads",
    "2",
];

/// A run's stderr as text.
pub fn stderr_of(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// No panic, backtrace or death by signal in a run of the `surfcache` binary.
pub fn assert_no_panic(out: &Output) {
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
pub fn expect_error(out: &Output, needles: &[&str]) -> String {
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
    one_stderr_line(&stderr, "error", needles)
}

/// `stderr` is exactly one line `KIND: …` (`error`, `warning`) containing every needle.
/// Returns the line.
#[track_caller]
pub fn one_stderr_line(stderr: &str, kind: &str, needles: &[&str]) -> String {
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 1, "expected one stderr line, got:\n{stderr}");
    let line = lines[0];
    assert!(
        line.starts_with(&format!("{kind}: ")),
        "not a {kind} line: {line}"
    );
    for needle in needles {
        assert!(line.contains(needle), "'{needle}' missing from: {line}");
    }
    line.to_string()
}

/// A fresh, empty directory for one test, in the test binary's own folder of cargo's
/// temporary directory.
pub fn temp_dir(test: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(env!("CARGO_CRATE_NAME"))
        .join(test);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The repository's `assets` folder.
pub const ASSETS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/assets");

/// The Cornell box glTF (`assets/cornell.gltf`) as JSON.
pub fn cornell_json() -> Value {
    let text = std::fs::read_to_string(Path::new(ASSETS).join("cornell.gltf")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// The Cornell box glTF's binary buffer (`assets/cornell.bin`).
pub fn cornell_bin() -> Vec<u8> {
    std::fs::read(Path::new(ASSETS).join("cornell.bin")).unwrap()
}

/// The index of the mesh called `name` in glTF document `doc`.
pub fn mesh_index(doc: &Value, name: &str) -> usize {
    doc["meshes"]
        .as_array()
        .unwrap()
        .iter()
        .position(|m| m["name"] == name)
        .unwrap_or_else(|| panic!("no mesh {name}"))
}

/// The run exited 0; otherwise fails showing its status and stderr.
#[track_caller]
pub fn expect_success(out: &Output, what: &str) {
    assert!(
        out.status.success(),
        "{what} failed: {:?}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Packs a JSON document and one binary buffer into a GLB (glTF 2.0, "GLB File Format
/// Specification"): 12-byte header, JSON chunk padded with spaces, BIN chunk padded with
/// zeros.
pub fn pack_glb(json: &[u8], bin: &[u8]) -> Vec<u8> {
    let mut json_chunk = json.to_vec();
    json_chunk.resize(json_chunk.len().next_multiple_of(4), b' ');
    let mut bin_chunk = bin.to_vec();
    bin_chunk.resize(bin_chunk.len().next_multiple_of(4), 0);
    let total = 12 + 8 + json_chunk.len() + 8 + bin_chunk.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json_chunk.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json_chunk);
    out.extend_from_slice(&(bin_chunk.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin_chunk);
    out
}
