//! Choosing light sources for next-event estimation: emissive triangles by power, the
//! environment map by its luminance, and the densities multiple importance sampling needs.

use crate::traced_scene::TracedScene;
use glam::{Vec2, Vec3};
use surfcache_core::{
    EnvironmentSampler,
    color::luminance,
    geometry::{interpolate, triangle_area, triangle_point},
    index::NO_INDEX,
    sampling::{Distribution1D, uniform_triangle},
};

/// The light sources of a scene that next-event estimation samples (punctual lights are
/// handled exactly, by shadow rays, and are not part of this).
#[derive(Clone, Debug, Default)]
pub struct LightSampler {
    /// Emissive triangles.
    emitters: Vec<u32>,
    /// Area of each emitter.
    emitter_area: Vec<f32>,
    /// Choice among emitters, proportional to power π A Y(L_e) (doubled when two-sided).
    emitter_distribution: Distribution1D,
    /// Position of each triangle in `emitters`, or [`NO_INDEX`].
    emitter_slot: Vec<u32>,
    /// Importance sampling of the environment map (`None`: no map, or a black one).
    environment: Option<EnvironmentSampler>,
    /// Probability of sampling the environment rather than an emitter.
    p_environment: f32,
}

/// A direction towards a light source chosen for next-event estimation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightSample {
    /// Unit direction from the shading point towards the light.
    pub direction: Vec3,
    /// Distance to the sampled point (∞ for the environment).
    pub distance: f32,
    /// Radiance leaving an emissive triangle towards the shading point; `None` for the
    /// environment, whose radiance along `direction` the caller looks up only when it is
    /// needed ([`surfcache_core::Environment::radiance_uv`]: a cache miss in a large map,
    /// and most samples of an enclosed point are occluded).
    pub emitted: Option<Vec3>,
    /// Solid-angle density of this direction, light choice included.
    pub pdf: f32,
}

impl LightSampler {
    /// Collects the emissive triangles and the environment map of `scene`.
    pub fn new(scene: &TracedScene) -> Self {
        let mut emitters = Vec::new();
        let mut emitter_area = Vec::new();
        let mut power = Vec::new();
        let mut emitter_slot = vec![NO_INDEX; scene.triangle_count()];
        for t in 0..scene.triangle_count() as u32 {
            let m = scene.material_of(t);
            if !m.is_emissive() {
                continue;
            }
            let [a, b, c] = scene.positions()[t as usize];
            let area = triangle_area(a, b, c);
            let sides = if m.double_sided { 2.0 } else { 1.0 };
            emitter_slot[t as usize] = emitters.len() as u32;
            emitters.push(t);
            emitter_area.push(area);
            power.push(core::f32::consts::PI * area * luminance(m.emission) * sides);
        }
        let env = scene.environment();
        let environment = match &env.map {
            Some(map) if !env.is_black() => Some(EnvironmentSampler::new(map)),
            // A uniform sky is sampled perfectly by cosine-weighted directions already.
            _ => None,
        };
        let p_environment = match (environment.is_some(), emitters.is_empty()) {
            (false, _) => 0.0,
            (true, true) => 1.0,
            (true, false) => 0.5,
        };
        Self {
            emitters,
            emitter_area,
            emitter_distribution: Distribution1D::new(&power),
            emitter_slot,
            environment,
            p_environment,
        }
    }

    /// True when there is nothing to sample (no emitters, no environment map).
    pub fn is_empty(&self) -> bool {
        self.emitters.is_empty() && self.environment.is_none()
    }

    /// The importance sampler of the environment map (`None`: no map, or a black one).
    pub fn environment(&self) -> Option<&EnvironmentSampler> {
        self.environment.as_ref()
    }

    /// Number of emissive triangles.
    pub fn emitter_count(&self) -> usize {
        self.emitters.len()
    }

