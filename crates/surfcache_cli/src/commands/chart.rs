//! `surfcache chart`: speed against accuracy (docs/design.md, Speed against accuracy). Bakes every method × sampler
//! over a sweep of error bounds, in process through the same bake path as `surfcache bake`,
//! measures each bake's time, cache bytes and sample points, and its per-point relative
//! error against a converged reference at a fixed point set (relative RMS, median and
//! 90th percentile, the figures `surfcache compare` reports), then writes
//! `speed_accuracy.csv`, two log-log charts and a summary. Each scene's panel plots the
//! measure that says most about it ([`panel_measure`]).

use crate::{
    baking::{self, BakeOptions, parse_method, parse_sampler},
    commands::compare::compare,
    points::{ResultRow, lookup_points, read_points, read_results},
    scene_args::{EnvArgs, LoadedWorld},
};
use anyhow::{Context, Result, bail};
use std::{
    collections::BTreeMap,
    fmt::Write as _,
    path::{Path, PathBuf},
    time::{Duration, Instant},
};
use surfcache_cache::{Method, SurfaceCache, bake::JobProgress};
use surfcache_trace::{Query, Sampler};

mod plot;
mod summary;

/// The CSV header of `speed_accuracy.csv`.
pub const CSV_HEADER: &str =
    "scene,method,sampler,bound,seconds,rel_rms,bytes,sample_points,median_rel,p90_rel";

/// The header of CSVs written before the median and 90th percentile were kept (read
/// with those two unknown).
const CSV_HEADER_RMS_ONLY: &str = "scene,method,sampler,bound,seconds,rel_rms,bytes,sample_points";

/// The per-point error a panel of the charts plots.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorMeasure {
    RelRms,
    Median,
}

impl ErrorMeasure {
    /// The measure's value in a measured row (NaN where the CSV did not keep it).
    pub fn of(self, m: &Measured) -> f64 {
        match self {
            ErrorMeasure::RelRms => m.rel_rms,
            ErrorMeasure::Median => m.median_rel,
        }
    }

    /// Axis title.
    pub fn describe(self) -> &'static str {
        match self {
            ErrorMeasure::RelRms => "relative RMS error (log)",
            ErrorMeasure::Median => "median per-point relative error (log)",
        }
    }
}

/// What a scene's panel plots: on a level (Sponza) the median per-point error, which
/// a few contact spots cannot decide; on the Cornell box the relative RMS, as before.
pub fn panel_measure(scene: &str) -> ErrorMeasure {
    match scene {
        "sponza" => ErrorMeasure::Median,
        _ => ErrorMeasure::RelRms,
    }
}

#[derive(clap::Args)]
pub struct ChartArgs {
    /// Folder for speed_accuracy.csv, speed_accuracy_seconds.png, speed_accuracy_bytes.png
    /// and speed_accuracy.md (created).
    #[arg(long, default_value = "docs")]
    out: PathBuf,
    /// Scenes: cornell (built in) and sponza (Crytek Sponza from the shared assets, under
    /// one HDR map; skipped with a message when the assets are absent).
    #[arg(long, value_delimiter = ',', default_value = "cornell,sponza")]
    scenes: Vec<String>,
    /// Error bounds (--max-rel-error of each bake), baked loosest first.
    #[arg(long, value_delimiter = ',', default_value = "0.2,0.1,0.05,0.02,0.01")]
    bounds: Vec<f32>,
    /// Error bounds for Sponza [default: the --bounds].
    #[arg(long, value_delimiter = ',')]
    sponza_bounds: Option<Vec<f32>>,
    /// Hemisphere samplers (uniform, cosine, qmc, mis, best), baked in this order.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "best,uniform,cosine,qmc,mis"
    )]
    samplers: Vec<String>,
    /// Methods (vertex, irradiance-map, lightmap).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "vertex,irradiance-map,lightmap"
    )]
    methods: Vec<String>,
    /// Worker threads [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
    /// The shared assets folder (scenes/sponza_crytek/Sponza.gltf, envmaps/).
    #[arg(long, default_value = "../shared/assets")]
    shared_assets: PathBuf,
    /// The repository's assets folder (cornell_points.csv, cornell_reference.csv,
    /// reference/sponza_visible_points.csv, reference/sponza_visible_immenstadter.csv).
    #[arg(long, default_value = "assets")]
    assets: PathBuf,
    /// A bake still running after this many seconds is abandoned, and the tighter bounds
    /// of its (method, sampler) curve are skipped; so are bounds whose predicted time
    /// (at least the last bake's time × the bound ratio) exceeds it.
    #[arg(long, default_value_t = 120.0)]
    max_seconds: f64,
    /// --max-seconds for Sponza.
    #[arg(long, default_value_t = 300.0)]
    sponza_max_seconds: f64,
    /// Wall-clock budget of each scene's sweep in seconds: once spent, its remaining bakes
    /// are skipped (every curve's loose bounds are baked before any tight ones)
    /// [default: none].
    #[arg(long)]
    budget_seconds: Option<f64>,
    /// --budget-seconds for Sponza [default: --budget-seconds].
    #[arg(long)]
    sponza_budget_seconds: Option<f64>,
    /// Use only the first N points of each point set (and reference).
    #[arg(long)]
    points: Option<usize>,
    /// Random seed of every bake.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Redraw the charts and the summary from OUT/speed_accuracy.csv without baking.
    #[arg(long)]
    replot: bool,
}

