//! Scene sync: a Bevy scene mirrored into surfcache's scene components by change
//! detection, so that whatever a game spawns (by code or with Bevy's glTF loader) is baked
//! without extra code.
//!
//! - Every entity with `Mesh3d`, `MeshMaterial3d<StandardMaterial>` and `GlobalTransform`
//!   gets [`MeshGeometry`], [`SurfaceMaterial`] and [`WorldTransform`] (and
//!   [`InstanceName`] from its `Name`), once its mesh and textures are loaded.
//! - Every `DirectionalLight`, `PointLight` and `SpotLight` of [`LightBaking::Baked`] gets
//!   a [`PunctualLight`].
//! - The image named by [`BakeEnvironment`] becomes the [`EnvironmentLight`].
//!
//! Components are written only when their value changes, so surfcache's own change
//! detection ([`surfcache_ecs::scene_sync`]) sees real edits alone: a transform that
//! Bevy re-propagates unchanged, or the UV1 copy the plugin swaps in, starts no bake.
//! Meshes, materials and textures are converted once per asset (instances share them)
//! and again when the asset changes.

use crate::{
    environment::BakeEnvironment,
    glam_bridge,
    light::{self, LightBaking},
    lightmap::LightmappedMesh,
    material::{MaterialError, material_from_standard, texture_from_image},
    mesh::mesh_from_bevy,
};
use bevy::{
    asset::{AssetEvent, AssetId, AssetServer, Assets, LoadState},
    ecs::system::SystemParam,
    image::Image,
    light::{DirectionalLight, PointLight, SpotLight},
    log::warn,
    mesh::{Mesh, Mesh3d},
    pbr::{MeshMaterial3d, StandardMaterial},
    prelude::*,
};
use std::{
    collections::{HashMap, hash_map::Entry},
    sync::Arc,
};
use surfcache_core::{Material as CoreMaterial, Mesh as CoreMesh, Texture};
use surfcache_ecs::{
    EnvironmentLight, InstanceName, MeshGeometry, PunctualLight, SurfaceMaterial, WorldTransform,
};

/// Marks the entities whose surfcache components this plugin keeps in step.
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct MirroredByPlugin;

/// Meshes, materials and textures converted so far, by asset. A mesh or texture that
/// cannot be read is kept as such (and warned about once) until the asset changes.
#[derive(Resource, Default)]
pub struct ConvertedAssets {
    meshes: HashMap<AssetId<Mesh>, Result<Arc<CoreMesh>, String>>,
    materials: HashMap<AssetId<StandardMaterial>, Arc<CoreMaterial>>,
    textures: HashMap<AssetId<Image>, Result<Arc<Texture>, String>>,
}

impl ConvertedAssets {
    /// Forgets what asset events say changed. A changed texture drops every material
    /// (they are re-read, and compared by value before anything is written).
    fn forget_changed(
        &mut self,
        meshes: &mut MessageReader<AssetEvent<Mesh>>,
        materials: &mut MessageReader<AssetEvent<StandardMaterial>>,
        images: &mut MessageReader<AssetEvent<Image>>,
    ) {
        for e in meshes.read() {
            if let AssetEvent::Modified { id } | AssetEvent::Removed { id } = e {
                self.meshes.remove(id);
            }
        }
        for e in materials.read() {
            if let AssetEvent::Modified { id } | AssetEvent::Removed { id } = e {
                self.materials.remove(id);
            }
        }
        for e in images.read() {
            if let AssetEvent::Modified { id } | AssetEvent::Removed { id } = e
                && self.textures.remove(id).is_some()
            {
                self.materials.clear();
            }
        }
    }

    /// The converted mesh `id`; `None` while it loads or when it cannot be baked.
    fn mesh(&mut self, assets: &Assets<Mesh>, id: AssetId<Mesh>) -> Option<Arc<CoreMesh>> {
        let converted = match self.meshes.entry(id) {
            Entry::Occupied(e) => e.into_mut(),
            Entry::Vacant(e) => {
                let converted = mesh_from_bevy(assets.get(id)?, &format!("{id}")).map(Arc::new);
                if let Err(why) = &converted {
                    warn!("surfcache: not baked: {why}");
                }
                e.insert(converted)
            }
        };
        converted.as_ref().ok().cloned()
    }

