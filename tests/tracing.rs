//! The BVH against brute force: random rays, grazing rays and rays leaving surfaces must
//! find the same closest hit (distance and triangle) as testing every triangle in f64, and
//! the any-hit query must agree with it, at every SIMD level the CPU supports (each forced
//! in turn). Rays whose brute-force answer lies within a relative 1e-4 of a triangle edge
//! are skipped: either answer is right there.

use surfcache::core::{
    geometry::to_world,
    glam::Vec3,
    sampling::{Rng, cosine_hemisphere, uniform_sphere},
    scenes,
};
use surfcache::trace::{Bvh, SimdLevel, TracedScene};

/// Closest hit by testing every triangle in f64: (t, triangle, edge margin), where the
/// margin is the smallest barycentric of the hit (negative distance outside for near misses).
fn brute_force(tris: &[[Vec3; 3]], o: Vec3, d: Vec3, tmax: f64) -> (Option<(f64, usize)>, f64) {
    brute_force_from(tris, o, d, 0.0, tmax)
}

/// [`brute_force`] for `t ∈ (tmin, tmax]`.
fn brute_force_from(
    tris: &[[Vec3; 3]],
    o: Vec3,
    d: Vec3,
    tmin: f64,
    tmax: f64,
) -> (Option<(f64, usize)>, f64) {
    let (o, d) = (o.as_dvec3(), d.as_dvec3());
    let mut best: Option<(f64, usize)> = None;
    let mut margin = f64::INFINITY; // distance of the answer from being ambiguous
    for (i, t) in tris.iter().enumerate() {
        let [a, b, c] = t.map(|p| p.as_dvec3());
        let (e1, e2) = (b - a, c - a);
        let p = d.cross(e2);
        let det = e1.dot(p);
        if det.abs() < 1e-300 {
            continue;
        }
        let s = o - a;
        let u = s.dot(p) / det;
        let q = s.cross(e1);
        let v = d.dot(q) / det;
        let t = e2.dot(q) / det;
        let w = 1.0 - u - v;
        let m = u.min(v).min(w);
        if t > tmin && t <= tmax {
            if m.abs() < margin && best.is_none_or(|(bt, _)| t < bt * (1.0 + 1e-4)) {
                margin = margin.min(m.abs());
            }
            if m >= 0.0 && best.is_none_or(|(bt, _)| t < bt) {
                best = Some((t, i));
            }
        }
    }
    (best, margin)
}

/// The SIMD levels this CPU runs (scalar always).
fn levels() -> Vec<SimdLevel> {
    SimdLevel::ALL
        .into_iter()
        .filter(|l| l.is_supported())
        .collect()
}

/// What [`check`] forces through the SIMD levels: a BVH, or a traced scene's.
trait Traversed {
    fn bvh(&self) -> &Bvh;
    fn set_simd_level(&mut self, level: SimdLevel) -> bool;
}

impl Traversed for Bvh {
    fn bvh(&self) -> &Bvh {
        self
    }
    fn set_simd_level(&mut self, level: SimdLevel) -> bool {
        Bvh::set_simd_level(self, level)
    }
}

impl Traversed for TracedScene {
    fn bvh(&self) -> &Bvh {
        TracedScene::bvh(self)
    }
    fn set_simd_level(&mut self, level: SimdLevel) -> bool {
        TracedScene::set_simd_level(self, level)
    }
}

/// [`check_level`] at every supported SIMD level, forced one by one; the levels must also
/// return identical hits.
fn check(traversed: &mut impl Traversed, tris: &[[Vec3; 3]], rays: &[(Vec3, Vec3)]) -> usize {
    let detected = traversed.bvh().simd_level();
    let mut compared = usize::MAX;
    let mut answers = Vec::new();
    for level in levels() {
        assert!(traversed.set_simd_level(level));
        let bvh = traversed.bvh();
        assert_eq!(bvh.simd_level(), level);
        compared = compared.min(check_level(bvh, tris, rays));
        let hits: Vec<_> = rays
            .iter()
            .map(|&(o, d)| bvh.closest_hit(o, d, 0.0, f32::INFINITY))
            .collect();
        answers.push((level, hits));
    }
    for (level, hits) in &answers[1..] {
        assert_eq!(
            hits, &answers[0].1,
            "{level:?} and {:?} differ",
            answers[0].0
        );
    }
    traversed.set_simd_level(detected);
    compared
}

