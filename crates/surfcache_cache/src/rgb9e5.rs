//! Shared-exponent RGB in 32 bits (the `RGB9_E5` format of OpenGL's
//! `EXT_texture_shared_exponent`): three 9-bit mantissas and one 5-bit exponent.
//!
//! Precision: every channel is stored to within half a unit of 2^(e−9), where 2^e is the
//! smallest power of two above the largest channel, so each channel's error is at most
//! 1/512 of the largest channel (0.2 %, typically half that); channels far below the
//! largest lose relative precision. Range: 0 and
//! 2⁻²⁴ … 65,408; callers scale their values into it (see [`Rgb9e5Scale`]).

use glam::Vec3;
use serde::{Deserialize, Serialize};

const MANTISSA_BITS: i32 = 9;
const EXPONENT_BIAS: i32 = 15;
const MAX_EXPONENT: i32 = 31;
/// Largest representable value: (511/512) · 2¹⁶.
pub const RGB9E5_MAX: f32 = 511.0 / 512.0 * 65536.0;

/// Packs non-negative linear RGB (negative and NaN become 0, values above
/// [`RGB9E5_MAX`] saturate) with round-to-nearest mantissas.
///
/// ```
/// use surfcache_cache::rgb9e5::{pack, unpack};
/// use glam::Vec3;
/// let c = Vec3::new(3.0, 0.5, 0.125);
/// assert!((unpack(pack(c)) - c).abs().max_element() <= 3.0 / 512.0);
/// ```
pub fn pack(c: Vec3) -> u32 {
    let clamp = |x: f32| {
        if x.is_nan() || x <= 0.0 {
            0.0
        } else {
            x.min(RGB9E5_MAX)
        }
    };
    let (r, g, b) = (clamp(c.x), clamp(c.y), clamp(c.z));
    let max = r.max(g).max(b);
    if max == 0.0 {
        return 0;
    }
    // Exponent such that max < 2^(exp - bias) (frexp-style), at least the smallest.
    let mut exp = (max.log2().floor() as i32 + 1).max(-EXPONENT_BIAS) + EXPONENT_BIAS;
    let mut scale = 2f32.powi(exp - EXPONENT_BIAS - MANTISSA_BITS);
    // Rounding may carry the largest mantissa to 512: step the exponent up.
    if (max / scale).round() as i32 >= 1 << MANTISSA_BITS {
        exp += 1;
        scale *= 2.0;
    }
    let exp = exp.min(MAX_EXPONENT);
    let q = |x: f32| ((x / scale).round() as u32).min((1 << MANTISSA_BITS) - 1);
    q(r) | (q(g) << 9) | (q(b) << 18) | ((exp as u32) << 27)
}

/// Unpacks a value made by [`pack`].
#[inline]
pub fn unpack(v: u32) -> Vec3 {
    let exp = (v >> 27) as i32;
    let scale = 2f32.powi(exp - EXPONENT_BIAS - MANTISSA_BITS);
    let m = |shift: u32| ((v >> shift) & 0x1FF) as f32 * scale;
    Vec3::new(m(0), m(9), m(18))
}

/// A power-of-two scale that brings a cache's values into the RGB9E5 range with the
/// largest one near 2¹⁵, so that both very bright (suns) and dim scenes keep full
/// precision. Stored with the cache.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Rgb9e5Scale {
    /// Stored values are value · 2^-shift.
    pub shift: i32,
}

impl Rgb9e5Scale {
    /// The scale for values up to `max` (a non-positive or non-finite `max` gives shift 0).
    pub fn for_max(max: f32) -> Self {
        if !(max.is_finite() && max > 0.0) {
            return Self { shift: 0 };
        }
        Self {
            shift: (max.log2().ceil() as i32 - 15).clamp(-60, 60),
        }
    }

    #[inline]
    pub fn pack(&self, c: Vec3) -> u32 {
        pack(c * 2f32.powi(-self.shift))
    }

    #[inline]
    pub fn unpack(&self, v: u32) -> Vec3 {
        unpack(v) * 2f32.powi(self.shift)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_error_is_bounded_by_largest_channel() {
        let mut x = 0x1234_5678u32;
        for _ in 0..100_000 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            let f = |k: u32| ((x.rotate_left(k) & 0xFFFF) as f32 / 65536.0).powi(3) * 1000.0;
            let c = Vec3::new(f(0), f(11), f(22));
            let back = unpack(pack(c));
            let bound = c.max_element() / 512.0 * 1.0001 + 1e-30;
            assert!((back - c).abs().max_element() <= bound, "{c} -> {back}");
        }
    }

    #[test]
    fn edge_values() {
        assert_eq!(pack(Vec3::ZERO), 0);
        assert_eq!(unpack(pack(Vec3::new(-1.0, f32::NAN, 0.0))), Vec3::ZERO);
        let big = unpack(pack(Vec3::splat(1e9)));
        assert_eq!(big, Vec3::splat(RGB9E5_MAX));
        // Rounding carry: just below a power of two.
        let c = Vec3::new(0.99999, 0.0, 0.0);
        assert!((unpack(pack(c)).x - 1.0).abs() < 1e-3);
        let s = Rgb9e5Scale::for_max(1e7);
        let v = Vec3::new(1e7, 5e6, 1.0);
        let back = s.unpack(s.pack(v));
        assert!((back - v).abs().max_element() <= 1e7 / 512.0);
    }
}
