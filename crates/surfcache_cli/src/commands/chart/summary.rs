//! The summary of `surfcache chart` (markdown): settings, the table at the 1 % bound (or
//! the tightest one reached), the time ratio of the uniform and best samplers at equal
//! error, bytes per method at equal error, and what was skipped.

use super::{Row, panel_measure};
use std::fmt::Write as _;

/// One curve's measured points (bound, seconds, error, bytes), loosest bound first; the
/// error is the one the scene's panel plots ([`panel_measure`]).
fn curve(rows: &[Row], scene: &str, method: &str, sampler: &str) -> Vec<(f32, f64, f64, f64)> {
    let measure = panel_measure(scene);
    let mut c: Vec<_> = rows
        .iter()
        .filter(|r| r.scene == scene && r.method == method && r.sampler == sampler)
        .filter_map(|r| {
            let m = r.measured?;
            Some((r.bound, r.seconds, measure.of(&m), m.bytes as f64))
        })
        .filter(|p| p.1 > 0.0 && p.2 > 0.0 && p.3 > 0.0 && p.2.is_finite())
        .collect();
    c.sort_by(|a, b| b.0.total_cmp(&a.0));
    c
}

/// How a figure read off a curve at a given error relates to the curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Read {
    /// Interpolated between two measured points (log-log).
    Exact(f64),
    /// Already the loosest point is at least this accurate: the figure is at most this.
    AtMost(f64),
}

impl Read {
    #[cfg(test)]
    fn value(self) -> f64 {
        match self {
            Read::Exact(v) | Read::AtMost(v) => v,
        }
    }
}

/// The `field` (1: seconds, 3: bytes) a curve needs to reach relative error `e`, read
/// along it from the loosest bound: log-log interpolation between the first two
/// consecutive points that bracket `e`. `None` if the curve never gets to `e`.
pub fn at_error(c: &[(f32, f64, f64, f64)], e: f64, field: usize) -> Option<Read> {
    let get = |p: &(f32, f64, f64, f64)| if field == 1 { p.1 } else { p.3 };
    let first = c.first()?;
    if first.2 <= e {
        return Some(Read::AtMost(get(first)));
    }
    for w in c.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        if b.2 <= e && a.2 > e {
            let t = (e.ln() - a.2.ln()) / (b.2.ln() - a.2.ln());
            let v = (get(a).ln() + t * (get(b).ln() - get(a).ln())).exp();
            return Some(Read::Exact(v));
        }
    }
    None
}

/// Error levels at which curves are compared.
const LEVELS: [f64; 6] = [0.2, 0.1, 0.05, 0.02, 0.015, 0.01];

fn lowest_error(c: &[(f32, f64, f64, f64)]) -> Option<f64> {
    c.iter().map(|p| p.2).min_by(f64::total_cmp)
}

fn unique<'a>(rows: &'a [Row], f: impl Fn(&'a Row) -> &'a str) -> Vec<&'a str> {
    let mut out: Vec<&str> = Vec::new();
    for r in rows {
        let v = f(r);
        if !out.contains(&v) {
            out.push(v);
        }
    }
    out
}

fn pct(v: f64) -> String {
    format!("{:.2} %", 100.0 * v)
}

/// A percentage, or – where the row did not keep it.
fn pct_or_dash(v: f64) -> String {
    if v.is_finite() { pct(v) } else { "–".into() }
}

fn read_str(r: Read, unit: &str) -> String {
    let d = if unit == " s" { 1 } else { 0 };
    match r {
        Read::Exact(v) => format!("{v:.d$}{unit}"),
        Read::AtMost(v) => format!("≤ {v:.d$}{unit}"),
    }
}

