//! Publishing: the finished bake's irradiance textures on the mesh entities they belong to.
//!
//! This module owns the [`BakedLightmap`] component, the [`BakeFinished`] message and the
//! [`PendingPublish`] slot that [`publish`] empties into them and into
//! [`BakedSurfaceCache`].
//!
//! Every mesh entity a published bake covers carries a [`BakedLightmap`]: linear-RGB
//! irradiance textures (W/m²) with the UV1 coordinates and UV rectangle that address them
//! — what Bevy's `Lightmap` takes (image, `uv_rect`, the mesh's UV_1). [`publish`] writes
//! the components of one bake in one system run (its commands apply together), so the
//! world never shows textures of two scene generations; it writes only those whose
//! textures changed, so `Changed<BakedLightmap>` finds exactly the entities to
//! re-upload, and it removes the component from entities the bake no longer covers.
//!
//! ```
//! # use bevy_ecs::prelude::*;
//! # use surfcache_ecs::BakedLightmap;
//! /// A game's upload system: runs for the entities whose textures a bake changed.
//! fn upload(changed: Query<(Entity, &BakedLightmap), Changed<BakedLightmap>>) {
//!     for (entity, lightmap) in &changed {
//!         if let Some(front) = &lightmap.front {
//!             println!("{entity}: {}×{} texels", front.width, front.height);
//!         }
//!     }
//! }
//! # let mut schedule = Schedule::default();
//! # schedule.add_systems(upload);
//! ```

use crate::baking::{BakeResult, BakedSurfaceCache};
use bevy_ecs::prelude::*;
use std::{collections::HashMap, sync::Arc};
use surfcache_cache::IrradianceTexture;

/// The irradiance textures of one mesh entity (module docs), on the entity.
#[derive(Component, Clone, Debug, PartialEq)]
pub struct BakedLightmap {
    /// Front side (counter-clockwise).
    pub front: Option<Arc<IrradianceTexture>>,
    /// Back side, for double-sided materials baked on both sides.
    pub back: Option<Arc<IrradianceTexture>>,
    /// Scene generation at which these textures last changed.
    pub version: u64,
}

/// A bake's textures grouped by entity, on their way from the bake to the entities (and
/// kept with the baseline, so that the next bake can tell which textures it changed).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct EntityTextures(pub HashMap<Entity, BakedLightmap>);

impl EntityTextures {
    /// Groups a cache's textures (instance `k` belongs to `entities[k]`) by entity; an
    /// entity whose textures equal those in `previous` keeps them and their version.
    pub fn from_textures(
        textures: Vec<IrradianceTexture>,
        entities: &[Entity],
        generation: u64,
        previous: Option<&EntityTextures>,
    ) -> Self {
        let mut by_entity: HashMap<Entity, BakedLightmap> = HashMap::new();
        for t in textures {
            let Some(&entity) = entities.get(t.instance as usize) else {
                continue;
            };
            let entry = by_entity.entry(entity).or_insert(BakedLightmap {
                front: None,
                back: None,
                version: generation,
            });
            if t.front {
                entry.front = Some(Arc::new(t));
            } else {
                entry.back = Some(Arc::new(t));
            }
        }
        if let Some(previous) = previous {
            for (entity, entry) in by_entity.iter_mut() {
                if let Some(old) = previous.0.get(entity)
                    && same_texture(&old.front, &entry.front)
                    && same_texture(&old.back, &entry.back)
                {
                    *entry = old.clone();
                }
            }
        }
        Self(by_entity)
    }
}

/// Same texels and layout (the instance index may differ after other entities were
/// added or removed).
fn same_texture(a: &Option<Arc<IrradianceTexture>>, b: &Option<Arc<IrradianceTexture>>) -> bool {
    match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => {
            a.width == b.width
                && a.height == b.height
                && a.front == b.front
                && a.uv_rect == b.uv_rect
                && a.uv1 == b.uv1
                && a.texels == b.texels
        }
        _ => false,
    }
}

/// The message sent when a bake or re-bake was published: its results are then in
/// [`BakedSurfaceCache`] and on the entities ([`BakedLightmap`]).
#[derive(Message, Clone, Debug, PartialEq)]
pub struct BakeFinished {
    /// Scene generation it was baked from.
    pub generation: u64,
    /// An incremental re-bake (else from scratch).
    pub incremental: bool,
    /// Wall-clock seconds the bake took.
    pub seconds: f64,
    /// Entities whose textures changed (including new ones).
    pub updated: Vec<Entity>,
    /// Entities whose textures were removed.
    pub removed: Vec<Entity>,
}

/// The hand-over from the bake systems to [`publish`]: the newest finished bake's results
/// (`BakeResult`), not published yet. [`publish`] empties it and sends [`BakeFinished`].
#[derive(Resource, Default)]
pub struct PendingPublish(pub(crate) Option<BakeResult>);

/// Publish: swaps a finished bake into [`BakedSurfaceCache`] and the entities'
/// [`BakedLightmap`]s (module docs) and sends [`BakeFinished`]. An entity despawned while
/// the bake ran gets nothing; one despawned since the last publish counts as removed.
pub fn publish(
    mut commands: Commands,
    mut pending: ResMut<PendingPublish>,
    mut cache: ResMut<BakedSurfaceCache>,
    lightmaps: Query<(Entity, Option<&BakedLightmap>)>,
    mut last: Local<Vec<Entity>>,
    mut messages: MessageWriter<BakeFinished>,
) {
    let Some(f) = pending.0.take() else {
        return;
    };
    let same = |a: &Option<Arc<IrradianceTexture>>, b: &Option<Arc<IrradianceTexture>>| match (a, b)
    {
        (None, None) => true,
        (Some(a), Some(b)) => Arc::ptr_eq(a, b),
        _ => false,
    };
    let mut updated: Vec<Entity> = Vec::new();
    for (&entity, new) in &f.published.0 {
        let Ok((_, old)) = lightmaps.get(entity) else {
            continue;
        };
        if old.is_none_or(|old| !same(&old.front, &new.front) || !same(&old.back, &new.back)) {
            commands.entity(entity).insert(new.clone());
            updated.push(entity);
        }
    }
    updated.sort();
    // Entities that carry textures or got them last time, and are not in this bake.
    let mut removed: Vec<Entity> = lightmaps
        .iter()
        .filter(|(_, old)| old.is_some())
        .map(|(e, _)| e)
        .chain(last.iter().copied())
        .filter(|e| !f.published.0.contains_key(e))
        .collect();
    removed.sort();
    removed.dedup();
    for &entity in &removed {
        if lightmaps.contains(entity) {
            commands.entity(entity).remove::<BakedLightmap>();
        }
    }
    *last = f.published.0.keys().copied().collect();
    *cache = BakedSurfaceCache {
        outcome: Some(f.outcome),
        scene: Some(f.scene),
        entities: f.entities,
        generation: f.generation,
    };
    messages.write(BakeFinished {
        generation: f.generation,
        incremental: f.incremental,
        seconds: f.seconds,
        updated,
        removed,
    });
}
