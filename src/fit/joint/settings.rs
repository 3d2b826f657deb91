//! What the joint fit is told: the user's settings ([`Settings`], the one settings type of a
//! fit: `solve::Options` holds one, the command line maps onto it once), what the photos and the
//! detector measured ([`Measured`]), and both with what one (re)fit changes ([`Setup`]: the
//! extensions in force, the reduction, a warm start, whether the checks run).

use crate::model::{idx, LightAngles, Model, Params, N_PARAMS};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Default prior on η (a typical wax, soap or resin).
pub(crate) const ETA_PRIOR: (f64, f64) = (1.45, 0.05);

/// Roughness held when the data cannot determine it.
pub(crate) const ALPHA_PRIOR: f64 = 0.1;

/// How many residuals the solver sees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reduction {
    /// The coarsest level whose predicted shifts stay below [`crate::fit::joint::reduction::SHIFT_LIMIT`] std or tolerance.
    Auto,
    /// Every pixel.
    None,
    /// Cells of this many × 0.25°.
    Factor(u32),
}

/// Which model extensions are on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Extensions {
    pub sigma_exponent: bool,
    pub albedo_curvature: bool,
    /// The blur kernel as two Gaussians ([`crate::model::mixture`]).
    #[serde(default)]
    pub two_gaussian: bool,
}

impl Extensions {
    pub fn any(&self) -> bool {
        self.sigma_exponent || self.albedo_curvature || self.two_gaussian
    }

    /// The extensions of a fit: those whose parameters were free.
    pub(crate) fn of_fit(free: &[bool; N_PARAMS]) -> Extensions {
        Extensions {
            sigma_exponent: free[idx::SIGMA_EXPONENT],
            albedo_curvature: free[idx::ALBEDO_CURVATURE],
            two_gaussian: free[idx::KERNEL_WEIGHT],
        }
    }

    pub fn name(&self) -> String {
        let parts: Vec<&str> = [
            (self.two_gaussian, "two-gaussian"),
            (self.sigma_exponent, "sigma-exponent"),
            (self.albedo_curvature, "albedo-curvature"),
        ]
        .iter()
        .filter(|p| p.0)
        .map(|p| p.1)
        .collect();
        if parts.is_empty() {
            "plain".into()
        } else {
            parts.join("+")
        }
    }
}

/// How the joint fit treats the light direction.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LightFit {
    /// The detector's light is a measurement: it enters as a Gaussian prior (its own standard
    /// error on each angle, widened by [`crate::fit::joint::light::LIGHT_PRIOR_FLOOR`]), and the shading may move it only as
    /// far as the data support against that.
    #[default]
    Prior,
    /// The light refined by the shading alone (no prior): the behaviour before the prior.
    Free,
    /// The light held at the detector's estimate (or the given start).
    Hold,
}

impl LightFit {
    pub fn name(&self) -> &'static str {
        match self {
            LightFit::Prior => "prior",
            LightFit::Free => "free",
            LightFit::Hold => "hold",
        }
    }
}

/// Model extensions: the default, none, the ones named, or chosen by held-out error.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ExtensionChoice {
    /// The albedo's curvature dependence where 3 or more radii are fitted, plain otherwise: what
    /// lowered the extrapolation to a held-out radius on every physically based session without
    /// hurting the own-model stress sessions (docs/uncertainty.md, "Three physically based
    /// sessions").
    #[default]
    Default,
    None,
    On(Extensions),
    Auto,
}

/// Distinct radii the default extension needs (b is an exponential in 1/r: two radii fix the
/// albedo and b, a third is what tests them).
pub(crate) const DEFAULT_EXTENSION_RADII: usize = 3;

/// How the jackknife's leave-one-radius-out estimates are taken.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum JackknifeMethod {
    /// Newton steps from the full fit's normal equations, one pass over the observations
    /// ([`super::jackknife::jackknife_linear`]).
    #[default]
    Linear,
    /// The fit repeated without each radius ([`super::jackknife::jackknife_refit`]): the check
    /// of the linear estimates, several times the cost.
    Refit,
    /// None: the standard errors are the formal ones.
    Off,
}

impl JackknifeMethod {
    pub fn name(&self) -> &'static str {
        match self {
            JackknifeMethod::Linear => "linear",
            JackknifeMethod::Refit => "refit",
            JackknifeMethod::Off => "off",
        }
    }
}

