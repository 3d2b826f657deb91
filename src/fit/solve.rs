//! `workbench solve <session>/`: from photos to a measured material, written as `fit.json`
//! (schema `workbench.fit/1`).
//!
//! Runs what is needed: the session is checked ([`crate::formats::session::inspect`]), `detections.json` is
//! reused when it is newer than every input (session.json, the photos, the intrinsics) and
//! describes the same photos, else detection runs ([`crate::detect`]); the photos are decoded and
//! sampled ([`crate::fit::observe`]); then the joint fit ([`crate::fit::joint`]) or the paper's baseline
//! ([`crate::fit::paper`]). Optional: model extensions chosen by held-out error, a held-out sphere's
//! prediction error, and figures.

use crate::camera::outline::Projection;
use crate::detect::{self, Detections};
use crate::error::{Error, Result};
use crate::fit::joint::{
    self, Extensions, JointFit, Level, LightFit, LightPull, Prediction, Reduction, Setup, Stage,
};
use crate::fit::observe::{self, SphereData};
use crate::fit::paper::{self, RadiusFit};
use crate::fit::solver;
use crate::formats::session::{self, LightMode, Session, SessionReport};
use crate::model::{idx, LightAngles, Model, Params, N_PARAMS, PARAM_NAMES};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::{Instant, SystemTime};

pub const SCHEMA: &str = "workbench.fit/1";
/// Pixels per sphere used for RMSE and predictions (every k-th beyond this).
pub const PREDICT_PIXELS: usize = 200_000;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    #[default]
    Joint,
    Paper,
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
pub const DEFAULT_EXTENSION_RADII: usize = 3;

#[derive(Clone, Debug)]
pub struct Options {
    pub session: PathBuf,
    /// Where fit.json goes (default: beside session.json).
    pub out: Option<PathBuf>,
    pub method: Method,
    pub holdout: Option<f64>,
    /// Prior on η (mean, std); `eta_prior_given` says whether the user chose it.
    pub eta_prior: (f64, f64),
    pub irradiance: Option<f64>,
    pub reduction: Reduction,
    pub robust: bool,
    pub extensions: ExtensionChoice,
    pub start_sigma0: Option<[f64; 3]>,
    pub start_light: Option<LightAngles>,
    /// Run detection even when detections.json is up to date.
    pub redetect: bool,
    /// How the fit treats the detector's light (prior, free, held).
    pub light_fit: LightFit,
    /// Refit with each radius left out in turn: the jackknife spread of every parameter joins its
    /// standard error, and each left-out radius is predicted (needs 3 or more radii).
    pub jackknife: bool,
    /// Blur the irradiance transmitted into the medium (entry-side Fresnel) rather than the bare
    /// clamped cosine (docs/model.md; off by default, docs/uncertainty.md says why).
    pub entry_transmission: bool,
    pub plots: Option<PathBuf>,
    /// Run the paper's baseline beside a joint fit (also when `plots` is set: its curves are drawn).
    pub baseline: bool,
    pub quiet: bool,
}

impl Options {
    pub fn new(session: impl Into<PathBuf>) -> Options {
        Options {
            session: session.into(),
            out: None,
            method: Method::Joint,
            holdout: None,
            eta_prior: joint::ETA_PRIOR,
            irradiance: None,
            reduction: Reduction::Auto,
            robust: true,
            extensions: ExtensionChoice::Default,
            start_sigma0: None,
            start_light: None,
            redetect: false,
            light_fit: LightFit::Prior,
            jackknife: true,
            entry_transmission: false,
            plots: None,
            baseline: false,
            quiet: true,
        }
    }
}

/// A specular lobe as written.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpecularJson {
    pub ks: f64,
    pub alpha: f64,
}

/// Standard errors, mirroring the values.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StdJson {
    pub sigma0_mm: [f64; 3],
    pub albedo: [f64; 3],
    pub eta: f64,
    pub specular: Option<SpecularJson>,
    /// Angular standard error of the light direction (degrees; from the two angles').
    pub light_deg: f64,
    pub sigma_exponent: Option<f64>,
    pub albedo_curvature: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kernel: Option<KernelJson>,
}

/// The two-Gaussian kernel: (1 − weight)·f(θ; σ) + weight·f(θ; ratio·σ).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct KernelJson {
    pub weight: f64,
    pub ratio: f64,
}

/// One parameter, flat.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParamJson {
    pub name: String,
    pub value: f64,
    /// The standard error stated: see `FitFile::std_source`.
    pub std: f64,
    /// From σ²(JᵀJ)⁻¹ (noise only, the model taken as exact).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub std_formal: Option<f64>,
    /// The leave-one-radius-out jackknife spread (model error across radii included).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub std_jackknife: Option<f64>,
    /// The factor `std` took because the data and the parameter's prior disagree (PDG scale
    /// factor, docs/uncertainty.md; absent when 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prior_tension: Option<f64>,
    /// "fitted", "fixed", "prior …", "off: …".
    pub status: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CorrelationJson {
    pub names: Vec<String>,
    pub matrix: Vec<Vec<f64>>,
}

