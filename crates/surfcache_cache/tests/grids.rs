//! Irradiance-map grids without ray tracing: indexing, keys, interpolation, refinement
//! that keeps every sample, buried samples, and vertex-lighting bookkeeping. Estimates are
//! synthetic (see `common::bake_synthetic`).

mod common;

use common::{Points, bake_synthetic, bake_synthetic_watched};
use std::collections::HashSet;
use surfcache_cache::stored_rgb::STORED_RGB_BYTES;
use surfcache_cache::{
    SampleSite, SurfaceCache,
    irradiance_map::{
        IrradianceMapSettings, IrradianceMaps, coarse_neighbours, grid_index, grid_interpolate,
        grid_size, sample_key,
    },
    stored_rgb::StoreScale,
    vertex_lighting::{VertexLighting, VertexLightingSettings},
};
use surfcache_core::{
    Instance, Material, Mesh, Scene,
    glam::{Vec2, Vec3},
    scenes::{quad, tiled_floor},
};
use surfcache_trace::TracedScene;

#[test]
fn grid_index_enumerates_each_grid_diagonal_by_diagonal() {
    for n in [1u32, 2, 4, 8, 16, 64] {
        let mut next = 0;
        for d in 0..=n {
            for j in 0..=d {
                assert_eq!(grid_index(d - j, j), next, "n={n} ({}, {j})", d - j);
                next += 1;
            }
        }
        assert_eq!(next, grid_size(n));
        assert_eq!(grid_size(n), ((n + 1) * (n + 2) / 2) as usize);
    }
    assert_eq!(
        [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)].map(|(i, j)| grid_index(i, j)),
        [0, 1, 2, 3, 4, 5]
    );
}

#[test]
fn new_samples_halve_coarse_edges() {
    for n in [2u32, 4, 8, 16] {
        for d in 0..=n {
            for j in 0..=d {
                let i = d - j;
                if i % 2 == 0 && j % 2 == 0 {
                    continue;
                }
                let [[ai, aj], [bi, bj]] = coarse_neighbours(i, j);
                for (x, y) in [(ai, aj), (bi, bj)] {
                    assert!(x % 2 == 0 && y % 2 == 0 && x + y <= n, "({i},{j}) of {n}");
                }
                assert_eq!((ai + bi, aj + bj), (2 * i, 2 * j));
                // The ends of one coarse cell edge: a row, column or diagonal step.
                let step = (bi as i32 - ai as i32, bj as i32 - aj as i32);
                assert!(
                    matches!(step, (2, 0) | (0, 2) | (-2, 2)),
                    "({i},{j}): {step:?}"
                );
            }
        }
    }
}

#[test]
fn keys_depend_on_position_not_order() {
    let k = 0xDEAD_BEEF_u64;
    for (i, j, n) in [(0, 0, 2), (1, 0, 2), (1, 1, 2), (3, 5, 8), (7, 0, 16)] {
        assert_eq!(
            sample_key(k, true, i, j, n),
            sample_key(k, true, 2 * i, 2 * j, 2 * n)
        );
        assert_eq!(
            sample_key(k, false, i, j, n),
            sample_key(k, false, 4 * i, 4 * j, 4 * n)
        );
        assert_ne!(sample_key(k, true, i, j, n), sample_key(k, false, i, j, n));
        assert_ne!(
            sample_key(k, true, i, j, n),
            sample_key(k + 1, true, i, j, n)
        );
    }
    let mut seen = HashSet::new();
    for d in 0..=64u32 {
        for j in 0..=d {
            assert!(seen.insert(sample_key(k, true, d - j, j, 64)));
        }
    }
}

#[test]
fn max_order_follows_density_and_cap() {
    let s = IrradianceMapSettings {
        density: 10.0,
        max_order: 48, // rounded down to 32
        ..Default::default()
    };
    assert_eq!(s.order_cap(), 32);
    assert_eq!(s.max_order_for(0.01), 1); // corners 0.1 sample spacings apart
    assert_eq!(s.max_order_for(0.1), 1);
    assert_eq!(s.max_order_for(0.15), 2);
    assert_eq!(s.max_order_for(0.25), 4); // ceil(2.5) = 3 → 4
    assert_eq!(s.max_order_for(0.8), 8);
    assert_eq!(s.max_order_for(1.6), 16);
    assert_eq!(s.max_order_for(100.0), 32);
}

