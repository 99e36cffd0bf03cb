//! Registration of the systems, and spawning a plain [`Scene`] into a world.

use crate::{components::*, systems::*};
use bevy_ecs::prelude::*;
use surfcache_core::Scene;

/// Ordered stages of one surfcache update.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SurfcacheSet {
    /// Change detection on scene components.
    SceneSync,
    /// BVH build or refit.
    Bvh,
    /// Deciding which cache samples are stale.
    Invalidate,
    /// Estimating samples within the frame budget.
    Bake,
    /// Publishing irradiance textures as resources.
    Publish,
}

/// Registers surfcache's resources and systems.
pub struct SurfcachePlugin;

impl SurfcachePlugin {
    /// Adds the resources to `world` and the systems to `schedule`, in [`SurfcacheSet`] order.
    pub fn build(&self, world: &mut World, schedule: &mut Schedule) {
        world.init_resource::<TracedSceneResource>();
        schedule.configure_sets(
            (
                SurfcacheSet::SceneSync,
                SurfcacheSet::Bvh,
                SurfcacheSet::Invalidate,
                SurfcacheSet::Bake,
                SurfcacheSet::Publish,
            )
                .chain(),
        );
        schedule.add_systems((
            detect_scene_changes.in_set(SurfcacheSet::SceneSync),
            build_traced_scene.in_set(SurfcacheSet::Bvh),
        ));
    }
}

/// Spawns every instance, light and the environment of `scene` as entities; returns the
/// instance entities in scene order.
pub fn spawn_scene(world: &mut World, scene: &Scene) -> Vec<Entity> {
    let entities = scene
        .instances
        .iter()
        .map(|inst| {
            world
                .spawn((
                    MeshGeometry(inst.mesh.clone()),
                    SurfaceMaterial(inst.material.clone()),
                    WorldTransform(inst.transform),
                    InstanceName(inst.name.clone()),
                ))
                .id()
        })
        .collect();
    for light in &scene.lights {
        world.spawn(PunctualLight(*light));
    }
    world.spawn(EnvironmentLight(scene.environment.clone()));
    entities
}
