//! The medium fit (`solve --model medium`, docs/medium.md "The medium fit"): σa and σs′ per
//! channel and η from the spheres' pixels, by diffusion solved in each sphere
//! ([`crate::model::sphere_diffusion`], beam sources, level corrected) entering and leaving
//! through the boundary the highlights measured ([`crate::model::boundary`], GGX of the lobe's
//! roughness). The light is held where the joint fit put it, and η's prior is the joint fit's
//! η with its error.
//!
//! Pixels near the highlight (half vector within 25° of the normal) and the rim (φ beyond 75°)
//! are left out: the lobe and the rough boundary's grazing exit rule them, and neither is in the
//! diffusion model. The absolute level needs the light's irradiance; without it one irradiance
//! per channel is fitted too, and σa and σs′ rest on the profile's shape alone (said in a note).
//!
//! Errors: σ²(JᵀJ)⁻¹ with σ² the residuals' mean square (not below 1), and with three radii or
//! more a leave-one-radius-out jackknife by one Gauss–Newton step from the fit (widened for its
//! few estimates, [`crate::stats::jackknife_widening`]); each parameter's std is the larger, and
//! the model's own error measured on physically based renders ([`MODEL_ERROR`]) is added to it.

mod errors;
mod problem;

use crate::fit::observe::SphereData;
use crate::model::dipole::Medium;
use levenberg_marquardt::LevenbergMarquardt;
use nalgebra::{DMatrix, DVector, Vector3};
use problem::{physical, predicted, profiles, Problem};
use std::time::Instant;

pub use errors::{Derived, ModelError, PerChannel, MODEL_ERROR};

/// What the medium fit is given besides the pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setup {
    /// The light, toward it, in the frame of the observations' normals.
    pub light: Vector3<f64>,
    /// η's prior: the joint fit's η and its std.
    pub eta_prior: (f64, f64),
    /// The boundary's GGX roughness (the lobe's α; 0: smooth).
    pub alpha: f64,
    /// The light's irradiance in the photos' units, when known.
    pub irradiance: Option<f64>,
    /// The largest sphere's radius (mm): it bounds σs′ (`MAX_SIGMA_T_RADIUS`).
    pub largest_radius: f64,
}

/// One pixel and channel: where it lies and what it saw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Px {
    /// n·l and n·v.
    pub cos_theta: f64,
    pub cos_phi: f64,
    pub radiance: f64,
    /// 1/σ of its noise.
    pub weight: f64,
}

/// Every sphere of one radius: its pixels per channel.
#[derive(Clone, Debug, PartialEq)]
pub struct Radius {
    pub radius_mm: f64,
    pub pixels: [Vec<Px>; 3],
}

/// Whether a pixel is fitted: its half vector more than 25° from the normal (out of the lobe)
/// and φ within 75° (off the rim).
pub fn fitted(n: &Vector3<f64>, v: &Vector3<f64>, light: &Vector3<f64>) -> bool {
    let h = (light + v).normalize();
    n.dot(&h) <= 25f64.to_radians().cos() && n.dot(v) >= 75f64.to_radians().cos()
}

/// The spheres' fitted pixels, pooled by radius (in increasing radius).
pub fn pixels(spheres: &[&SphereData], light: &Vector3<f64>) -> Vec<Radius> {
    let mut radii: Vec<Radius> = Vec::new();
    for s in spheres {
        let at = match radii
            .iter()
            .position(|r| (r.radius_mm - s.radius_mm).abs() < 1e-9)
        {
            Some(i) => i,
            None => {
                radii.push(Radius {
                    radius_mm: s.radius_mm,
                    pixels: [vec![], vec![], vec![]],
                });
                radii.len() - 1
            }
        };
        for o in &s.obs {
            let (n, v) = (o.geometry.normal, o.geometry.view);
            if !fitted(&n, &v, light) {
                continue;
            }
            for c in 0..3 {
                if o.weight[c] > 0.0 {
                    radii[at].pixels[c].push(Px {
                        cos_theta: n.dot(light),
                        cos_phi: n.dot(&v),
                        radiance: o.radiance[c],
                        weight: o.weight[c],
                    });
                }
            }
        }
    }
    radii.retain(|r| r.pixels.iter().all(|p| !p.is_empty()));
    radii.sort_by(|a, b| a.radius_mm.total_cmp(&b.radius_mm));
    radii
}

/// The medium fit's result.
#[derive(Clone, Debug, PartialEq)]
pub struct MediumFit {
    pub media: [Medium; 3],
    /// The irradiance per channel: the given one, or fitted.
    pub irradiance: [f64; 3],
    pub irradiance_given: bool,
    /// The boundary's roughness used.
    pub alpha: f64,
    /// u = (ln σa ×3, ln σs′ ×3, ln(η − 1), [ln E ×3]) and its covariance (the stated one: the
    /// statistical errors and the model's own).
    pub u: DVector<f64>,
    pub covariance: DMatrix<f64>,
    /// Per u: the formal std and the jackknife's (None under three radii).
    pub std_formal: Vec<f64>,
    pub std_jackknife: Option<Vec<f64>>,
    /// The residuals' RMS in units of the noise (η's prior row left out).
    pub residual_over_noise: f64,
    pub pixels: usize,
    pub radii: Vec<f64>,
    /// Profiles computed, and the solver's evaluations.
    pub profiles: usize,
    pub evaluations: usize,
    pub converged: bool,
    /// Parameters that ended at the edge of their range (σa_r, σs′_g, η, …).
    pub at_bounds: Vec<String>,
    pub seconds: f64,
}

