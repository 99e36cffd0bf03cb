//! Property-based fuzzing of the file loaders (issue "speed vs accuracy", robustness item).
//!
//! Valid files are mutated (byte flips, truncation, inserted and deleted chunks, numbers
//! swapped for huge, negative or NaN-ish values, JSON keys removed or added, GLB chunk
//! headers and EXR header attributes corrupted) and handed to `load_scene`/`load_gltf`,
//! `read_environment_map` and `read_rgb_exr`. Every case must:
//! - return `Ok` or `Err` and **never panic**, not even inside a third-party decoder where
//!   `no_panic` would catch it: a panic hook records every panic of the process, and the
//!   fuzz tests of this binary run one at a time (the loaders use rayon threads, so a
//!   thread-local record would miss panics on worker threads);
//! - on `Err`, give one printable line: no line breaks, terminal escapes or other control
//!   or invisible format characters, whatever the file's names hold;
//! - on `Ok`, return only finite data: positions (also in world space), normals, UVs,
//!   transforms, materials, textures and lights of a `Scene`, texels of a map.
//!
//! Seeds: `assets/cornell.gltf` + `cornell.bin` as they are, a "rich" variant built here
//! (node transforms, `KHR_lights_punctual`, emissive strength, alpha mask, PNG and JPEG
//! textures, a data-URI buffer, u8/u16 indices, normalized TEXCOORD_1, a sparse accessor,
//! strip and fan primitives), GLB packings of both, `assets/cornell_environment.exr`, an
//! EXR written by `write_rgb_exr` and EXRs of other compressions, sample types and tiles
//! written with the exr crate. `../shared/assets/scenes/cornell_box_suzanne/*.glb` is an
//! extra seed when it exists (skipped silently otherwise).
//!
//! Short run (part of `cargo test --workspace`, a few hundred cases per loader, fixed seed):
//!
//! ```text
//! cargo test --test fuzz_loaders
//! ```
//!
//! Long run (≥ 100,000 cases in total over all loaders, random seed, prints a summary):
//!
//! ```text
//! SURFCACHE_FUZZ_CASES=100000 cargo test --release --test fuzz_loaders long_run -- --ignored --nocapture
//! ```
//!
//! `SURFCACHE_FUZZ_CASES` is the total for the long run (default 100,000), split between
//! the loaders by weight; each loader's cases use the run's seed plus its weight.
//! `SURFCACHE_FUZZ_SEED=N` fixes the seed of either run, `SURFCACHE_FUZZ_TARGETS=exr,glb`
//! limits the long run to some loaders (with the cases they get in the full run). A failure
//! prints proptest's minimal failing input (it shrinks the mutation list) and the command
//! that runs the failing loader's cases again; such a case then becomes a fixed case here
//! (`exr_cases_that_failed_before`), since a short run's random cases need not come near it.

mod checking;
#[path = "../common/mod.rs"]
mod common;
mod exr;
mod gltf_seeds;
mod gltf_targets;
mod mutations;
mod panics;
mod running;

use common::temp_dir;
use exr::{HOSTILE_BYTES, check_exr, exr_seeds, fuzz_exr};
use gltf_targets::{fuzz_glb, fuzz_gltf_bin, fuzz_gltf_json};
use panics::{serial, take_panics};
use running::{Stats, seed};
use std::time::Instant;

// --- the tests --------------------------------------------------------------------------------

/// Fixed seed of the short runs, so `cargo test` is reproducible.
const SHORT_SEED: u64 = 0x5eed;

/// A short run of `target`: `cases` cases with [`SHORT_SEED`] or `SURFCACHE_FUZZ_SEED`.
fn short_run(test: &str, target: Target, cases: u32) {
    let seed = seed(Some(SHORT_SEED));
    let rerun = format!("SURFCACHE_FUZZ_SEED={seed} cargo test --test fuzz_loaders {test}");
    target(cases, seed, &rerun);
}

#[test]
fn gltf_json_mutations_never_panic() {
    short_run("gltf_json_mutations_never_panic", fuzz_gltf_json, 400);
}

#[test]
fn gltf_buffer_mutations_never_panic() {
    short_run("gltf_buffer_mutations_never_panic", fuzz_gltf_bin, 250);
}

#[test]
fn glb_mutations_never_panic() {
    short_run("glb_mutations_never_panic", fuzz_glb, 400);
}

#[test]
fn exr_mutations_never_panic() {
    short_run("exr_mutations_never_panic", fuzz_exr, 400);
}

