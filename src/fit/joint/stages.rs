//! The joint fit's stages ([`fit_joint`]), each a Levenberg–Marquardt fit
//! ([`crate::fit::solver`]) from the previous one's result: the diffuse stage on 2° cells without
//! the highlight, then the full fit on the chosen reduction level, repeated with what the data do
//! not determine held ([`super::identify`]); the phases before and the checks after come from the
//! folder's other files.

use super::checks::{
    self, alpha_from_detector, eta_at_detector_alpha, eta_from_highlight, fit_notes,
};
use super::identify::{
    degenerate_check, hold, parameter_set, poorly_determined, prior_tension, resolution_notes,
    Round,
};
use super::light::LightPrior;
use super::reduction::{choose_reduction, HIGHLIGHT_KEEP, SHIFT_LIMIT};
use super::settings::{LightFit, Reduction, Setup};
use super::start;
use crate::fit::observe::SphereData;
use crate::fit::reduce::{Pooled, SphereObs};
use crate::fit::solver::{self, Fit, Obs, Prior};
use crate::formats::fit::{Level, LightPull, Stage};
use crate::model::{idx, Model, Params, N_PARAMS, PARAM_NAMES};
use nalgebra::Vector3;
use std::time::Instant;

/// Huber threshold (in robust σ of the residuals).
pub(crate) const HUBER_K: f64 = 1.345;

impl Stage {
    pub(crate) fn of(name: &str, obs: usize, f: &Fit, t: std::time::Instant) -> Stage {
        Stage {
            name: name.into(),
            observations: obs,
            free: (0..N_PARAMS)
                .filter(|&k| f.free[k])
                .map(|k| PARAM_NAMES[k].to_string())
                .collect(),
            evaluations: f.evaluations,
            termination: f.termination.clone(),
            converged: f.converged,
            cost_start: f.history.first().copied().unwrap_or(f.cost),
            cost_end: f.cost,
            cost_history: f.history.clone(),
            seconds: t.elapsed().as_secs_f64(),
        }
    }
}

/// What [`fit_joint`] returns.
#[derive(Clone, Debug)]
pub struct JointFit {
    pub fit: Fit,
    pub model: Model,
    pub stages: Vec<Stage>,
    pub levels: Vec<Level>,
    /// The level used (width 0: every pixel).
    pub chosen: Level,
    pub pixels: usize,
    pub downweighted: usize,
    /// Why parameters were held or switched off, and other decisions.
    pub notes: Vec<String>,
    /// How each parameter was treated: "fitted", "fixed", "prior …", "off: …".
    pub status: [String; N_PARAMS],
    /// Whether a specular lobe was fitted.
    pub specular: bool,
    /// Seconds spent in each phase (pooling, start values, stages, reduction choice).
    pub phases: Vec<(String, f64)>,
    /// How far the fit moved the detector's light (when the light was free and a detector's
    /// light with its error was given).
    pub light_pull: Option<LightPull>,
    /// Per parameter, the scale factor its stated error takes for the disagreement between its
    /// prior and the data ([`super::identify::prior_tension`]; 1 without a prior or without disagreement).
    pub prior_tension: [f64; N_PARAMS],
    /// Per parameter, the disagreement between two measurements of it when it is beyond their
    /// errors (0 otherwise): η from the whole fit and from the highlight alone (only with the
    /// irradiance given), and from the highlight with α held at the detector's where the two
    /// α disagree (in quadrature with the first), α from the whole fit and from the detector's
    /// lobe fits. Joins the parameter's stated error in quadrature.
    pub systematic: [f64; N_PARAMS],
    /// χ²/dof against the measured noise: (residual / noise)² per observation row.
    pub chi2_dof: f64,
    /// The final stage's least-squares problem, for what is computed from its linearisation.
    pub problem: FinalProblem,
    /// σ0 was checked against the limits of what the data resolve ([`JointFit::check_resolution`]).
    pub resolution_checked: bool,
    /// The notes of [`checks::fit_notes`] among `notes` (what a held light's fit replaces).
    pub quality: Vec<String>,
}

