//! A [`Scene`] flattened into world-space triangles (structure of arrays) with its BVH:
//! what the path tracer and every surface cache read.

use crate::{
    bvh::{Bvh, Hit, SimdLevel},
    light_sampling::LightSampler,
};
use glam::{Vec2, Vec3};
use std::{ops::Range, sync::Arc};
use surfcache_core::{
    AlphaMode, Environment, Instance, Light, Material, Scene, SceneError,
    geometry::{closest_point_barycentric, interpolate, to_world, triangle_area, triangle_point},
    sampling::{Distribution1D, Rng, splitmix64, uniform_hemisphere, uniform_triangle},
};

/// FNV-1a hash of a name, mixed: the stable key of an instance.
pub fn name_key(name: &str) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for b in name.bytes() {
        h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
    }
    splitmix64(h)
}

/// Spawned rays start this fraction of the scene diagonal above the surface, along the
/// geometric normal of the side they leave (self-intersection avoidance that scales with
/// the scene; far above both float precision in canonical space and obvhs' node epsilon).
pub const SPAWN_OFFSET: f32 = 2e-5;

/// Query points farther than this fraction of the diagonal from every surface are not on
/// the scene (docs/cli.md, `query`).
pub const SURFACE_TOLERANCE: f32 = 1e-4;

/// A point on one side of a triangle, with the frame irradiance is measured in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    pub position: Vec3,
    pub triangle: u32,
    /// Barycentrics (u, v).
    pub uv: Vec2,
    /// Unit geometric normal μ of the side the point is on.
    pub geometric_normal: Vec3,
    /// Unit shading normal ν on that side (never below the geometric surface).
    pub shading_normal: Vec3,
}

/// World-space triangles in structure-of-arrays form, their materials, the lights and
/// environment, and the BVH over them.
///
/// The fields are private so that they stay consistent: every per-triangle array has
/// [`Self::triangle_count`] entries (`uv1` has them too, or none when no mesh has
/// TEXCOORD_1), every per-instance array one entry per instance, the BVH is built over
/// `positions`, and the light sampler is collected from `materials` and `environment`.
/// [`Self::new`] is the only constructor; the accessors below read the arrays.
pub struct TracedScene {
    bvh: Bvh,
    /// Corner positions per triangle (front face counter-clockwise, even under mirroring).
    positions: Vec<[Vec3; 3]>,
    /// Corner shading normals μ_A, μ_B, μ_C per triangle (world space, unit).
    normals: Vec<[Vec3; 3]>,
    /// Unit front-face geometric normal per triangle.
    geometric_normals: Vec<Vec3>,
    /// TEXCOORD_0 per corner (zero when the mesh has none).
    uv0: Vec<[Vec2; 3]>,
    /// TEXCOORD_1 (lightmap layout) per corner, for instances whose mesh has it; empty
    /// when no mesh has one (see `has_uv1`).
    uv1: Vec<[Vec2; 3]>,
    /// Whether each instance's mesh has TEXCOORD_1.
    has_uv1: Vec<bool>,
    /// Index into `materials` per triangle.
    material: Vec<u32>,
    /// Mesh vertex index of each corner (in the corner order above).
    vertex_indices: Vec<[u32; 3]>,
    /// Instance each triangle came from, and its index inside that instance's mesh.
    instance: Vec<u32>,
    local_triangle: Vec<u32>,
    /// Triangle range of each instance.
    instance_triangles: Vec<Range<u32>>,
    /// Name of each instance.
    instance_names: Vec<String>,
    /// A stable 64-bit identity of each instance (a hash of its name), for keying random
    /// streams so that results do not depend on instance order.
    instance_keys: Vec<u64>,
    /// Whether an instance's transform mirrors: its triangles' corners B and C are then
    /// swapped relative to the mesh (to keep the front face counter-clockwise).
    mirrored: Vec<bool>,
    materials: Vec<Arc<Material>>,
    /// Metres per texel of each material's albedo texture (level 0), over the surfaces it
    /// covers: √(world area / texel area) summed over its triangles; 0 without one.
    albedo_texel_size: Vec<f32>,
    lights: Vec<Light>,
    environment: Environment,
    /// Emitters and environment for next-event estimation.
    light_sampler: LightSampler,
    /// Whether any material is alpha-masked (then hits are filtered through the mask).
    has_masks: bool,
    diagonal: f32,
}

