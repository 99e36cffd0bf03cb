//! surfcache bakes diffuse global illumination into surface caches.
//!
//! This facade re-exports the workspace crates:
//! - [`core`]: scene data, geometry, environment maps, sampling (no ECS);
//! - [`trace`]: the obvhs BVH, ray queries and the path tracer;
//! - [`cache`]: the surface caches (vertex lighting, irradiance maps, texel lightmaps),
//!   their baking and the irradiance textures they publish;
//! - [`io`]: glTF and OpenEXR import and export;
//! - [`ecs`]: bevy_ecs components, resources and systems;
//! - [`cli`]: the `surfcache` command-line tool.

pub use surfcache_cache as cache;
pub use surfcache_cli as cli;
pub use surfcache_core as core;
pub use surfcache_ecs as ecs;
pub use surfcache_io as io;
pub use surfcache_trace as trace;
