//! Irradiance textures as engines consume them: a linear-RGB image plus the UV1
//! coordinates (a second UV channel) that address it.

use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

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