impl TracedScene {
    /// Flattens `scene` into world space and builds the BVH.
    pub fn new(scene: &Scene) -> Result<Self, SceneError> {
        scene.validate()?;
        let n = scene.triangle_count();
        let instances = scene.instances.len();
        let mut s = TracedScene {
            bvh: Bvh::build(&[]),
            positions: Vec::with_capacity(n),
            normals: Vec::with_capacity(n),
            vertex_indices: Vec::with_capacity(n),
            geometric_normals: Vec::with_capacity(n),
            uv0: Vec::with_capacity(n),
            uv1: Vec::new(),
            has_uv1: Vec::with_capacity(instances),
            material: Vec::with_capacity(n),
            instance: Vec::with_capacity(n),
            local_triangle: Vec::with_capacity(n),
            instance_triangles: Vec::with_capacity(instances),
            instance_names: Vec::with_capacity(instances),
            instance_keys: Vec::with_capacity(instances),
            mirrored: Vec::with_capacity(instances),
            materials: Vec::new(),
            albedo_texel_size: Vec::new(),
            lights: scene.lights.clone(),
            environment: scene.environment.clone(),
            light_sampler: LightSampler::default(),
            has_masks: false,
            diagonal: 1.0,
        };
        let any_uv1 = scene.instances.iter().any(|i| !i.mesh.uv1.is_empty());
        for (k, inst) in scene.instances.iter().enumerate() {
            s.push_instance(k as u32, inst, any_uv1);
        }
        if s.positions.is_empty() {
            return Err(SceneError::Empty);
        }
        s.has_masks = s
            .materials
            .iter()
            .any(|m| matches!(m.alpha_mode, AlphaMode::Mask(_)));
        s.albedo_texel_size = s.albedo_texel_sizes();
        s.bvh = Bvh::build(&s.positions);
        let masked: Vec<bool> = s
            .materials
            .iter()
            .map(|m| matches!(m.alpha_mode, AlphaMode::Mask(_)))
            .collect();
        s.bvh
            .filter_only(|t| masked[s.material[t as usize] as usize]);
        s.diagonal = s.bvh.scene_diagonal();
        s.light_sampler = LightSampler::new(&s);
        Ok(s)
    }

    /// Appends instance `k`'s triangles in world space (those degenerate after the
    /// transformation are skipped), and its per-instance entries.
    fn push_instance(&mut self, k: u32, inst: &Instance, any_uv1: bool) {
        let material = match self
            .materials
            .iter()
            .position(|m| Arc::ptr_eq(m, &inst.material))
        {
            Some(i) => i,
            None => {
                self.materials.push(inst.material.clone());
                self.materials.len() - 1
            }
        } as u32;
        let normal_matrix = inst.transform.matrix3.inverse().transpose();
        // A mirroring transform reverses the winding; swap B and C to keep the front face.
        let mirrored = inst.transform.matrix3.determinant() < 0.0;
        self.mirrored.push(mirrored);
        self.instance_names.push(inst.name.clone());
        self.instance_keys.push(name_key(&inst.name));
        let mesh = &inst.mesh;
        let start = self.positions.len() as u32;
        self.has_uv1.push(!mesh.uv1.is_empty());
        for (t, tri) in mesh.indices.iter().enumerate() {
            let idx = if mirrored {
                [tri[0], tri[2], tri[1]]
            } else {
                *tri
            };
            let p = idx.map(|i| inst.transform.transform_point3(mesh.positions[i as usize]));
            let geo = (p[1] - p[0]).cross(p[2] - p[0]);
            let Some(geo) = geo.try_normalize() else {
                continue; // degenerate after transformation
            };
            self.positions.push(p);
            self.vertex_indices.push(idx);
            self.geometric_normals.push(geo);
            self.normals.push(idx.map(|i| {
                let n = (normal_matrix * mesh.normals[i as usize]).normalize_or(geo);
                // The normal function must keep ⟨μ_X, μ⟩ > 0 (docs/design.md, Physics).
                if n.dot(geo) > 0.0 { n } else { geo }
            }));
            self.uv0.push(if mesh.uv0.is_empty() {
                [Vec2::ZERO; 3]
            } else {
                idx.map(|i| mesh.uv0[i as usize])
            });
            if any_uv1 {
                self.uv1.push(if mesh.uv1.is_empty() {
                    [Vec2::ZERO; 3]
                } else {
                    idx.map(|i| mesh.uv1[i as usize])
                });
            }
            self.material.push(material);
            self.instance.push(k);
            self.local_triangle.push(t as u32);
        }
        self.instance_triangles
            .push(start..self.positions.len() as u32);
    }

