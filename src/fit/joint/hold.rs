//! The light held at the detector's where the shading pulls it too far ([`hold_pulled_light`]):
//! the held fit by Newton steps from the fit with the light free ([`held_from_the_fit`]); the
//! whole fit repeated only where those do not settle.

use super::checks::{alpha_from_detector, fit_notes};
use super::identify::{poorly_determined, prior_tension};
use super::light::PULL_WARN;
use super::newton;
use super::settings::{Extensions, LightFit, Measured, Settings, Setup};
use super::stages::{fit_joint, FinalProblem, JointFit};
use crate::fit::observe::SphereData;
use crate::fit::solver::{from_unbounded, to_unbounded, Fit};
use crate::model::{idx, LightAngles, Params, N_PARAMS};

/// The fit after the light's hold, the settings it ran with, and the light's systematic.
pub(crate) struct Held {
    pub fit: JointFit,
    pub settings: Settings,
    /// Per parameter, the light's systematic on it (0 where none).
    pub light_shift: [f64; N_PARAMS],
    /// The shading pulled the light beyond [`PULL_WARN`].
    pub pulled: bool,
}

/// A light pulled beyond [`PULL_WARN`] of the detector's errors is pulled by the model's error,
/// not supported by the data: it is held at the detector's and the fit repeated from the fit's
/// final stage ([`held_from_the_fit`]) or, where that fails, in full. Each parameter's
/// shift between the two fits is the light's systematic on it and joins its std; a light taken
/// from the detector keeps the detector's error (docs/uncertainty.md, "When the shading pulls the
/// light").
pub(crate) fn hold_pulled_light(
    settings: &Settings,
    measured: &Measured,
    fitted: &[&SphereData],
    ext: Extensions,
    first: JointFit,
    notes: &mut Vec<String>,
) -> Held {
    let mut jf = first;
    let mut fit_settings = *settings;
    let mut light_shift = [0.0; N_PARAMS];
    let pulled = jf.light_pull.filter(|p| p.pull > PULL_WARN);
    if let (LightFit::Prior, Some(pull), Some(_)) = (settings.light_fit, pulled, measured.light) {
        fit_settings.light_fit = LightFit::Hold;
        let light = LightAngles::from_direction(&measured.light.expect("matched above"));
        let held = held_from_the_fit(&jf, light, fitted, measured, settings.eta_prior)
            .unwrap_or_else(|| {
                fit_joint(
                    &Setup::new(&fit_settings, measured, ext, settings.reduction),
                    fitted,
                )
            });
        let (a, b) = (jf.fit.params.to_vec(), held.fit.params.to_vec());
        light_shift = std::array::from_fn(|k| {
            if held.fit.free[k] {
                (a[k] - b[k]).abs()
            } else {
                0.0
            }
        });
        let moved_sigma0: Vec<String> = (0..3)
            .map(|c| format!("{:.3}", jf.fit.params.material.sigma0_mm[c]))
            .collect();
        notes.push(format!(
            "the light is held at the highlights' estimate: the shading pulled it {:.1} of its errors, further than the data support; with the pulled light σ0 was {} mm, and each parameter's shift between the two fits joins its std",
            pull.pull,
            moved_sigma0.join(", ")
        ));
        jf = JointFit {
            light_pull: Some(pull),
            ..held
        };
        let why = format!("held: the detector's (pulled {:.1} std)", pull.pull);
        jf.status[idx::AZIMUTH] = why.clone();
        jf.status[idx::ELEVATION] = why;
    }
    if fit_settings.light_fit == LightFit::Hold && settings.start_light.is_none() {
        if let (Some(s), Some(d)) = (measured.light_std, measured.light) {
            let el = LightAngles::from_direction(&d).elevation;
            light_shift[idx::AZIMUTH] = s / el.cos().abs().max(1e-3);
            light_shift[idx::ELEVATION] = s;
        }
    }
    Held {
        fit: jf,
        settings: fit_settings,
        light_shift,
        pulled: pulled.is_some(),
    }
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
        history: vec![],
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
