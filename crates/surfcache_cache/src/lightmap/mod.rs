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

mod guides;

use crate::burial::Burial;
use crate::{
    CacheStats, Diagnostic, IrradianceTexture, Method, SamplePoint, SampleSite, SurfaceCache,
    UNMAPPED,
    charts::{self, TEXEL_EPSILON},
    crossings::{self, Probe},
    filter::{self, FilterInput, FilterSettings},
    stored_rgb::{STORED_RGB_BYTES, StoreScale, StoredRgb},
};
use glam::{Vec2, Vec3};
use guides::TexelGuides;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use surfcache_core::{
    geometry::{closest_point_barycentric, interpolate, triangle_area},
    sampling::splitmix64,
};
use surfcache_trace::{Estimate, EstimatorSettings, Guidance, TracedScene};

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

/// No triangle owns the texel.
const NONE: u32 = u32::MAX;

/// Barycentric margin of sample positions: every barycentric coordinate is at least this.
const INSIDE_MARGIN: f32 = 1e-4;

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
    priors: Vec<Option<Vec3>>,
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
    /// the visible part of its footprint, [`crossings`]), and the exit its probe found.
    #[serde(skip)]
    site_uv: Vec<Vec2>,
    #[serde(skip)]
    exits: Vec<Option<Vec2>>,
    /// Per slot: index into `crossing_lines` of the crossing that cuts its footprint, or
    /// [`NONE`]; lookups leave out texels whose crossing separates them from the point
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
    /// While baking: each line's foot (barycentrics on the texel's owner), if it has one,
    /// and its estimate (NaN: none yet, or buried).
    #[serde(skip)]
    foot_sites: Vec<Option<Vec2>>,
    #[serde(skip)]
    feet: Vec<Vec3>,
    /// The line of each foot point of the current round (after its texel points).
    #[serde(skip)]
    foot_lines: Vec<u32>,
    /// Hemisphere samples the feet took (counted in the statistics).
    #[serde(skip)]
    foot_samples: u64,
    /// While baking: every round's records and the guides of the next round.
    #[serde(skip)]
    guides: TexelGuides,
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

/// What one instance's layout contributes before the instances are concatenated.
struct BuiltInstance {
    map: InstanceMap,
    uv1: Vec<[Vec2; 3]>,
    chart: Vec<u32>,
    chart_count: u32,
    owner: Vec<u32>,
    sample_uv: Vec<Vec2>,
}

impl Lightmaps {
    /// Lays out and rasterises every instance of `scene` (in parallel over instances).
    pub fn new(scene: &TracedScene, settings: LightmapSettings) -> Self {
        let built: Vec<BuiltInstance> = (0..scene.instance_triangles.len())
            .into_par_iter()
            .map(|i| build_instance(scene, i, &settings))
            .collect();
        Self::from_instances(scene, settings, built)
    }

    /// Concatenates the instances' layouts into the flat arrays of a layer.
    fn from_instances(
        scene: &TracedScene,
        settings: LightmapSettings,
        built: Vec<BuiltInstance>,
    ) -> Self {
        let n = scene.triangle_count();
        let mut maps = Vec::with_capacity(built.len());
        let mut uv1 = Vec::with_capacity(n);
        let mut chart = Vec::with_capacity(n);
        let mut triangle_instance = Vec::with_capacity(n);
        let mut owner = Vec::new();
        let mut sample_uv = Vec::new();
        let mut chart_base = 0u32;
        for (i, b) in built.into_iter().enumerate() {
            let mut map = b.map;
            map.offset = owner.len();
            maps.push(map);
            uv1.extend_from_slice(&b.uv1);
            chart.extend(b.chart.iter().map(|c| c + chart_base));
            chart_base += b.chart_count;
            triangle_instance.extend(std::iter::repeat_n(i as u32, b.uv1.len()));
            owner.extend_from_slice(&b.owner);
            sample_uv.extend_from_slice(&b.sample_uv);
        }
        let layer_texels = owner.len();
        let layers = if settings.both_sides { 2 } else { 1 };
        Self {
            settings,
            maps,
            triangle_instance,
            uv1,
            chart,
            layer_texels,
            layers,
            owner,
            sample_uv,
            priors: Vec::new(),
            buried_slots: Vec::new(),
            slots: Vec::new(),
            plan: None,
            rounds: 0,
            pending: Vec::new(),
            later_samples: 0,
            merged: Vec::new(),
            state: Vec::new(),
            guide: Vec::new(),
            site_uv: Vec::new(),
            exits: Vec::new(),
            crossing_slot: Vec::new(),
            crossing_lines: Vec::new(),
            crossing_feet: Vec::new(),
            foot_sites: Vec::new(),
            feet: Vec::new(),
            foot_lines: Vec::new(),
            foot_samples: 0,
            guides: TexelGuides::default(),
            emitted: false,
            packed: vec![[0; 3]; layers * layer_texels],
            sample_counts: Vec::new(),
            scale: StoreScale::default(),
            stats: CacheStats::default(),
        }
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
        self.owner.iter().filter(|&&t| t != NONE).count()
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

    /// Instance `io`'s finished layout, for the same mesh placed again with its triangles
    /// starting at traced index `first_triangle`.
    fn instance_layout(
        &self,
        scene: &TracedScene,
        io: usize,
        first_triangle: u32,
    ) -> BuiltInstance {
        let m = self.maps[io];
        let range = scene.instance_triangles[io].clone();
        let (start, end) = (range.start as usize, range.end as usize);
        let charts = &self.chart[start..end];
        let base = charts.iter().copied().min().unwrap_or(0);
        let owner = self.owner[m.offset..m.offset + m.texels()]
            .iter()
            .map(|&t| {
                if t == NONE {
                    NONE
                } else {
                    t - range.start + first_triangle
                }
            })
            .collect();
        BuiltInstance {
            map: m,
            uv1: self.uv1[start..end].to_vec(),
            chart: charts.iter().map(|c| c - base).collect(),
            chart_count: charts.iter().map(|c| c - base + 1).max().unwrap_or(0),
            owner,
            sample_uv: self.sample_uv[m.offset..m.offset + m.texels()].to_vec(),
        }
    }

    /// The texels of one layer of one instance.
    fn texture_slice(&self, layer: usize, instance: usize) -> &[StoredRgb] {
        let m = &self.maps[instance];
        let start = layer * self.layer_texels + m.offset;
        &self.packed[start..start + m.texels()]
    }
}

/// Before any estimate is in, a lightmap's progress report expects its later rounds to
/// take this many times the samples of the first; the guess is replaced by a prediction
/// once the first round is in.
pub const LATER_ROUNDS_GUESS: f32 = 2.0;

/// How a lightmap plans its rounds of samples (module docs, Rounds), from the bake's
/// estimator settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SamplingPlan {
    /// Samples of every texel in the first round (the estimator's `min_samples`).
    pub first: u32,
    /// Most samples of one texel over all rounds.
    pub max: u32,
    /// Bound on the filtered estimate's relative error, per channel (0: one round).
    pub bound: f32,
    /// The absolute floor ε of relative errors (W/m²).
    pub floor: f32,
    pub filter: FilterSettings,
}

