//! Scene data: primitives p = (Δ, ν, m) grouped into meshes, materials, lights, environment.
//!
//! A [`Mesh`] is one glTF primitive: indexed triangles with one material, vertex normals
//! (the normal function ν of docs/design.md, Physics) and optional UV sets. An [`Instance`] places a
//! mesh in the world with a material. Lights are stored in world space.

use crate::{environment::Environment, geometry};
use glam::{Affine3A, Vec2, Vec3, Vec4};
use std::sync::Arc;

/// Errors in scene data, each naming where it is.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SceneError {
    #[error("mesh '{mesh}': vertex {vertex} has a non-finite position {position:?}")]
    NonFinitePosition {
        mesh: String,
        vertex: usize,
        position: [f32; 3],
    },
    #[error("mesh '{mesh}': vertex {vertex} has a non-finite normal")]
    NonFiniteNormal { mesh: String, vertex: usize },
    #[error("mesh '{mesh}': vertex {vertex} has a non-finite {attribute} {uv:?}")]
    NonFiniteTexcoord {
        mesh: String,
        attribute: &'static str,
        vertex: usize,
        uv: [f32; 2],
    },
    #[error(
        "mesh '{mesh}': triangle {triangle} uses vertex {index} but the mesh has {vertex_count} vertices"
    )]
    IndexOutOfRange {
        mesh: String,
        triangle: usize,
        index: u32,
        vertex_count: usize,
    },
    #[error("mesh '{mesh}': {attribute} has {found} entries for {vertex_count} vertices")]
    AttributeLength {
        mesh: String,
        attribute: &'static str,
        found: usize,
        vertex_count: usize,
    },
    #[error("instance '{instance}': transform is not finite or not invertible")]
    BadTransform { instance: String },
    #[error("the scene has no triangles")]
    Empty,
}

/// Indexed triangles of one material with vertex normals and optional UV sets.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub name: String,
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals μ_X (unit). Computed from the triangles when a file has none.
    pub normals: Vec<Vec3>,
    /// TEXCOORD_0 (material textures); empty when absent.
    pub uv0: Vec<Vec2>,
    /// TEXCOORD_1 (lightmap layout); empty when absent.
    pub uv1: Vec<Vec2>,
    pub indices: Vec<[u32; 3]>,
}

impl Mesh {
    /// A mesh with flat (geometric) normals: vertices are not shared between triangles
    /// that are not coplanar, so the area-weighted normals equal each face normal.
    pub fn new(name: impl Into<String>, positions: Vec<Vec3>, indices: Vec<[u32; 3]>) -> Self {
        let mut mesh = Mesh {
            name: name.into(),
            positions,
            normals: Vec::new(),
            uv0: Vec::new(),
            uv1: Vec::new(),
            indices,
        };
        mesh.compute_normals();
        mesh
    }

    /// Area-weighted vertex normals: μ_X ∝ Σ over adjacent triangles of (B−A)×(C−A).
    pub fn compute_normals(&mut self) {
        let mut normals = vec![Vec3::ZERO; self.positions.len()];
        for tri in &self.indices {
            let [a, b, c] = tri.map(|i| self.positions[i as usize]);
            let n = geometry::triangle_cross(a, b, c);
            for &i in tri {
                normals[i as usize] += n;
            }
        }
        for n in &mut normals {
            *n = n.normalize_or(Vec3::Y);
        }
        self.normals = normals;
    }

