//! Texel lightmaps on TEXCOORD_1 or a generated chart atlas (docs/design.md, Caches): irradiance
//! per texel of one texture per instance, looked up exactly as an engine samples it.
//!
//! - **Layout.** An instance whose mesh has a usable TEXCOORD_1 keeps it; its square
//!   texture has the side √(world area / UV1 area) × density. Otherwise
//!   [`charts::generate_atlas`] makes one (charts grown over smooth edges, flattened and
//!   packed by footprint).
//! - **Rasterisation.** Every triangle covers every texel its UV1 footprint overlaps
//!   (conservative rasterisation, [`conservative_texels`]). A texel belongs to one
//!   triangle: the one containing its centre, else the nearest; it is estimated at the
//!   centre, or at the closest point of its triangle, nudged inside.
//! - **Rounds.** Every owned texel is one [`SampleSite::Surface`] on the front side, and
//!   on the back side in a second layer when [`LightmapSettings::both_sides`]; texels are
//!   adaptive through rounds of doubling samples where their filtered error is still above
//!   the bound, not through refinement. Rounds after the first draw their directions
//!   through the guide their block of texels learnt ([`guides`]; docs/design.md, Guiding).
//! - **Buried texels** (estimates whose first rays mostly hit back faces: the texel lies
//!   inside other geometry) are refilled from valid neighbours, and texels owned by no
//!   triangle are **dilated** from their neighbours `gutter` times, so that bilinear
//!   filtering at chart borders never pulls in black.
//! - **Storage.** Three half floats a texel ([`crate::stored_rgb`]) with one power-of-two
//!   [`StoreScale`].
//! - **Crossings.** A texel whose footprint another surface crosses keeps that crossing
//!   as a line in UV1 space, with one more estimate at its foot ([`crate::crossings`]);
//!   lookups leave out texels that their crossing separates from the point looked up.
//!
//! The parts: [`layout`] (instance textures and texel owners) over [`conservative`]
//! rasterisation; [`rounds`] (sample points of each round and the plan of the next) and
//! [`estimates`] (per-texel estimates merged, filtered and finished into stored texels)
//! with [`fill`] (buried texels and gutters) and [`guides`]; [`lookup`] (bilinear lookups
//! that respect crossings); [`publish`] and [`remap`] (incremental re-bakes).

mod conservative;
mod estimates;
mod fill;
mod guides;
mod layout;
mod lookup;
mod publish;
mod remap;
mod rounds;

pub use conservative::conservative_texels;
pub(crate) use conservative::texels_overlapped_by;
pub use rounds::{LATER_ROUNDS_GUESS, SamplingPlan};

use crate::burial::Burial;
use crate::{
    CacheStats, Diagnostic, IrradianceTexture, Method, Prior, SamplePoint, SurfaceCache, crossings,
    filter::FilterSettings,
    stored_rgb::{StoreScale, StoredRgb},
};
use estimates::TexelEstimate;
use glam::{Vec2, Vec3};
use guides::TexelGuides;
use layout::{BuiltInstance, build_instance};
use lookup::bilinear_packed;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use surfcache_core::{geometry::interpolate, index::NO_INDEX};
use surfcache_trace::{
    Estimate, EstimatorSettings, Guidance, TracedScene, guiding::DirectionGuide,
};

