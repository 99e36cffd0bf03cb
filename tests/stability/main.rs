//! Failure modes, tested on purpose (docs/design.md, Speed against accuracy): thin walls, hard shadows between
//! samples, dark niches, intersecting triangles, degenerate and needle triangles, a
//! sun-sized hot spot in an HDR map, very small and very large scenes, and shading normals
//! bent far from the geometry.
//!
//! One test per failure mode. Each says in its doc comment what fails and how the project
//! copes, and checks it against a closed form or a path-traced reference
//! ([`reference_irradiance`]), never against timings. Where the project does *not* cope,
//! the test asserts what happens today and says so, so that a fix has to update it.
//!
//! Tolerances: an adaptive estimate stops once its relative standard error
//! C = se/(E + ε) is at most `max_rel_error`; a cache lookup is a convex combination of
//! such estimates, so it lies within about 4·`max_rel_error`·(E + ε) of the truth (four
//! standard errors), plus half-float rounding (2⁻¹¹ of each channel) and, where E
//! varies, interpolation.

#[path = "../common/mod.rs"]
mod common;
mod extremes;
mod geometry;
mod visibility;

use surfcache::cache::bake::bake_to_convergence;
use surfcache::cache::{
    IrradianceMapSettings, IrradianceMaps, LightmapSettings, Lightmaps, SurfaceCache,
    VertexLighting, VertexLightingSettings,
};
use surfcache::core::glam::Vec3;
use surfcache::trace::{
    Estimate, EstimatorSettings, Query, Sampler, TracedScene, reference_irradiance,
};

// ---------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------

/// Path-traced reference at the points, `samples` `best` samples each.
fn reference(scene: &TracedScene, points: &[(Vec3, Vec3)], samples: u32) -> Vec<Estimate> {
    let queries: Vec<Query> = points
        .iter()
        .map(|&(position, normal)| Query { position, normal })
        .collect();
    let settings = EstimatorSettings::fixed(Sampler::Best, samples, None);
    reference_irradiance(scene, &queries, &settings, 17, &|| {})
        .into_iter()
        .zip(points)
        .map(|(e, (x, _))| e.unwrap_or_else(|| panic!("{x} is on no surface")))
        .collect()
}

fn bake_maps(
    scene: &TracedScene,
    maps: IrradianceMapSettings,
    e: &EstimatorSettings,
) -> IrradianceMaps {
    bake_to_convergence(scene, IrradianceMaps::new(scene, maps), e, 3)
}

fn bake_lightmaps(scene: &TracedScene, lm: LightmapSettings, e: &EstimatorSettings) -> Lightmaps {
    bake_to_convergence(scene, Lightmaps::new(scene, lm), e, 3)
}

fn bake_vertex(scene: &TracedScene, e: &EstimatorSettings) -> VertexLighting {
    let v = VertexLighting::new(scene, VertexLightingSettings::default());
    bake_to_convergence(scene, v, e, 3)
}

fn lightmap_density(texels_per_metre: f32) -> LightmapSettings {
    LightmapSettings {
        texels_per_metre,
        ..Default::default()
    }
}

/// Every texel of every texture a cache publishes is finite and non-negative.
#[track_caller]
fn assert_published_finite(cache: &dyn SurfaceCache, scene: &TracedScene, what: &str) {
    let textures = cache.publish(scene);
    assert!(!textures.is_empty(), "{what}: nothing published");
    for t in &textures {
        assert!(
            t.texels
                .iter()
                .all(|v| v.is_finite() && v.min_element() >= 0.0),
            "{what}: texture of '{}' has a non-finite or negative texel",
            t.name
        );
        assert!(
            t.uv1.iter().flatten().all(|uv| uv.is_finite()),
            "{what}: non-finite UV1"
        );
    }
}
