//! Incremental re-bakes after a scene edit (docs/design.md, Incremental re-baking).
//!
//! A re-bake starts from the finished cache of the scene before the edit, remapped onto
//! the edited scene ([`SurfaceCache::remap`]: samples of surviving triangles keep their
//! values as priors, new triangles get fresh samples), and updates it in stages of
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
//! 2. **Indirect change**, [`INDIRECT_STAGES`] times. Surfaces whose irradiance changed
//!    in the stage before (a shadow that moved, a wall that sees the moved object, the
//!    moved object itself, whose first-stage radiance was its old one) relight
//!    everything that sees them: stage k adds `∫ ρ/π · (E_k(y) − E_{k−1}(y)) ⟨ν, ω⟩ dω`
//!    (E_0 = the old cache), estimated with the same directions for both lookups in the
//!    edited scene: exactly zero where no seen surface changed. Each stage carries the
//!    change one bounce further; the residual shrinks by the albedo times the share of
//!    the hemisphere that changed. Three stages matter where two surfaces end up facing
//!    each other closely (the Cornell box's short block moved next to the tall one: one
//!    stage is not enough there; docs/results.md, "Incremental re-bakes", has the figures).
//!
//!    Each indirect stage first bounds its integrand from every stored sample of both
//!    caches ([`triangle_changes`]: the largest change anywhere on each triangle),
//!    binned into [`ChangeBound`]'s cells, each a bounding sphere with the largest
//!    `ΔL = ρ/π · ΔE` of its triangles. A point whose bound `Σ ΔL_c ∫_cone cos dω` is
//!    within [`SKIP_SHARE`] of its error bound keeps its value without a ray;
//!    the others integrate over the cone towards the cells that carry the rest. Far from
//!    a small edit (a vase moved in a large hall) most points are skipped this way.
//!
//! **Which points a stage touches.** Before each stage, its sources (the edited
//! surfaces, then the surfaces whose irradiance the stage before changed) are traced
//! forward ([`Influence`]; the indirect stages' sources texel by texel for lightmaps,
//! [`change_patches`]). A point keeps its value, with no ray traced and no noise
//! added, unless the forward hits near it estimate a change above its share of the error
//! bound, a bright light's shadow from a source falls near it, or it lies on an edited
//! surface. A point found buried stays buried in the indirect stages (no surface moves
//! there): its filled value is filled in again from its neighbours. In a level, the points that face an edited prop but do not see it, most of
//! them, are left alone this way.
//!
//! Points where estimating the change is dearer than estimating E afresh (a shadow moved
//! onto them) are estimated afresh ([`surfcache_trace::estimate_change`]).
//!
//! Left out: points the forward rays miss although their change exceeds their share
//! (module docs of [`Influence`]); changes that reach a sample over more bounces off the
//! edited region than the stages carry, i.e. `ρ/π ∫ (E_new − E_last)(y)`; per indirect stage and point at
//! most [`SKIP_SHARE`] × the stage's bound × (E + ε), proven by
//! [`ChangeBound`]; and the noise of the change estimates, bounded by
//! [`surfcache_trace::irradiance::CHANGE_ERROR_SHARE`] of the error bound each. Refinement (irradiance maps) continues as in a full bake where the
//! updated values call for it.

mod influence;

pub use influence::{
    BRIGHT_FACTOR, ChangePatch, Influence, MAX_RAYS, MIN_RAYS, RAYS_PER_DISC, RAYS_PER_TRIANGLE,
    Side,
};

use crate::{
    Cache, SurfaceCache, UNMAPPED,
    bake::{BakeOutcome, Baker, JobProgress, Previous, TRACE_PASSES_VAR, step_pass},
    stored_rgb::difference_beyond,
};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::{f32::consts::PI, sync::Arc, time::Instant};
use surfcache_core::sampling::{Cone, splitmix64};
use surfcache_trace::{
    EstimatorSettings, IrradianceLookup, TracedScene, irradiance::CHANGE_ERROR_SHARE,
};

