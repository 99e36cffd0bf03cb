//! Our traversal of obvhs' compressed 8-wide BVH (CWBVH, Ylitie et al. 2017, "Efficient
//! incoherent ray traversal on GPUs through compressed wide BVHs").
//!
//! obvhs builds the tree (PLOC, reinsertion, CWBVH layout); this module only walks it:
//!
//! - **Node test**: the ray against all 8 quantised child boxes of a node at once (slab test
//!   in the node's local grid, Ylitie §3.1), honouring the ray's `tmin` and `tmax`. The
//!   near and far planes per axis are picked by byte offset from the ray's direction signs,
//!   so no per-child select is needed, and the result is the paper's 32-bit hit mask (§3.2):
//!   internal children in bits 24..31, ordered by the ray's octant (slot ⊕ octant, highest
//!   bit first = nearest first), leaf triangles in bits 0..23.
//! - **Stack of node groups** (Ylitie §3.2): a group is a node's child base and its remaining
//!   child hits, so a node pushes at most one entry; the stack is a fixed array of
//!   uninitialised entries, never cleared, as deep as the tree.
//! - **Triangles**: every node's triangles are copied once after the build into blocks of 8
//!   in structure-of-arrays form ([`TriangleBlock`], each node's triangles starting a new
//!   block), and all hit triangles of a node are tested together, 8 lanes at a time, with a
//!   division-free Möller–Trumbore test; the division `t = T / det` runs only for lanes that
//!   passed it.
//! - **Closest hit** shrinks `tmax` as hits are found; **any hit** stops at the first one
//!   and visits children in slot order (no octant ordering).
//!
//! The kernels ([`Kernel`]: the node test and the block test) exist as portable scalar code
//! and as AVX2 code (`super::avx2`), chosen at run time ([`SimdLevel`]). Both evaluate the
//! same IEEE operations in the same order (no fused multiply-add), so every level visits the
//! same nodes and returns bit-identical answers.

use obvhs::cwbvh::{CwBvh, node::CwBvhNode};
use std::{mem::MaybeUninit, sync::OnceLock};
use surfcache_core::index::NO_INDEX;

/// Barycentric slack of the triangle test: edges shared by two triangles overlap by this
/// much instead of leaving float-precision cracks that rays slip through.
pub const EDGE_SLACK: f32 = 1.0 / (1 << 21) as f32;

/// Lanes per triangle block.
pub const LANES: usize = 8;

/// Stack entries kept on the machine stack; deeper trees use a heap stack.
const STACK: usize = 64;

/// Slot index of padding lanes in [`Tree::slot_index`]: they hold no triangle.
pub const PADDING: u32 = NO_INDEX;

/// Eight triangles in structure-of-arrays form: `v0`, `e1 = v0 − v1`, `e2 = v2 − v0` per
/// axis (the edge convention of obvhs' `RtTriangle`, so `u` weighs `v1` and `v` weighs `v2`).
#[derive(Clone, Copy, Default, Debug)]
#[repr(C, align(32))]
pub struct TriangleBlock {
    pub v0: [[f32; LANES]; 3],
    pub e1: [[f32; LANES]; 3],
    pub e2: [[f32; LANES]; 3],
}

/// A ray prepared for traversal (canonical space, see `super`): everything the node and
/// block tests read, computed once per ray.
#[derive(Clone, Copy, Debug)]
pub struct TraversalRay {
    pub origin: [f32; 3],
    pub direction: [f32; 3],
    pub inv_direction: [f32; 3],
    pub tmin: f32,
    /// Upper end of the interval; closest-hit traversal lowers it to the nearest hit.
    pub tmax: f32,
    /// Child-order key: octant code `(d.x ≥ 0)·4 + (d.y ≥ 0)·2 + (d.z ≥ 0)` (obvhs'
    /// `oct_inv4` byte), or 0 for unordered (any-hit) traversal.
    pub order: u32,
    /// Byte offsets inside a [`CwBvhNode`] of the near planes' quantised coordinates per
    /// axis (`child_min_*` when the direction component is ≥ 0, else `child_max_*`).
    pub near: [usize; 3],
    /// Byte offsets of the far planes.
    pub far: [usize; 3],
}

/// `1/x`, saturating at ±1e35 so that axis-parallel rays keep finite slab distances.
#[inline(always)]
fn inverse(x: f32) -> f32 {
    if x.abs() < 1e-35 {
        1e35f32.copysign(x)
    } else {
        1.0 / x
    }
}

