//! Numerical stress: extreme materials, sizes and lights, saturation, heavy noise and outliers,
//! through the whole pipeline (synthetic photos → detection → joint fit), and the model itself
//! over the extreme parameter ranges. Every case must end in one of three ways, and each case
//! states which:
//! - accurate: converged, σ0 within the stated tolerance of the truth, the light within its own;
//! - flagged: the result says it is not a measurement (not converged, σ0 reported as a bound,
//!   or a note naming the problem);
//! - refused: a one-line error naming the photo or file.
//!
//! Never NaN, never a panic, never a wrong answer reported as converged without a flag.

use crate::common;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use std::path::Path;
use workbench::formats::fit::FitFile;
use workbench::model::{Geometry, LightAngles, Model, Params};
use workbench::solve::{self, Options};
use workbench::synth::session::{self, SessionConfig, SessionTruth};

#[derive(Debug, PartialEq)]
enum Outcome {
    Accurate,
    Flagged(String),
    Refused(String),
}

/// A 320×240 camera and three radii unless the case says otherwise.
fn config(f: impl FnOnce(&mut SessionConfig)) -> SessionConfig {
    let mut cfg = SessionConfig {
        camera: common::camera_320x240(),
        radii_mm: vec![30.0, 20.0, 12.0],
        ..SessionConfig::default()
    };
    f(&mut cfg);
    cfg
}

fn sigma_error(f: &FitFile, t: &SessionTruth) -> f64 {
    (0..3)
        .map(|c| (f.sigma0_mm[c] - t.sigma0_mm[c]).abs() / t.sigma0_mm[c])
        .fold(0.0, f64::max)
}

fn light_error(f: &FitFile, t: &SessionTruth) -> f64 {
    Vector3::from(f.light_direction)
        .angle(&Vector3::from(t.light_direction))
        .to_degrees()
}

/// Generate, optionally tamper, solve; judge against the truth.
fn run_case(
    name: &str,
    cfg: SessionConfig,
    tamper: Option<&dyn Fn(&Path)>,
    opts: impl FnOnce(&mut Options),
    sigma_tol: f64,
    light_tol_deg: f64,
) -> (Outcome, Option<FitFile>) {
    let dir = tempfile::tempdir().unwrap();
    session::generate(&cfg, dir.path(), None, true).unwrap();
    if let Some(t) = tamper {
        t(dir.path());
    }
    let truth: SessionTruth =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("truth.json")).unwrap())
            .unwrap();
    let mut o = Options::new(dir.path());
    opts(&mut o);
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| solve::run(&o)));
    let result = result.unwrap_or_else(|_| panic!("{name}: solve panicked"));
    let f = match result {
        Err(e) => {
            let msg = e.to_string();
            assert!(!msg.contains('\n'), "{name}: multi-line error {msg}");
            println!("{name}: refused: {msg}");
            return (Outcome::Refused(msg), None);
        }
        Ok(f) => f,
    };
    // Never NaN: every reported value is a number.
    let values = f
        .sigma0_mm
        .iter()
        .chain(&f.albedo)
        .chain(&f.light_direction)
        .chain([&f.eta]);
    for v in values {
        assert!(
            v.is_finite(),
            "{name}: a reported value is {v}: σ0 {:?} albedo {:?} η {} light {:?}",
            f.sigma0_mm,
            f.albedo,
            f.eta,
            f.light_direction
        );
    }
    if f.convergence.converged {
        for p in &f.parameters {
            assert!(!p.std.is_nan(), "{name}: std of {} is NaN", p.name);
        }
    }
    let (se, le) = (sigma_error(&f, &truth), light_error(&f, &truth));
    println!(
        "{name}: converged {}, σ0 {:.4?} (truth {:?}, worst {:.2}%), light {le:.3}°",
        f.convergence.converged,
        f.sigma0_mm,
        truth.sigma0_mm,
        100.0 * se
    );
    for n in &f.notes {
        println!("  note {n}");
    }
    for sp in &f.rmse.spheres {
        println!(
            "  sphere {} mm: {} pixels ({} impulses, {} saturated, {} edge left out), rel. RMSE {:.4}",
            sp.radius_mm, sp.pixels, sp.impulses, sp.saturated, sp.edge, sp.rel_rmse
        );
    }
    if f.convergence.converged && se <= sigma_tol && le <= light_tol_deg {
        return (Outcome::Accurate, Some(f));
    }
    let bound = f
        .parameters
        .iter()
        .filter(|p| p.name.starts_with("sigma0"))
        .find(|p| p.status.contains("bound"));
    let warned = f.notes.iter().find(|n| {
        n.contains("not a measurement")
            || n.contains("clipped")
            || n.contains("prior σ from")
            || n.contains("measured noise")
            || n.contains("from the camera's direction")
            || n.contains("is poorly determined")
    });
    let why = if !f.convergence.converged {
        Some("not converged".to_string())
    } else if let Some(b) = bound {
        Some(format!("{}: {}", b.name, b.status))
    } else {
        warned.cloned()
    };
    match why {
        Some(w) => (Outcome::Flagged(w), Some(f)),
        None => panic!(
            "{name}: a wrong answer reported as converged without a flag: σ0 off by {:.2}%, light {le:.3}°",
            100.0 * se
        ),
    }
}

