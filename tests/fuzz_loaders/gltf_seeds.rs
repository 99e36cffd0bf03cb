//! glTF seeds: the Cornell box as it is, a "rich" variant, and GLB packings of both.

use crate::checking::check_scene;
use crate::common::{cornell_bin, cornell_json, mesh_index, pack_glb, temp_dir};
use proptest::prelude::*;
use proptest::sample::Index;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// A glTF document whose buffer 0 is `bin` (its `uri` is set when written).
pub(crate) struct GltfSeed {
    pub(crate) name: &'static str,
    pub(crate) json: Value,
    pub(crate) bin: Vec<u8>,
}

/// Appends `data` to `bin` (4-byte aligned) as a new buffer view of buffer 0; its index.
fn add_view(doc: &mut Value, bin: &mut Vec<u8>, data: &[u8]) -> usize {
    bin.resize(bin.len().next_multiple_of(4), 0);
    let views = doc["bufferViews"].as_array_mut().unwrap();
    views.push(json!({ "buffer": 0, "byteOffset": bin.len(), "byteLength": data.len() }));
    bin.extend_from_slice(data);
    views.len() - 1
}

fn add_accessor(doc: &mut Value, accessor: Value) -> usize {
    let accessors = doc["accessors"].as_array_mut().unwrap();
    accessors.push(accessor);
    accessors.len() - 1
}

/// Accessor `attribute` (or "indices") of the first primitive of mesh `name`.
fn accessor_of(doc: &Value, name: &str, attribute: &str) -> usize {
    let prim = &doc["meshes"][mesh_index(doc, name)]["primitives"][0];
    let v = if attribute == "indices" {
        &prim["indices"]
    } else {
        &prim["attributes"][attribute]
    };
    v.as_u64().unwrap() as usize
}

/// The bytes of accessor `a` (tightly packed views, as in cornell.bin).
fn accessor_bytes<'b>(doc: &Value, bin: &'b [u8], a: usize, size: usize) -> &'b [u8] {
    let acc = &doc["accessors"][a];
    let view = &doc["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
    let start = view["byteOffset"].as_u64().unwrap_or(0) as usize
        + acc["byteOffset"].as_u64().unwrap_or(0) as usize;
    &bin[start..start + acc["count"].as_u64().unwrap() as usize * size]
}

fn base64(data: &[u8]) -> String {
    const ALPHABET: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in data.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

fn png_image() -> Vec<u8> {
    use image::ImageEncoder;
    let pixels: Vec<u8> = (0..4 * 4)
        .flat_map(|i| {
            [
                (i * 16) as u8,
                200,
                (255 - i * 10) as u8,
                if i % 5 == 0 { 0 } else { 255 },
            ]
        })
        .collect();
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(&pixels, 4, 4, image::ExtendedColorType::Rgba8)
        .unwrap();
    out
}

fn jpeg_image() -> Vec<u8> {
    let pixels: Vec<u8> = (0..8 * 8)
        .flat_map(|i| [(i * 4) as u8, (i * 3) as u8, 128])
        .collect();
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 80)
        .encode(&pixels, 8, 8, image::ExtendedColorType::Rgb8)
        .unwrap();
    out
}

