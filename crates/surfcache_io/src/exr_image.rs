//! Linear-RGB OpenEXR images: equirectangular environment maps and lightmap textures.

use crate::IoError;
use crate::error::{Untrusted, no_panic};
use crate::file_replace::replace_with;
use exr::prelude::{
    AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, ReadChannels, ReadLayers,
    SpecificChannels, WritableImage,
};
use std::path::Path;
use surfcache_core::EnvironmentMap;
use surfcache_core::glam::Vec3;

/// Largest image accepted, in pixels (guards allocations against corrupt headers).
const MAX_PIXELS: usize = 1 << 28;

/// Largest decoded layer accepted, in bytes of samples over all its channels (the exr crate
/// allocates them all before reading a pixel, so a corrupt header of a tiny file could
/// otherwise ask for any amount of memory).
const MAX_SAMPLE_BYTES: usize = 1 << 32;

/// Reads an equirectangular radiance map (docs/cli.md convention; negative values are
/// clamped to 0 with one warning).
pub fn read_environment_map(path: &Path) -> Result<(EnvironmentMap, Vec<String>), IoError> {
    let (width, height, mut texels, mut warnings) = read_rgb(path)?;
    let mut negative = 0usize;
    for t in &mut texels {
        let clamped = t.max(Vec3::ZERO);
        negative += (clamped != *t) as usize;
        *t = clamped;
    }
    if negative > 0 {
        warnings.push(format!(
            "EXR '{}': {negative} pixels had negative values, clamped to 0",
            Untrusted::path(path)
        ));
    }
    Ok((
        EnvironmentMap {
            width,
            height,
            texels,
        },
        warnings,
    ))
}

/// Reads the R, G, B channels of an EXR's first layer as (width, height, row-major texels,
/// row 0 at the top); every value must be finite.
pub fn read_rgb_exr(path: &Path) -> Result<(u32, u32, Vec<Vec3>), IoError> {
    let (w, h, texels, _) = read_rgb(path)?;
    Ok((w, h, texels))
}

/// Writes a linear-RGB f32 EXR (ZIP scanlines, `Encoding::SMALL_LOSSLESS`) through a
/// temporary file renamed into place; `texels` are row-major, row 0 at the top.
pub fn write_rgb_exr(path: &Path, width: u32, height: u32, texels: &[Vec3]) -> Result<(), IoError> {
    let (w, h) = (width as usize, height as usize);
    if w == 0 || h == 0 || w.checked_mul(h) != Some(texels.len()) {
        return Err(IoError::write(
            path,
            format!("{} texels given for a {width}×{height} image", texels.len()),
        ));
    }
    if let Some(i) = texels.iter().position(|t| !t.is_finite()) {
        return Err(IoError::write(
            path,
            format!(
                "pixel ({}, {}) is not finite: {:?}",
                i % w,
                i / w,
                texels[i]
            ),
        ));
    }
    let channels = SpecificChannels::rgb(|p: exr::prelude::Vec2<usize>| {
        let t = texels.get(p.1 * w + p.0).copied().unwrap_or(Vec3::ZERO);
        (t.x, t.y, t.z)
    });
    let layer = Layer::new(
        (w, h),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        channels,
    );
    let image = Image::from_layer(layer);
    replace_with(path, |tmp| {
        image.write().to_file(tmp).map_err(|e| e.to_string())
    })
}

/// One channel of the image: its name and samples (data window, row-major).
type Channel = exr::image::AnyChannel<FlatSamples>;

/// Finds the R, G, B channels: plain `R`, `G`, `B`, else the first `prefix.R` with matching
/// `prefix.G` and `prefix.B`.
fn find_rgb(channels: &[Channel]) -> Option<[&Channel; 3]> {
    let named = |n: &str| channels.iter().find(|c| c.name.to_string() == n);
    if let (Some(r), Some(g), Some(b)) = (named("R"), named("G"), named("B")) {
        return Some([r, g, b]);
    }
    channels.iter().find_map(|c| {
        let name = c.name.to_string();
        let prefix = name.strip_suffix(".R")?;
        Some([
            c,
            named(&format!("{prefix}.G"))?,
            named(&format!("{prefix}.B"))?,
        ])
    })
}