/// The largest σ0 error in units of its stated standard error (each channel), printed.
fn sigma_error_in_std(f: &FitFile, truth: [f64; 3], name: &str) -> f64 {
    let worst = (0..3)
        .map(|c| {
            let p = f
                .parameters
                .iter()
                .find(|p| p.name == ["sigma0_r", "sigma0_g", "sigma0_b"][c])
                .unwrap();
            (f.sigma0_mm[c] - truth[c]).abs() / p.std
        })
        .fold(0.0, f64::max);
    println!("{name}: σ0 off by at most {worst:.2} of its stated std");
    worst
}

fn accurate(o: &(Outcome, Option<FitFile>), name: &str) {
    assert_eq!(o.0, Outcome::Accurate, "{name}");
}

fn flagged(o: &(Outcome, Option<FitFile>), name: &str) -> FitFile {
    assert!(matches!(o.0, Outcome::Flagged(_)), "{name}: {:?}", o.0);
    o.1.clone().unwrap()
}

#[test]
fn scattering_length_at_both_extremes_is_reported_as_a_bound() {
    // σ0 = 10⁻⁶ mm: no blur at all; the pixels' footprint is the finest the photos resolve.
    let o = run_case(
        "sigma0 1e-6",
        config(|c| c.material.sigma0_mm = [1e-6; 3]),
        None,
        |_| {},
        0.01,
        0.2,
    );
    let f = flagged(&o, "sigma0 1e-6");
    for p in f.parameters.iter().filter(|p| p.name.starts_with("sigma0")) {
        assert!(
            p.status.starts_with("upper bound"),
            "{}: {}",
            p.name,
            p.status
        );
    }
    // σ0 = 1000 mm: a uniform glow on every sphere.
    let o = run_case(
        "sigma0 1e3",
        config(|c| c.material.sigma0_mm = [1e3; 3]),
        None,
        |_| {},
        0.01,
        0.2,
    );
    // Either each σ0 is reported as a lower bound, or (the light lost with the shading's shape)
    // the fit says it did not converge.
    let f = flagged(&o, "sigma0 1e3");
    assert!(
        !f.convergence.converged
            || f.parameters
                .iter()
                .filter(|p| p.name.starts_with("sigma0"))
                .all(|p| p.status.starts_with("lower bound")),
        "{:?}",
        f.parameters
    );
}

#[test]
fn radii_from_1_to_1000_mm() {
    // Small spheres: σ = σ0/r is large and well resolved.
    let o = run_case(
        "radii 3,2,1",
        config(|c| c.radii_mm = vec![3.0, 2.0, 1.0]),
        None,
        |_| {},
        0.01,
        0.3,
    );
    accurate(&o, "radii 3,2,1");
    // Metre spheres: the blur is below a pixel, so σ0 is only bounded.
    let o = run_case(
        "radii 1000,600,300",
        config(|c| c.radii_mm = vec![1000.0, 600.0, 300.0]),
        None,
        |_| {},
        0.01,
        0.3,
    );
    let f = flagged(&o, "radii 1000,600,300");
    assert!(f
        .parameters
        .iter()
        .filter(|p| p.name.starts_with("sigma0"))
        .all(|p| p.status.starts_with("upper bound")));
}

