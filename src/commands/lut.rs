//! `workbench lut`: a fit's CDRF tabulated over N·L and curvature.

use super::{beside, Report};
use crate::cli::*;
use anyhow::{Context, Result};
use std::fmt;
use std::path::PathBuf;

pub(crate) fn lut(a: LutArgs) -> Result<Tabulated> {
    let out = a.out.clone().unwrap_or_else(|| beside(&a.fit, "lut"));
    let (t, fm, paths) = workbench::render::job::write_lut(
        &a.fit,
        &out,
        table_size(a.size, a.tolerance),
        a.kappa_max,
    )
    .with_context(|| format!("lut {}", a.fit.display()))?;
    Ok(Tabulated { t, fm, paths })
}

/// The table written, its size search and its error.
pub(crate) struct Tabulated {
    t: workbench::render::job::Table,
    fm: workbench::render::lut::FitMaterial,
    paths: [PathBuf; 3],
}

impl fmt::Display for Tabulated {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        let (t, fm, paths) = (&self.t, &self.fm, &self.paths);
        for ((nc, nk), e) in &t.tried {
            writeln!(
                f,
                "size     {nc}x{nk}: largest interpolation error {:.2e} of the peak",
                e
            )?;
        }
        let e = &t.error;
        writeln!(
            f,
            "table    {}x{} nodes, N·L -1..1, curvature 0..{:.4}/mm (fit measured {:.4}..{:.4}/mm)",
            t.lut.n_cos, t.lut.n_kappa, t.lut.kappa_max, fm.measured_kappa[0], fm.measured_kappa[1]
        )?;
        writeln!(
            f,
            "error    largest {:.2e} ({:.2e} of the peak {:.4}) at N·L {:.3}, curvature {:.4}/mm; rms {:.2e}",
            e.max_abs,
            e.max_rel,
            t.lut.peak(),
            e.at_cos,
            e.at_kappa_per_mm,
            e.rms
        )?;
        for p in paths {
            writeln!(f, "wrote    {}", p.display())?;
        }
        Ok(())
    }
}

impl Report for Tabulated {}
