//! The BVH build: a background thread turns each scene snapshot into a
//! [`TracedScene`]; the finished one replaces [`TracedSceneResource`]'s.

use crate::{
    components::*,
    scene_sync::{InstanceQuery, SceneChanges, gather_scene},
};
use bevy_ecs::prelude::*;
use std::sync::{
    Arc, Mutex,
    mpsc::{Receiver, TryRecvError, channel},
};
use surfcache_trace::TracedScene;

/// The traced scene built from the world's components, the entity of each of its
/// instances, and what changed since the bake systems last took [`Self::changes`].
#[derive(Resource, Default)]
pub struct TracedSceneResource {
    scene: Option<Arc<TracedScene>>,
    /// `entities[k]` is the entity of the traced scene's instance `k`.
    pub entities: Vec<Entity>,
    /// The snapshot generation the scene was built from (0: none yet).
    pub generation: u64,
    /// What changed since the bake systems last took it (they take it with each new
    /// generation).
    pub changes: SceneChanges,
    /// Why the latest snapshot could not be built (invalid or empty scene), if it failed.
    pub error: Option<String>,
}

impl TracedSceneResource {
    /// The current traced scene, if one was built.
    pub fn scene(&self) -> Option<&Arc<TracedScene>> {
        self.scene.as_ref()
    }
}

/// A finished background build.
struct Built {
    generation: u64,
    entities: Vec<Entity>,
    changes: SceneChanges,
    scene: Result<Arc<TracedScene>, String>,
}

/// Background BVH builds in flight (the newest snapshot wins; older results are dropped).
#[derive(Resource, Default)]
pub struct BvhBuilds {
    /// The newest snapshot's generation.
    pub requested: u64,
    /// (`Mutex`es only to make the resource `Sync`; one system reads them.)
    pending: Vec<Mutex<Receiver<Built>>>,
}

impl BvhBuilds {
    /// Whether a build is still running.
    pub fn busy(&self) -> bool {
        !self.pending.is_empty()
    }
}

/// BVH build, part 1: when the scene changed, snapshots it and builds its traced scene
/// (BVH, light and area tables) on a background thread.
pub fn start_bvh_build(
    mut changes: ResMut<SceneChanges>,
    mut builds: ResMut<BvhBuilds>,
    instances: InstanceQuery,
    lights: Query<&PunctualLight>,
    environment: Query<&EnvironmentLight>,
) {
    if !changes.dirty {
        return;
    }
    let changes = changes.take();
    let (scene, entities) = gather_scene(&instances, &lights, &environment);
    builds.requested += 1;
    let generation = builds.requested;
    let (tx, rx) = channel();
    std::thread::spawn(move || {
        let scene = TracedScene::new(&scene)
            .map(Arc::new)
            .map_err(|e| e.to_string());
        // The receiver is gone when the world was dropped; nothing to do then.
        let _ = tx.send(Built {
            generation,
            entities,
            changes,
            scene,
        });
    });
    builds.pending.push(Mutex::new(rx));
}

/// BVH build, part 2: installs finished builds in snapshot order. Changes of a build that
/// a newer one supersedes are carried into the newer one's [`TracedSceneResource::changes`].
pub fn finish_bvh_build(mut builds: ResMut<BvhBuilds>, mut traced: ResMut<TracedSceneResource>) {
    // Builds finish in any order, but are installed in request order.
    while let Some(rx) = builds.pending.first() {
        let received = match rx.lock() {
            Ok(rx) => rx.try_recv(),
            Err(_) => Err(TryRecvError::Disconnected),
        };
        let built = match received {
            Ok(b) => b,
            Err(TryRecvError::Empty) => return,
            Err(TryRecvError::Disconnected) => {
                builds.pending.remove(0);
                traced.error = Some("internal error: a BVH build thread panicked".into());
                continue;
            }
        };
        builds.pending.remove(0);
        // Changes the bake systems have not taken yet carry over.
        let mut changes = std::mem::take(&mut traced.changes);
        changes.merge(&built.changes);
        match built.scene {
            Ok(scene) => {
                traced.scene = Some(scene);
                traced.entities = built.entities;
                traced.generation = built.generation;
                traced.changes = changes;
                traced.error = None;
            }
            Err(e) => {
                // Keep the last good scene; its changes stay pending for the next build.
                traced.changes = changes;
                traced.error = Some(e);
            }
        }
    }
}
