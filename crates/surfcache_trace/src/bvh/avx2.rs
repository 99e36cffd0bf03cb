//! AVX2 kernels of the traversal (`super::traversal`): one node's 8 child boxes and 8
//! triangles per instruction. Same operations, in the same order, as the scalar kernels.

use super::traversal::{EDGE_SLACK, Kernel, LANES, TraversalRay, TriangleBlock, node_grid};
use obvhs::cwbvh::node::CwBvhNode;
use std::arch::x86_64::*;

/// The AVX2 kernels (x86-64 CPUs with AVX2).
pub struct Avx2;

impl Kernel for Avx2 {
    #[inline(always)]
    unsafe fn node_hits(node: &CwBvhNode, ray: &TraversalRay, near: &mut [f32; 8]) -> u32 {
        unsafe { node_hits(node, ray, near) }
    }

    #[inline(always)]
    unsafe fn block_hits(
        block: &TriangleBlock,
        ray: &TraversalRay,
        lanes: u32,
        t: &mut [f32; LANES],
    ) -> u32 {
        unsafe { block_hits(block, ray, lanes, t) }
    }
}

/// Slab test of the ray against a node's 8 quantised child boxes (Ylitie et al. 2017 §3.1),
/// all children at once: the hit mask of §3.2, and each child's entry distance in
/// `near_out`.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn node_hits(node: &CwBvhNode, ray: &TraversalRay, near_out: &mut [f32; 8]) -> u32 {
    let (scale, offset) = node_grid(node, ray);
    let base = node as *const CwBvhNode as *const u8;
    // Quantised plane coordinates of the 8 children at byte offset `at`, as f32.
    let planes = |at: usize| {
        // SAFETY: `at` + 8 ≤ 80, inside the node.
        let q = unsafe { _mm_loadl_epi64(base.add(at) as *const __m128i) };
        _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(q))
    };
    let t = |at: usize, k: usize| {
        _mm256_add_ps(
            _mm256_mul_ps(planes(at), _mm256_set1_ps(scale[k])),
            _mm256_set1_ps(offset[k]),
        )
    };
    let near = _mm256_max_ps(
        _mm256_max_ps(t(ray.near[0], 0), t(ray.near[1], 1)),
        _mm256_max_ps(t(ray.near[2], 2), _mm256_set1_ps(ray.tmin)),
    );
    let far = _mm256_min_ps(
        _mm256_min_ps(t(ray.far[0], 0), t(ray.far[1], 1)),
        _mm256_min_ps(t(ray.far[2], 2), _mm256_set1_ps(ray.tmax)),
    );
    // SAFETY: near_out holds 8 f32.
    unsafe { _mm256_storeu_ps(near_out.as_mut_ptr(), near) };
    let hit = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LE_OQ>(near, far));
    // Per child: (meta >> 5) << (meta & 31).
    // SAFETY: child_meta is 8 bytes.
    let meta = _mm256_cvtepu8_epi32(unsafe {
        _mm_loadl_epi64(node.child_meta.as_ptr() as *const __m128i)
    });
    let offset = _mm256_and_si256(meta, _mm256_set1_epi32(31));
    let bits = _mm256_sllv_epi32(_mm256_srli_epi32::<5>(meta), offset);
    let bits = _mm256_and_si256(bits, hit);
    // Horizontal OR of the 8 lanes.
    let x = _mm_or_si128(
        _mm256_castsi256_si128(bits),
        _mm256_extracti128_si256::<1>(bits),
    );
    let x = _mm_or_si128(x, _mm_shuffle_epi32::<0b01_00_11_10>(x));
    let x = _mm_or_si128(x, _mm_shuffle_epi32::<0b10_11_00_01>(x));
    _mm_cvtsi128_si32(x) as u32
}

/// Division-free Möller–Trumbore test of 8 triangles (see `Kernel::block_hits`); the
/// division runs once, for the block, only when some lane passed.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn block_hits(
    block: &TriangleBlock,
    ray: &TraversalRay,
    lanes: u32,
    t_out: &mut [f32; LANES],
) -> u32 {
    let load = |a: &[f32; LANES]| unsafe { _mm256_load_ps(a.as_ptr()) };
    let mul = |a, b| _mm256_mul_ps(a, b);
    let add = |a, b| _mm256_add_ps(a, b);
    let sub = |a, b| _mm256_sub_ps(a, b);
    let splat = |x| _mm256_set1_ps(x);
    let o = ray.origin.map(splat);
    let d = ray.direction.map(splat);
    let c = [0, 1, 2].map(|k| sub(load(&block.v0[k]), o[k]));
    let cross = |a: [__m256; 3], b: [__m256; 3]| {
        [
            sub(mul(a[1], b[2]), mul(a[2], b[1])),
            sub(mul(a[2], b[0]), mul(a[0], b[2])),
            sub(mul(a[0], b[1]), mul(a[1], b[0])),
        ]
    };
    let dot = |a: [__m256; 3], b: [__m256; 3]| {
        add(add(mul(a[0], b[0]), mul(a[1], b[1])), mul(a[2], b[2]))
    };
    let e1 = [0, 1, 2].map(|k| load(&block.e1[k]));
    let e2 = [0, 1, 2].map(|k| load(&block.e2[k]));
    let r = cross(d, c);
    let ng = cross(e1, e2);
    let det = dot(ng, d);
    let sign = _mm256_and_ps(det, splat(-0.0));
    let adet = _mm256_xor_ps(det, sign);
    let u = _mm256_xor_ps(dot(r, e2), sign);
    let v = _mm256_xor_ps(dot(r, e1), sign);
    let tt = _mm256_xor_ps(dot(ng, c), sign);
    let w = sub(sub(adet, u), v);
    let slack = _mm256_xor_ps(mul(splat(EDGE_SLACK), adet), splat(-0.0));
    let ge = |a, b| _mm256_cmp_ps::<_CMP_GE_OQ>(a, b);
    let le = |a, b| _mm256_cmp_ps::<_CMP_LE_OQ>(a, b);
    let inside = _mm256_and_ps(_mm256_and_ps(ge(u, slack), ge(v, slack)), ge(w, slack));
    let front = _mm256_and_ps(
        _mm256_cmp_ps::<_CMP_GT_OQ>(adet, _mm256_setzero_ps()),
        ge(tt, mul(splat(ray.tmin), adet)),
    );
    let range = _mm256_and_ps(front, le(tt, mul(splat(ray.tmax), adet)));
    let candidates = _mm256_movemask_ps(_mm256_and_ps(inside, range)) as u32 & lanes;
    if candidates == 0 {
        return 0;
    }
    let t = _mm256_div_ps(tt, adet);
    let ok = _mm256_and_ps(ge(t, splat(ray.tmin)), le(t, splat(ray.tmax)));
    // SAFETY: t_out holds 8 f32.
    unsafe { _mm256_storeu_ps(t_out.as_mut_ptr(), t) };
    candidates & _mm256_movemask_ps(ok) as u32
}
