//! glTF 2.0 import (`.gltf` with external or embedded buffers, `.glb`) into a [`Scene`].
//!
//! The node hierarchy becomes one [`Instance`] per (node, triangle primitive), sharing one
//! `Arc<Mesh>` per (mesh, primitive). Materials follow docs/cli.md (albedo =
//! baseColorFactor.rgb × (1 − metallic), emission = emissiveFactor × emissive strength);
//! textures are decoded from sRGB to linear once per image and only when a material in the
//! scene uses them. `KHR_lights_punctual` lights become world-space [`Light`]s.
//!
//! The parts: [`container`] (the JSON or GLB container and its buffers), [`nodes`] (the
//! node hierarchy), [`primitive`] (meshes), [`material`] (materials and their textures)
//! and [`light`].

mod container;
mod light;
mod material;
mod nodes;
mod primitive;

use crate::error::{IoError, Untrusted};
use container::{load_buffers, parse};
use gltf::Document;
use gltf::json::extensions::scene::khr_lights_punctual as json_lights;
use light::convert_light;
use material::{convert_material, decode_image, default_material};
use nodes::{Placed, walk_nodes};
use primitive::{DecodedPrimitive, decode_primitive};
use rayon::prelude::*;
use std::collections::{HashMap, HashSet};
use std::path::Path;
use std::sync::Arc;
use surfcache_core::{Environment, Instance, Material, Scene, Texture};

/// A scene read from a file and what the import had to leave out.
#[derive(Clone, Debug)]
pub struct LoadedScene {
    /// The scene, validated.
    pub scene: Scene,
    /// Skipped primitives, dropped triangles and warnings.
    pub report: ImportReport,
}

/// What an import skipped, dropped or found doubtful. Counts are per instance (a mesh used
/// by three nodes counts three times), so they add up with [`Scene::triangle_count`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImportReport {
    /// Primitives that are points or lines (not triangles), skipped.
    pub skipped_primitives: usize,
    /// Zero-area or repeated-index triangles removed by [`Mesh::drop_degenerate`].
    pub degenerate_triangles: usize,
    /// One line each: things that were read differently from what the file says.
    pub warnings: Vec<String>,
}

/// Extensions whose presence in `extensionsRequired` this importer honours or may ignore.
const SUPPORTED_REQUIRED: &[&str] = &[
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "KHR_mesh_quantization",
];

/// Loads a `.gltf` or `.glb` file: glTF 2.0 → [`Scene`] + [`ImportReport`] (module docs).
pub fn load_gltf(path: &Path) -> Result<LoadedScene, IoError> {
    let bytes = std::fs::read(path).map_err(|e| IoError::read("glTF", path, e))?;
    let gltf = parse(path, &bytes)?;
    drop(bytes);
    let base = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => std::path::PathBuf::from("."),
    };
    let doc = &gltf.document;
    for ext in doc.extensions_required() {
        if !SUPPORTED_REQUIRED.contains(&ext) {
            return Err(IoError::gltf(
                path,
                format!(
                    "requires the unsupported extension {}",
                    Untrusted::name(ext)
                ),
            ));
        }
    }
    let buffers = load_buffers(path, doc, &base, gltf.blob.clone())?;
    let mut report = ImportReport::default();

    // 1. Walk the node hierarchy of the scene.
    let placed = walk_nodes(doc, &mut report.warnings);
    // 2. Decode each distinct (mesh, primitive) that is placed, in parallel.
    let meshes =
        decode_placed_primitives(doc, &buffers, &placed).map_err(|e| IoError::gltf(path, e))?;
    // 3. Decode the images the used materials need, in parallel, then build materials.
    let materials = build_materials(doc, &buffers, &base, &meshes, &mut report.warnings)
        .map_err(|e| IoError::gltf(path, e))?;
    // 4. Instances and lights.
    let scene = place_instances(path, doc, &placed, &meshes, &materials, &mut report);
    check_scene(path, &scene, &report)?;
    Ok(LoadedScene { scene, report })
}

/// Decodes each distinct (mesh, primitive) that `placed` nodes use, in parallel.
fn decode_placed_primitives(
    doc: &Document,
    buffers: &container::Buffers,
    placed: &[Placed],
) -> Result<HashMap<(usize, usize), DecodedPrimitive>, String> {
    let mut keys: Vec<(usize, usize)> = Vec::new();
    let mut seen = HashSet::new();
    for p in placed {
        if let Some(mesh) = p.node.mesh() {
            for prim in mesh.primitives() {
                if seen.insert((mesh.index(), prim.index())) {
                    keys.push((mesh.index(), prim.index()));
                }
            }
        }
    }
    let meshes: Vec<DecodedPrimitive> = keys
        .par_iter()
        .map(|&(m, p)| decode_primitive(doc, buffers, m, p))
        .collect::<Result<_, String>>()?;
    let meshes: HashMap<(usize, usize), DecodedPrimitive> = keys.into_iter().zip(meshes).collect();
    Ok(meshes)
}

