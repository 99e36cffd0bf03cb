//! surfcache inside a Bevy 0.19 game: an ordinary Bevy scene bakes itself, and the baked
//! irradiance comes back as Bevy [`Lightmap`](bevy::pbr::Lightmap)s.
//!
//! Bevy 0.19 is the newest release that builds with Rust 1.95 (0.20 needs 1.97); the
//! whole workspace uses its `bevy_ecs`, since a plugin on another `bevy_ecs` could not be
//! added to a Bevy app.
//!
//! Data flows in one loop, every frame, none of it waiting for a bake:
//!
//! ```text
//! Bevy scene (Mesh3d + MeshMaterial3d<StandardMaterial> + GlobalTransform, lights,
//!             BakeEnvironment's HDR image)
//!   │ scene_sync: change detection, converted once per asset
//!   ▼
//! surfcache_ecs components ─► BVH build ─► (incremental) bake in the background
//!   │                                      (BakeStatus: progress)
//!   ▼ BakedLightmap (a component on each baked mesh entity)
//! lightmap: Image (E/π, Rgba16Float, updated in place) + Lightmap + ATTRIBUTE_UV_1 mesh
//! ```
//!
//! What each module owns:
//! - [`scene_sync`]: the systems that mirror the Bevy scene into surfcache's components.
//! - [`mesh`], [`material`], [`light`], [`environment`]: reading Bevy meshes, standard
//!   materials, lights (and each light's [`LightBaking`]) and the environment image.
//! - [`lightmap`]: the published textures as Bevy images and lightmaps, and their units
//!   ([`LIGHTMAP_SCALE`]).
//! - [`spawn`]: a plain surfcache scene (a built-in one) spawned as a Bevy scene.
//! - [`view`]: a Bevy camera exposure that matches `surfcache render --exposure`.
//! - [`plugin`]: [`SurfcacheBevyPlugin`] and its [`SurfcacheBevySystems`].
//!
//! ```no_run
//! use bevy::prelude::*;
//! use surfcache_bevy::SurfcacheBevyPlugin;
//!
//! App::new()
//!     .add_plugins((DefaultPlugins, SurfcacheBevyPlugin::default()))
//!     .add_systems(Startup, |mut commands: Commands, assets: Res<AssetServer>| {
//!         // Loaded with Bevy's glTF loader: baked, once loaded, with no more code.
//!         commands.spawn(WorldAssetRoot(
//!             assets.load(GltfAssetLabel::Scene(0).from_asset("level.glb")),
//!         ));
//!     })
//!     .run();
//! ```

pub mod environment;
mod glam_bridge;
pub mod light;
pub mod lightmap;
pub mod material;
pub mod mesh;
pub mod plugin;
pub mod scene_sync;
pub mod spawn;
pub mod view;

pub use environment::BakeEnvironment;
pub use light::LightBaking;
pub use lightmap::{LIGHTMAP_SCALE, LightmappedMesh};
pub use plugin::{SurfcacheBevyPlugin, SurfcacheBevySystems};
pub use spawn::{SceneSpawner, spawn_scene};
pub use surfcache_ecs::{BakeConfig, BakeFinished, BakeStatus};
