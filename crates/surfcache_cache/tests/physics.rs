//! Closed-form physics checks of the irradiance maps and vertex lighting, baked through
//! `bake::bake_to_convergence` with modest estimator settings.
//!
//! Tolerances: an estimate stops once its relative standard error C ≤ `max_rel_error`
//! in every channel, and a lookup is a convex combination of estimates, so a lookup lies
//! within 4·`max_rel_error`·E of the truth (four standard errors) plus the half-float
//! rounding of 2⁻¹¹ of each channel.

mod common;

use common::{PI, Points, estimator, locate};
use surfcache_cache::{
    SurfaceCache,
    bake::{Baker, FLOOR_FRACTION, bake_to_convergence, mean_irradiance},
    irradiance_map::{IrradianceMapSettings, IrradianceMaps},
    vertex_lighting::{VertexLighting, VertexLightingSettings},
};
use surfcache_core::{
    Environment, Instance, Light, Material, Mesh, Scene,
    glam::{Vec2, Vec3},
    scenes::{cornell, cuboid, quad, tiled_floor},
};
use surfcache_trace::{Sampler, TracedScene};

/// |got − expected| ≤ 4·rel·expected + expected/1024 in every channel.
fn assert_near(got: Vec3, expected: Vec3, rel: f32, what: &str) {
    for c in 0..3 {
        let tol = 4.0 * rel * expected[c] + expected[c] / 1024.0 + 1e-6;
        assert!(
            (got[c] - expected[c]).abs() <= tol,
            "{what}: channel {c}: got {got}, expected {expected}"
        );
    }
}

/// Lookups at random points of random triangles, on the given sides.
fn check_everywhere(
    cache: &dyn SurfaceCache,
    scene: &TracedScene,
    sides: &[bool],
    expected: Vec3,
    rel: f32,
    what: &str,
) {
    let mut rng = Points(0x1234_5678);
    for k in 0..400 {
        let t = ((rng.next_f32() * scene.triangle_count() as f32) as u32)
            .min(scene.triangle_count() as u32 - 1);
        let uv = rng.barycentrics();
        let front = sides[k % sides.len()];
        let e = cache.lookup(t, uv, front);
        assert_near(
            e,
            expected,
            rel,
            &format!("{what}: triangle {t} {uv} front {front}"),
        );
    }
}

#[test]
fn plane_under_uniform_sky_receives_pi_l() {
    let l = Vec3::new(0.5, 1.0, 2.0);
    let v = Vec3::new;
    let h = 10.0;
    let scene = Scene {
        instances: vec![Instance::new(
            quad(
                "floor",
                [v(-h, 0., -h), v(h, 0., -h), v(h, 0., h), v(-h, 0., h)],
                Vec3::Y,
            ),
            Material::diffuse("floor", Vec3::splat(0.5)),
        )],
        environment: Environment::uniform(l),
        ..Default::default()
    };
    let traced = TracedScene::new(&scene).unwrap();
    // Uniform hemisphere sampling: real noise (relative spread 1/√3 per sample).
    let rel = 0.02;
    let settings = estimator(Sampler::Uniform, rel, 64, 8192, 0.0);
    let maps = IrradianceMaps::new(&traced, IrradianceMapSettings::default());
    let maps = bake_to_convergence(&traced, maps, &settings, 1);
    let vertex = VertexLighting::new(&traced, VertexLightingSettings::default());
    let vertex = bake_to_convergence(&traced, vertex, &settings, 1);
    // Both sides see a uniform sky hemisphere.
    check_everywhere(&maps, &traced, &[true, false], PI * l, rel, "maps");
    check_everywhere(&vertex, &traced, &[true, false], PI * l, rel, "vertex");
    // Noise alone does not refine: every grid stays at order 2.
    let stats = maps.stats();
    assert_eq!(
        stats.order_histogram.into_iter().collect::<Vec<_>>(),
        [(2, 4)]
    );
    // 4 grids of 6, the diagonal's two corners shared on each side.
    assert_eq!(stats.sample_points, 4 * 6 - 2 * 2);
    assert_eq!(vertex.stats().sample_points, 2 * 4);
    assert!(stats.mean_rel_error <= rel as f64);
}

