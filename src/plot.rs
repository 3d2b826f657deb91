//! The one plotting module every command uses: plotters with an embedded font (DejaVu Sans through
//! ab_glyph, no system font lookup), one small style, the Okabe–Ito colour-blind-safe palette, and
//! every figure written as PNG and SVG (atomically).

use crate::error::{Error, Result};
use image::ImageEncoder as _;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::FontStyle;
use std::path::{Path, PathBuf};
use std::sync::Once;

static FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");
static REGISTER: Once = Once::new();

pub(crate) fn register_font() {
    REGISTER.call_once(|| {
        // The bytes are a valid TrueType font shipped with the crate.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

/// Okabe–Ito palette (colour-blind safe), in the order series use it.
pub const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 114, 178),   // blue
    RGBColor(213, 94, 0),    // vermillion
    RGBColor(0, 158, 115),   // bluish green
    RGBColor(230, 159, 0),   // orange
    RGBColor(204, 121, 167), // reddish purple
    RGBColor(86, 180, 233),  // sky blue
    RGBColor(0, 0, 0),       // black
];
pub(crate) const BLUE: RGBColor = PALETTE[0];
pub(crate) const VERMILLION: RGBColor = PALETTE[1];
pub(crate) const GREEN: RGBColor = PALETTE[2];
pub(crate) const ORANGE: RGBColor = PALETTE[3];
pub const GREY: RGBColor = RGBColor(120, 120, 120);
pub(crate) const BLACK_LINE: RGBColor = RGBColor(0, 0, 0);

/// How a legend entry is drawn.
#[derive(Clone, Debug, PartialEq)]
pub enum Swatch {
    Point(RGBColor),
    Line {
        color: RGBColor,
        width: u32,
        dashed: bool,
    },
    Box(RGBColor),
}

/// One drawable layer.
#[derive(Clone, Debug)]
pub enum Layer {
    /// Filled circles (of radius 1: half transparent, for dense scatters).
    Points {
        xy: Vec<(f64, f64)>,
        color: RGBColor,
        size: u32,
        label: Option<String>,
    },
    /// A polyline.
    Line {
        xy: Vec<(f64, f64)>,
        color: RGBColor,
        width: u32,
        dashed: bool,
        label: Option<String>,
    },
    /// Bars centred at x with the given heights (from 0), one colour each.
    Bars {
        x: Vec<f64>,
        heights: Vec<f64>,
        width: f64,
        colors: Vec<RGBColor>,
    },
    /// A horizontal reference line across the plot.
    HLine {
        y: f64,
        color: RGBColor,
        dashed: bool,
        label: Option<String>,
    },
    /// Filled axis-aligned cells `[x0, y0, x1, y1]`, one colour each (heat maps, matrices).
    Cells { cells: Vec<([f64; 4], RGBColor)> },
    /// A raster of `width × height` RGB8 pixels covering `[x0, y0, x1, y1]` in data coordinates,
    /// row 0 at y0. Embedded as one PNG in the SVG.
    Image {
        extent: [f64; 4],
        width: u32,
        height: u32,
        rgb: Vec<u8>,
    },
    /// Text centred at points.
    Text {
        items: Vec<((f64, f64), String, RGBColor)>,
        size: u32,
    },
    /// A legend entry with nothing drawn in the plot.
    Key { swatch: Swatch, label: String },
}

impl Layer {
    /// Its legend entry, if any.
    fn key(&self) -> Option<(Swatch, String)> {
        match self {
            Layer::Points {
                color,
                label: Some(l),
                ..
            } => Some((Swatch::Point(*color), l.clone())),
            Layer::Line {
                color,
                width,
                dashed,
                label: Some(l),
                ..
            } => Some((
                Swatch::Line {
                    color: *color,
                    width: *width,
                    dashed: *dashed,
                },
                l.clone(),
            )),
            Layer::HLine {
                color,
                dashed,
                label: Some(l),
                ..
            } => Some((
                Swatch::Line {
                    color: *color,
                    width: 2,
                    dashed: *dashed,
                },
                l.clone(),
            )),
            Layer::Key { swatch, label } => Some((swatch.clone(), label.clone())),
            _ => None,
        }
    }
}

/// A 2D plot: one panel of a [`Figure`], or a figure of its own ([`Plot::save`]).
#[derive(Clone, Debug)]
pub struct Plot {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    /// Axis ranges; computed from the data (with a margin) when absent.
    pub x_range: Option<(f64, f64)>,
    pub y_range: Option<(f64, f64)>,
    /// Image coordinates: y grows downward.
    pub y_down: bool,
    /// Labels for integer positions 0, 1, 2, … (categorical axes).
    pub x_categories: Option<Vec<String>>,
    pub y_categories: Option<Vec<String>>,
    /// Tick labels on the axes (off for pictures and colour bars).
    pub x_ticks: bool,
    pub y_ticks: bool,
    /// Light grid lines.
    pub grid: bool,
    /// A unit as long on both axes (pictures): one range is widened to fit the panel.
    pub equal_aspect: bool,
    pub layers: Vec<Layer>,
    /// Pixel size when saved alone (the SVG has the same nominal size).
    pub size: (u32, u32),
}

/// A figure: rows of panels (each with a relative width), a title, and one legend for all of
/// them in a column on the right, outside the data.
#[derive(Clone, Debug)]
pub struct Figure {
    pub title: String,
    /// Panels with their relative widths; `None` leaves the space empty.
    pub rows: Vec<Vec<(Option<Plot>, f64)>>,
    /// Legend entries besides those of the panels' labelled layers.
    pub legend: Vec<(Swatch, String)>,
    pub size: (u32, u32),
}

/// What the SVG back end cannot draw itself: rasters, drawn as placeholder rectangles of a unique
/// colour and swapped for embedded PNGs afterwards.
#[derive(Default)]
struct Rasters {
    svg: bool,
    png: Vec<Vec<u8>>,
}

/// Placeholder fill of the k-th raster in SVG output.
fn placeholder(k: usize) -> RGBColor {
    RGBColor(1, 2, k as u8)
}

const MAX_RASTERS: usize = 250;

type Chart<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

impl Plot {
    pub fn new(title: &str, x_label: &str, y_label: &str) -> Self {
        Plot {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            x_range: None,
            y_range: None,
            y_down: false,
            x_categories: None,
            y_categories: None,
            x_ticks: true,
            y_ticks: true,
            grid: true,
            equal_aspect: false,
            layers: vec![],
            size: (900, 600),
        }
    }

    fn data_range(&self) -> ((f64, f64), (f64, f64)) {
        let mut xs = vec![];
        let mut ys = vec![];
        for l in &self.layers {
            match l {
                Layer::Points { xy, .. } | Layer::Line { xy, .. } => {
                    xs.extend(xy.iter().map(|p| p.0));
                    ys.extend(xy.iter().map(|p| p.1));
                }
                Layer::Bars {
                    x, heights, width, ..
                } => {
                    xs.extend(x.iter().map(|v| v - width));
                    xs.extend(x.iter().map(|v| v + width));
                    ys.extend(heights.iter().cloned());
                    ys.push(0.0);
                }
                Layer::HLine { y, .. } => ys.push(*y),
                Layer::Cells { cells } => {
                    for (c, _) in cells {
                        xs.extend([c[0], c[2]]);
                        ys.extend([c[1], c[3]]);
                    }
                }
                Layer::Image { extent: c, .. } => {
                    xs.extend([c[0], c[2]]);
                    ys.extend([c[1], c[3]]);
                }
                Layer::Text { items, .. } => {
                    xs.extend(items.iter().map(|i| i.0 .0));
                    ys.extend(items.iter().map(|i| i.0 .1));
                }
                Layer::Key { .. } => {}
            }
        }
        let span = |v: &[f64]| {
            let lo = v
                .iter()
                .cloned()
                .filter(|x| x.is_finite())
                .fold(f64::INFINITY, f64::min);
            let hi = v
                .iter()
                .cloned()
                .filter(|x| x.is_finite())
                .fold(f64::NEG_INFINITY, f64::max);
            if !lo.is_finite() {
                return (0.0, 1.0);
            }
            let pad = if hi > lo {
                0.05 * (hi - lo)
            } else {
                0.5 * lo.abs().max(1.0)
            };
            (lo - pad, hi + pad)
        };
        (
            self.x_range.unwrap_or_else(|| span(&xs)),
            self.y_range.unwrap_or_else(|| span(&ys)),
        )
    }

    /// Draw into one panel of a figure.
    fn draw_panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        caption: u32,
        rasters: &mut Rasters,
    ) -> Result<(), String>
    where
        DB::ErrorType: 'static,
    {
        let e = |x: &dyn std::fmt::Display| x.to_string();
        let ((mut x0, mut x1), (mut y0, mut y1)) = self.data_range();
        let area = if self.title.is_empty() {
            area.clone()
        } else {
            area.titled(&self.title, ("sans-serif", caption))
                .map_err(|x| e(&x))?
        };
        let y_area = match (&self.y_categories, self.y_ticks) {
            (Some(c), _) => 30 + 8 * c.iter().map(|s| s.chars().count()).max().unwrap_or(0) as u32,
            (None, true) => 70,
            (None, false) => 24,
        };
        let y_area = if self.y_label.is_empty() && !self.y_ticks {
            4
        } else {
            y_area
        };
        let x_area = if self.x_ticks { 48 } else { 24 };
        let build = |xr: std::ops::Range<f64>, yr: std::ops::Range<f64>| {
            ChartBuilder::on(&area)
                .margin(10)
                .x_label_area_size(x_area)
                .y_label_area_size(y_area)
                .build_cartesian_2d(xr, yr)
        };
        if self.equal_aspect {
            // Building draws nothing: measure the plotting area, then widen one range so that a
            // unit is as long on both axes.
            let probe = build(x0..x1, y0..y1).map_err(|x| e(&x))?;
            let (pw, ph) = probe.plotting_area().dim_in_pixel();
            let (sx, sy) = ((x1 - x0) / pw.max(1) as f64, (y1 - y0) / ph.max(1) as f64);
            if sx > sy {
                let (c, half) = (0.5 * (y0 + y1), 0.5 * sx * ph as f64);
                (y0, y1) = (c - half, c + half);
            } else {
                let (c, half) = (0.5 * (x0 + x1), 0.5 * sy * pw as f64);
                (x0, x1) = (c - half, c + half);
            }
        }
        let (ya, yb) = if self.y_down { (y1, y0) } else { (y0, y1) };
        let mut chart = build(x0..x1, ya..yb).map_err(|x| e(&x))?;
        let xcats = self.x_categories.clone();
        let ycats = self.y_categories.clone();
        let xfmt = move |v: &f64| category_or_number(*v, &xcats);
        let yfmt = move |v: &f64| category_or_number(*v, &ycats);
        let mut mesh = chart.configure_mesh();
        mesh.x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .light_line_style(WHITE)
            .bold_line_style(RGBColor(225, 225, 225))
            .x_label_formatter(&xfmt)
            .y_label_formatter(&yfmt);
        if let Some(c) = &self.x_categories {
            mesh.x_labels(c.len().min(40) + 1);
        }
        if let Some(c) = &self.y_categories {
            mesh.y_labels(c.len().min(40) + 1);
        }
        if !self.x_ticks {
            mesh.x_labels(0);
        }
        if !self.y_ticks {
            mesh.y_labels(0);
        }
        if !self.grid {
            mesh.disable_x_mesh().disable_y_mesh();
        }
        mesh.draw().map_err(|x| e(&x))?;

        self.draw_layers(&mut chart, (x0, x1), rasters)
    }

    /// Each layer into the chart, in order (`xr`: the x range, where a horizontal line runs). One
    /// arm per kind of layer: the match is the clearest form.
    fn draw_layers<DB: DrawingBackend>(
        &self,
        chart: &mut Chart<'_, DB>,
        (x0, x1): (f64, f64),
        rasters: &mut Rasters,
    ) -> Result<(), String>
    where
        DB::ErrorType: 'static,
    {
        let e = |x: &dyn std::fmt::Display| x.to_string();
        for layer in &self.layers {
            match layer {
                Layer::Cells { cells } => {
                    chart
                        .draw_series(cells.iter().map(|(c, fill)| {
                            Rectangle::new([(c[0], c[1]), (c[2], c[3])], fill.filled())
                        }))
                        .map_err(|x| e(&x))?;
                }
                Layer::Image {
                    extent,
                    width,
                    height,
                    rgb,
                } => draw_image(chart, *extent, *width, *height, rgb, rasters)?,
                Layer::Bars {
                    x,
                    heights,
                    width,
                    colors,
                } => {
                    chart
                        .draw_series(x.iter().zip(heights).enumerate().map(|(i, (xc, h))| {
                            let c = colors.get(i).copied().unwrap_or(BLUE);
                            Rectangle::new(
                                [(xc - width / 2.0, 0.0), (xc + width / 2.0, *h)],
                                c.filled(),
                            )
                        }))
                        .map_err(|x| e(&x))?;
                }
                Layer::Points {
                    xy, color, size, ..
                } => {
                    let c = color.mix(if *size <= 1 { 0.45 } else { 0.8 });
                    chart
                        .draw_series(xy.iter().map(|p| Circle::new(*p, *size, c.filled())))
                        .map_err(|x| e(&x))?;
                }
                Layer::Line {
                    xy,
                    color,
                    width,
                    dashed,
                    ..
                } => line(chart, xy, *color, *width, *dashed).map_err(|x| e(&x))?,
                Layer::HLine {
                    y, color, dashed, ..
                } => line(chart, &[(x0, *y), (x1, *y)], *color, 2, *dashed).map_err(|x| e(&x))?,
                Layer::Text { items, size } => {
                    let style = TextStyle::from(("sans-serif", *size).into_font())
                        .pos(Pos::new(HPos::Center, VPos::Center));
                    chart
                        .draw_series(
                            items
                                .iter()
                                .map(|(p, s, c)| Text::new(s.clone(), *p, style.color(c))),
                        )
                        .map_err(|x| e(&x))?;
                }
                Layer::Key { .. } => {}
            }
        }
        Ok(())
    }

    /// This plot as a figure of its own.
    pub fn figure(&self) -> Figure {
        Figure {
            title: String::new(),
            rows: vec![vec![(Some(self.clone()), 1.0)]],
            legend: vec![],
            size: self.size,
        }
    }

    /// Write `<base>.png` and `<base>.svg`.
    pub fn save(&self, base: &Path) -> Result<(PathBuf, PathBuf)> {
        self.figure().save(base)
    }
}

