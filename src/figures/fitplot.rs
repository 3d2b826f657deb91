//! Figures of a fit, drawn with [`crate::plot`] from `fit.json` and the session's pixels (so that
//! `workbench plot` redraws them without solving again):
//!
//! - `radiance-theta`: radiance against θ per channel, a thinned scatter of the pixels per radius,
//!   the fitted model's mean per 1° of θ as solid curves, the paper's baseline dashed;
//! - `residual-theta`, `residual-phi`: data − model (% of the radius's peak radiance) against θ and
//!   against φ (normal to view), one panel per radius, with running medians per channel;
//! - `residual-<photo>-<n>`: per sphere, the photo crop beside the false-colour residual image
//!   (diverging map, zero white, symmetric limits) and its colour bar;
//! - `correlation`: the free parameters' correlation matrix with values;
//! - `holdout`: predicted against observed for the held-out radius (with `--holdout`);
//! - `medium-radiance-theta`, `medium-residual-theta`: the same two against θ for the medium fit
//!   (`solve --model medium`), on its pixels and with its model;
//! - `index.html` ([`crate::figures::report`]): all of them with the fit's summary.

use crate::error::{Error, Result};
use crate::figures::report::Named;
use crate::fit::observe::SphereData;
use crate::formats::fit::{FitFile, MediumJson};
use crate::model::{Model, Params};
use crate::plot::{
    colorbar, diverging, Figure, Layer, Plot, Swatch, BLACK_LINE, BLUE, GREEN, GREY, PALETTE,
    VERMILLION,
};
use crate::stats::percentile;
use plotters::style::RGBColor;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// Channel names and their colours (Okabe–Ito, distinguishable without colour vision).
pub(crate) const CHANNELS: [&str; 3] = ["red", "green", "blue"];
pub(crate) const CHANNEL_COLORS: [RGBColor; 3] = [VERMILLION, GREEN, BLUE];
/// Pixels evaluated per sphere (every k-th beyond this).
const PIXELS: usize = 200_000;
/// Points drawn per scatter (every k-th beyond this): keeps the SVGs near a megabyte.
const SCATTER: usize = 1500;
/// Cells without data in the residual images.
const NO_DATA: RGBColor = RGBColor(190, 190, 190);

/// One sphere's pixels with the model's prediction.
struct Evaluated<'a> {
    sphere: &'a SphereData,
    /// Degrees.
    theta: Vec<f64>,
    phi: Vec<f64>,
    data: Vec<[f64; 3]>,
    model: Vec<[f64; 3]>,
    baseline: Option<Vec<[f64; 3]>>,
    px: Vec<[u32; 2]>,
}

fn evaluate<'a>(
    s: &'a SphereData,
    model: &Model,
    p: &Params,
    baseline: Option<&Params>,
) -> Evaluated<'a> {
    let paper = crate::fit::paper::predicting_model();
    let l = p.light.direction();
    let stride = (s.obs.len() / PIXELS).max(1);
    let idx: Vec<usize> = (0..s.obs.len()).step_by(stride).collect();
    let angle = |a: f64| a.clamp(-1.0, 1.0).acos().to_degrees();
    let rows: Vec<_> = idx
        .par_iter()
        .map(|&k| {
            let o = &s.obs[k];
            let g = &o.geometry;
            (
                angle(g.normal.dot(&l)),
                angle(g.normal.dot(&g.view)),
                o.radiance,
                model.radiance(p, g),
                baseline.map(|b| paper.radiance(b, g)),
                s.px[k],
            )
        })
        .collect();
    Evaluated {
        sphere: s,
        theta: rows.iter().map(|r| r.0).collect(),
        phi: rows.iter().map(|r| r.1).collect(),
        data: rows.iter().map(|r| r.2).collect(),
        model: rows.iter().map(|r| r.3).collect(),
        baseline: baseline.map(|_| rows.iter().map(|r| r.4.unwrap_or([0.0; 3])).collect()),
        px: rows.iter().map(|r| r.5).collect(),
    }
}

