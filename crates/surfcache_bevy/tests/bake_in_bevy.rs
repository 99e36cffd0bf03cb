//! The plugin in a Bevy app without a renderer: an ordinary Bevy scene is read, baked in
//! the background and published as `Lightmap`s on UV1 meshes with texels of E/π; a moved
//! mesh re-bakes incrementally into the same images; lights are baked or left to real
//! time as each one chooses.

use bevy::{
    asset::AssetPlugin, ecs::message::Messages, ecs::system::RunSystemOnce, pbr::Lightmap,
    prelude::*,
};
use half::f16;
use std::time::{Duration, Instant};
use surfcache_bevy::{
    BakeConfig, BakeFinished, LightBaking, LightmappedMesh, SceneSpawner, SurfcacheBevyPlugin,
    mesh::has_uv1,
};
use surfcache_cache::{CacheSettings, LightmapSettings, bake::BakeSettings};
use surfcache_core::{Environment, Instance, Material, Scene, scenes};
use surfcache_ecs::{BakedLightmap, PunctualLight};
use surfcache_trace::EstimatorSettings;

/// A coarse, quick bake: 12 texels per metre, a 3 % bound, full paths.
fn config() -> BakeConfig {
    let cache = CacheSettings::Lightmap(LightmapSettings {
        texels_per_metre: 12.0,
        both_sides: false,
        ..Default::default()
    });
    BakeConfig {
        settings: BakeSettings {
            cache,
            estimator: EstimatorSettings {
                max_rel_error: 0.03,
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
    }
}

/// A Bevy app with assets, transforms and the plugin, but no window or renderer.
fn app() -> App {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, AssetPlugin::default(), TransformPlugin))
        .init_asset::<Mesh>()
        .init_asset::<StandardMaterial>()
        .init_asset::<Image>()
        .add_plugins(SurfcacheBevyPlugin { config: config() });
    app
}

fn spawn(app: &mut App, scene: Scene) -> Vec<Entity> {
    app.world_mut()
        .run_system_once(move |mut spawner: SceneSpawner| spawner.spawn(&scene))
        .unwrap()
}