    /// `albedo_texel_size` of every material: √(Σ world area / Σ texel area) over its
    /// triangles, the texel area being the UV0 area times the texture's texels.
    fn albedo_texel_sizes(&self) -> Vec<f32> {
        let mut sums = vec![(0.0f64, 0.0f64); self.materials.len()];
        for (t, &m) in self.material.iter().enumerate() {
            let Some(texture) = &self.materials[m as usize].albedo_texture else {
                continue;
            };
            let [a, b, c] = self.positions[t];
            let [u, v, w] = self.uv0[t];
            let texels = texture.width() as f64 * texture.height() as f64;
            sums[m as usize].0 += 0.5 * (b - a).cross(c - a).length() as f64;
            sums[m as usize].1 += 0.5 * ((v - u).perp_dot(w - u) as f64).abs() * texels;
        }
        sums.iter()
            .map(|&(world, texel)| {
                if texel > 0.0 {
                    (world / texel).sqrt() as f32
                } else {
                    0.0
                }
            })
            .collect()
    }

    /// Albedo at barycentrics-mapped `uv0` of triangle `t`, averaged over about `footprint`
    /// metres: the texture level whose texels are at most that wide
    /// ([`Material::albedo_at_level`], level ⌊log₂(footprint / texel size)⌋). A gather
    /// reads ρ · E at a hit from a cache whose E is smooth at that scale, so
    /// ∫ ρ E = ∫ ρ̄ E up to the covariance of ρ with E's curvature inside the footprint,
    /// while the full-resolution texture would cost a cache miss per hit (docs/design.md,
    /// Gathering).
    #[inline]
    pub fn albedo_over(&self, t: u32, uv0: Vec2, footprint: f32) -> Vec3 {
        let m = self.material[t as usize] as usize;
        let ratio = footprint / self.albedo_texel_size[m];
        // ⌊log₂ ratio⌋ from the exponent bits (ratio ≥ 2 is a normal float).
        let level = if (2.0..f32::INFINITY).contains(&ratio) {
            ((ratio.to_bits() >> 23) - 127) as usize
        } else {
            0
        };
        self.materials[m].albedo_at_level(uv0, level)
    }

    /// The BVH over [`Self::positions`].
    #[inline]
    pub fn bvh(&self) -> &Bvh {
        &self.bvh
    }

    /// Makes the BVH traversal run with `level` (for tests and benchmarks: every level
    /// gives the same answers); see [`Bvh::set_simd_level`].
    #[doc(hidden)]
    pub fn set_simd_level(&mut self, level: SimdLevel) -> bool {
        self.bvh.set_simd_level(level)
    }

    /// Corner positions per triangle (front face counter-clockwise, even under mirroring).
    #[inline]
    pub fn positions(&self) -> &[[Vec3; 3]] {
        &self.positions
    }

    /// Corner shading normals μ_A, μ_B, μ_C per triangle (world space, unit).
    #[inline]
    pub fn normals(&self) -> &[[Vec3; 3]] {
        &self.normals
    }

    /// Unit front-face geometric normal μ per triangle.
    #[inline]
    pub fn geometric_normals(&self) -> &[Vec3] {
        &self.geometric_normals
    }

    /// TEXCOORD_0 per corner (zero when the mesh has none).
    #[inline]
    pub fn uv0(&self) -> &[[Vec2; 3]] {
        &self.uv0
    }

    /// TEXCOORD_1 (lightmap layout) per corner, zero for instances whose mesh has none
    /// (see [`Self::has_uv1`]); empty when no mesh has one.
    #[inline]
    pub fn uv1(&self) -> &[[Vec2; 3]] {
        &self.uv1
    }

    /// Whether each instance's mesh has TEXCOORD_1.
    #[inline]
    pub fn has_uv1(&self) -> &[bool] {
        &self.has_uv1
    }

    /// Index into [`Self::materials`] per triangle.
    #[inline]
    pub fn material(&self) -> &[u32] {
        &self.material
    }

    /// Mesh vertex index of each corner per triangle (in the corner order of
    /// [`Self::positions`]).
    #[inline]
    pub fn vertex_indices(&self) -> &[[u32; 3]] {
        &self.vertex_indices
    }

