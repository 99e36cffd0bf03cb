//! A Bevy game whose scene bakes itself: open a window, load a scene, fly around while
//! surfcache bakes its diffuse light in the background, and move an object to watch the
//! incremental re-bake arrive.
//!
//! ```sh
//! cargo run --release -p surfcache_bevy --example bevy_viewer                 # built-in Cornell box
//! cargo run --release -p surfcache_bevy --example bevy_viewer -- --scene sponza
//! cargo run --release -p surfcache_bevy --example bevy_viewer -- --scene cornell-suzanne
//! ```
//!
//! `sponza` and `cornell-suzanne` come from `../shared/assets` (`--assets DIR` says where
//! else); any `.gltf`/`.glb` path works too, lit by `--env FILE.exr`. Keys: W A S D, E Q
//! and the mouse fly the camera; Space moves the marked object 10 cm (and back).
//! `--screenshot FILE.png` captures the window once the first bake shows and exits.

use bevy::{
    asset::LoadState,
    camera::Exposure,
    camera::{
        primitives::Aabb,
        visibility::{InheritedVisibility, ViewVisibility, VisibilityClass},
    },
    camera_controller::free_camera::{FreeCamera, FreeCameraPlugin},
    core_pipeline::tonemapping::Tonemapping,
    gltf::{
        GltfAssetLabel, GltfExtras, GltfMaterialExtras, GltfMaterialName, GltfMeshExtras,
        GltfMeshName, GltfSceneExtras, GltfSceneName,
    },
    prelude::*,
    transform::components::TransformTreeChanged,
    window::WindowResolution,
};
use std::path::{Path, PathBuf};
use surfcache_bevy::{
    BakeEnvironment, BakeFinished, BakeStatus, SceneSpawner, SurfcacheBevyPlugin,
    environment::environment_image,
    view::{CaptureWhenBaked, capture_when_baked, ev100_for_exposure, matched_camera},
};
use surfcache_core::scenes;
use surfcache_ecs::{BakedLightmap, BakedSurfaceCache};

/// What to show, from the command line.
#[derive(Resource, Clone, Debug)]
struct Args {
    scene: String,
    assets: PathBuf,
    env: Option<PathBuf>,
    exposure: Option<f32>,
    screenshot: Option<PathBuf>,
    size: (u32, u32),
    /// A coarser bake (5 % bound, 4 texels per metre at most) for a quick look.
    quick: bool,
}

fn parse_args() -> Result<Args, String> {
    let mut args = Args {
        scene: "cornell".into(),
        assets: PathBuf::from("../shared/assets"),
        env: None,
        exposure: None,
        screenshot: None,
        size: (1280, 720),
        quick: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().ok_or(format!("{flag} needs a value"));
        match flag.as_str() {
            "--scene" => args.scene = value()?,
            "--assets" => args.assets = value()?.into(),
            "--env" => args.env = Some(value()?.into()),
            "--exposure" => {
                let v = value()?;
                args.exposure = Some(
                    v.parse::<f32>()
                        .ok()
                        .filter(|e| e.is_finite() && *e > 0.0)
                        .ok_or(format!("--exposure takes a positive number, not '{v}'"))?,
                );
            }
            "--screenshot" => args.screenshot = Some(value()?.into()),
            "--size" => {
                let v = value()?;
                args.size = v
                    .split_once('x')
                    .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
                    .filter(|&(w, h): &(u32, u32)| {
                        (64..=8192).contains(&w) && (64..=8192).contains(&h)
                    })
                    .ok_or(format!("--size takes WxH, not '{v}'"))?;
            }
            "--quick" => args.quick = true,
            other => return Err(format!("unknown option '{other}' (see the example's docs)")),
        }
    }
    Ok(args)
}

/// The scene chosen: where it comes from, where to look from, what Space moves.
struct Choice {
    /// A glTF file (else the built-in Cornell box).
    file: Option<PathBuf>,
    env: Option<PathBuf>,
    eye: Vec3,
    target: Vec3,
    /// Camera exposure (`None`: set from the first bake).
    exposure: Option<f32>,
    /// Name or glTF material name of the object Space moves.
    movable: &'static str,
    /// Emission scale (the Cornell box with Suzanne has an LDR lamp).
    emission: f32,
}