/// Runs frames until a bake newer than scene generation `after` is published (and one
/// more frame, which gives Bevy its lightmaps). Messages can stay for several frames (an
/// app advances them with its fixed-time steps), hence the generation.
fn until_baked(app: &mut App, after: u64) -> BakeFinished {
    let start = Instant::now();
    loop {
        app.update();
        let done = app
            .world()
            .resource::<Messages<BakeFinished>>()
            .iter_current_update_messages()
            .filter(|m| m.generation > after)
            .last()
            .cloned();
        if let Some(done) = done {
            app.update();
            return done;
        }
        let status = app.world().resource::<surfcache_ecs::BakeStatus>();
        assert!(status.error.is_none(), "{:?}", status.error);
        assert!(
            start.elapsed() < Duration::from_secs(600),
            "no bake within 10 minutes"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// The RGB of texel `k` of an `Rgba16Float` image.
fn texel(image: &Image, k: usize) -> [f32; 3] {
    let data = image.data.as_ref().unwrap();
    std::array::from_fn(|c| {
        let at = 8 * k + 2 * c;
        f16::from_le_bytes([data[at], data[at + 1]]).to_f32()
    })
}

/// A bilinear, clamp-to-edge lookup of an `Rgba16Float` image at `uv`, as Bevy's
/// lightmap sampler does.
fn bilinear(image: &Image, uv: glam::Vec2) -> glam::Vec3 {
    let (w, h) = (image.width(), image.height());
    let texels: Vec<glam::Vec3> = (0..(w * h) as usize)
        .map(|k| glam::Vec3::from_array(texel(image, k)))
        .collect();
    surfcache_cache::texture::bilinear(&texels, w, h, uv)
}

#[test]
fn a_bevy_scene_bakes_into_lightmaps_and_rebakes_a_moved_mesh_in_place() {
    let mut app = app();
    let entities = spawn(&mut app, scenes::cornell());
    let first = until_baked(&mut app, 0);
    assert!(!first.incremental);
    let world = app.world_mut();
    let mut images_before = Vec::new();
    for &entity in &entities {
        let e = world.entity(entity);
        let state = e
            .get::<LightmappedMesh>()
            .expect("every mesh is lightmapped");
        let lightmap = e.get::<Lightmap>().expect("and has a Lightmap");
        assert_eq!(lightmap.image, state.image);
        let texture = e.get::<BakedLightmap>().unwrap().front.clone().unwrap();
        // The drawn mesh carries the bake's layout in UV1 (the built-in meshes have none
        // of their own, so it is the plugin's copy).
        let drawn = &e.get::<Mesh3d>().unwrap().0;
        assert_eq!(Some(drawn), state.uv1_mesh.as_ref());
        assert!(has_uv1(
            world.resource::<Assets<Mesh>>().get(drawn).unwrap(),
            &texture.uv1
        ));
        // Texels are E/π.
        let image = world.resource::<Assets<Image>>().get(&state.image).unwrap();
        assert_eq!(
            (image.width(), image.height()),
            (texture.width, texture.height)
        );
        for (k, e) in texture.texels.iter().enumerate() {
            let got = texel(image, k);
            for c in 0..3 {
                let want = e[c] / std::f32::consts::PI;
                assert!(
                    (got[c] - want).abs() <= 1e-3 * want + 1e-6,
                    "{k}: {got:?} {e}"
                );
            }
        }
        images_before.push((state.image.clone(), image.data.clone()));
    }

    // Move the short block 10 cm: an incremental re-bake, published into the same images.
    let block = entities[6];
    let name = world.entity(block).get::<Name>().unwrap().to_string();
    assert_eq!(name, "short_block");
    world
        .entity_mut(block)
        .get_mut::<Transform>()
        .unwrap()
        .translation
        .x += 0.1;
    let second = until_baked(&mut app, first.generation);
    assert!(second.incremental, "{second:?}");
    assert!(second.updated.contains(&block));
    let world = app.world();
    for (&entity, (handle, data)) in entities.iter().zip(&images_before) {
        let state = world.entity(entity).get::<LightmappedMesh>().unwrap();
        assert_eq!(&state.image, handle, "updated in place");
        let image = world.resource::<Assets<Image>>().get(handle).unwrap();
        if second.updated.contains(&entity) {
            assert_ne!(&image.data, data);
        }
    }
    // The floor sees the block move.
    assert!(second.updated.contains(&entities[0]));
}

/// A lone floor under a uniform sky of radiance L receives E = πL, so its lightmap texels
/// are L: Bevy's shader then gives it the radiance ρL a Lambertian floor has.
#[test]
fn a_floor_under_a_uniform_sky_has_texels_of_the_sky_radiance() {
    let radiance = glam::Vec3::new(0.5, 1.0, 2.0);
    let mut scene = Scene {
        name: "floor".into(),
        environment: Environment::uniform(radiance),
        ..Default::default()
    };
    scene.instances.push(Instance::new(
        scenes::square("floor", 1.0, 0.0, glam::Vec3::Y),
        Material::diffuse("grey", glam::Vec3::splat(0.5)),
    ));
    let mut app = app();
    let floor = spawn(&mut app, scene)[0];
    until_baked(&mut app, 0);
    let world = app.world();
    let state = world.entity(floor).get::<LightmappedMesh>().unwrap();
    let image = world.resource::<Assets<Image>>().get(&state.image).unwrap();
    let texture = world
        .get::<BakedLightmap>(floor)
        .unwrap()
        .front
        .clone()
        .unwrap();
    // What Bevy's sampler reads at points of each triangle (centroid and towards each
    // corner), through the UV1 the drawn mesh carries.
    let mut sum = glam::Vec3::ZERO;
    let mut count = 0.0;
    for [a, b, c] in &texture.uv1 {
        let centroid = (*a + *b + *c) / 3.0;
        for uv in [
            centroid,
            centroid.lerp(*a, 0.8),
            centroid.lerp(*b, 0.8),
            centroid.lerp(*c, 0.8),
        ] {
            let got = bilinear(image, uv);
            let error = ((got - radiance) / radiance).abs().max_element();
            assert!(error < 0.1, "at {uv}: {got} against {radiance}");
            sum += got;
            count += 1.0;
        }
    }
    let mean = sum / count;
    assert!(
        ((mean - radiance) / radiance).abs().max_element() < 0.03,
        "{mean}"
    );
}

#[test]
fn each_light_is_either_baked_or_real_time_never_both() {
    let mut app = app();
    let baked = app
        .world_mut()
        .spawn((DirectionalLight::default(), Transform::default()))
        .id();
    let realtime = app
        .world_mut()
        .spawn((
            PointLight::default(),
            Transform::from_xyz(0.0, 2.0, 0.0),
            LightBaking::Realtime,
        ))
        .id();
    app.update();
    app.update();
    let world = app.world();
    let b = world.entity(baked);
    assert!(b.get::<PunctualLight>().is_some());
    assert!(
        !b.get::<DirectionalLight>()
            .unwrap()
            .affects_lightmapped_mesh_diffuse
    );
    let r = world.entity(realtime);
    assert!(r.get::<PunctualLight>().is_none());
    assert!(
        r.get::<PointLight>()
            .unwrap()
            .affects_lightmapped_mesh_diffuse
    );
    // Switching the point light to baked mirrors it (at lumens / 4π candela).
    app.world_mut()
        .entity_mut(realtime)
        .insert(LightBaking::Baked);
    app.update();
    let r = app.world().entity(realtime);
    let Some(PunctualLight(surfcache_core::Light::Point {
        intensity,
        position,
    })) = r.get::<PunctualLight>().copied()
    else {
        panic!("the point light is not baked");
    };
    assert!((position - glam::Vec3::new(0.0, 2.0, 0.0)).length() < 1e-6);
    let lumens = PointLight::default().intensity;
    assert!((intensity.x - lumens / (4.0 * std::f32::consts::PI)).abs() < 1e-3);
    assert!(
        !r.get::<PointLight>()
            .unwrap()
            .affects_lightmapped_mesh_diffuse
    );
}
