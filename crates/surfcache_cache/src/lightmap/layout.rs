//! Layout: each instance's texture (its TEXCOORD_1 or a generated chart atlas) and which
//! triangle owns each texel, with the point it is estimated at (module docs, Layout and
//! Rasterisation).

use super::{InstanceMap, LightmapSettings, Lightmaps, TexelGuides, conservative_texels};
use crate::{CacheStats, charts, stored_rgb::StoreScale};
use glam::Vec2;
use surfcache_core::{
    geometry::{closest_point_barycentric, interpolate, triangle_area},
    index::NO_INDEX,
};
use surfcache_trace::TracedScene;

/// Barycentric margin of sample positions: every barycentric coordinate is at least this.
const INSIDE_MARGIN: f32 = 1e-4;

/// What one instance's layout contributes before the instances are concatenated.
pub(super) struct BuiltInstance {
    map: InstanceMap,
    uv1: Vec<[Vec2; 3]>,
    chart: Vec<u32>,
    chart_count: u32,
    owner: Vec<u32>,
    sample_uv: Vec<Vec2>,
}

impl Lightmaps {
    /// Concatenates the instances' layouts into the flat arrays of a layer.
    pub(super) fn from_instances(
        scene: &TracedScene,
        settings: LightmapSettings,
        built: Vec<BuiltInstance>,
    ) -> Self {
        let n = scene.triangle_count();
        let mut maps = Vec::with_capacity(built.len());
        let mut uv1 = Vec::with_capacity(n);
        let mut chart = Vec::with_capacity(n);
        let mut triangle_instance = Vec::with_capacity(n);
        let mut owner = Vec::new();
        let mut sample_uv = Vec::new();
        let mut chart_base = 0u32;
        for (i, b) in built.into_iter().enumerate() {
            let mut map = b.map;
            map.offset = owner.len();
            maps.push(map);
            uv1.extend_from_slice(&b.uv1);
            chart.extend(b.chart.iter().map(|c| c + chart_base));
            chart_base += b.chart_count;
            triangle_instance.extend(std::iter::repeat_n(i as u32, b.uv1.len()));
            owner.extend_from_slice(&b.owner);
            sample_uv.extend_from_slice(&b.sample_uv);
        }
        let layer_texels = owner.len();
        let layers = if settings.both_sides { 2 } else { 1 };
        Self {
            settings,
            maps,
            triangle_instance,
            uv1,
            chart,
            layer_texels,
            layers,
            owner,
            sample_uv,
            priors: Vec::new(),
            prior_feet: Default::default(),
            buried_slots: Vec::new(),
            slots: Vec::new(),
            plan: None,
            rounds: 0,
            pending: Vec::new(),
            later_samples: 0,
            merged: Vec::new(),
            state: Vec::new(),
            guide: Vec::new(),
            site_uv: Vec::new(),
            crossing_slot: Vec::new(),
            crossing_lines: Vec::new(),
            crossing_feet: Vec::new(),
            feet: Vec::new(),
            foot_lines: Vec::new(),
            foot_samples: 0,
            guides: TexelGuides::default(),
            probed: None,
            emitted: false,
            packed: vec![[0; 3]; layers * layer_texels],
            sample_counts: Vec::new(),
            scale: StoreScale::default(),
            stats: CacheStats::default(),
        }
    }

    /// Instance `io`'s finished layout, for the same mesh placed again with its triangles
    /// starting at traced index `first_triangle`.
    pub(super) fn instance_layout(
        &self,
        scene: &TracedScene,
        io: usize,
        first_triangle: u32,
    ) -> BuiltInstance {
        let m = self.maps[io];
        let range = scene.instance_triangles()[io].clone();
        let (start, end) = (range.start as usize, range.end as usize);
        let charts = &self.chart[start..end];
        let base = charts.iter().copied().min().unwrap_or(0);
        let owner = self.owner[m.offset..m.offset + m.texels()]
            .iter()
            .map(|&t| {
                if t == NO_INDEX {
                    NO_INDEX
                } else {
                    t - range.start + first_triangle
                }
            })
            .collect();
        BuiltInstance {
            map: m,
            uv1: self.uv1[start..end].to_vec(),
            chart: charts.iter().map(|c| c - base).collect(),
            chart_count: charts.iter().map(|c| c - base + 1).max().unwrap_or(0),
            owner,
            sample_uv: self.sample_uv[m.offset..m.offset + m.texels()].to_vec(),
        }
    }
}

