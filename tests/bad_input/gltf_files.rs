//! Broken glTF input: containers, referenced files, accessors and primitives.

use crate::common::{ASSETS, cornell_bin, cornell_json, mesh_index, temp_dir};
use crate::{
    as_usize, cornell_triangles, expect_clean_success, expect_error, expect_warning,
    first_triangle, glb_of, points_csv, position_offset, primitive, read_vec3, reference,
    triangles_of, write_gltf, write_vec3,
};
use serde_json::json;
use std::path::Path;

// --- containers ---------------------------------------------------------------------------

#[test]
fn truncated_glb() {
    let dir = temp_dir("truncated_glb");
    let points = points_csv(&dir);
    let glb = glb_of(&cornell_json(), &cornell_bin());
    // The whole file loads, so what fails below is the truncation alone.
    let whole = dir.join("cornell.glb");
    std::fs::write(&whole, &glb).unwrap();
    expect_clean_success(&reference(&whole, &points, &[]));
    let loaded = surfcache::io::load_gltf(&whole).unwrap();
    assert_eq!(loaded.scene.triangle_count(), cornell_triangles());

    for len in [100, 8, 30, glb.len() / 2, glb.len() - 1] {
        let cut = dir.join(format!("cut{len}.glb"));
        std::fs::write(&cut, &glb[..len]).unwrap();
        expect_error(
            &reference(&cut, &points, &[]),
            &[&format!("cut{len}.glb"), "truncated"],
        );
    }
}

#[test]
fn garbage_named_glb() {
    let dir = temp_dir("garbage_named_glb");
    let points = points_csv(&dir);
    // Deterministic noise (a 64-bit LCG), never starting with "glTF" or '{'.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut noise: Vec<u8> = (0..600)
        .map(|_| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 56) as u8
        })
        .collect();
    noise[0] = 0x89;
    let path = dir.join("noise.glb");
    std::fs::write(&path, &noise).unwrap();
    expect_error(
        &reference(&path, &points, &[]),
        &["noise.glb", "not a GLB file"],
    );

    // The magic and a consistent length, then noise: the chunk headers are nonsense.
    let mut fake = b"glTF".to_vec();
    fake.extend_from_slice(&2u32.to_le_bytes());
    fake.extend_from_slice(&(noise.len() as u32 + 12).to_le_bytes());
    fake.extend_from_slice(&noise);
    let path = dir.join("fake.glb");
    std::fs::write(&path, &fake).unwrap();
    expect_error(&reference(&path, &points, &[]), &["fake.glb"]);

    let empty = dir.join("empty.glb");
    std::fs::write(&empty, b"").unwrap();
    expect_error(&reference(&empty, &points, &[]), &["empty.glb", "empty"]);
}