    /// Draws a light direction as seen from `x`: `select` chooses the source, `u` the
    /// point on it. Emissive triangles are sampled uniformly by area and converted to solid
    /// angle, p(ω) = P(triangle) · d² / (A |cos θ_l|) (pbrt-v4 §12.2); the environment by
    /// [`EnvironmentSampler`]. `None` when the sample carries no light.
    #[inline]
    pub fn sample(
        &self,
        scene: &TracedScene,
        x: Vec3,
        select: f32,
        u: Vec2,
    ) -> Option<LightSample> {
        if self.is_empty() {
            return None;
        }
        if select < self.p_environment {
            let env = self.environment.as_ref()?;
            let (direction, pdf) = env.sample(u);
            if pdf <= 0.0 {
                return None;
            }
            return Some(LightSample {
                direction,
                distance: f32::INFINITY,
                emitted: None,
                pdf: pdf * self.p_environment,
            });
        }
        let select = (select - self.p_environment) / (1.0 - self.p_environment);
        let (k, p_choice, _) = self.emitter_distribution.sample(select);
        let t = self.emitters[k];
        let [a, b, c] = scene.positions()[t as usize];
        let uv = uniform_triangle(u);
        let y = triangle_point(a, b, c, uv);
        let to_light = y - x;
        let d2 = to_light.length_squared();
        if d2 <= 0.0 {
            return None;
        }
        let distance = d2.sqrt();
        let direction = to_light / distance;
        let mu = scene.geometric_normals()[t as usize];
        let cos_light = mu.dot(direction);
        if cos_light == 0.0 {
            return None;
        }
        // The light's front face looks at x when its normal points back along the ray.
        let front = cos_light < 0.0;
        let material = scene.material_of(t);
        let uv0 = interpolate(
            scene.uv0()[t as usize][0],
            scene.uv0()[t as usize][1],
            scene.uv0()[t as usize][2],
            uv,
        );
        let radiance = material.emission_at(uv0, front);
        if radiance == Vec3::ZERO {
            return None;
        }
        let pdf =
            (1.0 - self.p_environment) * p_choice * d2 / (self.emitter_area[k] * cos_light.abs());
        Some(LightSample {
            direction,
            distance,
            emitted: Some(radiance),
            pdf,
        })
    }

    /// Prefetches what [`Self::sample`] will read first for (`select`, `u`) when it
    /// chooses the environment: the entries of its sampling tables (a cache miss each
    /// in a large map), so that a light sample drawn after tracing another ray finds
    /// them in the caches.
    #[inline]
    pub fn prefetch(&self, select: f32, u: Vec2) {
        if let Some(env) = &self.environment
            && select < self.p_environment
        {
            env.prefetch(u);
        }
    }

    /// Density [`Self::sample`] gives direction `w` from `x` when the ray in that direction
    /// first hits emissive triangle `t` at `y` (0 for a triangle that is not an emitter).
    #[inline]
    pub fn pdf_emitter(&self, scene: &TracedScene, t: u32, x: Vec3, y: Vec3, w: Vec3) -> f32 {
        let k = self.emitter_slot[t as usize];
        if k == NO_INDEX {
            return 0.0;
        }
        let k = k as usize;
        let cos_light = scene.geometric_normals()[t as usize].dot(w).abs();
        if cos_light == 0.0 {
            return 0.0;
        }
        (1.0 - self.p_environment) * self.emitter_distribution.pmf(k) * (y - x).length_squared()
            / (self.emitter_area[k] * cos_light)
    }

    /// Density [`Self::sample`] gives the environment direction whose image coordinates
    /// are `uv` ([`surfcache_core::environment::direction_to_uv`]).
    #[inline]
    pub fn pdf_environment(&self, uv: Vec2) -> f32 {
        match &self.environment {
            Some(env) => self.p_environment * env.pdf_uv(uv),
            None => 0.0,
        }
    }
}

/// Power heuristic with β = 2 (Veach 1997, eq. 9.13), for one sample from each technique:
/// w = p_a² / (p_a² + p_b²).
#[inline]
pub fn power_heuristic(pdf_a: f32, pdf_b: f32) -> f32 {
    let (a, b) = (pdf_a * pdf_a, pdf_b * pdf_b);
    if a == 0.0 {
        return 0.0;
    }
    if !b.is_finite() {
        return 0.0;
    }
    if !a.is_finite() {
        return 1.0;
    }
    a / (a + b)
}