    /// The converted material `id`; `None` while it or its textures load. A texture that
    /// cannot be read is left out (and warned about once).
    fn material(
        &mut self,
        assets: &Assets<StandardMaterial>,
        images: &Assets<Image>,
        server: Option<&AssetServer>,
        id: AssetId<StandardMaterial>,
    ) -> Option<Arc<CoreMaterial>> {
        if !self.materials.contains_key(&id) {
            let material = assets.get(id)?;
            let textures = &mut self.textures;
            let converted = material_from_standard(material, &format!("{id}"), |image| {
                if let Some(t) = textures.get(&image) {
                    return Ok(t.as_ref().ok().cloned());
                }
                let failed =
                    || server.is_some_and(|s| matches!(s.load_state(image), LoadState::Failed(_)));
                match texture_from_image(images, image) {
                    Err(MaterialError::Loading) if failed() => {
                        warn!("surfcache: texture {image} failed to load; left out of the bake");
                        textures.insert(image, Err("failed to load".into()));
                        Ok(None)
                    }
                    Err(MaterialError::Loading) => Err(MaterialError::Loading),
                    Err(MaterialError::Unreadable(e)) => {
                        warn!("surfcache: texture {image} left out of the bake: {e}");
                        textures.insert(image, Err(e));
                        Ok(None)
                    }
                    Ok(t) => {
                        textures.insert(image, Ok(t.clone()));
                        Ok(Some(t))
                    }
                }
            });
            match converted {
                Ok(m) => self.materials.insert(id, Arc::new(m)),
                Err(_) => return None,
            };
        }
        self.materials.get(&id).cloned()
    }
}

/// The asset collections and their change messages that [`sync_instances`] reads.
#[derive(SystemParam)]
pub struct SceneAssets<'w, 's> {
    converted: ResMut<'w, ConvertedAssets>,
    meshes: Res<'w, Assets<Mesh>>,
    materials: Res<'w, Assets<StandardMaterial>>,
    images: Res<'w, Assets<Image>>,
    /// Tells textures that failed to load from those still loading (absent in apps
    /// without an asset server).
    server: Option<Res<'w, AssetServer>>,
    mesh_events: MessageReader<'w, 's, AssetEvent<Mesh>>,
    material_events: MessageReader<'w, 's, AssetEvent<StandardMaterial>>,
    image_events: MessageReader<'w, 's, AssetEvent<Image>>,
}

/// The mesh entities [`sync_instances`] mirrors, with what they already carry.
type Instances<'w, 's> = Query<
    'w,
    's,
    (
        Entity,
        &'static Mesh3d,
        &'static MeshMaterial3d<StandardMaterial>,
        &'static GlobalTransform,
        Option<&'static Name>,
        Option<&'static LightmappedMesh>,
        Option<&'static mut MeshGeometry>,
        Option<&'static mut SurfaceMaterial>,
        Option<&'static mut WorldTransform>,
    ),
>;

/// Mirrored entities that are no longer Bevy mesh entities.
type LeftTheScene = (With<MirroredByPlugin>, With<MeshGeometry>, Without<Mesh3d>);

/// Scene sync of mesh entities (module docs).
pub fn sync_instances(
    mut commands: Commands,
    mut assets: SceneAssets,
    mut instances: Instances,
    gone: Query<Entity, LeftTheScene>,
) {
    let SceneAssets {
        converted,
        meshes,
        materials,
        images,
        server,
        mesh_events,
        material_events,
        image_events,
    } = &mut assets;
    converted.forget_changed(mesh_events, material_events, image_events);
    for (entity, drawn, material, transform, name, lightmapped, geometry, surface, world) in
        &mut instances
    {
        let source = LightmappedMesh::source_of(lightmapped, &drawn.0);
        let Some(mesh) = converted.mesh(meshes, source.id()) else {
            continue;
        };
        let Some(material) =
            converted.material(materials, images, server.as_deref(), material.id())
        else {
            continue;
        };
        let transform = glam_bridge::affine3a(transform.affine());
        match (geometry, surface, world) {
            (Some(mut geometry), Some(mut surface), Some(mut world)) => {
                if !Arc::ptr_eq(&geometry.0, &mesh) && *geometry.0 != *mesh {
                    geometry.0 = mesh;
                }
                if !Arc::ptr_eq(&surface.0, &material) && *surface.0 != *material {
                    surface.0 = material;
                }
                world.set_if_neq(WorldTransform(transform));
            }
            _ => {
                let name =
                    name.map_or_else(|| format!("entity{}", entity.index()), |n| n.to_string());
                commands.entity(entity).insert((
                    MeshGeometry(mesh),
                    SurfaceMaterial(material),
                    WorldTransform(transform),
                    InstanceName(name),
                    MirroredByPlugin,
                ));
            }
        }
    }
    for entity in &gone {
        commands
            .entity(entity)
            .remove::<(MeshGeometry, SurfaceMaterial, WorldTransform, InstanceName)>();
    }
}

