//! Meshes: a Bevy [`Mesh`] read as surfcache triangles, and the copy of a mesh that
//! carries a bake's UV1 layout in `ATTRIBUTE_UV_1`.
//!
//! surfcache bakes every triangle of a triangle-list mesh in index order. When the mesh
//! has its own `ATTRIBUTE_UV_1`, the lightmap uses that layout and the mesh is drawn as it
//! is; otherwise surfcache generates an atlas whose charts split the mesh, so the drawn
//! mesh becomes a copy with one vertex per triangle corner and the atlas in UV1
//! ([`with_lightmap_uv1`]).

use crate::glam_bridge;
use bevy::{
    mesh::{Indices, Mesh, PrimitiveTopology, VertexAttributeValues},
    prelude::Vec2 as BevyVec2,
};
use glam::{Vec2, Vec3};
use surfcache_core::Mesh as CoreMesh;

/// Reads a Bevy triangle-list mesh (positions; normals, UV0 and UV1 when present) as a
/// surfcache mesh, triangles in index order. Meshes without normals get area-weighted
/// ones. Fails with a one-line reason on other topologies, missing positions or invalid
/// data.
pub fn mesh_from_bevy(mesh: &Mesh, name: &str) -> Result<CoreMesh, String> {
    if mesh.primitive_topology() != PrimitiveTopology::TriangleList {
        return Err(format!(
            "mesh '{name}' is a {:?}, not a triangle list",
            mesh.primitive_topology()
        ));
    }
    let attribute = |id| {
        mesh.try_attribute_option(id)
            .map_err(|e| format!("mesh '{name}' cannot be read here: {e}"))
    };
    let positions: Vec<Vec3> = attribute(Mesh::ATTRIBUTE_POSITION.id)?
        .and_then(VertexAttributeValues::as_float3)
        .ok_or_else(|| format!("mesh '{name}' has no float3 positions"))?
        .iter()
        .map(|p| Vec3::from_array(*p))
        .collect();
    let indices = mesh
        .try_indices_option()
        .map_err(|e| format!("mesh '{name}' cannot be read here: {e}"))?;
    let corners: Vec<u32> = match indices {
        Some(indices) => indices.iter().map(|i| i as u32).collect(),
        None => (0..positions.len() as u32).collect(),
    };
    if !corners.len().is_multiple_of(3) {
        return Err(format!(
            "mesh '{name}' has {} indices, not a multiple of 3",
            corners.len()
        ));
    }
    let mut core = CoreMesh {
        name: name.to_string(),
        positions,
        normals: Vec::new(),
        uv0: uvs(attribute(Mesh::ATTRIBUTE_UV_0.id)?),
        uv1: uvs(attribute(Mesh::ATTRIBUTE_UV_1.id)?),
        indices: corners
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect(),
    };
    match attribute(Mesh::ATTRIBUTE_NORMAL.id)?.and_then(VertexAttributeValues::as_float3) {
        Some(normals) => core.normals = normals.iter().map(|n| Vec3::from_array(*n)).collect(),
        None => core.compute_normals(),
    }
    core.validate().map_err(|e| e.to_string())?;
    Ok(core)
}

/// A float2 attribute as surfcache UVs (empty when absent or of another type).
fn uvs(values: Option<&VertexAttributeValues>) -> Vec<Vec2> {
    match values {
        Some(VertexAttributeValues::Float32x2(uv)) => {
            uv.iter().map(|uv| Vec2::from_array(*uv)).collect()
        }
        _ => Vec::new(),
    }
}

/// Whether `mesh`'s own `ATTRIBUTE_UV_1` equals `uv1` (per triangle corner, in index
/// order) at every corner: then it can be drawn with the lightmap as it is.
pub fn has_uv1(mesh: &Mesh, uv1: &[[Vec2; 3]]) -> bool {
    let Ok(Some(VertexAttributeValues::Float32x2(own))) =
        mesh.try_attribute_option(Mesh::ATTRIBUTE_UV_1)
    else {
        return false;
    };
    let Ok(indices) = mesh.try_indices_option() else {
        return false;
    };
    let corner = |k: usize| match indices {
        Some(Indices::U16(i)) => i.get(k).map(|&i| i as usize),
        Some(Indices::U32(i)) => i.get(k).map(|&i| i as usize),
        None => Some(k),
    };
    let corners = indices.map_or(own.len(), Indices::len);
    corners == 3 * uv1.len()
        && uv1.iter().flatten().enumerate().all(|(k, uv)| {
            corner(k)
                .and_then(|i| own.get(i))
                .is_some_and(|own| Vec2::from_array(*own) == *uv)
        })
}

