//! Lightmaps: every baked entity's irradiance texture as a Bevy [`Image`] and a Bevy
//! [`Lightmap`] component, in Bevy's units, updated in place after every re-bake.
//!
//! **Units.** Bevy's PBR shader adds `texel × StandardMaterial::lightmap_exposure ×
//! diffuse colour` to a surface's indirect light, a radiance in the units of its emissive
//! colours and lights, before the camera's exposure. A Lambertian surface of albedo ρ under
//! irradiance E leaves L = ρ/π · E, so a texel holds [`LIGHTMAP_SCALE`]` × E` = E/π and
//! `lightmap_exposure` stays 1. Texels are `Rgba16Float` (surfcache stores E as half
//! floats too, docs/design.md, Storage), sampled bilinearly and clamped to the edge, as
//! surfcache's own lookups are.
//!
//! **Meshes.** Bevy reads a lightmap through the mesh's `ATTRIBUTE_UV_1`. A mesh whose own
//! UV1 the bake used is drawn as it is; otherwise the entity's `Mesh3d` is switched to a
//! copy carrying the generated layout ([`crate::mesh::with_lightmap_uv1`]), and back to
//! the original when the entity leaves the bake. [`LightmappedMesh`] remembers both.

use crate::mesh::{has_uv1, with_lightmap_uv1};
use bevy::{
    asset::{Assets, Handle, RenderAssetUsages},
    image::{Image, ImageSampler},
    log::warn,
    math::Rect,
    mesh::{Mesh, Mesh3d},
    pbr::Lightmap,
    prelude::*,
    render::render_resource::{Extent3d, TextureDimension, TextureFormat},
};
use half::f16;
use surfcache_cache::IrradianceTexture;
use surfcache_ecs::BakedLightmap;

/// Bevy lightmap texel per unit of irradiance E (W/m²): 1/π (module docs).
pub const LIGHTMAP_SCALE: f32 = core::f32::consts::FRAC_1_PI;

