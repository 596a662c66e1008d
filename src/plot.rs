//! PNG figures without system libraries: plotters' bitmap backend with an
//! embedded DejaVu Sans (its license is in `assets/fonts/`).
//!
//! [`LogLogChart`] draws the log-log plots of the Allan stage: lines, shaded
//! bands and markers, in data coordinates, with decade ticks.

use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::{Path, PathBuf};
use std::sync::Once;

/// Why a figure could not be written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// No finite point to draw (all series empty or non-finite).
    #[error("{}: nothing to plot (no finite points)", .0.display())]
    Empty(PathBuf),
    /// The drawing backend failed (e.g. the file cannot be written).
    #[error("{}: {message}", path.display())]
    Draw {
        /// The figure's file.
        path: PathBuf,
        /// The backend's message.
        message: String,
    },
}

impl PlotError {
    /// A drawing failure in words: what is wrong with the path when something
    /// is, else the backend's own message without its debug dump.
    fn draw(path: &Path, e: &dyn std::fmt::Display) -> PlotError {
        let message = figure_path_problem(path).unwrap_or_else(|| {
            let text = e.to_string();
            // plotters prints the image crate's error with {:?}: keep its io message.
            match text.split_once("message: \"").and_then(|(_, m)| m.split_once('"')) {
                Some((m, _)) => format!("cannot write the figure: {m}"),
                None => format!("cannot draw the figure: {}", text.split(':').next_back().unwrap_or(&text).trim()),
            }
        });
        PlotError::Draw { path: path.to_path_buf(), message }
    }
}

/// What keeps a PNG from being written at `path`, if anything visible
/// beforehand: an extension other than `.png`, a folder that does not exist.
pub fn figure_path_problem(path: &Path) -> Option<String> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if ext.as_deref() != Some("png") {
        return Some(format!(
            "figures are PNG images: give a file name ending in .png (got {})",
            ext.map_or("no extension".to_string(), |e| format!(".{e}"))
        ));
    }
    let parent = path.parent().filter(|p| !p.as_os_str().is_empty())?;
    (!parent.is_dir()).then(|| format!("cannot write the figure: the folder {} does not exist", parent.display()))
}

static FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");

/// Register the embedded font as "sans-serif" (once per process).
pub fn ensure_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The font is a known-good TTF compiled into the binary.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

/// Colors of the x, y and z axes (red, green, blue, slightly darkened).
pub const AXIS_COLORS: [RGBColor; 3] = [RGBColor(214, 39, 40), RGBColor(44, 160, 44), RGBColor(31, 119, 180)];

/// One item on a log-log chart.
pub enum Layer {
    /// A polyline with a legend label (empty label: no legend entry).
    Line {
        /// Vertices (x, y) in data coordinates.
        points: Vec<(f64, f64)>,
        /// Line color.
        color: RGBColor,
        /// Line width \[px\].
        width: u32,
        /// Legend label.
        label: String,
    },
    /// A shaded band between lower and upper values at the same abscissae.
    Band {
        /// Abscissae in data coordinates.
        x: Vec<f64>,
        /// Lower edge at each abscissa.
        lo: Vec<f64>,
        /// Upper edge at each abscissa.
        hi: Vec<f64>,
        /// Fill color (drawn translucent).
        color: RGBColor,
    },
    /// Markers (circles) with a legend label.
    Points {
        /// Marker positions (x, y) in data coordinates.
        points: Vec<(f64, f64)>,
        /// Marker color.
        color: RGBColor,
        /// Legend label.
        label: String,
    },
}

/// A log-log chart description.
pub struct LogLogChart {
    /// Title on top.
    pub title: String,
    /// Label of the horizontal axis.
    pub x_label: String,
    /// Label of the vertical axis.
    pub y_label: String,
    /// What to draw, in order.
    pub layers: Vec<Layer>,
}

