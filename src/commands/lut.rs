//! `workbench lut`: a fit's CDRF tabulated over N·L and curvature.

use super::beside;
use crate::cli::*;
use anyhow::{Context, Result};

pub(crate) fn lut(a: LutArgs) -> Result<()> {
    let out = a.out.clone().unwrap_or_else(|| beside(&a.fit, "lut"));
    let (t, fm, paths) = workbench::render::job::write_lut(
        &a.fit,
        &out,
        table_size(a.size, a.tolerance),
        a.kappa_max,
    )
    .with_context(|| format!("lut {}", a.fit.display()))?;
    for ((nc, nk), e) in &t.tried {
        println!(
            "size     {nc}x{nk}: largest interpolation error {:.2e} of the peak",
            e
        );
    }
    let e = &t.error;
    println!(
        "table    {}x{} nodes, N·L -1..1, curvature 0..{:.4}/mm (fit measured {:.4}..{:.4}/mm)",
        t.lut.n_cos, t.lut.n_kappa, t.lut.kappa_max, fm.measured_kappa[0], fm.measured_kappa[1]
    );
    println!(
        "error    largest {:.2e} ({:.2e} of the peak {:.4}) at N·L {:.3}, curvature {:.4}/mm; rms {:.2e}",
        e.max_abs,
        e.max_rel,
        t.lut.peak(),
        e.at_cos,
        e.at_kappa_per_mm,
        e.rms
    );
    for p in &paths {
        println!("wrote    {}", p.display());
    }
    Ok(())
}