impl SamplingPlan {
    fn new(estimator: &EstimatorSettings, settings: &LightmapSettings) -> Self {
        let max = estimator.max_samples.max(1);
        Self {
            first: if estimator.max_rel_error > 0.0 {
                estimator.min_samples.clamp(1, max)
            } else {
                max
            },
            max,
            bound: estimator.max_rel_error,
            floor: estimator.floor,
            filter: settings.filter,
        }
    }

    /// C = σ / (E + ε), the largest over the channels, of a (filtered) estimate with
    /// value `v` and variance `s`.
    fn relative_error(&self, v: Vec3, s: Vec3) -> f32 {
        let c = s.max(Vec3::ZERO).map(f32::sqrt) / (v.max(Vec3::ZERO) + Vec3::splat(self.floor));
        c.max_element()
    }
}

/// The estimates of one texel over all rounds, merged.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct TexelEstimate {
    samples: u32,
    mean: Vec3,
    /// Variance of the mean, per channel.
    variance: Vec3,
}

impl TexelEstimate {
    /// Merges an independent estimate of the same texel: means weighted by sample
    /// counts, `σ² = (n_a² σ_a² + n_b² σ_b²) / (n_a + n_b)²`. An estimate that is exactly
    /// zero (every sample was zero: in a gathering pass every ray met unlit surfaces)
    /// counts as exact. An estimate without samples (a re-bake's prior kept as it is,
    /// [`surfcache_trace::irradiance::unchanged`]) is taken as it is until samples
    /// arrive.
    fn merge(&mut self, e: &Estimate) {
        let variance = if e.value == Vec3::ZERO {
            Vec3::ZERO
        } else {
            e.std_error * e.std_error
        };
        let (na, nb) = (self.samples as f32, e.samples as f32);
        let n = na + nb;
        if n == 0.0 {
            self.mean = e.value;
            self.variance = variance;
            return;
        }
        self.mean = (self.mean * na + e.value * nb) / n;
        self.variance = (self.variance * na * na + variance * nb * nb) / (n * n);
        self.samples += e.samples;
    }
}

impl Lightmaps {
    /// The sample point of texel `i` of `layer` in `round` (its key differs per round, so
    /// rounds are independent estimates), with `budget` samples.
    fn texel_point(
        &self,
        scene: &TracedScene,
        layer: usize,
        i: usize,
        round: u32,
        budget: Option<u32>,
    ) -> SamplePoint {
        let triangle = self.owner[i];
        let m = self.maps[self.triangle_instance[triangle as usize] as usize];
        let k = (i - m.offset) as u32;
        let (x, y) = (k % m.width, k / m.width);
        let key = texel_key(scene.triangle_key(triangle), layer, x, y);
        let uv = self
            .site_uv
            .get(layer * self.layer_texels + i)
            .copied()
            .unwrap_or(self.sample_uv[i]);
        SamplePoint {
            site: SampleSite::Surface {
                triangle,
                uv,
                front: layer == 0,
            },
            key: if round == 0 {
                key
            } else {
                splitmix64(key ^ round as u64)
            },
            prior: self
                .priors
                .get(layer * self.layer_texels + i)
                .copied()
                .flatten(),
            budget,
        }
    }

    /// Sample point and shading normal of every owned slot (zero elsewhere).
    fn texel_guides(&self, scene: &TracedScene) -> Vec<(Vec3, Vec3)> {
        (0..self.layers * self.layer_texels)
            .into_par_iter()
            .map(|slot| {
                let (layer, i) = (slot / self.layer_texels, slot % self.layer_texels);
                match self.owner[i] {
                    NONE => (Vec3::ZERO, Vec3::ZERO),
                    t => {
                        let p = scene.surface_point(t, self.site_uv[slot], layer == 0);
                        (p.position, p.shading_normal)
                    }
                }
            })
            .collect()
    }

    /// The merged estimates, filtered texture by texture when `plan` filters (else as
    /// they are): value and variance per slot.
    fn filtered(&self, plan: Option<&SamplingPlan>) -> Vec<(Vec3, Vec3)> {
        let mut out: Vec<(Vec3, Vec3)> = self.merged.iter().map(|e| (e.mean, e.variance)).collect();
        let Some(plan) = plan.filter(|p| p.filter.iterations > 0) else {
            return out;
        };
        for layer in 0..self.layers {
            for m in &self.maps {
                let range = layer * self.layer_texels + m.offset
                    ..layer * self.layer_texels + m.offset + m.texels();
                let value: Vec<Vec3> = out[range.clone()].iter().map(|v| v.0).collect();
                let variance: Vec<Vec3> = out[range.clone()].iter().map(|v| v.1).collect();
                let position: Vec<Vec3> = self.guide[range.clone()].iter().map(|g| g.0).collect();
                let normal: Vec<Vec3> = self.guide[range.clone()].iter().map(|g| g.1).collect();
                // Crossed texels keep their own estimates: their neighbours may lie beyond
                // the crossing.
                let valid: Vec<bool> = range
                    .clone()
                    .map(|k| {
                        self.state[k] == Burial::Valid
                            && self.crossing_slot.get(k).is_none_or(|&c| c == NONE)
                    })
                    .collect();
                let (v, s) = filter::filter(
                    &FilterInput {
                        width: m.width as usize,
                        height: m.height as usize,
                        value: &value,
                        variance: &variance,
                        position: &position,
                        normal: &normal,
                        valid: &valid,
                        texel: 1.0 / m.texels_per_metre.max(f32::MIN_POSITIVE),
                        floor: plan.floor,
                    },
                    &plan.filter,
                );
                for (o, vs) in out[range].iter_mut().zip(v.into_iter().zip(s)) {
                    *o = vs;
                }
            }
        }
        out
    }

