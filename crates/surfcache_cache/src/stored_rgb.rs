//! How the caches store irradiance: three IEEE 754 half floats per sample (6 bytes),
//! after one power-of-two scale per cache ([`StoreScale`]) that puts the brightest value
//! near the top of the half-float range.
//!
//! Every channel keeps its own exponent, so each channel is stored to within a relative
//! 2⁻¹¹ ≈ 0.05 % of itself (round to nearest, normal range: 29 binary orders of magnitude
//! below the cache's brightest value; dimmer values lose precision gradually as
//! subnormals). A channel that is a few percent of the others is kept as precisely as
//! the bright ones — unlike a shared-exponent format such as RGB9E5 (4 bytes), whose
//! error of up to 1/512 of the largest channel is 6 % of a channel at 3 % of it.
//! Engines upload the same bits as an `Rgba16Float` texture.

use glam::Vec3;
use half::f16;
use serde::{Deserialize, Serialize};

/// One stored sample: red, green, blue as half-float bits.
pub type StoredRgb = [u16; 3];

/// Two stored values closer than this share of the larger one may differ by rounding
/// alone (one unit in the last place of a half float, 2⁻¹⁰, twice over): an average of
/// stored values stored again, say.
pub const STORED_TOLERANCE: f32 = 1.0 / 512.0;

/// The part of `|a − b|` beyond `share` (at least [`STORED_TOLERANCE`]) of the larger of
/// the two, per channel.
#[inline]
pub fn difference_beyond(a: Vec3, b: Vec3, share: f32) -> Vec3 {
    let share = share.max(STORED_TOLERANCE);
    ((a - b).abs() - share * a.abs().max(b.abs())).max(Vec3::ZERO)
}

/// Bytes of one [`StoredRgb`].
pub const STORED_RGB_BYTES: u64 = 6;

/// The power-of-two scale `2^shift` by which stored values are multiplied back.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StoreScale {
    pub shift: i32,
}

impl StoreScale {
    /// The scale that stores values up to `max` with the brightest at most 2¹⁵ (half
    /// floats reach 65504).
    pub fn for_max(max: f32) -> Self {
        if !(max.is_finite() && max > 0.0) {
            return Self { shift: 0 };
        }
        Self {
            shift: (max.log2().ceil() as i32 - 15).clamp(-100, 100),
        }
    }

    /// Stores `c` (negative and NaN channels as 0, rounded to nearest).
    #[inline]
    pub fn pack(&self, c: Vec3) -> StoredRgb {
        let k = 2f32.powi(-self.shift);
        c.to_array().map(|x| {
            let x = if x > 0.0 { (x * k).min(65504.0) } else { 0.0 };
            f16::from_f32(x).to_bits()
        })
    }

    /// The value stored in `v`.
    #[inline]
    pub fn unpack(&self, v: StoredRgb) -> Vec3 {
        let k = 2f32.powi(self.shift);
        Vec3::from_array(v.map(|b| f16::from_bits(b).to_f32())) * k
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_channel_keeps_its_own_relative_precision() {
        let scale = StoreScale::for_max(1.0e5);
        for c in [
            Vec3::new(1.0e5, 3.0e3, 1.0),
            Vec3::new(0.785, 0.3925, 0.19625),
            // The dimmest channel about 2^-28 of the brightest value: still in the normal range.
            Vec3::new(2.0e-2, 4.0e-4, 1.0e-1),
        ] {
            let back = scale.unpack(scale.pack(c));
            let rel = ((back - c) / c).abs().max_element();
            assert!(rel <= 2f32.powi(-11) * 1.0001, "{c} -> {back}: {rel}");
        }
    }

    #[test]
    fn edge_values() {
        let scale = StoreScale::for_max(4.0);
        assert_eq!(
            scale.unpack(scale.pack(Vec3::new(-1.0, f32::NAN, 0.0))),
            Vec3::ZERO
        );
        let big = scale.unpack(scale.pack(Vec3::splat(4.0)));
        assert_eq!(big, Vec3::splat(4.0));
        assert_eq!(StoreScale::for_max(f32::NAN), StoreScale::default());
    }
}
