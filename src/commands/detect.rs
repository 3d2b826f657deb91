//! `workbench detect`: spheres, highlights and the light; detections.json.

use super::Report;
use crate::cli::*;
use anyhow::Result;
use std::fmt;
use std::path::PathBuf;
use workbench::formats::detections::Detections;

pub(crate) fn detect(a: DetectArgs, quiet: bool) -> Result<Detected> {
    use workbench::detect::{self, Options};
    let opts = Options {
        session: a.session.clone(),
        out: a.out.clone(),
        overlays: !a.no_overlays,
        quiet,
        medium_outlines: medium_outlines(&a)?,
    };
    let d = detect::run(&opts)?;
    let out = a
        .out
        .unwrap_or_else(|| std::path::Path::new(&d.session).with_file_name("detections.json"));
    Ok(Detected { d, out })
}

/// Whether `detect --model` asks for the medium's outlines too: `auto` where session.json names
/// a diffuse reference, as `solve`'s auto then fits the medium (`SolveModel::resolve`).
fn medium_outlines(a: &DetectArgs) -> Result<bool> {
    use workbench::solve::SolveModel;
    let model = super::solve::solve_model(a.model);
    let with_reference = model == SolveModel::Auto
        && workbench::formats::session::Session::load(&a.session)?
            .0
            .reference
            .is_some();
    Ok(model
        .resolve(workbench::formats::fit::Method::Joint, with_reference)
        .medium_outlines())
}

/// What the detector found, and where it was written.
pub(crate) struct Detected {
    d: Detections,
    out: PathBuf,
}

impl fmt::Display for Detected {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        let d = &self.d;
        writeln!(f, "session  {} ({} camera)", d.session, d.projection)?;
        let deg = |v: &[f64; 3]| {
            let l = workbench::model::LightAngles::from_direction(&nalgebra::Vector3::from(*v));
            format!(
                "[{:+.4}, {:+.4}, {:+.4}] (az {:.2}°, el {:.2}°)",
                v[0],
                v[1],
                v[2],
                l.azimuth.to_degrees(),
                l.elevation.to_degrees()
            )
        };
        for im in &d.images {
            for n in &im.exif_notes {
                writeln!(f, "exif     {:<12} {n}", im.file)?;
            }
            for (k, s) in im.spheres.iter().enumerate() {
                let light = match (&s.light_direction, &s.highlight, &s.no_highlight) {
                    (Some(l), Some(h), _) => format!(
                        "light {} ± {:.3}°{}{}",
                        deg(l),
                        s.light_std_deg.unwrap_or(f64::NAN),
                        match h.method {
                            workbench::formats::detections::Method::LobeFit => " (lobe fit)",
                            workbench::formats::detections::Method::Centroid => " (centroid)",
                        },
                        if h.outlier { " OUTLIER" } else { "" }
                    ),
                    (_, _, Some(why)) => format!("no highlight: {why}"),
                    _ => "no highlight".into(),
                };
                let e = &s.ellipse;
                writeln!(
                    f,
                    "image    {:<12} #{} r {} mm: centre ({:.2}, {:.2}) px, axes {:.2}×{:.2} px ± {:.3} px; {light}",
                    im.file,
                    k + 1,
                    s.radius_mm,
                    e.center_px[0],
                    e.center_px[1],
                    e.axes_px[0],
                    e.axes_px[1],
                    s.silhouette_std_px[2],
                )?;
            }
            if d.light_direction.is_none() {
                if let Some(l) = &im.light_direction {
                    writeln!(
                        f,
                        "light    {:<12} {} ± {:.3}°",
                        im.file,
                        deg(l),
                        im.light_std_deg.unwrap_or(f64::NAN)
                    )?;
                }
            }
        }
        match (&d.light_direction, d.light) {
            (Some(l), _) => writeln!(
                f,
                "light    session {} ± {:.3}°{}",
                deg(l),
                d.light_std_deg.unwrap_or(f64::NAN),
                match d.light_scatter_deg {
                    Some(t) if t > 0.0 => {
                        format!(" (the spheres scatter {t:.3}° beyond their own errors)")
                    }
                    _ => String::new(),
                }
            )?,
            (None, workbench::formats::session::LightMode::Shared) => {
                writeln!(f, "light    none: no usable highlight on any sphere")?
            }
            (None, workbench::formats::session::LightMode::PerImage) => {}
        }
        writeln!(f, "wrote    {} in {:.2} s", self.out.display(), d.seconds)
    }
}

impl Report for Detected {}
