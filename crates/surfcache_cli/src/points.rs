//! The query-point CSV (`x,y,z,nx,ny,nz`) and result CSV (`x,y,z,r,g,b[,rel_std]`).

use anyhow::{Context, Result, bail};
use glam::Vec3;
use rayon::prelude::*;
use std::{io::Write, path::Path};
use surfcache_cache::{IrradianceTexture, PublishedLookup, SurfaceCache};
use surfcache_io::Untrusted;
use surfcache_trace::{Query, SurfacePoint, TracedScene};

/// Baked irradiance at each query point: the point is located on `geometry` (the baked
/// triangles, in the cache's order) and looked up in `cache` on the side whose geometric
/// normal points along the query normal; `None` for a point off every surface.
pub fn lookup_points<C: SurfaceCache>(
    geometry: &TracedScene,
    cache: &C,
    queries: &[Query],
) -> Vec<Option<Vec3>> {
    locate_points(geometry, queries, |p, front| {
        Some(cache.lookup(p.triangle, p.uv, front))
    })
}

/// [`lookup_points`] through the cache's published textures, sampled as a game engine
/// samples them ([`PublishedLookup`]): what a player sees.
pub fn lookup_published(
    geometry: &TracedScene,
    textures: &[IrradianceTexture],
    queries: &[Query],
) -> Vec<Option<Vec3>> {
    let published = PublishedLookup::new(textures, geometry);
    locate_points(geometry, queries, |p, front| {
        published.lookup(p.triangle, p.uv, front)
    })
}

/// Each query point located on `geometry`, with the side its normal asks about, and
/// looked up by `look`.
fn locate_points(
    geometry: &TracedScene,
    queries: &[Query],
    look: impl Fn(&SurfacePoint, bool) -> Option<Vec3> + Sync,
) -> Vec<Option<Vec3>> {
    queries
        .par_iter()
        .map(|q| {
            let p = geometry.locate(q.position, q.normal)?;
            let front =
                geometry.geometric_normals()[p.triangle as usize].dot(p.geometric_normal) > 0.0;
            look(&p, front)
        })
        .collect()
}

/// Reads `x,y,z,nx,ny,nz` rows; rejects a wrong header, short rows and non-finite numbers.
pub fn read_points(path: &Path) -> Result<Vec<Query>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read points file '{}'", Untrusted::path(path)))?;
    let mut lines = text.lines().enumerate();
    let header = lines.next().map(|(_, l)| l.trim()).unwrap_or("");
    let columns: Vec<&str> = header.split(',').map(str::trim).collect();
    if columns != ["x", "y", "z", "nx", "ny", "nz"] {
        bail!(
            "points file '{}': header must be 'x,y,z,nx,ny,nz', found '{}'",
            Untrusted::path(path),
            Untrusted::name(header)
        );
    }
    let mut queries = Vec::new();
    for (i, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let values: Vec<f32> = line
            .split(',')
            .map(|v| v.trim().parse::<f32>())
            .collect::<Result<_, _>>()
            .map_err(|e| {
                anyhow::anyhow!(
                    "points file '{}' line {}: {e}",
                    Untrusted::path(path),
                    i + 1
                )
            })?;
        if values.len() != 6 {
            bail!(
                "points file '{}' line {}: expected 6 values, found {}",
                Untrusted::path(path),
                i + 1,
                values.len()
            );
        }
        if values.iter().any(|v| !v.is_finite()) {
            bail!(
                "points file '{}' line {}: non-finite value",
                Untrusted::path(path),
                i + 1
            );
        }
        let normal = Vec3::new(values[3], values[4], values[5]);
        if normal.length_squared() == 0.0 {
            bail!(
                "points file '{}' line {}: zero normal",
                Untrusted::path(path),
                i + 1
            );
        }
        queries.push(Query {
            position: Vec3::new(values[0], values[1], values[2]),
            normal: normal.normalize(),
        });
    }
    Ok(queries)
}

/// Writes the result CSV to `path` (through a temporary file renamed into place) or stdout.
pub fn write_results(path: Option<&Path>, header: &str, rows: &[String]) -> Result<()> {
    let mut text = String::with_capacity(rows.len() * 64 + header.len() + 1);
    text.push_str(header);
    text.push('\n');
    for row in rows {
        text.push_str(row);
        text.push('\n');
    }
    match path {
        Some(path) => Ok(surfcache_io::write_file_atomically(path, text.as_bytes())?),
        None => std::io::stdout()
            .lock()
            .write_all(text.as_bytes())
            .context("cannot write to stdout"),
    }
}

/// One row of a result CSV: position, irradiance (NaN for points off the scene) and the
/// reference's relative standard error when the file has that column.
pub struct ResultRow {
    pub position: Vec3,
    pub irradiance: Vec3,
    pub rel_std: Option<f32>,
}

/// Reads a result CSV with header `x,y,z,r,g,b` or `x,y,z,r,g,b,rel_std`.
pub fn read_results(path: &Path) -> Result<Vec<ResultRow>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read results file '{}'", Untrusted::path(path)))?;
    let mut lines = text.lines().enumerate();
    let header = lines.next().map(|(_, l)| l.trim()).unwrap_or("");
    let with_std = match header {
        "x,y,z,r,g,b" => false,
        "x,y,z,r,g,b,rel_std" => true,
        _ => bail!(
            "results file '{}': header must be 'x,y,z,r,g,b[,rel_std]', found '{}'",
            Untrusted::path(path),
            Untrusted::name(header)
        ),
    };
    let mut rows = Vec::new();
    for (i, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let v: Vec<f32> = line
            .split(',')
            .map(|v| v.trim().parse::<f32>())
            .collect::<Result<_, _>>()
            .map_err(|e| {
                anyhow::anyhow!(
                    "results file '{}' line {}: {e}",
                    Untrusted::path(path),
                    i + 1
                )
            })?;
        if v.len() != 6 + with_std as usize {
            bail!(
                "results file '{}' line {}: wrong number of values",
                Untrusted::path(path),
                i + 1
            );
        }
        rows.push(ResultRow {
            position: Vec3::new(v[0], v[1], v[2]),
            irradiance: Vec3::new(v[3], v[4], v[5]),
            rel_std: with_std.then(|| v[6]),
        });
    }
    Ok(rows)
}