/// How lightmaps are laid out and which texels are trusted.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LightmapSettings {
    /// Texels per metre along a surface (density² texels per m²). Default 64: texels of
    /// about 1.6 cm, 35 across a Cornell-box wall (error against time per density:
    /// docs/results.md). Large scenes lower it to the bake's density budget.
    pub texels_per_metre: f32,
    /// Largest texture side in texels; generated atlases lower their density to fit,
    /// TEXCOORD_1 textures are clamped. Default 2048.
    pub max_size: u32,
    /// Free texels around every generated chart, filled by dilation (`gutter` passes).
    /// Default 1: bilinear filtering at a point of a triangle reads the texel holding it
    /// and its 8 neighbours at most, so one ring of the chart's own keeps every read in
    /// the chart (points near a slanted chart edge read unowned texels of that ring).
    /// The textures are sampled without mipmaps; a second ring would keep mipmap level
    /// 1 clean. TEXCOORD_1 layouts bring their own gutters.
    pub gutter: u32,
    /// Also bake the back side of every surface (a second layer; published for
    /// double-sided materials). Default true.
    pub both_sides: bool,
    /// A texel whose estimate has a back-face share ([`Estimate::back_face_share`]) above
    /// this is buried in geometry and refilled from its neighbours. Default 0.5; above 1
    /// turns detection off.
    pub buried_threshold: f32,
    /// How far texels share their samples with their neighbours ([`crate::filter`]) when
    /// the bake plans rounds ([`SurfaceCache::plan_sampling`]).
    #[serde(default)]
    pub filter: FilterSettings,
    /// Texels that need more than the first round draw their directions through a guide
    /// learnt from the first round of their block ([`guides`]; docs/design.md, Guiding).
    /// Default true.
    #[serde(default = "guiding_default")]
    pub guiding: bool,
}

fn guiding_default() -> bool {
    true
}

impl Default for LightmapSettings {
    fn default() -> Self {
        Self {
            texels_per_metre: 64.0,
            max_size: 2048,
            gutter: 1,
            both_sides: true,
            buried_threshold: 0.5,
            filter: FilterSettings::default(),
            guiding: true,
        }
    }
}

/// The results of probing every slot for crossings ([`Lightmaps::probe_crossings`]),
/// per slot of the layout: where it is estimated, its exit, its crossing line (index into
/// the lines and their feet). A probe sees the surfaces within [`crossings::LINE_REACH`]
/// texels only, so a re-bake carries the probes of slots far from every changed surface
/// and probes again only the `stale` ones (all, where `stale` is empty, are carried).
#[derive(Clone, Debug, Default)]
struct Probed {
    site_uv: Vec<Vec2>,
    exits: Vec<Option<Vec2>>,
    crossing_slot: Vec<u32>,
    crossing_lines: Vec<crossings::SampleCrossing>,
    foot_sites: Vec<Option<Vec2>>,
    stale: Vec<bool>,
}

/// One instance's texture within the flat texel arrays of a layer.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
struct InstanceMap {
    width: u32,
    height: u32,
    /// First texel of the instance in a layer.
    offset: usize,
    uses_mesh_uv1: bool,
    texels_per_metre: f32,
}

impl InstanceMap {
    fn texels(&self) -> usize {
        (self.width * self.height) as usize
    }
}

