//! The plugin end to end: background bakes, incremental re-bakes after each kind of edit
//! (checked against from-scratch bakes of the edited scene), removal, superseded bakes,
//! independence from frame pacing, and BVH builds that keep only the newest waiting
//! snapshot.

use bevy_ecs::prelude::*;
use glam::{Affine3A, Vec3};
use std::{collections::BTreeMap, sync::Arc, time::Duration};
use surfcache_cache::{Cache, CacheSettings, Method, SurfaceCache, bake::BakeSettings};
use surfcache_core::{Environment, Instance, Material, Mesh, Scene, sampling::Rng, scenes};
use surfcache_ecs::{
    BakeConfig, BakeFinished, BakeMode, BakedLightmap, BakedSurfaceCache, BvhBuilds,
    EnvironmentLight, InstanceName, SurfaceMaterial, SurfcachePlugin, TracedSceneState,
    WorldTransform, spawn_scene,
};
use surfcache_trace::{EstimatorSettings, TracedScene};

const BOUND: f32 = 0.05;

/// Quick settings: coarse caches, a 5 % bound, full paths (no gathering pre-passes).
fn settings(method: Method) -> BakeSettings {
    let mut cache = CacheSettings::for_method(method);
    // Vertex lighting has no density.
    if let Some(density) = cache.density_mut() {
        *density = match method {
            Method::Lightmap => 12.0,
            _ => 8.0,
        };
    }
    BakeSettings {
        cache,
        estimator: EstimatorSettings {
            max_rel_error: BOUND,
            min_samples: 64,
            max_samples: 4096,
            floor: 0.0,
            ..Default::default()
        },
        seed: 7,
        gather_passes: 0,
        density_budget: None,
    }
}

fn world_with(scene: &Scene, config: BakeConfig) -> (World, Schedule, Vec<Entity>) {
    let mut world = World::new();
    let mut schedule = Schedule::default();
    SurfcachePlugin::with_config(config).build(&mut world, &mut schedule);
    let entities = spawn_scene(&mut world, scene);
    (world, schedule, entities)
}

fn config(method: Method) -> BakeConfig {
    BakeConfig {
        settings: settings(method),
        threads: Some(2),
        ..Default::default()
    }
}

fn bake(world: &mut World, schedule: &mut Schedule) -> BakeFinished {
    SurfcachePlugin::run_until_baked(world, schedule, Duration::from_millis(1), |_| true)
        .expect("the bake finishes")
}

fn baked(world: &World) -> (Arc<TracedScene>, Arc<Cache>) {
    let r = world.resource::<BakedSurfaceCache>();
    (r.scene.clone().unwrap(), r.cache().unwrap().clone())
}

/// Relative RMS of `a` against `b` at area-weighted random front-side points in open air
/// ([`TracedScene::in_open_air`]; the metric of `surfcache compare`, ε = 1 % of the mean).
fn rel_rms(scene: &TracedScene, a: &dyn SurfaceCache, b: &dyn SurfaceCache) -> f64 {
    let areas = scene.area_distribution();
    let mut rng = Rng::new(3, 4);
    let pairs: Vec<(Vec3, Vec3)> = (0..1500)
        .filter_map(|_| {
            let p = scene.sample_surface(&areas, rng.next_f32(), rng.next_vec2(), true);
            scene.in_open_air(&p, 32, &mut rng).then(|| {
                (
                    a.lookup(p.triangle, p.uv, true),
                    b.lookup(p.triangle, p.uv, true),
                )
            })
        })
        .filter(|(_, b)| b.max_element() > 0.0)
        .collect();
    assert!(pairs.len() > 1000, "{} points in open air", pairs.len());
    let mean = pairs.iter().map(|p| p.1).sum::<Vec3>() / pairs.len() as f32;
    let eps = 0.01 * mean;
    let sq: f64 = pairs
        .iter()
        .map(|(a, b)| (((*a - *b) / (*b + eps)).length_squared()) as f64)
        .sum();
    (sq / (3 * pairs.len()) as f64).sqrt()
}

/// Every entity's published textures (its [`BakedLightmap`] component).
fn lightmaps(world: &mut World) -> BTreeMap<Entity, BakedLightmap> {
    world
        .query::<(Entity, &BakedLightmap)>()
        .iter(world)
        .map(|(e, l)| (e, l.clone()))
        .collect()
}

fn entity_named(world: &mut World, name: &str) -> Entity {
    let mut q = world.query::<(Entity, &InstanceName)>();
    q.iter(world)
        .find(|(_, n)| n.0 == name)
        .map(|(e, _)| e)
        .unwrap_or_else(|| panic!("no instance '{name}'"))
}

/// One edit: applied to the world (as a game would) and to the plain scene (for the
/// from-scratch bake).
struct EditCase {
    name: &'static str,
    world: fn(&mut World),
    scene: fn(&mut Scene),
}

