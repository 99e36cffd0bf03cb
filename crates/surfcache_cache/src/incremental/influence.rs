//! Where an edit's change can reach, traced forward from what changed (docs/design.md,
//! Incremental re-baking).
//!
//! In every stage of a re-bake, a point's change is an integral over the directions in
//! which it sees a *source*: the surfaces the edit moved, added or removed (the direct
//! stage), or the surfaces whose irradiance changed in the stage before (the indirect
//! stages). A bound from the sources' extent alone cannot know what hides them from a
//! point, and in a level most points that face an edited prop do not see it. So the
//! sources are traced forward instead. N rays leave them, cosine-distributed about the
//! side they leave, and each hit x carries a weight w. By reciprocity, the hits per unit
//! area at x are N/(πA) times the projected solid angle of the source seen from x (A its
//! area, both sides). So the weights of the hits within a radius R of a point, summed and
//! divided by πR², estimate
//!
//! `Q(x) = |∫ ΔL(ω) cos θ dω|`
//!
//! over the directions in which x sees a source, per channel ([`Influence::reaches`]).
//! The weights are signed: a prop moved by a metre darkens one patch of floor and
//! lights the one next to it, and far away the two nearly cancel, as they do in the
//! change itself.
//!
//! - **Direct stage** ([`Influence::of_edit`]). Source points s are drawn uniformly by area
//!   over both sides of the changed triangles: before the edit in the old scene, after
//!   it in the edited one. Rays leave in cosine directions. At each hit x, the stage's own
//!   integrand is evaluated along the reversed ray in both scenes:
//!   `ΔL = L_new − L_old`, with `L = L_e + ρ/π · E_old` at the first hit. Then
//!   `w = πA·|ΔL| / N`. Where s is a prop that moved away, the new scene's ray passes
//!   through and finds what the prop hid.
//! - **Bright lights** are not found by cosine directions: the sun of a sky map (pixels
//!   above [`BRIGHT_FACTOR`] × the map's mean) and punctual lights. Their shadows are
//!   traced from the sources away from the light, and every point within R of such a
//!   hit is re-estimated outright.
//! - **Indirect stages** ([`Influence::of_changes`]). The sources are [`ChangePatch`]es:
//!   every texel of a lightmap whose irradiance the stage before changed (at its sample
//!   point, with the area it stands for), or for the other caches both sides of every
//!   triangle with the largest change on it. A patch p is drawn in proportion to
//!   `ΔL_p · A_p`, with `ΔL_p = ρ_p/π · ΔE_p`. A hit then carries
//!   `w = πΦ/N · ΔL(s)/ΔL_p`, where `Φ = Σ ΔL_p · A_p` over the patches' sides and ΔL(s)
//!   is the signed change where the ray left. Texels make the weights nearly constant:
//!   rays go where the change is, not where the largest change of a large triangle is.
//!   Buried texels are no sources (their values are filled in from neighbours; no
//!   surface sees their light).
//!
//! A point is re-estimated when `Q + 2σ_Q` exceeds its allowance (σ_Q from the sum of
//! w²), when a shadow hit lies within R, or when it lies on a changed triangle itself.
//!
//! What is approximated: Q is estimated, not bounded. A point whose change is above
//! its allowance is still missed when none of the N rays lands within R of it. The
//! number of rays is chosen so that this takes a view of the source far smaller than the
//! allowance allows: [`RAYS_PER_DISC`] rays per disc of radius R on the sources.

use crate::stored_rgb::difference_beyond;
use glam::{IVec3, Vec2, Vec3};
use rayon::prelude::*;
use rustc_hash::FxHashMap;
use std::{
    f32::consts::PI,
    ops::Range,
    sync::atomic::{AtomicU64, Ordering::Relaxed},
};
use surfcache_core::Light;
use surfcache_core::{
    color::luminance,
    geometry::{to_world, triangle_area},
    sampling::{Distribution1D, Rng, cosine_hemisphere, splitmix64, uniform_triangle},
};
use surfcache_trace::{IrradianceLookup, PathOptions, SurfacePoint, TracedScene};

/// Forward rays per disc of radius R of source area (module docs).
pub const RAYS_PER_DISC: f32 = 2048.0;

