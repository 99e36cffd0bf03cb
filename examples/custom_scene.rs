//! A scene built by code: spawn primitives, materials, a light and an environment as ECS
//! entities, let the plugin bake them, and read the published irradiance textures.
//!
//! The scene is a grey floor with a white box on it, lit by a uniform blue-white sky and
//! a low directional "sun". After the bake the example prints, for each entity, its
//! texture size and UV rectangle, and checks one closed form: a floor texel far from the
//! box receives E = π·L_sky + E_sun·cos θ (plus the little light the box reflects).
//!
//! ```text
//! cargo run --release --example custom_scene
//! ```

use bevy_ecs::prelude::*;
use std::{f32::consts::PI, sync::Arc, time::Duration};
use surfcache::{
    cache::{CacheSettings, LightmapSettings, bake::BakeSettings},
    core::{
        Environment, Light, Material,
        glam::{Affine3A, Vec3},
        scenes::{cuboid, quad},
    },
    ecs::{
        BakeConfig, BakedLightmap, EnvironmentLight, InstanceName, MeshGeometry, PunctualLight,
        SurfaceMaterial, SurfcachePlugin, WorldTransform,
    },
};

fn main() {
    let mut world = World::new();
    let mut schedule = Schedule::default();
    // Texel lightmaps at 16 texels per metre; everything else at its defaults.
    let cache = CacheSettings::Lightmap(LightmapSettings {
        texels_per_metre: 16.0,
        ..Default::default()
    });
    SurfcachePlugin::with_config(BakeConfig {
        settings: BakeSettings {
            cache,
            ..Default::default()
        },
        ..Default::default()
    })
    .build(&mut world, &mut schedule);

    // Primitives: meshes in object space, shared through Arc; materials likewise.
    let floor_mesh = Arc::new(quad(
        "floor",
        [
            Vec3::new(-2.0, 0.0, -2.0),
            Vec3::new(2.0, 0.0, -2.0),
            Vec3::new(2.0, 0.0, 2.0),
            Vec3::new(-2.0, 0.0, 2.0),
        ],
        Vec3::Y,
    ));
    let box_mesh = Arc::new(cuboid(
        "box",
        Vec3::new(-0.25, 0.0, -0.25),
        Vec3::new(0.25, 0.5, 0.25),
        false,
    ));
    let grey = Arc::new(Material::diffuse("grey", Vec3::splat(0.5)));
    let white = Arc::new(Material::diffuse("white", Vec3::splat(0.8)));
    let floor = world
        .spawn((
            MeshGeometry(floor_mesh),
            SurfaceMaterial(grey),
            WorldTransform(Affine3A::IDENTITY),
            InstanceName("floor".into()),
        ))
        .id();
    let block = world
        .spawn((
            MeshGeometry(box_mesh),
            SurfaceMaterial(white),
            WorldTransform(Affine3A::from_rotation_y(0.4)),
            InstanceName("box".into()),
        ))
        .id();
    // Lights: a sky of radiance L and a sun 30° above the horizon.
    let sky = Vec3::new(0.3, 0.4, 0.6);
    let sun_direction = Vec3::new(1.0, -0.5, 0.3).normalize();
    let sun = Vec3::splat(3.0);
    world.spawn(EnvironmentLight(Environment::uniform(sky)));
    world.spawn(PunctualLight(Light::Directional {
        direction: sun_direction,
        irradiance: sun,
    }));

    let done = SurfcachePlugin::run_until_baked(
        &mut world,
        &mut schedule,
        Duration::from_millis(16),
        |_| true,
    )
    .expect("the bake finishes");
    println!("baked in {:.2} s", done.seconds);

    // Every baked mesh entity now carries its textures as a `BakedLightmap` component.
    let lightmap = |entity: Entity| world.get::<BakedLightmap>(entity).expect("baked");
    for (name, entity) in [("floor", floor), ("box", block)] {
        let front = lightmap(entity).front.as_ref().expect("front side");
        println!(
            "{name}: {}x{} texels, UV rectangle {:?}, {} triangles addressed by UV1",
            front.width,
            front.height,
            front.uv_rect,
            front.uv1.len()
        );
    }
    // A floor corner is 1.75 m from the box: only the sky and the sun light it.
    let floor_texture = lightmap(floor).front.as_ref().unwrap();
    let corner = floor_texture.texels[floor_texture.width as usize + 1];
    let expected = PI * sky + sun * (-sun_direction).dot(Vec3::Y);
    println!("floor corner: E = {corner:.3}, closed form π·L + E_sun·cos θ = {expected:.3}");
    let rel = ((corner - expected) / expected).abs().max_element();
    assert!(rel < 0.05, "floor corner off by {:.1} %", 100.0 * rel);
}