/// Cornell with most of what the importer reads: node transforms and a hierarchy,
/// `KHR_lights_punctual` lights, emissive strength, an alpha mask, a PNG texture in a
/// buffer view and a JPEG one in a data URI, a data-URI buffer, TEXCOORD_0/1 (float and
/// normalized u16), u8 and u16 indices, a sparse accessor and strip/fan primitives.
fn rich_seed() -> GltfSeed {
    let mut doc = cornell_json();
    let mut bin = cornell_bin();

    // Texture coordinates on the floor: TEXCOORD_0 float from a data-URI buffer, TEXCOORD_1
    // normalized u16.
    let uv0: Vec<u8> = [0.0f32, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0]
        .iter()
        .flat_map(|f| f.to_le_bytes())
        .collect();
    doc["buffers"]
        .as_array_mut()
        .unwrap()
        .push(json!({ "byteLength": uv0.len(),
            "uri": format!("data:application/octet-stream;base64,{}", base64(&uv0)) }));
    doc["bufferViews"]
        .as_array_mut()
        .unwrap()
        .push(json!({ "buffer": 1, "byteLength": uv0.len() }));
    let uv0_view = doc["bufferViews"].as_array().unwrap().len() - 1;
    let uv0_acc = add_accessor(
        &mut doc,
        json!({ "bufferView": uv0_view, "componentType": 5126, "count": 4, "type": "VEC2" }),
    );
    let uv1: Vec<u8> = [0u16, 0, 65535, 0, 65535, 32768, 0, 32768]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let uv1_view = add_view(&mut doc, &mut bin, &uv1);
    let uv1_acc = add_accessor(
        &mut doc,
        json!({ "bufferView": uv1_view, "componentType": 5123, "normalized": true,
            "count": 4, "type": "VEC2" }),
    );
    let floor = mesh_index(&doc, "floor");
    doc["meshes"][floor]["primitives"][0]["attributes"]["TEXCOORD_0"] = json!(uv0_acc);
    doc["meshes"][floor]["primitives"][0]["attributes"]["TEXCOORD_1"] = json!(uv1_acc);

    // u16 indices on the back wall, u8 on the red wall.
    for (name, size, ty) in [("back_wall", 2, 5123), ("red_wall", 1, 5121)] {
        let acc = accessor_of(&doc, name, "indices");
        let data: Vec<u8> = accessor_bytes(&doc, &bin, acc, 4)
            .chunks_exact(4)
            .flat_map(|c| {
                let i = u32::from_le_bytes(c.try_into().unwrap());
                i.to_le_bytes()[..size].to_vec()
            })
            .collect();
        let count = data.len() / size;
        let view = add_view(&mut doc, &mut bin, &data);
        let new = add_accessor(
            &mut doc,
            json!({ "bufferView": view, "componentType": ty, "count": count, "type": "SCALAR" }),
        );
        let mesh = mesh_index(&doc, name);
        doc["meshes"][mesh]["primitives"][0]["indices"] = json!(new);
    }

    // A sparse accessor over the ceiling's positions: vertex 1 moved a little.
    let ceiling_pos = accessor_of(&doc, "ceiling", "POSITION");
    let p1: Vec<f32> = accessor_bytes(&doc, &bin, ceiling_pos, 12)[12..24]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()) * 0.99)
        .collect();
    let sparse_idx = add_view(&mut doc, &mut bin, &[1, 0, 0, 0]);
    let sparse_val = add_view(
        &mut doc,
        &mut bin,
        &p1.iter().flat_map(|f| f.to_le_bytes()).collect::<Vec<u8>>(),
    );
    let mut sparse = doc["accessors"][ceiling_pos].clone();
    sparse["sparse"] = json!({
        "count": 1,
        "indices": { "bufferView": sparse_idx, "componentType": 5121 },
        "values": { "bufferView": sparse_val }
    });
    let sparse = add_accessor(&mut doc, sparse);
    let ceiling = mesh_index(&doc, "ceiling");
    doc["meshes"][ceiling]["primitives"][0]["attributes"]["POSITION"] = json!(sparse);

    // Textures: a PNG in a buffer view, a JPEG in a data URI.
    let png_view = add_view(&mut doc, &mut bin, &png_image());
    doc["images"] = json!([
        { "bufferView": png_view, "mimeType": "image/png", "name": "png" },
        { "uri": format!("data:image/jpeg;base64,{}", base64(&jpeg_image())) }
    ]);
    doc["samplers"] = json!([{}]);
    doc["textures"] = json!([{ "source": 0, "sampler": 0 }, { "source": 1 }]);
    let white = &mut doc["materials"][0];
    white["pbrMetallicRoughness"]["baseColorTexture"] = json!({ "index": 0 });
    white["emissiveTexture"] = json!({ "index": 1, "texCoord": 1 });
    white["emissiveFactor"] = json!([0.1, 0.1, 0.1]);
    let red = &mut doc["materials"][1];
    red["alphaMode"] = json!("MASK");
    red["alphaCutoff"] = json!(0.3);
    red["pbrMetallicRoughness"]["metallicFactor"] = json!(0.25);
    let light_material = doc["meshes"][mesh_index(&doc, "light")]["primitives"][0]["material"]
        .as_u64()
        .unwrap() as usize;
    doc["materials"][light_material]["extensions"] =
        json!({ "KHR_materials_emissive_strength": { "emissiveStrength": 4.0 } });

    // Strip and fan primitives over the floor's vertices, in one two-primitive mesh.
    let floor_pos = accessor_of(&doc, "floor", "POSITION");
    let floor_idx = accessor_of(&doc, "floor", "indices");
    doc["meshes"].as_array_mut().unwrap().push(json!({
        "name": "strip_and_fan",
        "primitives": [
            { "attributes": { "POSITION": floor_pos }, "indices": floor_idx, "mode": 5 },
            { "attributes": { "POSITION": floor_pos }, "mode": 6, "material": 1 }
        ]
    }));
    let extra_mesh = doc["meshes"].as_array().unwrap().len() - 1;

    // Node transforms, a hierarchy and lights.
    doc["nodes"][0]["translation"] = json!([0.0, 0.001, 0.0]);
    doc["nodes"][0]["rotation"] = json!([0.0, 0.0, 0.0, 1.0]);
    doc["nodes"][0]["scale"] = json!([1.0, 1.0, 1.0]);
    doc["nodes"][1]["matrix"] = json!([
        1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -0.001, 1.0
    ]);
    let nodes = doc["nodes"].as_array_mut().unwrap();
    let base = nodes.len();
    nodes.push(
        json!({ "name": "blocks", "children": [6, 7, base + 1, base + 2],
        "translation": [0.01, 0.0, 0.0], "scale": [1.0, 1.0, 1.0] }),
    );
    nodes.push(json!({ "name": "point", "translation": [0.27, 0.5, 0.27],
        "extensions": { "KHR_lights_punctual": { "light": 0 } } }));
    nodes.push(json!({ "name": "spot", "translation": [0.27, 0.54, 0.27],
        "rotation": [-std::f32::consts::FRAC_1_SQRT_2, 0.0, 0.0, std::f32::consts::FRAC_1_SQRT_2],
        "extensions": { "KHR_lights_punctual": { "light": 1 } } }));
    nodes.push(
        json!({ "name": "sun", "rotation": [-0.3826834, 0.0, 0.0, 0.9238795],
        "extensions": { "KHR_lights_punctual": { "light": 2 } } }),
    );
    nodes.push(json!({ "name": "extra", "mesh": extra_mesh, "translation": [0.0, -0.01, 0.0] }));
    doc["scenes"][0]["nodes"] = json!([0, 1, 2, 3, 4, 5, base, base + 3, base + 4]);
    doc["extensions"] = json!({ "KHR_lights_punctual": { "lights": [
        { "type": "point", "color": [1.0, 0.9, 0.8], "intensity": 2.0 },
        { "type": "spot", "intensity": 5.0,
          "spot": { "innerConeAngle": 0.2, "outerConeAngle": 0.6 } },
        { "type": "directional", "intensity": 1.5 }
    ] } });
    doc["extensionsUsed"] = json!(["KHR_materials_emissive_strength", "KHR_lights_punctual"]);
    doc["extensionsRequired"] = json!(["KHR_lights_punctual"]);

    doc["buffers"][0]["byteLength"] = json!(bin.len());
    GltfSeed {
        name: "rich",
        json: doc,
        bin,
    }
}

