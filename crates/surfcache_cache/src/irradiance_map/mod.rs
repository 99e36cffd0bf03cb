//! Per-triangle adaptive irradiance maps (docs/design.md, Caches), the thesis' surface cache.
//!
//! Every (triangle, side) owns a barycentric grid of order `n` (a power of two): samples
//! E(i, j) at index coordinates `i + j ≤ n`, position φ(i/n, j/n), `s(n) = (n+1)(n+2)/2`
//! of them ([`grid_size`]) stored at `m(i, j) = (i+j)(i+j+1)/2 + j` ([`grid_index`]).
//! Lookup interpolates linearly inside the grid cell that holds `(u, v)`
//! ([`grid_interpolate`]) and never crosses into another triangle.
//!
//! **Generator.** Round 0 asks for every grid at order `min(2, n_max)`. After each round,
//! every grid that just doubled compares each *new* sample (one with an odd index
//! coordinate) with the linear interpolation of the coarse grid there: the mean of the
//! two coarse samples at the ends of the coarse edge it halves ([`coarse_neighbours`]).
//! It doubles again while the largest difference exceeds
//! [`IrradianceMapSettings::interpolation_error`] (the thesis' test) or a cell is active
//! for a crossing or a burial boundary (Local refinement), and its order is below its
//! maximum `n_max = clamp(next_pow2(ceil(longest edge · density)), 1, max_order)`
//! ([`IrradianceMapSettings::max_order_for`]). Doubling keeps every sample ((i, j) of
//! order n is (2i, 2j) of order 2n); only new ones are estimated, and where a crossing
//! or a burial boundary alone makes a grid double, only those local refinement asks
//! for. A triangle no longer than one sample spacing (`longest edge · density ≤ 1`)
//! keeps an order-1 grid, its three corners: on a finely tessellated mesh (Sponza at a
//! coarse density) the maps then cost three samples per triangle side instead of six.
//!
//! **Local refinement** (the thesis' outlook: model no more than a scene needs). A grid
//! whose test failed doubles whole: every new sample of its next round is estimated, as
//! in the thesis. A grid that doubles only because a crossing or a burial boundary runs
//! through it doubles *locally*: a cell (three neighbouring samples) is *active* when, of
//! its corners, one is valid (not buried) and they span buried and valid samples, or a
//! crossing passes one within [`crossings::LINE_REACH`] spacings of the grid's order
//! (each sample's probe reaches that far at the order that made it), or one *failed* the
//! cell test (the difference above, with [`IrradianceMapSettings::cell_sigmas`] standard
//! errors for noise, above [`IrradianceMapSettings::cell_error`]); the new samples on
//! the edges of active cells are estimated, and every other new sample, lying inside or
//! between cells whose linear interpolation the cell test accepted, takes that
//! interpolation, the mean of the edge's ends, as its value (*interpolated*: no estimate,
//! no rays but its probes'). The cell test is tighter than the grid's (1 % beyond two
//! standard errors against 5 % beyond three): the grid's decides whether to look closer
//! at all, where noise must not refine a flat grid; the cell's decides which values are
//! kept between a crossing's cells, where an interpolated sample is off by at most about
//! the noise of an estimate there plus its bound. Storage and lookups stay those of the
//! uniform grid of the grid's order. Grids on a punctual shadow edge and first doublings
//! (orders 1 and 2) estimate every new sample; so does a sample that its probe finds on a
//! crossing surface or with a crossing line. So a large floor triangle that a column
//! pierces reaches its maximum order around the column, and the contact shadow there,
//! while its open parts stop where the light is smooth, as they would without the
//! column: the crossed and partly buried grids that refined to their maximum order
//! everywhere took most of a Sponza bake's samples (docs/results.md, "Local refinement
//! of irradiance maps"). Local refinement of every grid, the whole-grid test's included,
//! saved more and cost accuracy (the same section).
//!
//! **Samples by area.** Every estimated sample draws until the estimator's bound or its
//! cap, and on a level most valid samples end at the cap. The cap is what a sample one
//! density spacing (1/density) from its neighbours may draw; a sample whose grid spacing
//! h is smaller stands for less surface and draws at most the share
//! `h · density / FULL_CAP_SPACING` of it ([`IrradianceMapSettings::cap_share`], never
//! fewer than the estimator's minimum): one half to all of the cap on grids at their
//! maximum order (spacings between one half and one density spacing), less at the
//! corners of small triangles. For the error over a surface, samples count the most
//! where they stand for the most area: n_i samples of variance σ_i² standing for area
//! a_i give the area-weighted error Σ a_i σ_i² / n_i, least for n_i ∝ σ_i √a_i, and
//! √a_i ∝ h_i. The spacing h is the grid's longest edge over its order, except on a
//! sliver, whose order follows its longest edge while its samples share a small area:
//! there h is the side of the area a sample stands for
//! ([`IrradianceMapSettings::cap_spacing`]). Crossing feet keep the full cap. On Sponza this spends a fifth fewer
//! samples for nearly the same error, where lowering the cap for all samples by as much
//! loses the median (docs/results.md, "Light-sample roulette and samples by area").
//!
//! **Guiding** (the thesis' outlook: importance sampling). A grid that may still refine
//! twice records, region by region, where the light of its new samples came from, and
//! the new samples of its later rounds draw their directions through the guide learnt
//! from its earlier rounds ([`guides`]; docs/design.md, Guiding): a gallery floor lit through an arcade
//! gets most of its light from a small part of its hemisphere, which plain cosine
//! sampling finds by chance. [`IrradianceMapSettings::guiding`] turns it off.
//!
//! **Shadow probes.** A hard shadow narrower than the coarse sample spacing can fall
//! between all of a grid's samples (the thesis' misjudged triangle), where no comparison
//! of samples sees it. Grids that a punctual light's shadow boundary crosses — found by
//! one shadow ray per light at each point of the maximum-order grid,
//! [`punctual_shadow_edges`] — therefore refine to their maximum order.
//!
//! **Noise rule.** Estimates are noisy, and a plain test would keep refining noise. Only
//! the part of a difference that exceeds `k` combined standard errors counts:
//! `e = max_c max(0, |ΔE_c| − k·σ_c) / (E_new,c + ε)` with
//! `ΔE = E_new − (E_a + E_b)/2`, `σ² = se_new² + (se_a² + se_b²)/4` (per channel `c`),
//! `k =` [`IrradianceMapSettings::noise_sigmas`] (default 3; the cell test's
//! [`IrradianceMapSettings::cell_sigmas`], default 2) and ε the estimator's floor
//! ([`IrradianceMapSettings::floor`]). A grid refines when the largest `e` over its new
//! samples exceeds the bound. Pure noise then passes with near certainty (it would need
//! `|ΔE| > kσ + bound·(E + ε)`), while a real change of E between neighbours triggers
//! refinement once it stands out of the noise by the bound.
//!
//! **Keys.** A sample's random stream is keyed by ([`TracedScene::triangle_key`], side,
//! position on a fixed grid of [`KEY_RESOLUTION`]), see [`sample_key`]: the same point
//! gets the same estimate whichever round or order introduced it, so results do not
//! depend on scheduling.
//!
//! **Shared corners** (the thesis' outlook: mark vertices that are safe to share). The
//! triangles around a mesh vertex all ask for a sample at their corner there. Within one
//! instance and on the same side, corners are estimated once for every triangle that may
//! share them, when
//! 1. they belong to the same mesh vertex and their traced vertex normals are equal
//!    (a vertex normal facing away from a triangle is replaced by its geometric normal);
//! 2. their geometric normals differ by at most [`IrradianceMapSettings::share_angle`]
//!    (default 10°): the shared estimate clips its hemisphere by the representative's
//!    plane, the other triangle's differs by a lune of dihedral angle α that carries
//!    (1 − cos α)/2 of E under a uniform sky, 0.76 % at 10°. Coplanar and smoothly
//!    curved neighbours share; a box's faces, 90° apart, never do;
//! 3. nothing lies between their two ray origins (each a small step inside its own
//!    triangle, the leak guard): a wall of another instance standing on the vertex keeps
//!    the two sides apart.
//!
//! The triangles around a vertex are visited in ascending index, and each joins the first
//! earlier *representative* it may share with or becomes one itself ([`corner_links`]).
//! A shared corner is estimated at its representative's site with the representative's
//! key, so results do not depend on which grid asked first; [`SurfaceCache::next_round`]
//! asks for one point per distinct site and [`SurfaceCache::finish_round`] copies its
//! estimate into every grid that uses it ([`CacheStats::sample_points`] counts points,
//! `cache_bytes` stored copies). On a finely tessellated mesh whose triangles keep
//! order-1 grids this about halves the points (docs/results.md, "Sponza"); corners on
//! creases and the larger triangles' refinement remain. Edges are not shared: their samples are estimated once per
//! adjacent grid.
//!
//! **Buried samples.** An estimate whose `back_face_share` exceeds
//! [`IrradianceMapSettings::buried_threshold`] lies inside other geometry (a floor under
//! a box). Its value is replaced by the mean of its non-buried grid neighbours, ring by
//! ring from the valid ones ([`IrradianceMaps`] keeps the raw estimates while baking and
//! refills after each round); a grid that is buried everywhere keeps its raw values.
//! Buried samples are left out of the refinement test as new samples (their filled values
//! are used as coarse neighbours). A cell with both buried and valid corners is active
//! whatever the tests say: other geometry cuts through it, and the light next to the
//! cut (the contact shadow around a box standing in the middle of a large floor
//! triangle, whose only sample near the box is buried) would otherwise pass the test
//! unseen between the valid samples. A cell buried at every corner shows nothing and is
//! not refined; its interpolated samples count as buried and are filled. Buried samples
//! are counted in [`CacheStats::buried`].
//!
//! **Crossings** ([`crate::crossings`]). Grids that another surface crosses or touches
//! ([`crossed_grids`]) probe each new sample in the surface's plane: as far as
//! [`crossings::LINE_REACH`] spacings of the grid's order, for the cells it makes active
//! (Local refinement), so that the cells around a crossing refine to the maximum order;
//! and as far as a little more than one spacing of the maximum order, for the line its
//! lookups use (both from one probe, [`crossings::Probe::within`]). A sample on a
//! crossing surface (a grid point on the line where a wall stands) is estimated just
//! beyond it, on the open side. A sample that a crossing passes within reach keeps the
//! crossing's line (in barycentrics, oriented towards the sample) and one more estimate
//! at its *foot*, the nearest point of the triangle just short of the line
//! ([`crossings::foot`]). A lookup then leaves out the cell's samples that the line of
//! their own crossing separates from the point looked up (renormalising the others'
//! weights; the interpolation is unchanged where none is), and takes for a sample whose
//! line lies between it and the point the value linear from its foot to it: E next to a contact is that of the contact, not of a
//! sample up to a spacing away, and no light is carried across the crossing. The
//! published textures cannot show either (an engine's filter knows no crossings).
//!
//! **Filtering** (the thesis' outlook: sharing samples). Once no grid refines any more,
//! every valid estimate of a bake is filtered with its neighbours in space
//! ([`crate::filter::filter_points`], [`IrradianceMapSettings::filter`]): each estimate
//! once however many corners share it, with the spacing at which estimates lie around it
//! (at most one sample spacing of the density), a weighted mean at the largest of three
//! scales whose value the smaller ones agree with. Samples with a crossing line keep
//! their own estimates; the other samples of crossed grids share only with neighbours an
//! any-hit ray finds nothing between. Interpolated samples are then interpolated anew
//! from the filtered estimates. The refinement test before saw each sample's own estimate.
//! An incremental re-bake does not filter: its estimates update values that were
//! filtered when they were made (re-estimated ones meet the bound on their own), and a
//! changed sample averaged with neighbours that kept their values would lose most of its
//! change (as lightmaps do, [`crate::lightmap`]). Nor does it test grids that kept all
//! their priors: such a grid keeps the order the bake before chose, since its values are
//! that bake's, and so were the test and the burial that decided it. Tested anew, priors
//! (their errors taken at the bound, their burial unknown) doubled grids the bake before
//! had let be (crossed grids buried all over among them), and every new sample of those
//! was estimated from scratch (docs/results.md, "Editing a level: irradiance maps").
//! A grid the edit reaches has samples the re-bake estimates again, and is tested and
//! forced as in any bake. A sample buried before the edit (its value filled in) stays
//! buried where the edit does not reach it, as does a crossing foot that was; the
//! indirect stages of a re-bake take no surface away, so there it is never estimated,
//! and it is no source of their forward rays ([`IrradianceMaps::sample_changes`]).
//!
//! **Storage.** Samples are three half floats (6 bytes, [`crate::stored_rgb`], one
//! [`StoreScale`] chosen from the largest
//! stored value), grid by grid; a grid slot `2·triangle + side` (side 0 = front) has a
//! `u32` offset and a `u8` level `log2(order) + 1` (0 = not baked). `cache_bytes = 6·samples +
//! 5·grid slots + 4` (the last 4: the scale), plus, for crossed grids, 4 bytes a sample
//! (its line), 8 a grid and 26 a line (line, distances, foot value). Estimates' f32
//! values, standard errors and burial flags live only while baking.
//!
//! ```
//! use surfcache_cache::{SurfaceCache, bake::bake_to_convergence};
//! use surfcache_cache::irradiance_map::{IrradianceMapSettings, IrradianceMaps};
//! use surfcache_core::{Environment, Instance, Material, Scene, glam::*, scenes::quad};
//! use surfcache_trace::{EstimatorSettings, Sampler, TracedScene};
//! use std::sync::Arc;
//! // A square under a uniform sky of radiance 1: E = π everywhere.
//! let v = Vec3::new;
//! let mesh = quad("floor", [v(0., 0., 0.), v(1., 0., 0.), v(1., 0., 1.), v(0., 0., 1.)], Vec3::Y);
//! let scene = Scene {
//!     instances: vec![Instance {
//!         name: "floor".into(),
//!         mesh: Arc::new(mesh),
//!         material: Arc::new(Material::diffuse("white", Vec3::splat(0.8))),
//!         transform: Affine3A::IDENTITY,
//!     }],
//!     environment: Environment::uniform(Vec3::ONE),
//!     ..Default::default()
//! };
//! let traced = TracedScene::new(&scene).unwrap();
//! let maps = IrradianceMaps::new(&traced, IrradianceMapSettings::default());
//! let estimator = EstimatorSettings::fixed(Sampler::Best, 64, None);
//! let maps = bake_to_convergence(&traced, maps, &estimator, 0);
//! let e = maps.lookup(0, Vec2::new(0.2, 0.3), true);
//! assert!((e - Vec3::splat(std::f32::consts::PI)).abs().max_element() < 0.02);
//! assert_eq!(maps.stats().order_histogram[&2], 4); // 2 triangles × 2 sides, flat E
//! ```
//!
//! The parts: [`grid`] (one barycentric grid), [`settings`], [`sharing`] (shared
//! corners), [`filtering`] (sharing samples between neighbours), [`forced_refinement`]
//! (shadow probes and crossed grids), [`working`] (the state of a bake in progress),
//! [`rounds`] (the points of each round and what its estimates change), [`guides`]
//! (direction guides of refining grids) and [`refinement`] (burial fill and the
//! refinement test).

