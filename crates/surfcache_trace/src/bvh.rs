//! The ray-tracing acceleration structure: an obvhs CWBVH over world triangles.
//!
//! Triangles are stored in a *canonical space*, `q = (p − c) / D` with `c` the centre and
//! `D` the diagonal of the scene's bounding box, so that precision and obvhs' fixed node
//! epsilon (a hit must lie at `t ≥ 1e-4` along the traversal direction) behave the same at
//! every scene scale. Rays are mapped into that space with a direction of fixed length
//! [`TRAVERSAL_DIRECTION_LENGTH`] = 2⁻¹⁶, which puts the node epsilon at ~1.5e-9 D, below
//! float precision: a ray that leaves a surface right next to a corner still finds the
//! adjacent wall a few nanometres away. Hit distances are mapped back, so callers never
//! see canonical space.
//!
//! The BVH2 the CWBVH is converted from is kept: it answers point queries (nearest surface)
//! and can be refit when instances move.

use glam::{Vec2, Vec3, Vec3A};
use obvhs::{
    BvhBuildParams,
    aabb::Aabb,
    bvh2::{Bvh2, reinsertion::ReinsertionOptimizer},
    cwbvh::{CwBvh, bvh2_to_cwbvh::bvh2_to_cwbvh},
    ploc::PlocBuilder,
    ray::{Ray, RayHit},
    rt_triangle::RtTriangle,
    splits::split_aabbs_preset,
    triangle::Triangle,
};
use std::time::Instant;

/// Length of traversal directions in canonical space (see the module doc).
pub const TRAVERSAL_DIRECTION_LENGTH: f32 = 1.0 / 65536.0;

/// Barycentric slack of the triangle test: edges shared by two triangles overlap by this
/// much instead of leaving float-precision cracks that rays slip through.
const EDGE_SLACK: f32 = 1.0 / (1 << 21) as f32;

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

/// obvhs CWBVH plus the BVH2 it was built from, in canonical space.
pub struct Bvh {
    centre: Vec3A,
    inv_scale: f32,
    scale: f32,
    cwbvh: CwBvh,
    bvh2: Bvh2,
    /// Triangles reordered into CWBVH slot order (a triangle may occupy several slots
    /// when spatial pre-splits are on).
    slot_triangles: Vec<RtTriangle>,
    /// Original triangle index of each CWBVH slot.
    slot_index: Vec<u32>,
    /// Seconds spent building (PLOC, reinsertion, conversion).
    pub build_seconds: f64,
}