/// The texture's texels × [`LIGHTMAP_SCALE`] as an `Rgba16Float` image (alpha 1), sampled
/// bilinearly and clamped to the edge. Values beyond half-float range saturate.
pub fn lightmap_image(texture: &IrradianceTexture) -> Image {
    let data: Vec<u8> = texture
        .texels
        .iter()
        .flat_map(|e| (*e * LIGHTMAP_SCALE).extend(1.0).to_array())
        .flat_map(|x| f16::from_f32(x.min(f16::MAX.to_f32())).to_le_bytes())
        .collect();
    let mut image = Image::new(
        Extent3d {
            width: texture.width,
            height: texture.height,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        data,
        TextureFormat::Rgba16Float,
        RenderAssetUsages::default(),
    );
    image.sampler = ImageSampler::linear();
    image
}

/// On a mesh entity that shows a baked lightmap: its mesh before the plugin gave it UV1,
/// the UV1 copy it draws instead (if it needs one) and its lightmap image.
#[derive(Component, Clone, Debug)]
pub struct LightmappedMesh {
    /// The game's own mesh (the one baked).
    pub source: Handle<Mesh>,
    /// The copy with the generated UV1 layout, when the source has no usable UV1.
    pub uv1_mesh: Option<Handle<Mesh>>,
    /// The lightmap image (also in the entity's [`Lightmap`]).
    pub image: Handle<Image>,
    /// [`BakedLightmap::version`] of the texture shown.
    pub version: u64,
}

impl LightmappedMesh {
    /// The game's mesh of an entity that draws `drawn`: the source when `drawn` is the
    /// plugin's UV1 copy.
    pub fn source_of(this: Option<&Self>, drawn: &Handle<Mesh>) -> Handle<Mesh> {
        match this {
            Some(l) if l.uv1_mesh.as_ref() == Some(drawn) => l.source.clone(),
            _ => drawn.clone(),
        }
    }
}

/// Publishing into Bevy: writes the texels of every entity whose [`BakedLightmap`] a bake
/// changed into its lightmap image (in place), gives newly baked entities an image, a
/// [`Lightmap`] and the UV1 their layout needs, and takes them away from entities that
/// left the bake.
pub fn apply_lightmaps(
    mut commands: Commands,
    mut images: ResMut<Assets<Image>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut baked: Query<(
        Entity,
        &mut Mesh3d,
        Ref<BakedLightmap>,
        Option<&mut LightmappedMesh>,
    )>,
    mut left: Query<(Entity, &mut Mesh3d, &LightmappedMesh), Without<BakedLightmap>>,
) {
    for (entity, mut drawn, state) in &mut left {
        unlight(&mut commands, entity, &mut drawn, state);
    }
    for (entity, mut drawn, lightmap, mut state) in &mut baked {
        let version = lightmap.version;
        if !lightmap.is_changed() || state.as_ref().is_some_and(|s| s.version == version) {
            continue;
        }
        let Some(texture) = lightmap.front.as_ref() else {
            if let Some(state) = state {
                unlight(&mut commands, entity, &mut drawn, &state);
            }
            continue;
        };
        let source = LightmappedMesh::source_of(state.as_deref(), &drawn.0);
        let kept = state.as_ref().and_then(|s| s.uv1_mesh.clone());
        if !meshes.contains(&source) {
            continue;
        }
        let uv1_mesh = match uv1_mesh_for(&mut meshes, &source, kept, texture) {
            Ok(uv1_mesh) => uv1_mesh,
            Err(e) => {
                warn!("surfcache: no lightmap for {entity}: {e}");
                continue;
            }
        };
        let target = uv1_mesh.clone().unwrap_or_else(|| source.clone());
        if drawn.0 != target {
            drawn.0 = target;
        }
        let pixels = lightmap_image(texture);
        match &mut state {
            Some(state) => {
                if let Some(mut image) = images.get_mut(&state.image) {
                    *image = pixels;
                } else {
                    state.image = images.add(pixels);
                }
                state.source = source;
                state.uv1_mesh = uv1_mesh;
                state.version = version;
                commands.entity(entity).insert(bevy_lightmap(&state.image));
            }
            None => {
                let image = images.add(pixels);
                commands.entity(entity).insert((
                    bevy_lightmap(&image),
                    LightmappedMesh {
                        source,
                        uv1_mesh,
                        image,
                        version,
                    },
                ));
            }
        }
    }
}

/// The UV1 copy of `source` an entity draws with `texture`: none when the source's own
/// UV1 is the layout, else `kept` (the entity's copy) when it carries this layout, else a
/// new copy, written over `kept` where that still exists.
fn uv1_mesh_for(
    meshes: &mut Assets<Mesh>,
    source: &Handle<Mesh>,
    kept: Option<Handle<Mesh>>,
    texture: &IrradianceTexture,
) -> Result<Option<Handle<Mesh>>, String> {
    let source = meshes.get(source).ok_or("its mesh is not loaded")?;
    if has_uv1(source, &texture.uv1) {
        return Ok(None);
    }
    if kept
        .as_ref()
        .and_then(|h| meshes.get(h))
        .is_some_and(|m| has_uv1(m, &texture.uv1))
    {
        return Ok(kept);
    }
    let copy = with_lightmap_uv1(source, &texture.uv1)?;
    match kept {
        Some(h) if meshes.contains(&h) => {
            if let Some(mut m) = meshes.get_mut(&h) {
                *m = copy;
            }
            Ok(Some(h))
        }
        _ => Ok(Some(meshes.add(copy))),
    }
}

/// Takes an entity's lightmap away and draws its own mesh again.
fn unlight(commands: &mut Commands, entity: Entity, drawn: &mut Mesh3d, state: &LightmappedMesh) {
    if state.uv1_mesh.as_ref() == Some(&drawn.0) {
        drawn.0 = state.source.clone();
    }
    commands
        .entity(entity)
        .remove::<(Lightmap, LightmappedMesh)>();
}

/// The [`Lightmap`] of a whole image (surfcache's textures are one per entity).
fn bevy_lightmap(image: &Handle<Image>) -> Lightmap {
    Lightmap {
        image: image.clone(),
        uv_rect: Rect::new(0.0, 0.0, 1.0, 1.0),
        bicubic_sampling: false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn a_texel_holds_irradiance_over_pi_in_half_floats() {
        let e = [Vec3::new(314.159, 100.0, 0.0), Vec3::new(1.0, 2.0, 3.0)];
        let texture = IrradianceTexture {
            width: 2,
            height: 1,
            texels: e.to_vec(),
            ..Default::default()
        };
        let image = lightmap_image(&texture);
        assert_eq!(image.texture_descriptor.format, TextureFormat::Rgba16Float);
        let data = image.data.unwrap();
        let texel = |k: usize, c: usize| {
            let at = 8 * k + 2 * c;
            f16::from_le_bytes([data[at], data[at + 1]]).to_f32()
        };
        for (k, e) in e.iter().enumerate() {
            for c in 0..3 {
                let want = e[c] / core::f32::consts::PI;
                // Half floats keep 11 significant bits.
                assert!((texel(k, c) - want).abs() <= want * 1e-3, "{k} {c}");
            }
            assert_eq!(texel(k, 3), 1.0);
        }
        assert!((texel(0, 0) - 100.0).abs() < 0.05);
    }
}
