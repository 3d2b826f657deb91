//! The checks on a joint fit's result, each a note (and a status) rather than a silent number:
//! clipped pixels, residuals beyond the measured noise, a light beside
//! the camera, η against its prior, η from the highlight alone and α from the detector's lobe
//! fits against the whole fit's.

use super::settings::{Measured, Setup};
use crate::fit::observe::SphereData;
use crate::fit::reduce::Pooled;
use crate::fit::solver::{self, Fit};
use crate::model::{idx, N_PARAMS};
use nalgebra::Vector3;

/// A light closer than this to the viewing direction (degrees) gets a note: θ ≈ φ.
pub(crate) const NEAR_VIEW_DEG: f64 = 15.0;

/// Above this χ²/dof (residuals twice the measured noise) the fit warns.
pub(crate) const CHI2_WARN: f64 = 4.0;

/// Above this fraction of clipped sphere pixels the fit warns.
pub(crate) const CLIPPED_WARN: f64 = 0.5;

/// With the irradiance given, η is measured by the highlight's height — and, through the
/// transmissions, by the diffuse shading, the least exact part of the model. η (and α) refitted
/// on the highlight's pixels alone, the rest held: a disagreement beyond the two formal errors is
/// flagged and returned, to join η's error as a systematic (docs/uncertainty.md, "η").
pub(crate) fn eta_from_highlight(
    setup: &Setup,
    pooled: &Pooled,
    specular: bool,
    fit: &Fit,
    notes: &mut Vec<String>,
) -> f64 {
    let mut eta_systematic = 0.0;
    if setup.settings.irradiance.is_some()
        && specular
        && fit.free[idx::ETA]
        && pooled.kept.len() > 8
    {
        let mut hl_free = [false; N_PARAMS];
        hl_free[idx::ETA] = true;
        hl_free[idx::ALPHA] = fit.free[idx::ALPHA];
        let hl = on_highlight(setup, pooled, fit, &fit.params, hl_free);
        let (a, b) = (hl.params.material.eta, fit.params.material.eta);
        let combined = (hl.std[idx::ETA].powi(2) + fit.std[idx::ETA].powi(2)).sqrt();
        if hl.converged && combined > 0.0 && (a - b).abs() > 3.0 * combined {
            eta_systematic = (a - b).abs();
            notes.push(format!(
                "η = {b:.4} from the joint fit, {a:.4} ± {:.4} from the highlight alone ({:.1} of their errors apart): the diffuse shading pulls η through the transmissions; the difference joins η's std",
                hl.std[idx::ETA],
                (a - b).abs() / combined
            ));
        }
    }
    eta_systematic
}

/// With the irradiance given, the highlight's height measures F(η) through the lobe's peak; where
/// the peak is clipped only its wings are left, whose height goes as F(η) α², and η trades with α
/// further than the fit's own error and the highlight-alone check (which frees α too) say: on
/// the thin, dark corner of the range (`datasets/pbr-range/thin-dark`, 253 pixels
/// clipped on its 35 mm sphere) the joint fit's η was stated 2.67 ± 0.30 against the truth's
/// 1.6, its α 0.042 against the detector's lobe fits' 0.093 ± 0.011 (with α held there the
/// highlight says 1.50; η is now stated ± 1.00). So where α disagrees with the
/// detector's ([`alpha_from_detector`] returned a difference), η is fitted again on the
/// highlight's pixels with α held at the detector's, and the difference joins η's error as a
/// systematic, with a note (docs/uncertainty.md, "η with the detector's α").
pub(crate) fn eta_at_detector_alpha(
    setup: &Setup,
    pooled: &Pooled,
    fit: &Fit,
    alpha_apart: f64,
    notes: &mut Vec<String>,
) -> f64 {
    let Some(detected) = setup.measured.alpha else {
        return 0.0;
    };
    if alpha_apart <= 0.0
        || setup.settings.irradiance.is_none()
        || !fit.free[idx::ETA]
        || pooled.kept.len() <= 8
    {
        return 0.0;
    }
    let mut free = [false; N_PARAMS];
    free[idx::ETA] = true;
    let mut start = fit.params;
    start.material.specular.alpha = detected;
    let at = on_highlight(setup, pooled, fit, &start, free);
    let (a, b) = (at.params.material.eta, fit.params.material.eta);
    if !at.converged || !a.is_finite() {
        return 0.0;
    }
    notes.push(format!(
        "η = {b:.4} from the joint fit, {a:.4} on the highlight with α held at the detector's {detected:.4}: η trades with α where the lobe's peak is not seen (clipped, or faint), so the difference joins η's std"
    ));
    (a - b).abs()
}

