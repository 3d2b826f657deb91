//! Calibration figures, drawn with the shared [`crate::plot`] module: per-view reprojection error,
//! the corner residual scatter, and the corner coverage of the frame.

use super::{coverage, view_residuals, Calibration};
use crate::error::Result;
use crate::plot::{shade, Layer, Plot, Swatch, BLACK_LINE, BLUE, GREY, VERMILLION};
use nalgebra::Vector3;
use std::path::{Path, PathBuf};

/// Write all calibration figures (PNG + SVG each) into `dir`; returns the files.
pub(crate) fn write_all(
    cal: &Calibration,
    object: &[Vector3<f64>],
    size: [u32; 2],
    dir: &Path,
) -> Result<Vec<PathBuf>> {
    let mut files = vec![];
    for (plot, name) in [
        (per_view_errors(cal), "calibration-views"),
        (residual_scatter(cal, object), "calibration-residuals"),
        (coverage_map(cal, size), "calibration-coverage"),
    ] {
        let (png, svg) = plot.save(&dir.join(name))?;
        files.push(png);
        files.push(svg);
    }
    Ok(files)
}

/// Bars of per-view RMS error: used views blue, rejected vermillion, with the overall RMS and the
/// outlier limit.
pub(crate) fn per_view_errors(cal: &Calibration) -> Plot {
    let mut rows: Vec<(String, f64, bool)> = cal
        .used
        .iter()
        .map(|(v, _, e)| (v.file.clone(), *e, true))
        .collect();
    rows.extend(
        cal.rejected
            .iter()
            .map(|(v, e, _)| (v.file.clone(), *e, false)),
    );
    rows.sort_by(|a, b| a.0.cmp(&b.0));
    let all: Vec<f64> = rows.iter().map(|r| r.1).collect();
    let limit = cal.outlier_limit_px;
    let mut p = Plot::new(
        &format!(
            "Reprojection error per view (overall RMS {:.3} px)",
            cal.rms_px
        ),
        "view",
        "RMS reprojection error (px)",
    );
    p.x_categories = Some(rows.iter().map(|r| short(&r.0)).collect());
    p.x_range = Some((-0.7, rows.len() as f64 - 0.3));
    let top = all
        .iter()
        .cloned()
        .fold(if limit.is_finite() { limit } else { 0.0 }, f64::max);
    p.y_range = Some((0.0, 1.25 * top));
    p.layers.push(Layer::Bars {
        x: (0..rows.len()).map(|i| i as f64).collect(),
        heights: all.clone(),
        width: 0.7,
        colors: rows
            .iter()
            .map(|r| if r.2 { BLUE } else { VERMILLION })
            .collect(),
    });
    p.layers.push(Layer::HLine {
        y: cal.rms_px,
        color: BLACK_LINE,
        dashed: false,
        label: Some("overall RMS (used views)".into()),
    });
    if limit.is_finite() {
        p.layers.push(Layer::HLine {
            y: limit,
            color: VERMILLION,
            dashed: true,
            label: Some("outlier limit".into()),
        });
    }
    p.layers.push(Layer::Key {
        swatch: Swatch::Box(BLUE),
        label: "view used".into(),
    });
    if !cal.rejected.is_empty() {
        p.layers.push(Layer::Key {
            swatch: Swatch::Box(VERMILLION),
            label: "view rejected".into(),
        });
    }
    p
}

fn short(f: &str) -> String {
    let stem = f.rsplit_once('.').map(|s| s.0).unwrap_or(f);
    if stem.len() > 10 {
        format!("…{}", &stem[stem.len() - 9..])
    } else {
        stem.to_string()
    }
}

/// Every corner's residual (observed − projected) of the used views, with the RMS circle.
pub(crate) fn residual_scatter(cal: &Calibration, object: &[Vector3<f64>]) -> Plot {
    let mut xy = vec![];
    for (v, pose, _) in &cal.used {
        xy.extend(
            view_residuals(&cal.camera, pose, &v.corners, object)
                .iter()
                .map(|r| (r.x, r.y)),
        );
    }
    let lim = xy
        .iter()
        .map(|p| p.0.abs().max(p.1.abs()))
        .fold(cal.rms_px * 2.0, f64::max)
        * 1.1;
    let mut p = Plot::new(
        &format!(
            "Corner residuals, {} corners (RMS {:.3} px)",
            xy.len(),
            cal.rms_px
        ),
        "x residual (px)",
        "y residual (px)",
    );
    p.size = (700, 700);
    p.x_range = Some((-lim, lim));
    p.y_range = Some((-lim, lim));
    p.y_down = true;
    p.equal_aspect = true;
    p.layers.push(Layer::Points {
        xy,
        color: BLUE,
        size: 2,
        label: Some("corner".into()),
    });
    let circle: Vec<(f64, f64)> = (0..=120)
        .map(|k| {
            let t = k as f64 * std::f64::consts::TAU / 120.0;
            (cal.rms_px * t.cos(), cal.rms_px * t.sin())
        })
        .collect();
    p.layers.push(Layer::Line {
        xy: circle,
        color: VERMILLION,
        width: 2,
        dashed: false,
        label: Some("RMS radius".into()),
    });
    p
}

/// Where the corners of the used views fell: an 8×6 grid shaded by corner count, and the corners.
pub(crate) fn coverage_map(cal: &Calibration, size: [u32; 2]) -> Plot {
    let corners: Vec<_> = cal
        .used
        .iter()
        .flat_map(|(v, _, _)| v.corners.iter().cloned())
        .collect();
    let (gx, gy) = (8, 6);
    let cells = coverage(&corners, size, gx, gy);
    let max = cells.iter().cloned().max().unwrap_or(1).max(1) as f64;
    let (w, h) = (size[0] as f64, size[1] as f64);
    let covered = cells.iter().filter(|&&c| c > 0).count();
    let mut p = Plot::new(
        &format!("Corner coverage: {covered} of {} cells", gx * gy),
        "x (px)",
        "y (px)",
    );
    p.size = (900, (900.0 * h / w).round().clamp(400.0, 900.0) as u32 + 60);
    p.x_range = Some((0.0, w));
    p.y_range = Some((0.0, h));
    p.y_down = true;
    p.equal_aspect = true;
    p.layers.push(Layer::Cells {
        cells: (0..gx * gy)
            .map(|k| {
                let (i, j) = ((k % gx) as f64, (k / gx) as f64);
                (
                    [
                        i * w / gx as f64,
                        j * h / gy as f64,
                        (i + 1.0) * w / gx as f64,
                        (j + 1.0) * h / gy as f64,
                    ],
                    shade(GREY, 0.6 * cells[k] as f64 / max),
                )
            })
            .collect(),
    });
    p.layers.push(Layer::Line {
        xy: vec![(0.0, 0.0), (w, 0.0), (w, h), (0.0, h), (0.0, 0.0)],
        color: BLACK_LINE,
        width: 1,
        dashed: false,
        label: Some("frame".into()),
    });
    p.layers.push(Layer::Points {
        xy: corners.iter().map(|c| (c.x, c.y)).collect(),
        color: BLUE,
        size: 2,
        label: Some("detected corner".into()),
    });
    p
}