/// The spheres of one radius.
struct Group<'a> {
    radius_mm: f64,
    held_out: bool,
    color: RGBColor,
    spheres: Vec<Evaluated<'a>>,
    /// Per channel: the 99.5th percentile of the data (the residuals' scale).
    peak: [f64; 3],
}

impl Group<'_> {
    fn label(&self) -> String {
        let n = self.spheres.len();
        format!(
            "r = {} mm{}{}",
            self.radius_mm,
            if n > 1 {
                format!(" ({n} spheres)")
            } else {
                String::new()
            },
            if self.held_out { ", held out" } else { "" }
        )
    }

    fn all<'b, T: 'b>(
        &'b self,
        f: impl Fn(&'b Evaluated<'_>) -> &'b Vec<T> + 'b,
    ) -> impl Iterator<Item = &'b T> + 'b {
        self.spheres.iter().flat_map(move |e| f(e).iter())
    }
}

/// Medians of y in windows of x of width `window` every `step`, where a window holds at least
/// `min` points.
pub(crate) fn running_median(
    x: &[f64],
    y: &[f64],
    window: f64,
    step: f64,
    min: usize,
) -> Vec<(f64, f64)> {
    let mut xy: Vec<(f64, f64)> = x
        .iter()
        .zip(y)
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| (*a, *b))
        .collect();
    if xy.is_empty() {
        return vec![];
    }
    xy.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (lo, hi) = (xy[0].0, xy[xy.len() - 1].0);
    let mut out = vec![];
    let mut c = lo;
    while c <= hi {
        let a = xy.partition_point(|p| p.0 < c - window / 2.0);
        let b = xy.partition_point(|p| p.0 <= c + window / 2.0);
        if b - a >= min.max(1) {
            let mut w: Vec<f64> = xy[a..b].iter().map(|p| p.1).collect();
            let m = w.len() / 2;
            out.push((c, *w.select_nth_unstable_by(m, |p, q| p.total_cmp(q)).1));
        }
        c += step;
    }
    out
}

/// Means of `f` per 1° of θ (bins with at least 3 pixels).
fn binned(theta: &[f64], v: impl Fn(usize) -> f64) -> Vec<(f64, f64)> {
    let mut bins = vec![(0usize, 0.0); 181];
    for (k, t) in theta.iter().enumerate() {
        let b = &mut bins[(t.floor().max(0.0) as usize).min(180)];
        b.0 += 1;
        b.1 += v(k);
    }
    bins.iter()
        .enumerate()
        .filter(|(_, b)| b.0 >= 3)
        .map(|(i, b)| (i as f64 + 0.5, b.1 / b.0 as f64))
        .collect()
}

fn stride(n: usize, max: usize) -> usize {
    n.div_ceil(max.max(1)).max(1)
}

/// The θ range of the radiance figure's lower row (degrees).
const ZOOM_DEG: (f64, f64) = (60.0, 125.0);

