//! Bevy 0.19 links glam 0.32, surfcache glam 0.34: the two crates' vectors and transforms
//! are different types with the same layout, converted here through plain arrays.

use bevy::math as bevy_math;

/// A Bevy vector as surfcache's.
#[inline]
pub fn vec3(v: bevy_math::Vec3) -> glam::Vec3 {
    glam::Vec3::from_array(v.to_array())
}

/// A surfcache vector as Bevy's.
#[inline]
pub fn bevy_vec3(v: glam::Vec3) -> bevy_math::Vec3 {
    bevy_math::Vec3::from_array(v.to_array())
}

/// A Bevy affine transform as surfcache's.
#[inline]
pub fn affine3a(a: bevy_math::Affine3A) -> glam::Affine3A {
    glam::Affine3A::from_cols_array(&a.to_cols_array())
}

/// A surfcache affine transform as Bevy's.
#[inline]
pub fn bevy_affine3a(a: glam::Affine3A) -> bevy_math::Affine3A {
    bevy_math::Affine3A::from_cols_array(&a.to_cols_array())
}