fn check_level(bvh: &Bvh, tris: &[[Vec3; 3]], rays: &[(Vec3, Vec3)]) -> usize {
    let mut compared = 0;
    for (k, &(o, d)) in rays.iter().enumerate() {
        let (expected, margin) = brute_force(tris, o, d, f64::INFINITY);
        if margin < 1e-4 {
            continue;
        }
        compared += 1;
        let got = bvh.closest_hit(o, d, 0.0, f32::INFINITY);
        match (expected, got) {
            (None, None) => {}
            (Some((t, tri)), Some(hit)) => {
                assert!(
                    ((hit.t as f64) - t).abs() <= 1e-4 * t.max(1e-3),
                    "ray {k}: t {} vs brute force {t}",
                    hit.t
                );
                assert_eq!(hit.triangle as usize, tri, "ray {k}: triangle");
                assert!(bvh.occluded(o, d, 0.0, hit.t * 1.001));
                assert!(!bvh.occluded(o, d, 0.0, hit.t * 0.999) || t < 1e-3);
            }
            (e, g) => panic!("ray {k} from {o} along {d}: brute force {e:?}, BVH {g:?}"),
        }
        assert_eq!(
            bvh.occluded(o, d, 0.0, f32::INFINITY),
            expected.is_some(),
            "ray {k}"
        );
    }
    compared
}

fn soup(n: usize, seed: u64) -> Vec<[Vec3; 3]> {
    let mut rng = Rng::new(seed, 0);
    (0..n)
        .map(|_| {
            let c = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 10.0 - 5.0;
            let s = 0.05 + rng.next_f32() * 1.5;
            [0, 1, 2].map(|_| c + uniform_sphere(rng.next_vec2()) * s)
        })
        .collect()
}

#[test]
fn random_rays_match_brute_force() {
    let tris = soup(2000, 1);
    let mut bvh = Bvh::build(&tris);
    let mut rng = Rng::new(2, 0);
    let rays: Vec<(Vec3, Vec3)> = (0..3000)
        .map(|_| {
            let o = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 14.0 - 7.0;
            // Unnormalised directions: t is in units of the direction's length.
            (
                o,
                uniform_sphere(rng.next_vec2()) * (0.1 + 3.0 * rng.next_f32()),
            )
        })
        .collect();
    assert!(check(&mut bvh, &tris, &rays) > 2900);
}

#[test]
fn grazing_rays_match_brute_force() {
    let mut scene = TracedScene::new(&scenes::cornell()).unwrap();
    let tris = scene.positions().to_vec();
    let mut rng = Rng::new(3, 0);
    // Rays skimming the floor (y = 0) at angles down to 1e-4 rad, from just above it.
    let rays: Vec<(Vec3, Vec3)> = (0..2000)
        .map(|i| {
            let angle = 10f32.powf(-1.0 - 3.0 * rng.next_f32());
            let phi = rng.next_f32() * std::f32::consts::TAU;
            let o = Vec3::new(
                0.05 + 0.45 * rng.next_f32(),
                1e-3,
                0.05 + 0.45 * rng.next_f32(),
            );
            let sign = if i % 2 == 0 { -1.0 } else { 1.0 };
            (o, Vec3::new(phi.cos(), sign * angle.sin(), phi.sin()))
        })
        .collect();
    assert!(check(&mut scene, &tris, &rays) > 1500);
}

#[test]
fn rays_leaving_surfaces_match_brute_force() {
    for scene in [scenes::cornell()] {
        let mut traced = TracedScene::new(&scene).unwrap();
        let tris = traced.positions().to_vec();
        let mut rng = Rng::new(4, 0);
        let mut rays = Vec::new();
        for t in 0..traced.triangle_count() as u32 {
            for _ in 0..60 {
                let uv = surfcache::core::sampling::uniform_triangle(rng.next_vec2());
                let p = traced.surface_point(t, uv, rng.next_f32() < 0.5);
                let d = to_world(cosine_hemisphere(rng.next_vec2()), p.geometric_normal);
                rays.push((traced.spawn_origin(&p), d));
            }
        }
        let n = rays.len();
        assert!(check(&mut traced, &tris, &rays) > n * 9 / 10);
    }
}

