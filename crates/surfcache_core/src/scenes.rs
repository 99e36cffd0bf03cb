//! Built-in scenes and the mesh builders they (and tests) are made of.

use crate::{
    environment::{Environment, EnvironmentMap},
    scene::{Instance, Material, Mesh, Scene},
};
use glam::{Affine3A, Vec3};
use std::sync::Arc;

/// Names accepted by [`by_name`].
pub const BUILTIN_NAMES: &[&str] = &["cornell"];

/// A built-in scene by name, or `None` for an unknown name.
pub fn by_name(name: &str) -> Option<Scene> {
    match name {
        "cornell" => Some(cornell()),
        _ => None,
    }
}

/// A planar quad of corners `c` (in order around the rim), wound so that its front face
/// (counter-clockwise) looks along `facing`.
pub fn quad(name: impl Into<String>, c: [Vec3; 4], facing: Vec3) -> Mesh {
    let n = (c[1] - c[0]).cross(c[2] - c[0]);
    let c = if n.dot(facing) >= 0.0 {
        c
    } else {
        [c[0], c[3], c[2], c[1]]
    };
    Mesh::new(name, c.to_vec(), vec![[0, 1, 2], [0, 2, 3]])
}

/// A horizontal square of half-side `half` centred on the Y axis at height `y`, its front
/// face looking along `facing` (a floor: `Vec3::Y`; a ceiling panel: `-Vec3::Y`).
pub fn square(name: impl Into<String>, half: f32, y: f32, facing: Vec3) -> Mesh {
    let v = |x: f32, z: f32| Vec3::new(x, y, z);
    quad(
        name,
        [
            v(-half, -half),
            v(half, -half),
            v(half, half),
            v(-half, half),
        ],
        facing,
    )
}

/// A square floor of side `size` in the plane y = 0 from the origin towards +X and +Z,
/// facing +Y, made of `cells` × `cells` quads (a finely tessellated surface, as levels
/// have).
pub fn tiled_floor(size: f32, cells: u32) -> Mesh {
    let mut mesh = Mesh {
        name: "floor".into(),
        ..Default::default()
    };
    let s = size / cells as f32;
    for i in 0..cells {
        for j in 0..cells {
            let (x, z) = (i as f32 * s, j as f32 * s);
            let c = [
                Vec3::new(x, 0.0, z),
                Vec3::new(x + s, 0.0, z),
                Vec3::new(x + s, 0.0, z + s),
                Vec3::new(x, 0.0, z + s),
            ];
            append(&mut mesh, &quad("floor", c, Vec3::Y));
        }
    }
    mesh
}

/// Appends `other`'s triangles to `mesh` (vertices are not shared between the two).
pub fn append(mesh: &mut Mesh, other: &Mesh) {
    let base = mesh.positions.len() as u32;
    mesh.positions.extend_from_slice(&other.positions);
    mesh.normals.extend_from_slice(&other.normals);
    mesh.indices
        .extend(other.indices.iter().map(|t| t.map(|i| i + base)));
}

/// An axis-aligned box from `lo` to `hi` with six flat faces, looking outwards
/// (`inward = false`) or into the box (`inward = true`).
pub fn cuboid(name: impl Into<String>, lo: Vec3, hi: Vec3, inward: bool) -> Mesh {
    let name = name.into();
    let mut mesh = Mesh {
        name: name.clone(),
        ..Default::default()
    };
    let centre = 0.5 * (lo + hi);
    for axis in 0..3 {
        for side in [lo[axis], hi[axis]] {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let corner = |a: f32, b: f32| {
                let mut p = Vec3::ZERO;
                p[axis] = side;
                p[u] = a;
                p[v] = b;
                p
            };
            let c = [
                corner(lo[u], lo[v]),
                corner(hi[u], lo[v]),
                corner(hi[u], hi[v]),
                corner(lo[u], hi[v]),
            ];
            let mut outward = Vec3::ZERO;
            outward[axis] = (side - centre[axis]).signum();
            let facing = if inward { -outward } else { outward };
            append(&mut mesh, &quad(&name, c, facing));
        }
    }
    mesh
}

/// A block standing on the floor: the quad `top` (at its height) and four sides down to
/// y = 0, all facing outwards. The bottom is left open; it rests on the floor.
fn block(name: &str, top: [Vec3; 4]) -> Mesh {
    let centre = top.iter().copied().sum::<Vec3>() / 4.0;
    let mut mesh = quad(name, top, Vec3::Y);
    for k in 0..4 {
        let (a, b) = (top[k], top[(k + 1) % 4]);
        let side = [a, b, Vec3::new(b.x, 0.0, b.z), Vec3::new(a.x, 0.0, a.z)];
        let mid = 0.5 * (a + b);
        let out = Vec3::new(mid.x - centre.x, 0.0, mid.z - centre.z);
        append(&mut mesh, &quad(name, side, out));
    }
    mesh
}

fn instance(mesh: Mesh, material: &Arc<Material>) -> Instance {
    Instance {
        name: mesh.name.clone(),
        mesh: Arc::new(mesh),
        material: material.clone(),
        transform: Affine3A::IDENTITY,
    }
}

