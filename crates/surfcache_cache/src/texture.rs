//! Irradiance textures as engines consume them: a linear-RGB image plus the UV1
//! coordinates (a second UV channel) that address it.

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};
use surfcache_core::geometry::interpolate;
use surfcache_trace::TracedScene;

/// One instance's baked irradiance, ready to upload: Bevy's `Lightmap` takes the image,
/// the UV rectangle and the mesh's `UV_1` (here [`Self::uv1`], per triangle corner).
///
/// Texel (x, y) of a `width × height` image covers UV [x/W, (x+1)/W] × [y/H, (y+1)/H] with
/// row 0 at the top (glTF's convention: UV (0, 0) is the image's top-left corner); engines
/// sample it bilinearly, clamped to the edge.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct IrradianceTexture {
    /// Index of the instance in the traced scene.
    pub instance: u32,
    /// The instance's name (used for file names).
    pub name: String,
    /// Front side (`true`), or the back side of a double-sided material.
    pub front: bool,
    pub width: u32,
    pub height: u32,
    /// Irradiance E in W/m², linear RGB, row-major, row 0 at the top.
    pub texels: Vec<Vec3>,
    /// UV1 of each corner of each triangle of the instance's mesh, in mesh triangle and
    /// corner order (zero for triangles the tracer dropped as degenerate).
    pub uv1: Vec<[Vec2; 3]>,
    /// Whether the mesh's own TEXCOORD_1 was used (otherwise the UV1 layout is generated
    /// and the mesh needs one vertex per triangle corner).
    pub uses_mesh_uv1: bool,
    /// The instance's rectangle in the image: x, y, width, height in UV units.
    pub uv_rect: [f32; 4],
}

impl IrradianceTexture {
    /// Bilinear lookup at `uv` (clamped to the edge), as a GPU sampler does.
    pub fn sample(&self, uv: Vec2) -> Vec3 {
        bilinear(&self.texels, self.width, self.height, uv)
    }
}

/// A cache's published textures looked up as a game engine does: a surface point's UV1
/// interpolated from its triangle's corners, then a plain bilinear fetch from its
/// instance's texture for that side ([`IrradianceTexture::sample`]). What a player sees,
/// without the cache's own crossing-aware lookup (docs/design.md, "Crossings").
pub struct PublishedLookup<'a> {
    scene: &'a TracedScene,
    textures: &'a [IrradianceTexture],
    /// Per instance: index of its front texture and of its back texture in `textures`.
    sides: Vec<[Option<usize>; 2]>,
}

impl<'a> PublishedLookup<'a> {
    /// An index over `textures`, as [`crate::SurfaceCache::publish`] returns them for
    /// `scene`.
    pub fn new(textures: &'a [IrradianceTexture], scene: &'a TracedScene) -> Self {
        let mut sides = vec![[None; 2]; scene.instance_names().len()];
        for (k, t) in textures.iter().enumerate() {
            if let Some(s) = sides.get_mut(t.instance as usize) {
                s[usize::from(!t.front)] = Some(k);
            }
        }
        Self {
            scene,
            textures,
            sides,
        }
    }

    /// E at barycentrics `uv` of traced `triangle`, on the given side, as
    /// [`crate::SurfaceCache::lookup`] takes them; a single-sided instance shows its front
    /// texture on both sides, as an engine does. `None` where nothing was published.
    pub fn lookup(&self, triangle: u32, uv: Vec2, front: bool) -> Option<Vec3> {
        let t = triangle as usize;
        let instance = *self.scene.instance().get(t)? as usize;
        let [f, b] = *self.sides.get(instance)?;
        let texture = &self.textures[if front { f? } else { b.or(f)? }];
        let [p0, p1, p2] = *texture.uv1.get(self.scene.local_triangle()[t] as usize)?;
        // Traced corners B and C are the mesh's C and B under a mirroring transform.
        let (p1, p2) = if self.scene.mirrored()[instance] {
            (p2, p1)
        } else {
            (p1, p2)
        };
        Some(texture.sample(interpolate(p0, p1, p2, uv)))
    }
}

/// Bilinear lookup with clamp-to-edge in a row-major `width × height` image at `uv`
/// (texel centres at ((x+½)/W, (y+½)/H)).
#[inline]
pub fn bilinear(texels: &[Vec3], width: u32, height: u32, uv: Vec2) -> Vec3 {
    let x = (uv.x * width as f32 - 0.5).clamp(0.0, (width - 1) as f32);
    let y = (uv.y * height as f32 - 0.5).clamp(0.0, (height - 1) as f32);
    let (x0, y0) = (x.floor() as u32, y.floor() as u32);
    let (x1, y1) = ((x0 + 1).min(width - 1), (y0 + 1).min(height - 1));
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let t = |i: u32, j: u32| texels[(j * width + i) as usize];
    let top = t(x0, y0) * (1.0 - fx) + t(x1, y0) * fx;
    let bottom = t(x0, y1) * (1.0 - fx) + t(x1, y1) * fx;
    top * (1.0 - fy) + bottom * fy
}
