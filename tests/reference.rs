//! Closed-form checks of the path-traced reference E(x, n) (issue: foundation).
//!
//! Each scene has an exact answer; the estimate must lie within 3 standard errors of it
//! (plus a float-precision allowance where the estimator has no variance at all).

mod common;

use surfcache::core::EnvironmentMap;
use surfcache::core::{
    Environment, Instance, Light, Material, Scene,
    glam::Vec3,
    scenes::{cuboid, quad},
};
use surfcache::trace::{EstimatorSettings, Query, Sampler, TracedScene, reference_irradiance};

/// A square of half-size `h` in the plane y = 0, facing +Y.
fn floor(h: f32, albedo: f32) -> Instance {
    let v = Vec3::new;
    Instance::new(
        quad(
            "floor",
            [v(-h, 0., -h), v(h, 0., -h), v(h, 0., h), v(-h, 0., h)],
            Vec3::Y,
        ),
        Material::diffuse("floor", Vec3::splat(albedo)),
    )
}

fn reference(
    scene: &Scene,
    queries: &[Query],
    samples: u32,
    sampler: Sampler,
) -> Vec<(Vec3, Vec3)> {
    reference_bounded(scene, queries, samples, sampler, None)
}

fn reference_bounded(
    scene: &Scene,
    queries: &[Query],
    samples: u32,
    sampler: Sampler,
    max_bounces: Option<u32>,
) -> Vec<(Vec3, Vec3)> {
    let traced = TracedScene::new(scene).unwrap();
    let settings = EstimatorSettings::fixed(sampler, samples, max_bounces);
    reference_irradiance(&traced, queries, &settings, 7, &|| {})
        .into_iter()
        .map(|e| {
            let e = e.expect("query point must be on a surface");
            (e.value, e.std_error)
        })
        .collect()
}

/// |E − expected| ≤ 3 se + 1e-4 expected + 1e-6 in every channel.
#[track_caller]
fn assert_close(got: (Vec3, Vec3), expected: Vec3, what: &str) {
    common::assert_within_errors(got, expected, 3.0, what);
}

#[test]
fn plane_under_uniform_sky_receives_pi_l() {
    let l = Vec3::new(0.5, 1.0, 2.0);
    let scene = Scene {
        instances: vec![floor(10.0, 0.5)],
        environment: Environment::uniform(l),
        ..Default::default()
    };
    let queries = [
        Query {
            position: Vec3::ZERO,
            normal: Vec3::Y,
        },
        Query {
            position: Vec3::new(3.0, 0.0, -2.0),
            normal: Vec3::Y,
        },
        // The underside sees the sky's lower hemisphere, also uniform.
        Query {
            position: Vec3::new(1.0, 0.0, 1.0),
            normal: Vec3::NEG_Y,
        },
    ];
    for sampler in Sampler::ALL {
        for (i, r) in reference(&scene, &queries, 4096, sampler)
            .into_iter()
            .enumerate()
        {
            assert_close(
                r,
                std::f32::consts::PI * l,
                &format!("{sampler:?} point {i}"),
            );
        }
    }
}

#[test]
fn light_tight_box_stays_black_inside() {
    // A closed 1 m box under a very bright sky; points on the floor's centre and 1 mm from
    // walls, edges and corners.
    let scene = Scene {
        instances: vec![Instance::new(
            cuboid("box", Vec3::ZERO, Vec3::ONE, true),
            Material::diffuse("wall", Vec3::splat(0.8)),
        )],
        environment: Environment::uniform(Vec3::splat(1e4)),
        ..Default::default()
    };
    let mm = 1e-3;
    let queries = [
        Query {
            position: Vec3::new(0.5, 0.0, 0.5),
            normal: Vec3::Y,
        },
        Query {
            position: Vec3::new(mm, 0.0, 0.5),
            normal: Vec3::Y,
        },
        Query {
            position: Vec3::new(mm, 0.0, mm),
            normal: Vec3::Y,
        },
        Query {
            position: Vec3::new(0.0, mm, mm),
            normal: Vec3::X,
        },
        Query {
            position: Vec3::new(1.0 - mm, 1.0, 1.0 - mm),
            normal: Vec3::NEG_Y,
        },
    ];
    for sampler in Sampler::ALL {
        for (i, (e, _)) in reference(&scene, &queries, 20_000, sampler)
            .into_iter()
            .enumerate()
        {
            assert_eq!(e, Vec3::ZERO, "{sampler:?}: point {i} leaked light");
        }
    }
}

