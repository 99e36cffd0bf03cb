//! glTF 2.0 import (`.gltf` with external or embedded buffers, `.glb`) into a [`Scene`].
//!
//! The node hierarchy becomes one [`Instance`] per (node, triangle primitive), sharing one
//! `Arc<Mesh>` per (mesh, primitive). Materials follow docs/cli.md (albedo =
//! baseColorFactor.rgb × (1 − metallic), emission = emissiveFactor × emissive strength);
//! textures are decoded from sRGB to linear once per image and only when a material in the
//! scene uses them. `KHR_lights_punctual` lights become world-space [`Light`]s.

use crate::error::{IoError, Untrusted, no_panic};
use crate::gltf_accessor::{self, Buffers};
use crate::uri::{UriTarget, resolve};
use gltf::accessor::DataType;
use gltf::json::extensions::scene::khr_lights_punctual as json_lights;
use gltf::mesh::Mode;
use gltf::{Document, Semantic};
use rayon::prelude::*;
use std::collections::{HashMap, HashSet};
use std::path::Path;
use std::sync::Arc;
use surfcache_core::color::srgb_to_linear;
use surfcache_core::glam::{Affine3A, Mat4, Vec2, Vec3, Vec4};
use surfcache_core::{AlphaMode, Environment, Instance, Light, Material, Mesh, Scene, Texture};

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
    let mut keys: Vec<(usize, usize)> = Vec::new();
    let mut seen = HashSet::new();
    for p in &placed {
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
        .map(|&(m, p)| decode_primitive(doc, &buffers, m, p))
        .collect::<Result<_, String>>()
        .map_err(|e| IoError::gltf(path, e))?;
    let meshes: HashMap<(usize, usize), DecodedPrimitive> = keys.into_iter().zip(meshes).collect();

    // 3. Decode the images the used materials need, in parallel, then build materials.
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
        .map(|&i| decode_image(doc, &buffers, &base, i).map(Arc::new))
        .collect::<Result<_, String>>()
        .map_err(|e| IoError::gltf(path, e))?;
    let textures: HashMap<usize, Arc<Texture>> = images.into_iter().zip(textures).collect();
    let mut materials: HashMap<Option<usize>, Arc<Material>> = HashMap::new();
    for key in &used_materials {
        let material = match key.and_then(|i| doc.materials().nth(i)) {
            Some(m) => convert_material(&m, &textures, &mut report.warnings)
                .map_err(|e| IoError::gltf(path, e))?,
            None => default_material(),
        };
        materials.insert(*key, Arc::new(material));
    }

    // 4. Instances and lights.
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
    for p in &placed {
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
    Ok(LoadedScene { scene, report })
}

/// Parses the JSON or GLB container (checking the GLB header first: the gltf crate
/// underflows on a header length below 12).
fn parse(path: &Path, bytes: &[u8]) -> Result<gltf::Gltf, IoError> {
    if bytes.is_empty() {
        return Err(IoError::read("glTF", path, "file is empty"));
    }
    // A `.glb` that is not GLB and does not look like JSON either would otherwise get a
    // confusing JSON parser message.
    let named_glb = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    let looks_json = bytes
        .iter()
        .find(|b| !b.is_ascii_whitespace())
        .is_some_and(|&b| b == b'{' || b == 0xEF); // '{' or a UTF-8 byte-order mark
    if named_glb && !bytes.starts_with(b"glTF") && !looks_json {
        return Err(IoError::read(
            "glTF",
            path,
            "not a GLB file (it does not start with the 'glTF' magic)",
        ));
    }
    if let Some(rest) = bytes.strip_prefix(b"glTF") {
        let declared = rest
            .get(4..8)
            .and_then(|b| b.try_into().ok())
            .map(u32::from_le_bytes);
        match declared {
            Some(len) if (20..=bytes.len() as u64).contains(&(len as u64)) => {}
            Some(len) => {
                return Err(IoError::read(
                    "glTF",
                    path,
                    format!(
                        "file is truncated or not glTF (GLB header says {len} bytes, file has {})",
                        bytes.len()
                    ),
                ));
            }
            None => {
                return Err(IoError::read(
                    "glTF",
                    path,
                    "file is truncated or not glTF (GLB header cut short)",
                ));
            }
        }
    }
    let gltf_error = |e: gltf::Error| {
        let cause = match &e {
            gltf::Error::Binary(_) => format!("file is truncated or not glTF ({e})"),
            gltf::Error::Deserialize(_) => format!("malformed glTF JSON ({e})"),
            gltf::Error::Validation(_) => format!("invalid glTF document ({e})"),
            _ => e.to_string(),
        };
        IoError::read("glTF", path, cause)
    };
    // Parsing and validation are separate so that what gltf-json's validation indexes without
    // checking is checked first. `no_panic` stays as a safety net.
    let gltf::Gltf { document, blob } = no_panic("glTF parsing", || {
        gltf::Gltf::from_slice_without_validation(bytes)
    })
    .map_err(|e| IoError::read("glTF", path, e))?
    .map_err(gltf_error)?;
    let root = document.into_json();
    check_before_validation(&root).map_err(|cause| IoError::read("glTF", path, cause))?;
    let document = no_panic("glTF validation", || gltf::Document::from_json(root))
        .map_err(|e| IoError::read("glTF", path, e))?
        .map_err(gltf_error)?;
    Ok(gltf::Gltf { document, blob })
}

/// What gltf-json 1.4's validation takes for granted: it looks up each primitive's POSITION
/// accessor (for its min/max) by indexing, so an out-of-range index would panic there.
fn check_before_validation(root: &gltf::json::Root) -> Result<(), String> {
    use gltf::json::validation::Checked;
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            if let Some(acc) = prim.attributes.get(&Checked::Valid(Semantic::Positions))
                && acc.value() >= root.accessors.len()
            {
                return Err(format!(
                    "invalid glTF document (mesh {m} primitive {p}: POSITION accessor {} does not exist, the file has {})",
                    acc.value(),
                    root.accessors.len()
                ));
            }
        }
    }
    Ok(())
}

