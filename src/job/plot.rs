//! PNG plots and captions with `plotters` (bitmap backend, an embedded font): panels stacked
//! vertically, each with axes, ticks, labels, a legend, several series, an optional log-scale
//! y axis and an optional secondary y axis on the right (a learning rate, say).
use crate::image_io::write_atomic_with;
use crate::{Error, Result};
use image::RgbImage;
use plotters::prelude::*;
use std::path::Path;

/// One line of a panel.
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend entry.
    pub name: String,
    /// RGB color.
    pub color: [u8; 3],
    /// (x, y) points; non-finite ones (and, on a log axis, non-positive ones) are skipped.
    pub points: Vec<(f64, f64)>,
}

/// One chart.
#[derive(Clone, Debug, Default)]
pub struct Panel {
    /// Title above the chart.
    pub title: String,
    /// Label of the y axis.
    pub y_label: String,
    /// Logarithmic y axis.
    pub log_y: bool,
    /// Series on the left axis.
    pub series: Vec<Series>,
    /// Label and series of a secondary (linear) y axis on the right, if any.
    pub secondary: Option<(String, Vec<Series>)>,
}

/// The family the embedded font is registered under.
const FONT: &str = "sans-serif";

fn register_font() -> Result<()> {
    static DONE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *DONE.get_or_init(|| {
        plotters::style::register_font(FONT, FontStyle::Normal, epaint_default_fonts::UBUNTU_LIGHT)
            .is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(Error::Invalid(
            "plot: the embedded font did not load".into(),
        ))
    }
}

fn err(e: impl std::fmt::Display) -> Error {
    Error::Invalid(format!("plot: {e}"))
}

fn rgb(c: [u8; 3]) -> RGBColor {
    RGBColor(c[0], c[1], c[2])
}

/// Points of a series as drawn: finite, and mapped to log10 on a log axis.
fn drawn(points: &[(f64, f64)], log_y: bool) -> Vec<(f64, f64)> {
    points
        .iter()
        .filter(|(x, y)| x.is_finite() && y.is_finite() && (!log_y || *y > 0.0))
        .map(|&(x, y)| (x, if log_y { y.log10() } else { y }))
        .collect()
}

/// A padded range around `values` (never empty).
fn range(values: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-12 {
        let d = if lo.abs() > 1e-12 {
            0.05 * lo.abs()
        } else {
            0.5
        };
        return (lo - d, hi + d);
    }
    let d = pad * (hi - lo);
    (lo - d, hi + d)
}

fn tick_label(v: f64, log_y: bool) -> String {
    let v = if log_y { 10f64.powf(v) } else { v };
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if !(1e-2..1e4).contains(&a) {
        format!("{v:.1e}")
    } else if a >= 100.0 {
        format!("{v:.0}")
    } else {
        format!("{v:.3}")
            .trim_end_matches('0')
            .trim_end_matches('.')
            .to_string()
    }
}

/// A series as drawn: name, color, points.
type Drawn = (String, [u8; 3], Vec<(f64, f64)>);

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    x_label: &str,
    panel: &Panel,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let left: Vec<Drawn> = panel
        .series
        .iter()
        .map(|s| (s.name.clone(), s.color, drawn(&s.points, panel.log_y)))
        .collect();
    let right: Vec<Drawn> = panel
        .secondary
        .iter()
        .flat_map(|(_, ss)| ss.iter())
        .map(|s| (s.name.clone(), s.color, drawn(&s.points, false)))
        .collect();
    let all_x = left
        .iter()
        .chain(&right)
        .flat_map(|s| s.2.iter().map(|p| p.0));
    let (mut x0, x1) = range(all_x, 0.0);
    if x0 > 0.0 && x0 < 0.2 * x1 {
        x0 = 0.0;
    }
    let (y0, y1) = range(left.iter().flat_map(|s| s.2.iter().map(|p| p.1)), 0.05);
    let (s0, s1) = range(right.iter().flat_map(|s| s.2.iter().map(|p| p.1)), 0.05);
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, (FONT, 18))
        .margin(8)
        .x_label_area_size(36)
        .y_label_area_size(64)
        .right_y_label_area_size(if right.is_empty() { 0 } else { 64 })
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(err)?
        .set_secondary_coord(x0..x1, s0..s1);
    let log_y = panel.log_y;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(if log_y {
            format!("{} (log)", panel.y_label)
        } else {
            panel.y_label.clone()
        })
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .y_label_formatter(&|v| tick_label(*v, log_y))
        .x_label_formatter(&|v| tick_label(*v, false))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(err)?;
    if let Some((label, _)) = &panel.secondary {
        chart
            .configure_secondary_axes()
            .y_desc(label.as_str())
            .label_style((FONT, 13))
            .axis_desc_style((FONT, 14))
            .y_label_formatter(&|v| tick_label(*v, false))
            .draw()
            .map_err(err)?;
    }
    for (name, color, pts) in &left {
        let c = rgb(*color);
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))
            .map_err(err)?
            .label(name.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2)));
    }
    for (name, color, pts) in &right {
        let c = rgb(*color);
        chart
            .draw_secondary_series(LineSeries::new(pts.iter().copied(), c.stroke_width(1)))
            .map_err(err)?
            .label(format!("{name} (right axis)"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(1)));
    }
    if left.iter().chain(&right).any(|s| !s.2.is_empty()) {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font((FONT, 13))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(180, 180, 180))
            .draw()
            .map_err(err)?;
    }
    Ok(())
}

