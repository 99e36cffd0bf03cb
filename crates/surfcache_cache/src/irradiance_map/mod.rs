//! Per-triangle adaptive irradiance maps (docs/design.md, Caches), the thesis' surface cache.
//!
//! Every (triangle, side) owns a barycentric grid of order `n` (a power of two): samples
//! E(i, j) at index coordinates `i + j ≤ n`, position φ(i/n, j/n), `s(n) = (n+1)(n+2)/2`
//! of them ([`grid_size`]) stored at `m(i, j) = (i+j)(i+j+1)/2 + j` ([`grid_index`]).
//! Lookup interpolates linearly inside the grid cell that holds `(u, v)`
//! ([`grid_interpolate`]) and never crosses into another triangle.
//!
//! **Generator.** Round 0 asks for every grid at order `min(2, n_max)`. After each round,
//! every grid that just doubled compares each *new* sample (one with an odd index coordinate) with
//! the linear interpolation of the coarse grid there: the mean of the two coarse samples
//! at the ends of the coarse edge it halves ([`coarse_neighbours`]). It doubles again
//! while the largest difference exceeds
//! [`IrradianceMapSettings::interpolation_error`] and its order is below its maximum
//! `n_max = clamp(next_pow2(ceil(longest edge · density)), 1, max_order)`
//! ([`IrradianceMapSettings::max_order_for`]). Doubling keeps every sample ((i, j) of
//! order n is (2i, 2j) of order 2n); only the new ones are estimated. A triangle no
//! longer than one sample spacing (`longest edge · density ≤ 1`) keeps an order-1 grid,
//! its three corners: on a finely tessellated mesh (Sponza at a coarse density) the maps
//! then cost three samples per triangle side instead of six.
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
//! `k =` [`IrradianceMapSettings::noise_sigmas`] (default 3) and ε the estimator's floor
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
//! are used as coarse neighbours). A grid with both buried and valid samples refines
//! anyway, up to its maximum order: other geometry cuts through the triangle, and the
//! light next to the cut (the contact shadow around a box standing in the middle of a
//! large floor triangle, whose only sample near the box is buried) would otherwise pass
//! the test unseen between the valid samples. A grid buried everywhere shows nothing and
//! does not refine. Buried samples are counted in [`CacheStats::buried`].
//!
//! **Crossings** ([`crate::crossings`]). Grids that another surface crosses or touches
//! ([`crossed_grids`]) refine to their maximum order, and each of their samples is probed
//! in the surface's plane a little farther than one spacing of that order. A sample on a
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

mod forced_refinement;
mod grid;
mod settings;
mod sharing;

pub use forced_refinement::{crossed_grids, punctual_shadow_edges};
pub use grid::{
    KEY_RESOLUTION, MAX_ORDER_LIMIT, coarse_neighbours, grid_index, grid_interpolate,
    grid_interpolate_kept, grid_size, sample_key,
};
use grid::{corner_of, for_each_new_sample, order_of_level};
pub(crate) use settings::EstimateTotals;
pub use settings::IrradianceMapSettings;
pub use sharing::corner_links;
use surfcache_core::index::NO_INDEX;

use crate::burial::Burial;
use crate::{
    CacheStats, Diagnostic, IrradianceTexture, Method, SamplePoint, SampleSite, SurfaceCache,
    UNMAPPED, crossings, mesh_colour,
    stored_rgb::{STORED_RGB_BYTES, StoreScale, StoredRgb},
};
use crossings::SampleCrossing;
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use surfcache_core::{geometry::longest_edge, sampling::splitmix64};
use surfcache_trace::{Estimate, TracedScene};

