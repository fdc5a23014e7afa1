//! Image decoding with limits checked before any pixel is decoded.
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

/// Refuse an image whose declared size would exhaust memory.
pub fn check_dimensions(path: &Path, w: u64, h: u64, bytes_per_pixel: u64) -> Result<()> {
    if w == 0 || h == 0 {
        return Err(Error::file(
            path,
            format!("image has an empty size {w}x{h}"),
        ));
    }
    if w > MAX_IMAGE_DIM as u64
        || h > MAX_IMAGE_DIM as u64
        || w * h * bytes_per_pixel > MAX_IMAGE_BYTES
    {
        return Err(Error::file(
            path,
            format!(
                "image declares {w}x{h} pixels, over the limit of {MAX_IMAGE_DIM}x{MAX_IMAGE_DIM} \
                 and {} MiB decoded; refused before decoding",
                MAX_IMAGE_BYTES >> 20
            ),
        ));
    }
    Ok(())
}

fn limits() -> image::Limits {
    let mut l = image::Limits::default();
    l.max_image_width = Some(MAX_IMAGE_DIM);
    l.max_image_height = Some(MAX_IMAGE_DIM);
    l.max_alloc = Some(MAX_IMAGE_BYTES);
    l
}

/// Decode a PNG or JPEG texture. `path` names the source in errors (the file, or the scene
/// file plus the image's name for embedded images).
pub fn decode_texture(bytes: &[u8], path: &Path, name: &str) -> Result<Image8> {
    let reader = image::ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| Error::file(path, format!("image `{name}`: {e}")))?;
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
                format!("image `{name}` is not PNG or JPEG: unsupported texture format"),
            ))
        }
    }
    let (w, h) = image::ImageReader::with_format(
        Cursor::new(bytes),
        reader.format().unwrap_or(image::ImageFormat::Png),
    )
    .into_dimensions()
    .map_err(|e| Error::file(path, format!("image `{name}`: {e}")))?;
    check_dimensions(path, w as u64, h as u64, 4)?;
    let mut reader = reader;
    reader.limits(limits());
    let img = reader
        .decode()
        .map_err(|e| Error::file(path, format!("image `{name}`: {e}")))?;
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
    check_dimensions(path, w as u64, h as u64, 12)?;
    let mut reader = reader;
    reader.limits(limits());
    let img = reader
        .decode()
        .map_err(|e| Error::file(path, format!("Radiance HDR: {e}")))?
        .to_rgb32f();
    Ok((w, h, bytemuck::cast_slice(img.as_raw()).to_vec()))
}

/// Decode the first RGB(A) layer of an OpenEXR image into linear RGB floats.
pub fn decode_exr(path: &Path) -> Result<(u32, u32, Vec<[f32; 3]>)> {
    use exr::prelude::read_first_rgba_layer_from_file;
    let meta = exr::meta::MetaData::read_from_file(path, false)
        .map_err(|e| Error::file(path, format!("not a readable OpenEXR file: {e}")))?;
    let header = meta
        .headers
        .first()
        .ok_or_else(|| Error::file(path, "OpenEXR file has no layer"))?;
    let size = header.layer_size;
    check_dimensions(path, size.0 as u64, size.1 as u64, 16)?;
    let image = read_first_rgba_layer_from_file(
        path,
        |res, _| {
            let (w, h) = (res.width(), res.height());
            (w, vec![[0f32; 3]; w * h])
        },
        |(w, px): &mut (usize, Vec<[f32; 3]>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            px[pos.y() * *w + pos.x()] = [r, g, b];
        },
    )
    .map_err(|e| Error::file(path, format!("OpenEXR: {e}")))?;
    let (w, px) = image.layer_data.channel_data.pixels;
    let h = px.len() / w.max(1);
    Ok((w as u32, h as u32, px))
}
