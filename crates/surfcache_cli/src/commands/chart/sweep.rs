//! One scene's sweep of `surfcache chart`: every (sampler, bound, method) point in turn,
//! skipped when its curve stopped or the scene's caps say so, else baked through the same
//! path as `surfcache bake` and measured against the scene's reference.

use super::{Measured, Row, SceneSpec, describe_settings, write_csv};
use crate::{
    baking::{self, BakeOptions},
    commands::compare::compare,
    points::{ResultRow, lookup_points, read_points, read_results},
    scene_args::LoadedWorld,
};
use anyhow::{Result, bail};
use glam::Vec3;
use std::{
    collections::BTreeMap,
    fmt::Write as _,
    path::Path,
    sync::{Arc, Mutex},
    time::{Duration, Instant},
};
use surfcache_cache::{Cache, Method, SurfaceCache, bake::JobProgress};
use surfcache_trace::{Query, Sampler, TracedScene};

/// What the sweeps of every scene share: the curves, the seed and threads of every bake,
/// the point limit, and the CSV each finished point is written to at once.
pub(super) struct SweepPlan<'a> {
    pub methods: &'a [Method],
    pub samplers: &'a [Sampler],
    pub seed: u64,
    pub threads: Option<usize>,
    pub points: Option<usize>,
    pub csv_path: &'a Path,
}

/// A curve of the sweep: indices of its method and sampler.
type Curve = (usize, usize);

/// Bakes and measures every point of `spec`'s sweep, sampler by sampler (in the order
/// given), each bound for every method before the next tighter one: under a budget the
/// first samplers' curves come out whole and the later ones keep at least their loose
/// ends. Appends a row per point to `rows` (rewriting the CSV after each) and a line
/// describing the scene to `settings_notes`.
pub(super) fn sweep_scene(
    plan: &SweepPlan,
    spec: &SceneSpec,
    rows: &mut Vec<Row>,
    settings_notes: &mut String,
) -> Result<()> {
    let (queries, reference) = point_set(spec, plan.points)?;
    let reference: Vec<_> = reference
        .iter()
        .map(|r| (r.position, r.irradiance, r.rel_std))
        .collect();
    let start = Instant::now();
    let max = Duration::from_secs_f64(spec.limits.max_seconds);
    let budget = spec.limits.budget_seconds.map(Duration::from_secs_f64);
    let loaded = LoadedWorld::load(&spec.scene, &spec.env)?;
    let scene = loaded.traced()?;
    let note = scene_note(spec, &scene, queries.len(), &reference);
    eprintln!("chart: {note}");
    let _ = writeln!(settings_notes, "- {note}");
    let mut sweep = SceneSweep {
        spec,
        loaded,
        scene,
        queries,
        reference,
        start,
        max,
        budget,
        last: BTreeMap::new(),
        stopped: BTreeMap::new(),
    };
    for (si, &sampler) in plan.samplers.iter().enumerate() {
        for &bound in &spec.limits.bounds {
            for (mi, &method) in plan.methods.iter().enumerate() {
                let row = sweep.point(plan, (mi, si), method, sampler, bound)?;
                rows.push(row);
                write_csv(plan.csv_path, rows)?;
            }
        }
    }
    Ok(())
}

/// The line describing a scene's sweep: its size, its reference (and that reference's
/// own noise in the rel_rms measure) and the settings of its bakes.
fn scene_note(
    spec: &SceneSpec,
    scene: &TracedScene,
    points: usize,
    reference: &[(Vec3, Vec3, Option<f32>)],
) -> String {
    let own_noise = compare(
        &reference.iter().map(|r| (r.0, r.1)).collect::<Vec<_>>(),
        reference,
    );
    let noise = own_noise
        .reference_noise
        .map_or("unknown".into(), |s| format!("{:.2} %", 100.0 * s));
    format!(
        "{}: {} triangles, {} reference points ({} lit), the reference's own noise in the rel_rms measure {noise}; {}",
        spec.name,
        scene.triangle_count(),
        points,
        own_noise.points,
        describe_settings(spec)
    )
}

/// The point set and reference of a scene, the first `limit` rows.
fn point_set(spec: &SceneSpec, limit: Option<usize>) -> Result<(Vec<Query>, Vec<ResultRow>)> {
    let mut queries = read_points(&spec.points)?;
    let mut reference = read_results(&spec.reference)?;
    if queries.len() != reference.len() {
        bail!(
            "'{}' has {} points but '{}' has {} rows",
            spec.points.display(),
            queries.len(),
            spec.reference.display(),
            reference.len()
        );
    }
    if let Some(n) = limit {
        queries.truncate(n);
        reference.truncate(n);
    }
    if let Some(i) = queries
        .iter()
        .zip(&reference)
        .position(|(q, r)| (q.position - r.position).length() > 1e-5 * (1.0 + r.position.length()))
    {
        bail!(
            "row {} of '{}' is not at the point of '{}'",
            i + 1,
            spec.reference.display(),
            spec.points.display()
        );
    }
    if queries.is_empty() {
        bail!("'{}' has no points", spec.points.display());
    }
    Ok((queries, reference))
}

/// One scene's sweep in progress.
struct SceneSweep<'a> {
    spec: &'a SceneSpec,
    loaded: LoadedWorld,
    scene: Arc<TracedScene>,
    queries: Vec<Query>,
    /// (position, irradiance, relative standard deviation) of each reference point.
    reference: Vec<(Vec3, Vec3, Option<f32>)>,
    /// When the sweep started (its budget counts from here).
    start: Instant,
    /// Each bake's cap.
    max: Duration,
    budget: Option<Duration>,
    /// Per curve: the last finished bake (bound, seconds).
    last: BTreeMap<Curve, (f32, f64)>,
    /// Per curve: why its tighter bounds are skipped.
    stopped: BTreeMap<Curve, String>,
}

