//! Bounce passes against the closed form they must sum to (issue #13): a closed box whose
//! inner walls emit Le with albedo ρ holds E = π Le / (1 − ρ) everywhere inside, the
//! geometric series of bounces. A complete bake ([`common::bake`]: direct light, bounce
//! passes gathered from the cache until the series has converged, then the final pass)
//! must reach it within 4·C·E for irradiance maps and lightmaps; stopping the series
//! early, or gathering with a wrong ρ/π factor, misses it by far more.

mod common;

use common::{bake, estimator, grey, instance, lookup, traced};
use std::{f32::consts::PI, sync::Arc};
use surfcache::cache::{
    CacheSettings, IrradianceMapSettings, LightmapSettings, Method, SurfaceCache,
    bake::{BakeJob, BakeSettings},
};
use surfcache::core::{
    Environment, Instance, Material, Texture,
    color::srgb8_to_linear,
    glam::{Affine3A, Quat, Vec2, Vec3},
    scenes::{cuboid, square, tiled_floor},
};
use surfcache::trace::TracedScene;

/// The caches that gather bounce passes (irradiance maps and lightmaps), front faces only.
fn front_only_caches() -> [CacheSettings; 2] {
    [
        CacheSettings::IrradianceMap(IrradianceMapSettings {
            both_sides: false,
            ..Default::default()
        }),
        CacheSettings::Lightmap(LightmapSettings {
            both_sides: false,
            ..Default::default()
        }),
    ]
}

#[test]
fn furnace_box_through_bounce_passes_sums_the_series() {
    let (le, rho) = (Vec3::new(1.0, 2.0, 0.5), 0.6);
    let expected = PI * le / (1.0 - rho);
    let wall = Material::emissive("wall", Vec3::splat(rho), le);
    let mesh = cuboid("box", Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0), true);
    let scene = traced(vec![instance(mesh, wall)], Environment::black());
    let points = [
        (Vec3::new(0.5, 0.0, 1.5), Vec3::Y),
        (Vec3::new(0.5, 2.0, 0.7), Vec3::NEG_Y),
        (Vec3::new(0.0, 1.0, 2.5), Vec3::X),
        (Vec3::new(0.9, 0.2, 3.0), Vec3::NEG_Z),
    ];
    assert_both_caches_hold(&scene, expected, &points);
}

/// Bakes `scene` as front-only irradiance maps and lightmaps at a 2 % bound and checks
/// that each holds `expected` within 4·C·E at every (point, normal) of `points`.
fn assert_both_caches_hold(scene: &TracedScene, expected: Vec3, points: &[(Vec3, Vec3)]) {
    let rel = 0.02;
    for settings in front_only_caches() {
        let (cache, _) = bake(scene, settings, estimator(rel));
        for &(x, n) in points {
            let got = lookup(cache.as_ref(), scene, x, n);
            for c in 0..3 {
                let tol = 4.0 * rel * expected[c] + expected[c] / 1024.0;
                assert!(
                    (got[c] - expected[c]).abs() <= tol,
                    "{}: channel {c} at {x}: {got} against {expected}",
                    settings.method().name()
                );
            }
        }
    }
}

/// Gathers read a textured hit's albedo averaged over half the cache's sample spacing, a
/// coarser level of its texture (docs/design.md, Gathering); that level must keep the
/// texture's mean. The furnace box with walls of a fine checker of two albedos (8 mm
/// squares on a 1 m box, so E does not see them) holds E = π Le / (1 − ρ̄), ρ̄ the mean of
/// their *linear* values. Averaging the encoded sRGB codes instead gives ρ̄ = 0.28 against
/// 0.42 here, and E 19 % low.
#[test]
fn textured_furnace_box_gathers_the_mean_albedo() {
    let codes = [60u8, 230u8];
    let lut = srgb8_to_linear();
    let mean = (lut[codes[0] as usize] + lut[codes[1] as usize]) / 2.0;
    let checker = (0..64 * 64)
        .map(|k| {
            let c = codes[(k % 64 + k / 64) % 2];
            [c, c, c, 255]
        })
        .collect();
    let texture = Texture::from_srgb8(64, 64, checker).expect("64 × 64 texels");
    let le = Vec3::new(1.0, 2.0, 0.5);
    let expected = PI * le / (1.0 - mean);
    let wall = Material {
        albedo_texture: Some(Arc::new(texture)),
        ..Material::emissive("wall", Vec3::ONE, le)
    };
    let mut mesh = cuboid("box", Vec3::ZERO, Vec3::ONE, true);
    // Each face mapped by its own plane, the texture repeated twice per metre.
    mesh.uv0 = mesh
        .positions
        .iter()
        .zip(&mesh.normals)
        .map(|(p, n)| {
            let a = n.abs().max_position();
            2.0 * Vec2::new(p[(a + 1) % 3], p[(a + 2) % 3])
        })
        .collect();
    let scene = traced(vec![instance(mesh, wall)], Environment::black());
    let points = [
        (Vec3::new(0.5, 0.0, 0.3), Vec3::Y),
        (Vec3::new(0.2, 1.0, 0.7), Vec3::NEG_Y),
        (Vec3::new(0.0, 0.6, 0.9), Vec3::X),
        (Vec3::new(0.9, 0.1, 1.0), Vec3::NEG_Z),
    ];
    assert_both_caches_hold(&scene, expected, &points);
}