/// Points on the inside of the unit box within 1 mm of its edges (and corners), with the
/// inward normal of their face.
fn points_near_walls() -> Vec<(Vec3, Vec3)> {
    let mm = 1e-3;
    let mut rng = Points(77);
    let mut out = Vec::new();
    for axis in 0..3 {
        for side in [0.0f32, 1.0] {
            let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
            let mut n = Vec3::ZERO;
            n[axis] = 1.0 - 2.0 * side;
            for (fu, fv) in [
                (Some(mm), None),
                (Some(1.0 - mm), None),
                (None, Some(mm)),
                (None, Some(1.0 - mm)),
                (Some(mm), Some(mm)),
                (Some(1.0 - mm), Some(1.0 - mm)),
            ] {
                for _ in 0..4 {
                    let mut x = Vec3::ZERO;
                    x[axis] = side;
                    x[a] = fu.unwrap_or_else(|| rng.next_f32());
                    x[b] = fv.unwrap_or_else(|| rng.next_f32());
                    out.push((x, n));
                }
            }
        }
    }
    out
}

#[test]
fn light_tight_box_stays_black_inside_maps_but_vertex_lighting_leaks() {
    let sky = 1e4;
    let scene = Scene {
        instances: vec![Instance::new(
            cuboid("box", Vec3::ZERO, Vec3::ONE, true),
            Material::diffuse("wall", Vec3::splat(0.8)),
        )],
        environment: Environment::uniform(Vec3::splat(sky)),
        ..Default::default()
    };
    let traced = TracedScene::new(&scene).unwrap();
    let settings = estimator(Sampler::Best, 0.05, 64, 1024, FLOOR_FRACTION * sky);
    let maps = IrradianceMaps::new(&traced, IrradianceMapSettings::default());
    let maps = bake_to_convergence(&traced, maps, &settings, 3);
    let vertex = VertexLighting::new(&traced, VertexLightingSettings::default());
    let vertex = bake_to_convergence(&traced, vertex, &settings, 3);
    for (x, n) in points_near_walls() {
        let (t, uv, front) = locate(&traced, x, n);
        assert!(front, "{x} {n} should be on the inside");
        // The leak guard: samples on edges and corners are estimated a step inside their
        // triangle, so no ray passes a wall's edge and everything inside is exactly black.
        assert_eq!(maps.lookup(t, uv, true), Vec3::ZERO, "maps leak at {x}");
        // Vertex lighting estimates at the box's corners: a corner vertex lies on three
        // walls at once, its rays start on the walls' planes and most of them leave the
        // box, so every vertex sees the bright sky and interpolation spreads it over the
        // triangles — the leak docs/design.md, Caches describes, shown here, not fixed.
        let e = vertex.lookup(t, uv, true);
        assert!(
            e.min_element() > 0.1 * PI * sky,
            "vertex lighting unexpectedly tight at {x}: {e}"
        );
    }
    // The outside (back sides) sees the sky: πL.
    check_everywhere(
        &maps,
        &traced,
        &[false],
        Vec3::splat(PI * sky),
        0.05,
        "outside",
    );
    assert_eq!(maps.stats().buried, 0);
}

/// A closed box whose inner faces emit `le` (front side only) with albedo ρ.
fn furnace(le: Vec3, rho: f32, double_sided: bool, environment: Environment) -> Scene {
    let mut wall = Material::emissive("wall", Vec3::splat(rho), le);
    wall.double_sided = double_sided;
    Scene {
        instances: vec![Instance::new(
            cuboid("box", Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0), true),
            wall,
        )],
        environment,
        ..Default::default()
    }
}

