//! `workbench export`: a fit's measured medium in the files renderers read
//! ([`workbench::formats::material_export`]), written as one set.

use super::{beside, Report};
use crate::cli::*;
use anyhow::{Context, Result};
use std::fmt;
use std::path::PathBuf;
use workbench::formats::fit::FitFile;
use workbench::formats::material_export::Target;

pub(crate) fn export(a: ExportArgs) -> Result<Exported> {
    let fit: FitFile = workbench::formats::output::read_json(&a.fit)
        .with_context(|| format!("export {}", a.fit.display()))?;
    fit.validate(&a.fit)
        .with_context(|| format!("export {}", a.fit.display()))?;
    let m = fit
        .medium(&a.fit)
        .with_context(|| format!("export {}", a.fit.display()))?;
    let out = a.out.clone().unwrap_or_else(|| beside(&a.fit, "export"));
    let mut targets: Vec<Target> =
        a.to.iter()
            .map(|t| match t {
                ExportTarget::Mitsuba => Target::Mitsuba,
                ExportTarget::Pbrt => Target::Pbrt,
                ExportTarget::Blender => Target::Blender,
                ExportTarget::Unreal => Target::Unreal,
            })
            .collect();
    targets.dedup();
    let radius = m.radii_mm.iter().copied().fold(f64::NAN, f64::max);
    let radius = if radius.is_finite() { radius } else { 25.0 };
    let files: Vec<PathBuf> = targets.iter().map(|t| out.join(t.file_name())).collect();
    let roots: Vec<&std::path::Path> = files.iter().map(|p| p.as_path()).collect();
    let set = workbench::formats::output::OutputSet::begin(&roots)?;
    std::fs::create_dir_all(&out).with_context(|| format!("export --out {}", out.display()))?;
    for (t, f) in targets.iter().zip(&files) {
        workbench::formats::output::write_bytes(f, t.text(m, radius).as_bytes())?;
    }
    set.commit()?;
    Ok(Exported { files })
}

/// The files written.
pub(crate) struct Exported {
    files: Vec<PathBuf>,
}

impl fmt::Display for Exported {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        for p in &self.files {
            writeln!(f, "wrote    {}", p.display())?;
        }
        Ok(())
    }
}

impl Report for Exported {}
