//! Surface caches: where baked irradiance lives, how it is looked up, and the textures it
//! publishes for engines (docs/design.md, Caches and Publishing).
//!
//! Three caches share one interface, [`SurfaceCache`]:
//! - [`vertex_lighting`]: E at mesh vertices, barycentric interpolation (the baseline);
//! - [`irradiance_map`]: the thesis' per-triangle adaptive barycentric grids;
//! - [`lightmap`]: irradiance per texel of a UV1 layout (the mesh's or a generated one).
//!
//! A cache is baked in *rounds*: it names the sample points it needs
//! ([`SurfaceCache::next_round`]), the baker estimates them (in parallel, in any order,
//! over as many frames as it likes, see [`bake`]) and hands the estimates back
//! ([`SurfaceCache::finish_round`]); an adaptive cache then asks for more. Every point
//! carries a stable key for its random stream, so results never depend on scheduling.
//! Caches are plain data over the triangle arrays of a
//! [`surfcache_trace::TracedScene`]: no ECS in here.

pub mod archive;
pub mod atlas;
pub mod bake;
mod burial;
pub mod charts;
pub mod crossings;
pub mod filter;
pub mod incremental;
pub mod irradiance_map;
pub mod lightmap;
pub mod mesh_colour;
pub mod stored_rgb;
pub mod texture;
pub mod vertex_lighting;

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use surfcache_core::index::NO_INDEX;
use surfcache_trace::{
    Estimate, EstimatorSettings, Guidance, IrradianceLookup, TracedScene, guiding::DirectionGuide,
};

pub use irradiance_map::{IrradianceMapSettings, IrradianceMaps};
pub use lightmap::{LightmapSettings, Lightmaps};
pub use texture::{IrradianceTexture, PublishedLookup};
pub use vertex_lighting::{VertexLighting, VertexLightingSettings};

/// Which cache to bake. The default is the one that bakes game levels best for the time
/// spent: lightmaps (docs/results.md, "Sponza: error against time").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Method {
    /// E at mesh vertices, interpolated with barycentrics.
    Vertex,
    /// Per-triangle adaptive irradiance maps (the thesis).
    IrradianceMap,
    /// Texel lightmaps on TEXCOORD_1 or a generated atlas.
    #[default]
    Lightmap,
}

impl Method {
    pub const ALL: [Method; 3] = [Method::Vertex, Method::IrradianceMap, Method::Lightmap];

    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Method::Vertex => "vertex",
            Method::IrradianceMap => "irradiance-map",
            Method::Lightmap => "lightmap",
        }
    }

    /// Parses a command-line name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }

    /// Default fewest and most hemisphere samples per estimate. Lightmap texels and
    /// irradiance-map grid samples share samples with their neighbours ([`filter`]) and
    /// a level holds millions of them: their own estimates start far lower than the
    /// thesis' (a lightmap's adaptive rounds compare the *filtered* error with the
    /// bound), and the cap keeps the dimmest, noisiest of them (lit through small
    /// openings) from taking tens of thousands of samples each. Vertex lighting takes the
    /// estimator's: every vertex meets the bound on its own, the thesis' model.
    pub fn default_sample_range(self) -> (u32, u32) {
        match self {
            Method::Lightmap | Method::IrradianceMap => (64, 1024),
            Method::Vertex => {
                let e = surfcache_trace::EstimatorSettings::default();
                (e.min_samples, e.max_samples)
            }
        }
    }
}

/// Where one sample of a cache is estimated.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum SampleSite {
    /// Barycentrics `uv` of `triangle`, on its front or back side. Rays leave from
    /// [`TracedScene::spawn_origin`], a small step inside the triangle (the leak guard).
    Surface {
        triangle: u32,
        uv: Vec2,
        front: bool,
    },
    /// Corner `corner` (0..3) of `triangle`, estimated at the vertex itself about its
    /// vertex normal (flipped for the back side), rays lifted off along that normal only:
    /// the classic vertex-lighting estimate, which sees through walls meeting the vertex.
    Vertex {
        triangle: u32,
        corner: u8,
        front: bool,
    },
}

/// What a sample held before an edit, in the first round of an incremental re-bake.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Prior {
    /// Its estimate: kept where the edit cannot reach the sample, else updated by the
    /// estimated change ([`surfcache_trace::estimate_change`]).
    Estimated(Vec3),
    /// A value filled from its neighbours (the sample was buried in other geometry):
    /// kept, still buried, where the edit cannot reach the sample, else estimated afresh.
    Filled(Vec3),
}