    /// Checks that every position, normal and texture coordinate is finite, every index is in
    /// range and every attribute has one entry per vertex.
    pub fn validate(&self) -> Result<(), SceneError> {
        let n = self.positions.len();
        for (vertex, p) in self.positions.iter().enumerate() {
            if !p.is_finite() {
                return Err(SceneError::NonFinitePosition {
                    mesh: self.name.clone(),
                    vertex,
                    position: p.to_array(),
                });
            }
        }
        for (attribute, found) in [
            ("NORMAL", self.normals.len()),
            (
                "TEXCOORD_0",
                if self.uv0.is_empty() {
                    n
                } else {
                    self.uv0.len()
                },
            ),
            (
                "TEXCOORD_1",
                if self.uv1.is_empty() {
                    n
                } else {
                    self.uv1.len()
                },
            ),
        ] {
            if found != n {
                return Err(SceneError::AttributeLength {
                    mesh: self.name.clone(),
                    attribute,
                    found,
                    vertex_count: n,
                });
            }
        }
        if let Some(vertex) = self.normals.iter().position(|v| !v.is_finite()) {
            return Err(SceneError::NonFiniteNormal {
                mesh: self.name.clone(),
                vertex,
            });
        }
        for (attribute, uvs) in [("TEXCOORD_0", &self.uv0), ("TEXCOORD_1", &self.uv1)] {
            if let Some(vertex) = uvs.iter().position(|uv| !uv.is_finite()) {
                return Err(SceneError::NonFiniteTexcoord {
                    mesh: self.name.clone(),
                    attribute,
                    vertex,
                    uv: uvs[vertex].to_array(),
                });
            }
        }
        for (triangle, tri) in self.indices.iter().enumerate() {
            if let Some(&index) = tri.iter().find(|&&i| i as usize >= n) {
                return Err(SceneError::IndexOutOfRange {
                    mesh: self.name.clone(),
                    triangle,
                    index,
                    vertex_count: n,
                });
            }
        }
        Ok(())
    }

    /// Removes zero-area and degenerate triangles (area below 1e-7 of the squared longest
    /// edge, or with a repeated index) and returns how many were dropped.
    pub fn drop_degenerate(&mut self) -> usize {
        let before = self.indices.len();
        let positions = &self.positions;
        self.indices.retain(|tri| {
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                return false;
            }
            let [a, b, c] = tri.map(|i| positions[i as usize]);
            let longest = (b - a)
                .length_squared()
                .max((c - b).length_squared())
                .max((a - c).length_squared());
            let cross = geometry::triangle_cross(a, b, c).length();
            cross.is_finite() && cross > 2e-7 * longest && longest > 0.0
        });
        before - self.indices.len()
    }

    /// The mesh with one vertex per triangle corner and the given TEXCOORD_1 per corner
    /// (`uv1[t]` for triangle `t`): the vertex split a generated lightmap layout needs,
    /// where neighbouring triangles no longer share UV1 coordinates.
    pub fn with_corner_uv1(&self, uv1: &[[Vec2; 3]]) -> Mesh {
        let n = self.indices.len();
        let corners = || self.indices.iter().flatten().map(|&i| i as usize);
        Mesh {
            name: self.name.clone(),
            positions: corners().map(|i| self.positions[i]).collect(),
            normals: corners().map(|i| self.normals[i]).collect(),
            uv0: if self.uv0.is_empty() {
                Vec::new()
            } else {
                corners().map(|i| self.uv0[i]).collect()
            },
            uv1: (0..n)
                .flat_map(|t| uv1.get(t).copied().unwrap_or([Vec2::ZERO; 3]))
                .collect(),
            indices: (0..n as u32)
                .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
                .collect(),
        }
    }

    /// Corner positions of triangle `t`.
    #[inline]
    pub fn triangle(&self, t: usize) -> [Vec3; 3] {
        self.indices[t].map(|i| self.positions[i as usize])
    }
}

/// A linear-RGBA texture, read with glTF's default sampler (bilinear, repeat), with a
/// pyramid of box-filtered reductions for lookups that may average it.
///
/// 8-bit images keep their encoded bytes (4 per texel instead of 16: game textures are
/// what a bake's hit points read most, and at a quarter of the memory far more of them
/// stay in the caches); a lookup decodes colour through the exact sRGB curve
/// ([`crate::color::srgb_to_linear`], tabulated) and alpha as `a / 255`. Deeper images are
/// decoded to linear on load.
///
/// Level ℓ > 0 halves level ℓ − 1 (rounding down, at least one texel), each texel the
/// area-weighted mean of the *linear* values it covers, so every level keeps the image's
/// mean; reductions of 8-bit images are stored the same way, each colour at the code whose
/// decoded value is nearest ([`Self::sample_level`]).
///
/// ```
/// use surfcache_core::Texture;
/// let t = Texture::from_srgb8(1, 1, vec![[255, 188, 0, 128]]).unwrap();
/// let c = t.sample(glam::Vec2::new(0.3, 0.7));
/// assert!((c.x - 1.0).abs() < 1e-6 && (c.y - 0.5).abs() < 3e-3 && c.z == 0.0);
/// assert_eq!(c.w, 128.0 / 255.0);
/// // A 2×2 black-and-white checker reduces to one texel of their linear mean.
/// let checker = Texture::from_srgb8(2, 2, vec![[0, 0, 0, 255], [255; 4], [255; 4], [0, 0, 0, 255]]);
/// let grey = checker.unwrap().sample_level(glam::Vec2::ZERO, 1);
/// assert!((grey.x - 0.5).abs() < 3e-3);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    /// The image (level 0) and its reductions down to one texel.
    levels: Vec<Level>,
}

