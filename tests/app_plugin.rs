//! surfcache as a `bevy_app` Plugin (cargo feature `app` of surfcache_ecs): added to an
//! `App`, it bakes a spawned scene in the background while `App::update` runs frames,
//! sends `BakeFinished` and publishes textures that match the closed form.

use bevy_app::App;
use bevy_ecs::message::Messages;
use glam::Vec3;
use std::{
    f32::consts::PI,
    time::{Duration, Instant},
};
use surfcache::{
    cache::{CacheSettings, LightmapSettings, bake::BakeSettings},
    core::{Environment, Material, Scene, scenes::square},
    ecs::{BakeConfig, BakeFinished, BakedLightmap, SurfcachePlugin, spawn_scene},
    trace::EstimatorSettings,
};

/// A 2 m floor alone under a uniform sky of radiance L: E = πL everywhere on its front.
#[test]
fn app_plugin_bakes_a_floor_under_a_uniform_sky() {
    let radiance = Vec3::new(0.5, 1.0, 2.0);
    let floor = square("floor", 1.0, 0.0, Vec3::Y);
    let mut scene = Scene {
        name: "floor".into(),
        environment: Environment::uniform(radiance),
        ..Default::default()
    };
    scene.instances.push(surfcache::core::Instance::new(
        floor,
        Material::diffuse("grey", Vec3::splat(0.5)),
    ));
    let cache = CacheSettings::Lightmap(LightmapSettings {
        texels_per_metre: 8.0,
        ..Default::default()
    });
    let config = BakeConfig {
        settings: BakeSettings {
            cache,
            estimator: EstimatorSettings {
                max_rel_error: 0.02,
                min_samples: 64,
                max_samples: 4096,
                ..Default::default()
            },
            seed: 3,
            gather_passes: 0,
            density_budget: None,
        },
        threads: Some(2),
        ..Default::default()
    };

    let mut app = App::new();
    app.add_plugins(SurfcachePlugin::with_config(config));
    let entities = spawn_scene(app.world_mut(), &scene);
    let start = Instant::now();
    let finished = loop {
        app.update();
        let messages = app.world().resource::<Messages<BakeFinished>>();
        if let Some(done) = messages.iter_current_update_messages().last() {
            break done.clone();
        }
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no bake within 2 min"
        );
        std::thread::sleep(Duration::from_millis(2));
    };
    assert!(!finished.incremental);

    let floor = app.world().get::<BakedLightmap>(entities[0]).unwrap();
    let front = floor.front.as_ref().expect("the floor's front texture");
    let expected = PI * radiance;
    let mut lit = 0;
    for texel in &front.texels {
        if *texel == Vec3::ZERO {
            continue; // gutter
        }
        lit += 1;
        let rel = ((*texel - expected) / expected).abs().max_element();
        assert!(rel < 0.06, "texel {texel} vs πL = {expected}");
    }
    assert!(lit > 100, "only {lit} texels baked");
}
