//! One sample point: where it is estimated, how, and how an incremental re-bake updates
//! it by its change since an edit; and the scene's mean irradiance, which sets the floor
//! of relative errors.

use crate::{
    Prior, SamplePoint, SampleSite, UNMAPPED,
    incremental::{ChangePlan, Influence, SKIP_SHARE},
};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::sync::Arc;
use surfcache_core::{
    color::luminance,
    sampling::{Cone, Rng},
};
use surfcache_trace::{
    Estimate, EstimatorSettings, Guidance, IrradianceLookup, PointInScene, Sampler, SurfacePoint,
    TracedScene, estimate, estimate_change, unchanged,
};

/// The point and ray origin at which `site` is estimated.
///
/// A [`SampleSite::Surface`] uses [`TracedScene::surface_point`] and the leak-guarded
/// [`TracedScene::spawn_origin`]. A [`SampleSite::Vertex`] sits exactly on the vertex, with
/// the vertex normal μ_X (negated for the back side) as both shading and geometric normal
/// and the origin lifted along it by [`TracedScene::spawn_offset`].
pub fn sample_frame(scene: &TracedScene, site: &SampleSite) -> (SurfacePoint, Vec3) {
    match *site {
        SampleSite::Surface {
            triangle,
            uv,
            front,
        } => {
            let p = scene.surface_point(triangle, uv, front);
            let origin = scene.spawn_origin(&p);
            (p, origin)
        }
        SampleSite::Vertex {
            triangle,
            corner,
            front,
        } => {
            let k = corner as usize;
            let sign = if front { 1.0 } else { -1.0 };
            let n = scene.normals()[triangle as usize][k] * sign;
            let position = scene.positions()[triangle as usize][k];
            let uv = [Vec2::ZERO, Vec2::X, Vec2::Y][k];
            let p = SurfacePoint {
                position,
                triangle,
                uv,
                geometric_normal: n,
                shading_normal: n,
            };
            (p, position + n * scene.spawn_offset())
        }
    }
}

/// `site` of an edited scene `new` as the scene `old` before the edit had it (same
/// barycentrics on the corresponding triangle, the same mesh vertex for vertex sites);
/// `None` for a site without a counterpart.
pub fn map_site(
    old: &TracedScene,
    new: &TracedScene,
    site: &SampleSite,
    triangle_map: &[u32],
) -> Option<SampleSite> {
    match *site {
        SampleSite::Surface {
            triangle,
            uv,
            front,
        } => {
            let t = *triangle_map.get(triangle as usize)?;
            (t != UNMAPPED).then_some(SampleSite::Surface {
                triangle: t,
                uv,
                front,
            })
        }
        SampleSite::Vertex {
            triangle,
            corner,
            front,
        } => {
            let t = *triangle_map.get(triangle as usize)?;
            if t == UNMAPPED {
                return None;
            }
            let vertex = new.vertex_indices()[triangle as usize][corner as usize];
            let corner = old.vertex_indices()[t as usize]
                .iter()
                .position(|&v| v == vertex)? as u8;
            Some(SampleSite::Vertex {
                triangle: t,
                corner,
                front,
            })
        }
    }
}

/// The scene before an edit, for incremental re-bakes: sample points that carry a
/// [`SamplePoint::prior`] are updated by the change between it and the edited scene
/// ([`surfcache_trace::estimate_change`]).
#[derive(Clone)]
pub struct Previous {
    pub scene: Arc<TracedScene>,
    /// `triangle_map[t_new]`: the corresponding triangle of `scene` ([`crate::triangle_map`]).
    pub triangle_map: Arc<Vec<u32>>,
    /// The gathering lookup the pass used before the edit.
    pub gather: Option<Arc<dyn IrradianceLookup + Send>>,
    /// A sphere (centre, radius) holding every surface the edit changed: changes are then
    /// integrated over the cone of directions towards it only.
    pub focus: Option<(Vec3, f32)>,
    /// A bound on the change (indirect stages of a re-bake): points it proves unchanged
    /// keep their value, the others integrate over the cone it gives
    /// ([`crate::incremental::ChangeBound::plan`]).
    pub bound: Option<Arc<crate::incremental::ChangeBound>>,
    /// Where the stage's change can reach: points it does not reach keep their value
    /// without a ray ([`Influence::reaches`]).
    pub influence: Option<Arc<Influence>>,
    /// Whether the surfaces differ from `scene`'s (the direct stage of a re-bake). Where
    /// they do not, a point found buried before stays buried: its filled prior is kept
    /// and filled again from its neighbours, never estimated.
    pub geometry_changed: bool,
}