/// Radiance against θ, one panel per channel, and below each the range near the terminator.
fn radiance_theta(groups: &[Group], fitted: &str, baseline: bool) -> Figure {
    let mut panels = vec![];
    let mut zooms = vec![];
    let mut keys = vec![];
    for (c, name) in CHANNELS.iter().enumerate() {
        let mut p = Plot::new(
            &format!("{name} channel"),
            "θ, normal to light (°)",
            if c == 0 {
                "radiance (pixel value / exposure)"
            } else {
                ""
            },
        );
        // Every radius's pixels first, then the curves on top of them all.
        let mut curves = vec![];
        for g in groups {
            let n: usize = g.spheres.iter().map(|e| e.data.len()).sum();
            let k = stride(n, SCATTER);
            let theta: Vec<f64> = g.all(|e| &e.theta).cloned().collect();
            let data: Vec<[f64; 3]> = g.all(|e| &e.data).cloned().collect();
            let model: Vec<[f64; 3]> = g.all(|e| &e.model).cloned().collect();
            p.layers.push(Layer::Points {
                xy: (0..n).step_by(k).map(|i| (theta[i], data[i][c])).collect(),
                color: g.color,
                size: 1,
                label: None,
            });
            curves.push(Layer::Line {
                xy: binned(&theta, |i| model[i][c]),
                color: g.color,
                width: if g.held_out { 3 } else { 2 },
                dashed: false,
                label: None,
            });
            if baseline {
                let b: Vec<[f64; 3]> = g
                    .spheres
                    .iter()
                    .flat_map(|e| e.baseline.clone().unwrap_or_default())
                    .collect();
                curves.push(Layer::Line {
                    xy: binned(&theta, |i| b[i][c]),
                    color: g.color,
                    width: 2,
                    dashed: true,
                    label: None,
                });
            }
        }
        p.layers.extend(curves);
        // The same near the terminator, where the radii part: light bleeding past it.
        let mut zoom = p.clone();
        zoom.title = format!("{name} channel near the terminator");
        zoom.x_range = Some(ZOOM_DEG);
        let top = zoom
            .layers
            .iter()
            .filter_map(|l| match l {
                Layer::Line { xy, .. } => Some(xy),
                _ => None,
            })
            .flatten()
            .filter(|q| q.0 >= ZOOM_DEG.0 && q.0 <= ZOOM_DEG.1)
            .fold(0.0, |t: f64, q| t.max(q.1));
        zoom.y_range = Some((-0.03 * top, 1.05 * top));
        for l in zoom.layers.iter_mut() {
            if let Layer::Points { xy, .. } = l {
                xy.retain(|q| q.0 >= ZOOM_DEG.0 && q.0 <= ZOOM_DEG.1 && q.1 <= 1.05 * top);
            }
        }
        panels.push((Some(p), 1.0));
        zooms.push((Some(zoom), 1.0));
    }
    for g in groups {
        keys.push((Swatch::Box(g.color), g.label()));
    }
    keys.push((
        Swatch::Point(GREY),
        format!("pixels (at most {SCATTER} a radius)"),
    ));
    keys.push((
        Swatch::Line {
            color: BLACK_LINE,
            width: 2,
            dashed: false,
        },
        format!("{fitted}, mean per 1°"),
    ));
    if baseline {
        keys.push((
            Swatch::Line {
                color: BLACK_LINE,
                width: 2,
                dashed: true,
            },
            "paper's baseline".into(),
        ));
    }
    Figure {
        title: "Radiance against θ per radius: pixels and fitted model".into(),
        rows: vec![panels, zooms],
        legend: keys,
        size: (1700, 1040),
    }
}

/// The residual-against-φ figure shows pixels with θ below this (degrees).
const LIT_DEG: f64 = 85.0;

#[derive(Clone, Copy, PartialEq)]
enum Axis {
    Theta,
    Phi,
}

