//! Bakes and re-bakes of the surface cache, off the frame.
//!
//! **Invalidation policy** ([`start_bake`], docs/design.md, Incremental re-baking). Each new traced scene, and
//! each change of [`BakeConfig`], starts a bake and supersedes (cancels) one in flight;
//! when nothing changed that the baseline depends on, the baseline is published again
//! as it is. It re-bakes *incrementally* from the
//! last finished bake (the *baseline*) when
//! - a baseline exists and was baked with the same [`BakeSettings`],
//! - neither lights nor the environment changed since (they light every surface),
//! - and the changed instances (added, removed, moved, re-meshed or re-coloured since the
//!   baseline, over every superseded snapshot too) hold at most
//!   [`BakeConfig::full_rebake_share`] of the triangles before and after the edit.
//!
//! Otherwise it bakes from scratch. An incremental re-bake
//! ([`surfcache_cache::incremental::IncrementalJob`]) keeps every sample of unchanged
//! triangles as a prior, and re-estimates the *change* of each sample: first the direct
//! change through the directions towards the box around the changed instances' old and
//! new surfaces (exactly zero, without tracing, where that box lies below a sample's
//! horizon), then three stages of indirect change from surfaces whose irradiance changed
//! in the stage before. Each stage first traces its sources forward
//! (`surfcache_cache::incremental::Influence`) and keeps the value of every point where
//! the change they estimate stays below a quarter of its error bound; each indirect stage
//! also bounds its change from all stored samples
//! (`surfcache_cache::incremental::ChangeBound`). Left out, as its docs bound:
//! changes that reach a sample over more than four bounces off the edited region, and
//! what the skipped points' bounds allow.
//!
//! **Never blocking a frame.** In [`BakeMode::Background`] (the default) the BVH build
//! and the bake run on background threads (the bake on a rayon pool of
//! [`BakeConfig::threads`]); the systems only start work, poll channels and swap finished
//! results in, in time independent of the scene's size except for the O(instances)
//! snapshot. [`BakeMode::Foreground`] instead estimates the bake's points on the thread
//! running the schedule, in steps of [`BakeConfig::points_per_step`] until the update's
//! time budget is spent (a step started before the budget ran out finishes, so keep
//! steps small); the BVH build stays in the background. It serves tests and tools that
//! want the bake in their own thread, and shows that results do not depend on pacing.
//!
//! **Determinism.** Every sample's random stream is keyed by its position and the seed,
//! never by frame or step, so a bake's result depends only on the scene, the settings and
//! the baseline it started from — not on frame pacing, step sizes, budgets or threads.
//! A superseded bake never publishes: results carry the generation of the scene snapshot
//! they were baked from, and only the newest is accepted.

use crate::{
    bvh::TracedSceneState,
    publish::{EntityTextures, PendingPublish},
    scene_sync::SceneChanges,
};
use bevy_ecs::prelude::*;
use crossbeam_channel::{Receiver, TryRecvError, bounded};
use std::{
    collections::{BTreeSet, HashMap},
    sync::{
        Arc, Mutex,
        atomic::{AtomicBool, Ordering},
    },
    time::{Duration, Instant},
};
use surfcache_cache::{
    Cache, SurfaceCache,
    bake::{BakeJob, BakeOutcome, BakeSettings, JobProgress},
    incremental::{Edit, IncrementalJob},
};
use surfcache_trace::TracedScene;

/// Where bake work runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BakeMode {
    /// On a background thread and rayon pool; systems never wait for it.
    Background,
    /// On the thread running the schedule, for about `budget` per update.
    Foreground { budget: Duration },
}