impl SceneSweep<'_> {
    /// The row of one point of `curve`: skipped, abandoned, or baked and measured.
    fn point(
        &mut self,
        plan: &SweepPlan,
        curve: Curve,
        method: Method,
        sampler: Sampler,
        bound: f32,
    ) -> Result<Row> {
        let spec = self.spec;
        let mut row = Row {
            scene: spec.name.into(),
            method: method.name().into(),
            sampler: sampler.name().into(),
            bound,
            seconds: 0.0,
            measured: None,
            note: String::new(),
        };
        if let Some(why) = self.skip_reason(curve, bound) {
            eprintln!(
                "chart: {} {} {} bound {bound}: skipped ({why})",
                spec.name,
                method.name(),
                sampler.name()
            );
            row.note = why;
            return Ok(row);
        }
        let options = bake_options(method, sampler, bound, plan.seed);
        let elapsed_at_start = self.start.elapsed();
        let reached = Mutex::new(JobProgress::default());
        let (max, budget) = (self.max, self.budget);
        let stop = |t: Duration, p: &JobProgress| {
            if let Ok(mut r) = reached.lock() {
                *r = *p;
            }
            t > max || budget.is_some_and(|b| elapsed_at_start + t > b)
        };
        let started = Instant::now();
        let baked = baking::bake(&mut self.loaded, options.settings()?, plan.threads, &stop)?;
        let Some(baked) = baked else {
            let t = started.elapsed().as_secs_f64();
            let progress = reached.into_inner().unwrap_or_default();
            let why = abandon_reason(t, &progress, spec.limits.max_seconds);
            eprintln!(
                "chart: {} {} {} bound {bound}: {why}; tighter bounds skipped",
                spec.name,
                method.name(),
                sampler.name()
            );
            row.seconds = t;
            row.note = why.clone();
            self.stopped
                .insert(curve, format!("a looser bound was {why}"));
            return Ok(row);
        };
        let m = self.measure(&baked.cache);
        eprintln!(
            "chart: {} {} {} bound {bound}: {:.1} s, rel_rms {:.4}, median {:.4}, p90 {:.4}, {} bytes, {} sample points",
            spec.name,
            method.name(),
            sampler.name(),
            baked.seconds,
            m.rel_rms,
            m.median_rel,
            m.p90_rel,
            m.bytes,
            m.sample_points
        );
        row.seconds = baked.seconds;
        row.measured = Some(m);
        self.last.insert(curve, (bound, baked.seconds));
        Ok(row)
    }

    /// A finished bake's cache measured at the scene's points against its reference (the
    /// figures `surfcache compare` reports), with its size.
    fn measure(&self, cache: &Cache) -> Measured {
        let values = lookup_points(&self.scene, cache, &self.queries);
        let result: Vec<_> = self
            .queries
            .iter()
            .zip(&values)
            .map(|(q, v)| (q.position, v.unwrap_or(Vec3::NAN)))
            .collect();
        let c = compare(&result, &self.reference);
        let stats = cache.stats();
        Measured {
            rel_rms: c.rel_rms,
            bytes: stats.cache_bytes,
            sample_points: stats.sample_points,
            median_rel: c.median_rel,
            p90_rel: c.p90_rel,
        }
    }

    /// Why the point of `curve` at `bound` is not baked: its curve stopped, the scene's
    /// budget is spent, or its predicted time exceeds the scene's cap. `None`: bake it.
    fn skip_reason(&self, curve: Curve, bound: f32) -> Option<String> {
        if let Some(why) = self.stopped.get(&curve) {
            Some(why.clone())
        } else if self.budget.is_some_and(|b| self.start.elapsed() >= b) {
            Some("the scene's --budget-seconds was spent".to_string())
        } else if let Some(&(b0, t0)) = self.last.get(&curve) {
            // Time grows with the square of 1/bound once sampling dominates, more slowly
            // while fixed costs (minimum samples, pre-passes) do: growing linearly is the
            // cautious guess.
            let predicted = t0 * (b0 as f64 / bound as f64);
            (predicted > self.spec.limits.max_seconds).then(|| {
                format!(
                    "predicted at least {predicted:.0} s (from {t0:.0} s at bound {b0}) > the scene's cap (--max-seconds)"
                )
            })
        } else {
            None
        }
    }
}

/// The options of one bake of the sweep: every setting but the method, the sampler and
/// the bound as `surfcache bake` has it by default.
fn bake_options(method: Method, sampler: Sampler, bound: f32, seed: u64) -> BakeOptions {
    BakeOptions::defaults(method, sampler, bound, seed)
}

/// Why a bake stopped after `t` seconds at `progress`: over the scene's cap
/// `max_seconds`, or out of the scene's budget.
fn abandon_reason(t: f64, progress: &JobProgress, max_seconds: f64) -> String {
    let p = progress;
    let (done, pending) = (p.current.points_done, p.current.points_pending);
    let rate = if p.pass + 1 == p.passes && done > 0 {
        format!(
            "; its current round alone would take about {:.0} min at this rate",
            t * (done + pending) as f64 / done as f64 / 60.0
        )
    } else {
        String::new()
    };
    let at = format!(
        "pass {}/{}, {done} points done, {pending} pending{rate}",
        p.pass + 1,
        p.passes,
    );
    if t > max_seconds {
        format!("abandoned after {t:.0} s ({at}) > the scene's cap")
    } else {
        format!("abandoned after {t:.0} s ({at}): the scene's --budget-seconds ran out")
    }
}