#[test]
fn grid_interpolation_is_exact_for_linear_functions_and_at_samples() {
    let f = |uv: Vec2| Vec3::new(1.0 + 2.0 * uv.x - uv.y, 3.0 * uv.y, 0.5);
    let mut rng = Points(5);
    for n in [1u32, 2, 4, 16] {
        let grid = |i: u32, j: u32| f(Vec2::new(i as f32, j as f32) / n as f32);
        for _ in 0..500 {
            let uv = rng.barycentrics();
            assert!((grid_interpolate(n, uv, grid) - f(uv)).abs().max_element() < 1e-5);
        }
        // A bumpy grid is reproduced at its own samples.
        let bumpy = |i: u32, j: u32| Vec3::splat(((i * 7 + j * 3) % 5) as f32);
        for d in 0..=n {
            for j in 0..=d {
                let uv = Vec2::new((d - j) as f32, j as f32) / n as f32;
                assert_eq!(grid_interpolate(n, uv, bumpy), bumpy(d - j, j));
            }
        }
    }
}

fn unit_floor() -> Scene {
    let v = Vec3::new;
    Scene {
        instances: vec![Instance::new(
            quad(
                "floor",
                [v(0., 0., 0.), v(1., 0., 0.), v(1., 0., 1.), v(0., 0., 1.)],
                Vec3::Y,
            ),
            Material::default(),
        )],
        ..Default::default()
    }
}

/// A ramp that is steep around x = 0.4 (exact estimates refine grids up to their cap) and
/// whose maximum (at x = 1) is already sampled in round 0, so the store's scale never
/// changes.
fn steep_ramp(x: f32) -> Vec3 {
    Vec3::new(1.0 + 4.0 / (1.0 + (-(x - 0.4) * 40.0).exp()), 2.0, 0.5)
}

/// Front sides only, grids up to order 16 whatever the triangles' size.
fn front_to_order_16() -> IrradianceMapSettings {
    IrradianceMapSettings {
        density: 1000.0,
        max_order: 16,
        both_sides: false,
        ..Default::default()
    }
}

/// A triangle no longer than one sample spacing keeps its three corners: one round, three
/// points per grid, stored and looked up like any other grid (exact for a linear E).
#[test]
fn triangles_within_one_sample_spacing_keep_order_one_grids() {
    let traced = TracedScene::new(&unit_floor()).unwrap();
    let f = |p: Vec3| Vec3::new(1.0 + p.x, 2.0 - p.z, 0.5 + p.x * p.z.min(0.0));
    let settings = IrradianceMapSettings {
        density: 0.5, // longest edge √2 m · 0.5/m ≤ 1
        both_sides: true,
        ..Default::default()
    };
    let maps = IrradianceMaps::new(&traced, settings);
    let (maps, rounds) = bake_synthetic(&traced, maps, |sp| (f(sp.position), 0.0));
    assert_eq!(rounds.len(), 1, "order-1 grids cannot refine");
    assert_eq!(
        rounds[0].len(),
        2 * 4,
        "2 sides × 4 vertices (the diagonal's corners are shared)"
    );
    let stats = maps.stats();
    assert_eq!(stats.order_histogram.get(&1), Some(&4));
    assert_eq!(stats.cache_bytes, STORED_RGB_BYTES * 12 + 5 * 4 + 4);
    let mut rng = Points(9);
    for t in 0..2u32 {
        let [a, b, c] = traced.positions()[t as usize];
        for front in [true, false] {
            assert_eq!(maps.order(t, front), 1);
            for _ in 0..50 {
                let uv = rng.barycentrics();
                let p = a * (1.0 - uv.x - uv.y) + b * uv.x + c * uv.y;
                let got = maps.lookup(t, uv, front);
                assert!((got - f(p)).abs().max_element() < 0.02, "{got} vs {}", f(p));
            }
        }
    }
    // One sample spacing more and the same floor starts at order 2 again.
    let settings = IrradianceMapSettings {
        density: 1.0,
        ..settings
    };
    let maps = IrradianceMaps::new(&traced, settings);
    let (maps, rounds) = bake_synthetic(&traced, maps, |sp| (f(sp.position), 0.0));
    assert_eq!(
        rounds[0].len(),
        2 * (2 * 6 - 2),
        "2 sides × (2 grids of 6 − 2 shared)"
    );
    assert_eq!(maps.stats().order_histogram.get(&2), Some(&4));
}

