//! Guided hemisphere sampling stays unbiased whatever the guide (docs/design.md, Guiding):
//! closed forms reached with guides that point at the light, away from it, or nowhere
//! in particular, and a lightmap and irradiance maps of a room lit only through a hole in
//! its ceiling (the case guides are for) against Lambert's polygon formula.

mod common;

use surfcache::cache::{
    CacheSettings, SurfaceCache,
    bake::{BakeJob, BakeSettings},
    irradiance_map::IrradianceMapSettings,
    lightmap::LightmapSettings,
};
use surfcache::core::{
    Environment, EnvironmentMap, Instance, Material, Scene,
    geometry::orthonormal_basis,
    glam::{Vec2, Vec3},
    sampling::{Rng, cosine_hemisphere_square},
    scenes::{cuboid, quad},
};
use surfcache::trace::{
    EstimatorSettings, Guidance, IrradianceLookup, PointInScene, Sampler, TracedScene, estimate,
    guiding::{DirectionGuide, GuideRecord},
};

/// A guide that believes all light comes through the square cells around `centre`.
fn guide_towards(centre: Vec2) -> DirectionGuide {
    let record = GuideRecord::new(1.0);
    let mut rng = Rng::new(1, 2);
    for _ in 0..4096 {
        let u = rng.next_vec2();
        let v = if (u - centre).length() < 0.2 {
            50.0
        } else {
            0.0
        };
        record.add(u, v);
    }
    DirectionGuide::from_record(&record).unwrap()
}

fn guides() -> Vec<(&'static str, DirectionGuide)> {
    vec![
        ("corner", guide_towards(Vec2::new(0.05, 0.05))),
        ("centre", guide_towards(Vec2::splat(0.5))),
        ("edge", guide_towards(Vec2::new(0.95, 0.5))),
    ]
}

/// E at `position` (facing `normal`) with `guide`, `samples` samples: value and standard
/// error per channel.
fn guided(
    scene: &TracedScene,
    position: Vec3,
    normal: Vec3,
    guide: Option<&DirectionGuide>,
    sampler: Sampler,
    samples: u32,
) -> (Vec3, Vec3) {
    let p = scene.locate(position, normal).expect("on a surface");
    let at = PointInScene::new(scene, p, scene.spawn_origin(&p)).with_guidance(Guidance {
        guide,
        record: None,
    });
    let e = estimate(
        &at,
        &EstimatorSettings::fixed(sampler, samples, None),
        3,
        11,
    );
    (e.value, e.std_error)
}

/// Within four standard errors (plus rounding) in every channel.
#[track_caller]
fn assert_close(got: (Vec3, Vec3), expected: Vec3, what: &str) {
    common::assert_within_errors(got, expected, 4.0, what);
}

fn floor(h: f32) -> Instance {
    let v = Vec3::new;
    Instance::new(
        quad(
            "floor",
            [v(-h, 0., -h), v(h, 0., -h), v(h, 0., h), v(-h, 0., h)],
            Vec3::Y,
        ),
        Material::diffuse("floor", Vec3::splat(0.5)),
    )
}

#[test]
fn plane_under_uniform_sky_receives_pi_l_whatever_the_guide() {
    let l = Vec3::new(0.5, 1.0, 2.0);
    let scene = TracedScene::new(&Scene {
        instances: vec![floor(10.0)],
        environment: Environment::uniform(l),
        ..Default::default()
    })
    .unwrap();
    for (name, g) in guides() {
        for sampler in [Sampler::Cosine, Sampler::Qmc, Sampler::Mis, Sampler::Best] {
            let r = guided(&scene, Vec3::ZERO, Vec3::Y, Some(&g), sampler, 8192);
            assert_close(r, std::f32::consts::PI * l, &format!("{name} {sampler:?}"));
        }
    }
}

