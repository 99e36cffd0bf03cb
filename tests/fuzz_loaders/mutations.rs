//! Mutations: edits of raw bytes and of JSON text, and the values they write.

use proptest::prelude::*;
use proptest::sample::Index;
use serde_json::{Value, json};
use std::fmt::Debug;
use std::sync::OnceLock;

/// 32-bit values that tend to break parsers: small counts, boundaries, sign bits and the bit
/// patterns of special floats.
pub(crate) const INTERESTING_32: &[u32] = &[
    0,
    1,
    2,
    3,
    4,
    7,
    8,
    12,
    15,
    16,
    20,
    31,
    32,
    63,
    64,
    77,
    255,
    256,
    0x7fff,
    0x8000,
    0xffff,
    0x1_0000,
    0x10_0000,
    0x100_0000,
    0x4000_0000,
    0x7fff_ffff,
    0x8000_0000,
    0x8000_0001,
    0xffff_fff4,
    0xffff_fffe,
    0xffff_ffff,
    0x7fc0_0000, // NaN
    0xffc0_0000, // -NaN
    0x7f80_0000, // +inf
    0xff80_0000, // -inf
    0x7f7f_ffff, // f32::MAX
    0xff7f_ffff, // f32::MIN
    0x0000_0001, // smallest subnormal
    0x8000_0000, // -0.0
    0x3f80_0000, // 1.0
    0xbf80_0000, // -1.0
    0x6c00_0000, // ~6e26
    0x7e96_7699, // 1e38
];

/// Number tokens written over a number of the JSON text.
const NUMBER_TOKENS: &[&str] = &[
    "0",
    "-0",
    "-1",
    "-2",
    "1",
    "2",
    "3",
    "5",
    "0.5",
    "-0.5",
    "1.5",
    "255",
    "65535",
    "65536",
    "2147483647",
    "2147483648",
    "4294967295",
    "4294967296",
    "9007199254740993",
    "9223372036854775807",
    "-9223372036854775808",
    "18446744073709551615",
    "18446744073709551616",
    "99999999999999999999999999",
    "3.4028235e38",
    "3.5e38",
    "1e39",
    "-1e39",
    "1e300",
    "1.7976931348623157e308",
    "1e309",
    "-1e309",
    "1e-45",
    "1e-320",
    "NaN",
    "-Infinity",
    "Infinity",
    "1e",
    "0x10",
    "--1",
    "1.2.3",
];

/// Tokens inserted into JSON text.
const JSON_TOKENS: &[&str] = &[
    "{",
    "}",
    "[",
    "]",
    ",",
    ":",
    "\"",
    "\\",
    "null",
    "true",
    "-",
    "0",
    "1e39",
    "\"\":",
    "\\u0000",
    "\\ud800",
    "{}",
    "[]",
    "\u{feff}",
    "\u{0}",
    "\u{ffff}",
    "\\n",
    "\\r",
    "\\u001b[2J",
    "\\u009b",
    "\\u202e",
    "\u{1b}",
    "\n",
    "\u{9b}",
];

/// Keys added to objects of the document, most of them glTF properties.
const JSON_KEYS: &[&str] = &[
    "name",
    "byteOffset",
    "byteLength",
    "byteStride",
    "count",
    "componentType",
    "type",
    "normalized",
    "sparse",
    "bufferView",
    "buffer",
    "indices",
    "mode",
    "material",
    "POSITION",
    "NORMAL",
    "TEXCOORD_0",
    "TEXCOORD_1",
    "matrix",
    "translation",
    "rotation",
    "scale",
    "children",
    "mesh",
    "scene",
    "nodes",
    "uri",
    "min",
    "max",
    "emissiveFactor",
    "baseColorFactor",
    "metallicFactor",
    "alphaMode",
    "alphaCutoff",
    "doubleSided",
    "baseColorTexture",
    "emissiveTexture",
    "images",
    "textures",
    "source",
    "index",
    "texCoord",
    "mimeType",
    "extensionsRequired",
    "extensionsUsed",
    "extensions",
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "emissiveStrength",
    "lights",
    "light",
    "intensity",
    "color",
    "spot",
    "innerConeAngle",
    "outerConeAngle",
    "values",
];

