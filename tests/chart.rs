//! `surfcache chart` on a tiny sweep: one method, one sampler, one loose bound, the
//! Cornell box, a few reference points. Checks the outputs' form and that every figure is
//! finite and positive (never how fast anything is).

use std::{path::Path, process::Command};

const SURFCACHE: &str = env!("CARGO_BIN_EXE_surfcache");
const ASSETS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/assets");

#[test]
fn tiny_sweep_writes_csv_charts_and_summary() {
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("chart/tiny");
    let _ = std::fs::remove_dir_all(&out);
    let missing = Path::new(env!("CARGO_TARGET_TMPDIR")).join("chart/no_shared_assets");
    let run = Command::new(SURFCACHE)
        .args(["chart", "--scenes", "cornell,sponza", "--methods", "vertex"])
        .args(["--samplers", "best", "--bounds", "0.2", "--points", "40"])
        .args(["--threads", "2", "--assets", ASSETS, "--out"])
        .arg(&out)
        .arg("--shared-assets")
        .arg(&missing)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "chart failed: {stderr}");
    assert!(
        stderr.contains("skipping sponza"),
        "no message about the missing shared assets: {stderr}"
    );

    let csv = std::fs::read_to_string(out.join("speed_accuracy.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("scene,method,sampler,bound,seconds,rel_rms,bytes,sample_points,median_rel,p90_rel")
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 1, "{csv}");
    let row = &rows[0];
    assert_eq!(&row[..4], ["cornell", "vertex", "best", "0.2"]);
    for (name, value) in [
        "seconds",
        "rel_rms",
        "bytes",
        "sample_points",
        "median_rel",
        "p90_rel",
    ]
    .iter()
    .zip(&row[4..])
    {
        let v: f64 = value
            .parse()
            .unwrap_or_else(|_| panic!("{name} '{value}' is not a number"));
        assert!(v.is_finite() && v > 0.0, "{name} = {v}");
    }
    assert!(
        row[6].parse::<u64>().is_ok() && row[7].parse::<u64>().is_ok(),
        "bytes and sample points are whole numbers: {row:?}"
    );

    for png in ["speed_accuracy_seconds.png", "speed_accuracy_bytes.png"] {
        let bytes = std::fs::read(out.join(png)).unwrap();
        assert!(
            bytes.starts_with(b"\x89PNG\r\n\x1a\n"),
            "{png} is not a PNG"
        );
        let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        let reader = decoder.read_info().unwrap();
        let info = reader.info();
        assert!(info.width > 100 && info.height > 100, "{png}");
    }
    let summary = std::fs::read_to_string(out.join("speed_accuracy.md")).unwrap();
    assert!(
        summary.contains("| cornell | vertex | best | 0.2 |"),
        "{summary}"
    );

    // Redrawing from the CSV alone keeps it as it is.
    replot(&out);
    assert_eq!(
        std::fs::read_to_string(out.join("speed_accuracy.csv")).unwrap(),
        csv
    );
}

#[test]
fn replot_reads_csvs_written_before_the_median_was_kept() {
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("chart/old_csv");
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(
        out.join("speed_accuracy.csv"),
        "scene,method,sampler,bound,seconds,rel_rms,bytes,sample_points\n\
         cornell,lightmap,best,0.05,2.000,0.030000,1000,100\n\
         cornell,lightmap,best,0.01,8.000,0.010000,1000,100\n\
         cornell,vertex,best,0.01,0.000,,,\n",
    )
    .unwrap();
    replot(&out);
    let csv = std::fs::read_to_string(out.join("speed_accuracy.csv")).unwrap();
    assert_eq!(
        csv,
        "scene,method,sampler,bound,seconds,rel_rms,bytes,sample_points,median_rel,p90_rel\n\
         cornell,lightmap,best,0.05,2.000,0.030000,1000,100,,\n\
         cornell,lightmap,best,0.01,8.000,0.010000,1000,100,,\n\
         cornell,vertex,best,0.01,0.000,,,,,\n"
    );
    let summary = std::fs::read_to_string(out.join("speed_accuracy.md")).unwrap();
    assert!(summary.contains("| 1.00 % | – | – |"), "{summary}");
}

/// `surfcache chart --replot --out OUT`, which must succeed.
fn replot(out: &Path) {
    let run = Command::new(SURFCACHE)
        .args(["chart", "--replot", "--out"])
        .arg(out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
}
