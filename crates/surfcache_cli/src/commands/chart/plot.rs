//! The two log-log charts of `surfcache chart`: relative RMS error against bake seconds
//! and against cache bytes, one panel per scene, one curve per (method, sampler).

use super::{ErrorMeasure, Row, panel_measure};
use anyhow::{Context, Result, anyhow};
use plotters::{
    prelude::*,
    style::{FontStyle, register_font},
};
use std::{path::Path, sync::Once};

/// DejaVu Sans (assets/fonts/DejaVuSans.LICENSE): embedded so that text needs no system
/// fonts.
const FONT: &[u8] = include_bytes!("../../../../../assets/fonts/DejaVuSans.ttf");

/// The horizontal axis of a chart.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum XAxis {
    Seconds,
    Bytes,
}

const PANEL: (u32, u32) = (900, 680);

fn method_colour(method: &str) -> RGBColor {
    match method {
        "vertex" => RGBColor(31, 119, 180),
        "irradiance-map" => RGBColor(214, 39, 40),
        "lightmap" => RGBColor(44, 160, 44),
        _ => RGBColor(90, 90, 90),
    }
}

/// Lighter for the plainer samplers: uniform lightest, best full colour.
fn sampler_colour(base: RGBColor, sampler: &str) -> RGBColor {
    let t = match sampler {
        "uniform" => 0.55,
        "cosine" => 0.3,
        "qmc" | "mis" => 0.15,
        _ => 0.0,
    };
    let mix = |c: u8| (c as f64 + (255.0 - c as f64) * t).round() as u8;
    RGBColor(mix(base.0), mix(base.1), mix(base.2))
}

/// The point marker of a sampler's curves, `size` pixels from its centre, `dx` right of
/// the point: best ■, uniform ●, cosine ▲, qmc ✕, mis ○.
fn marker<DB: DrawingBackend>(
    sampler: &str,
    colour: RGBColor,
    dx: i32,
    size: i32,
) -> DynElement<'static, DB, (i32, i32)> {
    match sampler {
        "uniform" => Circle::new((dx, 0), size, colour.filled()).into_dyn(),
        "cosine" => TriangleMarker::new((dx, 0), size + 1, colour.filled()).into_dyn(),
        "qmc" => Cross::new((dx, 0), size, colour.stroke_width(2)).into_dyn(),
        "mis" => Circle::new((dx, 0), size, colour.stroke_width(2)).into_dyn(),
        _ => Rectangle::new([(dx - size, -size), (dx + size, size)], colour.filled()).into_dyn(),
    }
}

/// Log-axis range holding `values`, widened to whole decades (so that every decade gets
/// its labels).
fn range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !lo.is_finite() {
        return 0.1..10.0;
    }
    let lo = 10f64.powf((lo / 1.02).log10().floor());
    let hi = 10f64.powf((hi * 1.02).log10().ceil());
    lo..hi
}

/// Draws the chart of `rows` (measured points only) into a PNG at `path`.
pub fn draw(path: &Path, rows: &[Row], axis: XAxis) -> Result<()> {
    static FONTS: Once = Once::new();
    FONTS.call_once(|| {
        // The font is a valid TTF (a test draws with it).
        let _ = register_font("sans-serif", FontStyle::Normal, FONT);
    });
    let mut scenes: Vec<&str> = Vec::new();
    for r in rows {
        if !scenes.contains(&r.scene.as_str()) {
            scenes.push(&r.scene);
        }
    }
    let panels = scenes.len().max(1) as u32;
    let (w, h) = (PANEL.0 * panels, PANEL.1);
    let mut buffer = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        let areas = root.split_evenly((1, panels as usize));
        for (area, scene) in areas.iter().zip(&scenes) {
            draw_panel(area, rows, scene, axis)
                .map_err(|e| anyhow!("cannot draw the chart: {e}"))?;
        }
        root.present()
            .map_err(|e| anyhow!("cannot draw the chart: {e}"))?;
    }
    let mut file = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut file, w, h);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().context("cannot encode PNG")?;
        writer
            .write_image_data(&buffer)
            .context("cannot encode PNG")?;
    }
    Ok(surfcache_io::write_file_atomically(path, &file)?)
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

/// A panel's chart: log-log axes on the bitmap.
type LogChart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<LogCoord<f64>, LogCoord<f64>>>;

/// A point of a panel: its row, and its x (seconds or bytes) and y (the error measure).
type Point<'a> = (&'a Row, f64, f64);