#[test]
fn furnace_box_matches_geometric_series_whatever_the_guide() {
    // Closed box whose inner walls emit Le with albedo ρ: E = π Le / (1 − ρ).
    let (le, rho) = (Vec3::new(1.0, 2.0, 0.5), 0.6);
    let mut wall = Material::emissive("wall", Vec3::splat(rho), le);
    wall.double_sided = false;
    let scene = TracedScene::new(&Scene {
        instances: vec![Instance::new(
            cuboid("box", Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0), true),
            wall,
        )],
        ..Default::default()
    })
    .unwrap();
    let expected = std::f32::consts::PI * le / (1.0 - rho);
    for (name, g) in guides() {
        for sampler in [Sampler::Cosine, Sampler::Best] {
            let r = guided(
                &scene,
                Vec3::new(0.5, 0.0, 1.5),
                Vec3::Y,
                Some(&g),
                sampler,
                40_000,
            );
            assert_close(r, expected, &format!("furnace {name} {sampler:?}"));
        }
    }
}

#[test]
fn sun_and_sky_map_agrees_with_and_without_guides() {
    // A sky of radiance 1 with a sun 2,000 times as bright in a few pixels, over a plane
    // with a wall beside it: guided and plain estimates of the same point agree.
    let sun = Vec3::new(0.5, 0.6, 0.3).normalize();
    let map = EnvironmentMap::from_fn(64, 32, |d| {
        if d.dot(sun) > 0.995 {
            Vec3::splat(2000.0)
        } else {
            Vec3::ONE
        }
    });
    let v = Vec3::new;
    let wall = Instance::new(
        quad(
            "wall",
            [v(1., 0., -5.), v(1., 3., -5.), v(1., 3., 5.), v(1., 0., 5.)],
            Vec3::NEG_X,
        ),
        Material::diffuse("wall", Vec3::splat(0.7)),
    );
    let scene = TracedScene::new(&Scene {
        instances: vec![floor(10.0), wall],
        environment: Environment::from_map(std::sync::Arc::new(map)),
        ..Default::default()
    })
    .unwrap();
    let plain = guided(&scene, Vec3::ZERO, Vec3::Y, None, Sampler::Best, 200_000);
    for (name, g) in guides() {
        let r = guided(
            &scene,
            Vec3::ZERO,
            Vec3::Y,
            Some(&g),
            Sampler::Best,
            200_000,
        );
        let se = (r.1 * r.1 + plain.1 * plain.1).map(f32::sqrt);
        assert_close((r.0, se), plain.0, &format!("sun and sky, {name}"));
    }
}

/// Radiance of the sky above [`room_with_a_ceiling_hole`].
const SKY: f32 = 2.0;

