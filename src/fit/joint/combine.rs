//! The detector's light and the shading's, combined by their covariances ([`combine_lights`]):
//! the detector's (from the highlights and the outlines, with the arcs' jackknife) is one
//! measurement, the shading's alone ([`super::shading_light`], its regions' spread included) the
//! other; the light is their inverse-covariance mean, each winning where its error is the
//! smaller, and where they disagree beyond both errors the combined error is widened until it
//! covers the disagreement (docs/uncertainty.md, "The detector's light and the shading's").

use super::hold::hold_at;
use super::light::LIGHT_PRIOR_FLOOR;
use super::settings::{Extensions, LightFit, Measured, Settings};
use super::shading_light::{shading_light, ShadingLight};
use super::stages::JointFit;
use crate::fit::observe::SphereData;
use crate::fit::solver::from_unbounded;
use crate::model::{idx, LightAngles, N_PARAMS};
use nalgebra::{Matrix2, Vector2};

/// The fit that stands after the combination, the settings it ran with, and the light's
/// systematic.
pub(crate) struct Held {
    pub fit: JointFit,
    pub settings: Settings,
    /// Per parameter, the light's error carried into it (0 where none).
    pub light_shift: [f64; N_PARAMS],
    /// The light was moved to the combination and held there.
    pub combined: bool,
}

/// The two lights combined, in (azimuth, elevation) radians.
pub(crate) struct Combined {
    pub light: LightAngles,
    pub cov: Matrix2<f64>,
    /// The shading's light's error as the combination took it (radians, RMS of the two axes on
    /// the sphere of directions).
    pub shading_std: f64,
    /// χ² of the two lights' difference against the sum of their covariances (2 degrees of
    /// freedom), and the factor the combined covariance was widened by (χ²/2, at least 1).
    pub chi2: f64,
    pub widened: f64,
}

/// The inverse-covariance mean of the detector's light (isotropic, `detector_std` radians) and
/// the shading's ([`ShadingLight`]: its formal covariance plus its regions' jackknife, the latter
/// widened by the residuals' χ² per degree of freedom where that is above 1: a model that does
/// not describe the photos misplaces each region's light by more than the regions' spread shows;
/// plus its radii's jackknife).
/// In the tangent plane at the detector's light (azimuth × cos elevation, elevation): μ = μ_d +
/// D (D + S)⁻¹ (μ_s − μ_d), C = D − D (D + S)⁻¹ D, widened by χ²/2 where the difference's χ² (2
/// degrees of freedom) exceeds 2.
pub(crate) fn combine(
    detector: LightAngles,
    detector_std: f64,
    shading: &ShadingLight,
) -> Option<Combined> {
    let c = detector.elevation.cos().abs().max(1e-3);
    let t = Matrix2::new(c, 0.0, 0.0, 1.0);
    let d = Matrix2::identity() * detector_std.powi(2);
    let s = t * (shading.formal + shading.regions * shading.chi2_dof.max(1.0) + shading.radii) * t;
    let mut daz = shading.light.azimuth - detector.azimuth;
    daz -= (daz / std::f64::consts::TAU).round() * std::f64::consts::TAU;
    let diff = Vector2::new(daz * c, shading.light.elevation - detector.elevation);
    let sum_inv = (d + s).try_inverse()?;
    let chi2 = diff.dot(&(sum_inv * diff));
    let widened = (chi2 / 2.0).max(1.0);
    let mu = d * sum_inv * diff;
    let cov_t = (d - d * sum_inv * d) * widened;
    let t_inv = Matrix2::new(1.0 / c, 0.0, 0.0, 1.0);
    Some(Combined {
        light: LightAngles {
            azimuth: detector.azimuth + mu.x / c,
            elevation: detector.elevation + mu.y,
        },
        cov: t_inv * cov_t * t_inv,
        shading_std: (s.trace() / 2.0).sqrt(),
        chi2,
        widened,
    })
}

