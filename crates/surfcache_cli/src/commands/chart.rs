//! `surfcache chart`: speed against accuracy (docs/design.md, Speed against accuracy). Bakes every method × sampler
//! over a sweep of error bounds, in process through the same bake path as `surfcache bake`,
//! measures each bake's time, cache bytes and sample points, and its per-point relative
//! error against a converged reference at a fixed point set (relative RMS, median and
//! 90th percentile, the figures `surfcache compare` reports), then writes
//! `speed_accuracy.csv`, two log-log charts and a summary. Each scene's panel plots the
//! measure that says most about it ([`panel_measure`]).

use crate::baking::{parse_method, parse_sampler};
use anyhow::{Context, Result, bail};
use std::{
    path::{Path, PathBuf},
    time::Instant,
};
use surfcache_cache::Method;
use surfcache_trace::Sampler;
use sweep::SweepPlan;

mod plot;
mod scenes;
mod summary;
mod sweep;

pub use scenes::{SceneSpec, panel_measure};

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

/// `surfcache chart`: sweeps every scene (or redraws from the CSV with `--replot`), then
/// writes the CSV, the charts and the summary.
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
    let limits = scenes::sweep_limits(&args)?;
    if args.points == Some(0) {
        bail!("--points must be at least 1");
    }
    let specs: Vec<SceneSpec> = args
        .scenes
        .iter()
        .map(|s| scenes::scene_spec(s, &args, &limits))
        .collect::<Result<Vec<_>>>()?
        .into_iter()
        .flatten()
        .collect();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create '{}'", args.out.display()))?;
    let plan = SweepPlan {
        methods: &methods,
        samplers: &samplers,
        seed: args.seed,
        threads: args.threads,
        points: args.points,
        csv_path: &csv_path,
    };
    let run_start = Instant::now();
    let mut rows: Vec<Row> = Vec::new();
    let mut settings_notes = String::new();
    for spec in &specs {
        sweep::sweep_scene(&plan, spec, &mut rows, &mut settings_notes)?;
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
        spec.limits.max_seconds
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