/// Errors of drawing a panel.
type DrawResult<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// Draws `scene`'s panel into `area`: a curve with markers per (method, sampler) and a
/// legend, or a note when the scene has no point to plot.
fn draw_panel(area: &Area<'_>, rows: &[Row], scene: &str, axis: XAxis) -> DrawResult<()> {
    let measure = panel_measure(scene);
    let measured = panel_points(rows, scene, axis, measure);
    if measured.is_empty() {
        return draw_no_bakes(area, scene);
    }
    let mut chart = draw_axes(area, &measured, scene, axis, measure)?;
    for (method, sampler) in curves(&measured) {
        draw_curve(&mut chart, &measured, method, sampler)?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .label_font(("sans-serif", 15))
        .draw()?;
    Ok(())
}

/// `scene`'s measured rows as points on `axis` and `measure`, those with both
/// coordinates positive and finite (a log axis can show no other).
fn panel_points<'a>(
    rows: &'a [Row],
    scene: &str,
    axis: XAxis,
    measure: ErrorMeasure,
) -> Vec<Point<'a>> {
    rows.iter()
        .filter(|r| r.scene == scene)
        .filter_map(|r| {
            let m = r.measured?;
            let x = match axis {
                XAxis::Seconds => r.seconds,
                XAxis::Bytes => m.bytes as f64,
            };
            let y = measure.of(&m);
            (x > 0.0 && y > 0.0 && x.is_finite() && y.is_finite()).then_some((r, x, y))
        })
        .collect()
}

/// The panel of a scene with no point to plot (no bake finished, or none kept the panel's
/// measure): a note pointing to the summary.
fn draw_no_bakes(area: &Area<'_>, scene: &str) -> DrawResult<()> {
    let (_, h) = area.dim_in_pixel();
    let style = ("sans-serif", 24).into_font().color(&BLACK);
    area.draw_text(
        &format!("{scene}: no bake finished within its cap"),
        &style,
        (40, h as i32 / 2 - 20),
    )?;
    area.draw_text(
        "(see speed_accuracy.md)",
        &("sans-serif", 18).into_font().color(&BLACK),
        (40, h as i32 / 2 + 16),
    )?;
    Ok(())
}

/// The panel's caption and its log-log axes with grid and labels, spanning whole decades
/// around `measured` ([`range`]).
fn draw_axes<'a, 'b>(
    area: &'a Area<'b>,
    measured: &[Point],
    scene: &str,
    axis: XAxis,
    measure: ErrorMeasure,
) -> DrawResult<LogChart<'a, 'b>> {
    let xr = range(measured.iter().map(|m| m.1));
    let yr = range(measured.iter().map(|m| m.2));
    let (caption, x_desc) = match axis {
        XAxis::Seconds => (
            format!("{scene}: error against bake time"),
            "bake seconds (log)",
        ),
        XAxis::Bytes => (
            format!("{scene}: error against cache size"),
            "cache bytes (log)",
        ),
    };
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 26))
        .margin(18)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d(xr.log_scale(), yr.log_scale())?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(measure.describe())
        .x_labels(12)
        .y_labels(16)
        .label_style(("sans-serif", 15))
        .axis_desc_style(("sans-serif", 17))
        .x_label_formatter(&|v| format_number(*v))
        .y_label_formatter(&|v| format!("{}%", format_number(v * 100.0)))
        .draw()?;
    Ok(chart)
}

/// The (method, sampler) pairs of `measured`, in order of first appearance.
fn curves<'a>(measured: &[Point<'a>]) -> Vec<(&'a str, &'a str)> {
    let mut curves: Vec<(&str, &str)> = Vec::new();
    for (r, _, _) in measured {
        if !curves.contains(&(r.method.as_str(), r.sampler.as_str())) {
            curves.push((&r.method, &r.sampler));
        }
    }
    curves
}

/// The curve of (`method`, `sampler`) through its points, loosest bound first, with a
/// marker at each point and a legend entry.
fn draw_curve<'a, 'b: 'a>(
    chart: &mut LogChart<'a, 'b>,
    measured: &[Point],
    method: &str,
    sampler: &str,
) -> DrawResult<()> {
    let mut points: Vec<(f32, f64, f64)> = measured
        .iter()
        .filter(|(r, _, _)| r.method == method && r.sampler == sampler)
        .map(|(r, x, y)| (r.bound, *x, *y))
        .collect();
    points.sort_by(|a, b| b.0.total_cmp(&a.0));
    let colour = sampler_colour(method_colour(method), sampler);
    let width = if sampler == "best" { 3 } else { 2 };
    let line = colour.stroke_width(width);
    let sampler_name = sampler.to_string();
    chart
        .draw_series(LineSeries::new(points.iter().map(|p| (p.1, p.2)), line))?
        .label(format!("{method} / {sampler}"))
        .legend(move |(x, y)| {
            EmptyElement::at((x, y))
                + PathElement::new(vec![(-8, 0), (12, 0)], colour.stroke_width(width))
                + marker(&sampler_name, colour, 2, 4)
        });
    chart.draw_series(
        points
            .iter()
            .map(|p| EmptyElement::at((p.1, p.2)) + marker(sampler, colour, 0, 5)),
    )?;
    Ok(())
}

/// 0.5, 2, 30, 1.2k, 4M: short labels for log axes.
fn format_number(v: f64) -> String {
    let (v, suffix) = if v >= 1e9 {
        (v / 1e9, "G")
    } else if v >= 1e6 {
        (v / 1e6, "M")
    } else if v >= 1e3 {
        (v / 1e3, "k")
    } else {
        (v, "")
    };
    let s = if v >= 10.0 {
        format!("{v:.0}")
    } else if v >= 1.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    };
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    format!("{s}{suffix}")
}