/// Per-texel irradiance of every instance in its own texture (module docs).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Lightmaps {
    settings: LightmapSettings,
    maps: Vec<InstanceMap>,
    /// Instance of each traced triangle.
    triangle_instance: Vec<u32>,
    /// UV1 per traced triangle, in the traced scene's corner order, UV units.
    uv1: Vec<[Vec2; 3]>,
    /// Chart (coplanar group, numbered over the whole scene) of each triangle.
    chart: Vec<u32>,
    /// Texels in one layer (all instances), and the number of layers (1 or 2).
    layer_texels: usize,
    layers: usize,
    /// Owning triangle and sample barycentrics per texel of a layer (kept in memory for
    /// incremental re-bakes, not stored in archives).
    #[serde(skip)]
    owner: Vec<u32>,
    #[serde(skip)]
    sample_uv: Vec<Vec2>,
    /// Values before an edit per texel slot, for an incremental re-bake.
    #[serde(skip)]
    priors: Vec<Option<Prior>>,
    /// Before an edit, per texel slot of a kept layout: its crossing and the value at
    /// the crossing's foot (NaN: buried), the foot's prior where the crossing is the same
    /// after it.
    #[serde(skip)]
    prior_feet: std::collections::HashMap<u32, (crossings::SampleCrossing, Vec3)>,
    /// Texel slots whose estimate was buried (their stored value was filled from
    /// neighbours, so it is no prior for a change estimate).
    #[serde(skip)]
    buried_slots: Vec<bool>,
    /// Texel slot (layer · layer_texels + texel) of each point of the round.
    slots: Vec<u32>,
    /// How rounds of samples are planned ([`SurfaceCache::plan_sampling`]).
    #[serde(skip)]
    plan: Option<SamplingPlan>,
    /// Rounds asked for so far, and the slots and sample budgets of the next one.
    #[serde(skip)]
    rounds: u32,
    #[serde(skip)]
    pending: Vec<(u32, u32)>,
    /// Samples the rounds after the next are expected to take
    /// ([`SurfaceCache::later_samples`]); before the first round's estimates arrive,
    /// [`LATER_ROUNDS_GUESS`] times the first round.
    #[serde(skip)]
    later_samples: u64,
    /// Every round's estimates merged per slot while baking.
    #[serde(skip)]
    merged: Vec<TexelEstimate>,
    #[serde(skip)]
    state: Vec<Burial>,
    /// Sample point and shading normal of every owned slot (the filter's guides).
    #[serde(skip)]
    guide: Vec<(Vec3, Vec3)>,
    /// Where each slot is estimated (barycentrics on its owner; a buried texel moves to
    /// the visible part of its footprint, [`crossings`]: the exit its probe found).
    #[serde(skip)]
    site_uv: Vec<Vec2>,
    /// Per slot: index into `crossing_lines` of the crossing that cuts its footprint, or
    /// [`NO_INDEX`]; lookups leave out texels whose crossing separates them from the point
    /// looked up (module docs, Crossings).
    #[serde(default)]
    crossing_slot: Vec<u32>,
    /// Crossing lines in UV1 space (`a·u + b·v + c ≥ 0` on the texel's own side) with the
    /// distances of the texel's site and of its foot.
    #[serde(default)]
    crossing_lines: Vec<crossings::SampleCrossing>,
    /// E at each crossing line's foot (zero where it has none).
    #[serde(default)]
    crossing_feet: Vec<StoredRgb>,
    /// While baking: each line's foot estimate (NaN: none yet, or buried); where the
    /// feet lie is in [`Probed::foot_sites`].
    #[serde(skip)]
    feet: Vec<Vec3>,
    /// The line of each foot point of the current round (after its texel points), and
    /// whether the foot was buried before an edit (it stays buried unless estimated).
    #[serde(skip)]
    foot_lines: Vec<(u32, bool)>,
    /// Hemisphere samples the feet took (counted in the statistics).
    #[serde(skip)]
    foot_samples: u64,
    /// While baking: every round's records and the guides of the next round.
    #[serde(skip)]
    guides: TexelGuides,
    /// What [`Self::probe_crossings`] found over the scene this cache was laid out over
    /// (exits and feet are read from it while baking), kept for re-bakes ([`Probed`]).
    #[serde(skip)]
    probed: Option<std::sync::Arc<Probed>>,
    emitted: bool,
    /// Stored texels of all layers.
    packed: Vec<StoredRgb>,
    /// Hemisphere samples per texel of all layers (diagnostics only, not in
    /// `cache_bytes`; 0 for texels filled from neighbours).
    #[serde(default)]
    sample_counts: Vec<u32>,
    scale: StoreScale,
    stats: CacheStats,
}

impl Lightmaps {
    /// Lays out and rasterises every instance of `scene` (in parallel over instances).
    pub fn new(scene: &TracedScene, settings: LightmapSettings) -> Self {
        let built: Vec<BuiltInstance> = (0..scene.instance_triangles().len())
            .into_par_iter()
            .map(|i| build_instance(scene, i, &settings))
            .collect();
        Self::from_instances(scene, settings, built)
    }

    /// The plan that filters each round's estimates and refines where they are above
    /// the bound: none in an incremental re-bake (priors), whose estimates update
    /// filtered values and are stopped by the estimator itself.
    fn refining_plan(&self) -> Option<SamplingPlan> {
        self.plan.filter(|_| self.priors.is_empty())
    }

