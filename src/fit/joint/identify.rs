//! Identifiability: which parameters the full fit frees (the lobe, η on its prior unless the
//! irradiance is given, the extensions that 3 radii at least can test), which of them the data
//! leave undetermined and how each is then held ([`hold`]), σ0 at the edges of what the data
//! resolve (a bound, not a measurement), a fit with a singular covariance marked degenerate
//! ([`degenerate_check`]), and how far a prior and the data disagree ([`prior_tension`]).

use super::settings::{Extensions, Setup, ALPHA_PRIOR};
use super::start;
use crate::fit::observe::{self, SphereData};
use crate::fit::solver::{self, Fit, Obs, Prior};
use crate::formats::fit::Stage;
use crate::model::{idx, Model, Params, N_PARAMS, PARAM_NAMES};

/// The parameters of the full fit and their priors: the lobe, η (on its prior unless the
/// irradiance is given), the extensions asked for (3 radii at least), the kernel's start.
pub(crate) fn parameter_set(
    setup: &Setup,
    spheres: &[&SphereData],
    specular: bool,
    light_priors: &[Prior],
    (p, free): (&mut Params, &mut [bool; N_PARAMS]),
    status: &mut [String; N_PARAMS],
    notes: &mut Vec<String>,
) -> Vec<Prior> {
    let (eta_mean, eta_std) = setup.settings.eta_prior;
    let distinct_radii = observe::distinct_radii(spheres).len();
    let mut priors: Vec<Prior> = light_priors.to_vec();
    free[idx::KS] = specular && setup.settings.irradiance.is_none();
    free[idx::ALPHA] = specular;
    free[idx::ETA] = true;
    match setup.settings.irradiance {
        Some(e) => {
            if specular {
                status[idx::KS] = format!("fixed: the given irradiance {e}");
            }
        }
        None => {
            // Without the light's irradiance a free ks absorbs F(η) (docs/pipeline.md, step 6): η rests on its
            // prior, and on the exit transmission T(φ) as far as the data determine it.
            status[idx::ETA] = format!("prior {eta_mean} ± {eta_std}");
            priors.push(Prior {
                index: idx::ETA,
                mean: eta_mean,
                std: eta_std,
            });
        }
    }
    let mut ext = setup.extensions;
    if ext.any() && distinct_radii < 3 {
        notes.push(format!(
            "extensions {} need at least 3 different radii ({} given): off",
            ext.name(),
            distinct_radii
        ));
        ext = Extensions::default();
    }
    free[idx::SIGMA_EXPONENT] = ext.sigma_exponent;
    free[idx::ALBEDO_CURVATURE] = ext.albedo_curvature;
    free[idx::KERNEL_WEIGHT] = ext.two_gaussian;
    free[idx::KERNEL_RATIO] = ext.two_gaussian;
    if ext.two_gaussian && p.material.kernel_weight == 0.0 {
        start::kernel(p);
    }
    if !ext.two_gaussian {
        p.material.kernel_weight = 0.0;
        p.material.kernel_ratio = 0.0;
    }
    for (k, on) in [
        (idx::SIGMA_EXPONENT, ext.sigma_exponent),
        (idx::ALBEDO_CURVATURE, ext.albedo_curvature),
        (idx::KERNEL_WEIGHT, ext.two_gaussian),
        (idx::KERNEL_RATIO, ext.two_gaussian),
    ] {
        if !on {
            status[k] = "off".into();
        }
    }
    priors
}

/// What an identifiability round changes: the next fit's start, which parameters are free and
/// their priors, whether the lobe is on, the statuses and the notes.
pub(crate) struct Round<'a> {
    pub(crate) p: &'a mut Params,
    pub(crate) free: &'a mut [bool; N_PARAMS],
    pub(crate) priors: &'a mut Vec<Prior>,
    pub(crate) specular: &'a mut bool,
    pub(crate) status: &'a mut [String; N_PARAMS],
    pub(crate) notes: &'a mut Vec<String>,
}

