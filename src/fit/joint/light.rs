//! The light's prior: the detector's light (from the highlights) is a measurement with its own
//! standard error, so the joint fit sees it as a Gaussian prior on the light's two angles
//! ([`LightFit::Prior`]), or holds it, or leaves it free; after the fit, how far the shading
//! pulled it from the detector's ([`LightPrior::pull`]). Combining the shading's light with the
//! detector's and refitting there is a phase of the session ([`crate::fit::joint::combine`]).

use super::settings::{LightFit, Setup};
use crate::fit::solver::{Fit, Prior};
use crate::formats::fit::LightPull;
use crate::model::{idx, LightAngles, N_PARAMS};

/// A pull of the light beyond this many standard errors gets a note.
pub const PULL_WARN: f64 = 3.0;

/// Floor on the light prior's width (radians): the detector's modelling error that its own
/// statistics do not see.
pub(crate) const LIGHT_PRIOR_FLOOR: f64 = crate::detect::LIGHT_FLOOR;

/// The detector's light as a prior on the light's two angles (none when it is held or free).
pub(crate) struct LightPrior {
    pub(crate) detector: Option<LightAngles>,
    /// The prior's width (radians).
    pub(crate) std: Option<f64>,
    pub(crate) priors: Vec<Prior>,
}

impl LightPrior {
    pub(crate) fn of(setup: &Setup, status: &mut [String; N_PARAMS]) -> LightPrior {
        let hold_light = setup.settings.light_fit == LightFit::Hold;
        // The detector's light as a prior on the two angles: isotropic with the detector's standard
        // error (floored), so the azimuth's is that over cos(elevation).
        let detector = setup
            .measured
            .light
            .map(|l| LightAngles::from_direction(&l));
        let light_prior_std = match (setup.settings.light_fit, detector, setup.measured.light_std) {
            (LightFit::Prior, Some(_), Some(s)) if s.is_finite() => Some(s.max(LIGHT_PRIOR_FLOOR)),
            _ => None,
        };
        let light_priors: Vec<Prior> = match (light_prior_std, detector) {
            (Some(s), Some(d)) => vec![
                Prior {
                    index: idx::AZIMUTH,
                    mean: d.azimuth,
                    std: s / d.elevation.cos().abs().max(1e-3),
                },
                Prior {
                    index: idx::ELEVATION,
                    mean: d.elevation,
                    std: s,
                },
            ],
            _ => vec![],
        };
        if let Some(s) = light_prior_std {
            let what = format!("prior: the detector's ± {:.4}°", s.to_degrees());
            status[idx::AZIMUTH] = what.clone();
            status[idx::ELEVATION] = what;
        }
        if hold_light {
            let why = if setup.settings.start_light.is_some() {
                "fixed: as given"
            } else if setup.measured.light.is_some() {
                "fixed: from the detector"
            } else {
                "fixed: from the shading"
            };
            status[idx::AZIMUTH] = why.into();
            status[idx::ELEVATION] = why.into();
        }
        LightPrior {
            detector,
            std: light_prior_std,
            priors: light_priors,
        }
    }

    /// How far the shading pulled the light from the detector's, in the detector's errors.
    pub(crate) fn pull(
        &self,
        setup: &Setup,
        fit: &Fit,
        light_free: bool,
        notes: &mut Vec<String>,
    ) -> Option<LightPull> {
        let (detector, light_prior_std) = (self.detector, self.std);
        let light_pull = match (detector, setup.measured.light_std) {
            (Some(d), Some(s)) if light_free && s > 0.0 => {
                let moved = fit.params.light.direction().angle(&d.direction());
                Some(LightPull {
                    moved_deg: moved.to_degrees(),
                    detector_std_deg: s.to_degrees(),
                    prior_std_deg: light_prior_std.map(f64::to_degrees),
                    pull: moved / light_prior_std.unwrap_or(s),
                })
            }
            _ => None,
        };
        if let Some(lp) = &light_pull {
            if lp.pull > PULL_WARN {
                notes.push(format!(
                    "the shading pulls the light {:.3}° from the highlights' estimate ({:.1} times its ± {:.4}°): the model does not describe the shading fully, or the outlines the highlights' light rests on are off{}",
                    lp.moved_deg,
                    lp.pull,
                    lp.prior_std_deg.unwrap_or(lp.detector_std_deg),
                    if light_prior_std.is_some() {
                        ""
                    } else {
                        "; σ0 moves with the light — without --free-light the detector's light is a prior"
                    }
                ));
            }
        }
        light_pull
    }
}
