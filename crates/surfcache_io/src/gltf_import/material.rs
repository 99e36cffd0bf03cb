//! Materials (docs/cli.md) and the images their textures decode from.

use super::container::Buffers;
use crate::error::{Untrusted, no_panic};
use crate::uri::{UriTarget, resolve};
use gltf::Document;
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;
use surfcache_core::color::srgb_to_linear;
use surfcache_core::glam::{Vec3, Vec4};
use surfcache_core::{AlphaMode, Material, Texture};

/// glTF's default material: base colour 1, metallic 1, so the diffuse albedo is 0.
pub(super) fn default_material() -> Material {
    Material::diffuse("default", Vec3::ZERO)
}

/// glTF material → [`Material`] (docs/cli.md: albedo = base colour × (1 − metallic)).
pub(super) fn convert_material(
    m: &gltf::Material<'_>,
    textures: &HashMap<usize, Arc<Texture>>,
    warnings: &mut Vec<String>,
) -> Result<Material, String> {
    let name = m
        .name()
        .map(str::to_string)
        .unwrap_or_else(|| format!("material{}", m.index().unwrap_or(0)));
    let shown = Untrusted::name(&name);
    let pbr = m.pbr_metallic_roughness();
    let base = Vec4::from_array(pbr.base_color_factor());
    let metallic = pbr.metallic_factor();
    let strength = m.emissive_strength().unwrap_or(1.0);
    let emission = Vec3::from_array(m.emissive_factor()) * strength;
    let cutoff = m.alpha_cutoff().unwrap_or(0.5);
    // JSON has no NaN or infinity, but numbers beyond f32's range parse as infinities.
    for (what, finite) in [
        ("baseColorFactor", base.is_finite()),
        ("metallicFactor", metallic.is_finite()),
        ("emissiveFactor × emissiveStrength", emission.is_finite()),
        ("alphaCutoff", cutoff.is_finite()),
    ] {
        if !finite {
            return Err(format!("material '{shown}': {what} is not finite"));
        }
    }
    let metallic = metallic.clamp(0.0, 1.0);
    let mut texture = |info: Option<gltf::texture::Info<'_>>, slot: &str| {
        let info = info?;
        if info.tex_coord() != 0 {
            warnings.push(format!(
                "material '{shown}': {slot} uses TEXCOORD_{}; read with TEXCOORD_0",
                info.tex_coord()
            ));
        }
        textures.get(&info.texture().source().index()).cloned()
    };
    let albedo_texture = texture(pbr.base_color_texture(), "baseColorTexture");
    let emission_texture = texture(m.emissive_texture(), "emissiveTexture");
    Ok(Material {
        albedo: base.truncate() * (1.0 - metallic),
        alpha: base.w,
        albedo_texture,
        emission,
        emission_texture,
        double_sided: m.double_sided(),
        alpha_mode: match m.alpha_mode() {
            gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
            gltf::material::AlphaMode::Mask => AlphaMode::Mask(cutoff),
            gltf::material::AlphaMode::Blend => AlphaMode::Blend,
        },
        name,
    })
}

/// Decodes image `index` (PNG or JPEG, from a file, data URI or buffer view) into a
/// linear-RGBA texture; colour channels are sRGB-decoded, alpha is kept linear.
pub(super) fn decode_image(
    doc: &Document,
    buffers: &Buffers,
    base: &Path,
    index: usize,
) -> Result<Texture, String> {
    let image = doc
        .images()
        .nth(index)
        .ok_or_else(|| format!("image {index} is missing"))?;
    // `Image::source` unwraps these (gltf 1.4 does not validate them).
    if let Some(json) = doc.as_json().images.get(index) {
        match (&json.buffer_view, &json.uri) {
            (Some(_), _) if json.mime_type.is_none() => {
                return Err(format!(
                    "image {index} is in a buffer view but has no mimeType"
                ));
            }
            (None, None) => {
                return Err(format!("image {index} has neither a uri nor a bufferView"));
            }
            _ => {}
        }
    }
    let label = match image.source() {
        gltf::image::Source::Uri { uri, .. } if !uri.starts_with("data:") => {
            format!("image {index} ('{}')", Untrusted::name(uri))
        }
        _ => match image.name() {
            Some(n) => format!("image {index} ('{}')", Untrusted::name(n)),
            None => format!("image {index}"),
        },
    };
    match image.source() {
        gltf::image::Source::Uri { uri, .. } => match resolve(uri, base) {
            Ok(UriTarget::File(file)) if !file.is_file() => {
                return Err(format!(
                    "{label}: file '{}' not found",
                    Untrusted::name(uri)
                ));
            }
            Ok(_) => {}
            Err(e) => return Err(format!("{label}: {e}")),
        },
        gltf::image::Source::View { view, .. } => {
            let ok = buffers
                .get(view.buffer().index())
                .zip(view.offset().checked_add(view.length()))
                .is_some_and(|(b, end)| end <= b.len());
            if !ok {
                return Err(format!(
                    "{label}: buffer view {} lies beyond its buffer",
                    view.index()
                ));
            }
        }
    }
    let data = no_panic("image decoding", || {
        gltf::image::Data::from_source(image.source(), Some(base), buffers)
    })
    .map_err(|e| format!("{label}: {e}"))?
    .map_err(|e| format!("{label}: {}", image_error(&e)))?;
    to_texture(&data).map_err(|e| format!("{label}: {e}"))
}

