//! Surfaces that cross or touch (issue #12): closed forms where other geometry meets a
//! surface, through complete bakes as the product runs them ([`common::bake`]).
//!
//! - **Intersecting light-tight box.** Six single-sided quads facing inward, each
//!   sticking out 5 cm past the box's edges so the walls pierce each other, under a
//!   bright uniform sky: the inside is black however the walls meet. The same box of six
//!   closed slabs overlapping at every edge (walls as levels build them); the box of
//!   merely touching walls is in the cache crate's physics tests.
//! - **Contact.** Black surfaces under a uniform sky of radiance L, where E at a point of
//!   a surface is πL less what the blockers cover (Lambert's polygon formula,
//!   [`common::sky_minus_blockers`]): a box standing on a floor, a box piercing it, a
//!   zero-thickness wall standing on a larger floor triangle (both sides), a T-junction
//!   of walls, a wall piercing a floor at 60°, a prop piercing a wall — at 1 mm, 1 cm and
//!   10 cm from the contact, within [`CONTACT_TOLERANCE`] for irradiance maps and
//!   lightmaps.

mod common;

use common::{bake, estimator, grey, instance, lookup, sky_minus_blockers, traced};
use std::f32::consts::PI;
use surfcache::cache::{CacheSettings, IrradianceMapSettings, LightmapSettings, Method};
use surfcache::core::{
    Environment,
    glam::Vec3,
    scenes::{cuboid, quad},
};
use surfcache::trace::TracedScene;

/// Relative tolerance of E near contacts (the target).
const CONTACT_TOLERANCE: f32 = 0.03;

/// The two caches that claim not to leak.
const METHODS: [Method; 2] = [Method::IrradianceMap, Method::Lightmap];

/// Front sides only (every test point is on a front face): half the work.
fn settings(method: Method) -> CacheSettings {
    match method {
        Method::IrradianceMap => CacheSettings::IrradianceMap(IrradianceMapSettings {
            both_sides: false,
            ..Default::default()
        }),
        Method::Lightmap => CacheSettings::Lightmap(LightmapSettings {
            both_sides: false,
            ..Default::default()
        }),
        Method::Vertex => CacheSettings::for_method(method),
    }
}

/// A quad's corners as a polygon.
fn rect(c: [Vec3; 4]) -> Vec<Vec3> {
    c.to_vec()
}

