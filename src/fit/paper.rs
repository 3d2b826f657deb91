//! The source paper's procedure (Okamoto et al.), as a baseline in the same binary: the light taken
//! as given (here: the detector's), the specular peak masked, the exit Fresnel transmission divided
//! out with an assumed η, and σ fitted per radius (with a scale per radius), so that σ0 = σ · r is
//! one number per sphere size. The per-radius values are then combined by an inverse-variance
//! weighted mean whose standard error is widened by the scatter between radii (Birge ratio) when
//! they disagree more than their errors allow.

use crate::fit::observe::SphereData;
use crate::fit::predict::{predict, Prediction};
use crate::fit::reduce::Pooled;
use crate::fit::sigma_grid::diffuse_start;
use crate::fit::solver::{self, Obs};
use crate::formats::fit::RadiusFit;
use crate::model::fresnel;
use crate::model::{idx, LightAngles, Model, Params, N_PARAMS};
use nalgebra::Vector3;

/// Pixels whose normal lies within this angle of the half vector are masked (at least; twice the
/// detector's highlight radius when that is larger).
pub(crate) const MASK_DEG: f64 = 10.0;
/// Cell width of the per-radius fits (factor of 0.25°): 1°.
pub(crate) const FACTOR: u32 = 4;

/// The baseline's result.
#[derive(Clone, Debug)]
pub struct PaperFit {
    pub per_radius: Vec<RadiusFit>,
    /// Combined over radii.
    pub params: Params,
    pub std: [f64; N_PARAMS],
    pub mask_deg: f64,
    pub eta: f64,
    pub converged: bool,
}

impl PaperFit {
    /// The parameters of one radius's own fit (for its predictions).
    pub fn params_for(&self, radius_mm: f64) -> Params {
        let mut p = self.params;
        if let Some(r) = self
            .per_radius
            .iter()
            .find(|r| (r.radius_mm - radius_mm).abs() < 1e-9)
        {
            p.material.sigma0_mm = r.sigma0_mm;
            p.material.albedo = r.albedo;
        }
        p
    }

    /// Predict a sphere with its radius's fit (a · T(φ; η) · f(θ; σ)).
    pub fn predict(&self, s: &SphereData, max_pixels: usize) -> Prediction {
        predict(
            &predicting_model(),
            &self.params_for(s.radius_mm),
            s,
            [0.0; 3],
            max_pixels,
        )
    }
}

/// The model that predicts photos from the procedure's parameters: the exit transmission the
/// procedure divided out multiplied back, and no entry transmission (the paper has none).
pub(crate) fn predicting_model() -> Model {
    Model {
        entry_fresnel: false,
        ..Model::default()
    }
}

/// Run the baseline. `light` is required (the paper assumed it known).
pub fn fit(
    spheres: &[&SphereData],
    light: &Vector3<f64>,
    highlight_radius: Option<f64>,
    eta: f64,
) -> PaperFit {
    let mask = (2.0 * highlight_radius.unwrap_or(0.0)).max(MASK_DEG.to_radians());
    let model = Model {
        exit_fresnel: false,
        entry_fresnel: false,
        ..Model::default()
    };
    let angles = LightAngles::from_direction(light);
    let mut radii = crate::fit::observe::distinct_radii(spheres);
    radii.reverse();
    let mut per_radius = vec![];
    let mut converged = true;
    for &r in &radii {
        let group: Vec<&&SphereData> = spheres
            .iter()
            .filter(|s| (s.radius_mm - r).abs() < 1e-9)
            .collect();
        let mut pooled = Pooled::new(*light, 0.0);
        let mut pixels = 0;
        for (k, s) in group.iter().enumerate() {
            let obs: Vec<Obs> = s
                .obs
                .iter()
                .filter(|o| {
                    let h = (light + o.geometry.view).normalize();
                    o.geometry.normal.dot(&h).clamp(-1.0, 1.0).acos() >= mask
                })
                .map(|o| {
                    let t = fresnel::transmission(o.geometry.normal.dot(&o.geometry.view), eta);
                    Obs {
                        geometry: o.geometry,
                        radiance: o.radiance.map(|v| v / t),
                        weight: o.weight.map(|w| w * t),
                    }
                })
                .collect();
            pixels += obs.len();
            pooled.add_sphere(k, &obs, None);
        }
        let obs = pooled.observations(&pooled.merged(FACTOR));
        let (s0, a0) = diffuse_start(&model, &obs, &angles, eta, None);
        let start = Params::diffuse(s0, a0, eta, angles);
        let mut free = [false; N_PARAMS];
        free[..6].fill(true);
        let f = solver::fit(model, &obs, &start, free, &[]);
        converged &= f.converged;
        let m = &f.params.material;
        per_radius.push(RadiusFit {
            radius_mm: r,
            spheres: group.len(),
            pixels,
            sigma_rad: m.sigma0_mm.map(|s| s / r),
            sigma0_mm: m.sigma0_mm,
            sigma0_std: [f.std[0], f.std[1], f.std[2]],
            albedo: m.albedo,
            albedo_std: [f.std[3], f.std[4], f.std[5]],
            converged: f.converged,
        });
    }
    let mut std = [0.0; N_PARAMS];
    let mut sigma0 = [0.0; 3];
    let mut albedo = [0.0; 3];
    for c in 0..3 {
        let of = |f: &dyn Fn(&RadiusFit) -> (f64, f64)| {
            crate::stats::inverse_variance_mean(&per_radius.iter().map(f).collect::<Vec<_>>())
        };
        (sigma0[c], std[idx::SIGMA0 + c]) = of(&|r| (r.sigma0_mm[c], r.sigma0_std[c]));
        (albedo[c], std[idx::ALBEDO + c]) = of(&|r| (r.albedo[c], r.albedo_std[c]));
    }
    PaperFit {
        per_radius,
        params: Params::diffuse(sigma0, albedo, eta, angles),
        std,
        mask_deg: mask.to_degrees(),
        eta,
        converged,
    }
}