impl JointFit {
    /// σ0 against the limits of what the data resolve ([`resolution_notes`]: refits with σ0 → 0
    /// or → ∞), once: the statuses and notes of the channels that are bounds, not measurements,
    /// and its seconds as the phase "resolution check". A fit that another replaces (the light's
    /// before it is held at the combination with the detector's) skips it.
    pub(crate) fn check_resolution(&mut self, setup: &Setup, spheres: &[&SphereData]) {
        if self.resolution_checked {
            return;
        }
        let t = std::time::Instant::now();
        resolution_notes(
            setup,
            spheres,
            &self.problem.obs,
            &self.fit,
            &self.problem.priors,
            &mut self.status,
            &mut self.notes,
        );
        each_once(&mut self.notes);
        self.resolution_checked = true;
        self.phases
            .push(("resolution check".into(), t.elapsed().as_secs_f64()));
    }
}

/// Each note once, where it first appears (the identifiability rounds repeat theirs).
fn each_once(notes: &mut Vec<String>) {
    let mut seen = std::collections::HashSet::new();
    notes.retain(|n| seen.insert(n.clone()));
}

/// The observations the final stage fitted, with its robust weights (`weighted`) and without
/// (`obs`), the sphere each comes from (its index in the fitted spheres) and the priors it fitted
/// with: the leave-one-group-out estimates are Newton steps from the fit on these
/// ([`super::jackknife`]).
#[derive(Clone, Debug, Default)]
pub struct FinalProblem {
    pub obs: Vec<Obs>,
    pub weighted: Vec<Obs>,
    /// The weights are the Huber loss's, [`HUBER_K`] (else `weighted` is `obs`).
    pub robust: bool,
    pub sphere: Vec<usize>,
    pub priors: Vec<Prior>,
}

/// Seconds per phase, each from the end of the one before.
struct Laps {
    clock: Instant,
    phases: Vec<(String, f64)>,
}

impl Laps {
    fn start() -> Laps {
        Laps {
            clock: Instant::now(),
            phases: vec![],
        }
    }

    fn lap(&mut self, name: &str) {
        self.phases
            .push((name.to_string(), self.clock.elapsed().as_secs_f64()));
        self.clock = Instant::now();
    }
}