/// Loads every buffer: the GLB BIN chunk, a data URI or a file next to the glTF.
fn load_buffers(
    path: &Path,
    doc: &Document,
    base: &Path,
    mut blob: Option<Vec<u8>>,
) -> Result<Vec<gltf::buffer::Data>, IoError> {
    let mut out = Vec::new();
    for buffer in doc.buffers() {
        let i = buffer.index();
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => blob.take().ok_or_else(|| {
                IoError::gltf(
                    path,
                    format!("buffer {i} refers to a missing GLB BIN chunk"),
                )
            })?,
            gltf::buffer::Source::Uri(uri) => match resolve(uri, base) {
                Ok(UriTarget::Data) => {
                    no_panic("data URI decoding", || {
                        gltf::buffer::Data::from_source(buffer.source(), None)
                    })
                    .map_err(|e| IoError::gltf(path, format!("buffer {i}: {e}")))?
                    .map_err(|e| IoError::gltf(path, format!("buffer {i} data URI: {e}")))?
                    .0
                }
                Ok(UriTarget::File(file)) => std::fs::read(&file).map_err(|e| {
                    let cause = if e.kind() == std::io::ErrorKind::NotFound {
                        "not found".to_string()
                    } else {
                        e.to_string()
                    };
                    IoError::gltf(
                        path,
                        format!("buffer {i} file '{}' {cause}", Untrusted::name(uri)),
                    )
                })?,
                Err(e) => return Err(IoError::gltf(path, format!("buffer {i}: {e}"))),
            },
        };
        if data.len() < buffer.length() {
            return Err(IoError::gltf(
                path,
                format!(
                    "buffer {i} has {} bytes but declares byteLength {} (file truncated?)",
                    data.len(),
                    buffer.length()
                ),
            ));
        }
        out.push(gltf::buffer::Data(data));
    }
    Ok(out)
}

/// A node placed in the world.
struct Placed<'a> {
    node: gltf::Node<'a>,
    world: Affine3A,
}

