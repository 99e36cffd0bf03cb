//! Scene components: each wraps a plain `surfcache_core` type.

use bevy_ecs::prelude::*;
use glam::Affine3A;
use std::sync::Arc;
use surfcache_core::{Environment, Light, Material, Mesh};

/// Triangles of one mesh instance, in object space (shared between instances).
#[derive(Component, Clone, Debug)]
pub struct MeshGeometry(pub Arc<Mesh>);

/// The Lambertian material of a mesh instance.
#[derive(Component, Clone, Debug)]
pub struct SurfaceMaterial(pub Arc<Material>);

/// Object-to-world transform of a mesh instance.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
pub struct WorldTransform(pub Affine3A);

/// A punctual light, in world space.
#[derive(Component, Clone, Copy, Debug, PartialEq)]
pub struct PunctualLight(pub Light);

/// Environment radiance; the first such entity lights the scene (none: black).
#[derive(Component, Clone, Debug, PartialEq)]
pub struct EnvironmentLight(pub Environment);

/// A human-readable name for a mesh instance (used for output file names).
#[derive(Component, Clone, Debug, PartialEq, Eq)]
pub struct InstanceName(pub String);