/// Indirect-change stages after the direct one: each propagates the previous stage's
/// change by one more bounce (module docs).
pub const INDIRECT_STAGES: u32 = 3;

/// The error bound of the indirect stages relative to the bake's.
pub const INDIRECT_ERROR_FACTOR: f32 = 2.0;

/// The share of a point's error bound (`bound · (E + ε)`, E's dimmest channel) that a
/// stage may leave out there: where the stage's [`Influence`] or (indirect stages)
/// [`ChangeBound`] finds the change smaller, the point keeps its value; otherwise the
/// change is integrated over the cone towards the cells that carry all but this much
/// of it.
pub const SKIP_SHARE: f32 = 0.25;

/// Cells per axis of [`ChangeBound`]'s grid.
pub const CHANGE_CELLS: usize = 8;

/// What an edit changed, in the terms a re-bake needs.
#[derive(Clone, Debug)]
pub struct Edit {
    /// `triangle_map[t_new]`: the triangle before the edit ([`crate::triangle_map`]).
    pub triangle_map: Arc<Vec<u32>>,
    /// A box (min, max) holding every surface that moved, appeared, disappeared or
    /// changed material, before and after the edit.
    pub region: (Vec3, Vec3),
    /// Those surfaces' triangles in the scene before the edit and in the edited one.
    pub changed_old: Arc<Vec<u32>>,
    pub changed_new: Arc<Vec<u32>>,
}

impl Edit {
    /// The edit that turns `old` into `new`: instance `i` of `new` is instance
    /// `instance_map[i]` of `old` (`None`: new), and `changed_old(k)` / `changed_new(k)`
    /// say which instances of each scene moved, appeared, disappeared or changed material.
    /// `None` when those instances hold no triangle.
    pub fn between(
        old: &TracedScene,
        new: &TracedScene,
        instance_map: &[Option<u32>],
        changed_old: impl Fn(usize) -> bool,
        changed_new: impl Fn(usize) -> bool,
    ) -> Option<Self> {
        let triangles = |scene: &TracedScene, changed: &dyn Fn(usize) -> bool| -> Vec<u32> {
            (0..scene.instance_triangles().len())
                .filter(|&k| changed(k))
                .flat_map(|k| scene.instance_triangles()[k].clone())
                .collect()
        };
        let (changed_old, changed_new) =
            (triangles(old, &changed_old), triangles(new, &changed_new));
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for (scene, list) in [(old, &changed_old), (new, &changed_new)] {
            for &t in list {
                for p in scene.positions()[t as usize] {
                    (lo, hi) = (lo.min(p), hi.max(p));
                }
            }
        }
        if changed_old.is_empty() && changed_new.is_empty() {
            return None;
        }
        Some(Self {
            triangle_map: Arc::new(crate::triangle_map(old, new, instance_map)),
            region: (lo, hi),
            changed_old: Arc::new(changed_old),
            changed_new: Arc::new(changed_new),
        })
    }

    /// Changed triangles before and after the edit, counted together.
    pub fn changed_triangles(&self) -> usize {
        self.changed_old.len() + self.changed_new.len()
    }
}

/// A cache of the scene before an edit, looked up on the edited scene's triangles
/// (zero on triangles that did not exist before).
pub struct MappedLookup {
    pub cache: Arc<Cache>,
    pub triangle_map: Arc<Vec<u32>>,
}

impl IrradianceLookup for MappedLookup {
    fn irradiance(&self, triangle: u32, uv: Vec2, front: bool) -> Option<Vec3> {
        match self.triangle_map.get(triangle as usize) {
            Some(&t) if t != UNMAPPED => self.cache.irradiance(t, uv, front),
            _ => Some(Vec3::ZERO),
        }
    }

    fn albedo_footprint(&self) -> f32 {
        self.cache.albedo_footprint()
    }
}

