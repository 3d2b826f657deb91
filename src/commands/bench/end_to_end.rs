//! `workbench bench`'s end-to-end rows: `solve` on a fresh folder with every default on —
//! detection, the fit with the light's hold, and the jackknife — each stage timed against
//! decoding the photos in the same run ([`solve_fresh`]); and the many-photo session they are
//! also measured on, one light per photo, as photometric-stereo sets such as DiLiGenT's are
//! taken ([`per_image_session`]); and `solve --model medium` on a fresh copy of the bundled
//! physically based soap session, against its truth ([`medium_fresh`]).

use nalgebra::Vector3;
use std::path::Path;
use workbench::error::{Error, Result};
use workbench::formats::fit::FitFile;
use workbench::formats::session::{LightMode, Session, SessionImage};
use workbench::solve::{self, Options, SolveModel};
use workbench::synth::session::{self, SessionConfig};
use workbench::synth::volpath::PbrTruth;

/// One end-to-end solve: its stages' seconds (fit.json's timings) and its errors.
pub(super) struct EndToEnd {
    pub decode_s: f64,
    pub detect_s: f64,
    /// The fit, the light's hold and the rest of the solve stage.
    pub solve_s: f64,
    pub jackknife_s: f64,
    /// The medium fit (`--model medium`); `None` when it did not run.
    pub medium_s: Option<f64>,
    pub total_s: f64,
    /// The error against the truth (%) and what it is of: the worst channel's σ0, or with the
    /// medium, the worst of σa and σs′.
    pub error_pct: f64,
    pub error_unit: &'static str,
    /// The (first photo's) light against the truth (degrees).
    pub light_error_deg: f64,
}

/// `solve` with the defaults on `dir` as a fresh folder (its detections and fits removed first):
/// what a user waits for, against `sigma0` and `light`, the truth.
pub(super) fn solve_fresh(dir: &Path, sigma0: [f64; 3], light: Vector3<f64>) -> Result<EndToEnd> {
    for stale in ["detections.json", "fit.json"] {
        let p = dir.join(stale);
        if p.exists() {
            std::fs::remove_file(&p).map_err(|e| Error::io(&p, e))?;
        }
    }
    let mut o = Options::new(dir);
    o.quiet = true;
    let f = solve::run(&o)?;
    Ok(EndToEnd::of(
        &f,
        false,
        (
            100.0
                * (0..3)
                    .map(|c| (f.sigma0_mm[c] - sigma0[c]).abs() / sigma0[c])
                    .fold(0.0, f64::max),
            "σ0 %",
        ),
        &light,
    ))
}

impl EndToEnd {
    /// A solve's row from its fit.json: its stages' seconds (the medium stage's with `medium`),
    /// `error` (value and unit) and its light against `light`, the truth.
    fn of(f: &FitFile, medium: bool, error: (f64, &'static str), light: &Vector3<f64>) -> EndToEnd {
        let t = &f.timings;
        EndToEnd {
            decode_s: t.decode_s,
            detect_s: t.detect_s,
            solve_s: t.solve_s,
            jackknife_s: t.jackknife_s,
            medium_s: medium.then_some(t.medium_s),
            total_s: t.total_s,
            error_pct: error.0,
            error_unit: error.1,
            light_error_deg: Vector3::from(f.light_direction).angle(light).to_degrees(),
        }
    }
}

/// A session of `n` photos of one 25 mm sphere that stays put, each under its own light
/// (`"light": "per-image"`): `base`'s camera, material and noise, the lights on a cone 50° × 35°
/// around the camera's axis, each photo rendered on its own into `l<k>/` with its own seed.
/// Returns σ0 and the first photo's light, the truth.
pub(super) fn per_image_session(
    dir: &Path,
    n: usize,
    base: &SessionConfig,
) -> Result<([f64; 3], Vector3<f64>)> {
    let mut images = vec![];
    let mut truth = None;
    for k in 0..n {
        let t = std::f64::consts::TAU * (k as f64 + 0.25) / n as f64;
        let mut cfg = SessionConfig {
            radii_mm: vec![25.0],
            seed: base.seed + k as u64 + 1,
            ..base.clone()
        };
        cfg.light.azimuth = 50f64.to_radians() * t.cos();
        cfg.light.elevation = 35f64.to_radians() * t.sin();
        let sub = format!("l{k}");
        let out = session::generate(&cfg, &dir.join(&sub), None, true)?;
        let own: Session = workbench::formats::output::read_json(&out.session_file)?;
        images.extend(own.images.into_iter().map(|im| SessionImage {
            file: format!("{sub}/{}", im.file),
            ..im
        }));
        truth.get_or_insert((
            out.truth.sigma0_mm,
            Vector3::from(out.truth.light_direction),
        ));
    }
    let session = serde_json::json!({
        "schema": "workbench.session/1",
        "intrinsics": "l0/intrinsics.json",
        "light": LightMode::PerImage,
        "images": images,
    });
    workbench::formats::output::write_json(&dir.join("session.json"), &session)?;
    truth.ok_or_else(|| Error::Argument("a per-image session needs one photo or more".into()))
}

/// `solve --model medium --irradiance <truth>` on `dir`, a fresh copy of the physically based
/// session `src` (its photos, session.json, intrinsics.json and truth.json): what a user waits
/// for, and the medium against the renders' truth.
pub(super) fn medium_fresh(src: &Path, dir: &Path) -> Result<EndToEnd> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    for entry in std::fs::read_dir(src).map_err(|e| Error::io(src, e))? {
        let path = entry.map_err(|e| Error::io(src, e))?.path();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if name.ends_with(".png")
            || ["session.json", "intrinsics.json", "truth.json"].contains(&name)
        {
            std::fs::copy(&path, dir.join(name)).map_err(|e| Error::io(&path, e))?;
        }
    }
    let truth: PbrTruth = workbench::formats::output::read_json(&dir.join("truth.json"))?;
    let mut o = Options::new(dir);
    o.quiet = true;
    o.model = SolveModel::Medium;
    o.fit.irradiance = Some(truth.irradiance_in_png_units);
    let f = solve::run(&o)?;
    let m = f
        .medium
        .as_ref()
        .ok_or_else(|| Error::invalid(dir, "the medium fit wrote no medium"))?;
    let mat = &truth.material;
    let worst = |fitted: &[f64; 3], truth: &dyn Fn(usize) -> f64| {
        100.0
            * (0..3)
                .map(|c| (fitted[c] / truth(c) - 1.0).abs())
                .fold(0.0, f64::max)
    };
    let sigma_a = worst(&m.sigma_a_per_mm.value, &|c| {
        (1.0 - mat.albedo_rgb[c]) * mat.sigma_t_per_mm
    });
    let sigma_s = worst(&m.sigma_s_reduced_per_mm.value, &|c| {
        mat.albedo_rgb[c] * mat.sigma_t_per_mm
    });
    Ok(EndToEnd::of(
        &f,
        true,
        (sigma_a.max(sigma_s), "σa, σs′ %"),
        &Vector3::from(truth.light.direction_to_light_camera_frame),
    ))
}
