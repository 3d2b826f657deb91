//! `fit.json` (schema `workbench.fit/1`): a measured material as `workbench solve` writes it —
//! the parameters with their standard errors and how each was obtained, the fit's convergence,
//! its error per sphere, the choices made and why — as the figures, `workbench lut` and
//! `workbench render` read it. docs/formats.md describes every field.

use crate::error::{Error, Result};
use crate::formats::session::RADIUS_RANGE_MM;
use crate::model::{LightAngles, Model, Params, N_PARAMS, PARAM_NAMES};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub(crate) const SCHEMA: &str = "workbench.fit/1";

/// Every number of fit.json that is infinite or NaN where a fit failed (a standard error, a cost,
/// a correlation) is written as null — JSON has no infinity — and read back as NaN, "not finite",
/// so that every reader opens a failed fit (issue 33: `plot`, what a user opens one with, refused
/// it). Each float field of the file carries one of these.
mod nullable {
    use serde::{Deserialize, Deserializer};

    pub fn f64<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
    }

    pub fn f64x3<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 3], D::Error> {
        Ok(<[Option<f64>; 3]>::deserialize(d)?.map(|x| x.unwrap_or(f64::NAN)))
    }

    pub fn opt_f64x3<'de, D: Deserializer<'de>>(d: D) -> Result<Option<[f64; 3]>, D::Error> {
        Ok(Option::<[Option<f64>; 3]>::deserialize(d)?.map(|a| a.map(|x| x.unwrap_or(f64::NAN))))
    }

    pub fn named<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<(String, f64)>, D::Error> {
        Ok(Vec::<(String, Option<f64>)>::deserialize(d)?
            .into_iter()
            .map(|(n, x)| (n, x.unwrap_or(f64::NAN)))
            .collect())
    }

    pub fn vec<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
        Ok(Vec::<Option<f64>>::deserialize(d)?
            .into_iter()
            .map(|x| x.unwrap_or(f64::NAN))
            .collect())
    }

    pub fn matrix<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<Vec<f64>>, D::Error> {
        Ok(Vec::<Vec<Option<f64>>>::deserialize(d)?
            .into_iter()
            .map(|r| r.into_iter().map(|x| x.unwrap_or(f64::NAN)).collect())
            .collect())
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    #[default]
    Joint,
    Paper,
}

/// A specular lobe as written.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpecularJson {
    #[serde(deserialize_with = "nullable::f64")]
    pub ks: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub alpha: f64,
}

/// Standard errors, mirroring the values.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StdJson {
    #[serde(deserialize_with = "nullable::f64x3")]
    pub sigma0_mm: [f64; 3],
    #[serde(deserialize_with = "nullable::f64x3")]
    pub albedo: [f64; 3],
    #[serde(deserialize_with = "nullable::f64")]
    pub eta: f64,
    pub specular: Option<SpecularJson>,
    /// Angular standard error of the light direction (degrees; from the two angles').
    #[serde(deserialize_with = "nullable::f64")]
    pub light_deg: f64,
    pub sigma_exponent: Option<f64>,
    pub albedo_curvature: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kernel: Option<KernelJson>,
}

/// The two-Gaussian kernel: (1 − weight)·f(θ; σ) + weight·f(θ; ratio·σ).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct KernelJson {
    #[serde(deserialize_with = "nullable::f64")]
    pub weight: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub ratio: f64,
}

/// A standard error more than this many times its value (or 1, whichever is larger) is not a
/// measurement: the data do not bound the parameter (an opaque ball's σ0 at the edge of its
/// range gave 1.1e32 mm). fit.json writes it as `null` with a reason, the summary as
/// `unbounded`.
pub const UNBOUNDED_RATIO: f64 = 1e6;

/// Whether a standard error says the data do not bound the value ([`UNBOUNDED_RATIO`]; an
/// infinite one too).
pub fn unbounded(value: f64, std: f64) -> bool {
    std == f64::INFINITY || (std.is_finite() && std > UNBOUNDED_RATIO * value.abs().max(1.0))
}

/// One parameter, flat.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParamJson {
    pub name: String,
    #[serde(deserialize_with = "nullable::f64")]
    pub value: f64,
    /// The standard error stated: see `FitFile::std_source`.
    #[serde(deserialize_with = "nullable::f64")]
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
    /// Why `std` is `null` where the data do not bound the parameter ([`unbounded`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub std_note: Option<String>,
    /// "fitted", "fixed", "prior …", "off: …".
    pub status: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CorrelationJson {
    pub names: Vec<String>,
    #[serde(deserialize_with = "nullable::matrix")]
    pub matrix: Vec<Vec<f64>>,
}