/// The light of the fit `first` (the detector's light its prior) settled: under
/// [`LightFit::Prior`] with the detector's light known, the shading's own light is measured
/// ([`shading_light`]) and combined with the detector's ([`combine`]); where the combination lies
/// more than half its error from the fitted light, the light is held there and the fit repeated
/// ([`hold_at`]), the combined covariance is the light's error, and it is carried into every
/// other parameter through how each follows the light ([`ShadingLight::follows`]), or, where
/// larger, the parameter's shift from the fit at the shading's light joins its std. A light held
/// from the start (`--hold-light`) keeps the detector's error on its two angles only.
pub(crate) fn combine_lights(
    settings: &Settings,
    measured: &Measured,
    fitted: &[&SphereData],
    ext: Extensions,
    first: JointFit,
    notes: &mut Vec<String>,
) -> Held {
    let mut held = Held {
        fit: first,
        settings: *settings,
        light_shift: [0.0; N_PARAMS],
        combined: false,
    };
    let (Some(dir), Some(d_std)) = (measured.light, measured.light_std) else {
        return held;
    };
    let detector = LightAngles::from_direction(&dir);
    if settings.light_fit == LightFit::Hold {
        if settings.start_light.is_none() {
            let el = detector.elevation;
            held.light_shift[idx::AZIMUTH] = d_std / el.cos().abs().max(1e-3);
            held.light_shift[idx::ELEVATION] = d_std;
        }
        return held;
    }
    if settings.light_fit != LightFit::Prior || !d_std.is_finite() {
        return held;
    }
    let d_std = d_std.max(LIGHT_PRIOR_FLOOR);
    let Some(shading) = shading_light(&held.fit, fitted) else {
        return held;
    };
    let Some(comb) = combine(detector, d_std, &shading) else {
        return held;
    };
    let fitted_light = held.fit.fit.params.light.direction();
    let moved = comb.light.direction().angle(&fitted_light);
    let comb_std = comb.cov.symmetric_eigenvalues().min().max(0.0).sqrt()
        * comb.light.elevation.cos().abs().min(1.0);
    if moved <= 0.5 * comb_std.max(1e-12) {
        return held;
    }
    held.settings.light_fit = LightFit::Hold;
    held.settings.start_light = Some(comb.light);
    let before = held.fit.fit.params;
    held.fit = hold_at(
        &held.fit,
        comb.light,
        (&held.settings, measured, ext),
        fitted,
    );
    held.combined = true;
    // The light's systematic on each other parameter: the combined error carried through, or
    // the parameter's shift between the fit at the shading's light and the fit at the
    // combination, whichever is larger (either light may be the right one).
    held.light_shift = carried(&comb.cov, &shading, &held.fit);
    let (a, b) = (before.to_vec(), held.fit.fit.params.to_vec());
    for k in 0..N_PARAMS {
        if held.fit.fit.free[k] && k != idx::AZIMUTH && k != idx::ELEVATION {
            held.light_shift[k] = held.light_shift[k].max((a[k] - b[k]).abs());
        }
    }
    let ce = comb.light.elevation.cos().abs();
    let light_std = (comb.cov[(0, 0)] * ce * ce + comb.cov[(1, 1)]).sqrt() / 2f64.sqrt();
    let s0 = |p: &crate::model::Params| {
        (0..3)
            .map(|c| format!("{:.3}", p.material.sigma0_mm[c]))
            .collect::<Vec<_>>()
            .join(", ")
    };
    notes.push(format!(
        "the light combines the highlights' estimate (± {:.4}° per axis) and the shading's ({:.3}° from it, ± {:.4}° per axis with its regions' and radii's spread) by their errors: {:.3}° from the highlights' (± {:.4}° per axis){}; with the shading's light σ0 was {} mm",
        d_std.to_degrees(),
        dir.angle(&shading.light.direction()).to_degrees(),
        comb.shading_std.to_degrees(),
        comb.light.direction().angle(&dir).to_degrees(),
        light_std.to_degrees(),
        if comb.widened > 1.0 {
            format!(
                "; the two disagree by {:.1} of their joint errors, so its error is widened {:.1}× to cover both",
                comb.chi2.sqrt(),
                comb.widened.sqrt()
            )
        } else {
            String::new()
        },
        s0(&before)
    ));
    let why = format!(
        "combined: the detector's ± {:.4}° and the shading's ± {:.4}°",
        d_std.to_degrees(),
        comb.shading_std.to_degrees()
    );
    held.fit.status[idx::AZIMUTH] = why.clone();
    held.fit.status[idx::ELEVATION] = why;
    held
}

