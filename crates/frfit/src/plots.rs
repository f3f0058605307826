//! SVG figures (plotters, SVG backend only): the CMIF with picked modes (Fig. 3 of the
//! wafer-stage paper), Bode magnitude grids of data and model, one entry with data, model
//! and residual against the noise.
//!
//! The building blocks are reusable:
//!
//! - [`LinePlot`]: one panel with a linear or logarithmic [`Axis`] each way, any number of
//!   [`Series`] (lines, dashed lines, points) and labelled [`Marker`]s;
//! - [`PlotGrid`]: panels in rows and columns under one title;
//! - ready-made figures: [`cmif_plot`] / [`cmif_svg`], [`magnitude_grid`] and
//!   [`entry_overlay`].
//!
//! Values that a log axis cannot show (zero, negative, non-finite) break the line
//! instead of failing; axis ranges are taken from the data unless given.

use crate::FrfitError;
use frf_data::cmif::{Cmif, CmifPeak};
use frf_data::FrfDataset;
use plotters::coord::ranged1d::{AsRangedCoord, Ranged, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::Path;

/// Colours of successive series (the "tab10" palette).
pub const PALETTE: [(u8, u8, u8); 10] = [
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
];

/// Linear or base-10 logarithmic axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    /// Linear.
    Linear,
    /// Logarithmic (only positive values are drawn).
    Log,
}

/// One axis: label, scale and an optional fixed range.
#[derive(Debug, Clone, PartialEq)]
pub struct Axis {
    /// Axis label, e.g. `"Frequency [Hz]"`.
    pub label: String,
    /// Linear or log.
    pub scale: Scale,
    /// Fixed `(min, max)`; `None` takes the range of the data (with a small margin).
    pub range: Option<(f64, f64)>,
}

impl Axis {
    /// A logarithmic axis with a label and an automatic range.
    pub fn log(label: impl Into<String>) -> Self {
        Self {
            label: label.into(),
            scale: Scale::Log,
            range: None,
        }
    }
    /// A linear axis with a label and an automatic range.
    pub fn linear(label: impl Into<String>) -> Self {
        Self {
            label: label.into(),
            scale: Scale::Linear,
            range: None,
        }
    }
    /// The same axis with a fixed range.
    pub fn with_range(mut self, lo: f64, hi: f64) -> Self {
        self.range = Some((lo, hi));
        self
    }
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SeriesKind {
    /// A solid line.
    Line,
    /// A dashed line.
    Dashed,
    /// Dots, one per point.
    Points,
}

/// One series of points `(x[i], y[i])`.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend entry (an empty name is left out of the legend).
    pub name: String,
    /// Abscissae.
    pub x: Vec<f64>,
    /// Ordinates (same length as `x`; extra values of either are ignored).
    pub y: Vec<f64>,
    /// Line or point style.
    pub kind: SeriesKind,
    /// RGB colour; `None` takes the next colour of [`PALETTE`].
    pub color: Option<(u8, u8, u8)>,
    /// Line width or dot radius, pixels.
    pub width: u32,
}

