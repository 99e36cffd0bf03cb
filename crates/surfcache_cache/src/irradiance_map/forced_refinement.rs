//! Grids that refine whatever their samples say: those another surface crosses (around
//! the crossing) and those a punctual light's shadow boundary crosses (everywhere, to
//! their maximum order; the module docs of [`super`], Shadow probes, Local refinement and
//! Crossings).

use crate::{SampleSite, crossings};
use glam::Vec2;
use surfcache_trace::TracedScene;

/// Grid slots (`2·triangle + side`, among those `bake` marks) that another surface
/// crosses or touches ([`crossings::grid_crossed`] at the order the grid starts at,
/// `min(2, n_max)`). The cells of such a grid that the crossing passes near refine to the
/// maximum order whatever its samples say: when all its coarse samples lie on one side of
/// the crossing (the lit overhang of a wall that pierces its neighbour, the thesis' known
/// failure) they agree, and the refinement test sees nothing to refine. Costs [`crossings::PROBE_DIRECTIONS`] rays per point,
/// except for the grids whose answer `known` gives (a re-bake's grids that no changed
/// surface comes near).
pub fn crossed_grids(
    scene: &TracedScene,
    max_orders: &[u32],
    bake: &[bool],
    known: impl Fn(usize) -> Option<bool> + Sync,
) -> Vec<bool> {
    use rayon::prelude::*;
    (0..bake.len())
        .into_par_iter()
        .map(|g| {
            let t = (g / 2) as u32;
            bake[g]
                && known(g).unwrap_or_else(|| {
                    crossings::grid_crossed(scene, t, g % 2 == 0, max_orders[t as usize].min(2))
                })
        })
        .collect()
}

/// Grid slots (`2·triangle + side`, among those `bake` marks) that a hard shadow of a
/// punctual light crosses: the light's exact irradiance (one shadow ray per light) at the
/// points of the grid at its maximum order `max_orders[t]` is zero at some and positive
/// at others. Such a grid refines to its maximum order whatever its samples say: a
/// shadow strip narrower than the coarse sample spacing can fall between all of them
/// (the thesis' misjudged triangle), and no comparison of samples can see it. Costs one
/// shadow ray per light and probe point; none without punctual lights. Shadows of area
/// lights and of a bright sky are left to the refinement test.
pub fn punctual_shadow_edges(scene: &TracedScene, max_orders: &[u32], bake: &[bool]) -> Vec<bool> {
    use rayon::prelude::*;
    if scene.lights().is_empty() {
        return vec![false; bake.len()];
    }
    (0..bake.len())
        .into_par_iter()
        .map(|g| {
            if !bake[g] {
                return false;
            }
            let (t, front) = ((g / 2) as u32, g % 2 == 0);
            let n = max_orders[t as usize];
            let inv = 1.0 / n as f32;
            let (mut lit, mut dark) = (false, false);
            let mut rays = 0;
            for d in 0..=n {
                for j in 0..=d {
                    let i = d - j;
                    let site = SampleSite::Surface {
                        triangle: t,
                        uv: Vec2::new(i as f32 * inv, j as f32 * inv),
                        front,
                    };
                    let (p, origin) = crate::bake::sample_frame(scene, &site);
                    let e = scene.punctual_irradiance_from(&p, origin, &mut rays);
                    if e.max_element() > 0.0 {
                        lit = true;
                    } else {
                        dark = true;
                    }
                    if lit && dark {
                        return true;
                    }
                }
            }
            false
        })
        .collect()
}
