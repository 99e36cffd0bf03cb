//! Ray tracing for surfcache: the obvhs BVH, ray queries, and the path tracer.
//!
//! - [`bvh`]: obvhs-built CWBVH over world triangles in a scale-normalised space, traversed
//!   by our own SIMD kernels (level chosen at run time); closest hit with
//!   barycentrics, any hit for shadow rays, point queries.
//! - [`traced_scene`]: a `Scene` flattened into world-space triangle arrays with its BVH,
//!   surface points with the normal function ν, spawn offsets that scale with the scene,
//!   and the nearest-surface lookup for query points.
//! - [`path_tracer`]: unbiased incident radiance L_in(x, ω).
//! - [`light_sampling`]: emitters and environment map for next-event estimation.
//! - [`irradiance`]: Monte Carlo irradiance E(x, ν) with selectable samplers and the
//!   adaptive relative-error stopping rule.
//! - [`guiding`]: densities over the hemisphere learned from earlier samples, which the
//!   estimator draws directions from.
//!
//! ```
//! use surfcache_core::{glam::Vec3, scenes};
//! use surfcache_trace::TracedScene;
//! let scene = TracedScene::new(&scenes::cornell()).unwrap();
//! // Straight down from under the ceiling hits the floor.
//! let hit = scene.closest_hit(Vec3::new(0.1, 0.5, 0.1), Vec3::NEG_Y, f32::INFINITY).unwrap();
//! assert!((hit.t - 0.5).abs() < 1e-5);
//! ```

pub mod bvh;
pub mod guiding;
pub mod irradiance;
pub mod light_sampling;
pub mod path_tracer;
pub mod traced_scene;

pub use bvh::{Bvh, Hit, SimdLevel};
pub use irradiance::{
    BURIED_PROBE_SAMPLES, Estimate, EstimatorSettings, FLOOR_FRACTION, Guidance, PointInScene,
    Query, Sampler, ZERO_RUN_EVENTS, estimate, estimate_change, reference_irradiance, unchanged,
    zero_run_std_error,
};
pub use light_sampling::LightSampler;
pub use path_tracer::{FirstHit, IrradianceLookup, PathOptions};
pub use traced_scene::{SurfacePoint, TracedScene};
