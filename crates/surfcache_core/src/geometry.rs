//! Triangle geometry: the parametrisation φ(u,v), normals, areas, closest points.

use glam::{Vec2, Vec3};

/// φ(u,v) = (1−u−v)A + uB + vC: the point of triangle (A,B,C) at barycentrics (u,v)
/// (docs/design.md, Physics).
#[inline]
pub fn triangle_point(a: Vec3, b: Vec3, c: Vec3, uv: Vec2) -> Vec3 {
    a * (1.0 - uv.x - uv.y) + b * uv.x + c * uv.y
}

/// Unnormalised geometric normal (B−A)×(C−A); its length is twice the area.
#[inline]
pub fn triangle_cross(a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    (b - a).cross(c - a)
}

/// The longest edge of triangle abc: max(|B−A|, |C−B|, |A−C|).
#[inline]
pub fn longest_edge(a: Vec3, b: Vec3, c: Vec3) -> f32 {
    (b - a).length().max((c - b).length()).max((a - c).length())
}

/// Area ½|(B−A)×(C−A)|.
#[inline]
pub fn triangle_area(a: Vec3, b: Vec3, c: Vec3) -> f32 {
    0.5 * triangle_cross(a, b, c).length()
}

/// Interpolates a per-vertex attribute with barycentrics (u,v): (1−u−v)x_A + u x_B + v x_C.
#[inline]
pub fn interpolate<T>(xa: T, xb: T, xc: T, uv: Vec2) -> T
where
    T: core::ops::Mul<f32, Output = T> + core::ops::Add<Output = T>,
{
    xa * (1.0 - uv.x - uv.y) + xb * uv.x + xc * uv.y
}

/// Barycentrics (u,v) of the projection of `p` onto the plane of triangle (A,B,C), not
/// clamped to the triangle (Ericson, *Real-Time Collision Detection*, §3.4, by dot
/// products of the edge vectors).
pub fn plane_barycentric(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec2 {
    let (e0, e1, d) = (b - a, c - a, p - a);
    let (d00, d01, d11) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
    let (d20, d21) = (d.dot(e0), d.dot(e1));
    let denom = d00 * d11 - d01 * d01;
    if denom == 0.0 {
        return Vec2::ZERO;
    }
    Vec2::new(d11 * d20 - d01 * d21, d00 * d21 - d01 * d20) / denom
}

/// Closest point of triangle (A,B,C) to `p`, returned as barycentrics (u,v)
/// (Ericson, *Real-Time Collision Detection*, §5.1.5, Voronoi regions of the triangle).
pub fn closest_point_barycentric(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec2 {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return Vec2::ZERO;
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return Vec2::new(1.0, 0.0);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return Vec2::new(v, 0.0);
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return Vec2::new(0.0, 1.0);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return Vec2::new(0.0, w);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return Vec2::new(1.0 - w, w);
    }
    let denom = 1.0 / (va + vb + vc);
    Vec2::new(vb * denom, vc * denom)
}

/// An orthonormal basis (t, b, n) around unit `n` without branches on the sign
/// (Duff et al., "Building an Orthonormal Basis, Revisited", JCGT 2017).
#[inline]
pub fn orthonormal_basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// Local direction (x, y, z) in the frame whose z axis is `n`, mapped to world space.
#[inline]
pub fn to_world(local: Vec3, n: Vec3) -> Vec3 {
    let (t, b) = orthonormal_basis(n);
    t * local.x + b * local.y + n * local.z
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_point_inside_and_outside() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        let uv = closest_point_barycentric(Vec3::new(0.25, 0.25, 1.0), a, b, c);
        assert!((uv - Vec2::new(0.25, 0.25)).length() < 1e-6);
        let uv = closest_point_barycentric(Vec3::new(2.0, -1.0, 0.0), a, b, c);
        assert!((uv - Vec2::new(1.0, 0.0)).length() < 1e-6);
        let uv = closest_point_barycentric(Vec3::new(1.0, 1.0, 0.0), a, b, c);
        assert!((uv - Vec2::new(0.5, 0.5)).length() < 1e-6);
    }

    #[test]
    fn basis_is_orthonormal() {
        for n in [Vec3::Z, -Vec3::Z, Vec3::new(0.3, -0.8, 0.1).normalize()] {
            let (t, b) = orthonormal_basis(n);
            assert!(t.dot(b).abs() < 1e-6 && t.dot(n).abs() < 1e-6 && b.dot(n).abs() < 1e-6);
            assert!((t.cross(b) - n).length() < 1e-5);
        }
    }
}