impl Prior {
    /// Whether a sample with `prior` whose estimate is `e` stays buried: a filled prior
    /// the re-bake kept without drawing a sample (the edit did not reach it).
    pub fn kept_buried(prior: Option<Prior>, e: &Estimate) -> bool {
        e.samples == 0 && matches!(prior, Some(Prior::Filled(_)))
    }
}

/// A sample a cache needs, with the key of its random stream.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SamplePoint {
    pub site: SampleSite,
    /// Stable identity: derive it from [`TracedScene::triangle_key`] and the sample's
    /// position in the cache, never from its position in a round.
    pub key: u64,
    /// In the first round of an incremental re-bake ([`SurfaceCache::remap`]): what the
    /// sample held before the edit.
    pub prior: Option<Prior>,
    /// Exactly this many hemisphere samples, whatever their error (the cache decides
    /// where more are needed, e.g. after filtering); `None`: the estimator's own stopping
    /// rule.
    pub budget: Option<u32>,
    /// Share of the estimator's `max_samples` this point may draw when `budget` is `None`
    /// (1: all of them; never below `min_samples`). Irradiance-map samples that stand for
    /// less surface than the density's spacing draw fewer (`irradiance_map` module docs,
    /// Samples by area).
    pub cap_share: f32,
}

/// Figures every cache reports (`report.json`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CacheStats {
    /// Points at which E was estimated.
    pub sample_points: u64,
    /// Hemisphere samples over all points.
    pub samples: u64,
    /// Most hemisphere samples at one point.
    pub max_samples_per_point: u32,
    /// Bytes of the cache's stored irradiance and its indexing.
    pub cache_bytes: u64,
    /// Mean estimated relative error C of the sample points.
    pub mean_rel_error: f64,
    /// Irradiance maps: number of (triangle, side) grids per final order.
    pub order_histogram: BTreeMap<u32, u64>,
    /// Sample points or texels found buried in other geometry (not used; filled from
    /// valid neighbours).
    pub buried: u64,
    /// Texels covered by no triangle that were filled by dilation (lightmaps).
    pub dilated_texels: u64,
}

/// What every surface cache offers (module docs).
pub trait SurfaceCache: Send + Sync {
    /// The method this cache implements.
    fn method(&self) -> Method;

    /// Called once before the first round with the estimator the baker will use, for
    /// caches that plan their own rounds of samples ([`lightmap`]). The default ignores it.
    fn plan_sampling(&mut self, _estimator: &EstimatorSettings) {}

    /// Appends the sample points of the next round to `points`; appends nothing once the
    /// cache has converged.
    fn next_round(&mut self, scene: &TracedScene, points: &mut Vec<SamplePoint>);

    /// Samples the cache expects to ask for in the rounds after the one it last handed
    /// out, if it can tell, where a point takes `samples_per_point` on average (progress
    /// reports use it; `None` leaves them counting the running round's points).
    fn later_samples(&self, _samples_per_point: f64) -> Option<u64> {
        None
    }

    /// How point `i` of the round [`Self::next_round`] last produced draws its directions
    /// and what it records for later rounds (docs/design.md, Guiding). The default:
    /// plain cosine-weighted directions, nothing recorded.
    fn guidance(&self, _i: usize) -> Guidance<'_> {
        Guidance::default()
    }

    /// Whether a point that [`Self::guidance`] gives no guide draws through the guide the
    /// pass it gathers from learnt where it lies ([`IrradianceLookup::guide`];
    /// docs/design.md, Guiding). The default: no.
    fn borrows_guides(&self) -> bool {
        false
    }

    /// The back-face share above which the cache will discard point `i` of the round
    /// [`Self::next_round`] last produced as buried, if it discards any: its estimate may
    /// stop as soon as that is sure ([`PointInScene::with_buried_share`]). The default:
    /// none, every estimate runs to its own stopping rule.
    fn buried_share(&self, _i: usize) -> Option<f32> {
        None
    }

    /// Takes the estimates of the points the last [`Self::next_round`] produced, in the
    /// same order.
    fn finish_round(&mut self, scene: &TracedScene, points: &[SamplePoint], estimates: &[Estimate]);

    /// Baked irradiance E (W/m²) at barycentrics `uv` of `triangle`, on the given side.
    fn lookup(&self, triangle: u32, uv: Vec2, front: bool) -> Vec3;

    /// Whether the cache bakes that side of `triangle` (a front-only bake leaves back
    /// faces out): where it does not, [`Self::lookup`] has no meaning and a gathering
    /// path traces on.
    fn holds(&self, triangle: u32, front: bool) -> bool;

    /// Sample counts, bytes and method-specific figures.
    fn stats(&self) -> CacheStats;

    /// Irradiance textures with their UV1 layout: the front side of every instance, and
    /// the back side of instances with a double-sided material.
    fn publish(&self, scene: &TracedScene) -> Vec<IrradianceTexture>;

    /// Sample count (and irradiance-map order) behind the value at a point, for the
    /// thesis' diagnostic pictures.
    fn diagnostic(&self, triangle: u32, uv: Vec2, front: bool) -> Diagnostic;

    /// The cache laid out for an edited scene `new`, ready for an incremental re-bake:
    /// its first round asks again for every sample whose triangle still exists
    /// (`triangle_map[t_new]` is its triangle in `old`, or [`UNMAPPED`]) with the value it
    /// had as [`SamplePoint::prior`], and for fresh samples elsewhere; later rounds refine
    /// as usual. The cache must have finished baking over `old`.
    fn remap(&self, old: &TracedScene, new: &TracedScene, triangle_map: &[u32]) -> Self
    where
        Self: Sized;
}

