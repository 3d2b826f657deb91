//! `workbench solve <session>/`: from photos to a measured material, written as `fit.json`
//! (schema `workbench.fit/1`).
//!
//! Runs what is needed: the session is checked ([`crate::formats::session::inspect`]), `detections.json` is
//! reused when every input it records (session.json, the photos, the intrinsics) has the same
//! content now ([`crate::formats::fingerprint`]) and it describes the same photos, else detection runs ([`crate::detect`]); the photos are decoded and
//! sampled ([`crate::fit::observe`]); then the joint fit ([`crate::fit::joint::fit_session`]) or the paper's baseline
//! ([`crate::fit::paper`]). Optional: model extensions chosen by held-out error, a held-out sphere's
//! prediction error, and figures.

use crate::error::{Error, Result};
use crate::fit::joint;
use crate::fit::observe::SphereData;
use crate::formats::detections::Detections;
use crate::formats::fit::{FitFile, Method};
use crate::formats::session;
use std::path::Path;
use std::time::Instant;

mod file;
mod irradiance;
mod load;
mod medium;
mod options;
mod outcome;
mod replot;
mod summary;

use file::{fit_file, predictions};
use load::{cached, load_inspected};
pub use load::{fingerprint, load, Loaded};
pub use medium::{medium_spheres, outline_error, PROFILE};
pub use options::{Options, SolveModel};
use outcome::{paper_outcome, Outcome};
pub use replot::{load_fit, replot};
pub use summary::summary;

/// Run `solve` and write fit.json (or reuse the one an identical earlier run wrote).
pub fn run(opts: &Options) -> Result<FitFile> {
    let t0 = Instant::now();
    let (report, now) = inspected(opts)?;
    if let Some(f) = reused(opts, &report, &now, t0) {
        return Ok(f);
    }
    // fit.json keeps the options as asked, for the reuse check (`--model auto` as such: what it
    // stands for follows from the irradiance asked and session.json, an input).
    let asked = load::fingerprint(opts);
    // `--model auto` stands for the medium or the CDRF alone from here on.
    let mut model_skipped = vec![];
    let resolved = options::resolved(opts, report.has_reference, &mut model_skipped);
    let opts = &resolved;
    let mut l = load_inspected(opts, report, now, t0)?;
    l.skipped.append(&mut model_skipped);
    // Stages after loading (detection shows its own bar): fit, predictions, output.
    let pb = crate::progress::bar(3, "solve", opts.quiet);
    pb.enable_steady_tick(std::time::Duration::from_millis(200));
    let out = opts
        .out
        .clone()
        .unwrap_or_else(|| l.report.session_file.with_file_name("fit.json"));
    check_holdout(opts, &l)?;
    medium::check(opts)?;
    // Without --irradiance, session.json's diffuse reference gives it.
    let (reference, with_reference) = irradiance::apply(opts, &l)?;
    let opts = &with_reference;
    let is_held = |s: &SphereData| opts.holdout.is_some_and(|r| (s.radius_mm - r).abs() < 1e-9);
    let mut notes: Vec<String> = unfitted_floor_note(opts, &l)
        .into_iter()
        .chain(scattered_highlights_note(&l.detections))
        .chain(reference.as_ref().map(irradiance::note))
        .collect();
    let t_solve = Instant::now();
    if opts.method == Method::Joint {
        fit_intensities(opts, &mut l, is_held);
    }
    let mut outcome = {
        let fitted: Vec<&SphereData> = l.spheres.iter().filter(|s| !is_held(s)).collect();
        match opts.method {
            Method::Joint => {
                let settings = opts.fit_settings();
                Outcome::joint(joint::fit_session(
                    &settings,
                    &l.measured,
                    &fitted,
                    &mut notes,
                ))
            }
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
            *s = s.less_floor(fl.value);
        }
    }
    let t_hold = Instant::now();
    let (spheres, holdout) = predictions(opts, &l, &outcome);
    l.timings.holdout_s = t_hold.elapsed().as_secs_f64();
    pb.inc(1);
    // The medium's pixels are seated on the outlines drawn for it.
    let medium_spheres = (opts.model == SolveModel::Medium)
        .then(|| medium::medium_spheres(&l, &l.spheres))
        .flatten();
    let mut medium_skipped = vec![];
    let medium = medium_spheres.as_ref().and_then(|spheres| {
        let source = irradiance::source(reference.as_ref());
        medium::run(
            opts,
            (&l, &source),
            spheres,
            &outcome,
            is_held,
            (&mut notes, &mut medium_skipped),
        )
    });
    l.skipped.append(&mut medium_skipped);
    l.timings.medium_s = medium.as_ref().map_or(0.0, |m| m.seconds);
    let mut fit = fit_file(opts, &l, outcome, spheres, holdout, notes, t0);
    fit.options = asked;
    fit.medium = medium;
    // One set: the figures, then fit.json (what the reuse check trusts) last.
    let mut roots: Vec<&Path> = vec![&out];
    roots.extend(opts.plots.as_deref());
    let set = crate::formats::output::OutputSet::begin(&roots)?;
    if let Some(dir) = &opts.plots {
        crate::figures::fitplot::write_all(
            &fit,
            &out,
            (&l.spheres, medium_spheres.as_deref()),
            dir,
        )?;
    }
    crate::formats::output::write_json(&out, &fit)?;
    set.commit()?;
    pb.finish_and_clear();
    Ok(fit)
}