#[test]
fn refinement_keeps_every_sample_and_asks_only_for_new_ones() {
    let traced = TracedScene::new(&unit_floor()).unwrap();
    let f = steep_ramp;
    let mut maps = IrradianceMaps::new(&traced, front_to_order_16());
    let mut keys = HashSet::new();
    let mut previous: Vec<(u32, u32, Vec<Vec3>)> = Vec::new();
    let mut round = 0;
    loop {
        let mut points = Vec::new();
        maps.next_round(&traced, &mut points);
        if points.is_empty() {
            break;
        }
        for p in &points {
            assert!(
                keys.insert(p.key),
                "round {round}: a sample was asked for twice"
            );
            let SampleSite::Surface {
                triangle,
                uv,
                front,
            } = p.site
            else {
                panic!("irradiance maps sample surfaces")
            };
            assert!(front);
            // New samples have an odd index coordinate at their grid's new order.
            if round > 0 {
                let n = (2 * maps.order(triangle, true)) as f32;
                let (i, j) = ((uv.x * n).round() as u32, (uv.y * n).round() as u32);
                assert!(i % 2 == 1 || j % 2 == 1, "round {round}: ({i},{j}) not new");
            }
        }
        let estimates: Vec<_> = points
            .iter()
            .map(|p| {
                let (sp, _) = surfcache_cache::bake::sample_frame(&traced, &p.site);
                surfcache_trace::Estimate {
                    value: f(sp.position.x),
                    samples: 1,
                    ..Default::default()
                }
            })
            .collect();
        maps.finish_round(&traced, &points, &estimates);
        // Every sample of the previous round's grids is where doubling puts it.
        for &(t, n_old, ref old) in &previous {
            let n = maps.order(t, true);
            let ratio = n / n_old;
            for d in 0..=n_old {
                for j in 0..=d {
                    let i = d - j;
                    assert_eq!(
                        maps.sample(t, true, ratio * i, ratio * j),
                        old[grid_index(i, j)],
                        "round {round}: triangle {t} ({i},{j}) of {n_old} moved"
                    );
                }
            }
        }
        previous = (0..2u32)
            .map(|t| {
                let n = maps.order(t, true);
                let mut v = Vec::new();
                for d in 0..=n {
                    for j in 0..=d {
                        v.push(maps.sample(t, true, d - j, j));
                    }
                }
                (t, n, v)
            })
            .collect();
        round += 1;
    }
    assert!(round >= 3, "only {round} rounds");
    let stats = maps.stats();
    assert_eq!(stats.order_histogram.values().sum::<u64>(), 2);
    assert_eq!(stats.order_histogram.keys().max(), Some(&16));
    // Every estimate was kept: as many points as the final grids hold, less the two
    // corners on the diagonal that both grids share.
    let held: usize = (0..2).map(|t| grid_size(maps.order(t, true))).sum();
    assert_eq!(stats.sample_points as usize, held - 2);
    assert_eq!(
        stats.cache_bytes,
        6 * held as u64 + 5 * 4 + 4,
        "6 bytes per sample, 5 per grid slot (2 triangles × 2 sides), 4 for the scale"
    );
    // Lookups at every sample return its estimate (up to half-float rounding).
    let scale = StoreScale::for_max(5.0);
    for t in 0..2u32 {
        let n = maps.order(t, true);
        let [a, b, c] = traced.positions()[t as usize];
        for d in 0..=n {
            for j in 0..=d {
                let uv = Vec2::new((d - j) as f32, j as f32) / n as f32;
                let x = (a * (1.0 - uv.x - uv.y) + b * uv.x + c * uv.y).x;
                let want = scale.unpack(scale.pack(f(x)));
                assert!((maps.lookup(t, uv, true) - want).abs().max_element() < 1e-4);
            }
        }
    }
}

/// A 4-m floor (two triangles) that a wall pierces along a 1-m segment at x = 1.
fn floor_with_wall() -> TracedScene {
    let v = Vec3::new;
    let floor = tiled_floor(4.0, 1);
    let wall = quad(
        "wall",
        [
            v(1., -0.5, 1.),
            v(1., -0.5, 2.),
            v(1., 0.5, 2.),
            v(1., 0.5, 1.),
        ],
        Vec3::X,
    );
    let scene = Scene {
        instances: vec![
            Instance::new(floor, Material::default()),
            Instance::new(wall, Material::default()),
        ],
        ..Default::default()
    };
    TracedScene::new(&scene).unwrap()
}

/// Each floor grid sample of an order-16 grid on the floor of [`floor_with_wall`]:
/// triangle, barycentrics and position.
fn floor_samples(traced: &TracedScene) -> Vec<(u32, Vec2, Vec3)> {
    let mut out = Vec::new();
    for t in 0..2u32 {
        let [a, b, c] = traced.positions()[t as usize];
        for d in 0..=16u32 {
            for j in 0..=d {
                let uv = Vec2::new((d - j) as f32, j as f32) / 16.0;
                out.push((t, uv, a * (1.0 - uv.x - uv.y) + b * uv.x + c * uv.y));
            }
        }
    }
    out
}

