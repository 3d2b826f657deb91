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
use crate::detect;
use crate::error::{Error, Result};
use crate::fit::joint::{self, Extensions, JointFit, LightFit, Prediction, Reduction, Setup};
use crate::fit::observe::{self, SphereData};
use crate::fit::paper;
use crate::fit::solver;
use crate::formats::detections::{self, Detections};
use crate::formats::fit::*;
use crate::formats::session::{self, LightMode, Session, SessionReport};
use crate::model::{idx, LightAngles, Model, Params, N_PARAMS, PARAM_NAMES};
use nalgebra::Vector3;
use std::path::{Path, PathBuf};
use std::time::{Instant, SystemTime};

mod choice;
mod jackknife;
mod load;
mod replot;
mod summary;

pub use choice::choose_extensions;
use choice::setup;
use jackknife::combine_predictions;
pub use jackknife::{jackknife, Jackknife, JACKKNIFE_CELLS};
use load::{cached, load_inspected};
pub use load::{fingerprint, load, Loaded};
pub use replot::replot;
pub use summary::summary;

/// Pixels per sphere used for RMSE and predictions (every k-th beyond this).
pub const PREDICT_PIXELS: usize = 200_000;

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
                    let (mc, e) = choose_extensions(opts, &l, &fitted);
                    l.timings.model_choice_s = t.elapsed().as_secs_f64();
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
