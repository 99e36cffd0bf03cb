//! Random numbers and the warps that turn them into directions and points.
//!
//! Every estimate draws from its own [`Rng`] stream keyed by (seed, point index), so a
//! result never depends on how work was split across threads or frames.

use core::f32::consts::{FRAC_1_PI, PI, TAU};
use glam::{Vec2, Vec3};
use rand_core::RngCore;
use rand_pcg::Pcg32;

/// A small, fast, reproducible random stream (PCG32).
#[derive(Clone, Debug)]
pub struct Rng(Pcg32);

impl Rng {
    /// The stream for work item `index` under the user's `seed`.
    ///
    /// ```
    /// use surfcache_core::sampling::Rng;
    /// let mut a = Rng::new(7, 42);
    /// let mut b = Rng::new(7, 42);
    /// assert_eq!(a.next_f32(), b.next_f32());
    /// ```
    pub fn new(seed: u64, index: u64) -> Self {
        // splitmix64 decorrelates neighbouring seeds and indices before PCG's own mixing.
        let state = splitmix64(seed ^ splitmix64(index.wrapping_add(0x9E37_79B9_7F4A_7C15)));
        Rng(Pcg32::new(state, splitmix64(index) | 1))
    }

    /// Uniform in [0, 1), 24 bits of precision.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.0.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }

    /// Two uniform numbers in [0, 1)².
    #[inline]
    pub fn next_vec2(&mut self) -> Vec2 {
        Vec2::new(self.next_f32(), self.next_f32())
    }

    /// Raw 32 random bits.
    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        self.0.next_u32()
    }
}

/// splitmix64 finaliser (Steele et al. 2014), a bijective 64-bit mixer.
#[inline]
pub fn splitmix64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// Uniform direction on the hemisphere around +z, density p(ω) = 1/(2π)
/// (pbrt-v4 §A.5.3, `SampleUniformHemisphere`).
#[inline]
pub fn uniform_hemisphere(u: Vec2) -> Vec3 {
    let z = u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = TAU * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Density of [`uniform_hemisphere`]: 1/(2π).
pub const UNIFORM_HEMISPHERE_PDF: f32 = 0.5 * FRAC_1_PI;

/// Cosine-weighted direction around +z, p(ω) = cos θ / π, by Malley's method on
/// Shirley–Chiu's concentric disk (pbrt-v4 §A.5.3, `SampleCosineHemisphere`).
#[inline]
pub fn cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = concentric_disk(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

/// Density of [`cosine_hemisphere`] for a direction with cos θ = `cos_theta`.
#[inline]
pub fn cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    cos_theta.max(0.0) * FRAC_1_PI
}

/// The square point that [`cosine_hemisphere`] maps to the local direction `w` (z ≥ 0):
/// the inverse of Malley's projection and of [`concentric_disk`]. Directed learning of
/// where light comes from works on this square (`surfcache_trace::guiding`).
///
/// ```
/// use surfcache_core::{glam::Vec2, sampling::{cosine_hemisphere, cosine_hemisphere_square}};
/// let u = Vec2::new(0.3, 0.8);
/// assert!((cosine_hemisphere_square(cosine_hemisphere(u)) - u).length() < 1e-5);
/// ```
#[inline]
pub fn cosine_hemisphere_square(w: Vec3) -> Vec2 {
    concentric_disk_inverse(Vec2::new(w.x, w.y))
}

/// Inverse of [`concentric_disk`]: the point of [0,1)² that maps to the disk point `d`
/// (|d| ≤ 1), by the same four wedges.
#[inline]
pub fn concentric_disk_inverse(d: Vec2) -> Vec2 {
    let r = d.length().min(1.0);
    if r == 0.0 {
        return Vec2::splat(0.5);
    }
    let quarter = 0.25 * PI;
    let mut phi = d.y.atan2(d.x);
    if phi < -quarter {
        phi += TAU;
    }
    let o = if phi < quarter {
        Vec2::new(r, r * phi / quarter)
    } else if phi < 3.0 * quarter {
        Vec2::new(r * (0.5 * PI - phi) / quarter, r)
    } else if phi < 5.0 * quarter {
        Vec2::new(-r, -r * (phi - PI) / quarter)
    } else {
        Vec2::new(-r * (1.5 * PI - phi) / quarter, -r)
    };
    ((o + Vec2::ONE) * 0.5).clamp(Vec2::ZERO, Vec2::splat(ONE_MINUS_EPSILON))
}

/// Shirley–Chiu concentric map from the unit square to the unit disk (pbrt-v4 §A.5.1).
#[inline]
pub fn concentric_disk(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, theta) = if o.x.abs() > o.y.abs() {
        (o.x, 0.25 * PI * (o.y / o.x))
    } else {
        (o.y, 0.5 * PI - 0.25 * PI * (o.x / o.y))
    };
    r * Vec2::new(theta.cos(), theta.sin())
}