impl TraversalRay {
    /// Prepares `origin + t·direction`, `t ∈ [tmin, tmax]`; `ordered` selects octant child
    /// ordering (closest hit) or slot order (any hit). Directions must have no −0.0
    /// components (add `+0.0`), so that signs and octants agree.
    #[inline(always)]
    pub fn new(origin: [f32; 3], direction: [f32; 3], tmin: f32, tmax: f32, ordered: bool) -> Self {
        use std::mem::offset_of;
        let inv_direction = direction.map(inverse);
        let lo = [
            offset_of!(CwBvhNode, child_min_x),
            offset_of!(CwBvhNode, child_min_y),
            offset_of!(CwBvhNode, child_min_z),
        ];
        let hi = [
            offset_of!(CwBvhNode, child_max_x),
            offset_of!(CwBvhNode, child_max_y),
            offset_of!(CwBvhNode, child_max_z),
        ];
        let positive = inv_direction.map(|x| x >= 0.0);
        let near = std::array::from_fn(|k| if positive[k] { lo[k] } else { hi[k] });
        let far = std::array::from_fn(|k| if positive[k] { hi[k] } else { lo[k] });
        let order = if ordered {
            ((positive[0] as u32) << 2) | ((positive[1] as u32) << 1) | positive[2] as u32
        } else {
            0
        };
        Self {
            origin,
            direction,
            inv_direction,
            tmin,
            tmax,
            order,
            near,
            far,
        }
    }
}

/// The two tests a traversal needs, per SIMD level.
///
/// # Safety
/// Implementations may require CPU features: call them only from code compiled for those
/// features on a CPU that has them (see [`SimdLevel::is_supported`]).
pub trait Kernel {
    /// The Ylitie hit mask of `node` (see the module doc).
    ///
    /// # Safety
    /// See the trait.
    unsafe fn node_hits(node: &CwBvhNode, ray: &TraversalRay) -> u32;

    /// Division-free Möller–Trumbore test (Möller & Trumbore 1997) of the ray against the
    /// lanes of `block` selected by `lanes`, with [`EDGE_SLACK`] on the barycentrics: the
    /// lanes hit within `[tmin, tmax]`, and their distances written to `t`.
    ///
    /// # Safety
    /// See the trait.
    unsafe fn block_hits(
        block: &TriangleBlock,
        ray: &TraversalRay,
        lanes: u32,
        t: &mut [f32; LANES],
    ) -> u32;
}

/// Portable kernels (any CPU).
pub struct Scalar;

/// `(p − o)·d⁻¹` and `e·d⁻¹` of the node's grid per axis: a child plane `q` lies at
/// `t = q·scale + offset` along the ray.
#[inline(always)]
pub fn node_grid(node: &CwBvhNode, ray: &TraversalRay) -> ([f32; 3], [f32; 3]) {
    let p = [node.p.x, node.p.y, node.p.z];
    let scale =
        std::array::from_fn(|k| f32::from_bits((node.e[k] as u32) << 23) * ray.inv_direction[k]);
    let offset = std::array::from_fn(|k| (p[k] - ray.origin[k]) * ray.inv_direction[k]);
    (scale, offset)
}

/// The bytes of a node (it is `repr(C)` plain data of 80 bytes).
#[inline(always)]
pub fn node_bytes(node: &CwBvhNode) -> &[u8; 80] {
    const _: () = assert!(size_of::<CwBvhNode>() == 80);
    // SAFETY: CwBvhNode is repr(C) without padding (obvhs derives bytemuck::Pod for it).
    unsafe { &*(node as *const CwBvhNode as *const [u8; 80]) }
}

/// Bit of the Ylitie hit mask a hit child `meta` sets: `count << offset` with the
/// unary triangle count in the top 3 bits of a leaf's meta byte and its first triangle in
/// the low 5; internal children (offset 24 + slot) are reordered by `order`.
#[inline(always)]
pub fn child_bits(meta: u8, order: u32) -> u32 {
    let meta = meta as u32;
    let mut offset = meta & 31;
    if offset >= 24 {
        offset ^= order;
    }
    (meta >> 5) << offset
}