fn move_block(world: &mut World) {
    let e = entity_named(world, "short_block");
    world.get_mut::<WorldTransform>(e).unwrap().0 =
        Affine3A::from_translation(Vec3::new(0.0, 0.0, 0.1));
}

fn move_block_scene(scene: &mut Scene) {
    for i in &mut scene.instances {
        if i.name == "short_block" {
            i.transform = Affine3A::from_translation(Vec3::new(0.0, 0.0, 0.1));
        }
    }
}

fn red_block() -> Arc<Material> {
    Arc::new(Material::diffuse("red", Vec3::new(0.8, 0.1, 0.1)))
}

fn recolour(world: &mut World) {
    let e = entity_named(world, "tall_block");
    world.get_mut::<SurfaceMaterial>(e).unwrap().0 = red_block();
}

fn recolour_scene(scene: &mut Scene) {
    for i in &mut scene.instances {
        if i.name == "tall_block" {
            i.material = red_block();
        }
    }
}

fn remove(world: &mut World) {
    let e = entity_named(world, "short_block");
    world.despawn(e);
}

fn remove_scene(scene: &mut Scene) {
    scene.instances.retain(|i| i.name != "short_block");
}

/// Checks the incremental re-bake after `case` against a from-scratch bake of the
/// edited scene, for `method`.
fn check_edit(method: Method, case: &EditCase) {
    let before = scenes::cornell();
    let (mut world, mut schedule, _) = world_with(&before, config(method));
    let first = bake(&mut world, &mut schedule);
    assert!(!first.incremental);
    let (_, stale) = baked(&world);
    (case.world)(&mut world);
    let rebake = bake(&mut world, &mut schedule);
    assert!(rebake.incremental, "{}: re-baked incrementally", case.name);
    assert!(rebake.generation > first.generation);
    let (scene, incremental) = baked(&world);

    let mut after = before.clone();
    (case.scene)(&mut after);
    let (mut w2, mut s2, _) = world_with(&after, config(method));
    bake(&mut w2, &mut s2);
    let (scratch_scene, scratch) = baked(&w2);
    assert_eq!(
        scratch_scene.positions(),
        scene.positions(),
        "{}",
        case.name
    );
    let err = rel_rms(&scene, incremental.as_ref(), scratch.as_ref());
    eprintln!(
        "{} / {}: incremental vs scratch rel_rms {err:.4}",
        method.name(),
        case.name
    );
    assert!(
        err <= 2.0 * BOUND as f64,
        "{} / {}: incremental differs from scratch by {err:.4}",
        method.name(),
        case.name
    );
    // The edit mattered (else the check above proves nothing): a stale cache, where it
    // still applies (same triangles), is worse.
    if stale.as_ref().stats().sample_points > 0 && case.name != "remove" {
        let stale_err = rel_rms(&scene, stale.as_ref(), scratch.as_ref());
        eprintln!("  stale cache: {stale_err:.4}");
        assert!(stale_err > 1.5 * err, "{}: stale {stale_err:.4}", case.name);
    }
}

const CASES: [EditCase; 3] = [
    EditCase {
        name: "move",
        world: move_block,
        scene: move_block_scene,
    },
    EditCase {
        name: "recolour",
        world: recolour,
        scene: recolour_scene,
    },
    EditCase {
        name: "remove",
        world: remove,
        scene: remove_scene,
    },
];

#[test]
fn incremental_rebakes_agree_with_scratch_lightmap() {
    for case in &CASES {
        check_edit(Method::Lightmap, case);
    }
}

#[test]
fn incremental_rebakes_agree_with_scratch_irradiance_map() {
    for case in &CASES {
        check_edit(Method::IrradianceMap, case);
    }
}

#[test]
fn added_entity_is_baked_and_removed_entity_textures_disappear() {
    let scene = scenes::cornell();
    let (mut world, mut schedule, entities) = world_with(&scene, config(Method::Lightmap));
    bake(&mut world, &mut schedule);
    let block = entity_named(&mut world, "short_block");
    assert!(world.get::<BakedLightmap>(block).is_some());
    // Add a copy of the tall block, moved: re-baked incrementally, published.
    let tall = scene
        .instances
        .iter()
        .find(|i| i.name == "tall_block")
        .unwrap();
    let added = world
        .spawn((
            surfcache_ecs::MeshGeometry(tall.mesh.clone()),
            SurfaceMaterial(tall.material.clone()),
            WorldTransform(Affine3A::from_translation(Vec3::new(0.0, 0.0, 0.2)) * tall.transform),
            InstanceName("tall_block_copy".into()),
        ))
        .id();
    let done = bake(&mut world, &mut schedule);
    assert!(done.incremental);
    assert!(done.updated.contains(&added));
    assert!(world.get::<BakedLightmap>(added).unwrap().front.is_some());
    // The components that changed are exactly the updated entities'.
    for (entity, lightmap) in lightmaps(&mut world) {
        let changed = lightmap.version == done.generation;
        assert_eq!(changed, done.updated.contains(&entity), "{entity}");
    }
    // Remove the short block: its textures disappear, the others stay.
    world.despawn(block);
    let done = bake(&mut world, &mut schedule);
    assert!(done.incremental);
    assert_eq!(done.removed, vec![block]);
    let published = lightmaps(&mut world);
    assert!(!published.contains_key(&block));
    assert!(published.contains_key(&entities[0]));
    assert_eq!(published.len(), scene.instances.len());
}

