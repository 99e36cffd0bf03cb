//! A finished bake on disk: the cache plus the world-space triangles it is keyed by, so
//! that `surfcache query` can answer from the file alone.

use glam::{Affine3A, Vec3};
use serde::{Deserialize, Serialize, de::DeserializeOwned};
use std::sync::Arc;
use surfcache_core::{Instance, Material, Mesh, Scene};
use surfcache_trace::TracedScene;

/// Identifies the format; bumped whenever the layout changes.
pub const ARCHIVE_MAGIC: [u8; 8] = *b"SCACHE06";

/// Why an archive could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ArchiveError {
    #[error("not a surfcache bake archive (or from an incompatible version)")]
    Format,
    #[error("corrupt bake archive: {0}")]
    Corrupt(String),
}

/// The triangles of a traced scene (world space, in traced order) and a cache over them.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BakeArchive<C> {
    /// Corner positions per triangle.
    pub positions: Vec<[Vec3; 3]>,
    /// Corner shading normals per triangle (the normal function ν).
    pub normals: Vec<[Vec3; 3]>,
    pub cache: C,
}

impl<C: Serialize + DeserializeOwned> BakeArchive<C> {
    /// Captures `scene`'s triangles with `cache`.
    pub fn new(scene: &TracedScene, cache: C) -> Self {
        Self {
            positions: scene.positions().to_vec(),
            normals: scene.normals().to_vec(),
            cache,
        }
    }

    /// Serialises: the magic, then postcard.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = ARCHIVE_MAGIC.to_vec();
        // Serialising plain data into a Vec cannot fail.
        out.extend(postcard::to_stdvec(self).unwrap_or_default());
        out
    }

    /// Reads what [`Self::to_bytes`] wrote.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, ArchiveError> {
        let body = bytes
            .strip_prefix(&ARCHIVE_MAGIC[..])
            .ok_or(ArchiveError::Format)?;
        let archive: Self =
            postcard::from_bytes(body).map_err(|e| ArchiveError::Corrupt(e.to_string()))?;
        if archive.positions.len() != archive.normals.len() {
            return Err(ArchiveError::Corrupt(
                "triangle arrays differ in length".into(),
            ));
        }
        Ok(archive)
    }

    /// A traced scene with the archive's triangles in the same order (one mesh of
    /// unshared vertices; materials and lights are not stored), for locating query points.
    pub fn geometry(&self) -> Result<TracedScene, ArchiveError> {
        let n = self.positions.len();
        let mesh = Mesh {
            name: "baked".into(),
            positions: self.positions.iter().flatten().copied().collect(),
            normals: self.normals.iter().flatten().copied().collect(),
            uv0: Vec::new(),
            uv1: Vec::new(),
            indices: (0..n as u32)
                .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
                .collect(),
        };
        let scene = Scene {
            name: "baked".into(),
            instances: vec![Instance {
                name: "baked".into(),
                mesh: Arc::new(mesh),
                material: Arc::new(Material::default()),
                transform: Affine3A::IDENTITY,
            }],
            ..Default::default()
        };
        let traced = TracedScene::new(&scene).map_err(|e| ArchiveError::Corrupt(e.to_string()))?;
        if traced.triangle_count() != n {
            return Err(ArchiveError::Corrupt(
                "degenerate triangles in the archive".into(),
            ));
        }
        Ok(traced)
    }
}
