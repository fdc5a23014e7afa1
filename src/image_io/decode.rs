//! Image decoding (PNG, JPEG, Radiance HDR, OpenEXR) with limits checked before any pixel is
//! decoded: glTF textures, environment maps, targets and captures all come through here.
use crate::{Error, Result};
use std::io::Cursor;
use std::path::Path;

/// Largest width or height psrestir decodes.
pub const MAX_IMAGE_DIM: u32 = 16384;
/// Largest decoded size psrestir accepts, in bytes (RGBA8 or RGB f32).
pub const MAX_IMAGE_BYTES: u64 = 1 << 30;

/// An RGBA8 image, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Image8 {
    /// Name for messages (file or glTF image name).
    pub name: String,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Pixels, row-major, RGBA.
    pub rgba: Vec<[u8; 4]>,
}

/// Most decoded bytes per byte of file that psrestir believes, so that a small file declaring
/// a huge image (a memory bomb, found by fuzzing) is refused before decoding. It is above what
/// the formats reach on flat content: deflate's 1032:1 on 8-bit grey PNG, expanded 4x to RGBA;
/// a JPEG's DC scan needs at least 2 bits per 8x8 block (under 1100:1); EXR halves decoded to
/// f32 (under 2800:1). Only 1- and 2-bit PNGs of flat content can exceed it, and only above
/// [`EXPANSION_FLOOR`]; they are refused.
pub const MAX_EXPANSION: u64 = 4200;
/// Decoded size below which [`MAX_EXPANSION`] is not applied.
pub const EXPANSION_FLOOR: u64 = 16 << 20;

/// Why an image of the declared size is refused (it would exhaust memory), if it is: an
/// empty size, a side over [`MAX_IMAGE_DIM`], more than [`MAX_IMAGE_BYTES`] decoded at
/// `bytes_per_pixel`, or more than [`MAX_EXPANSION`] times the `file_len` bytes it comes from.
pub fn size_problem(w: u64, h: u64, bytes_per_pixel: u64, file_len: u64) -> Option<String> {
    if w == 0 || h == 0 {
        return Some(format!("image has an empty size {w}x{h}"));
    }
    let too_big = w > MAX_IMAGE_DIM as u64
        || h > MAX_IMAGE_DIM as u64
        || w * h * bytes_per_pixel > MAX_IMAGE_BYTES;
    if too_big {
        return Some(format!(
            "image declares {w}x{h} pixels, over the limit of {MAX_IMAGE_DIM}x{MAX_IMAGE_DIM} \
             and {} MiB decoded; refused before decoding",
            MAX_IMAGE_BYTES >> 20
        ));
    }
    let decoded = w * h * bytes_per_pixel;
    (decoded > EXPANSION_FLOOR && decoded > MAX_EXPANSION * file_len).then(|| {
        format!(
            "image declares {w}x{h} pixels, more than a file of {file_len} bytes can hold \
             (truncated or corrupt); refused before decoding"
        )
    })
}

fn limits() -> image::Limits {
    let mut l = image::Limits::default();
    l.max_image_width = Some(MAX_IMAGE_DIM);
    l.max_image_height = Some(MAX_IMAGE_DIM);
    l.max_alloc = Some(MAX_IMAGE_BYTES);
    l
}