/// Fewest and most forward rays of a stage, the most also at most [`RAYS_PER_TRIANGLE`]
/// per triangle of the scene. R starts at the cache's sample spacing and grows where the
/// sources are too large for [`RAYS_PER_DISC`] within the most.
pub const MIN_RAYS: u32 = 1 << 16;
pub const MAX_RAYS: u32 = 1 << 21;
pub const RAYS_PER_TRIANGLE: u32 = 8;

/// Sky-map pixels brighter than this many times the map's mean luminance count as a
/// bright light whose shadows are traced (module docs).
pub const BRIGHT_FACTOR: f32 = 16.0;

/// Hits a grid cell keeps of each kind, finite and infinite ([`Influence`]'s binning).
pub const HITS_PER_CELL: usize = 64;

/// Shadow rays per bright light, as a share of the forward rays.
const SHADOW_SHARE: f32 = 0.25;

/// Points whose changes a stage of a re-bake must estimate (module docs).
pub struct Influence {
    radius: f32,
    /// Hits sorted by grid cell (cell size R); each cell's range of them.
    cells: FxHashMap<IVec3, Range<u32>>,
    /// The cells within one cell of a cell with hits: most points of a level have no
    /// hit within R, and one test tells them so ([`Self::change_at`]).
    near_hits: CellFilter,
    position: Vec<Vec3>,
    normal: Vec<Vec3>,
    /// `w` of each hit, per channel and signed; infinite for a bright light's shadow.
    weight: Vec<Vec3>,
    /// Per triangle of the edited scene: a changed triangle, always re-estimated.
    changed: Vec<bool>,
    rays: u64,
    /// Source triangles and their flux Σ |ΔL| · A (both sides).
    sources: (usize, f32),
    /// Why points were reached: on a changed triangle, near a shadow hit, by Q alone, by
    /// Q + 2σ only; and points kept. Counted only for `SURFCACHE_TRACE_PASSES`.
    tally: Option<[AtomicU64; 5]>,
}

/// One forward hit: where, the normal of the side it arrived at, its weight.
#[derive(Clone, Copy)]
struct ForwardHit {
    position: Vec3,
    normal: Vec3,
    weight: Vec3,
}

impl ForwardHit {
    fn certain(&self) -> bool {
        self.weight.x == f32::INFINITY
    }
}

/// Which sides of a triangle a [`ChangePatch`] stands for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    Front,
    Back,
    Both,
}

impl Side {
    fn count(self) -> f32 {
        match self {
            Self::Both => 2.0,
            _ => 1.0,
        }
    }
}

/// A part of a surface whose irradiance changed, as a source of forward rays: a texel
/// (at its sample point `uv`) or a whole triangle (`uv` `None`: drawn uniformly over it),
/// the world area it stands for on each of its sides, and the largest change of its
/// irradiance in any channel (W/m²; infinite where it is unknown).
#[derive(Clone, Copy, Debug)]
pub struct ChangePatch {
    pub triangle: u32,
    pub side: Side,
    pub uv: Option<Vec2>,
    pub area: f32,
    pub change: f32,
}

impl ChangePatch {
    /// One side of `triangle` at `uv`, standing for `area`, whose irradiance went from
    /// `old` to `after`: its whole change once that is beyond `share`
    /// ([`difference_beyond`]; infinite where either value is unknown), else `None`.
    pub fn of_sample(
        triangle: u32,
        front: bool,
        uv: Vec2,
        area: f32,
        after: Vec3,
        old: Vec3,
        share: f32,
    ) -> Option<Self> {
        let change = if !(after - old).is_finite() {
            f32::INFINITY
        } else if difference_beyond(after, old, share).max_element() > 0.0 {
            (after - old).abs().max_element()
        } else {
            0.0
        };
        (change > 0.0).then_some(Self {
            triangle,
            side: if front { Side::Front } else { Side::Back },
            uv: Some(uv),
            area,
            change,
        })
    }

    /// Both sides of triangle `t` of `scene`, drawn uniformly over it.
    pub fn whole_triangle(scene: &TracedScene, t: u32, change: f32) -> Self {
        let [a, b, c] = scene.positions()[t as usize];
        Self {
            triangle: t,
            side: Side::Both,
            uv: None,
            area: triangle_area(a, b, c),
            change,
        }
    }
}

