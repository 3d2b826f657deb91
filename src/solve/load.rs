//! What a solve starts from: the session checked, detections reused or run, the photos decoded
//! and sampled; and whether an earlier fit.json can stand for this run.

use super::Options;
use crate::camera::outline::Projection;
use crate::detect;
use crate::error::{Error, Result};
use crate::fit::joint::Measured;
use crate::fit::observe::{self, SphereData};
use crate::formats::detections::{self, Detections};
use crate::formats::fingerprint::{self, Inputs};
use crate::formats::fit::{FitFile, Timings, SCHEMA};
use crate::formats::photo::Decoded;
use crate::formats::session::{self, LightMode, Session, SessionReport};
use nalgebra::Vector3;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Everything loaded before fitting.
pub struct Loaded {
    pub report: SessionReport,
    pub detections: Detections,
    pub detections_path: PathBuf,
    pub proj: Projection,
    pub spheres: Vec<SphereData>,
    /// What the detector and the photos measured: the light and its error, the highlight's
    /// radius, the lobe's roughness, whether the dark floor is fitted (no photo gave one, and
    /// all share one exposure), the photos' pixel scale.
    pub measured: Measured,
    /// Under `"light": "per-image"`: each photo's rotation onto the common light frame.
    pub frames: Option<Vec<nalgebra::Rotation3<f64>>>,
    /// Under `"light": "per-image"` without intensities in session.json: each photo's lamp
    /// intensity as fitted ([`crate::fit::joint::intensity`]), its observations divided by it.
    pub intensities: Option<crate::fit::joint::intensity::PhotoIntensities>,
    /// session.json's grey card with its box's pixels, and its photo's dark floor (radiance units).
    pub reference: Option<(crate::fit::observe::ReferencePixels, Option<[f64; 3]>)>,
    pub skipped: Vec<String>,
    pub timings: Timings,
    /// What the fit is made from: the session's input files and detections.json, by content.
    pub inputs: Inputs,
}