/// One level of a [`Texture`].
#[derive(Clone, Debug, PartialEq)]
struct Level {
    width: u32,
    height: u32,
    /// Row-major, row 0 at the top (glTF UV (0,0) is the image's top-left).
    texels: Texels,
}

#[derive(Clone, Debug, PartialEq)]
enum Texels {
    /// sRGB-encoded colour, linear alpha.
    Srgb8(Vec<[u8; 4]>),
    Linear(Vec<Vec4>),
}

impl Texture {
    /// A texture of sRGB-encoded 8-bit colour and linear 8-bit alpha; `None` unless
    /// `texels` holds `width × height > 0` texels.
    pub fn from_srgb8(width: u32, height: u32, texels: Vec<[u8; 4]>) -> Option<Self> {
        Self::checked(width, height, texels.len(), Texels::Srgb8(texels))
    }

    /// A texture of linear RGBA; `None` unless `texels` holds `width × height > 0`
    /// texels.
    pub fn from_linear(width: u32, height: u32, texels: Vec<Vec4>) -> Option<Self> {
        Self::checked(width, height, texels.len(), Texels::Linear(texels))
    }

    fn checked(width: u32, height: u32, len: usize, texels: Texels) -> Option<Self> {
        let count = width as usize * height as usize;
        if count == 0 || len != count {
            return None;
        }
        let encoded = matches!(texels, Texels::Srgb8(_));
        let mut levels = vec![Level {
            width,
            height,
            texels,
        }];
        // Linear texels of the last level below the image (the image itself is read
        // through its decoding rather than copied).
        let mut linear = Vec::new();
        let (mut w, mut h) = (width, height);
        while w > 1 || h > 1 {
            let (next, w2, h2) = if levels.len() == 1 {
                let image = &levels[0];
                reduce(|k| image.texel(k as u32 % w, k as u32 / w), w, h)
            } else {
                reduce(|k| linear[k], w, h)
            };
            levels.push(Level {
                width: w2,
                height: h2,
                texels: if encoded {
                    Texels::Srgb8(next.iter().map(|&c| encode_srgb8(c)).collect())
                } else {
                    Texels::Linear(next.clone())
                },
            });
            (linear, w, h) = (next, w2, h2);
        }
        Some(Self { levels })
    }

    pub fn width(&self) -> u32 {
        self.levels[0].width
    }

    pub fn height(&self) -> u32 {
        self.levels[0].height
    }

    /// Number of levels: the image and its reductions, the last one texel.
    pub fn level_count(&self) -> usize {
        self.levels.len()
    }

    /// Linear RGBA of texel `(i, j)` (column, row from the top); `i < width`, `j < height`.
    #[inline]
    pub fn texel(&self, i: u32, j: u32) -> Vec4 {
        self.levels[0].texel(i, j)
    }

    /// Bilinear lookup with repeat wrapping, glTF's default sampler.
    #[inline]
    pub fn sample(&self, uv: Vec2) -> Vec4 {
        self.levels[0].sample(uv)
    }

    /// [`Self::sample`] on level `level` (the coarsest where `level` is beyond it): the
    /// texture averaged over boxes of 2^level texels, what a lookup may read whose result
    /// is itself averaged over that footprint.
    #[inline]
    pub fn sample_level(&self, uv: Vec2, level: usize) -> Vec4 {
        self.levels[level.min(self.levels.len() - 1)].sample(uv)
    }

