//! `workbench plot`: a fit's figures redrawn from fit.json.

use super::{beside, Report};
use crate::cli::*;
use anyhow::{Context, Result};
use std::fmt;
use std::path::PathBuf;

pub(crate) fn plot(a: PlotArgs, quiet: bool) -> Result<Plotted> {
    let out = a.out.clone().unwrap_or_else(|| beside(&a.fit, "plots"));
    let files = workbench::solve::replot(&a.fit, &out, quiet)
        .with_context(|| format!("plot {}", a.fit.display()))?;
    Ok(Plotted {
        out,
        files: files.len(),
    })
}

/// The figures written.
pub(crate) struct Plotted {
    out: PathBuf,
    files: usize,
}

impl fmt::Display for Plotted {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        writeln!(f, "figures  {} ({} files)", self.out.display(), self.files)?;
        writeln!(f, "index    {}", self.out.join("index.html").display())
    }
}

impl Report for Plotted {}