/// Splits a GLB into its JSON document and BIN chunk.
fn unpack_glb(glb: &[u8]) -> (Value, Vec<u8>) {
    let u32_at = |at: usize| u32::from_le_bytes(glb[at..at + 4].try_into().unwrap()) as usize;
    let json_len = u32_at(12);
    let json = serde_json::from_slice(&glb[20..20 + json_len]).unwrap();
    let bin_at = 20 + json_len;
    let bin = if bin_at + 8 <= glb.len() {
        glb[bin_at + 8..bin_at + 8 + u32_at(bin_at)].to_vec()
    } else {
        Vec::new()
    };
    (json, bin)
}

pub(crate) fn gltf_seeds() -> &'static [GltfSeed] {
    static SEEDS: OnceLock<Vec<GltfSeed>> = OnceLock::new();
    SEEDS.get_or_init(|| {
        let mut seeds = vec![
            GltfSeed {
                name: "cornell",
                json: cornell_json(),
                bin: cornell_bin(),
            },
            rich_seed(),
        ];
        let shared = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../shared/assets/scenes/cornell_box_suzanne/cornell_box_suzanne.glb");
        if let Ok(glb) = std::fs::read(shared) {
            let (json, bin) = unpack_glb(&glb);
            seeds.push(GltfSeed {
                name: "cornell_box_suzanne",
                json,
                bin,
            });
        }
        // Every seed must load cleanly, or the fuzzing would start from an error.
        let dir = temp_dir("seeds");
        for seed in &seeds {
            let text = gltf_text(&seed.json);
            let path = write_gltf_case(&dir, &text, &seed.bin);
            let (_, outcome) = check_scene(&path).unwrap_or_else(|e| panic!("{}: {e}", seed.name));
            outcome.unwrap_or_else(|e| panic!("seed {}: {e}", seed.name));
            let glb = dir.join("case.glb");
            std::fs::write(
                &glb,
                pack_glb(&glb_text(&seed.json, seed.bin.len()), &seed.bin),
            )
            .unwrap();
            let (_, outcome) = check_scene(&glb).unwrap_or_else(|e| panic!("{}: {e}", seed.name));
            outcome.unwrap_or_else(|e| panic!("seed {} as GLB: {e}", seed.name));
        }
        seeds
    })
}

/// The seed document for a `.gltf` next to `cornell.bin`.
pub(crate) fn gltf_text(json: &Value) -> Vec<u8> {
    let mut doc = json.clone();
    doc["buffers"][0]["uri"] = json!("cornell.bin");
    serde_json::to_vec_pretty(&doc).unwrap()
}

/// The seed document for a GLB whose BIN chunk holds `bin_len` bytes.
pub(crate) fn glb_text(json: &Value, bin_len: usize) -> Vec<u8> {
    let mut doc = json.clone();
    doc["buffers"][0] = json!({ "byteLength": bin_len });
    serde_json::to_vec(&doc).unwrap()
}

pub(crate) fn write_gltf_case(dir: &Path, text: &[u8], bin: &[u8]) -> PathBuf {
    std::fs::write(dir.join("cornell.bin"), bin).unwrap();
    let path = dir.join("case.gltf");
    std::fs::write(&path, text).unwrap();
    path
}

pub(crate) fn seed_index() -> impl Strategy<Value = Index> {
    any::<Index>()
}