mod filtering;
mod forced_refinement;
mod grid;
mod guides;
mod refinement;
mod rounds;
mod settings;
mod sharing;
mod working;

pub use forced_refinement::{crossed_grids, punctual_shadow_edges};
use grid::order_of_level;
pub use grid::{
    KEY_RESOLUTION, MAX_ORDER_LIMIT, coarse_neighbours, grid_index, grid_interpolate,
    grid_interpolate_kept, grid_size, sample_key,
};
pub(crate) use settings::EstimateTotals;
pub use settings::{FULL_CAP_SPACING, IrradianceMapSettings};
pub use sharing::corner_links;

use crate::burial::Burial;
use crate::{
    CacheStats, Diagnostic, IrradianceTexture, Method, Prior, SamplePoint, SurfaceCache, UNMAPPED,
    crossings,
    incremental::{ChangePatch, changed_region, near_changed_region},
    mesh_colour,
    stored_rgb::{STORED_RGB_BYTES, StoreScale, StoredRgb},
};
use crossings::SampleCrossing;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use rounds::grown_layout;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use surfcache_core::{
    geometry::{longest_edge, triangle_area},
    index::NO_INDEX,
};
use surfcache_trace::{Estimate, Guidance, TracedScene};
use working::{SampleProbe, Working};

