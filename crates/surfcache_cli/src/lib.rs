//! The `surfcache` command-line tool (docs/cli.md): `reference`, `trace`, `rays`,
//! `export`, and `bake`/`query` as the caches land.
//!
//! Every command is a thin app: it loads a scene into a `bevy_ecs` world, runs the
//! surfcache schedule (scene sync → BVH → …) and reads the results from its resources.
//! Errors print as one line on stderr with a non-zero exit status, and warnings as one line
//! each, both through [`surfcache_io::Untrusted`] so that no byte of an input file reaches
//! the terminal raw.

mod bake_dir;
mod baking;
pub mod camera;
mod commands;
pub mod picture;
mod points;
mod scene_args;

pub use commands::{
    compare::{Comparison, compare},
    render::{render_view, surface_radiance},
};

use clap::Parser;
use std::process::ExitCode;
use surfcache_io::Untrusted;

const ABOUT: &str = "Bakes diffuse global illumination into surface caches.

Conventions: glTF units are metres; radiance in W/(m²·sr), irradiance E in W/m², linear RGB.
E(x, n) = ∫ L_in(x, ω) max(0, n·ω) dω about the scene's shading normal on the side of the
surface that n selects; surfaces are two-sided Lambertian reflectors. Environment maps are
equirectangular, +Y up, image centre looking along −Z, +X a quarter turn to the right.
Built-in scenes (e.g. `cornell`) bring their own sky unless --env or --env-color is given.";

#[derive(Parser)]
#[command(name = "surfcache", version, about = ABOUT, long_about = ABOUT)]
struct Cli {
    #[command(subcommand)]
    command: commands::Command,
}

/// Runs the command line; returns the process exit code.
pub fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            // Help and version go to stdout with success; usage errors to stderr.
            let _ = e.print();
            return if e.use_stderr() {
                ExitCode::from(2)
            } else {
                ExitCode::SUCCESS
            };
        }
    };
    match commands::run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", Untrusted::text(&format!("{e:#}")));
            ExitCode::FAILURE
        }
    }
}

/// Prints `warning: MESSAGE` on stderr as one printable line (the message may quote a file).
pub(crate) fn warn(message: &str) {
    eprintln!("warning: {}", Untrusted::text(message));
}