/// How and when the world's surface cache is baked.
#[derive(Resource, Clone, Debug)]
pub struct BakeConfig {
    /// Method, sampler, error bound, sample limits, gathering, seed.
    pub settings: BakeSettings,
    /// Bake whenever the traced scene changes (off: only the BVH is kept current).
    pub enabled: bool,
    pub mode: BakeMode,
    /// Worker threads of background bakes (`None`: all cores).
    pub threads: Option<usize>,
    /// Points estimated between checks for cancellation and progress updates.
    pub points_per_step: usize,
    /// Re-bake from scratch when the changed instances hold more than this share of the
    /// triangles.
    pub full_rebake_share: f32,
}

impl Default for BakeConfig {
    fn default() -> Self {
        Self {
            settings: BakeSettings::default(),
            enabled: true,
            mode: BakeMode::Background,
            threads: None,
            points_per_step: 256,
            full_rebake_share: 0.5,
        }
    }
}

/// Progress of the bake in flight, and the outcome of the last one.
#[derive(Resource, Clone, Debug, Default, PartialEq)]
pub struct BakeStatus {
    /// A bake is in flight.
    pub running: bool,
    /// Scene generation of the bake in flight (or of the last one).
    pub generation: u64,
    /// Whether it is an incremental re-bake.
    pub incremental: bool,
    /// Estimated share done, 0–1.
    pub fraction: f32,
    pub samples: u64,
    pub rays: u64,
    pub rays_per_second: f64,
    /// Estimated seconds left.
    pub eta_seconds: Option<f64>,
    /// Wall-clock seconds so far (or of the finished bake).
    pub seconds: f64,
    /// Why the last bake failed, if it did.
    pub error: Option<String>,
    /// The job's own figures (pass, round, points done and pending).
    pub job: JobProgress,
}

impl BakeStatus {
    /// The time left as a bake's progress shows it: [`Self::eta_seconds`], which is a
    /// lower bound where the work still to come is not known ([`JobProgress::work_known`]:
    /// vertex lighting cannot tell its later rounds, and while the bounce passes of an
    /// irradiance-map bake run, its final pass' share is a guess).
    ///
    /// ```
    /// use surfcache_ecs::BakeStatus;
    /// let status = BakeStatus { eta_seconds: Some(12.0), ..Default::default() };
    /// assert_eq!(status.time_left().unwrap().to_string(), "at least 12 s left");
    /// ```
    pub fn time_left(&self) -> Option<TimeLeft> {
        let seconds = self.eta_seconds?;
        Some(if self.job.work_known {
            TimeLeft::About(seconds)
        } else {
            TimeLeft::AtLeast(seconds)
        })
    }
}

/// Seconds a bake has left ([`BakeStatus::time_left`]); shown as "about N s left" or
/// "at least N s left".
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TimeLeft {
    About(f64),
    AtLeast(f64),
}

impl std::fmt::Display for TimeLeft {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TimeLeft::About(s) => write!(f, "about {s:.0} s left"),
            TimeLeft::AtLeast(s) => write!(f, "at least {s:.0} s left"),
        }
    }
}

/// The finished surface cache of the newest baked scene.
#[derive(Resource, Default, Clone)]
pub struct BakedSurfaceCache {
    /// The bake (every pass; the final cache is [`BakeOutcome::cache`]).
    pub outcome: Option<BakeOutcome>,
    /// The traced scene it was baked over, and the entity of each of its instances.
    pub scene: Option<Arc<TracedScene>>,
    pub entities: Vec<Entity>,
    /// Its scene generation.
    pub generation: u64,
}

impl BakedSurfaceCache {
    /// The final cache, if a bake finished.
    pub fn cache(&self) -> Option<&Arc<Cache>> {
        self.outcome.as_ref().map(|o| o.cache())
    }
}

/// A bake job of either kind.
enum Job {
    Full(Box<BakeJob>),
    Incremental(Box<IncrementalJob>),
}

impl Job {
    fn step(&mut self, scene: &Arc<TracedScene>, points: usize) -> bool {
        match self {
            Job::Full(j) => j.step(scene, points),
            Job::Incremental(j) => j.step(scene, points),
        }
    }