/// One scene of the chart and the settings its bakes use.
pub struct SceneSpec {
    pub name: &'static str,
    /// A .gltf path or built-in name.
    scene: String,
    env: EnvArgs,
    points: PathBuf,
    reference: PathBuf,
    max_seconds: f64,
}

/// The HDR map Sponza is lit by (in the shared assets' `envmaps/`): the sunny sky its
/// reference was path-traced under (docs/results.md, "Sponza at the defaults: the
/// reference").
pub const SPONZA_ENV: &str = "immenstadter_horn_1k.exr";

fn scene_spec(name: &str, args: &ChartArgs) -> Result<Option<SceneSpec>> {
    match name {
        "cornell" => Ok(Some(SceneSpec {
            name: "cornell",
            scene: "cornell".into(),
            env: EnvArgs::default(),
            points: args.assets.join("cornell_points.csv"),
            reference: args.assets.join("cornell_reference.csv"),
            max_seconds: args.max_seconds,
        })),
        "sponza" => {
            let gltf = args.shared_assets.join("scenes/sponza_crytek/Sponza.gltf");
            let env = args.shared_assets.join("envmaps").join(SPONZA_ENV);
            if !gltf.is_file() || !env.is_file() {
                eprintln!(
                    "chart: skipping sponza: {} or {} is not there (--shared-assets)",
                    gltf.display(),
                    env.display()
                );
                return Ok(None);
            }
            Ok(Some(SceneSpec {
                name: "sponza",
                scene: gltf.display().to_string(),
                env: EnvArgs {
                    env: Some(env),
                    ..Default::default()
                },
                points: args.assets.join("reference/sponza_visible_points.csv"),
                reference: args
                    .assets
                    .join("reference/sponza_visible_immenstadter.csv"),
                max_seconds: args.sponza_max_seconds,
            }))
        }
        other => bail!("unknown chart scene '{other}' (known: cornell, sponza)"),
    }
}

/// What one (scene, method, sampler, bound) point of the sweep gave.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    pub scene: String,
    pub method: String,
    pub sampler: String,
    pub bound: f32,
    /// Bake seconds; for a skipped point the time spent before it was abandoned (0: not
    /// started).
    pub seconds: f64,
    /// `None` for a skipped point.
    pub measured: Option<Measured>,
    /// Why a point was skipped (not stored in the CSV).
    pub note: String,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measured {
    pub rel_rms: f64,
    pub bytes: u64,
    pub sample_points: u64,
    /// Median and 90th percentile of the per-point relative error (NaN in rows of older
    /// CSVs that did not keep them).
    pub median_rel: f64,
    pub p90_rel: f64,
}

