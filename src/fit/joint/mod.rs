//! The joint fit: σ0, albedo (per channel), the light direction, the specular lobe (ks, α) and,
//! when the light's irradiance is known, η — from every sphere at once. One file per phase:
//!
//! - [`settings`]: what the fit is told (the user's [`Settings`], what was [`Measured`], one
//!   refit's [`Setup`]);
//! - [`start`]: start values from the data — the light from the detector (or, without a
//!   highlight, from the shading), σ0 and the albedo by a grid search
//!   ([`crate::fit::sigma_grid`]), α from the detector's lobe, ks by linear least squares on the
//!   highlight;
//! - [`light`]: the detector's light as a prior on the light's angles, and how far the shading
//!   pulled it;
//! - [`stages`]: the diffuse fit (σ0, albedo, light) on 2° cells without the highlight, then
//!   the full fit with the Huber loss, each a Levenberg–Marquardt fit ([`crate::fit::solver`]);
//! - [`reduction`]: the choice of reduction level ([`crate::fit::reduce`]): the coarsest (θ, φ)
//!   cells whose predicted parameter shifts all stay below [`SHIFT_LIMIT`] standard errors or
//!   below a fixed tolerance ([`crate::fit::reduce::tolerance`]), then by the same test the
//!   largest pixel blocks for the highlight;
//! - [`identify`]: parameters whose standard error is not finite or larger than their plausible
//!   range are held at their prior (η, α) or switched off (ks, the extensions) and the fit
//!   repeated; σ0 beyond what the data resolve is a bound;
//! - [`checks`]: what the result's residuals and geometry say about it, as notes; [`regions`]:
//!   where the residuals lie when they are above the noise;
//! - [`choice`]: the extensions chosen by held-out error; [`jackknife`]: the leave-one-radius-out
//!   spread; [`baseline`]: the paper's procedure beside the fit;
//! - [`intensity`]: one lamp intensity per photo and channel, fitted where a session with one
//!   light per photo gives none;
//! - [`shading_light`]: the light the shading alone fits, and its spread over the spheres'
//!   regions; [`combine`]: that light and the detector's combined by their covariances;
//!   [`hold`]: the fit with the light held at the combination;
//! - [`newton`]: Newton steps from a fit to the fit of a changed problem (a radius left out, the
//!   light held), for the jackknife and the light's hold;
//! - [`session`]: the fit with all of that around it, as `solve` runs it.

pub mod baseline;
pub mod checks;
pub mod choice;
pub mod combine;
pub mod hold;
pub mod identify;
pub mod intensity;
pub mod jackknife;
pub mod light;
pub mod newton;
pub mod reduction;
pub mod regions;
pub mod session;
pub mod settings;
pub mod shading_light;
pub mod stages;
pub mod start;

pub use jackknife::{jackknife_linear, jackknife_refit, Jackknife};
pub use light::PULL_WARN;
pub(crate) use reduction::SHIFT_LIMIT;
pub use session::{fit_session, Session};
pub use settings::{
    ExtensionChoice, Extensions, JackknifeMethod, LightFit, Measured, Reduction, Settings, Setup,
};
pub(crate) use stages::HUBER_K;
pub use stages::{fit_joint, JointFit};