/// Uniform barycentrics (u,v) on a triangle, area density 1/A (pbrt-v4 §A.5.4,
/// Heitz's low-distortion mapping).
#[inline]
pub fn uniform_triangle(u: Vec2) -> Vec2 {
    let (b0, b1);
    if u.x < u.y {
        b0 = u.x / 2.0;
        b1 = u.y - b0;
    } else {
        b1 = u.y / 2.0;
        b0 = u.x - b1;
    }
    Vec2::new(b1, 1.0 - b0 - b1)
}

/// Uniform direction on the unit sphere, p(ω) = 1/(4π).
#[inline]
pub fn uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = TAU * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// A piecewise-constant distribution over `n` bins of [0, 1) with probabilities
/// proportional to non-negative weights (pbrt-v4 §A.1, `PiecewiseConstant1D`).
///
/// Sampling inverts the cdf through a guide table (the cutpoint method, Chen and Asau
/// 1974): for each of G = 2^⌈log₂ n⌉ equal slices of [0, 1) it holds the first bin the
/// slice can fall in, so a sample searches only the bins of its slice (about one)
/// instead of all n; the answer is the one a binary search over the whole cdf gives.
/// The cdf and the guide are interleaved in one table of 8-byte entries: where the weights
/// are even, a slice's guide points at a bin next to it, and a sample reads both from
/// one cache line (an environment map's 512 rows of 1,024 columns do not fit a core's
/// cache, and the two reads were two misses).
///
/// ```
/// use surfcache_core::sampling::Distribution1D;
/// let d = Distribution1D::new(&[1.0, 3.0]);
/// assert_eq!(d.sample(0.5).0, 1);
/// assert!((d.pmf(1) - 0.75).abs() < 1e-6);
/// ```
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Distribution1D {
    /// G + 1 entries (G ≥ n): entry k holds guide[k], and cdf[k] for k ≤ n (zero beyond).
    table: Vec<CdfEntry>,
    /// Number of bins n.
    bins: usize,
    /// Number of guide slices G, a power of two (so that g / G and u · G are exact in f32).
    slices: usize,
    /// Σ w (0 when every weight is zero: the distribution is then uniform).
    total: f64,
}

/// One entry of [`Distribution1D`]'s table: cdf[k] = Σ_{i<k} w_i / Σ w (cdf[n] = 1), and
/// guide[k], the first bin whose upper cdf exceeds k / G.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(8))]
struct CdfEntry {
    cdf: f32,
    guide: u32,
}

impl Distribution1D {
    /// Builds the distribution; non-finite or negative weights count as zero. All-zero
    /// weights give the uniform distribution.
    pub fn new(weights: &[f32]) -> Self {
        let clean = |w: f32| {
            if w.is_finite() && w > 0.0 {
                w as f64
            } else {
                0.0
            }
        };
        let total: f64 = weights.iter().map(|&w| clean(w)).sum();
        let n = weights.len();
        let mut cdf = Vec::with_capacity(n + 1);
        cdf.push(0.0);
        let mut acc = 0.0f64;
        for (i, &w) in weights.iter().enumerate() {
            acc += if total > 0.0 { clean(w) } else { 1.0 };
            let denom = if total > 0.0 { total } else { n as f64 };
            cdf.push(if i + 1 == n {
                1.0
            } else {
                (acc / denom) as f32
            });
        }
        let slices = n.next_power_of_two();
        let mut table = vec![CdfEntry::default(); slices + 1];
        for (entry, &c) in table.iter_mut().zip(&cdf) {
            entry.cdf = c;
        }
        for (g, entry) in table.iter_mut().enumerate() {
            entry.guide = cdf[1..].partition_point(|&c| c <= g as f32 / slices as f32) as u32;
        }
        Self {
            table,
            bins: n,
            slices,
            total,
        }
    }

    /// Number of bins.
    pub fn len(&self) -> usize {
        self.bins
    }

    /// True for a distribution over no bins.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Σ w of the weights it was built from.
    pub fn total(&self) -> f64 {
        self.total
    }

