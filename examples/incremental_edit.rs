//! Incremental re-baking after an edit, through the ECS plugin.
//!
//! Bakes the built-in Cornell box in a `bevy_ecs` world, moves the short block by 10 cm
//! (as a game's editor would, by writing its `WorldTransform`), and lets the plugin
//! re-bake incrementally in the background. Then bakes the edited scene from scratch in
//! a second world and compares the two caches at 2,000 random surface points. Writes
//! `out/incremental_edit/{before,after,from_scratch}.png`.
//!
//! With `--scene sponza` it does the same on Crytek Sponza from `../shared/assets` under
//! an HDR sky at the bake's defaults, moving one round vase by 1 m (Sponza's vases are one
//! mesh per material: the example splits one connected piece off into an entity of its
//! own first).
//!
//! ```text
//! cargo run --release --example incremental_edit [-- --method lightmap|irradiance-map|vertex]
//!     [--noise-floor]   # also bake the edited scene with another seed: the metric's noise
//!     [--scene cornell|sponza] [--density D] [--sides both|front] [--max-rel-error B] [--gather N]
//!     [--min-samples N] [--max-samples N]
//! ```
//!
//! The last line of output is
//! `full_s=<seconds> incremental_s=<seconds> ratio=<incremental/full> rel_rms_vs_full=<value>`,
//! where `full_s` is the from-scratch bake of the edited scene.

#[path = "shared/sponza.rs"]
mod sponza;

use bevy_ecs::prelude::*;
use std::{path::Path, sync::Arc, time::Duration};
use surfcache::{
    cache::{Cache, CacheSettings, Method, SurfaceCache, bake::BakeSettings},
    cli::{
        camera::{Camera, default_view},
        picture::{auto_exposure, write_png},
        render_view, surface_radiance,
    },
    core::{
        Scene,
        glam::{Affine3A, Vec3},
        scenes,
    },
    ecs::{
        BakeConfig, BakeFinished, BakedSurfaceCache, InstanceName, SurfcachePlugin, WorldTransform,
        spawn_scene,
    },
    trace::TracedScene,
};

/// A world with the plugin baking `scene` with `settings`.
fn world_with(scene: &Scene, settings: BakeSettings) -> (World, Schedule) {
    let mut world = World::new();
    let mut schedule = Schedule::default();
    SurfcachePlugin::with_config(BakeConfig {
        settings,
        ..Default::default()
    })
    .build(&mut world, &mut schedule);
    spawn_scene(&mut world, scene);
    (world, schedule)
}

/// Runs frames (a 60 Hz game loop) until the plugin publishes a bake.
fn run_until_baked(world: &mut World, schedule: &mut Schedule) -> BakeFinished {
    SurfcachePlugin::run_until_baked(world, schedule, Duration::from_millis(16), |_| true)
        .unwrap_or_else(|e| panic!("bake failed: {e}"))
}

fn baked(world: &World) -> (Arc<TracedScene>, Arc<Cache>) {
    let r = world.resource::<BakedSurfaceCache>();
    (r.scene.clone().unwrap(), r.cache().unwrap().clone())
}

/// The default camera's view of `scene` shaded from `cache`, as a PNG.
fn picture(scene: &TracedScene, cache: &Cache, path: &Path) {
    let (lo, hi) = scene.positions().iter().flatten().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let (eye, target) = default_view(lo, hi, 40.0);
    let camera = Camera::look_at(eye, target, 40.0);
    let shade = |hit: &surfcache::trace::Hit, d: Vec3, _key: u64| {
        let front = scene.geometric_normals()[hit.triangle as usize].dot(d) < 0.0;
        surface_radiance(scene, hit, d, cache.lookup(hit.triangle, hit.uv, front))
    };
    let pixels = render_view(scene, &camera, 320, 320, true, &shade, || {});
    write_png(path, 320, 320, &pixels, auto_exposure(&pixels)).expect("write the picture");
}

