//! Editing a level: after one change, how long until the lightmaps are right again?
//!
//! Bakes Crytek Sponza (from `../shared/assets`, under the sunny sky of its reference) at
//! `surfcache bake`'s defaults. Then it makes one edit at a time to that bake and
//! re-bakes incrementally:
//! - `vase_moved`: one round vase moved by 1 m;
//! - `vase_removed`: that vase taken out;
//! - `vase_added`: a copy of it put down 2 m away;
//! - `curtain_recoloured`: one curtain's fabric turned green;
//! - `vase_dragged`: the vase moved by 1 m in 10 steps of 10 cm as a drag makes them,
//!   each step superseding the re-bake of the one before after one batch of 65,536
//!   points, as the plugin does: a re-bake always starts from the last finished bake,
//!   so only the last position is re-baked to completion;
//! - `vase_dragged_slow` (not in the default list): the same 10 steps, each re-baked to
//!   completion from the one before.
//!
//! Each re-bake is compared with a bake of the edited scene from scratch. The noise floor
//! is two from-scratch bakes of the unedited scene with seeds 0 and 1, compared the same
//! way. The measure is the median per-point relative difference at 2,000 random points
//! in open air (`surfcache compare`'s per-point error): over the whole level (`err`,
//! `noise_floor`), and within 3 radii of the edited object (`err_near`, `noise_near`),
//! where an edit's error would hide in the level-wide median. `touched` is the share of
//! published texels the re-bake changed. Times leave out building the BVH of the edited
//! scene, which a game does on its own worker.
//!
//! ```text
//! cargo run --release --example level_edits [-- --edits vase_moved,curtain_recoloured]
//!     [--method lightmap|irradiance-map|vertex] [--density D] [--no-noise-floor]
//! ```
//!
//! One line per edit as it is measured, and at the end, after the noise floor's bake,
//! `edit=NAME full_s=F incremental_s=I ratio=R touched=T err=E noise_floor=N err_near=E' noise_near=N'`.

#[path = "shared/sponza.rs"]
mod sponza;

use std::{collections::BTreeSet, sync::Arc, time::Instant};
use surfcache::{
    cache::{
        Cache, CacheSettings, Method, SurfaceCache,
        bake::{BakeJob, BakeOutcome, BakeSettings},
        incremental::{Edit, IncrementalJob},
    },
    core::{
        Material, Scene,
        glam::{Affine3A, Vec3},
    },
    trace::TracedScene,
};

const VASE: &str = "vase_round_piece";
const CURTAIN: &str = "fabric_a_piece";
const POINTS: usize = 2000;

/// A bake from scratch and its seconds.
fn bake(scene: &TracedScene, settings: BakeSettings) -> (BakeOutcome, f64) {
    let start = Instant::now();
    let mut job = BakeJob::new(settings);
    while !job.step(scene, 1 << 16) {}
    let outcome = job.into_outcome().expect("a finished bake");
    (outcome, start.elapsed().as_secs_f64())
}

/// One scene of the level: the scene and its traced form.
struct Level {
    scene: Scene,
    traced: Arc<TracedScene>,
}

impl Level {
    fn new(scene: Scene) -> Self {
        let traced = Arc::new(TracedScene::new(&scene).expect("a valid scene"));
        Self { scene, traced }
    }

    fn index(&self, name: &str) -> usize {
        self.scene
            .instances
            .iter()
            .position(|i| i.name == name)
            .unwrap_or_else(|| panic!("no instance {name}"))
    }
}

/// An edit of `before` into `after`: instances correspond by name; `changed` names the
/// instances the edit moved, added, removed or re-coloured.
fn edit_between(before: &Level, after: &Level, changed: &BTreeSet<String>) -> Edit {
    let names = |level: &Level| level.traced.instance_names().to_vec();
    let (old_names, new_names) = (names(before), names(after));
    let instance_map: Vec<Option<u32>> = new_names
        .iter()
        .map(|n| old_names.iter().position(|o| o == n).map(|k| k as u32))
        .collect();
    Edit::between(
        &before.traced,
        &after.traced,
        &instance_map,
        |k| changed.contains(&old_names[k]),
        |k| changed.contains(&new_names[k]),
    )
    .expect("an edit that changes some triangles")
}

/// Points a re-bake estimates per step (a batch).
const BATCH: usize = 1 << 16;