    /// Probability of bin `i`.
    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        self.table[i + 1].cdf - self.table[i].cdf
    }

    /// Prefetches the table entry [`Self::sample`] starts its search at for `u`
    /// ([`crate::prefetch`]).
    #[inline]
    pub fn prefetch(&self, u: f32) {
        let g = ((u * self.slices as f32) as usize).min(self.slices - 1);
        crate::prefetch::prefetch(&self.table[g]);
    }

    /// Inverts the cdf at `u ∈ [0,1)`: the bin, its probability, and `u` remapped to [0,1)
    /// inside the bin (so one random number serves both the choice and the position).
    #[inline]
    pub fn sample(&self, u: f32) -> (usize, f32, f32) {
        let n = self.bins;
        // First bin whose upper cdf exceeds u (skipping zero-probability bins), searched
        // between the guides of u's slice: u ∈ [g/G, (g+1)/G) lies in bins guide[g] ..=
        // guide[g+1].
        let slices = self.slices;
        let g = ((u * slices as f32) as usize).min(slices - 1);
        let (first, last) = (
            self.table[g].guide as usize,
            (self.table[g + 1].guide as usize).min(n - 1),
        );
        let i =
            (first + self.table[first + 1..=last + 1].partition_point(|e| e.cdf <= u)).min(n - 1);
        let (lo, hi) = (self.table[i].cdf, self.table[i + 1].cdf);
        let pmf = hi - lo;
        let remapped = if pmf > 0.0 {
            ((u - lo) / pmf).clamp(0.0, ONE_MINUS_EPSILON)
        } else {
            0.5
        };
        (i, pmf, remapped)
    }
}

/// The largest f32 below 1.
pub const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// Owen-scrambled Sobol points (Burley 2020, "Practical Hash-based Owen Scrambling"),
/// one independent progressive sequence per `seed`: every aligned power-of-two run of
/// indices is a stratified (0, m, 2)-net in each consecutive pair of dimensions.
/// At most 2¹⁶ indices per seed.
#[inline]
pub fn sobol_4d(index: u32, dimension_set: u32, seed: u32) -> [f32; 4] {
    sobol_burley::sample_4d(index & 0xFFFF, dimension_set, seed)
}

/// A cone of directions around a unit `axis`: those within angle acos(`cos_max`) of it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cone {
    pub axis: Vec3,
    pub cos_max: f32,
}

impl Cone {
    /// The cone from `from` that holds the sphere (`centre`, `radius`): all directions
    /// when `from` is inside the sphere.
    pub fn towards_sphere(from: Vec3, centre: Vec3, radius: f32) -> Self {
        let d = centre - from;
        let dist2 = d.length_squared();
        if dist2 <= radius * radius {
            return Self {
                axis: Vec3::Z,
                cos_max: -1.0,
            };
        }
        let sin2 = radius * radius / dist2;
        Self {
            axis: d / dist2.sqrt(),
            cos_max: (1.0 - sin2).max(0.0).sqrt(),
        }
    }

    /// Solid angle 2π(1 − cos θ_max).
    #[inline]
    pub fn solid_angle(&self) -> f32 {
        TAU * (1.0 - self.cos_max)
    }

    /// Whether unit direction `w` lies in the cone.
    #[inline]
    pub fn contains(&self, w: Vec3) -> bool {
        self.axis.dot(w) >= self.cos_max
    }

    /// Whether every direction of the cone lies on or below the plane with normal `n`
    /// (the angle between `n` and the axis is at least 90° plus the cone's half-angle).
    #[inline]
    pub fn below(&self, n: Vec3) -> bool {
        if self.cos_max <= 0.0 {
            return false;
        }
        let sin_half = (1.0 - self.cos_max * self.cos_max).max(0.0).sqrt();
        n.dot(self.axis) <= -sin_half
    }

