//! Texel lightmaps against closed forms and a path-traced reference: layouts (TEXCOORD_1
//! and generated charts), conservative footprints, leak-free and buried texels,
//! determinism.

mod common;

use glam::{Affine3A, Vec2, Vec3};
use std::{collections::HashMap, f32::consts::PI, sync::Arc};
use surfcache_cache::{
    SurfaceCache,
    bake::{Baker, bake_to_convergence},
    charts::{coplanar_charts, generate_atlas},
    lightmap::{LightmapSettings, Lightmaps, conservative_texels},
};
use surfcache_core::{
    Environment, Instance, Material, Mesh, Scene,
    sampling::Rng,
    scenes::{append, cuboid, quad},
};
use surfcache_trace::{EstimatorSettings, Query, Sampler, TracedScene, reference_irradiance};

fn instance(mesh: Mesh, albedo: f32, transform: Affine3A) -> Instance {
    Instance {
        name: mesh.name.clone(),
        mesh: Arc::new(mesh),
        material: Arc::new(Material::diffuse("m", Vec3::splat(albedo))),
        transform,
    }
}

fn scene(instances: Vec<Instance>, sky: Vec3) -> TracedScene {
    TracedScene::new(&Scene {
        name: "test".into(),
        instances,
        lights: Vec::new(),
        environment: Environment::uniform(sky),
    })
    .unwrap()
}

/// Adaptive `best` estimates to a 2 % bound, 64 to 4096 samples, with floor `floor`.
fn estimator(floor: f32) -> EstimatorSettings {
    common::estimator(Sampler::Best, 0.02, 64, 4096, floor)
}

fn settings(texels_per_metre: f32) -> LightmapSettings {
    LightmapSettings {
        texels_per_metre,
        ..Default::default()
    }
}

/// A square of half-size `h` in the plane y = 0, facing +Y.
fn floor_quad(h: f32) -> Mesh {
    let v = Vec3::new;
    quad(
        "floor",
        [v(-h, 0., -h), v(h, 0., -h), v(h, 0., h), v(-h, 0., h)],
        Vec3::Y,
    )
}

#[test]
fn plane_under_uniform_sky_gets_pi_l_on_both_sides() {
    let l = Vec3::new(0.5, 1.0, 2.0);
    // A tilted, turned 1.3 m × 0.7 m plane: its chart must be rotated to a tight box.
    let v = Vec3::new;
    let mesh = quad(
        "plane",
        [
            v(0., 0., 0.),
            v(1.3, 0., 0.),
            v(1.3, 0., 0.7),
            v(0., 0., 0.7),
        ],
        Vec3::Y,
    );
    let turn = Affine3A::from_rotation_x(0.4) * Affine3A::from_rotation_y(0.7);
    let traced = scene(vec![instance(mesh, 0.5, turn)], l);
    let cache = Lightmaps::new(&traced, settings(20.0));
    let cache = bake_to_convergence(&traced, cache, &estimator(0.0), 3);
    let stats = cache.stats();
    assert_eq!(stats.buried, 0);
    assert!(stats.dilated_texels > 0);
    let expected = PI * l;
    // Bake error bound (4 C) plus half-float rounding (2⁻¹¹ of each channel).
    let tol = 4.0 * 0.02 * expected + expected / 1024.0;
    let mut rng = Rng::new(1, 2);
    for i in 0..400 {
        let t = i % 2;
        let mut uv = rng.next_vec2();
        if uv.x + uv.y > 1.0 {
            uv = Vec2::ONE - uv;
        }
        for front in [true, false] {
            let e = cache.lookup(t, uv, front);
            assert!(
                (e - expected).abs().cmple(tol).all(),
                "triangle {t} at {uv} (front {front}): {e}, expected {expected}"
            );
        }
    }
    // A single-sided material publishes its front side only.
    let textures = cache.publish(&traced);
    assert_eq!(textures.len(), 1);
    assert!(!textures[0].uses_mesh_uv1);
    assert_eq!(textures[0].uv_rect, [0.0, 0.0, 1.0, 1.0]);
}

