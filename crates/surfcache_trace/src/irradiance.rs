//! Monte Carlo estimation of irradiance E(x, ν) = ∫_H L_in(x, ω) ⟨ν, ω⟩ dω at one point.

use crate::{
    path_tracer::PathOptions,
    traced_scene::{SurfacePoint, TracedScene},
};
use glam::{DVec3, Vec3};
use surfcache_core::{
    geometry::to_world,
    sampling::{Rng, UNIFORM_HEMISPHERE_PDF, cosine_hemisphere, uniform_hemisphere},
};

/// How hemisphere directions are drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Sampler {
    /// Uniform over the hemisphere, p = 1/(2π): the thesis' sampler.
    Uniform,
    /// Cosine-weighted, p = cos θ/π.
    #[default]
    Cosine,
}

impl Sampler {
    /// All samplers, in the order the CLI lists them.
    pub const ALL: [Sampler; 2] = [Sampler::Uniform, Sampler::Cosine];

    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Sampler::Uniform => "uniform",
            Sampler::Cosine => "cosine",
        }
    }

    /// Parses a command-line name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }
}

/// Running sums of the samples X_i of one estimate (f64, so millions of samples stay exact).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Accumulator {
    pub count: u32,
    pub sum: DVec3,
    pub sum_sq: DVec3,
}

impl Accumulator {
    #[inline]
    pub fn add(&mut self, x: Vec3) {
        let x = x.as_dvec3();
        self.count += 1;
        self.sum += x;
        self.sum_sq += x * x;
    }

    /// The mean Ē = (1/n) Σ X_i.
    pub fn mean(&self) -> DVec3 {
        self.sum / self.count.max(1) as f64
    }

    /// Standard error of the mean, sqrt(Σ(X_i − Ē)² / (n(n−1))) per channel (DESIGN.md §2).
    pub fn std_error(&self) -> DVec3 {
        if self.count < 2 {
            return DVec3::splat(f64::INFINITY);
        }
        let n = self.count as f64;
        let var = ((self.sum_sq - self.sum * self.sum / n) / (n - 1.0)).max(DVec3::ZERO);
        (var / n).map(f64::sqrt)
    }

    /// Coefficient of variation of the mean, C = se / (Ē + ε), maximum over the channels
    /// (DESIGN.md §2). `floor` is ε.
    pub fn relative_error(&self, floor: f64) -> f64 {
        let se = self.std_error();
        let mean = self.mean();
        (0..3)
            .map(|c| {
                if se[c] == 0.0 {
                    0.0
                } else {
                    se[c] / (mean[c] + floor)
                }
            })
            .fold(0.0, f64::max)
    }
}

/// One irradiance estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IrradianceEstimate {
    /// Ē in W/m² (hemisphere samples plus the exact punctual-light part).
    pub value: Vec3,
    /// Standard error of `value` per channel.
    pub std_error: Vec3,
    /// Hemisphere samples drawn.
    pub samples: u32,
}

impl IrradianceEstimate {
    /// Standard error over value, the largest over channels with light (0 for black).
    pub fn relative_std(&self) -> f32 {
        (0..3)
            .filter(|&c| self.value[c] > 0.0)
            .map(|c| self.std_error[c] / self.value[c])
            .fold(0.0, f32::max)
    }
}

/// One sample X = L_in(x, ω) ⟨ν, ω⟩ / p(ω) of the hemisphere integral at `p`, with ω drawn
/// by `sampler` about the shading normal ν. Directions under the geometric surface carry
/// no light (CONTRACT.md) and give X = 0.
#[inline]
pub fn hemisphere_sample(
    scene: &TracedScene,
    p: &SurfacePoint,
    origin: Vec3,
    sampler: Sampler,
    rng: &mut Rng,
    options: PathOptions,
) -> Vec3 {
    let u = rng.next_vec2();
    let (local, weight) = match sampler {
        Sampler::Uniform => {
            let l = uniform_hemisphere(u);
            (l, l.z / UNIFORM_HEMISPHERE_PDF)
        }
        // cos θ / (cos θ/π) = π
        Sampler::Cosine => (cosine_hemisphere(u), core::f32::consts::PI),
    };
    let w = to_world(local, p.shading_normal);
    if w.dot(p.geometric_normal) <= 0.0 || local.z <= 0.0 {
        return Vec3::ZERO;
    }
    scene.incident_radiance(origin, w, rng, options) * weight
}

/// E(x, ν) at `p` from `samples` hemisphere samples plus the punctual lights' exact part.
pub fn estimate_irradiance(
    scene: &TracedScene,
    p: &SurfacePoint,
    samples: u32,
    sampler: Sampler,
    rng: &mut Rng,
    options: PathOptions,
) -> IrradianceEstimate {
    let origin = scene.spawn_origin(p);
    let mut acc = Accumulator::default();
    for _ in 0..samples {
        acc.add(hemisphere_sample(scene, p, origin, sampler, rng, options));
    }
    let punctual = scene.punctual_irradiance(p);
    IrradianceEstimate {
        value: acc.mean().as_vec3() + punctual,
        std_error: acc.std_error().as_vec3(),
        samples,
    }
}

/// A query: a world-space point on a surface and the normal of the side asked about.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Query {
    pub position: Vec3,
    pub normal: Vec3,
}

/// Brute-force reference E(x, n) at each query point with `samples` hemisphere samples,
/// in parallel over points. Point `i` draws from `Rng::new(seed, i)`, so the result does
/// not depend on the thread count. `None` marks a point that is not on any surface.
/// `progress` is called once per finished point.
pub fn reference_irradiance(
    scene: &TracedScene,
    queries: &[Query],
    samples: u32,
    sampler: Sampler,
    seed: u64,
    options: PathOptions,
    progress: &(dyn Fn() + Sync),
) -> Vec<Option<IrradianceEstimate>> {
    use rayon::prelude::*;
    queries
        .par_iter()
        .enumerate()
        .map(|(i, q)| {
            let p = scene.locate(q.position, q.normal)?;
            let mut rng = Rng::new(seed, i as u64);
            let e = estimate_irradiance(scene, &p, samples, sampler, &mut rng, options);
            progress();
            Some(e)
        })
        .collect()
}
