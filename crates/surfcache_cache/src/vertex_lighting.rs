//! Vertex lighting: E at mesh vertices, barycentric interpolation (DESIGN.md §3.1). (In progress.)