    /// The alpha channel of [`Self::sample`] alone (what an alpha test reads).
    #[inline]
    pub fn sample_alpha(&self, uv: Vec2) -> f32 {
        let level = &self.levels[0];
        let ([a, b, c, d], fx, fy) = level.footprint(uv);
        let t = |(i, j): (u32, u32)| match &level.texels {
            Texels::Srgb8(t) => t[level.index(i, j)][3] as f32 / 255.0,
            Texels::Linear(t) => t[level.index(i, j)].w,
        };
        let top = t(a) * (1.0 - fx) + t(b) * fx;
        let bottom = t(c) * (1.0 - fx) + t(d) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

impl Level {
    #[inline]
    fn texel(&self, i: u32, j: u32) -> Vec4 {
        let k = self.index(i, j);
        match &self.texels {
            Texels::Srgb8(t) => {
                let [r, g, b, a] = t[k];
                let lut = crate::color::srgb8_to_linear();
                Vec4::new(
                    lut[r as usize],
                    lut[g as usize],
                    lut[b as usize],
                    a as f32 / 255.0,
                )
            }
            Texels::Linear(t) => t[k],
        }
    }

    /// Row-major index of texel `(i, j)`.
    #[inline]
    fn index(&self, i: u32, j: u32) -> usize {
        j as usize * self.width as usize + i as usize
    }

    /// The four texels and weights of a bilinear lookup at `uv` with repeat wrapping.
    #[inline]
    fn footprint(&self, uv: Vec2) -> ([(u32, u32); 4], f32, f32) {
        let x = uv.x * self.width as f32 - 0.5;
        let y = uv.y * self.height as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (w, h) = (self.width as i64, self.height as i64);
        // Non-finite UVs saturate to i64::MIN/MAX under `as`; rem_euclid keeps them in range.
        let i0 = (x0 as i64).rem_euclid(w) as u32;
        let i1 = (x0 as i64).wrapping_add(1).rem_euclid(w) as u32;
        let j0 = (y0 as i64).rem_euclid(h) as u32;
        let j1 = (y0 as i64).wrapping_add(1).rem_euclid(h) as u32;
        ([(i0, j0), (i1, j0), (i0, j1), (i1, j1)], fx, fy)
    }

    #[inline]
    fn sample(&self, uv: Vec2) -> Vec4 {
        let ([a, b, c, d], fx, fy) = self.footprint(uv);
        let t = |(i, j): (u32, u32)| self.texel(i, j);
        let top = t(a) * (1.0 - fx) + t(b) * fx;
        let bottom = t(c) * (1.0 - fx) + t(d) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}

/// Halves a `w × h` image of linear texels, `texel(row-major index)` (rounding down, at least 1): each new texel is
/// the mean of the old texels under it, weighted by the area they share (a box filter
/// that keeps the image's mean exactly, odd sizes included).
fn reduce(texel: impl Fn(usize) -> Vec4, w: u32, h: u32) -> (Vec<Vec4>, u32, u32) {
    let (w2, h2) = ((w / 2).max(1), (h / 2).max(1));
    let (across, down) = (box_weights(w, w2), box_weights(h, h2));
    let rows: Vec<Vec4> = (0..h as usize)
        .flat_map(|j| {
            let (texel, row) = (&texel, j * w as usize);
            across.iter().map(move |taps| {
                taps.iter()
                    .map(|&(i, wt)| texel(row + i) * wt)
                    .sum::<Vec4>()
            })
        })
        .collect();
    let out = down
        .iter()
        .flat_map(|taps| {
            let rows = &rows;
            (0..w2 as usize).map(move |i| {
                taps.iter()
                    .map(|&(j, wt)| rows[j * w2 as usize + i] * wt)
                    .sum::<Vec4>()
            })
        })
        .collect();
    (out, w2, h2)
}

/// For each of `m` equal cells over `n` texels: the texels it overlaps and the share of
/// the cell each covers.
fn box_weights(n: u32, m: u32) -> Vec<Vec<(usize, f32)>> {
    let cell = n as f64 / m as f64;
    (0..m)
        .map(|k| {
            let (lo, hi) = (k as f64 * cell, (k + 1) as f64 * cell);
            (lo.floor() as usize..(hi.ceil() as usize).min(n as usize))
                .map(|i| {
                    let overlap = (hi.min(i as f64 + 1.0) - lo.max(i as f64)).max(0.0);
                    (i, (overlap / cell) as f32)
                })
                .filter(|&(_, wt)| wt > 0.0)
                .collect()
        })
        .collect()
}

/// The 8-bit code of linear RGBA `c`: each colour channel at the code whose decoded value
/// is nearest, alpha rounded.
fn encode_srgb8(c: Vec4) -> [u8; 4] {
    let lut = crate::color::srgb8_to_linear();
    let code = |x: f32| {
        let above = lut.partition_point(|&v| v < x).min(255);
        let below = above.saturating_sub(1);
        if (x - lut[below]).abs() <= (lut[above] - x).abs() {
            below as u8
        } else {
            above as u8
        }
    };
    [
        code(c.x),
        code(c.y),
        code(c.z),
        (c.w.clamp(0.0, 1.0) * 255.0).round() as u8,
    ]
}

/// How a material's alpha is used.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AlphaMode {
    Opaque,
    /// Opaque where base-colour alpha ≥ the cutoff, absent elsewhere (tested at every hit).
    Mask(f32),
    /// Treated as opaque: a diffuse baker has no notion of partial coverage.
    Blend,
}

/// A two-sided Lambertian reflector with optional front-face (or two-sided) emission.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    /// Diffuse albedo ρ = baseColorFactor.rgb × (1 − metallic) (docs/cli.md).
    pub albedo: Vec3,
    /// baseColorFactor.a
    pub alpha: f32,
    /// baseColorTexture (linear RGBA), multiplied into albedo and alpha, read with TEXCOORD_0.
    pub albedo_texture: Option<Arc<Texture>>,
    /// Emitted radiance L_e in W/(m²·sr) = emissiveFactor × emissive strength.
    pub emission: Vec3,
    /// emissiveTexture (linear RGB), multiplied into `emission`.
    pub emission_texture: Option<Arc<Texture>>,
    /// Emission leaves both faces; reflection is two-sided regardless.
    pub double_sided: bool,
    pub alpha_mode: AlphaMode,
}

impl Default for Material {
    fn default() -> Self {
        Self::diffuse("default", Vec3::splat(0.8))
    }
}

impl Material {
    /// A plain diffuse material.
    pub fn diffuse(name: impl Into<String>, albedo: Vec3) -> Self {
        Self {
            name: name.into(),
            albedo,
            alpha: 1.0,
            albedo_texture: None,
            emission: Vec3::ZERO,
            emission_texture: None,
            double_sided: false,
            alpha_mode: AlphaMode::Opaque,
        }
    }

