//! Scene data, geometry, environment maps and sampling for surfcache.
//!
//! This crate owns the plain data that every other part of surfcache works on, with no
//! ECS in it: triangle meshes with their normal function ν (docs/design.md, Physics), Lambertian
//! materials, punctual lights, equirectangular environment maps (docs/cli.md convention),
//! random numbers and the warps that turn them into directions, and the built-in scenes.
//! The ECS components in `surfcache_ecs` wrap these types; the tracer in
//! `surfcache_trace` flattens them into world-space triangles.

pub mod color;
pub mod environment;
pub mod geometry;
pub mod index;
pub mod prefetch;
pub mod sampling;
pub mod scene;
pub mod scenes;

pub use environment::{Environment, EnvironmentMap, EnvironmentSampler};
pub use scene::{AlphaMode, Instance, Light, Material, Mesh, Scene, SceneError, Texture};

/// glam types used throughout surfcache's public API.
pub use glam;