    /// Instance each triangle came from.
    #[inline]
    pub fn instance(&self) -> &[u32] {
        &self.instance
    }

    /// Index of each triangle inside its instance's mesh.
    #[inline]
    pub fn local_triangle(&self) -> &[u32] {
        &self.local_triangle
    }

    /// Triangle range of each instance.
    #[inline]
    pub fn instance_triangles(&self) -> &[Range<u32>] {
        &self.instance_triangles
    }

    /// Name of each instance.
    #[inline]
    pub fn instance_names(&self) -> &[String] {
        &self.instance_names
    }

    /// A stable 64-bit identity of each instance (a hash of its name, [`name_key`]), for
    /// keying random streams so that results do not depend on instance order.
    #[inline]
    pub fn instance_keys(&self) -> &[u64] {
        &self.instance_keys
    }

    /// Whether each instance's transform mirrors: its triangles' corners B and C are then
    /// swapped relative to the mesh (to keep the front face counter-clockwise).
    #[inline]
    pub fn mirrored(&self) -> &[bool] {
        &self.mirrored
    }

    /// The distinct materials, indexed by [`Self::material`].
    #[inline]
    pub fn materials(&self) -> &[Arc<Material>] {
        &self.materials
    }

    /// The punctual lights.
    #[inline]
    pub fn lights(&self) -> &[Light] {
        &self.lights
    }

    /// The environment (radiance arriving from infinitely far away).
    #[inline]
    pub fn environment(&self) -> &Environment {
        &self.environment
    }

    /// Emitters and environment for next-event estimation.
    #[inline]
    pub fn light_sampler(&self) -> &LightSampler {
        &self.light_sampler
    }

    /// A stable identity for triangle `t`: its instance's key and its index in the mesh.
    #[inline]
    pub fn triangle_key(&self, t: u32) -> u64 {
        let i = self.instance[t as usize] as usize;
        splitmix64(self.instance_keys[i] ^ self.local_triangle[t as usize] as u64)
    }

    /// The distribution of triangles by area, for drawing uniformly distributed surface
    /// points with [`Self::sample_surface`].
    pub fn area_distribution(&self) -> Distribution1D {
        let areas: Vec<f32> = self
            .positions
            .iter()
            .map(|&[a, b, c]| triangle_area(a, b, c))
            .collect();
        Distribution1D::new(&areas)
    }

    /// A point distributed uniformly by area over all triangles (`areas` from
    /// [`Self::area_distribution`]; `select` picks the triangle, `u` the point in it).
    pub fn sample_surface(
        &self,
        areas: &Distribution1D,
        select: f32,
        u: Vec2,
        front: bool,
    ) -> SurfacePoint {
        let (t, _, _) = areas.sample(select);
        self.surface_point(t as u32, uniform_triangle(u), front)
    }

    /// Number of triangles traced.
    pub fn triangle_count(&self) -> usize {
        self.positions.len()
    }

    /// Diagonal of the scene's bounding box (world units).
    pub fn diagonal(&self) -> f32 {
        self.diagonal
    }

    /// Distance spawned rays start above their surface: [`SPAWN_OFFSET`] × diagonal.
    pub fn spawn_offset(&self) -> f32 {
        SPAWN_OFFSET * self.diagonal
    }

    /// Material of triangle `t`.
    #[inline]
    pub fn material_of(&self, t: u32) -> &Material {
        &self.materials[self.material[t as usize] as usize]
    }

    /// TEXCOORD_0 at barycentrics `uv` of triangle `t`.
    #[inline]
    pub fn uv0_at(&self, t: u32, uv: Vec2) -> Vec2 {
        let [a, b, c] = self.uv0[t as usize];
        interpolate(a, b, c, uv)
    }

    /// Alpha-mask test of a candidate hit.
    #[inline]
    fn opaque_at(&self, t: u32, uv: Vec2) -> bool {
        self.material_of(t).is_opaque_at(self.uv0_at(t, uv))
    }

    /// Closest surface along `origin + t·direction` for `t ∈ [0, tmax]`, honouring alpha masks.
    #[inline]
    pub fn closest_hit(&self, origin: Vec3, direction: Vec3, tmax: f32) -> Option<Hit> {
        if self.has_masks {
            let accept = |t: u32, uv: Vec2| self.opaque_at(t, uv);
            self.bvh
                .closest_hit_filtered(origin, direction, 0.0, tmax, Some(&accept))
        } else {
            self.bvh.closest_hit(origin, direction, 0.0, tmax)
        }
    }