fn finite_positive(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

impl LogLogChart {
    /// Render to a PNG file of `width`×`height` pixels.
    pub fn write_png(&self, path: &Path, width: u32, height: u32) -> Result<(), PlotError> {
        ensure_font();
        let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64);
        let mut grow = |x: f64, y: f64| {
            if finite_positive(x) && finite_positive(y) {
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y);
            }
        };
        for l in &self.layers {
            match l {
                Layer::Line { points, .. } | Layer::Points { points, .. } => {
                    points.iter().for_each(|&(x, y)| grow(x, y))
                }
                Layer::Band { x, lo, hi, .. } => {
                    for i in 0..x.len() {
                        grow(x[i], lo[i]);
                        grow(x[i], hi[i]);
                    }
                }
            }
        }
        if !(x0 < x1 && y0 < y1) {
            return Err(PlotError::Empty(path.to_path_buf()));
        }
        // Whole decades around the data.
        let (x0, x1) = (10f64.powf(x0.log10().floor()), 10f64.powf(x1.log10().ceil()));
        let (y0, y1) = (10f64.powf(y0.log10().floor()), 10f64.powf(y1.log10().ceil()));
        let err = |e: &dyn std::fmt::Display| PlotError::draw(path, e);
        let root = BitMapBackend::new(path, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(&self.title, ("sans-serif", 22))
            .margin(14)
            .x_label_area_size(48)
            .y_label_area_size(78)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .x_label_formatter(&|v| format!("{v:.0e}"))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(|e| err(&e))?;
        let inside = |&(x, y): &(f64, f64)| finite_positive(x) && finite_positive(y);
        for l in &self.layers {
            match l {
                Layer::Band { x, lo, hi, color } => {
                    let mut poly: Vec<(f64, f64)> =
                        x.iter().zip(lo).map(|(&a, &b)| (a, b.max(y0))).filter(inside).collect();
                    poly.extend(x.iter().zip(hi).rev().map(|(&a, &b)| (a, b.min(y1))).filter(inside));
                    chart.draw_series(std::iter::once(Polygon::new(poly, color.mix(0.18)))).map_err(|e| err(&e))?;
                }
                Layer::Line { points, color, width, label } => {
                    let pts: Vec<(f64, f64)> = points.iter().copied().filter(inside).collect();
                    let s = chart.draw_series(LineSeries::new(pts, color.stroke_width(*width))).map_err(|e| err(&e))?;
                    if !label.is_empty() {
                        let c = *color;
                        s.label(label.as_str())
                            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2)));
                    }
                }
                Layer::Points { points, color, label } => {
                    let pts: Vec<(f64, f64)> = points.iter().copied().filter(inside).collect();
                    let c = *color;
                    let s = chart
                        .draw_series(pts.into_iter().map(move |p| Circle::new(p, 5, c.stroke_width(2))))
                        .map_err(|e| err(&e))?;
                    if !label.is_empty() {
                        s.label(label.as_str()).legend(move |(x, y)| Circle::new((x + 9, y), 5, c.stroke_width(2)));
                    }
                }
            }
        }
        finish(chart, &root, path)
    }
}

/// Draw the legend (upper right) and write the file.
fn finish<'a, DB, CT>(
    chart: ChartContext<'a, DB, CT>,
    root: &DrawingArea<DB, plotters::coord::Shift>,
    path: &Path,
) -> Result<(), PlotError>
where
    DB: DrawingBackend + 'a,
    CT: plotters::coord::CoordTranslate,
{
    legend(chart, path)?;
    root.present().map_err(|e| PlotError::draw(path, &e))
}

/// Draw the legend (upper right) of a chart.
fn legend<'a, DB, CT>(mut chart: ChartContext<'a, DB, CT>, path: &Path) -> Result<(), PlotError>
where
    DB: DrawingBackend + 'a,
    CT: plotters::coord::CoordTranslate,
{
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .label_font(("sans-serif", 13))
        .draw()
        .map_err(|e| PlotError::draw(path, &e))?;
    Ok(())
}

/// One set of markers or a polyline on a [`ScatterChart`].
#[derive(Clone, Default)]
pub struct Series {
    /// Legend label (empty: none).
    pub label: String,
    /// Color.
    pub color: RGBColor,
    /// Points in data coordinates.
    pub points: Vec<(f64, f64)>,
    /// Join the points with a line instead of drawing markers.
    pub line: bool,
}