impl Row {
    fn csv(&self) -> String {
        match &self.measured {
            Some(m) => {
                let optional = |v: f64| {
                    if v.is_finite() {
                        format!("{v:.6}")
                    } else {
                        String::new()
                    }
                };
                format!(
                    "{},{},{},{},{:.3},{:.6},{},{},{},{}",
                    self.scene,
                    self.method,
                    self.sampler,
                    self.bound,
                    self.seconds,
                    m.rel_rms,
                    m.bytes,
                    m.sample_points,
                    optional(m.median_rel),
                    optional(m.p90_rel)
                )
            }
            None => format!(
                "{},{},{},{},{:.3},,,,,",
                self.scene, self.method, self.sampler, self.bound, self.seconds
            ),
        }
    }
}

/// Writes the rows as `speed_accuracy.csv` (skipped points: empty error, bytes and
/// sample-point fields; a median or percentile not known: empty).
fn write_csv(path: &Path, rows: &[Row]) -> Result<()> {
    let mut text = String::from(CSV_HEADER);
    text.push('\n');
    for r in rows {
        text.push_str(&r.csv());
        text.push('\n');
    }
    Ok(surfcache_io::write_file_atomically(path, text.as_bytes())?)
}

/// Reads what [`write_csv`] wrote (or a CSV of the older header without the median
/// and 90th percentile).
pub fn read_csv(path: &Path) -> Result<Vec<Row>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read '{}'", path.display()))?;
    let mut lines = text.lines();
    let fields = match lines.next().map(str::trim) {
        Some(CSV_HEADER) => 10,
        Some(CSV_HEADER_RMS_ONLY) => 8,
        _ => bail!("'{}': header must be '{CSV_HEADER}'", path.display()),
    };
    let mut rows = Vec::new();
    for (i, line) in lines.enumerate().filter(|(_, l)| !l.trim().is_empty()) {
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        let bad = || anyhow::anyhow!("'{}' line {}: malformed row", path.display(), i + 2);
        if f.len() != fields {
            return Err(bad());
        }
        let optional = |k: usize| -> Result<f64> {
            match f.get(k) {
                None | Some(&"") => Ok(f64::NAN),
                Some(v) => v.parse().map_err(|_| bad()),
            }
        };
        let measured = if f[5].is_empty() {
            None
        } else {
            Some(Measured {
                rel_rms: f[5].parse().map_err(|_| bad())?,
                bytes: f[6].parse().map_err(|_| bad())?,
                sample_points: f[7].parse().map_err(|_| bad())?,
                median_rel: optional(8)?,
                p90_rel: optional(9)?,
            })
        };
        rows.push(Row {
            scene: f[0].into(),
            method: f[1].into(),
            sampler: f[2].into(),
            bound: f[3].parse().map_err(|_| bad())?,
            seconds: f[4].parse().map_err(|_| bad())?,
            note: if measured.is_some() {
                String::new()
            } else {
                "skipped".into()
            },
            measured,
        });
    }
    Ok(rows)
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

