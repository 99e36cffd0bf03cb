//! Baking a glTF scene through the ECS plugin and writing its irradiance textures.
//!
//! Loads a `.gltf`/`.glb` file (default: the Cornell box shipped in `assets/`) into a
//! `bevy_ecs` world, lights it with an environment map (default: the one shipped beside
//! it), runs the plugin's schedule as a game's frame loop would until the bake is
//! published, and writes each entity's irradiance texture as linear-RGB OpenEXR
//! (W/m²) into `out/bake_gltf/`, with the UV rectangle an engine needs to address it.
//! The `surfcache bake` command does the same, plus the scene written back with UV1.
//!
//! ```text
//! cargo run --release --example bake_gltf [-- SCENE.gltf [ENV.exr]]
//! ```

use bevy_ecs::prelude::*;
use std::{path::Path, time::Duration};
use surfcache::{
    core::Environment,
    ecs::{BakeConfig, BakeStatus, BakedLightmap, InstanceName, SurfcachePlugin, spawn_scene},
    io::{load_scene, read_environment_map, write_rgb_exr},
};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let scene_path = args.get(1).map_or("assets/cornell.gltf", String::as_str);
    let env_path = args
        .get(2)
        .map_or("assets/cornell_environment.exr", String::as_str);

    // The file becomes plain scene data, then entities: one per mesh instance, light and
    // the environment.
    let mut scene = load_scene(scene_path)?.scene;
    let (map, warnings) = read_environment_map(Path::new(env_path))?;
    warnings.iter().for_each(|w| eprintln!("warning: {w}"));
    scene.environment = Environment::from_map(std::sync::Arc::new(map));
    let mut world = World::new();
    let mut schedule = Schedule::default();
    SurfcachePlugin::with_config(BakeConfig::default()).build(&mut world, &mut schedule);
    spawn_scene(&mut world, &scene);

    // The frame loop: the BVH build and the bake run in the background.
    let mut last = -1.0;
    let done = SurfcachePlugin::run_until_baked(
        &mut world,
        &mut schedule,
        Duration::from_millis(16),
        |world| {
            let status = world.resource::<BakeStatus>();
            if status.fraction - last >= 0.1 {
                last = status.fraction;
                eprintln!(
                    "{:3.0} % ({:.1} Mrays/s)",
                    100.0 * status.fraction,
                    status.rays_per_second / 1e6
                );
            }
            true
        },
    )?;
    println!("baked {scene_path} in {:.1} s", done.seconds);

    let out = Path::new("out/bake_gltf");
    std::fs::create_dir_all(out)?;
    // Every baked mesh entity carries its textures as a `BakedLightmap` component.
    for (name, lightmap) in world
        .query::<(&InstanceName, &BakedLightmap)>()
        .iter(&world)
    {
        let name = &name.0;
        for (side, texture) in [("", &lightmap.front), ("_back", &lightmap.back)] {
            let Some(t) = texture else { continue };
            let path = out.join(format!("{name}{side}.exr"));
            write_rgb_exr(&path, t.width, t.height, &t.texels)?;
            println!(
                "{}: {}x{}, UV rectangle {:?}",
                path.display(),
                t.width,
                t.height,
                t.uv_rect
            );
        }
    }
    Ok(())
}
