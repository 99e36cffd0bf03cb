//! glTF 2.0 export of a [`Scene`]: a `.gltf` JSON file and a sibling `.bin` buffer.
//!
//! One node per instance (its transform as a `matrix`), one glTF mesh per distinct
//! (`Arc<Mesh>`, `Arc<Material>`) pair, one material per distinct `Arc<Material>`,
//! `KHR_lights_punctual` lights on their own nodes, and the environment in the scene's
//! `extras`. Material textures are not written (the factors are): a scene exported and
//! re-imported loses its base-colour and emissive textures.

use crate::IoError;
use crate::exr_image::write_rgb_exr;
use crate::file_replace::write_file_atomically;
use serde_json::{Value, json};
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;
use surfcache_core::glam::{Mat4, Quat, Vec3};
use surfcache_core::{AlphaMode, Instance, Light, Material, Mesh, Scene};

/// A baked lightmap for one instance, recorded in its node's `extras` as
/// `{"surfcache_lightmap": {"uri": .., "uv_rect": [x, y, w, h]}}`.
#[derive(Clone, Debug)]
pub struct LightmapRef {
    /// The lightmap image, relative to the `.gltf` file.
    pub uri: String,
    /// A replacement for the instance's mesh (e.g. with split vertices and a lightmap
    /// TEXCOORD_1); `None` keeps the instance's mesh.
    pub mesh: Option<Arc<Mesh>>,
    /// The instance's rectangle in the lightmap, in UV units: x, y, width, height.
    pub uv_rect: [f32; 4],
}

/// A number as JSON, keeping f32's shortest decimal form (0.725, not 0.7250000238…).
fn num(x: f32) -> Value {
    if !x.is_finite() {
        return Value::Null;
    }
    format!("{x}")
        .parse::<f64>()
        .ok()
        .and_then(serde_json::Number::from_f64)
        .map_or(Value::Null, Value::Number)
}

fn nums(xs: &[f32]) -> Value {
    Value::Array(xs.iter().map(|&x| num(x)).collect())
}

/// The growing binary buffer with its views and accessors.
#[derive(Default)]
struct BinaryBuilder {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl BinaryBuilder {
    /// Appends `floats` (groups of `dims`) as a view + FLOAT accessor; returns its index.
    fn floats(&mut self, floats: &[f32], dims: usize, with_bounds: bool) -> usize {
        let offset = self.bin.len();
        for f in floats {
            self.bin.extend_from_slice(&f.to_le_bytes());
        }
        let ty = ["SCALAR", "VEC2", "VEC3", "VEC4"][dims.clamp(1, 4) - 1];
        let mut acc = json!({
            "bufferView": self.view(offset, 34962),
            "componentType": 5126,
            "count": floats.len() / dims,
            "type": ty,
        });
        if with_bounds {
            let mut lo = vec![f32::INFINITY; dims];
            let mut hi = vec![f32::NEG_INFINITY; dims];
            for chunk in floats.chunks_exact(dims) {
                for (k, &v) in chunk.iter().enumerate() {
                    lo[k] = lo[k].min(v);
                    hi[k] = hi[k].max(v);
                }
            }
            acc["min"] = nums(&lo);
            acc["max"] = nums(&hi);
        }
        self.accessors.push(acc);
        self.accessors.len() - 1
    }

    /// Appends u32 triangle indices as a view + UNSIGNED_INT accessor.
    fn indices(&mut self, tris: &[[u32; 3]]) -> usize {
        let offset = self.bin.len();
        for i in tris.iter().flatten() {
            self.bin.extend_from_slice(&i.to_le_bytes());
        }
        let acc = json!({
            "bufferView": self.view(offset, 34963),
            "componentType": 5125,
            "count": tris.len() * 3,
            "type": "SCALAR",
        });
        self.accessors.push(acc);
        self.accessors.len() - 1
    }

