//! What a bake needs besides the scene, and the density a large scene's budget allows.

use crate::{CacheSettings, Method};
use serde::{Deserialize, Serialize};
use surfcache_trace::EstimatorSettings;

/// Everything a bake needs besides the scene.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BakeSettings {
    /// The cache to bake and its own settings.
    pub cache: CacheSettings,
    /// Per-point estimation; a `floor` of 0 is replaced by
    /// [`FLOOR_FRACTION`](super::FLOOR_FRACTION) of the scene's mean irradiance
    /// ([`mean_irradiance`](super::mean_irradiance)).
    pub estimator: EstimatorSettings,
    pub seed: u64,
    /// Most bounce passes before the final one (0: no passes, every path of the final
    /// pass is traced to its end). See [`BakeJob`](super::BakeJob).
    pub gather_passes: u32,
    /// Lower the cache's density for large scenes so that one side of all surfaces holds
    /// about this many samples or texels ([`fitted_density`]); `None` keeps the density
    /// as set.
    #[serde(default)]
    pub density_budget: Option<u64>,
}

impl Default for BakeSettings {
    fn default() -> Self {
        let method = Method::default();
        let (min_samples, max_samples) = method.default_sample_range();
        Self {
            cache: CacheSettings::for_method(method),
            estimator: EstimatorSettings {
                floor: 0.0,
                min_samples,
                max_samples,
                ..Default::default()
            },
            seed: 0,
            gather_passes: DEFAULT_GATHER_PASSES,
            density_budget: Some(DEFAULT_DENSITY_BUDGET),
        }
    }
}

/// Samples or texels on one side of a scene's surfaces by default: 2¹⁹, 8 texels per
/// metre over a level of 8,000 m² (Crytek Sponza), the caches' full density (64 per
/// metre) on scenes up to 128 m².
pub const DEFAULT_DENSITY_BUDGET: u64 = 1 << 19;

/// The coarsest density (samples or texels per metre) a budget may lower a cache to:
/// texels of 12.5 cm, what game levels are lightmapped at.
pub const MIN_FITTED_DENSITY: f32 = 8.0;

/// The density a bake at `density` per metre uses on a scene whose surfaces have `area`
/// m² (one side) within `budget` samples: `min(density, max(MIN, sqrt(budget / area)))`.
pub fn fitted_density(density: f32, area: f64, budget: u64) -> f32 {
    if area.is_nan() || area <= 0.0 {
        return density;
    }
    let fit = (budget as f64 / area).sqrt() as f32;
    density.min(fit.max(MIN_FITTED_DENSITY))
}

/// Most bounce passes before the final one by default: enough for the bounce series of
/// any scene whose surfaces reflect at most about 75 % of the light (0.75^16 ≈ 1 %);
/// passes normally stop earlier, once the series has converged ([`BakeJob`](super::BakeJob)).
pub const DEFAULT_GATHER_PASSES: u32 = 16;