pub fn run(args: ChartArgs) -> Result<()> {
    let csv_path = args.out.join("speed_accuracy.csv");
    if args.replot {
        let rows = read_csv(&csv_path)?;
        return finish(&args.out, &rows, "");
    }
    let methods: Vec<Method> = args
        .methods
        .iter()
        .map(|m| parse_method(m))
        .collect::<Result<_>>()?;
    let samplers: Vec<Sampler> = args
        .samplers
        .iter()
        .map(|s| parse_sampler(s))
        .collect::<Result<_>>()?;
    let sort_bounds = |b: &[f32]| -> Result<Vec<f32>> {
        if b.is_empty() || b.iter().any(|b| !(b.is_finite() && *b > 0.0)) {
            bail!("error bounds must be positive numbers");
        }
        let mut b = b.to_vec();
        b.sort_by(|x, y| y.total_cmp(x));
        b.dedup();
        Ok(b)
    };
    let bounds = sort_bounds(&args.bounds)?;
    let sponza_bounds = match &args.sponza_bounds {
        Some(b) => sort_bounds(b)?,
        None => bounds.clone(),
    };
    if !(args.max_seconds > 0.0 && args.sponza_max_seconds > 0.0) {
        bail!("--max-seconds and --sponza-max-seconds must be positive");
    }
    if args.points == Some(0) {
        bail!("--points must be at least 1");
    }
    let specs: Vec<SceneSpec> = args
        .scenes
        .iter()
        .map(|s| scene_spec(s, &args))
        .collect::<Result<Vec<_>>>()?
        .into_iter()
        .flatten()
        .collect();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create '{}'", args.out.display()))?;
    let run_start = Instant::now();
    let mut rows: Vec<Row> = Vec::new();
    let mut settings_notes = String::new();
    for spec in &specs {
        let (queries, reference) = point_set(spec, args.points)?;
        let reference_values: Vec<_> = reference
            .iter()
            .map(|r| (r.position, r.irradiance, r.rel_std))
            .collect();
        let sweep_start = Instant::now();
        let max = Duration::from_secs_f64(spec.max_seconds);
        let budget = if spec.name == "sponza" {
            args.sponza_budget_seconds.or(args.budget_seconds)
        } else {
            args.budget_seconds
        }
        .map(Duration::from_secs_f64);
        let mut loaded = LoadedWorld::load(&spec.scene, &spec.env)?;
        let scene = loaded.traced()?;
        let own_noise = compare(
            &reference_values
                .iter()
                .map(|r| (r.0, r.1))
                .collect::<Vec<_>>(),
            &reference_values,
        );
        let noise = own_noise
            .reference_noise
            .map_or("unknown".into(), |s| format!("{:.2} %", 100.0 * s));
        let note = format!(
            "{}: {} triangles, {} reference points ({} lit), the reference's own noise in the rel_rms measure {noise}; {}",
            spec.name,
            scene.triangle_count(),
            queries.len(),
            own_noise.points,
            describe_settings(spec)
        );
        eprintln!("chart: {note}");
        let _ = writeln!(settings_notes, "- {note}");
        let scene_bounds = if spec.name == "sponza" {
            &sponza_bounds
        } else {
            &bounds
        };
        // Per curve: the last finished bake (bound, seconds), or why it stopped.
        let mut last: BTreeMap<(usize, usize), (f32, f64)> = BTreeMap::new();
        let mut stopped: BTreeMap<(usize, usize), String> = BTreeMap::new();
        // Sampler by sampler (in the order given), each bound for every method before the
        // next tighter one: under a budget the first samplers' curves come out whole and
        // the later ones keep at least their loose ends.
        for (si, &sampler) in samplers.iter().enumerate() {
            for &bound in scene_bounds {
                for (mi, &method) in methods.iter().enumerate() {
                    let key = (mi, si);
                    let mut row = Row {
                        scene: spec.name.into(),
                        method: method.name().into(),
                        sampler: sampler.name().into(),
                        bound,
                        seconds: 0.0,
                        measured: None,
                        note: String::new(),
                    };
                    let skip = if let Some(why) = stopped.get(&key) {
                        Some(why.clone())
                    } else if budget.is_some_and(|b| sweep_start.elapsed() >= b) {
                        Some("the scene's --budget-seconds was spent".to_string())
                    } else if let Some(&(b0, t0)) = last.get(&key) {
                        // Time grows with the square of 1/bound once sampling dominates,
                        // more slowly while fixed costs (minimum samples, pre-passes) do:
                        // growing linearly is the cautious guess.
                        let predicted = t0 * (b0 as f64 / bound as f64);
                        (predicted > spec.max_seconds).then(|| {
                            format!(
                                "predicted at least {predicted:.0} s (from {t0:.0} s at bound {b0}) > the scene's cap (--max-seconds)"
                            )
                        })
                    } else {
                        None
                    };
                    if let Some(why) = skip {
                        eprintln!(
                            "chart: {} {} {} bound {bound}: skipped ({why})",
                            spec.name,
                            method.name(),
                            sampler.name()
                        );
                        row.note = why;
                        rows.push(row);
                        write_csv(&csv_path, &rows)?;
                        continue;
                    }
                    let options = BakeOptions {
                        method,
                        sampler,
                        max_rel_error: bound,
                        // Every other setting as `surfcache bake` has it by default.
                        min_samples: None,
                        max_samples: None,
                        samples: None,
                        bounces: None,
                        seed: args.seed,
                        density: None,
                        interpolation_error: None,
                        gather: surfcache_cache::bake::DEFAULT_GATHER_PASSES,
                        both_sides: true,
                        share_corners: true,
                        filter_passes: None,
                        guiding: true,
                    };
                    let elapsed_at_start = sweep_start.elapsed();
                    let reached = std::sync::Mutex::new(JobProgress::default());
                    let stop = |t: Duration, p: &JobProgress| {
                        if let Ok(mut r) = reached.lock() {
                            *r = *p;
                        }
                        t > max || budget.is_some_and(|b| elapsed_at_start + t > b)
                    };
                    let started = Instant::now();
                    let baked =
                        baking::bake(&mut loaded, options.settings()?, args.threads, &stop)?;
                    let Some(baked) = baked else {
                        let t = started.elapsed().as_secs_f64();
                        let p = reached.into_inner().unwrap_or_default();
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
                        let why = if t > spec.max_seconds {
                            format!("abandoned after {t:.0} s ({at}) > the scene's cap")
                        } else {
                            format!(
                                "abandoned after {t:.0} s ({at}): the scene's --budget-seconds ran out"
                            )
                        };
                        eprintln!(
                            "chart: {} {} {} bound {bound}: {why}; tighter bounds skipped",
                            spec.name,
                            method.name(),
                            sampler.name()
                        );
                        row.seconds = t;
                        row.note = why.clone();
                        stopped.insert(key, format!("a looser bound was {why}"));
                        rows.push(row);
                        write_csv(&csv_path, &rows)?;
                        continue;
                    };
                    let values = lookup_points(&scene, &baked.cache, &queries);
                    let result: Vec<_> = queries
                        .iter()
                        .zip(&values)
                        .map(|(q, v)| (q.position, v.unwrap_or(glam::Vec3::NAN)))
                        .collect();
                    let c = compare(&result, &reference_values);
                    let stats = baked.cache.stats();
                    row.seconds = baked.seconds;
                    row.measured = Some(Measured {
                        rel_rms: c.rel_rms,
                        bytes: stats.cache_bytes,
                        sample_points: stats.sample_points,
                        median_rel: c.median_rel,
                        p90_rel: c.p90_rel,
                    });
                    eprintln!(
                        "chart: {} {} {} bound {bound}: {:.1} s, rel_rms {:.4}, median {:.4}, p90 {:.4}, {} bytes, {} sample points",
                        spec.name,
                        method.name(),
                        sampler.name(),
                        baked.seconds,
                        c.rel_rms,
                        c.median_rel,
                        c.p90_rel,
                        stats.cache_bytes,
                        stats.sample_points
                    );
                    last.insert(key, (bound, baked.seconds));
                    rows.push(row);
                    write_csv(&csv_path, &rows)?;
                }
            }
        }
        finish(&args.out, &rows, &settings_notes)?;
    }
    finish(&args.out, &rows, &settings_notes)?;
    eprintln!(
        "chart: {} bakes in {:.0} s -> {}",
        rows.iter().filter(|r| r.measured.is_some()).count(),
        run_start.elapsed().as_secs_f64(),
        args.out.display()
    );
    Ok(())
}

/// The settings every bake of a chart scene shares: `surfcache bake`'s defaults.
fn describe_settings(spec: &SceneSpec) -> String {
    format!(
        "irradiance-map density default samples/m, lightmap default texels/m, samples per estimate default to default, gathering pre-passes {}, sides both, each bake capped at {:.0} s",
        surfcache_cache::bake::DEFAULT_GATHER_PASSES,
        spec.max_seconds
    )
}

/// Writes the CSV-derived outputs: both charts and the summary.
fn finish(out: &Path, rows: &[Row], settings_notes: &str) -> Result<()> {
    write_csv(&out.join("speed_accuracy.csv"), rows)?;
    plot::draw(
        &out.join("speed_accuracy_seconds.png"),
        rows,
        plot::XAxis::Seconds,
    )?;
    plot::draw(
        &out.join("speed_accuracy_bytes.png"),
        rows,
        plot::XAxis::Bytes,
    )?;
    let md = summary::summary(rows, settings_notes);
    Ok(surfcache_io::write_file_atomically(
        &out.join("speed_accuracy.md"),
        md.as_bytes(),
    )?)
}