/// The materials the decoded primitives use (the default material for none), with the
/// images they need decoded in parallel.
fn build_materials(
    doc: &Document,
    buffers: &container::Buffers,
    base: &Path,
    meshes: &HashMap<(usize, usize), DecodedPrimitive>,
    warnings: &mut Vec<String>,
) -> Result<HashMap<Option<usize>, Arc<Material>>, String> {
    let used_materials: HashSet<Option<usize>> = meshes.values().map(|d| d.material).collect();
    let mut images = Vec::new();
    for m in doc
        .materials()
        .filter(|m| used_materials.contains(&m.index()))
    {
        let pbr = m.pbr_metallic_roughness();
        for info in [pbr.base_color_texture(), m.emissive_texture()]
            .into_iter()
            .flatten()
        {
            let image = info.texture().source().index();
            if !images.contains(&image) {
                images.push(image);
            }
        }
    }
    let textures: Vec<Arc<Texture>> = images
        .par_iter()
        .map(|&i| decode_image(doc, buffers, base, i).map(Arc::new))
        .collect::<Result<_, String>>()?;
    let textures: HashMap<usize, Arc<Texture>> = images.into_iter().zip(textures).collect();
    let mut materials: HashMap<Option<usize>, Arc<Material>> = HashMap::new();
    for key in &used_materials {
        let material = match key.and_then(|i| doc.materials().nth(i)) {
            Some(m) => convert_material(&m, &textures, warnings)?,
            None => default_material(),
        };
        materials.insert(*key, Arc::new(material));
    }
    Ok(materials)
}

/// The scene's instances (one per placed node and triangle primitive, uniquely named)
/// and lights; what the decoding skipped or doubted goes into `report`.
fn place_instances(
    path: &Path,
    doc: &Document,
    placed: &[Placed],
    meshes: &HashMap<(usize, usize), DecodedPrimitive>,
    materials: &HashMap<Option<usize>, Arc<Material>>,
    report: &mut ImportReport,
) -> Scene {
    let light_defs: &[json_lights::Light] = doc.as_json().as_ref();
    let mut scene = Scene {
        name: path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
        instances: Vec::new(),
        lights: Vec::new(),
        environment: Environment::black(),
    };
    let mut names: HashSet<String> = HashSet::new();
    for p in placed {
        if let Some(mesh) = p.node.mesh() {
            let count = mesh.primitives().len();
            for prim in mesh.primitives() {
                let Some(decoded) = meshes.get(&(mesh.index(), prim.index())) else {
                    continue;
                };
                report.skipped_primitives += decoded.skipped as usize;
                report.degenerate_triangles += decoded.degenerate;
                report.warnings.extend(decoded.warnings.iter().cloned());
                let Some(m) = &decoded.mesh else { continue };
                if m.indices.is_empty() {
                    continue;
                }
                let base_name = p
                    .node
                    .name()
                    .or(mesh.name())
                    .map(str::to_string)
                    .unwrap_or_else(|| format!("node{}", p.node.index()));
                let name = if count > 1 {
                    format!("{base_name}.{}", prim.index())
                } else {
                    base_name
                };
                let name = unique_name(&mut names, name);
                let Some(material) = materials.get(&decoded.material) else {
                    continue;
                };
                scene.instances.push(Instance {
                    name,
                    mesh: m.clone(),
                    material: material.clone(),
                    transform: p.world,
                });
            }
        }
        if let Some(light) = p.node.light() {
            match light_defs.get(light.index()) {
                Some(def) => match convert_light(def, &p.world) {
                    Ok(l) => scene.lights.push(l),
                    Err(w) => report.warnings.push(format!(
                        "light {} on node {}: {w}",
                        light.index(),
                        p.node.index()
                    )),
                },
                None => report
                    .warnings
                    .push(format!("light {} is not defined; ignored", light.index())),
            }
        }
    }
    // A mesh decoded but used by no surviving instance reports nothing twice; warnings are
    // de-duplicated keeping the first occurrence.
    let mut seen_w = HashSet::new();
    report.warnings.retain(|w| seen_w.insert(w.clone()));
    scene
}

/// Rejects a scene without triangles, an invalid one, and one whose vertices overflow in
/// world space.
fn check_scene(path: &Path, scene: &Scene, report: &ImportReport) -> Result<(), IoError> {
    if scene.triangle_count() == 0 {
        return Err(IoError::gltf(
            path,
            format!(
                "the scene has no triangles ({} point/line primitive(s) skipped, {} degenerate triangle(s) dropped)",
                report.skipped_primitives, report.degenerate_triangles
            ),
        ));
    }
    scene
        .validate()
        .map_err(|e| IoError::gltf(path, scene_error(e)))?;
    // Finite positions under finite transforms can still overflow in world space.
    for inst in &scene.instances {
        if let Some(v) = inst
            .mesh
            .positions
            .iter()
            .position(|&p| !inst.transform.transform_point3(p).is_finite())
        {
            return Err(IoError::gltf(
                path,
                format!(
                    "instance '{}': vertex {v} of mesh '{}' lies at a non-finite world position (the node transforms overflow)",
                    Untrusted::name(&inst.name),
                    Untrusted::name(&inst.mesh.name)
                ),
            ));
        }
    }
    Ok(())
}

/// A [`SceneError`](surfcache_core::SceneError) as a cause, the mesh or instance name it
/// quotes through [`Untrusted::name`].
pub(super) fn scene_error(mut e: surfcache_core::SceneError) -> String {
    use surfcache_core::SceneError as E;
    match &mut e {
        E::NonFinitePosition { mesh: name, .. }
        | E::NonFiniteNormal { mesh: name, .. }
        | E::NonFiniteTexcoord { mesh: name, .. }
        | E::IndexOutOfRange { mesh: name, .. }
        | E::AttributeLength { mesh: name, .. }
        | E::BadTransform { instance: name } => *name = Untrusted::name(name).to_string(),
        E::Empty => {}
    }
    e.to_string()
}

/// `name`, or `name~2`, `name~3`, … whichever is not taken yet.
fn unique_name(taken: &mut HashSet<String>, name: String) -> String {
    if taken.insert(name.clone()) {
        return name;
    }
    let mut k = 2;
    loop {
        let candidate = format!("{name}~{k}");
        if taken.insert(candidate.clone()) {
            return candidate;
        }
        k += 1;
    }
}
