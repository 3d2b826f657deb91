//! The leave-one-radius-out jackknife of a joint fit: the spread of the estimates without each
//! radius joins each parameter's standard error (docs/uncertainty.md), and each left-out radius is
//! predicted. By default each estimate is a Newton step from the full fit on its normal equations
//! less the left-out radius's ([`jackknife_linear`]), one pass over the observations; the refits
//! ([`jackknife_refit`]) are the option that checks it.

use super::newton::{self, Estimate};
use super::settings::{Extensions, Measured, Reduction, Settings, Setup};
use super::stages::{fit_joint, JointFit};
use crate::fit::observe::{self, SphereData};
use crate::fit::predict::{combine_predictions, predict, Prediction, PREDICT_PIXELS};
use crate::fit::solver::{from_unbounded, to_unbounded, Obs, RawNormal};
use crate::formats::fit::{HoldoutJson, JackknifeJson};
use crate::model::{Params, N_PARAMS};
use std::time::Instant;

/// The most Newton steps of one linear estimate.
pub(crate) const MAX_STEPS: u32 = 4;

/// The jackknife spread of each parameter (0 where not free in the full fit) and its record.
pub struct Jackknife {
    pub std: [f64; N_PARAMS],
    pub json: JackknifeJson,
}

/// Leave-one-radius-out refits of a joint fit: the fit is repeated with every radius left out in
/// turn (warm-started from the full fit, on its cells), and the spread
/// of the n refits gives each parameter's jackknife standard error ([`spread`]). It sees what
/// the noise alone does not: a model that fits each radius a little differently. Each left-out
/// radius is predicted by the fit to the others. `None` with fewer than 3 radii.
pub fn jackknife_refit(
    settings: &Settings,
    measured: &Measured,
    fitted: &[&SphereData],
    jf: &JointFit,
    ext: Extensions,
) -> Option<Jackknife> {
    use rayon::prelude::*;
    let t = Instant::now();
    let mut radii = observe::distinct_radii(fitted);
    radii.reverse();
    if radii.len() < 3 {
        return None;
    }
    // The full fit's cells (its highlight pixel by pixel), so that the refits estimate what the
    // linear estimates do.
    let reduction = match (jf.chosen.width_deg / 0.25).round() as u32 {
        0 => Reduction::None,
        f => Reduction::Factor(f),
    };
    let runs: Vec<(Params, bool, HoldoutJson)> = radii
        .par_iter()
        .map(|&r| {
            let same = |s: &&&SphereData| (s.radius_mm - r).abs() < 1e-9;
            let train: Vec<&SphereData> = fitted.iter().filter(|s| !same(s)).copied().collect();
            let test: Vec<&SphereData> = fitted.iter().filter(same).copied().collect();
            let su = Setup::new(settings, measured, ext, reduction).refit(jf.fit.params);
            let f = fit_joint(&su, &train);
            let preds: Vec<Prediction> = test
                .iter()
                .map(|s| {
                    predict(
                        &f.model,
                        &f.fit.params,
                        s,
                        f.fit.floor_value(),
                        PREDICT_PIXELS,
                    )
                })
                .collect();
            (
                f.fit.params,
                f.fit.converged,
                combine_predictions(r, &preds),
            )
        })
        .collect();
    Some(summarise(radii, runs, jf, "refit", vec![], t))
}

/// Leave-one-radius-out estimates from the full fit's linearisation: the final stage's normal
/// equations are accumulated per radius in one pass, and each estimate without a radius starts
/// as the Gauss–Newton step from the full fit on the totals less that radius's part, with the
/// full fit's priors, holds, robust weights and dark floor treatment (θ₋g = θ̂ − (H − H_g)⁻¹(g −
/// g_g), g ≈ 0 at the full fit). Further steps on the other radii's observations ([`iterate`])
/// take the Huber weights again, as the refit does, until the steps are small against the
/// spread. The spread is then taken as the refits' ([`spread`]); each left-out radius is
/// predicted by its estimate. `None` with fewer than 3 radii.
pub fn jackknife_linear(fitted: &[&SphereData], jf: &JointFit) -> Option<Jackknife> {
    let t = Instant::now();
    let mut radii = observe::distinct_radii(fitted);
    radii.reverse();
    if radii.len() < 3 {
        return None;
    }
    let same = |s: &SphereData, r: f64| (s.radius_mm - r).abs() < 1e-9;
    let group_of = observe::radius_index(fitted, &radii);
    let groups: Vec<usize> = jf.problem.sphere.iter().map(|&s| group_of[s]).collect();
    let u_full = to_unbounded(&jf.fit.params.to_vec());
    let full = newton::problem(jf, &jf.problem.weighted, jf.fit.free, u_full);
    let parts = full.grouped_sums(Some((&groups, radii.len())));
    let total = RawNormal::sum(&parts)?;
    let first: Vec<Option<Estimate>> = parts
        .iter()
        .map(|part| full.newton_step(&total.less(part)))
        .collect();
    let tol = step_tolerance(&first, jf);
    let mut steps = vec![];
    let runs: Vec<(Params, bool, HoldoutJson)> = (0..radii.len())
        .map(|g| {
            let (estimate, n) = match first[g] {
                Some(x) => iterate(jf, &groups, g, x, &tol),
                None => (None, 1),
            };
            steps.push(n);
            let ok = estimate.is_some();
            let (u, floor) = estimate.unwrap_or((u_full, jf.fit.floor_value()));
            let p = Params::from_vec(&from_unbounded(&u).0);
            let preds: Vec<Prediction> = fitted
                .iter()
                .filter(|s| same(s, radii[g]))
                .map(|s| predict(&jf.model, &p, s, floor, PREDICT_PIXELS))
                .collect();
            (p, ok, combine_predictions(radii[g], &preds))
        })
        .collect();
    Some(summarise(radii, runs, jf, "linear", steps, t))
}