#[test]
fn environment_change_rebakes_from_scratch() {
    let scene = scenes::cornell();
    let (mut world, mut schedule, _) = world_with(&scene, config(Method::Lightmap));
    bake(&mut world, &mut schedule);
    let mut q = world.query::<&mut EnvironmentLight>();
    for mut env in q.iter_mut(&mut world) {
        env.0 = Environment::uniform(Vec3::splat(0.5));
    }
    let done = bake(&mut world, &mut schedule);
    assert!(
        !done.incremental,
        "a new sky lights everything: a full re-bake"
    );
}

/// An edit while the first bake is in flight supersedes it: it never publishes, and
/// what is published is exactly the from-scratch bake of the edited scene.
#[test]
fn edit_during_a_bake_never_publishes_the_old_scene() {
    let before = scenes::cornell();
    let (mut world, mut schedule, _) = world_with(&before, config(Method::Lightmap));
    // Run until the first bake is under way.
    while !world.resource::<surfcache_ecs::BakeStatus>().running {
        SurfcachePlugin::update(&mut world, &mut schedule);
        std::thread::sleep(Duration::from_millis(1));
    }
    move_block(&mut world);
    let done = bake(&mut world, &mut schedule);
    assert!(
        !done.incremental,
        "no bake had finished: this one starts from scratch"
    );
    assert_eq!(
        done.generation,
        world.resource::<TracedSceneState>().generation
    );
    let (scene, cache) = baked(&world);
    let mut after = before.clone();
    move_block_scene(&mut after);
    let (mut w2, mut s2, _) = world_with(&after, config(Method::Lightmap));
    bake(&mut w2, &mut s2);
    let (scratch_scene, scratch) = baked(&w2);
    assert_eq!(scene.positions(), scratch_scene.positions());
    assert_eq!(cache.publish(&scene), scratch.publish(&scratch_scene));
}

/// The same bake whatever the pacing: background with small or large steps, or on the
/// frame thread within a 1 ms or 20 ms budget, gives identical textures.
#[test]
fn results_are_identical_across_frame_budgets() {
    let scene = scenes::cornell();
    let mut results = Vec::new();
    for (mode, points) in [
        (BakeMode::Background, 64),
        (BakeMode::Background, 4096),
        (
            BakeMode::Foreground {
                budget: Duration::from_millis(1),
            },
            16,
        ),
        (
            BakeMode::Foreground {
                budget: Duration::from_millis(20),
            },
            256,
        ),
    ] {
        let config = BakeConfig {
            mode,
            points_per_step: points,
            ..config(Method::IrradianceMap)
        };
        let (mut world, mut schedule, _) = world_with(&scene, config);
        bake(&mut world, &mut schedule);
        results.push(lightmaps(&mut world));
    }
    for r in &results[1..] {
        assert_eq!(r, &results[0]);
    }
}

/// New settings re-bake from scratch; the same settings written again re-publish the
/// baseline without baking.
#[test]
fn settings_changes_rebake_and_unchanged_settings_republish() {
    let scene = scenes::cornell();
    let (mut world, mut schedule, _) = world_with(&scene, config(Method::Lightmap));
    let first = bake(&mut world, &mut schedule);
    let published = lightmaps(&mut world);
    world.insert_resource(config(Method::Lightmap));
    let again = bake(&mut world, &mut schedule);
    assert!(again.updated.is_empty() && again.removed.is_empty());
    assert_eq!(again.generation, first.generation);
    assert_eq!(lightmaps(&mut world), published);
    world.insert_resource(config(Method::IrradianceMap));
    let other = bake(&mut world, &mut schedule);
    assert!(!other.incremental);
    assert_eq!(other.updated.len(), scene.instances.len());
    let (_, cache) = baked(&world);
    assert_eq!(cache.method(), Method::IrradianceMap);
}

