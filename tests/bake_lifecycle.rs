//! `surfcache bake` as a process others kill and log (issue #18).
//!
//! - Killed outright (SIGKILL) in the middle of a bake, it leaves the earlier output whole —
//!   `query` reads it as before — and only its staging directory `.OUT.partial-PID`, which
//!   the next bake of the same output removes: after it, nothing but the output is left.
//! - The staging directory of a bake still running is never removed by another bake, while
//!   one named after a live process that holds no lock on it (a PID reused since its bake
//!   was killed) and one of a PID no process has are.
//! - A bake killed between the two renames of its commit has moved the earlier output
//!   aside; the next bake of the output puts it back, even one that then fails.
//! - With stderr not a terminal (a pipe here, a log in practice), a bake prints plain
//!   progress lines (pass, share done, rays per second, time left) and no bar.

mod common;

use common::{CORNELL_FAST, expect_success, temp_dir};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

const SURFCACHE: &str = env!("CARGO_BIN_EXE_surfcache");

/// A Cornell bake that runs far longer than a test waits (it is killed).
const SLOW: [&str; 6] = [
    "--max-rel-error",
    "0.001",
    "--min-samples",
    "4096",
    "--threads",
    "1",
];

fn bake_command(out: &Path, options: &[&str]) -> Command {
    let mut command = Command::new(SURFCACHE);
    command
        .args(["bake", "cornell", "--seed", "3"])
        .args(options)
        .arg("-o")
        .arg(out);
    command
}

fn fast_bake(out: &Path) {
    let run = bake_command(out, &CORNELL_FAST).output().unwrap();
    expect_success(&run, "bake");
}

/// Starts a slow bake printing a progress line every frame and returns once it has printed
/// one: its staging directory exists and it is baking.
fn start_slow_bake(out: &Path) -> Child {
    let mut child = bake_command(out, &SLOW)
        .env("SURFCACHE_PROGRESS_SECONDS", "0")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = child.stderr.take().unwrap();
    let mut lines = BufReader::new(stderr).lines();
    loop {
        match lines.next() {
            Some(Ok(line)) if line.starts_with("bake: pass ") => break,
            Some(Ok(_)) => {}
            _ => {
                let status = child.wait();
                panic!("the slow bake ended before baking: {status:?}");
            }
        }
    }
    // Keep reading so that the bake never blocks on a full pipe.
    std::thread::spawn(move || for _ in lines {});
    child
}

/// SIGKILL: no handler, no destructor runs.
fn kill(mut child: Child) {
    use std::os::unix::process::ExitStatusExt;
    child.kill().unwrap();
    let status = child.wait().unwrap();
    assert_eq!(status.signal(), Some(9), "{status:?}");
}

/// Names in `dir` that start with `.NAME.partial-` for output `NAME`, sorted.
fn staging_dirs(dir: &Path, name: &str) -> Vec<String> {
    let prefix = format!(".{name}.partial-");
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(&prefix))
        .collect();
    names.sort();
    names
}