    fn progress(&self) -> JobProgress {
        match self {
            Job::Full(j) => j.progress(),
            Job::Incremental(j) => j.progress(),
        }
    }

    fn into_outcome(self) -> Option<BakeOutcome> {
        match self {
            Job::Full(j) => j.into_outcome(),
            Job::Incremental(j) => j.into_outcome(),
        }
    }
}

/// The last finished bake, the start of incremental re-bakes.
#[derive(Clone)]
struct Baseline {
    scene: Arc<TracedScene>,
    entities: Vec<Entity>,
    outcome: BakeOutcome,
    published: Arc<EntityTextures>,
    /// The settings the bake was asked for ([`BakeConfig::settings`]); the outcome's
    /// differ where the bake fitted them to the scene (density budget, floor).
    requested: BakeSettings,
}

/// A finished bake's results (the cache, its scene, the textures per entity), on their
/// way through [`PendingPublish`] to [`publish`](crate::publish::publish).
pub(crate) struct BakeResult {
    pub generation: u64,
    pub incremental: bool,
    pub seconds: f64,
    pub scene: Arc<TracedScene>,
    pub entities: Vec<Entity>,
    pub outcome: BakeOutcome,
    pub published: Arc<EntityTextures>,
    /// The settings the bake was asked for.
    pub requested: BakeSettings,
}

/// One bake: the job, its scene and what it needs to publish.
struct Run {
    job: Job,
    requested: BakeSettings,
    scene: Arc<TracedScene>,
    entities: Vec<Entity>,
    /// Which bake this is ([`Baking::bake_id`]).
    id: u64,
    generation: u64,
    incremental: bool,
    previous: Option<Arc<EntityTextures>>,
    started: Instant,
    pace: Pace,
}

/// The recent rate of samples of a bake: samples done at moments of the last
/// [`Pace::WINDOW`] seconds. Later rounds of a pass sample other places than its first
/// (irradiance maps refine into enclosed detail, where rays are shorter) and run faster
/// per sample (docs/results.md, "Progress of irradiance maps"), so a time left from the
/// rate since the start would run long.
#[derive(Default)]
struct Pace {
    marks: std::collections::VecDeque<(f64, u64)>,
}

impl Pace {
    /// Seconds of marks kept, and the least span a rate is taken over.
    const WINDOW: f64 = 60.0;
    const LEAST_SPAN: f64 = 10.0;

    /// Records `samples` done at `seconds`; returns samples per second over the marks
    /// kept, once they span [`Self::LEAST_SPAN`].
    fn rate(&mut self, seconds: f64, samples: u64) -> Option<f64> {
        while self.marks.len() > 1 && self.marks[1].0 <= seconds - Self::WINDOW {
            self.marks.pop_front();
        }
        self.marks.push_back((seconds, samples));
        let &(t0, s0) = self.marks.front()?;
        (seconds - t0 >= Self::LEAST_SPAN && samples > s0)
            .then(|| (samples - s0) as f64 / (seconds - t0))
    }
}

impl Run {
    fn finish(self) -> Result<BakeResult, String> {
        let seconds = self.started.elapsed().as_secs_f64();
        let outcome = self
            .job
            .into_outcome()
            .ok_or("internal error: the bake did not finish")?;
        let textures = outcome.cache().publish(&self.scene);
        let published = EntityTextures::from_textures(
            textures,
            &self.entities,
            self.generation,
            self.previous.as_deref(),
        );
        Ok(BakeResult {
            generation: self.generation,
            incremental: self.incremental,
            seconds,
            scene: self.scene,
            entities: self.entities,
            outcome,
            published: Arc::new(published),
            requested: self.requested,
        })
    }