/// Depth-first walk of the default scene (or the first scene, or all root nodes when the
/// file has no scene); a node reached twice (cycle or shared child) is visited once.
fn walk_nodes<'a>(doc: &'a Document, warnings: &mut Vec<String>) -> Vec<Placed<'a>> {
    let roots: Vec<gltf::Node<'a>> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(scene) => scene.nodes().collect(),
        None => {
            let children: HashSet<usize> = doc
                .nodes()
                .flat_map(|n| n.children().map(|c| c.index()).collect::<Vec<_>>())
                .collect();
            doc.nodes()
                .filter(|n| !children.contains(&n.index()))
                .collect()
        }
    };
    let mut visited = HashSet::new();
    let mut out = Vec::new();
    let mut stack: Vec<(gltf::Node<'a>, Affine3A)> = roots
        .into_iter()
        .rev()
        .map(|n| (n, Affine3A::IDENTITY))
        .collect();
    while let Some((node, parent)) = stack.pop() {
        if !visited.insert(node.index()) {
            warnings.push(format!(
                "node {} is reached more than once (cycle or shared child); used once",
                node.index()
            ));
            continue;
        }
        let local = Affine3A::from_mat4(Mat4::from_cols_array_2d(&node.transform().matrix()));
        let world = parent * local;
        for child in node.children().collect::<Vec<_>>().into_iter().rev() {
            stack.push((child, world));
        }
        out.push(Placed { node, world });
    }
    out
}

/// One (mesh, primitive) decoded: the mesh (None when skipped) and what happened.
struct DecodedPrimitive {
    mesh: Option<Arc<Mesh>>,
    material: Option<usize>,
    skipped: bool,
    degenerate: usize,
    warnings: Vec<String>,
}

const FLOAT: &[DataType] = &[DataType::F32];
const UV_TYPES: &[DataType] = &[DataType::F32, DataType::U8, DataType::U16];

fn vec3s(v: Vec<f32>) -> Vec<Vec3> {
    v.chunks_exact(3).map(Vec3::from_slice).collect()
}

fn vec2s(v: Vec<f32>) -> Vec<Vec2> {
    v.chunks_exact(2).map(Vec2::from_slice).collect()
}

/// Reads a primitive's attributes and indices into a validated [`Mesh`].
fn decode_primitive(
    doc: &Document,
    buffers: &Buffers,
    mesh_index: usize,
    prim_index: usize,
) -> Result<DecodedPrimitive, String> {
    let mesh = doc
        .meshes()
        .nth(mesh_index)
        .ok_or_else(|| format!("mesh {mesh_index} is missing"))?;
    let prim = mesh
        .primitives()
        .nth(prim_index)
        .ok_or_else(|| format!("mesh {mesh_index} primitive {prim_index} is missing"))?;
    let mesh_name = match mesh.name() {
        Some(n) if !n.is_empty() => n.to_string(),
        _ => format!("mesh{mesh_index}"),
    };
    let name = if mesh.primitives().len() > 1 {
        format!("{mesh_name}.{prim_index}")
    } else {
        mesh_name
    };
    // What messages show of the name (the mesh keeps it as the file has it).
    let shown = Untrusted::name(&name).to_string();
    let mut out = DecodedPrimitive {
        mesh: None,
        material: prim.material().index(),
        skipped: false,
        degenerate: 0,
        warnings: Vec::new(),
    };
    let mode = prim.mode();
    if matches!(
        mode,
        Mode::Points | Mode::Lines | Mode::LineLoop | Mode::LineStrip
    ) {
        out.skipped = true;
        return Ok(out);
    }
    let what = |attr: &str| format!("mesh '{shown}' {attr}");
    let positions = match prim.get(&Semantic::Positions) {
        Some(acc) => vec3s(gltf_accessor::read_f32(
            &acc,
            buffers,
            3,
            FLOAT,
            &what("POSITION"),
        )?),
        None => {
            out.skipped = true;
            out.warnings
                .push(format!("mesh '{shown}' has no POSITION; skipped"));
            return Ok(out);
        }
    };
    let n = positions.len();
    let normals = match prim.get(&Semantic::Normals) {
        Some(acc) => Some(vec3s(gltf_accessor::read_f32(
            &acc,
            buffers,
            3,
            FLOAT,
            &what("NORMAL"),
        )?)),
        None => None,
    };
    let uv = |set: u32| -> Result<Vec<Vec2>, String> {
        match prim.get(&Semantic::TexCoords(set)) {
            Some(acc) => Ok(vec2s(gltf_accessor::read_f32(
                &acc,
                buffers,
                2,
                UV_TYPES,
                &what(&format!("TEXCOORD_{set}")),
            )?)),
            None => Ok(Vec::new()),
        }
    };
    let uv0 = uv(0)?;
    let uv1 = uv(1)?;
    let corners: Vec<u32> = match prim.indices() {
        Some(acc) => gltf_accessor::read_indices(&acc, buffers, &what("indices"))?,
        None => (0..n as u32).collect(),
    };
    let indices: Vec<[u32; 3]> = match mode {
        Mode::TriangleStrip => corners
            .windows(3)
            .enumerate()
            .map(|(i, w)| {
                if i % 2 == 0 {
                    [w[0], w[1], w[2]]
                } else {
                    [w[1], w[0], w[2]]
                }
            })
            .collect(),
        Mode::TriangleFan => match corners.split_first() {
            Some((&first, rest)) => rest.windows(2).map(|w| [first, w[0], w[1]]).collect(),
            None => Vec::new(),
        },
        _ => {
            if !corners.len().is_multiple_of(3) {
                out.warnings.push(format!(
                    "mesh '{shown}' has {} indices, not a multiple of 3; the last {} ignored",
                    corners.len(),
                    corners.len() % 3
                ));
            }
            corners
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect()
        }
    };
    let has_normals = normals.is_some();
    let mut m = Mesh {
        name: name.clone(),
        positions,
        normals: normals.unwrap_or_else(|| vec![Vec3::Y; n]),
        uv0,
        uv1,
        indices,
    };
    m.validate().map_err(scene_error)?;
    if has_normals {
        let mut fixed = 0;
        let mut computed: Option<Vec<Vec3>> = None;
        for v in 0..m.normals.len() {
            let len = m.normals[v].length();
            if len > 1e-12 && len.is_finite() {
                m.normals[v] /= len;
            } else {
                let c = computed.get_or_insert_with(|| {
                    let mut tmp = m.clone();
                    tmp.compute_normals();
                    tmp.normals
                });
                m.normals[v] = c[v];
                fixed += 1;
            }
        }
        if fixed > 0 {
            out.warnings.push(format!(
                "mesh '{shown}': {fixed} zero-length or overflowing normals replaced by computed ones"
            ));
        }
    } else {
        m.compute_normals();
    }
    out.degenerate = m.drop_degenerate();
    out.mesh = Some(Arc::new(m));
    Ok(out)
}