/// The highlight's pixels (the pooled ones kept unpooled, the fit's dark floor taken off) fitted
/// from `start` with `free` free, the rest held: the refits η's checks compare with the fit.
fn on_highlight(
    setup: &Setup,
    pooled: &Pooled,
    fit: &Fit,
    start: &crate::model::Params,
    free: [bool; N_PARAMS],
) -> Fit {
    let kept = solver::less_floor(&pooled.kept, fit.floor_value());
    solver::fit(setup.model(), &kept, start, free, &[])
}

/// How many of their combined errors the joint fit's α and the detector's may lie apart before
/// the difference joins α's error. Two, not three: the joint fit's own error is typically a
/// tenth of the detector's, so a disagreement of 2–3 combined errors is many of its own
/// (physically based soap: 2.8 apart, the joint α 24 of its std from the truth); on the
/// project's own renders, where both are right, it fires on about one seed in twenty.
pub(crate) const ALPHA_APART: f64 = 2.0;

/// The roughness is measured twice: by the joint fit, under the CDRF's diffuse shading, and by
/// the detector's lobe fits, each under a local trend of its own. Where the diffuse model is
/// wrong around the highlight the lobe's wings trade with it and α moves, alike on every radius
/// (the jackknife does not see it; physically based soap: 0.067 ± 0.0005 against the truth 0.08
/// and the detector's 0.079 ± 0.004, 2.8 of their errors apart). A disagreement beyond
/// [`ALPHA_APART`] of their combined errors is flagged and returned, to join α's error as a
/// systematic (docs/uncertainty.md, "α against the detector's").
pub(crate) fn alpha_from_detector(
    measured: &Measured,
    specular: bool,
    fit: &Fit,
    notes: &mut Vec<String>,
) -> f64 {
    let (Some(detected), Some(detected_std)) = (measured.alpha, measured.alpha_std) else {
        return 0.0;
    };
    if !specular || !fit.free[idx::ALPHA] {
        return 0.0;
    }
    let fitted = fit.params.material.specular.alpha;
    let combined = fit.std[idx::ALPHA].hypot(detected_std);
    let apart = (fitted - detected).abs() / combined;
    if !(combined > 0.0 && apart > ALPHA_APART) {
        return 0.0;
    }
    notes.push(format!(
        "α = {fitted:.4} from the joint fit, {detected:.4} ± {detected_std:.4} from the detector's lobe fits ({apart:.1} of their errors apart): the diffuse model around the highlight pulls the lobe's width; the difference joins α's std"
    ));
    (fitted - detected).abs()
}

