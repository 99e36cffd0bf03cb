//! Software prefetching: asking the processor to bring a value's cache line closer while
//! other work runs. A bake reads tables too large for a core's caches at random (the
//! environment map's sampling tables and texels); where the address is known before the
//! value is needed (before a ray is traced), a prefetch hides the wait behind the ray.

/// Hints that `value` will be read soon. Changes no result; a no-op on processors without
/// a prefetch instruction in the baseline instruction set.
#[inline(always)]
pub fn prefetch<T>(value: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use core::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        // SAFETY: SSE is part of x86-64, and a prefetch never faults.
        unsafe { _mm_prefetch::<_MM_HINT_T0>((value as *const T).cast()) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}