/// Per-triangle adaptive irradiance maps (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IrradianceMaps {
    settings: IrradianceMapSettings,
    /// `log2(order) + 1` of each grid slot `2·triangle + side`; 0: not baked.
    levels: Vec<u8>,
    /// First sample of each grid slot in `packed`.
    offsets: Vec<u32>,
    /// Stored samples, grid by grid, each in [`grid_index`] order.
    packed: Vec<StoredRgb>,
    /// Hemisphere samples behind each stored sample (diagnostics only; not part of
    /// `cache_bytes`).
    #[serde(default)]
    sample_counts: Vec<u32>,
    scale: StoreScale,
    totals: EstimateTotals,
    buried: u64,
    /// The crossing line of each sample that has one (module docs, Crossings).
    #[serde(default)]
    lines: Vec<SampleCrossing>,
    /// E at each line's foot ([`crossings::SampleCrossing::foot`]; zero where it has none).
    #[serde(default)]
    feet: Vec<StoredRgb>,
    /// Crossed grid slots, ascending, each with its first entry in `sample_lines`.
    #[serde(default)]
    crossed_grids: Vec<[u32; 2]>,
    /// Per sample of each crossed grid, in [`grid_index`] order: its line in `lines`, or
    /// [`NO_INDEX`].
    #[serde(default)]
    sample_lines: Vec<u32>,
    /// Per stored sample: whether it was buried (its value filled in from neighbours, so
    /// no surface sees its light and it is no prior for a change estimate). Kept for a
    /// re-bake of these maps; empty in maps read from a file (then none counts as buried).
    #[serde(skip)]
    buried_samples: Vec<bool>,
    /// Per sample of each crossed grid, as `sample_lines`: its probe, carried by a
    /// re-bake to grids that no changed surface comes near. Empty in maps read from a
    /// file (then a re-bake probes again).
    #[serde(skip)]
    sample_probes: Vec<SampleProbe>,
    #[serde(skip)]
    working: Option<Box<Working>>,
}