/// A dark floor fitted with the material: pixel values (full scale 1) per channel.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DarkFloorJson {
    #[serde(deserialize_with = "nullable::f64x3")]
    pub value: [f64; 3],
    #[serde(deserialize_with = "nullable::f64x3")]
    pub std: [f64; 3],
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SphereRmse {
    pub image: String,
    pub index: usize,
    #[serde(deserialize_with = "nullable::f64")]
    pub radius_mm: f64,
    /// Pixels used by the fit (saturated and edge pixels left out) and how many were left out.
    pub pixels: usize,
    pub saturated: usize,
    pub edge: usize,
    /// Pixels left out as impulses (a channel more than 6σ + 20% of the level, 50% in the
    /// highlight, from its row neighbours' mean).
    #[serde(default)]
    pub impulses: usize,
    /// Pixel noise σ per channel (radiance units), as measured.
    #[serde(deserialize_with = "nullable::f64x3")]
    pub noise: [f64; 3],
    /// The photo's dark floor, subtracted before fitting (null: not measurable).
    #[serde(default, deserialize_with = "nullable::opt_f64x3")]
    pub floor: Option<[f64; 3]>,
    #[serde(deserialize_with = "nullable::f64")]
    pub rmse: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub rel_rmse: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub lit_rel_rmse: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub unlit_rel_rmse: f64,
    /// Held out of the fit.
    pub held_out: bool,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RmseJson {
    /// Over all spheres' pixels (radiance units), and relative to their RMS.
    #[serde(deserialize_with = "nullable::f64")]
    pub overall: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub relative: f64,
    pub spheres: Vec<SphereRmse>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HoldoutJson {
    #[serde(deserialize_with = "nullable::f64")]
    pub radius_mm: f64,
    pub pixels: usize,
    #[serde(deserialize_with = "nullable::f64")]
    pub rel_rmse: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub lit_rel_rmse: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub unlit_rel_rmse: f64,
}

/// A value per channel (r, g, b) and its standard error.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PerChannelJson {
    #[serde(deserialize_with = "nullable::f64x3")]
    pub value: [f64; 3],
    #[serde(deserialize_with = "nullable::f64x3")]
    pub std: [f64; 3],
}

/// The std per channel that a held input's error (the light's, the outlines') gives σa and
/// σs′ (1/mm).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CarriedStdJson {
    #[serde(deserialize_with = "nullable::f64x3")]
    pub sigma_a_per_mm: [f64; 3],
    #[serde(deserialize_with = "nullable::f64x3")]
    pub sigma_s_reduced_per_mm: [f64; 3],
}

/// One value and its standard error.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ValueJson {
    #[serde(deserialize_with = "nullable::f64")]
    pub value: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub std: f64,
}

/// Where the medium's η came from (`MediumJson::eta_sources`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EtaSourcesJson {
    pub joint: ValueJson,
    /// Whether the joint fit's η was combined with the pixels' (false: left out, its model not
    /// describing the photos, and the medium's η is the pixels'); absent in files written
    /// before it could be left out (it was always combined).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joint_combined: Option<bool>,
    pub pixels: ValueJson,
}

