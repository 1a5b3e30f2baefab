//! The figure: a row of panels per metric (success rate, return), a column per x axis (env
//! steps, wall time), the runs overlaid in each and named in one legend above them. Rendered in
//! memory (PNG or SVG bytes) so that the caller can write the file atomically.

use super::series::{Curve, Metric, Point};
use anyhow::{Result, anyhow, bail};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::Path;

const FONT: &str = "sans-serif";
const PANEL_WIDTH: u32 = 620;
const PANEL_HEIGHT: u32 = 430;
/// Tableau 10: distinguishable, and readable on white.
pub(super) const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// Registers the embedded font as `sans-serif`. plotters' `ab_glyph` text needs a registered
/// font for every text, SVG layout included; embedding one means no system fonts are needed.
pub fn register_fonts() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // A font shipped in a crate cannot be malformed; if it were, text errors name it.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, notosans::REGULAR_TTF);
    });
}

/// The output format, chosen by the file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Png,
    Svg,
}

impl Format {
    pub fn from_path(path: &Path) -> Result<Self> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        match ext.as_deref() {
            Some("png") => Ok(Format::Png),
            Some("svg") => Ok(Format::Svg),
            _ => bail!(
                "{}: unknown figure format; the file name must end in .png or .svg",
                path.display()
            ),
        }
    }
}

/// Which x axes get a column of panels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum XAxis {
    Steps,
    Time,
    Both,
}

impl XAxis {
    fn columns(self) -> &'static [XAxis] {
        match self {
            XAxis::Steps => &[XAxis::Steps],
            XAxis::Time => &[XAxis::Time],
            XAxis::Both => &[XAxis::Steps, XAxis::Time],
        }
    }
}

/// One run as drawn: its legend label and its curves (already smoothed).
pub struct RunCurves {
    pub label: String,
    pub success: Option<Curve>,
    pub ret: Option<Curve>,
}

impl RunCurves {
    fn curve(&self, metric: Metric) -> Option<&Curve> {
        match metric {
            Metric::Success => self.success.as_ref(),
            Metric::Return => self.ret.as_ref(),
        }
    }
}

pub struct Figure<'a> {
    pub runs: &'a [RunCurves],
    pub x: XAxis,
    pub title: Option<&'a str>,
    /// The moving-average window the curves were smoothed with (named in the captions).
    pub smooth: usize,
}

impl Figure<'_> {
    pub fn size(&self) -> (u32, u32) {
        let columns = self.x.columns().len() as u32;
        (PANEL_WIDTH * columns, PANEL_HEIGHT * 2 + 120)
    }

    /// The figure as the bytes of a PNG or SVG file.
    pub fn render(&self, format: Format) -> Result<Vec<u8>> {
        register_fonts();
        let (w, h) = self.size();
        match format {
            Format::Png => {
                let mut rgb = vec![0u8; w as usize * h as usize * 3];
                {
                    let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
                    self.draw(&root)?;
                    root.present().map_err(plot_error)?;
                }
                encode_png(&rgb, w, h)
            }
            Format::Svg => {
                let mut svg = String::new();
                {
                    let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
                    self.draw(&root)?;
                    root.present().map_err(plot_error)?;
                }
                Ok(svg.into_bytes())
            }
        }
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<()> {
        root.fill(&WHITE).map_err(plot_error)?;
        let mut area = root.clone();
        if let Some(title) = self.title {
            area = area
                .titled(title, (FONT, 26).into_font().color(&BLACK))
                .map_err(plot_error)?;
        }
        let legend_height = self.draw_legend(&area)?;
        let (_, body) = area.split_vertically(legend_height);
        let columns = self.x.columns();
        let panels = body.split_evenly((2, columns.len()));
        let cells = Metric::ALL
            .iter()
            .flat_map(|m| columns.iter().map(move |x| (*m, *x)));
        for (panel, (metric, x)) in panels.iter().zip(cells) {
            self.draw_panel(panel, metric, x)?;
        }
        Ok(())
    }

    /// Draws the legend (a line sample and the label of each run, wrapped into centred rows) at
    /// the top of `area`; returns its height.
    fn draw_legend<DB: DrawingBackend>(&self, area: &DrawingArea<DB, Shift>) -> Result<u32> {
        const SAMPLE: i32 = 32;
        const ROW: i32 = 28;
        let style = (FONT, 19).into_font().color(&BLACK);
        let (width, _) = area.dim_in_pixel();
        let max_row = width as i32 - 40;
        let mut rows: Vec<Vec<(usize, i32)>> = vec![Vec::new()];
        let mut row_width = 0;
        for (i, run) in self.runs.iter().enumerate() {
            let (text_width, _) = area
                .estimate_text_size(&run.label, &style)
                .map_err(plot_error)?;
            let entry = SAMPLE + 8 + text_width as i32 + 30;
            if row_width > 0 && row_width + entry > max_row {
                rows.push(Vec::new());
                row_width = 0;
            }
            rows.last_mut().expect("one row").push((i, entry));
            row_width += entry;
        }
        for (r, row) in rows.iter().enumerate() {
            let total: i32 = row.iter().map(|(_, w)| w).sum();
            let mut x = (width as i32 - total) / 2;
            let y = 12 + ROW / 2 + r as i32 * ROW;
            for (i, entry) in row {
                let colour = PALETTE[i % PALETTE.len()];
                area.draw(&PathElement::new(
                    vec![(x, y), (x + SAMPLE, y)],
                    colour.stroke_width(3),
                ))
                .map_err(plot_error)?;
                area.draw(&Text::new(
                    self.runs[*i].label.clone(),
                    (x + SAMPLE + 8, y),
                    style.pos(Pos::new(HPos::Left, VPos::Center)),
                ))
                .map_err(plot_error)?;
                x += entry;
            }
        }
        Ok((12 + rows.len() as i32 * ROW + 8) as u32)
    }

    fn draw_panel<DB: DrawingBackend>(
        &self,
        panel: &DrawingArea<DB, Shift>,
        metric: Metric,
        x: XAxis,
    ) -> Result<()> {
        let curves: Vec<(usize, &Curve)> = self
            .runs
            .iter()
            .enumerate()
            .filter_map(|(i, r)| Some((i, r.curve(metric)?)))
            .collect();
        let all = || curves.iter().flat_map(|(_, c)| c.points.iter());
        let unit = XUnit::for_axis(x, all().map(|p| x_raw(x, p)).fold(0.0, f64::max));
        let x_max = all().map(|p| unit.of(x, p)).fold(0.0, f64::max);
        let x_hi = if x_max > 0.0 { x_max * 1.02 } else { 1.0 };
        let (y_range, y_desc, scale) = match metric {
            Metric::Success => (-2.0..102.0, "success rate (%)", 100.0),
            Metric::Return => {
                let (lo, hi) = all().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                    (lo.min(p.value), hi.max(p.value))
                });
                let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) };
                let pad = ((hi - lo) * 0.05).max(0.5);
                (lo - pad..hi + pad, "mean episode return", 1.0)
            }
        };
        let smoothed = match self.smooth {
            0 | 1 => String::new(),
            n => format!(", mean of {n}"),
        };
        let caption = format!(
            "{} ({}{smoothed}) against {}",
            match metric {
                Metric::Success => "Success rate",
                Metric::Return => "Return",
            },
            source(&curves),
            match x {
                XAxis::Time => "wall time",
                _ => "environment steps",
            }
        );
        let mut chart = ChartBuilder::on(panel)
            .caption(caption, (FONT, 19))
            .margin(14)
            .x_label_area_size(48)
            .y_label_area_size(64)
            .build_cartesian_2d(0.0..x_hi, y_range)
            .map_err(plot_error)?;
        chart
            .configure_mesh()
            .x_desc(unit.desc)
            .y_desc(y_desc)
            .x_labels(7)
            .y_labels(7)
            .x_label_formatter(&tick)
            .y_label_formatter(&tick)
            .label_style((FONT, 15))
            .axis_desc_style((FONT, 17))
            .light_line_style(RGBColor(244, 244, 244))
            .bold_line_style(RGBColor(215, 215, 215))
            .draw()
            .map_err(plot_error)?;
        for (i, curve) in &curves {
            let colour = PALETTE[i % PALETTE.len()];
            let xy = |p: &Point| (unit.of(x, p), p.value * scale);
            chart
                .draw_series(LineSeries::new(
                    curve.points.iter().map(xy),
                    colour.stroke_width(2),
                ))
                .map_err(plot_error)?;
            // Sparse curves (evaluations) get markers, so single points and gaps show.
            if curve.points.len() <= 80 {
                chart
                    .draw_series(
                        curve
                            .points
                            .iter()
                            .map(|p| Circle::new(xy(p), 3, colour.filled())),
                    )
                    .map_err(plot_error)?;
            }
        }
        Ok(())
    }
}

