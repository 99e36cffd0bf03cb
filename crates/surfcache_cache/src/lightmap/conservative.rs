//! Conservative rasterisation: the texels a triangle's UV footprint overlaps, for texel
//! ownership and for the atlas packer's reservations.

use crate::charts::TEXEL_EPSILON;
use glam::Vec2;

/// Calls `f(x, y)` for every texel of the rectangle `clip` (x, y, width, height) whose
/// square overlaps the triangle `corners` (texel units) in more than a sliver
/// ([`TEXEL_EPSILON`]): conservative rasterisation (Hasselgren, Akenine-Möller & Ohlsson,
/// "Conservative Rasterization", GPU Gems 2, ch. 42), decided per texel by the separating
/// axis test of a triangle and a box (Akenine-Möller 2001: the box axes, then each edge
/// normal against the box corner farthest along it). A triangle that overlaps no texel
/// that much still gets the texel holding its centroid. Degenerate triangles get none.
pub fn conservative_texels(corners: [Vec2; 3], clip: [u32; 4], f: impl FnMut(u32, u32)) {
    texels_overlapped_by(corners, clip, TEXEL_EPSILON, f);
}

/// [`conservative_texels`] with overlaps of at most `epsilon` texels counted as none (a
/// negative `epsilon` also counts texels the triangle comes within `-epsilon` of: a
/// superset, which the atlas packer reserves).
pub(crate) fn texels_overlapped_by(
    corners: [Vec2; 3],
    clip: [u32; 4],
    epsilon: f32,
    mut f: impl FnMut(u32, u32),
) {
    let [a, b, c] = corners;
    let twice_area = (b - a).perp_dot(c - a);
    if !twice_area.is_finite() || clip[2] == 0 || clip[3] == 0 {
        return;
    }
    if twice_area == 0.0 {
        segment_texels(corners, clip, epsilon, f);
        return;
    }
    let sign = twice_area.signum();
    // Inward edge normals (the interior is left of counter-clockwise edges).
    let edges = [(a, b), (b, c), (c, a)].map(|(p, q)| (p, (q - p).perp() * sign));
    let lo = a.min(b).min(c);
    let hi = a.max(b).max(c);
    let reach = Vec2::splat((-epsilon).max(0.0));
    let (lo, hi) = (lo - reach, hi + reach);
    let (cx1, cy1) = (clip[0] + clip[2] - 1, clip[1] + clip[3] - 1);
    let x0 = (lo.x.floor().max(0.0) as u32).clamp(clip[0], cx1);
    let y0 = (lo.y.floor().max(0.0) as u32).clamp(clip[1], cy1);
    let x1 = ((hi.x.ceil() - 1.0).max(0.0) as u32).clamp(clip[0], cx1);
    let y1 = ((hi.y.ceil() - 1.0).max(0.0) as u32).clamp(clip[1], cy1);
    let mut any = false;
    for y in y0..=y1 {
        let yf = y as f32;
        if yf + 1.0 - lo.y <= epsilon.max(0.0) || hi.y - yf <= epsilon.max(0.0) {
            continue;
        }
        for x in x0..=x1 {
            let xf = x as f32;
            if xf + 1.0 - lo.x <= epsilon.max(0.0) || hi.x - xf <= epsilon.max(0.0) {
                continue;
            }
            let separated = edges.iter().any(|&(p, n)| {
                let reach = n.dot(Vec2::new(xf, yf) - p) + n.x.max(0.0) + n.y.max(0.0);
                reach <= epsilon * n.length()
            });
            if !separated {
                any = true;
                f(x, y);
            }
        }
    }
    if !any {
        let centroid = (a + b + c) / 3.0;
        let x = (centroid.x.floor().max(0.0) as u32).clamp(clip[0], cx1);
        let y = (centroid.y.floor().max(0.0) as u32).clamp(clip[1], cy1);
        f(x, y);
    }
}

/// [`texels_overlapped_by`] for a triangle whose corners are collinear in UV1 (a chart of
/// a sliver whose parameterisation has no area): the texels whose centre lies within
/// ½ − `epsilon` of the segment the corners span, else the texel holding its midpoint.
fn segment_texels(corners: [Vec2; 3], clip: [u32; 4], epsilon: f32, mut f: impl FnMut(u32, u32)) {
    let [a, b, c] = corners;
    let (p, q) = [(a, b), (b, c), (c, a)]
        .into_iter()
        .max_by(|x, y| {
            (x.1 - x.0)
                .length_squared()
                .total_cmp(&(y.1 - y.0).length_squared())
        })
        .unwrap_or((a, b));
    let radius = 0.5 - epsilon;
    let (lo, hi) = (
        p.min(q) - Vec2::splat(radius),
        p.max(q) + Vec2::splat(radius),
    );
    let (cx1, cy1) = (clip[0] + clip[2] - 1, clip[1] + clip[3] - 1);
    let x0 = (lo.x.floor().max(0.0) as u32).clamp(clip[0], cx1);
    let y0 = (lo.y.floor().max(0.0) as u32).clamp(clip[1], cy1);
    let x1 = (hi.x.floor().max(0.0) as u32).clamp(clip[0], cx1);
    let y1 = (hi.y.floor().max(0.0) as u32).clamp(clip[1], cy1);
    let along = q - p;
    let length_squared = along.length_squared().max(f32::MIN_POSITIVE);
    let mut any = false;
    for y in y0..=y1 {
        for x in x0..=x1 {
            let centre = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            let s = ((centre - p).dot(along) / length_squared).clamp(0.0, 1.0);
            if (p + along * s - centre).length() <= radius {
                any = true;
                f(x, y);
            }
        }
    }
    if !any {
        let mid = 0.5 * (p + q);
        f(
            (mid.x.floor().max(0.0) as u32).clamp(clip[0], cx1),
            (mid.y.floor().max(0.0) as u32).clamp(clip[1], cy1),
        );
    }
}
