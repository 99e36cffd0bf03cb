//! glTF targets: mutated `.gltf` text, its buffer, and GLB containers.

use crate::checking::check_scene;
use crate::common::{ASSETS, pack_glb, temp_dir};
use crate::gltf_seeds::{glb_text, gltf_seeds, gltf_text, seed_index, write_gltf_case};
use crate::mutations::{ByteEdit, INTERESTING_32, TextEdit, byte_edit, pick, text_edit};
use crate::running::{Stats, fuzz};
use proptest::prelude::*;
use proptest::sample::Index;
use std::fmt::Debug;
use std::path::Path;

/// A mutated `.gltf` beside a `cornell.bin` that is intact or also mutated.
#[derive(Clone, Debug)]
struct GltfCase {
    seed: Index,
    text: Vec<TextEdit>,
    bin: Vec<ByteEdit>,
}

fn gltf_case() -> impl Strategy<Value = GltfCase> {
    (
        seed_index(),
        prop::collection::vec(text_edit(), 1..4),
        prop_oneof![
            3 => Just(Vec::new()),
            1 => prop::collection::vec(byte_edit(), 1..4),
        ],
    )
        .prop_map(|(seed, text, bin)| GltfCase { seed, text, bin })
}

pub(crate) fn fuzz_gltf_json(cases: u32, seed: u64, rerun: &str) -> Stats {
    let seeds = gltf_seeds();
    let dir = temp_dir("gltf_json");
    fuzz("glTF JSON", cases, seed, rerun, gltf_case(), |case| {
        let s = &seeds[case.seed.index(seeds.len())];
        let mut text = gltf_text(&s.json);
        if s.name == "cornell" {
            text = std::fs::read(Path::new(ASSETS).join("cornell.gltf")).unwrap();
        }
        for e in &case.text {
            e.apply(&mut text);
        }
        let mut bin = s.bin.clone();
        for e in &case.bin {
            e.apply(&mut bin);
        }
        check_scene(&write_gltf_case(&dir, &text, &bin))
    })
}

/// An intact `.gltf` beside a mutated `cornell.bin`.
#[derive(Clone, Debug)]
struct BinCase {
    seed: Index,
    bin: Vec<ByteEdit>,
}

pub(crate) fn fuzz_gltf_bin(cases: u32, seed: u64, rerun: &str) -> Stats {
    let seeds = gltf_seeds();
    let dir = temp_dir("gltf_bin");
    let strategy = (seed_index(), prop::collection::vec(byte_edit(), 1..6))
        .prop_map(|(seed, bin)| BinCase { seed, bin });
    fuzz("glTF buffer", cases, seed, rerun, strategy, |case| {
        let s = &seeds[case.seed.index(seeds.len())];
        let mut bin = s.bin.clone();
        for e in &case.bin {
            e.apply(&mut bin);
        }
        check_scene(&write_gltf_case(&dir, &gltf_text(&s.json), &bin))
    })
}

/// A field of the GLB container: magic, version, length, JSON chunk length and type, BIN
/// chunk length and type.
const GLB_FIELDS: usize = 7;

#[derive(Clone, Debug)]
enum FieldValue {
    Set(Index),
    Add(i32),
}

#[derive(Clone, Debug)]
enum GlbEdit {
    /// Of the JSON chunk's text, before packing.
    Json(TextEdit),
    /// Of the BIN chunk, before packing.
    Bin(ByteEdit),
    /// Of a header field, after packing.
    Field { field: usize, value: FieldValue },
    /// Of the packed bytes.
    Raw(ByteEdit),
}

#[derive(Clone, Debug)]
struct GlbCase {
    seed: Index,
    edits: Vec<GlbEdit>,
}

fn glb_edit() -> impl Strategy<Value = GlbEdit> {
    let value = prop_oneof![
        any::<Index>().prop_map(FieldValue::Set),
        (-9..=9i32).prop_map(FieldValue::Add),
    ];
    prop_oneof![
        3 => text_edit().prop_map(GlbEdit::Json),
        2 => byte_edit().prop_map(GlbEdit::Bin),
        2 => (0..GLB_FIELDS, value).prop_map(|(field, value)| GlbEdit::Field { field, value }),
        1 => byte_edit().prop_map(GlbEdit::Raw),
    ]
}

pub(crate) fn fuzz_glb(cases: u32, seed: u64, rerun: &str) -> Stats {
    let seeds = gltf_seeds();
    let dir = temp_dir("glb");
    let strategy = (seed_index(), prop::collection::vec(glb_edit(), 1..4))
        .prop_map(|(seed, edits)| GlbCase { seed, edits });
    fuzz("GLB", cases, seed, rerun, strategy, |case| {
        let s = &seeds[case.seed.index(seeds.len())];
        let mut json = glb_text(&s.json, s.bin.len());
        let mut bin = s.bin.clone();
        for e in &case.edits {
            match e {
                GlbEdit::Json(e) => e.apply(&mut json),
                GlbEdit::Bin(e) => e.apply(&mut bin),
                _ => {}
            }
        }
        let mut glb = pack_glb(&json, &bin);
        let bin_header = 20 + json.len().next_multiple_of(4);
        for e in &case.edits {
            match e {
                GlbEdit::Field { field, value } => {
                    let at = [0, 4, 8, 12, 16, bin_header, bin_header + 4][*field];
                    if let Some(word) = glb.get_mut(at..at + 4) {
                        let old = u32::from_le_bytes(word.try_into().unwrap());
                        let new = match value {
                            FieldValue::Set(i) => pick(INTERESTING_32, i),
                            FieldValue::Add(d) => old.wrapping_add_signed(*d),
                        };
                        word.copy_from_slice(&new.to_le_bytes());
                    }
                }
                GlbEdit::Raw(e) => e.apply(&mut glb),
                _ => {}
            }
        }
        let path = dir.join("case.glb");
        std::fs::write(&path, &glb).unwrap();
        check_scene(&path)
    })
}
