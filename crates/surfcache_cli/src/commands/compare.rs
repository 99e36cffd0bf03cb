//! `surfcache compare`: the error of a result CSV against a reference CSV.

use crate::points::read_results;
use anyhow::{Result, bail};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct CompareArgs {
    /// Results to judge (x,y,z,r,g,b), e.g. from `query`.
    result: PathBuf,
    /// Reference results for the same points in the same order, e.g. from `reference`.
    reference: PathBuf,
}

/// Error figures of a result against a reference.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct Comparison {
    /// Points compared (both finite, reference not zero).
    pub points: usize,
    /// Points skipped because either side is NaN (off the scene).
    pub skipped: usize,
    /// Points where the reference is exactly zero (no light reaches them: inside closed
    /// geometry), left out of the relative figures.
    pub dark_points: usize,
    /// The largest result at those points, relative to the mean reference (leaks show
    /// here; buried points filled from visible neighbours too).
    pub dark_max: f64,
    /// sqrt(mean over points and channels of ((E − R)/(R + ε))²), ε = 1 % of the
    /// channel's mean reference value.
    pub rel_rms: f64,
    /// Median and 90th percentile over points of the per-point relative error
    /// e = sqrt(mean over channels of ((E − R)/(R + ε))²), the same ε: `rel_rms` is the
    /// RMS of e, so a few leaking points show in it and in `max_rel`, noise in the median.
    pub median_rel: f64,
    pub p90_rel: f64,
    /// sqrt(Σ|E − R|² / Σ|R|²).
    pub nrmse: f64,
    /// Largest per-point relative error (with the same ε).
    pub max_rel: f64,
    /// RMS of the reference's own relative standard error (its noise floor), when given.
    pub reference_rel_std: Option<f64>,
    /// The reference's own standard error in the measure of `rel_rms` (each channel's
    /// standard error over R + ε), RMS over points and channels, when given: what
    /// `rel_rms` cannot fall below.
    pub reference_noise: Option<f64>,
}

/// Compares `result` with `reference` row by row (module docs define the figures).
pub fn compare(
    result: &[(glam::Vec3, glam::Vec3)],
    reference: &[(glam::Vec3, glam::Vec3, Option<f32>)],
) -> Comparison {
    let finite: Vec<(glam::DVec3, glam::DVec3, Option<f32>)> = result
        .iter()
        .zip(reference)
        .filter(|(r, f)| r.1.is_finite() && f.1.is_finite())
        .map(|(r, f)| (r.1.as_dvec3(), f.1.as_dvec3(), f.2))
        .collect();
    let (pairs, dark): (Vec<_>, Vec<_>) = finite
        .iter()
        .copied()
        .partition(|p| p.1.max_element() > 0.0);
    let n = pairs.len();
    let mut out = Comparison {
        points: n,
        skipped: result.len().min(reference.len()) - finite.len(),
        dark_points: dark.len(),
        ..Default::default()
    };
    if n == 0 {
        return out;
    }
    let mean = pairs.iter().map(|p| p.1).sum::<glam::DVec3>() / n as f64;
    let mean_max = mean.max_element().max(1e-300);
    out.dark_max = dark
        .iter()
        .map(|p| p.0.max_element() / mean_max)
        .fold(0.0, f64::max);
    let eps = mean * 0.01;
    let (mut sq, mut num, mut den, mut std_sq, mut std_n) = (0.0, 0.0, 0.0, 0.0, 0usize);
    let mut noise_sq = 0.0;
    let mut per_point = Vec::with_capacity(n);
    for (e, r, s) in &pairs {
        let d = (*e - *r) / (r.max(glam::DVec3::ZERO) + eps).max(glam::DVec3::splat(1e-300));
        sq += d.length_squared();
        per_point.push((d.length_squared() / 3.0).sqrt());
        out.max_rel = out.max_rel.max(d.abs().max_element());
        num += (*e - *r).length_squared();
        den += r.length_squared();
        if let Some(s) = s.filter(|s| s.is_finite()) {
            std_sq += (s as f64) * (s as f64);
            std_n += 1;
            let se = r.max(glam::DVec3::ZERO) * s as f64;
            noise_sq += (se / (r.max(glam::DVec3::ZERO) + eps).max(glam::DVec3::splat(1e-300)))
                .length_squared();
        }
    }
    out.rel_rms = (sq / (3 * n) as f64).sqrt();
    per_point.sort_by(f64::total_cmp);
    out.median_rel = quantile(&per_point, 0.5);
    out.p90_rel = quantile(&per_point, 0.9);
    out.nrmse = if den > 0.0 { (num / den).sqrt() } else { 0.0 };
    out.reference_rel_std = (std_n > 0).then(|| (std_sq / std_n as f64).sqrt());
    out.reference_noise = (std_n > 0).then(|| (noise_sq / (3 * std_n) as f64).sqrt());
    out
}

/// The `q`-quantile of sorted `values`, linearly interpolated between order statistics
/// (Hyndman & Fan 1996, definition 7, the default of R and NumPy).
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let h = (sorted.len() - 1) as f64 * q.clamp(0.0, 1.0);
    let (lo, hi) = (h.floor() as usize, h.ceil() as usize);
    sorted[lo] + (h - lo as f64) * (sorted[hi] - sorted[lo])
}

pub fn run(args: CompareArgs) -> Result<()> {
    let result = read_results(&args.result)?;
    let reference = read_results(&args.reference)?;
    if result.len() != reference.len() {
        bail!(
            "'{}' has {} rows but '{}' has {}",
            args.result.display(),
            result.len(),
            args.reference.display(),
            reference.len()
        );
    }
    if let Some((i, _)) = result
        .iter()
        .zip(&reference)
        .enumerate()
        .find(|(_, (a, b))| (a.position - b.position).length() > 1e-5 * (1.0 + b.position.length()))
    {
        bail!("row {} is at a different position in the two files", i + 1);
    }
    let a: Vec<_> = result.iter().map(|r| (r.position, r.irradiance)).collect();
    let b: Vec<_> = reference
        .iter()
        .map(|r| (r.position, r.irradiance, r.rel_std))
        .collect();
    println!("{}", serde_json::to_string(&compare(&a, &b))?);
    Ok(())
}