    /// After the last round: statistics, buried texels refilled from valid neighbours,
    /// dilation into the gutters, packing ([`crate::stored_rgb`]); the working state is dropped.
    fn finish(&mut self, mut values: Vec<Vec3>, plan: Option<&SamplingPlan>) {
        let total = self.layers * self.layer_texels;
        let mut state = std::mem::take(&mut self.state);
        let merged = std::mem::take(&mut self.merged);
        let mut stats = CacheStats::default();
        let mut rel_error = 0.0f64;
        self.sample_counts = merged.iter().map(|e| e.samples).collect();
        for (slot, e) in merged.iter().enumerate() {
            if e.samples == 0 {
                continue;
            }
            stats.sample_points += 1;
            stats.samples += e.samples as u64;
            stats.max_samples_per_point = stats.max_samples_per_point.max(e.samples);
            match state[slot] {
                Burial::Buried => stats.buried += 1,
                _ => {
                    let floor = plan.map_or(0.0, |p| p.floor).max(f32::MIN_POSITIVE);
                    let c =
                        e.variance.map(f32::sqrt) / (e.mean.max(Vec3::ZERO) + Vec3::splat(floor));
                    rel_error += c.max_element() as f64;
                }
            }
        }
        stats.mean_rel_error = rel_error / (stats.sample_points - stats.buried).max(1) as f64;
        self.buried_slots = state.iter().map(|&st| st == Burial::Buried).collect();
        // Chart of each texel of a layer (for the same-chart preference of the fill).
        let texel_chart: Vec<u32> = self
            .owner
            .iter()
            .map(|&t| {
                if t == NONE {
                    NONE
                } else {
                    self.chart[t as usize]
                }
            })
            .collect();
        for layer in 0..self.layers {
            for m in &self.maps {
                let range = layer * self.layer_texels + m.offset
                    ..layer * self.layer_texels + m.offset + m.texels();
                let (w, h) = (m.width as usize, m.height as usize);
                let chart = &texel_chart[m.offset..m.offset + m.texels()];
                fill_buried(
                    &mut values[range.clone()],
                    &mut state[range.clone()],
                    chart,
                    w,
                    h,
                );
                stats.dilated_texels += dilate(
                    &mut values[range.clone()],
                    &mut state[range],
                    w,
                    h,
                    self.settings.gutter,
                );
            }
        }
        let max = values
            .iter()
            .map(|v| v.max_element())
            .fold(0.0f32, f32::max);
        self.scale = StoreScale::for_max(max);
        self.packed = values.iter().map(|&v| self.scale.pack(v)).collect();
        // Feet share the texels' scale (clamped to their largest value, so that the
        // texels are stored as without them).
        let scale = self.scale;
        self.crossing_feet = crossings::settle_feet(&mut self.crossing_lines, &self.feet, |f| {
            scale.pack(f.min(Vec3::splat(max)))
        });
        stats.sample_points += self.foot_sites.iter().flatten().count() as u64;
        stats.samples += self.foot_samples;
        // UV1: three f32 pairs per triangle corner (a generated layout needs a vertex per
        // corner); the per-triangle instance index is the engine's mesh binding.
        stats.cache_bytes = STORED_RGB_BYTES * total as u64
            + 24 * self.uv1.len() as u64
            + 4 * self.crossing_slot.len() as u64
            + (20 + STORED_RGB_BYTES) * self.crossing_lines.len() as u64;
        self.stats = stats;
        self.slots = Vec::new();
        self.priors = Vec::new();
        self.guide = Vec::new();
        self.pending = Vec::new();
        self.site_uv = Vec::new();
        self.exits = Vec::new();
        self.foot_sites = Vec::new();
        self.feet = Vec::new();
        self.guides = TexelGuides::default();
    }

    /// Probes every owned slot for crossings near its texel ([`crossings::probe`], as far
    /// as [`crossings::LINE_REACH`] texels): records exits within its footprint
    /// ([`EXIT_REACH`]) for buried texels, and each crossing as a line in UV1 space with
    /// its foot for lookups.
    fn probe_crossings(&mut self, scene: &TracedScene) {
        let total = self.layers * self.layer_texels;
        let probes: Vec<(Vec2, Probe)> = (0..total)
            .into_par_iter()
            .map(|slot| {
                let (layer, i) = (slot / self.layer_texels, slot % self.layer_texels);
                let uv = self.sample_uv[i];
                match self.owner[i] {
                    NONE => (uv, Probe::default()),
                    t => {
                        let m = &self.maps[self.triangle_instance[t as usize] as usize];
                        let texel = 1.0 / m.texels_per_metre.max(f32::MIN_POSITIVE);
                        let mut probe = crossings::probe(
                            scene,
                            t,
                            uv,
                            layer == 0,
                            crossings::LINE_REACH * texel,
                        );
                        // A buried texel moves only within its own footprint.
                        if probe.exit_distance > EXIT_REACH * texel {
                            probe.exit = None;
                        }
                        // A centre on a crossing surface is estimated just beyond it, on
                        // the open side, from the first round on; its crossing line is
                        // oriented from there.
                        let site = probe.site(uv);
                        if probe.touching {
                            probe.exit = None;
                        }
                        (site, probe)
                    }
                }
            })
            .collect();
        self.site_uv = probes.iter().map(|(uv, _)| *uv).collect();
        self.exits = probes.iter().map(|(_, p)| p.exit).collect();
        self.crossing_slot = vec![NONE; total];
        self.crossing_lines.clear();
        self.foot_sites.clear();
        for (slot, (uv, probe)) in probes.iter().enumerate() {
            let Some(line) = probe.crossing else { continue };
            let t = self.owner[slot % self.layer_texels];
            let front = slot < self.layer_texels;
            let corners = self.uv1[t as usize];
            let Some((kept, foot)) =
                crossings::SampleCrossing::new(scene, t, front, &line, corners, *uv)
            else {
                continue;
            };
            self.crossing_slot[slot] = self.crossing_lines.len() as u32;
            self.crossing_lines.push(kept);
            self.foot_sites.push(foot);
        }
    }
}

