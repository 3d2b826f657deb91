//! `workbench solve`: the material fitted to a session; fit.json and its summary.

use crate::cli::*;
use anyhow::{bail, Context, Result};
use workbench::model::LightAngles;

pub(crate) fn solve(a: SolveArgs, quiet: bool) -> Result<()> {
    use workbench::fit::solve::{self, Method, Options};
    let _ = a.joint;
    let mut o = Options::new(&a.session);
    o.out = a.out.clone();
    o.method = match a.method {
        MethodArg::Joint => Method::Joint,
        MethodArg::Paper => Method::Paper,
    };
    o.holdout = a.holdout;
    if let Some(p) = a.prior {
        o.eta_prior = p;
    }
    if let Some(e) = a.irradiance {
        if !(e.is_finite() && e > 0.0) {
            bail!("--irradiance must be a positive number, got {e}");
        }
        o.irradiance = Some(e);
    }
    o.reduction = a.reduce;
    o.robust = !a.no_robust;
    o.extensions = a.extensions;
    if let Some(s) = a.start_sigma0 {
        if s.iter().any(|v| v.is_nan() || *v <= 0.0) {
            bail!("--start-sigma0 must be positive");
        }
    }
    o.start_sigma0 = a.start_sigma0;
    o.start_light = a.start_light.map(|[az, el]| LightAngles {
        azimuth: az.to_radians(),
        elevation: el.to_radians(),
    });
    o.redetect = a.redetect;
    o.light_fit = if a.hold_light {
        workbench::fit::joint::LightFit::Hold
    } else if a.free_light {
        workbench::fit::joint::LightFit::Free
    } else {
        workbench::fit::joint::LightFit::Prior
    };
    o.jackknife = !a.no_jackknife;
    o.entry_transmission = a.entry_transmission;
    o.plots = a.plots.clone();
    o.baseline = a.baseline;
    o.quiet = quiet;
    let f = solve::run(&o).with_context(|| format!("solve {}", a.session.display()))?;
    print!("{}", solve::summary(&f));
    let out = a
        .out
        .unwrap_or_else(|| std::path::Path::new(&f.session).with_file_name("fit.json"));
    println!("wrote    {}", out.display());
    if let Some(d) = &a.plots {
        println!(
            "figures  {} (open {})",
            d.display(),
            d.join("index.html").display()
        );
    }
    if !f.convergence.converged {
        eprintln!(
            "error: the fit did not converge (see convergence in {})",
            out.display()
        );
        std::process::exit(3);
    }
    Ok(())
}
