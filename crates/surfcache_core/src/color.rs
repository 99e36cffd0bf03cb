//! Linear-RGB colour helpers.

use glam::Vec3;
use std::sync::OnceLock;

/// Relative luminance of linear Rec. 709 RGB: Y = 0.2126 R + 0.7152 G + 0.0722 B.
#[inline]
pub fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// The exact sRGB EOTF (IEC 61966-2-1) of an encoded value in [0, 1]:
/// `c / 12.92` up to 0.04045, `((c + 0.055) / 1.055)^2.4` above.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// [`srgb_to_linear`] of every 8-bit code `v / 255`.
pub fn srgb8_to_linear() -> &'static [f32; 256] {
    static TABLE: OnceLock<[f32; 256]> = OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(|v| srgb_to_linear(v as f32 / 255.0)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_eotf_endpoints_and_knee() {
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
        assert!((srgb_to_linear(0.5) - 0.21404).abs() < 1e-4);
        assert!((srgb_to_linear(0.04045) - 0.04045 / 12.92).abs() < 1e-9);
        let table = srgb8_to_linear();
        assert_eq!((table[0], table[255]), (0.0, srgb_to_linear(1.0)));
        assert_eq!(table[128], srgb_to_linear(128.0 / 255.0));
    }
}