#[test]
fn light_tight_box_stays_black_near_its_walls() {
    let l = Vec3::splat(1e3);
    let traced = scene(
        vec![instance(
            cuboid("box", Vec3::ZERO, Vec3::ONE, true),
            0.8,
            Affine3A::IDENTITY,
        )],
        l,
    );
    let cache = Lightmaps::new(&traced, settings(16.0));
    let cache = bake_to_convergence(&traced, cache, &estimator(0.0), 5);
    let mut rng = Rng::new(3, 4);
    let mm = 1e-3;
    let mut checked = 0;
    for _ in 0..2000 {
        // A point within 1 mm of a wall of the box (on another wall), or near a corner.
        let axis = (rng.next_u32() % 3) as usize;
        let side = rng.next_u32() % 2;
        let mut p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        p[axis] = side as f32;
        let near = (axis + 1 + (rng.next_u32() % 2) as usize) % 3;
        p[near] = if rng.next_f32() < 0.5 {
            rng.next_f32() * mm
        } else {
            1.0 - rng.next_f32() * mm
        };
        if rng.next_f32() < 0.3 {
            let other = 3 - axis - near;
            p[other] = rng.next_f32() * mm;
        }
        let mut inward = Vec3::ZERO;
        inward[axis] = if side == 0 { 1.0 } else { -1.0 };
        let s = traced.locate(p, inward).expect("on the box");
        let front = traced.geometric_normals()[s.triangle as usize].dot(inward) > 0.0;
        assert!(front, "inner walls face inwards");
        let inside = cache.lookup(s.triangle, s.uv, true);
        assert_eq!(inside, Vec3::ZERO, "light leaked at {p}");
        // The outside (back layer) sees the whole sky.
        let outside = cache.lookup(s.triangle, s.uv, false);
        let expected = PI * l;
        assert!(
            (outside - expected).abs().max_element() <= 0.08 * expected.x + expected.x / 400.0,
            "outside at {p}: {outside}"
        );
        checked += 1;
    }
    assert_eq!(checked, 2000);
    assert_eq!(cache.stats().buried, 0);
}

/// The floor of [`buried_texels_are_refilled`] just outside the box, against the reference:
/// returns the smallest (value − reference + tolerance) / reference over the points for
/// lookups and for the published texture, and the number of buried texels.
fn floor_next_to_box(buried_threshold: f32) -> (f32, f32, u64) {
    let (lo, hi) = (
        Vec3::new(-0.3137, -0.1, -0.2571),
        Vec3::new(0.2863, 0.3, 0.3429),
    );
    let instances = vec![
        instance(floor_quad(0.6), 0.5, Affine3A::IDENTITY),
        instance(cuboid("box", lo, hi, false), 0.5, Affine3A::IDENTITY),
    ];
    let traced = scene(instances, Vec3::ONE);
    let density = 64.0;
    let lightmaps = Lightmaps::new(
        &traced,
        LightmapSettings {
            texels_per_metre: density,
            both_sides: false,
            buried_threshold,
            ..Default::default()
        },
    );
    let cache = bake_to_convergence(&traced, lightmaps, &estimator(0.02), 11);
    // Points 0.2 to 0.6 texels outside each wall, along the wall.
    let texel = 1.0 / density;
    let mut queries = Vec::new();
    for k in 0..40 {
        let s = (k as f32 + 0.5) / 40.0;
        let d = texel * (0.2 + 0.4 * ((k * 7) % 10) as f32 / 10.0);
        let x = lo.x + s * (hi.x - lo.x);
        let z = lo.z + s * (hi.z - lo.z);
        for p in [
            Vec3::new(lo.x - d, 0.0, z),
            Vec3::new(hi.x + d, 0.0, z),
            Vec3::new(x, 0.0, lo.z - d),
            Vec3::new(x, 0.0, hi.z + d),
        ] {
            queries.push(Query {
                position: p,
                normal: Vec3::Y,
            });
        }
    }
    let reference = reference_irradiance(
        &traced,
        &queries,
        &EstimatorSettings::fixed(Sampler::Best, 4096, None),
        17,
        &|| {},
    );
    let floor = &cache.publish(&traced)[0];
    assert_eq!((floor.instance, floor.front), (0, true));
    let (mut worst, mut worst_published) = (f32::INFINITY, f32::INFINITY);
    for (q, r) in queries.iter().zip(reference) {
        let r = r.expect("on the floor");
        let s = traced.locate(q.position, q.normal).unwrap();
        assert_eq!(traced.instance()[s.triangle as usize], 0, "floor");
        // Reference noise (3 se) and the bake's error bound (3 C).
        let tol = 3.0 * r.std_error.y + 3.0 * 0.02 * r.value.y;
        let margin = |e: Vec3| (e.y - r.value.y + tol) / r.value.y;
        worst = worst.min(margin(cache.lookup(s.triangle, s.uv, true)));
        // What an engine sees: the published texture's plain bilinear at the UV1.
        let [a, b, c] = floor.uv1[traced.local_triangle()[s.triangle as usize] as usize];
        let at = a * (1.0 - s.uv.x - s.uv.y) + b * s.uv.x + c * s.uv.y;
        worst_published = worst_published.min(margin(floor.sample(at)));
    }
    (worst, worst_published, cache.stats().buried)
}

