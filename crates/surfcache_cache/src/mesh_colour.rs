//! Mesh-colour textures: per-triangle barycentric grids laid out as texel blocks so that bilinear filtering reproduces their interpolation (DESIGN.md §4). (In progress.)
