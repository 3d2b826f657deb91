//! `workbench plot`: a fit's figures redrawn from fit.json.

use super::beside;
use crate::cli::*;
use anyhow::{Context, Result};

pub(crate) fn plot(a: PlotArgs, quiet: bool) -> Result<()> {
    let out = a.out.clone().unwrap_or_else(|| beside(&a.fit, "plots"));
    let files = workbench::figures::fitplot::replot(&a.fit, &out, quiet)
        .with_context(|| format!("plot {}", a.fit.display()))?;
    println!("figures  {} ({} files)", out.display(), files.len());
    println!("index    {}", out.join("index.html").display());
    Ok(())
}