    /// A diffuse material that also emits `emission` from its front face.
    pub fn emissive(name: impl Into<String>, albedo: Vec3, emission: Vec3) -> Self {
        Self {
            emission,
            ..Self::diffuse(name, albedo)
        }
    }

    /// Albedo at texture coordinate `uv0` (uv0 is ignored without a texture).
    #[inline]
    pub fn albedo_at(&self, uv0: Vec2) -> Vec3 {
        match &self.albedo_texture {
            Some(t) => self.albedo * t.sample(uv0).truncate(),
            None => self.albedo,
        }
    }

    /// [`Self::albedo_at`] from level `level` of the albedo texture
    /// ([`Texture::sample_level`]): the albedo averaged over boxes of 2^level texels.
    #[inline]
    pub fn albedo_at_level(&self, uv0: Vec2, level: usize) -> Vec3 {
        match &self.albedo_texture {
            Some(t) => self.albedo * t.sample_level(uv0, level).truncate(),
            None => self.albedo,
        }
    }

    /// Emitted radiance at `uv0` leaving the given face.
    #[inline]
    pub fn emission_at(&self, uv0: Vec2, front_face: bool) -> Vec3 {
        if !(front_face || self.double_sided) || self.emission == Vec3::ZERO {
            return Vec3::ZERO;
        }
        match &self.emission_texture {
            Some(t) => self.emission * t.sample(uv0).truncate(),
            None => self.emission,
        }
    }

    /// Whether the surface is present at `uv0` (alpha mask test).
    #[inline]
    pub fn is_opaque_at(&self, uv0: Vec2) -> bool {
        match self.alpha_mode {
            AlphaMode::Mask(cutoff) => {
                let a = match &self.albedo_texture {
                    Some(t) => self.alpha * t.sample_alpha(uv0),
                    None => self.alpha,
                };
                a >= cutoff
            }
            _ => true,
        }
    }

