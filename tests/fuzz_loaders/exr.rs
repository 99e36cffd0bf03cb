//! EXR: seeds of several compressions and layouts, header edits, and the EXR target.

use crate::common::{ASSETS, temp_dir};
use crate::gltf_seeds::seed_index;
use crate::mutations::{ByteEdit, INTERESTING_32, byte_edit, pick};
use crate::running::{Stats, fuzz, message, printable};
use proptest::prelude::*;
use proptest::sample::Index;
use std::fmt::Debug;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use surfcache::core::glam::Vec3;

/// Where things are in a single-part EXR: header attributes and the chunks.
pub(crate) struct ExrLayout {
    /// Per attribute: where its type name starts and ends (the NUL), its size field and value.
    pub(crate) attributes: Vec<ExrAttribute>,
    /// Start of the offset table and its entries.
    table: usize,
    chunks: usize,
}

pub(crate) struct ExrAttribute {
    pub(crate) type_name: (usize, usize),
    size_field: usize,
    pub(crate) value: (usize, usize),
}

fn exr_layout(bytes: &[u8]) -> ExrLayout {
    let cstr = |at: usize| at + bytes[at..].iter().position(|&b| b == 0).unwrap();
    let mut at = 8;
    let mut attributes = Vec::new();
    while bytes[at] != 0 {
        let name_end = cstr(at);
        let type_end = cstr(name_end + 1);
        let size_field = type_end + 1;
        let size = u32::from_le_bytes(bytes[size_field..size_field + 4].try_into().unwrap());
        let value = (size_field + 4, size_field + 4 + size as usize);
        attributes.push(ExrAttribute {
            type_name: (name_end + 1, type_end),
            size_field,
            value,
        });
        at = value.1;
    }
    let table = at + 1;
    let first = u64::from_le_bytes(bytes[table..table + 8].try_into().unwrap()) as usize;
    ExrLayout {
        attributes,
        table,
        chunks: (first - table) / 8,
    }
}

/// An EXR seed: its bytes and layout.
pub(crate) struct ExrSeed {
    pub(crate) bytes: Vec<u8>,
    pub(crate) layout: ExrLayout,
}

/// Bytes no terminal should receive raw: line breaks, ESC, DEL, a C1 CSI, bytes that are
/// not UTF-8 on their own.
pub(crate) const HOSTILE_BYTES: &[u8] = &[b'\n', b'\r', 0x1b, 0x7f, 0x9b, 0x85, 0xc3, 0xff];

const EXR_TYPES: &[&str] = &[
    "box2i",
    "chlist",
    "compression",
    "float",
    "int",
    "lineOrder",
    "string",
    "v2f",
    "tiledesc",
    "preview",
    "double",
    "",
    "x",
];

#[derive(Clone, Debug)]
enum ExrEdit {
    Bytes(ByteEdit),
    /// An attribute's size field set to one of [`INTERESTING_32`].
    AttrSize {
        attr: Index,
        value: Index,
    },
    /// A 4-byte word of an attribute's value set to one of [`INTERESTING_32`].
    AttrWord {
        attr: Index,
        at: Index,
        value: Index,
    },
    AttrFlip {
        attr: Index,
        at: Index,
        xor: u8,
    },
    /// A byte of an attribute's value (a channel or attribute name, say) set to one of
    /// [`HOSTILE_BYTES`].
    AttrByte {
        attr: Index,
        at: Index,
        byte: Index,
    },
    /// An attribute's type name replaced by another.
    AttrType {
        attr: Index,
        name: Index,
    },
    /// An entry of the offset table moved by `delta` or set to `set`.
    Offset {
        which: Index,
        delta: i64,
        set: Option<Index>,
    },
    /// A 4-byte word of a chunk's header (coordinates, size) set to one of [`INTERESTING_32`].
    ChunkWord {
        chunk: Index,
        word: usize,
        value: Index,
    },
}

fn exr_edit() -> impl Strategy<Value = ExrEdit> {
    prop_oneof![
        4 => byte_edit().prop_map(ExrEdit::Bytes),
        2 => (any::<Index>(), any::<Index>())
            .prop_map(|(attr, value)| ExrEdit::AttrSize { attr, value }),
        4 => (any::<Index>(), any::<Index>(), any::<Index>())
            .prop_map(|(attr, at, value)| ExrEdit::AttrWord { attr, at, value }),
        2 => (any::<Index>(), any::<Index>(), 1..=255u8)
            .prop_map(|(attr, at, xor)| ExrEdit::AttrFlip { attr, at, xor }),
        1 => (any::<Index>(), any::<Index>(), any::<Index>())
            .prop_map(|(attr, at, byte)| ExrEdit::AttrByte { attr, at, byte }),
        1 => (any::<Index>(), any::<Index>())
            .prop_map(|(attr, name)| ExrEdit::AttrType { attr, name }),
        2 => (any::<Index>(), -64..64i64, prop::option::of(any::<Index>()))
            .prop_map(|(which, delta, set)| ExrEdit::Offset { which, delta, set }),
        2 => (any::<Index>(), 0..5usize, any::<Index>())
            .prop_map(|(chunk, word, value)| ExrEdit::ChunkWord { chunk, word, value }),
    ]
}