/// The medium fit: the material as a path tracer takes it (isotropic phase function, so σs′ is
/// σs), with each quantity's stated error.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MediumJson {
    /// The model that predicted the pixels (docs/medium.md).
    pub profile: String,
    /// The model's prediction at a fixed reference, as the build that fitted it computed it
    /// (`fit::medium::model_reference`): `plot` and `close-loop` draw and compare this fit's
    /// pixels only with a build whose model gives the same. Absent in files written before it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model_reference: Option<Vec<f64>>,
    /// The boundary's GGX roughness, carried into exports: measured by the medium fit with
    /// the joint fit's lobe as its prior, or held at the lobe's (0: smooth).
    #[serde(deserialize_with = "nullable::f64")]
    pub alpha: f64,
    /// α's std where the medium fit measured it; absent where α was held, and in older files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha_std: Option<f64>,
    /// The lobe's α and its std (the joint fit's), the prior of the measured α.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha_lobe: Option<ValueJson>,
    pub sigma_a_per_mm: PerChannelJson,
    pub sigma_s_reduced_per_mm: PerChannelJson,
    pub eta: ValueJson,
    /// η's two sources, whose inverse-variance mean `eta` is: the joint fit's (its std with the
    /// joint fit's own error) and the medium's pixels' (with the model's own error).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eta_sources: Option<EtaSourcesJson>,
    /// The transport mean free path 1/(σa + σs′).
    pub mean_free_path_mm: PerChannelJson,
    /// The surface's diffuse albedo an artist sets: the classical dipole's total diffuse
    /// reflectance of a flat surface of the medium.
    pub diffuse_albedo: PerChannelJson,
    /// The light's irradiance in the photos' units: given (std 0), or fitted with the medium.
    pub irradiance: PerChannelJson,
    pub irradiance_source: String,
    /// What `std` is: the formal or the larger of formal and jackknife, with the model's own
    /// error added.
    pub std_source: String,
    /// The part of σa's and σs′'s std that the held light's error alone gives (included in
    /// their `std`); absent where the light had no stated error, and in older files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub std_from_light: Option<CarriedStdJson>,
    /// The part of σa's and σs′'s std that the detected outlines' error alone gives (included
    /// in their `std`): each outline's stated std with the edge model's own error; absent where
    /// it was not carried, and in older files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub std_from_outlines: Option<CarriedStdJson>,
    /// The residuals' RMS over the pixels' noise, per pixel (a block of pixels counted as its
    /// pixels: `fit::medium::MAX_PIXELS_A_SPHERE`).
    #[serde(deserialize_with = "nullable::f64")]
    pub residual_over_noise: f64,
    /// The residuals averaged over 5° bands of θ per radius and channel, against their noise:
    /// about 1 where the model describes the photos (docs/medium.md, "The renders' noise").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wave_over_noise: Option<f64>,
    /// Pixel-channels fitted, and the radii they came from.
    pub pixels: usize,
    /// The rows they were fitted as where fewer (a sphere of more than
    /// `fit::medium::MAX_PIXELS_A_SPHERE` fitted pixels in blocks); absent where every pixel
    /// was its own row.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub blocks: Option<usize>,
    #[serde(deserialize_with = "nullable::vec")]
    pub radii_mm: Vec<f64>,
    /// The held-out radius predicted by the medium and by the joint fit's CDRF, on the same
    /// pixels (away from the highlight and the rim).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout: Option<MediumHoldoutJson>,
    pub converged: bool,
    /// Profiles M(θ) computed (the fit's cost), and seconds.
    pub profiles: usize,
    #[serde(deserialize_with = "nullable::f64")]
    pub seconds: f64,
}

impl MediumJson {
    /// σt = σa + σs′ and the single-scattering albedo σs′/σt per channel: the medium as a path
    /// tracer takes it (isotropic phase, so σs′ is σs).
    pub fn extinction_and_albedo(&self) -> ([f64; 3], [f64; 3]) {
        let (a, s) = (self.sigma_a_per_mm.value, self.sigma_s_reduced_per_mm.value);
        let t = std::array::from_fn(|c| a[c] + s[c]);
        (t, std::array::from_fn(|c| s[c] / t[c]))
    }

    /// The fitted medium per channel as the diffusion model takes it (σa, σs′, the shared η).
    pub fn media(&self) -> [crate::model::dipole::Medium; 3] {
        std::array::from_fn(|c| crate::model::dipole::Medium {
            sigma_a: self.sigma_a_per_mm.value[c],
            sigma_s_reduced: self.sigma_s_reduced_per_mm.value[c],
            eta: self.eta.value,
        })
    }
}

/// A held-out radius's relative RMSE under the medium and under the CDRF.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MediumHoldoutJson {
    #[serde(deserialize_with = "nullable::f64")]
    pub radius_mm: f64,
    pub pixels: usize,
    #[serde(deserialize_with = "nullable::f64")]
    pub medium_rel_rmse: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub cdrf_rel_rmse: f64,
}

