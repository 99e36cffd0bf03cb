//! Matching a Bevy camera to surfcache's pictures (`surfcache render`), and capturing the
//! window once a bake shows.
//!
//! `surfcache render --exposure K` multiplies radiance by K before tone mapping; a Bevy
//! camera multiplies it by `2^−ev100 / 1.2` (its `Exposure`), which the lightmap, lights
//! and emission (at `emissive_exposure_weight` 1) all pass through. [`matched_camera`]
//! is a pinhole camera like `surfcache render`'s: eye, target, +Y up, vertical field of
//! view.

use bevy::{
    camera::{Exposure, PerspectiveProjection, Projection},
    core_pipeline::tonemapping::{DebandDither, Tonemapping},
    prelude::*,
    render::view::screenshot::{Screenshot, ScreenshotCaptured},
};
use std::sync::{Arc, Mutex};
use surfcache_ecs::BakedSurfaceCache;

/// The `Exposure::ev100` under which a Bevy camera scales radiance by `exposure`.
pub fn ev100_for_exposure(exposure: f32) -> f32 {
    -(1.2 * exposure).log2()
}

/// A 3D camera at `eye` looking at `target` (+Y up) with a vertical field of view in
/// degrees, scaling radiance by `exposure`, with `tonemapping` and no dithering.
pub fn matched_camera(
    eye: Vec3,
    target: Vec3,
    fov_degrees: f32,
    exposure: f32,
    tonemapping: Tonemapping,
) -> impl Bundle {
    (
        Camera3d::default(),
        Projection::Perspective(PerspectiveProjection {
            fov: fov_degrees.to_radians(),
            near: 0.01,
            ..Default::default()
        }),
        Transform::from_translation(eye).looking_at(target, Vec3::Y),
        Exposure {
            ev100: ev100_for_exposure(exposure),
        },
        tonemapping,
        DebandDither::Disabled,
    )
}

/// Captures the primary window once a bake is shown: after the first published bake it
/// takes a screenshot every `frames` frames until two in a row are identical (Bevy
/// uploads lightmaps and compiles their shaders over the frames after a publish), keeps
/// that picture in [`CaptureWhenBaked::picture`] and exits the app.
#[derive(Resource, Clone)]
pub struct CaptureWhenBaked {
    /// Frames between screenshots.
    pub frames: u32,
    /// The settled picture, once taken (the window's pixels, sRGB).
    pub picture: Arc<Mutex<Option<Image>>>,
    last: Arc<Mutex<Option<Image>>>,
    countdown: u32,
}

impl CaptureWhenBaked {
    /// Screenshots `frames` frames apart.
    pub fn every(frames: u32) -> Self {
        Self {
            frames: frames.max(1),
            picture: Arc::default(),
            last: Arc::default(),
            countdown: frames.max(1),
        }
    }
}

/// The system behind [`CaptureWhenBaked`]; add it to `Update`.
pub fn capture_when_baked(
    mut commands: Commands,
    mut capture: ResMut<CaptureWhenBaked>,
    baked: Res<BakedSurfaceCache>,
    mut exit: MessageWriter<AppExit>,
) {
    if capture.picture.lock().map(|p| p.is_some()).unwrap_or(true) {
        exit.write(AppExit::Success);
        return;
    }
    if baked.generation == 0 {
        return;
    }
    capture.countdown -= 1;
    if capture.countdown > 0 {
        return;
    }
    capture.countdown = capture.frames;
    let (last, picture) = (capture.last.clone(), capture.picture.clone());
    commands
        .spawn(Screenshot::primary_window())
        .observe(move |shot: On<ScreenshotCaptured>| {
            let (Ok(mut last), Ok(mut picture)) = (last.lock(), picture.lock()) else {
                return;
            };
            if last.as_ref().is_some_and(|l| l.data == shot.image.data) {
                *picture = Some(shot.image.clone());
            }
            *last = Some(shot.image.clone());
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bevy_exposure_inverts() {
        for k in [0.01, 0.25, 1.0, 7.5] {
            let exposure = Exposure {
                ev100: ev100_for_exposure(k),
            };
            assert!((exposure.exposure() - k).abs() <= 1e-6 * k, "{k}");
        }
    }
}
