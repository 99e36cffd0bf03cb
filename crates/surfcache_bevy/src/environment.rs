//! The environment: the equirectangular HDR [`Image`] a game names in
//! [`BakeEnvironment`], read as surfcache's environment radiance.
//!
//! The image follows surfcache's convention (docs/cli.md, Conventions): +Y up, row 0 the
//! zenith, the image centre looking along −Z; its texels are radiance in W/(m²·sr) (Bevy's
//! cd/m²), scaled by [`BakeEnvironment::intensity`]. Bevy's `.hdr` and `.exr` loaders give
//! such images. The sky is baked into the lightmaps; to keep it from lighting lightmapped
//! meshes twice, an `EnvironmentMapLight` a game also uses for reflections should keep
//! `affects_lightmapped_mesh_diffuse` off.

use crate::material::texture_from_image;
use bevy::{
    asset::{Assets, Handle, RenderAssetUsages},
    image::Image,
    prelude::Resource,
    render::render_resource::{Extent3d, TextureDimension, TextureFormat},
};
use glam::Vec3;
use std::sync::Arc;
use surfcache_core::{Environment, EnvironmentMap};

pub use crate::material::MaterialError;

/// The sky the bake sees: an equirectangular radiance image and a scale (none: black).
#[derive(Resource, Clone, Debug, PartialEq)]
pub struct BakeEnvironment {
    pub image: Option<Handle<Image>>,
    /// Scales the image's radiance.
    pub intensity: f32,
}

impl Default for BakeEnvironment {
    fn default() -> Self {
        Self {
            image: None,
            intensity: 1.0,
        }
    }
}

impl BakeEnvironment {
    /// The environment this names, read from `images`.
    pub fn environment(&self, images: &Assets<Image>) -> Result<Environment, MaterialError> {
        let Some(handle) = &self.image else {
            return Ok(Environment::black());
        };
        let texture = texture_from_image(images, handle.id())?;
        let (width, height) = (texture.width(), texture.height());
        let mut texels = Vec::with_capacity((width * height) as usize);
        for j in 0..height {
            for i in 0..width {
                texels.push(texture.texel(i, j).truncate());
            }
        }
        if let Some(bad) = texels
            .iter()
            .find(|t| !t.is_finite() || t.min_element() < 0.0)
        {
            return Err(MaterialError::Unreadable(format!(
                "the environment image has a texel {bad} that is not a finite radiance"
            )));
        }
        let mut environment = Environment::from_map(Arc::new(EnvironmentMap {
            width,
            height,
            texels,
        }));
        environment.intensity = self.intensity;
        Ok(environment)
    }
}

/// An environment map as a 32-bit float RGBA image for [`BakeEnvironment::image`].
pub fn environment_image(map: &EnvironmentMap) -> Image {
    let data: Vec<u8> = map
        .texels
        .iter()
        .flat_map(|t: &Vec3| t.extend(1.0).to_array())
        .flat_map(f32::to_le_bytes)
        .collect();
    Image::new(
        Extent3d {
            width: map.width,
            height: map.height,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        data,
        TextureFormat::Rgba32Float,
        RenderAssetUsages::default(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use surfcache_core::scenes;

    #[test]
    fn an_environment_map_round_trips_through_an_image() {
        let sky = scenes::cornell_sky();
        let mut images = Assets::<Image>::default();
        let handle = images.add(environment_image(&sky));
        let named = BakeEnvironment {
            image: Some(handle),
            intensity: 2.0,
        };
        let environment = named.environment(&images).unwrap();
        assert_eq!(environment.map.as_deref(), Some(&sky));
        assert_eq!(environment.intensity, 2.0);
        assert_eq!(
            BakeEnvironment::default().environment(&images).unwrap(),
            Environment::black()
        );
    }
}