impl IrradianceMaps {
    /// Unbaked maps for `scene`: every front side, and the back sides `settings` asks
    /// for, will start at order `min(2, n_max)`.
    pub fn new(scene: &TracedScene, settings: IrradianceMapSettings) -> Self {
        Self::knowing_crossings(scene, settings, |_| None)
    }

    /// [`Self::new`], with the grid slots whose crossing `known` gives left unprobed
    /// ([`crossed_grids`]).
    fn knowing_crossings(
        scene: &TracedScene,
        settings: IrradianceMapSettings,
        known: impl Fn(usize) -> Option<bool> + Sync,
    ) -> Self {
        let triangles = scene.triangle_count();
        let max_orders: Vec<u32> = scene
            .positions()
            .iter()
            .map(|[a, b, c]| settings.max_order_for(longest_edge(*a, *b, *c)))
            .collect();
        let refine: Vec<bool> = (0..2 * triangles)
            .map(|g| {
                g % 2 == 0 || settings.both_sides || scene.material_of((g / 2) as u32).double_sided
            })
            .collect();
        let shadow_edges = punctual_shadow_edges(scene, &max_orders, &refine);
        let crossed = crossed_grids(scene, &max_orders, &refine, known);
        let links = if settings.share_corners {
            corner_links(scene, settings.share_angle.to_radians().cos(), &refine)
        } else {
            Vec::new()
        };
        Self {
            settings,
            levels: vec![0; 2 * triangles],
            offsets: vec![0; 2 * triangles],
            packed: Vec::new(),
            sample_counts: Vec::new(),
            scale: StoreScale::default(),
            totals: EstimateTotals::default(),
            buried: 0,
            lines: Vec::new(),
            feet: Vec::new(),
            crossed_grids: Vec::new(),
            sample_lines: Vec::new(),
            buried_samples: Vec::new(),
            sample_probes: Vec::new(),
            working: Some(Box::new(Working {
                max_orders,
                refine,
                shadow_edges,
                crossed,
                links,
                points_per_sample: 1.0,
                ..Default::default()
            })),
        }
    }