fn put32(bytes: &mut [u8], at: usize, value: u32) {
    if let Some(w) = bytes.get_mut(at..at + 4) {
        w.copy_from_slice(&value.to_le_bytes());
    }
}

impl ExrEdit {
    /// Applies the edit; structure-aware edits use the seed's layout (an earlier edit that
    /// moved bytes makes them land elsewhere, which is fine for fuzzing).
    fn apply(&self, bytes: &mut Vec<u8>, layout: &ExrLayout) {
        let attr = |i: &Index| &layout.attributes[i.index(layout.attributes.len())];
        match self {
            ExrEdit::Bytes(e) => e.apply(bytes),
            ExrEdit::AttrSize { attr: a, value } => {
                put32(bytes, attr(a).size_field, pick(INTERESTING_32, value))
            }
            ExrEdit::AttrWord { attr: a, at, value } => {
                let (start, end) = attr(a).value;
                if end > start {
                    let at = start + at.index(end - start);
                    put32(bytes, at, pick(INTERESTING_32, value));
                }
            }
            ExrEdit::AttrFlip { attr: a, at, xor } => {
                let (start, end) = attr(a).value;
                if end > start
                    && let Some(b) = bytes.get_mut(start + at.index(end - start))
                {
                    *b ^= xor;
                }
            }
            ExrEdit::AttrByte { attr: a, at, byte } => {
                let (start, end) = attr(a).value;
                if end > start
                    && let Some(b) = bytes.get_mut(start + at.index(end - start))
                {
                    *b = pick(HOSTILE_BYTES, byte);
                }
            }
            ExrEdit::AttrType { attr: a, name } => {
                let (start, end) = attr(a).type_name;
                if end <= bytes.len() {
                    bytes.splice(start..end, pick(EXR_TYPES, name).bytes());
                }
            }
            ExrEdit::Offset { which, delta, set } => {
                if layout.chunks > 0 {
                    let at = layout.table + 8 * which.index(layout.chunks);
                    if let Some(w) = bytes.get_mut(at..at + 8) {
                        let old = u64::from_le_bytes(w.try_into().unwrap());
                        let len = bytes.len() as u64;
                        let new = match set {
                            Some(i) => pick(
                                &[
                                    0,
                                    1,
                                    8,
                                    len / 2,
                                    len - 1,
                                    len,
                                    len + 1,
                                    1 << 32,
                                    1 << 63,
                                    u64::MAX,
                                ],
                                i,
                            ),
                            None => old.wrapping_add_signed(*delta),
                        };
                        bytes[at..at + 8].copy_from_slice(&new.to_le_bytes());
                    }
                }
            }
            ExrEdit::ChunkWord { chunk, word, value } => {
                if layout.chunks > 0 {
                    let entry = layout.table + 8 * chunk.index(layout.chunks);
                    if let Some(w) = bytes.get(entry..entry + 8) {
                        let start = u64::from_le_bytes(w.try_into().unwrap());
                        if let Ok(start) = usize::try_from(start) {
                            put32(
                                bytes,
                                start.saturating_add(4 * word),
                                pick(INTERESTING_32, value),
                            );
                        }
                    }
                }
            }
        }
    }
}

/// A smooth test image with a few negative values.
fn exr_pixel(x: usize, y: usize) -> (f32, f32, f32) {
    let (fx, fy) = (x as f32, y as f32);
    (
        0.1 * fx + 0.01,
        0.5 + 0.25 * (fx * 0.7 + fy).sin(),
        2.0 - 0.3 * fy,
    )
}