impl Figure {
    /// Panels in rows of `cols` (each of relative width 1), the last row filled out with empty
    /// places.
    pub fn grid(panels: Vec<Plot>, cols: usize) -> Vec<Vec<(Option<Plot>, f64)>> {
        let cols = cols.max(1);
        let mut rows: Vec<Vec<(Option<Plot>, f64)>> = vec![];
        for (k, p) in panels.into_iter().enumerate() {
            if k % cols == 0 {
                rows.push(vec![]);
            }
            rows.last_mut().expect("a row").push((Some(p), 1.0));
        }
        if let Some(last) = rows.last_mut() {
            while last.len() < cols {
                last.push((None, 1.0));
            }
        }
        rows
    }

    /// Every legend entry: the figure's, then the panels' labelled layers (first of each label).
    fn keys(&self) -> Vec<(Swatch, String)> {
        let mut keys = self.legend.clone();
        for p in self.rows.iter().flatten().filter_map(|r| r.0.as_ref()) {
            for k in p.layers.iter().filter_map(Layer::key) {
                if !keys.iter().any(|x| x.1 == k.1) {
                    keys.push(k);
                }
            }
        }
        keys
    }

    fn draw<DB: DrawingBackend>(
        &self,
        root: DrawingArea<DB, Shift>,
        rasters: &mut Rasters,
    ) -> Result<(), String>
    where
        DB::ErrorType: 'static,
    {
        register_font();
        let e = |x: &dyn std::fmt::Display| x.to_string();
        root.fill(&WHITE).map_err(|x| e(&x))?;
        let area = if self.title.is_empty() {
            root.clone()
        } else {
            root.titled(&self.title, ("sans-serif", 20))
                .map_err(|x| e(&x))?
                .margin(8, 0, 0, 0)
        };
        let keys = self.keys();
        let w = area.dim_in_pixel().0 as i32;
        let (main, legend) = if keys.is_empty() {
            (area, None)
        } else {
            let chars = keys.iter().map(|k| k.1.chars().count()).max().unwrap_or(0);
            let lw = (44 + 8 * chars as i32).min(2 * w / 5);
            let (a, b) = area.split_horizontally(w - lw);
            (a, Some(b))
        };
        let single = self.rows.len() == 1 && self.rows[0].len() == 1;
        let caption = if single { 20 } else { 16 };
        let rows = main.split_evenly((self.rows.len().max(1), 1));
        for (row_area, row) in rows.iter().zip(&self.rows) {
            let total: f64 = row.iter().map(|p| p.1).sum();
            let width = row_area.dim_in_pixel().0 as f64;
            let mut rest = row_area.clone();
            for (k, (plot, weight)) in row.iter().enumerate() {
                let here = if k + 1 == row.len() {
                    rest.clone()
                } else {
                    let px = (width * weight / total).round() as i32;
                    let (a, b) = rest.split_horizontally(px);
                    rest = b;
                    a
                };
                if let Some(plot) = plot {
                    plot.draw_panel(&here, caption, rasters)?;
                }
            }
        }
        if let Some(l) = legend {
            draw_legend(&l, &keys, if single { 56 } else { 40 }).map_err(|x| e(&x))?;
        }
        root.present().map_err(|x| e(&x))?;
        Ok(())
    }