#[test]
fn index_of_refraction_from_1_0001_to_3() {
    // η = 1.0001 against the prior 1.45 ± 0.05: σ0 within 3% (1.83% measured), and the tension
    // is reported.
    let o = run_case(
        "eta 1.0001",
        config(|c| c.material.eta = 1.0001),
        None,
        |_| {},
        0.02,
        0.2,
    );
    let f = o.1.as_ref().unwrap();
    let t = config(|_| {}).material.sigma0_mm;
    assert!((0..3).all(|c| (f.sigma0_mm[c] - t[c]).abs() < 0.03 * t[c]));
    assert!(f.notes.iter().any(|n| n.contains("prior σ from the prior")));
    // η = 3 against the default prior 1.45 ± 0.05: σ0 is right (within 1.5%, 0.46% measured, and
    // within 3 of its stated std: 0.10), η is not, and a note says so.
    let o = run_case(
        "eta 3",
        config(|c| c.material.eta = 3.0),
        None,
        |_| {},
        0.01,
        0.2,
    );
    let f = o.1.as_ref().unwrap();
    assert!(
        (0..3).all(|c| (f.sigma0_mm[c] - t[c]).abs() < 0.015 * t[c]),
        "{:?}",
        f.sigma0_mm
    );
    assert!(sigma_error_in_std(f, t, "eta 3") < 3.0);
    assert!(
        f.notes.iter().any(|n| n.contains("prior σ from the prior")),
        "{:?}",
        f.notes
    );
    // With the irradiance known η is measured (σ0 within 2.5%, 1.51% measured; η 0.008 off).
    let o = run_case(
        "eta 3, irradiance",
        config(|c| c.material.eta = 3.0),
        None,
        |o| {
            o.fit.irradiance = Some(1.0);
            o.model = workbench::solve::SolveModel::Cdrf;
        },
        0.025,
        0.2,
    );
    accurate(&o, "eta 3, irradiance");
    let eta = o.1.unwrap().eta;
    eprintln!("eta 3, irradiance: η {eta:.4}");
    assert!((eta - 3.0).abs() < 0.025, "η {eta}");
}

#[test]
fn roughness_from_0_001_to_1() {
    // A mirror-sharp lobe is sub-pixel (no usable highlight, lobe off): σ0 within 1.5% (0.87%
    // measured); a very rough one is absorbed by the diffuse term: within 1% (0.33% measured).
    accurate(
        &run_case(
            "alpha 1e-3",
            config(|c| c.material.specular.alpha = 1e-3),
            None,
            |_| {},
            0.015,
            0.2,
        ),
        "alpha 1e-3",
    );
    accurate(
        &run_case(
            "alpha 1",
            config(|c| c.material.specular.alpha = 1.0),
            None,
            |_| {},
            0.01,
            0.3,
        ),
        "alpha 1",
    );
}

#[test]
fn grazing_camera_and_back_lights() {
    let light = |az: f64, el: f64| LightAngles {
        azimuth: az.to_radians(),
        elevation: el.to_radians(),
    };
    // Grazing: the terminator runs through the middle of every sphere; σ0 is biased by 2.9%
    // (measured), which the formal standard error (0.15%) would hide: the stated one (the
    // jackknife's) covers it — 2.07 std measured, 3 allowed — and σ0 within 5%.
    let o = run_case(
        "grazing light",
        config(|c| c.light = light(89.0, 0.0)),
        None,
        |_| {},
        0.05,
        0.3,
    );
    accurate(&o, "grazing light");
    let truth = config(|_| {}).material.sigma0_mm;
    assert!(sigma_error_in_std(o.1.as_ref().unwrap(), truth, "grazing light") < 3.0);
    // Light exactly at the camera: no terminator, θ = φ everywhere (σ0 24% off measured): flagged.
    let o = run_case(
        "light at the camera",
        config(|c| c.light = light(0.0, 0.0)),
        None,
        |_| {},
        0.03,
        0.3,
    );
    let f = flagged(&o, "light at the camera");
    assert!(f
        .notes
        .iter()
        .any(|n| n.contains("from the camera's direction")));
    // Knowing η (the irradiance given) does not save it (37% measured): still flagged.
    let o = run_case(
        "light at the camera, irradiance",
        config(|c| c.light = light(0.0, 0.0)),
        None,
        |o| {
            o.fit.irradiance = Some(1.0);
            o.model = workbench::solve::SolveModel::Cdrf;
        },
        0.03,
        0.3,
    );
    let f = flagged(&o, "light at the camera, irradiance");
    assert!(f
        .notes
        .iter()
        .any(|n| n.contains("from the camera's direction")));
    // Light exactly behind the spheres: only a glowing rim, no sphere to detect.
    let o = run_case(
        "light behind",
        config(|c| c.light = light(180.0, 0.0)),
        None,
        |_| {},
        0.03,
        0.3,
    );
    match &o.0 {
        Outcome::Refused(m) => assert!(m.contains(".png"), "{m}"),
        other => panic!("light behind: {other:?}"),
    }
}

