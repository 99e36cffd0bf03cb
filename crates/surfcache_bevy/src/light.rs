//! Lights: Bevy's [`DirectionalLight`], [`PointLight`] and [`SpotLight`] read as
//! surfcache's punctual lights, and each light's choice between baked and real-time
//! direct light ([`LightBaking`]).
//!
//! Units follow Bevy's renderer, so a baked light delivers what Bevy would shade in real
//! time: a directional light's `illuminance` (lux) is the irradiance E in W/m² it delivers
//! to a surface facing it, travelling along the light's −Z; a point or spot light's
//! `intensity` (lumens) becomes a radiant intensity of `intensity / 4π` W/sr, which is
//! Bevy's own conversion (a spot light keeps the point light's intensity inside its cone),
//! with the glTF cone falloff from `inner_angle` to `outer_angle`. Bevy's `range` window
//! and `radius` (sphere lights) are not baked.

use crate::glam_bridge;
use bevy::{
    color::Color,
    light::{DirectionalLight, PointLight, SpotLight},
    prelude::{Component, GlobalTransform, Transform},
};
use core::f32::consts::PI;
use glam::Vec3;
use surfcache_core::Light;

/// How a light reaches the surfaces that carry baked lightmaps. Without this component a
/// light is [`LightBaking::Baked`].
///
/// Either way no light is counted twice: Bevy adds a lightmap to its real-time lights
/// unless `affects_lightmapped_mesh_diffuse` is off, so the plugin keeps that flag in step.
#[derive(Component, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LightBaking {
    /// Direct light and every bounce are baked; in real time the light no longer lights
    /// the diffuse part of lightmapped meshes (`affects_lightmapped_mesh_diffuse` is set
    /// to `false`), but it still gives them highlights and lights every other mesh.
    #[default]
    Baked,
    /// The bake leaves the light out: it lights everything in real time (shadows and all,
    /// `affects_lightmapped_mesh_diffuse` set to `true`). Its bounced light is missing from
    /// the lightmaps.
    Realtime,
}

/// A colour and a scalar as linear RGB.
fn linear(color: Color, scale: f32) -> Vec3 {
    let c = color.to_linear();
    Vec3::new(c.red, c.green, c.blue) * scale
}

/// The unit direction a light at `transform` shines along (its −Z).
fn forward(transform: &GlobalTransform) -> Vec3 {
    glam_bridge::vec3(*transform.forward())
}

/// A directional light (module docs: units).
pub fn directional(light: &DirectionalLight, transform: &GlobalTransform) -> Light {
    Light::Directional {
        direction: forward(transform),
        irradiance: linear(light.color, light.illuminance),
    }
}

/// A point light (module docs: units).
pub fn point(light: &PointLight, transform: &GlobalTransform) -> Light {
    Light::Point {
        position: glam_bridge::vec3(transform.translation()),
        intensity: linear(light.color, light.intensity / (4.0 * PI)),
    }
}

/// A spot light (module docs: units).
pub fn spot(light: &SpotLight, transform: &GlobalTransform) -> Light {
    Light::Spot {
        position: glam_bridge::vec3(transform.translation()),
        direction: forward(transform),
        intensity: linear(light.color, light.intensity / (4.0 * PI)),
        inner_cone_angle: light.inner_angle,
        outer_cone_angle: light.outer_angle,
    }
}

/// A Bevy light that [`directional`], [`point`] or [`spot`] reads back as `light`.
pub enum BevyLight {
    Directional(DirectionalLight),
    Point(PointLight),
    Spot(SpotLight),
}

/// `light` as a Bevy light component and its transform.
pub fn bevy_light(light: &Light) -> (BevyLight, Transform) {
    let color = |c: Vec3| {
        let scale = c.max_element().max(f32::MIN_POSITIVE);
        (
            Color::linear_rgb(c.x / scale, c.y / scale, c.z / scale),
            scale,
        )
    };
    let aim = |position: Vec3, direction: Vec3| {
        let up = if direction.y.abs() > 0.9 {
            Vec3::X
        } else {
            Vec3::Y
        };
        Transform::from_translation(glam_bridge::bevy_vec3(position)).looking_to(
            glam_bridge::bevy_vec3(direction),
            glam_bridge::bevy_vec3(up),
        )
    };
    match *light {
        Light::Directional {
            direction,
            irradiance,
        } => {
            let (color, illuminance) = color(irradiance);
            let light = DirectionalLight {
                color,
                illuminance,
                ..Default::default()
            };
            (BevyLight::Directional(light), aim(Vec3::ZERO, direction))
        }
        Light::Point {
            position,
            intensity,
        } => {
            let (color, scale) = color(intensity);
            let light = PointLight {
                color,
                intensity: scale * 4.0 * PI,
                range: 1e4,
                ..Default::default()
            };
            (BevyLight::Point(light), aim(position, Vec3::NEG_Z))
        }
        Light::Spot {
            position,
            direction,
            intensity,
            inner_cone_angle,
            outer_cone_angle,
        } => {
            let (color, scale) = color(intensity);
            let light = SpotLight {
                color,
                intensity: scale * 4.0 * PI,
                range: 1e4,
                inner_angle: inner_cone_angle,
                outer_angle: outer_cone_angle,
                ..Default::default()
            };
            (BevyLight::Spot(light), aim(position, direction))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Light, b: Light) -> bool {
        let v = |l: Light| match l {
            Light::Directional {
                direction,
                irradiance,
            } => vec![direction, irradiance],
            Light::Point {
                position,
                intensity,
            } => vec![position, intensity],
            Light::Spot {
                position,
                direction,
                intensity,
                inner_cone_angle,
                outer_cone_angle,
            } => vec![
                position,
                direction,
                intensity,
                Vec3::new(inner_cone_angle, outer_cone_angle, 0.0),
            ],
        };
        let (a, b) = (v(a), v(b));
        a.len() == b.len()
            && a.iter()
                .zip(&b)
                .all(|(a, b)| (*a - *b).abs().max_element() <= 1e-5 * (1.0 + b.abs().max_element()))
    }

    #[test]
    fn lights_round_trip_through_bevy_units() {
        let lights = [
            Light::Directional {
                direction: Vec3::new(0.3, -1.0, 0.2).normalize(),
                irradiance: Vec3::new(900.0, 800.0, 700.0),
            },
            Light::Point {
                position: Vec3::new(1.0, 2.0, 3.0),
                intensity: Vec3::new(10.0, 5.0, 1.0),
            },
            Light::Spot {
                position: Vec3::new(0.0, 3.0, 0.0),
                direction: Vec3::NEG_Y,
                intensity: Vec3::splat(40.0),
                inner_cone_angle: 0.3,
                outer_cone_angle: 0.5,
            },
        ];
        for light in lights {
            let (bevy, transform) = bevy_light(&light);
            let global = GlobalTransform::from(transform);
            let back = match &bevy {
                BevyLight::Directional(l) => directional(l, &global),
                BevyLight::Point(l) => point(l, &global),
                BevyLight::Spot(l) => spot(l, &global),
            };
            assert!(close(back, light), "{light:?} came back as {back:?}");
        }
    }

    #[test]
    fn a_point_light_of_4pi_lumens_is_one_candela() {
        let light = PointLight {
            intensity: 4.0 * PI,
            ..Default::default()
        };
        let Light::Point { intensity, .. } = point(&light, &GlobalTransform::IDENTITY) else {
            unreachable!()
        };
        assert!((intensity - Vec3::ONE).abs().max_element() < 1e-6);
    }
}