/// A shaded band `(x, lo, hi)` on a [`ScatterChart`], drawn under the series.
#[derive(Clone, Default)]
pub struct Band {
    /// Color (drawn at 20 % opacity).
    pub color: RGBColor,
    /// `(x, lower, upper)` in data coordinates, ordered by x.
    pub points: Vec<(f64, f64, f64)>,
}

/// A chart with linear axes: shaded bands, markers or polylines.
#[derive(Clone, Default)]
pub struct ScatterChart {
    /// Title on top.
    pub title: String,
    /// Label of the horizontal axis.
    pub x_label: String,
    /// Label of the vertical axis.
    pub y_label: String,
    /// What to draw, in order.
    pub series: Vec<Series>,
    /// Bands drawn before the series.
    pub bands: Vec<Band>,
    /// Same scale on both axes (top views of trajectories).
    pub equal_aspect: bool,
}

fn finite2(p: &(f64, f64)) -> bool {
    p.0.is_finite() && p.1.is_finite()
}

/// Tick labels that suit the axis range: plain decimals for 0.01–10⁴, scientific otherwise.
fn tick_format(lo: f64, hi: f64) -> impl Fn(&f64) -> String {
    let m = lo.abs().max(hi.abs());
    let span = hi - lo;
    let plain = (1e-2..1e4).contains(&m);
    let digits = if span > 0.0 { (2.0 - span.log10().floor()).clamp(0.0, 4.0) as usize } else { 3 };
    move |v: &f64| {
        let label = if plain { format!("{v:.digits$}") } else { format!("{v:.2e}") };
        // A tick just below zero would read "-0.000".
        match label.strip_prefix('-') {
            Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
            _ => label,
        }
    }
}