/// An image of one layer, all its channels and attributes, as the exr crate reads it.
type OneLayerImage = Image<Layer<AnyChannels<FlatSamples>>>;

/// Reads the first layer's RGB into the display window (pixels outside the data window are
/// black, with a warning), rejecting NaN and infinities.
fn read_rgb(path: &Path) -> Result<(u32, u32, Vec<Vec3>, Vec<String>), IoError> {
    let bytes = std::fs::read(path).map_err(|e| IoError::read("EXR", path, e))?;
    let image = decode_first_layer(path, &bytes)?;
    let layer = &image.layer_data;
    let channels = &layer.channel_data.list;
    let Some(rgb) = find_rgb(channels) else {
        return Err(missing_channels(path, channels));
    };
    let (dw, dh) = (layer.size.0, layer.size.1);
    let n = dw.saturating_mul(dh);
    for c in rgb {
        if c.sample_data.len() != n {
            return Err(IoError::exr(
                path,
                format!(
                    "channel {} is subsampled ({} samples for {dw}×{dh} pixels), which is not supported",
                    Untrusted::bytes(c.name.bytes()),
                    c.sample_data.len()
                ),
            ));
        }
    }
    let display = image.attributes.display_window;
    let (width, height) = (display.size.0, display.size.1);
    if width == 0 || height == 0 || width.saturating_mul(height) > MAX_PIXELS {
        return Err(IoError::exr(
            path,
            format!("unsupported display window size {width}×{height}"),
        ));
    }
    let (Ok(w32), Ok(h32)) = (u32::try_from(width), u32::try_from(height)) else {
        return Err(IoError::exr(path, "image too large"));
    };
    // Data-window origin relative to the display window.
    let ox = layer.attributes.layer_position.0 as i64 - display.position.0 as i64;
    let oy = layer.attributes.layer_position.1 as i64 - display.position.1 as i64;
    let mut warnings = Vec::new();
    if ox != 0 || oy != 0 || dw != width || dh != height {
        warnings.push(format!(
            "EXR '{}': data window {dw}×{dh} at ({ox}, {oy}) differs from the {width}×{height} display window; pixels outside it are black",
            Untrusted::path(path)
        ));
    }
    let texels = place_data_window(path, rgb, (dw, dh), (ox, oy), (width, height))?;
    Ok((w32, h32, texels, warnings))
}

/// Checks the file's headers ([`check_before_decoding`]) and decodes its first valid layer,
/// all channels at the largest resolution level, without letting the exr crate panic.
fn decode_first_layer(path: &Path, bytes: &[u8]) -> Result<OneLayerImage, IoError> {
    let exr_error = |e: exr::error::Error| match e {
        exr::error::Error::Io(io) => IoError::read("EXR", path, io),
        other => IoError::read(
            "EXR",
            path,
            format!("not a readable OpenEXR file ({other})"),
        ),
    };
    no_panic("EXR header check", || check_before_decoding(bytes))
        .map_err(|e| IoError::read("EXR", path, e))?
        .map_err(exr_error)?
        .map_err(|cause| IoError::exr(path, cause))?;
    // `no_panic` stays as a safety net: the exr crate states many invariants of the file as
    // (debug) assertions rather than errors; those found by fuzzing are checked above, and so
    // are the sizes it would allocate.
    // Decompression is sequential: in parallel, exr decompresses on a thread pool of its own
    // built without a panic handler, where any panic aborts the whole process and `no_panic`
    // cannot catch it.
    no_panic("EXR decoding", || {
        exr::prelude::read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .first_valid_layer()
            .all_attributes()
            .non_parallel()
            .from_buffered(std::io::Cursor::new(bytes))
    })
    .map_err(|e| IoError::read("EXR", path, e))?
    .map_err(exr_error)
}

/// The error for a layer without R, G, B channels, listing the channels it has.
fn missing_channels(path: &Path, channels: &[Channel]) -> IoError {
    // At most LISTED names, so that a file of many channels still gives a short line.
    const LISTED: usize = 8;
    let mut found: Vec<String> = channels
        .iter()
        .take(LISTED)
        .map(|c| Untrusted::bytes(c.name.bytes()).to_string())
        .collect();
    if channels.len() > LISTED {
        found.push(format!("… ({} channels)", channels.len()));
    }
    IoError::MissingChannels {
        path: path.to_path_buf(),
        found: if found.is_empty() {
            "none".into()
        } else {
            found.join(", ")
        },
    }
}