    /// The status of the bake at `progress`: the time left from the recent rate of
    /// samples where the job can tell the samples it still needs, else from its share
    /// done at the rate since the start.
    fn status(&mut self, progress: &JobProgress) -> BakeStatus {
        let seconds = self.started.elapsed().as_secs_f64();
        let fraction = progress.fraction();
        let rate = self.pace.rate(seconds, progress.samples);
        let eta_seconds = match (progress.samples_left, rate) {
            (Some(left), Some(rate)) => Some(left as f64 / rate),
            _ => (fraction > 0.0).then(|| seconds * (1.0 - fraction as f64) / fraction as f64),
        };
        BakeStatus {
            running: !progress.finished,
            generation: self.generation,
            incremental: self.incremental,
            fraction,
            samples: progress.samples,
            rays: progress.rays,
            rays_per_second: progress.rays as f64 / seconds.max(1e-9),
            eta_seconds,
            seconds,
            error: None,
            job: *progress,
        }
    }
}

/// The background side of a bake in flight.
struct Worker {
    id: u64,
    cancel: Arc<AtomicBool>,
    status: Arc<Mutex<BakeStatus>>,
    result: Receiver<Result<BakeResult, String>>,
}

/// Bake bookkeeping: the baseline, changes since it, and the bake in flight.
#[derive(Resource, Default)]
pub struct Baking {
    baseline: Option<Baseline>,
    /// Instances changed since the baseline (over superseded snapshots too).
    changed: BTreeSet<Entity>,
    global: bool,
    /// The newest traced-scene generation a bake was started for.
    started: u64,
    /// Counts started bakes; only the newest may publish.
    bake_id: u64,
    worker: Option<Worker>,
    /// (A `Mutex` only to make the resource `Sync`; one system steps it.)
    foreground: Option<Mutex<Run>>,
    pool: Option<(Option<usize>, Arc<rayon::ThreadPool>)>,
}

impl Baking {
    /// Cancels the bake in flight; it will not publish.
    pub fn cancel(&mut self) {
        if let Some(w) = self.worker.take() {
            w.cancel.store(true, Ordering::SeqCst);
        }
        self.foreground = None;
    }

    /// Whether a bake is in flight.
    pub fn busy(&self) -> bool {
        self.worker.is_some() || self.foreground.is_some()
    }

    fn pool(&mut self, threads: Option<usize>) -> Result<Arc<rayon::ThreadPool>, String> {
        if let Some((n, pool)) = &self.pool
            && *n == threads
        {
            return Ok(pool.clone());
        }
        let mut builder =
            rayon::ThreadPoolBuilder::new().thread_name(|i| format!("surfcache-bake-{i}"));
        if let Some(n) = threads {
            builder = builder.num_threads(n);
        }
        let pool = Arc::new(
            builder
                .build()
                .map_err(|e| format!("cannot start the bake threads: {e}"))?,
        );
        self.pool = Some((threads, pool.clone()));
        Ok(pool)
    }
}

/// What a new traced scene needs.
enum Plan {
    Bake(Job, bool),
    /// No surface changed since the baseline (e.g. a component was written with its old
    /// value): the baseline holds for the new scene as it is.
    Unchanged,
}

/// Chooses the job for a new traced scene (module docs: the invalidation policy).
fn plan(
    config: &BakeConfig,
    baking: &Baking,
    scene: &Arc<TracedScene>,
    entities: &[Entity],
) -> Plan {
    let full = || Plan::Bake(Job::Full(Box::new(BakeJob::new(config.settings))), false);
    let Some(base) = &baking.baseline else {
        return full();
    };
    // Compared as asked for: a bake fits its own settings to the scene (the density
    // budget, the floor it measures), and the re-bake keeps the baseline's fitted ones.
    if baking.global || base.requested != config.settings {
        return full();
    }
    let index: HashMap<Entity, u32> = base
        .entities
        .iter()
        .enumerate()
        .map(|(k, e)| (*e, k as u32))
        .collect();
    let instance_map: Vec<Option<u32>> = entities.iter().map(|e| index.get(e).copied()).collect();
    let Some(edit) = Edit::between(
        &base.scene,
        scene,
        &instance_map,
        |k| baking.changed.contains(&base.entities[k]),
        |k| baking.changed.contains(&entities[k]),
    ) else {
        return Plan::Unchanged;
    };
    let total = base.scene.triangle_count() + scene.triangle_count();
    if edit.changed_triangles() as f32 > config.full_rebake_share * total as f32 {
        return full();
    }
    let job = IncrementalJob::new(base.outcome.clone(), base.scene.clone(), edit);
    Plan::Bake(Job::Incremental(Box::new(job)), true)
}