/// The light's covariance `cov` (azimuth, elevation) carried into each parameter of the held fit
/// `jf`: its own two angles' standard errors, and for every other parameter the standard error of
/// g·δ with g how it follows the light ([`ShadingLight::follows`], unbounded units, taken to
/// physical ones by d p / d u at the held fit).
fn carried(cov: &Matrix2<f64>, shading: &ShadingLight, jf: &JointFit) -> [f64; N_PARAMS] {
    let mut out = [0.0; N_PARAMS];
    out[idx::AZIMUTH] = cov[(0, 0)].max(0.0).sqrt();
    out[idx::ELEVATION] = cov[(1, 1)].max(0.0).sqrt();
    let dpdu = from_unbounded(&crate::fit::solver::to_unbounded(&jf.fit.params.to_vec())).1;
    for &(k, g) in &shading.follows {
        if jf.fit.free[k] {
            let g = Vector2::new(g[0], g[1]);
            out[k] = g.dot(&(cov * g)).max(0.0).sqrt() * dpdu[k].abs();
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shading's light, isotropic in the tangent plane at elevation 0.2 (the detector's).
    fn shading(light: LightAngles, std: f64) -> ShadingLight {
        let c = 0.2f64.cos();
        ShadingLight {
            light,
            // Isotropic on the sphere of directions: the azimuth's std is std / cos(elevation).
            formal: Matrix2::new((std / c).powi(2), 0.0, 0.0, std.powi(2)),
            regions: Matrix2::zeros(),
            radii: Matrix2::zeros(),
            chi2_dof: 1.0,
            follows: vec![],
        }
    }

    /// Two isotropic measurements combine as inverse-variance weights say, per axis: the mean
    /// w·μ_s + (1 − w)·μ_d with w = s_s⁻² / (s_d⁻² + s_s⁻²), and the variance
    /// 1 / (s_d⁻² + s_s⁻²); where they disagree by more than √2 of their joint errors per degree
    /// of freedom, the variance is widened by χ²/2.
    #[test]
    fn two_lights_combine_as_inverse_variance_weights() {
        let det = LightAngles {
            azimuth: 0.3,
            elevation: 0.2,
        };
        let (sd, ss): (f64, f64) = (0.002, 0.001);
        let w_s = ss.powi(-2) / (sd.powi(-2) + ss.powi(-2));
        let var = 1.0 / (sd.powi(-2) + ss.powi(-2));
        // Close (χ² < 2): no widening.
        let near = LightAngles {
            azimuth: 0.3 + 0.001,
            elevation: 0.2 - 0.001,
        };
        let c = combine(det, sd, &shading(near, ss)).unwrap();
        assert!((c.light.azimuth - (0.3 + w_s * 0.001)).abs() < 1e-12);
        assert!((c.light.elevation - (0.2 - w_s * 0.001)).abs() < 1e-12);
        assert!((c.cov[(1, 1)] - var).abs() < 1e-18);
        assert!((c.cov[(0, 0)] - var / 0.2f64.cos().powi(2)).abs() < 1e-16);
        assert_eq!(c.widened, 1.0);
        // Far apart in elevation (5 joint errors): widened by χ²/2 = 12.5.
        let joint = (sd * sd + ss * ss).sqrt();
        let far = LightAngles {
            azimuth: 0.3,
            elevation: 0.2 + 5.0 * joint,
        };
        let c = combine(det, sd, &shading(far, ss)).unwrap();
        assert!((c.chi2 - 25.0).abs() < 1e-9, "{}", c.chi2);
        assert!((c.widened - 12.5).abs() < 1e-9);
        assert!((c.light.elevation - (0.2 + w_s * 5.0 * joint)).abs() < 1e-12);
        assert!((c.cov[(1, 1)] - 12.5 * var).abs() < 1e-16);
    }
}