/// Local refinement around a crossing: a wall pierces the floor, and E is the same
/// everywhere (no sample fails a test). The floor's grids still reach their maximum
/// order around the wall, where a crossing passes within reach of their samples, and
/// stay coarse elsewhere: every floor sample within one spacing of the maximum order of
/// the wall (away from its ends) is estimated, and most of the floor is interpolated.
#[test]
fn crossed_grids_refine_around_the_crossing_only() {
    let traced = floor_with_wall();
    let maps = IrradianceMaps::new(&traced, front_to_order_16());
    let (maps, _) = bake_synthetic(&traced, maps, |_| (Vec3::ONE, 0.0));
    let spacing = 4.0 * 2f32.sqrt() / 16.0;
    let (mut near, mut far, mut interpolated) = (0, 0, 0);
    for t in 0..2u32 {
        assert!(maps.is_crossed(t, true), "floor triangle {t} not crossed");
        assert_eq!(maps.order(t, true), 16);
    }
    for (t, uv, p) in floor_samples(&traced) {
        // Distance from the wall's line on the floor, x = 1, away from the segment's
        // ends (where the eight in-plane probes may pass by).
        let distance = (p.x - 1.0).abs();
        let samples = maps.diagnostic(t, uv, true).samples;
        if distance < spacing && (1.1..=1.9).contains(&p.z) {
            assert!(
                samples > 0,
                "{p} is {distance} m from the wall, not estimated"
            );
            near += 1;
        } else if distance > 2.0 * spacing || !(0.8..=2.2).contains(&p.z) {
            far += 1;
            interpolated += (samples == 0) as u32;
        }
        assert!((maps.lookup(t, uv, true) - Vec3::ONE).abs().max_element() < 1e-3);
    }
    assert!(near >= 10, "{near} samples near the wall");
    assert!(
        2 * interpolated > far,
        "{interpolated} of {far} far samples interpolated"
    );
}

/// Away from the crossing, a crossed grid's cells follow the cell test: with a bump of
/// light far from the wall, gentle enough that the grid's own test (5 %) passes at order
/// 8, the cells on the bump are estimated where their interpolation would be off by more
/// than the cell test's 1 %, so every interpolated sample stays within about that bound
/// of E (without the cell test, samples on the bump were interpolated 2 % off).
#[test]
fn crossed_grids_estimate_where_the_cell_test_fails() {
    let traced = floor_with_wall();
    let f = |p: Vec3| {
        let r2 = (p.x - 3.0).powi(2) + (p.z - 3.0).powi(2);
        Vec3::splat(1.0 + 0.1 * (-r2 / (2.0 * 0.4 * 0.4)).exp())
    };
    let maps = IrradianceMaps::new(&traced, front_to_order_16());
    let (maps, _) = bake_synthetic(&traced, maps, |sp| (f(sp.position), 0.0));
    let (mut on_bump, mut interpolated) = (0, 0);
    for (t, uv, p) in floor_samples(&traced) {
        let samples = maps.diagnostic(t, uv, true).samples;
        let got = maps.lookup(t, uv, true);
        let e = ((got - f(p)).abs() / f(p)).max_element();
        if samples == 0 {
            interpolated += 1;
            assert!(e < 0.02, "{p}: interpolated {got}, E {}", f(p));
        }
        if (p - Vec3::new(3.0, 0.0, 3.0)).length() < 0.4 {
            on_bump += (samples > 0) as u32;
        }
    }
    assert!(interpolated > 50, "{interpolated} interpolated samples");
    assert!(on_bump >= 10, "{on_bump} samples estimated on the bump");
}

/// The forecast of later rounds that progress reports use: before the first refinement
/// test what forced grids will ask (none here: nothing crosses the floor and no punctual
/// light shines on it); then exact where every grid doubles up to its cap (the
/// share of tested grids that double stays 1); zero once nothing refines.
#[test]
fn later_rounds_are_forecast_from_the_grids_that_double() {
    let traced = TracedScene::new(&unit_floor()).unwrap();
    let settings = front_to_order_16();
    // Curved everywhere: the middle of every coarse edge lies far off the chord.
    let f = |p: Vec3| Vec3::splat((10.0 * p.x).exp() + (10.0 * p.z).exp());
    let mut forecasts = Vec::new();
    let (maps, rounds) = bake_synthetic_watched(
        &traced,
        IrradianceMaps::new(&traced, settings),
        |sp| (f(sp.position), 0.0),
        |maps| forecasts.push(maps.later_samples(1.0)),
    );
    assert_eq!(rounds.len(), 4, "orders 2, 4, 8 and 16");
    assert_eq!(forecasts[0], Some(0), "nothing forces these grids");
    for r in 1..rounds.len() {
        let later: usize = rounds[r + 1..].iter().map(Vec::len).sum();
        assert_eq!(forecasts[r], Some(later as u64), "after round {r}");
    }
    assert_eq!(maps.later_samples(1.0), Some(0));
    // A linear E: the first test doubles nothing, and nothing is forecast.
    let (maps, rounds) = bake_synthetic(&traced, IrradianceMaps::new(&traced, settings), |sp| {
        (Vec3::splat(1.0 + sp.position.x), 0.0)
    });
    assert_eq!(rounds.len(), 1);
    assert_eq!(maps.later_samples(1.0), Some(0));
}