#[test]
fn buried_texels_are_refilled() {
    let (worst, published, buried) = floor_next_to_box(0.5);
    // The floor under the 0.6 m × 0.6 m box: about (0.6 · 64)² texels.
    eprintln!("{buried} buried texels, worst margins {worst} (lookup), {published} (texture)");
    assert!(buried >= 1300, "{buried} buried texels");
    assert!(worst >= 0.0, "floor next to the box darkened: {worst}");
    assert!(
        published >= 0.0,
        "published floor next to the box darkened: {published}"
    );
    // Without detection the texels under the box stay dark. Lookups still leave them out
    // (the box's walls cross those texels' footprints), but an engine's bilinear filter
    // knows no crossings: the dark texels bleed into the floor outside.
    let (worst, published, none) = floor_next_to_box(2.0);
    assert_eq!(none, 0);
    assert!(worst >= 0.0, "lookup next to the box darkened: {worst}");
    assert!(published < -0.05, "{published}");
}

/// A 2 m × 1 m quad with a lightmap UV1 in [0.1, 0.9] × [0.1, 0.6].
fn quad_with_uv1() -> Mesh {
    let v = Vec3::new;
    let mut mesh = quad(
        "uv1",
        [v(0., 0., 0.), v(2., 0., 0.), v(2., 0., -1.), v(0., 0., -1.)],
        Vec3::Y,
    );
    let w = Vec2::new;
    mesh.uv1 = vec![w(0.1, 0.6), w(0.9, 0.6), w(0.9, 0.1), w(0.1, 0.1)];
    mesh
}

#[test]
fn texcoord_1_is_used_as_given() {
    let mesh = quad_with_uv1();
    let mut mirrored = mesh.clone();
    mirrored.name = "mirrored".into();
    let mut generated = floor_quad(0.5);
    generated.name = "generated".into();
    let instances = vec![
        instance(mesh.clone(), 0.5, Affine3A::IDENTITY),
        instance(
            mirrored,
            0.5,
            Affine3A::from_translation(Vec3::new(-0.5, 0.0, 0.0))
                * Affine3A::from_scale(Vec3::new(-1.0, 1.0, 1.0)),
        ),
        instance(
            generated,
            0.5,
            Affine3A::from_translation(Vec3::new(1.0, 0.5, -0.5)),
        ),
    ];
    let traced = scene(instances, Vec3::ONE);
    assert!(traced.mirrored()[1]);
    let cache = Lightmaps::new(&traced, settings(16.0));
    // World area 2 m², UV1 area 0.4: side √5 · 16 = 35.8, rounded up to 36.
    assert_eq!(cache.texture_size(0), [36, 36]);
    assert_eq!(cache.texture_size(1), [36, 36]);
    let cache = bake_to_convergence(&traced, cache, &estimator(0.02), 1);
    let textures = cache.publish(&traced);
    assert_eq!(textures.len(), 3);
    let mesh_uv1: Vec<[Vec2; 3]> = mesh
        .indices
        .iter()
        .map(|t| t.map(|i| mesh.uv1[i as usize]))
        .collect();
    for tex in &textures[..2] {
        assert!(tex.uses_mesh_uv1);
        assert_eq!((tex.width, tex.height), (36, 36));
        assert_eq!(tex.uv1, mesh_uv1, "{}", tex.name);
    }
    assert!(!textures[2].uses_mesh_uv1);
    // lookup is the published texture sampled at the mesh's UV1: what an engine sees.
    let mut rng = Rng::new(9, 9);
    for t in 0..traced.triangle_count() as u32 {
        let i = traced.instance()[t as usize] as usize;
        let tex = &textures[i];
        let local = traced.local_triangle()[t as usize] as usize;
        for _ in 0..50 {
            let mut uv = rng.next_vec2();
            if uv.x + uv.y > 1.0 {
                uv = Vec2::ONE - uv;
            }
            // Traced corners are the mesh's (A, C, B) under mirroring.
            let mesh_uv = if traced.mirrored()[i] {
                Vec2::new(uv.y, uv.x)
            } else {
                uv
            };
            let [a, b, c] = tex.uv1[local];
            let at = a * (1.0 - mesh_uv.x - mesh_uv.y) + b * mesh_uv.x + c * mesh_uv.y;
            let (got, seen) = (cache.lookup(t, uv, true), tex.sample(at));
            if traced.mirrored()[i] {
                // Barycentrics summed in another order: rounding only.
                assert!((got - seen).abs().max_element() <= 1e-6 * seen.max_element());
            } else {
                assert_eq!(got, seen);
            }
        }
    }
    // The quad hovering over the first one shades it: the texels are not all alike.
    let t = &textures[0].texels;
    assert!(
        t.iter()
            .any(|v| (*v - t[t.len() / 2]).max_element().abs() > 0.1)
    );
}