/// Decode a PNG or JPEG texture. Errors name `path` (the scene file) and `what` (the image,
/// with its own file when it has one); `name` is kept in the result.
pub fn decode_texture(bytes: &[u8], path: &Path, what: &str, name: &str) -> Result<Image8> {
    let reader = image::ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| Error::file(path, format!("{what}: {e}")))?;
    match reader.format() {
        Some(image::ImageFormat::Png) | Some(image::ImageFormat::Jpeg) => {}
        Some(f) => {
            return Err(Error::file(
                path,
                format!(
                "image `{name}` is {f:?}: unsupported texture format (psrestir reads PNG and JPEG)"
            ),
            ))
        }
        None => {
            return Err(Error::file(
                path,
                format!("{what} is not PNG or JPEG: unsupported texture format"),
            ))
        }
    }
    let (w, h) = image::ImageReader::with_format(
        Cursor::new(bytes),
        reader.format().unwrap_or(image::ImageFormat::Png),
    )
    .into_dimensions()
    .map_err(|e| Error::file(path, format!("{what}: {e}")))?;
    if let Some(problem) = size_problem(w as u64, h as u64, 4, bytes.len() as u64) {
        return Err(Error::file(path, format!("{what}: {problem}")));
    }
    let mut reader = reader;
    reader.limits(limits());
    // zune-jpeg 0.5.15 panics on some corrupt JPEGs (tests/fuzz_regressions/jpeg).
    let img = crate::error::catch_panic(path, &format!("{what}: the image decoder"), || {
        reader
            .decode()
            .map_err(|e| Error::file(path, format!("{what}: {e}")))
    })?;
    let rgba = img.to_rgba8();
    Ok(Image8 {
        name: name.to_string(),
        width: rgba.width(),
        height: rgba.height(),
        rgba: bytemuck::cast_slice(rgba.as_raw()).to_vec(),
    })
}

/// Decode a Radiance HDR image into linear RGB floats.
pub fn decode_hdr(bytes: &[u8], path: &Path) -> Result<(u32, u32, Vec<[f32; 3]>)> {
    let reader = image::ImageReader::with_format(Cursor::new(bytes), image::ImageFormat::Hdr);
    let (w, h) = image::ImageReader::with_format(Cursor::new(bytes), image::ImageFormat::Hdr)
        .into_dimensions()
        .map_err(|e| Error::file(path, format!("not a Radiance HDR image: {e}")))?;
    if let Some(problem) = size_problem(w as u64, h as u64, 12, bytes.len() as u64) {
        return Err(Error::file(path, problem));
    }
    let mut reader = reader;
    reader.limits(limits());
    let img = crate::error::catch_panic(path, "the Radiance HDR decoder", || {
        reader
            .decode()
            .map_err(|e| Error::file(path, format!("Radiance HDR: {e}")))
    })?
    .to_rgb32f();
    Ok((w, h, bytemuck::cast_slice(img.as_raw()).to_vec()))
}

/// Decode the first RGB(A) layer of an OpenEXR image into linear RGB floats.
pub fn decode_exr(path: &Path) -> Result<(u32, u32, Vec<[f32; 3]>)> {
    let (w, h, px) = decode_exr_rgba(path)?;
    Ok((w, h, px.iter().map(|p| [p[0], p[1], p[2]]).collect()))
}

/// [`decode_exr`] with the alpha channel (1 where the file has none).
pub fn decode_exr_rgba(path: &Path) -> Result<(u32, u32, Vec<[f32; 4]>)> {
    crate::error::catch_panic(path, "the OpenEXR decoder", || decode_exr_unguarded(path))
}

fn decode_exr_unguarded(path: &Path) -> Result<(u32, u32, Vec<[f32; 4]>)> {
    use exr::prelude::traits::*;
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| Error::file(path, format!("not a readable OpenEXR file: {e}")))?;
    if meta.headers.is_empty() {
        return Err(Error::file(path, "OpenEXR file has no layer"));
    }
    let file_len = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
    // Any layer may be the one read: check them all.
    for header in meta.headers.iter() {
        let size = header.layer_size;
        if let Some(problem) = size_problem(size.0 as u64, size.1 as u64, 16, file_len) {
            return Err(Error::file(path, problem));
        }
    }
    // Sequential: a panic in a decoder on a worker thread of the parallel reader aborts the
    // process (rayon), where on this thread it becomes an error (`catch_panic`).
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .rgba_channels(
            |res, _| {
                let (w, h) = (res.width(), res.height());
                (w, vec![[0f32; 4]; w * h])
            },
            |(w, px): &mut (usize, Vec<[f32; 4]>), pos, (r, g, b, a): (f32, f32, f32, f32)| {
                px[pos.y() * *w + pos.x()] = [r, g, b, a];
            },
        )
        .first_valid_layer()
        .all_attributes()
        .non_parallel()
        .from_file(path)
        .map_err(|e| Error::file(path, format!("OpenEXR: {e}")))?;
    let (w, px) = image.layer_data.channel_data.pixels;
    let h = px.len() / w.max(1);
    Ok((w as u32, h as u32, px))
}