/// A triangle of an edited scene that has no counterpart before the edit: the
/// `triangle_map` name of [`NO_INDEX`].
pub const UNMAPPED: u32 = NO_INDEX;

/// Corresponding triangles of a scene before and after an edit: `map[t_new]` is the old
/// index of new triangle `t_new`, or [`UNMAPPED`]. Instances correspond when
/// `instance_map[i_new] = Some(i_old)`; their triangles then correspond when both have the
/// same mesh triangle (`local_triangle`), e.g. the same mesh moved or re-coloured.
pub fn triangle_map(
    old: &TracedScene,
    new: &TracedScene,
    instance_map: &[Option<u32>],
) -> Vec<u32> {
    let mut map = vec![UNMAPPED; new.triangle_count()];
    for (i_new, range) in new.instance_triangles().iter().enumerate() {
        let Some(i_old) = instance_map.get(i_new).copied().flatten() else {
            continue;
        };
        let Some(old_range) = old.instance_triangles().get(i_old as usize) else {
            continue;
        };
        // Local triangle → old traced triangle (degenerate ones may be missing).
        let mut by_local = std::collections::HashMap::with_capacity(old_range.len());
        for t in old_range.clone() {
            by_local.insert(old.local_triangle()[t as usize], t);
        }
        for t in range.clone() {
            if let Some(&t_old) = by_local.get(&new.local_triangle()[t as usize]) {
                map[t as usize] = t_old;
            }
        }
    }
    map
}

/// What a cache knows about one surface point, for diagnostic pictures.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Diagnostic {
    /// Hemisphere samples of the nearest sample point.
    pub samples: u32,
    /// Irradiance maps: the order of the point's grid.
    pub order: Option<u32>,
}

/// Settings of the cache to bake, one variant per [`Method`]. Settings every cache has
/// (sides, density where there is one) have methods here; the rest belong to one method and
/// are reached through its own struct ([`Self::irradiance_map_mut`],
/// [`Self::lightmap_mut`], …), so setting one on a cache it does not fit cannot pass
/// silently.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "method", rename_all = "kebab-case")]
pub enum CacheSettings {
    Vertex(VertexLightingSettings),
    IrradianceMap(IrradianceMapSettings),
    Lightmap(LightmapSettings),
}

impl CacheSettings {
    /// The defaults of `method`.
    pub fn for_method(method: Method) -> Self {
        match method {
            Method::Vertex => Self::Vertex(Default::default()),
            Method::IrradianceMap => Self::IrradianceMap(Default::default()),
            Method::Lightmap => Self::Lightmap(Default::default()),
        }
    }

    pub fn method(&self) -> Method {
        match self {
            Self::Vertex(_) => Method::Vertex,
            Self::IrradianceMap(_) => Method::IrradianceMap,
            Self::Lightmap(_) => Method::Lightmap,
        }
    }

    /// Bake both sides of every surface, or the front (and double-sided back) only.
    pub fn set_both_sides(&mut self, both: bool) {
        match self {
            Self::Vertex(s) => s.both_sides = both,
            Self::IrradianceMap(s) => s.both_sides = both,
            Self::Lightmap(s) => s.both_sides = both,
        }
    }

    /// Whether both sides of every surface are baked.
    pub fn both_sides(&self) -> bool {
        match self {
            Self::Vertex(s) => s.both_sides,
            Self::IrradianceMap(s) => s.both_sides,
            Self::Lightmap(s) => s.both_sides,
        }
    }

