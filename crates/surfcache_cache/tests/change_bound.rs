//! The bound that lets an incremental re-bake's indirect stages skip far points
//! (`surfcache_cache::incremental::ChangeBound`): it must never be below the change it
//! bounds, or a skipped point would leave out more than its allowance.

mod common;

use common::{PI, square_projected_solid_angle};
use surfcache_cache::incremental::{ChangeBound, ChangePlan};
use surfcache_core::{
    Environment, Instance, Material, Scene,
    glam::{Vec2, Vec3},
    scenes::square,
};
use surfcache_trace::TracedScene;

/// A 20 m floor facing up (triangles 0, 1) and a 0.5 m patch 2 m above the origin facing
/// down (triangles 2, 3), albedo 0.8.
fn floor_and_patch() -> TracedScene {
    let material = Material::diffuse("grey", Vec3::splat(0.8));
    let floor = square("floor", 10.0, 0.0, Vec3::Y);
    let patch = square("patch", 0.25, 2.0, -Vec3::Y);
    TracedScene::new(&Scene {
        name: "patch".into(),
        instances: vec![
            Instance::new(floor, material.clone()),
            Instance::new(patch, material),
        ],
        lights: vec![],
        environment: Environment::black(),
    })
    .unwrap()
}

/// `∫ ρ/π ΔE cos θ dω` over the patch seen from floor point `x` (normal +Y).
fn exact_change(x: Vec3, delta_e: f32) -> f32 {
    0.8 / PI * delta_e * square_projected_solid_angle(x)
}

#[test]
fn bound_holds_the_change_and_tightens_with_distance() {
    let scene = floor_and_patch();
    let delta_e = 3.0;
    let bound = ChangeBound::new(&scene, &[0.0, 0.0, delta_e, delta_e]);
    let mut last_ratio = f32::INFINITY;
    for x in [0.0, 1.0, 3.0, 6.0, 9.5] {
        let p = Vec3::new(x, 0.0, 0.3 * x);
        let exact = exact_change(p, delta_e);
        let b = bound.bound(p, Vec3::Y);
        assert!(b >= exact, "at {p}: bound {b} below the change {exact}");
        let ratio = b / exact;
        assert!(
            ratio < 40.0,
            "at {p}: bound {b} is {ratio}× the change {exact}"
        );
        last_ratio = ratio;
    }
    // Far away the per-triangle solid angles, not the sphere, bound it: tight up to the
    // patch's own foreshortening (cos ≈ 0.2 there), which a two-sided bound ignores.
    assert!(last_ratio < 8.0, "far bound {last_ratio}× the change");
}

#[test]
fn plan_skips_only_what_the_allowance_covers() {
    let scene = floor_and_patch();
    let bound = ChangeBound::new(&scene, &[0.0, 0.0, 3.0, 3.0]);
    let p = Vec3::new(2.0, 0.0, 0.0);
    let exact = exact_change(p, 3.0);
    assert_eq!(
        bound.plan(p, Vec3::Y, bound.bound(p, Vec3::Y)),
        ChangePlan::Unchanged
    );
    match bound.plan(p, Vec3::Y, 0.5 * exact) {
        ChangePlan::Cone(cone) => {
            // The cone holds the whole patch.
            for c in [
                Vec2::new(-0.25, -0.25),
                Vec2::new(0.25, 0.25),
                Vec2::new(-0.25, 0.25),
            ] {
                let w = (Vec3::new(c.x, 2.0, c.y) - p).normalize();
                assert!(cone.contains(w), "corner {c} outside the cone");
            }
        }
        other => panic!("a small far patch is integrated over its cone, got {other:?}"),
    }
    // Seen from below its plane facing away, or with nothing changed: no change at all.
    assert_eq!(bound.bound(Vec3::new(0.0, 3.0, 0.0), Vec3::Y), 0.0);
    let nothing = ChangeBound::new(&scene, &[0.0; 4]);
    assert_eq!(nothing.plan(p, Vec3::Y, 0.0), ChangePlan::Unchanged);
}