/// A w × h grid of quads with shared vertices in the plane z = 0, tilted.
fn grid(n: u32) -> Mesh {
    let mut positions = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            positions.push(Vec3::new(i as f32 / n as f32, j as f32 / n as f32, 0.0));
        }
    }
    let mut indices = Vec::new();
    let at = |i: u32, j: u32| j * (n + 1) + i;
    for j in 0..n {
        for i in 0..n {
            indices.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            indices.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    Mesh::new("grid", positions, indices)
}

/// A 24-sided open cylinder of three rings of quads (vertices not shared).
fn cylinder() -> Mesh {
    let mut mesh = Mesh {
        name: "cylinder".into(),
        ..Default::default()
    };
    let segments = 24;
    for s in 0..segments {
        let angle = |k: u32| k as f32 / segments as f32 * std::f32::consts::TAU;
        let (a0, a1) = (angle(s), angle(s + 1));
        for ring in 0..3 {
            let (y0, y1) = (ring as f32 * 0.2, ring as f32 * 0.2 + 0.2);
            let p = |a: f32, y: f32| Vec3::new(0.3 * a.cos(), y, 0.3 * a.sin());
            let mid = 0.5 * (a0 + a1);
            let out = Vec3::new(mid.cos(), 0.0, mid.sin());
            append(
                &mut mesh,
                &quad("c", [p(a0, y0), p(a1, y0), p(a1, y1), p(a0, y1)], out),
            );
        }
    }
    mesh
}

/// Slivers and tiny triangles.
fn odd_triangles() -> Mesh {
    let v = Vec3::new;
    Mesh::new(
        "odd",
        vec![
            v(0., 0., 0.),
            v(0.5, 0.001, 0.),
            v(0.25, 0., 0.3),
            v(1., 1., 1.),
            v(1.001, 1., 1.),
            v(1., 1.0005, 1.0003),
            v(2., 0., 0.),
            v(2.4, 0.3, 0.1),
            v(2.1, 0.02, 0.01),
        ],
        vec![[0, 1, 2], [3, 4, 5], [6, 7, 8]],
    )
}

/// A UV sphere of radius `r` with shared vertices: curved everywhere, closed, so its
/// charts are cut where their growth fronts meet and flattened conformally.
fn sphere(r: f32, rings: u32, segments: u32) -> Mesh {
    let mut positions = vec![Vec3::new(0.0, r, 0.0)];
    for i in 1..rings {
        let theta = i as f32 / rings as f32 * PI;
        for j in 0..segments {
            let phi = j as f32 / segments as f32 * 2.0 * PI;
            positions.push(
                r * Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    theta.sin() * phi.sin(),
                ),
            );
        }
    }
    positions.push(Vec3::new(0.0, -r, 0.0));
    let bottom = positions.len() as u32 - 1;
    let at = |i: u32, j: u32| 1 + (i - 1) * segments + j % segments;
    let mut indices = Vec::new();
    for j in 0..segments {
        indices.push([0, at(1, j + 1), at(1, j)]);
        indices.push([bottom, at(rings - 1, j), at(rings - 1, j + 1)]);
        for i in 1..rings - 1 {
            indices.push([at(i, j), at(i, j + 1), at(i + 1, j + 1)]);
            indices.push([at(i, j), at(i + 1, j + 1), at(i + 1, j)]);
        }
    }
    Mesh::new("sphere", positions, indices)
}