    /// Records the bytes from `offset` to the end as a view (4-byte aligned).
    fn view(&mut self, offset: usize, target: u32) -> usize {
        self.views.push(json!({
            "buffer": 0,
            "byteOffset": offset,
            "byteLength": self.bin.len() - offset,
            "target": target,
        }));
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.views.len() - 1
    }
}

fn material_json(m: &Material) -> Value {
    let s = m.emission.max_element();
    let (factor, strength) = if s > 1.0 {
        (m.emission / s, Some(s))
    } else {
        (m.emission, None)
    };
    let mut v = json!({
        "name": m.name,
        "pbrMetallicRoughness": {
            "baseColorFactor": nums(&[m.albedo.x, m.albedo.y, m.albedo.z, m.alpha]),
            "metallicFactor": 0,
            "roughnessFactor": 1,
        },
        "emissiveFactor": nums(&factor.to_array()),
        "doubleSided": m.double_sided,
    });
    if let Some(s) = strength {
        v["extensions"] =
            json!({ "KHR_materials_emissive_strength": { "emissiveStrength": num(s) } });
    }
    match m.alpha_mode {
        AlphaMode::Opaque => {}
        AlphaMode::Mask(cutoff) => {
            v["alphaMode"] = json!("MASK");
            v["alphaCutoff"] = num(cutoff);
        }
        AlphaMode::Blend => v["alphaMode"] = json!("BLEND"),
    }
    v
}

/// A light as (light JSON, node JSON without the light reference).
fn light_json(light: &Light, k: usize) -> (Value, Value) {
    let split = |rgb: Vec3| {
        let i = rgb.max_element().max(0.0);
        if i > 0.0 {
            (rgb / i, i)
        } else {
            (Vec3::ONE, 0.0)
        }
    };
    let orient = |d: Vec3| {
        let q = Quat::from_rotation_arc(Vec3::NEG_Z, d.normalize_or(Vec3::NEG_Z));
        nums(&q.to_array())
    };
    let name = format!("light{k}");
    match *light {
        Light::Directional {
            direction,
            irradiance,
        } => {
            let (c, i) = split(irradiance);
            (
                json!({"name": name, "type": "directional", "color": nums(&c.to_array()), "intensity": num(i)}),
                json!({"name": name, "rotation": orient(direction)}),
            )
        }
        Light::Point {
            position,
            intensity,
        } => {
            let (c, i) = split(intensity);
            (
                json!({"name": name, "type": "point", "color": nums(&c.to_array()), "intensity": num(i)}),
                json!({"name": name, "translation": nums(&position.to_array())}),
            )
        }
        Light::Spot {
            position,
            direction,
            intensity,
            inner_cone_angle,
            outer_cone_angle,
        } => {
            let (c, i) = split(intensity);
            (
                json!({"name": name, "type": "spot", "color": nums(&c.to_array()), "intensity": num(i),
                    "spot": {"innerConeAngle": num(inner_cone_angle), "outerConeAngle": num(outer_cone_angle)}}),
                json!({"name": name, "translation": nums(&position.to_array()), "rotation": orient(direction)}),
            )
        }
    }
}

/// The glTF document being assembled: the binary buffer, and the materials, meshes and
/// nodes written so far, with the indices of the materials and meshes already written.
#[derive(Default)]
struct GltfDocument {
    b: BinaryBuilder,
    materials: Vec<Value>,
    material_ids: HashMap<*const Material, usize>,
    meshes: Vec<Value>,
    mesh_ids: HashMap<(*const Mesh, *const Material), usize>,
    nodes: Vec<Value>,
    /// Whether a material uses KHR_materials_emissive_strength.
    uses_strength: bool,
}

impl GltfDocument {
    /// The index of `material`, written on its first use.
    fn material(&mut self, material: &Arc<Material>) -> usize {
        match self.material_ids.get(&Arc::as_ptr(material)) {
            Some(&i) => i,
            None => {
                let v = material_json(material);
                self.uses_strength |= v.get("extensions").is_some();
                self.materials.push(v);
                self.material_ids
                    .insert(Arc::as_ptr(material), self.materials.len() - 1);
                self.materials.len() - 1
            }
        }
    }

    /// The index of the glTF mesh of (`mesh`, `material`), written on its first use with
    /// `mat`, the material's index.
    fn mesh(&mut self, mesh: &Arc<Mesh>, material: &Arc<Material>, mat: usize) -> usize {
        let key = (Arc::as_ptr(mesh), Arc::as_ptr(material));
        if let Some(&i) = self.mesh_ids.get(&key) {
            return i;
        }
        let b = &mut self.b;
        let flat3 = |v: &[Vec3]| v.iter().flat_map(|p| p.to_array()).collect::<Vec<_>>();
        let mut attributes = serde_json::Map::new();
        attributes.insert(
            "POSITION".into(),
            b.floats(&flat3(&mesh.positions), 3, true).into(),
        );
        if mesh.normals.len() == mesh.positions.len() {
            attributes.insert(
                "NORMAL".into(),
                b.floats(&flat3(&mesh.normals), 3, false).into(),
            );
        }
        for (name, uv) in [("TEXCOORD_0", &mesh.uv0), ("TEXCOORD_1", &mesh.uv1)] {
            if !uv.is_empty() && uv.len() == mesh.positions.len() {
                let flat: Vec<f32> = uv.iter().flat_map(|t| t.to_array()).collect();
                attributes.insert(name.into(), b.floats(&flat, 2, false).into());
            }
        }
        let indices = b.indices(&mesh.indices);
        self.meshes.push(json!({
            "name": mesh.name,
            "primitives": [{
                "attributes": attributes,
                "indices": indices,
                "material": mat,
                "mode": 4,
            }],
        }));
        self.mesh_ids.insert(key, self.meshes.len() - 1);
        self.meshes.len() - 1
    }