/// A light beside the camera: θ ≈ φ on every pixel, and the blur and the exit transmission trade
/// off. Each sphere's photo is looked at (its mean view against the light, in its photo's frame:
/// a per-image-light session turns each photo's geometry under the shared light); the note comes
/// only when every photo's light is within [`NEAR_VIEW_DEG`] of its view, since one photo lit from
/// the side shows a terminator that fixes σ0.
fn light_beside_the_camera(fit: &Fit, spheres: &[&SphereData]) -> Option<String> {
    let light = fit.params.light.direction();
    let angles: Vec<f64> = spheres
        .iter()
        .filter_map(|s| {
            let view: Vector3<f64> = s.obs.iter().map(|o| o.geometry.view).sum();
            (view.norm() > 0.0).then(|| light.angle(&view).to_degrees())
        })
        .collect();
    let widest = angles.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    if angles.is_empty() || widest >= NEAR_VIEW_DEG {
        return None;
    }
    let what = if angles.len() > 1 {
        let narrowest = angles.iter().cloned().fold(f64::INFINITY, f64::min);
        format!(
            "for every one of the {} spheres the light is {narrowest:.1}–{widest:.1}° from the camera's direction",
            angles.len()
        )
    } else {
        format!("the light is {widest:.1}° from the camera's direction")
    };
    Some(format!(
        "{what}: no terminator in view and θ ≈ φ on every pixel, so σ0 rests on the fall-off at the rim, where it trades off with the exit transmission T(φ; η) — expect σ0 off by 10% or more; light the spheres from the side"
    ))
}

/// What the fit's residuals and geometry say about it: the residuals against the measured noise
/// (returned as χ²/dof) and, above [`CHI2_WARN`], where they lie ([`super::regions`]), a light
/// beside the camera, and η against its prior. Returns χ²/dof and
/// the notes.
pub(crate) fn fit_notes(
    model: &crate::model::Model,
    fit: &Fit,
    spheres: &[&SphereData],
    (eta_mean, eta_std): (f64, f64),
    eta_status: &str,
) -> (f64, Vec<String>) {
    let mut notes = vec![];
    // Goodness of fit against the measured noise (weights are 1/σ per pixel and channel).
    let dof = fit
        .residuals
        .saturating_sub(fit.free.iter().filter(|f| **f).count())
        .saturating_sub(if fit.floor.is_some() { 3 } else { 0 })
        .max(1);
    let chi2 = 2.0 * fit.cost / dof as f64;
    if chi2 > CHI2_WARN {
        notes.push(format!(
            "the residuals are {:.1}× the measured noise (χ²/dof = {chi2:.1}): the model does not describe these photos fully — check the detections (light, outlines); a wrong light or outline biases σ0",
            chi2.sqrt()
        ));
        notes.extend(super::regions::worst_region(model, fit, spheres));
    }
    notes.extend(light_beside_the_camera(fit, spheres));
    let tension = (fit.params.material.eta - eta_mean).abs() / eta_std;
    if eta_status.starts_with("prior") && tension > 3.0 {
        notes.push(format!(
            "η = {:.4} lies {tension:.1} prior σ from the prior {eta_mean} ± {eta_std}: the prior or the model's fall-off at the rim and the terminator disagrees with the data (its std is scaled for the disagreement); measure η with --irradiance",
            fit.params.material.eta
        ));
    }
    if eta_status.starts_with("prior") && fit.std[idx::ETA] < 0.5 * eta_std {
        notes.push(format!(
            "η = {:.4} (formal ± {:.4}): the data, through the Fresnel transmissions, determine η better than its prior (± {eta_std}); that rests on the model's fall-off at the terminator and the rim",
            fit.params.material.eta, fit.std[idx::ETA]
        ));
    }
    (chi2, notes)
}

/// A note when more than [`CLIPPED_WARN`] of the sphere pixels are clipped.
pub(crate) fn clipped(spheres: &[&SphereData]) -> Option<String> {
    let (clipped, on) = spheres
        .iter()
        .fold((0, 0), |(c, n), s| (c + s.saturated, n + s.pixels));
    (on > 0 && clipped as f64 > CLIPPED_WARN * on as f64).then(|| format!(
        "{:.0}% of the sphere pixels are clipped: the fit rests on the rest (near the terminator), where σ0, the albedo and the light trade off — expect biases of several percent; lower the exposure",
        100.0 * clipped as f64 / on as f64
    ))
}