impl Series {
    /// A solid line.
    pub fn line(name: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Self {
        Self {
            name: name.into(),
            x,
            y,
            kind: SeriesKind::Line,
            color: None,
            width: 1,
        }
    }
    /// A dashed line.
    pub fn dashed(name: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Self {
        Self {
            kind: SeriesKind::Dashed,
            ..Self::line(name, x, y)
        }
    }
    /// Dots.
    pub fn points(name: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Self {
        Self {
            kind: SeriesKind::Points,
            width: 2,
            ..Self::line(name, x, y)
        }
    }
    /// The same series in colour `rgb`.
    pub fn with_color(mut self, rgb: (u8, u8, u8)) -> Self {
        self.color = Some(rgb);
        self
    }
    /// The same series with line width (or dot radius) `w` pixels.
    pub fn with_width(mut self, w: u32) -> Self {
        self.width = w.max(1);
        self
    }
}

/// A labelled dot, e.g. a picked mode.
#[derive(Debug, Clone, PartialEq)]
pub struct Marker {
    /// Abscissa.
    pub x: f64,
    /// Ordinate.
    pub y: f64,
    /// Text written next to the dot.
    pub label: Option<String>,
    /// RGB colour (default black).
    pub color: Option<(u8, u8, u8)>,
}

/// One panel: title, axes, series and markers.
#[derive(Debug, Clone, PartialEq)]
pub struct LinePlot {
    /// Panel title (empty for none).
    pub title: String,
    /// Horizontal axis.
    pub x: Axis,
    /// Vertical axis.
    pub y: Axis,
    /// The series, drawn in order.
    pub series: Vec<Series>,
    /// Dots with labels, drawn on top.
    pub markers: Vec<Marker>,
    /// Draw a legend of the named series.
    pub legend: bool,
    /// Where the legend goes.
    pub legend_corner: Corner,
}

/// A corner of a panel (for the legend).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Corner {
    /// Top right (the default).
    #[default]
    UpperRight,
    /// Top left.
    UpperLeft,
    /// Bottom left.
    LowerLeft,
    /// Bottom right.
    LowerRight,
}

impl LinePlot {
    /// A Bode-magnitude style panel: log frequency in Hz against a log magnitude.
    pub fn new(title: impl Into<String>) -> Self {
        Self {
            title: title.into(),
            x: Axis::log("Frequency [Hz]"),
            y: Axis::log("Magnitude"),
            series: Vec::new(),
            markers: Vec::new(),
            legend: true,
            legend_corner: Corner::UpperRight,
        }
    }
    /// Replaces the horizontal axis.
    pub fn with_x(mut self, axis: Axis) -> Self {
        self.x = axis;
        self
    }
    /// Replaces the vertical axis.
    pub fn with_y(mut self, axis: Axis) -> Self {
        self.y = axis;
        self
    }
    /// Adds a series.
    pub fn with_series(mut self, s: Series) -> Self {
        self.series.push(s);
        self
    }
    /// Adds a marker.
    pub fn with_marker(mut self, m: Marker) -> Self {
        self.markers.push(m);
        self
    }

    /// Writes this panel alone to an SVG file of `size` pixels.
    pub fn write_svg(&self, path: impl AsRef<Path>, size: (u32, u32)) -> Result<(), FrfitError> {
        let path = path.as_ref();
        let root = SVGBackend::new(path, size).into_drawing_area();
        let res = root
            .fill(&WHITE)
            .map_err(|e| e.to_string())
            .and_then(|_| self.draw(&root))
            .and_then(|_| root.present().map_err(|e| e.to_string()));
        res.map_err(|message| plot_error(path, message))
    }

    /// Draws the panel on a drawing area (of an SVG, or a cell of a [`PlotGrid`]).
    pub fn draw(&self, area: &DrawingArea<SVGBackend<'_>, Shift>) -> Result<(), String> {
        let (x0, x1) = axis_range(
            &self.x,
            self.series.iter().map(|s| &s.x),
            &self.markers,
            true,
        );
        let (y0, y1) = axis_range(
            &self.y,
            self.series.iter().map(|s| &s.y),
            &self.markers,
            false,
        );
        let (xb, xl) = log_ticks(x0, x1);
        let (yb, yl) = log_ticks(y0, y1);
        match (self.x.scale, self.y.scale) {
            (Scale::Log, Scale::Log) => self.draw_in(
                area,
                (x0..x1)
                    .log_scale()
                    .with_key_points(xb)
                    .with_light_points(xl),
                (y0..y1)
                    .log_scale()
                    .with_key_points(yb)
                    .with_light_points(yl),
            ),
            // Linear axes keep plotters' own (good) tick choice.
            (Scale::Log, Scale::Linear) => self.draw_in(
                area,
                (x0..x1)
                    .log_scale()
                    .with_key_points(xb)
                    .with_light_points(xl),
                y0..y1,
            ),
            (Scale::Linear, Scale::Log) => self.draw_in(
                area,
                x0..x1,
                (y0..y1)
                    .log_scale()
                    .with_key_points(yb)
                    .with_light_points(yl),
            ),
            (Scale::Linear, Scale::Linear) => self.draw_in(area, x0..x1, y0..y1),
        }
    }

    fn draw_in<XR, YR>(
        &self,
        area: &DrawingArea<SVGBackend<'_>, Shift>,
        xr: XR,
        yr: YR,
    ) -> Result<(), String>
    where
        XR: AsRangedCoord<Value = f64>,
        YR: AsRangedCoord<Value = f64>,
        XR::CoordDescType: Ranged<ValueType = f64> + ValueFormatter<f64>,
        YR::CoordDescType: Ranged<ValueType = f64> + ValueFormatter<f64>,
    {
        let err = |e: DrawingAreaErrorKind<_>| e.to_string();
        let (w, h) = area.dim_in_pixel();
        let small = w < 500 || h < 300;
        let font = if small { 11 } else { 14 };
        let mut builder = ChartBuilder::on(area);
        builder
            .margin(if small { 4 } else { 10 })
            .margin_right(if small { 14 } else { 28 })
            .x_label_area_size(if small { 30 } else { 45 })
            .y_label_area_size(if small { 52 } else { 70 });
        if !self.title.is_empty() {
            builder.caption(&self.title, ("sans-serif", font + 3));
        }
        let mut chart = builder.build_cartesian_2d(xr, yr).map_err(err)?;
        let x_log = self.x.scale == Scale::Log;
        let y_log = self.y.scale == Scale::Log;
        let xf = |v: &f64| fmt_tick(*v);
        let yf = |v: &f64| fmt_tick(*v);
        chart
            .configure_mesh()
            .x_desc(self.x.label.as_str())
            .y_desc(self.y.label.as_str())
            .x_label_formatter(&xf)
            .y_label_formatter(&yf)
            .label_style(("sans-serif", font))
            .axis_desc_style(("sans-serif", font))
            .light_line_style(RGBColor(235, 235, 235))
            .bold_line_style(RGBColor(200, 200, 200))
            .draw()
            .map_err(err)?;
        let mut any_named = false;
        for (idx, s) in self.series.iter().enumerate() {
            let (r, g, b) = s.color.unwrap_or(PALETTE[idx % PALETTE.len()]);
            let color = RGBColor(r, g, b);
            let style = ShapeStyle::from(color).stroke_width(s.width);
            let segments = segments(s, x_log, y_log);
            let mut first = true;
            for seg in segments {
                let anno = match s.kind {
                    SeriesKind::Line => chart
                        .draw_series(LineSeries::new(seg, style))
                        .map_err(err)?,
                    SeriesKind::Dashed => chart
                        .draw_series(DashedLineSeries::new(seg, 6, 4, style))
                        .map_err(err)?,
                    SeriesKind::Points => chart
                        .draw_series(
                            seg.into_iter()
                                .map(|p| Circle::new(p, s.width, style.filled())),
                        )
                        .map_err(err)?,
                };
                if first && !s.name.is_empty() {
                    let kind = s.kind;
                    anno.label(s.name.as_str()).legend(move |(x, y)| {
                        if kind == SeriesKind::Points {
                            EmptyElement::at((x, y))
                                + Circle::new((10, 0), 3, style.filled()).into_dyn()
                        } else {
                            EmptyElement::at((x, y))
                                + PathElement::new(vec![(0, 0), (20, 0)], style).into_dyn()
                        }
                    });
                    any_named = true;
                }
                first = false;
            }
        }
        // Markers: dots, then labels placed in pixel space so that close labels do not
        // overlap (a label moves up until it clears the ones already placed).
        let mut placed: Vec<(i32, i32, i32, i32)> = Vec::new();
        let mut marks: Vec<&Marker> = self
            .markers
            .iter()
            .filter(|m| visible(m.x, x_log) && visible(m.y, y_log))
            .collect();
        marks.sort_by(|a, b| a.x.total_cmp(&b.x));
        for m in &marks {
            let (r, g, b) = m.color.unwrap_or((0, 0, 0));
            let c = RGBColor(r, g, b);
            chart
                .draw_series(std::iter::once(Circle::new((m.x, m.y), 3, c.filled())))
                .map_err(err)?;
        }
        let (ax0, ay0) = chart.plotting_area().get_base_pixel();
        for m in &marks {
            // The dots are obstacles for the labels.
            let (px, py) = chart.backend_coord(&(m.x, m.y));
            let (px, py) = (px - ax0, py - ay0);
            placed.push((px - 4, py - 4, px + 4, py + 4));
        }
        for m in &marks {
            let Some(text) = &m.label else { continue };
            let (px, py) = chart.backend_coord(&(m.x, m.y));
            let (px, py) = (px - ax0, py - ay0);
            let tw = (text.chars().count() as f64 * font as f64 * 0.55).ceil() as i32;
            let th = font + 2;
            let mut x = px - tw / 2;
            let mut y = py - 8 - th;
            let mut tries = 0;
            while tries < 12
                && placed
                    .iter()
                    .any(|&(a, b, c, d)| x < c && x + tw > a && y < d && y + th > b)
            {
                y -= th;
                tries += 1;
            }
            x = x.max(0);
            y = y.max(0);
            placed.push((x, y, x + tw, y + th));
            let (r, g, b) = m.color.unwrap_or((0, 0, 0));
            let text_color = RGBColor(r, g, b);
            let style = TextStyle::from(("sans-serif", font - 1).into_font()).color(&text_color);
            chart
                .plotting_area()
                .strip_coord_spec()
                .draw(&Text::new(text.clone(), (x, y), style))
                .map_err(err)?;
            if y + th < py - 8 {
                // A leader from a raised label to its dot.
                chart
                    .plotting_area()
                    .strip_coord_spec()
                    .draw(&PathElement::new(
                        vec![(px, y + th), (px, py - 4)],
                        ShapeStyle::from(RGBColor(150, 150, 150)).stroke_width(1),
                    ))
                    .map_err(err)?;
            }
        }
        if self.legend && any_named {
            chart
                .configure_series_labels()
                .position(match self.legend_corner {
                    Corner::UpperRight => SeriesLabelPosition::UpperRight,
                    Corner::UpperLeft => SeriesLabelPosition::UpperLeft,
                    Corner::LowerLeft => SeriesLabelPosition::LowerLeft,
                    Corner::LowerRight => SeriesLabelPosition::LowerRight,
                })
                .label_font(("sans-serif", font))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()
                .map_err(err)?;
        }
        Ok(())
    }
}

/// Panels in a grid under one title.
#[derive(Debug, Clone, PartialEq)]
pub struct PlotGrid {
    /// Title over the grid (empty for none).
    pub title: String,
    /// Number of rows.
    pub rows: usize,
    /// Number of columns.
    pub cols: usize,
    /// The panels, row after row (missing panels stay blank, extra ones are dropped).
    pub panels: Vec<LinePlot>,
    /// Size of one panel, pixels.
    pub panel_size: (u32, u32),
}

impl PlotGrid {
    /// Writes the grid to an SVG file.
    pub fn write_svg(&self, path: impl AsRef<Path>) -> Result<(), FrfitError> {
        let path = path.as_ref();
        let (rows, cols) = (self.rows.max(1), self.cols.max(1));
        let title_h = if self.title.is_empty() { 0 } else { 40 };
        let w = (self.panel_size.0 as usize * cols).min(20_000) as u32;
        let h = (self.panel_size.1 as usize * rows).min(20_000) as u32 + title_h;
        let root = SVGBackend::new(path, (w, h)).into_drawing_area();
        let run = || -> Result<(), String> {
            root.fill(&WHITE).map_err(|e| e.to_string())?;
            let body = if self.title.is_empty() {
                root.clone()
            } else {
                root.titled(&self.title, ("sans-serif", 22))
                    .map_err(|e| e.to_string())?
            };
            let cells = body.split_evenly((rows, cols));
            for (cell, panel) in cells.iter().zip(&self.panels) {
                panel.draw(cell)?;
            }
            root.present().map_err(|e| e.to_string())
        };
        run().map_err(|message| plot_error(path, message))
    }
}

fn plot_error(path: &Path, message: String) -> FrfitError {
    FrfitError::Plot {
        path: path.display().to_string(),
        message,
    }
}

fn visible(v: f64, log: bool) -> bool {
    v.is_finite() && (!log || v > 0.0)
}

/// Splits a series into runs of drawable points.
fn segments(s: &Series, x_log: bool, y_log: bool) -> Vec<Vec<(f64, f64)>> {
    let mut out = Vec::new();
    let mut cur = Vec::new();
    for (&x, &y) in s.x.iter().zip(&s.y) {
        if visible(x, x_log) && visible(y, y_log) {
            cur.push((x, y));
        } else if !cur.is_empty() {
            out.push(std::mem::take(&mut cur));
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// The range of an axis: the fixed one when valid, else that of the data with a margin
/// (5 % linear, 3 % of the decades on log axes; the frequency axis gets none).
fn axis_range<'a>(
    axis: &Axis,
    values: impl Iterator<Item = &'a Vec<f64>>,
    markers: &[Marker],
    is_x: bool,
) -> (f64, f64) {
    let log = axis.scale == Scale::Log;
    if let Some((a, b)) = axis.range {
        if visible(a, log) && visible(b, log) && b > a {
            return (a, b);
        }
    }
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    let mut take = |v: f64| {
        if visible(v, log) {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    };
    for vs in values {
        vs.iter().copied().for_each(&mut take);
    }
    for m in markers {
        take(if is_x { m.x } else { m.y });
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return if log { (1.0, 10.0) } else { (0.0, 1.0) };
    }
    if log && is_x {
        // Snap to a neighbouring 1-2-5 value within 3 % so that the ends get a label
        // (data on 20.25..1999.75 Hz show 20..2000 Hz).
        return (snap125(lo, false), snap125(hi, true));
    }
    if log {
        let (l, h) = (lo.log10(), hi.log10());
        let span = (h - l).max(1e-3);
        let pad = if is_x { 0.0 } else { 0.05 * span };
        let (l, h) = if h - l < 1e-3 {
            (l - 0.5, h + 0.5)
        } else {
            (l - pad, h + pad)
        };
        (10f64.powf(l), 10f64.powf(h))
    } else {
        let span = hi - lo;
        if span <= 0.0 {
            (lo - 1.0, hi + 1.0)
        } else {
            let pad = if is_x { 0.0 } else { 0.05 * span };
            (lo - pad, hi + pad)
        }
    }
}

/// Labelled (bold) and minor (light) tick positions of a log axis on `[lo, hi]`: with
/// up to about two decades, labels at 1, 2, 5 times powers of ten and minor lines at
/// every integer multiple; with more, labels at the decades (every second or third one
/// when there are many) and minor lines at the integer multiples while there are at most
/// six decades. (Empty for an invalid range; linear axes use plotters' ticks.)
fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    if !(lo > 0.0 && hi > lo && lo.is_finite() && hi.is_finite()) {
        return (Vec::new(), Vec::new());
    }
    let inside = |v: f64| v >= lo * (1.0 - 1e-12) && v <= hi * (1.0 + 1e-12);
    let (d0, d1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    let decades = hi.log10() - lo.log10();
    let stride = if decades <= 8.0 {
        1
    } else if decades <= 16.0 {
        2
    } else {
        3
    };
    let mut bold = Vec::new();
    let mut light = Vec::new();
    for d in d0..=d1 {
        let p = 10f64.powi(d);
        if decades <= 2.2 {
            for m in [1.0, 2.0, 5.0] {
                if inside(m * p) {
                    bold.push(m * p);
                }
            }
        } else if d.rem_euclid(stride) == 0 && inside(p) {
            bold.push(p);
        }
        if decades <= 6.0 {
            for m in 1..10 {
                let v = m as f64 * p;
                if inside(v) {
                    light.push(v);
                }
            }
        } else if inside(p) {
            light.push(p);
        }
    }
    if bold.len() < 2 {
        // Less than a decade with at most one 1-2-5 point inside: label the minor lines.
        bold = light.clone();
    }
    (bold, light)
}

/// The nearest 1-2-5 value above (`up`) or below `v`, when it is within 3 %; else `v`.
fn snap125(v: f64, up: bool) -> f64 {
    let p = 10f64.powf(v.log10().floor());
    let cands = [p, 2.0 * p, 5.0 * p, 10.0 * p];
    let best = if up {
        cands.iter().copied().find(|&c| c >= v)
    } else {
        cands.iter().rev().copied().find(|&c| c <= v)
    };
    match best {
        Some(c) if (c / v).ln().abs() <= 0.03f64.ln_1p() => c,
        _ => v,
    }
}

/// Tick label: plain numbers for ordinary magnitudes (up to three decimals, trailing
/// zeros removed), `1.5e-7` style otherwise.
fn fmt_tick(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    if (1e-2..1e5).contains(&a) {
        let s = format!("{v:.3}");
        return s.trim_end_matches('0').trim_end_matches('.').to_string();
    }
    let s = format!("{v:.2e}");
    match s.split_once('e') {
        Some((m, e)) => {
            let m = m.trim_end_matches('0').trim_end_matches('.');
            format!("{m}e{e}")
        }
        None => s,
    }
}

/// The CMIF figure of section 4.4 / Fig. 3 of the wafer-stage paper as a [`LinePlot`]:
/// `sigma_i^2` against frequency on log axes, one line per singular value, the picked
/// peaks as dots labelled with their frequency in Hz.
pub fn cmif_plot(cmif: &Cmif, peaks: &[CmifPeak], title: &str) -> LinePlot {
    let mut plot = LinePlot::new(title).with_y(Axis::log("CMIF  σᵢ²"));
    plot.legend_corner = Corner::LowerLeft;
    let f = cmif.freq_hz.clone();
    for i in 0..cmif.n_sv() {
        let y: Vec<f64> = cmif.sv2.iter().map(|row| row[i]).collect();
        plot.series.push(Series::line(
            format!("σ{}²", subscript(i + 1)),
            f.clone(),
            y,
        ));
    }
    // Keep the noise floor of rank-deficient data from squashing the curves: show at
    // most 12 decades below the largest value.
    let top = cmif
        .sv2
        .iter()
        .filter_map(|r| r.first().copied())
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold(0.0, f64::max);
    let bottom = cmif
        .sv2
        .iter()
        .flat_map(|r| r.iter().copied())
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold(f64::INFINITY, f64::min);
    if top > 0.0 && bottom.is_finite() {
        let lo = bottom.max(top * 1e-12);
        let (l, h) = (lo.log10(), top.log10());
        let pad = 0.04 * (h - l).max(1.0);
        plot.y.range = Some((10f64.powf(l - pad), 10f64.powf(h + 3.0 * pad)));
    }
    for p in peaks {
        plot.markers.push(Marker {
            x: p.f_hz,
            y: p.sv2,
            label: Some(fmt_hz(p.f_hz)),
            color: None,
        });
    }
    plot
}

/// `n` in Unicode subscript digits.
fn subscript(n: usize) -> String {
    n.to_string()
        .chars()
        .map(|c| match c {
            '0'..='9' => char::from_u32(0x2080 + c as u32 - '0' as u32).unwrap_or(c),
            _ => c,
        })
        .collect()
}

fn fmt_hz(f: f64) -> String {
    if f >= 100.0 {
        format!("{f:.0}")
    } else if f >= 10.0 {
        format!("{f:.1}")
    } else {
        format!("{f:.2}")
    }
}

/// Writes the CMIF figure ([`cmif_plot`]) to an SVG file (1000 x 600 pixels).
pub fn cmif_svg(
    path: impl AsRef<Path>,
    cmif: &Cmif,
    peaks: &[CmifPeak],
    title: &str,
) -> Result<(), FrfitError> {
    cmif_plot(cmif, peaks, title).write_svg(path, (1000, 600))
}

/// A grid of Bode magnitude panels, one per entry `G_ij` (row = output, column = input),
/// each with one line per dataset (e.g. `[("data", &frf), ("model", &model_response)]`).
/// The datasets should have the same dimensions; entries a dataset lacks are skipped.
pub fn magnitude_grid(title: &str, sets: &[(&str, &dyn FrfDataset)]) -> PlotGrid {
    let ny = sets.iter().map(|(_, d)| d.ny()).max().unwrap_or(0);
    let nu = sets.iter().map(|(_, d)| d.nu()).max().unwrap_or(0);
    let mut panels = Vec::with_capacity(ny * nu);
    for i in 0..ny {
        for j in 0..nu {
            let mut p = LinePlot::new(format!("G{}_{}", i + 1, j + 1));
            p.legend = i == 0 && j == 0;
            for (name, d) in sets {
                if i < d.ny() && j < d.nu() {
                    let f = d.freqs_hz();
                    let y = (0..d.n_lines()).map(|k| d.value(k, i, j).norm()).collect();
                    p.series.push(Series::line(*name, f, y));
                }
            }
            panels.push(p);
        }
    }
    PlotGrid {
        title: title.to_string(),
        rows: ny.max(1),
        cols: nu.max(1),
        panels,
        panel_size: (320, 240),
    }
}

/// One entry `(i, j)` (0-based) with the data, the model, the magnitude of the residual
/// `G - M` on lines where the two share a frequency, and the noise standard deviation
/// `sqrt(var)` when the data carry a variance: the residual is significant where it
/// stands above the noise.
pub fn entry_overlay(
    title: &str,
    data: &dyn FrfDataset,
    model: &dyn FrfDataset,
    i: usize,
    j: usize,
) -> LinePlot {
    let mut p = LinePlot::new(title);
    if i >= data.ny() || j >= data.nu() {
        return p;
    }
    let f = data.freqs_hz();
    let g: Vec<f64> = (0..data.n_lines())
        .map(|k| data.value(k, i, j).norm())
        .collect();
    p.series.push(Series::line("data", f.clone(), g));
    if i < model.ny() && j < model.nu() {
        let fm = model.freqs_hz();
        let m = (0..model.n_lines())
            .map(|k| model.value(k, i, j).norm())
            .collect();
        p.series.push(Series::dashed("model", fm.clone(), m));
        // Residual on common lines (both sorted ascending).
        let (mut a, mut b) = (0, 0);
        let (mut rf, mut rv) = (Vec::new(), Vec::new());
        while a < f.len() && b < fm.len() {
            let (x, y) = (f[a], fm[b]);
            if (x - y).abs() <= 1e-9 * x.abs().max(1.0) {
                rf.push(x);
                rv.push((data.value(a, i, j) - model.value(b, i, j)).norm());
                a += 1;
                b += 1;
            } else if x < y {
                a += 1;
            } else {
                b += 1;
            }
        }
        p.series.push(Series::line("|residual|", rf, rv));
    }
    if data.has_variance() {
        let s = (0..data.n_lines())
            .map(|k| data.variance(k, i, j).unwrap_or(f64::NAN).sqrt())
            .collect();
        p.series
            .push(Series::line("noise std", f, s).with_color((127, 127, 127)));
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> std::path::PathBuf {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        std::env::temp_dir().join(format!(
            "frfit-plots-{name}-{}-{nanos}.svg",
            std::process::id()
        ))
    }

    #[test]
    fn log_ticks_follow_1_2_5_and_decades() {
        let (b, l) = log_ticks(20.0, 2000.0);
        assert_eq!(b, vec![20.0, 50.0, 100.0, 200.0, 500.0, 1000.0, 2000.0]);
        assert!(l.contains(&30.0) && l.contains(&900.0));
        let (b, l) = log_ticks(1e-16, 1e-6);
        assert_eq!(b.len(), 6); // every second decade of ten
        assert!(b
            .iter()
            .all(|v| (v.log10() - v.log10().round()).abs() < 1e-9));
        assert_eq!(l.len(), 11);
        let (b, _) = log_ticks(850.0, 1110.0);
        assert!(b.len() >= 2, "{b:?}");
        assert_eq!(log_ticks(-1.0, 2.0), (vec![], vec![]));
        assert_eq!(log_ticks(f64::NAN, 2.0), (vec![], vec![]));
    }

    #[test]
    fn snapping_and_labels() {
        assert_eq!(snap125(20.25, false), 20.0);
        assert_eq!(snap125(1999.75, true), 2000.0);
        assert_eq!(snap125(31.0, false), 31.0);
        assert_eq!(fmt_tick(2000.0), "2000");
        assert_eq!(fmt_tick(0.25), "0.25");
        assert_eq!(fmt_tick(1e-8), "1e-8");
        assert_eq!(fmt_tick(1.5e-7), "1.5e-7");
        assert_eq!(subscript(12), "₁₂");
        assert_eq!(fmt_hz(35.0), "35.0");
        assert_eq!(fmt_hz(1845.5), "1846");
    }

    #[test]
    fn undrawable_values_break_lines() {
        let s = Series::line(
            "x",
            vec![1.0, 2.0, 3.0, 4.0, 5.0],
            vec![1.0, -1.0, 2.0, f64::NAN, 3.0],
        );
        let seg = segments(&s, true, true);
        assert_eq!(
            seg,
            vec![vec![(1.0, 1.0)], vec![(3.0, 2.0)], vec![(5.0, 3.0)]]
        );
        assert_eq!(segments(&s, false, false).len(), 2);
    }

    #[test]
    fn panels_and_grids_write_svg() {
        // Every axis combination, an empty series, markers with labels.
        for (xs, ys) in [
            (Scale::Log, Scale::Log),
            (Scale::Log, Scale::Linear),
            (Scale::Linear, Scale::Log),
            (Scale::Linear, Scale::Linear),
        ] {
            let mut p = LinePlot::new("panel")
                .with_x(Axis {
                    label: "x".into(),
                    scale: xs,
                    range: None,
                })
                .with_y(Axis {
                    label: "y".into(),
                    scale: ys,
                    range: None,
                })
                .with_series(Series::line(
                    "a",
                    vec![1.0, 10.0, 100.0],
                    vec![1e-3, 1e-1, 1e-2],
                ))
                .with_series(Series::dashed("b", vec![1.0, 100.0], vec![2e-3, 2e-2]))
                .with_series(Series::points("", vec![], vec![]))
                .with_marker(Marker {
                    x: 10.0,
                    y: 1e-1,
                    label: Some("peak".into()),
                    color: None,
                });
            p.legend_corner = Corner::LowerRight;
            let path = tmp("panel");
            p.write_svg(&path, (500, 300)).unwrap();
            let text = std::fs::read_to_string(&path).unwrap();
            assert!(text.contains("<svg") && text.contains("peak"));
            let _ = std::fs::remove_file(&path);
        }
        // A panel with no data at all still draws.
        let path = tmp("empty");
        LinePlot::new("").write_svg(&path, (300, 200)).unwrap();
        let _ = std::fs::remove_file(&path);
        // A grid.
        let f: Vec<f64> = (1..=50).map(|k| k as f64).collect();
        let frf = frf_data::Frf::from_fn(f, 2, 2, |k, i, j| {
            frf_data::C64::new(1.0 / (1.0 + k as f64), (i + j) as f64 * 0.1)
        })
        .unwrap();
        let g = magnitude_grid("grid", &[("data", &frf as &dyn FrfDataset)]);
        assert_eq!((g.rows, g.cols, g.panels.len()), (2, 2, 4));
        let path = tmp("grid");
        g.write_svg(&path).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("G2_2"));
        let _ = std::fs::remove_file(&path);
        // An overlay of data and itself: the residual is zero (not drawable on a log
        // axis), the other series are there.
        let o = entry_overlay("overlay", &frf, &frf, 1, 0);
        assert_eq!(o.series.len(), 3);
        assert!(o.series[2].y.iter().all(|v| *v == 0.0));
        let o = entry_overlay("overlay", &frf, &frf, 5, 0);
        assert!(o.series.is_empty());
    }

    #[test]
    fn unwritable_path_is_an_error() {
        let p = LinePlot::new("x").with_series(Series::line("a", vec![1.0, 2.0], vec![1.0, 2.0]));
        let e = p
            .write_svg("/nonexistent-dir-frfit/x.svg", (300, 200))
            .unwrap_err();
        assert!(e.to_string().contains("nonexistent-dir-frfit"), "{e}");
    }
}
