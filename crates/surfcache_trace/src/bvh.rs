//! The ray-tracing acceleration structure: an obvhs-built CWBVH over world triangles,
//! traversed by our own kernels ([`traversal`](self) module: 8 children and 8 triangles
//! per step, SIMD level chosen at run time, see [`SimdLevel`]).
//!
//! Triangles are stored in a *canonical space*, `q = (p − c) / D` with `c` the centre and
//! `D` the diagonal of the scene's bounding box, so that precision behaves the same at
//! every scene scale. Rays are mapped into that space with a unit direction; the traversal
//! honours the ray's `[tmin, tmax]` exactly (the node test included), so a ray that leaves
//! a surface right next to a corner still finds the adjacent wall a few nanometres away.
//! The triangle test widens barycentrics by [`EDGE_SLACK`] so that shared edges are
//! watertight. Hit distances are mapped back, so callers never see canonical space.
//!
//! The BVH2 the CWBVH is converted from is kept: it answers point queries (nearest surface)
//! and can be refit when instances move.

#[cfg(target_arch = "x86_64")]
mod avx2;
mod traversal;

pub use traversal::{EDGE_SLACK, SimdLevel};

use glam::{Vec2, Vec3, Vec3A};
use obvhs::{
    BvhBuildParams,
    aabb::Aabb,
    bvh2::{Bvh2, reinsertion::ReinsertionOptimizer},
    cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh,
    ploc::PlocBuilder,
    splits::split_aabbs_preset,
    triangle::Triangle,
};
use std::time::Instant;
use traversal::{LANES, Scalar, TraversalRay, Tree, Visit, lane_barycentrics, traverse};

/// The closest intersection along a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter in units of the query direction's length.
    pub t: f32,
    /// Triangle index (in the order the triangles were given to [`Bvh::build`]).
    pub triangle: u32,
    /// Barycentrics (u, v): the hit is (1−u−v)A + uB + vC.
    pub uv: Vec2,
}

/// obvhs CWBVH laid out for our traversal, plus the BVH2 it was built from, in canonical
/// space.
pub struct Bvh {
    centre: Vec3A,
    inv_scale: f32,
    scale: f32,
    tree: Tree,
    /// Per triangle block, the lanes whose candidates a filtered query's `accept` sees
    /// ([`Self::filter_only`]); empty: every lane.
    filtered_lanes: Vec<u8>,
    bvh2: Bvh2,
    level: SimdLevel,
    /// Seconds spent building (PLOC, reinsertion, conversion, triangle blocks).
    pub build_seconds: f64,
}

/// Mapping a world ray into canonical space: the traversal ray and the factor that turns
/// canonical `t` back into the caller's `t`.
struct CanonicalRay {
    ray: TraversalRay,
    t_to_world: f32,
}

/// Candidate filter of a traversal: `ANY` stops at the first accepted hit; `accept`
/// (alpha masks) sees the caller's triangle index and the hit's barycentrics, for the
/// lanes `filtered` marks (all when it is empty).
struct Filter<'a, const ANY: bool> {
    tree: &'a Tree,
    filtered: &'a [u8],
    accept: Option<&'a dyn Fn(u32, Vec2) -> bool>,
}

impl<const ANY: bool> Visit for Filter<'_, ANY> {
    const ANY: bool = ANY;

    #[inline(always)]
    fn accept(&mut self, slot: usize, _t: f32, ray: &TraversalRay) -> bool {
        match self.accept {
            None => true,
            Some(_) if !lane_is_filtered(self.filtered, slot) => true,
            Some(accept) => accept(
                self.tree.slot_index[slot],
                barycentrics(self.tree, slot, ray),
            ),
        }
    }
}

/// Whether `slot`'s candidates go through `accept` (see [`Filter`]).
#[inline(always)]
fn lane_is_filtered(filtered: &[u8], slot: usize) -> bool {
    filtered
        .get(slot / LANES)
        .is_none_or(|&lanes| lanes & (1 << (slot % LANES)) != 0)
}

/// Barycentrics (u, v) of the ray's hit on slot `slot`, clamped into the triangle.
#[inline]
fn barycentrics(tree: &Tree, slot: usize, ray: &TraversalRay) -> Vec2 {
    let (u, v) = lane_barycentrics(&tree.blocks[slot / LANES], slot % LANES, ray);
    let uv = Vec2::new(u, v).clamp(Vec2::ZERO, Vec2::ONE);
    let s = uv.x + uv.y;
    if s > 1.0 { uv / s } else { uv }
}