/// Data − model against θ or φ, one panel per radius: the green channel's pixels and each
/// channel's running median.
fn residual_against(groups: &[Group], axis: Axis) -> Figure {
    let x_of = |e: &Evaluated, i: usize| match axis {
        Axis::Theta => e.theta[i],
        Axis::Phi => e.phi[i],
    };
    // Per group: x, residual per channel (% of peak).
    let series: Vec<(Vec<f64>, [Vec<f64>; 3])> = groups
        .iter()
        .map(|g| {
            let mut x = vec![];
            let mut r: [Vec<f64>; 3] = Default::default();
            for e in &g.spheres {
                // Against φ only the lit pixels: the dark side's zeros would pin the medians.
                for i in (0..e.data.len()).filter(|&i| axis == Axis::Theta || e.theta[i] < LIT_DEG)
                {
                    x.push(x_of(e, i));
                    for (c, rc) in r.iter_mut().enumerate() {
                        rc.push(100.0 * (e.data[i][c] - e.model[i][c]) / g.peak[c]);
                    }
                }
            }
            (x, r)
        })
        .collect();
    let medians: Vec<[Vec<(f64, f64)>; 3]> = series
        .iter()
        .map(|(x, r)| std::array::from_fn(|c| running_median(x, &r[c], 3.0, 0.5, 15)))
        .collect();
    let spread = series
        .iter()
        .map(|(_, r)| percentile(r[1].iter().map(|v| v.abs()).collect(), 0.99))
        .chain(
            medians
                .iter()
                .flat_map(|m| m.iter().flatten().map(|p| 1.3 * p.1.abs())),
        )
        .filter(|v| v.is_finite())
        .fold(0.1, f64::max)
        * 1.1;
    let (name, label) = match axis {
        Axis::Theta => ("θ".to_string(), "θ, normal to light (°)"),
        Axis::Phi => (
            format!("φ (lit pixels, θ < {LIT_DEG}°)"),
            "φ, normal to view (°)",
        ),
    };
    let cols = if groups.len() == 4 {
        2
    } else {
        groups.len().clamp(1, 3)
    };
    let mut panels = vec![];
    for (k, g) in groups.iter().enumerate() {
        let (x, r) = &series[k];
        let mut p = Plot::new(
            &g.label(),
            label,
            if k % cols == 0 {
                "data − model (% of peak)"
            } else {
                ""
            },
        );
        p.y_range = Some((-spread, spread));
        let s = stride(x.len(), SCATTER);
        p.layers.push(Layer::Points {
            xy: (0..x.len())
                .step_by(s)
                .filter(|&i| r[1][i].abs() <= spread)
                .map(|i| (x[i], r[1][i]))
                .collect(),
            color: RGBColor(170, 170, 170),
            size: 1,
            label: Some("green channel pixels (thinned)".into()),
        });
        p.layers.push(Layer::HLine {
            y: 0.0,
            color: BLACK_LINE,
            dashed: true,
            label: None,
        });
        for c in 0..3 {
            p.layers.push(Layer::Line {
                xy: medians[k][c].clone(),
                color: CHANNEL_COLORS[c],
                width: 2,
                dashed: false,
                label: Some(format!("{} channel, running median (3°)", CHANNELS[c])),
            });
        }
        panels.push(p);
    }
    let rows = Figure::grid(panels, cols);
    let n_rows = rows.len() as u32;
    Figure {
        title: format!("Residual against {name} per radius (positive: the data are brighter)"),
        rows,
        legend: vec![],
        size: (1500, 60 + 380 * n_rows),
    }
}

/// The photo crop, the residual image and its colour bar for one sphere.
fn residual_image(g: &Group, e: &Evaluated) -> Option<Figure> {
    let crop = &e.sphere.crop;
    if crop.width == 0 || crop.height == 0 {
        return None;
    }
    let (w, h) = (crop.width as usize, crop.height as usize);
    let mut sum = vec![(0.0, 0usize); w * h];
    for (i, px) in e.px.iter().enumerate() {
        if let Some((ci, cj)) = crop.cell(*px) {
            let v = (0..3)
                .map(|c| (e.data[i][c] - e.model[i][c]) / g.peak[c])
                .sum::<f64>()
                / 3.0;
            let cell = &mut sum[cj as usize * w + ci as usize];
            cell.0 += 100.0 * v;
            cell.1 += 1;
        }
    }
    let values: Vec<Option<f64>> = sum
        .iter()
        .map(|(s, n)| (*n > 0).then(|| s / *n as f64))
        .collect();
    let limit = percentile(values.iter().flatten().map(|v| v.abs()).collect(), 0.99);
    let limit = if limit.is_finite() {
        limit.max(0.05)
    } else {
        1.0
    };
    let rgb: Vec<u8> = values
        .iter()
        .flat_map(|v| {
            let c = v.map_or(NO_DATA, |v| diverging(v / limit));
            [c.0, c.1, c.2]
        })
        .collect();
    let step = crop.step as f64;
    let extent = [
        crop.x0 as f64,
        crop.y0 as f64,
        crop.x0 as f64 + w as f64 * step,
        crop.y0 as f64 + h as f64 * step,
    ];
    // Square axes around the crop: the pictures keep their aspect ratio.
    let side = (w.max(h) as f64) * step;
    let (cx, cy) = (0.5 * (extent[0] + extent[2]), 0.5 * (extent[1] + extent[3]));
    let panel = |title: &str, rgb: Vec<u8>| {
        let mut p = Plot::new(title, "x (px)", "y (px)");
        p.x_range = Some((cx - side / 2.0, cx + side / 2.0));
        p.y_range = Some((cy - side / 2.0, cy + side / 2.0));
        p.y_down = true;
        p.grid = false;
        p.equal_aspect = true;
        p.layers.push(Layer::Image {
            extent,
            width: w as u32,
            height: h as u32,
            rgb,
        });
        p
    };
    let photo = panel(
        &if crop.gain > 1.0 {
            format!("photo (brightened ×{:.1})", crop.gain)
        } else {
            "photo".to_string()
        },
        crop.rgb.clone(),
    );
    let mut res = panel("data − model, mean of r, g, b (% of peak)", rgb);
    res.y_label = String::new();
    res.layers.push(Layer::Key {
        swatch: Swatch::Box(NO_DATA),
        label: "no data (off the sphere, saturated, edge)".into(),
    });
    let s = e.sphere;
    Some(Figure {
        title: format!(
            "{}, sphere {} (r = {} mm){}: photo and residual",
            s.image,
            s.index + 1,
            s.radius_mm,
            if g.held_out { ", held out" } else { "" }
        ),
        rows: vec![vec![
            (Some(photo), 1.0),
            (Some(res), 1.0),
            (Some(colorbar("residual (% of peak)", limit)), 0.28),
        ]],
        legend: vec![],
        size: (1400, 560),
    })
}

