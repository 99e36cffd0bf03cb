//! Bounds-checked reading of glTF accessors (the gltf crate's reader can panic on
//! out-of-range or zero-count accessors, so this crate reads them itself).

use gltf::accessor::{
    Accessor, DataType, Dimensions,
    sparse::{IndexType, Sparse},
};

/// The loaded buffers, by index (file, data URI or GLB chunk).
pub(crate) type Buffers = [gltf::buffer::Data];

fn component_size(t: DataType) -> usize {
    match t {
        DataType::I8 | DataType::U8 => 1,
        DataType::I16 | DataType::U16 => 2,
        DataType::U32 | DataType::F32 => 4,
    }
}

fn dims_name(d: Dimensions) -> &'static str {
    match d {
        Dimensions::Scalar => "SCALAR",
        Dimensions::Vec2 => "VEC2",
        Dimensions::Vec3 => "VEC3",
        Dimensions::Vec4 => "VEC4",
        Dimensions::Mat2 => "MAT2",
        Dimensions::Mat3 => "MAT3",
        Dimensions::Mat4 => "MAT4",
    }
}

/// Decodes one component at `bytes[..size]` as f32 (normalised integers per the glTF spec).
fn component(bytes: &[u8], t: DataType, normalized: bool) -> Option<f32> {
    Some(match t {
        DataType::F32 => f32::from_le_bytes(bytes.get(..4)?.try_into().ok()?),
        DataType::U8 => {
            let v = *bytes.first()? as f32;
            if normalized { v / 255.0 } else { v }
        }
        DataType::I8 => {
            let v = *bytes.first()? as i8 as f32;
            if normalized { (v / 127.0).max(-1.0) } else { v }
        }
        DataType::U16 => {
            let v = u16::from_le_bytes(bytes.get(..2)?.try_into().ok()?) as f32;
            if normalized { v / 65535.0 } else { v }
        }
        DataType::I16 => {
            let v = i16::from_le_bytes(bytes.get(..2)?.try_into().ok()?) as f32;
            if normalized {
                (v / 32767.0).max(-1.0)
            } else {
                v
            }
        }
        DataType::U32 => {
            let v = u32::from_le_bytes(bytes.get(..4)?.try_into().ok()?) as f32;
            if normalized { v / 4294967295.0 } else { v }
        }
    })
}

fn integer(bytes: &[u8], size: usize) -> Option<u32> {
    Some(match size {
        1 => *bytes.first()? as u32,
        2 => u16::from_le_bytes(bytes.get(..2)?.try_into().ok()?) as u32,
        _ => u32::from_le_bytes(bytes.get(..4)?.try_into().ok()?),
    })
}

/// The bytes of a buffer view and the stride of elements of `elem_size` bytes in it,
/// checking that `count` elements from `offset` fit.
fn view_elements<'b>(
    view: &gltf::buffer::View<'_>,
    buffers: &'b Buffers,
    offset: usize,
    count: usize,
    elem_size: usize,
    what: &str,
) -> Result<(&'b [u8], usize), String> {
    let buffer = buffers
        .get(view.buffer().index())
        .ok_or_else(|| format!("{what}: buffer {} is missing", view.buffer().index()))?;
    let view_end = view.offset().checked_add(view.length());
    let data = view_end
        .and_then(|end| buffer.get(view.offset()..end))
        .ok_or_else(|| {
            format!(
                "{what}: buffer view {} (bytes {}..{}) lies beyond buffer {} ({} bytes)",
                view.index(),
                view.offset(),
                view.offset().saturating_add(view.length()),
                view.buffer().index(),
                buffer.len()
            )
        })?;
    let stride = view.stride().unwrap_or(elem_size);
    if stride < elem_size {
        return Err(format!(
            "{what}: buffer view {} has stride {stride} below the element size {elem_size}",
            view.index()
        ));
    }
    if count > 0 {
        let end = (count - 1)
            .checked_mul(stride)
            .and_then(|x| x.checked_add(elem_size))
            .and_then(|x| x.checked_add(offset));
        if end.is_none_or(|end| end > data.len()) {
            return Err(format!(
                "{what}: {count} elements of {elem_size} bytes (stride {stride}) from byte {offset} run past the end of buffer view {} ({} bytes)",
                view.index(),
                data.len()
            ));
        }
    }
    Ok((data, stride))
}

/// Largest all-zero accessor (no buffer view) accepted, in bytes.
const MAX_VIEWLESS_BYTES: usize = 1 << 30;

/// Reads an accessor of `dims` components per element as f32, applying sparse substitution.
/// `allowed` lists the component types the attribute may use.
pub(crate) fn read_f32(
    acc: &Accessor<'_>,
    buffers: &Buffers,
    dims: usize,
    allowed: &[DataType],
    what: &str,
) -> Result<Vec<f32>, String> {
    let what = format!("{what} (accessor {})", acc.index());
    if acc.dimensions().multiplicity() != dims {
        return Err(format!(
            "{what} has type {} but {} components are needed",
            dims_name(acc.dimensions()),
            dims
        ));
    }
    let t = acc.data_type();
    if !allowed.contains(&t) {
        return Err(format!("{what} has unsupported component type {t:?}"));
    }
    let mut out = read_dense_f32(acc, buffers, dims, &what)?;
    if let Some(sparse) = acc.sparse() {
        substitute_sparse_f32(acc, &sparse, buffers, dims, &mut out, &what)?;
    }
    Ok(out)
}