/// A black 2 × 1 × 2 m room whose ceiling has a 0.5 m square hole above (0.5, 1, 0.5),
/// under a uniform sky of radiance `SKY`: the floor sees the sky through the hole only,
/// E = the hole's polygon irradiance. Most of the floor gets its light from a small part
/// of its hemisphere: the case guides are for. Returns the scene and the hole.
fn room_with_a_ceiling_hole() -> (TracedScene, [Vec3; 4]) {
    let v = Vec3::new;
    let black = || common::grey(0.0);
    let rect = |name: &str, c: [Vec3; 4], n: Vec3| common::instance(quad(name, c, n), black());
    let (lo, hi) = (0.25, 0.75);
    let instances = vec![
        rect(
            "floor",
            [
                v(-1., 0., -1.),
                v(1., 0., -1.),
                v(1., 0., 1.),
                v(-1., 0., 1.),
            ],
            Vec3::Y,
        ),
        rect(
            "x-",
            [
                v(-1., 0., -1.),
                v(-1., 0., 1.),
                v(-1., 1., 1.),
                v(-1., 1., -1.),
            ],
            Vec3::X,
        ),
        rect(
            "x+",
            [v(1., 0., -1.), v(1., 1., -1.), v(1., 1., 1.), v(1., 0., 1.)],
            Vec3::NEG_X,
        ),
        rect(
            "z-",
            [
                v(-1., 0., -1.),
                v(-1., 1., -1.),
                v(1., 1., -1.),
                v(1., 0., -1.),
            ],
            Vec3::Z,
        ),
        rect(
            "z+",
            [v(-1., 0., 1.), v(1., 0., 1.), v(1., 1., 1.), v(-1., 1., 1.)],
            Vec3::NEG_Z,
        ),
        // The ceiling around the hole: four slabs.
        rect(
            "c1",
            [
                v(-1., 1., -1.),
                v(-1., 1., 1.),
                v(lo, 1., 1.),
                v(lo, 1., -1.),
            ],
            Vec3::NEG_Y,
        ),
        rect(
            "c2",
            [v(hi, 1., -1.), v(hi, 1., 1.), v(1., 1., 1.), v(1., 1., -1.)],
            Vec3::NEG_Y,
        ),
        rect(
            "c3",
            [v(lo, 1., -1.), v(lo, 1., lo), v(hi, 1., lo), v(hi, 1., -1.)],
            Vec3::NEG_Y,
        ),
        rect(
            "c4",
            [v(lo, 1., hi), v(lo, 1., 1.), v(hi, 1., 1.), v(hi, 1., hi)],
            Vec3::NEG_Y,
        ),
    ];
    let scene = common::traced(instances, Environment::uniform(Vec3::splat(SKY)));
    let hole = [v(lo, 1., lo), v(hi, 1., lo), v(hi, 1., hi), v(lo, 1., hi)];
    (scene, hole)
}

/// 60 points on the floor of [`room_with_a_ceiling_hole`], away from its walls.
fn floor_points() -> impl Iterator<Item = Vec3> {
    let mut points = common::Points(0x5eed);
    (0..60).map(move |_| {
        let x = -0.8 + 1.6 * points.next_f32();
        Vec3::new(x, 0.0, -0.8 + 1.6 * points.next_f32())
    })
}

/// Every one of 60 floor points of [`room_with_a_ceiling_hole`] (away from the walls)
/// looked up in `cache` within four standard errors of a bound `rel` (floor `floor`) of
/// Lambert's formula, plus `slack` of it (a cache's interpolation bound), plus the most E
/// changes within `reach` of the point (the cache's resolution, measured from the closed
/// form). Returns the values looked up.
fn assert_floor_matches_lambert(
    cache: &dyn SurfaceCache,
    scene: &TracedScene,
    hole: &[Vec3; 4],
    (rel, floor, slack): (f32, f32, f32),
    reach: f32,
) -> Vec<f32> {
    let v = Vec3::new;
    floor_points()
        .enumerate()
        .map(|(k, x)| {
            let expected = common::polygon_irradiance(x, Vec3::Y, hole, SKY);
            let got = common::lookup(cache, scene, x, Vec3::Y);
            let spread = [v(reach, 0., reach), v(reach, 0., -reach)]
                .iter()
                .flat_map(|d| [x + *d, x - *d])
                .map(|y| (common::polygon_irradiance(y, Vec3::Y, hole, SKY) - expected).abs())
                .fold(0.0f32, f32::max);
            let tol = 4.0 * rel * (expected + floor) + slack * expected + spread + 1e-4;
            assert!(
                (got.x - expected).abs() <= tol,
                "floor point {k} at {x}: got {}, expected {expected} (tolerance {tol})",
                got.x
            );
            got.x
        })
        .collect()
}

/// Lightmaps of [`room_with_a_ceiling_hole`], 16 texels per metre.
fn room_lightmaps() -> CacheSettings {
    CacheSettings::Lightmap(LightmapSettings {
        texels_per_metre: 16.0,
        ..Default::default()
    })
}

#[test]
fn room_lit_through_a_ceiling_hole_matches_lamberts_formula() {
    // The texels' first round draws through the guides the bounce passes lend, their
    // later rounds through their own. Bilinear lookups blend texels within one texel of
    // a point.
    let (scene, hole) = room_with_a_ceiling_hole();
    let rel = 0.02;
    let estimator = common::estimator_with(rel, 64, 4096, 0.0);
    let (cache, floor) = common::bake(&scene, room_lightmaps(), estimator);
    assert_floor_matches_lambert(cache.as_ref(), &scene, &hole, (rel, floor, 0.0), 1.0 / 16.0);
}

