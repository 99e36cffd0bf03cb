//! Unbiased path tracing of incident radiance L_in(x, ω) over two-sided Lambertian surfaces,
//! with or without next-event estimation.

use crate::{
    guiding::DirectionGuide,
    light_sampling::power_heuristic,
    traced_scene::{SurfacePoint, TracedScene},
};
use glam::{Vec2, Vec3};
use surfcache_core::{
    Light,
    environment::direction_to_uv,
    geometry::to_world,
    sampling::{Rng, cosine_hemisphere, cosine_hemisphere_pdf},
};

/// Russian roulette starts at this bounce: the first bounces, which carry most of the
/// indirect light, are never cut short (docs/results.md, "Figures once kept in code
/// docs").
pub const ROULETTE_FROM_BOUNCE: u32 = 2;

/// Limits and techniques of one path.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PathOptions {
    /// Maximum number of indirect bounces (reflections after the first hit); `None` runs
    /// until Russian roulette ends the path. `Some(0)` counts only what the first hit emits
    /// plus the environment.
    pub max_bounces: Option<u32>,
    /// Next-event estimation: at every bounce a shadow ray towards an emissive triangle or
    /// the environment map, combined with the cosine-sampled continuation by multiple
    /// importance sampling (power heuristic).
    pub next_event: bool,
}

/// Irradiance already known on the surfaces (a coarse surface cache). With it, a path
/// ends at its first hit y with L = L_e(y) + ρ/π · E(y): *final gathering*, which shares
/// the cache's samples among all points that see y instead of tracing deeper bounces.
pub trait IrradianceLookup: Sync {
    /// E at barycentrics `uv` of `triangle` on the given side; `None` where the cache
    /// holds no value for that side (a back face the bake left out): the path goes on
    /// there as a full path.
    fn irradiance(&self, triangle: u32, uv: Vec2, front: bool) -> Option<Vec3>;

    /// Width in metres over which the albedo at a gathered hit may be averaged: the scale
    /// at which the cache's E is smooth (half its sample spacing). 0, the default, reads
    /// the albedo texture at full resolution.
    fn albedo_footprint(&self) -> f32 {
        0.0
    }

    /// The direction guide the cache learnt at barycentrics `uv` of `triangle` on the
    /// given side while it was baked (docs/design.md, Guiding), for a point of the next
    /// pass that has learnt none of its own. `None`, the default, where it learnt none.
    fn guide(&self, _triangle: u32, _uv: Vec2, _front: bool) -> Option<DirectionGuide> {
        None
    }
}

/// Angular width (radians) one gather ray stands for: a hit at distance r reads the
/// albedo averaged over r · `GATHER_ALBEDO_CONE` at most (a ray cone, as texture
/// filtering does for secondary rays), so that near hits, which a point sees in detail,
/// keep their texture detail. About the spacing of 1,024 directions over a hemisphere,
/// √(2π / 1024) ≈ 1/13.
pub const GATHER_ALBEDO_CONE: f32 = 1.0 / 16.0;

/// What the first segment of a path met, for detecting points buried inside geometry.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FirstHit {
    /// The ray escaped to the environment.
    #[default]
    Miss,
    /// The front face of a triangle, or either face of a double-sided material.
    Front,
    /// The back face of a single-sided material: the origin may be inside a closed object.
    Back,
}

/// Light arriving along one path, and what its first segment hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PathSample {
    pub radiance: Vec3,
    pub first_hit: FirstHit,
    /// Rays traced for it (closest-hit and shadow rays).
    pub rays: u32,
    /// Weight of its first direction among cosine-weighted ones, `cos θ/π / p(ω)`: 1/g
    /// when a guide drew it, else 1 (what a back-face share is counted with).
    pub first_weight: f32,
}

/// No light, no rays, an escaping first ray of weight 1 (an unguided direction).
impl Default for PathSample {
    fn default() -> Self {
        Self {
            radiance: Vec3::ZERO,
            first_hit: FirstHit::default(),
            rays: 0,
            first_weight: 1.0,
        }
    }
}

impl TracedScene {
    /// Irradiance at `p` from the punctual lights, by shadow rays:
    /// `I cos θ / r²` for point and spot lights (times the glTF cone falloff),
    /// `E_s cos θ` for directional lights, with cos θ = ⟨ν, ω_l⟩ about the shading normal and
    /// nothing from below the geometric surface (docs/cli.md).
    pub fn punctual_irradiance(&self, p: &SurfacePoint) -> Vec3 {
        self.punctual_irradiance_from(p, self.spawn_origin(p), &mut 0)
    }

