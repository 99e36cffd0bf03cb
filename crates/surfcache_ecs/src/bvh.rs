//! The BVH build: one background worker per world turns scene snapshots into
//! [`TracedScene`]s, one at a time; the finished one replaces [`TracedSceneState`]'s.
//!
//! [`BvhBuilds`] owns the worker: a thread that starts with the first snapshot, builds one
//! snapshot at a time, and ends when the resource is dropped (after the build under way,
//! if any; nothing waits for it). At most one snapshot waits while it builds: a newer one
//! replaces it, so the replaced snapshot is never built and its changes ride on with the
//! newer one. A scene edited every frame (something dragged) thus costs one build at a
//! time, and the newest state is the one built next. [`start_bvh_build`] hands snapshots
//! over; [`finish_bvh_build`] installs finished builds in snapshot order. A failed build
//! (invalid or empty scene) or one that panicked keeps the last good scene and sets
//! [`TracedSceneState::error`].

use crate::{
    components::*,
    scene_sync::{InstanceQuery, SceneChanges, gather_scene},
};
use bevy_ecs::prelude::*;
use crossbeam_channel::{Receiver, Sender, TryRecvError, TrySendError, bounded, unbounded};
use std::{
    any::Any,
    panic::{AssertUnwindSafe, catch_unwind},
    sync::Arc,
};
use surfcache_core::Scene;
use surfcache_trace::TracedScene;

/// The traced scene built from the world's components, the entity of each of its
/// instances, and what changed since the bake systems last took [`Self::changes`].
#[derive(Resource, Default)]
pub struct TracedSceneState {
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

impl TracedSceneState {
    /// The current traced scene, if one was built.
    pub fn scene(&self) -> Option<&Arc<TracedScene>> {
        self.scene.as_ref()
    }

    /// Installs a finished build. Changes the bake systems have not taken yet carry over;
    /// a failed build keeps the last good scene, and its changes stay pending for the next.
    fn install(&mut self, built: Built) {
        self.changes.merge(&built.changes);
        match built.scene {
            Ok(scene) => {
                self.scene = Some(scene);
                self.entities = built.entities;
                self.generation = built.generation;
                self.error = None;
            }
            Err(e) => self.error = Some(e),
        }
    }
}

/// A scene snapshot on its way to the worker.
struct Snapshot {
    generation: u64,
    scene: Scene,
    entities: Vec<Entity>,
    /// What changed since the snapshot before (and in every snapshot this one replaced).
    changes: SceneChanges,
}

/// A finished build.
struct Built {
    generation: u64,
    entities: Vec<Entity>,
    changes: SceneChanges,
    scene: Result<Arc<TracedScene>, String>,
}

/// The background worker's ends: a one-snapshot inbox and the finished builds.
struct BvhWorker {
    /// Holds at most one snapshot waiting for the worker (capacity 1).
    inbox: Sender<Snapshot>,
    /// The inbox's other end, to take back a waiting snapshot that a newer one replaces.
    waiting: Receiver<Snapshot>,
    results: Receiver<Built>,
}

impl BvhWorker {
    /// Starts the worker thread; `build` turns a snapshot's scene into its traced scene.
    fn spawn(
        build: impl Fn(&Scene) -> Result<TracedScene, String> + Send + 'static,
    ) -> Result<Self, String> {
        let (inbox, snapshots) = bounded::<Snapshot>(1);
        let (finished, results) = unbounded();
        let waiting = snapshots.clone();
        std::thread::Builder::new()
            .name("surfcache-bvh".into())
            .spawn(move || {
                // Ends when the resource drops the inbox, or no longer takes results.
                for s in snapshots.iter() {
                    let scene = catch_unwind(AssertUnwindSafe(|| build(&s.scene)))
                        .unwrap_or_else(|panic| {
                            Err(format!(
                                "internal error: the BVH build panicked: {}",
                                panic_message(panic.as_ref())
                            ))
                        })
                        .map(Arc::new);
                    let built = Built {
                        generation: s.generation,
                        entities: s.entities,
                        changes: s.changes,
                        scene,
                    };
                    if finished.send(built).is_err() {
                        return;
                    }
                }
            })
            .map_err(|e| format!("cannot start the BVH build thread: {e}"))?;
        Ok(Self {
            inbox,
            waiting,
            results,
        })
    }

