//! Text from files that a message quotes: names, channels, paths and headers come out printable.

use crate::common::{ASSETS, cornell_bin, cornell_json, mesh_index, temp_dir};
use crate::environment::{ENV_H, ENV_W};
use crate::{
    SURFCACHE, as_usize, element_offset, expect_error, expect_warning, glb_of, points_csv,
    reference, write_gltf,
};
use serde_json::json;
use std::path::Path;
use std::process::{Command, Output};

/// A name no terminal should receive raw: line breaks, a colour and a screen-clearing escape
/// sequence, an OSC title sequence ended by BEL, a C1 CSI, a right-to-left override, a line
/// separator and a long tail that a message must cut.
fn hostile_name() -> String {
    format!(
        "evil\nline\r\u{1b}[31mred\u{1b}[2J\u{1b}]0;title\u{7}\u{9b}1m\u{202e}rtl\u{2028}{}",
        "x".repeat(600)
    )
}

/// The characters a message line may not hold: controls (C0, DEL, C1) and the invisible
/// format characters that reorder or hide text.
fn unprintable(c: char) -> bool {
    c.is_control()
        || matches!(c, '\u{200b}'..='\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2028}' | '\u{2029}'
            | '\u{2066}'..='\u{2069}' | '\u{feff}' | '\u{61c}')
}

/// Like [`expect_error`], and the line is UTF-8, holds nothing [`unprintable`] and is not
/// long: a name the message quotes is cut, and so is a cause quoting a long excerpt.
#[track_caller]
fn expect_printable_error(out: &Output, needles: &[&str]) -> String {
    assert!(
        std::str::from_utf8(&out.stderr).is_ok(),
        "stderr is not UTF-8: {:?}",
        out.stderr
    );
    let line = expect_error(out, needles);
    if let Some(c) = line.chars().find(|&c| unprintable(c)) {
        panic!("unprintable {c:?} in: {line:?}");
    }
    assert!(line.chars().count() < 800, "not cut: {line}");
    line
}

/// What the line shows of [`hostile_name`] is cut short.
#[track_caller]
fn assert_name_cut(line: &str) {
    assert!(!line.contains(&"x".repeat(100)), "name not cut: {line}");
}