/// Values written into the document.
fn json_values() -> &'static [Value] {
    static VALUES: OnceLock<Vec<Value>> = OnceLock::new();
    VALUES.get_or_init(|| {
        let mut identity = vec![0.0; 16];
        for k in 0..4 {
            identity[5 * k] = 1.0;
        }
        let mut huge_translation = identity.clone();
        huge_translation[12] = 1e39;
        let mut huge_scale = identity.clone();
        for k in 0..3 {
            huge_scale[5 * k] = 3e38;
        }
        let mut singular = identity.clone();
        singular[0] = 0.0;
        vec![
            json!(null),
            json!(true),
            json!(false),
            json!(0),
            json!(1),
            json!(2),
            json!(3),
            json!(4),
            json!(5),
            json!(6),
            json!(7),
            json!(12),
            json!(100),
            json!(-1),
            json!(5120),
            json!(5121),
            json!(5123),
            json!(5125),
            json!(5126),
            json!(34962),
            json!(4294967295u64),
            json!(4294967296u64),
            json!(u64::MAX),
            json!(i64::MIN),
            json!(0.5),
            json!(-0.5),
            json!(1e39),
            json!(-1e39),
            json!(3e38),
            json!(f64::MAX),
            json!(1e-45),
            json!(""),
            json!("x"),
            json!("\u{1b}[31mred\n\r\u{9b}2J\u{202e}\u{2028}"),
            json!("x".repeat(300)),
            json!("\u{1b}[2J.bin"),
            json!("\u{1b}[2J%ff.png"),
            json!("SCALAR"),
            json!("VEC2"),
            json!("VEC4"),
            json!("MAT4"),
            json!("MASK"),
            json!("BLEND"),
            json!("spot"),
            json!("directional"),
            json!("cornell.bin"),
            json!("missing.bin"),
            json!("../cornell.bin"),
            json!("a%zz.bin"),
            json!("file:cornell.bin"),
            json!("http://example.invalid/x.bin"),
            json!("data:application/octet-stream;base64,AAAA"),
            json!("data:application/octet-stream;base64,!!!"),
            json!("data:image/png;base64,iVBORw0KGgo="),
            json!("data:,"),
            json!("image/png"),
            json!("image/jpeg"),
            json!([]),
            json!([0]),
            json!([0, 1, 2]),
            json!([1e39, 1e39, 1e39]),
            json!([3e38, -3e38, 3e38]),
            json!([1e30, 1e30, 1e30]),
            json!([0.0, 0.0, 0.0]),
            json!([-1.0, -1.0, -1.0]),
            json!([0.0, 0.0, 0.0, 0.0]),
            json!([1.0, 0.0, 0.0, 0.0]),
            json!([1e39, 0.0, 0.0, 1.0]),
            json!([1.0, 1.0, 1.0, 1e39]),
            json!(identity),
            json!(huge_translation),
            json!(huge_scale),
            json!(singular),
            json!(vec![0.0; 16]),
            json!({}),
            json!({ "index": 0 }),
            json!({ "index": 0, "texCoord": 1 }),
            json!({ "index": 99 }),
            json!({ "light": 0 }),
            json!({ "emissiveStrength": 1e39 }),
            json!({ "emissiveStrength": -1.0 }),
            json!({ "type": "point", "intensity": 1e39 }),
            json!({ "type": "spot", "spot": { "innerConeAngle": 2.0, "outerConeAngle": 1e39 } }),
            json!({ "type": "directional", "color": [1e30, 1e30, 1e30], "intensity": 1e30 }),
            json!([{ "uri": "cornell.bin" }]),
            json!([{ "bufferView": 0, "mimeType": "image/png" }]),
            json!([{ "source": 0 }]),
            json!({
                "count": 1,
                "indices": { "bufferView": 2, "componentType": 5125 },
                "values": { "bufferView": 0 }
            }),
            json!({
                "count": 4294967295u64,
                "indices": { "bufferView": 2, "componentType": 5121, "byteOffset": 4294967295u64 },
                "values": { "bufferView": 0, "byteOffset": 4294967295u64 }
            }),
        ]
    })
}

/// Edits of raw bytes; positions are fractions of the current length.
#[derive(Clone, Debug)]
pub(crate) enum ByteEdit {
    Flip {
        at: Index,
        xor: u8,
    },
    Truncate {
        keep: Index,
    },
    Delete {
        at: Index,
        len: usize,
    },
    Insert {
        at: Index,
        bytes: Vec<u8>,
    },
    Duplicate {
        from: Index,
        len: usize,
        to: Index,
    },
    /// A 4-byte-aligned little-endian word set to one of [`INTERESTING_32`].
    Put32 {
        at: Index,
        value: Index,
    },
}