/// What only baking needs: raw estimates, their errors, burial flags, refinement state.
/// Arrays are parallel to the stored samples.
#[derive(Clone, Debug, Default, PartialEq)]
struct Working {
    /// Maximum order per triangle.
    max_orders: Vec<u32>,
    /// Whether each grid slot asks to double (or, before its first round, to be baked).
    refine: Vec<bool>,
    /// Grid slots whose new samples the current round estimates, ascending.
    pending: Vec<u32>,
    /// Number of points the current round asked for.
    pending_points: usize,
    /// Raw estimates E, their sample counts and standard errors.
    raw: Vec<Vec3>,
    samples: Vec<u32>,
    std_error: Vec<Vec3>,
    /// Values after burial filling, and their standard errors.
    filled: Vec<Vec3>,
    filled_error: Vec<Vec3>,
    /// Burial state of every sample ([`Burial::Buried`] or [`Burial::Valid`] when estimated).
    burial: Vec<Burial>,
    /// Per sample: its crossing line in [`IrradianceMaps::lines`], or
    /// [`NO_INDEX`] (module docs, Crossings).
    line_of: Vec<u32>,
    /// Grid slots another surface crosses ([`crossed_grids`]): their samples are probed.
    crossed: Vec<bool>,
    /// Per new grid sample of the current round, in the order of `sources`: its line.
    round_lines: Vec<u32>,
    /// Per line: the estimate at its sample's foot (NaN: none, or buried).
    feet: Vec<Vec3>,
    /// This round's foot points: (line, round point).
    round_feet: Vec<(u32, u32)>,
    /// Order (log2) of each grid slot's first round; empty: `min(2, n_max)` everywhere.
    start_log2: Vec<u8>,
    /// Grid slots whose punctual lights' shadow boundary crosses them
    /// ([`punctual_shadow_edges`]) or that another surface crosses ([`crossed_grids`]):
    /// they refine to their maximum order.
    shadow_edges: Vec<bool>,
    /// Corner links: `links[3·slot + k]` is `3·slot' + k'` when corner k of grid `slot`
    /// takes the estimate of corner k' of grid `slot'`, its representative, or
    /// [`NO_INDEX`]; empty when corners are not shared ([`corner_links`]).
    links: Vec<u32>,
    /// Per new grid sample of the current round, in [`for_each_new_sample`] order over
    /// `pending`: the round point whose estimate it takes.
    sources: Vec<u32>,
    /// Re-bakes: values of the maps before an edit, grid by grid, for the first round
    /// ([`SamplePoint::prior`]); `prior_offsets[g]` is grid slot g's first, or
    /// [`NO_INDEX`] for a grid without one.
    priors: Vec<Vec3>,
    prior_offsets: Vec<u32>,
}

impl Working {
    /// The order grid slot `g` has (`coarse`, 0 before its first round) and the order
    /// this round gives it: its first order, or double.
    fn round_orders(&self, g: usize, levels: &[u8]) -> (u32, u32) {
        match order_of_level(levels[g]) {
            0 => (0, 1 << self.start_log2(g)),
            coarse => (coarse, 2 * coarse),
        }
    }

    /// log2 of the order grid slot `g` starts at: a re-bake's prior order, else
    /// `min(2, n_max)`.
    fn start_log2(&self, g: usize) -> u8 {
        match self.start_log2.get(g) {
            Some(&l) => l,
            None => (self.max_orders[g / 2] >= 2) as u8,
        }
    }
}

/// Probes the new samples of this round's crossed grids ([`crossings::probe`], as far as
/// one spacing of the grid's maximum order, where lookups use the lines), in the order
/// [`SurfaceCache::next_round`] visits them: each sample's site (a sample on a crossing
/// surface moves just beyond it, as lightmap texels do) and its crossing line, oriented
/// from the site, in barycentric coordinates.
fn probe_new_samples(
    scene: &TracedScene,
    w: &Working,
    levels: &[u8],
) -> Vec<(Vec2, Option<SampleCrossing>, Option<Vec2>)> {
    use rayon::prelude::*;
    let mut sites = Vec::new();
    for &g in w.pending.iter().filter(|&&g| w.crossed[g as usize]) {
        let (coarse, n) = w.round_orders(g as usize, levels);
        let inv = 1.0 / n as f32;
        for_each_new_sample(coarse, n, |i, j, _| {
            sites.push((g, Vec2::new(i as f32 * inv, j as f32 * inv)));
        });
    }
    sites
        .par_iter()
        .map(|&(g, uv)| {
            let (t, front) = (g / 2, g % 2 == 0);
            let [a, b, c] = scene.positions[t as usize];
            let reach =
                crossings::LINE_REACH * longest_edge(a, b, c) / w.max_orders[t as usize] as f32;
            let probe = crossings::probe(scene, t, uv, front, reach);
            let site = probe.site(uv);
            let kept = probe.crossing.and_then(|crossing| {
                SampleCrossing::new(scene, t, front, &crossing, crossings::BARYCENTRIC, site)
            });
            (site, kept.map(|(c, _)| c), kept.and_then(|(_, foot)| foot))
        })
        .collect()
}

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
    #[serde(skip)]
    working: Option<Box<Working>>,
}

