//! The chart's scenes: for each, the scene and lighting its bakes use, the point set and
//! converged reference they are measured against, the measure its panel plots, and the
//! error bounds and time caps of its sweep (Sponza has its own `--sponza-*` options).

use super::{ChartArgs, ErrorMeasure};
use crate::scene_args::EnvArgs;
use anyhow::{Result, bail};
use std::path::PathBuf;

/// The HDR map Sponza is lit by (in the shared assets' `envmaps/`): the sunny sky its
/// reference was path-traced under (docs/results.md, "Sponza at the defaults: the
/// reference").
pub const SPONZA_ENV: &str = "immenstadter_horn_1k.exr";

/// Crytek Sponza's glTF file, in the shared assets.
const SPONZA_GLTF: &str = "scenes/sponza_crytek/Sponza.gltf";

/// The point set and reference of each scene, in the repository's assets folder.
const CORNELL_POINTS: &str = "cornell_points.csv";
const CORNELL_REFERENCE: &str = "cornell_reference.csv";
const SPONZA_POINTS: &str = "reference/sponza_visible_points.csv";
const SPONZA_REFERENCE: &str = "reference/sponza_visible_immenstadter.csv";

/// What a scene's panel plots: on a level (Sponza) the median per-point error, which
/// a few contact spots cannot decide; on the Cornell box the relative RMS, as before.
pub fn panel_measure(scene: &str) -> ErrorMeasure {
    match scene {
        "sponza" => ErrorMeasure::Median,
        _ => ErrorMeasure::RelRms,
    }
}

/// How far a scene's sweep goes.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepLimits {
    /// Error bounds, loosest first.
    pub bounds: Vec<f32>,
    /// A bake still running after this many seconds is abandoned (`--max-seconds`).
    pub max_seconds: f64,
    /// Wall-clock budget of the whole sweep in seconds (`--budget-seconds`).
    pub budget_seconds: Option<f64>,
}

/// The limits of the Cornell box's sweep and of Sponza's (each `--sponza-*` option
/// defaults to the general one), after checking them.
pub(super) fn sweep_limits(args: &ChartArgs) -> Result<(SweepLimits, SweepLimits)> {
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
    Ok((
        SweepLimits {
            bounds,
            max_seconds: args.max_seconds,
            budget_seconds: args.budget_seconds,
        },
        SweepLimits {
            bounds: sponza_bounds,
            max_seconds: args.sponza_max_seconds,
            budget_seconds: args.sponza_budget_seconds.or(args.budget_seconds),
        },
    ))
}

/// One scene of the chart and the settings its bakes use.
pub struct SceneSpec {
    pub name: &'static str,
    /// A .gltf path or built-in name.
    pub(super) scene: String,
    pub(super) env: EnvArgs,
    pub(super) points: PathBuf,
    pub(super) reference: PathBuf,
    pub(super) limits: SweepLimits,
}

/// The scene `name` with its limits (`cornell` or `sponza`, from [`sweep_limits`]);
/// `None`, with a message, when Sponza's assets are absent.
pub(super) fn scene_spec(
    name: &str,
    args: &ChartArgs,
    (cornell, sponza): &(SweepLimits, SweepLimits),
) -> Result<Option<SceneSpec>> {
    match name {
        "cornell" => Ok(Some(SceneSpec {
            name: "cornell",
            scene: "cornell".into(),
            env: EnvArgs::default(),
            points: args.assets.join(CORNELL_POINTS),
            reference: args.assets.join(CORNELL_REFERENCE),
            limits: cornell.clone(),
        })),
        "sponza" => {
            let gltf = args.shared_assets.join(SPONZA_GLTF);
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
                points: args.assets.join(SPONZA_POINTS),
                reference: args.assets.join(SPONZA_REFERENCE),
                limits: sponza.clone(),
            }))
        }
        other => bail!("unknown chart scene '{other}' (known: cornell, sponza)"),
    }
}
