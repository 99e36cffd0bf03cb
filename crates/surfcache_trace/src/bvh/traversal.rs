//! Our traversal of obvhs' compressed 8-wide BVH (CWBVH, Ylitie et al. 2017, "Efficient
//! incoherent ray traversal on GPUs through compressed wide BVHs").
//!
//! obvhs builds the tree (PLOC, reinsertion, CWBVH layout); this module only walks it:
//!
//! - **Node test**: the ray against all 8 quantised child boxes of a node at once (slab test
//!   in the node's local grid, Ylitie §3.1), honouring the ray's `tmin` and `tmax`. The
//!   near and far planes per axis are picked by byte offset from the ray's direction signs,
//!   so no per-child select is needed. The result is the paper's 32-bit hit mask (§3.2):
//!   internal children in bits 24..31 by slot, leaf triangles in bits 0..23; and each
//!   child's entry distance.
//! - **Triangles**: every node's triangles are copied once after the build into blocks of 8
//!   in structure-of-arrays form ([`TriangleBlock`], each node's triangles starting a new
//!   block), and all hit triangles of a node are tested together, 8 lanes at a time, with a
//!   division-free Möller–Trumbore test; the division `t = T / det` runs only for lanes that
//!   passed it.
//! - **Closest hit** visits front to back: a node's hit internal children are sorted by
//!   entry distance, the nearest is fetched while the node's triangles are tested and then
//!   visited, the others are pushed with their distance, and a popped entry beyond the
//!   nearest hit so far is skipped. Each accepted hit lowers `tmax`.
//! - **Any hit** stops at the first accepted hit and needs no order: its stack holds node
//!   groups (Ylitie §3.2), a node's child base and its remaining child hits, so a node
//!   pushes at most one entry.
//! - Both stacks are fixed arrays of uninitialised entries, never cleared, as deep as the
//!   tree needs.
//!
//! The kernels ([`Kernel`]: the node test and the block test) exist as portable scalar code
//! and as AVX2 code (`super::avx2`), chosen at run time ([`SimdLevel`]). Both evaluate the
//! same IEEE operations in the same order (no fused multiply-add), so every level visits the
//! same nodes and returns bit-identical answers.

use obvhs::cwbvh::{CwBvh, node::CwBvhNode};
use std::{mem::MaybeUninit, sync::OnceLock};
use surfcache_core::{index::NO_INDEX, prefetch::prefetch};

/// Barycentric slack of the triangle test: edges shared by two triangles overlap by this
/// much instead of leaving float-precision cracks that rays slip through.
pub const EDGE_SLACK: f32 = 1.0 / (1 << 21) as f32;

/// Lanes per triangle block.
pub const LANES: usize = 8;