/// Width of a plot in pixels.
pub const PLOT_WIDTH: u32 = 800;
/// Height of one panel in pixels.
pub const PANEL_HEIGHT: u32 = 300;

/// Draw `panels` stacked vertically, sharing the x label, and write them to `path` (PNG,
/// atomically).
pub fn plot(path: &Path, x_label: &str, panels: &[Panel]) -> Result<()> {
    register_font()?;
    let (w, h) = (PLOT_WIDTH, PANEL_HEIGHT * panels.len().max(1) as u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        let areas = root.split_evenly((panels.len().max(1), 1));
        for (area, panel) in areas.iter().zip(panels) {
            draw_panel(area, x_label, panel)?;
        }
        root.present().map_err(err)?;
    }
    let img = RgbImage::from_raw(w, h, buf).ok_or_else(|| err("buffer size"))?;
    save_png(path, &img)
}

/// Write `img` to `path` as PNG, atomically.
pub fn save_png(path: &Path, img: &RgbImage) -> Result<()> {
    write_atomic_with(path, |tmp| {
        img.save_with_format(tmp, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })
    .map_err(|e| Error::file(path, e.to_string()))
}

/// Tiles side by side on white, each under its caption (drawn with the embedded font).
pub fn captioned_row(tiles: &[(String, RgbImage)]) -> Result<RgbImage> {
    register_font()?;
    let (gap, header) = (6u32, 20u32);
    let col = |t: &(String, RgbImage)| t.1.width().max(7 * t.0.chars().count() as u32);
    let w: u32 = tiles.iter().map(|t| col(t) + gap).sum::<u32>() + gap;
    let h = tiles.iter().map(|t| t.1.height()).max().unwrap_or(0) + header + gap;
    let mut out = RgbImage::from_pixel(w, h, image::Rgb([255, 255, 255]));
    let mut x = gap;
    for t in tiles {
        image::imageops::replace(&mut out, &t.1, x as i64, header as i64);
        x += col(t) + gap;
    }
    let (w, h) = out.dimensions();
    let mut buf = out.into_raw();
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        let mut x = gap as i32;
        for t in tiles {
            root.draw(&Text::new(
                t.0.as_str(),
                (x, 3),
                (FONT, 14).into_font().color(&BLACK),
            ))
            .map_err(err)?;
            x += (col(t) + gap) as i32;
        }
        root.present().map_err(err)?;
    }
    RgbImage::from_raw(w, h, buf).ok_or_else(|| err("buffer size"))
}
