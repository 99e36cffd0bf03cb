//! Incremental re-bakes after a scene edit (DESIGN.md §6).
//!
//! A re-bake starts from the finished cache of the scene before the edit, remapped onto
//! the edited scene ([`SurfaceCache::remap`]: samples of surviving triangles keep their
//! values as priors, new triangles get fresh samples), and updates it in two stages of
//! *correlated sampling* ([`surfcache_trace::estimate_change`]), the perturbation of
//! one-bounce gathering:
//!
//! 1. **Direct change.** With radiance at first hits taken from the old cache,
//!    `L = L_e + ρ/π · E_old(y)`, only directions whose first hit changed can differ
//!    between the old and the edited scene: those towards the edited region. Each sample
//!    integrates `L_new − L_old` over the cone towards the region's bounding sphere (the
//!    whole sphere of directions for points inside it), with next-event estimation and
//!    MIS restricted to the cone; it is exactly zero, with no ray traced, where the cone
//!    lies below the surface. Fresh samples are estimated in full, gathering from the old
//!    cache.
//! 2. **Indirect change.** Surfaces whose irradiance changed in stage 1 (a shadow that
//!    moved, a wall that sees the moved object) relight everything that sees them: every
//!    sample adds `∫ ρ/π · (E_1(y) − E_old(y)) ⟨ν, ω⟩ dω`, estimated with the same
//!    directions for both lookups in the edited scene (exactly zero where no seen surface
//!    changed).
//!
//! Left out: changes that reach a sample over three or more bounces off the edited
//! region, i.e. `ρ/π ∫ (E_new − E_1)(y)` — at most the largest albedo times the largest
//! stage-2 change, a second-order fraction of the edit's effect; and the noise of both
//! change estimates, bounded by [`surfcache_trace::irradiance::CHANGE_ERROR_SHARE`] of
//! the error bound each. Refinement (irradiance maps) continues as in a full bake where
//! the updated values call for it.

use crate::{
    Cache, SurfaceCache, UNMAPPED,
    bake::{BakeOutcome, Baker, JobProgress, Previous},
};
use glam::{Vec2, Vec3};
use std::sync::Arc;
use surfcache_core::sampling::splitmix64;
use surfcache_trace::{IrradianceLookup, TracedScene};

/// What an edit changed, in the terms a re-bake needs.
#[derive(Clone, Debug)]
pub struct Edit {
    /// `triangle_map[t_new]`: the triangle before the edit ([`crate::triangle_map`]).
    pub triangle_map: Arc<Vec<u32>>,
    /// A box (min, max) holding every surface that moved, appeared, disappeared or
    /// changed material, before and after the edit.
    pub region: (Vec3, Vec3),
}

/// A cache of the scene before an edit, looked up on the edited scene's triangles
/// (zero on triangles that did not exist before).
pub struct MappedLookup {
    pub cache: Arc<Cache>,
    pub triangle_map: Arc<Vec<u32>>,
}

impl IrradianceLookup for MappedLookup {
    fn irradiance(&self, triangle: u32, uv: Vec2, front: bool) -> Vec3 {
        match self.triangle_map.get(triangle as usize) {
            Some(&t) if t != UNMAPPED => self.cache.lookup(t, uv, front),
            _ => Vec3::ZERO,
        }
    }
}

/// A re-bake of a finished bake after an edit (module docs).
pub struct IncrementalJob {
    before: BakeOutcome,
    old_scene: Arc<TracedScene>,
    edit: Edit,
    stage: u32,
    baker: Option<Baker<Cache>>,
    direct: Option<Arc<Cache>>,
    done: JobProgress,
    result: Option<Arc<Cache>>,
}

impl IncrementalJob {
    /// Re-bakes `before` (baked over `old_scene`) for the edited scene this job is
    /// stepped with.
    pub fn new(before: BakeOutcome, old_scene: Arc<TracedScene>, edit: Edit) -> Self {
        Self {
            before,
            old_scene,
            edit,
            stage: 0,
            baker: None,
            direct: None,
            done: JobProgress {
                passes: 2,
                ..Default::default()
            },
            result: None,
        }
    }

    fn old_lookup(&self) -> Arc<MappedLookup> {
        Arc::new(MappedLookup {
            cache: self.before.cache().clone(),
            triangle_map: self.edit.triangle_map.clone(),
        })
    }

    fn start_stage(&mut self, scene: &Arc<TracedScene>) {
        let settings = self.before.settings;
        let (lo, hi) = self.edit.region;
        let sphere = (
            0.5 * (lo + hi),
            0.5 * (hi - lo).length() + scene.spawn_offset(),
        );
        let baker = if self.stage == 0 {
            let cache = self
                .before
                .cache()
                .remap(&self.old_scene, scene, &self.edit.triangle_map);
            Baker::new(cache, settings.estimator, settings.seed)
                .with_gather(self.old_lookup())
                .with_previous(Previous {
                    scene: self.old_scene.clone(),
                    triangle_map: self.edit.triangle_map.clone(),
                    gather: Some(self.before.cache().clone()),
                    focus: Some(sphere),
                })
        } else {
            let direct = self.direct.clone().expect("stage 1 follows stage 0");
            let identity: Arc<Vec<u32>> = Arc::new((0..scene.triangle_count() as u32).collect());
            let cache = direct.remap(scene, scene, &identity);
            Baker::new(
                cache,
                settings.estimator,
                settings.seed ^ splitmix64(0x696e_6469_7265_6374),
            )
            .with_gather(direct)
            .with_previous(Previous {
                scene: scene.clone(),
                triangle_map: identity,
                gather: Some(self.old_lookup()),
                focus: None,
            })
        };
        self.baker = Some(baker);
    }

    /// Estimates up to `max_points` points of the edited `scene`; returns true once the
    /// re-baked cache is complete.
    pub fn step(&mut self, scene: &Arc<TracedScene>, max_points: usize) -> bool {
        if self.done.finished {
            return true;
        }
        if self.baker.is_none() {
            self.start_stage(scene);
        }
        let Some(baker) = self.baker.as_mut() else {
            return false;
        };
        if !baker.step(scene, max_points) {
            return false;
        }
        let Some(baker) = self.baker.take() else {
            return false;
        };
        let p = *baker.progress();
        self.done.samples += p.samples;
        self.done.rays += p.rays;
        self.done.pass = self.stage;
        self.done.current = p;
        let cache = Arc::new(baker.into_cache());
        if self.stage == 0 {
            self.direct = Some(cache);
            self.stage = 1;
            return false;
        }
        self.result = Some(cache);
        self.done.finished = true;
        true
    }

    /// The cache after stage 0 (the direct change), once that stage is done.
    pub fn direct_stage(&self) -> Option<&Arc<Cache>> {
        self.direct.as_ref()
    }

    /// Progress so far (stage 0: direct change, stage 1: indirect change).
    pub fn progress(&self) -> JobProgress {
        let mut p = self.done;
        if let Some(b) = &self.baker {
            p.pass = self.stage;
            p.current = *b.progress();
            p.samples += p.current.samples;
            p.rays += p.current.rays;
        }
        p
    }

    /// The re-baked cache as a one-pass outcome (the gathering pre-passes of the bake
    /// before the edit are stale and dropped), once [`Self::step`] returned true.
    pub fn into_outcome(self) -> Option<BakeOutcome> {
        let cache = self.result?;
        Some(BakeOutcome {
            passes: vec![cache],
            settings: self.before.settings,
            progress: self.done,
        })
    }
}