/// Stack entries kept on the machine stack; deeper trees use a heap stack.
const STACK: usize = 256;

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
    /// Prepares `origin + t·direction`, `t ∈ [tmin, tmax]`. Directions must have no −0.0
    /// components (add `+0.0`), so that the near and far planes follow the direction's signs.
    #[inline(always)]
    pub fn new(origin: [f32; 3], direction: [f32; 3], tmin: f32, tmax: f32) -> Self {
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
        Self {
            origin,
            direction,
            inv_direction,
            tmin,
            tmax,
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
    /// The Ylitie hit mask of `node` (see the module doc), and each child's entry distance
    /// `max(tmin, near planes)` in `near` (meaningful for the hit children).
    ///
    /// # Safety
    /// See the trait.
    unsafe fn node_hits(node: &CwBvhNode, ray: &TraversalRay, near: &mut [f32; 8]) -> u32;

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
/// the low 5; an internal child sets bit 24 + its slot.
#[inline(always)]
pub fn child_bits(meta: u8) -> u32 {
    let meta = meta as u32;
    (meta >> 5) << (meta & 31)
}

impl Kernel for Scalar {
    #[inline(always)]
    unsafe fn node_hits(node: &CwBvhNode, ray: &TraversalRay, near_out: &mut [f32; 8]) -> u32 {
        let bytes = node_bytes(node);
        let (scale, offset) = node_grid(node, ray);
        let mut mask = 0;
        for i in 0..8 {
            let plane = |at: usize, k: usize| bytes[at + i] as f32 * scale[k] + offset[k];
            let near = plane(ray.near[0], 0)
                .max(plane(ray.near[1], 1))
                .max(plane(ray.near[2], 2).max(ray.tmin));
            near_out[i] = near;
            let far = plane(ray.far[0], 0)
                .min(plane(ray.far[1], 1))
                .min(plane(ray.far[2], 2).min(ray.tmax));
            if near <= far {
                mask |= child_bits(node.child_meta[i]);
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
/// 0..7): one entry of the any-hit stack.
#[derive(Clone, Copy)]
struct Group {
    base: u32,
    bits: u32,
}

/// One entry of the closest-hit stack: a node's entry distance (its `f32` bits, ≥ 0, so
/// that entries order like distances) in the high half and its index in the low half.
type Entry = u64;

/// Entry distance of a closest-hit stack entry.
#[inline(always)]
fn entry_distance(e: Entry) -> f32 {
    f32::from_bits((e >> 32) as u32)
}

/// Node index of internal child `slot` of a node whose internal children start at `base`
/// and occupy the slots `imask` marks (CWBVH stores them packed in slot order).
#[inline(always)]
fn child_index(base: u32, imask: u32, slot: u32) -> usize {
    (base + (imask & ((1 << slot) - 1)).count_ones()) as usize
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
/// `K`'s CPU features must be present and enabled in the caller, and `tree` must have a
/// root node.
#[inline(always)]
pub unsafe fn traverse<K: Kernel, V: Visit>(
    tree: &Tree,
    ray: &mut TraversalRay,
    visit: &mut V,
) -> Option<(usize, f32)> {
    // At most one group per level is pending (any hit), or 7 entries per level (closest).
    // No closures here: they would not inherit the caller's CPU features, and the kernels
    // would not inline.
    if V::ANY {
        if tree.depth <= STACK {
            let mut stack = [const { MaybeUninit::<Group>::uninit() }; STACK];
            unsafe { traverse_any::<K, V>(tree, ray, visit, &mut stack) }
        } else {
            let mut stack = vec![MaybeUninit::<Group>::uninit(); tree.depth];
            unsafe { traverse_any::<K, V>(tree, ray, visit, &mut stack) }
        }
    } else if 7 * tree.depth < STACK {
        let mut stack = [const { MaybeUninit::<Entry>::uninit() }; STACK];
        unsafe { traverse_closest::<K, V>(tree, ray, visit, &mut stack) }
    } else {
        let mut stack = vec![MaybeUninit::<Entry>::uninit(); 7 * tree.depth + 1];
        unsafe { traverse_closest::<K, V>(tree, ray, visit, &mut stack) }
    }
}

/// Tests the hit triangles `pending` (8 lane bits per block, from block `block` on), a
/// block at a time, and returns the last accepted hit: closest hit lowers `ray.tmax` to
/// each (`found` says whether one was accepted before, so that a hit at `tmax` counts
/// only as the first), any hit returns at the first.
#[inline(always)]
unsafe fn test_triangles<K: Kernel, V: Visit>(
    tree: &Tree,
    ray: &mut TraversalRay,
    visit: &mut V,
    mut found: bool,
    mut pending: u32,
    mut block: usize,
) -> Option<(usize, f32)> {
    let mut best = None;
    while pending != 0 {
        let lanes = pending & 0xff;
        if lanes != 0 {
            let mut t = [0.0; LANES];
            // SAFETY: blocks exist for every slot a node names (Tree::new).
            let b = unsafe { tree.blocks.get_unchecked(block) };
            let mut hits = unsafe { K::block_hits(b, ray, lanes, &mut t) };
            while hits != 0 {
                let l = hits.trailing_zeros() as usize;
                hits &= hits - 1;
                let slot = block * LANES + l;
                if (V::ANY || t[l] < ray.tmax || !found) && visit.accept(slot, t[l], ray) {
                    best = Some((slot, t[l]));
                    if V::ANY {
                        return best;
                    }
                    found = true;
                    ray.tmax = t[l];
                }
            }
        }
        pending >>= 8;
        block += 1;
    }
    best
}

/// Any hit: node groups in slot order (Ylitie §3.2), stopping at the first accepted hit.
#[inline(always)]
unsafe fn traverse_any<K: Kernel, V: Visit>(
    tree: &Tree,
    ray: &mut TraversalRay,
    visit: &mut V,
    stack: &mut [MaybeUninit<Group>],
) -> Option<(usize, f32)> {
    debug_assert!(stack.len() >= tree.depth);
    let mut sp = 0usize;
    let mut near = [0.0; 8];
    let mut current = 0;
    loop {
        // SAFETY: child indices of a CWBVH node lie inside the node array.
        let node = unsafe { tree.nodes.get_unchecked(current) };
        let hits = unsafe { K::node_hits(node, ray, &mut near) };
        let mut group = Group {
            base: node.child_base_idx,
            bits: (hits & 0xff00_0000) | node.imask as u32,
        };
        let block = node.primitive_base_idx as usize / LANES;
        let triangles = hits & 0x00ff_ffff;
        let hit = unsafe { test_triangles::<K, V>(tree, ray, visit, false, triangles, block) };
        if hit.is_some() {
            return hit;
        }
        if group.bits & 0xff00_0000 == 0 {
            if sp == 0 {
                return None;
            }
            sp -= 1;
            // SAFETY: entries below `sp` were written by the push below.
            group = unsafe { stack.get_unchecked(sp).assume_init() };
        }
        let bit = 31 - group.bits.leading_zeros();
        group.bits &= !(1 << bit);
        let slot = bit - 24;
        current = child_index(group.base, group.bits & 0xff, slot);
        if group.bits & 0xff00_0000 != 0 {
            // SAFETY: at most one entry per tree level is pending (stack.len() ≥ depth).
            unsafe { stack.get_unchecked_mut(sp).write(group) };
            sp += 1;
        }
    }
}

/// Closest hit, front to back: a node's hit triangles are tested, then its hit internal
/// children visited nearest first, the others pushed with their entry distance and skipped
/// when popped beyond the nearest hit found so far.
#[inline(always)]
unsafe fn traverse_closest<K: Kernel, V: Visit>(
    tree: &Tree,
    ray: &mut TraversalRay,
    visit: &mut V,
    stack: &mut [MaybeUninit<Entry>],
) -> Option<(usize, f32)> {
    debug_assert!(stack.len() > 7 * tree.depth);
    let mut best = None;
    let mut sp = 0usize;
    let mut current = 0usize;
    let mut near = [0.0f32; 8];
    loop {
        // SAFETY: node indices come from the tree's child bases.
        let node = unsafe { tree.nodes.get_unchecked(current) };
        let hits = unsafe { K::node_hits(node, ray, &mut near) };
        // Hit internal children, sorted nearest first (insertion sort: most nodes hit few).
        let imask = node.imask as u32;
        let mut entries = [0 as Entry; 8];
        let mut n = 0;
        let mut rest = hits >> 24;
        while rest != 0 {
            let slot = rest.trailing_zeros();
            rest &= rest - 1;
            let child = child_index(node.child_base_idx, imask, slot);
            entries[n] = ((near[slot as usize].max(0.0).to_bits() as u64) << 32) | child as u64;
            n += 1;
        }
        for i in 1..n {
            let e = entries[i];
            let mut j = i;
            while j > 0 && entries[j - 1] > e {
                entries[j] = entries[j - 1];
                j -= 1;
            }
            entries[j] = e;
        }
        if n > 0 {
            // The next node is fetched while the triangles are tested.
            // SAFETY: as above.
            let next = unsafe { tree.nodes.get_unchecked(entries[0] as u32 as usize) };
            prefetch(next);
            prefetch(&node_bytes(next)[64]);
        }
        let block = node.primitive_base_idx as usize / LANES;
        let triangles = hits & 0x00ff_ffff;
        let found = best.is_some();
        if let Some(hit) =
            unsafe { test_triangles::<K, V>(tree, ray, visit, found, triangles, block) }
        {
            best = Some(hit);
        }
        while n > 0 && entry_distance(entries[n - 1]) > ray.tmax {
            n -= 1;
        }
        if n == 0 {
            loop {
                if sp == 0 {
                    return best;
                }
                sp -= 1;
                // SAFETY: entries below `sp` were written by the pushes below.
                let e = unsafe { stack.get_unchecked(sp).assume_init() };
                if entry_distance(e) <= ray.tmax {
                    current = e as u32 as usize;
                    break;
                }
            }
            continue;
        }
        for &e in entries[1..n].iter().rev() {
            // SAFETY: at most 7 entries per tree level are pending (stack.len() > 7·depth).
            unsafe { stack.get_unchecked_mut(sp).write(e) };
            sp += 1;
        }
        current = entries[0] as u32 as usize;
    }
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