/// The display window's texels (`width`×`height`, row-major, black where the data window
/// does not reach) with the `dw`×`dh` data window of `rgb` placed at (`ox`, `oy`); an
/// error names the first sample that is NaN or infinite.
fn place_data_window(
    path: &Path,
    rgb: [&Channel; 3],
    (dw, dh): (usize, usize),
    (ox, oy): (i64, i64),
    (width, height): (usize, usize),
) -> Result<Vec<Vec3>, IoError> {
    let mut texels = vec![Vec3::ZERO; width * height];
    const NAMES: [&str; 3] = ["R", "G", "B"];
    for y in 0..dh {
        let ty = y as i64 + oy;
        for x in 0..dw {
            let tx = x as i64 + ox;
            let mut v = [0.0f32; 3];
            for (k, c) in rgb.iter().enumerate() {
                let s = c.sample_data.value_by_flat_index(y * dw + x).to_f32();
                if !s.is_finite() {
                    let what = if s.is_nan() {
                        "NaN"
                    } else if s > 0.0 {
                        "+infinity"
                    } else {
                        "-infinity"
                    };
                    return Err(IoError::exr(
                        path,
                        format!("pixel ({tx}, {ty}) channel {} is {what}", NAMES[k]),
                    ));
                }
                v[k] = s;
            }
            if (0..width as i64).contains(&tx) && (0..height as i64).contains(&ty) {
                texels[ty as usize * width + tx as usize] = Vec3::from_array(v);
            }
        }
    }
    Ok(texels)
}

/// What the exr crate takes for granted, checked from the headers and chunk headers before
/// decoding; the outer error is the exr crate's, the inner one a cause for [`IoError::exr`].
///
/// - Window sizes: the data window of every layer (all its channels are allocated up front)
///   and the display window must stay within [`MAX_PIXELS`] and [`MAX_SAMPLE_BYTES`].
/// - Tile levels: every tile the offset tables list for the full-resolution level must say
///   so in its own chunk header. The exr crate selects the chunks to read by the offset table
///   but places their pixels by the level their header names, so a tile claiming another
///   level reaches the full-resolution buffer (a debug assertion inside exr, and pixels
///   written at the wrong place without it). The chunks of tiled files are read for this,
///   without decompressing them.
fn check_before_decoding(bytes: &[u8]) -> Result<Result<(), String>, exr::error::Error> {
    use exr::block::chunk::CompressedBlock;
    use exr::meta::BlockDescription;
    use exr::prelude::Vec2;
    let reader = exr::block::read(std::io::Cursor::new(bytes), false)?;
    for (i, header) in reader.headers().iter().enumerate() {
        let Vec2(w, h) = header.layer_size;
        let pixels = w.saturating_mul(h);
        let sample_bytes: usize = header
            .channels
            .list
            .iter()
            .map(|c| c.sample_type.bytes_per_sample())
            .fold(0, usize::saturating_add);
        if pixels > MAX_PIXELS || pixels.saturating_mul(sample_bytes) > MAX_SAMPLE_BYTES {
            return Ok(Err(format!(
                "layer {i}: unsupported data window size {w}×{h} ({} channels)",
                header.channels.list.len()
            )));
        }
        let Vec2(w, h) = header.shared_attributes.display_window.size;
        if w.saturating_mul(h) > MAX_PIXELS {
            return Ok(Err(format!("unsupported display window size {w}×{h}")));
        }
    }
    let tiled = reader
        .headers()
        .iter()
        .any(|h| matches!(h.blocks, BlockDescription::Tiles(_)));
    if !tiled {
        return Ok(Ok(()));
    }
    let full = Vec2(0, 0);
    for chunk in reader.filter_chunks(false, |_, tile, _| tile.level_index == full)? {
        if let CompressedBlock::Tile(tile) = chunk?.compressed_block
            && tile.coordinates.level_index != full
        {
            let (x, y) = (tile.coordinates.tile_index, tile.coordinates.level_index);
            return Ok(Err(format!(
                "tile ({}, {}) is listed for the full-resolution level but names level ({}, {})",
                x.0, x.1, y.0, y.1
            )));
        }
    }
    Ok(Ok(()))
}