/// Hold parameter `k`, which fit `f` leaves undetermined ([`poorly_determined`]): η at its
/// prior, α at the detector's, the lobe or an extension off (the start moved to match). Returns
/// whether the next fit differs (false for a parameter that is only reported).
pub(crate) fn hold(k: usize, f: &Fit, setup: &Setup, r: &mut Round) -> bool {
    let (eta_mean, eta_std) = setup.settings.eta_prior;
    match k {
        idx::ETA => {
            if r.priors.iter().any(|q| q.index == idx::ETA) {
                return false;
            }
            r.p.material.eta = eta_mean;
            r.priors.push(Prior {
                index: idx::ETA,
                mean: eta_mean,
                std: eta_std,
            });
            r.status[k] = format!("prior {eta_mean} ± {eta_std} (free fit: ± {:.3})", f.std[k]);
            r.notes.push(format!(
                "η is not determined by these data (std {:.3}): held at its prior {eta_mean} ± {eta_std}",
                f.std[k]
            ));
        }
        idx::ALPHA => {
            r.free[k] = false;
            r.p.material.specular.alpha = setup.measured.alpha.unwrap_or(ALPHA_PRIOR);
            r.status[k] = format!(
                "held at {} (free fit: ± {:.3})",
                r.p.material.specular.alpha, f.std[k]
            );
            r.notes
                .push(format!("α is not determined (std {:.3}): held", f.std[k]));
        }
        idx::KS => {
            r.free[idx::KS] = false;
            r.free[idx::ALPHA] = false;
            r.p.material.specular.ks = 0.0;
            *r.specular = false;
            r.status[idx::KS] = format!("off: not determined (free fit: ± {:.3})", f.std[k]);
            r.status[idx::ALPHA] = "off".into();
            r.notes
                .push("the specular scale is not determined: lobe off".into());
        }
        idx::SIGMA_EXPONENT | idx::ALBEDO_CURVATURE => {
            r.free[k] = false;
            r.status[k] = format!("off: not determined (free fit: ± {:.3})", f.std[k]);
            r.notes
                .push(format!("{} is not determined: off", PARAM_NAMES[k]));
        }
        idx::KERNEL_WEIGHT | idx::KERNEL_RATIO => {
            if !r.free[idx::KERNEL_WEIGHT] {
                return false;
            }
            r.free[idx::KERNEL_WEIGHT] = false;
            r.free[idx::KERNEL_RATIO] = false;
            r.status[idx::KERNEL_WEIGHT] =
                format!("off: not determined (free fit: ± {:.3})", f.std[k]);
            r.status[idx::KERNEL_RATIO] = "off".into();
            r.notes
                .push("the kernel's shape is not determined: one Gaussian".into());
        }
        _ => {
            r.notes.push(format!(
                "{} is poorly determined (std {:.3} for {:.4})",
                PARAM_NAMES[k],
                f.std[k],
                f.params.to_vec()[k]
            ));
            return false;
        }
    }
    if k == idx::SIGMA_EXPONENT {
        r.p.material.sigma_exponent = 0.0;
    }
    if k == idx::ALBEDO_CURVATURE {
        r.p.material.albedo_curvature = 0.0;
    }
    if k == idx::KERNEL_WEIGHT || k == idx::KERNEL_RATIO {
        // Back to one Gaussian of the mixture's width.
        let m = f.params.material;
        let grow =
            (1.0 - m.kernel_weight + m.kernel_weight * m.kernel_ratio * m.kernel_ratio).sqrt();
        r.p.material.sigma0_mm = m.sigma0_mm.map(|v| v * grow);
        r.p.material.kernel_weight = 0.0;
        r.p.material.kernel_ratio = 0.0;
    }
    true
}

/// σ0 at the edges of what the data resolve, where the linearised standard error means nothing:
/// compared with σ0 → 0 or → ∞ (profile likelihood), and below a pixel's angle; each such σ0's
/// status says it is a bound.
pub(crate) fn resolution_notes(
    setup: &Setup,
    spheres: &[&SphereData],
    final_obs: &[Obs],
    fit: &Fit,
    priors: &[Prior],
    status: &mut [String; N_PARAMS],
    notes: &mut Vec<String>,
) {
    let (r_min, r_max) = spheres.iter().fold((f64::INFINITY, 0.0f64), |(a, b), s| {
        (a.min(s.radius_mm), b.max(s.radius_mm))
    });
    // Below a pixel: the blur σ = σ0/r is smaller than one pixel's angle on the sphere (1/R for a
    // sphere R pixels in radius) on every sphere, so the pixels' own footprint hides it. Such a
    // channel is a bound whatever the refits below would say: they are left out for it.
    let mut limits: Vec<(usize, Bound)> = (0..3)
        .filter_map(|c| {
            let s0 = fit.params.material.sigma0_mm[c];
            let finest = spheres
                .iter()
                .filter(|s| s.pixels > 0)
                .map(|s| (s0 / s.radius_mm) * (s.pixels as f64 / std::f64::consts::PI).sqrt())
                .fold(0.0, f64::max);
            (fit.free[idx::SIGMA0 + c] && finest < 1.0).then_some((c, Bound::Pixel(finest)))
        })
        .collect();
    let bounded: Vec<usize> = limits.iter().map(|l| l.0).collect();
    limits.extend(resolution_limits(
        setup.model(),
        final_obs,
        fit,
        priors,
        setup.measured.fit_floor,
        (r_min, r_max),
        &bounded,
    ));
    limits.sort_by_key(|l| l.0);
    for (c, bound) in limits {
        let v = fit.params.material.sigma0_mm[c];
        let (what, test) = match bound {
            Bound::Pixel(f) => (
                format!("upper bound: the blur is {f:.2} of a pixel's angle"),
                format!("its blur σ0/r is {f:.2} of a pixel's angle on the sphere or less"),
            ),
            Bound::Zero(d) => (
                format!("upper bound: σ0 → 0 fits as well (Δχ² = {d:.2})"),
                format!("σ0 → 0 fits as well (Δχ² = {d:.2} < {RESOLVED_CHI2})"),
            ),
            Bound::Infinite(d) => (
                format!("lower bound: σ0 → ∞ fits as well (Δχ² = {d:.2})"),
                format!("σ0 → ∞, a uniform glow, fits as well (Δχ² = {d:.2} < {RESOLVED_CHI2})"),
            ),
        };
        status[idx::SIGMA0 + c] = what;
        notes.push(format!(
            "{} = {v:.4} mm is beyond what the data resolve: {test} (radii {r_min}–{r_max} mm); the value is a bound, not a measurement",
            PARAM_NAMES[idx::SIGMA0 + c]
        ));
    }
}

