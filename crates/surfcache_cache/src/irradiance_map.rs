//! Per-triangle adaptive irradiance maps (DESIGN.md §3.2). (In progress.)
