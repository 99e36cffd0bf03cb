//! Generated lightmap atlas against xatlas on one scene: per instance (one texture each,
//! as the lightmap cache lays them out) the texels, charts, overhead factor
//! (texels / (area · density²); also of the texels the triangles cover), the stretch of texel density, the smallest distance
//! between two charts' texels, and the time of each.
//!
//! ```text
//! cargo run --release --manifest-path scripts/xatlas_compare/Cargo.toml --target-dir target/xatlas -- SCENE [DENSITY] [GUTTER] [PADDING]
//! ```
//! DENSITY defaults to 8 texels per metre, GUTTER (ours: free texels of every chart's
//! own) to 1 (`LightmapSettings`' default) and PADDING (xatlas': free texels between two charts) to 2 · GUTTER, the
//! same gap.
//! Ours runs first on all threads (as `Lightmaps::new`, in parallel over instances), then
//! on one thread; xatlas runs instance after instance.

use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::time::Instant;
use surfcache_cache::{
    charts::{generate_atlas, singular_values},
    lightmap::conservative_texels,
};
use surfcache_core::geometry::triangle_area;
use surfcache_io::load_scene;
use surfcache_trace::TracedScene;

/// One instance's layout, whoever made it: texture size, chart per triangle, corners in
/// texel units.
struct Layout {
    width: u32,
    height: u32,
    chart: Vec<u32>,
    texels: Vec<[Vec2; 3]>,
    density: f32,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        return Err("usage: xatlas_compare SCENE [DENSITY] [GUTTER] [PADDING]".into());
    };
    let density: f32 = args.get(2).map_or(Ok(8.0), |s| s.parse())?;
    let gutter: u32 = args.get(3).map_or(Ok(1), |s| s.parse())?;
    // xatlas' padding is the free texels between two charts; our gutter is each chart's own.
    let padding: u32 = args.get(4).map_or(Ok(2 * gutter), |s| s.parse())?;
    let traced = TracedScene::new(&load_scene(path)?.scene)?;
    let instances: Vec<(Vec<[Vec3; 3]>, Vec<Vec3>)> = traced
        .instance_triangles()
        .iter()
        .map(|r| {
            let r = r.start as usize..r.end as usize;
            (
                traced.positions()[r.clone()].to_vec(),
                traced.geometric_normals()[r].to_vec(),
            )
        })
        .collect();
    let area: f64 = traced
        .positions()
        .iter()
        .map(|&[a, b, c]| triangle_area(a, b, c) as f64)
        .sum();
    println!(
        "{path}: {} instances, {} triangles, {area:.1} m², {density} texels/m, gutter {gutter}, xatlas padding {padding}",
        instances.len(),
        traced.triangle_count()
    );
    let ours = |(p, n): &(Vec<[Vec3; 3]>, Vec<Vec3>)| {
        let a = generate_atlas(p, n, density, gutter, 16384);
        let size = Vec2::new(a.width as f32, a.height as f32);
        Layout {
            width: a.width,
            height: a.height,
            chart: a.charts.chart,
            texels: a.uv1.iter().map(|q| q.map(|p| p * size)).collect(),
            density: a.texels_per_metre,
        }
    };
    let start = Instant::now();
    let layouts: Vec<Layout> = instances.par_iter().map(ours).collect();
    let ours_parallel = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    one.install(|| instances.iter().map(ours).for_each(drop));
    let ours_serial = start.elapsed().as_secs_f64();
    report(
        &format!(
            "ours ({ours_parallel:.2} s on {} threads, {ours_serial:.2} s on 1)",
            rayon::current_num_threads()
        ),
        &instances,
        &layouts,
        density,
    );
    let start = Instant::now();
    let theirs: Vec<Layout> = instances
        .iter()
        .map(|(p, _)| xatlas_layout(p, density, padding))
        .collect();
    let xatlas_seconds = start.elapsed().as_secs_f64();
    report(
        &format!("xatlas ({xatlas_seconds:.2} s)"),
        &instances,
        &theirs,
        density,
    );
    Ok(())
}