/// The session checked, with its inputs' fingerprints; refused where the outputs' folders or the
/// session's path cannot be written or recorded.
fn inspected(
    opts: &Options,
) -> Result<(session::SessionReport, crate::formats::fingerprint::Inputs)> {
    let outputs: Vec<&Path> = opts
        .out
        .iter()
        .chain(&opts.plots)
        .map(|p| p.as_path())
        .collect();
    crate::formats::output::check_roots(&outputs)?;
    let report = session::inspect(&opts.session)?;
    if report.session_file.to_str().is_none() {
        // fit.json names its session as text: a lossy name would point nowhere for `plot`.
        return Err(crate::error::Error::invalid(
            &report.session_file,
            "the session's path is not valid UTF-8, which fit.json cannot record: rename the folder",
        ));
    }
    let now = crate::formats::fingerprint::of_files(&report.input_files())?;
    Ok((report, now))
}

/// The fit.json an identical earlier run wrote ([`cached`]), said in its `skipped`.
fn reused(
    opts: &Options,
    report: &session::SessionReport,
    now: &crate::formats::fingerprint::Inputs,
    t0: Instant,
) -> Option<FitFile> {
    let (mut f, out) = cached(opts, report, now)?;
    f.skipped.insert(
        0,
        format!(
            "solve: {} reused (its inputs unchanged by content, same options; {:.3} s instead of {:.2} s)",
            out.display(),
            t0.elapsed().as_secs_f64(),
            f.timings.total_s
        ),
    );
    Some(f)
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
/// Where the spheres' highlights give lights that scatter beyond their own errors by more than
/// twice a typical sphere's error (`light_scatter_deg`, `detect::highlight::combine`): say so,
/// and that the highlights' light error includes it. (The physically based wax sessions scatter
/// 1.1–1.4 times theirs: the lobe on a translucent surface; not worth a note.)
fn scattered_highlights_note(d: &Detections) -> Option<String> {
    let tau = d.light_scatter_deg?;
    let typical = crate::stats::percentile(
        d.images
            .iter()
            .flat_map(|i| &i.spheres)
            .filter(|s| s.highlight.as_ref().is_some_and(|h| !h.outlier))
            .filter_map(|s| s.light_std_deg)
            .collect(),
        0.5,
    );
    (tau > 2.0 * typical).then(|| {
        format!(
            "the spheres' highlights disagree: each sphere's light lies {tau:.2}° from the others' beyond its own error (± {typical:.3}° typical), as a disturbed outline or highlight makes them (a stand, a backdrop edge, a shadow, an occlusion, impulse noise); the highlights' light error (± {:.3}°) includes that scatter",
            d.light_std_deg.unwrap_or(f64::NAN)
        )
    })
}

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
    // Without a measured floor the joint fit fits one (`Measured::fit_floor`); where it cannot, say so.
    let floor_fitted = l.measured.fit_floor && opts.method == Method::Joint;
    if !unmeasured.is_empty() && !floor_fitted {
        let why = if opts.method == Method::Paper {
            "the paper's procedure fits none"
        } else if l.measured.fit_floor {
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

/// Under `"light": "per-image"` with no photo's `light_intensity` in session.json: each photo's
/// lamp intensity fitted and divided out ([`crate::fit::joint::intensity`]), said in `skipped`.
fn fit_intensities(opts: &Options, l: &mut Loaded, is_held: impl Fn(&SphereData) -> bool) {
    let given = l.report.images.iter().any(|i| i.light_intensity.is_some());
    if l.frames.is_none() || given {
        return;
    }
    let fitted = joint::intensity::fit_photo_intensities(
        &opts.fit_settings(),
        &l.measured,
        &mut l.spheres,
        |s| !is_held(s),
    );
    let all = fitted.photos.iter().flat_map(|(_, k)| k.iter().copied());
    let (lo, hi) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    l.skipped.push(format!(
        "light intensities: none in session.json, one per photo and channel fitted ({:.3}–{:.3} of their geometric mean, {} rounds, last move {:.1e}); their errors are not in the material's",
        lo, hi, fitted.rounds, fitted.last_move
    ));
    l.intensities = Some(fitted);
}
