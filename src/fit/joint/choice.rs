//! The model extensions chosen by held-out error (`--extensions auto`): each candidate fitted
//! with every radius left out in turn predicts that radius.

use super::settings::{Extensions, Measured, Reduction, Settings, Setup};
use super::stages::fit_joint;
use crate::fit::observe::{self, SphereData};
use crate::fit::predict::predict;
use crate::formats::fit::{Candidate, ModelChoice};

/// Choose the extensions by held-out error: each candidate is fitted with every radius left out
/// in turn (4° cells: the choice compares errors of percents, not of standard errors) and
/// predicts that radius's pixels; the candidate with the lowest mean
/// relative RMSE (the simplest within 1% of it) wins if it beats the plain model by more than 2%
/// of its error.
pub(crate) fn choose_extensions(
    settings: &Settings,
    measured: &Measured,
    fitted: &[&SphereData],
) -> (ModelChoice, Extensions) {
    let radii = observe::distinct_radii(fitted);
    // Simplest first: one extension (the kernel's shape first), then pairs.
    let ext = |two_gaussian, sigma_exponent, albedo_curvature| Extensions {
        sigma_exponent,
        albedo_curvature,
        two_gaussian,
    };
    let candidates = [
        Extensions::default(),
        ext(true, false, false),
        ext(false, true, false),
        ext(false, false, true),
        ext(true, false, true),
        ext(false, true, true),
    ];
    if radii.len() < 4 {
        let plain = ModelChoice {
            candidates: vec![],
            chosen: "plain".into(),
            reason: format!(
                "{} radii: leaving one out leaves fewer than the 3 an extension needs",
                radii.len()
            ),
        };
        return (plain, Extensions::default());
    }
    // Every refit starts from the plain model's fit to all the spheres.
    let base = fit_joint(
        &Setup {
            checks: false,
            ..Setup::new(
                settings,
                measured,
                Extensions::default(),
                Reduction::Factor(16),
            )
        },
        fitted,
    );
    // Every (candidate, left-out radius) refit in parallel.
    use rayon::prelude::*;
    let pairs: Vec<(usize, f64)> = (0..candidates.len())
        .flat_map(|c| radii.iter().map(move |&r| (c, r)))
        .collect();
    let refits: Vec<(f64, bool)> = pairs
        .par_iter()
        .map(|&(c, r)| {
            let ext = candidates[c];
            let train: Vec<&SphereData> = fitted
                .iter()
                .copied()
                .filter(|s| s.radius_mm != r)
                .collect();
            let test: Vec<&SphereData> = fitted
                .iter()
                .copied()
                .filter(|s| s.radius_mm == r)
                .collect();
            let su =
                Setup::new(settings, measured, ext, Reduction::Factor(16)).refit(base.fit.params);
            let jf = fit_joint(&su, &train);
            let (mut d, mut o) = (0.0, 0.0);
            for s in test {
                let p = predict(&jf.model, &jf.fit.params, s, jf.fit.floor_value(), 20_000);
                d += (p.rel_rmse * p.rel_rmse) * p.pixels as f64;
                o += p.pixels as f64;
            }
            ((d / o.max(1.0)).sqrt(), jf.fit.converged)
        })
        .collect();
    let results = candidate_results(&candidates, &refits, radii.len());
    let (chosen, reason) = pick(&candidates, &results);
    let mc = ModelChoice {
        candidates: results,
        chosen: chosen.name(),
        reason,
    };
    (mc, chosen)
}

/// Each candidate's mean held-out error over the radii (`refits` run candidate by candidate:
/// each candidate's refits are one chunk of `n` radii) and whether all its refits converged.
fn candidate_results(
    candidates: &[Extensions],
    refits: &[(f64, bool)],
    n: usize,
) -> Vec<Candidate> {
    candidates
        .iter()
        .zip(refits.chunks(n))
        .map(|(ext, mine)| Candidate {
            extensions: ext.name(),
            heldout_rel_rmse: mine.iter().map(|r| r.0).sum::<f64>() / n as f64,
            converged: mine.iter().all(|r| r.1),
        })
        .collect()
}

/// The best candidate, or the simplest within 1% of the best's error, if it beats the plain
/// model by more than 2%; the plain model otherwise. Returns it and why.
fn pick(candidates: &[Extensions], results: &[Candidate]) -> (Extensions, String) {
    let plain = results[0].heldout_rel_rmse;
    // The best, or the simplest candidate within 1% of the best's error (candidates are listed
    // simplest first, the single extensions before the pairs).
    let lowest = results
        .iter()
        .filter(|c| c.converged)
        .map(|c| c.heldout_rel_rmse)
        .fold(f64::INFINITY, f64::min);
    let k = results
        .iter()
        .position(|c| c.converged && c.heldout_rel_rmse <= 1.01 * lowest)
        .unwrap_or(0);
    let best = &results[k];
    if k != 0 && best.heldout_rel_rmse < 0.98 * plain {
        (
            candidates[k],
            format!(
                "held-out error {:.4} against {:.4} for the plain model",
                best.heldout_rel_rmse, plain
            ),
        )
    } else {
        (
            Extensions::default(),
            format!(
                "no extension lowers the held-out error by 2% (plain {:.4}, best {:.4} for {})",
                plain, best.heldout_rel_rmse, best.extensions
            ),
        )
    }
}
