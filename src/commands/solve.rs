//! `workbench solve`: the material fitted to a session; fit.json and its summary.

use super::Report;
use crate::cli::*;
use anyhow::{bail, Context, Result};
use std::fmt;
use std::path::PathBuf;
use workbench::fit::joint::JackknifeMethod;
use workbench::formats::fit::FitFile;
use workbench::model::LightAngles;

pub(crate) fn solve(a: SolveArgs, quiet: bool) -> Result<Solved> {
    use workbench::formats::fit::Method;
    use workbench::solve::{self, Options};
    let _ = a.joint;
    let mut o = Options::new(&a.session);
    o.out = a.out.clone();
    o.method = match a.method {
        MethodArg::Joint => Method::Joint,
        MethodArg::Paper => Method::Paper,
    };
    o.model = solve_model(a.model);
    o.holdout = a.holdout;
    if let Some(p) = a.prior {
        o.fit.eta_prior = p;
    }
    if let Some(e) = a.irradiance {
        if !(e.is_finite() && e > 0.0) {
            bail!("--irradiance must be a positive number, got {e}");
        }
        o.fit.irradiance = Some(e);
    }
    o.fit.reduction = a.reduce;
    o.fit.robust = !a.no_robust;
    o.fit.extensions = a.extensions;
    if let Some(s) = a.start_sigma0 {
        if s.iter().any(|v| v.is_nan() || *v <= 0.0) {
            bail!("--start-sigma0 must be positive");
        }
    }
    o.fit.start_sigma0 = a.start_sigma0;
    o.fit.start_light = a.start_light.map(|[az, el]| LightAngles {
        azimuth: az.to_radians(),
        elevation: el.to_radians(),
    });
    o.redetect = a.redetect;
    o.fit.light_fit = if a.hold_light {
        workbench::fit::joint::LightFit::Hold
    } else if a.free_light {
        workbench::fit::joint::LightFit::Free
    } else {
        workbench::fit::joint::LightFit::Prior
    };
    o.fit.jackknife = match (a.no_jackknife, a.jackknife) {
        (true, _) | (_, JackknifeArg::Off) => JackknifeMethod::Off,
        (_, JackknifeArg::Refit) => JackknifeMethod::Refit,
        (_, JackknifeArg::Linear) => JackknifeMethod::Linear,
    };
    o.fit.entry_transmission = a.entry_transmission;
    o.plots = a.plots.clone();
    o.fit.baseline = a.baseline;
    o.quiet = quiet;
    let fit = solve::run(&o).with_context(|| format!("solve {}", a.session.display()))?;
    let out = a
        .out
        .unwrap_or_else(|| std::path::Path::new(&fit.session).with_file_name("fit.json"));
    Ok(Solved {
        fit,
        out,
        plots: a.plots,
    })
}

/// A fit written: its summary, where it went.
pub(crate) struct Solved {
    fit: FitFile,
    out: PathBuf,
    plots: Option<PathBuf>,
}

impl fmt::Display for Solved {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "{}", workbench::solve::summary(&self.fit))?;
        writeln!(f, "wrote    {}", self.out.display())?;
        if let Some(d) = &self.plots {
            writeln!(
                f,
                "figures  {} (open {})",
                d.display(),
                d.join("index.html").display()
            )?;
        }
        Ok(())
    }
}

impl Report for Solved {
    fn failure(&self) -> Option<String> {
        (!self.fit.convergence.converged).then(|| {
            format!(
                "the fit did not converge (see convergence in {})",
                self.out.display()
            )
        })
    }
}

/// The solve's model for `--model`.
pub(crate) fn solve_model(m: ModelArg) -> workbench::solve::SolveModel {
    match m {
        ModelArg::Cdrf => workbench::solve::SolveModel::Cdrf,
        ModelArg::Medium => workbench::solve::SolveModel::Medium,
        ModelArg::Auto => workbench::solve::SolveModel::Auto,
    }
}
