//! A pinhole camera for pictures and camera-ray benchmarks.

use anyhow::{Result, bail};
use glam::{Vec2, Vec3};

/// A pinhole camera looking from `eye` towards a target, +Y up.
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    pub eye: Vec3,
    forward: Vec3,
    right: Vec3,
    up: Vec3,
    /// tan(vertical field of view / 2).
    tan_half: f32,
}

impl Camera {
    /// A camera at `eye` looking at `target` with a vertical field of view in degrees.
    pub fn look_at(eye: Vec3, target: Vec3, fov_degrees: f32) -> Self {
        let forward = (target - eye).normalize_or(Vec3::Z);
        let right = forward.cross(Vec3::Y).try_normalize().unwrap_or(Vec3::X);
        let up = right.cross(forward);
        Self {
            eye,
            forward,
            right,
            up,
            tan_half: (fov_degrees.to_radians() * 0.5).tan(),
        }
    }

    /// Parses `--camera ex,ey,ez,tx,ty,tz`; `None` gives `default`.
    pub fn from_arg(arg: Option<&str>, fov_degrees: f32, default: (Vec3, Vec3)) -> Result<Self> {
        let (eye, target) = match arg {
            Some(s) => {
                let v: Vec<f32> = s
                    .split(',')
                    .map(|x| x.trim().parse::<f32>())
                    .collect::<Result<_, _>>()
                    .map_err(|e| anyhow::anyhow!("--camera '{s}': {e}"))?;
                if v.len() != 6 || v.iter().any(|x| !x.is_finite()) {
                    bail!("--camera needs six finite numbers ex,ey,ez,tx,ty,tz");
                }
                (Vec3::new(v[0], v[1], v[2]), Vec3::new(v[3], v[4], v[5]))
            }
            None => default,
        };
        if (target - eye).length_squared() == 0.0 {
            bail!("--camera: eye and target coincide");
        }
        if !(fov_degrees > 0.0 && fov_degrees < 180.0) {
            bail!("--fov must lie between 0 and 180 degrees");
        }
        Ok(Self::look_at(eye, target, fov_degrees))
    }

    /// Unit direction through image position `s` ∈ [−1, 1]² (x right, y down), for an
    /// image of the given aspect ratio (width / height).
    #[inline]
    pub fn direction(&self, s: Vec2, aspect: f32) -> Vec3 {
        (self.forward + self.right * (s.x * self.tan_half * aspect)
            - self.up * (s.y * self.tan_half))
            .normalize()
    }
}

/// A viewpoint in front of a scene's bounding box: on the −Z side of it, at its centre's
/// height, looking along +Z at its centre, far enough back to see its width in a
/// `fov_degrees` vertical field of view (the built-in Cornell box's open front).
pub fn default_view(lo: Vec3, hi: Vec3, fov_degrees: f32) -> (Vec3, Vec3) {
    let c = 0.5 * (lo + hi);
    let half = 0.5 * (hi.x - lo.x).max(hi.y - lo.y);
    let distance = half / (fov_degrees.to_radians() * 0.5).tan();
    (Vec3::new(c.x, c.y, lo.z - distance * 1.05), c)
}
