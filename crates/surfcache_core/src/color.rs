//! Linear-RGB colour helpers.

use glam::Vec3;

/// Relative luminance of linear Rec. 709 RGB: Y = 0.2126 R + 0.7152 G + 0.0722 B.
#[inline]
pub fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}