pub(crate) fn exr_seeds() -> &'static [ExrSeed] {
    static SEEDS: OnceLock<Vec<ExrSeed>> = OnceLock::new();
    SEEDS.get_or_init(|| {
        use exr::prelude::*;
        let dir = temp_dir("exr_seeds");
        let mut files =
            vec![std::fs::read(Path::new(ASSETS).join("cornell_environment.exr")).unwrap()];

        let (w, h) = (16u32, 8u32);
        let texels: Vec<Vec3> = (0..(w * h) as usize)
            .map(|i| {
                let (r, g, b) = exr_pixel(i % w as usize, i / w as usize);
                Vec3::new(r, g, b)
            })
            .collect();
        let path = dir.join("write_rgb_exr.exr");
        surfcache::io::write_rgb_exr(&path, w, h, &texels).unwrap();
        files.push(std::fs::read(&path).unwrap());

        let size = (w as usize, h as usize);
        let f32_rgb = |p: Vec2<usize>| exr_pixel(p.0, p.1);
        let f16_rgb = |p: Vec2<usize>| {
            let (r, g, b) = exr_pixel(p.0, p.1);
            (f16::from_f32(r), f16::from_f32(g), f16::from_f32(b))
        };
        let mixed = |p: Vec2<usize>| {
            let (r, g, b) = exr_pixel(p.0, p.1);
            (f16::from_f32(r), g, (b.max(0.0) * 10.0) as u32)
        };
        let encodings = [
            (Compression::Uncompressed, Blocks::ScanLines),
            (Compression::RLE, Blocks::ScanLines),
            (Compression::ZIP1, Blocks::Tiles(Vec2(8, 4))),
            (Compression::PIZ, Blocks::ScanLines),
            (Compression::PXR24, Blocks::ScanLines),
            (Compression::B44, Blocks::ScanLines),
            (Compression::B44A, Blocks::Tiles(Vec2(4, 4))),
        ];
        for (k, (compression, blocks)) in encodings.into_iter().enumerate() {
            let encoding = Encoding {
                compression,
                blocks,
                line_order: LineOrder::Increasing,
            };
            let path = dir.join(format!("{k}.exr"));
            let attributes = LayerAttributes::named("layer");
            // The B44 codecs compress only f16 samples; one file mixes sample types.
            if matches!(compression, Compression::B44 | Compression::B44A) {
                let channels = SpecificChannels::rgb(f16_rgb);
                Image::from_layer(Layer::new(size, attributes, encoding, channels))
                    .write()
                    .to_file(&path)
                    .unwrap();
            } else if compression == Compression::RLE {
                let channels = SpecificChannels::rgb(mixed);
                Image::from_layer(Layer::new(size, attributes, encoding, channels))
                    .write()
                    .to_file(&path)
                    .unwrap();
            } else {
                let channels = SpecificChannels::rgb(f32_rgb);
                Image::from_layer(Layer::new(size, attributes, encoding, channels))
                    .write()
                    .to_file(&path)
                    .unwrap();
            }
            files.push(std::fs::read(&path).unwrap());
        }
        files
            .into_iter()
            .map(|bytes| {
                let layout = exr_layout(&bytes);
                assert!(!layout.attributes.is_empty() && layout.chunks > 0);
                ExrSeed { bytes, layout }
            })
            .collect()
    })
}

#[derive(Clone, Debug)]
struct ExrCase {
    seed: Index,
    environment: bool,
    edits: Vec<ExrEdit>,
}

pub(crate) fn fuzz_exr(cases: u32, seed: u64, rerun: &str) -> Stats {
    let seeds = exr_seeds();
    let dir = temp_dir("exr");
    // Every seed reads cleanly.
    for (k, s) in seeds.iter().enumerate() {
        let path = dir.join(format!("seed{k}.exr"));
        std::fs::write(&path, &s.bytes).unwrap();
        surfcache::io::read_rgb_exr(&path).unwrap_or_else(|e| panic!("EXR seed {k}: {e}"));
    }
    let strategy = (
        seed_index(),
        any::<bool>(),
        prop::collection::vec(exr_edit(), 1..4),
    )
        .prop_map(|(seed, environment, edits)| ExrCase {
            seed,
            environment,
            edits,
        });
    fuzz("EXR", cases, seed, rerun, strategy, |case| {
        let s = &seeds[case.seed.index(seeds.len())];
        let mut bytes = s.bytes.clone();
        for e in &case.edits {
            e.apply(&mut bytes, &s.layout);
        }
        check_exr(&dir, &bytes, case.environment)
    })
}

/// Reads `bytes` as an EXR (an environment map or not): the outcome, or the violated
/// property.
pub(crate) fn check_exr(
    dir: &Path,
    bytes: &[u8],
    environment: bool,
) -> Result<(PathBuf, Result<(), String>), String> {
    let path = dir.join("case.exr");
    std::fs::write(&path, bytes).unwrap();
    let outcome = if environment {
        surfcache::io::read_environment_map(&path)
            .map(|(map, warnings)| (map.width, map.height, map.texels, warnings))
    } else {
        surfcache::io::read_rgb_exr(&path).map(|(w, h, t)| (w, h, t, Vec::new()))
    };
    let outcome = match outcome {
        Ok((w, h, texels, warnings)) => {
            if w == 0 || h == 0 || texels.len() != w as usize * h as usize {
                return Err(format!("{w}×{h} image with {} texels", texels.len()));
            }
            if let Some(i) = texels.iter().position(|t| !t.is_finite()) {
                return Err(format!("texel {i} is {}", texels[i]));
            }
            if environment && texels.iter().any(|t| t.min_element() < 0.0) {
                return Err("negative texel in an environment map".into());
            }
            if let Some(w) = warnings.iter().find(|w| !printable(w)) {
                return Err(format!("warning is not one printable line: {w:?}"));
            }
            Ok(())
        }
        Err(e) => Err(message(&e)?),
    };
    Ok((path, outcome))
}