    /// Visibility V: whether anything blocks `origin + t·direction` for `t ∈ [0, tmax]`.
    #[inline]
    pub fn occluded(&self, origin: Vec3, direction: Vec3, tmax: f32) -> bool {
        if self.has_masks {
            let accept = |t: u32, uv: Vec2| self.opaque_at(t, uv);
            self.bvh
                .occluded_filtered(origin, direction, 0.0, tmax, Some(&accept))
        } else {
            self.bvh.occluded(origin, direction, 0.0, tmax)
        }
    }

    /// The point at barycentrics `uv` of triangle `t`, on the front side (`front = true`)
    /// or the back side. The shading normal is ν(u,v) = normalize(wμ_A + uμ_B + vμ_C)
    /// (docs/design.md, Physics), flipped to the side, and replaced by μ where it would point below
    /// the geometric surface.
    #[inline]
    pub fn surface_point(&self, t: u32, uv: Vec2, front: bool) -> SurfacePoint {
        let i = t as usize;
        let [a, b, c] = self.positions[i];
        let sign = if front { 1.0 } else { -1.0 };
        let geo = self.geometric_normals[i] * sign;
        let [na, nb, nc] = self.normals[i];
        let shading = interpolate(na, nb, nc, uv) * sign;
        let shading = match shading.try_normalize() {
            Some(n) if n.dot(geo) > 1e-4 => n,
            _ => geo,
        };
        SurfacePoint {
            position: triangle_point(a, b, c, uv),
            triangle: t,
            uv,
            geometric_normal: geo,
            shading_normal: shading,
        }
    }

    /// The surface point a ray hit, on the side the ray arrived from.
    #[inline]
    pub fn hit_point(&self, hit: &Hit, direction: Vec3) -> SurfacePoint {
        let front = self.geometric_normals[hit.triangle as usize].dot(direction) < 0.0;
        self.surface_point(hit.triangle, hit.uv, front)
    }

    /// Origin for rays leaving `p`: moved at least [`Self::spawn_offset`] inside its
    /// triangle's edges (to the incentre for triangles too small for that), then lifted
    /// the same distance along the geometric normal of its side. The edge step is the
    /// thesis' leak guard: a wall that meets the triangle's edge is never closer to the
    /// origin than the offset, so rays cannot slip past it.
    ///
    /// A point closer than the offset to an edge moves to the nearest point of the
    /// triangle inset by the offset (the image of the triangle under the homothety about
    /// the incentre I with ratio (r − offset)/r, r the inradius): straight off a single
    /// edge, and into the inset corner near a vertex, where stepping off one edge after
    /// the other would leave acute corners (< 60°) outside the neighbouring edge.
    #[inline]
    pub fn spawn_origin(&self, p: &SurfacePoint) -> Vec3 {
        let off = self.spawn_offset();
        let [a, b, c] = self.positions[p.triangle as usize];
        let mu = self.geometric_normals[p.triangle as usize];
        let (la, lb, lc) = ((c - b).length(), (a - c).length(), (b - a).length());
        let twice_area = (b - a).cross(c - a).length();
        let perimeter = la + lb + lc;
        let inradius = twice_area / perimeter;
        let incentre = (a * la + b * lb + c * lc) / perimeter;
        let mut q = p.position;
        if inradius <= 2.0 * off {
            q = incentre;
        } else {
            let near_edge = [(a, b), (b, c), (c, a)].into_iter().any(|(e0, e1)| {
                // In-plane normal of the edge pointing into the (counter-clockwise) triangle.
                let inward = mu.cross(e1 - e0).normalize();
                (q - e0).dot(inward) < off
            });
            if near_edge {
                let k = (inradius - off) / inradius;
                let [a2, b2, c2] = [a, b, c].map(|x| incentre + (x - incentre) * k);
                q = triangle_point(a2, b2, c2, closest_point_barycentric(q, a2, b2, c2));
            }
        }
        q + p.geometric_normal * off
    }

