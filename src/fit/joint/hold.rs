//! A joint fit with its light held at a given direction ([`hold_at`]): by Newton steps from the
//! fit with the light free ([`held_from_the_fit`]); the whole fit repeated only where those do
//! not settle.

use super::checks::{alpha_from_detector, fit_notes};
use super::identify::{poorly_determined, prior_tension};
use super::newton;
use super::settings::{Extensions, LightFit, Measured, Settings, Setup};
use super::stages::{fit_joint, FinalProblem, JointFit};
use crate::fit::observe::SphereData;
use crate::fit::solver::{from_unbounded, to_unbounded, Fit};
use crate::model::{idx, LightAngles, Params, N_PARAMS};

/// The fit `jf` with its light held at `light` ([`held_from_the_fit`]), or, where those Newton
/// steps do not settle, the whole fit repeated with the light held there (`settings` has
/// [`LightFit::Hold`] and `start_light` at `light`).
pub(crate) fn hold_at(
    jf: &JointFit,
    light: LightAngles,
    (settings, measured, ext): (&Settings, &Measured, Extensions),
    fitted: &[&SphereData],
) -> JointFit {
    debug_assert!(settings.light_fit == LightFit::Hold && settings.start_light == Some(light));
    held_from_the_fit(jf, light, fitted, measured, settings.eta_prior).unwrap_or_else(|| {
        fit_joint(
            &Setup::new(settings, measured, ext, settings.reduction),
            fitted,
        )
    })
}

/// The most Newton steps of the held fit before the whole fit is repeated instead (the
/// reweighting converges by about 4× a step: 9 steps from a light 15 std away, measured on the
/// physically based wax).
pub(crate) const HOLD_STEPS: u32 = 16;

/// The fit `jf` with the light held at `light`, by Newton steps from it on its final stage's
/// problem with the light's angles fixed ([`newton::iterate`]: the Huber weights taken again at
/// each step), until a step moves no parameter by more than [`newton::STEP_TOL`] of its formal
/// standard error. `None` — the whole fit is repeated — where they do not settle within
/// [`HOLD_STEPS`] or stop contracting ([`newton::iterate`]; a light far from the pulled one:
/// Levenberg–Marquardt on the same problem from the fit was measured to land 2.8 std from the
/// repeated fit on the jade session, whose light was pulled 3°), or leave a parameter
/// undetermined (the whole fit's identifiability rounds would hold it).
fn held_from_the_fit(
    jf: &JointFit,
    light: LightAngles,
    fitted: &[&SphereData],
    measured: &Measured,
    eta_prior: (f64, f64),
) -> Option<JointFit> {
    let t = std::time::Instant::now();
    let mut free = jf.fit.free;
    free[idx::AZIMUTH] = false;
    free[idx::ELEVATION] = false;
    let start = Params {
        light,
        ..jf.fit.params
    };
    let u0 = to_unbounded(&start.to_vec());
    let first = newton::problem(jf, &jf.problem.weighted, free, u0);
    let tol = newton::tolerance(jf, &[0.0; N_PARAMS]);
    let newton = first
        .newton_step(&first.grouped_sums(None)[0])
        .and_then(|step| {
            newton::iterate(
                jf,
                (&jf.problem.obs, jf.problem.weighted.clone()),
                free,
                (&u0, step),
                &tol,
                (HOLD_STEPS, true),
            )
        })
        .filter(|it| it.converged);
    let it = newton?;
    let problem = newton::problem(jf, &it.weighted, free, it.estimate.0);
    let (std, correlation, cost, floor) = problem.covariance_and_floor();
    // The cost where the steps started (the light moved, the rest at the fit), with the last
    // step's weights as the end's: the stage's history is its start and its end.
    let at_start = newton::problem(jf, &it.weighted, free, u0);
    let cost_start = 0.5 * at_start.profiled(&at_start.grouped_sums(None)[0]).rtr_obs;
    let fit = Fit {
        params: Params::from_vec(&from_unbounded(&it.estimate.0).0),
        free,
        std,
        correlation,
        cost,
        residuals: 3 * it.weighted.len(),
        evaluations: it.steps as usize,
        termination: format!("{} Newton steps from the fit with the light free", it.steps),
        converged: true,
        history: vec![cost_start, cost],
        floor,
    };
    let weighted = it.weighted;
    if !fit.converged || !poorly_determined(&fit).is_empty() {
        return None;
    }
    let mut held = jf.clone();
    // The quality notes and χ² of the held fit replace those of the fit with the light free.
    held.notes.retain(|n| !jf.quality.contains(n));
    let (chi2, after) = fit_notes(&jf.model, &fit, fitted, eta_prior, &jf.status[idx::ETA]);
    held.notes.extend(after.iter().cloned());
    held.quality = after;
    held.chi2_dof = chi2;
    // So does α's check against the detector's (η's needs the pooled pixels: it stays).
    let mut before = vec![];
    alpha_from_detector(measured, jf.specular, &jf.fit, &mut before);
    held.notes.retain(|n| !before.contains(n));
    held.systematic[idx::ALPHA] = alpha_from_detector(measured, jf.specular, &fit, &mut held.notes);
    held.prior_tension = [1.0; N_PARAMS];
    for q in jf.problem.priors.iter().filter(|q| fit.free[q.index]) {
        held.prior_tension[q.index] =
            prior_tension(fit.params.to_vec()[q.index], fit.std[q.index], q);
    }
    held.stages.push(crate::formats::fit::Stage::of(
        "joint, the light held (Newton steps from the fit)",
        weighted.len(),
        &fit,
        t,
    ));
    held.problem = FinalProblem {
        weighted,
        ..jf.problem.clone()
    };
    held.fit = fit;
    Some(held)
}