impl Previous {
    /// Point `p` of the edited `scene` updated by its change since the edit
    /// ([`surfcache_trace::estimate_change`]), when it carries a prior and has a
    /// counterpart before the edit ([`map_site`]); `None` otherwise.
    pub(super) fn update(
        &self,
        scene: &TracedScene,
        p: &SamplePoint,
        settings: &EstimatorSettings,
        seed: u64,
        gather: Option<&dyn IrradianceLookup>,
    ) -> Option<Estimate> {
        let (prior, estimated) = match p.prior? {
            Prior::Estimated(v) => (v, true),
            Prior::Filled(v) => (v, false),
        };
        if !estimated && !self.geometry_changed {
            return Some(unchanged(prior, settings));
        }
        let old_site = map_site(&self.scene, scene, &p.site, &self.triangle_map)?;
        let (new_point, new_origin) = sample_frame(scene, &p.site);
        let allowance =
            SKIP_SHARE * settings.max_rel_error * (prior.min_element().max(0.0) + settings.floor);
        if let Some(influence) = &self.influence
            && !influence.reaches(
                new_point.triangle,
                new_point.position,
                new_point.geometric_normal,
                allowance,
            )
        {
            return Some(unchanged(prior, settings));
        }
        if !estimated {
            return None;
        }
        // Only points the stage estimates need their frame before the edit.
        let (old_point, old_origin) = sample_frame(&self.scene, &old_site);
        let new = PointInScene::new(scene, new_point, new_origin).with_gather(gather);
        let old = PointInScene::new(&self.scene, old_point, old_origin)
            .with_gather(self.gather.as_deref().map(|g| g as &dyn IrradianceLookup));
        let focus = match &self.bound {
            Some(bound) => match bound.plan(new_origin, new_point.geometric_normal, allowance) {
                ChangePlan::Unchanged => return Some(unchanged(prior, settings)),
                ChangePlan::Cone(cone) => Some(cone),
                ChangePlan::Hemisphere => None,
            },
            None => self
                .focus
                .map(|(c, r)| Cone::towards_sphere(new_origin, c, r)),
        };
        Some(estimate_change(
            &old,
            &new,
            prior,
            settings,
            seed,
            p.key,
            focus.as_ref(),
        ))
    }
}

/// Estimates E at one sample point of a cache (with final gathering from `gather` when
/// given: see [`IrradianceLookup`]), guided as the cache says, stopping early where the
/// cache will discard it as buried above `buried_share` ([`crate::SurfaceCache::buried_share`]).
/// A point with a budget draws exactly that many samples; one without draws until the
/// estimator's stopping rule, at most its [`SamplePoint::cap_share`] of `max_samples`.
pub fn estimate_point(
    scene: &TracedScene,
    point: &SamplePoint,
    settings: &EstimatorSettings,
    seed: u64,
    gather: Option<&dyn IrradianceLookup>,
    guidance: Guidance,
    buried_share: Option<f32>,
) -> Estimate {
    let (p, origin) = sample_frame(scene, &point.site);
    let at = PointInScene::new(scene, p, origin)
        .with_gather(gather)
        .with_guidance(guidance)
        .with_buried_share(buried_share);
    match point.budget {
        Some(n) => {
            let fixed = EstimatorSettings {
                max_rel_error: 0.0,
                min_samples: n,
                max_samples: n,
                ..*settings
            };
            estimate(&at, &fixed, seed, point.key)
        }
        None if point.cap_share < 1.0 => {
            let share = (settings.max_samples as f32 * point.cap_share) as u32;
            let capped = EstimatorSettings {
                max_samples: share.clamp(
                    settings.min_samples.min(settings.max_samples),
                    settings.max_samples,
                ),
                ..*settings
            };
            estimate(&at, &capped, seed, point.key)
        }
        None => estimate(&at, settings, seed, point.key),
    }
}

/// The scene's mean irradiance (luminance, W/m²) over the front sides of its surfaces,
/// from `points` area-weighted random points with 64 samples each: the scale the
/// relative-error floor ε follows ([`FLOOR_FRACTION`](super::FLOOR_FRACTION) of it).
pub fn mean_irradiance(scene: &TracedScene, points: u32, seed: u64) -> f32 {
    let areas = scene.area_distribution();
    let settings = EstimatorSettings::fixed(Sampler::Best, 64, None);
    let total: f64 = (0..points)
        .into_par_iter()
        .map(|i| {
            let mut rng = Rng::new(seed ^ 0xF100_F100, i as u64);
            let p = scene.sample_surface(&areas, rng.next_f32(), rng.next_vec2(), true);
            let origin = scene.spawn_origin(&p);
            let e = estimate(
                &PointInScene::new(scene, p, origin),
                &settings,
                seed,
                u64::MAX - i as u64,
            );
            luminance(e.value) as f64
        })
        .sum();
    (total / points.max(1) as f64) as f32
}