impl IrradianceMaps {
    /// Unbaked maps for `scene`: every front side, and the back sides `settings` asks
    /// for, will start at order `min(2, n_max)`.
    pub fn new(scene: &TracedScene, settings: IrradianceMapSettings) -> Self {
        let triangles = scene.triangle_count();
        let max_orders: Vec<u32> = scene
            .positions
            .iter()
            .map(|[a, b, c]| settings.max_order_for(longest_edge(*a, *b, *c)))
            .collect();
        let refine: Vec<bool> = (0..2 * triangles)
            .map(|g| {
                g % 2 == 0 || settings.both_sides || scene.material_of((g / 2) as u32).double_sided
            })
            .collect();
        let mut shadow_edges = punctual_shadow_edges(scene, &max_orders, &refine);
        let crossed = crossed_grids(scene, &max_orders, &refine);
        for (forced, &crossed) in shadow_edges.iter_mut().zip(&crossed) {
            *forced |= crossed;
        }
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
            working: Some(Box::new(Working {
                max_orders,
                refine,
                shadow_edges,
                crossed,
                links,
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

    /// Fills the buried samples of the grid at `base` of order `n` from their valid
    /// neighbours, ring by ring (module docs); writes `filled` and `filled_error`.
    fn fill_grid(w: &mut Working, base: usize, n: u32) {
        let size = grid_size(n);
        let range = base..base + size;
        w.filled[range.clone()].copy_from_slice(&w.raw[range.clone()]);
        w.filled_error[range.clone()].copy_from_slice(&w.std_error[range.clone()]);
        let burial = &mut w.burial[range];
        if burial.iter().all(|&b| b == Burial::Valid) || burial.iter().all(|&b| b != Burial::Valid)
        {
            return;
        }
        burial.iter_mut().for_each(|b| {
            if *b != Burial::Valid {
                *b = Burial::Buried;
            }
        });
        loop {
            let mut changed = false;
            for d in 0..=n {
                for j in 0..=d {
                    let i = d - j;
                    let m = grid_index(i, j);
                    if burial[m] != Burial::Buried {
                        continue;
                    }
                    let (mut sum, mut err, mut count) = (Vec3::ZERO, Vec3::ZERO, 0u32);
                    let (ii, jj) = (i as i64, j as i64);
                    for (di, dj) in [(-1, 0), (1, 0), (0, -1), (0, 1), (1, -1), (-1, 1)] {
                        let (a, b) = (ii + di, jj + dj);
                        if a < 0 || b < 0 || a + b > n as i64 {
                            continue;
                        }
                        let k = grid_index(a as u32, b as u32);
                        if burial[k] == Burial::Valid || burial[k] == Burial::Filled {
                            sum += w.filled[base + k];
                            err += w.filled_error[base + k];
                            count += 1;
                        }
                    }
                    if count > 0 {
                        w.filled[base + m] = sum / count as f32;
                        w.filled_error[base + m] = err / count as f32;
                        burial[m] = Burial::FilledNow;
                        changed = true;
                    }
                }
            }
            if !changed {
                break;
            }
            burial.iter_mut().for_each(|b| {
                if *b == Burial::FilledNow {
                    *b = Burial::Filled;
                }
            });
        }
    }

    /// The refinement test of a grid of order `n` at `base` that just doubled (or was
    /// just made): the largest noise-corrected relative difference e between a new,
    /// non-buried sample and the coarse interpolation there (module docs).
    fn interpolation_error(&self, w: &Working, base: usize, n: u32) -> f32 {
        let k = self.settings.noise_sigmas;
        let eps = self.settings.floor;
        let mut worst = 0.0f32;
        for_each_new_sample(n / 2, n, |i, j, m| {
            if w.burial[base + m] != Burial::Valid {
                return;
            }
            let [[ai, aj], [bi, bj]] = coarse_neighbours(i, j);
            let (a, b) = (base + grid_index(ai, aj), base + grid_index(bi, bj));
            let interp = 0.5 * (w.filled[a] + w.filled[b]);
            let sigma2 = w.std_error[base + m] * w.std_error[base + m]
                + 0.25
                    * (w.filled_error[a] * w.filled_error[a]
                        + w.filled_error[b] * w.filled_error[b]);
            let value = w.raw[base + m];
            for c in 0..3 {
                let excess = ((value[c] - interp[c]).abs() - k * sigma2[c].sqrt()).max(0.0);
                if excess > 0.0 {
                    let e = excess / (value[c].max(0.0) + eps);
                    worst = worst.max(if e.is_nan() { f32::INFINITY } else { e });
                }
            }
        });
        worst
    }
}

impl SurfaceCache for IrradianceMaps {
    fn method(&self) -> Method {
        Method::IrradianceMap
    }

    fn next_round(&mut self, scene: &TracedScene, points: &mut Vec<SamplePoint>) {
        let Some(w) = self.working.as_mut() else {
            return;
        };
        w.pending.clear();
        w.pending
            .extend((0..w.refine.len() as u32).filter(|&g| w.refine[g as usize]));
        if w.pending.is_empty() {
            self.working = None;
            return;
        }
        let start = points.len();
        let w = &mut **w;
        w.sources.clear();
        w.round_lines.clear();
        w.round_feet.clear();
        let mut probed = probe_new_samples(scene, w, &self.levels).into_iter();
        // Round point of each corner asked for in this round (only rounds that make
        // grids have corners to share).
        let mut corner_points = Vec::new();
        for &g in &w.pending {
            let (t, front) = (g / 2, g % 2 == 0);
            let (coarse, n) = w.round_orders(g as usize, &self.levels);
            if coarse == 0 && !w.links.is_empty() && corner_points.is_empty() {
                corner_points = vec![NO_INDEX; w.links.len()];
            }
            let key = scene.triangle_key(t);
            let inv = 1.0 / n as f32;
            let prior_base = match w.prior_offsets.get(g as usize) {
                Some(&o) if coarse == 0 && o != NO_INDEX => Some(o as usize),
                _ => None,
            };
            let crossed = w.crossed[g as usize];
            for_each_new_sample(coarse, n, |i, j, m| {
                let mut uv = Vec2::new(i as f32 * inv, j as f32 * inv);
                let mut line = NO_INDEX;
                let sample_key = sample_key(key, front, i, j, n);
                if crossed {
                    let (site, crossing, foot) = probed.next().expect("one probe per new sample");
                    uv = site;
                    if let Some(l) = crossing {
                        line = self.lines.len() as u32;
                        self.lines.push(l);
                        w.feet.push(Vec3::NAN);
                    }
                    if let Some(foot) = foot {
                        w.round_feet.push((line, (points.len() - start) as u32));
                        points.push(SamplePoint {
                            site: SampleSite::Surface {
                                triangle: t,
                                uv: foot,
                                front,
                            },
                            key: splitmix64(sample_key ^ crossings::FOOT_KEY),
                            prior: None,
                            budget: None,
                        });
                    }
                }
                w.round_lines.push(line);
                let corner = match (coarse, corner_of(i, j, n)) {
                    (0, Some(k)) if !corner_points.is_empty() => Some(3 * g as usize + k),
                    _ => None,
                };
                if let Some(c) = corner {
                    let link = w.links[c];
                    if link != NO_INDEX && corner_points[link as usize] != NO_INDEX {
                        w.sources.push(corner_points[link as usize]);
                        return;
                    }
                    corner_points[c] = (points.len() - start) as u32;
                }
                w.sources.push((points.len() - start) as u32);
                points.push(SamplePoint {
                    site: SampleSite::Surface {
                        triangle: t,
                        uv,
                        front,
                    },
                    key: sample_key,
                    prior: prior_base.map(|b| w.priors[b + m]),
                    budget: None,
                });
            });
        }
        w.pending_points = points.len() - start;
    }

    fn finish_round(
        &mut self,
        _scene: &TracedScene,
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
        // New layout: pending grids double (fresh ones start at their first order).
        let slots = self.levels.len();
        let mut new_levels = self.levels.clone();
        for &g in &w.pending {
            let first = w.start_log2(g as usize) + 1;
            let l = &mut new_levels[g as usize];
            *l = if *l == 0 { first } else { *l + 1 };
        }
        let mut offsets = vec![0u32; slots];
        let mut total = 0usize;
        for g in 0..slots {
            offsets[g] = total as u32;
            if new_levels[g] > 0 {
                total += grid_size(order_of_level(new_levels[g]));
            }
        }
        // Move the old samples to their places in the doubled grids.
        let mut raw = vec![Vec3::ZERO; total];
        let mut samples = vec![0u32; total];
        let mut std_error = vec![Vec3::ZERO; total];
        let mut burial = vec![Burial::Valid; total];
        let mut line_of = vec![NO_INDEX; total];
        for g in 0..slots {
            let (old, new) = (
                order_of_level(self.levels[g]),
                order_of_level(new_levels[g]),
            );
            if old == 0 {
                continue;
            }
            let (from, to) = (self.offsets[g] as usize, offsets[g] as usize);
            if old == new {
                let s = grid_size(old);
                raw[to..to + s].copy_from_slice(&w.raw[from..from + s]);
                samples[to..to + s].copy_from_slice(&w.samples[from..from + s]);
                std_error[to..to + s].copy_from_slice(&w.std_error[from..from + s]);
                burial[to..to + s].copy_from_slice(&w.burial[from..from + s]);
                line_of[to..to + s].copy_from_slice(&w.line_of[from..from + s]);
            } else {
                for d in 0..=old {
                    for j in 0..=d {
                        let i = d - j;
                        let (a, b) = (from + grid_index(i, j), to + grid_index(2 * i, 2 * j));
                        raw[b] = w.raw[a];
                        samples[b] = w.samples[a];
                        std_error[b] = w.std_error[a];
                        line_of[b] = w.line_of[a];
                        burial[b] = if w.burial[a] == Burial::Valid {
                            Burial::Valid
                        } else {
                            Burial::Buried
                        };
                    }
                }
            }
        }
        // Store the new estimates, in the order next_round asked for them.
        let threshold = self.settings.buried_threshold;
        let mut next = 0usize;
        for &g in &w.pending {
            let n = order_of_level(new_levels[g as usize]);
            let coarse = order_of_level(self.levels[g as usize]);
            let base = offsets[g as usize] as usize;
            for_each_new_sample(coarse, n, |_, _, m| {
                let e = &estimates[w.sources[next] as usize];
                line_of[base + m] = w.round_lines[next];
                next += 1;
                raw[base + m] = e.value;
                samples[base + m] = e.samples;
                std_error[base + m] = e.std_error;
                burial[base + m] = if e.back_face_share > threshold {
                    Burial::Buried
                } else {
                    Burial::Valid
                };
            });
        }
        for &(line, point) in &w.round_feet {
            let e = &estimates[point as usize];
            w.feet[line as usize] = crossings::foot_value(e);
        }
        estimates.iter().for_each(|e| self.totals.add(e));
        self.levels = new_levels;
        self.offsets = offsets;
        w.raw = raw;
        w.samples = samples;
        w.std_error = std_error;
        w.burial = burial;
        w.line_of = line_of;
        // Fill buried samples (every grid: cheap, and independent of history).
        w.filled = vec![Vec3::ZERO; total];
        w.filled_error = vec![Vec3::ZERO; total];
        for g in 0..slots {
            let n = order_of_level(self.levels[g]);
            if n > 0 {
                Self::fill_grid(&mut w, self.offsets[g] as usize, n);
            }
        }
        self.buried = w.burial.iter().filter(|&&b| b != Burial::Valid).count() as u64;
        // Decide which of the grids that just doubled double again.
        w.refine.iter_mut().for_each(|r| *r = false);
        let bound = self.settings.interpolation_error;
        for &g in &w.pending {
            let n = order_of_level(self.levels[g as usize]);
            if n < w.max_orders[g as usize / 2] {
                let base = self.offsets[g as usize] as usize;
                let burial = &w.burial[base..base + grid_size(n)];
                let mixed =
                    burial.contains(&Burial::Valid) && burial.iter().any(|&b| b != Burial::Valid);
                // A grid buried all over needs no detail, whatever crosses it.
                let shadow = w.shadow_edges.get(g as usize).copied().unwrap_or(false)
                    && burial.contains(&Burial::Valid);
                // An order-1 grid (a re-bake's prior) has no new samples to test: it
                // doubles.
                w.refine[g as usize] =
                    n == 1 || mixed || shadow || self.interpolation_error(&w, base, n) > bound;
            }
        }
        w.pending.clear();
        w.pending_points = 0;
        w.sources.clear();
        w.round_lines.clear();
        w.round_feet.clear();
        // Priors serve the first round only.
        w.priors = Vec::new();
        w.prior_offsets = Vec::new();
        // Pack: half floats with a scale for the largest value.
        let max = w
            .filled
            .iter()
            .chain(w.feet.iter().filter(|f| !f.is_nan()))
            .fold(0.0f32, |m, v| m.max(v.max_element()));
        self.scale = StoreScale::for_max(max);
        self.packed.clear();
        self.packed
            .extend(w.filled.iter().map(|&v| self.scale.pack(v)));
        self.sample_counts.clone_from(&w.samples);
        let scale = self.scale;
        self.feet = crossings::settle_feet(&mut self.lines, &w.feet, |f| scale.pack(f));
        self.crossed_grids.clear();
        self.sample_lines.clear();
        for g in (0..slots).filter(|&g| w.crossed[g] && self.levels[g] > 0) {
            let (base, n) = (self.offsets[g] as usize, order_of_level(self.levels[g]));
            self.crossed_grids
                .push([g as u32, self.sample_lines.len() as u32]);
            self.sample_lines
                .extend_from_slice(&w.line_of[base..base + grid_size(n)]);
        }
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
    /// samples asked for again with their values as priors (buried ones with the values
    /// filled in from their neighbours: the re-bake finds them buried again and refills
    /// them); grids of new triangles start afresh at order `min(2, n_max)`. Refinement then continues
    /// as in a full bake, so a grid the edit gave new detail (a shadow edge) doubles.
    fn remap(&self, _old: &TracedScene, new: &TracedScene, triangle_map: &[u32]) -> Self {
        let mut fresh = Self::new(new, self.settings);
        let slots = fresh.levels.len();
        let mut start_log2: Vec<u8> = (0..slots)
            .map(|g| fresh.working.as_ref().map_or(1, |w| w.start_log2(g)))
            .collect();
        let mut prior_offsets = vec![NO_INDEX; slots];
        let mut priors = Vec::new();
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
            let base = self.offsets[Self::slot(t_old, front)] as usize;
            priors.extend(
                self.packed[base..base + grid_size(n)]
                    .iter()
                    .map(|&p| self.scale.unpack(p)),
            );
        }
        if let Some(w) = fresh.working.as_mut() {
            w.start_log2 = start_log2;
            w.priors = priors;
            w.prior_offsets = prior_offsets;
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