/// Re-bakes `before_bake` (of `before`) for `after`: to completion, or superseded
/// after one batch (`superseded`, no outcome); the outcome and its seconds.
fn rebake(
    before: &Level,
    before_bake: &BakeOutcome,
    after: &Level,
    changed: &[&str],
    superseded: bool,
) -> (Option<BakeOutcome>, f64) {
    let changed = changed.iter().map(|s| s.to_string()).collect();
    let edit = edit_between(before, after, &changed);
    let start = Instant::now();
    let mut job = IncrementalJob::new(before_bake.clone(), before.traced.clone(), edit);
    let finished = job.step(&after.traced, BATCH);
    if !superseded && !finished {
        while !job.step(&after.traced, BATCH) {}
    }
    let outcome = (!superseded).then(|| job.into_outcome().expect("a finished re-bake"));
    (outcome, start.elapsed().as_secs_f64())
}

/// Share of the published texels of `after` that differ from `before`'s texture of the
/// same instance (all of an instance that is new or laid out anew).
fn touched(before: &(Level, Arc<Cache>), after: &(Level, Arc<Cache>)) -> f64 {
    let old = before.1.publish(&before.0.traced);
    let new = after.1.publish(&after.0.traced);
    let (mut changed, mut total) = (0usize, 0usize);
    for t in &new {
        total += t.texels.len();
        let name = &after.0.traced.instance_names()[t.instance as usize];
        let same = old.iter().find(|o| {
            &before.0.traced.instance_names()[o.instance as usize] == name
                && o.front == t.front
                && (o.width, o.height) == (t.width, t.height)
        });
        changed += match same {
            Some(o) => o
                .texels
                .iter()
                .zip(&t.texels)
                .filter(|(a, b)| a != b)
                .count(),
            None => t.texels.len(),
        };
    }
    changed as f64 / total.max(1) as f64
}

fn arg<'a>(args: &'a [String], name: &str) -> Option<&'a str> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .map(String::as_str)
}

