//! Publishing: the finished bake's irradiance textures per entity, as a resource.
//!
//! This module owns [`PublishedLightmaps`], the [`BakeFinished`] message and the
//! [`PendingPublish`] slot that [`publish`] empties into them and into
//! [`BakedSurfaceCache`].
//!
//! [`PublishedLightmaps`] holds, for every mesh entity, linear-RGB irradiance textures
//! (W/m²) with the UV1 coordinates and UV rectangle that address them — what Bevy's
//! `Lightmap` takes (image, `uv_rect`, the mesh's UV_1). It changes (Bevy change
//! detection) only when a bake finishes, all at once: it never mixes textures of two
//! scene generations. An entity's [`EntityLightmap::version`] is the generation at which
//! its textures last changed, so consumers re-upload only those.

use crate::baking::{BakeResult, BakedSurfaceCache};
use bevy_ecs::prelude::*;
use std::{collections::HashMap, sync::Arc};
use surfcache_cache::IrradianceTexture;

/// The irradiance textures of one mesh entity.
#[derive(Clone, Debug, PartialEq)]
pub struct EntityLightmap {
    /// Front side (counter-clockwise).
    pub front: Option<Arc<IrradianceTexture>>,
    /// Back side, for double-sided materials baked on both sides.
    pub back: Option<Arc<IrradianceTexture>>,
    /// Scene generation at which these textures last changed.
    pub version: u64,
}

/// Irradiance textures of every baked mesh entity (module docs).
#[derive(Resource, Clone, Debug, Default, PartialEq)]
pub struct PublishedLightmaps {
    pub by_entity: HashMap<Entity, EntityLightmap>,
    /// Scene generation of the bake these come from (0: nothing baked yet).
    pub generation: u64,
}

impl PublishedLightmaps {
    /// Groups a cache's textures (instance `k` belongs to `entities[k]`) by entity; an
    /// entity whose textures equal those in `previous` keeps them and their version.
    pub fn from_textures(
        textures: Vec<IrradianceTexture>,
        entities: &[Entity],
        generation: u64,
        previous: Option<&PublishedLightmaps>,
    ) -> Self {
        let mut by_entity: HashMap<Entity, EntityLightmap> = HashMap::new();
        for t in textures {
            let Some(&entity) = entities.get(t.instance as usize) else {
                continue;
            };
            let entry = by_entity.entry(entity).or_insert(EntityLightmap {
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
                if let Some(old) = previous.by_entity.get(entity)
                    && same_texture(&old.front, &entry.front)
                    && same_texture(&old.back, &entry.back)
                {
                    *entry = old.clone();
                }
            }
        }
        Self {
            by_entity,
            generation,
        }
    }

    /// Entities whose textures changed at `generation`.
    pub fn changed_at(&self, generation: u64) -> impl Iterator<Item = Entity> + '_ {
        self.by_entity
            .iter()
            .filter(move |(_, l)| l.version == generation)
            .map(|(e, _)| *e)
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
/// [`BakedSurfaceCache`] and [`PublishedLightmaps`].
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

/// Publish: swaps a finished bake into [`BakedSurfaceCache`] and
/// [`PublishedLightmaps`] and sends [`BakeFinished`].
pub fn publish(
    mut pending: ResMut<PendingPublish>,
    mut cache: ResMut<BakedSurfaceCache>,
    mut lightmaps: ResMut<PublishedLightmaps>,
    mut messages: MessageWriter<BakeFinished>,
) {
    let Some(f) = pending.0.take() else {
        return;
    };
    let published = Arc::unwrap_or_clone(f.published);
    let same = |a: &Option<Arc<IrradianceTexture>>, b: &Option<Arc<IrradianceTexture>>| match (a, b)
    {
        (None, None) => true,
        (Some(a), Some(b)) => Arc::ptr_eq(a, b),
        _ => false,
    };
    let mut updated: Vec<Entity> = published
        .by_entity
        .iter()
        .filter(|(e, new)| {
            lightmaps
                .by_entity
                .get(e)
                .is_none_or(|old| !same(&old.front, &new.front) || !same(&old.back, &new.back))
        })
        .map(|(e, _)| *e)
        .collect();
    updated.sort();
    let mut removed: Vec<Entity> = lightmaps
        .by_entity
        .keys()
        .filter(|e| !published.by_entity.contains_key(e))
        .copied()
        .collect();
    removed.sort();
    *lightmaps = published;
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
