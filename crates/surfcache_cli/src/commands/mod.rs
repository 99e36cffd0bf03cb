//! One module per subcommand.

mod bake;
mod chart;
pub(crate) mod compare;
mod export;
mod points;
mod query;
mod rays;
mod reference;
pub(crate) mod render;
mod trace;

use anyhow::Result;
use clap::Subcommand;

#[derive(Subcommand)]
pub enum Command {
    /// Brute-force path-traced irradiance E(x, n) at query points (no cache).
    Reference(reference::ReferenceArgs),
    /// Ray-tracing benchmark and oracle: traces RAYS.bin (8 little-endian f32 per ray:
    /// ox,oy,oz,dx,dy,dz,tmin,tmax; t in units of the direction's length).
    Trace(trace::TraceArgs),
    /// Writes a RAYS.bin for `trace`: incoherent rays leaving surfaces or camera rays.
    Rays(rays::RaysArgs),
    /// Writes a scene (e.g. a built-in one) as glTF, with its sky as OpenEXR beside it.
    Export(export::ExportArgs),
    /// Writes random query points (x,y,z,nx,ny,nz) uniformly distributed over a scene's
    /// surfaces.
    Points(points::PointsArgs),
    /// Error of a result CSV against a reference CSV (relative RMS; one JSON line).
    Compare(compare::CompareArgs),
    /// Bakes a surface cache (vertex lighting, irradiance maps or texel lightmaps) into an
    /// output directory: report.json, cache.bin, lightmaps/*.exr, scene.gltf with UV1.
    Bake(bake::BakeArgs),
    /// Answers E(x, n) at query points from a finished bake, without re-baking.
    Query(query::QueryArgs),
    /// Speed against accuracy: bakes every method × sampler over a sweep of error bounds
    /// (Cornell box, and Sponza from the shared assets when present), measures time, bytes
    /// and relative RMS error against a converged reference, and writes
    /// speed_accuracy.csv, two log-log charts and a summary.
    Chart(chart::ChartArgs),
    /// Renders a camera view shaded from a bake, path-traced, or as a diagnostic picture.
    Render(render::RenderArgs),
}

pub fn run(command: Command) -> Result<()> {
    match command {
        Command::Reference(args) => reference::run(args),
        Command::Trace(args) => trace::run(args),
        Command::Rays(args) => rays::run(args),
        Command::Export(args) => export::run(args),
        Command::Points(args) => points::run(args),
        Command::Compare(args) => compare::run(args),
        Command::Bake(args) => bake::run(args),
        Command::Query(args) => query::run(args),
        Command::Render(args) => render::run(args),
        Command::Chart(args) => chart::run(args),
    }
}