/// The unit box `[0, 1]³` with its inward faces each tiled into `cells × cells` squares.
fn tiled_box(cells: u32, material: &Material) -> Vec<Instance> {
    let tile = Arc::new(tiled_floor(1.0, cells));
    [
        Vec3::X,
        Vec3::NEG_X,
        Vec3::Y,
        Vec3::NEG_Y,
        Vec3::Z,
        Vec3::NEG_Z,
    ]
    .into_iter()
    .map(|inward| Instance {
        name: format!("wall {inward}"),
        mesh: tile.clone(),
        material: Arc::new(material.clone()),
        // The tile (normal +Y) centred, turned to face inwards, moved to its face.
        transform: Affine3A::from_translation(Vec3::splat(0.5) - 0.5 * inward)
            * Affine3A::from_quat(Quat::from_rotation_arc(Vec3::Y, inward))
            * Affine3A::from_translation(Vec3::new(-0.5, 0.0, -0.5)),
    })
    .collect()
}

/// Bounce passes of irradiance maps over a finely tessellated mesh (every triangle shorter
/// than a sample spacing of the bounce density) are lightmaps, over large triangles their
/// own grids (docs/design.md, Baking); either way the furnace box sums the series to
/// π Le / (1 − ρ).
#[test]
fn fine_meshes_bounce_through_lightmaps_and_still_sum_the_series() {
    let (le, rho) = (Vec3::new(1.0, 2.0, 0.5), 0.6);
    let expected = PI * le / (1.0 - rho);
    let wall = Material::emissive("wall", Vec3::splat(rho), le);
    let coarse = traced(
        vec![instance(
            cuboid("box", Vec3::ZERO, Vec3::ONE, true),
            wall.clone(),
        )],
        Environment::black(),
    );
    // 12.5 cm tiles: diagonals of 18 cm against the bounce passes' 25 cm spacing.
    let fine = traced(tiled_box(8, &wall), Environment::black());
    let rel = 0.02;
    for (scene, bounce) in [(&coarse, Method::IrradianceMap), (&fine, Method::Lightmap)] {
        let mut job = BakeJob::new(BakeSettings {
            cache: CacheSettings::IrradianceMap(IrradianceMapSettings {
                density: 8.0,
                both_sides: false,
                ..Default::default()
            }),
            estimator: estimator(rel),
            density_budget: None,
            ..Default::default()
        });
        while !job.step(scene, 4096) {}
        let outcome = job.into_outcome().expect("the bake finished");
        let (last, bounces) = outcome.passes.split_last().unwrap();
        assert!(!bounces.is_empty());
        assert!(bounces.iter().all(|p| p.method() == bounce), "{bounce:?}");
        assert_eq!(last.method(), Method::IrradianceMap);
        for (x, n) in [
            (Vec3::new(0.5, 0.0, 0.3), Vec3::Y),
            (Vec3::new(0.2, 1.0, 0.7), Vec3::NEG_Y),
            (Vec3::new(0.0, 0.6, 0.9), Vec3::X),
            (Vec3::new(0.9, 0.1, 1.0), Vec3::NEG_Z),
        ] {
            let got = lookup(last.as_ref(), scene, x, n);
            for c in 0..3 {
                let tol = 4.0 * rel * expected[c] + expected[c] / 1024.0;
                assert!(
                    (got[c] - expected[c]).abs() <= tol,
                    "{bounce:?} bounces: channel {c} at {x}: {got} against {expected}"
                );
            }
        }
    }
}

/// A white furnace baked on front faces only: under a uniform sky of radiance L every
/// surface of albedo 1 leaves L, so E = πL on both sides of everything, whatever the
/// geometry. A panel hangs over a floor with its front face up, so the floor's gather rays
/// meet the panel's back face, which a front-only bake leaves out: a path must trace on
/// there rather than read a value the cache does not hold (it read zero or NaN before:
/// the floor under the panel came out dark).
#[test]
fn a_front_only_bake_traces_through_back_faces_it_does_not_hold() {
    let sky = Vec3::new(1.0, 0.5, 2.0);
    let expected = PI * sky;
    let scene = traced(
        vec![
            instance(square("floor", 1.0, 0.0, Vec3::Y), grey(1.0)),
            instance(square("panel", 0.5, 0.6, Vec3::Y), grey(1.0)),
        ],
        Environment::uniform(sky),
    );
    let rel = 0.02;
    for settings in front_only_caches() {
        let (cache, _) = bake(&scene, settings, estimator(rel));
        for x in [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.2, 0.0, -0.1),
            Vec3::new(-0.3, 0.0, 0.3),
        ] {
            let got = lookup(cache.as_ref(), &scene, x, Vec3::Y);
            for c in 0..3 {
                let tol = 4.0 * rel * expected[c];
                assert!(
                    (got[c] - expected[c]).abs() <= tol,
                    "{}: channel {c} at {x}: {got} against {expected}",
                    settings.method().name()
                );
            }
        }
    }
}