/// glTF's default material: base colour 1, metallic 1, so the diffuse albedo is 0.
fn default_material() -> Material {
    Material::diffuse("default", Vec3::ZERO)
}

/// glTF material → [`Material`] (docs/cli.md: albedo = base colour × (1 − metallic)).
fn convert_material(
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
fn decode_image(
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

/// A light definition placed by a node's world transform → world-space [`Light`].
fn convert_light(def: &json_lights::Light, world: &Affine3A) -> Result<Light, String> {
    use gltf::json::validation::Checked;
    let rgb = Vec3::from_array(def.color) * def.intensity;
    if !rgb.is_finite() {
        return Err("color × intensity is not finite; ignored".into());
    }
    let position = Vec3::from(world.translation);
    if !position.is_finite() {
        return Err("the node transform gives no finite position; ignored".into());
    }
    let direction = world.transform_vector3(Vec3::NEG_Z).normalize_or_zero();
    let needs_direction = || {
        if direction == Vec3::ZERO || !direction.is_finite() {
            Err("the node transform gives no direction; ignored".to_string())
        } else {
            Ok(direction)
        }
    };
    match &def.type_ {
        Checked::Valid(json_lights::Type::Directional) => Ok(Light::Directional {
            direction: needs_direction()?,
            irradiance: rgb,
        }),
        Checked::Valid(json_lights::Type::Point) => Ok(Light::Point {
            position,
            intensity: rgb,
        }),
        Checked::Valid(json_lights::Type::Spot) => {
            let (inner, outer) = def
                .spot
                .as_ref()
                .map(|s| (s.inner_cone_angle, s.outer_cone_angle))
                .unwrap_or((0.0, std::f32::consts::FRAC_PI_4));
            if !(inner.is_finite() && outer.is_finite()) {
                return Err("spot cone angles are not finite; ignored".into());
            }
            Ok(Light::Spot {
                position,
                direction: needs_direction()?,
                intensity: rgb,
                inner_cone_angle: inner,
                outer_cone_angle: outer,
            })
        }
        Checked::Invalid => Err("unknown light type; ignored".into()),
    }
}

/// A [`SceneError`](surfcache_core::SceneError) as a cause, the mesh or instance name it
/// quotes through [`Untrusted::name`].
fn scene_error(mut e: surfcache_core::SceneError) -> String {
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
