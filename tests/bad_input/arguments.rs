//! Command-line arguments: unknown scenes, missing files, bad CSVs, bake options of another method.

use crate::common::temp_dir;
use crate::{SURFCACHE, expect_clean_success, expect_error, points_csv, reference};
use std::path::Path;
use std::process::{Command, Output};

// --- command-line arguments -----------------------------------------------------------------

#[test]
fn unknown_builtin_scene() {
    let dir = temp_dir("unknown_builtin_scene");
    let points = points_csv(&dir);
    expect_error(
        &reference("cornel", &points, &[]),
        &["unknown built-in scene 'cornel'", "cornell"],
    );
}

#[test]
fn missing_files() {
    let dir = temp_dir("missing_files");
    let points = points_csv(&dir);
    let scene = dir.join("absent.gltf");
    expect_error(&reference(&scene, &points, &[]), &["absent.gltf"]);
    let scene = dir.join("absent.glb");
    expect_error(&reference(&scene, &points, &[]), &["absent.glb"]);
    let env = dir.join("absent.exr");
    expect_error(
        &reference("cornell", &points, &["--env", env.to_str().unwrap()]),
        &["absent.exr"],
    );
    expect_error(
        &reference("cornell", &dir.join("absent.csv"), &[]),
        &["points file", "absent.csv"],
    );
}

#[test]
fn points_csv_with_bad_header() {
    let dir = temp_dir("points_csv_with_bad_header");
    let path = dir.join("bad_header.csv");
    std::fs::write(&path, "x,y,z,r,g,b\n0.3,0,0.3,0,1,0\n").unwrap();
    expect_error(
        &reference("cornell", &path, &[]),
        &["bad_header.csv", "header must be 'x,y,z,nx,ny,nz'"],
    );
    // And a good file for contrast: the same row under the right header runs.
    expect_clean_success(&reference("cornell", &points_csv(&dir), &[]));
}

// --- bake options that do not apply to the chosen method ----------------------------------

/// `surfcache bake cornell ARGS… -o OUT`, with backtraces enabled.
fn bake(out: &Path, args: &[&str]) -> Output {
    Command::new(SURFCACHE)
        .args(["bake", "cornell"])
        .args(args)
        .arg("-o")
        .arg(out)
        .env("RUST_BACKTRACE", "1")
        .output()
        .expect("the surfcache binary runs")
}

/// An option of one method given with another is an error, not silently ignored
/// (docs/cli.md, `surfcache bake`), and nothing is written.
#[test]
fn bake_options_that_do_not_apply_to_the_method() {
    let dir = temp_dir("bake_options_that_do_not_apply_to_the_method");
    let out = dir.join("out");
    let density = "--density applies to --method irradiance-map and lightmap only";
    let interpolation = "--interpolation-error applies to --method irradiance-map only";
    let share = "--no-share-corners applies to --method irradiance-map only";
    let filter = "--filter-passes applies to --method lightmap and irradiance-map only";
    let guiding = "--no-guiding applies to --method lightmap and irradiance-map only";
    let cases: [(&[&str], &str); 8] = [
        (&["--method", "vertex", "--density", "8"], density),
        // Checked before the value: the option is wrong whatever its value.
        (&["--method", "vertex", "--density", "0"], density),
        (
            &["--method", "vertex", "--interpolation-error", "0.1"],
            interpolation,
        ),
        // The default method, lightmaps.
        (&["--interpolation-error", "0.1"], interpolation),
        (&["--method", "vertex", "--no-share-corners"], share),
        (&["--method", "lightmap", "--no-share-corners"], share),
        (&["--method", "vertex", "--filter-passes", "2"], filter),
        (&["--method", "vertex", "--no-guiding"], guiding),
    ];
    for (args, message) in cases {
        let line = expect_error(&bake(&out, args), &[message]);
        assert_eq!(line, format!("error: {message}"), "{args:?}");
        assert!(
            std::fs::read_dir(&dir).unwrap().next().is_none(),
            "{args:?} wrote into {}",
            dir.display()
        );
    }
}