/// Source patches of a scene, drawn by weight × area.
struct Sources<'a> {
    scene: &'a TracedScene,
    patches: Vec<ChangePatch>,
    /// Each patch's weight per unit area (the bound of its |ΔL|, or 1).
    weights: Vec<f32>,
    choice: Distribution1D,
    /// Σ weight × area over the patches' sides.
    total: f32,
    /// Σ area over the patches' sides.
    area: f32,
}

impl<'a> Sources<'a> {
    /// The patches whose `weight` is positive.
    fn new(
        scene: &'a TracedScene,
        patches: impl IntoIterator<Item = ChangePatch>,
        weight: impl Fn(&ChangePatch) -> f32,
    ) -> Self {
        let (patches, weights): (Vec<ChangePatch>, Vec<f32>) = patches
            .into_iter()
            .map(|p| {
                let w = weight(&p);
                (p, w)
            })
            .filter(|&(_, w)| w > 0.0)
            .unzip();
        let sides: Vec<f32> = patches.iter().map(|p| p.area * p.side.count()).collect();
        let weighted: Vec<f32> = sides.iter().zip(&weights).map(|(a, w)| a * w).collect();
        Self {
            scene,
            choice: Distribution1D::new(&weighted),
            total: weighted.iter().sum(),
            area: sides.iter().sum(),
            patches,
            weights,
        }
    }

    /// Both sides of each of `triangles`, weight 1.
    fn triangles(scene: &'a TracedScene, triangles: &[u32]) -> Self {
        let patches = triangles
            .iter()
            .map(|&t| ChangePatch::whole_triangle(scene, t, 1.0));
        Self::new(scene, patches, |_| 1.0)
    }

    fn is_empty(&self) -> bool {
        self.patches.is_empty() || self.total.is_nan() || self.total <= 0.0
    }

    /// A point on a side of a patch drawn by weight × area, and the patch's index.
    fn sample(&self, rng: &mut Rng) -> (SurfacePoint, usize) {
        let (k, _, _) = self.choice.sample(rng.next_f32());
        let p = &self.patches[k];
        let front = match p.side {
            Side::Front => true,
            Side::Back => false,
            Side::Both => rng.next_f32() < 0.5,
        };
        let uv = p.uv.unwrap_or_else(|| uniform_triangle(rng.next_vec2()));
        (self.scene.surface_point(p.triangle, uv, front), k)
    }

    /// This set's share of a stage's `rays` over sources of total area `area`.
    fn share(&self, rays: u32, area: f32) -> u32 {
        if self.is_empty() {
            0
        } else {
            ((rays as f64 * (self.area / area) as f64).ceil() as u32).max(1)
        }
    }

    /// A cosine-distributed ray leaving the source point `p` on its side: origin,
    /// direction.
    fn leave(&self, p: &SurfacePoint, rng: &mut Rng) -> (Vec3, Vec3) {
        let d = to_world(cosine_hemisphere(rng.next_vec2()), p.geometric_normal);
        (self.scene.spawn_origin(p), d)
    }
}

/// A stage's forward rays and radius R for sources of total `area` (both sides):
/// [`RAYS_PER_DISC`] per disc of radius R, R at least `spacing`, the rays within
/// [`MIN_RAYS`]..=[`MAX_RAYS`] and [`RAYS_PER_TRIANGLE`] per triangle of the scene.
fn rays_and_radius(area: f32, spacing: f32, triangles: usize) -> (u32, f32) {
    let most = (RAYS_PER_TRIANGLE as usize * triangles).clamp(MIN_RAYS as usize, MAX_RAYS as usize);
    let discs = area / (PI * spacing * spacing);
    let rays = (discs * RAYS_PER_DISC).clamp(MIN_RAYS as f32, most as f32);
    let radius = (RAYS_PER_DISC * area / (PI * rays)).sqrt().max(spacing);
    (rays as u32, radius)
}

/// Where the ray (`origin`, `direction`) first meets a surface of `scene`: the point on
/// the side it arrived at.
fn first_hit(scene: &TracedScene, origin: Vec3, direction: Vec3) -> Option<SurfacePoint> {
    let hit = scene.closest_hit(origin, direction, f32::INFINITY)?;
    Some(scene.hit_point(&hit, direction))
}