    /// The figure as SVG text (rasters embedded as PNG).
    pub fn to_svg(&self) -> Result<String, String> {
        let mut svg = String::new();
        let mut rasters = Rasters {
            svg: true,
            png: vec![],
        };
        {
            let root = SVGBackend::with_string(&mut svg, self.size).into_drawing_area();
            self.draw(root, &mut rasters)?;
        }
        for (k, png) in rasters.png.iter().enumerate() {
            svg = embed_png(&svg, placeholder(k), png)?;
        }
        Ok(svg)
    }

    /// The figure as RGB8 pixels.
    pub fn to_rgb(&self) -> Result<Vec<u8>, String> {
        let (w, h) = self.size;
        let mut buf = vec![255u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            self.draw(root, &mut Rasters::default())?;
        }
        Ok(buf)
    }

    /// Write `<base>.png` and `<base>.svg` (atomically).
    pub fn save(&self, base: &Path) -> Result<(PathBuf, PathBuf)> {
        let png = base.with_extension("png");
        let svg = base.with_extension("svg");
        let pixels = self
            .to_rgb()
            .map_err(|m| Error::invalid(&png, format!("cannot draw: {m}")))?;
        crate::formats::photo::write_8bit(&png, self.size.0, self.size.1, 3, &pixels, 0, None)?;
        let text = self
            .to_svg()
            .map_err(|m| Error::invalid(&svg, format!("cannot draw: {m}")))?;
        crate::formats::output::write_bytes(&svg, text.as_bytes())?;
        Ok((png, svg))
    }
}