/// A dark floor fitted with the material: pixel values (full scale 1) per channel.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DarkFloorJson {
    pub value: [f64; 3],
    pub std: [f64; 3],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SphereRmse {
    pub image: String,
    pub index: usize,
    pub radius_mm: f64,
    /// Pixels used by the fit (saturated and edge pixels left out) and how many were left out.
    pub pixels: usize,
    pub saturated: usize,
    pub edge: usize,
    /// Pixel noise σ per channel (radiance units), as measured.
    pub noise: [f64; 3],
    /// The photo's dark floor, subtracted before fitting (null: not measurable).
    pub floor: Option<[f64; 3]>,
    pub rmse: f64,
    pub rel_rmse: f64,
    pub lit_rel_rmse: f64,
    pub unlit_rel_rmse: f64,
    /// Held out of the fit.
    pub held_out: bool,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RmseJson {
    /// Over all spheres' pixels (radiance units), and relative to their RMS.
    pub overall: f64,
    pub relative: f64,
    pub spheres: Vec<SphereRmse>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HoldoutJson {
    pub radius_mm: f64,
    pub pixels: usize,
    pub rel_rmse: f64,
    pub lit_rel_rmse: f64,
    pub unlit_rel_rmse: f64,
}

/// The jackknife's refits pool pixels in cells of this many × 0.25° at least.
pub const JACKKNIFE_CELLS: u32 = 8;

/// The leave-one-radius-out refits of a joint fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JackknifeJson {
    /// The radii left out in turn (mm).
    pub radii: Vec<f64>,
    /// Each left-out radius predicted by the fit to the others.
    pub heldout: Vec<HoldoutJson>,
    /// Pixel-weighted mean of the held-out relative RMSE.
    pub heldout_rel_rmse: f64,
    /// Every refit converged.
    pub converged: bool,
    pub seconds: f64,
}

/// The jackknife spread of each parameter (0 where not free in the full fit) and its record.
pub struct Jackknife {
    pub std: [f64; N_PARAMS],
    pub json: JackknifeJson,
}

/// Radiance units → pixel values (full scale 1) for a floor shared by photos of one exposure.
fn pixel_scale(report: &SessionReport) -> f64 {
    report
        .images
        .first()
        .and_then(|i| i.exposure)
        .unwrap_or(1.0)
}

/// A sphere's data less a dark floor (radiance units), which becomes its `floor`.
fn less_floor(s: &SphereData, floor: [f64; 3]) -> SphereData {
    SphereData {
        obs: solver::less_floor(&s.obs, floor),
        floor: Some(floor),
        ..s.clone()
    }
}

/// The different radii among the spheres (mm), smallest first.
fn distinct_radii(spheres: &[&SphereData]) -> Vec<f64> {
    let mut radii: Vec<f64> = spheres.iter().map(|s| s.radius_mm).collect();
    radii.sort_by(f64::total_cmp);
    radii.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    radii
}

/// Leave-one-radius-out refits of a joint fit: the fit is repeated with every radius left out in
/// turn (warm-started from the full fit, on 2° cells or its own coarser level), and the spread of
/// the n refits gives each parameter's jackknife standard error √((n−1)/n · Σ(θᵢ − θ̄)²),
/// widened by t_{n−1}/2 (its ±2 covers 95.4% with n − 1 degrees of freedom). It sees what the
/// noise alone does not: a model that fits each radius a little differently. Each left-out
/// radius is predicted by the fit to the others. `None` with fewer than 3 radii.
pub fn jackknife(
    opts: &Options,
    l: &Loaded,
    fitted: &[&SphereData],
    jf: &JointFit,
    ext: Extensions,
) -> Option<Jackknife> {
    use rayon::prelude::*;
    let t = Instant::now();
    let mut radii = distinct_radii(fitted);
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
            let mut su = setup(opts, l, ext, reduction);
            su.warm = Some(jf.fit.params);
            let f = joint::fit_joint(&su, &train);
            let preds: Vec<Prediction> = test
                .iter()
                .map(|s| {
                    joint::predict(
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

/// Predictions of the spheres of one radius combined (pixel-weighted RMS of each error).
fn combine_predictions(radius_mm: f64, preds: &[Prediction]) -> HoldoutJson {
    let n: f64 = preds.iter().map(|p| p.pixels as f64).sum::<f64>().max(1.0);
    let comb = |f: fn(&Prediction) -> f64| {
        (preds
            .iter()
            .map(|p| f(p).powi(2) * p.pixels as f64)
            .sum::<f64>()
            / n)
            .sqrt()
    };
    HoldoutJson {
        radius_mm,
        pixels: preds.iter().map(|p| p.pixels).sum(),
        rel_rmse: comb(|p| p.rel_rmse),
        lit_rel_rmse: comb(|p| p.lit_rel_rmse),
        unlit_rel_rmse: comb(|p| p.unlit_rel_rmse),
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReductionJson {
    pub setting: String,
    pub pixels: usize,
    /// The level used (width 0: every pixel).
    pub chosen: Level,
    /// Levels tried, coarsest first (with `auto`).
    pub levels: Vec<Level>,
    pub shift_limit_std: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConvergenceJson {
    pub converged: bool,
    pub stages: Vec<Stage>,
    /// Channel residuals down-weighted by the Huber loss in the last round.
    pub downweighted: usize,
    pub robust_loss: Option<String>,
    /// χ²/dof of the joint fit against the measured pixel noise (its square root: the residuals
    /// over the noise); null for the paper's method and in older files.
    #[serde(default)]
    pub chi2_per_dof: Option<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    pub extensions: String,
    /// Mean over radii of the held-out relative RMSE (each radius left out in turn).
    pub heldout_rel_rmse: f64,
    pub converged: bool,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelChoice {
    pub candidates: Vec<Candidate>,
    pub chosen: String,
    /// `chosen`, as the extensions it names.
    #[serde(skip)]
    pub extensions: Extensions,
    pub reason: String,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Timings {
    pub inspect_s: f64,
    pub detect_s: f64,
    pub decode_s: f64,
    pub samples_s: f64,
    pub solve_s: f64,
    pub model_choice_s: f64,
    pub holdout_s: f64,
    /// The leave-one-radius-out refits.
    #[serde(default)]
    pub jackknife_s: f64,
    pub total_s: f64,
    /// The solve stage's phases (joint method), seconds.
    #[serde(default)]
    pub solve_phases: Vec<(String, f64)>,
}

/// `fit.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitFile {
    pub schema: String,
    pub method: Method,
    pub session: String,
    pub detections: String,
    pub projection: String,
    pub sigma0_mm: [f64; 3],
    pub albedo: [f64; 3],
    pub eta: f64,
    /// Null when no lobe was fitted.
    pub specular: Option<SpecularJson>,
    pub light_direction: [f64; 3],
    pub light_azimuth_deg: f64,
    pub light_elevation_deg: f64,
    /// Under `"light": "per-image"`: each photo's fitted light (`light_direction` is the first's).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub image_lights: Vec<ImageLightJson>,
    /// The extensions' values when on (see `model`), with the reference radius.
    pub sigma_exponent: Option<f64>,
    pub albedo_curvature: Option<f64>,
    /// The kernel's shape when it is two Gaussians (null: one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kernel: Option<KernelJson>,
    pub reference_radius_mm: f64,
    /// The diffuse term blurs the irradiance transmitted into the medium (entry-side Fresnel,
    /// docs/model.md); false for the paper's procedure and in files written before it.
    #[serde(default)]
    pub entry_transmission: bool,
    pub std: StdJson,
    /// What `std` is: "formal" (σ²(JᵀJ)⁻¹) or "larger of formal and jackknife" per parameter.
    #[serde(default)]
    pub std_source: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jackknife: Option<JackknifeJson>,
    /// How the light was treated: "prior" (the detector's light as a prior), "free", "hold", or
    /// "prior, then hold" (the shading pulled the light beyond PULL_WARN of its errors, so it was
    /// held at the detector's; `light_pull` says how far).
    #[serde(default)]
    pub light_fit: String,
    /// How far the fit moved the detector's light, in the prior's (or detector's) errors.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub light_pull: Option<LightPull>,
    /// The dark floor fitted with the material when no photo measured one (absent otherwise:
    /// each sphere's `floor` in `rmse` is the one subtracted).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dark_floor: Option<DarkFloorJson>,
    pub parameters: Vec<ParamJson>,
    pub correlation: CorrelationJson,
    pub rmse: RmseJson,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout: Option<HoldoutJson>,
    /// The paper's per-radius fits (method "paper").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub per_radius: Option<Vec<RadiusFit>>,
    /// The paper's baseline run beside a joint fit, for comparison (needs the detector's light).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub baseline: Option<BaselineJson>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_choice: Option<ModelChoice>,
    pub reduction: Option<ReductionJson>,
    pub convergence: ConvergenceJson,
    /// What was skipped or reused, and why.
    pub skipped: Vec<String>,
    pub notes: Vec<String>,
    pub timings: Timings,
    /// What decides the result besides the inputs (method, priors, reduction, …): a later run with
    /// the same options on unchanged inputs reuses this file.
    #[serde(default)]
    pub options: String,
}

/// The paper's baseline beside a joint fit: its assumptions and per-radius fits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BaselineJson {
    /// η divided out, the light taken from the detector (degrees), the mask around the peak.
    pub eta: f64,
    pub light_azimuth_deg: f64,
    pub light_elevation_deg: f64,
    pub mask_deg: f64,
    /// Combined over radii.
    pub sigma0_mm: [f64; 3],
    pub albedo: [f64; 3],
    pub per_radius: Vec<RadiusFit>,
    pub seconds: f64,
}

impl BaselineJson {
    /// The baseline's parameters for a radius: its own fit, or the combined one for a radius it
    /// did not fit (held out).
    pub fn params_for(&self, radius_mm: f64) -> Params {
        let light = LightAngles {
            azimuth: self.light_azimuth_deg.to_radians(),
            elevation: self.light_elevation_deg.to_radians(),
        };
        match self
            .per_radius
            .iter()
            .find(|r| (r.radius_mm - radius_mm).abs() < 1e-9)
        {
            Some(r) => Params::diffuse(r.sigma0_mm, r.albedo, self.eta, light),
            None => Params::diffuse(self.sigma0_mm, self.albedo, self.eta, light),
        }
    }
}

impl FitFile {
    /// The model the fit's parameters belong to: its reference radius, and the entry
    /// transmission unless the file predates it or is the paper's procedure.
    pub fn model(&self) -> Model {
        Model {
            reference_radius_mm: self.reference_radius_mm,
            entry_fresnel: self.entry_transmission,
            ..Model::default()
        }
    }

    /// The fitted parameters (all of them, as in `parameters`; a missing one reads 0).
    pub fn params(&self) -> Params {
        let mut v = [0.0; N_PARAMS];
        for p in &self.parameters {
            if let Some(k) = PARAM_NAMES.iter().position(|n| *n == p.name) {
                v[k] = p.value;
            }
        }
        Params::from_vec(&v)
    }

    /// The parameters that predict spheres of a radius: the fit's, or for the paper's method that
    /// radius's own fit (the combined one for a held-out radius).
    pub fn params_for(&self, radius_mm: f64) -> Params {
        let mut p = self.params();
        if let Some(r) = self
            .per_radius
            .as_ref()
            .and_then(|pr| pr.iter().find(|r| (r.radius_mm - radius_mm).abs() < 1e-9))
        {
            p.material.sigma0_mm = r.sigma0_mm;
            p.material.albedo = r.albedo;
        }
        p
    }

    /// The session this fit was solved on: the file it names, or session.json beside the fit
    /// when that has moved.
    pub fn session_path(&self, fit_path: &Path) -> Result<PathBuf> {
        let named = PathBuf::from(&self.session);
        let beside = fit_path
            .parent()
            .unwrap_or(Path::new("."))
            .join("session.json");
        if named.is_file() {
            Ok(named)
        } else if beside.is_file() {
            Ok(beside)
        } else {
            Err(Error::invalid(
                fit_path,
                format!(
                    "its session {} is gone and no session.json lies beside it",
                    self.session
                ),
            ))
        }
    }

    /// Check what was read: schema and parameter names.
    pub fn validate(&self, file: &Path) -> Result<()> {
        if self.schema != SCHEMA {
            return Err(Error::invalid(
                file,
                format!("schema {:?}, expected {SCHEMA:?}", self.schema),
            ));
        }
        for name in PARAM_NAMES {
            match self.parameters.iter().find(|p| p.name == name) {
                Some(p) if p.value.is_finite() => {}
                Some(_) => {
                    return Err(Error::invalid(
                        file,
                        format!("parameter {name} is not finite"),
                    ))
                }
                // Written before the kernel's shape was a parameter: one Gaussian.
                None if name.starts_with("kernel_") => {}
                None => return Err(Error::invalid(file, format!("parameter {name} missing"))),
            }
        }
        let m = self.params().material;
        if !(0.0..1.0).contains(&m.kernel_weight)
            || (m.kernel_weight > 0.0 && !(m.kernel_ratio > 1.0))
        {
            return Err(Error::invalid(
                file,
                format!(
                    "kernel_weight {} must lie in [0, 1) and kernel_ratio {} above 1 when it is not 0",
                    m.kernel_weight, m.kernel_ratio
                ),
            ));
        }
        Ok(())
    }
}

/// One photo's light under `"light": "per-image"`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageLightJson {
    pub file: String,
    pub direction: [f64; 3],
    pub azimuth_deg: f64,
    pub elevation_deg: f64,
}

/// Everything loaded before fitting.
pub struct Loaded {
    pub report: SessionReport,
    pub detections: Detections,
    pub detections_path: PathBuf,
    pub proj: Projection,
    pub spheres: Vec<SphereData>,
    pub light: Option<Vector3<f64>>,
    /// The detector's standard error of the light (radians).
    pub light_std: Option<f64>,
    /// Under `"light": "per-image"`: each photo's rotation onto the common light frame.
    pub frames: Option<Vec<nalgebra::Rotation3<f64>>>,
    pub highlight_radius: Option<f64>,
    pub alpha: Option<f64>,
    /// No photo gave a dark floor (lit surroundings, none in session.json) and all share one
    /// exposure: the floor is fitted with the material ([`Setup::floor`]).
    pub fit_floor: bool,
    pub skipped: Vec<String>,
    pub timings: Timings,
}

fn mtime(p: &Path) -> Option<SystemTime> {
    std::fs::metadata(p).and_then(|m| m.modified()).ok()
}

/// The files a session's results depend on: session.json, the photos, the intrinsics.
fn inputs(report: &SessionReport) -> Vec<PathBuf> {
    let mut v = vec![report.session_file.clone()];
    v.extend(report.images.iter().map(|i| i.path.clone()));
    v.extend(report.intrinsics_file.clone());
    v
}

/// Whether `detections.json` can be reused: newer than every input, same schema, same photos.
fn reusable(path: &Path, report: &SessionReport) -> std::result::Result<Detections, String> {
    let Some(t) = mtime(path) else {
        return Err("no detections.json yet".into());
    };
    for p in &inputs(report) {
        match mtime(p) {
            Some(m) if m < t => {}
            _ => {
                return Err(format!(
                    "{} is newer than detections.json",
                    p.file_name().unwrap_or_default().to_string_lossy()
                ))
            }
        }
    }
    let d: Detections = crate::formats::output::read_json(path).map_err(|e| e.to_string())?;
    if d.schema != detect::SCHEMA {
        return Err(format!("detections.json has schema {:?}", d.schema));
    }
    let same = d.images.len() == report.images.len()
        && d.images.iter().zip(&report.images).all(|(a, b)| {
            a.file == b.file
                && a.spheres.len() == b.radii_mm.len()
                && a.spheres
                    .iter()
                    .zip(&b.radii_mm)
                    .all(|(s, r)| s.radius_mm == *r)
        });
    let proj = if report.camera.is_some() {
        "perspective"
    } else {
        "orthographic"
    };
    if !same || d.projection != proj {
        return Err("detections.json describes other photos or another camera".into());
    }
    Ok(d)
}

/// Check the session, reuse or run detection, decode and sample.
pub fn load(opts: &Options) -> Result<Loaded> {
    let t0 = Instant::now();
    load_inspected(opts, session::inspect(&opts.session)?, t0)
}

/// [`load`] for a session already inspected (at `t0`).
fn load_inspected(opts: &Options, report: SessionReport, t0: Instant) -> Result<Loaded> {
    let (sess, _) = Session::load(&report.session_file)?;
    let mut timings = Timings {
        inspect_s: t0.elapsed().as_secs_f64(),
        ..Timings::default()
    };
    let mut skipped = vec![];
    let proj = match &report.camera {
        Some(c) => {
            skipped.push(format!(
                "calibration: camera from {} (not recalibrated)",
                report
                    .intrinsics_file
                    .as_ref()
                    .map(|p| p.display().to_string())
                    .unwrap_or_default()
            ));
            Projection::Perspective(*c)
        }
        None => {
            skipped.push("calibration: no intrinsics in session.json, orthographic camera".into());
            Projection::Orthographic
        }
    };
    let detections_path = report.session_file.with_file_name("detections.json");
    let t1 = Instant::now();
    let reuse = if opts.redetect {
        Err("--redetect".to_string())
    } else {
        reusable(&detections_path, &report)
    };
    let detections = match reuse {
        Ok(d) => {
            skipped.push("detection: detections.json reused (newer than its inputs)".into());
            d
        }
        Err(why) => {
            let d = detect::run(&detect::Options {
                session: report.session_file.clone(),
                out: None,
                overlays: true,
                quiet: opts.quiet,
            })?;
            skipped.push(format!("detection: ran ({why})"));
            d
        }
    };
    timings.detect_s = t1.elapsed().as_secs_f64();
    // One light per photo: each photo is turned so that its light (from its own highlights)
    // lies on the first photo's, the material is fitted in that common frame, and the light's
    // prior is the photos' lights combined (`observe::light_frames`).
    let (light, light_std, frames) = match sess.light {
        LightMode::Shared => (
            detections.light_direction.map(Vector3::from),
            detections.light_std_deg.map(f64::to_radians),
            None,
        ),
        LightMode::PerImage => {
            let mut lights = vec![];
            let mut info = 0.0;
            for im in &detections.images {
                let (Some(l), Some(sd)) = (im.light_direction, im.light_std_deg) else {
                    return Err(Error::invalid(
                        &report.session_file,
                        format!(
                            "\"light\": \"per-image\", but {} has no usable highlight: its light is unknown (detections.json says why)",
                            im.file
                        ),
                    ));
                };
                lights.push(Vector3::from(l));
                info += 1.0 / sd.to_radians().max(detect::LIGHT_FLOOR).powi(2);
            }
            let reference = lights[0];
            let frames = observe::light_frames(&lights, &reference);
            skipped.push(format!(
                "light: one per photo ({} photos), each turned onto the first photo's light; the fit refines a correction they share",
                lights.len()
            ));
            (Some(reference), Some(info.powf(-0.5)), Some(frames))
        }
    };
    let hl: Vec<&detect::HighlightJson> = detections
        .images
        .iter()
        .flat_map(|i| i.spheres.iter())
        .filter_map(|s| s.highlight.as_ref())
        .filter(|h| !h.outlier)
        .collect();
    let highlight_radius = hl
        .iter()
        .map(|h| h.radius_deg.to_radians())
        .fold(None, |a: Option<f64>, r| Some(a.map_or(r, |a| a.max(r))));
    let mut alphas: Vec<f64> = hl.iter().filter_map(|h| h.alpha).collect();
    alphas.sort_by(|a, b| a.total_cmp(b));
    let alpha = alphas.get(alphas.len() / 2).copied();
    let obs = observe::observe(
        &report,
        &sess,
        &detections,
        &proj,
        &match sess.light {
            LightMode::Shared => vec![light],
            LightMode::PerImage => detections
                .images
                .iter()
                .map(|i| i.light_direction.map(Vector3::from))
                .collect(),
        },
        highlight_radius,
        frames.as_deref(),
    )?;
    timings.decode_s = obs.decode_s;
    timings.samples_s = obs.samples_s;
    if obs.spheres.iter().all(|s| s.obs.is_empty()) {
        return Err(Error::invalid(
            &report.session_file,
            "no usable pixels on any sphere (all saturated or on the edge)",
        ));
    }
    // The floor is fitted when no photo measured it and one floor (in pixel values) is one
    // constant in radiance units: the same exposure on every photo.
    let same_exposure = report
        .images
        .windows(2)
        .all(|w| w[0].exposure == w[1].exposure);
    let fit_floor = obs.spheres.iter().all(|s| s.floor.is_none()) && same_exposure;
    Ok(Loaded {
        fit_floor,
        report,
        detections,
        detections_path,
        proj,
        spheres: obs.spheres,
        light,
        light_std,
        frames,
        highlight_radius,
        alpha,
        skipped,
        timings,
    })
}

fn setup(opts: &Options, l: &Loaded, ext: Extensions, reduction: Reduction) -> Setup {
    Setup {
        model: Model {
            entry_fresnel: opts.entry_transmission,
            ..Model::default()
        },
        light: l.light,
        highlight_radius: l.highlight_radius,
        alpha: l.alpha,
        eta_prior: opts.eta_prior,
        irradiance: opts.irradiance,
        reduction,
        robust: opts.robust,
        extensions: ext,
        start_sigma0: opts.start_sigma0,
        start_light: opts.start_light,
        warm: None,
        light_fit: opts.light_fit,
        light_std: l.light_std,
        floor: l.fit_floor && opts.method == Method::Joint,
    }
}

/// Choose the extensions by held-out error: each candidate is fitted with every radius left out
/// in turn (4° cells: the choice compares errors of percents, not of standard errors) and
/// predicts that radius's pixels; the candidate with the lowest mean
/// relative RMSE (the simplest within 1% of it) wins if it beats the plain model by more than 2%
/// of its error.
pub fn choose_extensions(opts: &Options, l: &Loaded, fitted: &[&SphereData]) -> ModelChoice {
    let radii = distinct_radii(fitted);
    // Simplest first: one extension (the kernel's shape first), then pairs.
    let ext = |two_gaussian, sigma_exponent, albedo_curvature| Extensions {
        sigma_exponent,
        albedo_curvature,
        two_gaussian,
    };
    let candidates = [
        Extensions::default(),
        ext(true, false, false),
        ext(false, true, false),
        ext(false, false, true),
        ext(true, false, true),
        ext(false, true, true),
    ];
    if radii.len() < 4 {
        return ModelChoice {
            candidates: vec![],
            chosen: "plain".into(),
            extensions: Extensions::default(),
            reason: format!(
                "{} radii: leaving one out leaves fewer than the 3 an extension needs",
                radii.len()
            ),
        };
    }
    // Every refit starts from the plain model's fit to all the spheres.
    let base = joint::fit_joint(
        &setup(opts, l, Extensions::default(), Reduction::Factor(16)),
        fitted,
    );
    let results: Vec<Candidate> = candidates
        .iter()
        .map(|&ext| {
            let mut errs = vec![];
            let mut ok = true;
            for &r in &radii {
                let train: Vec<&SphereData> = fitted
                    .iter()
                    .copied()
                    .filter(|s| s.radius_mm != r)
                    .collect();
                let test: Vec<&SphereData> = fitted
                    .iter()
                    .copied()
                    .filter(|s| s.radius_mm == r)
                    .collect();
                let mut su = setup(opts, l, ext, Reduction::Factor(16));
                su.warm = Some(base.fit.params);
                let jf = joint::fit_joint(&su, &train);
                ok &= jf.fit.converged;
                let (mut d, mut o) = (0.0, 0.0);
                for s in test {
                    let p =
                        joint::predict(&jf.model, &jf.fit.params, s, jf.fit.floor_value(), 20_000);
                    d += (p.rel_rmse * p.rel_rmse) * p.pixels as f64;
                    o += p.pixels as f64;
                }
                errs.push((d / o.max(1.0)).sqrt());
            }
            Candidate {
                extensions: ext.name(),
                heldout_rel_rmse: errs.iter().sum::<f64>() / errs.len() as f64,
                converged: ok,
            }
        })
        .collect();
    let plain = results[0].heldout_rel_rmse;
    // The best, or the simplest candidate within 1% of the best's error (candidates are listed
    // simplest first, the single extensions before the pairs).
    let lowest = results
        .iter()
        .filter(|c| c.converged)
        .map(|c| c.heldout_rel_rmse)
        .fold(f64::INFINITY, f64::min);
    let k = results
        .iter()
        .position(|c| c.converged && c.heldout_rel_rmse <= 1.01 * lowest)
        .unwrap_or(0);
    let best = &results[k];
    let (chosen, reason) = if k != 0 && best.heldout_rel_rmse < 0.98 * plain {
        (
            candidates[k],
            format!(
                "held-out error {:.4} against {:.4} for the plain model",
                best.heldout_rel_rmse, plain
            ),
        )
    } else {
        (
            Extensions::default(),
            format!(
                "no extension lowers the held-out error by 2% (plain {:.4}, best {:.4} for {})",
                plain, best.heldout_rel_rmse, best.extensions
            ),
        )
    };
    ModelChoice {
        candidates: results,
        chosen: chosen.name(),
        extensions: chosen,
        reason,
    }
}

/// The options that decide a fit's result (not where it is written, nor progress display).
pub fn fingerprint(opts: &Options) -> String {
    format!(
        "workbench {} | method {:?} | holdout {:?} | eta prior {:?} | irradiance {:?} | reduction {:?} | robust {} | extensions {:?} | start sigma0 {:?} | start light {:?} | light {} | jackknife {} | entry {} | baseline {}",
        env!("CARGO_PKG_VERSION"),
        opts.method,
        opts.holdout,
        opts.eta_prior,
        opts.irradiance,
        opts.reduction,
        opts.robust,
        opts.extensions,
        opts.start_sigma0,
        opts.start_light.map(|l| (l.azimuth, l.elevation)),
        opts.light_fit.name(),
        opts.jackknife,
        opts.entry_transmission,
        opts.baseline || opts.plots.is_some()
    )
}

/// A fit.json that can stand for this run: newer than session.json, the photos, the intrinsics
/// and detections.json, of this schema, and written with the same options. Not with --redetect
/// or --plots (figures need the pixels).
fn cached(opts: &Options, report: &SessionReport) -> Option<(FitFile, PathBuf)> {
    if opts.redetect || opts.plots.is_some() {
        return None;
    }
    let out = opts
        .out
        .clone()
        .unwrap_or_else(|| report.session_file.with_file_name("fit.json"));
    let t = mtime(&out)?;
    let mut files = inputs(report);
    files.push(report.session_file.with_file_name("detections.json"));
    if !files.iter().all(|p| mtime(p).is_some_and(|m| m < t)) {
        return None;
    }
    let f: FitFile = crate::formats::output::read_json(&out).ok()?;
    (f.schema == SCHEMA && f.options == fingerprint(opts)).then_some((f, out))
}

/// Run `solve` and write fit.json (or reuse the one an identical earlier run wrote).
pub fn run(opts: &Options) -> Result<FitFile> {
    let t0 = Instant::now();
    let report = session::inspect(&opts.session)?;
    if let Some((mut f, out)) = cached(opts, &report) {
        f.skipped.insert(
            0,
            format!(
                "solve: {} reused (newer than its inputs, same options; {:.3} s instead of {:.2} s)",
                out.display(),
                t0.elapsed().as_secs_f64(),
                f.timings.total_s
            ),
        );
        return Ok(f);
    }
    let mut l = load_inspected(opts, report, t0)?;
    // Stages after loading (detection shows its own bar): fit, predictions, output.
    let pb = crate::progress::bar(3, "solve", opts.quiet);
    pb.enable_steady_tick(std::time::Duration::from_millis(200));
    let out = opts
        .out
        .clone()
        .unwrap_or_else(|| l.report.session_file.with_file_name("fit.json"));
    if let Some(r) = opts.holdout {
        if !l.spheres.iter().any(|s| (s.radius_mm - r).abs() < 1e-9) {
            return Err(Error::Argument(format!(
                "--holdout {r}: no sphere of radius {r} mm in {}",
                l.report.session_file.display()
            )));
        }
        if l.spheres.iter().all(|s| (s.radius_mm - r).abs() < 1e-9) {
            return Err(Error::Argument(format!(
                "--holdout {r}: every sphere has that radius, nothing is left to fit"
            )));
        }
    }
    let is_held = |s: &SphereData| opts.holdout.is_some_and(|r| (s.radius_mm - r).abs() < 1e-9);
    let fitted: Vec<&SphereData> = l.spheres.iter().filter(|s| !is_held(s)).collect();
    let mut notes = vec![];
    // A photo whose surroundings are lit (a backdrop, a table) gives no dark floor to subtract.
    let unmeasured: Vec<&str> = {
        let mut v: Vec<&str> = l
            .spheres
            .iter()
            .filter(|s| s.floor.is_none())
            .map(|s| s.image.as_str())
            .collect();
        v.dedup();
        v
    };
    // Without a measured floor the joint fit fits one (Setup::floor); where it cannot, say so.
    let floor_fitted = l.fit_floor && opts.method == Method::Joint;
    if !unmeasured.is_empty() && !floor_fitted {
        let why = if opts.method == Method::Paper {
            "the paper's procedure fits none"
        } else if l.fit_floor {
            "it is fitted only when every photo lacks one"
        } else {
            "the photos differ in exposure, so one floor would not fit them all"
        };
        notes.push(format!(
            "no dark floor measured for {} (the photo around the spheres is lit or covered) and none fitted ({why}): none subtracted, and σ0 rests on the unlit side's level, which the floor raises — a floor of 0.2% of full scale moved σ0 by 6–18% in the synthetic backdrop tests; give \"floor\" in session.json (a lens-capped photo's mean)",
            unmeasured.join(", ")
        ));
    }
    let mut model_choice = None;
    let mut baseline = None;
    let t_solve = Instant::now();
    struct Outcome {
        params: Params,
        std: [f64; N_PARAMS],
        std_formal: [f64; N_PARAMS],
        jackknife: Option<Jackknife>,
        status: [String; N_PARAMS],
        free: [bool; N_PARAMS],
        correlation: nalgebra::DMatrix<f64>,
        specular: bool,
        extensions: Extensions,
        reduction: Option<ReductionJson>,
        convergence: ConvergenceJson,
        per_radius: Option<Vec<RadiusFit>>,
        paper: Option<paper::PaperFit>,
        light_pull: Option<LightPull>,
        /// The model the parameters belong to (what predicts the photos from them).
        model: Model,
        /// The dark floor fitted with the material (radiance units), when none was measured.
        floor: Option<solver::Floor>,
        prior_tension: [f64; N_PARAMS],
        light_fit: String,
    }
    let outcome = match opts.method {
        Method::Joint => {
            let ext = match opts.extensions {
                ExtensionChoice::None => Extensions::default(),
                ExtensionChoice::On(e) => e,
                ExtensionChoice::Default => {
                    let radii = distinct_radii(&fitted);
                    if radii.len() >= DEFAULT_EXTENSION_RADII {
                        Extensions {
                            albedo_curvature: true,
                            ..Extensions::default()
                        }
                    } else {
                        l.skipped.push(format!(
                            "albedo curvature (the default extension): {} radii, it needs {DEFAULT_EXTENSION_RADII}",
                            radii.len()
                        ));
                        Extensions::default()
                    }
                }
                ExtensionChoice::Auto => {
                    let t = Instant::now();
                    let mc = choose_extensions(opts, &l, &fitted);
                    l.timings.model_choice_s = t.elapsed().as_secs_f64();
                    let e = mc.extensions;
                    notes.push(format!("model: {} ({})", mc.chosen, mc.reason));
                    model_choice = Some(mc);
                    e
                }
            };
            let mut jf: JointFit = joint::fit_joint(&setup(opts, &l, ext, opts.reduction), &fitted);
            // A light pulled beyond PULL_WARN of the detector's errors is pulled by the model's
            // error, not supported by the data: hold it at the detector's and refit. Each
            // parameter's shift between the two fits is the light's systematic on it and joins its
            // std (docs/uncertainty.md, "When the shading pulls the light").
            let mut fit_opts = opts.clone();
            let mut light_shift = [0.0; N_PARAMS];
            let pulled = jf.light_pull.filter(|p| p.pull > joint::PULL_WARN);
            if let (LightFit::Prior, Some(pull), Some(_)) = (opts.light_fit, pulled, l.light) {
                fit_opts.light_fit = LightFit::Hold;
                let held = joint::fit_joint(&setup(&fit_opts, &l, ext, opts.reduction), &fitted);
                let (a, b) = (jf.fit.params.to_vec(), held.fit.params.to_vec());
                light_shift = std::array::from_fn(|k| {
                    if held.fit.free[k] {
                        (a[k] - b[k]).abs()
                    } else {
                        0.0
                    }
                });
                let moved_sigma0: Vec<String> = (0..3)
                    .map(|c| format!("{:.3}", jf.fit.params.material.sigma0_mm[c]))
                    .collect();
                notes.push(format!(
                    "the light is held at the highlights' estimate: the shading pulled it {:.1} of its errors, further than the data support; with the pulled light σ0 was {} mm, and each parameter's shift between the two fits joins its std",
                    pull.pull,
                    moved_sigma0.join(", ")
                ));
                jf = JointFit {
                    light_pull: Some(pull),
                    ..held
                };
                let why = format!("held: the detector's (pulled {:.1} std)", pull.pull);
                jf.status[idx::AZIMUTH] = why.clone();
                jf.status[idx::ELEVATION] = why;
            }
            // A light taken from the detector keeps the detector's error.
            if fit_opts.light_fit == LightFit::Hold && opts.start_light.is_none() {
                if let (Some(s), Some(d)) = (l.light_std, l.light) {
                    let el = LightAngles::from_direction(&d).elevation;
                    light_shift[idx::AZIMUTH] = s / el.cos().abs().max(1e-3);
                    light_shift[idx::ELEVATION] = s;
                }
            }
            let opts = &fit_opts;
            let jack = if opts.jackknife {
                let fitted_ext = Extensions::of_fit(&jf.fit.free);
                let j = jackknife(opts, &l, &fitted, &jf, fitted_ext);
                if j.is_none() {
                    l.skipped.push(
                        "jackknife: fewer than 3 radii, the standard errors are the formal ones"
                            .into(),
                    );
                }
                j
            } else {
                l.skipped.push(
                    "jackknife: off (--no-jackknife), the standard errors are the formal ones"
                        .into(),
                );
                None
            };
            if let Some(fl) = jf.fit.floor {
                let e = pixel_scale(&l.report);
                let show = |v: [f64; 3]| v.map(|x| format!("{:.5}", x * e)).join(", ");
                notes.push(format!(
                    "no dark floor measured (the photos around the spheres are lit): fitted with the material, {} ± {} of full scale (r, g, b), and subtracted before the predictions and figures",
                    show(fl.value),
                    show(fl.std)
                ));
            }
            // The paper's baseline beside it, for the figures and a comparison (on the photos
            // less the fitted floor, when one was fitted: the procedure assumes a measured one).
            let want = opts.baseline || opts.plots.is_some();
            if let (true, Some(light)) = (want, l.light) {
                let t = Instant::now();
                let floored: Vec<SphereData> = match jf.fit.floor {
                    Some(fl) => fitted.iter().map(|s| less_floor(s, fl.value)).collect(),
                    None => vec![],
                };
                let base: Vec<&SphereData> = if floored.is_empty() {
                    fitted.clone()
                } else {
                    floored.iter().collect()
                };
                let pf = paper::fit(&base, &light, l.highlight_radius, opts.eta_prior.0);
                let a = LightAngles::from_direction(&light);
                baseline = Some(BaselineJson {
                    eta: pf.eta,
                    light_azimuth_deg: a.azimuth.to_degrees(),
                    light_elevation_deg: a.elevation.to_degrees(),
                    mask_deg: pf.mask_deg,
                    sigma0_mm: pf.params.material.sigma0_mm,
                    albedo: pf.params.material.albedo,
                    per_radius: pf.per_radius,
                    seconds: t.elapsed().as_secs_f64(),
                });
            }
            l.timings.solve_phases = jf.phases.clone();
            notes.extend(jf.notes.iter().cloned());
            if !jf.specular {
                l.skipped
                    .push("specular lobe: off (no usable highlight)".into());
            }
            let setting = match opts.reduction {
                Reduction::Auto => "auto".to_string(),
                Reduction::None => "none".to_string(),
                Reduction::Factor(f) => format!("{}°", f as f64 * 0.25),
            };
            l.skipped.push(if jf.chosen.width_deg > 0.0 {
                format!(
                    "pixels: {} pooled into {} observations ({}° cells, predicted shift {:.2} std)",
                    jf.pixels,
                    jf.chosen.observations,
                    jf.chosen.width_deg,
                    jf.chosen.predicted_shift_std
                )
            } else {
                format!("pixels: all {} used", jf.pixels)
            });
            for (name, st) in PARAM_NAMES.iter().zip(&jf.status) {
                if st.starts_with("prior") {
                    l.skipped.push(format!("{name}: {st}"));
                }
            }
            Outcome {
                model: jf.model,
                floor: jf.fit.floor,
                params: jf.fit.params,
                std: std::array::from_fn(|k| {
                    let spread = jack.as_ref().map_or(0.0, |j| j.std[k]);
                    let s = (jf.fit.std[k].max(spread) * jf.prior_tension[k]).hypot(light_shift[k]);
                    if k == idx::ETA {
                        s.hypot(jf.eta_systematic)
                    } else {
                        s
                    }
                }),
                prior_tension: jf.prior_tension,
                std_formal: jf.fit.std,
                jackknife: jack,
                status: jf.status.clone(),
                free: jf.fit.free,
                correlation: jf.fit.correlation.clone(),
                specular: jf.specular,
                extensions: Extensions::of_fit(&jf.fit.free),
                reduction: Some(ReductionJson {
                    setting,
                    pixels: jf.pixels,
                    chosen: jf.chosen.clone(),
                    levels: jf.levels.clone(),
                    shift_limit_std: joint::SHIFT_LIMIT,
                }),
                convergence: ConvergenceJson {
                    converged: jf.fit.converged,
                    stages: jf.stages.clone(),
                    downweighted: jf.downweighted,
                    robust_loss: opts
                        .robust
                        .then(|| format!("huber, k = {}", joint::HUBER_K)),
                    chi2_per_dof: Some(jf.chi2_dof),
                },
                per_radius: None,
                paper: None,
                light_pull: jf.light_pull,
                light_fit: if pulled.is_some() && opts.light_fit == LightFit::Hold {
                    "prior, then hold".into()
                } else {
                    opts.light_fit.name().into()
                },
            }
        }
        Method::Paper => {
            let Some(light) = l.light else {
                return Err(Error::invalid(
                    &l.report.session_file,
                    "--method paper needs the light direction and the detector found no usable highlight",
                ));
            };
            let pf = paper::fit(&fitted, &light, l.highlight_radius, opts.eta_prior.0);
            notes.push(format!(
                "paper: light from the detector, specular peak masked within {:.1}° of the mirror direction, exit Fresnel divided out with η = {}, σ fitted per radius",
                pf.mask_deg, pf.eta
            ));
            let mut status: [String; N_PARAMS] = std::array::from_fn(|_| "fixed".to_string());
            for s in status.iter_mut().take(6) {
                *s = "fitted per radius, combined".into();
            }
            status[idx::ETA] = format!("fixed: divided out with η = {}", pf.eta);
            status[idx::KS] = "off: peak masked".into();
            status[idx::ALPHA] = "off: peak masked".into();
            status[idx::AZIMUTH] = "fixed: from the detector".into();
            status[idx::ELEVATION] = "fixed: from the detector".into();
            status[idx::SIGMA_EXPONENT] = "off".into();
            status[idx::ALBEDO_CURVATURE] = "off".into();
            let mut free = [false; N_PARAMS];
            for f in free.iter_mut().take(6) {
                *f = true;
            }
            Outcome {
                model: crate::fit::paper::predicting_model(),
                floor: None,
                prior_tension: [1.0; N_PARAMS],
                params: pf.params,
                std: pf.std,
                std_formal: pf.std,
                jackknife: None,
                status,
                free,
                // Separate fits per radius: no joint covariance to report.
                correlation: nalgebra::DMatrix::zeros(0, 0),
                specular: false,
                extensions: Extensions::default(),
                reduction: None,
                convergence: ConvergenceJson {
                    converged: pf.converged,
                    stages: vec![],
                    downweighted: 0,
                    robust_loss: None,
                    chi2_per_dof: None,
                },
                per_radius: Some(pf.per_radius.clone()),
                paper: Some(pf),
                light_pull: None,
                light_fit: LightFit::Hold.name().into(),
            }
        }
    };
    l.timings.jackknife_s = outcome.jackknife.as_ref().map_or(0.0, |j| j.json.seconds);
    l.timings.solve_s = t_solve.elapsed().as_secs_f64()
        - l.timings.model_choice_s
        - l.timings.jackknife_s
        - baseline.as_ref().map_or(0.0, |b: &BaselineJson| b.seconds);
    pb.inc(1);
    // A fitted floor comes off every sphere's pixels (the held-out one's too: the floor is the
    // camera's), for the predictions, the figures and fit.json's per-sphere floor.
    if let Some(fl) = outcome.floor {
        for s in l.spheres.iter_mut() {
            *s = less_floor(s, fl.value);
        }
    }
    // Predictions per sphere (the held-out one included).
    let t_hold = Instant::now();
    let model = outcome.model;
    let spheres: Vec<SphereRmse> = l
        .spheres
        .iter()
        .map(|s| {
            let p: Prediction = match &outcome.paper {
                Some(pf) if !is_held(s) => pf.predict(s, PREDICT_PIXELS),
                // A held-out radius has no per-radius fit: the combined σ0 predicts it.
                _ => joint::predict(&model, &outcome.params, s, [0.0; 3], PREDICT_PIXELS),
            };
            SphereRmse {
                image: s.image.clone(),
                index: s.index,
                radius_mm: s.radius_mm,
                pixels: s.obs.len(),
                saturated: s.saturated,
                edge: s.edge,
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
    l.timings.holdout_s = t_hold.elapsed().as_secs_f64();
    pb.inc(1);
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
    let p = &outcome.params;
    let m = &p.material;
    let l_dir = p.light.direction();
    let light_deg = (outcome.std[idx::AZIMUTH].powi(2) * p.light.elevation.cos().powi(2)
        + outcome.std[idx::ELEVATION].powi(2))
    .sqrt()
    .to_degrees();
    let free_names: Vec<String> = (0..N_PARAMS)
        .filter(|&k| outcome.free[k])
        .map(|k| PARAM_NAMES[k].to_string())
        .collect();
    let nc = outcome.correlation.nrows();
    let fit = FitFile {
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
        image_lights: l
            .frames
            .iter()
            .flatten()
            .zip(&l.report.images)
            .map(|(r, im)| {
                let d = r.inverse() * l_dir;
                let a = LightAngles::from_direction(&d);
                ImageLightJson {
                    file: im.file.clone(),
                    direction: [d.x, d.y, d.z],
                    azimuth_deg: a.azimuth.to_degrees(),
                    elevation_deg: a.elevation.to_degrees(),
                }
            })
            .collect(),
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
        reference_radius_mm: model.reference_radius_mm,
        entry_transmission: model.entry_fresnel,
        std: StdJson {
            sigma0_mm: [outcome.std[0], outcome.std[1], outcome.std[2]],
            albedo: [outcome.std[3], outcome.std[4], outcome.std[5]],
            eta: outcome.std[idx::ETA],
            specular: outcome.specular.then_some(SpecularJson {
                ks: outcome.std[idx::KS],
                alpha: outcome.std[idx::ALPHA],
            }),
            light_deg,
            sigma_exponent: outcome
                .extensions
                .sigma_exponent
                .then_some(outcome.std[idx::SIGMA_EXPONENT]),
            albedo_curvature: outcome
                .extensions
                .albedo_curvature
                .then_some(outcome.std[idx::ALBEDO_CURVATURE]),
            kernel: outcome.extensions.two_gaussian.then_some(KernelJson {
                weight: outcome.std[idx::KERNEL_WEIGHT],
                ratio: outcome.std[idx::KERNEL_RATIO],
            }),
        },
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
            let e = pixel_scale(&l.report);
            DarkFloorJson {
                value: f.value.map(|v| v * e),
                std: f.std.map(|v| v * e),
            }
        }),
        parameters: (0..N_PARAMS)
            .map(|k| ParamJson {
                name: PARAM_NAMES[k].into(),
                value: p.to_vec()[k],
                std: outcome.std[k],
                std_formal: outcome.jackknife.as_ref().map(|_| outcome.std_formal[k]),
                std_jackknife: outcome.jackknife.as_ref().map(|j| j.std[k]),
                prior_tension: (outcome.prior_tension[k] > 1.0).then_some(outcome.prior_tension[k]),
                status: outcome.status[k].clone(),
            })
            .collect(),
        correlation: CorrelationJson {
            names: if nc == free_names.len() {
                free_names
            } else {
                PARAM_NAMES[..nc].iter().map(|s| s.to_string()).collect()
            },
            matrix: (0..nc)
                .map(|i| (0..nc).map(|j| outcome.correlation[(i, j)]).collect())
                .collect(),
        },
        rmse: RmseJson {
            overall,
            relative,
            spheres,
        },
        holdout,
        per_radius: outcome.per_radius,
        baseline,
        model_choice,
        reduction: outcome.reduction,
        convergence: outcome.convergence,
        skipped: l.skipped,
        notes,
        timings: Timings {
            total_s: t0.elapsed().as_secs_f64(),
            ..l.timings
        },
        options: fingerprint(opts),
    };
    crate::formats::output::write_json(&out, &fit)?;
    if let Some(dir) = &opts.plots {
        crate::figures::fitplot::write_all(&fit, &out, &l.spheres, dir)?;
    }
    pb.finish_and_clear();
    Ok(fit)
}

/// The one-screen human summary of a fit.
pub fn summary(f: &FitFile) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let status = |name: &str| {
        f.parameters
            .iter()
            .find(|p| p.name == name)
            .map(|p| p.status.clone())
            .unwrap_or_default()
    };
    let rgb = |v: &[f64; 3], e: &[f64; 3], digits: usize| {
        format!(
            "{:.d$} ± {:.d$}, {:.d$} ± {:.d$}, {:.d$} ± {:.d$}",
            v[0],
            e[0],
            v[1],
            e[1],
            v[2],
            e[2],
            d = digits
        )
    };
    let _ = writeln!(
        s,
        "method   {} ({} camera), session {}",
        match f.method {
            Method::Joint => "joint",
            Method::Paper => "paper baseline",
        },
        f.projection,
        f.session
    );
    let _ = writeln!(
        s,
        "sigma0   {} mm (r, g, b)",
        rgb(&f.sigma0_mm, &f.std.sigma0_mm, 4)
    );
    let _ = writeln!(s, "albedo   {}", rgb(&f.albedo, &f.std.albedo, 4));
    let _ = writeln!(
        s,
        "eta      {:.4} ± {:.4}  [{}]",
        f.eta,
        f.std.eta,
        status("eta")
    );
    match (&f.specular, &f.std.specular) {
        (Some(sp), Some(e)) => {
            let _ = writeln!(
                s,
                "specular ks {:.4} ± {:.4} [{}], alpha {:.4} ± {:.4} [{}]",
                sp.ks,
                e.ks,
                status("ks"),
                sp.alpha,
                e.alpha,
                status("alpha")
            );
        }
        _ => {
            let _ = writeln!(s, "specular none  [{}]", status("ks"));
        }
    }
    let _ = writeln!(
        s,
        "light    [{:+.5}, {:+.5}, {:+.5}] (az {:.3}°, el {:.3}°) ± {:.3}°  [{}]",
        f.light_direction[0],
        f.light_direction[1],
        f.light_direction[2],
        f.light_azimuth_deg,
        f.light_elevation_deg,
        f.std.light_deg,
        status("light_azimuth")
    );
    if let Some(lp) = &f.light_pull {
        let _ = writeln!(
            s,
            "         moved {:.3}° from the detector's light (± {:.4}°): pull {:.1}",
            lp.moved_deg, lp.detector_std_deg, lp.pull
        );
    }
    for il in &f.image_lights {
        let _ = writeln!(
            s,
            "light    {:<12} [{:+.5}, {:+.5}, {:+.5}] (az {:.3}°, el {:.3}°)",
            il.file,
            il.direction[0],
            il.direction[1],
            il.direction[2],
            il.azimuth_deg,
            il.elevation_deg
        );
    }
    if let (Some(q), Some(e)) = (f.sigma_exponent, f.std.sigma_exponent) {
        let _ = writeln!(
            s,
            "extension sigma_exponent q = {q:.4} ± {e:.4} (r_ref {} mm)",
            f.reference_radius_mm
        );
    }
    if let (Some(k), Some(e)) = (f.kernel, f.std.kernel) {
        let _ = writeln!(
            s,
            "kernel   two Gaussians: weight {:.4} ± {:.4} in a tail {:.3} ± {:.3} times wider",
            k.weight, e.weight, k.ratio, e.ratio
        );
    }
    if let (Some(b), Some(e)) = (f.albedo_curvature, f.std.albedo_curvature) {
        let _ = writeln!(
            s,
            "extension albedo_curvature b = {b:.4} ± {e:.4} (r_ref {} mm)",
            f.reference_radius_mm
        );
    }
    if let Some(pr) = &f.per_radius {
        for r in pr {
            let _ = writeln!(
                s,
                "radius   {:>6} mm: σ {:.4}, {:.4}, {:.4} rad → σ0 {:.3}, {:.3}, {:.3} mm",
                r.radius_mm,
                r.sigma_rad[0],
                r.sigma_rad[1],
                r.sigma_rad[2],
                r.sigma0_mm[0],
                r.sigma0_mm[1],
                r.sigma0_mm[2]
            );
        }
    }
    if let Some(b) = &f.baseline {
        let _ = writeln!(
            s,
            "baseline paper's method: σ0 {:.4}, {:.4}, {:.4} mm (detector's light, η = {} divided out, peak masked; {:.2} s)",
            b.sigma0_mm[0], b.sigma0_mm[1], b.sigma0_mm[2], b.eta, b.seconds
        );
    }
    let _ = writeln!(
        s,
        "rmse     {:.3e} ({:.2}% of the data's RMS){}",
        f.rmse.overall,
        100.0 * f.rmse.relative,
        f.convergence
            .chi2_per_dof
            .map(|c| format!(", {:.2}× the measured noise (χ²/dof {c:.2})", c.sqrt()))
            .unwrap_or_default()
    );
    for sp in &f.rmse.spheres {
        let _ = writeln!(
            s,
            "sphere   {:<12} #{} r {:>5} mm: {:>8} px, rel. RMSE {:.2}% (lit {:.2}%, unlit {:.2}%){}",
            sp.image,
            sp.index + 1,
            sp.radius_mm,
            sp.pixels,
            100.0 * sp.rel_rmse,
            100.0 * sp.lit_rel_rmse,
            100.0 * sp.unlit_rel_rmse,
            if sp.held_out { "  HELD OUT" } else { "" }
        );
    }
    if let Some(j) = &f.jackknife {
        let per: Vec<String> = j
            .heldout
            .iter()
            .map(|h| format!("{} mm {:.2}%", h.radius_mm, 100.0 * h.rel_rmse))
            .collect();
        let _ = writeln!(
            s,
            "jackknife each radius left out and predicted: {} (mean {:.2}%); std = {}",
            per.join(", "),
            100.0 * j.heldout_rel_rmse,
            f.std_source
        );
    }
    if let Some(h) = &f.holdout {
        let _ = writeln!(
            s,
            "holdout  r {} mm predicted with rel. RMSE {:.2}% (lit {:.2}%, unlit {:.2}%)",
            h.radius_mm,
            100.0 * h.rel_rmse,
            100.0 * h.lit_rel_rmse,
            100.0 * h.unlit_rel_rmse
        );
    }
    let c = &f.convergence;
    let evals: usize = c.stages.iter().map(|st| st.evaluations).sum();
    let _ = writeln!(
        s,
        "solver   {} ({} stages, {} evaluations{}){}",
        if c.converged {
            "converged"
        } else {
            "DID NOT CONVERGE"
        },
        c.stages.len(),
        evals,
        c.robust_loss
            .as_ref()
            .map(|r| format!(", {r}, {} residuals down-weighted", c.downweighted))
            .unwrap_or_default(),
        c.stages
            .last()
            .map(|st| format!(": {}", st.termination))
            .unwrap_or_default()
    );
    for k in &f.skipped {
        let _ = writeln!(s, "skipped  {k}");
    }
    for n in &f.notes {
        let _ = writeln!(s, "note     {n}");
    }
    let t = &f.timings;
    let _ = writeln!(
        s,
        "time     {:.2} s: detect {:.2}, decode {:.2}, samples {:.2}, solve {:.2}{}{}{}",
        t.total_s,
        t.detect_s,
        t.decode_s,
        t.samples_s,
        t.solve_s,
        if t.model_choice_s > 0.0 {
            format!(", model choice {:.2}", t.model_choice_s)
        } else {
            String::new()
        },
        if t.jackknife_s > 0.0 {
            format!(", jackknife {:.2}", t.jackknife_s)
        } else {
            String::new()
        },
        if t.holdout_s > 0.0 {
            format!(", predictions {:.2}", t.holdout_s)
        } else {
            String::new()
        }
    );
    s
}