/// A bake fits its settings to the scene (here a density budget lowers the lightmaps'
/// density, as `surfcache bake`'s defaults do on a level); an edit afterwards must still
/// re-bake incrementally: the policy compares the settings asked for, not the fitted ones
/// (it compared the fitted ones, so every edit under the default budget re-baked from
/// scratch).
#[test]
fn an_edit_re_bakes_incrementally_when_the_bake_fitted_its_density() {
    let mut config = config(Method::Lightmap);
    config.settings.density_budget = Some(100);
    let asked = config.settings.cache.density();
    let (mut world, mut schedule, _) = world_with(&scenes::cornell(), config);
    let first = bake(&mut world, &mut schedule);
    assert!(!first.incremental);
    let fitted = world
        .resource::<BakedSurfaceCache>()
        .outcome
        .as_ref()
        .unwrap()
        .settings;
    assert!(
        fitted.cache.density() < asked,
        "the budget lowered the density"
    );
    move_block(&mut world);
    let rebake = bake(&mut world, &mut schedule);
    assert!(rebake.incremental, "re-baked incrementally");
}

/// A square panel of `n` × `n` quads (2 n² triangles) just below the Cornell box's
/// ceiling, facing down: enough triangles that each BVH build takes a while.
fn dense_panel(n: u32) -> Mesh {
    let step = 0.5 / n as f32;
    let mut positions = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            positions.push(Vec3::new(
                -0.25 + step * i as f32,
                0.9,
                -0.25 + step * j as f32,
            ));
        }
    }
    let v = |i: u32, j: u32| i * (n + 1) + j;
    let mut indices = Vec::new();
    for i in 0..n {
        for j in 0..n {
            indices.push([v(i, j), v(i + 1, j), v(i + 1, j + 1)]);
            indices.push([v(i, j), v(i + 1, j + 1), v(i, j + 1)]);
        }
    }
    Mesh::new("dense_panel", positions, indices)
}

fn place_block(world: &mut World, z: f32) {
    let e = entity_named(world, "short_block");
    world.get_mut::<WorldTransform>(e).unwrap().0 =
        Affine3A::from_translation(Vec3::new(0.0, 0.0, z));
}

/// Snapshots that arrive while a BVH build runs replace one another: the worker builds
/// fewer scenes than it was sent, and the traced scene ends as the last snapshot.
#[test]
fn bvh_builds_skip_superseded_snapshots_and_end_on_the_newest() {
    let mut scene = scenes::cornell();
    let grey = Arc::new(Material::diffuse("grey", Vec3::splat(0.5)));
    scene.instances.push(Instance {
        name: "dense_panel".into(),
        mesh: Arc::new(dense_panel(300)),
        material: grey,
        transform: Affine3A::IDENTITY,
    });
    // Only the BVH is kept current.
    let config = BakeConfig {
        enabled: false,
        ..config(Method::Lightmap)
    };
    let (mut world, mut schedule, _) = world_with(&scene, config);
    // One frame per edit, as when something is dragged: each frame snapshots the scene.
    let edits = 6;
    for k in 1..=edits {
        place_block(&mut world, 0.01 * k as f32);
        SurfcachePlugin::update(&mut world, &mut schedule);
    }
    let start = std::time::Instant::now();
    while world.resource::<BvhBuilds>().busy() {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "the builds never finished"
        );
        SurfcachePlugin::update(&mut world, &mut schedule);
        std::thread::sleep(Duration::from_millis(1));
    }
    let builds = world.resource::<BvhBuilds>();
    assert_eq!(builds.requested, edits);
    eprintln!("{} snapshots, {} built", builds.requested, builds.builds());
    assert!(
        builds.builds() < builds.requested,
        "{} snapshots arrived within a build, yet {} were built",
        builds.requested,
        builds.builds()
    );
    let traced = world.resource::<TracedSceneState>();
    assert!(traced.error.is_none());
    assert_eq!(traced.generation, edits);
    let mut last = scene.clone();
    for i in &mut last.instances {
        if i.name == "short_block" {
            i.transform = Affine3A::from_translation(Vec3::new(0.0, 0.0, 0.01 * edits as f32));
        }
    }
    // Instance order follows the entities; compare each instance's triangles by name.
    let by_name = |s: &TracedScene| {
        let mut triangles: Vec<(String, Vec<[Vec3; 3]>)> = (0..s.instance_names().len())
            .map(|k| {
                let positions = s.instance_triangles()[k]
                    .clone()
                    .map(|t| s.positions()[t as usize])
                    .collect();
                (s.instance_names()[k].clone(), positions)
            })
            .collect();
        triangles.sort_by(|a, b| a.0.cmp(&b.0));
        triangles
    };
    let expected = by_name(&TracedScene::new(&last).unwrap());
    let built = by_name(traced.scene().unwrap());
    assert_eq!(built.len(), scene.instances.len());
    assert!(
        built == expected,
        "the traced scene is not the last snapshot's"
    );
}
