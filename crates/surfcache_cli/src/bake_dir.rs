//! The bake output directory: written in a staging directory beside it and renamed into
//! place only when complete, so a failed or interrupted bake never leaves anything that
//! `query` could mistake for a finished bake.

use crate::scene_args::LoadedWorld;
use anyhow::{Context, Result, bail};
use serde_json::{Value, json};
use std::{
    collections::HashSet,
    path::{Path, PathBuf},
    sync::Arc,
};
use surfcache_cache::{Cache, IrradianceTexture, archive::BakeArchive};
use surfcache_io::LightmapRef;
use surfcache_trace::TracedScene;

/// Name of the archive `query` reads.
pub const ARCHIVE_FILE: &str = "cache.bin";

/// A directory filled under a temporary name and renamed to its final name by
/// [`StagingDir::commit`]; dropped uncommitted, it is removed.
pub struct StagingDir {
    staging: PathBuf,
    target: PathBuf,
    committed: bool,
}

impl StagingDir {
    /// Prepares to write `target`. It may not exist yet, or be empty, or hold an earlier
    /// bake (a `report.json` or `cache.bin`); anything else is refused rather than
    /// overwritten.
    pub fn create(target: &Path) -> Result<Self> {
        if target.exists() {
            if !target.is_dir() {
                bail!(
                    "output '{}' exists and is not a directory",
                    target.display()
                );
            }
            let earlier_bake =
                target.join("report.json").exists() || target.join(ARCHIVE_FILE).exists();
            let empty = std::fs::read_dir(target)
                .with_context(|| format!("cannot read '{}'", target.display()))?
                .next()
                .is_none();
            if !earlier_bake && !empty {
                bail!(
                    "output directory '{}' exists and does not hold a surfcache bake; refusing to overwrite it",
                    target.display()
                );
            }
        }
        let name = target
            .file_name()
            .with_context(|| format!("'{}' is not a directory path", target.display()))?
            .to_string_lossy()
            .into_owned();
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent)
            .with_context(|| format!("cannot create '{}'", parent.display()))?;
        let staging = parent.join(format!(".{name}.partial-{}", std::process::id()));
        if staging.exists() {
            let _ = std::fs::remove_dir_all(&staging);
        }
        std::fs::create_dir_all(staging.join("lightmaps"))
            .with_context(|| format!("cannot create '{}'", staging.display()))?;
        Ok(Self {
            staging,
            target: target.to_path_buf(),
            committed: false,
        })
    }

    /// The staging path of `relative`.
    pub fn path(&self, relative: &str) -> PathBuf {
        self.staging.join(relative)
    }

    /// Writes a file into the staging directory.
    pub fn write(&self, relative: &str, bytes: &[u8]) -> Result<()> {
        Ok(surfcache_io::write_file_atomically(
            &self.path(relative),
            bytes,
        )?)
    }

    /// Moves the finished directory into place (an earlier bake there is replaced).
    pub fn commit(mut self) -> Result<()> {
        if self.target.exists() {
            let old = self.staging.with_extension("old");
            std::fs::rename(&self.target, &old)
                .with_context(|| format!("cannot replace '{}'", self.target.display()))?;
            std::fs::rename(&self.staging, &self.target)
                .with_context(|| format!("cannot write '{}'", self.target.display()))?;
            let _ = std::fs::remove_dir_all(&old);
        } else {
            std::fs::rename(&self.staging, &self.target)
                .with_context(|| format!("cannot write '{}'", self.target.display()))?;
        }
        self.committed = true;
        Ok(())
    }
}

impl Drop for StagingDir {
    fn drop(&mut self) {
        if !self.committed {
            let _ = std::fs::remove_dir_all(&self.staging);
        }
    }
}

/// A file-name-safe, unique stem for an instance name.
fn file_stem(name: &str, taken: &mut HashSet<String>) -> String {
    let mut stem: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if stem.is_empty() {
        stem = "instance".into();
    }
    let mut candidate = stem.clone();
    let mut k = 1;
    while !taken.insert(candidate.to_ascii_lowercase()) {
        k += 1;
        candidate = format!("{stem}_{k}");
    }
    candidate
}

/// Writes every published texture as `lightmaps/<instance>.exr` (`_back` for back sides)
/// and the scene as `scene.gltf` with each instance's UV1 (splitting vertices where the
/// layout was generated) and a reference to its front lightmap in the node's extras.
/// Returns the report's list of textures.
pub fn write_lightmaps(
    staging: &StagingDir,
    loaded: &LoadedWorld,
    traced: &TracedScene,
    textures: &[IrradianceTexture],
) -> Result<Value> {
    let scene = &loaded.scene;
    if scene.instances.len() != traced.instance_names.len()
        || scene
            .instances
            .iter()
            .zip(&traced.instance_names)
            .any(|(i, n)| &i.name != n)
    {
        bail!("internal error: the traced scene's instances differ from the loaded scene's");
    }
    let mut taken = HashSet::new();
    let mut refs: Vec<Option<LightmapRef>> = vec![None; scene.instances.len()];
    let mut stems: Vec<Option<String>> = vec![None; scene.instances.len()];
    let mut listed = Vec::new();
    for t in textures {
        let k = t.instance as usize;
        let stem = stems[k]
            .get_or_insert_with(|| file_stem(&t.name, &mut taken))
            .clone();
        let file = if t.front {
            format!("lightmaps/{stem}.exr")
        } else {
            format!("lightmaps/{stem}_back.exr")
        };
        surfcache_io::write_rgb_exr(&staging.path(&file), t.width, t.height, &t.texels)?;
        listed.push(json!({
            "instance": t.name,
            "side": if t.front { "front" } else { "back" },
            "file": file,
            "width": t.width,
            "height": t.height,
            "uses_mesh_uv1": t.uses_mesh_uv1,
        }));
        if t.front {
            let mesh = &scene.instances[k].mesh;
            refs[k] = Some(LightmapRef {
                uri: file,
                mesh: (!t.uses_mesh_uv1).then(|| Arc::new(mesh.with_corner_uv1(&t.uv1))),
                uv_rect: t.uv_rect,
            });
        }
    }
    surfcache_io::write_gltf(scene, &staging.path("scene.gltf"), &refs)?;
    Ok(Value::Array(listed))
}

/// Reads `OUT_DIR/cache.bin`.
pub fn read_archive(out_dir: &Path) -> Result<BakeArchive<Cache>> {
    let path = out_dir.join(ARCHIVE_FILE);
    let bytes = std::fs::read(&path).with_context(|| {
        format!(
            "cannot read '{}': '{}' is not a finished surfcache bake",
            path.display(),
            out_dir.display()
        )
    })?;
    BakeArchive::from_bytes(&bytes).with_context(|| format!("'{}'", path.display()))
}