#[test]
fn malformed_json_gltf() {
    let dir = temp_dir("malformed_json_gltf");
    let points = points_csv(&dir);
    std::fs::write(dir.join("cornell.bin"), cornell_bin()).unwrap();
    let text = std::fs::read_to_string(Path::new(ASSETS).join("cornell.gltf")).unwrap();
    let cut = dir.join("cut.gltf");
    std::fs::write(&cut, &text[..text.len() / 2]).unwrap();
    expect_error(
        &reference(&cut, &points, &[]),
        &["cut.gltf", "malformed glTF JSON"],
    );

    // Valid JSON that is not a glTF document.
    let wrong = dir.join("wrong.gltf");
    std::fs::write(&wrong, r#"{"asset": 3, "meshes": "none"}"#).unwrap();
    expect_error(&reference(&wrong, &points, &[]), &["wrong.gltf"]);
}

// --- referenced files ---------------------------------------------------------------------

#[test]
fn missing_buffer_file() {
    let dir = temp_dir("missing_buffer_file");
    let points = points_csv(&dir);
    let mut doc = cornell_json();
    doc["buffers"][0]["uri"] = json!("gone.bin");
    let path = dir.join("nobuf.gltf");
    std::fs::write(&path, serde_json::to_vec(&doc).unwrap()).unwrap();
    expect_error(
        &reference(&path, &points, &[]),
        &["nobuf.gltf", "buffer 0", "gone.bin", "not found"],
    );
}

#[test]
fn missing_image_file() {
    let dir = temp_dir("missing_image_file");
    let points = points_csv(&dir);
    let mut doc = cornell_json();
    doc["images"] = json!([{ "uri": "gone.png" }]);
    doc["textures"] = json!([{ "source": 0 }]);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({ "index": 0 });
    let path = write_gltf(&dir, "noimage", &doc, &cornell_bin());
    expect_error(
        &reference(&path, &points, &[]),
        &["noimage.gltf", "image 0", "gone.png", "not found"],
    );
}

// --- accessors and primitives ---------------------------------------------------------------

#[test]
fn accessor_out_of_range() {
    let dir = temp_dir("accessor_out_of_range");
    let points = points_csv(&dir);
    let bin = cornell_bin();
    let floor_positions = as_usize(&primitive(&cornell_json(), "floor")["attributes"]["POSITION"]);
    let floor_indices = as_usize(&primitive(&cornell_json(), "floor")["indices"]);

    // Count beyond the buffer view.
    let mut doc = cornell_json();
    doc["accessors"][floor_positions]["count"] = json!(400);
    let path = write_gltf(&dir, "count", &doc, &bin);
    expect_error(
        &reference(&path, &points, &[]),
        &[
            "count.gltf",
            "floor",
            &format!("accessor {floor_positions}"),
            "400 elements",
        ],
    );

    // Offset pushing the last element past the view.
    let mut doc = cornell_json();
    doc["accessors"][floor_indices]["byteOffset"] = json!(8);
    let path = write_gltf(&dir, "offset", &doc, &bin);
    expect_error(
        &reference(&path, &points, &[]),
        &[
            "offset.gltf",
            "floor",
            &format!("accessor {floor_indices}"),
            "byte 8",
        ],
    );

    // A buffer view beyond the buffer.
    let mut doc = cornell_json();
    let view = as_usize(&doc["accessors"][floor_positions]["bufferView"]);
    doc["bufferViews"][view]["byteOffset"] = json!(bin.len() - 8);
    let path = write_gltf(&dir, "view", &doc, &bin);
    expect_error(
        &reference(&path, &points, &[]),
        &[
            "view.gltf",
            &format!("buffer view {view}"),
            "beyond buffer 0",
        ],
    );

    // An index naming a vertex that does not exist.
    let mut bad = bin.clone();
    let (_, at) = first_triangle(&cornell_json(), &bin, "floor");
    bad[at..at + 4].copy_from_slice(&77u32.to_le_bytes());
    let path = write_gltf(&dir, "index", &cornell_json(), &bad);
    expect_error(
        &reference(&path, &points, &[]),
        &["index.gltf", "floor", "77"],
    );
}

#[test]
fn points_and_lines_primitives_are_skipped() {
    let dir = temp_dir("points_and_lines_primitives_are_skipped");
    let points = points_csv(&dir);
    let mut doc = cornell_json();
    let back = mesh_index(&doc, "back_wall");
    let red = mesh_index(&doc, "red_wall");
    doc["meshes"][back]["primitives"][0]["mode"] = json!(0); // POINTS
    doc["meshes"][red]["primitives"][0]["mode"] = json!(1); // LINES
    let path = write_gltf(&dir, "mixed", &doc, &cornell_bin());
    expect_warning(
        &reference(&path, &points, &[]),
        &["skipped 2 primitive(s)", "points or lines"],
    );
    let loaded = surfcache::io::load_gltf(&path).unwrap();
    assert_eq!(loaded.report.skipped_primitives, 2);
    assert_eq!(loaded.report.degenerate_triangles, 0);
    assert_eq!(
        loaded.scene.triangle_count(),
        cornell_triangles() - triangles_of(&doc, "back_wall") - triangles_of(&doc, "red_wall")
    );
}

#[test]
fn only_points_and_lines_is_an_error() {
    let dir = temp_dir("only_points_and_lines_is_an_error");
    let points = points_csv(&dir);
    let mut doc = cornell_json();
    let meshes = doc["meshes"].as_array().unwrap().len();
    for m in 0..meshes {
        doc["meshes"][m]["primitives"][0]["mode"] = json!(if m % 2 == 0 { 3 } else { 0 });
    }
    let path = write_gltf(&dir, "lines", &doc, &cornell_bin());
    expect_error(
        &reference(&path, &points, &[]),
        &[
            "lines.gltf",
            "the scene has no triangles",
            &format!("{meshes} point/line primitive(s) skipped"),
        ],
    );
}

#[test]
fn nan_vertex_position() {
    let dir = temp_dir("nan_vertex_position");
    let points = points_csv(&dir);
    let doc = cornell_json();
    let mut bin = cornell_bin();
    let at = position_offset(&doc, "back_wall", 2);
    let mut p = read_vec3(&bin, at);
    p.y = f32::NAN;
    write_vec3(&mut bin, at, p);
    let path = write_gltf(&dir, "nan", &doc, &bin);
    expect_error(
        &reference(&path, &points, &[]),
        &["nan.gltf", "mesh 'back_wall'", "vertex 2", "NaN"],
    );
}

#[test]
fn infinite_vertex_position() {
    let dir = temp_dir("infinite_vertex_position");
    let points = points_csv(&dir);
    let doc = cornell_json();
    let mut bin = cornell_bin();
    let at = position_offset(&doc, "short_block", 5);
    let mut p = read_vec3(&bin, at);
    p.z = f32::NEG_INFINITY;
    write_vec3(&mut bin, at, p);
    let path = write_gltf(&dir, "inf", &doc, &bin);
    expect_error(
        &reference(&path, &points, &[]),
        &["inf.gltf", "mesh 'short_block'", "vertex 5", "inf"],
    );
}

#[test]
fn degenerate_triangles_are_dropped() {
    let dir = temp_dir("degenerate_triangles_are_dropped");
    let points = points_csv(&dir);
    let doc = cornell_json();
    let mut bin = cornell_bin();
    // Floor: the first triangle repeats an index.
    let ([a, _, c], at) = first_triangle(&doc, &bin, "floor");
    for (k, i) in [a, a, c].into_iter().enumerate() {
        bin[at + 4 * k..at + 4 * k + 4].copy_from_slice(&i.to_le_bytes());
    }
    // Back wall: the first triangle's third corner moves onto the middle of its first edge,
    // so its indices differ but its area is zero.
    let ([a, b, c], _) = first_triangle(&doc, &bin, "back_wall");
    let pa = read_vec3(&bin, position_offset(&doc, "back_wall", a as usize));
    let pb = read_vec3(&bin, position_offset(&doc, "back_wall", b as usize));
    write_vec3(
        &mut bin,
        position_offset(&doc, "back_wall", c as usize),
        0.5 * (pa + pb),
    );
    let path = write_gltf(&dir, "degenerate", &doc, &bin);
    expect_warning(
        &reference(&path, &points, &[]),
        &["dropped 2 degenerate or zero-area triangle(s)"],
    );
    let loaded = surfcache::io::load_gltf(&path).unwrap();
    assert_eq!(loaded.report.degenerate_triangles, 2);
    assert_eq!(loaded.report.skipped_primitives, 0);
    assert_eq!(loaded.scene.triangle_count(), cornell_triangles() - 2);
    // The other halves of both quads remain.
    for name in ["floor", "back_wall"] {
        let inst = loaded
            .scene
            .instances
            .iter()
            .find(|i| i.name == name)
            .unwrap();
        assert_eq!(inst.mesh.indices.len(), triangles_of(&doc, name) - 1);
    }
}
