//! `workbench plot <fit.json>`: a fit's figures redrawn from fit.json and its session
//! ([`load_fit`], which `workbench close-loop` shares).

use crate::error::{Error, Result};
use crate::formats::fit::FitFile;
use std::path::{Path, PathBuf};

/// `workbench plot <fit.json>`: redraw a fit's figures from fit.json and its session, without
/// solving. The session is the one fit.json names (or session.json beside fit.json when that
/// has moved); detections are reused when up to date.
pub fn replot(fit_path: &Path, dir: &Path, quiet: bool) -> Result<Vec<PathBuf>> {
    crate::formats::output::check_roots(&[dir])?;
    let (fit, l) = load_fit(fit_path, quiet)?;
    let medium = fit
        .medium
        .is_some()
        .then(|| super::medium_spheres(&l, &l.spheres))
        .flatten();
    let set = crate::formats::output::OutputSet::begin(&[dir])?;
    let files =
        crate::figures::fitplot::write_all(&fit, fit_path, (&l.spheres, medium.as_deref()), dir)?;
    set.commit()?;
    Ok(files)
}

/// fit.json and its session loaded again: the session it names (or session.json beside
/// fit.json when that has moved), detections reused when up to date, and the same spheres as
/// the fit's (else an error naming fit.json).
pub fn load_fit(fit_path: &Path, quiet: bool) -> Result<(FitFile, super::Loaded)> {
    let fit: FitFile = crate::formats::output::read_json(fit_path)?;
    fit.validate(fit_path)?;
    let session = fit.session_path(fit_path)?;
    let mut opts = super::Options::new(&session);
    opts.quiet = quiet;
    // Detections are looked for beside the session, then beside the fit (as `solve --out` left
    // them); nothing is written into a session folder that is not the fit's.
    opts.out = Some(fit_path.to_path_buf());
    // A medium fit's pixels are seated on the outlines drawn for it
    // (`SolveModel::medium_outlines`, [`super::medium_spheres`]).
    if fit.medium.is_some() {
        opts.model = super::SolveModel::Medium;
    }
    let l = super::load(&opts)?;
    let same = l.spheres.len() == fit.rmse.spheres.len()
        && l.spheres
            .iter()
            .zip(&fit.rmse.spheres)
            .all(|(a, b)| a.image == b.image && a.index == b.index && a.radius_mm == b.radius_mm);
    if !same {
        return Err(Error::invalid(
            fit_path,
            format!(
                "describes other spheres than {} holds now",
                session.display()
            ),
        ));
    }
    same_medium_model(&fit, fit_path)?;
    Ok((fit, l))
}

/// A medium fitted with another build's model is not drawn or compared with this one's: its
/// residuals would be against a model it was not fitted with (docs/formats.md,
/// "model_reference").
fn same_medium_model(fit: &FitFile, fit_path: &Path) -> Result<()> {
    let Some(m) = &fit.medium else {
        return Ok(());
    };
    let ours = crate::fit::medium::model_reference();
    let problem = match &m.model_reference {
        None => "its medium was fitted by a build that did not record its model".to_string(),
        Some(theirs) => {
            let d = crate::fit::medium::reference_difference(theirs, &ours);
            if d <= REFERENCE_TOLERANCE {
                return Ok(());
            }
            format!(
                "its medium was fitted with another model than this build's (the model's reference radiances differ by up to {:.2e} of themselves)",
                d
            )
        }
    };
    Err(Error::invalid(
        fit_path,
        format!("{problem}: solve again to draw or compare it with this build's model"),
    ))
}

/// How far the recorded reference may be from this build's: the same model built again gives
/// the same values within rounding (here the dev profile's build draws the release build's
/// fit), while a 1% change of the exit law's tilt moves them by 3e-4 (docs/formats.md).
const REFERENCE_TOLERANCE: f64 = 1e-9;