/// Short display names of the parameters.
pub(crate) fn short_name(name: &str) -> String {
    match name {
        "sigma0_r" => "σ0 r",
        "sigma0_g" => "σ0 g",
        "sigma0_b" => "σ0 b",
        "albedo_r" => "albedo r",
        "albedo_g" => "albedo g",
        "albedo_b" => "albedo b",
        "eta" => "η",
        "ks" => "ks",
        "alpha" => "α",
        "light_azimuth" => "light az",
        "light_elevation" => "light el",
        "sigma_exponent" => "q",
        "albedo_curvature" => "b",
        "kernel_weight" => "w",
        "kernel_ratio" => "s",
        other => other,
    }
    .to_string()
}

/// The free parameters' correlation matrix, cells coloured by value, values written.
fn correlation(fit: &FitFile) -> Option<Figure> {
    let names: Vec<String> = fit
        .correlation
        .names
        .iter()
        .map(|n| short_name(n))
        .collect();
    let m = &fit.correlation.matrix;
    let n = names.len();
    if n == 0 || m.len() != n || m.iter().any(|r| r.len() != n) {
        return None;
    }
    let mut p = Plot::new("", "", "");
    p.x_categories = Some(names.clone());
    p.y_categories = Some(names);
    p.x_range = Some((-0.5, n as f64 - 0.5));
    p.y_range = Some((-0.5, n as f64 - 0.5));
    p.y_down = true;
    p.grid = false;
    let mut cells = vec![];
    let mut text = vec![];
    for (i, row) in m.iter().enumerate() {
        for (j, &v) in row.iter().enumerate() {
            let (x, y) = (j as f64, i as f64);
            cells.push(([x - 0.5, y - 0.5, x + 0.5, y + 0.5], diverging(v)));
            let ink = if v.abs() > 0.65 {
                RGBColor(255, 255, 255)
            } else {
                BLACK_LINE
            };
            text.push(((x, y), format!("{v:.2}"), ink));
        }
    }
    p.layers.push(Layer::Cells { cells });
    p.layers.push(Layer::Text {
        items: text,
        size: if n > 10 { 12 } else { 14 },
    });
    let side = 64 * n as u32 + 140;
    Some(Figure {
        title: format!("Correlation of the {n} fitted parameters"),
        rows: vec![vec![
            (Some(p), side as f64),
            (Some(colorbar("correlation", 1.0)), 150.0),
        ]],
        legend: vec![],
        size: (side + 150, side + 40),
    })
}