impl Kernel for Scalar {
    #[inline(always)]
    unsafe fn node_hits(node: &CwBvhNode, ray: &TraversalRay) -> u32 {
        let bytes = node_bytes(node);
        let (scale, offset) = node_grid(node, ray);
        let mut mask = 0;
        for i in 0..8 {
            let plane = |at: usize, k: usize| bytes[at + i] as f32 * scale[k] + offset[k];
            let near = plane(ray.near[0], 0)
                .max(plane(ray.near[1], 1))
                .max(plane(ray.near[2], 2).max(ray.tmin));
            let far = plane(ray.far[0], 0)
                .min(plane(ray.far[1], 1))
                .min(plane(ray.far[2], 2).min(ray.tmax));
            if near <= far {
                mask |= child_bits(node.child_meta[i], ray.order);
            }
        }
        mask
    }

    #[inline(always)]
    unsafe fn block_hits(
        block: &TriangleBlock,
        ray: &TraversalRay,
        lanes: u32,
        t: &mut [f32; LANES],
    ) -> u32 {
        let mut hits = 0;
        let mut rest = lanes;
        while rest != 0 {
            let l = rest.trailing_zeros() as usize;
            rest &= rest - 1;
            if let Some(tl) = triangle_lane(block, l, ray) {
                t[l] = tl;
                hits |= 1 << l;
            }
        }
        hits
    }
}

/// The division-free triangle test of one lane, in exactly the operation order of the SIMD
/// kernels: `T/det` when the ray hits the triangle (with [`EDGE_SLACK`]) within
/// `[tmin, tmax]`.
#[inline(always)]
pub fn triangle_lane(block: &TriangleBlock, l: usize, ray: &TraversalRay) -> Option<f32> {
    let (e1, e2, c, r) = lane_terms(block, l, ray);
    let ng = cross(e1, e2);
    let det = dot(ng, ray.direction);
    let (u, v, tt) = (dot(r, e2), dot(r, e1), dot(ng, c));
    let sign = det.to_bits() & 0x8000_0000;
    let flip = |x: f32| f32::from_bits(x.to_bits() ^ sign);
    let adet = flip(det);
    let (u, v, tt) = (flip(u), flip(v), flip(tt));
    let w = adet - u - v;
    let slack = -(EDGE_SLACK * adet);
    let candidate = (u >= slack)
        & (v >= slack)
        & (w >= slack)
        & (adet > 0.0)
        & (tt >= ray.tmin * adet)
        & (tt <= ray.tmax * adet);
    if !candidate {
        return None;
    }
    let t = tt / adet;
    ((t >= ray.tmin) & (t <= ray.tmax)).then_some(t)
}

/// Barycentrics `(u, v)` of the ray's hit on lane `l` (same operations as the test).
#[inline]
pub fn lane_barycentrics(block: &TriangleBlock, l: usize, ray: &TraversalRay) -> (f32, f32) {
    let (e1, e2, _, r) = lane_terms(block, l, ray);
    let det = dot(cross(e1, e2), ray.direction);
    (dot(r, e2) / det, dot(r, e1) / det)
}

/// Lane `l`'s edges `e1`, `e2`, `c = v0 − o` and `r = d × c`, shared by the hit test and
/// the barycentrics (Möller and Trumbore 1997, in the division-free form).
#[inline(always)]
fn lane_terms(
    block: &TriangleBlock,
    l: usize,
    ray: &TraversalRay,
) -> ([f32; 3], [f32; 3], [f32; 3], [f32; 3]) {
    let (s, o) = (block, ray.origin);
    let e1 = [s.e1[0][l], s.e1[1][l], s.e1[2][l]];
    let e2 = [s.e2[0][l], s.e2[1][l], s.e2[2][l]];
    let c = [s.v0[0][l] - o[0], s.v0[1][l] - o[1], s.v0[2][l] - o[2]];
    (e1, e2, c, cross(ray.direction, c))
}

/// `a × b`, component order as in the SIMD kernels.
#[inline(always)]
fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// `a · b` as `(a₀b₀ + a₁b₁) + a₂b₂`.
#[inline(always)]
fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The CWBVH as traversed: obvhs' nodes with each node's `primitive_base_idx` moved to its
/// first slot in `blocks` (a multiple of [`LANES`]), the triangles in blocks, and the
/// caller's triangle index of every slot.
#[derive(Default)]
pub struct Tree {
    pub nodes: Vec<CwBvhNode>,
    pub blocks: Vec<TriangleBlock>,
    /// Triangle index (into the triangles the tree was made from) per slot; [`PADDING`]
    /// for unused lanes.
    pub slot_index: Vec<u32>,
    /// Depth of the tree in nodes (the most stack entries a traversal needs).
    pub depth: usize,
}