/// What a bake wrote to `out`: its files (path → bytes), sorted.
fn output(out: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(out.join("lightmaps"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    paths.extend(["report.json", "cache.bin", "scene.gltf"].map(|f| out.join(f)));
    paths.sort();
    paths
        .into_iter()
        .map(|p| {
            let bytes = std::fs::read(&p).unwrap();
            (p, bytes)
        })
        .collect()
}

/// `surfcache query OUT POINTS` succeeds; returns its stdout.
fn query(out: &Path, points: &Path) -> String {
    let run = Command::new(SURFCACHE)
        .arg("query")
        .arg(out)
        .arg(points)
        .output()
        .unwrap();
    expect_success(&run, "query");
    let stdout = String::from_utf8(run.stdout).unwrap();
    assert_eq!(stdout.lines().count(), 3, "{stdout}");
    stdout
}

fn points_csv(dir: &Path) -> PathBuf {
    let path = dir.join("points.csv");
    std::fs::write(
        &path,
        "x,y,z,nx,ny,nz\n0.3,0,0.3,0,1,0\n0.2,0.3,0.55,0,0,-1\n",
    )
    .unwrap();
    path
}

/// A test's directory holding a finished bake `out` and `points.csv`.
struct Earlier {
    dir: PathBuf,
    points: PathBuf,
    out: PathBuf,
    /// Its files and what `query` answered at the points.
    files: Vec<(PathBuf, Vec<u8>)>,
    answers: String,
}

fn earlier_bake(test: &str) -> Earlier {
    let dir = temp_dir(test);
    let points = points_csv(&dir);
    let out = dir.join("out");
    fast_bake(&out);
    Earlier {
        files: output(&out),
        answers: query(&out, &points),
        dir,
        points,
        out,
    }
}

#[test]
fn killed_bake_keeps_the_output_and_the_next_bake_cleans_up() {
    let earlier = earlier_bake("killed");
    let (dir, points, out) = (&earlier.dir, &earlier.points, &earlier.out);

    let child = start_slow_bake(out);
    let pid = child.id();
    kill(child);
    // What the kill left: the staging directory beside the untouched output.
    assert_eq!(staging_dirs(dir, "out"), [format!(".out.partial-{pid}")]);
    assert!(output(out) == earlier.files, "the earlier output changed");
    assert_eq!(query(out, points), earlier.answers);

    fast_bake(out);
    assert_eq!(staging_dirs(dir, "out"), Vec::<String>::new());
    let entries: Vec<_> = std::fs::read_dir(dir).unwrap().collect();
    assert_eq!(entries.len(), 2, "{entries:?}");
    // Same seed, same settings: the same bake as before.
    assert_eq!(query(out, points), earlier.answers);
}

#[test]
fn running_bakes_keep_their_staging_directory() {
    let dir = temp_dir("running");
    let points = points_csv(&dir);
    let out = dir.join("out");
    let running = start_slow_bake(&out);
    let running_dir = format!(".out.partial-{}", running.id());
    // Left by killed bakes: one whose PID is now this test's (alive, but holding no lock on
    // it), one whose PID no process has (above Linux's largest, 2^22).
    let reused = format!(".out.partial-{}", std::process::id());
    let gone = ".out.partial-99999999".to_string();
    for name in [&reused, &gone] {
        std::fs::create_dir_all(dir.join(name).join("lightmaps")).unwrap();
        std::fs::write(dir.join(name).join("report.json"), "{}").unwrap();
    }
    // Not staging directories of `out`.
    let others = [".outer.partial-1", ".out.partial-12x", ".out.partial-"];
    for name in others {
        std::fs::create_dir(dir.join(name)).unwrap();
    }

    fast_bake(&out);
    query(&out, &points);
    assert_eq!(staging_dirs(&dir, "out"), {
        let mut left = vec![
            running_dir.clone(),
            others[1].to_string(),
            others[2].to_string(),
        ];
        left.sort();
        left
    });
    assert!(dir.join(others[0]).is_dir());

    kill(running);
    fast_bake(&out);
    assert_eq!(
        staging_dirs(&dir, "out"),
        [".out.partial-", ".out.partial-12x"]
    );
}

#[test]
fn output_moved_aside_by_a_killed_commit_is_put_back() {
    let earlier = earlier_bake("moved_aside");
    let (dir, points, out) = (&earlier.dir, &earlier.points, &earlier.out);
    // A bake killed between its commit's two renames: the earlier output moved aside, its
    // own finished staging directory not yet in place.
    let pid = 99999999;
    std::fs::rename(out, dir.join(format!(".out.partial-{pid}.old"))).unwrap();
    std::fs::create_dir_all(dir.join(format!(".out.partial-{pid}")).join("lightmaps")).unwrap();

    // A bake that fails (its scene does not exist) after preparing the output.
    let run = Command::new(SURFCACHE)
        .args(["bake", "missing.gltf", "-o"])
        .arg(out)
        .output()
        .unwrap();
    assert!(!run.status.success());
    assert!(
        output(out) == earlier.files,
        "the earlier output was not put back"
    );
    assert_eq!(query(out, points), earlier.answers);
    assert_eq!(staging_dirs(dir, "out"), Vec::<String>::new());
}

#[test]
fn piped_bake_prints_progress_lines() {
    let dir = temp_dir("progress");
    let out = dir.join("out");
    let run = bake_command(&out, &CORNELL_FAST)
        .env("SURFCACHE_PROGRESS_SECONDS", "0.05")
        .output()
        .unwrap();
    expect_success(&run, "bake");
    let stderr = String::from_utf8(run.stderr).unwrap();
    assert!(
        !stderr.contains('\r') && !stderr.contains('\u{1b}'),
        "a bar was drawn: {stderr:?}"
    );
    let progress: Vec<&str> = stderr
        .lines()
        .filter(|l| l.starts_with("bake: pass "))
        .collect();
    assert!(!progress.is_empty(), "no progress line: {stderr}");
    for line in &progress {
        // bake: pass P/N, round K, F % done, R Mrays/s[, about|at least T s left] (S s so far)
        let rest = line.strip_prefix("bake: pass ").unwrap();
        let (pass, rest) = rest.split_once(", ").unwrap();
        let (p, n) = pass.split_once('/').unwrap();
        let (p, n): (u32, u32) = (p.parse().unwrap(), n.parse().unwrap());
        assert!(1 <= p && p <= n, "{line}");
        let (round, rest) = rest.split_once(", ").unwrap();
        let round: u32 = round.strip_prefix("round ").unwrap().parse().unwrap();
        assert!(round >= 1, "{line}");
        let (fraction, rest) = rest.split_once(" % done, ").unwrap();
        let fraction: f64 = fraction.parse().unwrap();
        assert!((0.0..=100.0).contains(&fraction), "{line}");
        let (rays, _) = rest.split_once(" Mrays/s").unwrap();
        assert!(rays.parse::<f64>().unwrap() >= 0.0, "{line}");
        assert!(line.ends_with(" s so far)"), "{line}");
    }
    let last = stderr.lines().last().unwrap();
    assert!(last.starts_with("baked cornell"), "{stderr}");
}
