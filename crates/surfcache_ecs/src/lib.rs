//! The surfcache ECS plugin: scene components, resources and systems for `bevy_ecs`.
//!
//! The scene *is* the ECS world: every mesh instance is an entity with [`MeshGeometry`],
//! [`SurfaceMaterial`] and [`WorldTransform`]; punctual lights carry [`PunctualLight`];
//! the sky is an entity with [`EnvironmentLight`]. [`SurfcachePlugin::build`] registers the
//! systems in the ordered sets of [`SurfcacheSystems`]: scene sync → BVH build →
//! invalidation → bake step → publish. The BVH build and the bake run in the background;
//! the finished surface cache lands in [`BakedSurfaceCache`], each mesh entity's textures
//! in its [`BakedLightmap`] component, and a [`BakeFinished`] message says so. Edits re-bake
//! incrementally ([`baking`] documents the policy). Systems are thin: they move data
//! between components, resources and the ECS-free math of the other crates.
//!
//! What each module owns:
//! - [`components`]: the scene components.
//! - [`scene_sync`]: change detection ([`SceneChanges`]) and the plain-scene snapshot.
//! - [`bvh`]: the BVH worker ([`BvhBuilds`]) and the current traced scene
//!   ([`TracedSceneState`]).
//! - [`baking`]: bake settings ([`BakeConfig`]), progress ([`BakeStatus`]), the baseline
//!   and the bake in flight ([`Baking`]), and the finished cache ([`BakedSurfaceCache`]).
//! - [`publish`]: the textures on each entity ([`BakedLightmap`]) and the
//!   [`BakeFinished`] message.
//! - [`plugin`]: registration ([`SurfcachePlugin`], [`SurfcacheSystems`]).
//!
//! ```
//! use bevy_ecs::prelude::*;
//! use surfcache_core::scenes;
//! use surfcache_ecs::{BakeConfig, BakedLightmap, SurfcachePlugin, spawn_scene};
//!
//! let mut world = World::new();
//! let mut schedule = Schedule::default();
//! // A quick, coarse bake for the example.
//! let mut config = BakeConfig::default();
//! config.settings.estimator.max_rel_error = 0.2;
//! // Lightmaps (the default method) at 4 texels per metre.
//! if let Some(density) = config.settings.cache.density_mut() {
//!     *density = 4.0;
//! }
//! config.settings.gather_passes = 0;
//! SurfcachePlugin::with_config(config).build(&mut world, &mut schedule);
//! let entities = spawn_scene(&mut world, &scenes::cornell());
//! // A game runs `SurfcachePlugin::update` once per frame while the bake runs in the
//! // background; this runs frames until the first bake is published.
//! let pause = std::time::Duration::from_millis(5);
//! let baked = SurfcachePlugin::run_until_baked(&mut world, &mut schedule, pause, |_| true)
//!     .unwrap();
//! assert!(!baked.incremental);
//! let floor = world.get::<BakedLightmap>(entities[0]).unwrap();
//! assert!(floor.front.as_ref().unwrap().texels.iter().all(|e| e.is_finite()));
//! ```

pub mod baking;
pub mod bvh;
pub mod components;
pub mod plugin;
pub mod publish;
pub mod scene_sync;

pub use baking::{BakeConfig, BakeMode, BakeStatus, BakedSurfaceCache, Baking, TimeLeft};
pub use bvh::{BvhBuilds, TracedSceneState};
pub use components::{
    EnvironmentLight, InstanceName, MeshGeometry, PunctualLight, SurfaceMaterial, WorldTransform,
};
pub use plugin::{BakeWaitError, SurfcachePlugin, SurfcacheSystems, spawn_scene};
pub use publish::{BakeFinished, BakedLightmap};
pub use scene_sync::SceneChanges;