fn choose(args: &Args) -> Result<Choice, String> {
    let shared = |p: &str| args.assets.join(p);
    let mut choice = match args.scene.as_str() {
        "cornell" => {
            let (lo, hi) = scenes::cornell().bounds();
            let (eye, target) = surfcache_cli::camera::default_view(lo, hi, 40.0);
            Choice {
                file: None,
                env: None,
                eye: Vec3::from_array(eye.to_array()),
                target: Vec3::from_array(target.to_array()),
                exposure: Some(0.5),
                movable: "short_block",
                emission: 1.0,
            }
        }
        "sponza" => Choice {
            file: Some(shared("scenes/sponza_crytek/Sponza.gltf")),
            env: Some(shared("envmaps/immenstadter_horn_1k.exr")),
            eye: Vec3::new(-11.0, 1.7, -0.4),
            target: Vec3::new(5.0, 4.0, 0.4),
            // What `surfcache render` chooses for the path-traced courtyard from here; the
            // automatic exposure over all texels counts the sunlit roofs and leaves the
            // galleries nearly black.
            exposure: Some(39.0),
            movable: "vase_round",
            emission: 1.0,
        },
        "cornell-suzanne" => Choice {
            file: Some(shared("scenes/cornell_box_suzanne/cornell_box_suzanne.glb")),
            env: None,
            eye: Vec3::new(0.0, 0.0, 3.6),
            target: Vec3::ZERO,
            exposure: None,
            movable: "Suzanne",
            emission: 20.0,
        },
        path => Choice {
            file: Some(PathBuf::from(path)),
            env: None,
            eye: Vec3::new(0.0, 1.7, 5.0),
            target: Vec3::new(0.0, 1.0, 0.0),
            exposure: None,
            movable: "",
            emission: 1.0,
        },
    };
    if let Some(env) = &args.env {
        choice.env = Some(env.clone());
    }
    if args.exposure.is_some() {
        choice.exposure = args.exposure;
    }
    if let Some(file) = &choice.file
        && !file.is_file()
    {
        return Err(format!("no scene file at '{}'", file.display()));
    }
    Ok(choice)
}

fn main() -> std::process::ExitCode {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("error: {e}");
            return std::process::ExitCode::FAILURE;
        }
    };
    let choice = match choose(&args) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e}");
            return std::process::ExitCode::FAILURE;
        }
    };
    // The environment, read by surfcache's EXR loader into a Bevy image.
    let environment = match &choice.env {
        Some(path) => match surfcache_io::read_environment_map(path) {
            Ok((map, _)) => Some(map),
            Err(e) => {
                eprintln!("error: {e}");
                return std::process::ExitCode::FAILURE;
            }
        },
        None => None,
    };

    let mut plugin = SurfcacheBevyPlugin::default();
    if args.quick {
        plugin.config.settings.estimator.max_rel_error = 0.05;
        // The default method, lightmaps, at 4 texels per metre.
        if let Some(density) = plugin.config.settings.cache.density_mut() {
            *density = 4.0;
        }
        plugin.config.settings.density_budget = None;
    }
    // Bevy resolves a relative asset folder against the executable's: make it absolute.
    let asset_root = match &choice.file {
        Some(file) => file.parent().unwrap_or(Path::new(".")).to_path_buf(),
        None => PathBuf::from("."),
    };
    let asset_root = std::fs::canonicalize(&asset_root).unwrap_or(asset_root);
    let capture = CaptureWhenBaked::every(10);
    let picture = capture.picture.clone();
    let mut app = App::new();
    app.add_plugins((
        DefaultPlugins
            .set(WindowPlugin {
                primary_window: Some(Window {
                    title: format!("surfcache: {}", args.scene),
                    resolution: WindowResolution::new(args.size.0, args.size.1)
                        .with_scale_factor_override(1.0),
                    ..Default::default()
                }),
                ..Default::default()
            })
            .set(AssetPlugin {
                file_path: asset_root.to_string_lossy().into_owned(),
                ..Default::default()
            }),
        FreeCameraPlugin,
        plugin,
    ))
    .insert_resource(GlobalAmbientLight::NONE)
    .insert_resource(ClearColor(Color::srgb(0.05, 0.05, 0.07)))
    // Bevy spawns glTF scenes by reflection. Without Bevy's default features (this crate
    // builds only what it uses, not `reflect_auto_register`) the components a glTF scene
    // holds must be registered by hand.
    .register_type::<Name>()
    .register_type::<Transform>()
    .register_type::<GlobalTransform>()
    .register_type::<TransformTreeChanged>()
    .register_type::<Visibility>()
    .register_type::<InheritedVisibility>()
    .register_type::<ViewVisibility>()
    .register_type::<VisibilityClass>()
    .register_type::<ChildOf>()
    .register_type::<Children>()
    .register_type::<Mesh3d>()
    .register_type::<MeshMaterial3d<StandardMaterial>>()
    .register_type::<Aabb>()
    .register_type::<GltfMeshName>()
    .register_type::<GltfMaterialName>()
    .register_type::<GltfSceneName>()
    .register_type::<GltfExtras>()
    .register_type::<GltfMeshExtras>()
    .register_type::<GltfMaterialExtras>()
    .register_type::<GltfSceneExtras>()
    .insert_resource(Viewer {
        eye: choice.eye,
        target: choice.target,
        exposure: choice.exposure,
        movable: choice.movable,
        emission: choice.emission,
        file: choice.file.clone(),
        loading: None,
        environment,
        moved: false,
        last: None,
    })
    .add_systems(Startup, setup)
    .add_systems(
        Update,
        (
            scale_emission,
            move_object,
            show_progress,
            auto_exposure,
            stop_on_load_failure,
        ),
    );
    if args.screenshot.is_some() {
        app.insert_resource(capture)
            .add_systems(Update, capture_when_baked);
    }
    if app.run() != AppExit::Success {
        return std::process::ExitCode::FAILURE;
    }
    if let Some(path) = &args.screenshot {
        let Some(shot) = picture.lock().ok().and_then(|mut p| p.take()) else {
            eprintln!("error: the window closed before a screenshot settled");
            return std::process::ExitCode::FAILURE;
        };
        if let Err(e) = write_screenshot(path, &shot) {
            eprintln!("error: {}: {e}", path.display());
            return std::process::ExitCode::FAILURE;
        }
        eprintln!("wrote {}", path.display());
    }
    std::process::ExitCode::SUCCESS
}