/// A re-bake of a finished bake after an edit (module docs).
pub struct IncrementalJob {
    before: BakeOutcome,
    old_scene: Arc<TracedScene>,
    edit: Edit,
    stage: u32,
    baker: Option<Baker<Cache>>,
    /// The cache after each finished stage.
    stages: Vec<Arc<Cache>>,
    /// The running stage's influence.
    influence: Option<Arc<Influence>>,
    /// When the running stage started, and the seconds its start took (remap, change
    /// sources, forward rays): reported with `SURFCACHE_TRACE_PASSES`.
    stage_clock: Option<(Instant, f64)>,
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
            stages: Vec::new(),
            influence: None,
            stage_clock: None,
            done: JobProgress {
                passes: 1 + INDIRECT_STAGES,
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

    /// The smallest radius R within which forward hits count for a point
    /// ([`Influence`]): the cache's sample spacing, or for vertex lighting a 256th of the
    /// scene's diagonal.
    fn sample_spacing(&self, scene: &TracedScene) -> f32 {
        match self.before.settings.cache.density() {
            Some(d) if d > 0.0 => 1.0 / d,
            _ => scene.diagonal() / 256.0,
        }
    }

    fn start_stage(&mut self, scene: &Arc<TracedScene>) {
        let baker = if self.stage == 0 {
            self.start_direct_stage(scene)
        } else {
            self.start_indirect_stage(scene, self.stage as usize)
        };
        self.baker = Some(baker);
    }

    /// Stage 0, the direct change: the cache remapped onto the edited scene; each point
    /// estimates the change it gets through the directions towards the box around the
    /// edit, where the edit's forward rays say it may exceed its error share.
    fn start_direct_stage(&mut self, scene: &Arc<TracedScene>) -> Baker<Cache> {
        let settings = self.before.settings;
        let (lo, hi) = self.edit.region;
        let sphere = (
            0.5 * (lo + hi),
            0.5 * (hi - lo).length() + scene.spawn_offset(),
        );
        let cache = self
            .before
            .cache()
            .remap(&self.old_scene, scene, &self.edit.triangle_map);
        let influence = Arc::new(Influence::of_edit(
            &self.old_scene,
            scene,
            self.before.cache().as_ref(),
            self.old_lookup().as_ref(),
            &self.edit.changed_old,
            &self.edit.changed_new,
            self.sample_spacing(scene),
            settings.seed,
        ));
        self.influence = Some(influence.clone());
        Baker::new(cache, settings.estimator, settings.seed)
            .with_gather(self.old_lookup())
            .with_previous(Previous {
                scene: self.old_scene.clone(),
                triangle_map: self.edit.triangle_map.clone(),
                gather: Some(self.before.cache().clone()),
                focus: Some(sphere),
                bound: None,
                influence: Some(influence),
                geometry_changed: true,
            })
    }

    /// Stage `k` ≥ 1, the indirect change one bounce further: what stage k − 1 changed,
    /// gathered from its cache against the one before it.
    fn start_indirect_stage(&mut self, scene: &Arc<TracedScene>, k: usize) -> Baker<Cache> {
        let settings = self.before.settings;
        let latest = self.stages[k - 1].clone();
        let before: Arc<dyn IrradianceLookup + Send> = match k {
            1 => self.old_lookup(),
            _ => self.stages[k - 2].clone(),
        };
        let identity: Arc<Vec<u32>> = Arc::new((0..scene.triangle_count() as u32).collect());
        let cache = latest.remap(scene, scene, &identity);
        // Indirect changes are a bounce weaker than the direct one: their estimates
        // may carry twice the error share (INDIRECT_ERROR_FACTOR).
        let estimator = EstimatorSettings {
            max_rel_error: settings.estimator.max_rel_error * INDIRECT_ERROR_FACTOR,
            ..settings.estimator
        };
        // What the stage integrates, ρ/π·(E_k − E_{k−1}) at first hits, bounded from
        // every stored sample of both caches.
        // A change within twice the noise the stage before may have left in its
        // estimates ([`CHANGE_ERROR_SHARE`] of its bound) is not passed on: noise
        // would otherwise spread one stage further each time.
        let noise = |bound: f32| 2.0 * CHANGE_ERROR_SHARE * bound;
        let (before_cache, map) = match k {
            1 => (self.before.cache(), &self.edit.triangle_map),
            _ => (&self.stages[k - 2], &identity),
        };
        let share = noise(match k {
            1 => settings.estimator.max_rel_error,
            _ => estimator.max_rel_error,
        });
        let changes = triangle_changes(&latest, before_cache, map, share);
        let patches = change_patches(scene, &latest, before_cache, map, &changes, share);
        let bound = ChangeBound::new(scene, &changes);
        // Changes a quarter of the smallest allowance at most, all of them together.
        let negligible = 0.25 * SKIP_SHARE * estimator.max_rel_error * estimator.floor;
        let influence = Arc::new(Influence::of_changes(
            scene,
            latest.as_ref(),
            before.as_ref(),
            &patches,
            negligible,
            self.sample_spacing(scene),
            settings.seed ^ k as u64,
        ));
        self.influence = Some(influence.clone());
        Baker::new(
            cache,
            estimator,
            settings.seed ^ splitmix64(0x696e_6469_7265_6374 + k as u64),
        )
        .with_gather(latest)
        .with_previous(Previous {
            scene: scene.clone(),
            triangle_map: identity,
            gather: Some(before),
            focus: None,
            bound: Some(Arc::new(bound)),
            influence: Some(influence),
            geometry_changed: false,
        })
    }

    /// Estimates up to `max_points` points of the edited `scene`; returns true once the
    /// re-baked cache is complete.
    pub fn step(&mut self, scene: &Arc<TracedScene>, max_points: usize) -> bool {
        if self.done.finished {
            return true;
        }
        if self.baker.is_none() {
            let start = Instant::now();
            self.start_stage(scene);
            self.stage_clock = Some((start, start.elapsed().as_secs_f64()));
        }
        let Some(cache) = step_pass(
            &mut self.baker,
            scene,
            max_points,
            self.stage,
            &mut self.done,
        ) else {
            return false;
        };
        if let Some(influence) = self.influence.take()
            && std::env::var_os(TRACE_PASSES_VAR).is_some()
        {
            let (start, setup) = self.stage_clock.take().unwrap_or((Instant::now(), 0.0));
            eprintln!(
                "[stage {}] {:.1} s (start {setup:.1} s) {}",
                self.stage,
                start.elapsed().as_secs_f64(),
                influence.report()
            );
        }
        let cache = Arc::new(cache);
        if self.stage < INDIRECT_STAGES {
            self.stages.push(cache);
            self.stage += 1;
            return false;
        }
        self.result = Some(cache);
        self.done.finished = true;
        true
    }

    /// The cache after stage 0 (the direct change), once that stage is done.
    pub fn direct_stage(&self) -> Option<&Arc<Cache>> {
        self.stages.first()
    }

    /// Progress so far (stage 0: direct change, later stages: indirect change).
    pub fn progress(&self) -> JobProgress {
        self.done.with_running(self.stage, self.baker.as_ref())
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

/// Per triangle of `after`'s scene: the largest change, in any channel and on either
/// side, between lookups of `after` on it and of `before` on `triangle_map[t]`
/// (zero where the triangle did not exist before), anywhere on the triangle, leaving out
/// differences within `share` of the values ([`difference_beyond`]: at least storage
/// precision; a re-bake passes the noise its change estimates may carry). Exact for
/// vertex lighting and irradiance maps (both interpolate linearly between grid nodes, so
/// the difference peaks at the nodes of the finer grid) and an upper bound for lightmaps
/// (the texels a lookup can read).
pub fn triangle_changes(
    after: &Cache,
    before: &Cache,
    triangle_map: &[u32],
    share: f32,
) -> Vec<f32> {
    if let (Cache::Lightmap(a), Cache::Lightmap(b)) = (after, before) {
        return a.triangle_changes(b, triangle_map, share);
    }
    let order = |cache: &Cache, t: u32, front: bool| match cache {
        Cache::IrradianceMap(m) => m.order(t, front),
        _ => 1,
    };
    (0..triangle_map.len() as u32)
        .into_par_iter()
        .map(|t| {
            let t_old = triangle_map[t as usize];
            let mut change = 0.0f32;
            for front in [true, false] {
                let n_old = match t_old {
                    UNMAPPED => 0,
                    _ => order(before, t_old, front),
                };
                let n = order(after, t, front).max(n_old).max(1);
                for i in 0..=n {
                    for j in 0..=n - i {
                        let uv = Vec2::new(i as f32, j as f32) / n as f32;
                        let old = match t_old {
                            UNMAPPED => Vec3::ZERO,
                            _ => before.lookup(t_old, uv, front),
                        };
                        let new = after.lookup(t, uv, front);
                        // An unbaked side (NaN lookups) may hold anything.
                        change = change.max(if (new - old).is_finite() {
                            difference_beyond(new, old, share).max_element()
                        } else {
                            f32::INFINITY
                        });
                    }
                }
            }
            change
        })
        .collect()
}

/// The patches whose irradiance changed between `before` (looked up on
/// `triangle_map[t]`) and `after`, as sources of an indirect stage's forward rays
/// ([`Influence::of_changes`]): every texel of a lightmap that changed beyond `share`
/// ([`Lightmaps::texel_changes`](crate::lightmap::Lightmaps::texel_changes)), every
/// sample of an irradiance map that did
/// ([`IrradianceMaps::sample_changes`](crate::IrradianceMaps::sample_changes)), for
/// vertex lighting both sides of every triangle with its largest change `changes[t]`
/// ([`triangle_changes`]).
pub fn change_patches(
    scene: &TracedScene,
    after: &Cache,
    before: &Cache,
    triangle_map: &[u32],
    changes: &[f32],
    share: f32,
) -> Vec<ChangePatch> {
    match (after, before) {
        (Cache::Lightmap(a), Cache::Lightmap(b)) => {
            return a.texel_changes(scene, b, triangle_map, share);
        }
        (Cache::IrradianceMap(a), Cache::IrradianceMap(b)) => {
            return a.sample_changes(scene, b, triangle_map, share);
        }
        _ => {}
    }
    (0..changes.len() as u32)
        .filter(|&t| changes[t as usize] > 0.0 || changes[t as usize].is_nan())
        .map(|t| ChangePatch::whole_triangle(scene, t, changes[t as usize]))
        .collect()
}

/// A box (min, max) around every triangle that an edit moved, added or removed: those of
/// `new` without a counterpart in `old` (`triangle_map`) or with other corners, and those
/// of `old` that no triangle of `new` maps to. `None` when none did.
pub fn changed_region(
    old: &TracedScene,
    new: &TracedScene,
    triangle_map: &[u32],
) -> Option<(Vec3, Vec3)> {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    let mut add = |corners: [Vec3; 3]| {
        for p in corners {
            (lo, hi) = (lo.min(p), hi.max(p));
        }
    };
    let mut kept = vec![false; old.triangle_count()];
    for (t, &corners) in new.positions().iter().enumerate() {
        let t_old = triangle_map.get(t).copied().unwrap_or(UNMAPPED);
        match old.positions().get(t_old as usize) {
            Some(&before) => {
                kept[t_old as usize] = true;
                if before != corners {
                    add(before);
                    add(corners);
                }
            }
            None => add(corners),
        }
    }
    for (t_old, &corners) in old.positions().iter().enumerate() {
        if !kept[t_old] {
            add(corners);
        }
    }
    (lo.x <= hi.x).then_some((lo, hi))
}

/// Whether the box `lo..=hi` comes within `reach` (per axis) of `region`, the box of
/// [`changed_region`] (`None`: nothing changed). A re-bake carries crossing probes only
/// where it does not.
pub fn near_changed_region(region: Option<(Vec3, Vec3)>, lo: Vec3, hi: Vec3, reach: Vec3) -> bool {
    region.is_some_and(|(r_lo, r_hi)| lo.cmple(r_hi + reach).all() && hi.cmpge(r_lo - reach).all())
}

/// A bound on the change an indirect stage integrates, `ΔL(y) = ρ(y)/π · ΔE(y)` at first
/// hits y: the changed triangles binned into a uniform grid of [`CHANGE_CELLS`]³ cells
/// over their bounds, each cell with a bounding sphere and the largest ΔL of its
/// triangles (ρ: the material's albedo factor; textures only scale it down).
pub struct ChangeBound {
    /// Per non-empty cell: bounding sphere (centre, radius), the largest ΔL of its
    /// triangles, and Σ ΔL_t · area_t over them.
    cells: Vec<ChangeCell>,
}

#[derive(Clone, Copy, Debug)]
struct ChangeCell {
    centre: Vec3,
    radius: f32,
    radiance: f32,
    flux: f32,
}

impl ChangeCell {
    /// A bound on `∫ |ΔL| cos θ dω` over the cell's triangles seen from `origin` above
    /// the plane of `normal`: with `c` the largest cos θ in the cone towards the cell's
    /// sphere, the cell's largest ΔL times `min(Ω · c, π)` ([`cone_cosine_bound`]), or,
    /// from outside the sphere, `c · Σ ΔL_t · Ω_t` with each triangle's solid angle
    /// `Ω_t ≤ area_t / d²`, d the distance to the sphere.
    fn bound(&self, origin: Vec3, normal: Vec3) -> f32 {
        let cone = Cone::towards_sphere(origin, self.centre, self.radius);
        let (weight, cos_max) = cone_cosine_bound(&cone, normal);
        let sphere = self.radiance * weight;
        let d = origin.distance(self.centre) - self.radius;
        if d > 0.0 && sphere > 0.0 {
            sphere.min(cos_max * self.flux / (d * d))
        } else {
            sphere
        }
    }
}

/// What a point of an indirect stage needs ([`ChangeBound::plan`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ChangePlan {
    /// The change is proven below the allowance: keep the value.
    Unchanged,
    /// Integrate over this cone only (what lies outside is below the allowance).
    Cone(Cone),
    /// Integrate over the whole hemisphere.
    Hemisphere,
}

impl ChangeBound {
    /// The bound for per-triangle changes of irradiance `changes` ([`triangle_changes`]).
    pub fn new(scene: &TracedScene, changes: &[f32]) -> Self {
        let changed: Vec<u32> = (0..changes.len() as u32)
            .filter(|&t| changes[t as usize] > 0.0)
            .collect();
        let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for &t in &changed {
            for p in scene.positions()[t as usize] {
                (lo, hi) = (lo.min(p), hi.max(p));
            }
        }
        let n = CHANGE_CELLS;
        let extent = (hi - lo).max(Vec3::splat(f32::MIN_POSITIVE));
        let mut boxes =
            vec![(Vec3::splat(f32::MAX), Vec3::splat(f32::MIN), 0.0f32, 0.0f32); n * n * n];
        for &t in &changed {
            let [a, b, c] = scene.positions()[t as usize];
            let centroid = (a + b + c) / 3.0;
            let cell = ((centroid - lo) / extent * n as f32)
                .as_uvec3()
                .min(glam::UVec3::splat(n as u32 - 1));
            let (blo, bhi, l, flux) =
                &mut boxes[(cell.z as usize * n + cell.y as usize) * n + cell.x as usize];
            *blo = blo.min(a.min(b).min(c));
            *bhi = bhi.max(a.max(b).max(c));
            let albedo = scene.material_of(t).albedo.max_element().max(0.0);
            let radiance = albedo / PI * changes[t as usize];
            *l = l.max(radiance);
            *flux += radiance * surfcache_core::geometry::triangle_area(a, b, c);
        }
        let pad = scene.spawn_offset();
        let cells = boxes
            .into_iter()
            .filter(|&(_, _, l, _)| l > 0.0)
            .map(|(blo, bhi, radiance, flux)| ChangeCell {
                centre: 0.5 * (blo + bhi),
                radius: 0.5 * (bhi - blo).length() + pad,
                radiance,
                flux,
            })
            .collect();
        Self { cells }
    }

    /// A bound on `|∫ ΔL cos θ dω|` over the hemisphere of `normal` at `origin`: the sum
    /// of every cell's bound (`ChangeCell::bound`).
    pub fn bound(&self, origin: Vec3, normal: Vec3) -> f32 {
        self.cells.iter().map(|c| c.bound(origin, normal)).sum()
    }

    /// The plan for the point at `origin` with unit normal `normal` that may leave out a
    /// change of `allowance` (W/m²). `|∫ ΔL cos θ dω| ≤ Σ_c ∫_c |ΔL| cos θ dω`, each
    /// cell's part bounded by `ChangeCell::bound`. If the sum is within the allowance, nothing is estimated; else the
    /// cells with the smallest contributions, together within it, are left out of the
    /// cone the change is integrated over.
    pub fn plan(&self, origin: Vec3, normal: Vec3, allowance: f32) -> ChangePlan {
        // A bound that is not a number (an unknown change) never skips.
        if self.bound(origin, normal) <= allowance {
            return ChangePlan::Unchanged;
        }
        // Only points that are estimated get here (and then trace at least
        // `CHANGE_MIN_SAMPLES` pairs): the cells' parts again, sorted.
        let mut parts: Vec<(f32, usize)> = self
            .cells
            .iter()
            .enumerate()
            .map(|(i, cell)| (cell.bound(origin, normal), i))
            .filter(|&(w, _)| w > 0.0)
            .collect();
        parts.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut left_out = 0.0;
        let mut first = 0;
        while first < parts.len() && left_out + parts[first].0 <= allowance {
            left_out += parts[first].0;
            first += 1;
        }
        let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for &(_, i) in &parts[first..] {
            let ChangeCell { centre, radius, .. } = self.cells[i];
            (lo, hi) = (lo.min(centre - radius), hi.max(centre + radius));
        }
        let cone = Cone::towards_sphere(origin, 0.5 * (lo + hi), 0.5 * (hi - lo).length());
        if cone.cos_max <= 0.0 {
            ChangePlan::Hemisphere
        } else {
            ChangePlan::Cone(cone)
        }
    }
}

/// `∫_{cone ∩ H} cos θ dω ≤ min(Ω · cos θ_min, π)` over the hemisphere H of `normal`, θ_min
/// the smallest angle between the normal and a direction of the cone, and cos θ_min
/// itself; (0, 0) when the cone lies below the surface.
fn cone_cosine_bound(cone: &Cone, normal: Vec3) -> (f32, f32) {
    if cone.cos_max <= -1.0 {
        return (PI, 1.0);
    }
    if cone.below(normal) {
        return (0.0, 0.0);
    }
    // cos(θ − α) from the cosines alone: θ between the normal and the axis, α the
    // cone's half-angle.
    let cos_theta = normal.dot(cone.axis).clamp(-1.0, 1.0);
    let cos_min = if cos_theta >= cone.cos_max {
        1.0
    } else {
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let sin_half = (1.0 - cone.cos_max * cone.cos_max).max(0.0).sqrt();
        (cos_theta * cone.cos_max + sin_theta * sin_half).clamp(0.0, 1.0)
    };
    ((cone.solid_angle() * cos_min).min(PI), cos_min)
}

/// The Cornell box before and after moving the instances whose name `moved` accepts by
/// `by`, traced, with the triangle map between them (tests of re-bakes' carried probes).
#[cfg(test)]
pub(crate) fn cornell_moved(
    moved: impl Fn(&str) -> bool,
    by: Vec3,
) -> (TracedScene, TracedScene, Vec<u32>) {
    use surfcache_core::{glam::Affine3A, scenes::cornell};
    let old_scene = cornell();
    let mut new_scene = old_scene.clone();
    for i in &mut new_scene.instances {
        if moved(&i.name) {
            i.transform = Affine3A::from_translation(by) * i.transform;
        }
    }
    let old = TracedScene::new(&old_scene).unwrap();
    let new = TracedScene::new(&new_scene).unwrap();
    let identity: Vec<Option<u32>> = (0..new.instance_triangles().len() as u32)
        .map(Some)
        .collect();
    let map = crate::triangle_map(&old, &new, &identity);
    (old, new, map)
}