/// A copy of `mesh` with one vertex per triangle corner and `uv1[t]` as the
/// `ATTRIBUTE_UV_1` of triangle `t`'s corners: what a generated lightmap layout needs,
/// since neighbouring triangles on different charts no longer share UV1. A mesh without
/// UV0 gets one of zeros (Bevy 0.19's shader needs UV0 once a mesh has UV1).
pub fn with_lightmap_uv1(mesh: &Mesh, uv1: &[[Vec2; 3]]) -> Result<Mesh, String> {
    let mut copy = mesh.clone();
    if copy.indices().is_some() {
        copy.duplicate_vertices();
    }
    let corners = copy.count_vertices();
    if corners != 3 * uv1.len() {
        return Err(format!(
            "the mesh has {} triangles but its lightmap layout {}",
            corners / 3,
            uv1.len()
        ));
    }
    let values: Vec<[f32; 2]> = uv1
        .iter()
        .flatten()
        .map(|uv| BevyVec2::from_array(uv.to_array()).to_array())
        .collect();
    // Bevy 0.19's PBR shader reads UV0 wherever a mesh has any UV set, and fails to
    // compile for a mesh with UV1 alone: such meshes get a UV0 of zeros.
    if !matches!(copy.try_attribute_option(Mesh::ATTRIBUTE_UV_0), Ok(Some(_))) {
        copy.insert_attribute(Mesh::ATTRIBUTE_UV_0, vec![[0.0f32; 2]; corners]);
    }
    copy.insert_attribute(Mesh::ATTRIBUTE_UV_1, values);
    Ok(copy)
}

/// A surfcache mesh as a Bevy triangle list (positions, normals, UV0 and UV1 when
/// present, u32 indices).
pub fn bevy_mesh(mesh: &CoreMesh) -> Mesh {
    let mut out = Mesh::new(
        PrimitiveTopology::TriangleList,
        bevy::asset::RenderAssetUsages::default(),
    );
    let v3 = |v: &[Vec3]| -> Vec<[f32; 3]> {
        v.iter()
            .map(|p| glam_bridge::bevy_vec3(*p).to_array())
            .collect()
    };
    let v2 = |v: &[Vec2]| -> Vec<[f32; 2]> { v.iter().map(|p| p.to_array()).collect() };
    out.insert_attribute(Mesh::ATTRIBUTE_POSITION, v3(&mesh.positions));
    out.insert_attribute(Mesh::ATTRIBUTE_NORMAL, v3(&mesh.normals));
    if !mesh.uv0.is_empty() {
        out.insert_attribute(Mesh::ATTRIBUTE_UV_0, v2(&mesh.uv0));
    }
    if !mesh.uv1.is_empty() {
        out.insert_attribute(Mesh::ATTRIBUTE_UV_1, v2(&mesh.uv1));
    }
    out.insert_indices(Indices::U32(
        mesh.indices.iter().flatten().copied().collect(),
    ));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use surfcache_core::scenes;

    #[test]
    fn a_mesh_survives_the_round_trip_through_bevy() {
        let core = scenes::cuboid("box", Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0), false);
        let back = mesh_from_bevy(&bevy_mesh(&core), "box").unwrap();
        assert_eq!(back.positions, core.positions);
        assert_eq!(back.normals, core.normals);
        assert_eq!(back.indices, core.indices);
    }

    #[test]
    fn a_generated_layout_goes_into_uv1_per_corner() {
        let core = scenes::cuboid("box", Vec3::ZERO, Vec3::ONE, false);
        let mesh = bevy_mesh(&core);
        let uv1: Vec<[Vec2; 3]> = (0..core.indices.len())
            .map(|t| {
                let x = t as f32 / 16.0;
                [
                    Vec2::new(x, 0.0),
                    Vec2::new(x, 0.5),
                    Vec2::new(x + 0.05, 0.5),
                ]
            })
            .collect();
        assert!(!has_uv1(&mesh, &uv1));
        let split = with_lightmap_uv1(&mesh, &uv1).unwrap();
        assert!(has_uv1(&split, &uv1));
        assert_eq!(split.count_vertices(), 3 * core.indices.len());
        // The same triangles, in the same order.
        let back = mesh_from_bevy(&split, "box").unwrap();
        for t in 0..core.indices.len() {
            assert_eq!(back.triangle(t), core.triangle(t));
        }
        assert!(with_lightmap_uv1(&mesh, &uv1[1..]).is_err());
    }

    #[test]
    fn other_topologies_are_a_clear_error() {
        let lines = Mesh::new(
            PrimitiveTopology::LineList,
            bevy::asset::RenderAssetUsages::default(),
        )
        .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, vec![[0.0f32; 3]; 2]);
        let e = mesh_from_bevy(&lines, "wire").unwrap_err();
        assert!(
            e.contains("wire") && e.contains("not a triangle list"),
            "{e}"
        );
    }
}