/// How far (in texels) a buried texel's exit may lie: within its footprint (¾ of a texel
/// reaches its corners' direction closely enough).
const EXIT_REACH: f32 = 0.75;

/// Lays out instance `i`: its TEXCOORD_1 when usable, else a generated atlas; then
/// rasterises its triangles into texel owners and sample positions.
fn build_instance(scene: &TracedScene, i: usize, settings: &LightmapSettings) -> BuiltInstance {
    let range = scene.instance_triangles[i].clone();
    let (start, end) = (range.start as usize, range.end as usize);
    let positions = &scene.positions[start..end];
    let normals = &scene.geometric_normals[start..end];
    let world_area: f32 = positions
        .iter()
        .map(|&[a, b, c]| triangle_area(a, b, c))
        .sum();
    let mesh_uv1 = scene.has_uv1[i].then(|| &scene.uv1[start..end]);
    let uv_area = mesh_uv1.and_then(usable_uv1_area);
    let (width, height, uv1, found, clip, density, uses_mesh_uv1) = match (mesh_uv1, uv_area) {
        (Some(uv1), Some(uv_area)) => {
            // Square texture whose texels cover the mesh at the asked density.
            let side = (world_area / uv_area).sqrt() * settings.texels_per_metre;
            let side = ((side.ceil() as u32).div_ceil(4) * 4).clamp(4, settings.max_size.max(4));
            let found = charts::coplanar_charts(positions, normals);
            let clip = vec![[0, 0, side, side]; uv1.len()];
            let density = side as f32 * (uv_area / world_area).sqrt();
            (side, side, uv1.to_vec(), found, clip, density, true)
        }
        _ => {
            let atlas = charts::generate_atlas(
                positions,
                normals,
                settings.texels_per_metre,
                settings.gutter,
                settings.max_size,
            );
            let clip = atlas
                .charts
                .chart
                .iter()
                .map(|&c| atlas.chart_texels[c as usize])
                .collect();
            (
                atlas.width,
                atlas.height,
                atlas.uv1,
                atlas.charts,
                clip,
                atlas.texels_per_metre,
                false,
            )
        }
    };
    let (owner, sample_uv) = rasterise(&uv1, &clip, width, height, start as u32);
    BuiltInstance {
        map: InstanceMap {
            width,
            height,
            offset: 0,
            uses_mesh_uv1,
            texels_per_metre: density,
        },
        uv1,
        chart: found.chart,
        chart_count: found.count,
        owner,
        sample_uv,
    }
}

/// Total UV area of a mesh's TEXCOORD_1 if it can address a texture: finite, inside
/// [0, 1]² (within a texel-sized tolerance; clamp-to-edge makes anything outside
/// meaningless) and of positive area. Overlapping islands are the mesh's business.
fn usable_uv1_area(uv1: &[[Vec2; 3]]) -> Option<f32> {
    let inside = |p: &Vec2| {
        p.is_finite() && p.cmpge(Vec2::splat(-1e-3)).all() && p.cmple(Vec2::splat(1.001)).all()
    };
    if !uv1.iter().flatten().all(inside) {
        return None;
    }
    let area: f32 = uv1
        .iter()
        .map(|[a, b, c]| 0.5 * (*b - *a).perp_dot(*c - *a).abs())
        .sum();
    (area > 1e-12).then_some(area)
}

/// Calls `f(x, y)` for every texel of the rectangle `clip` (x, y, width, height) whose
/// square overlaps the triangle `corners` (texel units) in more than a sliver
/// ([`TEXEL_EPSILON`]): conservative rasterisation (Hasselgren, Akenine-Möller & Ohlsson,
/// "Conservative Rasterization", GPU Gems 2, ch. 42), decided per texel by the separating
/// axis test of a triangle and a box (Akenine-Möller 2001: the box axes, then each edge
/// normal against the box corner farthest along it). A triangle that overlaps no texel
/// that much still gets the texel holding its centroid. Degenerate triangles get none.
pub fn conservative_texels(corners: [Vec2; 3], clip: [u32; 4], f: impl FnMut(u32, u32)) {
    texels_overlapped_by(corners, clip, TEXEL_EPSILON, f);
}

/// [`conservative_texels`] with overlaps of at most `epsilon` texels counted as none (a
/// negative `epsilon` also counts texels the triangle comes within `-epsilon` of: a
/// superset, which the atlas packer reserves).
pub(crate) fn texels_overlapped_by(
    corners: [Vec2; 3],
    clip: [u32; 4],
    epsilon: f32,
    mut f: impl FnMut(u32, u32),
) {
    let [a, b, c] = corners;
    let twice_area = (b - a).perp_dot(c - a);
    if !twice_area.is_finite() || clip[2] == 0 || clip[3] == 0 {
        return;
    }
    if twice_area == 0.0 {
        segment_texels(corners, clip, epsilon, f);
        return;
    }
    let sign = twice_area.signum();
    // Inward edge normals (the interior is left of counter-clockwise edges).
    let edges = [(a, b), (b, c), (c, a)].map(|(p, q)| (p, (q - p).perp() * sign));
    let lo = a.min(b).min(c);
    let hi = a.max(b).max(c);
    let reach = Vec2::splat((-epsilon).max(0.0));
    let (lo, hi) = (lo - reach, hi + reach);
    let (cx1, cy1) = (clip[0] + clip[2] - 1, clip[1] + clip[3] - 1);
    let x0 = (lo.x.floor().max(0.0) as u32).clamp(clip[0], cx1);
    let y0 = (lo.y.floor().max(0.0) as u32).clamp(clip[1], cy1);
    let x1 = ((hi.x.ceil() - 1.0).max(0.0) as u32).clamp(clip[0], cx1);
    let y1 = ((hi.y.ceil() - 1.0).max(0.0) as u32).clamp(clip[1], cy1);
    let mut any = false;
    for y in y0..=y1 {
        let yf = y as f32;
        if yf + 1.0 - lo.y <= epsilon.max(0.0) || hi.y - yf <= epsilon.max(0.0) {
            continue;
        }
        for x in x0..=x1 {
            let xf = x as f32;
            if xf + 1.0 - lo.x <= epsilon.max(0.0) || hi.x - xf <= epsilon.max(0.0) {
                continue;
            }
            let separated = edges.iter().any(|&(p, n)| {
                let reach = n.dot(Vec2::new(xf, yf) - p) + n.x.max(0.0) + n.y.max(0.0);
                reach <= epsilon * n.length()
            });
            if !separated {
                any = true;
                f(x, y);
            }
        }
    }
    if !any {
        let centroid = (a + b + c) / 3.0;
        let x = (centroid.x.floor().max(0.0) as u32).clamp(clip[0], cx1);
        let y = (centroid.y.floor().max(0.0) as u32).clamp(clip[1], cy1);
        f(x, y);
    }
}

