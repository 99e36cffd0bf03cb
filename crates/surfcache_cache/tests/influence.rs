//! Which points a re-bake's stage touches (`surfcache_cache::incremental::Influence`): the
//! change its forward rays estimate must match the change an edit makes, and an edit
//! must never reach a point that cannot see it.

mod common;

use common::{PI, square_cells, square_projected_solid_angle};
use surfcache_cache::incremental::{ChangePatch, Influence, Side};
use surfcache_core::{
    Environment, Instance, Material, Scene,
    geometry::plane_barycentric,
    glam::{Affine3A, Vec2, Vec3},
    scenes::{cuboid, square},
};
use surfcache_trace::{IrradianceLookup, TracedScene};

/// A cache that holds E = 1 everywhere.
struct Uniform;

impl IrradianceLookup for Uniform {
    fn irradiance(&self, _triangle: u32, _uv: Vec2, _front: bool) -> Option<Vec3> {
        Some(Vec3::ONE)
    }
}

fn traced(instances: Vec<Instance>, environment: Environment) -> TracedScene {
    TracedScene::new(&Scene {
        name: "influence".into(),
        instances,
        lights: vec![],
        environment,
    })
    .unwrap()
}

/// A black square hung 2 m above a floor under a uniform sky of radiance 1: wherever
/// the floor sees it, it hides sky of radiance 1 behind radiance 0, so the change is
/// |ΔL| = 1 over its projected solid angle.
#[test]
fn forward_rays_estimate_the_change_a_new_surface_makes() {
    let grey = Material::diffuse("grey", Vec3::splat(0.5));
    let floor = || Instance::new(square("floor", 10.0, 0.0, Vec3::Y), grey.clone());
    let sky = Environment::uniform(Vec3::ONE);
    let old = traced(vec![floor()], sky.clone());
    let black = Material::diffuse("black", Vec3::ZERO);
    let new = traced(
        vec![
            floor(),
            Instance::new(square("patch", 0.25, 2.0, -Vec3::Y), black),
        ],
        sky,
    );
    let influence = Influence::of_edit(&old, &new, &Uniform, &Uniform, &[], &[2, 3], 0.05, 7);
    for x in [0.0, 0.7, 1.5, 3.0] {
        let p = Vec3::new(x, 0.0, 0.3);
        let exact = square_projected_solid_angle(p);
        let (q, sigma) = influence.change_at(p, Vec3::Y);
        assert!(
            (q - exact).abs() <= 4.0 * sigma + 0.05 * exact,
            "at x = {x}: Q = {q} ± {sigma}, exact {exact}"
        );
        // Near the square, enough rays land to tell its change within a third.
        if x < 2.0 {
            assert!(sigma < exact / 3.0, "at x = {x}: σ = {sigma} of {exact}");
        }
    }
    // Far out along the floor the square is below a small allowance's reach; right
    // under it, far above.
    assert!(influence.reaches(0, Vec3::new(0.0, 0.0, 0.3), Vec3::Y, 0.01));
    assert!(!influence.reaches(0, Vec3::new(9.0, 0.0, 9.0), Vec3::Y, 0.01));
    // The other side of the floor sees nothing of it.
    assert_eq!(influence.change_at(Vec3::ZERO, -Vec3::Y).0, 0.0);
}

/// Irradiance `after` on some triangles' front sides, zero elsewhere and before.
struct OnTriangles {
    triangles: Vec<u32>,
    after: f32,
}

impl IrradianceLookup for OnTriangles {
    fn irradiance(&self, triangle: u32, _uv: Vec2, front: bool) -> Option<Vec3> {
        let on = front && self.triangles.contains(&triangle);
        Some(Vec3::splat(if on { self.after } else { 0.0 }))
    }
}