/// The summary markdown of `rows`, with `settings` (one list item per scene) on top.
pub fn summary(rows: &[Row], settings: &str) -> String {
    let mut md = String::from(
        "# Speed against accuracy: summary\n\nWritten by `surfcache chart` from `speed_accuracy.csv`.\n\n",
    );
    if !settings.is_empty() {
        md.push_str("## Scenes and settings\n\n");
        md.push_str(settings);
        md.push('\n');
    }
    let scenes = unique(rows, |r| &r.scene);
    let methods = unique(rows, |r| &r.method);
    let samplers = unique(rows, |r| &r.sampler);
    write_bound_table(&mut md, rows, &scenes, &methods, &samplers);
    write_time_ratios(&mut md, rows, &scenes, &methods);
    write_bytes_at_error(&mut md, rows, &scenes, &methods, &samplers);
    write_skipped(&mut md, rows);
    md
}

/// The summary's table of each curve's row at the 1 % bound, or the tightest one reached
/// ([`nearest_one_percent`]).
fn write_bound_table(
    md: &mut String,
    rows: &[Row],
    scenes: &[&str],
    methods: &[&str],
    samplers: &[&str],
) {
    md.push_str("## At the 1 % bound (or the tightest bound reached)\n\n");
    md.push_str("| scene | method | sampler | bound | seconds | rel_rms | median | p90 | bytes | sample points |\n|---|---|---|---:|---:|---:|---:|---:|---:|---:|\n");
    for scene in scenes {
        for method in methods {
            for sampler in samplers {
                let Some(r) = nearest_one_percent(rows, scene, method, sampler) else {
                    continue;
                };
                let m = r.measured.expect("filtered");
                let _ = writeln!(
                    md,
                    "| {scene} | {method} | {sampler} | {} | {:.1} | {} | {} | {} | {} | {} |",
                    r.bound,
                    r.seconds,
                    pct(m.rel_rms),
                    pct_or_dash(m.median_rel),
                    pct_or_dash(m.p90_rel),
                    m.bytes,
                    m.sample_points
                );
            }
        }
    }
}

/// The measured row of a curve whose bound is nearest 1 %, a looser bound before any
/// tighter one (|bound − 1 %|, plus 1 below 1 %); the first such row on a tie.
fn nearest_one_percent<'a>(
    rows: &'a [Row],
    scene: &str,
    method: &str,
    sampler: &str,
) -> Option<&'a Row> {
    rows.iter()
        .filter(|r| r.scene == scene && r.method == method && r.sampler == sampler)
        .filter(|r| r.measured.is_some())
        .min_by(|a, b| {
            let ka = (a.bound - 0.01).abs() + if a.bound < 0.01 { 1.0 } else { 0.0 };
            let kb = (b.bound - 0.01).abs() + if b.bound < 0.01 { 1.0 } else { 0.0 };
            ka.total_cmp(&kb)
        })
}

/// The summary's table of the seconds `uniform` and `best` need for equal error
/// ([`at_error`]), per scene and method: at the [`LEVELS`] above the lowest error both
/// curves reach, and at that error.
fn write_time_ratios(md: &mut String, rows: &[Row], scenes: &[&str], methods: &[&str]) {
    md.push_str("\n## Time of `uniform` against `best` at equal error\n\n");
    md.push_str("Read along each curve (log-log interpolation between measured bounds; `≤`: already the loosest bound was that accurate, so the time is at most the loosest bake's), at fixed error levels both curves reach and at the lowest error both reach.\n\n");
    md.push_str(
        "| scene | method | error | uniform | best | ratio |\n|---|---|---:|---:|---:|---:|\n",
    );
    for scene in scenes {
        for method in methods {
            let u = curve(rows, scene, method, "uniform");
            let b = curve(rows, scene, method, "best");
            let (Some(eu), Some(eb)) = (lowest_error(&u), lowest_error(&b)) else {
                continue;
            };
            let common = eu.max(eb);
            let mut levels: Vec<f64> = LEVELS.iter().copied().filter(|l| *l > common).collect();
            levels.push(common);
            for e in levels {
                let (Some(tu), Some(tb)) = (at_error(&u, e, 1), at_error(&b, e, 1)) else {
                    continue;
                };
                let _ = writeln!(
                    md,
                    "| {scene} | {method} | {} | {} | {} | {} |",
                    pct(e),
                    read_str(tu, " s"),
                    read_str(tb, " s"),
                    time_ratio(tu, tb)
                );
            }
        }
    }
}

