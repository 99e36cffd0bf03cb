//! Unbiased path tracing of incident radiance L_in(x, ω) over two-sided Lambertian surfaces.

use crate::traced_scene::{SurfacePoint, TracedScene};
use glam::Vec3;
use surfcache_core::{
    Light,
    geometry::to_world,
    sampling::{Rng, cosine_hemisphere},
};

/// Limits of one path.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PathOptions {
    /// Maximum number of indirect bounces (reflections after the first hit); `None` runs
    /// until Russian roulette ends the path. `Some(0)` counts only what the first hit emits
    /// plus the environment.
    pub max_bounces: Option<u32>,
}

impl TracedScene {
    /// Irradiance at `p` from the punctual lights, by shadow rays:
    /// `I cos θ / r²` for point and spot lights (times the glTF cone falloff),
    /// `E_s cos θ` for directional lights, with cos θ = ⟨ν, ω_l⟩ about the shading normal and
    /// nothing from below the geometric surface (CONTRACT.md).
    pub fn punctual_irradiance(&self, p: &SurfacePoint) -> Vec3 {
        let origin = self.spawn_origin(p);
        let mut e = Vec3::ZERO;
        for light in &self.lights {
            let (to_light, distance, arriving) = match *light {
                Light::Directional {
                    direction,
                    irradiance,
                } => (-direction.normalize(), f32::INFINITY, irradiance),
                Light::Point {
                    position,
                    intensity,
                } => {
                    let d = position - p.position;
                    let r2 = d.length_squared();
                    (d / r2.sqrt(), r2.sqrt(), intensity / r2)
                }
                Light::Spot {
                    position,
                    direction,
                    intensity,
                    inner_cone_angle,
                    outer_cone_angle,
                } => {
                    let d = position - p.position;
                    let r2 = d.length_squared();
                    let w = d / r2.sqrt();
                    let falloff = Light::spot_falloff(
                        direction.normalize(),
                        -w,
                        inner_cone_angle,
                        outer_cone_angle,
                    );
                    (w, r2.sqrt(), intensity * falloff / r2)
                }
            };
            let cos = p.shading_normal.dot(to_light);
            if cos <= 0.0 || p.geometric_normal.dot(to_light) <= 0.0 || arriving == Vec3::ZERO {
                continue;
            }
            if !self.occluded(origin, to_light, distance) {
                e += arriving * cos;
            }
        }
        e
    }

    /// One path-traced estimate of L_in(origin, ω): the radiance arriving at `origin` from
    /// direction `direction` (unit). Along the path it adds what surfaces emit towards it,
    /// the environment where it escapes, and punctual lights by shadow rays at every
    /// Lambertian bounce (throughput × ρ/π × E_punctual); bounces sample cosine-weighted
    /// directions about the shading normal (weight ρ), directions under the geometric
    /// surface end the path, and Russian roulette with survival probability
    /// min(max throughput, 0.95) keeps the estimate unbiased (pbrt-v4 §14.1.5).
    pub fn incident_radiance(
        &self,
        origin: Vec3,
        direction: Vec3,
        rng: &mut Rng,
        options: PathOptions,
    ) -> Vec3 {
        let mut radiance = Vec3::ZERO;
        let mut throughput = Vec3::ONE;
        let (mut o, mut d) = (origin, direction);
        let mut bounce = 0u32;
        loop {
            let Some(hit) = self.closest_hit(o, d, f32::INFINITY) else {
                radiance += throughput * self.environment.radiance(d);
                break;
            };
            let p = self.hit_point(&hit, d);
            let material = self.material_of(hit.triangle);
            let uv0 = self.uv0_at(hit.triangle, hit.uv);
            let front = self.geometric_normals[hit.triangle as usize].dot(d) < 0.0;
            radiance += throughput * material.emission_at(uv0, front);
            if options.max_bounces.is_some_and(|b| bounce >= b) {
                break;
            }
            let albedo = material.albedo_at(uv0);
            if albedo == Vec3::ZERO {
                break;
            }
            if !self.lights.is_empty() {
                radiance += throughput
                    * albedo
                    * core::f32::consts::FRAC_1_PI
                    * self.punctual_irradiance(&p);
            }
            throughput *= albedo;
            let survive = throughput.max_element().min(0.95);
            if survive <= 0.0 || rng.next_f32() >= survive {
                break;
            }
            throughput /= survive;
            let w = to_world(cosine_hemisphere(rng.next_vec2()), p.shading_normal);
            if w.dot(p.geometric_normal) <= 0.0 {
                break;
            }
            o = self.spawn_origin(&p);
            d = w;
            bounce += 1;
        }
        radiance
    }
}
