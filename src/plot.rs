//! The one plotting module every command uses: plotters with an embedded font (DejaVu Sans through
//! ab_glyph, no system font lookup), one small style, the Okabe–Ito colour-blind-safe palette, and
//! every figure written as PNG and SVG (atomically).

use crate::error::{Error, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
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
pub const BLUE: RGBColor = PALETTE[0];
pub const VERMILLION: RGBColor = PALETTE[1];
pub const GREEN: RGBColor = PALETTE[2];
pub const ORANGE: RGBColor = PALETTE[3];
pub const GREY: RGBColor = RGBColor(120, 120, 120);
pub const BLACK_LINE: RGBColor = RGBColor(0, 0, 0);

/// One drawable layer.
#[derive(Clone, Debug)]
pub enum Layer {
    /// Filled circles.
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
    /// Axis-aligned cells shaded from white (0) to `color` (1): a heat map.
    Cells {
        cells: Vec<([f64; 4], f64)>,
        color: RGBColor,
    },
}

/// A 2D figure.
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
    /// Labels for integer x positions 0, 1, 2, … (categorical axis).
    pub x_categories: Option<Vec<String>>,
    pub layers: Vec<Layer>,
    /// Pixel size of the PNG (the SVG has the same nominal size).
    pub size: (u32, u32),
}

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
                Layer::Cells { cells, .. } => {
                    for (c, _) in cells {
                        xs.extend([c[0], c[2]]);
                        ys.extend([c[1], c[3]]);
                    }
                }
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

    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Result<(), String>
    where
        DB::ErrorType: 'static,
    {
        register_font();
        let e = |x: &dyn std::fmt::Display| x.to_string();
        root.fill(&WHITE).map_err(|x| e(&x))?;
        let ((x0, x1), (y0, y1)) = self.data_range();
        let (ya, yb) = if self.y_down { (y1, y0) } else { (y0, y1) };
        let mut chart = ChartBuilder::on(&root)
            .caption(&self.title, ("sans-serif", 22))
            .margin(14)
            .x_label_area_size(48)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, ya..yb)
            .map_err(|x| e(&x))?;
        let cats = self.x_categories.clone();
        let mut mesh = chart.configure_mesh();
        mesh.x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .light_line_style(WHITE)
            .bold_line_style(RGBColor(225, 225, 225));
        let fmt = move |v: &f64| match &cats {
            Some(c) => {
                let i = v.round();
                if (v - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < c.len() {
                    c[i as usize].clone()
                } else {
                    String::new()
                }
            }
            None => plotters_number(*v),
        };
        let yfmt = |v: &f64| plotters_number(*v);
        if let Some(c) = &self.x_categories {
            mesh.x_labels(c.len().min(40) + 1);
        }
        mesh.x_label_formatter(&fmt);
        mesh.y_label_formatter(&yfmt);
        mesh.draw().map_err(|x| e(&x))?;

        let mut has_legend = false;
        for layer in &self.layers {
            match layer {
                Layer::Cells { cells, color } => {
                    chart
                        .draw_series(cells.iter().map(|(c, v)| {
                            let v = v.clamp(0.0, 1.0);
                            let mix = |a: u8| (255.0 + (a as f64 - 255.0) * v).round() as u8;
                            let fill = RGBColor(mix(color.0), mix(color.1), mix(color.2));
                            Rectangle::new([(c[0], c[1]), (c[2], c[3])], fill.filled())
                        }))
                        .map_err(|x| e(&x))?;
                }
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
                    xy,
                    color,
                    size,
                    label,
                } => {
                    let c = *color;
                    let s = chart
                        .draw_series(
                            xy.iter()
                                .map(|p| Circle::new(*p, *size, c.mix(0.8).filled())),
                        )
                        .map_err(|x| e(&x))?;
                    if let Some(l) = label {
                        has_legend = true;
                        s.label(l)
                            .legend(move |(x, y)| Circle::new((x + 10, y), 4, c.filled()));
                    }
                }
                Layer::Line {
                    xy,
                    color,
                    width,
                    dashed,
                    label,
                } => {
                    has_legend |=
                        line(&mut chart, xy, *color, *width, *dashed, label).map_err(|x| e(&x))?;
                }
                Layer::HLine {
                    y,
                    color,
                    dashed,
                    label,
                } => {
                    let xy = [(x0, *y), (x1, *y)];
                    has_legend |=
                        line(&mut chart, &xy, *color, 2, *dashed, label).map_err(|x| e(&x))?;
                }
            }
        }
        if has_legend {
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .label_font(("sans-serif", 14))
                .background_style(WHITE.mix(0.85))
                .border_style(RGBColor(180, 180, 180))
                .draw()
                .map_err(|x| e(&x))?;
        }
        root.present().map_err(|x| e(&x))?;
        Ok(())
    }

    /// The figure as SVG text.
    pub fn to_svg(&self) -> Result<String, String> {
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, self.size).into_drawing_area();
            self.draw(root)?;
        }
        Ok(svg)
    }

    /// The figure as RGB8 pixels.
    pub fn to_rgb(&self) -> Result<Vec<u8>, String> {
        let (w, h) = self.size;
        let mut buf = vec![255u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            self.draw(root)?;
        }
        Ok(buf)
    }

    /// Write `<base>.png` and `<base>.svg`.
    pub fn save(&self, base: &Path) -> Result<(PathBuf, PathBuf)> {
        let png = base.with_extension("png");
        let svg = base.with_extension("svg");
        let pixels = self
            .to_rgb()
            .map_err(|m| Error::invalid(&png, format!("cannot draw: {m}")))?;
        crate::photo::write_8bit(&png, self.size.0, self.size.1, 3, &pixels, 0, None)?;
        let text = self
            .to_svg()
            .map_err(|m| Error::invalid(&svg, format!("cannot draw: {m}")))?;
        crate::output::write_bytes(&svg, text.as_bytes())?;
        Ok((png, svg))
    }
}

/// Draw a polyline, solid or dashed, with an optional legend entry; says whether it added one.
fn line<DB: DrawingBackend>(
    chart: &mut ChartContext<
        '_,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
    xy: &[(f64, f64)],
    color: RGBColor,
    width: u32,
    dashed: bool,
    label: &Option<String>,
) -> Result<bool, DrawingAreaErrorKind<DB::ErrorType>> {
    let style = color.stroke_width(width);
    let s = if dashed {
        chart.draw_series(DashedLineSeries::new(xy.iter().copied(), 8, 5, style))?
    } else {
        chart.draw_series(LineSeries::new(xy.iter().copied(), style))?
    };
    if let Some(l) = label {
        s.label(l)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], color.stroke_width(2)));
    }
    Ok(label.is_some())
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
