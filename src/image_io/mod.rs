//! Float images and their output: OpenEXR (linear) or PNG (sRGB), written atomically; and
//! every image decoder ([`decode`]). It depends on no psrestir module but `error`.
pub mod decode;

use crate::{Error, Result};
use std::io::Write;
use std::path::{Path, PathBuf};

/// A linear RGB float image, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Pixels, row-major.
    pub rgb: Vec<[f32; 3]>,
}

/// Linear to sRGB transfer function.
pub fn linear_to_srgb(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.0031308 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// sRGB to linear transfer function.
pub fn srgb_to_linear(x: f32) -> f32 {
    if x <= 0.04045 {
        x / 12.92
    } else {
        ((x + 0.055) / 1.055).powf(2.4)
    }
}

/// `name` with every character other than ASCII letters, digits and '-' replaced by '_', for
/// use in file names.
pub fn file_safe(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "out".into());
    path.with_file_name(format!(".{name}.{}.tmp", std::process::id()))
}

/// Write `bytes` to `path` through a temporary file and a rename, so that `path` is never
/// seen half-written.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic_with(path, |tmp| {
        let mut f = std::fs::File::create(tmp)?;
        f.write_all(bytes)?;
        f.sync_all()
    })
}

/// Run `write` on a temporary path beside `path`, then rename it over `path`.
pub fn write_atomic_with(
    path: &Path,
    write: impl FnOnce(&Path) -> std::io::Result<()>,
) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e.to_string()))?;
    }
    let tmp = temp_path(path);
    let result = write(&tmp).and_then(|_| std::fs::rename(&tmp, path));
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(Error::file(path, write_error(&e, path.exists())));
    }
    Ok(())
}

/// What a failed atomic write says: a full disk by name (the run stops there), and that the
/// file it would have replaced (`existed`) is as it was.
fn write_error(e: &std::io::Error, existed: bool) -> String {
    let kept = if existed {
        "; the file it would have replaced is unchanged"
    } else {
        ""
    };
    if e.kind() == std::io::ErrorKind::StorageFull {
        format!("the disk is full ({e}): nothing was written{kept}; free space and resume")
    } else {
        format!("{e}{kept}")
    }
}

impl Image {
    /// A black image.
    pub fn new(width: u32, height: u32) -> Image {
        Image {
            width,
            height,
            rgb: vec![[0.0; 3]; (width * height) as usize],
        }
    }

    /// Pixel at (x, y).
    pub fn at(&self, x: u32, y: u32) -> [f32; 3] {
        self.rgb[(y * self.width + x) as usize]
    }

    /// Mean of all pixels.
    pub fn mean(&self) -> [f64; 3] {
        let mut s = [0f64; 3];
        for p in &self.rgb {
            for c in 0..3 {
                s[c] += p[c] as f64;
            }
        }
        let n = self.rgb.len().max(1) as f64;
        s.map(|v| v / n)
    }

    /// Save as `.exr` (linear float) or `.png` (sRGB 8-bit), chosen by the extension.
    pub fn save(&self, path: &Path) -> Result<()> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "exr" => self.save_exr(path),
            "png" => self.save_png(path),
            _ => Err(Error::file(
                path,
                "output must end in .exr (linear) or .png (sRGB)",
            )),
        }
    }

    fn save_exr(&self, path: &Path) -> Result<()> {
        let (w, h) = (self.width as usize, self.height as usize);
        write_atomic_with(path, |tmp| {
            exr::prelude::write_rgb_file(tmp, w, h, |x, y| {
                let p = self.rgb[y * w + x];
                (p[0], p[1], p[2])
            })
            .map_err(std::io::Error::other)
        })
    }

    /// The image as sRGB-encoded 8-bit RGB bytes.
    pub fn to_srgb8(&self) -> Vec<u8> {
        self.rgb
            .iter()
            .flat_map(|p| p.map(|v| (linear_to_srgb(v) * 255.0 + 0.5) as u8))
            .collect()
    }

    fn save_png(&self, path: &Path) -> Result<()> {
        let img = image::RgbImage::from_raw(self.width, self.height, self.to_srgb8())
            .ok_or_else(|| Error::file(path, "image size does not match its pixels"))?;
        write_atomic_with(path, |tmp| {
            img.save_with_format(tmp, image::ImageFormat::Png)
                .map_err(std::io::Error::other)
        })
    }
}