impl Tree {
    /// Lays out `cwbvh` for traversal; `triangles[i]` are the corners of the triangle that
    /// obvhs' `primitive_indices` entry `i` names.
    pub fn new(cwbvh: CwBvh, triangles: &[[[f32; 3]; 3]]) -> Self {
        let mut nodes = cwbvh.nodes;
        let mut blocks = Vec::new();
        let mut slot_index = Vec::new();
        for node in &mut nodes {
            let count = (0..8)
                .filter(|&i| node.imask & (1 << i) == 0 && node.child_meta[i] != 0)
                .map(|i| {
                    let m = node.child_meta[i];
                    (m & 31) as usize + (m >> 5).count_ones() as usize
                })
                .max()
                .unwrap_or(0);
            if count == 0 {
                node.primitive_base_idx = 0;
                continue;
            }
            let old = node.primitive_base_idx as usize;
            node.primitive_base_idx = slot_index.len() as u32;
            let new_blocks = count.div_ceil(LANES);
            slot_index.resize(slot_index.len() + new_blocks * LANES, PADDING);
            let first_block = blocks.len();
            blocks.resize(first_block + new_blocks, TriangleBlock::default());
            for k in 0..count {
                let prim = cwbvh.primitive_indices[old + k];
                let slot = node.primitive_base_idx as usize + k;
                slot_index[slot] = prim;
                let [a, b, c] = triangles[prim as usize];
                let block = &mut blocks[slot / LANES];
                let l = slot % LANES;
                for axis in 0..3 {
                    block.v0[axis][l] = a[axis];
                    block.e1[axis][l] = a[axis] - b[axis];
                    block.e2[axis][l] = c[axis] - a[axis];
                }
            }
        }
        let depth = depth(&nodes);
        Self {
            nodes,
            blocks,
            slot_index,
            depth,
        }
    }
}

/// Depth of the tree in nodes (0 when empty), in one pass: obvhs places every node's
/// children after it.
fn depth(nodes: &[CwBvhNode]) -> usize {
    let mut level = vec![0usize; nodes.len()];
    if let Some(root) = level.first_mut() {
        *root = 1;
    }
    for (i, n) in nodes.iter().enumerate() {
        for k in 0..n.imask.count_ones() as usize {
            let child = n.child_base_idx as usize + k;
            debug_assert!(child > i);
            level[child] = level[i] + 1;
        }
    }
    level.into_iter().max().unwrap_or(0)
}

/// A node's child base and its pending child hits (bits 24..31) with its `imask` (bits
/// 0..7): one stack entry.
#[derive(Clone, Copy)]
struct Group {
    base: u32,
    bits: u32,
}

/// What a traversal does with candidate hits.
pub trait Visit {
    /// Whether to stop at the first accepted hit (any hit) rather than shrink `tmax`.
    const ANY: bool;
    /// Whether `slot` at distance `t` counts (alpha masks); `ray` is the traversal ray.
    fn accept(&mut self, slot: usize, t: f32, ray: &TraversalRay) -> bool;
}

/// Walks the tree (see the module doc): the slot and distance of the closest accepted hit,
/// or for `V::ANY` of the first accepted hit found.
///
/// # Safety
/// `K`'s CPU features must be present and enabled in the caller.
#[inline(always)]
pub unsafe fn traverse<K: Kernel, V: Visit>(
    tree: &Tree,
    ray: &mut TraversalRay,
    visit: &mut V,
) -> Option<(usize, f32)> {
    if tree.depth <= STACK {
        let mut stack = [const { MaybeUninit::<Group>::uninit() }; STACK];
        unsafe { traverse_with::<K, V>(tree, ray, visit, &mut stack) }
    } else {
        let mut stack = vec![MaybeUninit::<Group>::uninit(); tree.depth];
        unsafe { traverse_with::<K, V>(tree, ray, visit, &mut stack) }
    }
}