/// The sky behind the open front of the Cornell box: a blue zenith fading to a bright
/// horizon over a dim brown ground, radiance about 1 W/(m²·sr). 64×32 texels.
pub fn cornell_sky() -> EnvironmentMap {
    EnvironmentMap::from_fn(64, 32, |d| {
        if d.y >= 0.0 {
            let t = d.y.powf(0.5);
            Vec3::new(1.0, 0.95, 0.85).lerp(Vec3::new(0.35, 0.55, 1.0), t)
        } else {
            Vec3::new(0.25, 0.2, 0.15)
        }
    })
}

/// The classic Cornell box (published Cornell data, millimetres turned into metres):
/// white floor, ceiling and back wall, red left and green right wall (seen from the open
/// front, looking along +Z), a tall and a short block, and a square light flush with the
/// ceiling emitting (17, 12, 4) W/(m²·sr) downwards. The front (z = 0) is open to
/// [`cornell_sky`].
pub fn cornell() -> Scene {
    let (w, h, d) = (0.5528, 0.5488, 0.5592);
    let white = Arc::new(Material::diffuse("white", Vec3::new(0.725, 0.71, 0.68)));
    let red = Arc::new(Material::diffuse("red", Vec3::new(0.63, 0.065, 0.05)));
    let green = Arc::new(Material::diffuse("green", Vec3::new(0.14, 0.45, 0.091)));
    let light = Arc::new(Material::emissive(
        "light",
        Vec3::splat(0.78),
        Vec3::new(17.0, 12.0, 4.0),
    ));
    let v = Vec3::new;
    let mut instances = vec![
        instance(
            quad(
                "floor",
                [v(0., 0., 0.), v(w, 0., 0.), v(w, 0., d), v(0., 0., d)],
                Vec3::Y,
            ),
            &white,
        ),
        instance(
            quad(
                "back_wall",
                [v(0., 0., d), v(w, 0., d), v(w, h, d), v(0., h, d)],
                Vec3::NEG_Z,
            ),
            &white,
        ),
        instance(
            quad(
                "red_wall",
                [v(w, 0., 0.), v(w, 0., d), v(w, h, d), v(w, h, 0.)],
                Vec3::NEG_X,
            ),
            &red,
        ),
        instance(
            quad(
                "green_wall",
                [v(0., 0., 0.), v(0., 0., d), v(0., h, d), v(0., h, 0.)],
                Vec3::X,
            ),
            &green,
        ),
    ];
    // Ceiling: four white strips around the light, all in the plane y = h.
    let (lx0, lx1, lz0, lz1) = (0.213, 0.343, 0.227, 0.332);
    let mut ceiling = Mesh {
        name: "ceiling".into(),
        ..Default::default()
    };
    for (x0, x1, z0, z1) in [
        (0.0, w, 0.0, lz0),
        (0.0, w, lz1, d),
        (0.0, lx0, lz0, lz1),
        (lx1, w, lz0, lz1),
    ] {
        let c = [v(x0, h, z0), v(x1, h, z0), v(x1, h, z1), v(x0, h, z1)];
        append(&mut ceiling, &quad("ceiling", c, Vec3::NEG_Y));
    }
    instances.push(instance(ceiling, &white));
    instances.push(instance(
        quad(
            "light",
            [
                v(lx0, h, lz0),
                v(lx1, h, lz0),
                v(lx1, h, lz1),
                v(lx0, h, lz1),
            ],
            Vec3::NEG_Y,
        ),
        &light,
    ));
    let mm = |x: f32, y: f32, z: f32| v(x, y, z) * 0.001;
    instances.push(instance(
        block(
            "short_block",
            [
                mm(130., 165., 65.),
                mm(82., 165., 225.),
                mm(240., 165., 272.),
                mm(290., 165., 114.),
            ],
        ),
        &white,
    ));
    instances.push(instance(
        block(
            "tall_block",
            [
                mm(423., 330., 247.),
                mm(265., 330., 296.),
                mm(314., 330., 456.),
                mm(472., 330., 406.),
            ],
        ),
        &white,
    ));
    Scene {
        name: "cornell".into(),
        instances,
        lights: Vec::new(),
        environment: Environment::from_map(Arc::new(cornell_sky())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cornell_is_valid_and_faces_inward() {
        let s = cornell();
        s.validate().unwrap();
        assert_eq!(s.triangle_count(), 2 * 4 + 8 + 2 + 2 * 10);
        // Every triangle of the walls faces the box centre.
        let centre = Vec3::new(0.2764, 0.2744, 0.2796);
        for inst in s.instances.iter().filter(|i| !i.name.ends_with("block")) {
            for t in 0..inst.mesh.indices.len() {
                let [a, b, c] = inst.mesh.triangle(t);
                let n = (b - a).cross(c - a);
                assert!(n.dot(centre - a) > 0.0, "{} faces outward", inst.name);
            }
        }
    }

    #[test]
    fn cuboid_faces_follow_flag() {
        for inward in [false, true] {
            let m = cuboid("b", Vec3::ZERO, Vec3::ONE, inward);
            assert_eq!(m.indices.len(), 12);
            for t in 0..12 {
                let [a, b, c] = m.triangle(t);
                let n = (b - a).cross(c - a);
                let out = n.dot((a + b + c) / 3.0 - Vec3::splat(0.5)) > 0.0;
                assert_eq!(out, !inward);
            }
        }
    }
}