fn moved(scene: &Scene, name: &str, by: Vec3) -> Scene {
    let mut s = scene.clone();
    for i in &mut s.instances {
        if i.name == name {
            i.transform = Affine3A::from_translation(by) * i.transform;
        }
    }
    s
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let method = arg(&args, "--method")
        .map(|m| Method::from_name(m).expect("method: vertex, irradiance-map or lightmap"))
        .unwrap_or_default();
    let mut settings = BakeSettings {
        cache: CacheSettings::for_method(method),
        ..Default::default()
    };
    // A coarser density for a quicker look (the defaults' is the one to report).
    if let (Some(d), Some(density)) = (arg(&args, "--density"), settings.cache.density_mut()) {
        *density = d
            .parse()
            .expect("--density: texels (or grid points) per metre");
    }
    let all = "vase_moved,vase_removed,vase_added,curtain_recoloured,vase_dragged";
    let wanted: Vec<&str> = arg(&args, "--edits").unwrap_or(all).split(',').collect();

    let base = Level::new(sponza::sponza(&["vase_round", "fabric_a"]));
    let (base_bake, base_s) = bake(&base.traced, settings);
    println!("base bake: {base_s:.1} s");
    let base_pair = (base, base_bake.cache().clone());
    // Per edit: the line without the noise floor, and the neighbourhood compared.
    let mut lines: Vec<(String, (Vec3, f32))> = Vec::new();
    let mut scratch_bakes: std::collections::HashMap<&str, (BakeOutcome, f64)> = Default::default();

    for name in wanted {
        let scene = &base_pair.0.scene;
        let (after, changed): (Scene, Vec<&str>) = match name {
            "vase_moved" | "vase_dragged" | "vase_dragged_slow" => {
                (moved(scene, VASE, Vec3::X), vec![VASE])
            }
            "vase_removed" => {
                let mut s = scene.clone();
                s.instances.retain(|i| i.name != VASE);
                (s, vec![VASE])
            }
            "vase_added" => {
                let mut s = scene.clone();
                let mut copy = s.instances[base_pair.0.index(VASE)].clone();
                copy.name = "vase_round_copy".into();
                copy.transform =
                    Affine3A::from_translation(Vec3::new(0.0, 0.0, 2.0)) * copy.transform;
                s.instances.push(copy);
                (s, vec!["vase_round_copy"])
            }
            "curtain_recoloured" => {
                let mut s = scene.clone();
                let k = base_pair.0.index(CURTAIN);
                let mut material: Material = (*s.instances[k].material).clone();
                material.albedo = Vec3::new(0.1, 0.6, 0.15);
                material.albedo_texture = None;
                material.name = "fabric_green".into();
                s.instances[k].material = Arc::new(material);
                (s, vec![CURTAIN])
            }
            other => panic!("unknown edit {other} ({all}, vase_dragged_slow)"),
        };
        let after = Level::new(after);
        let (rebaked, incremental_s) = if name == "vase_dragged" {
            // Ten steps of 10 cm, each from the base bake, the first nine superseded.
            // The scenes a drag passes through are built first: an editor has them.
            let steps: Vec<Level> = (1..10)
                .map(|step| Level::new(moved(scene, VASE, Vec3::X * step as f32 * 0.1)))
                .collect();
            let mut total = 0.0;
            for next in &steps {
                total += rebake(&base_pair.0, &base_bake, next, &changed, true).1;
            }
            let (outcome, s) = rebake(&base_pair.0, &base_bake, &after, &changed, false);
            (outcome, total + s)
        } else if name == "vase_dragged_slow" {
            // Ten steps of 10 cm, each from the re-bake before it.
            let (mut level, mut outcome, mut total) = (None::<Level>, base_bake.clone(), 0.0);
            for step in 1..=10 {
                let next = Level::new(moved(scene, VASE, Vec3::X * step as f32 * 0.1));
                let from = level.as_ref().unwrap_or(&base_pair.0);
                let (o, s) = rebake(from, &outcome, &next, &changed, false);
                (outcome, total) = (o.expect("a finished re-bake"), total + s);
                level = Some(next);
            }
            (Some(outcome), total)
        } else {
            rebake(&base_pair.0, &base_bake, &after, &changed, false)
        };
        eprintln!("{name}: re-baked in {incremental_s:.1} s");
        // A drag ends where the move does: one bake from scratch serves both.
        let key = if name.starts_with("vase_dragged") {
            "vase_moved"
        } else {
            name
        };
        let (scratch, full_s) = scratch_bakes
            .entry(key)
            .or_insert_with(|| bake(&after.traced, settings))
            .clone();
        let near = match name {
            "vase_removed" => sponza::neighbourhood(&base_pair.0.traced, VASE),
            _ => sponza::neighbourhood(&after.traced, changed[0]),
        };
        let incremental = rebaked.expect("a finished re-bake").cache().clone();
        let err =
            sponza::compare_caches(&after.traced, &incremental, scratch.cache(), POINTS, None);
        let err_near = sponza::compare_caches(
            &after.traced,
            &incremental,
            scratch.cache(),
            POINTS,
            Some(near),
        );
        let touched = touched(&base_pair, &(after, incremental));
        let line = format!(
            "edit={name} full_s={full_s:.1} incremental_s={incremental_s:.1} ratio={:.3} touched={touched:.4} err={:.4}",
            incremental_s / full_s,
            err.median_rel,
        );
        println!(
            "{line} err_near={:.4} (whole level: p90 {:.4}, rel_rms {:.4}; near: p90 {:.4}, rel_rms {:.4})",
            err_near.median_rel, err.p90_rel, err.rel_rms, err_near.p90_rel, err_near.rel_rms
        );
        lines.push((format!("{line} err_near={:.4}", err_near.median_rel), near));
    }
    if args.iter().any(|a| a == "--no-noise-floor") {
        return;
    }
    // The noise floor: the unedited level baked again with another seed.
    let (other, s) = bake(
        &base_pair.0.traced,
        BakeSettings {
            seed: 1,
            ..settings
        },
    );
    println!("base bake with seed 1: {s:.1} s");
    let t = &base_pair.0.traced;
    let floor = sponza::compare_caches(t, other.cache(), &base_pair.1, POINTS, None);
    println!(
        "noise floor over the whole level: median {:.4}, p90 {:.4}, rel_rms {:.4}",
        floor.median_rel, floor.p90_rel, floor.rel_rms
    );
    for (line, near) in lines {
        let near = sponza::compare_caches(t, other.cache(), &base_pair.1, POINTS, Some(near));
        let (head, err_near) = line.split_once(" err_near=").unwrap();
        println!(
            "{head} noise_floor={:.4} err_near={err_near} noise_near={:.4} (near: p90 {:.4}, rel_rms {:.4})",
            floor.median_rel, near.median_rel, near.p90_rel, near.rel_rms
        );
    }
}
