//! Systems: scene sync (change detection) and the BVH build.

use crate::components::*;
use bevy_ecs::prelude::*;
use std::sync::Arc;
use surfcache_core::{Environment, Instance, Scene};
use surfcache_trace::TracedScene;

/// The traced scene built from the world's components, and the entity of each instance.
#[derive(Resource, Default)]
pub struct TracedSceneResource {
    scene: Option<Arc<TracedScene>>,
    /// `entities[k]` is the entity of the scene's instance `k`.
    pub entities: Vec<Entity>,
    /// Bumped on every rebuild.
    pub generation: u64,
    /// Why the last rebuild failed (invalid or empty scene), if it did.
    pub error: Option<String>,
    /// Set by [`detect_scene_changes`] when a component changed since the last build.
    pub dirty: bool,
}

impl TracedSceneResource {
    /// The current traced scene, if one was built.
    pub fn scene(&self) -> Option<&Arc<TracedScene>> {
        self.scene.as_ref()
    }
}

type GeometryChanged = Or<(
    Changed<MeshGeometry>,
    Changed<SurfaceMaterial>,
    Changed<WorldTransform>,
)>;

/// Scene sync: marks the traced scene dirty when instances, lights or the environment
/// were added, changed or removed.
pub fn detect_scene_changes(
    mut traced: ResMut<TracedSceneResource>,
    geometry: Query<(), GeometryChanged>,
    lights: Query<(), Changed<PunctualLight>>,
    environment: Query<(), Changed<EnvironmentLight>>,
    mut removed_meshes: RemovedComponents<MeshGeometry>,
    mut removed_lights: RemovedComponents<PunctualLight>,
    mut removed_env: RemovedComponents<EnvironmentLight>,
) {
    let removed =
        removed_meshes.read().count() + removed_lights.read().count() + removed_env.read().count();
    if !geometry.is_empty() || !lights.is_empty() || !environment.is_empty() || removed > 0 {
        traced.dirty = true;
    }
}

/// Gathers the world's scene components into a plain [`Scene`] (instances in entity order).
pub fn gather_scene(
    instances: &Query<(
        Entity,
        &MeshGeometry,
        &SurfaceMaterial,
        &WorldTransform,
        Option<&InstanceName>,
    )>,
    lights: &Query<&PunctualLight>,
    environment: &Query<&EnvironmentLight>,
) -> (Scene, Vec<Entity>) {
    let mut rows: Vec<_> = instances.iter().collect();
    rows.sort_by_key(|(e, ..)| *e);
    let entities = rows.iter().map(|(e, ..)| *e).collect();
    let scene = Scene {
        name: String::new(),
        instances: rows
            .into_iter()
            .map(|(e, mesh, material, transform, name)| Instance {
                name: name.map_or_else(|| format!("entity{}", e.index()), |n| n.0.clone()),
                mesh: mesh.0.clone(),
                material: material.0.clone(),
                transform: transform.0,
            })
            .collect(),
        lights: lights.iter().map(|l| l.0).collect(),
        environment: environment
            .iter()
            .next()
            .map_or_else(Environment::black, |e| e.0.clone()),
    };
    (scene, entities)
}

/// BVH build: rebuilds the traced scene when it is dirty.
pub fn build_traced_scene(
    mut traced: ResMut<TracedSceneResource>,
    instances: Query<(
        Entity,
        &MeshGeometry,
        &SurfaceMaterial,
        &WorldTransform,
        Option<&InstanceName>,
    )>,
    lights: Query<&PunctualLight>,
    environment: Query<&EnvironmentLight>,
) {
    if !traced.dirty {
        return;
    }
    traced.dirty = false;
    let (scene, entities) = gather_scene(&instances, &lights, &environment);
    traced.generation += 1;
    match TracedScene::new(&scene) {
        Ok(s) => {
            traced.scene = Some(Arc::new(s));
            traced.entities = entities;
            traced.error = None;
        }
        Err(e) => {
            traced.scene = None;
            traced.entities.clear();
            traced.error = Some(e.to_string());
        }
    }
}