/// [`texels_overlapped_by`] for a triangle whose corners are collinear in UV1 (a chart of
/// a sliver whose parameterisation has no area): the texels whose centre lies within
/// ½ − `epsilon` of the segment the corners span, else the texel holding its midpoint.
fn segment_texels(corners: [Vec2; 3], clip: [u32; 4], epsilon: f32, mut f: impl FnMut(u32, u32)) {
    let [a, b, c] = corners;
    let (p, q) = [(a, b), (b, c), (c, a)]
        .into_iter()
        .max_by(|x, y| {
            (x.1 - x.0)
                .length_squared()
                .total_cmp(&(y.1 - y.0).length_squared())
        })
        .unwrap_or((a, b));
    let radius = 0.5 - epsilon;
    let (lo, hi) = (
        p.min(q) - Vec2::splat(radius),
        p.max(q) + Vec2::splat(radius),
    );
    let (cx1, cy1) = (clip[0] + clip[2] - 1, clip[1] + clip[3] - 1);
    let x0 = (lo.x.floor().max(0.0) as u32).clamp(clip[0], cx1);
    let y0 = (lo.y.floor().max(0.0) as u32).clamp(clip[1], cy1);
    let x1 = (hi.x.floor().max(0.0) as u32).clamp(clip[0], cx1);
    let y1 = (hi.y.floor().max(0.0) as u32).clamp(clip[1], cy1);
    let along = q - p;
    let length_squared = along.length_squared().max(f32::MIN_POSITIVE);
    let mut any = false;
    for y in y0..=y1 {
        for x in x0..=x1 {
            let centre = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            let s = ((centre - p).dot(along) / length_squared).clamp(0.0, 1.0);
            if (p + along * s - centre).length() <= radius {
                any = true;
                f(x, y);
            }
        }
    }
    if !any {
        let mid = 0.5 * (p + q);
        f(
            (mid.x.floor().max(0.0) as u32).clamp(clip[0], cx1),
            (mid.y.floor().max(0.0) as u32).clamp(clip[1], cy1),
        );
    }
}

/// Texel owners and sample barycentrics of one instance's texture: every triangle's
/// conservative footprint ([`conservative_texels`], limited to its `clip` rectangle)
/// competes for its texels by the distance from the texel centre to the triangle (zero
/// when it contains the centre; ties keep the lower triangle). The sample lies at the
/// closest point (Ericson, *Real-Time Collision Detection* §5.1.5, in UV1 space), i.e.
/// the centre when inside, with every barycentric at least [`INSIDE_MARGIN`].
fn rasterise(
    uv1: &[[Vec2; 3]],
    clip: &[[u32; 4]],
    width: u32,
    height: u32,
    first_triangle: u32,
) -> (Vec<u32>, Vec<Vec2>) {
    let n = (width * height) as usize;
    let mut owner = vec![NONE; n];
    let mut sample_uv = vec![Vec2::ZERO; n];
    let mut best = vec![f32::INFINITY; n];
    let size = Vec2::new(width as f32, height as f32);
    for (t, (corners, clip)) in uv1.iter().zip(clip).enumerate() {
        let [a, b, c] = corners.map(|p| (p * size).extend(0.0));
        conservative_texels(corners.map(|p| p * size), *clip, |x, y| {
            let centre = Vec2::new(x as f32 + 0.5, y as f32 + 0.5).extend(0.0);
            let uv = closest_point_barycentric(centre, a, b, c);
            let d = (interpolate(a, b, c, uv) - centre).length_squared();
            let k = (y * width + x) as usize;
            if d < best[k] {
                best[k] = d;
                owner[k] = first_triangle + t as u32;
                sample_uv[k] = uv;
            }
        });
    }
    for uv in &mut sample_uv {
        let w = 1.0 - uv.x - uv.y;
        if uv.min_element().min(w) < INSIDE_MARGIN {
            // Shrink the triangle towards its centroid so every coordinate is ≥ the margin.
            *uv = *uv * (1.0 - 3.0 * INSIDE_MARGIN) + Vec2::splat(INSIDE_MARGIN);
        }
    }
    (owner, sample_uv)
}

/// The random-stream key of a texel: its owner's stable key, the side and the texel
/// coordinates, so that results never depend on scheduling.
fn texel_key(triangle_key: u64, layer: usize, x: u32, y: u32) -> u64 {
    splitmix64(triangle_key ^ splitmix64(((layer as u64) << 62) | ((x as u64) << 31) | y as u64))
}

/// The up-to-8 neighbours of texel `k` of a `w × h` image.
#[inline]
fn neighbours(k: usize, w: usize, h: usize) -> impl Iterator<Item = usize> {
    let (x, y) = ((k % w) as isize, (k / w) as isize);
    (-1isize..=1)
        .flat_map(move |dy| (-1isize..=1).map(move |dx| (x + dx, y + dy)))
        .filter(move |&(i, j)| {
            (i, j) != (x, y) && i >= 0 && j >= 0 && (i as usize) < w && (j as usize) < h
        })
        .map(move |(i, j)| j as usize * w + i as usize)
}