/// Predicted against observed radiance for the held-out radius, per channel.
fn holdout(fit: &FitFile, g: &Group) -> Figure {
    let mut p = Plot::new("", "observed radiance", "predicted radiance");
    let mut top: f64 = 0.0;
    for c in 0..3 {
        let d: Vec<(f64, f64)> = g
            .spheres
            .iter()
            .flat_map(|e| e.data.iter().zip(&e.model).map(move |(d, m)| (d[c], m[c])))
            .collect();
        let k = stride(d.len(), SCATTER);
        top = d.iter().fold(top, |t, p| t.max(p.0).max(p.1));
        p.layers.push(Layer::Points {
            xy: d.iter().step_by(k).cloned().collect(),
            color: CHANNEL_COLORS[c],
            size: 2,
            label: Some(if k == 1 {
                format!("{} channel, all {} pixels", CHANNELS[c], d.len())
            } else {
                format!("{} channel, 1 in {k} pixels", CHANNELS[c])
            }),
        });
    }
    let lo = -0.03 * top;
    p.x_range = Some((lo, 1.05 * top));
    p.y_range = Some((lo, 1.05 * top));
    p.layers.push(Layer::Line {
        xy: vec![(lo, lo), (1.05 * top, 1.05 * top)],
        color: BLACK_LINE,
        width: 1,
        dashed: true,
        label: Some("predicted = observed".into()),
    });
    let rel = fit
        .holdout
        .as_ref()
        .map(|h| format!(" (relative RMSE {:.2}%)", 100.0 * h.rel_rmse))
        .unwrap_or_default();
    Figure {
        title: format!(
            "Held-out r = {} mm predicted by the fit to the other radii{rel}",
            g.radius_mm
        ),
        rows: vec![vec![(Some(p), 1.0)]],
        legend: vec![],
        size: (1000, 760),
    }
}

/// Every figure of a fit (not yet written): radiance and residuals against θ and φ, the
/// correlation, the holdout, a residual image per sphere.
pub fn figures(
    fit: &FitFile,
    (spheres, medium): (&[SphereData], Option<&[SphereData]>),
) -> Vec<Named> {
    let groups = groups(fit, spheres);
    let fitted = match fit.method {
        crate::formats::fit::Method::Joint => "joint fit",
        crate::formats::fit::Method::Paper => "paper's fit per radius",
    };
    let mut out = vec![
        Named {
            name: "radiance-theta".into(),
            caption: format!(
                "Radiance against θ per channel: pixels per radius, the {fitted} as solid curves{}.",
                if fit.baseline.is_some() {
                    ", the paper's baseline dashed"
                } else {
                    ""
                }
            ),
            figure: radiance_theta(&groups, fitted, fit.baseline.is_some()),
        },
        Named {
            name: "residual-theta".into(),
            caption: "Data − model against θ per radius (% of the radius's peak radiance), running medians per channel.".into(),
            figure: residual_against(&groups, Axis::Theta),
        },
        Named {
            name: "residual-phi".into(),
            caption: format!("Data − model against φ (normal to view) for the lit pixels (θ < {LIT_DEG}°): Fresnel and specular misfit shows here."),
            figure: residual_against(&groups, Axis::Phi),
        },
    ];
    if let Some(f) = correlation(fit) {
        out.push(Named {
            name: "correlation".into(),
            caption: "Correlation of the fitted parameters (from the covariance at the solution)."
                .into(),
            figure: f,
        });
    }
    if let Some(g) = groups.iter().find(|g| g.held_out) {
        out.push(Named {
            name: "holdout".into(),
            caption: format!(
                "Held-out radius {} mm: predicted against observed radiance per pixel.",
                g.radius_mm
            ),
            figure: holdout(fit, g),
        });
    }
    if let Some(m) = &fit.medium {
        let medium = medium_groups(fit, m, &groups, medium);
        out.push(Named {
            name: "medium-radiance-theta".into(),
            caption: "The medium fit (solve --model medium): its pixels (off the highlight and the rim, θ up to 105°) against θ per channel, per radius, its model's prediction as solid curves.".into(),
            figure: radiance_theta(&medium, "medium fit", false),
        });
        out.push(Named {
            name: "medium-residual-theta".into(),
            caption: "The medium fit: data − its model against θ per radius (% of the radius's peak radiance), running medians per channel.".into(),
            figure: residual_against(&medium, Axis::Theta),
        });
    }
    out.extend(groups.iter().flat_map(residual_images));
    out
}

