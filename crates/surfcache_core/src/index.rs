//! The "no index" sentinel of index arrays.
//!
//! surfcache keeps its relations as flat `u32` index arrays: the triangle that owns a
//! texel, the chart of a triangle, the counterpart of a triangle in a scene before an
//! edit, the emitter slot of a triangle. Where an entry has no index, it holds
//! [`NO_INDEX`]; crates may name it after their relation (`surfcache_cache::UNMAPPED`).

/// The entry of an index array that refers to nothing (`u32::MAX`, never a valid index).
pub const NO_INDEX: u32 = u32::MAX;
