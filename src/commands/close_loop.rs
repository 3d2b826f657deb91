//! `workbench close-loop`: a fit's measured medium path-traced back into its spheres and compared
//! with the photos ([`workbench::synth::close_loop`]).

use super::{beside, Report};
use crate::cli::CloseLoopArgs;
use anyhow::{Context, Result};
use std::fmt;
use workbench::synth::close_loop::{self, Comparison, Written};

pub(crate) fn close_loop(a: CloseLoopArgs, quiet: bool) -> Result<Closed> {
    let out = a
        .out
        .clone()
        .unwrap_or_else(|| beside(&a.fit, "close-loop"));
    let opts = close_loop::Options {
        spp: a.spp,
        pixels: a.pixels as usize,
        seed: a.seed,
        quiet,
    };
    let written = close_loop::close_loop(&a.fit, &out, &opts)
        .with_context(|| format!("close-loop {}", a.fit.display()))?;
    Ok(Closed(written))
}

/// What was compared and written.
pub(crate) struct Closed(Written);

fn line(f: &mut fmt::Formatter, what: &str, c: &Comparison) -> fmt::Result {
    writeln!(
        f,
        "{what:<10} path-traced {:>5.2} ± {:.2}% (its noise {:.2}%, taken out)   medium model {:>5.2}%   CDRF {:>5.2}%   render/model {:.2}   photo noise {:.2}%",
        100.0 * c.render_rel_rmse,
        100.0 * c.render_rel_rmse_std,
        100.0 * c.render_noise_rel,
        100.0 * c.medium_rel_rmse,
        100.0 * c.cdrf_rel_rmse,
        c.render_over_medium,
        100.0 * c.photo_noise_rel
    )
}

impl fmt::Display for Closed {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        let j = &self.0.json;
        writeln!(
            f,
            "relative RMSE against the photos on the medium fit's pixels ({} spp, {:.1} s):",
            j.spp, j.seconds
        )?;
        for r in &j.radii {
            line(f, &format!("r = {} mm", r.radius_mm), &r.comparison)?;
        }
        line(f, "all", &j.overall)?;
        for n in &j.notes {
            writeln!(f, "note: {n}")?;
        }
        for p in &self.0.files {
            writeln!(f, "wrote    {}", p.display())?;
        }
        Ok(())
    }
}

impl Report for Closed {}