    /// [`Self::punctual_irradiance`] with shadow rays leaving from `origin`; adds the
    /// shadow rays traced to `rays`.
    pub fn punctual_irradiance_from(&self, p: &SurfacePoint, origin: Vec3, rays: &mut u32) -> Vec3 {
        let mut e = Vec3::ZERO;
        for light in self.lights() {
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
            *rays += 1;
            if !self.occluded(origin, to_light, distance) {
                e += arriving * cos;
            }
        }
        e
    }

    /// Next-event estimate of the irradiance-like integral ∫ L_e(ω) ⟨ν, ω⟩ dω at `p` from
    /// one light sample (`select`, `u`), MIS-weighted against cosine sampling about ν
    /// (density `cos θ/π`): L_e ⟨ν,ω⟩ / p_l · w_l (Veach 1997, §9.2). Zero for directions
    /// below the shading or geometric surface and for occluded samples. Adds the shadow
    /// ray to `rays`.
    #[inline]
    pub fn direct_light_sample(
        &self,
        p: &SurfacePoint,
        origin: Vec3,
        select: f32,
        u: Vec2,
        rays: &mut u32,
    ) -> Vec3 {
        self.direct_light_sample_against(p, origin, select, u, rays, |cos, _| {
            Some(cosine_hemisphere_pdf(cos))
        })
    }

    /// [`Self::direct_light_sample`] MIS-weighted against another direction sampler:
    /// `other_pdf(cos θ, ω)` gives its density at ω, or `None` when ω lies outside the
    /// integral's domain (the sample then counts nothing).
    #[inline]
    pub fn direct_light_sample_against(
        &self,
        p: &SurfacePoint,
        origin: Vec3,
        select: f32,
        u: Vec2,
        rays: &mut u32,
        other_pdf: impl Fn(f32, Vec3) -> Option<f32>,
    ) -> Vec3 {
        // Sampled as seen from the ray origin, so the shadow ray ends exactly on the light.
        let Some(ls) = self.light_sampler().sample(self, origin, select, u) else {
            return Vec3::ZERO;
        };
        let cos = p.shading_normal.dot(ls.direction);
        if cos <= 0.0 || p.geometric_normal.dot(ls.direction) <= 0.0 {
            return Vec3::ZERO;
        }
        let Some(pdf_other) = other_pdf(cos, ls.direction) else {
            return Vec3::ZERO;
        };
        // Stop short of the sampled point so the emitter itself does not occlude it.
        let tmax = if ls.distance.is_finite() {
            ls.distance - self.spawn_offset()
        } else {
            f32::INFINITY
        };
        if tmax <= 0.0 {
            return Vec3::ZERO;
        }
        // The sky's texels are fetched while the shadow ray is traced, and read only if
        // it is not occluded.
        let sky_uv = ls.emitted.is_none().then(|| {
            let uv = direction_to_uv(ls.direction);
            self.environment().prefetch_uv(uv);
            uv
        });
        *rays += 1;
        if self.occluded(origin, ls.direction, tmax) {
            return Vec3::ZERO;
        }
        let weight = power_heuristic(ls.pdf, pdf_other);
        let radiance = match sky_uv {
            Some(uv) => self.environment().radiance_uv(uv),
            None => ls.emitted.unwrap_or_default(),
        };
        radiance * (cos * weight / ls.pdf)
    }