    /// The spatial density (irradiance-map samples or lightmap texels per metre; `None`
    /// for vertex lighting).
    pub fn density(&self) -> Option<f32> {
        match self {
            Self::Vertex(_) => None,
            Self::IrradianceMap(s) => Some(s.density),
            Self::Lightmap(s) => Some(s.texels_per_metre),
        }
    }

    /// The spatial density to change in place (irradiance-map samples or lightmap texels
    /// per metre), or `None` for vertex lighting, which has none: whoever sets a density
    /// must say what happens when it does not apply.
    pub fn density_mut(&mut self) -> Option<&mut f32> {
        match self {
            Self::Vertex(_) => None,
            Self::IrradianceMap(s) => Some(&mut s.density),
            Self::Lightmap(s) => Some(&mut s.texels_per_metre),
        }
    }

    /// The cache the bounce passes before a final cache of these settings bake over
    /// `scene` ([`bake::BakeJob`]): at [`bake::BOUNCE_PASS_DENSITY`] of the final density
    /// and unguided (a bounce pass reaches the final cache only through gathers over whole
    /// hemispheres, which average its noise: guiding would cost more than it buys).
    ///
    /// A bounce pass is read only through gathers, so it may be any cache. Irradiance maps
    /// bounce through a lightmap where most triangles are no longer than one sample
    /// spacing of the bounce density ([`IrradianceMapSettings::order_one_share`] above
    /// [`bake::FINE_MESH_SHARE`]): their grids would sample the mesh, several points per
    /// texel a lightmap of that density holds (Sponza: 0.88 M first-round points against
    /// 0.20 M texels a side at 4 per metre; docs/results.md, "Irradiance maps on Sponza"),
    /// while a lightmap samples the light at the density asked for. On coarser meshes
    /// their own grids resolve what lies between texels (a tunnel narrower than a texel).
    /// Vertex lighting, which has no density, bounces through vertex lighting.
    pub fn bounce_pass(&self, scene: &TracedScene) -> CacheSettings {
        match self {
            CacheSettings::Vertex(_) => *self,
            CacheSettings::IrradianceMap(m) => {
                let maps = IrradianceMapSettings {
                    density: m.density * bake::BOUNCE_PASS_DENSITY,
                    guiding: false,
                    ..*m
                };
                if maps.order_one_share(scene) <= bake::FINE_MESH_SHARE {
                    return CacheSettings::IrradianceMap(maps);
                }
                CacheSettings::Lightmap(LightmapSettings {
                    texels_per_metre: maps.density,
                    both_sides: m.both_sides,
                    guiding: false,
                    ..Default::default()
                })
            }
            CacheSettings::Lightmap(l) => CacheSettings::Lightmap(LightmapSettings {
                texels_per_metre: l.texels_per_metre * bake::BOUNCE_PASS_DENSITY,
                guiding: false,
                ..*l
            }),
        }
    }

    /// The vertex-lighting settings, if this bakes vertex lighting.
    pub fn vertex(&self) -> Option<&VertexLightingSettings> {
        match self {
            Self::Vertex(s) => Some(s),
            _ => None,
        }
    }

    /// The vertex-lighting settings to change, if this bakes vertex lighting.
    pub fn vertex_mut(&mut self) -> Option<&mut VertexLightingSettings> {
        match self {
            Self::Vertex(s) => Some(s),
            _ => None,
        }
    }

    /// The irradiance-map settings, if this bakes irradiance maps.
    pub fn irradiance_map(&self) -> Option<&IrradianceMapSettings> {
        match self {
            Self::IrradianceMap(s) => Some(s),
            _ => None,
        }
    }

    /// The irradiance-map settings to change (shared corners, interpolation error, floor),
    /// if this bakes irradiance maps.
    pub fn irradiance_map_mut(&mut self) -> Option<&mut IrradianceMapSettings> {
        match self {
            Self::IrradianceMap(s) => Some(s),
            _ => None,
        }
    }

    /// The lightmap settings, if this bakes lightmaps.
    pub fn lightmap(&self) -> Option<&LightmapSettings> {
        match self {
            Self::Lightmap(s) => Some(s),
            _ => None,
        }
    }

    /// The lightmap settings to change (filter, guiding), if this bakes lightmaps.
    pub fn lightmap_mut(&mut self) -> Option<&mut LightmapSettings> {
        match self {
            Self::Lightmap(s) => Some(s),
            _ => None,
        }
    }
}

/// One of the three caches, chosen at run time; stored in bake archives.
// A cache is a few large arrays behind a small header and lives behind an `Arc`, so the
// header's size difference between variants costs nothing worth a box.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, Serialize, Deserialize)]
pub enum Cache {
    Vertex(VertexLighting),
    IrradianceMap(IrradianceMaps),
    Lightmap(Lightmaps),
}

