//! `KHR_lights_punctual` lights placed in the world.

use gltf::json::extensions::scene::khr_lights_punctual as json_lights;
use surfcache_core::Light;
use surfcache_core::glam::{Affine3A, Vec3};

/// A light definition placed by a node's world transform → world-space [`Light`].
pub(super) fn convert_light(def: &json_lights::Light, world: &Affine3A) -> Result<Light, String> {
    use gltf::json::validation::Checked;
    let rgb = Vec3::from_array(def.color) * def.intensity;
    if !rgb.is_finite() {
        return Err("color × intensity is not finite; ignored".into());
    }
    let position = Vec3::from(world.translation);
    if !position.is_finite() {
        return Err("the node transform gives no finite position; ignored".into());
    }
    let direction = world.transform_vector3(Vec3::NEG_Z).normalize_or_zero();
    let needs_direction = || {
        if direction == Vec3::ZERO || !direction.is_finite() {
            Err("the node transform gives no direction; ignored".to_string())
        } else {
            Ok(direction)
        }
    };
    match &def.type_ {
        Checked::Valid(json_lights::Type::Directional) => Ok(Light::Directional {
            direction: needs_direction()?,
            irradiance: rgb,
        }),
        Checked::Valid(json_lights::Type::Point) => Ok(Light::Point {
            position,
            intensity: rgb,
        }),
        Checked::Valid(json_lights::Type::Spot) => {
            let (inner, outer) = def
                .spot
                .as_ref()
                .map(|s| (s.inner_cone_angle, s.outer_cone_angle))
                .unwrap_or((0.0, std::f32::consts::FRAC_PI_4));
            if !(inner.is_finite() && outer.is_finite()) {
                return Err("spot cone angles are not finite; ignored".into());
            }
            Ok(Light::Spot {
                position,
                direction: needs_direction()?,
                intensity: rgb,
                inner_cone_angle: inner,
                outer_cone_angle: outer,
            })
        }
        Checked::Invalid => Err("unknown light type; ignored".into()),
    }
}