/// An incremental re-bake starts from the grids of the bake before, with their values as
/// priors. A grid that keeps every prior (the edit cannot reach it) keeps that bake's
/// order: its priors carry errors at the bound, far below the noise the bake before
/// tested its own estimates with, and testing them again would double grids that bake had
/// let be and estimate their new samples from scratch. A grid whose samples the re-bake
/// estimates again is tested as in any bake.
#[test]
fn a_re_bake_keeps_the_order_of_grids_whose_priors_it_kept() {
    let traced = TracedScene::new(&unit_floor()).unwrap();
    let (f, settings) = (steep_ramp, front_to_order_16());
    let estimator = common::estimator(surfcache_trace::Sampler::Best, 0.01, 64, 1024, 0.0);
    let x_of = |p: &surfcache_cache::SamplePoint| {
        surfcache_cache::bake::sample_frame(&traced, &p.site)
            .0
            .position
            .x
    };
    // Estimates of the ramp with standard errors `noise` × E.
    let ramp = |points: &[surfcache_cache::SamplePoint], noise: f32| -> Vec<_> {
        points
            .iter()
            .map(|p| {
                let value = f(x_of(p));
                surfcache_trace::Estimate {
                    value,
                    std_error: noise * value,
                    samples: 64,
                    ..Default::default()
                }
            })
            .collect()
    };
    // The bake before: estimates so noisy (standard error half the value) that no
    // interpolation error stands out, so every grid stays at its first order.
    let mut before = IrradianceMaps::new(&traced, settings);
    let mut points = Vec::new();
    before.next_round(&traced, &mut points);
    before.finish_round(&traced, &points, &ramp(&points, 0.5));
    points.clear();
    before.next_round(&traced, &mut points);
    assert!(points.is_empty(), "the noisy bake refined");
    let orders = |m: &IrradianceMaps| [m.order(0, true), m.order(1, true)];
    assert_eq!(orders(&before), [2, 2]);

    // A re-bake that keeps every prior: one round, the same orders and values.
    let identity = [0u32, 1];
    let mut kept = before.remap(&traced, &traced, &identity);
    points.clear();
    kept.next_round(&traced, &mut points);
    let unchanged: Vec<_> = points
        .iter()
        .map(|p| match p.prior {
            Some(surfcache_cache::Prior::Estimated(v)) => {
                surfcache_trace::irradiance::unchanged(v, &estimator)
            }
            other => panic!("a remapped grid sample without its estimate: {other:?}"),
        })
        .collect();
    kept.finish_round(&traced, &points, &unchanged);
    points.clear();
    kept.next_round(&traced, &mut points);
    assert!(
        points.is_empty(),
        "kept priors asked for {} new samples",
        points.len()
    );
    assert_eq!(orders(&kept), orders(&before));
    for t in 0..2u32 {
        for uv in [Vec2::new(0.2, 0.3), Vec2::new(0.5, 0.1), Vec2::ZERO] {
            assert_eq!(kept.lookup(t, uv, true), before.lookup(t, uv, true));
        }
    }

    // A re-bake whose estimates changed (here: exact ones) tests them and refines.
    let mut changed = before.remap(&traced, &traced, &identity);
    points.clear();
    changed.next_round(&traced, &mut points);
    changed.finish_round(&traced, &points, &ramp(&points, 0.0));
    points.clear();
    changed.next_round(&traced, &mut points);
    assert!(!points.is_empty(), "changed estimates did not refine");
}

/// Where [`floor_under_attic`] is buried: the floor beyond z = 0.6, the attic all over.
fn buried_in_attic_scene(p: Vec3) -> bool {
    p.z > 0.6 || p.y > 4.0
}

/// The unit floor and a second quad far above it (the attic), baked front side only with
/// synthetic estimates: 1000 where [`buried_in_attic_scene`] (back-face share 0.9), 5 in
/// the open (0.1).
fn floor_under_attic() -> (TracedScene, IrradianceMaps) {
    let v = Vec3::new;
    let mut scene = unit_floor();
    scene.instances.push(Instance::new(
        quad(
            "attic",
            [v(0., 5., 0.), v(1., 5., 0.), v(1., 5., 1.), v(0., 5., 1.)],
            Vec3::Y,
        ),
        Material::default(),
    ));
    let traced = TracedScene::new(&scene).unwrap();
    let settings = IrradianceMapSettings {
        both_sides: false,
        ..Default::default()
    };
    let (maps, _) = bake_synthetic(&traced, IrradianceMaps::new(&traced, settings), |p| {
        if buried_in_attic_scene(p.position) {
            (Vec3::splat(1000.0), 0.9)
        } else {
            (Vec3::splat(5.0), 0.1)
        }
    });
    (traced, maps)
}