/// A raster: per pixel a rectangle on bitmaps; a placeholder rectangle (swapped for a PNG) in SVG.
fn draw_image<DB: DrawingBackend>(
    chart: &mut Chart<'_, DB>,
    c: [f64; 4],
    w: u32,
    h: u32,
    rgb: &[u8],
    rasters: &mut Rasters,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let e = |x: &dyn std::fmt::Display| x.to_string();
    if rgb.len() != (w * h * 3) as usize || w == 0 || h == 0 {
        return Err(format!("raster of {w}×{h} with {} bytes", rgb.len()));
    }
    if rasters.svg {
        if rasters.png.len() >= MAX_RASTERS {
            return Err(format!("more than {MAX_RASTERS} rasters in one figure"));
        }
        let mut png = vec![];
        image::codecs::png::PngEncoder::new(&mut png)
            .write_image(rgb, w, h, image::ExtendedColorType::Rgb8)
            .map_err(|x| e(&x))?;
        let fill = placeholder(rasters.png.len());
        rasters.png.push(png);
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(c[0], c[1]), (c[2], c[3])],
                fill.filled(),
            )))
            .map_err(|x| e(&x))?;
        return Ok(());
    }
    let (dx, dy) = ((c[2] - c[0]) / w as f64, (c[3] - c[1]) / h as f64);
    chart
        .draw_series((0..h).flat_map(|j| {
            (0..w).map(move |i| {
                let k = 3 * (j * w + i) as usize;
                let (x, y) = (c[0] + i as f64 * dx, c[1] + j as f64 * dy);
                Rectangle::new(
                    [(x, y), (x + dx, y + dy)],
                    RGBColor(rgb[k], rgb[k + 1], rgb[k + 2]).filled(),
                )
            })
        }))
        .map_err(|x| e(&x))?;
    Ok(())
}