#[test]
fn the_final_pass_borrows_guides_that_point_at_the_opening() {
    // A lightmap bake of the room: its bounce passes record where their texels' light
    // came from, and the final pass's first round, which has learnt nothing yet, draws
    // through those guides. At floor points they must favour the hole.
    let (scene, hole) = room_with_a_ceiling_hole();
    let mut job = BakeJob::new(BakeSettings {
        cache: room_lightmaps(),
        estimator: common::estimator_with(0.02, 64, 4096, 0.0),
        ..Default::default()
    });
    while !job.step(&scene, 4096) {}
    let outcome = job.into_outcome().expect("the bake finished");
    let bounce = &outcome.passes[outcome.passes.len() - 2];
    let centre = hole.iter().copied().sum::<Vec3>() / 4.0;
    let (t, b) = orthonormal_basis(Vec3::Y);
    let mut guided = 0;
    for x in floor_points() {
        let (triangle, uv, front) = common::locate(&scene, x, Vec3::Y);
        let Some(guide) = bounce.guide(triangle, uv, front) else {
            continue;
        };
        guided += 1;
        let w = (centre - x).normalize();
        let square = cosine_hemisphere_square(Vec3::new(t.dot(w), b.dot(w), w.y));
        let density = guide.density(square);
        assert!(density > 2.0, "at {x}: density {density} towards the hole");
    }
    assert!(guided >= 54, "{guided} of 60 floor points have a guide");
}

#[test]
fn irradiance_maps_of_a_room_lit_through_a_ceiling_hole_match_lamberts_formula() {
    // The floor's grids refine over several rounds; the new samples of each round after
    // the first draw through the guide their grid learnt from the rounds before.
    let (scene, hole) = room_with_a_ceiling_hole();
    let maps = |guiding| {
        CacheSettings::IrradianceMap(IrradianceMapSettings {
            density: 16.0,
            max_order: 32,
            guiding,
            ..Default::default()
        })
    };
    let rel = 0.02;
    let estimator = common::estimator_with(rel, 64, 4096, 0.0);
    let (guided, floor) = common::bake(&scene, maps(true), estimator);
    // A lookup interpolates within a cell of its grid: at most one spacing of the floor
    // triangles' maximum order away (their long edge is 2√2 m), or within the
    // interpolation bound of a coarser grid's cell.
    let spacing = 8f32.sqrt() / 32.0;
    let slack = IrradianceMapSettings::default().interpolation_error;
    let got =
        assert_floor_matches_lambert(guided.as_ref(), &scene, &hole, (rel, floor, slack), spacing);
    // The guides were used: the same bake without them draws other directions. (It is
    // not held to the formula: where the hole covers a few percent of a point's
    // hemisphere, a point's first 64 samples can all miss it, and with gathered bounces
    // such an all-zero run is taken for a dark point and stops; docs/design.md,
    // Estimator, "All-zero runs".)
    let (plain, _) = common::bake(&scene, maps(false), estimator);
    let without: Vec<f32> = floor_points()
        .map(|x| common::lookup(plain.as_ref(), &scene, x, Vec3::Y).x)
        .collect();
    assert_ne!(got, without);
    // Without guides but with every path traced to its end, an all-zero run goes on
    // until the light it may have missed is below the bound, and the plain estimates
    // hold the formula too.
    let (traced, traced_floor) = common::bake_with(
        &scene,
        BakeSettings {
            cache: maps(false),
            estimator,
            gather_passes: 0,
            ..Default::default()
        },
    );
    let bounds = (rel, traced_floor, slack);
    assert_floor_matches_lambert(traced.as_ref(), &scene, &hole, bounds, spacing);
}