/// The traversal compiled for AVX2.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn traverse_avx2<V: Visit>(
    tree: &Tree,
    ray: &mut TraversalRay,
    visit: &mut V,
) -> Option<(usize, f32)> {
    unsafe { traverse::<avx2::Avx2, V>(tree, ray, visit) }
}

impl Bvh {
    /// Builds the BVH over world-space triangles with obvhs' `very_slow_build` preset
    /// (spatial pre-splits, full reinsertion): the preset that traces fastest.
    pub fn build(triangles: &[[Vec3; 3]]) -> Self {
        Self::build_with(triangles, BvhBuildParams::very_slow_build())
    }

    /// Builds with explicit obvhs parameters (for benchmarks of the presets).
    pub fn build_with(triangles: &[[Vec3; 3]], params: BvhBuildParams) -> Self {
        let start = Instant::now();
        let level = SimdLevel::detected();
        if triangles.is_empty() {
            return Self {
                centre: Vec3A::ZERO,
                inv_scale: 1.0,
                scale: 1.0,
                tree: Tree::default(),
                filtered_lanes: Vec::new(),
                bvh2: Bvh2::default(),
                level,
                build_seconds: 0.0,
            };
        }
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for t in triangles {
            for p in t {
                lo = lo.min(*p);
                hi = hi.max(*p);
            }
        }
        let (centre, scale) = (0.5 * (lo + hi), (hi - lo).length().max(f32::MIN_POSITIVE));
        let centre = Vec3A::from(centre);
        let inv_scale = 1.0 / scale;
        let tris: Vec<Triangle> = triangles
            .iter()
            .map(|t| {
                let [v0, v1, v2] = t.map(|p| (Vec3A::from(p) - centre) * inv_scale);
                Triangle { v0, v1, v2 }
            })
            .collect();

        let mut indices: Vec<u32> = (0..tris.len() as u32).collect();
        let mut bvh2 = if params.pre_split {
            let mut aabbs: Vec<Aabb> = tris.iter().map(|t| t.aabb()).collect();
            let largest = aabbs.iter().map(|a| a.half_area()).fold(0.0, f32::max);
            let average = aabbs.iter().map(|a| a.half_area()).sum::<f32>() / aabbs.len() as f32;
            split_aabbs_preset(&mut aabbs, &mut indices, &tris, average, largest);
            PlocBuilder::with_capacity(aabbs.len()).build(
                params.ploc_search_distance,
                &aabbs,
                indices,
                params.sort_precision,
                params.search_depth_threshold,
            )
        } else {
            PlocBuilder::with_capacity(tris.len()).build(
                params.ploc_search_distance,
                &tris,
                indices,
                params.sort_precision,
                params.search_depth_threshold,
            )
        };
        bvh2.uses_spatial_splits = params.pre_split;
        ReinsertionOptimizer::default().run(&mut bvh2, params.reinsertion_batch_ratio, None);
        let cwbvh = bvh2_to_cwbvh(&bvh2, params.max_prims_per_leaf.clamp(1, 3), true, false);
        let corners: Vec<[[f32; 3]; 3]> = tris
            .iter()
            .map(|t| [t.v0, t.v1, t.v2].map(|p| p.to_array()))
            .collect();
        let tree = Tree::new(cwbvh, &corners);
        Self {
            centre,
            inv_scale,
            scale,
            tree,
            filtered_lanes: Vec::new(),
            bvh2,
            level,
            build_seconds: start.elapsed().as_secs_f64(),
        }
    }

    /// Makes filtered queries ask their `accept` only about candidates on triangles for
    /// which `filtered(triangle)` holds (the alpha-masked ones) and take every other
    /// candidate as it is, without reading anything of the caller's per triangle: most
    /// candidates of a level lie on opaque triangles, and the test read their material.
    pub fn filter_only(&mut self, filtered: impl Fn(u32) -> bool) {
        self.filtered_lanes = self
            .tree
            .slot_index
            .chunks(LANES)
            .map(|lanes| {
                lanes.iter().enumerate().fold(0u8, |mask, (l, &t)| {
                    if t != traversal::PADDING && filtered(t) {
                        mask | (1 << l)
                    } else {
                        mask
                    }
                })
            })
            .collect();
    }

    /// Diagonal of the bounding box of all triangles, in world units.
    pub fn scene_diagonal(&self) -> f32 {
        self.scale
    }

    /// The instruction set the traversal runs with ([`SimdLevel::detected`] at build time).
    pub fn simd_level(&self) -> SimdLevel {
        self.level
    }