fn arg<'a>(args: &'a [String], name: &str) -> Option<&'a str> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .map(String::as_str)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let method = arg(&args, "--method")
        .map(|m| Method::from_name(m).expect("method: vertex, irradiance-map or lightmap"))
        .unwrap_or_default();
    let mut settings = BakeSettings {
        cache: CacheSettings::for_method(method),
        ..Default::default()
    };
    let (before_scene, edited_name, shift) = match arg(&args, "--scene").unwrap_or("cornell") {
        "cornell" => (
            scenes::cornell(),
            "short_block".to_string(),
            Affine3A::from_translation(Vec3::new(0.0, 0.0, 0.1)),
        ),
        "sponza" => {
            // Sponza at `surfcache bake`'s defaults (the density budget fits the
            // lightmaps to 8 texels per metre), one round vase moved by 1 m.
            (
                sponza::sponza(&["vase_round"]),
                "vase_round_piece".to_string(),
                Affine3A::from_translation(Vec3::new(1.0, 0.0, 0.0)),
            )
        }
        other => panic!("unknown --scene {other} (cornell, sponza)"),
    };
    if arg(&args, "--sides") == Some("front") {
        settings.cache.set_both_sides(false);
    }
    if let Some(d) = arg(&args, "--density") {
        let density = settings
            .cache
            .density_mut()
            .expect("--density applies to --method irradiance-map and lightmap only");
        *density = d.parse().expect("--density D");
    }
    if let Some(b) = arg(&args, "--max-rel-error") {
        settings.estimator.max_rel_error = b.parse().expect("--max-rel-error B");
    }
    if let Some(n) = arg(&args, "--min-samples") {
        settings.estimator.min_samples = n.parse().expect("--min-samples N");
    }
    if let Some(n) = arg(&args, "--max-samples") {
        settings.estimator.max_samples = n.parse().expect("--max-samples N");
    }
    if let Some(g) = arg(&args, "--gather") {
        settings.gather_passes = g.parse().expect("--gather N");
    }
    let out = Path::new("out/incremental_edit");
    std::fs::create_dir_all(out).expect("create out/incremental_edit");

    // 1. The game's world: bake, then edit and let the plugin re-bake.
    let (mut world, mut schedule) = world_with(&before_scene, settings);
    let first = run_until_baked(&mut world, &mut schedule);
    let (scene, cache) = baked(&world);
    picture(&scene, &cache, &out.join("before.png"));
    println!(
        "{}: baked in {:.1} s; moving '{edited_name}' by {:.2} m",
        method.name(),
        first.seconds,
        shift.translation.length()
    );
    let mut blocks = world.query::<(&InstanceName, &mut WorldTransform)>();
    for (name, mut transform) in blocks.iter_mut(&mut world) {
        if name.0 == edited_name {
            transform.0 = shift * transform.0;
        }
    }
    let rebake = run_until_baked(&mut world, &mut schedule);
    assert!(
        rebake.incremental,
        "an edit of one block re-bakes incrementally"
    );
    let (edited, incremental) = baked(&world);
    picture(&edited, &incremental, &out.join("after.png"));
    println!(
        "re-baked incrementally in {:.1} s ({} entities' textures updated)",
        rebake.seconds,
        rebake.updated.len()
    );

    // 2. The edited scene from scratch, in a world of its own.
    let mut after_scene = before_scene.clone();
    for inst in &mut after_scene.instances {
        if inst.name == edited_name {
            inst.transform = shift * inst.transform;
        }
    }
    let (mut world2, mut schedule2) = world_with(&after_scene, settings);
    let full = run_until_baked(&mut world2, &mut schedule2);
    let (scratch_scene, scratch) = baked(&world2);
    assert_eq!(scratch_scene.positions(), edited.positions());
    picture(&scratch_scene, &scratch, &out.join("from_scratch.png"));
    let error = sponza::compare_caches(&edited, &incremental, &scratch, 2000, None);
    // The cache before the edit, looked up on the edited scene (same triangles).
    let stale = sponza::compare_caches(&edited, &cache, &scratch, 2000, None);
    println!(
        "from scratch: {:.1} s; incremental vs from scratch: rel_rms {:.4}, max {:.3} over {} points (the stale cache before the edit: rel_rms {:.4})",
        full.seconds, error.rel_rms, error.max_rel, error.points, stale.rel_rms
    );
    let near = sponza::neighbourhood(&edited, &edited_name);
    let near_error = sponza::compare_caches(&edited, &incremental, &scratch, 2000, Some(near));
    let near_stale = sponza::compare_caches(&edited, &cache, &scratch, 2000, Some(near));
    println!(
        "within {:.2} m of '{edited_name}' ({} points): incremental rel_rms {:.4} nrmse {:.4}, stale cache rel_rms {:.4} nrmse {:.4}",
        near.1,
        near_error.points,
        near_error.rel_rms,
        near_error.nrmse,
        near_stale.rel_rms,
        near_stale.nrmse
    );
    if args.iter().any(|a| a == "--noise-floor") {
        let mut other = settings;
        other.seed = 1;
        let (mut w, mut s) = world_with(&after_scene, other);
        run_until_baked(&mut w, &mut s);
        let other = baked(&w).1;
        let floor = sponza::compare_caches(&edited, &other, &scratch, 2000, None);
        let near_floor = sponza::compare_caches(&edited, &other, &scratch, 2000, Some(near));
        println!(
            "noise floor: two from-scratch bakes with seeds 0 and 1 differ by rel_rms {:.4} (near the edit: rel_rms {:.4} nrmse {:.4})",
            floor.rel_rms, near_floor.rel_rms, near_floor.nrmse
        );
    }
    println!(
        "full_s={:.2} incremental_s={:.2} ratio={:.3} rel_rms_vs_full={:.4}",
        full.seconds,
        rebake.seconds,
        rebake.seconds / full.seconds,
        error.rel_rms
    );
}
