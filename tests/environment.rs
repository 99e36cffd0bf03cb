//! Environment-map orientation (docs/cli.md): an equirectangular map written with
//! `write_rgb_exr` and read back with `read_environment_map` lights the scene from the
//! directions the contract assigns to its pixels.
//!
//! The maps are built here from the contract's formula alone (pixel (i, j) of W×H covers
//! u = (i+½)/W, v = (j+½)/H, θ = vπ, φ = (u−½)2π, d = (sin θ sin φ, cos θ, −sin θ cos φ)),
//! not from `surfcache_core::environment`, and hold one smooth lobe
//! L(d) = L₀ max(0, d·a)^K around an axis `a`. A small black plane facing `n` then receives,
//! in closed form:
//! - n = a: E = 2π L₀ / (K+2);
//! - n ⟂ a: E = L₀ W_K / (K+2) with W_K = ∫_{−π/2}^{π/2} cos^K φ dφ = π (K−1)!!/K!!;
//! - n = −a: E = 0 exactly (the lobe is zero over that whole hemisphere).
//!
//! Checking all six faces for lobes at +X, +Y and −Z pins down every axis and sign.

use rayon::prelude::*;
use std::f64::consts::PI;
use std::path::Path;
use std::sync::Arc;
use surfcache::core::{
    Environment, Instance, Material, Scene,
    environment::uv_to_direction,
    glam::{Affine3A, Vec2, Vec3},
    scenes::quad,
};
use surfcache::trace::{EstimatorSettings, Query, Sampler, TracedScene, reference_irradiance};

const W: u32 = 512;
const H: u32 = 256;
const K: i32 = 64;
const L0: f32 = 40.0;
const SAMPLES: u32 = 1_000_000;

/// The contract's direction of pixel (i, j), written out independently of the crate.
fn contract_direction(i: u32, j: u32) -> Vec3 {
    let u = (i as f64 + 0.5) / W as f64;
    let v = (j as f64 + 0.5) / H as f64;
    let (theta, phi) = (v * PI, (u - 0.5) * 2.0 * PI);
    Vec3::new(
        (theta.sin() * phi.sin()) as f32,
        theta.cos() as f32,
        (-theta.sin() * phi.cos()) as f32,
    )
}

/// Row-major texels (row 0 at the top) of the lobe L₀ max(0, d·a)^K.
fn lobe_texels(axis: Vec3) -> Vec<Vec3> {
    let mut texels = Vec::with_capacity((W * H) as usize);
    for j in 0..H {
        for i in 0..W {
            let c = contract_direction(i, j).dot(axis).max(0.0);
            texels.push(Vec3::splat(L0 * c.powi(K)));
        }
    }
    texels
}

/// Writes the lobe map as EXR and reads it back through the environment-map loader.
fn lobe_map(dir: &Path, name: &str, axis: Vec3) -> surfcache::core::EnvironmentMap {
    let texels = lobe_texels(axis);
    let path = dir.join(format!("{name}.exr"));
    surfcache::io::write_rgb_exr(&path, W, H, &texels).unwrap();
    let (map, warnings) = surfcache::io::read_environment_map(&path).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!((map.width, map.height), (W, H));
    assert!(
        map.texels == texels,
        "{name}: EXR round trip changed texels"
    );
    map
}

/// A 10 cm black square at the origin whose front face looks along `normal`.
fn black_plane(normal: Vec3) -> Instance {
    let t = normal.any_orthonormal_vector() * 0.05;
    let b = normal.cross(t);
    Instance {
        name: "plane".into(),
        mesh: Arc::new(quad("plane", [-t - b, t - b, t + b, -t + b], normal)),
        material: Arc::new(Material::diffuse("black", Vec3::ZERO)),
        transform: Affine3A::IDENTITY,
    }
}