/// The viewer's state.
#[derive(Resource)]
struct Viewer {
    eye: Vec3,
    target: Vec3,
    /// `None` until the first bake sets it.
    exposure: Option<f32>,
    movable: &'static str,
    emission: f32,
    file: Option<PathBuf>,
    /// The glTF scene being loaded.
    loading: Option<Handle<WorldAsset>>,
    environment: Option<surfcache_core::EnvironmentMap>,
    /// Whether the movable object is moved away from its place.
    moved: bool,
    /// The last bake: incremental or not, and its seconds.
    last: Option<(bool, f64)>,
}

/// The progress line on screen.
#[derive(Component)]
struct ProgressText;

fn setup(mut spawner: SceneSpawner, assets: Res<AssetServer>, mut viewer: ResMut<Viewer>) {
    match &viewer.file {
        None => {
            spawner.spawn(&scenes::cornell());
        }
        Some(file) => {
            let name = file
                .file_name()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned();
            let scene = assets.load(GltfAssetLabel::Scene(0).from_asset(name));
            viewer.loading = Some(scene.clone());
            spawner.commands.spawn(WorldAssetRoot(scene));
            if let Some(map) = &viewer.environment {
                spawner.commands.insert_resource(BakeEnvironment {
                    image: Some(spawner.images.add(environment_image(map))),
                    intensity: 1.0,
                });
            }
        }
    }
    spawner.commands.spawn((
        matched_camera(
            viewer.eye,
            viewer.target,
            40.0,
            viewer.exposure.unwrap_or(1.0),
            Tonemapping::AcesFitted,
        ),
        FreeCamera::default(),
    ));
    spawner.commands.spawn((
        Text::new("loading"),
        TextFont::from_font_size(18.0),
        Node {
            position_type: PositionType::Absolute,
            top: Val::Px(8.0),
            left: Val::Px(8.0),
            ..Default::default()
        },
        ProgressText,
    ));
}

/// Without `--exposure`: once the first bake is published, exposes the view as
/// `surfcache render` does by default (95th percentile to 0.8), taking the lightmaps'
/// radiance on a mid-grey surface (albedo 0.5) as the picture's.
fn auto_exposure(
    mut viewer: ResMut<Viewer>,
    baked: Res<BakedSurfaceCache>,
    lightmaps: Query<&BakedLightmap>,
    mut cameras: Query<&mut Exposure>,
) {
    if viewer.exposure.is_some() || baked.generation == 0 {
        return;
    }
    let radiance: Vec<glam::Vec3> = lightmaps
        .iter()
        .filter_map(|l| l.front.as_ref())
        .flat_map(|t| t.texels.iter().map(|e| *e * (0.5 / std::f32::consts::PI)))
        .collect();
    let exposure = surfcache_cli::picture::auto_exposure(&radiance);
    viewer.exposure = Some(exposure);
    for mut camera in &mut cameras {
        camera.ev100 = ev100_for_exposure(exposure);
    }
}

