//! Publishing: the textures an engine samples, one per instance and baked side.

use super::Lightmaps;
use crate::IrradianceTexture;
use glam::Vec2;
use surfcache_trace::TracedScene;

impl Lightmaps {
    /// One texture per instance for the front side, and one for the back side of
    /// instances with a double-sided material (when baked); UV1 in mesh order.
    pub(super) fn textures(&self, scene: &TracedScene) -> Vec<IrradianceTexture> {
        let mut out = Vec::new();
        for (i, m) in self.maps.iter().enumerate() {
            let range = scene.instance_triangles()[i].clone();
            let mesh_triangles = range
                .clone()
                .map(|t| scene.local_triangle()[t as usize] + 1)
                .max()
                .unwrap_or(0);
            let mut uv1 = vec![[Vec2::ZERO; 3]; mesh_triangles as usize];
            for t in range.clone() {
                let [a, b, c] = self.uv1[t as usize];
                // Traced corners B and C are the mesh's C and B under a mirroring transform.
                uv1[scene.local_triangle()[t as usize] as usize] = if scene.mirrored()[i] {
                    [a, c, b]
                } else {
                    [a, b, c]
                };
            }
            let double_sided = !range.is_empty() && scene.material_of(range.start).double_sided;
            for layer in 0..self.layers {
                if layer == 1 && !double_sided {
                    continue;
                }
                out.push(IrradianceTexture {
                    instance: i as u32,
                    name: scene.instance_names()[i].clone(),
                    front: layer == 0,
                    width: m.width,
                    height: m.height,
                    texels: self
                        .texture_slice(layer, i)
                        .iter()
                        .map(|&v| self.scale.unpack(v))
                        .collect(),
                    uv1: uv1.clone(),
                    uses_mesh_uv1: m.uses_mesh_uv1,
                    uv_rect: [0.0, 0.0, 1.0, 1.0],
                });
            }
        }
        out
    }
}