/// Refills buried texels of one texture from valid 8-neighbours by iterative averaging
/// (a Jacobi-style flood fill: each pass sets every buried texel that touches a valid one
/// to the mean of those, which then count as valid), preferring neighbours of the same
/// chart; only when no buried texel has such a neighbour does a pass take any valid
/// neighbour. Buried texels that no valid texel reaches keep their own estimate.
fn fill_buried(values: &mut [Vec3], state: &mut [Burial], chart: &[u32], w: usize, h: usize) {
    let mut pending: Vec<usize> = (0..values.len())
        .filter(|&k| state[k] == Burial::Buried)
        .collect();
    let mut updates: Vec<(usize, Vec3)> = Vec::new();
    let mut any_chart = false;
    while !pending.is_empty() {
        updates.clear();
        for &k in &pending {
            let (mut sum, mut count) = (Vec3::ZERO, 0u32);
            for j in neighbours(k, w, h) {
                if state[j] == Burial::Valid && (any_chart || chart[j] == chart[k]) {
                    sum += values[j];
                    count += 1;
                }
            }
            if count > 0 {
                updates.push((k, sum / count as f32));
            }
        }
        if updates.is_empty() {
            if any_chart {
                break;
            }
            any_chart = true;
            continue;
        }
        any_chart = false;
        for &(k, v) in &updates {
            values[k] = v;
            state[k] = Burial::Valid;
        }
        pending.retain(|&k| state[k] == Burial::Buried);
    }
}

/// Dilation: `passes` times, every texel no triangle owns that touches a set texel takes
/// the mean of its set 8-neighbours and becomes set (texels beyond stay black). Returns
/// how many texels were filled.
fn dilate(values: &mut [Vec3], state: &mut [Burial], w: usize, h: usize, passes: u32) -> u64 {
    let mut filled = 0;
    let mut updates: Vec<(usize, Vec3)> = Vec::new();
    for _ in 0..passes {
        updates.clear();
        for k in (0..values.len()).filter(|&k| state[k] == Burial::Empty) {
            let (mut sum, mut count) = (Vec3::ZERO, 0u32);
            for j in neighbours(k, w, h) {
                if state[j] != Burial::Empty {
                    sum += values[j];
                    count += 1;
                }
            }
            if count > 0 {
                updates.push((k, sum / count as f32));
            }
        }
        if updates.is_empty() {
            break;
        }
        for &(k, v) in &updates {
            values[k] = v;
            state[k] = Burial::Valid;
        }
        filled += updates.len() as u64;
    }
    filled
}