/// Where a panel's values come from, for its caption.
fn source(curves: &[(usize, &Curve)]) -> &'static str {
    let eval = curves
        .iter()
        .filter(|(_, c)| c.column.starts_with("eval/"))
        .count();
    match (eval, curves.len() - eval) {
        (_, 0) => "evaluation",
        (0, _) => "training episodes",
        _ => "evaluation, else training episodes",
    }
}

fn x_raw(x: XAxis, p: &Point) -> f64 {
    match x {
        XAxis::Time => p.seconds,
        _ => p.steps,
    }
}

/// The unit of an x axis, chosen so that its labels stay short.
struct XUnit {
    divisor: f64,
    desc: &'static str,
}

impl XUnit {
    fn for_axis(x: XAxis, max: f64) -> Self {
        let (divisor, desc) = match x {
            XAxis::Time if max >= 3.0 * 3600.0 => (3600.0, "wall time (h)"),
            XAxis::Time if max >= 120.0 => (60.0, "wall time (min)"),
            XAxis::Time => (1.0, "wall time (s)"),
            _ if max >= 1e6 => (1e6, "environment steps (millions)"),
            _ if max >= 1e4 => (1e3, "environment steps (thousands)"),
            _ => (1.0, "environment steps"),
        };
        Self { divisor, desc }
    }

    fn of(&self, x: XAxis, p: &Point) -> f64 {
        x_raw(x, p) / self.divisor
    }
}

/// A tick label without trailing zeros ("100", "2.5"), where plotters would print "100.0".
fn tick(v: &f64) -> String {
    let text = format!("{v:.3}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    if text == "-0" {
        "0".into()
    } else {
        text.into()
    }
}

fn plot_error(e: impl std::fmt::Display) -> anyhow::Error {
    anyhow!("drawing the figure: {e}")
}

fn encode_png(rgb: &[u8], w: u32, h: u32) -> Result<Vec<u8>> {
    let mut bytes = Vec::new();
    let mut encoder = png::Encoder::new(&mut bytes, w, h);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    // Figures go into docs and git: a few ms more for a file several times smaller.
    encoder.set_compression(png::Compression::High);
    encoder.set_filter(png::Filter::Adaptive);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(rgb)?;
    writer.finish()?;
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_drop_trailing_zeros() {
        let labels: Vec<String> = [100.0, 2.5, -20.0, 0.125, -0.0, 0.0001]
            .iter()
            .map(tick)
            .collect();
        assert_eq!(labels, ["100", "2.5", "-20", "0.125", "0", "0"]);
    }
}