/// (E, standard error) of the red channel on the `normal` side of a black plane.
fn irradiance(map: &Arc<surfcache::core::EnvironmentMap>, normal: Vec3) -> (f32, f32) {
    let scene = Scene {
        instances: vec![black_plane(normal)],
        environment: Environment::from_map(map.clone()),
        ..Default::default()
    };
    let traced = TracedScene::new(&scene).unwrap();
    let q = Query {
        position: Vec3::ZERO,
        normal,
    };
    let settings = EstimatorSettings::fixed(Sampler::Best, SAMPLES, None);
    let e = reference_irradiance(&traced, &[q], &settings, 3, &|| {})[0]
        .expect("the query point lies on the plane");
    assert!(
        e.value.x == e.value.y && e.value.y == e.value.z,
        "grey map gave {:?}",
        e.value
    );
    (e.value.x, e.std_error.x)
}

/// W_K = ∫_{−π/2}^{π/2} cos^K φ dφ = π (K−1)!!/K!! for even K.
fn wallis(k: i32) -> f64 {
    assert!(k % 2 == 0);
    (1..=k / 2).fold(PI, |w, i| w * (2 * i - 1) as f64 / (2 * i) as f64)
}

#[test]
fn lobe_maps_light_the_faces_the_contract_says() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("environment_orientation");
    std::fs::create_dir_all(&dir).unwrap();
    let head_on = 2.0 * PI * L0 as f64 / (K + 2) as f64;
    let side = L0 as f64 * wallis(K) / (K + 2) as f64;
    let faces = [
        Vec3::X,
        Vec3::NEG_X,
        Vec3::Y,
        Vec3::NEG_Y,
        Vec3::Z,
        Vec3::NEG_Z,
    ];
    for (name, axis) in [
        ("plus_x", Vec3::X),
        ("plus_y", Vec3::Y),
        ("minus_z", Vec3::NEG_Z),
    ] {
        let map = Arc::new(lobe_map(&dir, name, axis));
        let results: Vec<(Vec3, (f32, f32))> = faces
            .par_iter()
            .map(|&n| (n, irradiance(&map, n)))
            .collect();
        for (n, (e, se)) in results {
            let expected = if n == axis {
                head_on
            } else if n == -axis {
                0.0
            } else {
                side
            } as f32;
            if expected == 0.0 {
                assert_eq!(e, 0.0, "lobe {name}: face {n} must be dark");
            } else {
                // 4 standard errors plus 1% for the map's pixels and bilinear lookup.
                let tol = 4.0 * se + 0.01 * expected;
                assert!(
                    (e - expected).abs() <= tol,
                    "lobe {name}: face {n}: E = {e} ± {se}, expected {expected}"
                );
            }
        }
    }
}

#[test]
fn brightest_pixel_looks_along_the_lobe_axis() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("environment_brightest");
    std::fs::create_dir_all(&dir).unwrap();
    // One pixel spans 2π/W = π/H radians; the brightest must be within one pixel of the axis.
    let pixel = std::f32::consts::TAU / W as f32;
    for (name, axis) in [
        ("plus_x", Vec3::X),
        ("minus_x", Vec3::NEG_X),
        ("plus_y", Vec3::Y),
        ("minus_z", Vec3::NEG_Z),
        ("plus_z", Vec3::Z),
    ] {
        let map = lobe_map(&dir, name, axis);
        let (k, _) =
            map.texels
                .iter()
                .enumerate()
                .fold((0, f32::NEG_INFINITY), |(bk, bv), (k, t)| {
                    if t.x > bv { (k, t.x) } else { (bk, bv) }
                });
        let (i, j) = (k as u32 % W, k as u32 / W);
        let uv = Vec2::new((i as f32 + 0.5) / W as f32, (j as f32 + 0.5) / H as f32);
        let d = uv_to_direction(uv);
        let angle = d.dot(axis).clamp(-1.0, 1.0).acos();
        assert!(
            angle <= pixel,
            "lobe {name}: brightest pixel ({i}, {j}) looks along {d}, {angle} rad off"
        );
        // The crate's lookup agrees: the lobe's peak radiance is seen along the axis.
        let peak = map.radiance(axis).x;
        assert!(
            peak > 0.99 * L0,
            "lobe {name}: radiance along the axis {peak}"
        );
        assert_eq!(map.radiance(-axis).x, 0.0, "lobe {name}: opposite side");
    }
}
