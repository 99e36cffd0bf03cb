//! Registration of the resources and systems, and spawning a plain [`Scene`] into a world.

use crate::{baking::*, bvh::*, components::*, publish::*, scene_sync::*};
use bevy_ecs::{
    message::{MessageRegistry, Messages, message_update_system},
    prelude::*,
};
use surfcache_core::Scene;

/// Ordered stages of one surfcache update.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SurfcacheSystems {
    /// Change detection on scene components; starting background BVH builds.
    SceneSync,
    /// Installing finished BVH builds.
    Bvh,
    /// Deciding what a new scene invalidates; starting (or superseding) a bake.
    Invalidate,
    /// Advancing the bake and its progress.
    Bake,
    /// Publishing finished irradiance textures as resources.
    Publish,
}

/// Registers surfcache's resources, its [`BakeFinished`] message and its systems.
///
/// With a plain `bevy_ecs` [`Schedule`] (no `bevy_app`), run frames with
/// [`SurfcachePlugin::update`], which also advances messages and clears removal
/// trackers as an app would. With the cargo feature `app` it is also a `bevy_app`
/// `Plugin` whose systems run in `Update`:
///
/// ```ignore
/// App::new().add_plugins(SurfcachePlugin::default()).run();
/// ```
#[derive(Clone, Debug, Default)]
pub struct SurfcachePlugin {
    /// Bake settings; `None` keeps a [`BakeConfig`] already in the world, or the default.
    pub config: Option<BakeConfig>,
}

impl SurfcachePlugin {
    /// A plugin with these bake settings.
    pub fn with_config(config: BakeConfig) -> Self {
        Self {
            config: Some(config),
        }
    }

    /// Adds the resources to `world` and the systems to `schedule`, in [`SurfcacheSystems`] order.
    pub fn build(&self, world: &mut World, schedule: &mut Schedule) {
        self.insert_resources(world);
        MessageRegistry::register_message::<BakeFinished>(world);
        schedule.add_systems(message_update_system.before(SurfcacheSystems::SceneSync));
        Self::add_systems(schedule);
    }

    /// The resources, with this plugin's [`BakeConfig`].
    fn insert_resources(&self, world: &mut World) {
        match &self.config {
            Some(c) => world.insert_resource(c.clone()),
            None => {
                world.init_resource::<BakeConfig>();
            }
        }
        world.init_resource::<SceneChanges>();
        world.init_resource::<BvhBuilds>();
        world.init_resource::<TracedSceneState>();
        world.init_resource::<Baking>();
        world.init_resource::<BakeStatus>();
        world.init_resource::<PendingPublish>();
        world.init_resource::<BakedSurfaceCache>();
    }

    /// The systems, in [`SurfcacheSystems`] order (messages are advanced by the caller).
    fn add_systems(schedule: &mut Schedule) {
        schedule.configure_sets(
            (
                SurfcacheSystems::SceneSync,
                SurfcacheSystems::Bvh,
                SurfcacheSystems::Invalidate,
                SurfcacheSystems::Bake,
                SurfcacheSystems::Publish,
            )
                .chain(),
        );
        schedule.add_systems((
            (detect_scene_changes, start_bvh_build)
                .chain()
                .in_set(SurfcacheSystems::SceneSync),
            finish_bvh_build.in_set(SurfcacheSystems::Bvh),
            start_bake.in_set(SurfcacheSystems::Invalidate),
            step_bake.in_set(SurfcacheSystems::Bake),
            publish.in_set(SurfcacheSystems::Publish),
        ));
    }

    /// Runs one frame: the schedule, then clears change trackers (as `bevy_app` does).
    pub fn update(world: &mut World, schedule: &mut Schedule) {
        schedule.run(world);
        world.clear_trackers();
    }

    /// Runs frames, `pause` apart (a game's frame loop), until a bake is published, and
    /// returns its [`BakeFinished`]. After each frame `on_frame` sees the world; returning
    /// false cancels the bake in flight and stops with [`BakeWaitError::Stopped`].
    pub fn run_until_baked(
        world: &mut World,
        schedule: &mut Schedule,
        pause: std::time::Duration,
        mut on_frame: impl FnMut(&World) -> bool,
    ) -> Result<BakeFinished, BakeWaitError> {
        loop {
            Self::update(world, schedule);
            if let Some(done) = world
                .resource::<Messages<BakeFinished>>()
                .iter_current_update_messages()
                .last()
            {
                return Ok(done.clone());
            }
            if let Some(e) = &world.resource::<BakeStatus>().error {
                return Err(BakeWaitError::Failed(e.clone()));
            }
            if let Some(e) = &world.resource::<TracedSceneState>().error {
                return Err(BakeWaitError::Failed(e.clone()));
            }
            if !on_frame(world) {
                world.resource_mut::<Baking>().cancel();
                return Err(BakeWaitError::Stopped);
            }
            std::thread::sleep(pause);
        }
    }
}

/// Why [`SurfcachePlugin::run_until_baked`] returned without a bake.
#[derive(Debug, Clone, PartialEq)]
pub enum BakeWaitError {
    /// The scene could not be built or baked.
    Failed(String),
    /// `on_frame` asked to stop.
    Stopped,
}

impl std::fmt::Display for BakeWaitError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Failed(e) => f.write_str(e),
            Self::Stopped => f.write_str("stopped before the bake finished"),
        }
    }
}

impl std::error::Error for BakeWaitError {}

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

/// With `bevy_app`: the resources, the [`BakeFinished`] message (advanced by the app) and
/// the systems in the app's `Update` schedule.
#[cfg(feature = "app")]
impl bevy_app::Plugin for SurfcachePlugin {
    fn build(&self, app: &mut bevy_app::App) {
        self.insert_resources(app.world_mut());
        app.add_message::<BakeFinished>();
        app.edit_schedule(bevy_app::Update, Self::add_systems);
    }
}