    /// The settings the maps were made with.
    pub fn settings(&self) -> &IrradianceMapSettings {
        &self.settings
    }

    #[inline]
    fn slot(triangle: u32, front: bool) -> usize {
        2 * triangle as usize + (!front) as usize
    }

    /// The current order of the grid on one side of `triangle` (0: not baked).
    pub fn order(&self, triangle: u32, front: bool) -> u32 {
        order_of_level(self.levels[Self::slot(triangle, front)])
    }

    /// Stored sample (i, j) of the grid on one side of `triangle` (which must be baked).
    #[inline]
    pub fn sample(&self, triangle: u32, front: bool, i: u32, j: u32) -> Vec3 {
        let g = Self::slot(triangle, front);
        self.scale
            .unpack(self.packed[self.offsets[g] as usize + grid_index(i, j)])
    }

    /// Whether another surface crosses the grid on one side of `triangle`: its lookups
    /// then leave out samples across the crossing and blend towards the samples' feet
    /// (module docs, Crossings), which the published textures cannot show.
    pub fn is_crossed(&self, triangle: u32, front: bool) -> bool {
        let g = Self::slot(triangle, front) as u32;
        self.crossed_grids
            .binary_search_by_key(&g, |c| c[0])
            .is_ok()
    }

    /// Whether the bake has converged (no grid asks for refinement any more).
    pub fn is_converged(&self) -> bool {
        self.working.is_none()
    }

    /// Every stored sample, not buried, whose value changed beyond `share`
    /// ([`ChangePatch::of_sample`]) against `before` looked up on `triangle_map[t]`: sample
    /// against sample where the grid kept its order, against `before`'s lookup at the
    /// sample's grid point elsewhere (zero where the triangle did not exist before).
    /// Each sample as a [`ChangePatch`] at its grid point on its side, standing for an
    /// equal share of the triangle's area (the sources of an indirect stage of a re-bake,
    /// as [`Lightmaps::texel_changes`](crate::lightmap::Lightmaps::texel_changes) gives a
    /// lightmap's).
    pub fn sample_changes(
        &self,
        scene: &TracedScene,
        before: &IrradianceMaps,
        triangle_map: &[u32],
        share: f32,
    ) -> Vec<ChangePatch> {
        (0..self.levels.len())
            .into_par_iter()
            .flat_map_iter(|g| {
                let (t, front) = ((g / 2) as u32, g % 2 == 0);
                let n = self.order(t, front);
                let t_old = triangle_map.get(t as usize).copied().unwrap_or(UNMAPPED);
                let n_old = match t_old {
                    UNMAPPED => 0,
                    _ => before.order(t_old, front),
                };
                let [a, b, c] = scene.positions()[t as usize];
                let area = triangle_area(a, b, c) / grid_size(n.max(1)) as f32;
                let base = self.offsets[g] as usize;
                (0..=n).flat_map(move |i| {
                    (0..=n - i).filter_map(move |j| {
                        let k = base + grid_index(i, j);
                        // A buried sample's value is filled in from its neighbours: no
                        // surface sees its light.
                        if n == 0 || self.buried_samples.get(k) == Some(&true) {
                            return None;
                        }
                        let uv = Vec2::new(i as f32, j as f32) / n as f32;
                        let after = self.scale.unpack(self.packed[k]);
                        let old = match (t_old, n_old == n) {
                            (UNMAPPED, _) => Vec3::ZERO,
                            (_, true) => before.sample(t_old, front, i, j),
                            (_, false) => before.lookup(t_old, uv, front),
                        };
                        ChangePatch::of_sample(t, front, uv, area, after, old, share)
                    })
                })
            })
            .collect()
    }
}