#[test]
fn scale_does_not_change_answers() {
    // The same scene at 1e-3 and 1e4 times its size gives the same hits (scaled t).
    let tris = soup(500, 5);
    let mut rng = Rng::new(6, 0);
    let rays: Vec<(Vec3, Vec3)> = (0..500)
        .map(|_| {
            let o = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 14.0 - 7.0;
            (o, uniform_sphere(rng.next_vec2()))
        })
        .collect();
    let base = Bvh::build(&tris);
    for scale in [1e-3f32, 1e4] {
        let scaled: Vec<[Vec3; 3]> = tris.iter().map(|t| t.map(|p| p * scale)).collect();
        let bvh = Bvh::build(&scaled);
        for &(o, d) in &rays {
            let a = base.closest_hit(o, d, 0.0, f32::INFINITY);
            let b = bvh.closest_hit(o * scale, d, 0.0, f32::INFINITY);
            match (a, b) {
                (None, None) => {}
                (Some(a), Some(b)) => {
                    assert!(
                        (a.t * scale - b.t).abs() <= 1e-4 * b.t,
                        "{} vs {}",
                        a.t * scale,
                        b.t
                    );
                }
                (a, b) => {
                    // Only edge-grazing rays may differ.
                    let (_, margin) = brute_force(&tris, o, d, f64::INFINITY);
                    assert!(margin < 1e-4, "scale {scale}: {a:?} vs {b:?}");
                }
            }
        }
    }
}

#[test]
fn rays_starting_past_tmin_match_brute_force() {
    // tmin skips the hits before it (the node test honours tmin, not a fixed epsilon):
    // every ray starts inside the soup, at tmin from 0 to half the box.
    let tris = soup(1000, 7);
    let mut bvh = Bvh::build(&tris);
    let mut rng = Rng::new(8, 0);
    let mut compared = 0;
    for level in levels() {
        bvh.set_simd_level(level);
        for k in 0..2000 {
            let o = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 10.0 - 5.0;
            let d = uniform_sphere(rng.next_vec2());
            let tmin = if k % 4 == 0 {
                0.0
            } else {
                5.0 * rng.next_f32()
            };
            let (expected, margin) = brute_force_from(&tris, o, d, tmin as f64, f64::INFINITY);
            // Also skip answers that lie right at tmin.
            if margin < 1e-4 || expected.is_some_and(|(t, _)| t < tmin as f64 * (1.0 + 1e-5)) {
                continue;
            }
            let got = bvh.closest_hit(o, d, tmin, f32::INFINITY);
            match (expected, got) {
                (None, None) => {}
                (Some((t, tri)), Some(hit)) => {
                    assert!(
                        ((hit.t as f64) - t).abs() <= 1e-4 * t.max(1e-3),
                        "{level:?} ray {k}"
                    );
                    assert_eq!(hit.triangle as usize, tri, "{level:?} ray {k}");
                }
                (e, g) => panic!("{level:?} ray {k}: brute force {e:?}, BVH {g:?}"),
            }
            assert_eq!(bvh.occluded(o, d, tmin, f32::INFINITY), expected.is_some());
            compared += 1;
        }
    }
    assert!(compared > 1500 * levels().len());
}

#[test]
fn alpha_filters_skip_rejected_hits_at_every_level() {
    // A filter that rejects every other triangle: the closest hit is the closest accepted
    // triangle of brute force, and occlusion sees only accepted triangles.
    let tris = soup(800, 9);
    let kept: Vec<[Vec3; 3]> = tris.iter().step_by(2).copied().collect();
    let mut bvh = Bvh::build(&tris);
    let accept = |t: u32, uv: surfcache::core::glam::Vec2| {
        assert!(uv.x >= 0.0 && uv.y >= 0.0 && uv.x + uv.y <= 1.0 + 1e-6);
        t.is_multiple_of(2)
    };
    let mut rng = Rng::new(10, 0);
    let rays: Vec<(Vec3, Vec3)> = (0..1500)
        .map(|_| {
            let o = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 14.0 - 7.0;
            (o, uniform_sphere(rng.next_vec2()))
        })
        .collect();
    let mut compared = 0;
    for level in levels() {
        bvh.set_simd_level(level);
        for &(o, d) in &rays {
            let (expected, margin) = brute_force(&kept, o, d, f64::INFINITY);
            let (_, margin_all) = brute_force(&tris, o, d, f64::INFINITY);
            if margin.min(margin_all) < 1e-4 {
                continue;
            }
            let got = bvh.closest_hit_filtered(o, d, 0.0, f32::INFINITY, Some(&accept));
            match (expected, got) {
                (None, None) => {}
                (Some((t, tri)), Some(hit)) => {
                    assert!(((hit.t as f64) - t).abs() <= 1e-4 * t.max(1e-3));
                    assert_eq!(hit.triangle as usize, 2 * tri);
                }
                (e, g) => panic!("{level:?}: brute force {e:?}, BVH {g:?}"),
            }
            let occluded = bvh.occluded_filtered(o, d, 0.0, f32::INFINITY, Some(&accept));
            assert_eq!(occluded, expected.is_some());
            compared += 1;
        }
    }
    assert!(compared > 1200 * levels().len());
}