/// The xatlas C++ API (vendored xatlas.h of xatlas-rs 0.1.3), declared here because the
/// crate's own bindings carry MSVC symbol names and do not link elsewhere; xatlas-rs
/// still compiles and links the library.
mod ffi {
    use std::ffi::c_void;
    use xatlas_rs as _;

    #[repr(C)]
    pub struct Chart {
        pub atlas_index: u32,
        pub index_array: *const u32,
        pub index_count: u32,
    }
    #[repr(C)]
    pub struct Vertex {
        pub atlas_index: i32,
        pub uv: [f32; 2],
        pub xref: u32,
    }
    #[repr(C)]
    pub struct Mesh {
        pub chart_array: *const Chart,
        pub chart_count: u32,
        pub index_array: *const u32,
        pub index_count: u32,
        pub vertex_array: *const Vertex,
        pub vertex_count: u32,
    }
    #[repr(C)]
    pub struct Atlas {
        pub width: u32,
        pub height: u32,
        pub atlas_count: u32,
        pub chart_count: u32,
        pub mesh_count: u32,
        pub meshes: *const Mesh,
        pub utilization: *const f32,
        pub texels_per_unit: f32,
    }
    #[repr(C)]
    pub struct MeshDecl {
        pub vertex_count: u32,
        pub vertex_position_data: *const c_void,
        pub vertex_position_stride: u32,
        pub vertex_normal_data: *const c_void,
        pub vertex_normal_stride: u32,
        pub vertex_uv_data: *const c_void,
        pub vertex_uv_stride: u32,
        pub index_count: u32,
        pub index_data: *const c_void,
        pub index_offset: i32,
        /// 1: UInt32.
        pub index_format: u32,
        pub face_ignore_data: *const bool,
    }
    #[repr(C)]
    #[derive(Clone, Copy)]
    pub struct ChartOptions {
        pub max_chart_area: f32,
        pub max_boundary_length: f32,
        pub proxy_fit_metric_weight: f32,
        pub roundness_metric_weight: f32,
        pub straightness_metric_weight: f32,
        pub normal_seam_metric_weight: f32,
        pub texture_seam_metric_weight: f32,
        pub max_threshold: f32,
        pub grow_face_count: u32,
        pub max_iterations: u32,
    }
    /// The header's defaults.
    pub const CHART_OPTIONS: ChartOptions = ChartOptions {
        max_chart_area: 0.0,
        max_boundary_length: 0.0,
        proxy_fit_metric_weight: 2.0,
        roundness_metric_weight: 0.01,
        straightness_metric_weight: 6.0,
        normal_seam_metric_weight: 4.0,
        texture_seam_metric_weight: 0.5,
        max_threshold: 2.0,
        grow_face_count: 32,
        max_iterations: 1,
    };
    #[repr(C)]
    #[derive(Clone, Copy)]
    pub struct PackOptions {
        pub attempts: i32,
        pub texels_per_unit: f32,
        pub resolution: u32,
        pub max_chart_size: u32,
        pub block_align: bool,
        pub conservative: bool,
        pub padding: u32,
    }
    unsafe extern "C" {
        #[link_name = "_ZN6xatlas6CreateEv"]
        pub fn create() -> *mut Atlas;
        #[link_name = "_ZN6xatlas7DestroyEPNS_5AtlasE"]
        pub fn destroy(atlas: *mut Atlas);
        #[link_name = "_ZN6xatlas7AddMeshEPNS_5AtlasERKNS_8MeshDeclE"]
        pub fn add_mesh(atlas: *mut Atlas, decl: *const MeshDecl) -> u32;
        #[link_name = "_ZN6xatlas8GenerateEPNS_5AtlasENS_12ChartOptionsEPFvPKfPfjPKjjbENS_11PackOptionsEPFvNS_16ProgressCategory4EnumEiPvESD_"]
        pub fn generate(
            atlas: *mut Atlas,
            chart: ChartOptions,
            parameterise: *const c_void,
            pack: PackOptions,
            progress: *const c_void,
            user: *mut c_void,
        );
    }
}