impl Influence {
    /// The direct stage's influence of an edit (module docs): the triangles `changed_old`
    /// of `old` and `changed_new` of `new` traced forward, the change at each hit
    /// evaluated with the old cache (`old_lookup` on `old`, `new_lookup` on `new`), and
    /// the shadows of bright lights.
    #[allow(clippy::too_many_arguments)]
    pub fn of_edit(
        old: &TracedScene,
        new: &TracedScene,
        old_lookup: &dyn IrradianceLookup,
        new_lookup: &dyn IrradianceLookup,
        changed_old: &[u32],
        changed_new: &[u32],
        spacing: f32,
        seed: u64,
    ) -> Self {
        let mut hits = Vec::new();
        let mut rays = 0u64;
        let options = PathOptions {
            max_bounces: None,
            next_event: false,
        };
        let sets = [
            Sources::triangles(old, changed_old),
            Sources::triangles(new, changed_new),
        ];
        let area: f32 = sets.iter().map(|s| s.area).sum();
        let (total_rays, radius) = rays_and_radius(area, spacing, new.triangle_count());
        for (k, sources) in sets.iter().enumerate() {
            let scene = sources.scene;
            let n = sources.share(total_rays, area);
            if n == 0 {
                continue;
            }
            let weight = PI * sources.area / n as f32;
            let stream = splitmix64(seed ^ 0x696e_666c_7565_6e63 ^ k as u64);
            let found: Vec<(Option<ForwardHit>, u64)> = (0..n)
                .into_par_iter()
                .map(|i| {
                    let mut rng = Rng::new(stream, i as u64);
                    let (s, _) = sources.sample(&mut rng);
                    let (o, d) = sources.leave(&s, &mut rng);
                    let Some(x) = first_hit(scene, o, d) else {
                        return (None, 1);
                    };
                    // The stage's integrand along the reversed ray, in both scenes, with
                    // the same random numbers.
                    let from = scene.spawn_origin(&x);
                    let mut twin = rng.clone();
                    let l_new =
                        new.incident_radiance(from, -d, None, &mut rng, options, Some(new_lookup));
                    let l_old =
                        old.incident_radiance(from, -d, None, &mut twin, options, Some(old_lookup));
                    let change = l_new.radiance - l_old.radiance;
                    let hit = ForwardHit {
                        position: x.position,
                        normal: x.geometric_normal,
                        weight: weight * change,
                    };
                    let traced = 1 + l_new.rays as u64 + l_old.rays as u64;
                    ((change != Vec3::ZERO).then_some(hit), traced)
                })
                .collect();
            for (hit, traced) in found {
                rays += traced;
                hits.extend(hit);
            }
            let shadows = shadow_hits(sources, (n as f32 * SHADOW_SHARE) as u32, stream);
            rays += shadows.1;
            hits.extend(shadows.0);
        }
        let mut changed = vec![false; new.triangle_count()];
        for &t in changed_new {
            changed[t as usize] = true;
        }
        let sources = sets
            .iter()
            .map(|s| (s.patches.len(), s.total))
            .fold((0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
        Self::from_hits(hits, radius, changed, rays, sources)
    }

    /// An indirect stage's influence (module docs): the patches of `scene` whose
    /// irradiance changed ([`super::change_patches`]) traced forward, each ray weighted
    /// by the signed change `after − before` at the point it leaves. Patches with
    /// `ρ·ΔE ≤ negligible` are left out: seen over a whole hemisphere, all of them
    /// together change a point's E by at most that much.
    #[allow(clippy::too_many_arguments)]
    pub fn of_changes(
        scene: &TracedScene,
        after: &dyn IrradianceLookup,
        before: &dyn IrradianceLookup,
        changes: &[ChangePatch],
        negligible: f32,
        spacing: f32,
        seed: u64,
    ) -> Self {
        // The bound of |ΔL| = ρ/π · |ΔE| on a patch.
        let radiance = |p: &ChangePatch| {
            let albedo = scene.material_of(p.triangle).albedo.max_element().max(0.0);
            albedo / PI * p.change
        };
        let matters: Vec<ChangePatch> = changes
            .iter()
            .filter(|p| {
                let most = PI * radiance(p);
                most.is_nan() || most > negligible
            })
            .copied()
            .collect();
        // A change that is not a number (an unbaked side) may be anything: whatever its
        // patches see is re-estimated.
        let known = |p: &ChangePatch| {
            let l = radiance(p);
            if l.is_finite() { l } else { 0.0 }
        };
        let unknown = |p: &ChangePatch| {
            if radiance(p).is_finite() { 0.0 } else { 1.0 }
        };
        let sets = [
            (Sources::new(scene, matters.iter().copied(), known), false),
            (Sources::new(scene, matters.iter().copied(), unknown), true),
        ];
        let stream = splitmix64(seed ^ 0x696e_6469_7265_6374);
        let mut hits = Vec::new();
        let mut rays = 0;
        let area: f32 = sets.iter().map(|(s, _)| s.area).sum();
        let source_stats = (
            sets.iter().map(|(s, _)| s.patches.len()).sum(),
            sets[0].0.total,
        );
        let (total_rays, radius) = rays_and_radius(area, spacing, scene.triangle_count());
        for (sources, certain) in sets {
            let n = sources.share(total_rays, area);
            if n == 0 {
                continue;
            }
            let scale = PI * sources.total / n as f32;
            let found: Vec<Option<ForwardHit>> = (0..n)
                .into_par_iter()
                .map(|i| {
                    let mut rng = Rng::new(stream ^ certain as u64, i as u64);
                    forward_ray(scene, after, before, &sources, certain, scale, &mut rng)
                })
                .collect();
            rays += n as u64;
            hits.extend(found.into_iter().flatten());
        }
        Self::from_hits(hits, radius, Vec::new(), rays, source_stats)
    }

    /// Hits binned by grid cell of size R; a cell with more than [`HITS_PER_CELL`] finite
    /// (or infinite) hits keeps an even subset of them, the finite ones' weights scaled so
    /// that their sum stays the same in expectation: queries then cost a bounded amount,
    /// however many rays a small scene concentrates.
    fn from_hits(
        mut hits: Vec<ForwardHit>,
        radius: f32,
        changed: Vec<bool>,
        rays: u64,
        sources: (usize, f32),
    ) -> Self {
        let cell = |p: Vec3| (p / radius).floor().as_ivec3();
        hits.sort_by_key(|h| {
            let c = cell(h.position);
            (c.x, c.y, c.z, h.certain())
        });
        let mut kept: Vec<ForwardHit> = Vec::with_capacity(hits.len());
        let mut cells = FxHashMap::default();
        let mut start = 0;
        for i in 1..=hits.len() {
            let group_ends = i == hits.len()
                || cell(hits[i].position) != cell(hits[start].position)
                || hits[i].certain() != hits[start].certain();
            if !group_ends {
                continue;
            }
            let group = &hits[start..i];
            let stride = group.len().div_ceil(HITS_PER_CELL);
            let chosen = group.len().div_ceil(stride);
            let scale = group.len() as f32 / chosen as f32;
            let first = kept.len() as u32;
            kept.extend(group.iter().step_by(stride).map(|h| ForwardHit {
                weight: h.weight * scale,
                ..*h
            }));
            let range = cells
                .entry(cell(hits[start].position))
                .or_insert(first..first);
            range.end = kept.len() as u32;
            start = i;
        }
        let mut near_hits = CellFilter::with_capacity(27 * cells.len());
        for c in cells.keys() {
            for dz in -1..=1 {
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        near_hits.insert(*c + IVec3::new(dx, dy, dz));
                    }
                }
            }
        }
        Self {
            radius,
            cells,
            near_hits,
            position: kept.iter().map(|h| h.position).collect(),
            normal: kept.iter().map(|h| h.normal).collect(),
            weight: kept.iter().map(|h| h.weight).collect(),
            changed,
            rays,
            sources,
            tally: std::env::var_os(crate::bake::TRACE_PASSES_VAR).map(|_| Default::default()),
        }
    }