#[test]
fn furnace_box_matches_geometric_series() {
    // Closed box, black outside: inside E = π Le / (1 − ρ) everywhere.
    let (le, rho) = (Vec3::new(1.0, 2.0, 0.5), 0.6);
    let expected = PI * le / (1.0 - rho);
    let rel = 0.02;
    let settings = estimator(Sampler::Best, rel, 128, 16_384, 0.0);
    let traced = TracedScene::new(&furnace(le, rho, false, Environment::black())).unwrap();
    let maps = IrradianceMaps::new(
        &traced,
        IrradianceMapSettings {
            both_sides: false,
            ..Default::default()
        },
    );
    let maps = bake_to_convergence(&traced, maps, &settings, 5);
    check_everywhere(
        &maps,
        &traced,
        &[true],
        expected,
        rel,
        "closed furnace, maps",
    );
    assert_eq!(
        maps.stats().order_histogram[&2],
        12,
        "noise refined a flat furnace"
    );

    // The same box in equilibrium with the world: double-sided walls and a sky of the
    // furnace radiance Le/(1 − ρ). Then E = π Le/(1 − ρ) on both sides of every wall,
    // whatever a sample sees — also for vertex lighting, whose corner vertices see
    // through the walls (see the light-tight box test).
    let traced = TracedScene::new(&furnace(
        le,
        rho,
        true,
        Environment::uniform(le / (1.0 - rho)),
    ))
    .unwrap();
    let maps = IrradianceMaps::new(&traced, IrradianceMapSettings::default());
    let maps = bake_to_convergence(&traced, maps, &settings, 6);
    check_everywhere(
        &maps,
        &traced,
        &[true, false],
        expected,
        rel,
        "open furnace, maps",
    );
    let vertex = VertexLighting::new(&traced, VertexLightingSettings::default());
    let vertex = bake_to_convergence(&traced, vertex, &settings, 6);
    check_everywhere(
        &vertex,
        &traced,
        &[true, false],
        expected,
        rel,
        "open furnace, vertex",
    );
}

/// A floor lit straight down by a directional light of 3 W/m², with a black square
/// blocker 1 m above it casting the hard shadow `lo < x, z < hi`.
fn shadow_scene(floor: Mesh, lo: Vec2, hi: Vec2) -> Scene {
    let v = Vec3::new;
    let blocker = quad(
        "blocker",
        [
            v(lo.x, 1.0, lo.y),
            v(hi.x, 1.0, lo.y),
            v(hi.x, 1.0, hi.y),
            v(lo.x, 1.0, hi.y),
        ],
        Vec3::NEG_Y,
    );
    Scene {
        instances: vec![
            Instance::new(floor, Material::diffuse("floor", Vec3::splat(0.5))),
            Instance::new(blocker, Material::diffuse("black", Vec3::ZERO)),
        ],
        lights: vec![Light::Directional {
            direction: Vec3::NEG_Y,
            irradiance: Vec3::splat(3.0),
        }],
        environment: Environment::black(),
        ..Default::default()
    }
}

#[test]
fn refinement_follows_the_shadow_edge_only() {
    let (lo, hi) = (Vec2::splat(1.1), Vec2::splat(2.9));
    let scene = shadow_scene(tiled_floor(4.0, 16), lo, hi);
    let traced = TracedScene::new(&scene).unwrap();
    let floor_triangles = traced.instance_triangles()[0].clone();
    let settings = estimator(Sampler::Best, 0.05, 16, 64, 0.03);
    let maps = IrradianceMaps::new(
        &traced,
        IrradianceMapSettings {
            density: 1000.0,
            max_order: 16,
            both_sides: false,
            ..Default::default()
        },
    );
    let maps = bake_to_convergence(&traced, maps, &settings, 9);
    let shadowed = |p: Vec3| p.x > lo.x && p.x < hi.x && p.z > lo.y && p.z < hi.y;
    let (mut edge, mut calm) = (0, 0);
    for t in floor_triangles {
        let [a, b, c] = traced.positions()[t as usize];
        let at = |u: f32, v: f32| a * (1.0 - u - v) + b * u + c * v;
        // Lit and shadowed among the order-2 samples: the generator sees the edge.
        let grid2: Vec<bool> = [
            (0., 0.),
            (0.5, 0.),
            (1., 0.),
            (0., 0.5),
            (0.5, 0.5),
            (0., 1.),
        ]
        .iter()
        .map(|&(u, v)| shadowed(at(u, v)))
        .collect();
        // Lit or shadowed all over (dense check): E is constant on the triangle.
        let mut dense = (0..=40)
            .flat_map(|i| (0..=40 - i).map(move |j| (i as f32 / 40.0, j as f32 / 40.0)))
            .map(|(u, v)| shadowed(at(u, v)));
        let first = dense.next().unwrap();
        let uniform = dense.all(|s| s == first);
        let order = maps.order(t, true);
        if grid2.iter().any(|&s| s != grid2[0]) {
            assert_eq!(order, 16, "triangle {t} crosses the shadow edge");
            edge += 1;
        } else if uniform {
            assert_eq!(order, 2, "triangle {t} is evenly lit");
            calm += 1;
        }
    }
    assert!(edge >= 50 && calm >= 300, "edge {edge}, calm {calm}");
    // At the finest grids the shadow is resolved to 1/16 of a cell.
    let (t, uv, _) = locate(&traced, Vec3::new(1.05, 0.0, 2.0), Vec3::Y);
    assert!(
        (maps.lookup(t, uv, true) - Vec3::splat(3.0))
            .abs()
            .max_element()
            < 0.01
    );
    let (t, uv, _) = locate(&traced, Vec3::new(1.15, 0.0, 2.0), Vec3::Y);
    assert!(maps.lookup(t, uv, true).max_element() < 0.01);
}