#[test]
fn saturation() {
    // Exposed 40× too long: three quarters of the sphere clipped, and a note says what that does.
    let o = run_case(
        "74% clipped",
        config(|c| c.exposure = 50.0),
        None,
        |_| {},
        0.01,
        0.2,
    );
    let f = flagged(&o, "74% clipped");
    assert!(f.notes.iter().any(|n| n.contains("clipped")));
    // Every pixel clipped: refused, naming the photo.
    let o = run_case(
        "all clipped",
        config(|c| c.exposure = 5000.0),
        None,
        |_| {},
        0.01,
        0.2,
    );
    match &o.0 {
        Outcome::Refused(m) => assert!(m.contains(".png"), "{m}"),
        other => panic!("all clipped: {other:?}"),
    }
}

/// Replace 5% of the sphere pixels (brighter than 2% of full scale) of every photo with random
/// values drawn from `seed`.
fn outliers(dir: &Path, seed: u64) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_none_or(|x| x != "png") {
            continue;
        }
        let mut img = image::open(&p).unwrap().to_rgb16();
        for px in img.pixels_mut() {
            if px.0.iter().any(|&v| v > 1300) && rng.random::<f64>() < 0.05 {
                for v in px.0.iter_mut() {
                    *v = rng.random_range(0..65535);
                }
            }
        }
        img.save(&p).unwrap();
    }
}

#[test]
fn heavy_noise_and_outliers() {
    // 20% noise at 320×240: either within 5% or flagged, and the stated std covers the σ0 error
    // (measured: converged, σ0_g 45% off at 0.49 of its std, flagged by η's note on the prior;
    // since the lights are combined (2026-12-04), σ0 41% off, flagged by the notes that σ0 and
    // the albedo are poorly determined at the combined light).
    let o = run_case(
        "20% noise",
        config(|c| c.noise = 0.2),
        None,
        |_| {},
        0.05,
        1.0,
    );
    assert!(
        matches!(o.0, Outcome::Accurate | Outcome::Flagged(_)),
        "{:?}",
        o.0
    );
    let truth = config(|_| {}).material.sigma0_mm;
    assert!(sigma_error_in_std(o.1.as_ref().unwrap(), truth, "20% noise") < 3.0);
    // 5% outlier pixels, ten draws. Measured: σ0 off by 3–36% (median 6.4%, high on nine), the
    // light by 0.04–1.2°, with the impulses left out (src/fit/observe.rs; the residuals fall from
    // about 10% to 5% of the data, σ0 barely moves: the bias is not the fitted pixels'). The fit
    // says so: its stated std covers every error (at most 1.1 of it; 3 allowed). The worst draw
    // (seed 3, 36%) is one where the impulses move the three highlights' lights 5.6° apart, far
    // beyond their errors: the detector keeps all three (a random-effects mean, ± 3.4°: before
    // 2026-12-04 it kept whichever one sphere agreed with itself, and σ0 was at most 21% off), and
    // a note says the highlights disagree.
    let mut errors = vec![];
    for seed in 1..=10u64 {
        let name = format!("5% outliers, seed {seed}");
        let tamper = |d: &Path| outliers(d, seed);
        let o = run_case(
            &name,
            config(|_| {}),
            Some(&tamper),
            |_| {},
            WORST_OUTLIER_ERROR,
            1.5,
        );
        // Not an accurate measurement (σ0 up to 36% off) but a converged one, honest about it.
        let f = o.1.unwrap();
        assert!(f.convergence.converged, "{name}: not converged");
        let truth = config(|_| {}).material.sigma0_mm;
        errors.push(
            (0..3)
                .map(|c| (f.sigma0_mm[c] - truth[c]).abs() / truth[c])
                .fold(0.0, f64::max),
        );
        assert!(sigma_error_in_std(&f, truth, &name) < 3.0, "{name}");
        if *errors.last().unwrap() > 0.21 {
            assert!(
                f.notes
                    .iter()
                    .any(|n| n.starts_with("the spheres' highlights disagree")),
                "{name}: {:?}",
                f.notes
            );
        }
    }
    println!("5% outliers: σ0 errors over ten draws {errors:.4?}");
    // Measured (2026-12-04, late): 2.8–36.3%, median 6.4%.
    errors.sort_by(f64::total_cmp);
    assert!(errors[9] < WORST_OUTLIER_ERROR, "{errors:?}");
    assert!(errors[4] < 0.12, "median {errors:?}");
}

