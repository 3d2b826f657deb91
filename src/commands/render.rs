//! `workbench render`: a mesh rendered with a fit's CDRF, or the renderer checked.

use super::{beside, Report};
use crate::cli::*;
use anyhow::{bail, Context, Result};
use std::fmt;
use std::path::PathBuf;
use workbench::render::check::SphereComparison;
use workbench::render::job::RenderReport;

pub(crate) fn render(a: RenderArgs) -> Result<Rendered> {
    let table = table_size(a.table, workbench::render::lut::DEFAULT_TOLERANCE);
    if a.check {
        let dir = a
            .out
            .clone()
            .unwrap_or_else(|| beside(&a.fit, "render-check"));
        let res = workbench::render::job::check(&a.fit, &dir, table)
            .with_context(|| format!("render --check {}", a.fit.display()))?;
        return Ok(Rendered::Check { spheres: res, dir });
    }
    let (Some(mesh), Some(out)) = (a.mesh.clone(), a.out.clone()) else {
        bail!("a mesh and --out are needed without --check");
    };
    let mut o = workbench::render::job::RenderOptions::new(&mesh, &a.fit, &out);
    o.unit = a.scene.unit;
    o.object_size_mm = a.scene.object_size;
    o.light_deg = a.scene.light.map(|[az, el]| (az, el));
    o.view = a.scene.view();
    (o.width, o.height) = a.resolution;
    o.fov_deg = a.scene.fov;
    o.samples = a.samples;
    o.shading = a.shading;
    o.bits = a.bits;
    o.tone = a.tone;
    o.exposure = a.exposure;
    o.table = table;
    let r =
        workbench::render::job::run(&o).with_context(|| format!("render {}", mesh.display()))?;
    Ok(Rendered::Image { r, out })
}

/// A mesh rendered, or the renderer checked against the fit's spheres.
pub(crate) enum Rendered {
    Check {
        spheres: Vec<SphereComparison>,
        dir: PathBuf,
    },
    Image {
        r: RenderReport,
        out: PathBuf,
    },
}

impl fmt::Display for Rendered {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        match self {
            Rendered::Check { spheres, dir } => {
                writeln!(
                    f,
                    "sphere               radius  pixels  silhouette  rel. RMS   largest"
                )?;
                for c in spheres {
                    writeln!(
                        f,
                        "{:<16} {:>2}  {:>5.1}  {:>6}  {:>10}  {:>8.2e}  {:>8.2e}",
                        c.image,
                        c.index,
                        c.radius_mm,
                        c.pixels,
                        c.silhouette_px,
                        c.rel_rmse,
                        c.max_rel
                    )?;
                }
                writeln!(f, "wrote    {}", dir.join("sphere-check.json").display())
            }
            Rendered::Image { r, out } => {
                writeln!(
                    f,
                    "mesh     {} vertices, {} triangles, {:.1} mm across",
                    r.vertices,
                    r.triangles,
                    2.0 * r.radius_mm
                )?;
                writeln!(
                    f,
                    "curvature 5/50/95%: {:.4} {:.4} {:.4} /mm; {:.1}% of vertices beyond the table's range (clamped)",
                    r.curvature[0],
                    r.curvature[1],
                    r.curvature[2],
                    100.0 * r.clamped
                )?;
                writeln!(
                    f,
                    "table    {}x{} (largest error {:.2e} of the peak); light azimuth {:.1}°, elevation {:.1}°",
                    r.table.0,
                    r.table.1,
                    r.table_error,
                    r.light.azimuth.to_degrees(),
                    r.light.elevation.to_degrees()
                )?;
                writeln!(
                    f,
                    "time     load {:.3} s, curvature {:.3} s, table {:.3} s, frame {:.1} ms, write {:.3} s",
                    r.load_s,
                    r.curvature_s,
                    r.table_s,
                    1e3 * r.frame_s,
                    r.write_s
                )?;
                writeln!(f, "wrote    {}", out.display())
            }
        }
    }
}

impl Report for Rendered {}
