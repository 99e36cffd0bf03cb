//! glTF import/export and OpenEXR environment maps and textures.
//!
//! This crate owns every file format surfcache reads or writes:
//! - [`load_gltf`] turns a `.gltf`/`.glb` file into a [`surfcache_core::Scene`] (meshes,
//!   materials with decoded textures, `KHR_lights_punctual` lights) plus an
//!   [`ImportReport`] of what was skipped or dropped; [`load_scene`] also accepts the names
//!   of built-in scenes;
//! - [`write_gltf`] writes a scene (and per-instance lightmap references) back as glTF;
//! - [`read_environment_map`], [`read_rgb_exr`] and [`write_rgb_exr`] read and write
//!   linear-RGB OpenEXR images (equirectangular environment maps, lightmaps);
//! - [`write_file_atomically`] is the one way surfcache writes an output file: through a
//!   temporary sibling renamed into place.
//!
//! Every function returns an [`IoError`] whose message is one printable line naming the file
//! and the cause; no input, however malformed, makes these functions panic. Text a message
//! quotes from a file (names, URIs, excerpts) or from the command line goes through
//! [`Untrusted`], which escapes what is not printable and cuts what is long; the
//! command-line tool prints every message through it too.

mod error;
mod exr_image;
mod file_replace;
mod gltf_accessor;
mod gltf_export;
mod gltf_import;
mod uri;

pub use error::{IoError, Untrusted};
pub use exr_image::{read_environment_map, read_rgb_exr, write_rgb_exr};
pub use file_replace::write_file_atomically;
pub use gltf_export::{LightmapRef, write_gltf};
pub use gltf_import::{ImportReport, LoadedScene, load_gltf};

use std::path::Path;

/// Loads `arg` as a `.gltf`/`.glb` file when it has that extension, else as a built-in scene.
pub fn load_scene(arg: &str) -> Result<LoadedScene, IoError> {
    let lower = arg.to_ascii_lowercase();
    if lower.ends_with(".gltf") || lower.ends_with(".glb") {
        return load_gltf(Path::new(arg));
    }
    match surfcache_core::scenes::by_name(arg) {
        Some(scene) => Ok(LoadedScene {
            scene,
            report: ImportReport::default(),
        }),
        None => Err(IoError::UnknownScene {
            name: arg.to_string(),
            known: surfcache_core::scenes::BUILTIN_NAMES.join(", "),
        }),
    }
}