#[test]
fn shadow_between_samples_is_caught_by_the_shadow_probes() {
    // docs/design.md, Caches: a hard shadow that falls between all samples of a triangle passes
    // the error test while wrong. A 1 m floor of two triangles (order-2 samples at
    // x = 0, 0.5, 1) under a strip of shadow 0.2 < x < 0.3: the punctual-light shadow
    // probes send the grid to its maximum order, which resolves the strip.
    let v = Vec3::new;
    let floor = quad(
        "floor",
        [v(0., 0., 0.), v(1., 0., 0.), v(1., 0., 1.), v(0., 0., 1.)],
        Vec3::Y,
    );
    let scene = shadow_scene(floor, Vec2::new(0.2, -1.0), Vec2::new(0.3, 2.0));
    let traced = TracedScene::new(&scene).unwrap();
    let settings = estimator(Sampler::Best, 0.05, 16, 64, 0.03);
    let maps = IrradianceMaps::new(&traced, IrradianceMapSettings::default());
    let maps = bake_to_convergence(&traced, maps, &settings, 2);
    let (t, uv, _) = locate(&traced, v(0.25, 0.0, 0.5), Vec3::Y);
    let max = IrradianceMapSettings::default().max_order_for(2f32.sqrt());
    assert_eq!(maps.order(t, true), max);
    // Truth: 0 (in the shadow); without the probes the map said 3 (fully lit).
    assert!(maps.lookup(t, uv, true).max_element() < 0.3);
    // And lit away from the strip.
    let (t, uv, _) = locate(&traced, v(0.7, 0.0, 0.5), Vec3::Y);
    assert!(
        (maps.lookup(t, uv, true) - Vec3::splat(3.0))
            .abs()
            .max_element()
            < 0.1
    );
}

#[test]
fn same_seed_same_cache_whatever_the_schedule() {
    let traced = TracedScene::new(&cornell()).unwrap();
    let floor = FLOOR_FRACTION * mean_irradiance(&traced, 256, 0);
    let settings = estimator(Sampler::Best, 0.05, 32, 256, floor);
    let map_settings = IrradianceMapSettings {
        density: 16.0,
        max_order: 8,
        floor,
        ..Default::default()
    };
    let pool = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
    };
    let stepped = |threads: usize, batch: usize| {
        pool(threads).install(|| {
            let mut baker = Baker::new(IrradianceMaps::new(&traced, map_settings), settings, 11);
            while !baker.step(&traced, batch) {}
            let maps = baker.into_cache();
            let mut baker = Baker::new(
                VertexLighting::new(&traced, VertexLightingSettings::default()),
                settings,
                11,
            );
            while !baker.step(&traced, batch) {}
            (maps, baker.into_cache())
        })
    };
    let (maps_a, vertex_a) = stepped(2, 4096);
    let (maps_b, vertex_b) = stepped(1, 7);
    let (maps_c, vertex_c) = stepped(2, 333);
    assert!(maps_a.is_converged());
    assert!(
        maps_a.stats().order_histogram.keys().any(|&n| n > 2),
        "no refinement"
    );
    assert_eq!(maps_a, maps_b);
    assert_eq!(maps_a, maps_c);
    assert_eq!(maps_a.stats(), maps_c.stats());
    assert_eq!(vertex_a, vertex_b);
    assert_eq!(vertex_a, vertex_c);
    // A different seed gives a different cache.
    let other = pool(2).install(|| {
        bake_to_convergence(
            &traced,
            IrradianceMaps::new(&traced, map_settings),
            &settings,
            12,
        )
    });
    assert_ne!(maps_a, other);
}
