//! fit.json's contents: each sphere predicted, and the outcome written out with its errors.

use super::load::{fingerprint, Loaded};
use super::outcome::Outcome;
use super::Options;
use crate::fit::observe::SphereData;
use crate::fit::predict::{combine_predictions, predict, Prediction, PREDICT_PIXELS};
use crate::formats::fit::*;
use crate::model::{idx, LightAngles, N_PARAMS, PARAM_NAMES};
use std::time::Instant;

/// Each sphere predicted by the fit (the held-out one included), and the held-out radius's
/// error combined.
pub(super) fn predictions(
    opts: &Options,
    l: &Loaded,
    outcome: &Outcome,
) -> (Vec<SphereRmse>, Option<HoldoutJson>) {
    let is_held = |s: &SphereData| opts.holdout.is_some_and(|r| (s.radius_mm - r).abs() < 1e-9);
    let model = outcome.model;
    let spheres: Vec<SphereRmse> = l
        .spheres
        .iter()
        .map(|s| {
            let p: Prediction = match &outcome.paper {
                Some(pf) if !is_held(s) => pf.predict(s, PREDICT_PIXELS),
                // A held-out radius has no per-radius fit: the combined σ0 predicts it.
                _ => predict(&model, &outcome.params, s, [0.0; 3], PREDICT_PIXELS),
            };
            SphereRmse {
                image: s.image.clone(),
                index: s.index,
                radius_mm: s.radius_mm,
                pixels: s.obs.len(),
                saturated: s.saturated,
                edge: s.edge,
                impulses: s.impulses,
                noise: s.noise,
                floor: s.floor,
                rmse: p.rmse,
                rel_rmse: p.rel_rmse,
                lit_rel_rmse: p.lit_rel_rmse,
                unlit_rel_rmse: p.unlit_rel_rmse,
                held_out: is_held(s),
            }
        })
        .collect();
    let holdout = opts.holdout.map(|r| {
        let held: Vec<Prediction> = spheres
            .iter()
            .filter(|s| s.held_out)
            .map(|s| Prediction {
                pixels: s.pixels,
                rmse: s.rmse,
                rel_rmse: s.rel_rmse,
                lit_rel_rmse: s.lit_rel_rmse,
                unlit_rel_rmse: s.unlit_rel_rmse,
            })
            .collect();
        combine_predictions(r, &held)
    });
    (spheres, holdout)
}

/// fit.json's contents from the fit's outcome and the predictions.
pub(super) fn fit_file(
    opts: &Options,
    l: &Loaded,
    outcome: Outcome,
    spheres: Vec<SphereRmse>,
    holdout: Option<HoldoutJson>,
    notes: Vec<String>,
    t0: Instant,
) -> FitFile {
    let (overall, relative) = overall_rmse(&spheres);
    let p = &outcome.params;
    let m = &p.material;
    let l_dir = p.light.direction();
    FitFile {
        schema: SCHEMA.into(),
        method: opts.method,
        session: l.report.session_file.display().to_string(),
        detections: l.detections_path.display().to_string(),
        projection: l.detections.projection.clone(),
        sigma0_mm: m.sigma0_mm,
        albedo: m.albedo,
        eta: m.eta,
        specular: outcome.specular.then_some(SpecularJson {
            ks: m.specular.ks,
            alpha: m.specular.alpha,
        }),
        light_direction: [l_dir.x, l_dir.y, l_dir.z],
        light_azimuth_deg: p.light.azimuth.to_degrees(),
        light_elevation_deg: p.light.elevation.to_degrees(),
        image_lights: image_lights(l, &l_dir),
        sigma_exponent: outcome
            .extensions
            .sigma_exponent
            .then_some(m.sigma_exponent),
        albedo_curvature: outcome
            .extensions
            .albedo_curvature
            .then_some(m.albedo_curvature),
        kernel: outcome.extensions.two_gaussian.then_some(KernelJson {
            weight: m.kernel_weight,
            ratio: m.kernel_ratio,
        }),
        reference_radius_mm: outcome.model.reference_radius_mm,
        entry_transmission: outcome.model.entry_fresnel,
        std: std_json(&outcome),
        std_source: format!(
            "{}{}",
            match &outcome.jackknife {
                Some(_) => "larger of formal and jackknife",
                None => "formal",
            },
            if outcome.prior_tension.iter().any(|&s| s > 1.0) {
                ", times the prior tension where it is given"
            } else {
                ""
            }
        ),
        jackknife: outcome.jackknife.as_ref().map(|j| j.json.clone()),
        light_fit: outcome.light_fit.clone(),
        light_pull: outcome.light_pull,
        dark_floor: outcome.floor.map(|f| {
            let e = l.measured.pixel_scale;
            DarkFloorJson {
                value: f.value.map(|v| v * e),
                std: f.std.map(|v| v * e),
            }
        }),
        parameters: parameters(&outcome),
        correlation: correlation(&outcome),
        rmse: RmseJson {
            overall,
            relative,
            spheres,
        },
        holdout,
        medium: None,
        per_radius: outcome.per_radius,
        baseline: outcome.baseline,
        model_choice: outcome.model_choice,
        reduction: outcome.reduction,
        convergence: outcome.convergence,
        skipped: l.skipped.clone(),
        notes,
        timings: Timings {
            total_s: t0.elapsed().as_secs_f64(),
            ..l.timings.clone()
        },
        options: fingerprint(opts),
        inputs: l.inputs.clone(),
        build: crate::formats::fingerprint::BUILD.into(),
    }
}