    /// Hands `snapshot` to the worker. A snapshot still waiting is dropped unbuilt; its
    /// changes are carried into `snapshot`. On failure (the worker stopped) the snapshot's
    /// changes come back.
    fn submit(&self, snapshot: Snapshot) -> Result<(), SceneChanges> {
        let mut snapshot = match self.inbox.try_send(snapshot) {
            Ok(()) => return Ok(()),
            Err(TrySendError::Full(s)) => s,
            Err(TrySendError::Disconnected(s)) => return Err(s.changes),
        };
        // Empty only if the worker took the waiting snapshot meanwhile: it is being built.
        if let Ok(replaced) = self.waiting.try_recv() {
            snapshot.changes.merge(&replaced.changes);
        }
        // Only this side sends, and the inbox is empty now.
        self.inbox
            .try_send(snapshot)
            .map_err(|e| e.into_inner().changes)
    }
}

impl Drop for BvhWorker {
    fn drop(&mut self) {
        // A waiting snapshot is not built; the worker ends after the build under way.
        while self.waiting.try_recv().is_ok() {}
    }
}

fn panic_message(panic: &(dyn Any + Send)) -> &str {
    if let Some(s) = panic.downcast_ref::<&str>() {
        s
    } else if let Some(s) = panic.downcast_ref::<String>() {
        s
    } else {
        "(no message)"
    }
}

fn build_traced_scene(scene: &Scene) -> Result<TracedScene, String> {
    TracedScene::new(scene).map_err(|e| e.to_string())
}

/// The BVH worker and its bookkeeping (module docs): the newest snapshot wins; older
/// ones waiting are never built, older results are installed before it.
#[derive(Resource, Default)]
pub struct BvhBuilds {
    /// The newest snapshot's generation.
    pub requested: u64,
    /// The generation of the newest build that came back (built or failed).
    received: u64,
    /// How many snapshots were built.
    built: u64,
    /// Started with the first snapshot.
    worker: Option<BvhWorker>,
}

impl BvhBuilds {
    /// Whether a build is still running (or waiting to be installed).
    pub fn busy(&self) -> bool {
        self.received < self.requested
    }

    /// How many of the [`Self::requested`] snapshots were built: fewer when snapshots
    /// arrived while a build ran and replaced one another.
    pub fn builds(&self) -> u64 {
        self.built
    }