/// The spheres by radius under the medium fit (fit.json's `"medium"`): each sphere's pixels the
/// medium fit uses ([`crate::fit::medium::fitted`] under the joint fit's light, every channel
/// weighted) with its model's prediction there ([`crate::fit::medium::predict_with`], the
/// profiles computed once a radius), in the colours and scales of `groups`. Each sphere's
/// pixels are its counterpart's in `seated` where given (the same sphere seated on the outline
/// drawn for the medium, `solve::medium::medium_spheres`).
fn medium_groups<'a>(
    fit: &FitFile,
    m: &MediumJson,
    groups: &[Group<'a>],
    seated: Option<&'a [SphereData]>,
) -> Vec<Group<'a>> {
    use crate::fit::medium::{self, Px, Radius};
    let angle = |a: f64| a.clamp(-1.0, 1.0).acos().to_degrees();
    let seated_of = |s: &'a SphereData| -> &'a SphereData {
        seated
            .and_then(|all| {
                all.iter()
                    .find(|x| x.image == s.image && x.index == s.index)
            })
            .unwrap_or(s)
    };
    groups
        .par_iter()
        .map(|g| {
            let light = fit.params_for(g.radius_mm).light.direction();
            let spheres: Vec<&SphereData> = g.spheres.iter().map(|e| seated_of(e.sphere)).collect();
            // Per sphere: the indices of its observations the medium fit uses.
            let chosen: Vec<Vec<usize>> = spheres
                .iter()
                .map(|s| {
                    let stride = (s.obs.len() / PIXELS).max(1);
                    (0..s.obs.len())
                        .step_by(stride)
                        .filter(|&i| medium::fitted_obs(&s.obs[i], &light))
                        .collect()
                })
                .collect();
            let obs = || {
                spheres
                    .iter()
                    .zip(&chosen)
                    .flat_map(|(s, idx)| idx.iter().map(move |&i| &s.obs[i]))
            };
            let px = |c: usize| -> Vec<Px> {
                obs()
                    .map(|o| {
                        let n = &o.geometry.normal;
                        Px::at(n, &o.geometry.view, &light, o.radiance[c], o.weight[c])
                    })
                    .collect()
            };
            let radius = Radius {
                radius_mm: g.radius_mm,
                pixels: [px(0), px(1), px(2)],
            };
            let model = medium::predict_with(m.media(), m.irradiance.value, m.alpha, &radius);
            let mut at = 0;
            let spheres = spheres
                .iter()
                .zip(&chosen)
                .map(|(&s, idx)| {
                    let rows = at..at + idx.len();
                    at += idx.len();
                    Evaluated {
                        sphere: s,
                        theta: rows
                            .clone()
                            .map(|k| angle(radius.pixels[0][k].cos_theta))
                            .collect(),
                        phi: rows
                            .clone()
                            .map(|k| angle(radius.pixels[0][k].cos_phi))
                            .collect(),
                        data: idx.iter().map(|&i| s.obs[i].radiance).collect(),
                        model: rows.map(|k| std::array::from_fn(|c| model[c][k])).collect(),
                        baseline: None,
                        px: idx.iter().map(|&i| s.px[i]).collect(),
                    }
                })
                .collect();
            Group {
                radius_mm: g.radius_mm,
                held_out: g.held_out,
                color: g.color,
                spheres,
                peak: g.peak,
            }
        })
        .collect()
}