#[test]
fn buried_samples_are_filled_from_neighbours_and_counted() {
    let (traced, maps) = floor_under_attic();
    let buried = buried_in_attic_scene;
    let stats = maps.stats();
    // The floor triangles' samples at z > 0.6 of their final order-64 grids (at order 2:
    // 1 of 6 and 3 of 6), and all 12 of the attic's.
    let n = 64;
    let floor_buried: u64 = (0..2)
        .map(|t| {
            let [a, b, c] = traced.positions()[t];
            (0..=n)
                .flat_map(|d| (0..=d).map(move |j| (d - j, j)))
                .filter(|&(i, j)| {
                    let (u, w) = (i as f32 / n as f32, j as f32 / n as f32);
                    buried(a * (1.0 - u - w) + b * u + c * w)
                })
                .count() as u64
        })
        .sum();
    assert_eq!(stats.buried, floor_buried + 12);
    // A grid that is partly buried has an intersection line to resolve: the floor
    // triangles refine to their maximum order (√2 m × 64 per metre, capped at 64). A grid
    // buried everywhere shows nothing and stays at order 2; buried samples' own values
    // never drive refinement (every valid sample here is 5).
    assert_eq!(
        stats.order_histogram.into_iter().collect::<Vec<_>>(),
        [(2, 2), (64, 2)]
    );
    let mut rng = Points(9);
    for _ in 0..200 {
        let uv = rng.barycentrics();
        for t in 0..2 {
            let e = maps.lookup(t, uv, true);
            assert!(
                (e - Vec3::splat(5.0)).abs().max_element() < 0.02,
                "floor {t}: {e}"
            );
        }
        for t in 2..4 {
            // Buried everywhere: the raw values stay.
            let e = maps.lookup(t, uv, true);
            assert!(
                (e - Vec3::splat(1000.0)).abs().max_element() < 2.0,
                "attic {t}: {e}"
            );
        }
    }
    // The back side was not asked for: it reads zero.
    assert_eq!(maps.lookup(0, Vec2::splat(0.3), false), Vec3::ZERO);
}

/// A re-bake takes a buried sample's filled value as [`Prior::Filled`]: where the edit
/// does not reach it (no samples drawn) it stays buried, and a changed neighbour changes
/// its filled value without making it a source of the next stage's forward rays.
#[test]
fn a_re_bake_keeps_buried_samples_buried_and_no_source() {
    use surfcache_cache::Prior;
    let (traced, before) = floor_under_attic();
    let identity: Vec<u32> = (0..traced.triangle_count() as u32).collect();
    let estimator = common::estimator(surfcache_trace::Sampler::Best, 0.01, 64, 1024, 0.0);
    // A re-bake whose points get `update` of their prior and of whether it was filled.
    let re_bake = |update: &dyn Fn(Vec3, bool) -> surfcache_trace::Estimate| {
        let mut maps = before.remap(&traced, &traced, &identity);
        let mut points = Vec::new();
        maps.next_round(&traced, &mut points);
        let estimates: Vec<_> = points
            .iter()
            .map(|p| {
                let x = surfcache_cache::bake::sample_frame(&traced, &p.site)
                    .0
                    .position;
                let filled = match p.prior {
                    Some(Prior::Estimated(v)) => (v, false),
                    Some(Prior::Filled(v)) => (v, true),
                    None => panic!("a remapped grid sample without its prior"),
                };
                assert_eq!(filled.1, buried_in_attic_scene(x), "the prior at {x}");
                update(filled.0, filled.1)
            })
            .collect();
        maps.finish_round(&traced, &points, &estimates);
        maps
    };
    let unchanged = |v: Vec3, _| surfcache_trace::irradiance::unchanged(v, &estimator);
    let kept = re_bake(&unchanged);
    assert_eq!(kept.stats().buried, before.stats().buried);
    assert!(
        kept.sample_changes(&traced, &before, &identity, 0.0)
            .is_empty()
    );

    // The open floor re-estimated brighter: its samples are sources, the buried ones
    // (filled anew from their brighter neighbours) are not.
    let brighter = |v: Vec3, filled: bool| match filled {
        true => surfcache_trace::irradiance::unchanged(v, &estimator),
        false => surfcache_trace::Estimate {
            value: v + Vec3::ONE,
            std_error: Vec3::splat(0.01),
            samples: 64,
            ..Default::default()
        },
    };
    let changed = re_bake(&brighter);
    assert_eq!(changed.stats().buried, before.stats().buried);
    let patches = changed.sample_changes(&traced, &before, &identity, 0.0);
    assert!(!patches.is_empty(), "no source where the floor changed");
    for p in &patches {
        let [a, b, c] = traced.positions()[p.triangle as usize];
        let uv = p.uv.expect("a sample's own point");
        let x = a * (1.0 - uv.x - uv.y) + b * uv.x + c * uv.y;
        assert!(
            !buried_in_attic_scene(x),
            "a buried sample at {x} is a source"
        );
        assert_eq!(p.change, 1.0);
    }
}

