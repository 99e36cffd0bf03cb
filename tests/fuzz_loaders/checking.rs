//! Checking what loaded: a scene's data must be finite and consistent.

use crate::running::{message, printable};
use std::path::{Path, PathBuf};
use surfcache::core::glam::Vec2;
use surfcache::core::{AlphaMode, Light, Scene};

fn finite_texture(t: &surfcache::core::Texture) -> bool {
    (0..t.height()).all(|j| (0..t.width()).all(|i| t.texel(i, j).is_finite()))
}

/// The first non-finite or inconsistent datum of a loaded scene.
fn scene_problem(scene: &Scene) -> Option<String> {
    if scene.triangle_count() == 0 {
        return Some("no triangles".into());
    }
    if let Err(e) = scene.validate() {
        return Some(format!("does not validate: {e}"));
    }
    for inst in &scene.instances {
        let name = &inst.name;
        if !inst.transform.is_finite() {
            return Some(format!("instance '{name}': non-finite transform"));
        }
        let m = &inst.mesh;
        for (v, &p) in m.positions.iter().enumerate() {
            if !p.is_finite() || !inst.transform.transform_point3(p).is_finite() {
                return Some(format!(
                    "instance '{name}': vertex {v} at {p} lies at {} in world space",
                    inst.transform.transform_point3(p)
                ));
            }
        }
        if let Some(v) = m.normals.iter().position(|n| !n.is_finite()) {
            return Some(format!("instance '{name}': non-finite normal {v}"));
        }
        for (set, uvs) in [("uv0", &m.uv0), ("uv1", &m.uv1)] {
            if let Some(v) = uvs.iter().position(|t: &Vec2| !t.is_finite()) {
                return Some(format!("instance '{name}': non-finite {set} {v}"));
            }
        }
        let mat = &inst.material;
        let cutoff = match mat.alpha_mode {
            AlphaMode::Mask(c) => c,
            _ => 0.0,
        };
        if !(mat.albedo.is_finite()
            && mat.emission.is_finite()
            && mat.alpha.is_finite()
            && cutoff.is_finite())
        {
            return Some(format!("material '{}': non-finite factor", mat.name));
        }
        for t in [&mat.albedo_texture, &mat.emission_texture]
            .into_iter()
            .flatten()
        {
            if !finite_texture(t) {
                return Some(format!("material '{}': bad texture", mat.name));
            }
        }
    }
    for (i, light) in scene.lights.iter().enumerate() {
        let finite = match *light {
            Light::Directional {
                direction,
                irradiance,
            } => direction.is_finite() && irradiance.is_finite(),
            Light::Point {
                position,
                intensity,
            } => position.is_finite() && intensity.is_finite(),
            Light::Spot {
                position,
                direction,
                intensity,
                inner_cone_angle,
                outer_cone_angle,
            } => {
                position.is_finite()
                    && direction.is_finite()
                    && intensity.is_finite()
                    && inner_cone_angle.is_finite()
                    && outer_cone_angle.is_finite()
            }
        };
        if !finite {
            return Some(format!("light {i} is not finite: {light:?}"));
        }
    }
    let env = &scene.environment;
    if !env.color.is_finite() || !env.intensity.is_finite() {
        return Some("non-finite environment".into());
    }
    None
}

/// Loads a scene file: the outcome, or the violated property.
pub(crate) fn check_scene(path: &Path) -> Result<(PathBuf, Result<(), String>), String> {
    let outcome = match surfcache::io::load_scene(path.to_str().unwrap()) {
        Ok(loaded) => {
            if let Some(problem) = scene_problem(&loaded.scene) {
                return Err(format!("loaded with {problem}"));
            }
            if let Some(w) = loaded.report.warnings.iter().find(|w| !printable(w)) {
                return Err(format!("warning is not one printable line: {w:?}"));
            }
            Ok(())
        }
        Err(e) => Err(message(&e)?),
    };
    Ok((path.to_path_buf(), outcome))
}
