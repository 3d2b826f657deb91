//! `workbench solve <session>/`: from photos to a measured material, written as `fit.json`
//! (schema `workbench.fit/1`).
//!
//! Runs what is needed: the session is checked ([`crate::formats::session::inspect`]), `detections.json` is
//! reused when every input it records (session.json, the photos, the intrinsics) has the same
//! content now ([`crate::formats::fingerprint`]) and it describes the same photos, else detection runs ([`crate::detect`]); the photos are decoded and
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
use std::time::Instant;

mod choice;
mod file;
mod jackknife;
mod load;
mod outcome;
mod replot;
mod summary;

use choice::choose_extensions;
use choice::setup;
use file::{fit_file, predictions};
use jackknife::combine_predictions;
pub use jackknife::jackknife;
use jackknife::Jackknife;
use load::{cached, load_inspected};
pub use load::{fingerprint, load, Loaded};
use outcome::{joint_outcome, paper_outcome, Outcome};
pub use replot::replot;
pub use summary::summary;

/// Pixels per sphere used for RMSE and predictions (every k-th beyond this).
pub(crate) const PREDICT_PIXELS: usize = 200_000;

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
    /// The CDRF from its table (the default) or the closed form (docs/model.md, "The tabulated
    /// CDRF").
    pub tabulated: bool,
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
            tabulated: true,
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
    let now = crate::formats::fingerprint::of_files(&report.input_files())?;
    if let Some((mut f, out)) = cached(opts, &report, &now) {
        f.skipped.insert(
            0,
            format!(
                "solve: {} reused (its inputs unchanged by content, same options; {:.3} s instead of {:.2} s)",
                out.display(),
                t0.elapsed().as_secs_f64(),
                f.timings.total_s
            ),
        );
        return Ok(f);
    }
    let mut l = load_inspected(opts, report, now, t0)?;
    // Stages after loading (detection shows its own bar): fit, predictions, output.
    let pb = crate::progress::bar(3, "solve", opts.quiet);
    pb.enable_steady_tick(std::time::Duration::from_millis(200));
    let out = opts
        .out
        .clone()
        .unwrap_or_else(|| l.report.session_file.with_file_name("fit.json"));
    check_holdout(opts, &l)?;
    let is_held = |s: &SphereData| opts.holdout.is_some_and(|r| (s.radius_mm - r).abs() < 1e-9);
    let mut notes: Vec<String> = unfitted_floor_note(opts, &l).into_iter().collect();
    let t_solve = Instant::now();
    let mut outcome = {
        let fitted: Vec<&SphereData> = l.spheres.iter().filter(|s| !is_held(s)).collect();
        match opts.method {
            Method::Joint => joint_outcome(opts, &l, &fitted, &mut notes),
            Method::Paper => paper_outcome(opts, &l, &fitted, &mut notes)?,
        }
    };
    l.skipped.append(&mut outcome.skipped);
    l.timings.model_choice_s = outcome.model_choice_s;
    l.timings.solve_phases = std::mem::take(&mut outcome.solve_phases);
    l.timings.jackknife_s = outcome.jackknife.as_ref().map_or(0.0, |j| j.json.seconds);
    l.timings.solve_s = t_solve.elapsed().as_secs_f64()
        - l.timings.model_choice_s
        - l.timings.jackknife_s
        - outcome.baseline.as_ref().map_or(0.0, |b| b.seconds);
    pb.inc(1);
    // A fitted floor comes off every sphere's pixels (the held-out one's too: the floor is the
    // camera's), for the predictions, the figures and fit.json's per-sphere floor.
    if let Some(fl) = outcome.floor {
        for s in l.spheres.iter_mut() {
            *s = less_floor(s, fl.value);
        }
    }
    let t_hold = Instant::now();
    let (spheres, holdout) = predictions(opts, &l, &outcome);
    l.timings.holdout_s = t_hold.elapsed().as_secs_f64();
    pb.inc(1);
    let fit = fit_file(opts, &l, outcome, spheres, holdout, notes, t0);
    // One set: the figures, then fit.json (what the reuse check trusts) last.
    let mut roots: Vec<&Path> = vec![&out];
    roots.extend(opts.plots.as_deref());
    let set = crate::formats::output::OutputSet::begin(&roots);
    if let Some(dir) = &opts.plots {
        crate::figures::fitplot::write_all(&fit, &out, &l.spheres, dir)?;
    }
    crate::formats::output::write_json(&out, &fit)?;
    set.commit()?;
    pb.finish_and_clear();
    Ok(fit)
}

/// `--holdout r` names a radius the session has, and leaves another to fit.
fn check_holdout(opts: &Options, l: &Loaded) -> Result<()> {
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
    Ok(())
}

/// The note for photos whose dark floor was neither measured nor fitted.
fn unfitted_floor_note(opts: &Options, l: &Loaded) -> Option<String> {
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
        return Some(format!(
        "no dark floor measured for {} (the photo around the spheres is lit or covered) and none fitted ({why}): none subtracted, and σ0 rests on the unlit side's level, which the floor raises — a floor of 0.2% of full scale moved σ0 by 6–18% in the synthetic backdrop tests; give \"floor\" in session.json (a lens-capped photo's mean)",
        unmeasured.join(", ")
    ));
    }
    None
}
