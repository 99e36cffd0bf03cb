//! Vertex lighting (docs/design.md, Caches): E at mesh vertices, interpolated with barycentrics.
//!
//! The baseline cache. Every unique (instance, mesh vertex, side) gets one estimate at a
//! [`SampleSite::Vertex`]: exactly on the vertex, about its vertex normal, rays lifted
//! along that normal only. One round. A lookup interpolates the triangle's three vertex
//! values, `E = (1−u−v)E_A + u E_B + v E_C`.
//!
//! **It leaks, by design.** A vertex where a wall meets a floor lies on both surfaces:
//! its rays start on the wall's plane, so half of them pass the wall's edge and see what
//! lies behind it, and interpolation then spreads that light over the whole triangle.
//! Cheap and smooth on finely tessellated meshes, wrong near every crease; the irradiance
//! maps' leak guard exists because of this, and the tests show both.
//!
//! **Keys.** A vertex's random stream is keyed by its instance's stable key, its mesh
//! vertex index and the side, so every triangle sharing the vertex reads one estimate.
//!
//! **Storage.** Three half floats (6 bytes, [`crate::stored_rgb`]) per (vertex, side) — two slots per vertex, the back one
//! zero where the back side is not baked — plus a `u32` vertex index per triangle corner:
//! `cache_bytes = 6·2·vertices + 12·triangles + 4` (the last 4: the scale). Buried
//! estimates (`back_face_share > 0.5`) are counted in [`CacheStats::buried`] but kept: the
//! baseline is shown as it is.
//!
//! Published as mesh-colour textures of order-1 blocks ([`crate::mesh_colour`]): 2×2
//! texels per triangle, the fourth extrapolated, so bilinear filtering reproduces the
//! barycentric interpolation exactly.

use crate::{
    CacheStats, Diagnostic, IrradianceTexture, Method, Prior, SamplePoint, SampleSite,
    SurfaceCache, UNMAPPED,
    irradiance_map::EstimateTotals,
    mesh_colour,
    stored_rgb::{STORED_RGB_BYTES, StoreScale, StoredRgb},
};
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};
use surfcache_core::index::NO_INDEX;
use surfcache_core::{geometry::interpolate, sampling::splitmix64};
use surfcache_trace::{Estimate, TracedScene};

/// Share of back-face first hits above which a vertex estimate counts as buried.
pub const BURIED_THRESHOLD: f32 = 0.5;

/// What vertex lighting bakes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct VertexLightingSettings {
    /// Bake the back side of every vertex (true), or only of instances whose material is
    /// double-sided; lookups on a side that was not baked return zero. Default true.
    pub both_sides: bool,
}

impl Default for VertexLightingSettings {
    fn default() -> Self {
        Self { both_sides: true }
    }
}

/// The random-stream key of a vertex: (instance key, mesh vertex index, side).
#[inline]
pub fn vertex_key(instance_key: u64, vertex: u32, front: bool) -> u64 {
    splitmix64(
        instance_key ^ splitmix64(((vertex as u64) << 1 | (!front) as u64) ^ 0x7e47_0000_0000_0000),
    )
}

/// Irradiance at mesh vertices (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VertexLighting {
    settings: VertexLightingSettings,
    /// Unique vertex of each traced triangle corner. Vertices are numbered in order of
    /// first appearance (triangle by triangle, corner by corner).
    corners: Vec<[u32; 3]>,
    /// Stored irradiance per vertex slot `2·vertex + side` (side 0 = front).
    packed: Vec<StoredRgb>,
    /// Hemisphere samples per vertex slot (diagnostics only).
    #[serde(default)]
    sample_counts: Vec<u32>,
    scale: StoreScale,
    totals: EstimateTotals,
    buried: u64,
    /// Whether the one round was asked for.
    requested: bool,
    /// Values before an edit, per slot, for an incremental re-bake ([`SurfaceCache::remap`]).
    #[serde(skip)]
    priors: Vec<Option<Vec3>>,
}

impl VertexLighting {
    /// Unbaked vertex lighting for `scene`: unique vertices are (instance, mesh vertex
    /// index) pairs of the traced triangles.
    pub fn new(scene: &TracedScene, settings: VertexLightingSettings) -> Self {
        let mut corners = vec![[0u32; 3]; scene.triangle_count()];
        let mut next = 0u32;
        let mut map: Vec<u32> = Vec::new();
        for range in scene.instance_triangles() {
            let (lo, hi) = (range.start as usize, range.end as usize);
            let largest = scene.vertex_indices()[lo..hi]
                .iter()
                .flatten()
                .max()
                .map_or(0, |&v| v as usize + 1);
            map.clear();
            map.resize(largest, NO_INDEX);
            for (ids, vertices) in corners[lo..hi]
                .iter_mut()
                .zip(&scene.vertex_indices()[lo..hi])
            {
                for (id, &v) in ids.iter_mut().zip(vertices) {
                    let slot = &mut map[v as usize];
                    if *slot == NO_INDEX {
                        *slot = next;
                        next += 1;
                    }
                    *id = *slot;
                }
            }
        }
        Self {
            settings,
            corners,
            packed: vec![[0; 3]; 2 * next as usize],
            sample_counts: vec![0; 2 * next as usize],
            scale: StoreScale::default(),
            totals: EstimateTotals::default(),
            buried: 0,
            requested: false,
            priors: Vec::new(),
        }
    }

    /// Number of unique vertices.
    pub fn vertex_count(&self) -> usize {
        self.packed.len() / 2
    }

