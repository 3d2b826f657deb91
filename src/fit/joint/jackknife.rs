//! The leave-one-radius-out jackknife of a joint fit: the spread of the refits joins each
//! parameter's standard error (docs/uncertainty.md), and each left-out radius is predicted.

use super::settings::{Extensions, Measured, Reduction, Settings, Setup};
use super::stages::{fit_joint, JointFit};
use crate::fit::observe::{self, SphereData};
use crate::fit::predict::{combine_predictions, predict, Prediction, PREDICT_PIXELS};
use crate::formats::fit::{HoldoutJson, JackknifeJson};
use crate::model::{Params, N_PARAMS};
use std::time::Instant;

/// The jackknife's refits pool pixels in cells of this many × 0.25° at least.
pub(crate) const JACKKNIFE_CELLS: u32 = 8;

/// The jackknife spread of each parameter (0 where not free in the full fit) and its record.
pub struct Jackknife {
    pub std: [f64; N_PARAMS],
    pub json: JackknifeJson,
}

/// Leave-one-radius-out refits of a joint fit: the fit is repeated with every radius left out in
/// turn (warm-started from the full fit, on 2° cells or its own coarser level), and the spread of
/// the n refits gives each parameter's jackknife standard error √((n−1)/n · Σ(θᵢ − θ̄)²),
/// widened by t_{n−1}/2 (its ±2 covers 95.4% with n − 1 degrees of freedom). It sees what the
/// noise alone does not: a model that fits each radius a little differently. Each left-out
/// radius is predicted by the fit to the others. `None` with fewer than 3 radii.
pub fn jackknife(
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
    // The refits compare errors of percents between subsets, not of standard errors: 2° cells
    // (or the full fit's level when coarser).
    let reduction =
        Reduction::Factor(((jf.chosen.width_deg / 0.25).round() as u32).max(JACKKNIFE_CELLS));
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
    let n = runs.len() as f64;
    let values: Vec<[f64; N_PARAMS]> = runs.iter().map(|r| r.0.to_vec()).collect();
    // An estimate from n − 1 degrees of freedom: widened so that ±2 of it covers as ±2σ of a
    // Gaussian does (95.4%), by t_{n−1} / 2 (1.42 for five radii).
    let widen =
        crate::stats::t_quantile_central(crate::stats::TWO_SIGMA, runs.len() as u32 - 1) / 2.0;
    let std = std::array::from_fn(|k| {
        if !jf.fit.free[k] {
            return 0.0;
        }
        let mean = values.iter().map(|v| v[k]).sum::<f64>() / n;
        widen * ((n - 1.0) / n * values.iter().map(|v| (v[k] - mean).powi(2)).sum::<f64>()).sqrt()
    });
    let heldout: Vec<HoldoutJson> = runs.iter().map(|r| r.2.clone()).collect();
    let w: f64 = heldout
        .iter()
        .map(|h| h.pixels as f64)
        .sum::<f64>()
        .max(1.0);
    Some(Jackknife {
        std,
        json: JackknifeJson {
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
    })
}