    /// A direction uniformly distributed in the cone, density 1 / [`Self::solid_angle`]
    /// (pbrt-v4 §A.5.4, `SampleUniformCone`).
    #[inline]
    pub fn sample(&self, u: Vec2) -> Vec3 {
        let cos_theta = (1.0 - u.x) + u.x * self.cos_max;
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let phi = TAU * u.y;
        crate::geometry::to_world(
            Vec3::new(sin_theta * phi.cos(), sin_theta * phi.sin(), cos_theta),
            self.axis,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn warps_stay_on_hemisphere() {
        let mut rng = Rng::new(1, 2);
        for _ in 0..10_000 {
            let u = rng.next_vec2();
            for d in [uniform_hemisphere(u), cosine_hemisphere(u)] {
                assert!(d.z >= 0.0 && (d.length() - 1.0).abs() < 1e-5);
            }
            let b = uniform_triangle(u);
            assert!(b.x >= 0.0 && b.y >= 0.0 && b.x + b.y <= 1.0 + 1e-6);
        }
    }

    #[test]
    fn cosine_mean_matches_closed_form() {
        // E[cos θ] under cosine sampling = ∫cos² θ/π dω = 2/3.
        let mut rng = Rng::new(3, 4);
        let n = 200_000;
        let mean: f64 = (0..n)
            .map(|_| cosine_hemisphere(rng.next_vec2()).z as f64)
            .sum::<f64>()
            / n as f64;
        assert!((mean - 2.0 / 3.0).abs() < 3e-3, "{mean}");
    }

    #[test]
    fn concentric_inverse_undoes_the_warp() {
        let mut rng = Rng::new(11, 12);
        for _ in 0..20_000 {
            let u = rng.next_vec2();
            let back = cosine_hemisphere_square(cosine_hemisphere(u));
            assert!((back - u).length() < 2e-4, "{u} -> {back}");
        }
        // Wedge boundaries and the centre.
        for u in [
            Vec2::new(0.5, 0.5),
            Vec2::new(0.9, 0.9),
            Vec2::new(0.1, 0.9),
            Vec2::new(0.1, 0.1),
            Vec2::new(0.9, 0.1),
            Vec2::new(0.0, 0.5),
        ] {
            let back = concentric_disk_inverse(concentric_disk(u));
            assert!((back - u).length() < 1e-5, "{u} -> {back}");
        }
    }

    #[test]
    fn distribution_matches_weights() {
        let d = Distribution1D::new(&[0.0, 1.0, 0.0, 3.0]);
        assert_eq!(d.len(), 4);
        let mut counts = [0u32; 4];
        let mut rng = Rng::new(5, 6);
        for _ in 0..40_000 {
            let (i, p, r) = d.sample(rng.next_f32());
            assert!((0.0..1.0).contains(&r));
            assert!((p - d.pmf(i)).abs() < 1e-7 && p > 0.0);
            counts[i] += 1;
        }
        assert_eq!((counts[0], counts[2]), (0, 0));
        let share = counts[3] as f32 / 40_000.0;
        assert!((share - 0.75).abs() < 0.01, "{share}");
        let uniform = Distribution1D::new(&[0.0, 0.0]);
        assert_eq!(uniform.pmf(0), 0.5);
    }

    #[test]
    fn guide_table_gives_the_bin_of_a_full_search() {
        // Skewed weights with runs of zeros (a sun in a dark sky), sizes that are and are
        // not powers of two, u at bin edges and slice edges.
        let mut rng = Rng::new(9, 1);
        for n in [1usize, 2, 3, 7, 64, 100, 1000] {
            let weights: Vec<f32> = (0..n)
                .map(|i| match i % 7 {
                    0 | 3 => 0.0,
                    5 => 1e4 * rng.next_f32(),
                    _ => rng.next_f32(),
                })
                .collect();
            let d = Distribution1D::new(&weights);
            let cdf: Vec<f32> = d.table[..=n].iter().map(|e| e.cdf).collect();
            let mut us: Vec<f32> = (0..5000).map(|_| rng.next_f32()).collect();
            us.extend(cdf.iter().copied().filter(|&c| c < 1.0));
            let slices = n.next_power_of_two();
            us.extend((0..slices).map(|g| g as f32 / slices as f32));
            us.push(ONE_MINUS_EPSILON);
            for u in us {
                // The first bin whose upper cdf exceeds u, searched over the whole cdf.
                let full = cdf[1..].partition_point(|&c| c <= u).min(n - 1);
                assert_eq!(d.sample(u).0, full, "n {n} u {u}");
            }
        }
    }

    #[test]
    fn sobol_points_are_stratified() {
        // 16 points of one aligned run hit each of the 4×4 strata once.
        for seed in [0, 17] {
            let mut hit = [false; 16];
            for i in 0..16 {
                let [x, y, ..] = sobol_4d(i, 0, seed);
                hit[(x * 4.0) as usize * 4 + (y * 4.0) as usize] = true;
            }
            assert!(hit.iter().all(|&h| h));
        }
    }

    #[test]
    fn cone_samples_stay_inside_and_cover_it() {
        let cone = Cone::towards_sphere(Vec3::ZERO, Vec3::new(1.0, 2.0, 2.0), 1.5);
        assert!((cone.axis.length() - 1.0).abs() < 1e-6);
        let mut rng = Rng::new(9, 9);
        let mut mean = Vec3::ZERO;
        for _ in 0..20_000 {
            let w = cone.sample(rng.next_vec2());
            assert!((w.length() - 1.0).abs() < 1e-4 && cone.axis.dot(w) >= cone.cos_max - 1e-5);
            mean += w;
        }
        // The mean direction of a uniform cone is its axis.
        assert!((mean.normalize() - cone.axis).length() < 1e-2);
        assert!(Cone::towards_sphere(Vec3::ZERO, Vec3::ZERO, 1.0).solid_angle() > 12.5);
        let below = Cone::towards_sphere(Vec3::ZERO, Vec3::new(0.0, -5.0, 0.0), 1.0);
        assert!(below.below(Vec3::Y) && !below.below(Vec3::X));
    }

    #[test]
    fn streams_differ() {
        let a: Vec<u32> = (0..4).map(|i| Rng::new(0, i).next_u32()).collect();
        assert!(a.windows(2).all(|w| w[0] != w[1]));
    }
}