/// A 1 m square heightfield of n × n quads, z = 0.15 sin(6x) cos(5y): smooth, not
/// developable.
fn wavy(n: u32) -> Mesh {
    let mut mesh = grid(n);
    for p in &mut mesh.positions {
        p.z = 0.15 * (6.0 * p.x).sin() * (5.0 * p.y).cos();
    }
    mesh.name = "wavy".into();
    mesh
}

/// The generated atlas' invariants on every test mesh, as `Lightmaps` lays them out:
/// deterministic, every triangle covers texels inside its chart's box, no texel centre
/// (at a quarter-texel pitch) lies inside two triangles, two charts' texels are at least
/// 2 · gutter apart inside the texture, and the texels follow the surface area.
#[test]
fn generated_charts_do_not_overlap_and_cover_every_triangle() {
    let meshes = [
        cuboid("cube", Vec3::ZERO, Vec3::new(0.5, 0.3, 0.2), false),
        grid(8),
        cylinder(),
        odd_triangles(),
        sphere(0.4, 12, 24),
        wavy(24),
    ];
    // Coplanar charts: six faces, one plane, a column per cylinder segment.
    for (mesh, expected) in meshes.iter().zip([Some(6), Some(1), Some(24), None]) {
        let tris: Vec<[Vec3; 3]> = (0..mesh.indices.len()).map(|t| mesh.triangle(t)).collect();
        let normals: Vec<Vec3> = tris
            .iter()
            .map(|[a, b, c]| (*b - *a).cross(*c - *a).normalize())
            .collect();
        let charts = coplanar_charts(&tris, &normals);
        if let Some(n) = expected {
            assert_eq!(charts.count, n, "{}", mesh.name);
        }
    }
    let turn = Affine3A::from_rotation_z(0.3) * Affine3A::from_rotation_x(1.1);
    let traced = scene(
        meshes
            .iter()
            .map(|m| instance(m.clone(), 0.5, turn))
            .collect(),
        Vec3::ONE,
    );
    for (gutter, density) in [(1, 32.0), (2, 32.0), (1, 5.0)] {
        let settings = LightmapSettings {
            texels_per_metre: density,
            gutter,
            ..Default::default()
        };
        let cache = Lightmaps::new(&traced, settings);
        assert_eq!(cache.texels_per_metre(1), density);
        for inst in 0..traced.instance_triangles().len() {
            let [w, h] = cache.texture_size(inst as u32);
            assert!(w % 4 == 0 && h % 4 == 0);
            let range = traced.instance_triangles()[inst].clone();
            let tris: Vec<[Vec3; 3]> = range
                .clone()
                .map(|t| traced.positions()[t as usize])
                .collect();
            let normals: Vec<Vec3> = range
                .clone()
                .map(|t| traced.geometric_normals()[t as usize])
                .collect();
            // The layout `Lightmaps` made, made again: the same.
            let atlas = generate_atlas(&tris, &normals, density, gutter, settings.max_size);
            assert_eq!(
                atlas,
                generate_atlas(&tris, &normals, density, gutter, settings.max_size)
            );
            assert_eq!([atlas.width, atlas.height], [w, h]);
            for (k, t) in range.clone().enumerate() {
                assert_eq!(atlas.uv1[k], cache.triangle_uv1(t), "triangle {t}");
            }
            let size = Vec2::new(w as f32, h as f32);
            // Chart of every texel a footprint (grown by the gutter) reaches.
            let mut claimed: HashMap<(i64, i64), u32> = HashMap::new();
            let mut footprint_box =
                vec![[i64::MAX, i64::MAX, i64::MIN, i64::MIN]; atlas.charts.count as usize];
            let mut owned = 0usize;
            for (k, t) in range.clone().enumerate() {
                let corners = cache.triangle_uv1(t).map(|p| p * size);
                let [a, b, c] = tris[k];
                let mut texels = Vec::new();
                conservative_texels(corners, [0, 0, w, h], |x, y| texels.push((x, y)));
                if (b - a).cross(c - a).length() == 0.0 {
                    continue;
                }
                assert!(!texels.is_empty(), "triangle {t} has no texel");
                let chart = atlas.charts.chart[k];
                let [bx, by, bw, bh] = atlas.chart_texels[chart as usize];
                assert!(
                    texels
                        .iter()
                        .all(|&(x, y)| x >= bx && y >= by && x < bx + bw && y < by + bh),
                    "triangle {t} outside its chart's box"
                );
                // Conservative: every point of the triangle lies in a footprint texel.
                let mut rng = Rng::new(t as u64, 1);
                for _ in 0..200 {
                    let mut uv = rng.next_vec2();
                    if uv.x + uv.y > 1.0 {
                        uv = Vec2::ONE - uv;
                    }
                    let [a, b, c] = corners;
                    let p = a * (1.0 - uv.x - uv.y) + b * uv.x + c * uv.y;
                    let texel = (p.x.floor() as u32, p.y.floor() as u32);
                    // Points within the sliver tolerance of a texel border may fall outside.
                    let frac = p - p.floor();
                    let interior = frac.cmpgt(Vec2::splat(2e-3)).all()
                        && frac.cmplt(Vec2::splat(1.0 - 2e-3)).all();
                    assert!(
                        !interior || texels.contains(&texel),
                        "triangle {t}: {p} outside its footprint"
                    );
                }
                for &(x, y) in &texels {
                    let fb = &mut footprint_box[chart as usize];
                    fb[0] = fb[0].min(x as i64);
                    fb[1] = fb[1].min(y as i64);
                    fb[2] = fb[2].max(x as i64);
                    fb[3] = fb[3].max(y as i64);
                    let g = gutter as i64;
                    for dy in -g..=g {
                        for dx in -g..=g {
                            let key = (x as i64 + dx, y as i64 + dy);
                            if (dx, dy) == (0, 0) && !claimed.contains_key(&key) {
                                owned += 1;
                            }
                            let owner = *claimed.entry(key).or_insert(chart);
                            assert_eq!(
                                owner, chart,
                                "instance {inst}: charts {owner} and {chart} closer than 2 gutters at {key:?}"
                            );
                        }
                    }
                }
            }
            // Charts and their gutters stay inside the texture.
            for fb in footprint_box.iter().filter(|fb| fb[0] <= fb[2]) {
                let g = gutter as i64;
                assert!(fb[0] >= g && fb[1] >= g && fb[2] + g < w as i64 && fb[3] + g < h as i64);
            }
            if inst == 1 {
                // The unit grid spans 32 texels from texel centre to texel centre.
                let fb = footprint_box[0];
                if density == 32.0 {
                    assert_eq!((fb[2] - fb[0] + 1, fb[3] - fb[1] + 1), (33, 33));
                }
                let lo = range
                    .clone()
                    .flat_map(|t| cache.triangle_uv1(t))
                    .fold(Vec2::INFINITY, |a, p| a.min(p * size));
                assert!((lo - Vec2::splat(gutter as f32 + 0.5)).abs().max_element() < 1e-3);
            }
            // Texels follow the surface area: the curved meshes at 32 texels/m, laid out
            // in a few charts, cover at most 1.5 times their area's texels.
            let area: f32 = tris
                .iter()
                .map(|&[a, b, c]| 0.5 * (b - a).cross(c - a).length())
                .sum();
            if inst >= 4 && density == 32.0 {
                let ideal = area * density * density;
                assert!(
                    (owned as f32) < 1.5 * ideal,
                    "{}: {owned} texels for {ideal}",
                    traced.instance_names()[inst]
                );
            }
            // No point at a quarter-texel pitch lies inside two triangles.
            let mut inside = vec![0u8; (16 * w * h) as usize];
            for t in range {
                let [a, b, c] = cache.triangle_uv1(t).map(|p| p * size * 4.0);
                let area = (b - a).perp_dot(c - a);
                if area == 0.0 {
                    continue;
                }
                let (lo, hi) = (a.min(b).min(c).max(Vec2::ZERO), a.max(b).max(c));
                for y in lo.y as u32..(hi.y.ceil() as u32).min(4 * h) {
                    for x in lo.x as u32..(hi.x.ceil() as u32).min(4 * w) {
                        let q = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                        let l = [
                            (b - q).perp_dot(c - q),
                            (c - q).perp_dot(a - q),
                            (a - q).perp_dot(b - q),
                        ]
                        .map(|e| e / area);
                        if l.iter().all(|&e| e > 1e-4) {
                            inside[(y * 4 * w + x) as usize] += 1;
                        }
                    }
                }
            }
            assert!(
                inside.iter().all(|&n| n <= 1),
                "instance {inst}: overlapping triangles"
            );
        }
    }
}

