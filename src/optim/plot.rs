//! Line plots as PNG (curves against time), drawn by hand with an 8x8 bitmap font, so that
//! outputs need no system fonts.
use crate::{Error, Result};
use image::{Rgb, RgbImage};
use std::path::Path;

/// One curve.
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// Line colour.
    pub color: [u8; 3],
    /// (x, y) points; non-finite or non-positive y (on a log axis) are skipped.
    pub points: Vec<(f64, f64)>,
}

/// One panel: curves sharing axes, y logarithmic.
#[derive(Clone, Debug)]
pub struct Panel {
    /// Title above the panel (also names the y quantity).
    pub title: String,
    /// The curves.
    pub series: Vec<Series>,
}

const PW: u32 = 640;
const PH: u32 = 220;
const ML: u32 = 80;
const MR: u32 = 20;
const MT: u32 = 24;
const MB: u32 = 30;

pub(crate) fn text(img: &mut RgbImage, x: i64, y: i64, s: &str, color: [u8; 3]) {
    for (k, ch) in s.chars().enumerate() {
        let glyph = font8x8::legacy::BASIC_LEGACY[(ch as usize).min(127)];
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..8 {
                if bits >> col & 1 == 1 {
                    let (px, py) = (x + k as i64 * 8 + col, y + row as i64);
                    if px >= 0 && py >= 0 && (px as u32) < img.width() && (py as u32) < img.height()
                    {
                        img.put_pixel(px as u32, py as u32, Rgb(color));
                    }
                }
            }
        }
    }
}

fn line(img: &mut RgbImage, a: (f64, f64), b: (f64, f64), color: [u8; 3]) {
    let n = ((b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil() as usize).clamp(1, 4096);
    for i in 0..=n {
        let t = i as f64 / n as f64;
        let (x, y) = (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
        for (dx, dy) in [(0, 0), (1, 0), (0, 1)] {
            let (px, py) = (x.round() as i64 + dx, y.round() as i64 + dy);
            if px >= 0 && py >= 0 && (px as u32) < img.width() && (py as u32) < img.height() {
                img.put_pixel(px as u32, py as u32, Rgb(color));
            }
        }
    }
}

fn fmt(v: f64) -> String {
    if v != 0.0 && (v.abs() < 1e-2 || v.abs() >= 1e4) {
        format!("{v:.1e}")
    } else {
        format!("{v:.3}")
    }
}

/// Draw stacked panels against a shared x quantity and write a PNG atomically.
pub fn plot(path: &Path, x_label: &str, panels: &[Panel]) -> Result<()> {
    let height = PH * panels.len().max(1) as u32;
    let mut img = RgbImage::from_pixel(PW, height, Rgb([255, 255, 255]));
    let all_x = panels
        .iter()
        .flat_map(|p| p.series.iter().flat_map(|s| s.points.iter().map(|q| q.0)));
    let (x0, x1) = all_x
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(x), b.max(x))
        });
    let (x0, x1) = if x0.is_finite() && x1 > x0 {
        (x0, x1)
    } else {
        (0.0, 1.0)
    };
    for (k, panel) in panels.iter().enumerate() {
        let top = k as u32 * PH;
        let ys = panel
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|q| q.1))
            .filter(|y| y.is_finite() && *y > 0.0);
        let (y0, y1) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), y| {
            (a.min(y), b.max(y))
        });
        let (ly0, ly1) = if y0.is_finite() {
            let (a, b) = (y0.log10(), y1.log10());
            if b - a < 1e-6 {
                (a - 0.5, b + 0.5)
            } else {
                (a, b)
            }
        } else {
            (0.0, 1.0)
        };
        let (left, right) = (ML as f64, (PW - MR) as f64);
        let (ptop, pbottom) = ((top + MT) as f64, (top + PH - MB) as f64);
        let to_px = |x: f64, y: f64| {
            (
                left + (x - x0) / (x1 - x0) * (right - left),
                pbottom - (y.log10() - ly0) / (ly1 - ly0) * (pbottom - ptop),
            )
        };
        let axis = [60, 60, 60];
        line(&mut img, (left, ptop), (left, pbottom), axis);
        line(&mut img, (left, pbottom), (right, pbottom), axis);
        text(
            &mut img,
            left as i64,
            top as i64 + 6,
            &format!("{} (log scale)", panel.title),
            [0, 0, 0],
        );
        text(&mut img, 4, ptop as i64, &fmt(10f64.powf(ly1)), axis);
        text(&mut img, 4, pbottom as i64 - 8, &fmt(10f64.powf(ly0)), axis);
        text(&mut img, left as i64, pbottom as i64 + 6, &fmt(x0), axis);
        let xr = fmt(x1);
        text(
            &mut img,
            right as i64 - 8 * xr.len() as i64,
            pbottom as i64 + 6,
            &xr,
            axis,
        );
        text(
            &mut img,
            (left + right) as i64 / 2 - 4 * x_label.len() as i64,
            pbottom as i64 + 16,
            x_label,
            axis,
        );
        for (i, s) in panel.series.iter().enumerate() {
            text(
                &mut img,
                right as i64 - 8 * s.name.len() as i64,
                top as i64 + 6 + 10 * i as i64,
                &s.name,
                s.color,
            );
            let pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .filter(|(x, y)| x.is_finite() && y.is_finite() && *y > 0.0)
                .map(|&(x, y)| to_px(x, y))
                .collect();
            for w in pts.windows(2) {
                line(&mut img, w[0], w[1], s.color);
            }
            if pts.len() == 1 {
                line(&mut img, pts[0], pts[0], s.color);
            }
        }
    }
    crate::image_io::write_atomic_with(path, |tmp| {
        img.save_with_format(tmp, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })
    .map_err(|e| Error::file(path, e.to_string()))
}