/// The RMSE over the fitted spheres (pixel-weighted), absolute and relative.
fn overall_rmse(spheres: &[SphereRmse]) -> (f64, f64) {
    let used: Vec<&SphereRmse> = spheres.iter().filter(|s| !s.held_out).collect();
    let n: f64 = used.iter().map(|s| s.pixels as f64).sum::<f64>().max(1.0);
    let overall = (used
        .iter()
        .map(|s| s.rmse.powi(2) * s.pixels as f64)
        .sum::<f64>()
        / n)
        .sqrt();
    let relative = (used
        .iter()
        .map(|s| s.rel_rmse.powi(2) * s.pixels as f64)
        .sum::<f64>()
        / n)
        .sqrt();
    (overall, relative)
}

/// Each photo's light (one light per photo): the fitted light turned back into its frame.
fn image_lights(l: &Loaded, l_dir: &nalgebra::Vector3<f64>) -> Vec<ImageLightJson> {
    l.frames
        .iter()
        .flatten()
        .zip(&l.report.images)
        .map(|(r, im)| {
            let d = r.inverse() * l_dir;
            let a = LightAngles::from_direction(&d);
            let fitted = l.intensities.as_ref().and_then(|f| {
                f.photos
                    .iter()
                    .find(|(file, _)| *file == im.file)
                    .map(|(_, k)| *k)
            });
            let (intensity, source) = match (im.light_intensity, fitted) {
                (Some(k), _) => (Some(k), Some("session.json".to_string())),
                (None, Some(k)) => (Some(k), Some("fitted".to_string())),
                (None, None) => (None, None),
            };
            ImageLightJson {
                file: im.file.clone(),
                direction: [d.x, d.y, d.z],
                azimuth_deg: a.azimuth.to_degrees(),
                elevation_deg: a.elevation.to_degrees(),
                intensity,
                intensity_source: source,
            }
        })
        .collect()
}

/// A standard error as fit.json states it: infinite (written `null`) where the data do not bound
/// the parameter ([`unbounded`]).
fn bounded(value: f64, std: f64) -> f64 {
    if unbounded(value, std) {
        f64::INFINITY
    } else {
        std
    }
}

/// Each parameter's stated standard error as fit.json writes it ([`bounded`]).
fn stated_std(outcome: &Outcome) -> [f64; N_PARAMS] {
    let v = outcome.params.to_vec();
    std::array::from_fn(|k| bounded(v[k], outcome.std[k]))
}

/// The stated standard errors, the light's as one angle.
fn std_json(outcome: &Outcome) -> StdJson {
    let p = &outcome.params;
    let std = stated_std(outcome);
    let light_deg = (std[idx::AZIMUTH].powi(2) * p.light.elevation.cos().powi(2)
        + std[idx::ELEVATION].powi(2))
    .sqrt()
    .to_degrees();
    StdJson {
        sigma0_mm: [std[0], std[1], std[2]],
        albedo: [std[3], std[4], std[5]],
        eta: std[idx::ETA],
        specular: outcome.specular.then_some(SpecularJson {
            ks: std[idx::KS],
            alpha: std[idx::ALPHA],
        }),
        light_deg,
        sigma_exponent: outcome
            .extensions
            .sigma_exponent
            .then_some(std[idx::SIGMA_EXPONENT]),
        albedo_curvature: outcome
            .extensions
            .albedo_curvature
            .then_some(std[idx::ALBEDO_CURVATURE]),
        kernel: outcome.extensions.two_gaussian.then_some(KernelJson {
            weight: std[idx::KERNEL_WEIGHT],
            ratio: std[idx::KERNEL_RATIO],
        }),
    }
}

/// Every parameter with its value, errors and status.
fn parameters(outcome: &Outcome) -> Vec<ParamJson> {
    let p = &outcome.params;
    let v = p.to_vec();
    (0..N_PARAMS)
        .map(|k| ParamJson {
            name: PARAM_NAMES[k].into(),
            value: v[k],
            std: bounded(v[k], outcome.std[k]),
            std_formal: outcome
                .jackknife
                .as_ref()
                .map(|_| bounded(v[k], outcome.std_formal[k])),
            std_jackknife: outcome.jackknife.as_ref().map(|j| bounded(v[k], j.std[k])),
            prior_tension: (outcome.prior_tension[k] > 1.0).then_some(outcome.prior_tension[k]),
            std_note: unbounded(v[k], outcome.std[k]).then(|| {
                format!(
                    "unbounded: the data do not bound {} (its standard error came out above {UNBOUNDED_RATIO:e} times its value)",
                    PARAM_NAMES[k]
                )
            }),
            status: outcome.status[k].clone(),
        })
        .collect()
}

/// The free parameters' correlation matrix.
fn correlation(outcome: &Outcome) -> CorrelationJson {
    let free_names: Vec<String> = (0..N_PARAMS)
        .filter(|&k| outcome.free[k])
        .map(|k| PARAM_NAMES[k].to_string())
        .collect();
    let nc = outcome.correlation.nrows();
    CorrelationJson {
        names: if nc == free_names.len() {
            free_names
        } else {
            PARAM_NAMES[..nc].iter().map(|s| s.to_string()).collect()
        },
        matrix: (0..nc)
            .map(|i| (0..nc).map(|j| outcome.correlation[(i, j)]).collect())
            .collect(),
    }
}