/// Fit the joint model to the given spheres, in its phases: the pixels pooled around the start
/// light, the start values, the light's prior, the diffuse stage, the lobe's start, the parameter
/// set, the reduction level, the full fit with what the data do not determine held, and the
/// checks on its result.
pub fn fit_joint(setup: &Setup, spheres: &[&SphereData]) -> JointFit {
    let mut laps = Laps::start();
    let mut notes = vec![];
    let mut status: [String; N_PARAMS] = std::array::from_fn(|_| "fitted".to_string());
    let highlight = setup.measured.light.is_some() && setup.measured.highlight_radius.is_some();
    let light0 = start::light(setup, spheres);
    let pool = pooling(setup, spheres, highlight);
    let mut pooled = pool(light0);
    laps.lap("pool");
    let mut p = start::params(setup, &pooled, light0);
    laps.lap("start values");
    let mut free = diffuse_free(setup);
    let light = LightPrior::of(setup, &mut status);
    if let Some(w) = setup.warm {
        p = w;
    }
    let mut stages = vec![];
    diffuse_stage(
        setup,
        &mut pooled,
        &pool,
        (&mut p, free),
        &light.priors,
        &mut stages,
        &mut notes,
    );
    laps.lap("diffuse stage");
    let mut specular =
        start::specular_start(setup, &pooled, highlight, &mut p, &mut status, &mut notes);
    let mut priors = parameter_set(
        setup,
        spheres,
        specular,
        &light.priors,
        (&mut p, &mut free),
        &mut status,
        &mut notes,
    );
    laps.lap("specular start");
    let model = setup.model();
    let (final_obs, final_sphere, chosen, levels) =
        choose_reduction(setup.reduction, &pooled, spheres, &model, &p, free);
    if chosen.width_deg == 0.0 && setup.reduction == Reduction::Auto {
        notes.push(format!(
            "no reduction level keeps the predicted shift below {SHIFT_LIMIT} std or its tolerance: every pixel used"
        ));
    }
    laps.lap("reduction choice");
    let (fit, downweighted, weighted, fit_priors) = fit_identified(
        setup,
        &final_obs,
        (&mut p, &mut free),
        &mut priors,
        &mut specular,
        &mut status,
        &mut stages,
        &mut notes,
    );
    notes.extend(checks::clipped(spheres));
    let fit = degenerate_check(fit, &mut stages, &mut notes);
    let (chi2, quality) = fit_notes(
        &model,
        &fit,
        spheres,
        setup.settings.eta_prior,
        &status[idx::ETA],
    );
    notes.extend(quality.iter().cloned());
    let light_pull = light.pull(setup, &fit, free[idx::AZIMUTH], &mut notes);
    for k in 0..N_PARAMS {
        if !free[k] && status[k] == "fitted" {
            status[k] = "fixed".into();
        }
    }
    let mut tension = [1.0; N_PARAMS];
    for q in priors.iter().filter(|q| fit.free[q.index]) {
        tension[q.index] = prior_tension(fit.params.to_vec()[q.index], fit.std[q.index], q);
    }
    let mut systematic = [0.0; N_PARAMS];
    systematic[idx::ETA] = eta_from_highlight(setup, &pooled, specular, &fit, &mut notes);
    systematic[idx::ALPHA] = alpha_from_detector(&setup.measured, specular, &fit, &mut notes);
    let traded = eta_at_detector_alpha(setup, &pooled, &fit, systematic[idx::ALPHA], &mut notes);
    systematic[idx::ETA] = systematic[idx::ETA].hypot(traded);
    laps.lap("joint stage");
    each_once(&mut notes);
    let mut jf = JointFit {
        phases: laps.phases,
        fit,
        model,
        stages,
        levels,
        chosen,
        pixels: pooled.pixels,
        downweighted,
        notes,
        status,
        specular,
        light_pull,
        prior_tension: tension,
        systematic,
        chi2_dof: chi2,
        problem: FinalProblem {
            obs: final_obs,
            weighted,
            robust: setup.settings.robust,
            sphere: final_sphere,
            priors: fit_priors,
        },
        resolution_checked: false,
        quality,
    };
    if setup.checks {
        jf.check_resolution(setup, spheres);
    }
    jf
}

/// The pixels pooled around a light: in (θ, φ) cells, those within the detector's highlight
/// radius in pixel blocks (twice that radius was measured to gain nothing and cost 4× the
/// pixels).
fn pooling<'a>(
    setup: &Setup,
    spheres: &'a [&'a SphereData],
    highlight: bool,
) -> impl Fn(Vector3<f64>) -> Pooled + 'a {
    let keep = if highlight {
        HIGHLIGHT_KEEP * setup.measured.highlight_radius.unwrap_or(0.0)
    } else {
        0.0
    };
    move |light: Vector3<f64>| {
        let parts: Vec<SphereObs> = spheres
            .iter()
            .map(|s| (&s.obs[..], Some(&s.px[..])))
            .collect();
        Pooled::of_spheres(light, keep, &parts)
    }
}

/// The diffuse stage's free parameters: σ0 and the albedo, and the light unless it is held.
fn diffuse_free(setup: &Setup) -> [bool; N_PARAMS] {
    let mut free = [false; N_PARAMS];
    free[..6].fill(true);
    let hold_light = setup.settings.light_fit == LightFit::Hold;
    free[idx::AZIMUTH] = !hold_light;
    free[idx::ELEVATION] = !hold_light;
    free
}

