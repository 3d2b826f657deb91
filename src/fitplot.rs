//! Figures of a fit (`solve --plots <dir>`), drawn with [`crate::plot`]: the green channel's
//! radiance against θ per radius (data as 1° bin means, the model's prediction at the same pixels
//! as lines; the held-out radius marked in the legend and drawn thicker), and the relative residual
//! against θ per radius.

use crate::error::Result;
use crate::model::{Model, Params};
use crate::observe::SphereData;
use crate::plot::{Layer, Plot, BLACK_LINE, PALETTE};
use std::path::{Path, PathBuf};

/// Per radius: θ bin centre (degrees), mean observed and mean predicted green radiance.
fn binned(model: &Model, p: &Params, s: &SphereData) -> Vec<(f64, f64, f64)> {
    let l = p.light.direction();
    let mut bins = vec![(0usize, 0.0, 0.0); 181];
    let stride = (s.obs.len() / 100_000).max(1);
    for o in s.obs.iter().step_by(stride) {
        let t = o
            .geometry
            .normal
            .dot(&l)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees();
        let b = &mut bins[t.floor() as usize];
        b.0 += 1;
        b.1 += o.radiance[1];
        b.2 += model.radiance(p, &o.geometry)[1];
    }
    bins.iter()
        .enumerate()
        .filter(|(_, b)| b.0 >= 3)
        .map(|(i, b)| (i as f64 + 0.5, b.1 / b.0 as f64, b.2 / b.0 as f64))
        .collect()
}

/// Write the figures (PNG + SVG each); `params_for` gives each sphere's parameters (the joint
/// fit's for all, or the paper's per-radius ones), `held_out` marks the held-out radius.
pub fn write_all(
    spheres: &[SphereData],
    params_for: &dyn Fn(&SphereData) -> Params,
    held_out: Option<f64>,
    title: &str,
    dir: &Path,
) -> Result<Vec<PathBuf>> {
    let model = Model::default();
    let mut radii: Vec<f64> = spheres.iter().map(|s| s.radius_mm).collect();
    radii.sort_by(|a, b| b.total_cmp(a));
    radii.dedup();
    let mut fig = Plot::new(
        &format!("{title}: green radiance against θ"),
        "θ, angle between normal and light (°)",
        "radiance (green, exposure-normalised)",
    );
    let mut res = Plot::new(
        &format!("{title}: relative residual against θ"),
        "θ, angle between normal and light (°)",
        "(model − data) / max data",
    );
    for (k, &r) in radii.iter().enumerate() {
        let color = PALETTE[k % PALETTE.len()];
        let held = held_out.is_some_and(|h| (h - r).abs() < 1e-9);
        let mut data = vec![];
        let mut pred = vec![];
        for s in spheres.iter().filter(|s| s.radius_mm == r) {
            let b = binned(&model, &params_for(s), s);
            data.extend(b.iter().map(|x| (x.0, x.1)));
            pred.extend(b.iter().map(|x| (x.0, x.2)));
        }
        let peak = data.iter().map(|x| x.1).fold(1e-12, f64::max);
        let resid: Vec<(f64, f64)> = data
            .iter()
            .zip(&pred)
            .map(|(d, p)| (d.0, (p.1 - d.1) / peak))
            .collect();
        let name = format!("r = {r} mm{}", if held { " (held out)" } else { "" });
        fig.layers.push(Layer::Points {
            xy: data,
            color,
            size: 2,
            label: Some(format!("{name} data")),
        });
        // Solid even when held out (a dashed line on a jagged, few-pixel curve is unreadable): the
        // legend says which radius was held out, and its line is thicker.
        fig.layers.push(Layer::Line {
            xy: pred,
            color,
            width: if held { 3 } else { 2 },
            dashed: false,
            label: Some(format!("{name} model")),
        });
        res.layers.push(Layer::Line {
            xy: resid,
            color,
            width: if held { 3 } else { 2 },
            dashed: false,
            label: Some(name),
        });
    }
    res.layers.push(Layer::HLine {
        y: 0.0,
        color: BLACK_LINE,
        dashed: true,
        label: None,
    });
    let mut files = vec![];
    for (plot, name) in [(fig, "radiance-theta"), (res, "residual-theta")] {
        let (png, svg) = plot.save(&dir.join(name))?;
        files.push(png);
        files.push(svg);
    }
    Ok(files)
}