/// Keeps one light's [`PunctualLight`] and `affects_lightmapped_mesh_diffuse` in step with
/// its [`LightBaking`]; returns the flag's value to write, if it must change.
fn sync_light(
    commands: &mut Commands,
    entity: Entity,
    baking: Option<&LightBaking>,
    light: surfcache_core::Light,
    mirrored: Option<Mut<PunctualLight>>,
    affects_lightmapped: bool,
) -> Option<bool> {
    let baked = baking.copied().unwrap_or_default() == LightBaking::Baked;
    match (baked, mirrored) {
        (true, Some(mut mirrored)) => {
            mirrored.set_if_neq(PunctualLight(light));
        }
        (true, None) => {
            commands
                .entity(entity)
                .insert((PunctualLight(light), MirroredByPlugin));
        }
        (false, Some(_)) => {
            commands.entity(entity).remove::<PunctualLight>();
        }
        (false, None) => {}
    }
    // Baked lights must not also light lightmapped meshes' diffuse in real time.
    (affects_lightmapped == baked).then_some(!baked)
}

/// Scene sync of lights (module docs).
#[allow(clippy::type_complexity)] // one query per Bevy light type
pub fn sync_lights(
    mut commands: Commands,
    mut directional: Query<
        (
            Entity,
            &mut DirectionalLight,
            &GlobalTransform,
            Option<&LightBaking>,
            Option<&mut PunctualLight>,
        ),
        (Without<PointLight>, Without<SpotLight>),
    >,
    mut point: Query<
        (
            Entity,
            &mut PointLight,
            &GlobalTransform,
            Option<&LightBaking>,
            Option<&mut PunctualLight>,
        ),
        Without<SpotLight>,
    >,
    mut spot: Query<(
        Entity,
        &mut SpotLight,
        &GlobalTransform,
        Option<&LightBaking>,
        Option<&mut PunctualLight>,
    )>,
    gone: Query<
        Entity,
        (
            With<MirroredByPlugin>,
            With<PunctualLight>,
            Without<DirectionalLight>,
            Without<PointLight>,
            Without<SpotLight>,
        ),
    >,
) {
    for (entity, mut l, transform, baking, mirrored) in &mut directional {
        let light = light::directional(&l, transform);
        let flag = l.affects_lightmapped_mesh_diffuse;
        if let Some(f) = sync_light(&mut commands, entity, baking, light, mirrored, flag) {
            l.affects_lightmapped_mesh_diffuse = f;
        }
    }
    for (entity, mut l, transform, baking, mirrored) in &mut point {
        let light = light::point(&l, transform);
        let flag = l.affects_lightmapped_mesh_diffuse;
        if let Some(f) = sync_light(&mut commands, entity, baking, light, mirrored, flag) {
            l.affects_lightmapped_mesh_diffuse = f;
        }
    }
    for (entity, mut l, transform, baking, mirrored) in &mut spot {
        let light = light::spot(&l, transform);
        let flag = l.affects_lightmapped_mesh_diffuse;
        if let Some(f) = sync_light(&mut commands, entity, baking, light, mirrored, flag) {
            l.affects_lightmapped_mesh_diffuse = f;
        }
    }
    for entity in &gone {
        commands.entity(entity).remove::<PunctualLight>();
    }
}

/// The entity that carries the environment, and whether its image still has to be read.
#[derive(Default)]
pub struct EnvironmentState {
    entity: Option<Entity>,
    pending: bool,
}

/// Scene sync of the environment (module docs): reads [`BakeEnvironment`]'s image once it
/// is loaded and whenever it or the resource changes.
pub fn sync_environment(
    mut commands: Commands,
    named: Res<BakeEnvironment>,
    images: Res<Assets<Image>>,
    mut events: MessageReader<AssetEvent<Image>>,
    mut state: Local<EnvironmentState>,
    mut current: Query<&mut EnvironmentLight>,
) {
    let image = named.image.as_ref().map(|h| h.id());
    let touched = events.read().any(|e| match e {
        AssetEvent::Added { id }
        | AssetEvent::Modified { id }
        | AssetEvent::LoadedWithDependencies { id } => Some(*id) == image,
        _ => false,
    });
    if !(named.is_changed() || touched || state.pending) {
        return;
    }
    let environment = match named.environment(&images) {
        Ok(e) => e,
        Err(MaterialError::Loading) => {
            state.pending = true;
            return;
        }
        Err(MaterialError::Unreadable(e)) => {
            warn!("surfcache: the environment is not baked: {e}");
            state.pending = false;
            return;
        }
    };
    state.pending = false;
    match state.entity.and_then(|e| current.get_mut(e).ok()) {
        Some(mut light) => {
            light.set_if_neq(EnvironmentLight(environment));
        }
        None => {
            state.entity = Some(
                commands
                    .spawn((EnvironmentLight(environment), MirroredByPlugin))
                    .id(),
            );
        }
    }
}
