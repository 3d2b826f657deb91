//! `workbench detect`: spheres, highlights and the light; detections.json.

use crate::cli::*;
use anyhow::Result;

pub(crate) fn detect(a: DetectArgs, quiet: bool) -> Result<()> {
    use workbench::detect::{self, Options};
    let opts = Options {
        session: a.session.clone(),
        out: a.out.clone(),
        overlays: !a.no_overlays,
        quiet,
    };
    let d = detect::run(&opts)?;
    println!("session  {} ({} camera)", d.session, d.projection);
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
            println!("exif     {:<12} {n}", im.file);
        }
        for (k, s) in im.spheres.iter().enumerate() {
            let light = match (&s.light_direction, &s.highlight, &s.no_highlight) {
                (Some(l), Some(h), _) => format!(
                    "light {} ± {:.3}°{}{}",
                    deg(l),
                    s.light_std_deg.unwrap_or(f64::NAN),
                    match h.method {
                        workbench::detect::highlight::Method::LobeFit => " (lobe fit)",
                        workbench::detect::highlight::Method::Centroid => " (centroid)",
                    },
                    if h.outlier { " OUTLIER" } else { "" }
                ),
                (_, _, Some(why)) => format!("no highlight: {why}"),
                _ => "no highlight".into(),
            };
            let e = &s.ellipse;
            println!(
                "image    {:<12} #{} r {} mm: centre ({:.2}, {:.2}) px, axes {:.2}×{:.2} px ± {:.3} px; {light}",
                im.file,
                k + 1,
                s.radius_mm,
                e.center_px[0],
                e.center_px[1],
                e.axes_px[0],
                e.axes_px[1],
                s.silhouette_std_px[2],
            );
        }
        if d.light_direction.is_none() {
            if let Some(l) = &im.light_direction {
                println!(
                    "light    {:<12} {} ± {:.3}°",
                    im.file,
                    deg(l),
                    im.light_std_deg.unwrap_or(f64::NAN)
                );
            }
        }
    }
    match (&d.light_direction, d.light) {
        (Some(l), _) => println!(
            "light    session {} ± {:.3}°",
            deg(l),
            d.light_std_deg.unwrap_or(f64::NAN)
        ),
        (None, workbench::formats::session::LightMode::Shared) => {
            println!("light    none: no usable highlight on any sphere")
        }
        (None, workbench::formats::session::LightMode::PerImage) => {}
    }
    let out = a
        .out
        .unwrap_or_else(|| std::path::Path::new(&d.session).with_file_name("detections.json"));
    println!("wrote    {} in {:.2} s", out.display(), d.seconds);
    Ok(())
}