/// xatlas on one instance's triangles (welded by exact position, as a mesh with an
/// index buffer), packed at `density` with `padding`, conservative rasterisation, its
/// default chart options and 4096 placement attempts.
fn xatlas_layout(positions: &[[Vec3; 3]], density: f32, padding: u32) -> Layout {
    let mut ids: std::collections::HashMap<[u32; 3], u32> = Default::default();
    let mut vertices: Vec<[f32; 3]> = Vec::new();
    let mut indices: Vec<u32> = Vec::new();
    for tri in positions {
        for p in tri {
            let key = p.to_array().map(f32::to_bits);
            let id = *ids.entry(key).or_insert_with(|| {
                vertices.push(p.to_array());
                vertices.len() as u32 - 1
            });
            indices.push(id);
        }
    }
    let null = std::ptr::null();
    // SAFETY: the declarations above match xatlas.h; the input outlives AddMesh (which
    // copies it) and the output is read before Destroy.
    unsafe {
        let atlas = ffi::create();
        let error = ffi::add_mesh(
            atlas,
            &ffi::MeshDecl {
                vertex_count: vertices.len() as u32,
                vertex_position_data: vertices.as_ptr().cast(),
                vertex_position_stride: 12,
                vertex_normal_data: null,
                vertex_normal_stride: 0,
                vertex_uv_data: null,
                vertex_uv_stride: 0,
                index_count: indices.len() as u32,
                index_data: indices.as_ptr().cast(),
                index_offset: 0,
                index_format: 1,
                face_ignore_data: std::ptr::null(),
            },
        );
        assert_eq!(error, 0, "xatlas AddMesh failed");
        ffi::generate(
            atlas,
            ffi::CHART_OPTIONS,
            null,
            ffi::PackOptions {
                attempts: 4096,
                texels_per_unit: density,
                resolution: 0,
                max_chart_size: 16384,
                block_align: false,
                conservative: true,
                padding,
            },
            null,
            std::ptr::null_mut(),
        );
        let a = &*atlas;
        let mesh = &*a.meshes;
            let vertices = std::slice::from_raw_parts(mesh.vertex_array, mesh.vertex_count as usize);
        let indices = std::slice::from_raw_parts(mesh.index_array, mesh.index_count as usize);
        let charts = std::slice::from_raw_parts(mesh.chart_array, mesh.chart_count as usize);
        let mut vertex_chart = vec![0u32; vertices.len()];
        for (c, chart) in charts.iter().enumerate() {
            for &v in std::slice::from_raw_parts(chart.index_array, chart.index_count as usize) {
                vertex_chart[v as usize] = c as u32;
            }
        }
        let layout = Layout {
            width: a.width,
            height: a.height,
            chart: indices
                .chunks(3)
                .map(|t| vertex_chart[t[0] as usize])
                .collect(),
            texels: indices
                .chunks(3)
                .map(|t| [0, 1, 2].map(|k| Vec2::from(vertices[t[k] as usize].uv)))
                .collect(),
            density: a.texels_per_unit,
        };
        ffi::destroy(atlas);
        layout
    }
}