/// Mapping a world ray into canonical space: origin, direction, and the factor that turns
/// canonical `t` back into the caller's `t`.
struct CanonicalRay {
    ray: Ray,
    t_to_world: f32,
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
        if triangles.is_empty() {
            return Self {
                centre: Vec3A::ZERO,
                inv_scale: 1.0,
                scale: 1.0,
                cwbvh: CwBvh::default(),
                bvh2: Bvh2::default(),
                slot_triangles: Vec::new(),
                slot_index: Vec::new(),
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
        let slot_index = cwbvh.primitive_indices.clone();
        let slot_triangles = slot_index
            .iter()
            .map(|&i| RtTriangle::from(&tris[i as usize]))
            .collect();
        Self {
            centre,
            inv_scale,
            scale,
            cwbvh,
            bvh2,
            slot_triangles,
            slot_index,
            build_seconds: start.elapsed().as_secs_f64(),
        }
    }

    /// Diagonal of the bounding box of all triangles, in world units.
    pub fn scene_diagonal(&self) -> f32 {
        self.scale
    }

    #[inline(always)]
    fn canonical(&self, origin: Vec3, direction: Vec3, tmin: f32, tmax: f32) -> CanonicalRay {
        let o = (Vec3A::from(origin) - self.centre) * self.inv_scale;
        // `+ 0.0` turns −0.0 components into +0.0: obvhs derives the traversal octant and
        // the inverse direction differently for −0.0, and such rays miss everything.
        let d = Vec3A::from(direction) * self.inv_scale + Vec3A::ZERO;
        let len = d.length();
        // t_world = t_canonical * TRAVERSAL_DIRECTION_LENGTH / len
        let k = TRAVERSAL_DIRECTION_LENGTH / len;
        let t_to_world = k;
        let to_canonical = len / TRAVERSAL_DIRECTION_LENGTH;
        let d = d * k;
        // obvhs' `Ray::new` clamps components below f32::EPSILON before inverting, which
        // is wrong for directions this short; invert exactly, saturating only at ±1e35.
        let inv = |x: f32| {
            if x.abs() < 1e-35 {
                1e35f32.copysign(x)
            } else {
                1.0 / x
            }
        };
        CanonicalRay {
            ray: Ray {
                origin: o,
                direction: d,
                inv_direction: Vec3A::new(inv(d.x), inv(d.y), inv(d.z)),
                tmin: tmin * to_canonical,
                tmax: tmax * to_canonical,
            },
            t_to_world,
        }
    }

    /// Möller–Trumbore ray/triangle test (Möller & Trumbore 1997) with [`EDGE_SLACK`] on
    /// the barycentrics, so shared edges are watertight. Returns `t` or ∞.
    #[inline(always)]
    fn intersect(tri: &RtTriangle, ray: &Ray) -> f32 {
        let c = tri.v0 - ray.origin;
        let r = ray.direction.cross(c);
        let inv_det = 1.0 / tri.ng.dot(ray.direction);
        let u = r.dot(tri.e2) * inv_det;
        let v = r.dot(tri.e1) * inv_det;
        let w = 1.0 - u - v;
        let t = tri.ng.dot(c) * inv_det;
        // Non-short-circuit `&`: one well-predicted branch instead of six.
        // (A zero determinant gives inv_det = ±∞ and NaN or infinite u, v, t: rejected.)
        let inside = (u >= -EDGE_SLACK) & (v >= -EDGE_SLACK) & (w >= -EDGE_SLACK);
        if inside & (t >= ray.tmin) & (t <= ray.tmax) {
            t
        } else {
            f32::INFINITY
        }
    }

    /// Barycentrics (u, v) of the ray's hit on slot `slot`, clamped into the triangle.
    #[inline(always)]
    fn barycentrics(&self, slot: usize, ray: &Ray) -> Vec2 {
        let uv = self.slot_triangles[slot].compute_barycentric(ray);
        let uv = uv.clamp(Vec2::ZERO, Vec2::ONE);
        let s = uv.x + uv.y;
        if s > 1.0 { uv / s } else { uv }
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
        if self.slot_triangles.is_empty() {
            return None;
        }
        let c = self.canonical(origin, direction, tmin, tmax);
        let mut hit = RayHit::none();
        let found = match accept {
            None => self.cwbvh.ray_traverse(c.ray, &mut hit, |ray, slot| {
                Self::intersect(&self.slot_triangles[slot], ray)
            }),
            Some(accept) => self.cwbvh.ray_traverse(c.ray, &mut hit, |ray, slot| {
                let t = Self::intersect(&self.slot_triangles[slot], ray);
                if t.is_finite() && !accept(self.slot_index[slot], self.barycentrics(slot, ray)) {
                    return f32::INFINITY;
                }
                t
            }),
        };
        if !found {
            return None;
        }
        let slot = hit.primitive_id as usize;
        Some(Hit {
            t: hit.t * c.t_to_world,
            triangle: self.slot_index[slot],
            uv: self.barycentrics(slot, &c.ray),
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
        if self.slot_triangles.is_empty() {
            return false;
        }
        let c = self.canonical(origin, direction, tmin, tmax);
        let miss = match accept {
            None => self.cwbvh.ray_traverse_miss(c.ray, |ray, slot| {
                Self::intersect(&self.slot_triangles[slot], ray)
            }),
            Some(accept) => self.cwbvh.ray_traverse_miss(c.ray, |ray, slot| {
                let t = Self::intersect(&self.slot_triangles[slot], ray);
                if t.is_finite() && !accept(self.slot_index[slot], self.barycentrics(slot, ray)) {
                    return f32::INFINITY;
                }
                t
            }),
        };
        !miss
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
