//! `surfcache points`: the sky view it reports for given points is the cosine-weighted
//! share of the sky a point sees, checked against the form factor of the Cornell box's
//! open front (Lambert's polygon formula).

mod common;

use common::{expect_success, polygon_irradiance, temp_dir};
use glam::Vec3;
use std::f32::consts::PI;
use std::process::Command;

const SURFCACHE: &str = env!("CARGO_BIN_EXE_surfcache");

/// Points near the open front of the built-in Cornell box (z = 0), where no block stands
/// between them and the opening: the sky view must be the opening's form factor
/// `F = E/(πL)` for a polygon of radiance L (the rest of the hemisphere meets walls).
#[test]
fn sky_view_is_the_form_factor_of_the_opening() {
    let (w, h) = (0.5528, 0.5488);
    let opening = [
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(w, 0.0, 0.0),
        Vec3::new(w, h, 0.0),
        Vec3::new(0.0, h, 0.0),
    ];
    let points = [
        (Vec3::new(0.276, h, 0.05), Vec3::NEG_Y), // ceiling, just inside the front
        (Vec3::new(0.1, 0.0, 0.03), Vec3::Y),     // floor, left front corner
        (Vec3::new(0.45, 0.0, 0.1), Vec3::Y),     // floor, right front
        (Vec3::new(0.0, 0.3, 0.1), Vec3::X),      // green wall
    ];
    let dir = temp_dir("sky_view");
    let input = dir.join("points.csv");
    let mut csv = String::from("x,y,z,nx,ny,nz\n");
    for (x, n) in points {
        csv += &format!("{},{},{},{},{},{}\n", x.x, x.y, x.z, n.x, n.y, n.z);
    }
    std::fs::write(&input, csv).unwrap();
    let output = dir.join("sky.csv");
    let run = Command::new(SURFCACHE)
        .args(["points", "cornell", "--sky-view"])
        .arg(&input)
        .arg("-o")
        .arg(&output)
        .output()
        .unwrap();
    expect_success(&run, "surfcache points --sky-view");
    let text = std::fs::read_to_string(&output).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("x,y,z,nx,ny,nz,sky"));
    let skies: Vec<f32> = lines
        .map(|l| l.rsplit(',').next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(skies.len(), points.len());
    for ((x, n), sky) in points.iter().zip(skies) {
        let expected = polygon_irradiance(*x, *n, &opening, 1.0) / PI;
        assert!(
            (sky - expected).abs() < 0.015,
            "sky view at {x}: {sky}, form factor of the opening {expected}"
        );
    }
}