/// The leave-one-radius-out estimates of a joint fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JackknifeJson {
    /// How each estimate was taken: "linear" (Newton steps from the full fit's normal equations,
    /// the default) or "refit" (the fit repeated).
    #[serde(default)]
    pub method: String,
    /// With "linear": the Newton steps each estimate took (a second where the first was large).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub newton_steps: Vec<u32>,
    /// The radii left out in turn (mm).
    #[serde(deserialize_with = "nullable::vec")]
    pub radii: Vec<f64>,
    /// Each left-out radius predicted by the fit to the others.
    pub heldout: Vec<HoldoutJson>,
    /// Pixel-weighted mean of the held-out relative RMSE.
    #[serde(deserialize_with = "nullable::f64")]
    pub heldout_rel_rmse: f64,
    /// Every refit converged (with "linear": every step was a descent of its subset's normal
    /// equations).
    pub converged: bool,
    #[serde(deserialize_with = "nullable::f64")]
    pub seconds: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReductionJson {
    pub setting: String,
    pub pixels: usize,
    /// The level used (width 0: every pixel).
    pub chosen: Level,
    /// Levels tried, coarsest first (with `auto`).
    pub levels: Vec<Level>,
    #[serde(deserialize_with = "nullable::f64")]
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
    #[serde(deserialize_with = "nullable::f64")]
    pub heldout_rel_rmse: f64,
    pub converged: bool,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ModelChoice {
    pub candidates: Vec<Candidate>,
    pub chosen: String,
    pub reason: String,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Timings {
    #[serde(deserialize_with = "nullable::f64")]
    pub inspect_s: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub detect_s: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub decode_s: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub samples_s: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub solve_s: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub model_choice_s: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub holdout_s: f64,
    /// The leave-one-radius-out refits.
    #[serde(default)]
    #[serde(deserialize_with = "nullable::f64")]
    pub jackknife_s: f64,
    /// The medium fit (`--model medium`, or `auto` with the irradiance known).
    #[serde(default)]
    #[serde(deserialize_with = "nullable::f64")]
    pub medium_s: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub total_s: f64,
    /// The solve stage's phases (joint method), seconds.
    #[serde(default)]
    #[serde(deserialize_with = "nullable::named")]
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
    #[serde(deserialize_with = "nullable::f64x3")]
    pub sigma0_mm: [f64; 3],
    #[serde(deserialize_with = "nullable::f64x3")]
    pub albedo: [f64; 3],
    #[serde(deserialize_with = "nullable::f64")]
    pub eta: f64,
    /// Null when no lobe was fitted.
    pub specular: Option<SpecularJson>,
    #[serde(deserialize_with = "nullable::f64x3")]
    pub light_direction: [f64; 3],
    #[serde(deserialize_with = "nullable::f64")]
    pub light_azimuth_deg: f64,
    #[serde(deserialize_with = "nullable::f64")]
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
    #[serde(deserialize_with = "nullable::f64")]
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
    /// "prior, then combined" (the detector's light and the shading's combined by their
    /// covariances, and the fit redone with the light held there; docs/uncertainty.md).
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
    /// The medium fit (`solve --model medium`): σa, σs′ and η as a path tracer takes them
    /// (docs/formats.md, "medium").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub medium: Option<MediumJson>,
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
    /// What it was made from: session.json, the photos, the intrinsics and detections.json, each
    /// as `"<bytes>:<hash>"` (`crate::formats::fingerprint`); reused only while they match.
    #[serde(default)]
    pub inputs: crate::formats::fingerprint::Inputs,
    /// The workbench build that made it (`crate::formats::fingerprint::BUILD`); reused only by
    /// the same build.
    #[serde(default)]
    pub build: String,
}

/// The paper's baseline beside a joint fit: its assumptions and per-radius fits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BaselineJson {
    /// η divided out, the light taken from the detector (degrees), the mask around the peak.
    #[serde(deserialize_with = "nullable::f64")]
    pub eta: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub light_azimuth_deg: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub light_elevation_deg: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub mask_deg: f64,
    /// Combined over radii.
    #[serde(deserialize_with = "nullable::f64x3")]
    pub sigma0_mm: [f64; 3],
    #[serde(deserialize_with = "nullable::f64x3")]
    pub albedo: [f64; 3],
    pub per_radius: Vec<RadiusFit>,
    #[serde(deserialize_with = "nullable::f64")]
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
    pub(crate) fn session_path(&self, fit_path: &Path) -> Result<PathBuf> {
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

    /// The fit's measured medium, for a renderer: an error naming `file` when there is none
    /// (a solve without the irradiance, or `--model cdrf`, fits none) or when it is not a medium
    /// (a failed fit).
    pub fn medium(&self, file: &Path) -> Result<&MediumJson> {
        let Some(m) = &self.medium else {
            return Err(Error::invalid(
                file,
                "no \"medium\" in this fit; run `workbench solve <session> --irradiance <E>` (or `--model medium`) first",
            ));
        };
        let positive = m
            .sigma_a_per_mm
            .value
            .iter()
            .chain(&m.sigma_s_reduced_per_mm.value)
            .chain(&m.mean_free_path_mm.value)
            .chain(&m.irradiance.value)
            .all(|v| v.is_finite() && *v > 0.0);
        if !(positive && m.eta.value.is_finite() && m.eta.value > 1.0 && m.alpha.is_finite()) {
            return Err(Error::invalid(
                file,
                "the medium's σa, σs′, mean free path and irradiance must be positive and η above 1; this fit's are not (a failed medium fit)",
            ));
        }
        Ok(m)
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
        let c = &self.correlation;
        if c.names.len() > PARAM_NAMES.len()
            || c.matrix.len() != c.names.len()
            || c.matrix.iter().any(|r| r.len() != c.names.len())
        {
            return Err(Error::invalid(
                file,
                format!(
                    "correlation: {} names and a {}-row matrix; expected at most {} parameters and a square matrix of them",
                    c.names.len(),
                    c.matrix.len(),
                    PARAM_NAMES.len()
                ),
            ));
        }
        self.summary_agrees(file)?;
        self.physical(file)?;
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

/// The largest |q| (σ exponent) and |b| (albedo curvature) a fit.json may hold: far beyond what
/// a fit produces (0.06–0.6 measured), short of what overflows the model or hangs a figure's axes
/// (b = 10⁴ did).
pub const EXTENSION_LIMIT: f64 = 20.0;

impl FitFile {
    /// The summary at the top (σ0, albedo, η, the lobe, the extensions, the light's angles)
    /// repeats parameters[], which every reader takes: an edit to one alone is refused, so that
    /// fit.json has one source of truth.
    fn summary_agrees(&self, file: &Path) -> Result<()> {
        let p = self.params();
        let m = &p.material;
        let mut pairs: Vec<(&str, f64, f64)> = vec![];
        for c in 0..3 {
            pairs.push(("sigma0_mm", self.sigma0_mm[c], m.sigma0_mm[c]));
            pairs.push(("albedo", self.albedo[c], m.albedo[c]));
        }
        pairs.push(("eta", self.eta, m.eta));
        if let Some(s) = &self.specular {
            pairs.push(("specular.ks", s.ks, m.specular.ks));
            pairs.push(("specular.alpha", s.alpha, m.specular.alpha));
        }
        if let Some(q) = self.sigma_exponent {
            pairs.push(("sigma_exponent", q, m.sigma_exponent));
        }
        if let Some(b) = self.albedo_curvature {
            pairs.push(("albedo_curvature", b, m.albedo_curvature));
        }
        pairs.push((
            "light_azimuth_deg",
            self.light_azimuth_deg,
            p.light.azimuth.to_degrees(),
        ));
        pairs.push((
            "light_elevation_deg",
            self.light_elevation_deg,
            p.light.elevation.to_degrees(),
        ));
        let same = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs());
        match pairs.into_iter().find(|&(_, a, b)| !same(a, b)) {
            Some((name, a, b)) => Err(Error::invalid(
                file,
                format!("{name} is {a} but parameters[] says {b}: every reader takes parameters[]; edit both or neither"),
            )),
            None => Ok(()),
        }
    }

    /// The values a fit can hold: σ0, albedo and ks ≥ 0, α > 0, η ≥ 1, the extensions within
    /// [`EXTENSION_LIMIT`], every sphere's radius within [`RADIUS_RANGE_MM`].
    fn physical(&self, file: &Path) -> Result<()> {
        let m = self.params().material;
        let why = if m.sigma0_mm.iter().chain(&m.albedo).any(|v| *v < 0.0) {
            Some(format!(
                "σ0 {:?} mm and albedo {:?} must be ≥ 0",
                m.sigma0_mm, m.albedo
            ))
        } else if !(m.eta >= 1.0) {
            Some(format!("eta {} must be ≥ 1", m.eta))
        } else if !(m.specular.ks >= 0.0 && m.specular.alpha > 0.0) {
            Some(format!(
                "ks {} must be ≥ 0 and alpha {} > 0",
                m.specular.ks, m.specular.alpha
            ))
        } else if m.sigma_exponent.abs() > EXTENSION_LIMIT
            || m.albedo_curvature.abs() > EXTENSION_LIMIT
        {
            Some(format!(
                "sigma_exponent {} and albedo_curvature {} must lie within ±{EXTENSION_LIMIT}",
                m.sigma_exponent, m.albedo_curvature
            ))
        } else if let Some(s) = self
            .rmse
            .spheres
            .iter()
            .find(|s| !RADIUS_RANGE_MM.contains(&s.radius_mm))
        {
            Some(format!(
                "sphere radius {} mm ({}) outside {} to {} mm",
                s.radius_mm, s.image, RADIUS_RANGE_MM.start, RADIUS_RANGE_MM.end
            ))
        } else if !(self.reference_radius_mm > 0.0 && self.reference_radius_mm.is_finite()) {
            Some(format!(
                "reference_radius_mm {} must be positive",
                self.reference_radius_mm
            ))
        } else {
            None
        };
        match why {
            Some(w) => Err(Error::invalid(file, w)),
            None => Ok(()),
        }
    }
}

/// One photo's light under `"light": "per-image"`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImageLightJson {
    pub file: String,
    #[serde(deserialize_with = "nullable::f64x3")]
    pub direction: [f64; 3],
    #[serde(deserialize_with = "nullable::f64")]
    pub azimuth_deg: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub elevation_deg: f64,
    /// The lamp's relative intensity per channel: session.json's, or fitted (geometric mean 1
    /// per channel) where the session gives none; absent in older files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intensity: Option<[f64; 3]>,
    /// "session.json" or "fitted".
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intensity_source: Option<String>,
}

/// One stage's convergence record.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stage {
    pub name: String,
    pub observations: usize,
    pub free: Vec<String>,
    pub evaluations: usize,
    pub termination: String,
    pub converged: bool,
    #[serde(deserialize_with = "nullable::f64")]
    pub cost_start: f64,
    #[serde(deserialize_with = "nullable::f64")]
    pub cost_end: f64,
    /// ½Σr² at every residual evaluation (trial steps included).
    #[serde(deserialize_with = "nullable::vec")]
    pub cost_history: Vec<f64>,
    #[serde(deserialize_with = "nullable::f64")]
    pub seconds: f64,
}

/// A reduction level as considered.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Level {
    /// Cell width (degrees; 0 = every pixel).
    #[serde(deserialize_with = "nullable::f64")]
    pub width_deg: f64,
    /// Highlight pixels pooled in blocks of this many pixels square (1: one by one).
    pub highlight_block_px: u32,
    pub observations: usize,
    /// Predicted largest parameter shift, in standard errors.
    #[serde(deserialize_with = "nullable::f64")]
    pub predicted_shift_std: f64,
    /// Every parameter's predicted shift is below `SHIFT_LIMIT` (fit::joint) standard errors or below its
    /// tolerance (`fit::reduce::tolerance`).
    pub within_tolerance: bool,
    /// The parameter whose predicted shift is largest against what is accepted for it.
    pub limiting: Option<String>,
}

