//! Scene and environment options shared by the commands, and loading them into a world.

use anyhow::{Context, Result, anyhow, bail};
use bevy_ecs::{schedule::Schedule, world::World};
use clap::Args;
use glam::Vec3;
use std::{path::PathBuf, sync::Arc};
use surfcache_core::{Environment, Scene};
use surfcache_ecs::{BakeConfig, SurfcachePlugin, TracedSceneState, spawn_scene};
use surfcache_trace::TracedScene;

/// Environment options (docs/cli.md).
#[derive(Args, Debug, Clone)]
pub struct EnvArgs {
    /// Environment radiance map, equirectangular OpenEXR (W/(m²·sr), +Y up, centre = −Z).
    #[arg(long, value_name = "FILE.exr")]
    pub env: Option<PathBuf>,
    /// Uniform environment radiance R,G,B in W/(m²·sr) [default: 0,0,0 unless --env].
    #[arg(long, value_name = "R,G,B", value_parser = parse_rgb)]
    pub env_color: Option<Vec3>,
    /// Scales the environment (--env or --env-color, or a built-in scene's sky).
    #[arg(long, value_name = "K", default_value_t = 1.0)]
    pub env_intensity: f32,
}

/// No options given: the scene's own environment at intensity 1 (what the command line's
/// defaults mean).
impl Default for EnvArgs {
    fn default() -> Self {
        Self {
            env: None,
            env_color: None,
            env_intensity: 1.0,
        }
    }
}

fn parse_rgb(s: &str) -> Result<Vec3, String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>().map_err(|e| format!("'{s}': {e}")))
        .collect::<Result<_, _>>()?;
    match v.as_slice() {
        [r, g, b] if v.iter().all(|x| x.is_finite() && *x >= 0.0) => Ok(Vec3::new(*r, *g, *b)),
        _ => Err(format!(
            "'{s}' is not three finite non-negative numbers R,G,B"
        )),
    }
}

impl EnvArgs {
    /// Applies the options to `scene`'s environment. Files (glTF) have a black sky unless
    /// told otherwise; built-in scenes keep their own sky unless --env/--env-color is given.
    pub fn apply(&self, scene: &mut Scene) -> Result<()> {
        if !self.env_intensity.is_finite() || self.env_intensity < 0.0 {
            bail!("--env-intensity must be a finite non-negative number");
        }
        if self.env.is_some() && self.env_color.is_some() {
            bail!("give either --env or --env-color, not both");
        }
        if let Some(path) = &self.env {
            let (map, warnings) = surfcache_io::read_environment_map(path)?;
            for w in warnings {
                crate::warn(&w);
            }
            scene.environment = Environment::from_map(Arc::new(map));
        } else if let Some(color) = self.env_color {
            scene.environment = Environment::uniform(color);
        }
        scene.environment.intensity = self.env_intensity;
        Ok(())
    }
}

/// A scene loaded into a `bevy_ecs` world, run until its BVH was built (baking off until
/// a command turns it on in [`BakeConfig`]).
pub struct LoadedWorld {
    pub world: World,
    pub schedule: Schedule,
    /// The scene as loaded (environment options applied), its instances in the traced
    /// scene's order.
    pub scene: Scene,
    /// The scene's name (file stem or built-in name).
    pub name: String,
}

impl LoadedWorld {
    /// Loads `scene_arg` (a .gltf/.glb path or a built-in name), applies the environment
    /// options, spawns it into a world and runs the schedule (scene sync, BVH).
    pub fn load(scene_arg: &str, env: &EnvArgs) -> Result<Self> {
        let loaded = surfcache_io::load_scene(scene_arg)?;
        let report = &loaded.report;
        if report.skipped_primitives > 0 {
            crate::warn(&format!(
                "skipped {} primitive(s) that are not triangles (points or lines)",
                report.skipped_primitives
            ));
        }
        if report.degenerate_triangles > 0 {
            crate::warn(&format!(
                "dropped {} degenerate or zero-area triangle(s)",
                report.degenerate_triangles
            ));
        }
        for w in &report.warnings {
            crate::warn(w);
        }
        let mut scene = loaded.scene;
        env.apply(&mut scene)?;
        let mut world = World::new();
        let mut schedule = Schedule::default();
        SurfcachePlugin::with_config(BakeConfig {
            enabled: false,
            ..Default::default()
        })
        .build(&mut world, &mut schedule);
        let spawned = spawn_scene(&mut world, &scene);
        let name = scene.name.clone();
        // The BVH is built in the background; wait for it.
        loop {
            SurfcachePlugin::update(&mut world, &mut schedule);
            let resource = world.resource::<TracedSceneState>();
            if let Some(e) = &resource.error {
                return Err(anyhow!("scene '{scene_arg}': {e}"));
            }
            if resource.scene().is_some() {
                break;
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        let resource = world.resource::<TracedSceneState>();
        // Keep the plain scene's instances in the traced scene's (entity) order.
        let index: std::collections::HashMap<_, _> =
            spawned.iter().enumerate().map(|(i, e)| (*e, i)).collect();
        let mut instances = Vec::with_capacity(resource.entities.len());
        for e in &resource.entities {
            let i = index
                .get(e)
                .context("internal error: a traced instance was not spawned from the scene")?;
            instances.push(scene.instances[*i].clone());
        }
        scene.instances = instances;
        Ok(Self {
            world,
            schedule,
            scene,
            name,
        })
    }

    /// The traced scene the BVH system built.
    pub fn traced(&self) -> Result<Arc<TracedScene>> {
        self.world
            .resource::<TracedSceneState>()
            .scene()
            .cloned()
            .context("the scene was not built")
    }
}

/// Runs `f` on a rayon pool of `threads` workers (all cores when `None`).
pub fn with_threads<T: Send>(threads: Option<usize>, f: impl FnOnce() -> T + Send) -> Result<T> {
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        if n == 0 {
            bail!("--threads must be at least 1");
        }
        builder = builder.num_threads(n);
    }
    let pool = builder.build().context("cannot start worker threads")?;
    Ok(pool.install(f))
}