#[test]
fn furnace_box_matches_geometric_series() {
    // Closed box whose inner walls emit Le with albedo ρ: E = π Le / (1 − ρ).
    let (le, rho) = (Vec3::new(1.0, 2.0, 0.5), 0.6);
    let mut wall = Material::emissive("wall", Vec3::splat(rho), le);
    wall.double_sided = false;
    let scene = Scene {
        instances: vec![Instance::new(
            cuboid("box", Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0), true),
            wall,
        )],
        ..Default::default()
    };
    let queries = [
        Query {
            position: Vec3::new(0.5, 0.0, 1.5),
            normal: Vec3::Y,
        },
        Query {
            position: Vec3::new(0.0, 1.999, 0.2),
            normal: Vec3::X,
        },
    ];
    let expected = std::f32::consts::PI * le / (1.0 - rho);
    for sampler in Sampler::ALL {
        for (i, r) in reference(&scene, &queries, 40_000, sampler)
            .into_iter()
            .enumerate()
        {
            assert_close(r, expected, &format!("{sampler:?}: furnace point {i}"));
        }
    }
}

#[test]
fn point_and_spot_lights_follow_inverse_square_cosine_law() {
    let intensity = Vec3::new(3.0, 2.0, 1.0);
    let position = Vec3::new(0.3, 2.0, -0.4);
    let scene = Scene {
        instances: vec![floor(10.0, 0.7)],
        lights: vec![Light::Point {
            position,
            intensity,
        }],
        ..Default::default()
    };
    let points = [
        Vec3::ZERO,
        Vec3::new(2.0, 0.0, 1.0),
        Vec3::new(-4.0, 0.0, 3.0),
    ];
    let queries: Vec<Query> = points
        .iter()
        .map(|&p| Query {
            position: p,
            normal: Vec3::Y,
        })
        .collect();
    for (r, x) in reference(&scene, &queries, 64, Sampler::Cosine)
        .into_iter()
        .zip(points)
    {
        let d = position - x;
        let expected = intensity * (d.normalize().y / d.length_squared());
        assert_close(r, expected, "point light");
    }
}

#[test]
fn directional_light_gives_cosine_law_and_hard_shadow() {
    // Light travelling down and towards +X at 30° from the vertical; a black box on a
    // black floor, so nothing reflects and the shadow is exactly 0.
    let es = Vec3::new(2.0, 1.5, 1.0);
    let direction = Vec3::new(0.5, -(0.75f32.sqrt()), 0.0);
    let scene = Scene {
        instances: vec![
            floor(10.0, 0.0),
            Instance::new(
                cuboid(
                    "blocker",
                    Vec3::new(-0.5, 0.0, -0.5),
                    Vec3::new(0.5, 1.0, 0.5),
                    false,
                ),
                Material::diffuse("black", Vec3::ZERO),
            ),
        ],
        lights: vec![Light::Directional {
            direction,
            irradiance: es,
        }],
        ..Default::default()
    };
    let lit = Query {
        position: Vec3::new(-3.0, 0.0, 0.0),
        normal: Vec3::Y,
    };
    // The shadow of the 1 m box reaches tan 30° ≈ 0.577 m beyond its +X face.
    let shadow = Query {
        position: Vec3::new(0.8, 0.0, 0.0),
        normal: Vec3::Y,
    };
    let r = reference(&scene, &[lit, shadow], 16, Sampler::Cosine);
    assert_close(r[0], es * 0.75f32.sqrt(), "lit floor");
    assert_eq!(r[1].0, Vec3::ZERO, "shadowed floor");
}

#[test]
fn bounce_limit_zero_counts_only_first_hits() {
    // Furnace again with no indirect bounces: E = π Le exactly.
    let le = Vec3::splat(1.0);
    let scene = Scene {
        instances: vec![Instance::new(
            cuboid("box", Vec3::ZERO, Vec3::ONE, true),
            Material::emissive("wall", Vec3::splat(0.9), le),
        )],
        ..Default::default()
    };
    let q = [Query {
        position: Vec3::new(0.5, 0.0, 0.5),
        normal: Vec3::Y,
    }];
    let r = reference_bounded(&scene, &q, 2000, Sampler::Uniform, Some(0));
    assert_close(r[0], std::f32::consts::PI * le, "bounces=0");
}

