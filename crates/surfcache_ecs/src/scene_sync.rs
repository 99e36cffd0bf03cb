//! Scene sync: change detection on the scene components, and the plain [`Scene`] snapshot
//! the background BVH build and bakes work on.

use crate::components::*;
use bevy_ecs::prelude::*;
use std::collections::BTreeSet;
use surfcache_core::{Environment, Instance, Scene};

/// What changed in the world's scene since the last snapshot ([`SceneChanges::take`]).
#[derive(Resource, Default, Debug, Clone, PartialEq, Eq)]
pub struct SceneChanges {
    /// Some scene component was added, changed or removed.
    pub dirty: bool,
    /// Mesh instances whose geometry, material or transform was added, changed or removed.
    pub instances: BTreeSet<Entity>,
    /// Lights or the environment changed: they light every surface, so a re-bake starts
    /// from scratch.
    pub global: bool,
}

impl SceneChanges {
    /// Merges `other` into `self`.
    pub fn merge(&mut self, other: &SceneChanges) {
        self.dirty |= other.dirty;
        self.global |= other.global;
        self.instances.extend(other.instances.iter().copied());
    }

    /// The changes so far, leaving `self` clean.
    pub fn take(&mut self) -> SceneChanges {
        std::mem::take(self)
    }
}

type InstanceChanged = Or<(
    Changed<MeshGeometry>,
    Changed<SurfaceMaterial>,
    Changed<WorldTransform>,
)>;

/// Scene sync: records which instances were added, changed or removed, and whether
/// lights or the environment changed (`Changed` includes `Added`).
#[allow(clippy::too_many_arguments)] // one removal reader per scene component
pub fn detect_scene_changes(
    mut changes: ResMut<SceneChanges>,
    instances: Query<Entity, (InstanceChanged, With<MeshGeometry>)>,
    lights: Query<(), Changed<PunctualLight>>,
    environment: Query<(), Changed<EnvironmentLight>>,
    mut removed_meshes: RemovedComponents<MeshGeometry>,
    mut removed_materials: RemovedComponents<SurfaceMaterial>,
    mut removed_transforms: RemovedComponents<WorldTransform>,
    mut removed_lights: RemovedComponents<PunctualLight>,
    mut removed_env: RemovedComponents<EnvironmentLight>,
) {
    let before = changes.instances.len();
    changes.instances.extend(instances.iter());
    changes.instances.extend(removed_meshes.read());
    changes.instances.extend(removed_materials.read());
    changes.instances.extend(removed_transforms.read());
    let global = !lights.is_empty()
        || !environment.is_empty()
        || removed_lights.read().count() + removed_env.read().count() > 0;
    if global || changes.instances.len() > before {
        changes.dirty = true;
    }
    changes.global |= global;
}

/// The instance query [`gather_scene`] reads.
pub type InstanceQuery<'w, 's> = Query<
    'w,
    's,
    (
        Entity,
        &'static MeshGeometry,
        &'static SurfaceMaterial,
        &'static WorldTransform,
        Option<&'static InstanceName>,
    ),
>;

/// Gathers the world's scene components into a plain [`Scene`] (instances in entity
/// order; meshes and materials are shared, not copied) and the entity of each instance.
pub fn gather_scene(
    instances: &InstanceQuery,
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