/// The ratio t_uniform / t_best, marked by how each time was read: ≥, ≤, or ~ when both
/// are upper bounds.
fn time_ratio(tu: Read, tb: Read) -> String {
    match (tu, tb) {
        (Read::Exact(u), Read::Exact(b)) => format!("{:.1}×", u / b),
        (Read::Exact(u), Read::AtMost(b)) => format!("≥ {:.1}×", u / b),
        (Read::AtMost(u), Read::Exact(b)) => format!("≤ {:.1}×", u / b),
        (Read::AtMost(u), Read::AtMost(b)) => format!("~{:.1}× (both ≤)", u / b),
    }
}

/// The summary's table of the cache bytes each method needs at each of the [`LEVELS`],
/// per scene and sampler ([`at_error`]); levels no method reaches are left out.
fn write_bytes_at_error(
    md: &mut String,
    rows: &[Row],
    scenes: &[&str],
    methods: &[&str],
    samplers: &[&str],
) {
    md.push_str("\n## Bytes per method at equal error\n\n");
    md.push_str("Cache bytes each method needs for a given error (the measure its scene's chart plots), read along its curve as above (–: never that accurate in this sweep).\n\n");
    md.push_str("| scene | sampler | error |");
    for m in methods {
        let _ = write!(md, " {m} |");
    }
    md.push_str("\n|---|---|---:|");
    for _ in methods {
        md.push_str("---:|");
    }
    md.push('\n');
    for scene in scenes {
        for sampler in samplers {
            let curves: Vec<_> = methods
                .iter()
                .map(|m| curve(rows, scene, m, sampler))
                .collect();
            for &e in &LEVELS {
                let cells: Vec<String> = curves
                    .iter()
                    .map(|c| at_error(c, e, 3).map_or("–".into(), |r| read_str(r, "")))
                    .collect();
                if cells.iter().all(|c| c == "–") {
                    continue;
                }
                let _ = write!(md, "| {scene} | {sampler} | {} |", pct(e));
                for cell in cells {
                    let _ = write!(md, " {cell} |");
                }
                md.push('\n');
            }
        }
    }
}

/// The summary's list of the rows skipped or capped (no measurement), with their notes.
fn write_skipped(md: &mut String, rows: &[Row]) {
    let skipped: Vec<&Row> = rows.iter().filter(|r| r.measured.is_none()).collect();
    md.push_str("\n## Skipped or capped\n\n");
    if skipped.is_empty() {
        md.push_str("Nothing: every bake of the sweep finished.\n");
    } else {
        md.push_str("These rows of the CSV have empty rel_rms, bytes, sample_points, median_rel and p90_rel (seconds: time spent before the bake was abandoned, 0 if not started).\n\n");
        for r in skipped {
            let _ = writeln!(
                md,
                "- {} {} {} bound {}: {}",
                r.scene, r.method, r.sampler, r.bound, r.note
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_along_a_curve() {
        // Error halves per 4x time.
        let c = vec![
            (0.2, 1.0, 0.08, 10.0),
            (0.1, 4.0, 0.04, 10.0),
            (0.05, 16.0, 0.02, 10.0),
        ];
        assert_eq!(at_error(&c, 0.1, 1), Some(Read::AtMost(1.0)));
        let Some(Read::Exact(t)) = at_error(&c, 0.02 * 2f64.sqrt(), 1) else {
            panic!()
        };
        assert!((t - 8.0).abs() < 1e-9);
        assert_eq!(at_error(&c, 0.01, 1), None);
        let bytes = at_error(&c, 0.03, 3).map(Read::value).unwrap();
        assert!((bytes - 10.0).abs() < 1e-9);
    }
}
