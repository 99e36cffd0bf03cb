//! Loads the shared test assets (`../shared/assets`, described in its README.md) when they
//! are present beside the repository: every scene and object glTF/GLB with the triangle
//! count the README documents, and every environment map at 1024×512.
//!
//! Without the folder each test prints that it is skipped and passes.

use std::path::{Path, PathBuf};
use surfcache::core::{
    environment::uv_to_direction,
    glam::{Vec2, Vec3},
};

/// The shared assets folder, or `None` (with a note) when it is not there.
fn assets(test: &str) -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/assets");
    if dir.is_dir() {
        Some(dir)
    } else {
        println!("{test}: skipped, {} does not exist", dir.display());
        None
    }
}

/// Loads a glTF/GLB and checks it against the README's triangle count: every primitive is a
/// triangle list, and the triangles kept plus those dropped as degenerate are all of them.
fn check_model(path: &Path, expected_triangles: usize) -> surfcache::io::LoadedScene {
    let loaded = surfcache::io::load_gltf(path)
        .unwrap_or_else(|e| panic!("{} does not load: {e}", path.display()));
    let report = &loaded.report;
    assert_eq!(
        report.skipped_primitives,
        0,
        "{}: the README says every primitive is mode 4",
        path.display()
    );
    assert_eq!(
        loaded.scene.triangle_count() + report.degenerate_triangles,
        expected_triangles,
        "{}: {} triangles kept + {} degenerate",
        path.display(),
        loaded.scene.triangle_count(),
        report.degenerate_triangles
    );
    loaded
}

#[test]
fn sponza() {
    let Some(dir) = assets("sponza") else { return };
    let path = dir.join("scenes/sponza_crytek/Sponza.gltf");
    let scene = check_model(&path, 262_267).scene;
    // The README's world bounding box, x −15.37…14.40, y −1.01…11.44, z −9.46…8.84 m.
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    let mut textured = 0;
    for inst in &scene.instances {
        for &p in &inst.mesh.positions {
            let w = inst.transform.transform_point3(p);
            lo = lo.min(w);
            hi = hi.max(w);
        }
        textured += inst.material.albedo_texture.is_some() as usize;
    }
    let lo_doc = Vec3::new(-15.37, -1.01, -9.46);
    let hi_doc = Vec3::new(14.40, 11.44, 8.84);
    assert!(
        (lo - lo_doc).abs().max_element() < 0.01 && (hi - hi_doc).abs().max_element() < 0.01,
        "bounds {lo}..{hi}"
    );
    // 25 primitives, all but Material__47 with a base colour texture.
    assert_eq!(scene.instances.len(), 25);
    assert_eq!(textured, 24);
}

#[test]
fn cornell_box_suzanne() {
    let Some(dir) = assets("cornell_box_suzanne") else {
        return;
    };
    check_model(
        &dir.join("scenes/cornell_box_suzanne/cornell_box_suzanne.glb"),
        1_040,
    );
}

/// The objects the README lists, by file stem.
const OBJECTS: &[(&str, usize)] = &[
    ("stanford_bunny", 69_451),
    ("suzanne", 15_744),
    ("DamagedHelmet", 15_452),
];

#[test]
fn every_object() {
    let Some(dir) = assets("every_object") else {
        return;
    };
    let mut files = Vec::new();
    let mut stack = vec![dir.join("objects")];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            let ext = path
                .extension()
                .map(|e| e.to_ascii_lowercase())
                .unwrap_or_default();
            if path.is_dir() {
                stack.push(path);
            } else if ext == "gltf" || ext == "glb" {
                files.push(path);
            }
        }
    }
    files.sort();
    let mut seen = Vec::new();
    for path in &files {
        let stem = path.file_stem().unwrap().to_string_lossy().into_owned();
        match OBJECTS.iter().find(|(name, _)| *name == stem) {
            Some(&(name, triangles)) => {
                check_model(path, triangles);
                seen.push(name);
            }
            // Not in the README's table: it must load and have triangles.
            None => {
                let loaded = surfcache::io::load_gltf(path)
                    .unwrap_or_else(|e| panic!("{} does not load: {e}", path.display()));
                assert!(loaded.scene.triangle_count() > 0, "{}", path.display());
            }
        }
    }
    for (name, _) in OBJECTS {
        assert!(seen.contains(name), "{name} is missing from objects/");
    }
}

/// The README's elevation of each map's brightest (Rec. 709 luminance) pixel, in degrees.
const PEAK_ELEVATION: &[(&str, f32)] = &[
    ("immenstadter_horn_1k", 35.3),
    ("venice_sunset_1k", 3.3),
    ("st_fagans_interior_1k", 28.3),
    ("empty_warehouse_01_1k", 50.1),
];

#[test]
fn every_environment_map() {
    let Some(dir) = assets("every_environment_map") else {
        return;
    };
    let mut maps: Vec<PathBuf> = std::fs::read_dir(dir.join("envmaps"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr")))
        .collect();
    maps.sort();
    assert_eq!(maps.len(), PEAK_ELEVATION.len(), "{maps:?}");
    for path in &maps {
        let (map, warnings) = surfcache::io::read_environment_map(path)
            .unwrap_or_else(|e| panic!("{} does not load: {e}", path.display()));
        assert!(warnings.is_empty(), "{}: {warnings:?}", path.display());
        assert_eq!((map.width, map.height), (1024, 512), "{}", path.display());
        assert!(
            map.texels
                .iter()
                .all(|t| t.is_finite() && t.min_element() >= 0.0)
        );
        // Row 0 is the zenith: the brightest pixel sits at the documented elevation.
        let stem = path.file_stem().unwrap().to_string_lossy();
        let &(_, elevation) = PEAK_ELEVATION
            .iter()
            .find(|(name, _)| *name == stem)
            .unwrap_or_else(|| panic!("{stem} is not in the README"));
        let lum = |k: usize| {
            let t = map.texels[k];
            0.2126 * t.x + 0.7152 * t.y + 0.0722 * t.z
        };
        let k = (0..map.texels.len())
            .max_by(|&a, &b| lum(a).total_cmp(&lum(b)))
            .unwrap();
        let (i, j) = (k as u32 % map.width, k as u32 / map.width);
        let d = uv_to_direction(Vec2::new(
            (i as f32 + 0.5) / map.width as f32,
            (j as f32 + 0.5) / map.height as f32,
        ));
        let got = d.y.asin().to_degrees();
        assert!(
            (got - elevation).abs() < 0.5,
            "{stem}: brightest pixel ({i}, {j}) at elevation {got}°, README says {elevation}°"
        );
    }
}
