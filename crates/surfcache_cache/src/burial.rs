//! Whether a sample of a cache (an irradiance-map grid point, a lightmap texel) sees the
//! scene or lies inside geometry, and how a buried one got its value (docs/design.md,
//! Caches). One state per sample, kept only while baking.

/// Burial state of one sample while baking.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) enum Burial {
    /// No estimate yet: a texel owned by no triangle, or not estimated so far.
    #[default]
    Empty,
    /// Estimated in open air: its value is trusted.
    Valid,
    /// Inside geometry (its estimate's rays mostly hit back faces): not trusted, to be filled.
    Buried,
    /// Buried, moved to the visible part of its footprint, waiting for a fresh estimate.
    Moved,
    /// Filled from its neighbours in the fill sweep under way.
    FilledNow,
    /// Filled from its neighbours.
    Filled,
}
