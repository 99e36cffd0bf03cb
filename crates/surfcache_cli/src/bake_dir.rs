//! The bake output directory: written in a staging directory beside it and renamed into
//! place only when complete, so a failed or interrupted bake never leaves anything that
//! `query` could mistake for a finished bake, and what a killed bake left is removed by the
//! next bake of the same output.

use crate::scene_args::LoadedWorld;
use anyhow::{Context, Result, bail};
use serde_json::{Value, json};
use std::{
    collections::HashSet,
    ffi::{OsStr, OsString},
    fs::File,
    path::{Path, PathBuf},
    sync::Arc,
};
use surfcache_cache::{Cache, IrradianceTexture, archive::BakeArchive};
use surfcache_io::{LightmapRef, Untrusted};
use surfcache_trace::TracedScene;

/// Name of the archive `query` reads.
pub const ARCHIVE_FILE: &str = "cache.bin";

/// A directory filled under a temporary name and renamed to its final name by
/// [`StagingDir::commit`]; dropped uncommitted, it is removed.
///
/// The staging directory of output `OUT` is `.OUT.partial-PID` beside it, locked (`flock`)
/// by its bake for as long as that runs. A bake killed outright (SIGKILL, power loss) cannot
/// remove it, so every bake first removes the staging directories of earlier bakes of the
/// same output whose lock it can take: the kernel drops a lock when its process ends, so a
/// free lock means the bake is gone, whatever has since become of its PID, and a bake still
/// running is never touched.
pub struct StagingDir {
    staging: PathBuf,
    /// Where the output already there is moved while the new one takes its place.
    old: PathBuf,
    target: PathBuf,
    /// The staging directory opened and locked (`None` where directories cannot be opened).
    _lock: Option<File>,
    committed: bool,
}

