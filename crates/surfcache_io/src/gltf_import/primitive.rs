//! Mesh primitives: attributes and indices read into validated meshes.

use super::scene_error;
use crate::error::Untrusted;
use crate::gltf_accessor::{self, Buffers};
use gltf::Document;
use gltf::Semantic;
use gltf::accessor::DataType;
use gltf::mesh::{Mode, Primitive};
use std::sync::Arc;
use surfcache_core::Mesh;
use surfcache_core::glam::{Vec2, Vec3};

/// One (mesh, primitive) decoded: the mesh (None when skipped) and what happened.
pub(super) struct DecodedPrimitive {
    pub(super) mesh: Option<Arc<Mesh>>,
    pub(super) material: Option<usize>,
    pub(super) skipped: bool,
    pub(super) degenerate: usize,
    pub(super) warnings: Vec<String>,
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
pub(super) fn decode_primitive(
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
    let name = primitive_name(&mesh, mesh_index, prim_index);
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
    let Some(attributes) = read_attributes(&prim, buffers, &shown)? else {
        out.skipped = true;
        out.warnings
            .push(format!("mesh '{shown}' has no POSITION; skipped"));
        return Ok(out);
    };
    let n = attributes.positions.len();
    let corners: Vec<u32> = match prim.indices() {
        Some(acc) => {
            gltf_accessor::read_indices(&acc, buffers, &format!("mesh '{shown}' indices"))?
        }
        None => (0..n as u32).collect(),
    };
    let indices = triangles(mode, &corners, &shown, &mut out.warnings);
    let has_normals = attributes.normals.is_some();
    let mut m = Mesh {
        name: name.clone(),
        positions: attributes.positions,
        normals: attributes.normals.unwrap_or_else(|| vec![Vec3::Y; n]),
        uv0: attributes.uv0,
        uv1: attributes.uv1,
        indices,
    };
    m.validate().map_err(scene_error)?;
    if has_normals {
        normalise_normals(&mut m, &shown, &mut out.warnings);
    } else {
        m.compute_normals();
    }
    out.degenerate = m.drop_degenerate();
    out.mesh = Some(Arc::new(m));
    Ok(out)
}

/// The name of a primitive's mesh: the glTF mesh's name (`mesh<i>` when it has none),
/// suffixed `.<j>` with the primitive's index when the mesh has several primitives.
fn primitive_name(mesh: &gltf::Mesh, mesh_index: usize, prim_index: usize) -> String {
    let mesh_name = match mesh.name() {
        Some(n) if !n.is_empty() => n.to_string(),
        _ => format!("mesh{mesh_index}"),
    };
    if mesh.primitives().len() > 1 {
        format!("{mesh_name}.{prim_index}")
    } else {
        mesh_name
    }
}

/// A primitive's vertex attributes as read: TEXCOORD sets the primitive lacks are empty.
struct Attributes {
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    uv0: Vec<Vec2>,
    uv1: Vec<Vec2>,
}

/// Reads POSITION, NORMAL, TEXCOORD_0 and TEXCOORD_1 (in that order); `None` when the
/// primitive has no POSITION. `shown` names the mesh in messages.
fn read_attributes(
    prim: &Primitive,
    buffers: &Buffers,
    shown: &str,
) -> Result<Option<Attributes>, String> {
    let what = |attr: &str| format!("mesh '{shown}' {attr}");
    let positions = match prim.get(&Semantic::Positions) {
        Some(acc) => vec3s(gltf_accessor::read_f32(
            &acc,
            buffers,
            3,
            FLOAT,
            &what("POSITION"),
        )?),
        None => return Ok(None),
    };
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
    Ok(Some(Attributes {
        positions,
        normals,
        uv0,
        uv1,
    }))
}

/// The triangles of a primitive of `mode` from its vertex indices: strips with every
/// other triangle's first two corners swapped (keeping the winding), fans around the
/// first corner, lists in threes (a warning when indices are left over).
fn triangles(
    mode: Mode,
    corners: &[u32],
    shown: &str,
    warnings: &mut Vec<String>,
) -> Vec<[u32; 3]> {
    match mode {
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
                warnings.push(format!(
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
    }
}

/// Normalises the file's normals; those of zero length or overflowing are replaced by
/// the ones [`Mesh::compute_normals`] gives (with a warning).
fn normalise_normals(m: &mut Mesh, shown: &str, warnings: &mut Vec<String>) {
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
        warnings.push(format!(
            "mesh '{shown}': {fixed} zero-length or overflowing normals replaced by computed ones"
        ));
    }
}