#[test]
fn vertex_lighting_estimates_each_mesh_vertex_once_per_side() {
    // A 2×2-cell grid mesh with shared vertices: 9 vertices, 8 triangles; two instances.
    let mut positions = Vec::new();
    for j in 0..3 {
        for i in 0..3 {
            positions.push(Vec3::new(i as f32, 0.0, j as f32));
        }
    }
    let mut indices = Vec::new();
    for j in 0..2u32 {
        for i in 0..2u32 {
            let a = j * 3 + i;
            indices.push([a, a + 3, a + 4]);
            indices.push([a, a + 4, a + 1]);
        }
    }
    let mesh = Mesh::new("grid", positions, indices);
    let mut second = Instance::new(mesh.clone(), Material::default());
    second.name = "grid2".into();
    second.transform = surfcache_core::glam::Affine3A::from_translation(Vec3::Y);
    let scene = Scene {
        instances: vec![Instance::new(mesh, Material::default()), second],
        ..Default::default()
    };
    let traced = TracedScene::new(&scene).unwrap();
    let (vl, rounds) = bake_synthetic(
        &traced,
        VertexLighting::new(&traced, VertexLightingSettings::default()),
        |p| {
            (
                Vec3::new(p.position.x, p.position.z, 1.0 + p.position.y),
                0.0,
            )
        },
    );
    assert_eq!(rounds.len(), 1);
    assert_eq!(vl.vertex_count(), 18);
    assert_eq!(rounds[0].len(), 36);
    let keys: HashSet<u64> = rounds[0].iter().map(|p| p.key).collect();
    assert_eq!(keys.len(), 36);
    let stats = vl.stats();
    assert_eq!(stats.sample_points, 36);
    assert_eq!(stats.cache_bytes, STORED_RGB_BYTES * 36 + 12 * 16 + 4);
    // E is linear in position here, so barycentric interpolation is exact.
    let mut rng = Points(3);
    for t in 0..16u32 {
        let [a, b, c] = traced.positions()[t as usize];
        for _ in 0..20 {
            let uv = rng.barycentrics();
            let p = a * (1.0 - uv.x - uv.y) + b * uv.x + c * uv.y;
            let want = Vec3::new(p.x, p.z, 1.0 + p.y);
            let got = vl.lookup(t, uv, true);
            assert!(
                (got - want).abs().max_element() < 0.01,
                "{t} {uv}: {got} vs {want}"
            );
        }
    }
}

/// A welded mesh from corner positions and quads (corner indices, counter-clockwise seen
/// from the side `facing` points to): vertices are shared between the quads.
fn welded(name: &str, positions: Vec<Vec3>, quads: &[([u32; 4], Vec3)]) -> Mesh {
    let mut indices = Vec::new();
    for &([a, b, c, d], facing) in quads {
        let p = |i: u32| positions[i as usize];
        let n = (p(b) - p(a)).cross(p(c) - p(a));
        if n.dot(facing) >= 0.0 {
            indices.extend([[a, b, c], [a, c, d]]);
        } else {
            indices.extend([[a, c, b], [a, d, c]]);
        }
    }
    Mesh::new(name, positions, indices)
}

/// An `nx` × `nz` grid of 1 m cells on y = 0, facing up, vertices shared.
fn floor_grid(nx: u32, nz: u32) -> Mesh {
    let mut positions = Vec::new();
    for z in 0..=nz {
        for x in 0..=nx {
            positions.push(Vec3::new(x as f32, 0.0, z as f32));
        }
    }
    let at = |x: u32, z: u32| z * (nx + 1) + x;
    let quads: Vec<_> = (0..nz)
        .flat_map(|z| (0..nx).map(move |x| (x, z)))
        .map(|(x, z)| {
            (
                [at(x, z), at(x + 1, z), at(x + 1, z + 1), at(x, z + 1)],
                Vec3::Y,
            )
        })
        .collect();
    welded("floor", positions, &quads)
}