/// Swap the placeholder rectangle of colour `fill` for an `<image>` holding the PNG.
fn embed_png(svg: &str, fill: RGBColor, png: &[u8]) -> Result<String, String> {
    use base64::Engine as _;
    let key = format!("fill=\"#{:02X}{:02X}{:02X}\"", fill.0, fill.1, fill.2);
    let at = svg
        .find(&key)
        .ok_or("raster placeholder missing from the SVG")?;
    let start = svg[..at]
        .rfind("<rect")
        .ok_or("raster placeholder is not a rect")?;
    let end = at + svg[at..].find("/>").ok_or("unterminated rect")? + 2;
    let tag = &svg[start..end];
    let attr = |name: &str| -> Result<f64, String> {
        let k = format!(" {name}=\"");
        let i = tag.find(&k).ok_or("rect without position")? + k.len();
        let j = tag[i..].find('"').ok_or("rect without position")?;
        tag[i..i + j]
            .parse()
            .map_err(|_| "bad rect position".to_string())
    };
    let (x, y, w, h) = (attr("x")?, attr("y")?, attr("width")?, attr("height")?);
    let data = base64::engine::general_purpose::STANDARD.encode(png);
    let image = format!(
        "<image x=\"{x}\" y=\"{y}\" width=\"{w}\" height=\"{h}\" preserveAspectRatio=\"none\" style=\"image-rendering:pixelated\" href=\"data:image/png;base64,{data}\"/>"
    );
    Ok(format!("{}{}{}", &svg[..start], image, &svg[end..]))
}