/// Cases a long run once failed on, kept here as fixed cases (a short run's random ones need
/// not come near them again, and a change of the strategies changes what a seed generates):
///
/// - `SURFCACHE_FUZZ_SEED=1796197522859263124`, EXR target (case seed …127), minimal input:
///   seed 2, the channel list's first byte flipped by 0x48, so channel `B` is named `\n`;
///   the error `EXR '…' has no R, G, B channels (found: \n, G, R)` broke over two lines.
///
/// The same edit with every byte of [`HOSTILE_BYTES`] and on every EXR seed, read as a
/// texture and as an environment map.
#[test]
fn exr_cases_that_failed_before() {
    let seeds = exr_seeds();
    let _serial = serial();
    let dir = temp_dir("exr_fixed");
    take_panics();
    for (k, s) in seeds.iter().enumerate() {
        let channels = s
            .layout
            .attributes
            .iter()
            .find(|a| &s.bytes[a.type_name.0..a.type_name.1] == b"chlist")
            .expect("every EXR has a channel list");
        let first = channels.value.0;
        let mut edits: Vec<u8> = HOSTILE_BYTES.iter().map(|b| b ^ s.bytes[first]).collect();
        edits.push(0x48);
        for xor in edits {
            let mut bytes = s.bytes.clone();
            bytes[first] ^= xor;
            for environment in [false, true] {
                let case = format!(
                    "seed {k}, byte {:#04x}, environment {environment}",
                    bytes[first]
                );
                let (_, outcome) =
                    check_exr(&dir, &bytes, environment).unwrap_or_else(|e| panic!("{case}: {e}"));
                let panics = take_panics();
                assert!(panics.is_empty(), "{case}: panicked: {panics:?}");
                if (k, xor) == (2, 0x48) {
                    let e = outcome.expect_err("channel B is gone");
                    assert!(
                        e.ends_with(r"has no R, G, B channels (found: \n, G, R)"),
                        "{e}"
                    );
                }
            }
        }
    }
}

/// A fuzz target: (cases, case seed, command to run it again) → what the loader returned.
type Target = fn(u32, u64, &str) -> Stats;

/// The long run's targets: name (for `SURFCACHE_FUZZ_TARGETS`), weight (its share of the
/// cases in tenths, and what is added to the run's seed for its own), function.
const TARGETS: [(&str, u64, Target); 4] = [
    ("gltf_json", 3, fuzz_gltf_json),
    ("gltf_bin", 2, fuzz_gltf_bin),
    ("glb", 2, fuzz_glb),
    ("exr", 3, fuzz_exr),
];

/// The long run: `SURFCACHE_FUZZ_CASES` cases in total (default 100,000), random seed;
/// `SURFCACHE_FUZZ_TARGETS=exr,glb` runs only those targets (with the cases they would get
/// in the full run, so a seed's failure comes again).
#[test]
#[ignore = "long fuzzing run; see the module docs"]
fn long_run() {
    let total: u64 = std::env::var("SURFCACHE_FUZZ_CASES")
        .ok()
        .map(|s| {
            s.trim()
                .parse()
                .expect("SURFCACHE_FUZZ_CASES must be a number")
        })
        .unwrap_or(100_000);
    let only: Option<Vec<String>> = std::env::var("SURFCACHE_FUZZ_TARGETS")
        .ok()
        .map(|s| s.split(',').map(|t| t.trim().to_string()).collect());
    if let Some(only) = &only {
        for t in only {
            assert!(
                TARGETS.iter().any(|(name, _, _)| name == t),
                "unknown fuzz target '{t}' in SURFCACHE_FUZZ_TARGETS (known: gltf_json, gltf_bin, glb, exr)"
            );
        }
    }
    let seed = seed(None);
    println!("long run: {total} cases, SURFCACHE_FUZZ_SEED={seed}");
    let share = |weight: u64| (total * weight).div_ceil(10) as u32;
    let started = Instant::now();
    let mut done = 0u64;
    // Every target runs even when an earlier one fails (each stops at its first failure).
    let mut failures = Vec::new();
    for (name, weight, target) in TARGETS {
        if only.as_ref().is_some_and(|o| !o.iter().any(|t| t == name)) {
            continue;
        }
        let cases = share(weight);
        let rerun = format!(
            "SURFCACHE_FUZZ_SEED={seed} SURFCACHE_FUZZ_CASES={total} SURFCACHE_FUZZ_TARGETS={name} \
             cargo test --release --test fuzz_loaders long_run -- --ignored --nocapture"
        );
        match std::panic::catch_unwind(|| target(cases, seed.wrapping_add(weight), &rerun)) {
            Ok(_) => done += cases as u64,
            Err(payload) => failures.push(
                payload
                    .downcast_ref::<String>()
                    .cloned()
                    .unwrap_or_else(|| "(no message)".into()),
            ),
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
    println!(
        "long run: {done} cases in {:.1} s, no panic, no non-finite data",
        started.elapsed().as_secs_f64()
    );
}