/// Δχ² below which σ0 → 0 or → ∞ counts as fitting the data as well (3σ for one parameter).
pub(crate) const RESOLVED_CHI2: f64 = 9.0;

/// σ = σ0/r below this at the largest radius, or above this at the smallest, is checked against
/// the limits (radians).
const SIGMA_CHECK: (f64, f64) = (0.05, 1.5);

/// Which end of the scale a channel's σ0 cannot be told from, with its Δχ².
#[derive(Clone, Copy, Debug, PartialEq)]
enum Bound {
    /// σ0/r below a pixel's angle on every sphere (the largest fraction).
    Pixel(f64),
    Zero(f64),
    Infinite(f64),
}

/// Channels whose σ0 the data cannot tell from 0 or ∞: for each channel with σ0/r_max small or
/// σ0/r_min large, the fit is repeated (plain least squares) with that σ0 held at 10⁻⁶ mm or
/// 10⁶ mm, and the cost compared with the free refit's in units of the residual variance.
/// `floor`: the dark floor is fitted ([`crate::fit::joint::Measured::fit_floor`]); `radii`: the
/// smallest and largest; `bounded`: channels already known to be bounds, not checked.
fn resolution_limits(
    model: Model,
    obs: &[Obs],
    fit: &Fit,
    priors: &[Prior],
    floor: bool,
    (r_min, r_max): (f64, f64),
    bounded: &[usize],
) -> Vec<(usize, Bound)> {
    let s0 = fit.params.material.sigma0_mm;
    let suspects: Vec<(usize, bool)> = (0..3)
        .filter_map(|c| {
            if !fit.free[idx::SIGMA0 + c] || bounded.contains(&c) {
                None
            } else if s0[c] / r_max < SIGMA_CHECK.0 {
                Some((c, true))
            } else if s0[c] / r_min > SIGMA_CHECK.1 {
                Some((c, false))
            } else {
                None
            }
        })
        .collect();
    if suspects.is_empty() {
        return vec![];
    }
    let free_fit = solver::fit_with_floor(model, obs, &fit.params, fit.free, priors, floor);
    let n = fit.free.iter().filter(|f| **f).count();
    let dof = free_fit.residuals.saturating_sub(n).max(1) as f64;
    let var = 2.0 * free_fit.cost / dof;
    if !(var.is_finite() && var > 0.0) {
        return vec![];
    }
    suspects
        .into_iter()
        .filter_map(|(c, small)| {
            let mut p = free_fit.params;
            p.material.sigma0_mm[c] = if small { 1e-6 } else { 1e6 };
            let mut free = fit.free;
            free[idx::SIGMA0 + c] = false;
            let held = solver::fit_with_floor(model, obs, &p, free, priors, floor);
            let d = 2.0 * (held.cost - free_fit.cost) / var;
            (d < RESOLVED_CHI2).then_some((
                c,
                if small {
                    Bound::Zero(d.max(0.0))
                } else {
                    Bound::Infinite(d.max(0.0))
                },
            ))
        })
        .collect()
}