    /// What the influence found and decided so far, for `SURFCACHE_TRACE_PASSES`.
    pub fn report(&self) -> String {
        let t: Vec<u64> = match &self.tally {
            Some(tally) => tally.iter().map(|c| c.load(Relaxed)).collect(),
            None => vec![0; 5],
        };
        format!(
            "sources {} flux {:.4} rays {} radius {:.3} hits {} | reached: changed {} shadow {} q {} sigma {} | kept {}",
            self.sources.0,
            self.sources.1,
            self.rays,
            self.radius,
            self.position.len(),
            t[0],
            t[1],
            t[2],
            t[3],
            t[4]
        )
    }

    /// Rays traced to find the influence.
    pub fn rays(&self) -> u64 {
        self.rays
    }

    /// Whether the change at point `x` (unit normal `n`) of `triangle` of the edited
    /// scene may exceed `allowance` (W/m²): on a changed triangle, or where
    /// `Q + 2σ_Q > allowance` ([`Self::change_at`]).
    pub fn reaches(&self, triangle: u32, x: Vec3, n: Vec3, allowance: f32) -> bool {
        let count = |k: usize| {
            if let Some(tally) = &self.tally {
                tally[k].fetch_add(1, Relaxed);
            }
        };
        if self.changed.get(triangle as usize) == Some(&true) {
            count(0);
            return true;
        }
        let (q, sigma) = self.change_at(x, n);
        count(if q == f32::INFINITY {
            1
        } else if q > allowance {
            2
        } else if q + 2.0 * sigma > allowance {
            3
        } else {
            4
        });
        q + 2.0 * sigma > allowance
    }