/// The fit's settings, as the user chose them (the defaults: [`Settings::default`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Prior on η (mean, std).
    pub eta_prior: (f64, f64),
    /// The light's irradiance in the photos' radiance units: the specular scale is then known
    /// (ks = E) and η is fitted.
    pub irradiance: Option<f64>,
    pub reduction: Reduction,
    /// The Huber loss (else plain least squares).
    pub robust: bool,
    pub extensions: ExtensionChoice,
    /// Start values given by the user (instead of those from the data).
    pub start_sigma0: Option<[f64; 3]>,
    pub start_light: Option<LightAngles>,
    /// How the fit treats the detector's light (prior, free, held).
    pub light_fit: LightFit,
    /// The leave-one-radius-out jackknife: the spread of the estimates without each radius joins
    /// every parameter's standard error, and each left-out radius is predicted (needs 3 or more
    /// radii).
    pub jackknife: JackknifeMethod,
    /// Blur the irradiance transmitted into the medium (entry-side Fresnel) rather than the bare
    /// clamped cosine (docs/model.md; off by default, docs/uncertainty.md says why).
    pub entry_transmission: bool,
    /// The CDRF from its table (the default) or the closed form (docs/model.md, "The tabulated
    /// CDRF").
    pub tabulated: bool,
    /// Run the paper's baseline beside a joint fit.
    pub baseline: bool,
}

impl Default for Settings {
    fn default() -> Settings {
        Settings {
            eta_prior: ETA_PRIOR,
            irradiance: None,
            reduction: Reduction::Auto,
            robust: true,
            extensions: ExtensionChoice::Default,
            start_sigma0: None,
            start_light: None,
            light_fit: LightFit::Prior,
            jackknife: JackknifeMethod::Linear,
            entry_transmission: false,
            tabulated: true,
            baseline: false,
        }
    }
}

impl Settings {
    /// The radiance model these settings fit.
    pub fn model(&self) -> Model {
        Model {
            entry_fresnel: self.entry_transmission,
            tabulated: self.tabulated,
            ..Model::default()
        }
    }
}

/// What the photos and the detector measured, beside the user's settings.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Measured {
    /// The detector's light (pooling is done around it), or `None`.
    pub light: Option<Vector3<f64>>,
    /// The detector's standard error of its light (radians, the largest axis): the width of the
    /// light's prior under [`LightFit::Prior`].
    pub light_std: Option<f64>,
    /// Angular radius of the highlight (pixels within it are kept unpooled).
    pub highlight_radius: Option<f64>,
    /// The detector's roughness, when it fitted a lobe.
    pub alpha: Option<f64>,
    /// Its standard error, from the lobe fits (formal, the diffuse trend's and the clipping's).
    pub alpha_std: Option<f64>,
    /// The photos' dark floor is unknown (lit surroundings, none in session.json) and all share
    /// one exposure: a constant per channel is fitted with the rest
    /// ([`crate::fit::solver::fit_with_floor`]; [`crate::fit::solver::Fit::floor`] holds it).
    pub fit_floor: bool,
    /// Radiance units → pixel values (full scale 1), for what is said in pixel values.
    pub pixel_scale: f64,
}

/// Everything one (re)fit is told: the settings, what was measured, and what the refit changes.
#[derive(Clone, Debug)]
pub struct Setup {
    pub settings: Settings,
    pub measured: Measured,
    /// The reduction of this fit (a refit's may be coarser than the settings').
    pub reduction: Reduction,
    /// The extensions this fit frees (the settings' choice resolved).
    pub extensions: Extensions,
    /// A previous fit of the same scene to start from: the start-value search and the diffuse
    /// stage are skipped (used to refit subsets, e.g. for held-out errors).
    pub warm: Option<Params>,
    /// Run the checks whose refits only feed notes and statuses (σ0 against the limits of what
    /// the data resolve); off for refits whose parameters alone are used (the jackknife's, the
    /// model choice's).
    pub checks: bool,
}

impl Setup {
    /// A fit of `extensions` at `reduction`, from the data's start values, with its checks.
    pub fn new(
        settings: &Settings,
        measured: &Measured,
        extensions: Extensions,
        reduction: Reduction,
    ) -> Setup {
        Setup {
            settings: *settings,
            measured: *measured,
            reduction,
            extensions,
            warm: None,
            checks: true,
        }
    }

    /// A refit whose parameters alone are used: from `warm`, without the checks.
    pub(crate) fn refit(mut self, warm: Params) -> Setup {
        self.warm = Some(warm);
        self.checks = false;
        self
    }

    /// The radiance model this fit fits.
    pub fn model(&self) -> Model {
        self.settings.model()
    }
}
