//! Shared corners: which triangles around a mesh vertex take one estimate for their
//! corner there (the module docs of [`super`], Shared corners).

use super::IrradianceMaps;
use crate::SampleSite;
use glam::Vec2;
use surfcache_core::index::NO_INDEX;
use surfcache_trace::TracedScene;

/// The most representatives a vertex keeps while its triangles look for one to share
/// with ([`corner_links`]); later triangles that match none estimate their own corner.
const MAX_REPRESENTATIVES: usize = 8;

/// The corner links of every grid slot (module docs, Shared corners): for each instance,
/// the corners of its triangles grouped by mesh vertex, visited in ascending triangle
/// index; `baked[slot]` says which grid slots will be baked (the others neither share nor
/// represent). Costs one any-hit ray per corner that passes rules 1 and 2.
pub fn corner_links(scene: &TracedScene, cos_max: f32, baked: &[bool]) -> Vec<u32> {
    use rayon::prelude::*;
    let slot = |t: u32, front: bool| IrradianceMaps::slot(t, front);
    let site = |t: u32, k: u8, front: bool| SampleSite::Surface {
        triangle: t,
        uv: [Vec2::ZERO, Vec2::X, Vec2::Y][k as usize],
        front,
    };
    // Rules 2 and 3 for corner kr of r (the representative) and corner k of t.
    let may_share = |(r, kr): (u32, u8), (t, k): (u32, u8), front: bool| {
        if scene.normals()[r as usize][kr as usize] != scene.normals()[t as usize][k as usize]
            || scene.geometric_normals()[r as usize].dot(scene.geometric_normals()[t as usize])
                < cos_max
        {
            return false;
        }
        let (_, a) = crate::bake::sample_frame(scene, &site(r, kr, front));
        let (_, b) = crate::bake::sample_frame(scene, &site(t, k, front));
        let d = b - a;
        let length = d.length();
        length == 0.0 || !scene.occluded(a, d / length, length)
    };
    let per_instance: Vec<Vec<(usize, u32)>> = scene
        .instance_triangles()
        .par_iter()
        .map(|range| {
            let mut items: Vec<(u32, u32, u8)> = range
                .clone()
                .flat_map(|t| {
                    let v = scene.vertex_indices()[t as usize];
                    (0..3u8).map(move |k| (v[k as usize], t, k))
                })
                .collect();
            items.sort_unstable();
            let mut links = Vec::new();
            let mut reps: Vec<(u32, u8)> = Vec::new();
            for group in items.chunk_by(|a, b| a.0 == b.0) {
                if group.len() < 2 {
                    continue;
                }
                for front in [true, false] {
                    reps.clear();
                    for &(_, t, k) in group {
                        if !baked[slot(t, front)] {
                            continue;
                        }
                        match reps.iter().find(|&&r| may_share(r, (t, k), front)) {
                            Some(&(r, kr)) => links.push((
                                3 * slot(t, front) + k as usize,
                                (3 * slot(r, front) + kr as usize) as u32,
                            )),
                            None if reps.len() < MAX_REPRESENTATIVES => reps.push((t, k)),
                            None => {}
                        }
                    }
                }
            }
            links
        })
        .collect();
    let mut links = vec![NO_INDEX; 3 * baked.len()];
    for (corner, link) in per_instance.into_iter().flatten() {
        links[corner] = link;
    }
    links
}