/// The spheres by radius, largest first, each evaluated under the fit (and the baseline).
fn groups<'a>(fit: &FitFile, spheres: &'a [SphereData]) -> Vec<Group<'a>> {
    let held = |r: f64| {
        fit.holdout
            .as_ref()
            .is_some_and(|h| (h.radius_mm - r).abs() < 1e-9)
    };
    let mut radii = crate::fit::observe::distinct_radii(&spheres.iter().collect::<Vec<_>>());
    radii.reverse();
    let model = fit.model();
    radii
        .iter()
        .enumerate()
        .map(|(k, &r)| {
            let p = fit.params_for(r);
            let b = fit.baseline.as_ref().map(|b| b.params_for(r));
            let spheres: Vec<Evaluated> = spheres
                .iter()
                .filter(|s| (s.radius_mm - r).abs() < 1e-9)
                .map(|s| evaluate(s, &model, &p, b.as_ref()))
                .collect();
            let peak = std::array::from_fn(|c| {
                let v = percentile(
                    spheres
                        .iter()
                        .flat_map(|e| e.data.iter().map(|d| d[c]))
                        .collect(),
                    0.995,
                );
                if v.is_finite() && v > 0.0 {
                    v
                } else {
                    1.0
                }
            });
            Group {
                radius_mm: r,
                held_out: held(r),
                color: PALETTE[k % (PALETTE.len() - 1)],
                spheres,
                peak,
            }
        })
        .collect()
}

/// The residual image's name of the `index`-th sphere of photo `image`: `residual-<stem>-<n>`,
/// the stem's characters other than letters, digits, `-` and `_` replaced by `_`.
fn residual_name(image: &str, index: usize) -> String {
    let stem: String = Path::new(image)
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_default()
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    format!("residual-{stem}-{}", index + 1)
}

/// The names (without extension) of every figure [`write_all`] may draw for `fit`: what another
/// reader of the plots folder (the browser page) takes from it, and nothing else.
pub(crate) fn figure_names(fit: &FitFile) -> Vec<String> {
    let fixed = [
        "radiance-theta",
        "residual-theta",
        "residual-phi",
        "correlation",
        "holdout",
    ];
    let mut names: Vec<String> = fixed.iter().map(|n| n.to_string()).collect();
    names.extend(
        fit.rmse
            .spheres
            .iter()
            .map(|s| residual_name(&s.image, s.index)),
    );
    names
}

/// The residual image of each sphere of a group.
fn residual_images(g: &Group) -> Vec<Named> {
    let mut out = vec![];
    for e in &g.spheres {
        if let Some(f) = residual_image(g, e) {
            out.push(Named {
                name: residual_name(&e.sphere.image, e.sphere.index),
                caption: format!(
                    "{}, sphere {} (r = {} mm): the photo and data − model per pixel block.",
                    e.sphere.image,
                    e.sphere.index + 1,
                    e.sphere.radius_mm
                ),
                figure: f,
            });
        }
    }
    out
}

/// Draw every figure of a fit into `dir` (PNG and SVG each) with `index.html`; returns the files.
pub(crate) fn write_all(
    fit: &FitFile,
    fit_path: &Path,
    spheres: (&[SphereData], Option<&[SphereData]>),
    dir: &Path,
) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let named = figures(fit, spheres);
    let files: Vec<(PathBuf, PathBuf)> = named
        .par_iter()
        .map(|n| n.figure.save(&dir.join(&n.name)))
        .collect::<Result<_>>()?;
    let index = crate::figures::report::write_index(fit, fit_path, &named, dir)?;
    let mut out: Vec<PathBuf> = files.into_iter().flat_map(|(a, b)| [a, b]).collect();
    out.push(index);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::PARAM_NAMES;

    #[test]
    fn running_median_of_a_line_with_outliers() {
        let x: Vec<f64> = (0..1000).map(|i| i as f64 * 0.1).collect();
        let y: Vec<f64> = x
            .iter()
            .enumerate()
            .map(|(i, v)| match i % 20 {
                // Outliers on both sides: the median stays on the line.
                0 => 1e6,
                10 => -1e6,
                _ => 2.0 * v,
            })
            .collect();
        let m = running_median(&x, &y, 2.0, 1.0, 5);
        assert!(m.len() > 90);
        for (c, v) in &m[2..m.len() - 2] {
            assert!((v - 2.0 * c).abs() < 0.25, "{c}: {v}");
        }
    }

    #[test]
    fn names_cover_parameters() {
        let short: std::collections::HashSet<String> =
            PARAM_NAMES.iter().map(|n| short_name(n)).collect();
        assert_eq!(short.len(), PARAM_NAMES.len());
        assert!(short.iter().all(|s| !s.is_empty() && !s.contains('_')));
    }
}