/// The start: the diffusion length 1/σtr from the joint fit's blur length σ0 (on the
/// physically based renders they agree within 20%), and the reduced albedo α′ from the level:
/// on the largest sphere, the α′ of [`START_ALBEDOS`] whose prediction needs the least scale
/// (weighted least squares) to meet the pixels. Without the irradiance, α′ = 0.95 and the scale
/// is E's start. One profile per candidate and channel.
pub fn start(radii: &[Radius], setup: &Setup, sigma0_mm: [f64; 3]) -> Vec<f64> {
    let eta = setup.eta_prior.0.clamp(1.1, 2.4);
    let largest = radii.last().expect("a radius to fit");
    let boundary = crate::model::boundary::Boundary::rough(eta, setup.alpha);
    let medium = |a: f64, c: usize| {
        let sigma_tr = 1.0 / sigma0_mm[c].clamp(0.05, 50.0);
        let sigma_t = sigma_tr / (3.0 * (1.0 - a)).sqrt();
        Medium {
            sigma_a: (1.0 - a) * sigma_t,
            sigma_s_reduced: a * sigma_t,
            eta,
        }
    };
    // The weighted least-squares scale that brings (α′, c)'s prediction to the pixels.
    let scale = |a: f64, c: usize| {
        let m = medium(a, c);
        let t = crate::model::sphere_diffusion::SphereDiffusion::through(
            &m,
            largest.radius_mm,
            &boundary,
        )
        .tabulate();
        let (mut lp, mut pp) = (0.0, 0.0);
        for px in &largest.pixels[c] {
            let p = setup.irradiance.unwrap_or(1.0)
                * boundary.exit_law(px.cos_phi)
                * t.at(px.cos_theta);
            let w2 = px.weight * px.weight;
            lp += px.radiance * p * w2;
            pp += p * p * w2;
        }
        lp / pp
    };
    let mut u = vec![0.0; 7];
    u[6] = (eta - 1.0).ln();
    let mut e = [0.0; 3];
    for c in 0..3 {
        let a = match setup.irradiance {
            Some(_) => {
                use rayon::prelude::*;
                let scales: Vec<f64> = START_ALBEDOS.par_iter().map(|&a| scale(a, c)).collect();
                START_ALBEDOS
                    .iter()
                    .zip(scales)
                    .filter(|(_, s)| s.is_finite() && *s > 0.0)
                    .min_by(|x, y| x.1.ln().abs().total_cmp(&y.1.ln().abs()))
                    .map_or(0.95, |(a, _)| *a)
            }
            None => 0.95,
        };
        let m = medium(a, c);
        u[c] = m.sigma_a.ln();
        u[3 + c] = m.sigma_s_reduced.ln();
        if setup.irradiance.is_none() {
            e[c] = scale(a, c).max(1e-12).ln();
        }
    }
    if setup.irradiance.is_none() {
        u.extend(e);
    }
    u
}

/// The reduced albedos [`start`] tries.
pub const START_ALBEDOS: [f64; 8] = [0.6, 0.8, 0.9, 0.95, 0.975, 0.99, 0.995, 0.999];

/// Fit the medium to `radii`'s pixels from `start` (u as [`MediumFit::u`]).
pub fn fit(radii: &[Radius], setup: &Setup, start: &[f64]) -> MediumFit {
    let t0 = Instant::now();
    let problem = Problem::new(radii, setup, DVector::from_column_slice(start));
    let (problem, report) = LevenbergMarquardt::new()
        .with_ftol(1e-8)
        .with_xtol(1e-8)
        .with_patience(30)
        .with_stepbound(1.0)
        .minimize(problem);
    let p = physical(problem.u.as_slice(), setup);
    let errors = errors::of(&problem);
    let profiles = problem
        .evaluations
        .load(std::sync::atomic::Ordering::Relaxed)
        + errors.profiles;
    MediumFit {
        media: p.media,
        irradiance: p.irradiance,
        irradiance_given: setup.irradiance.is_some(),
        alpha: setup.alpha,
        u: problem.u.clone(),
        covariance: errors.covariance,
        std_formal: errors.std_formal,
        std_jackknife: errors.std_jackknife,
        residual_over_noise: errors.residual_over_noise,
        pixels: problem.pixel_rows(),
        radii: radii.iter().map(|r| r.radius_mm).collect(),
        profiles,
        evaluations: report.number_of_evaluations,
        converged: report.termination.was_successful()
            && p.media.iter().all(|m| m.sigma_a.is_finite()),
        at_bounds: problem::at_bounds(&p, setup),
        seconds: t0.elapsed().as_secs_f64(),
    }
}

/// The fitted medium's prediction of `radius`'s pixels, per channel (radiance units).
pub fn predict(f: &MediumFit, setup: &Setup, radius: &Radius) -> [Vec<f64>; 3] {
    let p = physical(f.u.as_slice(), setup);
    let t = profiles(std::slice::from_ref(radius), &p, &[0, 1, 2]);
    std::array::from_fn(|c| {
        let table = t[0][c].as_ref().expect("every channel's profile");
        radius.pixels[c]
            .iter()
            .map(|px| {
                predicted(
                    p.irradiance[c],
                    p.boundary.exit_law(px.cos_phi),
                    table.at(px.cos_theta),
                )
            })
            .collect()
    })
}