    /// The estimate `Q(x) = |∫ ΔL cos θ dω|` at point `x` with unit normal `n` and its
    /// standard error, in the channel where `Q + 2σ` is largest: the signed weights of the
    /// hits within R on a side facing the same way (normals within 60°), summed over πR²
    /// (module docs); infinite within R of a bright light's shadow hit.
    pub fn change_at(&self, x: Vec3, n: Vec3) -> (f32, f32) {
        let r2 = self.radius * self.radius;
        let centre = (x / self.radius).floor().as_ivec3();
        if !self.near_hits.may_contain(centre) {
            return (0.0, 0.0);
        }
        let (mut sum, mut squares) = (Vec3::ZERO, Vec3::ZERO);
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let Some(range) = self.cells.get(&(centre + IVec3::new(dx, dy, dz))) else {
                        continue;
                    };
                    for i in range.start as usize..range.end as usize {
                        if self.position[i].distance_squared(x) > r2 || self.normal[i].dot(n) < 0.5
                        {
                            continue;
                        }
                        let w = self.weight[i];
                        if w.x == f32::INFINITY {
                            return (f32::INFINITY, 0.0);
                        }
                        sum += w;
                        squares += w * w;
                    }
                }
            }
        }
        let disc = PI * r2;
        let (q, sigma) = (sum.abs() / disc, squares.map(f32::sqrt) / disc);
        let reach = q + 2.0 * sigma;
        let c = if reach.x >= reach.y && reach.x >= reach.z {
            0
        } else if reach.y >= reach.z {
            1
        } else {
            2
        };
        (q[c], sigma[c])
    }
}

/// A set of grid cells that may answer "yes" for a cell it does not hold, never "no" for
/// one it does (a Bloom filter with one hash): a bit per hashed cell, about eight bits
/// per cell inserted.
struct CellFilter {
    bits: Vec<u64>,
    mask: u64,
}

impl CellFilter {
    fn with_capacity(cells: usize) -> Self {
        let bits = (8 * cells).next_power_of_two().max(64);
        Self {
            bits: vec![0; bits / 64],
            mask: bits as u64 - 1,
        }
    }

    fn bit(&self, cell: IVec3) -> u64 {
        let key =
            cell.x as u32 as u64 ^ (cell.y as u32 as u64) << 21 ^ (cell.z as u32 as u64) << 42;
        splitmix64(key) & self.mask
    }

    fn insert(&mut self, cell: IVec3) {
        let b = self.bit(cell);
        self.bits[(b / 64) as usize] |= 1 << (b % 64);
    }

    fn may_contain(&self, cell: IVec3) -> bool {
        let b = self.bit(cell);
        self.bits[(b / 64) as usize] & (1 << (b % 64)) != 0
    }
}

/// The direction towards a bright light from a source point, or `None` (a sky sample too
/// dim to count).
type TowardsLight<'a> = Box<dyn Fn(Vec3, &mut Rng) -> Option<Vec3> + Sync + 'a>;