/// The square of the test above, grey and lit afresh on its lower side (ΔE = 1 there),
/// as an indirect stage sees it: 8 × 8 texels as sources. The floor below gets
/// `ρ/π · ΔE` over the square's projected solid angle.
#[test]
fn forward_rays_from_changed_texels_estimate_the_change_they_pass_on() {
    let albedo = 0.5;
    let grey = Material::diffuse("grey", Vec3::splat(albedo));
    let scene = traced(
        vec![
            Instance::new(square("floor", 10.0, 0.0, Vec3::Y), grey.clone()),
            Instance::new(square("patch", 0.25, 2.0, -Vec3::Y), grey),
        ],
        Environment::uniform(Vec3::ZERO),
    );
    let square_triangles = [2u32, 3];
    let (centres, size) = square_cells(8);
    let patches: Vec<ChangePatch> = centres
        .map(|p| {
            // The triangle of the square that holds the texel centre.
            let (triangle, uv) = square_triangles
                .iter()
                .map(|&t| {
                    let [a, b, c] = scene.positions()[t as usize];
                    (t, plane_barycentric(p, a, b, c))
                })
                .find(|(_, uv)| uv.min_element() >= 0.0 && uv.x + uv.y <= 1.0)
                .unwrap();
            ChangePatch {
                triangle,
                side: Side::Front,
                uv: Some(uv),
                area: size * size,
                change: 1.0,
            }
        })
        .collect();
    let after = OnTriangles {
        triangles: square_triangles.to_vec(),
        after: 1.0,
    };
    let before = OnTriangles {
        triangles: Vec::new(),
        after: 0.0,
    };
    let influence = Influence::of_changes(&scene, &after, &before, &patches, 0.0, 0.05, 11);
    for x in [0.0, 0.7, 1.5] {
        let p = Vec3::new(x, 0.0, 0.3);
        let exact = albedo / PI * square_projected_solid_angle(p);
        let (q, sigma) = influence.change_at(p, Vec3::Y);
        assert!(
            (q - exact).abs() <= 4.0 * sigma + 0.05 * exact,
            "at x = {x}: Q = {q} ± {sigma}, exact {exact}"
        );
        assert!(sigma < exact / 3.0, "at x = {x}: σ = {sigma} of {exact}");
    }
    // The square's upper side did not change: nothing above it is reached.
    assert_eq!(
        influence.change_at(Vec3::new(0.0, 3.0, 0.0), -Vec3::Y).0,
        0.0
    );
}

/// Two sealed rooms side by side, each lit (its cache holds E = 1 everywhere), and a
/// black block moved in the first: nothing in the second room may count as reached,
/// however small the allowance, while the floor around the block must.
#[test]
fn an_edit_in_a_sealed_room_never_reaches_the_room_next_door() {
    let white = Material::diffuse("white", Vec3::splat(0.8));
    let room = |name: &str, x: f32| {
        Instance::new(
            cuboid(
                name,
                Vec3::new(x, 0.0, 0.0),
                Vec3::new(x + 2.0, 2.0, 2.0),
                true,
            ),
            white.clone(),
        )
    };
    let black = Material::diffuse("black", Vec3::ZERO);
    let block = |dx: f32| {
        let mut b = Instance::new(
            cuboid(
                "block",
                Vec3::new(0.8, 0.0, 0.8),
                Vec3::new(1.2, 0.4, 1.2),
                false,
            ),
            black.clone(),
        );
        b.transform = Affine3A::from_translation(Vec3::new(dx, 0.0, 0.0));
        b
    };
    let scene = |dx: f32| {
        traced(
            vec![room("a", 0.0), room("b", 2.5), block(dx)],
            Environment::uniform(Vec3::ONE),
        )
    };
    let (old, new) = (scene(0.0), scene(0.3));
    let blocks: Vec<u32> = (24..36).collect();
    let influence = Influence::of_edit(&old, &new, &Uniform, &Uniform, &blocks, &blocks, 0.05, 3);
    // Room b: triangles 12..24, sampled at their corners' centroid and along their edges.
    for t in 12..24u32 {
        let [a, b, c] = new.positions()[t as usize];
        let n = new.geometric_normals()[t as usize];
        for (u, v) in [
            (1.0 / 3.0, 1.0 / 3.0),
            (0.05, 0.05),
            (0.9, 0.05),
            (0.05, 0.9),
        ] {
            let p = a + (b - a) * u + (c - a) * v;
            assert!(
                !influence.reaches(t, p, n, 1e-9),
                "room b, triangle {t} at {p} counts as reached"
            );
        }
    }
    // Room a's floor (facing up, y = 0) next to the block: reached.
    let floor = (0..12u32)
        .find(|&t| new.geometric_normals()[t as usize].y > 0.9)
        .unwrap();
    for p in [Vec3::new(1.6, 0.0, 1.0), Vec3::new(0.6, 0.0, 1.0)] {
        assert!(
            influence.reaches(floor, p, Vec3::Y, 0.01 * PI),
            "next to the block at {p}"
        );
    }
    // The block itself always is.
    assert!(influence.reaches(30, Vec3::new(1.5, 0.4, 1.0), Vec3::Y, f32::INFINITY));
}