    /// The settings the maps were laid out with.
    pub fn settings(&self) -> &LightmapSettings {
        &self.settings
    }

    /// Texture width and height of `instance`.
    pub fn texture_size(&self, instance: u32) -> [u32; 2] {
        let m = &self.maps[instance as usize];
        [m.width, m.height]
    }

    /// The texel density `instance` got (texels per metre): lower than asked when its
    /// atlas had to shrink to [`LightmapSettings::max_size`]; for TEXCOORD_1 layouts the
    /// mean over the mesh.
    pub fn texels_per_metre(&self, instance: u32) -> f32 {
        self.maps[instance as usize].texels_per_metre
    }

    /// Texels of one layer that a triangle owns (the estimated ones; the rest are gutter).
    pub fn owned_texels(&self) -> usize {
        self.owner.iter().filter(|&&t| t != NO_INDEX).count()
    }

    /// Number of charts over all instances.
    pub fn chart_count(&self) -> usize {
        self.chart
            .iter()
            .map(|&c| c as usize + 1)
            .max()
            .unwrap_or(0)
    }

    /// UV1 of the corners of traced triangle `t`, in the traced scene's corner order.
    pub fn triangle_uv1(&self, t: u32) -> [Vec2; 3] {
        self.uv1[t as usize]
    }

    /// The guide of the texel block that holds the texel under barycentrics `uv` of
    /// `triangle` on the given side, from everything the bake recorded there
    /// ([`guides`]); `None` where it recorded nothing, or light spread over the whole
    /// hemisphere.
    pub fn guide_at(&self, triangle: u32, uv: Vec2, front: bool) -> Option<DirectionGuide> {
        DirectionGuide::from_record(self.guides.record(self.slot_at(triangle, uv, front)?)?)
    }

    /// The layer (side), instance and texture coordinates (UV1, in [0, 1]²) of
    /// barycentrics `uv` of `triangle`; `None` for a back side that was not baked.
    fn locate(&self, triangle: u32, uv: Vec2, front: bool) -> Option<(usize, usize, Vec2)> {
        let layer = match (front, self.layers) {
            (true, _) => 0,
            (false, 2) => 1,
            _ => return None,
        };
        let t = triangle as usize;
        let [a, b, c] = self.uv1[t];
        Some((
            layer,
            self.triangle_instance[t] as usize,
            interpolate(a, b, c, uv),
        ))
    }

    /// The texel slot (layer · layer_texels + texel) that holds barycentrics `uv` of
    /// `triangle` on the given side.
    fn slot_at(&self, triangle: u32, uv: Vec2, front: bool) -> Option<usize> {
        let (layer, instance, at) = self.locate(triangle, uv, front)?;
        let m = &self.maps[instance];
        let p = at * Vec2::new(m.width as f32, m.height as f32);
        let x = (p.x.max(0.0) as usize).min(m.width as usize - 1);
        let y = (p.y.max(0.0) as usize).min(m.height as usize - 1);
        Some(layer * self.layer_texels + m.offset + y * m.width as usize + x)
    }

    /// The texels of one layer of one instance.
    fn texture_slice(&self, layer: usize, instance: usize) -> &[StoredRgb] {
        let m = &self.maps[instance];
        let start = layer * self.layer_texels + m.offset;
        &self.packed[start..start + m.texels()]
    }
}

impl SurfaceCache for Lightmaps {
    fn method(&self) -> Method {
        Method::Lightmap
    }

    /// Takes the bake's error bound, sample limits and floor: rounds are then planned
    /// by the cache (module docs, Rounds).
    fn plan_sampling(&mut self, estimator: &EstimatorSettings) {
        self.plan = Some(SamplingPlan::new(estimator, &self.settings));
    }

    /// Round 0: every owned texel of every layer, instance by instance, row-major; later
    /// rounds: the texels whose filtered estimate is still above the bound.
    fn next_round(&mut self, scene: &TracedScene, points: &mut Vec<SamplePoint>) {
        if self.emitted {
            return;
        }
        self.slots.clear();
        let round = self.rounds;
        self.rounds += 1;
        if round == 0 {
            self.first_round(scene, points);
        } else {
            self.later_round(scene, round, points);
        }
    }