/// A fit whose core parameters have no finite standard error is degenerate, whatever the
/// optimiser's stopping test said: not a measurement.
pub(crate) fn degenerate_check(fit: Fit, stages: &mut [Stage], notes: &mut Vec<String>) -> Fit {
    let mut fit = fit;
    let core = (0..6).chain([idx::AZIMUTH, idx::ELEVATION]);
    let singular: Vec<&str> = core
        .filter(|&k| fit.free[k] && !fit.std[k].is_finite())
        .map(|k| PARAM_NAMES[k])
        .collect();
    if !singular.is_empty() && fit.converged {
        fit.converged = false;
        fit.termination = format!(
            "degenerate: no finite standard error for {}",
            singular.join(", ")
        );
        if let Some(st) = stages.last_mut() {
            st.converged = false;
            st.termination = fit.termination.clone();
        }
        notes.push(format!(
            "the fit is degenerate (the covariance is singular for {}): the result is not a measurement — check the detections and the photos' noise and exposure",
            singular.join(", ")
        ));
    }
    fit
}

/// Free parameters the data leave undetermined: a standard error that is not finite, or larger
/// than the parameter's plausible range (relative 50% for positive ones, 0.5 for η − 1, 1 for the
/// extensions, 10° for the light angles).
pub(crate) fn poorly_determined(f: &Fit) -> Vec<usize> {
    let p = f.params.to_vec();
    (0..N_PARAMS)
        .filter(|&k| f.free[k] && beyond_range(k, p[k], f.std[k]))
        .collect()
}

/// Whether a standard error `std` of parameter `k` at `value` is not finite or larger than the
/// parameter's plausible range ([`poorly_determined`]'s rule).
pub(crate) fn beyond_range(k: usize, value: f64, std: f64) -> bool {
    !std.is_finite()
        || match k {
            idx::ETA => std > 0.5,
            idx::AZIMUTH | idx::ELEVATION => std > 10f64.to_radians(),
            idx::SIGMA_EXPONENT | idx::ALBEDO_CURVATURE => std > 1.0,
            _ => beyond_relative_range(value, std),
        }
}

/// Whether a positive quantity's standard error is not finite or past [`PLAUSIBLE_RELATIVE`] of
/// it: the error bar, not the value, is then what the data say ([`beyond_range`]; the medium
/// fit's σa and σs′ by the same rule).
pub fn beyond_relative_range(value: f64, std: f64) -> bool {
    !std.is_finite() || std > PLAUSIBLE_RELATIVE * value.abs()
}

/// The largest error a positive quantity may have, relative to it, and still be measured.
const PLAUSIBLE_RELATIVE: f64 = 0.5;

/// The Particle Data Group's scale factor for a parameter with a prior: the prior (m_p ± σ_p)
/// and the data alone (m_d ± σ_d, recovered from the posterior m ± σ through
/// 1/σ² = 1/σ_p² + 1/σ_d² and m/σ² = m_p/σ_p² + m_d/σ_d²) are two measurements of one quantity;
/// when they disagree by more than their errors allow, S = |m_d − m_p| / √(σ_p² + σ_d²) > 1
/// and the stated error is scaled by S (docs/uncertainty.md). 1 where the data add nothing.
pub fn prior_tension(value: f64, std: f64, prior: &Prior) -> f64 {
    let inv_data = 1.0 / (std * std) - 1.0 / (prior.std * prior.std);
    if !(inv_data > 0.0) || !inv_data.is_finite() {
        return 1.0;
    }
    let var_data = 1.0 / inv_data;
    let m_data = var_data * (value / (std * std) - prior.mean / (prior.std * prior.std));
    let s = (m_data - prior.mean).abs() / (prior.std * prior.std + var_data).sqrt();
    if s.is_finite() {
        s.max(1.0)
    } else {
        1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prior_tension_is_the_pdg_scale_factor() {
        let prior = Prior {
            index: idx::ETA,
            mean: 0.0,
            std: 1.0,
        };
        // Data 5 ± 1 against the prior 0 ± 1: posterior 2.5 ± 1/√2, and the two measurements
        // disagree by 5 / √2 of their combined error.
        let s = prior_tension(2.5, 0.5f64.sqrt(), &prior);
        assert!((s - 5.0 / 2f64.sqrt()).abs() < 1e-12, "{s}");
        // Data 1 ± 1: within their errors, no scaling.
        assert_eq!(prior_tension(0.5, 0.5f64.sqrt(), &prior), 1.0);
        // Data that add nothing (posterior = prior) or a degenerate std: 1.
        assert_eq!(prior_tension(0.0, 1.0, &prior), 1.0);
        assert_eq!(prior_tension(0.3, 0.0, &prior), 1.0);
        // Very precise data far from the prior: S → |m − m_p| / σ_p.
        let s = prior_tension(3.0, 1e-4, &prior);
        assert!((s - 3.0).abs() < 1e-3, "{s}");
    }
}