impl SurfaceCache for IrradianceMaps {
    fn method(&self) -> Method {
        Method::IrradianceMap
    }

    /// The new samples of every grid that asks to double (or to be made): see
    /// [`Self::ask_new_samples`].
    fn next_round(&mut self, scene: &TracedScene, points: &mut Vec<SamplePoint>) {
        self.ask_new_samples(scene, points);
    }

    /// The forecast of the rounds after the one handed out ([`working::LaterRounds`]).
    fn later_samples(&self, samples_per_point: f64) -> Option<u64> {
        let Some(w) = self.working.as_ref() else {
            return Some(0);
        };
        let later = w.later.as_ref()?;
        Some((later.samples() * w.points_per_sample * samples_per_point) as u64)
    }

    /// New samples of refining grids draw through their region's guide and record into
    /// its record ([`guides`]); feet do neither.
    fn guidance(&self, i: usize) -> Guidance<'_> {
        match self.working.as_ref() {
            Some(w) => w.guides.guidance(i),
            None => Guidance::default(),
        }
    }

    fn borrows_guides(&self) -> bool {
        self.settings.guiding
    }

    /// A grid sample is buried above [`IrradianceMapSettings::buried_threshold`], a
    /// crossing's foot above [`crossings::FOOT_BURIED_SHARE`].
    fn buried_share(&self, i: usize) -> Option<f32> {
        let w = self.working.as_ref()?;
        let foot = w
            .round_feet
            .binary_search_by_key(&(i as u32), |f| f.1)
            .is_ok();
        Some(match foot {
            true => crossings::FOOT_BURIED_SHARE,
            false => self.settings.buried_threshold,
        })
    }

    /// Moves the samples into the grids' new orders with the round's estimates, fills
    /// buried samples, decides which grids double again, and packs.
    fn finish_round(
        &mut self,
        scene: &TracedScene,
        points: &[SamplePoint],
        estimates: &[Estimate],
    ) {
        let Some(mut w) = self.working.take() else {
            return;
        };
        assert_eq!(
            (points.len(), estimates.len()),
            (w.pending_points, w.pending_points),
            "finish_round needs the estimates of the points next_round asked for"
        );
        let (new_levels, offsets, total) = grown_layout(&self.levels, &w);
        w.regrid(&self.levels, &self.offsets, &new_levels, &offsets, total);
        w.store_estimates(
            &self.levels,
            &new_levels,
            &offsets,
            points,
            estimates,
            self.settings.buried_threshold,
        );
        for &(line, point) in &w.round_feet {
            let e = &estimates[point as usize];
            // A re-bake's buried foot that the edit did not reach stays buried.
            w.feet[line as usize] = match Prior::kept_buried(points[point as usize].prior, e) {
                true => Vec3::NAN,
                false => crossings::foot_value(e),
            };
        }
        estimates.iter().for_each(|e| self.totals.add(e));
        self.levels = new_levels;
        self.offsets = offsets;
        self.fill_buried(&mut w, total);
        self.buried = w.burial.iter().filter(|&&b| b != Burial::Valid).count() as u64;
        self.decide_refinement(&mut w, scene);
        // The grids are final: share samples between neighbours, interpolate anew, then
        // refill.
        if !w.refine.contains(&true) && self.share_samples(scene, &mut w) {
            self.rederive(&mut w);
            self.fill_buried(&mut w, total);
        }
        w.end_round();
        self.pack(&w);
        self.working = Some(w);
    }

    /// Sides with a grid: front faces, and back faces where both sides or the material's
    /// two sides are baked.
    fn holds(&self, triangle: u32, front: bool) -> bool {
        self.order(triangle, front) > 0
    }

    fn lookup(&self, triangle: u32, uv: Vec2, front: bool) -> Vec3 {
        let g = Self::slot(triangle, front);
        let n = order_of_level(self.levels[g]);
        if n == 0 {
            return Vec3::ZERO;
        }
        let base = self.offsets[g] as usize;
        let packed = &self.packed[base..base + grid_size(n)];
        let value = |i, j| self.scale.unpack(packed[grid_index(i, j)]);
        match self
            .crossed_grids
            .binary_search_by_key(&(g as u32), |c| c[0])
        {
            Ok(k) => {
                let first = self.crossed_grids[k][1] as usize;
                let lines = &self.sample_lines[first..first + grid_size(n)];
                let near = |i, j| match lines[grid_index(i, j)] {
                    NO_INDEX => value(i, j),
                    l => self.lines[l as usize].value(
                        uv,
                        value(i, j),
                        self.scale.unpack(self.feet[l as usize]),
                    ),
                };
                grid_interpolate_kept(n, uv, near, |i, j| match lines[grid_index(i, j)] {
                    NO_INDEX => true,
                    l => self.lines[l as usize].on_side(uv),
                })
            }
            Err(_) => grid_interpolate(n, uv, value),
        }
    }

    /// Every grid of a surviving triangle starts at its order before the edit, all its
    /// samples asked for again with their values as priors (buried ones as
    /// [`Prior::Filled`]: they stay buried where the edit does not reach them, and are
    /// estimated afresh where it does); grids of new triangles start afresh at order
    /// `min(2, n_max)`. Refinement then continues as in a full bake, so a grid the edit
    /// gave new detail (a shadow edge) doubles. Grids that no changed surface comes near
    /// keep their crossed flags and their samples' probes.
    fn remap(&self, old: &TracedScene, new: &TracedScene, triangle_map: &[u32]) -> Self {
        // A grid's crossings lie within its probes' reach (at most `LINE_REACH` times its
        // longest edge): a kept triangle that no changed surface comes that near keeps them.
        let region = changed_region(old, new, triangle_map);
        let known = |g: usize| {
            let (t, front) = (g / 2, g.is_multiple_of(2));
            let t_old = *triangle_map.get(t)?;
            let corners = new.positions()[t];
            if t_old == UNMAPPED
                || old.positions().get(t_old as usize) != Some(&corners)
                || self.order(t_old, front) == 0
            {
                return None;
            }
            let [a, b, c] = corners;
            let reach = Vec3::splat(
                crossings::LINE_REACH * longest_edge(a, b, c) + 4.0 * new.spawn_offset(),
            );
            if near_changed_region(region, a.min(b).min(c), a.max(b).max(c), reach) {
                return None;
            }
            Some(self.is_crossed(t_old, front))
        };
        let mut fresh = Self::knowing_crossings(new, self.settings, known);
        let slots = fresh.levels.len();
        let mut start_log2: Vec<u8> = (0..slots)
            .map(|g| fresh.working.as_ref().map_or(1, |w| w.start_log2(g)))
            .collect();
        let mut prior_offsets = vec![NO_INDEX; slots];
        let mut priors = Vec::new();
        let mut prior_feet = Vec::new();
        let mut prior_probe_offsets = vec![NO_INDEX; slots];
        let mut prior_probes = Vec::new();
        for g in 0..slots {
            let (t, front) = ((g / 2) as u32, g % 2 == 0);
            let t_old = triangle_map[t as usize];
            if t_old == UNMAPPED {
                continue;
            }
            let n = self.order(t_old, front);
            if n == 0 {
                continue;
            }
            start_log2[g] = n.trailing_zeros() as u8;
            prior_offsets[g] = priors.len() as u32;
            let old_slot = Self::slot(t_old, front);
            let base = self.offsets[old_slot] as usize;
            priors.extend((base..base + grid_size(n)).map(|k| {
                let value = self.scale.unpack(self.packed[k]);
                match self.buried_samples.get(k) {
                    Some(true) => Prior::Filled(value),
                    _ => Prior::Estimated(value),
                }
            }));
            // The feet of its samples' crossing lines, with their lines.
            if let Ok(k) = self
                .crossed_grids
                .binary_search_by_key(&(old_slot as u32), |c| c[0])
            {
                let first = self.crossed_grids[k][1] as usize;
                // Its samples' probes, where no changed surface comes near.
                let probes = self.sample_probes.get(first..first + grid_size(n));
                if let (Some(probes), Some(true)) = (probes, known(g)) {
                    prior_probe_offsets[g] = prior_probes.len() as u32;
                    prior_probes.extend_from_slice(probes);
                }
                for m in 0..grid_size(n) {
                    let l = self.sample_lines[first + m];
                    if l == NO_INDEX {
                        continue;
                    }
                    // A line settled without a foot had a buried one: NaN.
                    let line = self.lines[l as usize];
                    let value = match line.has_foot() {
                        true => self.scale.unpack(self.feet[l as usize]),
                        false => Vec3::NAN,
                    };
                    prior_feet.push((prior_offsets[g] + m as u32, line, value));
                }
            }
        }
        if let Some(w) = fresh.working.as_mut() {
            w.start_log2 = start_log2;
            w.priors = priors;
            w.prior_offsets = prior_offsets;
            w.prior_feet = prior_feet;
            w.prior_probes = prior_probes;
            w.prior_probe_offsets = prior_probe_offsets;
            w.rebake = true;
        }
        fresh
    }

    fn diagnostic(&self, triangle: u32, uv: Vec2, front: bool) -> Diagnostic {
        let g = Self::slot(triangle, front);
        let n = self.order(triangle, front);
        if n == 0 {
            return Diagnostic::default();
        }
        // The nearest grid sample.
        let p = (uv.clamp(Vec2::ZERO, Vec2::ONE) * n as f32).round();
        let (mut i, mut j) = (p.x as u32, p.y as u32);
        if i + j > n {
            if i > j { i -= 1 } else { j -= 1 }
        }
        let k = self.offsets[g] as usize + grid_index(i.min(n), j.min(n - i.min(n)));
        Diagnostic {
            samples: self.sample_counts.get(k).copied().unwrap_or(0),
            order: Some(n),
        }
    }

    fn stats(&self) -> CacheStats {
        let mut order_histogram = BTreeMap::new();
        for &l in &self.levels {
            if l > 0 {
                *order_histogram.entry(order_of_level(l)).or_insert(0) += 1;
            }
        }
        CacheStats {
            cache_bytes: STORED_RGB_BYTES * self.packed.len() as u64
                + 5 * self.levels.len() as u64
                + 4
                + (20 + STORED_RGB_BYTES) * self.lines.len() as u64
                + 8 * self.crossed_grids.len() as u64
                + 4 * self.sample_lines.len() as u64,
            order_histogram,
            buried: self.buried,
            ..self.totals.stats()
        }
    }

    fn publish(&self, scene: &TracedScene) -> Vec<IrradianceTexture> {
        mesh_colour::publish_all(
            scene,
            |t, front| self.order(t, front),
            |t, front, i, j| {
                if self.order(t, front) == 0 {
                    Vec3::ZERO
                } else {
                    self.sample(t, front, i, j)
                }
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::incremental::cornell_moved;

    /// A re-bake carries the crossings of the grids that no changed surface comes near
    /// and probes the others: together they must be the crossings of the edited scene.
    #[test]
    fn carried_crossings_are_the_crossings_of_the_edited_scene() {
        // Both blocks lifted 10 cm off the floor: the floor, which keeps its triangles,
        // is no longer crossed.
        let (old, new, map) = cornell_moved(|name| name.ends_with("_block"), Vec3::Y * 0.1);
        let settings = IrradianceMapSettings::default();
        // Baked with a constant E: only forced grids refine.
        let mut before = IrradianceMaps::new(&old, settings);
        let mut points = Vec::new();
        loop {
            points.clear();
            before.next_round(&old, &mut points);
            if points.is_empty() {
                break;
            }
            let e = Estimate {
                value: Vec3::ONE,
                samples: 1,
                ..Default::default()
            };
            before.finish_round(&old, &points, &vec![e; points.len()]);
        }
        let crossed = |m: &IrradianceMaps| m.working.as_ref().unwrap().crossed.clone();
        let carried = crossed(&before.remap(&old, &new, &map));
        let fresh = crossed(&IrradianceMaps::new(&new, settings));
        assert_eq!(carried, fresh);

        // Where nothing changed (as in a re-bake's indirect stages) every crossed grid
        // carries its samples' probes: they must be the ones probing gives.
        let same: Vec<u32> = (0..old.triangle_count() as u32).collect();
        let mut remapped = before.remap(&old, &old, &same);
        let mut probed = remapped.clone();
        let w = probed.working.as_mut().unwrap();
        assert!(!w.prior_probes.is_empty(), "no probe carried");
        w.prior_probe_offsets = Vec::new();
        let (mut a, mut b) = (Vec::new(), Vec::new());
        remapped.next_round(&old, &mut a);
        probed.next_round(&old, &mut b);
        assert_eq!(a, b);
        assert_eq!(remapped.lines, probed.lines);
        assert!(!remapped.lines.is_empty());

        let unchanged = |t: usize| old.positions()[map[t] as usize] == new.positions()[t];
        let moved_off: Vec<usize> = (0..fresh.len())
            .filter(|&g| unchanged(g / 2) && before.is_crossed(map[g / 2], g % 2 == 0) != fresh[g])
            .collect();
        assert!(!moved_off.is_empty(), "no kept grid changed its crossing");
    }
}
