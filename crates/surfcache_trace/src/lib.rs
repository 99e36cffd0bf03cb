//! obvhs BVH, ray queries and the path tracer for incident radiance.