    /// One path-traced estimate of L_in(origin, ω): the radiance arriving at `origin` from
    /// direction `direction` (unit). Along the path it adds what surfaces emit towards it,
    /// the environment where it escapes, and punctual lights by shadow rays at every
    /// Lambertian bounce (throughput × ρ/π × E_punctual); bounces sample cosine-weighted
    /// directions about the shading normal (weight ρ), directions under the geometric
    /// surface end the path, and Russian roulette with survival probability
    /// min(max throughput, 0.95) from bounce [`ROULETTE_FROM_BOUNCE`] on keeps the
    /// estimate unbiased (pbrt-v4 §14.1.5).
    ///
    /// With [`PathOptions::next_event`], every bounce also samples a light (see
    /// [`Self::direct_light_sample`]) and emission found by the continuation rays is
    /// weighted by the power heuristic; `direction_pdf` is the solid-angle density with
    /// which the caller drew `direction` (cosine sampling), or `None` when emission along
    /// it must be counted in full.
    ///
    /// With `gather`, the path ends at its first hit y that the lookup holds, adding
    /// ρ/π · E(y) from it (its emission still counts, MIS-weighted as above), ρ averaged
    /// over min([`IrradianceLookup::albedo_footprint`], r · [`GATHER_ALBEDO_CONE`]) at
    /// distance r ([`TracedScene::albedo_over`]).
    pub fn incident_radiance(
        &self,
        origin: Vec3,
        direction: Vec3,
        direction_pdf: Option<f32>,
        rng: &mut Rng,
        options: PathOptions,
        gather: Option<&dyn IrradianceLookup>,
    ) -> PathSample {
        let nee = options.next_event && !self.light_sampler().is_empty();
        let mut radiance = Vec3::ZERO;
        let mut throughput = Vec3::ONE;
        let (mut o, mut d) = (origin, direction);
        let mut pdf = direction_pdf.filter(|_| nee);
        let mut first_hit = None;
        let mut bounce = 0u32;
        let mut rays = 0u32;
        loop {
            rays += 1;
            let Some(hit) = self.closest_hit(o, d, f32::INFINITY) else {
                // Image coordinates once for the radiance and the density (a uniform sky
                // reads neither).
                let uv = match self.environment().map {
                    Some(_) => direction_to_uv(d),
                    None => Vec2::ZERO,
                };
                let mut weight = 1.0;
                if let Some(p_bsdf) = pdf {
                    weight = power_heuristic(p_bsdf, self.light_sampler().pdf_environment(uv));
                }
                radiance += throughput * self.environment().radiance_uv(uv) * weight;
                first_hit.get_or_insert(FirstHit::Miss);
                break;
            };
            let t = hit.triangle;
            let material = self.material_of(t);
            let front = self.geometric_normals()[t as usize].dot(d) < 0.0;
            first_hit.get_or_insert(if front || material.double_sided {
                FirstHit::Front
            } else {
                FirstHit::Back
            });
            let uv0 = self.uv0_at(t, hit.uv);
            let emitted = material.emission_at(uv0, front);
            if emitted != Vec3::ZERO {
                let mut weight = 1.0;
                if let Some(p_bsdf) = pdf {
                    let x = self.surface_point(t, hit.uv, front).position;
                    let p_light = self.light_sampler().pdf_emitter(self, t, o, x, d);
                    weight = power_heuristic(p_bsdf, p_light);
                }
                radiance += throughput * emitted * weight;
            }
            if options.max_bounces.is_some_and(|b| bounce >= b) {
                break;
            }
            // A gathered hit ends the path without its position or normals: their
            // triangle data is read only by paths that go on.
            if let Some(cache) = gather
                && let Some(e) = cache.irradiance(t, hit.uv, front)
            {
                let footprint = cache.albedo_footprint().min(hit.t * GATHER_ALBEDO_CONE);
                let albedo = self.albedo_over(t, uv0, footprint);
                radiance += throughput * albedo * core::f32::consts::FRAC_1_PI * e;
                break;
            }
            let p = self.surface_point(t, hit.uv, front);
            let albedo = material.albedo_at(uv0);
            if albedo == Vec3::ZERO {
                break;
            }
            let spawn = self.spawn_origin(&p);
            let reflect = throughput * albedo * core::f32::consts::FRAC_1_PI;
            if !self.lights().is_empty() {
                radiance += reflect * self.punctual_irradiance_from(&p, spawn, &mut rays);
            }
            if nee {
                let select = rng.next_f32();
                let u = rng.next_vec2();
                radiance += reflect * self.direct_light_sample(&p, spawn, select, u, &mut rays);
            }
            throughput *= albedo;
            if bounce >= ROULETTE_FROM_BOUNCE {
                let survive = throughput.max_element().min(0.95);
                if survive <= 0.0 || rng.next_f32() >= survive {
                    break;
                }
                throughput /= survive;
            }
            let local = cosine_hemisphere(rng.next_vec2());
            let w = to_world(local, p.shading_normal);
            if w.dot(p.geometric_normal) <= 0.0 {
                break;
            }
            pdf = nee.then(|| cosine_hemisphere_pdf(local.z));
            o = spawn;
            d = w;
            bounce += 1;
        }
        PathSample {
            radiance,
            first_hit: first_hit.unwrap_or_default(),
            rays,
            first_weight: 1.0,
        }
    }
}