/// A contact case: its name, the scene, and points (position, normal, blockers).
type Contact = (&'static str, TracedScene, Vec<(Vec3, Vec3, Vec<Vec<Vec3>>)>);

/// Bakes every case with each of `methods` and checks E at its points against the
/// sky-minus-blockers closed form.
fn check_contacts(cases: &[Contact], methods: &[Method]) {
    let mut failures = Vec::new();
    for (name, scene, points) in cases {
        for &method in methods {
            let (cache, _) = bake(scene, settings(method), estimator(0.01));
            let mut worst = 0.0f32;
            for (x, n, blockers) in points {
                let want = sky_minus_blockers(*x, *n, blockers, 1.0);
                let got = lookup(cache.as_ref(), scene, *x, *n);
                let err = ((got - Vec3::splat(want)) / want).abs().max_element();
                worst = worst.max(err);
                eprintln!(
                    "{name} {}: at {x}: {got} vs {want} ({:.2} %)",
                    method.name(),
                    err * 100.0
                );
                if err > CONTACT_TOLERANCE {
                    failures.push(format!(
                        "{name}, {}: at {x} got {got}, closed form {want} ({:.1} % off)",
                        method.name(),
                        err * 100.0
                    ));
                }
            }
            eprintln!("{name} {}: worst {:.2} %", method.name(), worst * 100.0);
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Distances from a contact at which E is checked.
const DISTANCES: [f32; 3] = [0.001, 0.01, 0.1];

#[test]
fn intersecting_walls_keep_a_light_tight_box_black() {
    // Box [0, 1]³; every wall spans [−0.05, 1.05] in its own plane.
    let (lo, hi) = (-0.05f32, 1.05f32);
    let mut instances = Vec::new();
    for axis in 0..3 {
        for (side, inward) in [(0.0f32, 1.0f32), (1.0, -1.0)] {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let corner = |a: f32, b: f32| {
                let mut p = Vec3::ZERO;
                p[axis] = side;
                p[u] = a;
                p[v] = b;
                p
            };
            let mut facing = Vec3::ZERO;
            facing[axis] = inward;
            let mesh = quad(
                format!("wall{axis}{side}"),
                [
                    corner(lo, lo),
                    corner(hi, lo),
                    corner(hi, hi),
                    corner(lo, hi),
                ],
                facing,
            );
            instances.push(instance(mesh, grey(0.8)));
        }
    }
    assert_black_inside_unit_box(&traced(instances, Environment::uniform(Vec3::splat(10.0))));
}

#[test]
fn overlapping_solid_walls_keep_a_light_tight_box_black() {
    // Box [0, 1]³ built as a level is: six closed slabs 10 cm thick (faces outward),
    // each reaching 10 cm past the box's edges, so that they overlap at every edge and
    // corner; each slab's face towards the inside is the box's wall.
    let (lo, hi, t) = (-0.1f32, 1.1f32, 0.1f32);
    let mut instances = Vec::new();
    for axis in 0..3 {
        for side in [0.0f32, 1.0] {
            let (mut min, mut max) = (Vec3::splat(lo), Vec3::splat(hi));
            min[axis] = if side == 0.0 { -t } else { 1.0 };
            max[axis] = if side == 0.0 { 0.0 } else { 1.0 + t };
            instances.push(instance(
                cuboid(format!("slab{axis}{side}"), min, max, false),
                grey(0.8),
            ));
        }
    }
    assert_black_inside_unit_box(&traced(instances, Environment::uniform(Vec3::splat(10.0))));
}

/// Bakes `scene` (whose inside is the light-tight box [0, 1]³ under a uniform sky of
/// radiance 10) with every method that claims not to leak, and checks that E at 13
/// points of the inside walls (the centre of every wall, and 5 cm inside two edges of
/// each of them but the last) is black: at most 10⁻³ of the outside's πL.
fn assert_black_inside_unit_box(scene: &TracedScene) {
    let mut points = Vec::new();
    for axis in 0..3 {
        for (side, inward) in [(0.0f32, 1.0f32), (1.0, -1.0)] {
            for (a, b) in [(0.5, 0.5), (0.05, 0.5)] {
                let mut p = Vec3::ZERO;
                p[axis] = side;
                p[(axis + 1) % 3] = a;
                p[(axis + 2) % 3] = b;
                let mut n = Vec3::ZERO;
                n[axis] = inward;
                points.push((p, n));
            }
        }
    }
    points.truncate(13);
    let outside = PI * 10.0;
    for method in METHODS {
        let (cache, _) = bake(scene, settings(method), estimator(0.01));
        for (x, n) in &points {
            let e = lookup(cache.as_ref(), scene, *x, *n);
            eprintln!("box {}: {x} -> {e}", method.name());
            assert!(
                e.max_element() <= 1e-3 * outside,
                "{}: inside the box at {x} E = {e} (outside: {outside})",
                method.name()
            );
        }
    }
}

/// A black floor of two triangles, 3 m across, centred at the origin, facing up.
fn floor() -> surfcache::core::Instance {
    instance(
        surfcache::core::scenes::square("floor", 1.5, 0.0, Vec3::Y),
        grey(0.0),
    )
}

/// Floor points at each of [`DISTANCES`] in front of the plane x = `x0` (towards +x if
/// `dir` = 1), with `blockers`.
fn floor_points(x0: f32, dir: f32, blockers: &[Vec<Vec3>]) -> Vec<(Vec3, Vec3, Vec<Vec<Vec3>>)> {
    DISTANCES
        .iter()
        .map(|d| {
            (
                Vec3::new(x0 + dir * d, 0.0, 0.05),
                Vec3::Y,
                blockers.to_vec(),
            )
        })
        .collect()
}

fn boxes_on_a_floor() -> Vec<Contact> {
    let mut cases = Vec::new();
    for (name, bottom) in [("standing box", 0.0f32), ("piercing box", -0.1)] {
        let b = cuboid(
            "box",
            Vec3::new(-0.25, bottom, -0.25),
            Vec3::new(0.25, 0.5, 0.25),
            false,
        );
        let scene = traced(
            vec![floor(), instance(b, grey(0.0))],
            Environment::uniform(Vec3::ONE),
        );
        // Seen from in front of its +x face, the box is that face alone.
        let face = rect([
            Vec3::new(0.25, 0.0, -0.25),
            Vec3::new(0.25, 0.0, 0.25),
            Vec3::new(0.25, 0.5, 0.25),
            Vec3::new(0.25, 0.5, -0.25),
        ]);
        cases.push((name, scene, floor_points(0.25, 1.0, &[face])));
    }
    cases
}

fn thin_wall() -> Vec<Contact> {
    let c = [
        Vec3::new(0.1, 0.0, -0.5),
        Vec3::new(0.1, 0.0, 0.5),
        Vec3::new(0.1, 0.6, 0.5),
        Vec3::new(0.1, 0.6, -0.5),
    ];
    let wall = quad("wall", c, Vec3::X);
    let scene = traced(
        vec![floor(), instance(wall, grey(0.0))],
        Environment::uniform(Vec3::ONE),
    );
    let mut points = floor_points(0.1, 1.0, &[rect(c)]);
    points.extend(floor_points(0.1, -1.0, &[rect(c)]));
    vec![("thin wall", scene, points)]
}

fn t_junction() -> Vec<Contact> {
    // Wall A in the plane z = 0 facing +z; wall B stands on it along x = 0, facing +x.
    let a = quad(
        "a",
        [
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        Vec3::Z,
    );
    let c = [
        Vec3::new(0.0, -0.4, 0.0),
        Vec3::new(0.0, 0.4, 0.0),
        Vec3::new(0.0, 0.4, 0.5),
        Vec3::new(0.0, -0.4, 0.5),
    ];
    let b = quad("b", c, Vec3::X);
    let scene = traced(
        vec![instance(a, grey(0.0)), instance(b, grey(0.0))],
        Environment::uniform(Vec3::ONE),
    );
    let points: Vec<_> = DISTANCES
        .iter()
        .flat_map(|d| [*d, -*d])
        .map(|x| (Vec3::new(x, 0.05, 0.0), Vec3::Z, vec![rect(c)]))
        .collect();
    vec![("T-junction", scene, points)]
}

fn leaning_wall() -> Vec<Contact> {
    // A wall through the line x = 0.1 on the floor, leaning 30° from vertical towards +x,
    // reaching 10 cm below the floor and 0.6 m along its slope above it.
    let lean = Vec3::new(30f32.to_radians().sin(), 30f32.to_radians().cos(), 0.0);
    let base = |z: f32, s: f32| Vec3::new(0.1, 0.0, z) + lean * s;
    let c = [
        base(-0.5, -0.1),
        base(0.5, -0.1),
        base(0.5, 0.6),
        base(-0.5, 0.6),
    ];
    let wall = quad("wall", c, Vec3::new(lean.y, -lean.x, 0.0));
    let scene = traced(
        vec![floor(), instance(wall, grey(0.0))],
        Environment::uniform(Vec3::ONE),
    );
    let above = rect([
        base(-0.5, 0.0),
        base(0.5, 0.0),
        base(0.5, 0.6),
        base(-0.5, 0.6),
    ]);
    let mut points = floor_points(0.1, 1.0, std::slice::from_ref(&above));
    points.extend(floor_points(0.1, -1.0, &[above]));
    vec![("leaning wall", scene, points)]
}

fn pierced_wall() -> Vec<Contact> {
    // A wall z = 0 facing +z; a box x, y ∈ [−0.2, 0.2], z ∈ [−0.2, 0.2] through it.
    let wall = quad(
        "wall",
        [
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        Vec3::Z,
    );
    let b = cuboid("prop", Vec3::splat(-0.2), Vec3::splat(0.2), false);
    let scene = traced(
        vec![instance(wall, grey(0.0)), instance(b, grey(0.0))],
        Environment::uniform(Vec3::ONE),
    );
    // In front of the prop's +x face, the part of it in front of the wall.
    let face = rect([
        Vec3::new(0.2, -0.2, 0.0),
        Vec3::new(0.2, 0.2, 0.0),
        Vec3::new(0.2, 0.2, 0.2),
        Vec3::new(0.2, -0.2, 0.2),
    ]);
    let points: Vec<_> = DISTANCES
        .iter()
        .map(|d| (Vec3::new(0.2 + d, 0.03, 0.0), Vec3::Z, vec![face.clone()]))
        .collect();
    vec![("pierced wall", scene, points)]
}

#[test]
fn a_zero_thickness_wall_on_a_larger_floor_triangle() {
    check_contacts(&thin_wall(), &METHODS);
}

#[test]
fn a_wall_piercing_a_floor_at_an_angle_lightmap() {
    check_contacts(&leaning_wall(), &[Method::Lightmap]);
}

#[test]
fn a_prop_piercing_a_wall_lightmap() {
    check_contacts(&pierced_wall(), &[Method::Lightmap]);
}

#[test]
fn a_wall_piercing_a_floor_at_an_angle_irradiance_maps() {
    check_contacts(&leaning_wall(), &[Method::IrradianceMap]);
}

#[test]
fn a_prop_piercing_a_wall_irradiance_maps() {
    check_contacts(&pierced_wall(), &[Method::IrradianceMap]);
}

#[test]
fn a_box_standing_on_and_piercing_a_floor_lightmap() {
    check_contacts(&boxes_on_a_floor(), &[Method::Lightmap]);
}

#[test]
fn a_box_standing_on_and_piercing_a_floor_irradiance_maps() {
    check_contacts(&boxes_on_a_floor(), &[Method::IrradianceMap]);
}

#[test]
fn a_t_junction_of_walls_lightmap() {
    check_contacts(&t_junction(), &[Method::Lightmap]);
}

#[test]
fn a_t_junction_of_walls_irradiance_maps() {
    check_contacts(&t_junction(), &[Method::IrradianceMap]);
}
