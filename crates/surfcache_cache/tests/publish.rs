//! Published mesh-colour textures against the caches' own lookups: sampled bilinearly at
//! a mesh triangle's UV1, a texture reproduces `lookup` exactly at texel centres and on
//! the cells along each triangle's hypotenuse, and elsewhere within
//! |E00 + E11 − E10 − E01|/4 of the cell (see `mesh_colour`); vertex lighting (order 1)
//! is exact everywhere. UV1 must follow the *mesh's* triangle and corner order, also for
//! mirrored instances.

mod common;

use common::{Points, bake_synthetic};
use surfcache_cache::{
    IrradianceTexture, SurfaceCache,
    irradiance_map::{IrradianceMapSettings, IrradianceMaps},
    vertex_lighting::{VertexLighting, VertexLightingSettings},
};
use surfcache_core::{
    Instance, Material, Scene,
    geometry::closest_point_barycentric,
    glam::{Affine3A, Quat, Vec2, Vec3},
    scenes::{cuboid, quad},
};
use surfcache_trace::{SurfacePoint, TracedScene};

/// Three instances: a floor, a mirrored double-sided box, a rotated wall.
fn scene() -> Scene {
    let v = Vec3::new;
    let mut mirrored = Instance::new(
        cuboid("box", v(0.0, 0.0, 0.0), v(0.5, 0.7, 0.3), false),
        Material {
            double_sided: true,
            ..Material::default()
        },
    );
    mirrored.transform = Affine3A::from_scale_rotation_translation(
        v(-1.0, 1.0, 1.0),
        Quat::IDENTITY,
        v(1.0, 0.0, 0.5),
    );
    let mut wall = Instance::new(
        quad(
            "wall",
            [
                v(0., 0., 0.),
                v(1.2, 0., 0.),
                v(1.2, 0.8, 0.),
                v(0., 0.8, 0.),
            ],
            Vec3::Z,
        ),
        Material::default(),
    );
    wall.transform =
        Affine3A::from_rotation_translation(Quat::from_rotation_y(0.7), v(0.0, 0.0, -1.0));
    Scene {
        instances: vec![
            Instance::new(
                quad(
                    "floor",
                    [
                        v(-1., 0., -1.),
                        v(2., 0., -1.),
                        v(2., 0., 2.),
                        v(-1., 0., 2.),
                    ],
                    Vec3::Y,
                ),
                Material::default(),
            ),
            mirrored,
            wall,
        ],
        ..Default::default()
    }
}

/// A synthetic irradiance with a steep ramp (so grids reach different orders), different
/// on the two sides.
fn irradiance(p: &SurfacePoint) -> (Vec3, f32) {
    let x = p.position;
    let ramp = 4.0 / (1.0 + (-(x.x - 0.3) * 25.0).exp());
    let side = p.geometric_normal.dot(Vec3::new(0.3, 0.5, 0.8));
    (
        Vec3::new(1.0 + ramp, 2.0 + (3.0 * x.z).sin(), 1.5 + x.y + side),
        0.0,
    )
}

/// For every mesh triangle of every texture: points given by mesh barycentrics, mapped
/// through the texture's UV1 and, independently, to the traced triangle; `bound(t, front,
/// uv)` is the allowed difference at traced barycentrics `uv`.
fn check_textures(
    scene: &Scene,
    traced: &TracedScene,
    textures: &[IrradianceTexture],
    cache: &dyn SurfaceCache,
    bound: impl Fn(u32, bool, Vec2) -> f32,
    extra_points: impl Fn(u32, bool) -> Vec<Vec2>,
) {
    let mut rng = Points(17);
    for tex in textures {
        let inst = &scene.instances[tex.instance as usize];
        assert_eq!(tex.uv1.len(), inst.mesh.indices.len());
        assert!(!tex.uses_mesh_uv1);
        assert_eq!(tex.uv_rect, [0.0, 0.0, 1.0, 1.0]);
        assert_eq!(tex.texels.len(), (tex.width * tex.height) as usize);
        for t in traced.instance_triangles()[tex.instance as usize].clone() {
            let l = traced.local_triangle()[t as usize] as usize;
            // The mesh triangle's corners in world space, in mesh order.
            let m = inst.mesh.indices[l].map(|i| {
                inst.transform
                    .transform_point3(inst.mesh.positions[i as usize])
            });
            let [a, b, c] = traced.positions()[t as usize];
            let mut uvs: Vec<Vec2> = (0..200).map(|_| rng.barycentrics()).collect();
            uvs.extend(extra_points(t, tex.front));
            for uv in uvs {
                let p = a * (1.0 - uv.x - uv.y) + b * uv.x + c * uv.y;
                // Mesh barycentrics of the same point, and its UV1.
                let beta = closest_point_barycentric(p, m[0], m[1], m[2]);
                let uv1 = tex.uv1[l][0] * (1.0 - beta.x - beta.y)
                    + tex.uv1[l][1] * beta.x
                    + tex.uv1[l][2] * beta.y;
                let from_texture = tex.sample(uv1);
                let looked_up = cache.lookup(t, uv, tex.front);
                let allowed = bound(t, tex.front, uv) + 2e-4 * looked_up.max_element();
                assert!(
                    (from_texture - looked_up).abs().max_element() <= allowed,
                    "{} front {} triangle {t} at {uv}: texture {from_texture}, lookup {looked_up}",
                    tex.name,
                    tex.front
                );
            }
        }
    }
}