/// The largest σ0 error accepted over the ten outlier draws (36% measured): a cap on an error
/// the fit's stated std must cover (checked per draw), not a claim of accuracy.
const WORST_OUTLIER_ERROR: f64 = 0.45;

#[test]
fn one_radius_and_two_identical_radii() {
    accurate(
        &run_case(
            "one radius",
            config(|c| c.radii_mm = vec![20.0]),
            None,
            |_| {},
            0.01,
            0.2,
        ),
        "one radius",
    );
    accurate(
        &run_case(
            "two identical radii",
            config(|c| {
                c.radii_mm = vec![20.0, 20.0];
                c.layout = session::Layout::Row;
            }),
            None,
            |_| {},
            0.01,
            0.2,
        ),
        "two identical radii",
    );
}

/// The model and its gradient stay finite over the whole range: σ0 10⁻⁶–10³ mm, radii 1–1000 mm,
/// η 1.0001–3, α 10⁻³–1, normals and views up to grazing, lights from every side.
#[test]
fn model_is_finite_over_the_extreme_ranges() {
    let model = Model::default();
    let mut n = 0;
    for &s0 in &[1e-6, 1e-3, 1.0, 30.0, 1e3] {
        for &r in &[1.0, 30.0, 1000.0] {
            for &eta in &[1.0001, 1.45, 3.0] {
                for &alpha in &[1e-3, 0.1, 1.0] {
                    for &(az, el) in &[(0.0, 0.0), (89.9, 0.0), (180.0, 0.0), (45.0, 89.9)] {
                        let mut p = Params::diffuse(
                            [s0; 3],
                            [0.5; 3],
                            eta,
                            LightAngles {
                                azimuth: f64::to_radians(az),
                                elevation: f64::to_radians(el),
                            },
                        );
                        p.material.specular.ks = 1.0;
                        p.material.specular.alpha = alpha;
                        for k in 0..24 {
                            let t = k as f64 / 23.0 * std::f64::consts::FRAC_PI_2;
                            // From facing the camera to exactly grazing.
                            let normal = Vector3::new(t.sin(), 0.3 * t.cos(), -t.cos()).normalize();
                            let g = Geometry {
                                normal,
                                view: Vector3::new(0.0, 0.0, -1.0),
                                radius_mm: r,
                            };
                            let (v, grad) = model.radiance_with_gradient(&p, &g);
                            assert!(
                                v.iter().all(|x| x.is_finite() && *x >= 0.0),
                                "σ0 {s0} r {r} η {eta} α {alpha} light {az},{el}: {v:?}"
                            );
                            assert!(
                                grad.iter().flatten().all(|x| x.is_finite()),
                                "σ0 {s0} r {r} η {eta} α {alpha} light {az},{el}: gradient"
                            );
                            n += 1;
                        }
                    }
                }
            }
        }
    }
    assert_eq!(n, 5 * 3 * 3 * 3 * 4 * 24);
}