impl ScatterChart {
    /// The axis ranges: the finite data with 5 % margins (widened to equal scales when asked).
    fn ranges(&self, width: u32, height: u32) -> Option<((f64, f64), (f64, f64))> {
        let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
        let mut grow = |x: f64, y: f64| {
            if x.is_finite() && y.is_finite() {
                (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
            }
        };
        self.series.iter().flat_map(|s| s.points.iter()).for_each(|&(x, y)| grow(x, y));
        for &(x, lo, hi) in self.bands.iter().flat_map(|b| b.points.iter()) {
            grow(x, lo);
            grow(x, hi);
        }
        if !(x0.is_finite() && y0.is_finite()) {
            return None;
        }
        let pad = |a: f64, b: f64| {
            let d = if b > a { 0.05 * (b - a) } else { 0.5 * a.abs().max(1e-12) };
            (a - d, b + d)
        };
        let ((mut x0, mut x1), (mut y0, mut y1)) = (pad(x0, x1), pad(y0, y1));
        if self.equal_aspect {
            // Plot area ≈ the image minus the label areas and margins.
            let (pw, ph) = ((width as f64 - 120.0).max(1.0), (height as f64 - 100.0).max(1.0));
            let scale = ((x1 - x0) / pw).max((y1 - y0) / ph);
            let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
            (x0, x1, y0, y1) =
                (cx - 0.5 * scale * pw, cx + 0.5 * scale * pw, cy - 0.5 * scale * ph, cy + 0.5 * scale * ph);
        }
        Some(((x0, x1), (y0, y1)))
    }

    /// Draw onto an area of a bitmap (`path` only names errors).
    fn draw_on(&self, area: &DrawingArea<BitMapBackend, plotters::coord::Shift>, path: &Path) -> Result<(), PlotError> {
        let (width, height) = area.dim_in_pixel();
        let ((x0, x1), (y0, y1)) = self.ranges(width, height).ok_or_else(|| PlotError::Empty(path.to_path_buf()))?;
        let err = |e: &dyn std::fmt::Display| PlotError::draw(path, e);
        let mut chart = ChartBuilder::on(area)
            .caption(&self.title, ("sans-serif", 20))
            .margin(14)
            .x_label_area_size(48)
            .y_label_area_size(78)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| err(&e))?;
        let (fx, fy) = (tick_format(x0, x1), tick_format(y0, y1));
        chart
            .configure_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .x_label_formatter(&fx)
            .y_label_formatter(&fy)
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(|e| err(&e))?;
        for b in &self.bands {
            let pts: Vec<(f64, f64)> = b
                .points
                .iter()
                .map(|p| (p.0, p.1))
                .chain(b.points.iter().rev().map(|p| (p.0, p.2)))
                .filter(finite2)
                .collect();
            chart.draw_series(std::iter::once(Polygon::new(pts, b.color.mix(0.2).filled()))).map_err(|e| err(&e))?;
        }
        for s in &self.series {
            let c = s.color;
            let pts: Vec<(f64, f64)> = s.points.iter().copied().filter(finite2).collect();
            let drawn = if s.line {
                // plotters draws a 2 px polyline segment by segment, which leaves
                // gaps where segments are shorter than a pixel: dense lines get 1 px.
                let width = if pts.len() as u32 > width { 1 } else { 2 };
                chart.draw_series(LineSeries::new(pts, c.stroke_width(width))).map_err(|e| err(&e))?
            } else {
                chart.draw_series(pts.into_iter().map(move |p| Circle::new(p, 3, c.filled()))).map_err(|e| err(&e))?
            };
            if s.label.is_empty() {
                continue;
            }
            let drawn = drawn.label(s.label.as_str());
            if s.line {
                drawn.legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2)));
            } else {
                drawn.legend(move |(x, y)| Circle::new((x + 9, y), 4, c.filled()));
            }
        }
        if self.series.iter().any(|s| !s.label.is_empty()) {
            legend(chart, path)?;
        }
        Ok(())
    }

    /// Render to a PNG file of `width`×`height` pixels (axes span the finite data, with 5 % margins).
    pub fn write_png(&self, path: &Path, width: u32, height: u32) -> Result<(), PlotError> {
        write_panels(path, std::slice::from_ref(self), width, height)
    }
}

/// Render charts stacked vertically into one PNG of `width`×`height` pixels.
pub fn write_panels(path: &Path, charts: &[ScatterChart], width: u32, height: u32) -> Result<(), PlotError> {
    ensure_font();
    if charts.is_empty() {
        return Err(PlotError::Empty(path.to_path_buf()));
    }
    let err = |e: &dyn std::fmt::Display| PlotError::draw(path, e);
    let root = BitMapBackend::new(path, (width, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    for (chart, area) in charts.iter().zip(root.split_evenly((charts.len(), 1))) {
        chart.draw_on(&area, path)?;
    }
    root.present().map_err(|e| err(&e))
}

#[cfg(test)]
mod tests {
    use super::{tick_format, PlotError};
    use std::path::Path;

    #[test]
    fn tick_labels_never_read_minus_zero() {
        let f = tick_format(-0.1, 0.1);
        assert_eq!(f(&-1e-9), "0.000");
        assert_eq!(f(&-0.05), "-0.050");
    }

    #[test]
    fn figure_errors_are_words_not_debug_dumps() {
        for (path, want) in [
            ("/nonexistent-tumble-dir/x.png", "does not exist"),
            ("/tmp/x.txt", "give a file name ending in .png"),
            ("/tmp/x", "no extension"),
        ] {
            let e = PlotError::draw(Path::new(path), &"Drawing backend error: ImageError(IoError(Os { code: 2 }))");
            let m = e.to_string();
            assert!(m.contains(want) && !m.contains("Os {"), "{path}: {m}");
        }
        let e = PlotError::draw(
            Path::new("/tmp/ok.png"),
            &"backend error: Drawing backend error: ImageError(IoError(Os { code: 13, kind: PermissionDenied, message: \"Permission denied\" }))",
        );
        assert_eq!(e.to_string(), "/tmp/ok.png: cannot write the figure: Permission denied");
    }
}
