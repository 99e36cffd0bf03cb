//! Writing pictures: linear radiance tone-mapped to an sRGB PNG, plus the linear EXR.

use anyhow::{Context, Result};
use glam::Vec3;
use std::path::Path;
use surfcache_core::color::luminance;

/// Exposure that maps the image's 95th-percentile luminance to 0.8 before tone mapping
/// (1 for a black image).
pub fn auto_exposure(pixels: &[Vec3]) -> f32 {
    let mut lum: Vec<f32> = pixels
        .iter()
        .map(|&p| luminance(p))
        .filter(|l| l.is_finite() && *l > 0.0)
        .collect();
    if lum.is_empty() {
        return 1.0;
    }
    let k = ((lum.len() as f32 * 0.95) as usize).min(lum.len() - 1);
    let (_, p95, _) = lum.select_nth_unstable_by(k, f32::total_cmp);
    0.8 / *p95
}

/// The ACES filmic curve fitted by Narkowicz (2015): x(2.51x + 0.03) / (x(2.43x + 0.59) + 0.14).
#[inline]
pub fn aces(x: f32) -> f32 {
    ((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)).clamp(0.0, 1.0)
}

/// The sRGB transfer function (IEC 61966-2-1) from linear [0, 1].
#[inline]
pub fn srgb_encode(x: f32) -> f32 {
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// Writes `pixels` (linear, row-major, row 0 at the top) as an 8-bit sRGB PNG after
/// `exposure` and ACES tone mapping, through a temporary file renamed into place.
pub fn write_png(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[Vec3],
    exposure: f32,
) -> Result<()> {
    let mut bytes = Vec::with_capacity(pixels.len() * 3);
    for p in pixels {
        for c in p.to_array() {
            let v = if c.is_finite() { c * exposure } else { 0.0 };
            bytes.push((srgb_encode(aces(v.max(0.0))) * 255.0 + 0.5) as u8);
        }
    }
    let mut file = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut file, width, height);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().context("cannot encode PNG")?;
        writer
            .write_image_data(&bytes)
            .context("cannot encode PNG")?;
    }
    Ok(surfcache_io::write_file_atomically(path, &file)?)
}

/// A false-colour ramp (blue → green → red) for diagnostic pictures, `t` in [0, 1].
pub fn heat(t: f32) -> Vec3 {
    let t = t.clamp(0.0, 1.0);
    if t < 0.5 {
        Vec3::new(0.0, 2.0 * t, 1.0 - 2.0 * t)
    } else {
        Vec3::new(2.0 * t - 1.0, 2.0 - 2.0 * t, 0.0)
    }
}