/// Prints the per-instance and total figures of one layouter.
fn report(name: &str, instances: &[(Vec<[Vec3; 3]>, Vec<Vec3>)], layouts: &[Layout], density: f32) {
    println!("{name}");
    println!(
        "  {:>3} {:>7} {:>9} {:>11} {:>7} {:>9} {:>6} {:>6} {:>6} {:>5}",
        "#", "tris", "m²", "texels", "charts", "overhead", "mean σ", "min σ", "max σ", "gap"
    );
    let (mut texels, mut area, mut charts, mut owned) = (0u64, 0.0f64, 0u64, 0u64);
    let (mut lo, mut hi, mut sum, mut weight) = (f32::INFINITY, 0.0f32, 0.0f64, 0.0f64);
    let mut min_gap = u32::MAX;
    for (i, ((p, _), l)) in instances.iter().zip(layouts).enumerate() {
        let a: f64 = p.iter().map(|&[a, b, c]| triangle_area(a, b, c) as f64).sum();
        let n_charts = l.chart.iter().map(|&c| c as u64 + 1).max().unwrap_or(0);
        let (mut ilo, mut ihi) = (f32::INFINITY, 0.0f32);
        for (tri, q) in p.iter().zip(&l.texels) {
            let at = triangle_area(tri[0], tri[1], tri[2]);
            if at * l.density * l.density < 1e-3 {
                continue;
            }
            if let Some((s0, s1)) = singular_values(*tri, *q) {
                ilo = ilo.min(s0 / l.density);
                ihi = ihi.max(s1 / l.density);
                sum += at as f64 * 0.5 * (s0 + s1) as f64 / l.density as f64;
                weight += at as f64;
            }
        }
        let (gap, covered) = chart_gap(l);
        owned += covered;
        let t = l.width as u64 * l.height as u64;
        println!(
            "  {i:>3} {:>7} {a:>9.1} {t:>11} {n_charts:>7} {:>9.2} {:>6} {ilo:>6.3} {ihi:>6.3} {gap:>5}",
            p.len(),
            t as f64 / (a * (density as f64).powi(2)),
            "",
        );
        texels += t;
        area += a;
        charts += n_charts;
        lo = lo.min(ilo);
        hi = hi.max(ihi);
        min_gap = min_gap.min(gap);
    }
    println!(
        "  all {texels} texels ({owned} covered by triangles), {charts} charts, overhead {:.2} ({:.2} covered), σ/density mean {:.3} min {lo:.3} max {hi:.3}, smallest gap between charts {min_gap} texels",
        texels as f64 / (area * (density as f64).powi(2)),
        owned as f64 / (area * (density as f64).powi(2)),
        sum / weight.max(1e-30)
    );
}

/// Fewest free texels between the conservative footprints of two different charts (up
/// to 8; 8 means "8 or more"), and the texels in footprints (the ones a bake estimates).
fn chart_gap(l: &Layout) -> (u32, u64) {
    const REACH: i64 = 9;
    let (w, h) = (l.width as i64, l.height as i64);
    let mut owner = vec![u32::MAX; (w * h) as usize];
    let mut shared = 0u64;
    for (q, &c) in l.texels.iter().zip(&l.chart) {
        conservative_texels(*q, [0, 0, l.width, l.height], |x, y| {
            let k = (y as i64 * w + x as i64) as usize;
            if owner[k] != u32::MAX && owner[k] != c {
                shared += 1;
            }
            owner[k] = c;
        });
    }
    let covered = owner.iter().filter(|&&c| c != u32::MAX).count() as u64;
    if shared > 0 {
        return (0, covered);
    }
    let mut gap = REACH - 1;
    for y in 0..h {
        for x in 0..w {
            let c = owner[(y * w + x) as usize];
            if c == u32::MAX {
                continue;
            }
            for dy in -REACH..=REACH {
                for dx in -REACH..=REACH {
                    let d = dx.abs().max(dy.abs());
                    if d - 1 >= gap {
                        continue;
                    }
                    let (i, j) = (x + dx, y + dy);
                    if i >= 0 && j >= 0 && i < w && j < h {
                        let o = owner[(j * w + i) as usize];
                        if o != u32::MAX && o != c {
                            gap = gap.min(d - 1);
                        }
                    }
                }
            }
        }
    }
    (gap as u32, covered)
}