/// Whether `detections.json` can be reused: made from inputs of the same content (`now`), same
/// schema, same photos, and with the outlines drawn for the medium where `medium` asks for them.
fn reusable(
    path: &Path,
    report: &SessionReport,
    (now, medium): (&Inputs, bool),
) -> std::result::Result<Detections, String> {
    if !path.is_file() {
        return Err("no detections.json yet".into());
    }
    let d: Detections = crate::formats::output::read_json(path).map_err(|e| e.to_string())?;
    if d.schema != detections::SCHEMA {
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
    if let Some(why) = fingerprint::differs(&d.inputs, now) {
        return Err(format!("detections.json is stale: {why}"));
    }
    if let Some(why) = fingerprint::other_build(&d.build) {
        return Err(format!("detections.json is stale: {why}"));
    }
    if d.edge_weights.as_deref() == Some("contrast") {
        return Err("detections.json's outlines were drawn for the medium alone, by an earlier build (its \"edge_weights\": \"contrast\")".into());
    }
    if medium && !d.has_medium_outlines() {
        return Err(
            "detections.json has no outlines drawn for the medium, which the medium fit needs"
                .into(),
        );
    }
    Ok(d)
}

/// Check the session, reuse or run detection, decode and sample.
pub fn load(opts: &Options) -> Result<Loaded> {
    let t0 = Instant::now();
    let report = session::inspect(&opts.session)?;
    let now = fingerprint::of_files(&report.input_files())?;
    load_inspected(opts, report, now, t0)
}

/// [`load`] for a session already inspected (at `t0`).
/// `now`: the inputs' fingerprints ([`SessionReport::input_files`]).
pub(super) fn load_inspected(
    opts: &Options,
    report: SessionReport,
    now: Inputs,
    t0: Instant,
) -> Result<Loaded> {
    let (sess, _) = Session::load(&report.session_file)?;
    let mut timings = Timings {
        inspect_s: t0.elapsed().as_secs_f64(),
        ..Timings::default()
    };
    let mut skipped = vec![];
    let proj = projection(&report, &mut skipped);
    let t1 = Instant::now();
    let (detections_path, reuse) = detections_location(opts, &report, &now);
    let (detections, decoded) = detections(
        (&report, &sess),
        &now,
        (&detections_path, reuse),
        (opts.quiet, opts.model.medium_outlines()),
        &mut skipped,
    )?;
    timings.detect_s = t1.elapsed().as_secs_f64();
    let mut inputs = now;
    inputs.insert(
        detections_path.display().to_string(),
        fingerprint::of_file(&detections_path)?,
    );
    let (light, light_std, frames) = lights(&sess, &detections, &report, &mut skipped)?;
    let (highlight_radius, alpha) = highlight_radius_alpha(&detections);
    let alpha_std = alpha.and_then(|_| highlight_alpha_std(&detections));
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
        decoded.as_ref(),
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
    let measured = Measured {
        light,
        light_std,
        highlight_radius,
        alpha,
        alpha_std,
        fit_floor,
        pixel_scale: pixel_scale(&report),
    };
    Ok(Loaded {
        report,
        detections,
        detections_path,
        proj,
        spheres: obs.spheres,
        measured,
        frames,
        intensities: None,
        reference: obs.reference.map(|pixels| {
            let floor = obs.floors[pixels.image];
            (pixels, floor)
        }),
        skipped,
        timings,
        inputs,
    })
}

/// The options that decide a fit's result (not where it is written, nor progress display).
pub fn fingerprint(opts: &Options) -> String {
    let f = &opts.fit;
    format!(
        "workbench {} | method {:?} | model {:?} | holdout {:?} | eta prior {:?} | irradiance {:?} | reduction {:?} | robust {} | extensions {:?} | start sigma0 {:?} | start light {:?} | light {} | jackknife {} | entry {} | cdrf {} | baseline {}",
        env!("CARGO_PKG_VERSION"),
        opts.method,
        opts.model,
        opts.holdout,
        f.eta_prior,
        f.irradiance,
        f.reduction,
        f.robust,
        f.extensions,
        f.start_sigma0,
        f.start_light.map(|l| (l.azimuth, l.elevation)),
        f.light_fit.name(),
        f.jackknife.name(),
        f.entry_transmission,
        if f.tabulated { "table" } else { "closed form" },
        opts.fit_settings().baseline
    )
}

/// Radiance units → pixel values (full scale 1) for a floor shared by photos of one exposure.
fn pixel_scale(report: &SessionReport) -> f64 {
    report
        .images
        .first()
        .and_then(|i| i.exposure)
        .unwrap_or(1.0)
}

/// A fit.json that can stand for this run: made from inputs of the same content (`now`, and
/// detections.json as it is), of this schema, and written with the same options. Not with
/// --redetect or --plots (figures need the pixels).
pub(super) fn cached(
    opts: &Options,
    report: &SessionReport,
    now: &Inputs,
) -> Option<(FitFile, PathBuf)> {
    if opts.redetect || opts.plots.is_some() {
        return None;
    }
    let out = opts
        .out
        .clone()
        .unwrap_or_else(|| report.session_file.with_file_name("fit.json"));
    if !out.is_file() {
        return None;
    }
    let f: FitFile = crate::formats::output::read_json(&out).ok()?;
    if f.schema != SCHEMA
        || f.options != fingerprint(opts)
        || fingerprint::other_build(&f.build).is_some()
    {
        return None;
    }
    let mut now = now.clone();
    // The detections the fit was made from, wherever they were (beside the session or the fit).
    let det = PathBuf::from(&f.detections);
    now.insert(det.display().to_string(), fingerprint::of_file(&det).ok()?);
    fingerprint::differs(&f.inputs, &now)
        .is_none()
        .then_some((f, out))
}

/// The camera: the session's intrinsics (perspective), else orthographic; said in `skipped`.
fn projection(report: &SessionReport, skipped: &mut Vec<String>) -> Projection {
    match &report.camera {
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
    }
}

/// Where detections.json (and the overlays beside it) is read and written: the session's own, or
/// — when `--out` puts the fit in another folder and the session's cannot be reused — one beside
/// the fit, so that nothing is written into the session folder and a read-only dataset can be
/// solved (issue 33).
/// Returns the path with whether its detections.json can be reused (or why not).
fn detections_location(
    opts: &Options,
    report: &SessionReport,
    now: &Inputs,
) -> (PathBuf, std::result::Result<Detections, String>) {
    let verdict = |p: &Path| {
        if opts.redetect {
            Err("--redetect".to_string())
        } else {
            reusable(p, report, (now, opts.model.medium_outlines()))
        }
    };
    let in_session = report.session_file.with_file_name("detections.json");
    let folder = |p: &Path| {
        let dir = p.parent().unwrap_or(Path::new("."));
        std::fs::canonicalize(dir)
            .unwrap_or_else(|_| std::path::absolute(dir).unwrap_or(dir.into()))
    };
    let beside = match &opts.out {
        Some(out) => out.with_file_name("detections.json"),
        None => in_session.clone(),
    };
    let in_session_verdict = verdict(&in_session);
    if in_session_verdict.is_ok() || folder(&beside) == folder(&in_session) {
        (in_session, in_session_verdict)
    } else {
        let v = verdict(&beside);
        (beside, v)
    }
}

/// detections.json reused when [`detections_location`] found it reusable, else detection run
/// into that place; said in `skipped`.
fn detections(
    (report, sess): (&SessionReport, &Session),
    now: &Inputs,
    (detections_path, reuse): (&Path, std::result::Result<Detections, String>),
    (quiet, medium_outlines): (bool, bool),
    skipped: &mut Vec<String>,
) -> Result<(Detections, Option<Decoded>)> {
    Ok(match reuse {
        Ok(d) => {
            skipped.push("detection: detections.json reused (its inputs unchanged)".into());
            (d, None)
        }
        Err(why) => {
            // The photos decoded once: detection reads them, then the fit's samples.
            let t = Instant::now();
            let decoded = report.decode(sess)?;
            let d = detect::run_decoded(
                &detect::Options {
                    session: report.session_file.clone(),
                    out: Some(detections_path.to_path_buf()),
                    overlays: true,
                    quiet,
                    medium_outlines,
                },
                (report, sess),
                &decoded,
                now.clone(),
                t,
            )?;
            skipped.push(format!("detection: ran ({why})"));
            (d, Some(decoded))
        }
    })
}

/// The light (the session's), its standard error (radians), and each photo's rotation onto it.
type Lights = (
    Option<Vector3<f64>>,
    Option<f64>,
    Option<Vec<nalgebra::Rotation3<f64>>>,
);

/// The detector's light and its error, and under `"light": "per-image"` each photo's rotation
/// onto the first photo's light: each photo is turned so that its light (from its own
/// highlights) lies on the first photo's, the material is fitted in that common frame, and the
/// light's prior is the photos' lights combined (`observe::light_frames`).
fn lights(
    sess: &Session,
    detections: &Detections,
    report: &SessionReport,
    skipped: &mut Vec<String>,
) -> Result<Lights> {
    Ok(match sess.light {
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
    })
}

/// The highlights' largest angular radius and their median roughness (outliers left out).
fn highlight_radius_alpha(detections: &Detections) -> (Option<f64>, Option<f64>) {
    let hl: Vec<&detections::HighlightJson> = detections
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
    (highlight_radius, alpha)
}

/// The standard error of the highlights' roughness: the median of the lobe fits' own, not
/// divided by their number (most of it is the diffuse trend's error, which every sphere of a
/// session shares). `None` when a detections.json written before the field has none.
fn highlight_alpha_std(detections: &Detections) -> Option<f64> {
    let mut stds: Vec<f64> = detections
        .images
        .iter()
        .flat_map(|i| i.spheres.iter())
        .filter_map(|s| s.highlight.as_ref())
        .filter(|h| !h.outlier && h.alpha.is_some())
        .filter_map(|h| h.alpha_std)
        .filter(|s| s.is_finite() && *s >= 0.0)
        .collect();
    stds.sort_by(|a, b| a.total_cmp(b));
    stds.get(stds.len() / 2).copied()
}