#[test]
fn spot_light_cone_falloff() {
    // A spot pointing straight down: full intensity inside the inner cone, nothing outside
    // the outer cone.
    let intensity = Vec3::splat(5.0);
    let position = Vec3::new(0.0, 2.0, 0.0);
    let scene = Scene {
        instances: vec![floor(10.0, 0.5)],
        lights: vec![Light::Spot {
            position,
            direction: Vec3::NEG_Y,
            intensity,
            inner_cone_angle: 0.3,
            outer_cone_angle: 0.5,
        }],
        ..Default::default()
    };
    let inside = Vec3::new(0.2, 0.0, 0.0); // 5.7° off axis
    let outside = Vec3::new(2.0, 0.0, 0.0); // 45° off axis
    let q = [inside, outside].map(|p| Query {
        position: p,
        normal: Vec3::Y,
    });
    let r = reference(&scene, &q, 16, Sampler::Cosine);
    let d = position - inside;
    assert_close(
        r[0],
        intensity * (d.normalize().y / d.length_squared()),
        "inside cone",
    );
    assert_eq!(r[1].0, Vec3::ZERO, "outside cone");
}

#[test]
fn tilted_planes_under_sky_only_map() {
    // A map that is L above the horizon and black below: a black plane whose normal is
    // tilted α from the zenith receives E = π L (1 + cos α) / 2. Exercises environment
    // importance sampling (the map is not uniform, so `mis`/`best` sample it).
    let l = Vec3::new(1.0, 0.8, 0.6);
    let sky = EnvironmentMap::from_fn(128, 64, |d| if d.y > 0.0 { l } else { Vec3::ZERO });
    // The horizon row of pixels is half lit; give the map an exact horizon by evaluating
    // the closed form against the map's own row integral.
    let map = std::sync::Arc::new(sky);
    for (k, alpha) in [0.0f32, 0.5, 1.2, 2.0].into_iter().enumerate() {
        let n = Vec3::new(alpha.sin(), alpha.cos(), 0.0);
        // A small square centred at the origin, facing n.
        let (t, b) = surfcache::core::geometry::orthonormal_basis(n);
        let h = 0.5;
        let corners = [(-h, -h), (h, -h), (h, h), (-h, h)].map(|(x, y)| t * x + b * y);
        let scene = Scene {
            instances: vec![Instance::new(
                quad("plane", corners, n),
                Material::diffuse("black", Vec3::ZERO),
            )],
            environment: Environment::from_map(map.clone()),
            ..Default::default()
        };
        // Exact for this map: sum over lit pixels of L max(0, n·ω) ΔΩ, by fine quadrature.
        let mut expected = 0.0f64;
        let (w, hgt) = (128u32, 64u32);
        let sub = 8;
        for j in 0..hgt * sub {
            for i in 0..w * sub {
                let uv = surfcache::core::glam::Vec2::new(
                    (i as f32 + 0.5) / (w * sub) as f32,
                    (j as f32 + 0.5) / (hgt * sub) as f32,
                );
                let d = surfcache::core::environment::uv_to_direction(uv);
                // Nearest pixel decides lit or not, as the bilinear lookup does away from the
                // horizon row.
                let lit = ((j / sub) as f32 + 0.5) / hgt as f32 * std::f32::consts::PI
                    < std::f32::consts::FRAC_PI_2;
                if !lit {
                    continue;
                }
                let th0 = j as f64 / (hgt * sub) as f64 * std::f64::consts::PI;
                let th1 = (j + 1) as f64 / (hgt * sub) as f64 * std::f64::consts::PI;
                let d_omega = std::f64::consts::TAU / (w * sub) as f64 * (th0.cos() - th1.cos());
                expected += (n.dot(d).max(0.0) as f64) * d_omega;
            }
        }
        let closed_form = std::f64::consts::PI * (1.0 + alpha.cos() as f64) / 2.0;
        // The pixelated horizon differs from the ideal one by under 2 %.
        assert!(
            (expected - closed_form).abs() < 0.02 * closed_form,
            "{expected} {closed_form}"
        );
        let q = [Query {
            position: Vec3::ZERO,
            normal: n,
        }];
        for sampler in Sampler::ALL {
            let r = reference(&scene, &q, 20_000, sampler);
            let (e, se) = r[0];
            for c in 0..3 {
                let exp = l[c] as f64 * expected;
                // Bilinear filtering blurs the horizon by half a pixel row: allow 1 %.
                let tol = 3.0 * se[c] as f64 + 0.01 * exp;
                assert!(
                    (e[c] as f64 - exp).abs() <= tol,
                    "{sampler:?} tilt {k}: channel {c}: {} ± {} vs {exp}",
                    e[c],
                    se[c]
                );
            }
        }
    }
}