    /// Whether `p` lies in open air: none of `rays` uniform directions over its side's
    /// hemisphere (from its spawn origin, drawn from `rng`) meets the back of a
    /// single-sided surface. A point inside a solid (a floor under a block) sees no light
    /// and caches fill it from its neighbours by convention, so comparisons of two bakes
    /// leave such points out.
    pub fn in_open_air(&self, p: &SurfacePoint, rays: u32, rng: &mut Rng) -> bool {
        let origin = self.spawn_origin(p);
        (0..rays).all(|_| {
            let d = to_world(uniform_hemisphere(rng.next_vec2()), p.geometric_normal);
            self.closest_hit(origin, d, f32::INFINITY).is_none_or(|h| {
                self.geometric_normals[h.triangle as usize].dot(d) < 0.0
                    || self.material_of(h.triangle).double_sided
            })
        })
    }

    /// The surface a query point `x` with normal `n` lies on (docs/cli.md, `query`): among
    /// triangles within [`SURFACE_TOLERANCE`] × diagonal of `x`, the one whose geometric
    /// normal is most nearly parallel to `n` (either orientation), then whose plane passes
    /// closest to `x`; the side is the one whose geometric normal points along `n`.
    /// `None` when no surface is that close.
    pub fn locate(&self, x: Vec3, n: Vec3) -> Option<SurfacePoint> {
        let radius = SURFACE_TOLERANCE * self.diagonal;
        let n = n.normalize_or_zero();
        // (parallelism, plane distance, point distance, triangle, uv)
        let mut best: Option<(f32, f32, f32, u32, Vec2)> = None;
        self.bvh.triangles_near(x, radius, |t| {
            let [a, b, c] = self.positions[t as usize];
            let uv = closest_point_barycentric(x, a, b, c);
            let distance = (triangle_point(a, b, c, uv) - x).length();
            if distance > radius {
                return;
            }
            let mu = self.geometric_normals[t as usize];
            let parallel = mu.dot(n).abs();
            let plane = mu.dot(x - a).abs();
            let better = match best {
                None => true,
                Some((bp, bd, bx, bt, _)) => {
                    if (parallel - bp).abs() > 1e-3 {
                        parallel > bp
                    } else if (plane - bd).abs() > 1e-7 * self.diagonal {
                        plane < bd
                    } else if distance != bx {
                        distance < bx
                    } else {
                        t < bt
                    }
                }
            };
            if better {
                best = Some((parallel, plane, distance, t, uv));
            }
        });
        let (_, _, _, t, uv) = best?;
        let front = self.geometric_normals[t as usize].dot(n) >= 0.0;
        Some(self.surface_point(t, uv, front))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Affine3A;
    use surfcache_core::Mesh;

    /// Every spawn origin lies at least the offset inside all three edges, also at acute
    /// corners (the leak guard).
    #[test]
    fn spawn_origins_keep_the_offset_from_every_edge() {
        // Corners of 10°, 45°, 90°, 135° and an obtuse sliver-free triangle.
        let triangles = [
            [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 0.176, 0.0)],
            [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0)],
            [
                Vec3::ZERO,
                Vec3::new(2.0, 0.0, 0.3),
                Vec3::new(-0.5, 0.5, 0.0),
            ],
        ];
        for tri in triangles {
            let mesh = Mesh::new("t", tri.to_vec(), vec![[0, 1, 2]]);
            let scene = Scene {
                instances: vec![Instance {
                    name: "t".into(),
                    mesh: Arc::new(mesh),
                    material: Arc::new(Material::default()),
                    transform: Affine3A::IDENTITY,
                }],
                ..Default::default()
            };
            let s = TracedScene::new(&scene).unwrap();
            let off = s.spawn_offset();
            let [a, b, c] = s.positions[0];
            let mu = s.geometric_normals[0];
            for uv in [
                Vec2::ZERO,
                Vec2::X,
                Vec2::Y,
                Vec2::new(0.5, 0.0),
                Vec2::new(0.5, 0.5),
                Vec2::new(0.0, 0.5),
                Vec2::new(1e-6, 1e-6),
                Vec2::splat(1.0 / 3.0),
            ] {
                for front in [true, false] {
                    let p = s.surface_point(0, uv, front);
                    let o = s.spawn_origin(&p);
                    for (e0, e1) in [(a, b), (b, c), (c, a)] {
                        let inward = mu.cross(e1 - e0).normalize();
                        let d = (o - e0).dot(inward);
                        assert!(d >= 0.99 * off, "{tri:?} {uv}: {d} < {off}");
                    }
                    let lift = (o - p.position).dot(p.geometric_normal);
                    assert!((lift - off).abs() < 1e-3 * off + 1e-7);
                }
            }
        }
    }
}