impl StagingDir {
    /// Prepares to write `target`. It may not exist yet, or be empty, or hold an earlier
    /// bake (a `report.json` or `cache.bin`); anything else is refused rather than
    /// overwritten. Staging directories of earlier bakes of `target` that were killed are
    /// removed first.
    pub fn create(target: &Path) -> Result<Self> {
        let name = target
            .file_name()
            .with_context(|| format!("'{}' is not a directory path", Untrusted::path(target)))?;
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let mut prefix = OsString::from(".");
        prefix.push(name);
        prefix.push(".partial-");
        // Before looking at `target`: a bake killed while committing may have left the
        // earlier output moved aside, and this puts it back.
        remove_stale(&parent, &prefix, target);
        if target.exists() {
            if !target.is_dir() {
                bail!(
                    "output '{}' exists and is not a directory",
                    Untrusted::path(target)
                );
            }
            let earlier_bake =
                target.join("report.json").exists() || target.join(ARCHIVE_FILE).exists();
            let empty = std::fs::read_dir(target)
                .with_context(|| format!("cannot read '{}'", Untrusted::path(target)))?
                .next()
                .is_none();
            if !earlier_bake && !empty {
                bail!(
                    "output directory '{}' exists and does not hold a surfcache bake; refusing to overwrite it",
                    Untrusted::path(target)
                );
            }
        }
        std::fs::create_dir_all(&parent)
            .with_context(|| format!("cannot create '{}'", Untrusted::path(&parent)))?;
        let staging = parent.join(staging_name(&prefix, std::process::id(), false));
        let old = parent.join(staging_name(&prefix, std::process::id(), true));
        let lock = create_locked(&staging)?;
        std::fs::create_dir(staging.join("lightmaps"))
            .with_context(|| format!("cannot create '{}'", Untrusted::path(&staging)))?;
        Ok(Self {
            staging,
            old,
            target: target.to_path_buf(),
            _lock: lock,
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

    /// Moves the finished directory into place (an earlier bake there is replaced: moved
    /// aside to `.OUT.partial-PID.old`, which a later bake puts back should this one be
    /// killed before the new directory is in place).
    pub fn commit(mut self) -> Result<()> {
        if self.target.exists() {
            std::fs::rename(&self.target, &self.old)
                .with_context(|| format!("cannot replace '{}'", Untrusted::path(&self.target)))?;
            if let Err(e) = std::fs::rename(&self.staging, &self.target) {
                let _ = std::fs::rename(&self.old, &self.target);
                return Err(e)
                    .with_context(|| format!("cannot write '{}'", Untrusted::path(&self.target)));
            }
            let _ = std::fs::remove_dir_all(&self.old);
        } else {
            std::fs::rename(&self.staging, &self.target)
                .with_context(|| format!("cannot write '{}'", Untrusted::path(&self.target)))?;
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

/// `PREFIX` + `PID`, and `.old` after it for the earlier output moved aside.
fn staging_name(prefix: &OsStr, pid: u32, old: bool) -> OsString {
    let mut name = prefix.to_os_string();
    name.push(pid.to_string());
    if old {
        name.push(".old");
    }
    name
}

/// The PID of a staging name `PREFIX` + digits (+ `.old` when `old`).
fn staging_pid(name: &OsStr, prefix: &OsStr, old: bool) -> Option<u32> {
    let rest = name
        .as_encoded_bytes()
        .strip_prefix(prefix.as_encoded_bytes())?;
    let digits = if old {
        rest.strip_suffix(b".old")?
    } else {
        rest
    };
    if digits.is_empty() || !digits.iter().all(u8::is_ascii_digit) {
        return None;
    }
    std::str::from_utf8(digits).ok()?.parse().ok()
}

/// Whether `file` (opened from `path`) is still what `path` names.
fn still_at(file: &File, path: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (file.metadata(), std::fs::symlink_metadata(path)) {
            (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        let _ = file;
        path.exists()
    }
}

/// The staging directory `path` of a bake whose lock could be taken (its bake is gone),
/// held locked; `None` while its bake runs or when it cannot be opened.
fn take_abandoned(path: &Path) -> Option<File> {
    let dir = File::open(path).ok()?;
    dir.try_lock().ok()?;
    still_at(&dir, path).then_some(dir)
}

/// Creates the directory `path` and locks it. A clean-up by another bake that took the lock
/// between the two removes the directory before letting go of it; then it is made again.
fn create_locked(path: &Path) -> Result<Option<File>> {
    loop {
        std::fs::create_dir(path)
            .with_context(|| format!("cannot create '{}'", Untrusted::path(path)))?;
        let Ok(dir) = File::open(path) else {
            return Ok(None);
        };
        dir.lock()
            .with_context(|| format!("cannot lock '{}'", Untrusted::path(path)))?;
        if still_at(&dir, path) {
            return Ok(Some(dir));
        }
    }
}

/// Removes, in `parent`, the staging directories `PREFIX<pid>` of bakes that are gone, and
/// deals with the earlier outputs `PREFIX<pid>.old` they had moved aside: put back when
/// `target` is missing (the bake was killed between the two renames of its commit), else
/// removed. Nothing of a bake still running is touched; what cannot be removed is left.
fn remove_stale(parent: &Path, prefix: &OsStr, target: &Path) {
    let Ok(entries) = std::fs::read_dir(parent) else {
        return;
    };
    let mut olds = Vec::new();
    for entry in entries.flatten() {
        let name = entry.file_name();
        if let Some(pid) = staging_pid(&name, prefix, true) {
            olds.push(pid);
        } else if staging_pid(&name, prefix, false).is_some() {
            let path = entry.path();
            if let Some(_lock) = take_abandoned(&path) {
                let _ = std::fs::remove_dir_all(&path);
            }
        }
    }
    for pid in olds {
        // The bake that moved it aside is still committing while its staging directory
        // stands locked.
        let staging = parent.join(staging_name(prefix, pid, false));
        let _lock = match take_abandoned(&staging) {
            Some(lock) => Some(lock),
            None if staging.exists() => continue,
            None => None,
        };
        let old = parent.join(staging_name(prefix, pid, true));
        if !target.exists() && std::fs::rename(&old, target).is_ok() {
            let _ = std::fs::remove_dir_all(&staging);
        } else {
            let _ = std::fs::remove_dir_all(&old);
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
    if scene.instances.len() != traced.instance_names().len()
        || scene
            .instances
            .iter()
            .zip(traced.instance_names())
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
            Untrusted::path(&path),
            Untrusted::path(out_dir)
        )
    })?;
    BakeArchive::from_bytes(&bytes).with_context(|| format!("'{}'", Untrusted::path(&path)))
}

/// Reads `OUT_DIR/cache.bin` of a bake of `scene` (named `scene_name` on the command
/// line); fails when the bake was made from other triangles.
pub fn read_archive_of(
    out_dir: &Path,
    scene: &TracedScene,
    scene_name: &str,
) -> Result<BakeArchive<Cache>> {
    let archive = read_archive(out_dir)?;
    if archive.positions != scene.positions() {
        bail!(
            "the bake in '{}' was made from a different scene than '{}'",
            Untrusted::path(out_dir),
            Untrusted::name(scene_name)
        );
    }
    Ok(archive)
}