    /// A texel's later rounds have budgets of their own: the mean so far is not needed.
    fn later_samples(&self, _samples_per_point: f64) -> Option<u64> {
        Some(self.later_samples)
    }

    /// Every round records into its texels' blocks; rounds after the first draw through
    /// their blocks' guides ([`guides`]). Feet do neither.
    fn guidance(&self, i: usize) -> Guidance<'_> {
        match self.slots.get(i) {
            Some(&slot) => Guidance {
                record: self.guides.record(slot as usize),
                guide: self.guides.guide(slot as usize),
            },
            None => Guidance::default(),
        }
    }

    fn borrows_guides(&self) -> bool {
        self.settings.guiding
    }

    /// Merges the round's estimates into their texels, marks buried ones (first round),
    /// filters, and asks for another round where the filtered error is above the bound;
    /// after the last round refills buried texels, dilates into the gutters and packs.
    fn finish_round(
        &mut self,
        scene: &TracedScene,
        points: &[SamplePoint],
        estimates: &[Estimate],
    ) {
        debug_assert_eq!(points.len(), self.slots.len() + self.foot_lines.len());
        self.record_feet(estimates);
        let moved = self.merge_round(scene, estimates);
        let plan = self.refining_plan();
        let filtered = self.filtered(plan.as_ref());
        self.plan_next_round(plan, &moved, &filtered);
        if self.settings.guiding {
            self.guides
                .learn(self.pending.iter().map(|&(slot, _)| slot as usize));
        }
        if self.pending.is_empty() {
            self.emitted = true;
            self.finish(
                filtered.into_iter().map(|(v, _)| v).collect(),
                plan.as_ref(),
            );
        }
        self.slots.clear();
    }

    /// A front-only bake ([`LightmapSettings::both_sides`] off) has no back layer.
    fn holds(&self, _triangle: u32, front: bool) -> bool {
        front || self.layers == 2
    }

    /// Bilinear sample of the side's texture at the triangle's interpolated UV1. A back
    /// side that was not baked (`both_sides` off) is NaN.
    fn lookup(&self, triangle: u32, uv: Vec2, front: bool) -> Vec3 {
        let Some((layer, instance, at)) = self.locate(triangle, uv, front) else {
            return Vec3::NAN;
        };
        let m = &self.maps[instance];
        let base = layer * self.layer_texels + m.offset;
        bilinear_packed(
            self.texture_slice(layer, instance),
            m.width,
            m.height,
            at,
            self.scale,
            |k| {
                self.crossing_slot
                    .get(base + k)
                    .copied()
                    .unwrap_or(NO_INDEX)
            },
            |c| {
                (
                    self.crossing_lines[c as usize],
                    self.crossing_feet
                        .get(c as usize)
                        .map_or(Vec3::ZERO, |&f| self.scale.unpack(f)),
                )
            },
        )
    }

    fn stats(&self) -> CacheStats {
        self.stats.clone()
    }

    /// Instances whose triangles all correspond one to one (same mesh, same mirroring)
    /// keep their layout, and their texels' values become priors; the others are laid out
    /// afresh.
    fn remap(&self, old: &TracedScene, new: &TracedScene, triangle_map: &[u32]) -> Self {
        self.remapped(old, new, triangle_map)
    }

    fn diagnostic(&self, triangle: u32, uv: Vec2, front: bool) -> Diagnostic {
        let Some(slot) = self.slot_at(triangle, uv, front) else {
            return Diagnostic::default();
        };
        Diagnostic {
            samples: self.sample_counts.get(slot).copied().unwrap_or(0),
            order: None,
        }
    }

    /// One texture per instance for the front side, and one for the back side of
    /// instances with a double-sided material (when baked); UV1 in mesh order.
    fn publish(&self, scene: &TracedScene) -> Vec<IrradianceTexture> {
        self.textures(scene)
    }
}