/// Load an image as linear RGB: OpenEXR and Radiance HDR as they are, PNG and JPEG decoded
/// from sRGB.
pub fn load_linear(path: &Path) -> Result<Image> {
    Ok(load_linear_alpha(path)?.0)
}

/// [`load_linear`] with the image's alpha channel in [0, 1], when it has one below 1
/// anywhere (PNG with alpha, EXR with an `A` channel); None otherwise.
pub fn load_linear_alpha(path: &Path) -> Result<(Image, Option<Vec<f32>>)> {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let (width, height, rgb, alpha) = match ext.as_str() {
        "exr" => {
            let (w, h, px) = decode::decode_exr_rgba(path)?;
            let rgb = px.iter().map(|p| [p[0], p[1], p[2]]).collect();
            let a: Vec<f32> = px.iter().map(|p| p[3]).collect();
            (w, h, rgb, a)
        }
        "hdr" => {
            let bytes = std::fs::read(path).map_err(|e| Error::file(path, e.to_string()))?;
            let (w, h, rgb) = decode::decode_hdr(&bytes, path)?;
            (w, h, rgb, Vec::new())
        }
        "png" | "jpg" | "jpeg" => {
            let bytes = std::fs::read(path).map_err(|e| Error::file(path, e.to_string()))?;
            let name = path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let img = decode::decode_texture(&bytes, path, "image", &name)?;
            let rgb = img
                .rgba
                .iter()
                .map(|p| [0, 1, 2].map(|c| srgb_to_linear(p[c] as f32 / 255.0)))
                .collect();
            let a = img.rgba.iter().map(|p| p[3] as f32 / 255.0).collect();
            (img.width, img.height, rgb, a)
        }
        _ => return Err(Error::file(path, "images must be .exr, .hdr, .png or .jpg")),
    };
    if rgb.iter().flatten().any(|v| !v.is_finite()) {
        return Err(Error::file(path, "image has non-finite pixels"));
    }
    let alpha = alpha.iter().any(|a| *a < 1.0).then(|| {
        alpha
            .iter()
            .map(|a| {
                if a.is_finite() {
                    a.clamp(0.0, 1.0)
                } else {
                    0.0
                }
            })
            .collect()
    });
    Ok((Image { width, height, rgb }, alpha))
}

/// A mask image: its alpha where it has one below 1, else its gray value (mean of RGB),
/// clamped to [0, 1].
pub fn load_mask(path: &Path) -> Result<(u32, u32, Vec<f32>)> {
    let (img, alpha) = load_linear_alpha(path)?;
    let m = alpha.unwrap_or_else(|| {
        img.rgb
            .iter()
            .map(|p| ((p[0] + p[1] + p[2]) / 3.0).clamp(0.0, 1.0))
            .collect()
    });
    Ok((img.width, img.height, m))
}

/// Two images side by side (left, right), same height.
pub fn side_by_side(a: &Image, b: &Image) -> Image {
    let h = a.height.max(b.height);
    let mut out = Image::new(a.width + b.width, h);
    for y in 0..h {
        for x in 0..out.width {
            let p = if x < a.width {
                (y < a.height).then(|| a.at(x, y))
            } else {
                (y < b.height).then(|| b.at(x - a.width, y))
            };
            out.rgb[(y * out.width + x) as usize] = p.unwrap_or([0.0; 3]);
        }
    }
    out
}

#[cfg(test)]
mod write_tests {
    use super::*;

    /// A write that runs out of space leaves the file it would have replaced as it was, no
    /// temporary file, and an error that names the file and says the disk is full.
    #[test]
    fn a_full_disk_keeps_the_old_file_and_says_so() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("checkpoint.bin");
        write_atomic(&path, b"the last checkpoint").unwrap();
        let e = write_atomic_with(&path, |tmp| {
            std::fs::write(tmp, b"half a checkp")?;
            Err(std::io::Error::from(std::io::ErrorKind::StorageFull))
        })
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("checkpoint.bin") && e.contains("disk is full") && e.contains("unchanged"),
            "{e}"
        );
        assert_eq!(std::fs::read(&path).unwrap(), b"the last checkpoint");
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().flatten().collect();
        assert_eq!(names.len(), 1, "a temporary file was left");
    }
}