pub(crate) fn byte_edit() -> impl Strategy<Value = ByteEdit> {
    prop_oneof![
        4 => (any::<Index>(), 1..=255u8).prop_map(|(at, xor)| ByteEdit::Flip { at, xor }),
        1 => any::<Index>().prop_map(|keep| ByteEdit::Truncate { keep }),
        1 => (any::<Index>(), 1..64usize).prop_map(|(at, len)| ByteEdit::Delete { at, len }),
        1 => (any::<Index>(), prop::collection::vec(any::<u8>(), 1..16))
            .prop_map(|(at, bytes)| ByteEdit::Insert { at, bytes }),
        1 => (any::<Index>(), 1..256usize, any::<Index>())
            .prop_map(|(from, len, to)| ByteEdit::Duplicate { from, len, to }),
        3 => (any::<Index>(), any::<Index>()).prop_map(|(at, value)| ByteEdit::Put32 { at, value }),
    ]
}

impl ByteEdit {
    pub(crate) fn apply(&self, bytes: &mut Vec<u8>) {
        let len = bytes.len();
        match self {
            ByteEdit::Flip { at, xor } => {
                if len > 0 {
                    bytes[at.index(len)] ^= xor;
                }
            }
            ByteEdit::Truncate { keep } => bytes.truncate(keep.index(len.max(1))),
            ByteEdit::Delete { at, len: n } => {
                if len > 0 {
                    let start = at.index(len);
                    bytes.drain(start..(start + n).min(len));
                }
            }
            ByteEdit::Insert { at, bytes: new } => {
                let at = at.index(len + 1);
                bytes.splice(at..at, new.iter().copied());
            }
            ByteEdit::Duplicate { from, len: n, to } => {
                if len > 0 {
                    let start = from.index(len);
                    let chunk = bytes[start..(start + n).min(len)].to_vec();
                    let to = to.index(len + 1);
                    bytes.splice(to..to, chunk);
                }
            }
            ByteEdit::Put32 { at, value } => {
                if len >= 4 {
                    let at = 4 * at.index(len / 4);
                    bytes[at..at + 4].copy_from_slice(&pick(INTERESTING_32, value).to_le_bytes());
                }
            }
        }
    }
}

pub(crate) fn pick<T: Copy>(list: &[T], i: &Index) -> T {
    list[i.index(list.len())]
}

/// Edits of JSON text that know its syntax: numbers replaced in the text, tokens inserted,
/// and (when the text still parses) keys removed or added and values replaced or copied.
#[derive(Clone, Debug)]
pub(crate) enum JsonEdit {
    Number {
        which: Index,
        token: Index,
    },
    Token {
        at: Index,
        token: Index,
    },
    RemoveKey {
        which: Index,
    },
    SetValue {
        which: Index,
        value: Index,
    },
    CopyValue {
        from: Index,
        to: Index,
    },
    AddKey {
        which: Index,
        key: Index,
        value: Index,
    },
}

fn json_edit() -> impl Strategy<Value = JsonEdit> {
    prop_oneof![
        3 => (any::<Index>(), any::<Index>())
            .prop_map(|(which, token)| JsonEdit::Number { which, token }),
        1 => (any::<Index>(), any::<Index>()).prop_map(|(at, token)| JsonEdit::Token { at, token }),
        3 => any::<Index>().prop_map(|which| JsonEdit::RemoveKey { which }),
        3 => (any::<Index>(), any::<Index>())
            .prop_map(|(which, value)| JsonEdit::SetValue { which, value }),
        2 => (any::<Index>(), any::<Index>()).prop_map(|(from, to)| JsonEdit::CopyValue { from, to }),
        3 => (any::<Index>(), any::<Index>(), any::<Index>())
            .prop_map(|(which, key, value)| JsonEdit::AddKey { which, key, value }),
    ]
}