/// Decodes `dst.len()` consecutive components of type `t` from `data` starting at byte
/// `base` ([`component`]); None when one of them runs past the end.
fn components_into(
    dst: &mut [f32],
    data: &[u8],
    base: usize,
    t: DataType,
    normalized: bool,
) -> Option<()> {
    let size = component_size(t);
    for (c, d) in dst.iter_mut().enumerate() {
        *d = data
            .get(base + c * size..)
            .and_then(|b| component(b, t, normalized))?;
    }
    Some(())
}

/// The accessor's elements of `dims` components as f32 from its buffer view, all zero
/// without one (before sparse substitution).
fn read_dense_f32(
    acc: &Accessor<'_>,
    buffers: &Buffers,
    dims: usize,
    what: &str,
) -> Result<Vec<f32>, String> {
    let t = acc.data_type();
    let elem = component_size(t) * dims;
    let count = acc.count();
    let viewed = match acc.view() {
        Some(view) => Some(view_elements(
            &view,
            buffers,
            acc.offset(),
            count,
            elem,
            what,
        )?),
        None if count.saturating_mul(elem) > MAX_VIEWLESS_BYTES => {
            return Err(format!(
                "{what} has no buffer view and an implausible count {count}"
            ));
        }
        None => None,
    };
    // The count is bounded by the checked view length (or MAX_VIEWLESS_BYTES) here.
    let mut out = vec![0.0f32; count * dims];
    if let Some((data, stride)) = viewed {
        for (i, dst) in out.chunks_exact_mut(dims).enumerate() {
            components_into(dst, data, acc.offset() + i * stride, t, acc.normalized())
                .ok_or_else(|| format!("{what}: element {i} is out of range"))?;
        }
    }
    Ok(out)
}

/// Replaces the elements of `out` (the accessor's, `dims` components each) that `sparse`
/// lists by its values.
fn substitute_sparse_f32(
    acc: &Accessor<'_>,
    sparse: &Sparse<'_>,
    buffers: &Buffers,
    dims: usize,
    out: &mut [f32],
    what: &str,
) -> Result<(), String> {
    let t = acc.data_type();
    let elem = component_size(t) * dims;
    let count = acc.count();
    let n = sparse.count();
    let idx = sparse.indices();
    let isize = match idx.index_type() {
        IndexType::U8 => 1,
        IndexType::U16 => 2,
        IndexType::U32 => 4,
    };
    let (idata, _) = view_elements(
        &idx.view(),
        buffers,
        idx.offset(),
        n,
        isize,
        &format!("{what} sparse indices"),
    )?;
    let vals = sparse.values();
    let (vdata, _) = view_elements(
        &vals.view(),
        buffers,
        vals.offset(),
        n,
        elem,
        &format!("{what} sparse values"),
    )?;
    for k in 0..n {
        let target = idata
            .get(idx.offset() + k * isize..)
            .and_then(|b| integer(b, isize))
            .ok_or_else(|| format!("{what}: sparse index {k} is out of range"))?
            as usize;
        let dst = out
            .get_mut(target * dims..(target + 1) * dims)
            .ok_or_else(|| {
                format!("{what}: sparse index {k} points at element {target} of {count}")
            })?;
        components_into(dst, vdata, vals.offset() + k * elem, t, acc.normalized())
            .ok_or_else(|| format!("{what}: sparse value {k} is out of range"))?;
    }
    Ok(())
}

/// Reads a scalar unsigned-integer accessor (vertex indices).
pub(crate) fn read_indices(
    acc: &Accessor<'_>,
    buffers: &Buffers,
    what: &str,
) -> Result<Vec<u32>, String> {
    let what = format!("{what} (accessor {})", acc.index());
    if acc.dimensions() != Dimensions::Scalar {
        return Err(format!(
            "{what} has type {} but indices must be SCALAR",
            dims_name(acc.dimensions())
        ));
    }
    let size = match acc.data_type() {
        DataType::U8 => 1,
        DataType::U16 => 2,
        DataType::U32 => 4,
        t => {
            return Err(format!(
                "{what} has component type {t:?}; indices must be unsigned"
            ));
        }
    };
    if acc.sparse().is_some() {
        // Sparse index accessors are legal but unheard of; read through the f32 path
        // would lose precision above 2^24, so refuse clearly instead.
        return Err(format!(
            "{what} is sparse, which is not supported for indices"
        ));
    }
    let count = acc.count();
    let Some(view) = acc.view() else {
        if count.saturating_mul(size) > MAX_VIEWLESS_BYTES {
            return Err(format!(
                "{what} has no buffer view and an implausible count {count}"
            ));
        }
        return Ok(vec![0; count]);
    };
    let (data, stride) = view_elements(&view, buffers, acc.offset(), count, size, &what)?;
    (0..count)
        .map(|i| {
            data.get(acc.offset() + i * stride..)
                .and_then(|b| integer(b, size))
                .ok_or_else(|| format!("{what}: element {i} is out of range"))
        })
        .collect()
}