#[test]
fn large_instances_shrink_to_the_maximum_size() {
    let traced = scene(
        vec![instance(floor_quad(50.0), 0.5, Affine3A::IDENTITY)],
        Vec3::ONE,
    );
    let cache = Lightmaps::new(
        &traced,
        LightmapSettings {
            texels_per_metre: 64.0,
            max_size: 512,
            ..Default::default()
        },
    );
    let [w, h] = cache.texture_size(0);
    assert!(w <= 512 && h <= 512 && w >= 480, "{w} × {h}");
    let d = cache.texels_per_metre(0);
    assert!(d < 5.12 && d > 4.5, "{d}");
}

/// A 2 m floor (albedo 0.5) pierced by a box (albedo 0.7) under a coloured sky.
fn floor_with_box() -> TracedScene {
    let instances = vec![
        instance(floor_quad(1.0), 0.5, Affine3A::IDENTITY),
        instance(
            cuboid(
                "box",
                Vec3::new(-0.2, -0.1, -0.3),
                Vec3::new(0.3, 0.4, 0.2),
                false,
            ),
            0.7,
            Affine3A::IDENTITY,
        ),
    ];
    scene(instances, Vec3::new(1.0, 0.8, 0.6))
}

#[test]
fn same_seed_gives_identical_texels_whatever_the_batches() {
    let traced = floor_with_box();
    let bake = |batch: usize| {
        let cache = Lightmaps::new(&traced, settings(12.0));
        let mut baker = Baker::new(cache, estimator(0.02), 21);
        while !baker.step(&traced, batch) {}
        baker.into_cache()
    };
    let (a, b) = (bake(7), bake(100_000));
    assert_eq!(a.stats(), b.stats());
    let (ta, tb) = (a.publish(&traced), b.publish(&traced));
    assert_eq!(ta, tb);
    assert!(ta[0].texels.iter().any(|v| v.max_element() > 0.0));
}

/// A lightmap's later rounds hold most of its samples in few points: progress counts
/// samples, known for every round (its budgets and the cache's guess of the rounds
/// after), stays within [0, 1], ends at 1, and the samples it expected at the first
/// round are within a factor of the samples taken.
#[test]
fn progress_counts_samples_across_rounds() {
    let traced = floor_with_box();
    let cache = Lightmaps::new(&traced, settings(12.0));
    let mut baker = Baker::new(cache, estimator(0.02), 3);
    let mut first_guess = None;
    let mut rounds_seen = 0;
    while !baker.step(&traced, 64) {
        let p = *baker.progress();
        let pending = p
            .samples_pending
            .expect("lightmaps know their samples to come");
        first_guess.get_or_insert(p.samples + pending);
        let f = p.fraction();
        assert!((0.0..=1.0).contains(&f), "{f}");
        rounds_seen = rounds_seen.max(p.rounds);
    }
    let p = *baker.progress();
    assert_eq!(p.fraction(), 1.0);
    assert!(rounds_seen >= 1, "the bound needed more than one round");
    let guess = first_guess.unwrap() as f64 / p.samples as f64;
    assert!(
        (0.25..4.0).contains(&guess),
        "first guess {guess} of the samples taken"
    );
}