/// Invalidation: when a new traced scene is installed, records what changed since the
/// baseline, cancels a bake in flight and starts the one the policy chooses.
pub fn start_bake(
    config: Res<BakeConfig>,
    mut baking: ResMut<Baking>,
    mut traced: ResMut<TracedSceneState>,
    mut status: ResMut<BakeStatus>,
    mut pending: ResMut<PendingPublish>,
) {
    // A new scene, or new settings (or baking switched on), start a bake.
    let new_scene = traced.generation != baking.started;
    if !config.enabled || !(new_scene || config.is_changed()) {
        return;
    }
    let Some(scene) = traced.scene().cloned() else {
        return;
    };
    let changes: SceneChanges = std::mem::take(&mut traced.changes);
    baking.changed.extend(changes.instances.iter().copied());
    baking.global |= changes.global;
    baking.started = traced.generation;
    baking.cancel();
    baking.bake_id += 1;
    let entities = traced.entities.clone();
    let (job, incremental) = match plan(&config, &baking, &scene, &entities) {
        Plan::Bake(job, incremental) => (job, incremental),
        Plan::Unchanged => {
            // The baseline holds: published again as it is, nothing updated.
            if let Some(base) = baking.baseline.as_mut() {
                base.scene = scene;
                base.entities = entities;
                pending.0 = Some(BakeResult {
                    generation: traced.generation,
                    incremental: true,
                    seconds: 0.0,
                    scene: base.scene.clone(),
                    entities: base.entities.clone(),
                    outcome: base.outcome.clone(),
                    published: base.published.clone(),
                    requested: base.requested,
                });
            }
            baking.changed.clear();
            return;
        }
    };
    let run = Run {
        job,
        requested: config.settings,
        scene,
        entities,
        id: baking.bake_id,
        generation: traced.generation,
        incremental,
        previous: baking.baseline.as_ref().map(|b| b.published.clone()),
        started: Instant::now(),
        pace: Pace::default(),
    };
    *status = BakeStatus {
        running: true,
        generation: run.generation,
        incremental,
        ..Default::default()
    };
    match config.mode {
        BakeMode::Foreground { .. } => baking.foreground = Some(Mutex::new(run)),
        BakeMode::Background => {
            let pool = match baking.pool(config.threads) {
                Ok(p) => p,
                Err(e) => {
                    status.running = false;
                    status.error = Some(e);
                    return;
                }
            };
            baking.worker = Some(spawn_worker(run, pool, config.points_per_step.max(1)));
        }
    }
}

fn spawn_worker(mut run: Run, pool: Arc<rayon::ThreadPool>, points: usize) -> Worker {
    let cancel = Arc::new(AtomicBool::new(false));
    let status = Arc::new(Mutex::new(BakeStatus {
        running: true,
        generation: run.generation,
        incremental: run.incremental,
        ..Default::default()
    }));
    let (tx, rx) = bounded(1);
    let worker = Worker {
        id: run.id,
        cancel: cancel.clone(),
        status: status.clone(),
        result: rx,
    };
    std::thread::spawn(move || {
        let result = pool.install(|| {
            loop {
                if cancel.load(Ordering::SeqCst) {
                    return None;
                }
                let done = run.job.step(&run.scene, points);
                if let Ok(mut s) = status.lock() {
                    *s = run.status(&run.job.progress());
                }
                if done {
                    return Some(run.finish());
                }
            }
        });
        if let Some(result) = result {
            // The receiver is gone when the bake was superseded meanwhile.
            let _ = tx.send(result);
        }
    });
    worker
}