/// Byte ranges of the number tokens in JSON text.
fn number_spans(text: &[u8]) -> Vec<(usize, usize)> {
    let mut spans = Vec::new();
    let mut in_string = false;
    let mut i = 0;
    while i < text.len() {
        let b = text[i];
        if in_string {
            match b {
                b'\\' => i += 1,
                b'"' => in_string = false,
                _ => {}
            }
            i += 1;
        } else if b == b'"' {
            in_string = true;
            i += 1;
        } else if b == b'-' || b.is_ascii_digit() {
            let start = i;
            while i < text.len()
                && matches!(text[i], b'0'..=b'9' | b'-' | b'+' | b'.' | b'e' | b'E')
            {
                i += 1;
            }
            spans.push((start, i));
        } else {
            i += 1;
        }
    }
    spans
}

/// JSON pointers of every value in `v` (the root included) and, separately, of every
/// (object, key) pair.
fn json_paths(v: &Value, at: String, values: &mut Vec<String>, keys: &mut Vec<(String, String)>) {
    match v {
        Value::Object(map) => {
            for (k, child) in map {
                keys.push((at.clone(), k.clone()));
                let escaped = k.replace('~', "~0").replace('/', "~1");
                json_paths(child, format!("{at}/{escaped}"), values, keys);
            }
        }
        Value::Array(items) => {
            for (i, child) in items.iter().enumerate() {
                json_paths(child, format!("{at}/{i}"), values, keys);
            }
        }
        _ => {}
    }
    values.push(at);
}

impl JsonEdit {
    fn apply(&self, text: &mut Vec<u8>) {
        match self {
            JsonEdit::Number { which, token } => {
                let spans = number_spans(text);
                if !spans.is_empty() {
                    let (a, b) = spans[which.index(spans.len())];
                    text.splice(a..b, pick(NUMBER_TOKENS, token).bytes());
                }
            }
            JsonEdit::Token { at, token } => {
                let at = at.index(text.len() + 1);
                text.splice(at..at, pick(JSON_TOKENS, token).bytes());
            }
            _ => {
                let Ok(mut doc) = serde_json::from_slice::<Value>(text) else {
                    return;
                };
                let (mut values, mut keys) = (Vec::new(), Vec::new());
                json_paths(&doc, String::new(), &mut values, &mut keys);
                let all = json_values();
                match self {
                    JsonEdit::RemoveKey { which } if !keys.is_empty() => {
                        let (object, key) = &keys[which.index(keys.len())];
                        if let Some(Value::Object(map)) = doc.pointer_mut(object) {
                            map.remove(key);
                        }
                    }
                    JsonEdit::SetValue { which, value } => {
                        let path = &values[which.index(values.len())];
                        if let Some(v) = doc.pointer_mut(path) {
                            *v = all[value.index(all.len())].clone();
                        }
                    }
                    JsonEdit::CopyValue { from, to } => {
                        let from = doc.pointer(&values[from.index(values.len())]).cloned();
                        let to = &values[to.index(values.len())];
                        if let (Some(from), Some(v)) = (from, doc.pointer_mut(to)) {
                            *v = from;
                        }
                    }
                    JsonEdit::AddKey { which, key, value } => {
                        let objects: Vec<&String> = values
                            .iter()
                            .filter(|p| doc.pointer(p).is_some_and(Value::is_object))
                            .collect();
                        if !objects.is_empty() {
                            let path = objects[which.index(objects.len())].clone();
                            if let Some(Value::Object(map)) = doc.pointer_mut(&path) {
                                map.insert(
                                    pick(JSON_KEYS, key).to_string(),
                                    all[value.index(all.len())].clone(),
                                );
                            }
                        }
                    }
                    _ => {}
                }
                *text = serde_json::to_vec_pretty(&doc).unwrap();
            }
        }
    }
}

/// An edit of JSON text: raw bytes or syntax-aware.
#[derive(Clone, Debug)]
pub(crate) enum TextEdit {
    Bytes(ByteEdit),
    Json(JsonEdit),
}

pub(crate) fn text_edit() -> impl Strategy<Value = TextEdit> {
    prop_oneof![
        1 => byte_edit().prop_map(TextEdit::Bytes),
        6 => json_edit().prop_map(TextEdit::Json),
    ]
}

impl TextEdit {
    pub(crate) fn apply(&self, text: &mut Vec<u8>) {
        match self {
            TextEdit::Bytes(e) => e.apply(text),
            TextEdit::Json(e) => e.apply(text),
        }
    }
}