    /// The node of instance `inst` showing mesh `mesh_id`: its transform as a `matrix`
    /// (none for the identity) and its lightmap in the `extras`.
    fn instance_node(inst: &Instance, mesh_id: usize, lightmap: Option<&LightmapRef>) -> Value {
        let mut node = json!({ "name": inst.name, "mesh": mesh_id });
        let m = Mat4::from(inst.transform);
        if m != Mat4::IDENTITY {
            node["matrix"] = nums(&m.to_cols_array());
        }
        if let Some(l) = lightmap {
            node["extras"] = json!({
                "surfcache_lightmap": { "uri": l.uri, "uv_rect": nums(&l.uv_rect) }
            });
        }
        node
    }

    /// The document's root: the scene (its environment in the `extras`, the map as
    /// `env_map_uri`), everything written, the buffer `bin_name`, the punctual `lights`
    /// and the extensions used.
    fn root(
        &self,
        scene: &Scene,
        lights: &[Value],
        env_map_uri: &Option<String>,
        bin_name: &str,
    ) -> Value {
        let env = &scene.environment;
        let b = &self.b;
        let mut root = json!({
            "asset": { "version": "2.0", "generator": "surfcache" },
            "scene": 0,
            "scenes": [{
                "name": scene.name,
                "nodes": (0..self.nodes.len()).collect::<Vec<_>>(),
                "extras": { "surfcache_environment": {
                    "color": nums(&env.color.to_array()),
                    "intensity": num(env.intensity),
                    "map": env_map_uri,
                }},
            }],
            "nodes": self.nodes,
            "meshes": self.meshes,
            "materials": self.materials,
            "accessors": b.accessors,
            "bufferViews": b.views,
            "buffers": [{ "uri": bin_name, "byteLength": b.bin.len() }],
        });
        let mut used = Vec::new();
        if !lights.is_empty() {
            used.push("KHR_lights_punctual");
            root["extensions"] = json!({ "KHR_lights_punctual": { "lights": lights } });
        }
        if self.uses_strength {
            used.push("KHR_materials_emissive_strength");
        }
        if !used.is_empty() {
            root["extensionsUsed"] = json!(used);
        }
        root
    }
}

/// Writes `scene` as `path` (.gltf JSON) + a sibling `.bin` (and `<stem>_environment.exr`
/// when the environment has a map), each through a temporary file renamed into place.
/// `lightmaps[k]` (if present) is the lightmap of instance `k`; `lightmaps` may be shorter
/// than the instance list, or empty.
pub fn write_gltf(
    scene: &Scene,
    path: &Path,
    lightmaps: &[Option<LightmapRef>],
) -> Result<(), IoError> {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .filter(|s| !s.is_empty())
        .ok_or_else(|| IoError::write(path, "the path has no file name"))?;
    let bin_name = format!("{stem}.bin");
    let mut doc = GltfDocument::default();
    for (k, inst) in scene.instances.iter().enumerate() {
        let lightmap = lightmaps.get(k).and_then(Option::as_ref);
        let mesh: &Arc<Mesh> = lightmap.and_then(|l| l.mesh.as_ref()).unwrap_or(&inst.mesh);
        if mesh.indices.is_empty() || mesh.positions.is_empty() {
            continue; // glTF accessors cannot be empty
        }
        let mat = doc.material(&inst.material);
        let mesh_id = doc.mesh(mesh, &inst.material, mat);
        doc.nodes
            .push(GltfDocument::instance_node(inst, mesh_id, lightmap));
    }

    let mut lights = Vec::new();
    for (k, light) in scene.lights.iter().enumerate() {
        let (l, mut node) = light_json(light, k);
        lights.push(l);
        node["extensions"] = json!({ "KHR_lights_punctual": { "light": k } });
        doc.nodes.push(node);
    }

    let env = &scene.environment;
    let env_map_uri = env.map.as_ref().map(|_| format!("{stem}_environment.exr"));
    let root = doc.root(scene, &lights, &env_map_uri, &bin_name);
    let text = serde_json::to_string_pretty(&root).map_err(|e| IoError::write(path, e))?;

    // Companions first, the .gltf last: a .gltf on disk always has its files.
    write_file_atomically(&path.with_file_name(&bin_name), &doc.b.bin)?;
    if let (Some(map), Some(uri)) = (&env.map, &env_map_uri) {
        write_rgb_exr(
            &path.with_file_name(uri),
            map.width,
            map.height,
            &map.texels,
        )?;
    }
    write_file_atomically(path, text.as_bytes())
}
