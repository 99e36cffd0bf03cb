//! The surfcache ECS plugin: scene components, resources and systems for `bevy_ecs`.
//!
//! The scene *is* the ECS world: every mesh instance is an entity with [`MeshGeometry`],
//! [`SurfaceMaterial`] and [`WorldTransform`]; punctual lights carry [`PunctualLight`];
//! the sky is an entity with [`EnvironmentLight`]. [`SurfcachePlugin::build`] registers the
//! systems in ordered [`SurfcacheSet`]s: scene sync → BVH → (invalidation → bake step →
//! publish, as the caches land). Systems are thin: they move data between components and
//! the ECS-free math in `surfcache_core` and `surfcache_trace`.
//!
//! ```
//! use bevy_ecs::prelude::*;
//! use surfcache_core::scenes;
//! use surfcache_ecs::{SurfcachePlugin, TracedSceneResource, spawn_scene};
//!
//! let mut world = World::new();
//! let mut schedule = Schedule::default();
//! SurfcachePlugin.build(&mut world, &mut schedule);
//! spawn_scene(&mut world, &scenes::cornell());
//! schedule.run(&mut world);
//! let traced = world.resource::<TracedSceneResource>();
//! assert_eq!(traced.scene().unwrap().triangle_count(), 38);
//! ```

pub mod components;
pub mod plugin;
pub mod systems;

pub use components::{
    EnvironmentLight, MeshGeometry, PunctualLight, SurfaceMaterial, WorldTransform,
};
pub use plugin::{SurfcachePlugin, SurfcacheSet, spawn_scene};
pub use systems::TracedSceneResource;