/// Bilinear lookup with clamp-to-edge in stored texels, arithmetic identical to
/// [`crate::texture::bilinear`] on the unpacked image (what the GPU sampler computes),
/// except near crossings: `line_of(k)` is texel k's crossing line ([`NONE`]: none) and
/// `crossing(line)` the line with the value at its foot; texels whose crossing separates
/// them from the point looked up are left out and the others' weights renormalised, and
/// a texel whose line lies between it and the point takes the value linear from its foot
/// to it ([`crossings::SampleCrossing::value`]). Where every texel is rejected the plain
/// bilinear value is returned.
#[inline]
fn bilinear_packed(
    texels: &[StoredRgb],
    width: u32,
    height: u32,
    uv: Vec2,
    scale: StoreScale,
    line_of: impl Fn(usize) -> u32,
    crossing: impl Fn(u32) -> (crossings::SampleCrossing, Vec3),
) -> Vec3 {
    let x = (uv.x * width as f32 - 0.5).clamp(0.0, (width - 1) as f32);
    let y = (uv.y * height as f32 - 0.5).clamp(0.0, (height - 1) as f32);
    let (x0, y0) = (x.floor() as u32, y.floor() as u32);
    let (x1, y1) = ((x0 + 1).min(width - 1), (y0 + 1).min(height - 1));
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let taps = [
        (x0, y0, (1.0 - fx) * (1.0 - fy)),
        (x1, y0, fx * (1.0 - fy)),
        (x0, y1, (1.0 - fx) * fy),
        (x1, y1, fx * fy),
    ];
    let keys = taps.map(|(i, j, _)| (j * width + i) as usize);
    let values = keys.map(|k| scale.unpack(texels[k]));
    // Exactly the published texture's bilinear ([`crate::texture::bilinear`]).
    let plain = || {
        let top = values[0] * (1.0 - fx) + values[1] * fx;
        let bottom = values[2] * (1.0 - fx) + values[3] * fx;
        top * (1.0 - fy) + bottom * fy
    };
    let lines = keys.map(&line_of);
    if lines.iter().all(|&l| l == NONE) {
        return plain();
    }
    let (mut sum, mut weight, mut changed) = (Vec3::ZERO, 0.0f32, false);
    for n in 0..4 {
        let w = taps[n].2;
        if w <= 0.0 {
            continue;
        }
        let mut value = values[n];
        if lines[n] != NONE {
            let (c, foot) = crossing(lines[n]);
            let Some((tapped, blended)) = c.tap(uv, value, foot) else {
                changed = true;
                continue;
            };
            changed |= blended;
            value = tapped;
        }
        sum += value * w;
        weight += w;
    }
    if !changed || weight <= 0.0 {
        plain()
    } else {
        sum / weight
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
        if round > 0 {
            for &(slot, budget) in &self.pending {
                let (layer, i) = (
                    slot as usize / self.layer_texels,
                    slot as usize % self.layer_texels,
                );
                points.push(self.texel_point(scene, layer, i, round, Some(budget)));
                self.slots.push(slot);
            }
            self.pending.clear();
            if self.slots.is_empty() {
                self.emitted = true;
            }
            return;
        }
        // An incremental re-bake (priors) keeps one round of estimates stopped by the
        // estimator itself: they update filtered values, which are not filtered again.
        let budget = match self.plan {
            Some(plan) if self.priors.is_empty() => Some(plan.first),
            _ => None,
        };
        if let Some(plan) = self.plan.filter(|p| {
            self.settings.guiding && self.priors.is_empty() && p.bound > 0.0 && p.max > p.first
        }) {
            self.guides = TexelGuides::recording(&self.maps, &self.owner, self.layers, plan.floor);
        }
        self.probe_crossings(scene);
        for layer in 0..self.layers {
            for m in &self.maps {
                for i in m.offset..m.offset + m.texels() {
                    if self.owner[i] == NONE {
                        continue;
                    }
                    points.push(self.texel_point(scene, layer, i, 0, budget));
                    self.slots.push((layer * self.layer_texels + i) as u32);
                }
            }
        }
        // Feet of crossed texels (module docs, Crossings): estimated once, unfiltered,
        // with a quarter of the most samples a texel may take (about what a texel takes
        // on average at the defaults); without a plan, to the estimator's own bound.
        let foot_budget = self.plan.map(|p| (p.max / 4).max(p.first));
        self.feet = vec![Vec3::NAN; self.crossing_lines.len()];
        self.foot_lines.clear();
        for (slot, &c) in self.crossing_slot.iter().enumerate() {
            let Some(foot) = self.foot_sites.get(c as usize).copied().flatten() else {
                continue;
            };
            let (layer, i) = (slot / self.layer_texels, slot % self.layer_texels);
            let texel = self.texel_point(scene, layer, i, 0, None);
            points.push(SamplePoint {
                site: SampleSite::Surface {
                    triangle: self.owner[i],
                    uv: foot,
                    front: layer == 0,
                },
                key: splitmix64(texel.key ^ crossings::FOOT_KEY),
                prior: None,
                budget: foot_budget,
            });
            self.foot_lines.push(c);
        }
        self.later_samples = budget.map_or(0, |b| {
            (LATER_ROUNDS_GUESS * b as f32 * self.slots.len() as f32) as u64
        });
    }

    fn later_samples(&self) -> Option<u64> {
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
        let total = self.layers * self.layer_texels;
        let foot_estimates = &estimates[self.slots.len().min(estimates.len())..];
        for (&line, e) in self.foot_lines.iter().zip(foot_estimates) {
            self.foot_samples += e.samples as u64;
            self.feet[line as usize] = crossings::foot_value(e);
        }
        self.foot_lines.clear();
        if self.merged.len() != total {
            self.merged = vec![TexelEstimate::default(); total];
            self.state = vec![Burial::Empty; total];
            self.guide = self.texel_guides(scene);
        }
        let mut moved = Vec::new();
        for (&slot, e) in self.slots.iter().zip(estimates) {
            let slot = slot as usize;
            self.merged[slot].merge(e);
            if matches!(self.state[slot], Burial::Empty | Burial::Moved) {
                let buried = e.back_face_share > self.settings.buried_threshold;
                let exit = self.exits.get(slot).copied().flatten();
                self.state[slot] = match (buried, exit, self.state[slot]) {
                    (false, _, _) => Burial::Valid,
                    // Inside a solid, with a visible part of the footprint beyond the
                    // crossing: estimate there instead.
                    (true, Some(uv), Burial::Empty)
                        if self.plan.is_some() && self.priors.is_empty() =>
                    {
                        self.site_uv[slot] = uv;
                        self.merged[slot] = TexelEstimate::default();
                        moved.push(slot as u32);
                        Burial::Moved
                    }
                    _ => Burial::Buried,
                };
            }
        }
        if !moved.is_empty() {
            self.guide = self.texel_guides(scene);
        }
        let plan = self.plan.filter(|_| self.priors.is_empty());
        let filtered = self.filtered(plan.as_ref());
        self.pending.clear();
        if let Some(plan) = plan {
            self.pending
                .extend(moved.iter().map(|&slot| (slot, plan.first)));
        }
        self.later_samples = 0;
        if let Some(plan) = plan.filter(|p| p.bound > 0.0) {
            for (slot, (e, (v, s))) in self.merged.iter().zip(&filtered).enumerate() {
                if self.state[slot] != Burial::Valid || e.samples == 0 || e.samples >= plan.max {
                    continue;
                }
                let error = plan.relative_error(*v, *s);
                if error > plan.bound {
                    // Double the samples; σ² falls like 1/n, so about n·(C/bound)² in all
                    // would meet the bound: what that needs beyond this round is the
                    // progress report's guess of the later rounds.
                    let more = e.samples.min(plan.max - e.samples);
                    let needed = (e.samples as f32 * (error / plan.bound).powi(2))
                        .min(plan.max as f32) as u64;
                    self.later_samples += needed.saturating_sub((e.samples + more) as u64);
                    self.pending.push((slot as u32, more));
                }
            }
        }
        self.guides
            .learn(self.pending.iter().map(|&(slot, _)| slot as usize));
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
        let layer = match (front, self.layers) {
            (true, _) => 0,
            (false, 2) => 1,
            _ => return Vec3::NAN,
        };
        let t = triangle as usize;
        let instance = self.triangle_instance[t] as usize;
        let m = &self.maps[instance];
        let [a, b, c] = self.uv1[t];
        let at = interpolate(a, b, c, uv);
        let base = layer * self.layer_texels + m.offset;
        bilinear_packed(
            self.texture_slice(layer, instance),
            m.width,
            m.height,
            at,
            self.scale,
            |k| self.crossing_slot.get(base + k).copied().unwrap_or(NONE),
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
        let mut reused: Vec<Option<usize>> = vec![None; new.instance_triangles.len()];
        let built: Vec<BuiltInstance> = (0..new.instance_triangles.len())
            .map(|i| {
                let range = new.instance_triangles[i].clone();
                let first_old = triangle_map
                    .get(range.start as usize)
                    .copied()
                    .unwrap_or(UNMAPPED);
                let i_old = old.instance.get(first_old as usize).map(|&k| k as usize);
                let one_to_one = i_old.is_some_and(|io| {
                    let old_range = &old.instance_triangles[io];
                    old_range.len() == range.len()
                        && old.mirrored[io] == new.mirrored[i]
                        && range
                            .clone()
                            .enumerate()
                            .all(|(k, t)| triangle_map[t as usize] == old_range.start + k as u32)
                        && !self.owner.is_empty()
                });
                match i_old.filter(|_| one_to_one) {
                    Some(io) => {
                        reused[i] = Some(io);
                        self.instance_layout(old, io, range.start)
                    }
                    None => build_instance(new, i, &self.settings),
                }
            })
            .collect();
        let mut fresh = Self::from_instances(new, self.settings, built);
        let mut priors = vec![None; fresh.layers * fresh.layer_texels];
        for (i, io) in reused.iter().enumerate() {
            let Some(io) = *io else { continue };
            let (m, m_old) = (fresh.maps[i], self.maps[io]);
            for layer in 0..fresh.layers.min(self.layers) {
                let slice = self.texture_slice(layer, io);
                for k in 0..m.texels() {
                    let old_slot = layer * self.layer_texels + m_old.offset + k;
                    let buried = self.buried_slots.get(old_slot).copied().unwrap_or(true);
                    if fresh.owner[m.offset + k] != NONE && !buried {
                        priors[layer * fresh.layer_texels + m.offset + k] =
                            Some(self.scale.unpack(slice[k]));
                    }
                }
            }
            debug_assert_eq!((m.width, m.height), (m_old.width, m_old.height));
        }
        fresh.priors = priors;
        fresh
    }

    fn diagnostic(&self, triangle: u32, uv: Vec2, front: bool) -> Diagnostic {
        let layer = match (front, self.layers) {
            (true, _) => 0,
            (false, 2) => 1,
            _ => return Diagnostic::default(),
        };
        let t = triangle as usize;
        let instance = self.triangle_instance[t] as usize;
        let m = &self.maps[instance];
        let [a, b, c] = self.uv1[t];
        let p = interpolate(a, b, c, uv) * Vec2::new(m.width as f32, m.height as f32);
        let x = (p.x.max(0.0) as usize).min(m.width as usize - 1);
        let y = (p.y.max(0.0) as usize).min(m.height as usize - 1);
        let slot = layer * self.layer_texels + m.offset + y * m.width as usize + x;
        Diagnostic {
            samples: self.sample_counts.get(slot).copied().unwrap_or(0),
            order: None,
        }
    }

    /// One texture per instance for the front side, and one for the back side of
    /// instances with a double-sided material (when baked); UV1 in mesh order.
    fn publish(&self, scene: &TracedScene) -> Vec<IrradianceTexture> {
        let mut out = Vec::new();
        for (i, m) in self.maps.iter().enumerate() {
            let range = scene.instance_triangles[i].clone();
            let mesh_triangles = range
                .clone()
                .map(|t| scene.local_triangle[t as usize] + 1)
                .max()
                .unwrap_or(0);
            let mut uv1 = vec![[Vec2::ZERO; 3]; mesh_triangles as usize];
            for t in range.clone() {
                let [a, b, c] = self.uv1[t as usize];
                // Traced corners B and C are the mesh's C and B under a mirroring transform.
                uv1[scene.local_triangle[t as usize] as usize] = if scene.mirrored[i] {
                    [a, c, b]
                } else {
                    [a, b, c]
                };
            }
            let double_sided = !range.is_empty() && scene.material_of(range.start).double_sided;
            for layer in 0..self.layers {
                if layer == 1 && !double_sided {
                    continue;
                }
                out.push(IrradianceTexture {
                    instance: i as u32,
                    name: scene.instance_names[i].clone(),
                    front: layer == 0,
                    width: m.width,
                    height: m.height,
                    texels: self
                        .texture_slice(layer, i)
                        .iter()
                        .map(|&v| self.scale.unpack(v))
                        .collect(),
                    uv1: uv1.clone(),
                    uses_mesh_uv1: m.uses_mesh_uv1,
                    uv_rect: [0.0, 0.0, 1.0, 1.0],
                });
            }
        }
        out
    }
}

impl Lightmaps {
    /// Per triangle (of the scene `self` was laid out over): the largest change, in any
    /// channel and layer, of the texels a lookup on it can read (its UV1 box plus the
    /// bilinear footprint), against `before` looked up on `triangle_map[t]`. Where the
    /// layouts differ, the sum of both sides' largest values bounds the change.
    pub fn triangle_changes(&self, before: &Lightmaps, triangle_map: &[u32]) -> Vec<f32> {
        (0..self.triangle_instance.len())
            .map(|t| {
                let t_old = triangle_map.get(t).copied().unwrap_or(UNMAPPED);
                let same_layout = t_old != UNMAPPED && {
                    let (i, io) = (
                        self.triangle_instance[t] as usize,
                        before.triangle_instance[t_old as usize] as usize,
                    );
                    let (m, mo) = (&self.maps[i], &before.maps[io]);
                    (m.width, m.height) == (mo.width, mo.height)
                        && self.uv1[t] == before.uv1[t_old as usize]
                        && self.layers == before.layers
                };
                let mut change = 0.0f32;
                for layer in 0..self.layers {
                    let after = self.footprint(layer, t as u32);
                    if same_layout {
                        let old = before.footprint(layer, t_old);
                        for (a, b) in after.zip(old) {
                            change = change.max((a - b).abs().max_element());
                        }
                    } else {
                        let a = after.fold(0.0f32, |m, v| m.max(v.abs().max_element()));
                        let b = if t_old == UNMAPPED || layer >= before.layers {
                            0.0
                        } else {
                            before
                                .footprint(layer, t_old)
                                .fold(0.0f32, |m, v| m.max(v.abs().max_element()))
                        };
                        change = change.max(a + b);
                    }
                }
                change
            })
            .collect()
    }

    /// The texels of `layer` that bilinear lookups on `triangle` read, row by row.
    fn footprint(&self, layer: usize, triangle: u32) -> impl Iterator<Item = Vec3> + '_ {
        let instance = self.triangle_instance[triangle as usize] as usize;
        let m = self.maps[instance];
        let texels = self.texture_slice(layer, instance);
        let [a, b, c] = self.uv1[triangle as usize];
        let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
        let size = Vec2::new(m.width as f32, m.height as f32);
        let first = ((lo * size - 0.5).floor().max(Vec2::ZERO)).as_uvec2();
        let last = (hi * size - 0.5).floor().max(Vec2::ZERO).as_uvec2() + 1;
        let last = last.min(glam::UVec2::new(m.width - 1, m.height - 1));
        let first = first.min(last);
        (first.y..=last.y).flat_map(move |y| {
            (first.x..=last.x).map(move |x| self.scale.unpack(texels[(y * m.width + x) as usize]))
        })
    }
}