/// Bake step: advances a foreground bake within its budget, or copies a background
/// bake's progress into [`BakeStatus`]; hands a finished bake to [`publish`](crate::publish::publish).
pub fn step_bake(
    config: Res<BakeConfig>,
    mut baking: ResMut<Baking>,
    mut status: ResMut<BakeStatus>,
    mut pending: ResMut<PendingPublish>,
) {
    if let Some(w) = &baking.worker {
        if let Ok(s) = w.status.lock()
            && *status != *s
        {
            *status = s.clone();
        }
        match w.result.try_recv() {
            Err(TryRecvError::Empty) => {}
            Ok(result) => {
                let id = w.id;
                baking.worker = None;
                accept(&mut baking, &mut status, &mut pending, id, result);
            }
            Err(TryRecvError::Disconnected) => {
                let id = w.id;
                baking.worker = None;
                accept(
                    &mut baking,
                    &mut status,
                    &mut pending,
                    id,
                    Err("internal error: the bake thread panicked".into()),
                );
            }
        }
        return;
    }
    let BakeMode::Foreground { budget } = config.mode else {
        return;
    };
    let Some(run) = baking.foreground.as_mut().and_then(|r| r.get_mut().ok()) else {
        return;
    };
    let start = Instant::now();
    let points = config.points_per_step.max(1);
    let mut done = false;
    while !done && start.elapsed() < budget {
        done = run.job.step(&run.scene, points);
    }
    *status = run.status(&run.job.progress());
    if done && let Some(run) = baking.foreground.take().and_then(|r| r.into_inner().ok()) {
        let id = run.id;
        let result = run.finish();
        accept(&mut baking, &mut status, &mut pending, id, result);
    }
}

/// Makes the newest bake, once finished, the baseline and queues it for publishing.
fn accept(
    baking: &mut Baking,
    status: &mut BakeStatus,
    pending: &mut PendingPublish,
    id: u64,
    result: Result<BakeResult, String>,
) {
    if id != baking.bake_id {
        return;
    }
    match result {
        Ok(f) => {
            status.running = false;
            status.fraction = 1.0;
            status.seconds = f.seconds;
            status.eta_seconds = Some(0.0);
            baking.baseline = Some(Baseline {
                scene: f.scene.clone(),
                entities: f.entities.clone(),
                outcome: f.outcome.clone(),
                published: f.published.clone(),
                requested: f.requested,
            });
            baking.changed.clear();
            baking.global = false;
            pending.0 = Some(f);
        }
        Err(e) => {
            status.running = false;
            status.error = Some(e);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Pace;

    #[test]
    fn pace_is_the_rate_of_the_last_window() {
        let mut pace = Pace::default();
        // 100 samples/s for the first 100 s.
        assert_eq!(pace.rate(0.0, 0), None);
        assert_eq!(pace.rate(5.0, 500), None, "shorter than the least span");
        for t in (10..=100).step_by(10) {
            let rate = pace.rate(t as f64, 100 * t).unwrap();
            assert!((rate - 100.0).abs() < 1e-9, "{rate} at {t} s");
        }
        // Then 300 samples/s: the old marks leave the window, and the rate follows.
        let mut samples = 10_000;
        for t in (110..=200).step_by(10) {
            samples += 3_000;
            pace.rate(t as f64, samples);
        }
        let rate = pace.rate(210.0, samples + 3_000).unwrap();
        assert!((rate - 300.0).abs() < 1e-9, "{rate}");
        // No samples for a while: no rate rather than zero or a stale one.
        let mut pace = Pace::default();
        pace.rate(0.0, 7);
        assert_eq!(pace.rate(30.0, 7), None);
    }
}