/// Bakes order-1 maps (front sides) of `scene` with synthetic estimates that name the
/// triangle a point was estimated on; returns the maps, the round-0 point count and the
/// traced scene.
fn bake_corners(scene: &Scene, share_corners: bool) -> (IrradianceMaps, usize, TracedScene) {
    let traced = TracedScene::new(scene).unwrap();
    let settings = IrradianceMapSettings {
        density: 0.1, // every triangle within one sample spacing: order 1
        both_sides: false,
        share_corners,
        ..Default::default()
    };
    let maps = IrradianceMaps::new(&traced, settings);
    let (maps, rounds) = bake_synthetic(&traced, maps, |sp| {
        (Vec3::splat(1.0 + sp.triangle as f32), 0.0)
    });
    assert_eq!(rounds.len(), 1);
    (maps, rounds[0].len(), traced)
}

/// The corner values of every triangle at each position (front sides).
fn corner_values(maps: &IrradianceMaps, traced: &TracedScene) -> Vec<(Vec3, Vec3)> {
    let mut out = Vec::new();
    for t in 0..traced.triangle_count() as u32 {
        for (k, (i, j)) in [(0, 0), (1, 0), (0, 1)].into_iter().enumerate() {
            out.push((
                traced.positions()[t as usize][k],
                maps.sample(t, true, i, j),
            ));
        }
    }
    out
}

/// Shared corners (the thesis' outlook): coplanar triangles around a vertex take one
/// estimate, so a tessellated floor costs one point per vertex and every grid shows the
/// same value at a shared vertex; without sharing each triangle estimates its own.
#[test]
fn coplanar_triangles_share_their_corners() {
    let scene = Scene {
        instances: vec![Instance::new(floor_grid(4, 3), Material::default())],
        ..Default::default()
    };
    let (maps, points, traced) = bake_corners(&scene, true);
    assert_eq!(points, 5 * 4, "one point per vertex");
    assert_eq!(maps.stats().sample_points, 20);
    assert_eq!(
        maps.stats().cache_bytes,
        STORED_RGB_BYTES * 3 * 24 + 5 * 48 + 4,
        "every grid stores its copies"
    );
    let values = corner_values(&maps, &traced);
    for (p, v) in &values {
        for (q, w) in &values {
            if p == q {
                assert_eq!(v, w, "corner at {p} differs between triangles");
            }
        }
    }
    let (maps, points, traced) = bake_corners(&scene, false);
    assert_eq!(points, 3 * 24);
    let values = corner_values(&maps, &traced);
    assert!(
        values
            .iter()
            .any(|(p, v)| values.iter().any(|(q, w)| p == q && v != w)),
        "without sharing, corners are the triangles' own"
    );
}

/// What may not share: triangles 90° apart around a welded crease (their estimates would
/// clip different hemispheres), and triangles on two sides of a wall of another instance
/// standing on their shared vertices (their ray origins, a step inside each triangle, see
/// different rooms).
#[test]
fn creases_and_walls_keep_corners_apart() {
    // An L: floor x ∈ [0, 1], a wall up from x = 1, welded along the crease.
    let v = Vec3::new;
    let positions = vec![
        v(0., 0., 0.),
        v(1., 0., 0.),
        v(1., 1., 0.),
        v(0., 0., 1.),
        v(1., 0., 1.),
        v(1., 1., 1.),
    ];
    let l = welded(
        "l",
        positions,
        &[([0, 1, 4, 3], Vec3::Y), ([1, 2, 5, 4], Vec3::NEG_X)],
    );
    let scene = Scene {
        instances: vec![Instance::new(l, Material::default())],
        ..Default::default()
    };
    let (_, points, _) = bake_corners(&scene, true);
    assert_eq!(points, 6 + 2, "the crease's two vertices once per face");

    // A 2 × 1 floor with a wall of another instance standing on its middle vertex row.
    let wall = quad(
        "wall",
        [v(1., 0., -1.), v(1., 1., -1.), v(1., 1., 2.), v(1., 0., 2.)],
        Vec3::X,
    );
    let open = Scene {
        instances: vec![Instance::new(floor_grid(2, 1), Material::default())],
        ..Default::default()
    };
    let (_, points, _) = bake_corners(&open, true);
    assert_eq!(points, 6);
    let mut walled = open.clone();
    walled
        .instances
        .push(Instance::new(wall, Material::default()));
    let (maps, points, traced) = bake_corners(&walled, true);
    // 6 floor vertices, the middle row's 2 once per side, and the wall's 2 triangles
    // (4 vertices, shared between them).
    assert_eq!(points, 6 + 2 + 4);
    // The floor's grids left and right of the wall keep different corner values there.
    let floor = traced.instance_triangles()[0].clone();
    let values: Vec<_> = corner_values(&maps, &traced)
        .into_iter()
        .filter(|(p, _)| p.x == 1.0 && p.y == 0.0)
        .collect();
    assert!(floor.len() == 4 && values.len() >= 4);
    assert!(
        values
            .iter()
            .any(|(p, v)| values.iter().any(|(q, w)| p == q && v != w))
    );
}