    /// Hands a snapshot to the worker, starting it if needed. On failure: why, and the
    /// snapshot's changes.
    fn submit(&mut self, snapshot: Snapshot) -> Result<(), (String, SceneChanges)> {
        if self.worker.is_none() {
            match BvhWorker::spawn(build_traced_scene) {
                Ok(w) => self.worker = Some(w),
                Err(e) => return Err((e, snapshot.changes)),
            }
        }
        let worker = self.worker.as_ref().expect("started above");
        worker.submit(snapshot).map_err(|changes| {
            self.worker = None;
            (
                "internal error: the BVH build thread stopped".into(),
                changes,
            )
        })
    }
}

/// BVH build, part 1: when the scene changed, snapshots it and hands it to the background
/// worker, which builds its traced scene (BVH, light and area tables).
pub fn start_bvh_build(
    mut changes: ResMut<SceneChanges>,
    mut builds: ResMut<BvhBuilds>,
    mut traced: ResMut<TracedSceneState>,
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
    let snapshot = Snapshot {
        generation: builds.requested,
        scene,
        entities,
        changes,
    };
    if let Err((e, changes)) = builds.submit(snapshot) {
        // As a failed build: nothing is in flight, the changes stay pending.
        builds.received = builds.requested;
        traced.changes.merge(&changes);
        traced.error = Some(e);
    }
}

/// BVH build, part 2: installs finished builds in snapshot order. Changes of a snapshot
/// that a newer one replaced, and of builds that failed, are carried into the newer one's
/// [`TracedSceneState::changes`].
pub fn finish_bvh_build(mut builds: ResMut<BvhBuilds>, mut traced: ResMut<TracedSceneState>) {
    loop {
        let received = match &builds.worker {
            Some(w) => w.results.try_recv(),
            None => return,
        };
        match received {
            Ok(built) => {
                builds.received = built.generation;
                builds.built += 1;
                traced.install(built);
            }
            Err(TryRecvError::Empty) => return,
            Err(TryRecvError::Disconnected) => {
                // The thread ended (it never should while the resource lives); the next
                // snapshot starts another.
                builds.worker = None;
                if builds.busy() {
                    builds.received = builds.requested;
                    traced.error = Some("internal error: the BVH build thread stopped".into());
                }
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::{collections::BTreeSet, sync::mpsc, time::Duration};
    use surfcache_core::scenes;

    const WAIT: Duration = Duration::from_secs(20);

    fn snapshot(generation: u64, changed: Entity) -> Snapshot {
        let mut changes = SceneChanges {
            dirty: true,
            ..Default::default()
        };
        changes.instances.insert(changed);
        Snapshot {
            generation,
            scene: scenes::cornell(),
            entities: Vec::new(),
            changes,
        }
    }

    /// A worker whose builds each wait for a token on the returned gate.
    fn gated_worker() -> (BvhWorker, mpsc::Sender<()>) {
        let (gate, tokens) = mpsc::channel::<()>();
        let worker = BvhWorker::spawn(move |scene| {
            tokens.recv().map_err(|e| e.to_string())?;
            build_traced_scene(scene)
        })
        .unwrap();
        (worker, gate)
    }

    /// Waits until the worker took the waiting snapshot (it is building it).
    fn until_taken(worker: &BvhWorker) {
        let start = std::time::Instant::now();
        while !worker.waiting.is_empty() {
            assert!(start.elapsed() < WAIT, "the worker never took the snapshot");
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    #[test]
    fn snapshots_arriving_during_a_build_replace_each_other() {
        let mut world = World::new();
        let e: Vec<Entity> = (0..4).map(|_| world.spawn_empty().id()).collect();
        let (worker, gate) = gated_worker();
        assert!(worker.submit(snapshot(1, e[0])).is_ok());
        until_taken(&worker);
        for g in 2..=4 {
            assert!(worker.submit(snapshot(g, e[g as usize - 1])).is_ok());
        }
        for _ in 0..4 {
            gate.send(()).unwrap();
        }
        let first = worker.results.recv_timeout(WAIT).unwrap();
        let last = worker.results.recv_timeout(WAIT).unwrap();
        assert_eq!((first.generation, last.generation), (1, 4));
        assert!(first.scene.is_ok() && last.scene.is_ok());
        assert_eq!(first.changes.instances, BTreeSet::from([e[0]]));
        // The replaced snapshots' changes ride on with the newest.
        assert_eq!(
            last.changes.instances,
            e[1..].iter().copied().collect::<BTreeSet<_>>()
        );
        // Nothing else was built.
        assert!(
            worker
                .results
                .recv_timeout(Duration::from_millis(200))
                .is_err()
        );
    }

    #[test]
    fn a_panicking_build_is_an_error_and_the_worker_goes_on() {
        let worker = BvhWorker::spawn(|scene| {
            if scene.name == "boom" {
                panic!("deliberate panic in a test build");
            }
            build_traced_scene(scene)
        })
        .unwrap();
        let mut bad = snapshot(1, Entity::PLACEHOLDER);
        bad.scene.name = "boom".into();
        assert!(worker.submit(bad).is_ok());
        let failed = worker.results.recv_timeout(WAIT).unwrap();
        let e = failed.scene.err().unwrap();
        assert!(
            e.contains("panicked") && e.contains("deliberate panic"),
            "{e}"
        );
        assert!(worker.submit(snapshot(2, Entity::PLACEHOLDER)).is_ok());
        let next = worker.results.recv_timeout(WAIT).unwrap();
        assert_eq!(next.generation, 2);
        assert!(next.scene.is_ok());
    }

    #[test]
    fn dropping_the_worker_ends_its_thread_without_building_what_waits() {
        let (worker, gate) = gated_worker();
        assert!(worker.submit(snapshot(1, Entity::PLACEHOLDER)).is_ok());
        until_taken(&worker);
        assert!(worker.submit(snapshot(2, Entity::PLACEHOLDER)).is_ok());
        let results = worker.results.clone();
        drop(worker);
        for _ in 0..2 {
            let _ = gate.send(());
        }
        // The build under way finishes; then the thread ends (the results close).
        assert_eq!(results.recv_timeout(WAIT).unwrap().generation, 1);
        assert_eq!(
            results.recv_timeout(WAIT).err(),
            Some(crossbeam_channel::RecvTimeoutError::Disconnected)
        );
    }
}