/// The light's move from the detector's estimate in the joint fit.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LightPull {
    /// Angle between the fitted light and the detector's (degrees).
    #[serde(deserialize_with = "nullable::f64")]
    pub moved_deg: f64,
    /// The detector's standard error (degrees).
    #[serde(deserialize_with = "nullable::f64")]
    pub detector_std_deg: f64,
    /// The prior's width (degrees; null without a prior, `--free-light`).
    pub prior_std_deg: Option<f64>,
    /// `moved_deg` over the prior's width (or the detector's error without one).
    #[serde(deserialize_with = "nullable::f64")]
    pub pull: f64,
}

/// One radius's fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RadiusFit {
    #[serde(deserialize_with = "nullable::f64")]
    pub radius_mm: f64,
    pub spheres: usize,
    pub pixels: usize,
    /// Fitted blur width σ (radians) and σ0 = σ · r (mm), per channel, with standard errors.
    #[serde(deserialize_with = "nullable::f64x3")]
    pub sigma_rad: [f64; 3],
    #[serde(deserialize_with = "nullable::f64x3")]
    pub sigma0_mm: [f64; 3],
    #[serde(deserialize_with = "nullable::f64x3")]
    pub sigma0_std: [f64; 3],
    #[serde(deserialize_with = "nullable::f64x3")]
    pub albedo: [f64; 3],
    #[serde(deserialize_with = "nullable::f64x3")]
    pub albedo_std: [f64; 3],
    pub converged: bool,
}