/// glTF names (mesh, material, node, image, URIs, extensions) through `.gltf` and `.glb`.
#[test]
fn gltf_names_are_escaped() {
    let dir = temp_dir("gltf_names_are_escaped");
    let points = points_csv(&dir);
    let name = hostile_name();
    let bin = cornell_bin();
    // What each message must show of the name: its start, escaped, and cut.
    let shown =
        r"evil\nline\r\u{1b}[31mred\u{1b}[2J\u{1b}]0;title\u{7}\u{9b}1m\u{202e}rtl\u{2028}…";

    // A mesh name, in an accessor error, a scene validation error (NaN), as .gltf and .glb.
    let mut doc = cornell_json();
    let floor = mesh_index(&doc, "floor");
    doc["meshes"][floor]["name"] = json!(name);
    let positions = as_usize(&doc["meshes"][floor]["primitives"][0]["attributes"]["POSITION"]);
    let mut count = doc.clone();
    count["accessors"][positions]["count"] = json!(400);
    let path = write_gltf(&dir, "mesh_count", &count, &bin);
    expect_printable_error(&reference(&path, &points, &[]), &["mesh_count.gltf", shown]);
    let glb = dir.join("mesh_count.glb");
    std::fs::write(&glb, glb_of(&count, &bin)).unwrap();
    expect_printable_error(&reference(&glb, &points, &[]), &["mesh_count.glb", shown]);
    let mut nan = bin.clone();
    let at = element_offset(&doc, positions, 1, 12);
    nan[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    let path = write_gltf(&dir, "mesh_nan", &doc, &nan);
    expect_printable_error(
        &reference(&path, &points, &[]),
        &["mesh_nan.gltf", shown, "NaN"],
    );

    // A material name.
    let mut doc = cornell_json();
    doc["materials"][0]["name"] = json!(name);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = json!([1e39, 1, 1, 1]);
    let path = write_gltf(&dir, "material", &doc, &bin);
    expect_printable_error(
        &reference(&path, &points, &[]),
        &["material.gltf", shown, "not finite"],
    );

    // A node name, on a node whose transform is not finite.
    let mut doc = cornell_json();
    let node = doc["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .position(|n| n.get("mesh").is_some())
        .unwrap();
    doc["nodes"][node]["name"] = json!(name);
    doc["nodes"][node]["scale"] = json!([1e39, 1, 1]);
    let path = write_gltf(&dir, "node", &doc, &bin);
    expect_printable_error(&reference(&path, &points, &[]), &["node.gltf", shown]);

    // An image URI and an image name.
    let mut doc = cornell_json();
    doc["images"] = json!([{ "uri": format!("{name}.png") }]);
    doc["textures"] = json!([{ "source": 0 }]);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({ "index": 0 });
    let path = write_gltf(&dir, "image_uri", &doc, &bin);
    expect_printable_error(
        &reference(&path, &points, &[]),
        &["image_uri.gltf", "image 0", shown, "not found"],
    );
    let mut doc = cornell_json();
    doc["images"] = json!([{ "name": name, "uri": "data:image/png;base64,AAAA" }]);
    doc["textures"] = json!([{ "source": 0 }]);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = json!({ "index": 0 });
    let path = write_gltf(&dir, "image_name", &doc, &bin);
    expect_printable_error(
        &reference(&path, &points, &[]),
        &["image_name.gltf", "image 0", shown],
    );

    // Buffer URIs: a missing file, a bad %-escape, a scheme, one decoding to invalid UTF-8.
    for (file, uri, needle) in [
        ("buffer_missing", format!("{name}.bin"), shown),
        ("buffer_escape", format!("{name}%zz.bin"), "bad %-escape"),
        (
            "buffer_scheme",
            format!("\u{1b}[2J{name}:x"),
            "unsupported URI scheme",
        ),
        (
            "buffer_utf8",
            format!("a%ff%9b\u{1b}[2J{name}"),
            "does not decode to UTF-8",
        ),
    ] {
        let mut doc = cornell_json();
        doc["buffers"][0]["uri"] = json!(uri);
        let path = dir.join(format!("{file}.gltf"));
        std::fs::write(&path, serde_json::to_vec(&doc).unwrap()).unwrap();
        expect_printable_error(
            &reference(&path, &points, &[]),
            &[&format!("{file}.gltf"), "buffer 0", needle],
        );
    }

    // A required extension: gltf's validation quotes it (and the cause is cut).
    let mut doc = cornell_json();
    doc["extensionsRequired"] = json!([name]);
    doc["extensionsUsed"] = json!([name]);
    let path = write_gltf(&dir, "extension", &doc, &bin);
    expect_printable_error(
        &reference(&path, &points, &[]),
        &[
            "extension.gltf",
            "extensionsRequired",
            r"evil\nline\r\u{1b}[31m",
        ],
    );

    // JSON that does not parse: raw control characters and invalid UTF-8 inside strings, and
    // a value of the wrong type (serde quotes it).
    let text = std::fs::read(Path::new(ASSETS).join("cornell.gltf")).unwrap();
    let mut raw = b"{\"asset\":{\"version\":\"2.0\"},\"scene\":\"\x1b[2J\n\xff\x9b\"".to_vec();
    raw.extend_from_slice(&text[1..]);
    let path = dir.join("raw.gltf");
    std::fs::write(&path, &raw).unwrap();
    expect_printable_error(&reference(&path, &points, &[]), &["raw.gltf"]);
    let mut doc = cornell_json();
    doc["scene"] = json!("\u{1b}[2J\nevil\u{202e}");
    let path = write_gltf(&dir, "wrong_type", &doc, &bin);
    expect_printable_error(&reference(&path, &points, &[]), &["wrong_type.gltf"]);
    // serde quotes the whole string: the cause is cut.
    let mut doc = cornell_json();
    doc["scene"] = json!(name);
    let path = write_gltf(&dir, "long", &doc, &bin);
    expect_printable_error(&reference(&path, &points, &[]), &["long.gltf", "evil"]);
}

/// A mesh name in a warning (the file still loads): one printable warning line.
#[test]
fn gltf_names_in_warnings_are_escaped() {
    let dir = temp_dir("gltf_names_in_warnings_are_escaped");
    let points = points_csv(&dir);
    let mut doc = cornell_json();
    let wall = mesh_index(&doc, "back_wall");
    doc["meshes"][wall]["name"] = json!(hostile_name());
    let indices = as_usize(&doc["meshes"][wall]["primitives"][0]["indices"]);
    let count = as_usize(&doc["accessors"][indices]["count"]);
    doc["accessors"][indices]["count"] = json!(count - 1);
    let path = write_gltf(&dir, "warn", &doc, &cornell_bin());
    let out = reference(&path, &points, &[]);
    let line = expect_warning(&out, &[r"evil\nline\r\u{1b}[31m", "not a multiple of 3"]);
    assert!(!line.chars().any(unprintable), "{line:?}");
    assert_name_cut(&line);
}

/// An EXR whose channel names hold a line break, an escape sequence and bytes that are not
/// UTF-8 (the fuzz failure of `SURFCACHE_FUZZ_SEED=1796197522859263124`, by hand).
#[test]
fn exr_channel_names_are_escaped() {
    use exr::prelude::*;
    let dir = temp_dir("exr_channel_names_are_escaped");
    let points = points_csv(&dir);
    let env = dir.join("channels.exr");
    let samples = || FlatSamples::F32(vec![1.0; ENV_W * ENV_H]);
    let names: [&[u8]; 4] = [b"\n", b"G", b"R\x1b[31m\r", b"\xff\x9b"];
    let channels = AnyChannels::sort(
        names
            .iter()
            .map(|n| AnyChannel::new(Text::from_slice_unchecked(n), samples()))
            .collect::<SmallVec<_>>(),
    );
    Image::from_channels((ENV_W, ENV_H), channels)
        .write()
        .to_file(&env)
        .unwrap();
    let line = expect_printable_error(
        &reference("cornell", &points, &["--env", env.to_str().unwrap()]),
        &["channels.exr", "no R, G, B channels"],
    );
    assert!(
        line.contains(r"found: \n, G, R\u{1b}[31m\r, \xff\x9b)"),
        "{line}"
    );
}

/// Paths with control characters and bytes that are not UTF-8, the CSV points header and a
/// built-in scene name.
#[test]
fn paths_csv_headers_and_scene_names_are_escaped() {
    use std::os::unix::ffi::OsStrExt;
    let dir = temp_dir("paths_csv_headers_and_scene_names_are_escaped");
    let points = points_csv(&dir);
    let bad = std::ffi::OsStr::from_bytes(b"bad\n\x1b[2J\xff\x9b");
    let mut missing_exr = dir.join(bad).into_os_string();
    missing_exr.push(".exr");
    let out = Command::new(SURFCACHE)
        .args(["reference", "cornell", "--samples", "1", "--env"])
        .arg(&missing_exr)
        .arg(&points)
        .output()
        .unwrap();
    expect_printable_error(&out, &[r"bad\n\u{1b}[2J\xff\x9b.exr"]);
    // A scene argument is text, so its path has no invalid UTF-8.
    let missing_gltf = dir.join("bad\n\u{1b}[2J.gltf");
    expect_printable_error(
        &reference(&missing_gltf, &points, &[]),
        &[r"bad\n\u{1b}[2J.gltf"],
    );
    let mut missing_csv = dir.join(bad).into_os_string();
    missing_csv.push(".csv");
    expect_printable_error(
        &reference("cornell", Path::new(&missing_csv), &[]),
        &["points file", r"bad\n\u{1b}[2J\xff\x9b.csv"],
    );

    let csv = dir.join("header.csv");
    std::fs::write(
        &csv,
        format!("x,y,z,\u{1b}[2J\r{}\n0,0,0,0,1,0\n", hostile_name()),
    )
    .unwrap();
    expect_printable_error(
        &reference("cornell", &csv, &[]),
        &["header.csv", r"found 'x,y,z,\u{1b}[2J\revil'"],
    );
    let csv = dir.join("not_utf8.csv");
    std::fs::write(&csv, b"x,y,z,nx,ny,nz\n0,0,\xff\x1b[2J,0,1,0\n").unwrap();
    expect_printable_error(&reference("cornell", &csv, &[]), &["not_utf8.csv"]);
    let csv = dir.join("value.csv");
    std::fs::write(&csv, "x,y,z,nx,ny,nz\n0,0,\u{1b}[2J\u{9b}1m,0,1,0\n").unwrap();
    expect_printable_error(&reference("cornell", &csv, &[]), &["value.csv", "line 2"]);

    expect_printable_error(
        &reference("cornell\u{1b}[2J\n", &points, &[]),
        &[r"unknown built-in scene 'cornell\u{1b}[2J\n'"],
    );
}
