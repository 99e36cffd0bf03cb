//! What the Sponza examples share: the scene with single pieces split off its merged
//! meshes, and comparisons of two caches at random points in open air.

use std::{path::Path, sync::Arc};
use surfcache::{
    cache::{Cache, SurfaceCache},
    cli::{Comparison, compare},
    core::{Environment, Mesh, Scene, glam::Vec3, sampling::Rng},
    io::{load_scene, read_environment_map},
    trace::TracedScene,
};

/// Splits the largest connected piece off `mesh`: (the rest, the piece).
pub fn split_largest_piece(mesh: &Mesh) -> (Mesh, Mesh) {
    let mut parent: Vec<u32> = (0..mesh.positions.len() as u32).collect();
    fn root(parent: &mut [u32], mut v: u32) -> u32 {
        while parent[v as usize] != v {
            parent[v as usize] = parent[parent[v as usize] as usize];
            v = parent[v as usize];
        }
        v
    }
    for [a, b, c] in &mesh.indices {
        for (x, y) in [(*a, *b), (*b, *c)] {
            let (rx, ry) = (root(&mut parent, x), root(&mut parent, y));
            parent[rx as usize] = ry;
        }
    }
    let mut sizes = std::collections::HashMap::new();
    for t in &mesh.indices {
        *sizes.entry(root(&mut parent, t[0])).or_insert(0usize) += 1;
    }
    let (&largest, _) = sizes.iter().max_by_key(|(r, n)| (**n, **r)).unwrap();
    let (mut rest, mut piece) = (mesh.clone(), mesh.clone());
    rest.indices.clear();
    piece.indices.clear();
    for t in &mesh.indices {
        if root(&mut parent, t[0]) == largest {
            piece.indices.push(*t);
        } else {
            rest.indices.push(*t);
        }
    }
    piece.name = format!("{}_piece", mesh.name);
    (rest, piece)
}

/// Crytek Sponza from `../shared/assets` under the sunny sky of its reference, with the
/// largest connected piece of each named material's mesh split off into an instance of
/// its own, named `<material>_piece` (Sponza's meshes are one per material: the
/// examples edit one vase or one curtain, not all of them).
pub fn sponza(pieces: &[&str]) -> Scene {
    let shared = Path::new("../shared/assets");
    let mut scene = load_scene(
        shared
            .join("scenes/sponza_crytek/Sponza.gltf")
            .to_str()
            .unwrap(),
    )
    .expect("Sponza from ../shared/assets")
    .scene;
    let (map, _) = read_environment_map(&shared.join("envmaps/immenstadter_horn_1k.exr"))
        .expect("an HDR map from ../shared/assets");
    scene.environment = Environment::from_map(Arc::new(map));
    for material in pieces {
        let k = scene
            .instances
            .iter()
            .position(|i| i.material.name == *material)
            .unwrap_or_else(|| panic!("Sponza has a mesh of material {material}"));
        let (rest, piece) = split_largest_piece(&scene.instances[k].mesh);
        let mut split = scene.instances[k].clone();
        split.name = format!("{material}_piece");
        split.mesh = Arc::new(piece);
        scene.instances[k].mesh = Arc::new(rest);
        scene.instances.push(split);
    }
    scene
}

/// `a` against the reference `b` at `n` random surface points of `scene` in open air
/// (front sides, area-weighted, [`TracedScene::in_open_air`]: points inside solids are
/// filled by convention and seen by nobody; the metric of `surfcache compare`), within
/// `near` (centre, radius) when given.
pub fn compare_caches(
    scene: &TracedScene,
    a: &Cache,
    b: &Cache,
    n: usize,
    near: Option<(Vec3, f32)>,
) -> Comparison {
    let areas = scene.area_distribution();
    let mut rng = Rng::new(2026, 12 + near.is_some() as u64);
    let (mut result, mut reference) = (Vec::new(), Vec::new());
    for _ in 0..1000 * n {
        if result.len() == n {
            break;
        }
        let p = scene.sample_surface(&areas, rng.next_f32(), rng.next_vec2(), true);
        let inside = near.is_none_or(|(c, r)| p.position.distance(c) <= r);
        if inside && scene.in_open_air(&p, 32, &mut rng) {
            result.push((p.position, a.lookup(p.triangle, p.uv, true)));
            reference.push((p.position, b.lookup(p.triangle, p.uv, true), None));
        }
    }
    compare(&result, &reference)
}

/// The sphere within 3 radii of the named instance's centre: the neighbourhood of an
/// edit, where its effect is not drowned by the rest of the scene.
pub fn neighbourhood(scene: &TracedScene, name: &str) -> (Vec3, f32) {
    let i = scene
        .instance_names()
        .iter()
        .position(|n| n == name)
        .expect("the edited instance");
    let (lo, hi) = scene.instance_triangles()[i]
        .clone()
        .flat_map(|t| scene.positions()[t as usize])
        .fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(p), hi.max(p)),
        );
    (0.5 * (lo + hi), 1.5 * (hi - lo).length())
}
