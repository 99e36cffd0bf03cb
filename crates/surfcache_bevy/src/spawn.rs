//! A plain surfcache [`Scene`] (a built-in one, say) spawned as an ordinary Bevy scene:
//! meshes with `Mesh3d` and `MeshMaterial3d<StandardMaterial>`, Bevy lights, and its sky
//! as the image of [`BakeEnvironment`]. The plugin then reads it back as it reads any Bevy
//! scene.

use crate::{
    environment::{BakeEnvironment, environment_image},
    glam_bridge,
    light::{BevyLight, bevy_light},
    material::standard_material,
    mesh::bevy_mesh,
};
use bevy::{ecs::system::SystemParam, prelude::*};
use surfcache_core::Scene;

/// What spawning a plain scene needs, as one system parameter:
/// `|mut spawner: SceneSpawner| { spawner.spawn(&scenes::cornell()); }` is a system.
#[derive(SystemParam)]
pub struct SceneSpawner<'w, 's> {
    pub commands: Commands<'w, 's>,
    pub meshes: ResMut<'w, Assets<Mesh>>,
    pub materials: ResMut<'w, Assets<StandardMaterial>>,
    pub images: ResMut<'w, Assets<Image>>,
}

impl SceneSpawner<'_, '_> {
    /// Spawns `scene` ([`spawn_scene`]).
    pub fn spawn(&mut self, scene: &Scene) -> Vec<Entity> {
        spawn_scene(
            &mut self.commands,
            &mut self.meshes,
            &mut self.materials,
            &mut self.images,
            scene,
        )
    }
}

/// Spawns `scene`'s instances (named after them), lights and environment into a Bevy
/// world; returns the instance entities in scene order. Lights are spawned without
/// shadow maps: their direct light is baked.
pub fn spawn_scene(
    commands: &mut Commands,
    meshes: &mut Assets<Mesh>,
    materials: &mut Assets<StandardMaterial>,
    images: &mut Assets<Image>,
    scene: &Scene,
) -> Vec<Entity> {
    let entities = scene
        .instances
        .iter()
        .map(|instance| {
            commands
                .spawn((
                    Mesh3d(meshes.add(bevy_mesh(&instance.mesh))),
                    MeshMaterial3d(materials.add(standard_material(&instance.material))),
                    Transform::from_matrix(Mat4::from(glam_bridge::bevy_affine3a(
                        instance.transform,
                    ))),
                    Name::new(instance.name.clone()),
                ))
                .id()
        })
        .collect();
    for light in &scene.lights {
        let (light, transform) = bevy_light(light);
        match light {
            BevyLight::Directional(l) => commands.spawn((l, transform)),
            BevyLight::Point(l) => commands.spawn((l, transform)),
            BevyLight::Spot(l) => commands.spawn((l, transform)),
        };
    }
    let environment = &scene.environment;
    let map = match &environment.map {
        Some(map) => Some((**map).clone()),
        None if environment.color != glam::Vec3::ZERO => Some(
            surfcache_core::EnvironmentMap::constant(4, 2, environment.color),
        ),
        None => None,
    };
    commands.insert_resource(BakeEnvironment {
        image: map.map(|m| images.add(environment_image(&m))),
        intensity: environment.intensity,
    });
    entities
}
