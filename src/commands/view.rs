//! `workbench view`: the page that shows a fit's material in the browser.

use super::{beside, Report};
use crate::cli::*;
use anyhow::{bail, Context, Result};
use std::fmt;
use std::path::PathBuf;
use workbench::render::view::{ViewMesh, ViewOptions, ViewReport};

pub(crate) fn view(a: ViewArgs) -> Result<Viewed> {
    let out = a.out.clone().unwrap_or_else(|| beside(&a.fit, "view"));
    let sc = &a.scene;
    if !(sc.fov > 1.0 && sc.fov < 170.0) {
        bail!("--fov must be in (1, 170) degrees, got {}", sc.fov);
    }
    if !sc.distance.is_finite() || sc.distance < 1.0 {
        bail!("--distance must be ≥ 1, got {}", sc.distance);
    }
    let mesh = match &a.mesh {
        Some(m) => {
            let p = workbench::render::job::prepare(m, sc.unit, sc.object_size)
                .with_context(|| format!("view --mesh {}", m.display()))?;
            Some(ViewMesh {
                mesh: p.mesh,
                curvature: p.curvature,
            })
        }
        None => None,
    };
    let r = workbench::render::view::write(ViewOptions {
        fit: &a.fit,
        out: &out,
        mesh,
        light_deg: sc.light.map(|[az, el]| (az, el)),
        view: sc.view(),
        fov_deg: sc.fov,
    })
    .with_context(|| format!("view {}", a.fit.display()))?;
    Ok(Viewed { r, out })
}

/// The page written.
pub(crate) struct Viewed {
    r: ViewReport,
    out: PathBuf,
}

impl fmt::Display for Viewed {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        let r = &self.r;
        writeln!(
            f,
            "table    {}x{} texels (generic preset), largest sampled error {:.2e} of the peak",
            r.table.0, r.table.1, r.table_error
        )?;
        writeln!(
            f,
            "scene    {} spheres{}; light azimuth {:.1}°, elevation {:.1}° (camera frame); exposure {:.3}",
            r.spheres,
            r.mesh_vertices
                .map_or(String::new(), |n| format!(" and a mesh of {n} vertices")),
            r.light_deg.0,
            r.light_deg.1,
            r.exposure
        )?;
        writeln!(f, "wrote    {} files", r.files.len())?;
        writeln!(f, "open     {}", self.out.join("index.html").display())?;
        Ok(())
    }
}

impl Report for Viewed {}