/// Ends the app with an error when the glTF scene cannot be loaded.
fn stop_on_load_failure(
    viewer: Res<Viewer>,
    assets: Res<AssetServer>,
    mut exit: MessageWriter<AppExit>,
) {
    if let Some(scene) = &viewer.loading
        && let LoadState::Failed(e) = assets.load_state(scene)
    {
        eprintln!("error: {e}");
        exit.write(AppExit::error());
    }
}

/// Scales loaded materials' emission (once each), for scenes with LDR lamps.
fn scale_emission(
    viewer: Res<Viewer>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut events: MessageReader<AssetEvent<StandardMaterial>>,
) {
    if viewer.emission == 1.0 {
        return;
    }
    for e in events.read() {
        if let AssetEvent::Added { id } = e
            && let Some(mut m) = materials.get_mut(*id)
        {
            m.emissive *= viewer.emission;
        }
    }
}

/// Space moves the marked object 10 cm along +X, and back.
fn move_object(
    keys: Res<ButtonInput<KeyCode>>,
    mut viewer: ResMut<Viewer>,
    mut objects: Query<(&mut Transform, Option<&Name>, Option<&GltfMaterialName>)>,
) {
    if !keys.just_pressed(KeyCode::Space) || viewer.movable.is_empty() {
        return;
    }
    let step = if viewer.moved { -0.1 } else { 0.1 };
    let mut any = false;
    for (mut transform, name, material) in &mut objects {
        let matches = name.is_some_and(|n| n.as_str() == viewer.movable)
            || material.is_some_and(|m| m.0 == viewer.movable);
        if matches {
            transform.translation.x += step;
            any = true;
        }
    }
    if any {
        viewer.moved = !viewer.moved;
    }
}

/// Bake progress and the last bake on screen.
fn show_progress(
    status: Res<BakeStatus>,
    mut viewer: ResMut<Viewer>,
    mut finished: MessageReader<BakeFinished>,
    mut text: Query<&mut Text, With<ProgressText>>,
) {
    if let Some(done) = finished.read().last() {
        viewer.last = Some((done.incremental, done.seconds));
    }
    let Ok(mut text) = text.single_mut() else {
        return;
    };
    let baking = if let Some(e) = &status.error {
        format!("bake failed: {e}")
    } else if status.running {
        let eta = status
            .time_left()
            .map(|t| format!(", {t}"))
            .unwrap_or_default();
        format!(
            "{} bake: {:.1} % done, {:.2} Mrays/s{eta}",
            if status.incremental {
                "incremental"
            } else {
                "full"
            },
            100.0 * status.fraction,
            status.rays_per_second / 1e6,
        )
    } else if viewer.last.is_some() {
        "baked: the lightmaps are up to date".into()
    } else {
        "waiting for the scene".into()
    };
    let last = match viewer.last {
        Some((true, s)) => format!("\nlast: incremental re-bake, {s:.1} s"),
        Some((false, s)) => format!("\nlast: bake from scratch, {s:.1} s"),
        None => String::new(),
    };
    let help = if viewer.movable.is_empty() {
        String::new()
    } else {
        format!("\nSpace: move {} 10 cm", viewer.movable)
    };
    let line = format!("{baking}{last}{help}\nW A S D E Q + mouse: fly");
    if text.0 != line {
        text.0 = line;
    }
}

/// A window screenshot as an 8-bit RGB PNG, written under a temporary name and renamed.
fn write_screenshot(path: &Path, shot: &Image) -> Result<(), String> {
    use bevy::render::render_resource::TextureFormat;
    let data = shot.data.as_ref().ok_or("the screenshot has no pixels")?;
    let bgra = matches!(
        shot.texture_descriptor.format,
        TextureFormat::Bgra8UnormSrgb | TextureFormat::Bgra8Unorm
    );
    let rgb: Vec<u8> = data
        .chunks_exact(4)
        .flat_map(|p| {
            if bgra {
                [p[2], p[1], p[0]]
            } else {
                [p[0], p[1], p[2]]
            }
        })
        .collect();
    let mut file = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut file, shot.width(), shot.height());
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(|e| e.to_string())?;
        writer.write_image_data(&rgb).map_err(|e| e.to_string())?;
    }
    surfcache_io::write_file_atomically(path, &file).map_err(|e| e.to_string())
}