#[test]
fn irradiance_map_textures_reproduce_lookup() {
    let scene = scene();
    let traced = TracedScene::new(&scene).unwrap();
    assert!(traced.mirrored()[1] && !traced.mirrored()[0]);
    let settings = IrradianceMapSettings {
        density: 40.0,
        max_order: 16,
        interpolation_error: 0.01,
        ..Default::default()
    };
    let (maps, _) = bake_synthetic(&traced, IrradianceMaps::new(&traced, settings), irradiance);
    let orders = maps.stats().order_histogram;
    assert!(orders.len() >= 3, "want mixed orders: {orders:?}");
    let textures = maps.publish(&traced);
    // Front of all three instances, back of the double-sided box.
    let sides: Vec<(u32, bool)> = textures.iter().map(|t| (t.instance, t.front)).collect();
    assert_eq!(sides, [(0, true), (1, true), (1, false), (2, true)]);
    // Where the wall stands on the floor, lookups know the crossing and the textures do
    // not (the irradiance-map module docs, Crossings): those grids are not compared.
    let crossed = (0..traced.triangle_count() as u32)
        .filter(|&t| maps.is_crossed(t, true))
        .count();
    assert!(
        crossed > 0 && crossed < traced.triangle_count(),
        "{crossed} crossed grids"
    );
    // The cell holding uv: exact (to float precision) on hypotenuse cells, else the
    // bilinear-versus-two-triangle bound.
    let bound = |t: u32, front: bool, uv: Vec2| {
        if maps.is_crossed(t, front) {
            return f32::INFINITY;
        }
        let n = maps.order(t, front);
        let (x, y) = (uv.x * n as f32, uv.y * n as f32);
        let i = (x.floor() as u32).min(n - 1);
        let j = (y.floor() as u32).min(n - 1 - i);
        if i + j + 1 >= n {
            return 0.0;
        }
        let e = |i, j| maps.sample(t, front, i, j);
        (e(i, j) + e(i + 1, j + 1) - e(i + 1, j) - e(i, j + 1))
            .abs()
            .max_element()
            / 4.0
    };
    // Texel centres (the grid samples themselves): exact.
    let centres = |t: u32, front: bool| {
        let n = maps.order(t, front);
        let mut v = Vec::new();
        for d in 0..=n {
            for j in 0..=d {
                v.push(Vec2::new((d - j) as f32, j as f32) / n as f32);
            }
        }
        v
    };
    check_textures(&scene, &traced, &textures, &maps, bound, centres);
    // And the bound is not vacuous: somewhere inside a full cell bilinear differs.
    let worst = (0..traced.triangle_count() as u32)
        .filter(|&t| !maps.is_crossed(t, true))
        .map(|t| bound(t, true, Vec2::new(0.26, 0.26)))
        .fold(0.0f32, f32::max);
    assert!(worst > 1e-3);
}

#[test]
fn vertex_lighting_textures_reproduce_lookup_exactly() {
    let scene = scene();
    let traced = TracedScene::new(&scene).unwrap();
    let cache = VertexLighting::new(&traced, VertexLightingSettings::default());
    let (cache, _) = bake_synthetic(&traced, cache, irradiance);
    let textures = cache.publish(&traced);
    assert_eq!(textures.len(), 4);
    for tex in &textures {
        // 2×2 texels per triangle.
        let blocks = traced.instance_triangles()[tex.instance as usize].len() as u32;
        assert!(tex.width * tex.height >= 4 * blocks);
    }
    let corners = |_, _| vec![Vec2::ZERO, Vec2::X, Vec2::Y];
    check_textures(&scene, &traced, &textures, &cache, |_, _, _| 0.0, corners);
}