    /// Makes the traversal run with `level` (for tests and benchmarks: every level gives
    /// the same answers). Returns false, leaving the level unchanged, when this CPU cannot
    /// run it.
    #[doc(hidden)]
    pub fn set_simd_level(&mut self, level: SimdLevel) -> bool {
        let ok = level.is_supported();
        if ok {
            self.level = level;
        }
        ok
    }

    #[inline(always)]
    fn canonical(&self, origin: Vec3, direction: Vec3, tmin: f32, tmax: f32) -> CanonicalRay {
        let o = (Vec3A::from(origin) - self.centre) * self.inv_scale;
        // `+ 0.0` turns −0.0 components into +0.0, so that the slab planes follow the signs.
        let d = Vec3A::from(direction) * self.inv_scale;
        let len = d.length();
        // A unit direction in canonical space: t_world = t_canonical / len.
        let d = d * (1.0 / len) + Vec3A::ZERO;
        CanonicalRay {
            ray: TraversalRay::new(o.to_array(), d.to_array(), tmin * len, tmax * len),
            t_to_world: 1.0 / len,
        }
    }

    /// Runs the traversal with this BVH's SIMD level (no hit in an empty tree).
    #[inline(always)]
    fn run<V: Visit>(&self, ray: &mut TraversalRay, visit: &mut V) -> Option<(usize, f32)> {
        if self.tree.nodes.is_empty() {
            return None;
        }
        match self.level {
            // SAFETY: the level is only ever set to one the CPU supports; the tree has a root.
            #[cfg(target_arch = "x86_64")]
            SimdLevel::Avx2 => unsafe { traverse_avx2(&self.tree, ray, visit) },
            // SAFETY: the scalar kernels need no CPU features; the tree has a root.
            _ => unsafe { traverse::<Scalar, V>(&self.tree, ray, visit) },
        }
    }

    /// Closest hit of the ray `origin + t·direction`, `t ∈ [tmin, tmax]`, skipping hits that
    /// `accept(triangle, uv)` rejects (alpha masks).
    #[inline]
    pub fn closest_hit_filtered(
        &self,
        origin: Vec3,
        direction: Vec3,
        tmin: f32,
        tmax: f32,
        accept: Option<&dyn Fn(u32, Vec2) -> bool>,
    ) -> Option<Hit> {
        let mut c = self.canonical(origin, direction, tmin, tmax);
        let mut filter = Filter::<false> {
            tree: &self.tree,
            filtered: &self.filtered_lanes,
            accept,
        };
        let (slot, t) = self.run(&mut c.ray, &mut filter)?;
        Some(Hit {
            t: t * c.t_to_world,
            triangle: self.tree.slot_index[slot],
            uv: barycentrics(&self.tree, slot, &c.ray),
        })
    }

    /// Closest hit without alpha masks.
    #[inline]
    pub fn closest_hit(&self, origin: Vec3, direction: Vec3, tmin: f32, tmax: f32) -> Option<Hit> {
        self.closest_hit_filtered(origin, direction, tmin, tmax, None)
    }

    /// Whether anything lies on the ray within `[tmin, tmax]` (stops at the first hit).
    #[inline]
    pub fn occluded_filtered(
        &self,
        origin: Vec3,
        direction: Vec3,
        tmin: f32,
        tmax: f32,
        accept: Option<&dyn Fn(u32, Vec2) -> bool>,
    ) -> bool {
        let mut c = self.canonical(origin, direction, tmin, tmax);
        let mut filter = Filter::<true> {
            tree: &self.tree,
            filtered: &self.filtered_lanes,
            accept,
        };
        self.run(&mut c.ray, &mut filter).is_some()
    }

    /// Any-hit query without alpha masks.
    #[inline]
    pub fn occluded(&self, origin: Vec3, direction: Vec3, tmin: f32, tmax: f32) -> bool {
        self.occluded_filtered(origin, direction, tmin, tmax, None)
    }

    /// Calls `visit(triangle)` for every triangle whose bounding box overlaps the world-space
    /// box `[centre − r, centre + r]` (a triangle may be visited more than once).
    pub fn triangles_near(&self, centre: Vec3, radius: f32, mut visit: impl FnMut(u32)) {
        let c = (Vec3A::from(centre) - self.centre) * self.inv_scale;
        let r = Vec3A::splat(radius * self.inv_scale);
        let query = Aabb::new(c - r, c + r);
        self.bvh2.aabb_traverse(query, |bvh, node| {
            let node = &bvh.nodes[node as usize];
            for k in 0..node.prim_count {
                visit(bvh.primitive_indices[(node.first_index + k) as usize]);
            }
            true
        });
    }
}
