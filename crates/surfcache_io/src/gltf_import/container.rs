//! The glTF container: JSON or GLB, checked before the gltf crate validates it, and its
//! buffers.

use crate::error::{IoError, Untrusted, no_panic};
pub(super) use crate::gltf_accessor::Buffers;
use crate::uri::{UriTarget, resolve};
use gltf::{Document, Semantic};
use std::path::Path;

/// Parses the JSON or GLB container (checking the GLB header first: the gltf crate
/// underflows on a header length below 12).
pub(super) fn parse(path: &Path, bytes: &[u8]) -> Result<gltf::Gltf, IoError> {
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
pub(super) fn load_buffers(
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