impl Cache {
    /// An empty cache of the kind `settings` names, laid out over `scene`'s triangles.
    pub fn new(scene: &TracedScene, settings: &CacheSettings) -> Self {
        match *settings {
            CacheSettings::Vertex(s) => Self::Vertex(VertexLighting::new(scene, s)),
            CacheSettings::IrradianceMap(s) => Self::IrradianceMap(IrradianceMaps::new(scene, s)),
            CacheSettings::Lightmap(s) => Self::Lightmap(Lightmaps::new(scene, s)),
        }
    }

    /// Takes what `other`, a finished pass over the same layout and scene, found once
    /// for every pass (a lightmap's crossing probes), instead of finding it again.
    pub fn adopt_probes(&mut self, other: &Cache) {
        if let (Self::Lightmap(a), Self::Lightmap(b)) = (self, other) {
            a.adopt_probes(b);
        }
    }

    fn inner(&self) -> &dyn SurfaceCache {
        match self {
            Self::Vertex(c) => c,
            Self::IrradianceMap(c) => c,
            Self::Lightmap(c) => c,
        }
    }

    fn inner_mut(&mut self) -> &mut dyn SurfaceCache {
        match self {
            Self::Vertex(c) => c,
            Self::IrradianceMap(c) => c,
            Self::Lightmap(c) => c,
        }
    }
}

impl SurfaceCache for Cache {
    fn method(&self) -> Method {
        self.inner().method()
    }

    fn plan_sampling(&mut self, estimator: &EstimatorSettings) {
        self.inner_mut().plan_sampling(estimator)
    }

    fn next_round(&mut self, scene: &TracedScene, points: &mut Vec<SamplePoint>) {
        self.inner_mut().next_round(scene, points)
    }

    fn later_samples(&self, samples_per_point: f64) -> Option<u64> {
        self.inner().later_samples(samples_per_point)
    }

    fn guidance(&self, i: usize) -> Guidance<'_> {
        self.inner().guidance(i)
    }

    fn borrows_guides(&self) -> bool {
        self.inner().borrows_guides()
    }

    fn buried_share(&self, i: usize) -> Option<f32> {
        self.inner().buried_share(i)
    }

    fn finish_round(
        &mut self,
        scene: &TracedScene,
        points: &[SamplePoint],
        estimates: &[Estimate],
    ) {
        self.inner_mut().finish_round(scene, points, estimates)
    }

    fn lookup(&self, triangle: u32, uv: Vec2, front: bool) -> Vec3 {
        self.inner().lookup(triangle, uv, front)
    }

    fn holds(&self, triangle: u32, front: bool) -> bool {
        self.inner().holds(triangle, front)
    }

    fn stats(&self) -> CacheStats {
        self.inner().stats()
    }

    fn publish(&self, scene: &TracedScene) -> Vec<IrradianceTexture> {
        self.inner().publish(scene)
    }

    fn diagnostic(&self, triangle: u32, uv: Vec2, front: bool) -> Diagnostic {
        self.inner().diagnostic(triangle, uv, front)
    }

    fn remap(&self, old: &TracedScene, new: &TracedScene, triangle_map: &[u32]) -> Self {
        match self {
            Self::Vertex(c) => Self::Vertex(c.remap(old, new, triangle_map)),
            Self::IrradianceMap(c) => Self::IrradianceMap(c.remap(old, new, triangle_map)),
            Self::Lightmap(c) => Self::Lightmap(c.remap(old, new, triangle_map)),
        }
    }
}

impl IrradianceLookup for Cache {
    fn irradiance(&self, triangle: u32, uv: Vec2, front: bool) -> Option<Vec3> {
        self.holds(triangle, front)
            .then(|| self.lookup(triangle, uv, front))
    }

    /// Half the sample spacing at the cache's density; 0 for vertex lighting, whose
    /// spacing is the mesh's.
    fn albedo_footprint(&self) -> f32 {
        match self {
            Self::Vertex(_) => 0.0,
            Self::IrradianceMap(c) => 0.5 / c.settings().density,
            Self::Lightmap(c) => 0.5 / c.settings().texels_per_metre,
        }
    }

    /// A lightmap's guide of the texel block around the point; the other caches keep
    /// none once baked.
    fn guide(&self, triangle: u32, uv: Vec2, front: bool) -> Option<DirectionGuide> {
        match self {
            Self::Lightmap(c) => c.guide_at(triangle, uv, front),
            _ => None,
        }
    }
}