/// Lays out instance `i`: its TEXCOORD_1 when usable, else a generated atlas; then
/// rasterises its triangles into texel owners and sample positions.
pub(super) fn build_instance(
    scene: &TracedScene,
    i: usize,
    settings: &LightmapSettings,
) -> BuiltInstance {
    let range = scene.instance_triangles()[i].clone();
    let (start, end) = (range.start as usize, range.end as usize);
    let positions = &scene.positions()[start..end];
    let normals = &scene.geometric_normals()[start..end];
    let world_area: f32 = positions
        .iter()
        .map(|&[a, b, c]| triangle_area(a, b, c))
        .sum();
    let mesh_uv1 = scene.has_uv1()[i].then(|| &scene.uv1()[start..end]);
    let uv_area = mesh_uv1.and_then(usable_uv1_area);
    let (width, height, uv1, found, clip, density, uses_mesh_uv1) = match (mesh_uv1, uv_area) {
        (Some(uv1), Some(uv_area)) => {
            // Square texture whose texels cover the mesh at the asked density.
            let side = (world_area / uv_area).sqrt() * settings.texels_per_metre;
            let side = ((side.ceil() as u32).div_ceil(4) * 4).clamp(4, settings.max_size.max(4));
            let found = charts::coplanar_charts(positions, normals);
            let clip = vec![[0, 0, side, side]; uv1.len()];
            let density = side as f32 * (uv_area / world_area).sqrt();
            (side, side, uv1.to_vec(), found, clip, density, true)
        }
        _ => {
            let atlas = charts::generate_atlas(
                positions,
                normals,
                settings.texels_per_metre,
                settings.gutter,
                settings.max_size,
            );
            let clip = atlas
                .charts
                .chart
                .iter()
                .map(|&c| atlas.chart_texels[c as usize])
                .collect();
            (
                atlas.width,
                atlas.height,
                atlas.uv1,
                atlas.charts,
                clip,
                atlas.texels_per_metre,
                false,
            )
        }
    };
    let (owner, sample_uv) = rasterise(&uv1, &clip, width, height, start as u32);
    BuiltInstance {
        map: InstanceMap {
            width,
            height,
            offset: 0,
            uses_mesh_uv1,
            texels_per_metre: density,
        },
        uv1,
        chart: found.chart,
        chart_count: found.count,
        owner,
        sample_uv,
    }
}

/// Total UV area of a mesh's TEXCOORD_1 if it can address a texture: finite, inside
/// [0, 1]² (within a texel-sized tolerance; clamp-to-edge makes anything outside
/// meaningless) and of positive area. Overlapping islands are the mesh's business.
fn usable_uv1_area(uv1: &[[Vec2; 3]]) -> Option<f32> {
    let inside = |p: &Vec2| {
        p.is_finite() && p.cmpge(Vec2::splat(-1e-3)).all() && p.cmple(Vec2::splat(1.001)).all()
    };
    if !uv1.iter().flatten().all(inside) {
        return None;
    }
    let area: f32 = uv1
        .iter()
        .map(|[a, b, c]| 0.5 * (*b - *a).perp_dot(*c - *a).abs())
        .sum();
    (area > 1e-12).then_some(area)
}
/// Texel owners and sample barycentrics of one instance's texture: every triangle's
/// conservative footprint ([`conservative_texels`], limited to its `clip` rectangle)
/// competes for its texels by the distance from the texel centre to the triangle (zero
/// when it contains the centre; ties keep the lower triangle). The sample lies at the
/// closest point (Ericson, *Real-Time Collision Detection* §5.1.5, in UV1 space), i.e.
/// the centre when inside, with every barycentric at least [`INSIDE_MARGIN`].
fn rasterise(
    uv1: &[[Vec2; 3]],
    clip: &[[u32; 4]],
    width: u32,
    height: u32,
    first_triangle: u32,
) -> (Vec<u32>, Vec<Vec2>) {
    let n = (width * height) as usize;
    let mut owner = vec![NO_INDEX; n];
    let mut sample_uv = vec![Vec2::ZERO; n];
    let mut best = vec![f32::INFINITY; n];
    let size = Vec2::new(width as f32, height as f32);
    for (t, (corners, clip)) in uv1.iter().zip(clip).enumerate() {
        let [a, b, c] = corners.map(|p| (p * size).extend(0.0));
        conservative_texels(corners.map(|p| p * size), *clip, |x, y| {
            let centre = Vec2::new(x as f32 + 0.5, y as f32 + 0.5).extend(0.0);
            let uv = closest_point_barycentric(centre, a, b, c);
            let d = (interpolate(a, b, c, uv) - centre).length_squared();
            let k = (y * width + x) as usize;
            if d < best[k] {
                best[k] = d;
                owner[k] = first_triangle + t as u32;
                sample_uv[k] = uv;
            }
        });
    }
    for uv in &mut sample_uv {
        let w = 1.0 - uv.x - uv.y;
        if uv.min_element().min(w) < INSIDE_MARGIN {
            // Shrink the triangle towards its centroid so every coordinate is ≥ the margin.
            *uv = *uv * (1.0 - 3.0 * INSIDE_MARGIN) + Vec2::splat(INSIDE_MARGIN);
        }
    }
    (owner, sample_uv)
}
