//! Materials: a Bevy [`StandardMaterial`] read as surfcache's Lambertian [`Material`].
//!
//! surfcache's albedo is Bevy's diffuse colour, `base_color × base_color_texture ×
//! (1 − metallic)` (the texture read with UV0), alpha masks cut surfaces out of every ray
//! as Bevy's `AlphaMode::Mask` does, and `emissive × emissive_texture` is the emitted
//! radiance (Bevy's cd/m², read one to one as W/(m²·sr)), leaving both faces of a
//! double-sided material and the front face otherwise.

use bevy::{
    asset::{AssetId, Assets},
    image::Image,
    pbr::StandardMaterial,
    prelude::AlphaMode as BevyAlphaMode,
    render::render_resource::TextureFormat,
};
use glam::{Vec3, Vec4};
use half::f16;
use std::sync::Arc;
use surfcache_core::{AlphaMode, Material, Texture};

/// Why a material cannot be read yet or at all.
#[derive(Clone, Debug, PartialEq)]
pub enum MaterialError {
    /// A texture it names is still loading.
    Loading,
    /// A texture it names cannot be read (the reason, one line).
    Unreadable(String),
}

/// Reads `material` as a surfcache material named `name`; `texture` turns a texture's
/// image into a surfcache texture (see [`texture_from_image`]), `None` to leave it out
/// (unreadable), or tells it is loading.
pub fn material_from_standard(
    material: &StandardMaterial,
    name: &str,
    mut texture: impl FnMut(AssetId<Image>) -> Result<Option<Arc<Texture>>, MaterialError>,
) -> Result<Material, MaterialError> {
    let base = material.base_color.to_linear();
    let emissive = material.emissive;
    Ok(Material {
        name: name.to_string(),
        albedo: Vec3::new(base.red, base.green, base.blue) * (1.0 - material.metallic),
        alpha: base.alpha,
        albedo_texture: match &material.base_color_texture {
            Some(h) => texture(h.id())?,
            None => None,
        },
        emission: Vec3::new(emissive.red, emissive.green, emissive.blue),
        emission_texture: match &material.emissive_texture {
            Some(h) => texture(h.id())?,
            None => None,
        },
        double_sided: material.double_sided,
        alpha_mode: match material.alpha_mode {
            BevyAlphaMode::Mask(cutoff) => AlphaMode::Mask(cutoff),
            BevyAlphaMode::Opaque => AlphaMode::Opaque,
            _ => AlphaMode::Blend,
        },
    })
}

/// The image `id` of `images` as a surfcache texture: 8-bit sRGB and linear, 16- and
/// 32-bit float RGBA. Block-compressed and other formats are [`MaterialError::Unreadable`].
pub fn texture_from_image(
    images: &Assets<Image>,
    id: AssetId<Image>,
) -> Result<Arc<Texture>, MaterialError> {
    let image = images.get(id).ok_or(MaterialError::Loading)?;
    let (width, height) = (image.width(), image.height());
    let data = image
        .data
        .as_deref()
        .ok_or_else(|| MaterialError::Unreadable("its pixels live on the GPU only".into()))?;
    let texels = (width * height) as usize;
    let unreadable = || {
        MaterialError::Unreadable(format!(
            "a {width}x{height} {:?} texture is not readable here",
            image.texture_descriptor.format
        ))
    };
    let texture = match image.texture_descriptor.format {
        TextureFormat::Rgba8UnormSrgb if data.len() >= 4 * texels => Texture::from_srgb8(
            width,
            height,
            data.chunks_exact(4)
                .take(texels)
                .map(|c| [c[0], c[1], c[2], c[3]])
                .collect(),
        ),
        TextureFormat::Rgba8Unorm if data.len() >= 4 * texels => Texture::from_linear(
            width,
            height,
            data.chunks_exact(4)
                .take(texels)
                .map(|c| Vec4::from_array([c[0], c[1], c[2], c[3]].map(|b| b as f32 / 255.0)))
                .collect(),
        ),
        TextureFormat::Rgba16Float if data.len() >= 8 * texels => Texture::from_linear(
            width,
            height,
            data.chunks_exact(8)
                .take(texels)
                .map(|c| {
                    Vec4::from_array(std::array::from_fn(|k| {
                        f16::from_le_bytes([c[2 * k], c[2 * k + 1]]).to_f32()
                    }))
                })
                .collect(),
        ),
        TextureFormat::Rgba32Float if data.len() >= 16 * texels => Texture::from_linear(
            width,
            height,
            data.chunks_exact(16)
                .take(texels)
                .map(|c| {
                    Vec4::from_array(std::array::from_fn(|k| {
                        f32::from_le_bytes([c[4 * k], c[4 * k + 1], c[4 * k + 2], c[4 * k + 3]])
                    }))
                })
                .collect(),
        ),
        _ => None,
    };
    texture.map(Arc::new).ok_or_else(unreadable)
}

/// A surfcache material as a Bevy [`StandardMaterial`] that shades as surfcache assumes:
/// fully rough and dielectric (no specular highlights from lights it does not bake),
/// emission scaled by the camera's exposure like the rest of the light, no back-face
/// culling where the material is double-sided. Textures are left out (the built-in scenes
/// have none).
pub fn standard_material(material: &Material) -> StandardMaterial {
    let a = material.albedo;
    let e = material.emission;
    StandardMaterial {
        base_color: bevy::color::Color::linear_rgba(a.x, a.y, a.z, material.alpha),
        perceptual_roughness: 1.0,
        metallic: 0.0,
        reflectance: 0.0,
        emissive: bevy::color::LinearRgba::rgb(e.x, e.y, e.z),
        emissive_exposure_weight: 1.0,
        double_sided: material.double_sided,
        cull_mode: (!material.double_sided).then_some(bevy::render::render_resource::Face::Back),
        alpha_mode: match material.alpha_mode {
            AlphaMode::Opaque => BevyAlphaMode::Opaque,
            AlphaMode::Mask(cutoff) => BevyAlphaMode::Mask(cutoff),
            AlphaMode::Blend => BevyAlphaMode::Blend,
        },
        ..Default::default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn diffuse_colour_emission_and_sides_round_trip() {
        let mut m = Material::emissive(
            "lamp",
            Vec3::new(0.5, 0.25, 0.125),
            Vec3::new(17.0, 12.0, 4.0),
        );
        m.double_sided = true;
        m.alpha_mode = AlphaMode::Mask(0.5);
        let back =
            material_from_standard(&standard_material(&m), "lamp", |_| unreachable!()).unwrap();
        assert_eq!(back, m);
    }

    #[test]
    fn metals_are_darker_and_missing_textures_wait() {
        let metal = StandardMaterial {
            base_color: bevy::color::Color::linear_rgb(0.8, 0.8, 0.8),
            metallic: 0.75,
            ..Default::default()
        };
        let m = material_from_standard(&metal, "m", |_| unreachable!()).unwrap();
        assert!((m.albedo - Vec3::splat(0.2)).abs().max_element() < 1e-6);
        let images = Assets::<Image>::default();
        let textured = StandardMaterial {
            base_color_texture: Some(bevy::asset::Handle::default()),
            ..Default::default()
        };
        let e = material_from_standard(&textured, "t", |id| {
            texture_from_image(&images, id).map(Some)
        });
        assert_eq!(e.unwrap_err(), MaterialError::Loading);
    }
}
