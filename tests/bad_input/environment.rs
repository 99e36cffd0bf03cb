//! Environment maps with NaN, infinite or negative texels, no RGB channels, or no EXR at all.

use crate::common::temp_dir;
use crate::{expect_error, expect_warning, points_csv, reference};
use std::path::Path;
use surfcache::core::glam::Vec3;

pub(crate) const ENV_W: usize = 8;
pub(crate) const ENV_H: usize = 4;

/// Writes an 8×4 RGB f32 EXR directly with the exr crate (write_rgb_exr refuses
/// non-finite values), uniform 1 except `special` at pixel `at` in channel `channel`.
fn write_env(path: &Path, at: (usize, usize), channel: usize, special: f32) {
    exr::prelude::write_rgb_file(path, ENV_W, ENV_H, |x, y| {
        let mut v = [1.0f32; 3];
        if (x, y) == at {
            v[channel] = special;
        }
        (v[0], v[1], v[2])
    })
    .unwrap();
}

#[test]
fn environment_map_with_nan() {
    let dir = temp_dir("environment_map_with_nan");
    let points = points_csv(&dir);
    let env = dir.join("nan.exr");
    write_env(&env, (5, 2), 1, f32::NAN);
    expect_error(
        &reference("cornell", &points, &["--env", env.to_str().unwrap()]),
        &["nan.exr", "pixel (5, 2)", "channel G", "NaN"],
    );
}

#[test]
fn environment_map_with_infinity() {
    let dir = temp_dir("environment_map_with_infinity");
    let points = points_csv(&dir);
    let env = dir.join("inf.exr");
    write_env(&env, (0, 3), 2, f32::INFINITY);
    expect_error(
        &reference("cornell", &points, &["--env", env.to_str().unwrap()]),
        &["inf.exr", "pixel (0, 3)", "channel B", "infinity"],
    );
}

#[test]
fn environment_map_with_negative_values_is_clamped() {
    let dir = temp_dir("environment_map_with_negative_values_is_clamped");
    let points = points_csv(&dir);
    let env = dir.join("negative.exr");
    write_env(&env, (6, 1), 0, -3.0);
    expect_warning(
        &reference("cornell", &points, &["--env", env.to_str().unwrap()]),
        &["negative.exr", "1 pixels had negative values, clamped to 0"],
    );
    let (map, warnings) = surfcache::io::read_environment_map(&env).unwrap();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    assert_eq!((map.width, map.height), (ENV_W as u32, ENV_H as u32));
    for j in 0..ENV_H as u32 {
        for i in 0..ENV_W as u32 {
            let expected = if (i, j) == (6, 1) {
                Vec3::new(0.0, 1.0, 1.0)
            } else {
                Vec3::ONE
            };
            assert_eq!(map.texel(i, j), expected, "pixel ({i}, {j})");
        }
    }
}

#[test]
fn environment_map_without_rgb_channels() {
    let dir = temp_dir("environment_map_without_rgb_channels");
    let points = points_csv(&dir);
    use exr::prelude::WritableImage;
    let env = dir.join("luminance.exr");
    let channels = exr::prelude::SpecificChannels::build()
        .with_channel("Y")
        .with_pixel_fn(|_| (1.0f32,));
    exr::prelude::Image::from_channels((ENV_W, ENV_H), channels)
        .write()
        .to_file(&env)
        .unwrap();
    expect_error(
        &reference("cornell", &points, &["--env", env.to_str().unwrap()]),
        &["luminance.exr", "no R, G, B channels", "found: Y"],
    );
}

#[test]
fn environment_map_that_is_not_exr() {
    let dir = temp_dir("environment_map_that_is_not_exr");
    let points = points_csv(&dir);
    let env = dir.join("text.exr");
    std::fs::write(&env, "this is not an image\n").unwrap();
    expect_error(
        &reference("cornell", &points, &["--env", env.to_str().unwrap()]),
        &["text.exr"],
    );
    // A real EXR cut short.
    let whole = dir.join("whole.exr");
    write_env(&whole, (0, 0), 0, 1.0);
    let bytes = std::fs::read(&whole).unwrap();
    let cut = dir.join("cut.exr");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    expect_error(
        &reference("cornell", &points, &["--env", cut.to_str().unwrap()]),
        &["cut.exr"],
    );
}