/// The shadows of bright lights cast by `sources` (module docs): `n` rays per light
/// from source points away from the light; every hit is marked with an infinite weight.
fn shadow_hits(sources: &Sources, n: u32, stream: u64) -> (Vec<ForwardHit>, u64) {
    let scene = sources.scene;
    let mut lights: Vec<TowardsLight> = Vec::new();
    if let Some(map) = &scene.environment().map
        && let Some(sampler) = scene.light_sampler().environment()
    {
        let cut = BRIGHT_FACTOR * sampler.mean_luminance();
        if map.texels.iter().any(|&t| luminance(t) > cut) {
            lights.push(Box::new(move |_, rng| {
                let (w, _) = sampler.sample(rng.next_vec2());
                (luminance(map.radiance(w)) > cut).then_some(w)
            }));
        }
    }
    for light in scene.lights() {
        match *light {
            Light::Directional { direction, .. } => {
                lights.push(Box::new(move |_, _| Some(-direction.normalize())))
            }
            Light::Point { position, .. } | Light::Spot { position, .. } => {
                lights.push(Box::new(move |s, _| (position - s).try_normalize()))
            }
        }
    }
    let mut hits = Vec::new();
    let mut rays = 0u64;
    for (k, towards) in lights.iter().enumerate() {
        let found: Vec<Option<ForwardHit>> = (0..n)
            .into_par_iter()
            .map(|i| {
                let mut rng = Rng::new(stream ^ splitmix64(0x5ad0 + k as u64), i as u64);
                let (s, _) = sources.sample(&mut rng);
                let w = towards(s.position, &mut rng)?;
                // Leave from the side that faces away from the light.
                let front = scene.geometric_normals()[s.triangle as usize].dot(w) < 0.0;
                let away = scene.surface_point(s.triangle, s.uv, front);
                let x = first_hit(scene, scene.spawn_origin(&away), -w)?;
                Some(ForwardHit {
                    position: x.position,
                    normal: x.geometric_normal,
                    weight: Vec3::INFINITY,
                })
            })
            .collect();
        rays += n as u64;
        hits.extend(found.into_iter().flatten());
    }
    (hits, rays)
}

/// One forward ray of [`Influence::of_changes`] from `sources`: its first hit, carrying
/// `scale` · ΔL(s) / w_k of the point s it left (ΔL = ρ/π · ΔE between `after` and
/// `before`, w_k the bound its patch was drawn by), or an infinite weight from sources
/// whose change is unknown (`certain`). `None` where it carries nothing or meets nothing.
fn forward_ray(
    scene: &TracedScene,
    after: &dyn IrradianceLookup,
    before: &dyn IrradianceLookup,
    sources: &Sources,
    certain: bool,
    scale: f32,
    rng: &mut Rng,
) -> Option<ForwardHit> {
    let (s, k) = sources.sample(rng);
    let (o, d) = sources.leave(&s, rng);
    let weight = if certain {
        Vec3::INFINITY
    } else {
        let front = s.geometric_normal == scene.geometric_normals()[s.triangle as usize];
        let change = after.irradiance(s.triangle, s.uv, front)?
            - before.irradiance(s.triangle, s.uv, front)?;
        let albedo = scene
            .material_of(s.triangle)
            .albedo_at(scene.uv0_at(s.triangle, s.uv));
        scale * (albedo / PI * change) / sources.weights[k]
    };
    if weight == Vec3::ZERO || weight.is_nan() {
        return None;
    }
    first_hit(scene, o, d).map(|x| ForwardHit {
        position: x.position,
        normal: x.geometric_normal,
        weight,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The filter never says "no" for a cell it holds (whatever the coordinates' signs
    /// and sizes), and says "no" for most cells it does not.
    #[test]
    fn cell_filter_holds_every_cell_inserted() {
        let mut rng = Rng::new(7, 0);
        let mut cell = || {
            let u = rng.next_vec2().extend(rng.next_f32());
            ((u - 0.5) * 2.0e5).floor().as_ivec3()
        };
        let inserted: Vec<IVec3> = (0..5_000).map(|_| cell()).collect();
        let mut filter = CellFilter::with_capacity(inserted.len());
        for &c in &inserted {
            filter.insert(c);
        }
        assert!(inserted.iter().all(|&c| filter.may_contain(c)));
        let others = (0..10_000).filter(|_| filter.may_contain(cell())).count();
        assert!(others < 2_000, "{others} of 10,000 other cells pass");
    }
}
