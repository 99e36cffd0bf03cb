//! The node hierarchy: every node of the scene placed in the world.

use gltf::Document;
use std::collections::HashSet;
use surfcache_core::glam::{Affine3A, Mat4};

/// A node placed in the world.
pub(super) struct Placed<'a> {
    pub(super) node: gltf::Node<'a>,
    pub(super) world: Affine3A,
}

/// Depth-first walk of the default scene (or the first scene, or all root nodes when the
/// file has no scene); a node reached twice (cycle or shared child) is visited once.
pub(super) fn walk_nodes<'a>(doc: &'a Document, warnings: &mut Vec<String>) -> Vec<Placed<'a>> {
    let roots: Vec<gltf::Node<'a>> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(scene) => scene.nodes().collect(),
        None => {
            let children: HashSet<usize> = doc
                .nodes()
                .flat_map(|n| n.children().map(|c| c.index()).collect::<Vec<_>>())
                .collect();
            doc.nodes()
                .filter(|n| !children.contains(&n.index()))
                .collect()
        }
    };
    let mut visited = HashSet::new();
    let mut out = Vec::new();
    let mut stack: Vec<(gltf::Node<'a>, Affine3A)> = roots
        .into_iter()
        .rev()
        .map(|n| (n, Affine3A::IDENTITY))
        .collect();
    while let Some((node, parent)) = stack.pop() {
        if !visited.insert(node.index()) {
            warnings.push(format!(
                "node {} is reached more than once (cycle or shared child); used once",
                node.index()
            ));
            continue;
        }
        let local = Affine3A::from_mat4(Mat4::from_cols_array_2d(&node.transform().matrix()));
        let world = parent * local;
        for child in node.children().collect::<Vec<_>>().into_iter().rev() {
            stack.push((child, world));
        }
        out.push(Placed { node, world });
    }
    out
}