    pub fn is_emissive(&self) -> bool {
        self.emission.max_element() > 0.0
    }
}

/// A punctual light (KHR_lights_punctual), in world space, radiometric units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Light {
    /// Delivers `irradiance` W/m² to a surface facing it head-on, travelling along `direction`.
    Directional { direction: Vec3, irradiance: Vec3 },
    /// Radiant intensity `intensity` W/sr in every direction.
    Point { position: Vec3, intensity: Vec3 },
    /// Radiant intensity `intensity` W/sr on the axis `direction`, with glTF's smooth cone falloff.
    Spot {
        position: Vec3,
        direction: Vec3,
        intensity: Vec3,
        inner_cone_angle: f32,
        outer_cone_angle: f32,
    },
}

impl Light {
    /// glTF spot attenuation: clamp((cos α − cos outer)/(cos inner − cos outer), 0, 1)².
    pub fn spot_falloff(direction: Vec3, to_point: Vec3, inner: f32, outer: f32) -> f32 {
        let cos_outer = outer.cos();
        let scale = 1.0 / (inner.cos() - cos_outer).max(1e-3);
        let t = ((direction.dot(to_point) - cos_outer) * scale).clamp(0.0, 1.0);
        t * t
    }
}

/// A mesh placed in the world with a material.
#[derive(Clone, Debug)]
pub struct Instance {
    pub name: String,
    pub mesh: Arc<Mesh>,
    pub material: Arc<Material>,
    /// Object to world.
    pub transform: Affine3A,
}

impl Instance {
    /// `mesh` with `material`, named after the mesh, placed with the identity transform.
    pub fn new(mesh: Mesh, material: Material) -> Self {
        Self {
            name: mesh.name.clone(),
            mesh: Arc::new(mesh),
            material: Arc::new(material),
            transform: Affine3A::IDENTITY,
        }
    }
}

/// Everything that is traced: instances, punctual lights and the environment.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    pub name: String,
    pub instances: Vec<Instance>,
    pub lights: Vec<Light>,
    pub environment: Environment,
}

impl Scene {
    /// Total triangle count over all instances.
    pub fn triangle_count(&self) -> usize {
        self.instances.iter().map(|i| i.mesh.indices.len()).sum()
    }