fn image_error(e: &gltf::Error) -> String {
    match e {
        gltf::Error::UnsupportedImageEncoding => {
            "unsupported image encoding (only PNG and JPEG are supported)".into()
        }
        gltf::Error::Io(io) if io.kind() == std::io::ErrorKind::NotFound => "file not found".into(),
        other => other.to_string(),
    }
}

/// Decoded pixels → linear RGBA texture.
fn to_texture(data: &gltf::image::Data) -> Result<Texture, String> {
    use gltf::image::Format;
    let (w, h) = (data.width, data.height);
    let count = w as usize * h as usize;
    let (channels, bytes_per) = match data.format {
        Format::R8 => (1, 1),
        Format::R8G8 => (2, 1),
        Format::R8G8B8 => (3, 1),
        Format::R8G8B8A8 => (4, 1),
        Format::R16 => (1, 2),
        Format::R16G16 => (2, 2),
        Format::R16G16B16 => (3, 2),
        Format::R16G16B16A16 => (4, 2),
        Format::R32G32B32FLOAT => (3, 4),
        Format::R32G32B32A32FLOAT => (4, 4),
    };
    if count == 0 || data.pixels.len() != count * channels * bytes_per {
        return Err(format!(
            "decoded {w}×{h} image has {} bytes of pixels, expected {}",
            data.pixels.len(),
            count * channels * bytes_per
        ));
    }
    let px = &data.pixels;
    let invalid = || format!("decoded {w}×{h} image is empty");
    if bytes_per == 1 {
        // Encoded bytes as they are; the texture decodes them on lookup.
        let texels = (0..count)
            .map(|i| {
                let k = i * channels;
                match channels {
                    1 => [px[k], px[k], px[k], 255],
                    2 => [px[k], px[k], px[k], px[k + 1]],
                    3 => [px[k], px[k + 1], px[k + 2], 255],
                    _ => [px[k], px[k + 1], px[k + 2], px[k + 3]],
                }
            })
            .collect();
        return Texture::from_srgb8(w, h, texels).ok_or_else(invalid);
    }
    let value = |k: usize| -> f32 {
        match bytes_per {
            2 => u16::from_le_bytes([px[2 * k], px[2 * k + 1]]) as f32 / 65535.0,
            _ => f32::from_le_bytes([px[4 * k], px[4 * k + 1], px[4 * k + 2], px[4 * k + 3]]),
        }
    };
    let colour = |k: usize| -> f32 {
        match bytes_per {
            2 => srgb_to_linear(value(k)),
            _ => value(k),
        }
    };
    let texels = (0..count)
        .map(|i| {
            let k = i * channels;
            match channels {
                1 => Vec3::splat(colour(k)).extend(1.0),
                2 => Vec3::splat(colour(k)).extend(value(k + 1)),
                3 => Vec4::new(colour(k), colour(k + 1), colour(k + 2), 1.0),
                _ => Vec4::new(colour(k), colour(k + 1), colour(k + 2), value(k + 3)),
            }
        })
        .collect();
    Texture::from_linear(w, h, texels).ok_or_else(invalid)
}