/// The legend column: one row per entry, a swatch then the label.
fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    keys: &[(Swatch, String)],
    top: i32,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let style =
        TextStyle::from(("sans-serif", 14).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
    for (k, (swatch, label)) in keys.iter().enumerate() {
        let y = top + 22 * k as i32;
        match swatch {
            Swatch::Point(c) => area.draw(&Circle::new((16, y), 5, c.filled()))?,
            Swatch::Box(c) => area.draw(&Rectangle::new([(6, y - 7), (26, y + 7)], c.filled()))?,
            Swatch::Line {
                color,
                width,
                dashed,
            } => {
                let s = color.stroke_width(*width);
                if *dashed {
                    for x in [4, 14, 24] {
                        area.draw(&PathElement::new([(x, y), (x + 6, y)], s))?;
                    }
                } else {
                    area.draw(&PathElement::new([(4, y), (30, y)], s))?;
                }
            }
        }
        area.draw(&Text::new(label.clone(), (38, y), style.clone()))?;
    }
    Ok(())
}

fn category_or_number(v: f64, cats: &Option<Vec<String>>) -> String {
    match cats {
        Some(c) => {
            let i = v.round();
            if (v - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < c.len() {
                c[i as usize].clone()
            } else {
                String::new()
            }
        }
        None => plotters_number(v),
    }
}

/// A diverging colour map (ColorBrewer RdBu, colour-blind safe) for v in [−1, 1]: negative blue,
/// zero white, positive red; clamped outside.
pub(crate) fn diverging(v: f64) -> RGBColor {
    const STOPS: [(u8, u8, u8); 11] = [
        (5, 48, 97),
        (33, 102, 172),
        (67, 147, 195),
        (146, 197, 222),
        (209, 229, 240),
        (255, 255, 255),
        (253, 219, 199),
        (244, 165, 130),
        (214, 96, 77),
        (178, 24, 43),
        (103, 0, 31),
    ];
    let v = if v.is_finite() {
        v.clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let t = (v + 1.0) * 5.0;
    let i = (t.floor() as usize).min(9);
    let f = t - i as f64;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    let mix = |x: u8, y: u8| (x as f64 + (y as f64 - x as f64) * f).round() as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// White (0) to `color` (1).
pub(crate) fn shade(color: RGBColor, v: f64) -> RGBColor {
    let v = v.clamp(0.0, 1.0);
    let mix = |a: u8| (255.0 + (a as f64 - 255.0) * v).round() as u8;
    RGBColor(mix(color.0), mix(color.1), mix(color.2))
}

/// A vertical colour bar for [`diverging`] over [−limit, limit].
pub(crate) fn colorbar(label: &str, limit: f64) -> Plot {
    let n = 256u32;
    let rgb: Vec<u8> = (0..n)
        .flat_map(|j| {
            let c = diverging(1.0 - 2.0 * (j as f64 + 0.5) / n as f64);
            [c.0, c.1, c.2]
        })
        .collect();
    let mut p = Plot::new("", "", label);
    p.x_range = Some((0.0, 1.0));
    p.y_range = Some((-limit, limit));
    p.x_ticks = false;
    p.grid = false;
    p.layers.push(Layer::Image {
        extent: [0.0, limit, 1.0, -limit],
        width: 1,
        height: n,
        rgb,
    });
    p
}

/// Draw a polyline, solid or dashed.
fn line<DB: DrawingBackend>(
    chart: &mut Chart<'_, DB>,
    xy: &[(f64, f64)],
    color: RGBColor,
    width: u32,
    dashed: bool,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let style = color.stroke_width(width);
    if dashed {
        chart.draw_series(DashedLineSeries::new(xy.iter().copied(), 8, 5, style))?;
    } else {
        chart.draw_series(LineSeries::new(xy.iter().copied(), style))?;
    }
    Ok(())
}

/// Tick label: up to 4 significant digits, no trailing zeros.
fn plotters_number(v: f64) -> String {
    // Ticks computed as sums of steps land a few ulps off zero.
    if v.abs() < 1e-12 {
        return "0".into();
    }
    let a = v.abs();
    let s = if !(1e-3..1e5).contains(&a) {
        format!("{v:.2e}")
    } else {
        let digits = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
        format!("{v:.digits$}")
    };
    if s.contains('.') && !s.contains('e') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels() {
        assert_eq!(plotters_number(0.5), "0.5");
        assert_eq!(plotters_number(1280.0), "1280");
        assert_eq!(plotters_number(-0.125), "-0.125");
        assert_eq!(plotters_number(0.0), "0");
        assert_eq!(plotters_number(-1.11e-16), "0");
        assert_eq!(plotters_number(100.0), "100");
    }
}