/// The diffuse stage: the material and the light on 2° cells with the highlight left out; the
/// cells pooled again around a light that moved more than 2° (none with a warm start).
pub(crate) fn diffuse_stage(
    setup: &Setup,
    pooled: &mut Pooled,
    pool: &dyn Fn(Vector3<f64>) -> Pooled,
    (p, free): (&mut Params, [bool; N_PARAMS]),
    light_priors: &[Prior],
    stages: &mut Vec<Stage>,
    notes: &mut Vec<String>,
) {
    let model = setup.model();
    for round in 0..if setup.warm.is_some() { 0 } else { 2 } {
        let t = std::time::Instant::now();
        let cells = pooled.merged(8);
        let obs: Vec<Obs> = pooled.observations(&cells);
        let (f, _, _) = solver::fit_robust(
            model,
            &obs,
            &*p,
            free,
            light_priors,
            setup.measured.fit_floor,
            HUBER_K,
            4,
        );
        stages.push(Stage::of(
            "diffuse (2° cells, highlight left out)",
            obs.len(),
            &f,
            t,
        ));
        let moved = f.params.light.direction().angle(&pooled.light);
        *p = f.params;
        // Cells follow the light: pool again around a light that moved by more than 2°.
        if moved > 2f64.to_radians() && round == 0 {
            notes.push(format!(
                "the light moved {:.1}° from its start in the diffuse fit: pixels pooled again around it",
                moved.to_degrees()
            ));
            *pooled = pool(p.light.direction());
        } else {
            break;
        }
    }
}

/// The full fit, repeated (at most twice more) with what the data do not determine held: η at
/// its prior, α held, the lobe or an extension off. Returns the fit, the residuals the Huber
/// loss down-weighted, the observations with the final robust weights and the priors of the
/// final fit.
#[allow(clippy::too_many_arguments)]
fn fit_identified(
    setup: &Setup,
    final_obs: &[Obs],
    (p, free): (&mut Params, &mut [bool; N_PARAMS]),
    priors: &mut Vec<Prior>,
    specular: &mut bool,
    status: &mut [String; N_PARAMS],
    stages: &mut Vec<Stage>,
    notes: &mut Vec<String>,
) -> (Fit, usize, Vec<Obs>, Vec<Prior>) {
    let model = setup.model();
    let mut fit = None;
    for attempt in 0..3 {
        let t = std::time::Instant::now();
        let fit_priors = priors.clone();
        let (f, weighted, down) = if setup.settings.robust {
            solver::fit_robust(
                model,
                final_obs,
                &*p,
                *free,
                priors,
                setup.measured.fit_floor,
                HUBER_K,
                6,
            )
        } else {
            let f = solver::fit_with_floor(
                model,
                final_obs,
                p,
                *free,
                priors,
                setup.measured.fit_floor,
            );
            (f, final_obs.to_vec(), 0)
        };
        stages.push(Stage::of(
            if attempt == 0 {
                "joint"
            } else {
                "joint (poorly determined parameters held)"
            },
            final_obs.len(),
            &f,
            t,
        ));
        let mut round = Round {
            p: &mut *p,
            free: &mut *free,
            priors: &mut *priors,
            specular: &mut *specular,
            status: &mut *status,
            notes: &mut *notes,
        };
        let mut changed = false;
        for k in poorly_determined(&f) {
            changed |= hold(k, &f, setup, &mut round);
        }
        if !changed || attempt == 2 {
            fit = Some((f, down, weighted, fit_priors));
            break;
        }
        // Keep what was fitted for the rest as the next start.
        let held = *p;
        *p = f.params;
        for k in 0..N_PARAMS {
            if !free[k] {
                let mut v = p.to_vec();
                v[k] = held.to_vec()[k];
                *p = Params::from_vec(&v);
            }
        }
    }
    fit.expect("the loop ends with a fit")
}