    /// Whether the back side of triangle `t`'s vertices is baked.
    fn bakes_back(&self, scene: &TracedScene, t: u32) -> bool {
        self.settings.both_sides || scene.material_of(t).double_sided
    }

    /// Stored E of corner `corner` of `triangle` on one side.
    #[inline]
    pub fn corner_value(&self, triangle: u32, corner: usize, front: bool) -> Vec3 {
        let v = self.corners[triangle as usize][corner] as usize;
        self.scale.unpack(self.packed[2 * v + (!front) as usize])
    }
}

impl SurfaceCache for VertexLighting {
    fn method(&self) -> Method {
        Method::Vertex
    }

    fn next_round(&mut self, scene: &TracedScene, points: &mut Vec<SamplePoint>) {
        if self.requested {
            return;
        }
        self.requested = true;
        // Vertices were numbered in order of first appearance: the first corner that
        // shows vertex `next` represents it.
        let mut next = 0u32;
        for (t, ids) in self.corners.iter().enumerate() {
            for (k, &id) in ids.iter().enumerate() {
                if id != next {
                    continue;
                }
                next += 1;
                let t = t as u32;
                let instance_key = scene.instance_keys()[scene.instance()[t as usize] as usize];
                let vertex = scene.vertex_indices()[t as usize][k];
                for front in [true, false] {
                    if front || self.bakes_back(scene, t) {
                        points.push(SamplePoint {
                            site: SampleSite::Vertex {
                                triangle: t,
                                corner: k as u8,
                                front,
                            },
                            key: vertex_key(instance_key, vertex, front),
                            prior: self
                                .priors
                                .get(2 * id as usize + (!front) as usize)
                                .copied()
                                .flatten()
                                .map(Prior::Estimated),
                            budget: None,
                            cap_share: 1.0,
                        });
                    }
                }
            }
        }
    }

    fn finish_round(
        &mut self,
        _scene: &TracedScene,
        points: &[SamplePoint],
        estimates: &[Estimate],
    ) {
        assert_eq!(points.len(), estimates.len());
        let mut values = vec![Vec3::ZERO; self.packed.len()];
        for (p, e) in points.iter().zip(estimates) {
            let SampleSite::Vertex {
                triangle,
                corner,
                front,
            } = p.site
            else {
                panic!("vertex lighting only asks for vertex sites");
            };
            let v = self.corners[triangle as usize][corner as usize] as usize;
            values[2 * v + (!front) as usize] = e.value;
            self.sample_counts[2 * v + (!front) as usize] = e.samples;
            self.totals.add(e);
            self.buried += (e.back_face_share > BURIED_THRESHOLD) as u64;
        }
        self.priors = Vec::new();
        let max = values.iter().fold(0.0f32, |m, v| m.max(v.max_element()));
        self.scale = StoreScale::for_max(max);
        for (p, v) in self.packed.iter_mut().zip(&values) {
            *p = self.scale.pack(*v);
        }
    }

    /// Back faces only when both sides are baked (the back of a double-sided material in
    /// a front-only bake is baked too, but not told apart here: a gathering path traces
    /// on through it, which is unbiased).
    fn holds(&self, _triangle: u32, front: bool) -> bool {
        front || self.settings.both_sides
    }

    /// E = (1−u−v)E_A + u E_B + v E_C.
    fn lookup(&self, triangle: u32, uv: Vec2, front: bool) -> Vec3 {
        let [a, b, c] = [0, 1, 2].map(|k| self.corner_value(triangle, k, front));
        interpolate(a, b, c, uv)
    }

    fn remap(&self, old: &TracedScene, new: &TracedScene, triangle_map: &[u32]) -> Self {
        let mut fresh = Self::new(new, self.settings);
        let mut priors = vec![None; fresh.packed.len()];
        for (t, ids) in fresh.corners.iter().enumerate() {
            let t_old = triangle_map[t];
            if t_old == UNMAPPED {
                continue;
            }
            for (k, &id) in ids.iter().enumerate() {
                // The same mesh vertex; its corner slot may differ if mirroring changed.
                let vertex = new.vertex_indices()[t][k];
                let Some(k_old) = old.vertex_indices()[t_old as usize]
                    .iter()
                    .position(|&v| v == vertex)
                else {
                    continue;
                };
                for front in [true, false] {
                    priors[2 * id as usize + (!front) as usize] =
                        Some(self.corner_value(t_old, k_old, front));
                }
            }
        }
        fresh.priors = priors;
        fresh
    }

    fn diagnostic(&self, triangle: u32, uv: Vec2, front: bool) -> Diagnostic {
        // The nearest corner.
        let w = [1.0 - uv.x - uv.y, uv.x, uv.y];
        let k = (0..3).fold(0, |best, k| if w[k] > w[best] { k } else { best });
        let v = self.corners[triangle as usize][k] as usize;
        Diagnostic {
            samples: self.sample_counts[2 * v + (!front) as usize],
            order: None,
        }
    }

    fn stats(&self) -> CacheStats {
        CacheStats {
            cache_bytes: STORED_RGB_BYTES * self.packed.len() as u64
                + 12 * self.corners.len() as u64
                + 4,
            buried: self.buried,
            ..self.totals.stats()
        }
    }

    fn publish(&self, scene: &TracedScene) -> Vec<IrradianceTexture> {
        // Order-1 grids: (0,0), (1,0), (0,1) are corners A, B, C.
        mesh_colour::publish_all(
            scene,
            |_, _| 1,
            |t, front, i, j| self.corner_value(t, (i + 2 * j) as usize, front),
        )
    }
}