    /// World-space bounding box (min, max) of all instances.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for inst in &self.instances {
            for p in &inst.mesh.positions {
                let w = inst.transform.transform_point3(*p);
                lo = lo.min(w);
                hi = hi.max(w);
            }
        }
        (lo, hi)
    }

    /// Validates every mesh and transform.
    pub fn validate(&self) -> Result<(), SceneError> {
        for inst in &self.instances {
            inst.mesh.validate()?;
            if !inst.transform.is_finite() || inst.transform.matrix3.determinant().abs() < 1e-30 {
                return Err(SceneError::BadTransform {
                    instance: inst.name.clone(),
                });
            }
        }
        if self.triangle_count() == 0 {
            return Err(SceneError::Empty);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn textures_check_their_size_and_read_both_stores_alike() {
        assert!(Texture::from_srgb8(2, 2, vec![[0; 4]; 3]).is_none());
        assert!(Texture::from_linear(0, 0, Vec::new()).is_none());
        let bytes: Vec<[u8; 4]> = (0..12u8)
            .map(|k| [k * 20, 255 - k * 20, k * 7, k * 21])
            .collect();
        let lut = crate::color::srgb8_to_linear();
        let decoded: Vec<Vec4> = bytes
            .iter()
            .map(|b| {
                Vec4::new(
                    lut[b[0] as usize],
                    lut[b[1] as usize],
                    lut[b[2] as usize],
                    b[3] as f32 / 255.0,
                )
            })
            .collect();
        let encoded = Texture::from_srgb8(4, 3, bytes).unwrap();
        let linear = Texture::from_linear(4, 3, decoded).unwrap();
        // A texel centre reads that texel; any UV (wrapped, negative) reads the same from
        // either store, and the alpha-only lookup equals the full lookup's alpha.
        assert_eq!(
            encoded.sample(Vec2::new(2.5 / 4.0, 1.5 / 3.0)),
            linear.texel(2, 1)
        );
        let mut x = 0.1234f32;
        for _ in 0..200 {
            x = (x * 997.13).fract();
            let uv = Vec2::new(x * 5.0 - 2.0, (x * 31.7).fract() * 3.0 - 1.0);
            assert_eq!(encoded.sample(uv), linear.sample(uv));
            assert_eq!(encoded.sample_alpha(uv), encoded.sample(uv).w);
            assert_eq!(linear.sample_alpha(uv), linear.sample(uv).w);
        }
    }

    #[test]
    fn texture_levels_keep_the_mean_down_to_one_texel() {
        // Odd sizes: every level is the area-weighted mean of the one before, so each
        // keeps the image's mean (exactly for linear texels, to the 8-bit step for
        // encoded ones), and the last level is one texel.
        let (w, h) = (37u32, 20u32);
        let mut x = 0.618f32;
        let bytes: Vec<[u8; 4]> = (0..w * h)
            .map(|_| {
                x = (x * 997.13 + 0.31).fract();
                let c = (x * 255.0) as u8;
                [c, c / 2, 255 - c, c]
            })
            .collect();
        let encoded = Texture::from_srgb8(w, h, bytes).unwrap();
        let linear = Texture::from_linear(
            w,
            h,
            (0..w * h).map(|k| encoded.texel(k % w, k / w)).collect(),
        )
        .unwrap();
        let mean = |t: &Texture, level: usize| {
            let (mut lw, mut lh) = (w, h);
            for _ in 0..level {
                (lw, lh) = ((lw / 2).max(1), (lh / 2).max(1));
            }
            let sum: Vec4 = (0..lw * lh)
                .map(|k| {
                    let centre = Vec2::new(
                        ((k % lw) as f32 + 0.5) / lw as f32,
                        ((k / lw) as f32 + 0.5) / lh as f32,
                    );
                    t.sample_level(centre, level)
                })
                .sum();
            sum / (lw * lh) as f32
        };
        assert_eq!(encoded.level_count(), 6); // 37 × 20, 18 × 10, 9 × 5, 4 × 2, 2 × 1, 1 × 1
        let base = mean(&linear, 0);
        for level in 1..encoded.level_count() {
            assert!((mean(&linear, level) - base).abs().max_element() < 1e-5);
            assert!((mean(&encoded, level) - base).abs().max_element() < 4e-3);
        }
        // Beyond the last level reads the last: one texel, the image's mean.
        let last = encoded.sample_level(Vec2::new(0.3, 0.8), 99);
        assert!(
            (last - encoded.sample_level(Vec2::ZERO, 5))
                .abs()
                .max_element()
                < 1e-6
        );
        assert!(
            (last - base).abs().max_element() < 4e-3,
            "{last} against {base}"
        );
        // A one-texel checker reduces to the mean of its linear values, not of its codes.
        let checker: Vec<[u8; 4]> = (0..16)
            .map(|k| {
                if (k % 4 + k / 4) % 2 == 0 {
                    [0; 4]
                } else {
                    [255; 4]
                }
            })
            .collect();
        let checker = Texture::from_srgb8(4, 4, checker).unwrap();
        let grey = checker.sample_level(Vec2::new(0.4, 0.1), 1);
        assert!(
            (grey - Vec4::splat(0.5)).abs().max_element() < 3e-3,
            "{grey}"
        );
    }

    #[test]
    fn validate_names_bad_vertex() {
        let mut m = Mesh::new("m", vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
        m.positions[1].y = f32::NAN;
        let e = m.validate().unwrap_err();
        assert!(e.to_string().contains("mesh 'm': vertex 1"), "{e}");
    }

    #[test]
    fn degenerate_triangles_dropped() {
        let mut m = Mesh::new(
            "m",
            vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(2.0, 0.0, 0.0)],
            vec![[0, 1, 2], [0, 1, 3], [0, 0, 2]],
        );
        assert_eq!(m.drop_degenerate(), 2);
        assert_eq!(m.indices, vec![[0, 1, 2]]);
    }

    #[test]
    fn spot_falloff_edges() {
        let d = Vec3::NEG_Y;
        assert_eq!(Light::spot_falloff(d, d, 0.2, 0.4), 1.0);
        let outside = Vec3::new(0.5f32.sin(), -0.5f32.cos(), 0.0);
        assert_eq!(Light::spot_falloff(d, outside, 0.2, 0.4), 0.0);
    }
}