#[inline(always)]
unsafe fn traverse_with<K: Kernel, V: Visit>(
    tree: &Tree,
    ray: &mut TraversalRay,
    visit: &mut V,
    stack: &mut [MaybeUninit<Group>],
) -> Option<(usize, f32)> {
    debug_assert!(stack.len() >= tree.depth);
    let mut best = None;
    let mut sp = 0usize;
    let root = &tree.nodes[0];
    let hits = unsafe { K::node_hits(root, ray) };
    let mut group = Group {
        base: root.child_base_idx,
        bits: (hits & 0xff00_0000) | root.imask as u32,
    };
    let mut prims = (root.primitive_base_idx, hits & 0x00ff_ffff);
    loop {
        // All hit triangles of the last node, a block of 8 at a time.
        let mut pending = prims.1;
        let mut block = prims.0 as usize / LANES;
        while pending != 0 {
            let lanes = pending & 0xff;
            if lanes != 0 {
                let mut t = [0.0; LANES];
                // SAFETY: blocks exist for every slot a node names (Tree::new).
                let b = unsafe { tree.blocks.get_unchecked(block) };
                let mut found = unsafe { K::block_hits(b, ray, lanes, &mut t) };
                while found != 0 {
                    let l = found.trailing_zeros() as usize;
                    found &= found - 1;
                    let slot = block * LANES + l;
                    if (V::ANY || t[l] < ray.tmax || best.is_none())
                        && visit.accept(slot, t[l], ray)
                    {
                        best = Some((slot, t[l]));
                        if V::ANY {
                            return best;
                        }
                        ray.tmax = t[l];
                    }
                }
            }
            pending >>= 8;
            block += 1;
        }
        if group.bits & 0xff00_0000 == 0 {
            if sp == 0 {
                break;
            }
            sp -= 1;
            // SAFETY: entries below `sp` were written by the push below.
            group = unsafe { stack.get_unchecked(sp).assume_init() };
        }
        let bit = 31 - group.bits.leading_zeros();
        group.bits &= !(1 << bit);
        let slot = (bit - 24) ^ ray.order;
        let child = group.base + (group.bits & 0xff & ((1 << slot) - 1)).count_ones();
        if group.bits & 0xff00_0000 != 0 {
            // SAFETY: at most one entry per tree level is pending (stack.len() ≥ depth).
            unsafe { stack.get_unchecked_mut(sp).write(group) };
            sp += 1;
        }
        // SAFETY: child indices of a CWBVH node lie inside the node array.
        let node = unsafe { tree.nodes.get_unchecked(child as usize) };
        let hits = unsafe { K::node_hits(node, ray) };
        group = Group {
            base: node.child_base_idx,
            bits: (hits & 0xff00_0000) | node.imask as u32,
        };
        prims = (node.primitive_base_idx, hits & 0x00ff_ffff);
    }
    best
}

/// Instruction sets the traversal kernels exist for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SimdLevel {
    /// Portable code (any CPU; what aarch64 runs).
    Scalar,
    /// x86-64 AVX2 (8 children / 8 triangles per instruction).
    Avx2,
}

impl SimdLevel {
    /// Every level, slowest first.
    pub const ALL: [SimdLevel; 2] = [SimdLevel::Scalar, SimdLevel::Avx2];

    /// Name as accepted by `SURFCACHE_SIMD`.
    pub fn name(self) -> &'static str {
        match self {
            SimdLevel::Scalar => "scalar",
            SimdLevel::Avx2 => "avx2",
        }
    }

    /// Whether this CPU can run the level.
    pub fn is_supported(self) -> bool {
        match self {
            SimdLevel::Scalar => true,
            #[cfg(target_arch = "x86_64")]
            SimdLevel::Avx2 => std::arch::is_x86_feature_detected!("avx2"),
            #[cfg(not(target_arch = "x86_64"))]
            SimdLevel::Avx2 => false,
        }
    }

    /// The level new BVHs use: the best this CPU supports, detected once, or the one the
    /// environment variable `SURFCACHE_SIMD` names (`scalar`, `avx2`; for benchmarks) when
    /// the CPU supports it.
    pub fn detected() -> SimdLevel {
        static LEVEL: OnceLock<SimdLevel> = OnceLock::new();
        *LEVEL.get_or_init(|| {
            let best = *Self::ALL
                .iter()
                .rev()
                .find(|l| l.is_supported())
                .unwrap_or(&SimdLevel::Scalar);
            match std::env::var("SURFCACHE_SIMD") {
                Ok(name) => Self::ALL
                    .into_iter()
                    .find(|l| l.name() == name && l.is_supported())
                    .unwrap_or(best),
                Err(_) => best,
            }
        })
    }
}