/// Per parameter, the largest step (unbounded coordinates) that ends a linear estimate: the
/// larger of its formal standard error and the spread of the first steps, times
/// [`newton::STEP_TOL`].
fn step_tolerance(first: &[Option<Estimate>], jf: &JointFit) -> [f64; N_PARAMS] {
    let values: Vec<[f64; N_PARAMS]> = first.iter().flatten().map(|e| e.0).collect();
    let s = if values.len() >= 2 {
        spread(&values, &jf.fit.free)
    } else {
        [0.0; N_PARAMS]
    };
    newton::tolerance(jf, &s)
}

/// The estimate without group `g` from its first Newton step `first`: further steps on the
/// other groups' observations ([`newton::iterate`]), at most [`MAX_STEPS`] in all. Returns the
/// estimate (`None` where a step failed) and the steps taken.
fn iterate(
    jf: &JointFit,
    groups: &[usize],
    g: usize,
    first: Estimate,
    tol: &[f64; N_PARAMS],
) -> (Option<Estimate>, u32) {
    let u_full = to_unbounded(&jf.fit.params.to_vec());
    let keep: Vec<usize> = (0..groups.len()).filter(|&i| groups[i] != g).collect();
    let obs: Vec<Obs> = keep.iter().map(|&i| jf.problem.obs[i]).collect();
    let weighted: Vec<Obs> = keep.iter().map(|&i| jf.problem.weighted[i]).collect();
    match newton::iterate(
        jf,
        (&obs, weighted),
        jf.fit.free,
        (&u_full, first),
        tol,
        (MAX_STEPS, false),
    ) {
        Some(it) => (Some(it.estimate), it.steps),
        None => (None, MAX_STEPS),
    }
}

/// Each parameter's jackknife standard error from the n leave-one-out estimates θᵢ,
/// √((n−1)/n · Σ(θᵢ − θ̄)²), widened by t_{n−1}/2 (its ±2 then covers 95.4% with n − 1 degrees
/// of freedom, as ±2σ of a Gaussian does: 1.42 for five radii); 0 where not free.
fn spread(values: &[[f64; N_PARAMS]], free: &[bool; N_PARAMS]) -> [f64; N_PARAMS] {
    let n = values.len() as f64;
    let widen = crate::stats::jackknife_widening(values.len());
    std::array::from_fn(|k| {
        if !free[k] {
            return 0.0;
        }
        let mean = values.iter().map(|v| v[k]).sum::<f64>() / n;
        widen * ((n - 1.0) / n * values.iter().map(|v| (v[k] - mean).powi(2)).sum::<f64>()).sqrt()
    })
}

/// The jackknife of the estimates (parameters, converged, the left-out radius predicted).
fn summarise(
    radii: Vec<f64>,
    runs: Vec<(Params, bool, HoldoutJson)>,
    jf: &JointFit,
    method: &str,
    newton_steps: Vec<u32>,
    t: Instant,
) -> Jackknife {
    let values: Vec<[f64; N_PARAMS]> = runs.iter().map(|r| r.0.to_vec()).collect();
    let std = spread(&values, &jf.fit.free);
    let heldout: Vec<HoldoutJson> = runs.iter().map(|r| r.2.clone()).collect();
    let w: f64 = heldout
        .iter()
        .map(|h| h.pixels as f64)
        .sum::<f64>()
        .max(1.0);
    Jackknife {
        std,
        json: JackknifeJson {
            method: method.into(),
            newton_steps,
            heldout_rel_rmse: heldout
                .iter()
                .map(|h| h.rel_rmse * h.pixels as f64)
                .sum::<f64>()
                / w,
            radii,
            heldout,
            converged: runs.iter().all(|r| r.1),
            seconds: t.elapsed().as_secs_f64(),
        },
    }
}
