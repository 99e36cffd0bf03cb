//! Registration: [`SurfcacheBevyPlugin`] and its system sets around surfcache's own.

use crate::{
    environment::BakeEnvironment,
    lightmap::apply_lightmaps,
    scene_sync::{ConvertedAssets, sync_environment, sync_instances, sync_lights},
};
use bevy::prelude::*;
use surfcache_ecs::{BakeConfig, SurfcachePlugin, SurfcacheSystems};

/// The two stages this crate adds to surfcache's schedule in `Update`.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SurfcacheBevySystems {
    /// Bevy's meshes, materials, lights and environment into surfcache's components
    /// (before [`SurfcacheSystems::SceneSync`]).
    ReadScene,
    /// Published textures into Bevy images, `Lightmap`s and UV1 meshes (after
    /// [`SurfcacheSystems::Publish`]).
    ApplyLightmaps,
}

/// Makes an ordinary Bevy scene bake itself: adds surfcache's ECS plugin
/// ([`SurfcachePlugin`], background bakes with [`surfcache_ecs::BakeStatus`] as progress)
/// and keeps it fed from the Bevy scene and its results in Bevy's lightmaps (crate docs).
#[derive(Clone, Debug)]
pub struct SurfcacheBevyPlugin {
    /// Bake settings. The default bakes front faces only (a Bevy mesh shows one lightmap,
    /// on both faces), otherwise `surfcache bake`'s defaults.
    pub config: BakeConfig,
}

impl Default for SurfcacheBevyPlugin {
    fn default() -> Self {
        let mut config = BakeConfig::default();
        config.settings.cache.set_both_sides(false);
        Self { config }
    }
}

impl Plugin for SurfcacheBevyPlugin {
    fn build(&self, app: &mut App) {
        app.add_plugins(SurfcachePlugin::with_config(self.config.clone()))
            .init_resource::<ConvertedAssets>()
            .init_resource::<BakeEnvironment>()
            .configure_sets(
                Update,
                (
                    SurfcacheBevySystems::ReadScene.before(SurfcacheSystems::SceneSync),
                    SurfcacheBevySystems::ApplyLightmaps.after(SurfcacheSystems::Publish),
                ),
            )
            .add_systems(
                Update,
                (
                    (sync_instances, sync_lights, sync_environment)
                        .in_set(SurfcacheBevySystems::ReadScene),
                    apply_lightmaps.in_set(SurfcacheBevySystems::ApplyLightmaps),
                ),
            );
    }
}
