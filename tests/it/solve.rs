//! `workbench solve` against ground truth: synthetic sessions rendered by the project's forward
//! model with known material and light (truth.json), through detection, sampling and the fit.

use crate::common;

use nalgebra::Vector3;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use workbench::fit::joint::ExtensionChoice;
use workbench::fit::joint::{Extensions, LightFit, Reduction};
use workbench::formats::fit::{FitFile, Method};
use workbench::solve::{self, Options};
use workbench::synth::session::{self, SessionConfig, SessionTruth};

/// A 640×480 camera: a quarter of the default's pixels, so that the tests stay fast.
fn small(cfg: SessionConfig) -> SessionConfig {
    SessionConfig {
        camera: common::camera_640x480(),
        ..cfg
    }
}

fn make(cfg: SessionConfig) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    session::generate(&small(cfg), dir.path(), None, true).unwrap();
    dir
}

fn truth(dir: &Path) -> SessionTruth {
    serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap()).unwrap()
}

/// The default session (five radii, 1% noise, 16-bit PNG): generated once, and copied into a
/// temporary folder of each test's own (tests run in parallel and write beside session.json).
fn default_session() -> tempfile::TempDir {
    static TEMPLATE: OnceLock<tempfile::TempDir> = OnceLock::new();
    let template = TEMPLATE.get_or_init(|| make(SessionConfig::default()));
    let dir = tempfile::tempdir().unwrap();
    for e in std::fs::read_dir(template.path()).unwrap() {
        let p = e.unwrap().path();
        if p.is_file() {
            std::fs::copy(&p, dir.path().join(p.file_name().unwrap())).unwrap();
        }
    }
    dir
}

fn solve_with(dir: &Path, name: &str, f: impl FnOnce(&mut Options)) -> FitFile {
    let mut o = Options::new(dir);
    o.out = Some(dir.join(name));
    f(&mut o);
    solve::run(&o).unwrap()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

fn light_err(f: &FitFile, t: &SessionTruth) -> f64 {
    Vector3::from(f.light_direction)
        .angle(&Vector3::from(t.light_direction))
        .to_degrees()
}

fn worst(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (0..3).map(|c| rel(a[c], b[c])).fold(0.0, f64::max)
}

#[test]
fn joint_fit_recovers_the_truth_and_says_how_it_was_reached() {
    let guard = default_session();
    let dir = guard.path();
    let t = truth(dir);
    let f = solve_with(dir, "fit-joint.json", |_| {});
    let (es, ea, el) = (
        worst(&f.sigma0_mm, &t.sigma0_mm),
        worst(&f.albedo, &t.albedo),
        light_err(&f, &t),
    );
    println!(
        "joint: σ0 {:.4?} (worst {:.3}%), albedo worst {:.3}%, light {el:.4}°, η {:.4} ± {:.4}, ks {:.4}, α {:.4}; {:.2} s",
        f.sigma0_mm,
        100.0 * es,
        100.0 * ea,
        f.eta,
        f.std.eta,
        f.specular.unwrap().ks,
        f.specular.unwrap().alpha,
        f.timings.solve_s
    );
    assert_eq!(f.schema, "workbench.fit/1");
    assert!(f.convergence.converged);
    // Measured (2026-12-04): σ0 0.193%, albedo 0.313%, light 0.0357°.
    assert!(es < 0.006, "σ0 {es}");
    assert!(ea < 0.01, "albedo {ea}");
    assert!(el < 0.1, "light {el}°");
    let sp = f.specular.unwrap();
    // α within 1.5% (0.5% measured).
    assert!(rel(sp.alpha, t.specular.alpha) < 0.015, "α {}", sp.alpha);
    // ks carries F(η) with η at its prior: within the prior's reach.
    assert!(rel(sp.ks, t.specular.ks) < 0.1, "ks {}", sp.ks);
    // η rests on its prior (1.45 ± 0.05) and on the exit transmission T(φ), which narrows it
    // well below the prior's width (measured 1.4251 ± 0.0125 against 1.44: 1.2 std); the prior
    // alone fails the width.
    assert!(f.std.eta < 0.03, "η std {}", f.std.eta);
    assert!((f.eta - t.eta).abs() < 3.0 * f.std.eta, "η {}", f.eta);
    let eta = f.parameters.iter().find(|p| p.name == "eta").unwrap();
    assert!(eta.status.starts_with("prior 1.45"), "{}", eta.status);
    // Standard errors and correlations are there and finite.
    assert!(f.std.sigma0_mm.iter().all(|s| s.is_finite() && *s > 0.0));
    let n = f.correlation.names.len();
    assert_eq!(f.correlation.matrix.len(), n);
    for i in 0..n {
        assert!((f.correlation.matrix[i][i] - 1.0).abs() < 1e-9);
    }
    // Every sphere's residual is at the noise level (1% shot noise): not more than 3%.
    assert_eq!(f.rmse.spheres.len(), 5);
    for s in &f.rmse.spheres {
        assert!(s.rel_rmse < 0.03, "{} {}", s.image, s.rel_rmse);
    }
    // The reduction chosen keeps the predicted shift under its limit (0.3 std or the fixed
    // tolerance), with fewer observations; coarser levels tried did not.
    let red = f.reduction.as_ref().unwrap();
    assert!(red.chosen.within_tolerance);
    assert!(red.chosen.observations < red.pixels);
    for l in &red.levels {
        if l.width_deg > red.chosen.width_deg {
            assert!(!l.within_tolerance, "{l:?}");
        }
    }
    // What was reused and skipped is listed: the camera from the session's intrinsics, and the
    // detection run because there was none yet.
    assert!(
        f.skipped
            .iter()
            .any(|s| s.starts_with("calibration: camera from") && s.contains("intrinsics.json")),
        "{:?}",
        f.skipped
    );
    assert!(
        f.skipped
            .iter()
            .any(|s| s == "detection: ran (no detections.json yet)"),
        "{:?}",
        f.skipped
    );
    // Stages record their cost history.
    for st in &f.convergence.stages {
        assert!(!st.cost_history.is_empty());
        assert!(st.cost_end <= st.cost_start * (1.0 + 1e-9), "{}", st.name);
    }
    // A second run on unchanged inputs reuses detections.json.
    let again = solve_with(dir, "fit-again.json", |_| {});
    assert!(
        again
            .skipped
            .iter()
            .any(|s| s.contains("detections.json reused")),
        "{:?}",
        again.skipped
    );
    // The same fit (to the rounding of the outlines written in degrees).
    for c in 0..3 {
        assert!(rel(again.sigma0_mm[c], f.sigma0_mm[c]) < 1e-8);
    }
    // And a third run is identical to the second to the last bit: nothing depends on thread timing.
    let third = solve_with(dir, "fit-third.json", |_| {});
    assert_eq!(third.sigma0_mm, again.sigma0_mm);
    assert_eq!(third.light_direction, again.light_direction);
}

/// With the light's irradiance known, ks is fixed and η is measured from the lobe's Fresnel term
/// and the exit transmission: on a session whose η (1.60) lies three of the prior's widths from
/// its mean (1.45 ± 0.05), the fit finds the truth, and the prior alone would fail the test.
#[test]
fn a_known_irradiance_makes_eta_measurable() {
    let mut cfg = SessionConfig::default();
    cfg.material.eta = 1.60;
    let guard = make(cfg);
    let dir = guard.path();
    let t = truth(dir);
    // The synthetic light's irradiance is 1 in radiance units (ks = 1 is the physical lobe).
    let f = solve_with(dir, "fit-irradiance.json", |o| {
        o.fit.irradiance = Some(1.0);
        o.model = workbench::solve::SolveModel::Cdrf;
    });
    println!(
        "irradiance 1: η {:.4} ± {:.4} (truth {}), σ0 worst {:.3}%",
        f.eta,
        f.std.eta,
        t.eta,
        100.0 * worst(&f.sigma0_mm, &t.sigma0_mm)
    );
    assert_eq!(t.eta, 1.60);
    // Measured (2026-12-04): 1.5985 ± 0.0007, 0.0015 off (2.1 of its std); σ0 0.37% off.
    let err = (f.eta - t.eta).abs();
    assert!(err < 0.005, "η {}", f.eta);
    // Its stated std covers the error and is not the prior's.
    assert!(
        err < 3.0 * f.std.eta && f.std.eta < 0.005,
        "η std {}",
        f.std.eta
    );
    let ks = f.parameters.iter().find(|p| p.name == "ks").unwrap();
    assert!(ks.status.starts_with("fixed"), "{}", ks.status);
    assert!(worst(&f.sigma0_mm, &t.sigma0_mm) < 0.01);
}

#[test]
fn a_bad_start_still_converges() {
    let guard = default_session();
    let dir = guard.path();
    let t = truth(dir);
    // Light 30° off the truth (70°, 20°) and σ0 ten times too large.
    let f = solve_with(dir, "fit-bad-start.json", |o| {
        o.fit.start_light = Some(workbench::model::LightAngles {
            azimuth: 40f64.to_radians(),
            elevation: 15f64.to_radians(),
        });
        o.fit.start_sigma0 = Some(t.sigma0_mm.map(|s| 10.0 * s));
    });
    println!(
        "bad start: σ0 worst {:.3}%, light {:.4}°, {} stages",
        100.0 * worst(&f.sigma0_mm, &t.sigma0_mm),
        light_err(&f, &t),
        f.convergence.stages.len()
    );
    assert!(f.convergence.converged);
    // Measured (2026-12-04): σ0 0.193% off at worst, the light 0.0357°: as from the default start.
    assert!(worst(&f.sigma0_mm, &t.sigma0_mm) < 0.006);
    assert!(light_err(&f, &t) < 0.1);
}

#[test]
fn paper_baseline_and_holdout() {
    // The paper's procedure assumes the bare clamped cosine (as this session is rendered): from
    // photos rendered with the entry transmission its per-radius σ0 comes out 40–60% low (35 mm:
    // 2.50, 1.51, 0.83 mm against 4, 3, 2.2; measured 2026-12-01).
    let session = make(SessionConfig {
        entry_transmission: false,
        ..SessionConfig::default()
    });
    let dir = session.path();
    let t = truth(dir);
    let p = solve_with(dir, "fit-paper.json", |o| o.method = Method::Paper);
    let pr = p.per_radius.as_ref().unwrap();
    assert_eq!(pr.len(), 5);
    for r in pr {
        println!(
            "paper r {}: σ0 {:.3?} (σ {:.4?} rad), albedo {:.3?}",
            r.radius_mm, r.sigma0_mm, r.sigma_rad, r.albedo
        );
        assert!((r.sigma_rad[1] * r.radius_mm - r.sigma0_mm[1]).abs() < 1e-9);
        // Each radius within 6% (2.1% measured at worst).
        assert!(worst(&r.sigma0_mm, &t.sigma0_mm) < 0.06);
    }
    assert!(p.specular.is_none());
    assert_eq!(p.method, Method::Paper);
    // The light is the detector's, not refined.
    let d: workbench::formats::detections::Detections =
        serde_json::from_str(&std::fs::read_to_string(dir.join("detections.json")).unwrap())
            .unwrap();
    let dl = Vector3::from(d.light_direction.unwrap());
    assert!(Vector3::from(p.light_direction).angle(&dl) < 1e-9);
    // The joint fit with the light held: the detector's light, σ0 still within 1%.
    // (the joint fits here with the model the session was rendered with).
    let held = solve_with(dir, "fit-hold.json", |o| {
        o.fit.light_fit = LightFit::Hold;
        o.fit.baseline = true;
        o.fit.entry_transmission = false;
    });
    assert!(Vector3::from(held.light_direction).angle(&dl) < 1e-9);
    // The baseline written beside a joint fit is the paper's method's own result.
    let b = held.baseline.as_ref().unwrap();
    assert_eq!(&b.per_radius, pr);
    assert!(Vector3::from(p.light_direction).angle(&b.params_for(35.0).light.direction()) < 1e-9);
    assert!(worst(&held.sigma0_mm, &t.sigma0_mm) < 0.01);
    let az = held
        .parameters
        .iter()
        .find(|p| p.name == "light_azimuth")
        .unwrap();
    assert_eq!(az.status, "fixed: from the detector");
    // Holdout: fit without the 15 mm sphere, predict it.
    let h = solve_with(dir, "fit-holdout.json", |o| {
        o.holdout = Some(15.0);
        o.fit.entry_transmission = false;
    });
    // Without --baseline or --plots the baseline is not run.
    assert!(h.baseline.is_none());
    let ho = h.holdout.as_ref().unwrap();
    let fitted: Vec<f64> = h
        .rmse
        .spheres
        .iter()
        .filter(|s| !s.held_out)
        .map(|s| s.rel_rmse)
        .collect();
    let mean = fitted.iter().sum::<f64>() / fitted.len() as f64;
    println!(
        "holdout 15 mm: rel. RMSE {:.4} (lit {:.4}, unlit {:.4}); fitted spheres {mean:.4}",
        ho.rel_rmse, ho.lit_rel_rmse, ho.unlit_rel_rmse
    );
    assert!(ho.rel_rmse < 1.5 * mean, "{} vs {mean}", ho.rel_rmse);
    assert_eq!(h.rmse.spheres.iter().filter(|s| s.held_out).count(), 1);
    // A radius that is not there is refused.
    let mut o = Options::new(dir);
    o.out = Some(dir.join("never.json"));
    o.holdout = Some(17.0);
    let e = solve::run(&o).unwrap_err().to_string();
    assert!(e.contains("--holdout 17") && !e.contains('\n'), "{e}");
    assert!(!dir.join("never.json").exists());
}

#[test]
fn every_pixel_and_the_chosen_reduction_agree() {
    let guard = default_session();
    let dir = guard.path();
    let auto = solve_with(dir, "fit-auto.json", |_| {});
    let all = solve_with(dir, "fit-all.json", |o| o.fit.reduction = Reduction::None);
    let coarse = solve_with(dir, "fit-4deg.json", |o| {
        o.fit.reduction = Reduction::Factor(16)
    });
    let z = |f: &FitFile| {
        (0..3)
            .map(|c| (f.sigma0_mm[c] - all.sigma0_mm[c]).abs() / all.std.sigma0_mm[c])
            .fold(0.0, f64::max)
    };
    println!(
        "σ0 against every pixel: auto ({}° cells, {} obs) {:.2} std, 4° cells {:.2} std; every pixel {} obs",
        auto.reduction.as_ref().unwrap().chosen.width_deg,
        auto.reduction.as_ref().unwrap().chosen.observations,
        z(&auto),
        z(&coarse),
        all.reduction.as_ref().unwrap().chosen.observations
    );
    // Auto accepts a shift of 0.3 std or 0.1% (the tolerance): allow twice that.
    for c in 0..3 {
        let d = (auto.sigma0_mm[c] - all.sigma0_mm[c]).abs();
        let allowed = (0.3 * all.std.sigma0_mm[c]).max(1e-3 * all.sigma0_mm[c]);
        assert!(d < 2.0 * allowed, "channel {c}: {d} vs {allowed}");
    }
    assert!(z(&coarse) > z(&auto));
}

#[test]
fn no_highlight_no_lobe_and_the_light_from_shading() {
    let dir = make(SessionConfig {
        radii_mm: vec![35.0, 25.0, 15.0],
        material: workbench::model::Material {
            specular: workbench::model::SpecularParams {
                ks: 0.0,
                alpha: 0.1,
            },
            ..SessionConfig::default().material
        },
        ..SessionConfig::default()
    });
    let t = truth(dir.path());
    let f = solve_with(dir.path(), "fit.json", |_| {});
    println!(
        "no highlight: σ0 worst {:.3}%, light {:.4}°",
        100.0 * worst(&f.sigma0_mm, &t.sigma0_mm),
        light_err(&f, &t)
    );
    assert!(f.specular.is_none());
    let ks = f.parameters.iter().find(|p| p.name == "ks").unwrap();
    assert!(ks.status.starts_with("off"), "{}", ks.status);
    assert!(f
        .skipped
        .iter()
        .any(|s| s.starts_with("specular lobe: off")));
    // Measured (2026-12-04): σ0 0.456% off at worst, the light 0.0102°.
    assert!(worst(&f.sigma0_mm, &t.sigma0_mm) < 0.01);
    assert!(light_err(&f, &t) < 0.03, "light {}°", light_err(&f, &t));
}

#[test]
fn one_radius_still_fits_with_a_wider_uncertainty() {
    let dir = make(SessionConfig {
        radii_mm: vec![25.0],
        ..SessionConfig::default()
    });
    let t = truth(dir.path());
    let f = solve_with(dir.path(), "fit.json", |o| {
        o.fit.extensions = ExtensionChoice::On(Extensions {
            sigma_exponent: true,
            albedo_curvature: false,
            two_gaussian: false,
        })
    });
    let guard = default_session();
    let five = solve_with(guard.path(), "fit-five.json", |_| {});
    println!(
        "one radius: σ0 {:.4?} ± {:.4?}; five radii ± {:.4?}",
        f.sigma0_mm, f.std.sigma0_mm, five.std.sigma0_mm
    );
    assert!(f.convergence.converged);
    // Measured (2026-12-04): 0.11% off at worst, each channel within 1 of its stated std.
    assert!(worst(&f.sigma0_mm, &t.sigma0_mm) < 0.004);
    for c in 0..3 {
        let err = (f.sigma0_mm[c] - t.sigma0_mm[c]).abs();
        assert!(
            err < 3.0 * f.std.sigma0_mm[c],
            "σ0[{c}] {err} off, std {}",
            f.std.sigma0_mm[c]
        );
    }
    // Against the five radii's formal std (the jackknife needs three radii; one has none).
    let five_formal = five
        .parameters
        .iter()
        .find(|p| p.name == "sigma0_g")
        .and_then(|p| p.std_formal)
        .unwrap();
    assert_eq!(f.std_source, "formal");
    assert!(f.std.sigma0_mm[1] > five_formal, "{five_formal}");
    // An extension is never fitted from one radius.
    assert!(f.sigma_exponent.is_none());
    assert!(f.notes.iter().any(|n| n.contains("need at least 3")));
}

#[test]
fn extensions_are_chosen_by_held_out_error() {
    // Truth with σ·r growing as r shrinks (q = 0.6): the plain model cannot follow it.
    let mut m = SessionConfig::default().material;
    m.sigma_exponent = 0.6;
    let dir = make(SessionConfig {
        radii_mm: vec![35.0, 28.0, 21.0, 15.0],
        material: m,
        ..SessionConfig::default()
    });
    let f = solve_with(dir.path(), "fit.json", |o| {
        o.fit.extensions = ExtensionChoice::Auto
    });
    let mc = f.model_choice.as_ref().unwrap();
    for c in &mc.candidates {
        println!("  {}: held-out {:.4}", c.extensions, c.heldout_rel_rmse);
    }
    println!(
        "chosen {} ({}), q = {:?} ± {:?}",
        mc.chosen, mc.reason, f.sigma_exponent, f.std.sigma_exponent
    );
    assert!(mc.chosen.contains("sigma-exponent"), "{}", mc.chosen);
    // Measured 0.601 ± 0.0013 with the light refined; 0.595 ± 0.012 since the light is held at
    // its combination with the detector's (2026-12-04), whose error q now carries.
    let q_std = f.std.sigma_exponent.unwrap();
    assert!(q_std < 0.04, "q ± {q_std}");
    assert!((f.sigma_exponent.unwrap() - 0.6).abs() < 3.0 * q_std);
    // On plain data the plain model is kept.
    let guard = default_session();
    let plain = solve_with(guard.path(), "fit-ext.json", |o| {
        o.fit.extensions = ExtensionChoice::Auto
    });
    let pc = plain.model_choice.as_ref().unwrap();
    println!("plain data: chosen {} ({})", pc.chosen, pc.reason);
    assert_eq!(pc.chosen, "plain");
    assert!(plain.sigma_exponent.is_none());
}

/// A PNG's size, and whether it holds a picture: many dark pixels and many colours.
fn png_check(path: &Path, size: Option<(u32, u32)>) {
    let png = image::open(path).unwrap().to_rgb8();
    if let Some(s) = size {
        assert_eq!(png.dimensions(), s, "{}", path.display());
    }
    let dark = png
        .pixels()
        .filter(|p| p.0.iter().any(|&v| v < 128))
        .count();
    let colours: std::collections::HashSet<[u8; 3]> = png.pixels().map(|p| p.0).collect();
    assert!(
        dark > 1000 && colours.len() > 50,
        "{}: {dark} dark pixels, {} colours",
        path.display(),
        colours.len()
    );
}

fn svg_has(dir: &Path, name: &str, texts: &[&str]) {
    let svg = std::fs::read_to_string(dir.join(format!("{name}.svg"))).unwrap();
    for t in texts {
        assert!(svg.contains(t), "{name}.svg lacks {t:?}");
    }
}

#[test]
fn figures_are_written_and_redrawn_from_fit_json() {
    let guard = default_session();
    let dir = guard.path();
    let plots: PathBuf = dir.join("plots");
    let fit_path = dir.join("fit-plots.json");
    let f = solve_with(dir, "fit-plots.json", |o| {
        o.plots = Some(plots.clone());
        o.holdout = Some(15.0);
    });
    // The baseline ran beside the joint fit.
    assert_eq!(f.baseline.as_ref().unwrap().per_radius.len(), 4);
    png_check(&plots.join("radiance-theta.png"), Some((1700, 1040)));
    svg_has(
        &plots,
        "radiance-theta",
        &[
            "θ, normal to light (°)",
            "radiance (pixel value / exposure)",
            "r = 35 mm",
            "r = 15 mm, held out",
            "joint fit, mean per 1°",
            "paper&apos;s baseline",
            "near the terminator",
        ],
    );
    for (name, axis) in [
        ("residual-theta", "θ, normal to light (°)"),
        ("residual-phi", "φ, normal to view (°)"),
    ] {
        png_check(&plots.join(format!("{name}.png")), Some((1500, 820)));
        svg_has(
            &plots,
            name,
            &[
                axis,
                "data − model (% of peak)",
                "r = 20 mm",
                "red channel, running median (3°)",
                "blue channel, running median (3°)",
            ],
        );
    }
    png_check(&plots.join("correlation.png"), None);
    svg_has(&plots, "correlation", &["σ0 r", "1.00", "correlation"]);
    // The light's angles are in the matrix where the fit refined them, not where they were held
    // at the combination with the detector's.
    let svg = std::fs::read_to_string(plots.join("correlation.svg")).unwrap();
    assert_eq!(
        svg.contains("light az"),
        f.light_fit != "prior, then combined",
        "{}",
        f.light_fit
    );
    png_check(&plots.join("holdout.png"), Some((1000, 760)));
    svg_has(
        &plots,
        "holdout",
        &[
            "observed radiance",
            "predicted radiance",
            "predicted = observed",
            "r = 15 mm",
        ],
    );
    // One residual image per sphere, the photo and the map embedded as PNGs with the colour bar.
    let mut images: Vec<String> = std::fs::read_dir(&plots)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().to_string())
        .filter(|n| {
            n.starts_with("residual-")
                && n.ends_with(".png")
                && !n.contains("theta")
                && !n.contains("phi")
        })
        .collect();
    images.sort();
    assert_eq!(images.len(), 5, "{images:?}");
    for n in &images {
        png_check(&plots.join(n), Some((1400, 560)));
        let stem = n.trim_end_matches(".png");
        svg_has(&plots, stem, &["residual (% of peak)", "no data", "x (px)"]);
        let svg = std::fs::read_to_string(plots.join(format!("{stem}.svg"))).unwrap();
        assert_eq!(svg.matches("data:image/png;base64,").count(), 3, "{stem}");
    }
    let index = std::fs::read_to_string(plots.join("index.html")).unwrap();
    for n in images.iter().map(|s| s.as_str()).chain([
        "radiance-theta.png",
        "residual-phi.png",
        "correlation.png",
        "holdout.png",
        "sigma0_r",
        "prior 1.45 ± 0.05",
        "held out",
    ]) {
        assert!(index.contains(n), "index.html lacks {n}");
    }
    assert!(!index.contains("http"), "index.html links outside");
    // Redrawn from fit.json without solving: the same pictures, byte for byte.
    let again = dir.join("replot");
    let files = workbench::solve::replot(&fit_path, &again, true).unwrap();
    for file in files
        .iter()
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
    {
        let name = file.file_name().unwrap();
        assert_eq!(
            std::fs::read(file).unwrap(),
            std::fs::read(plots.join(name)).unwrap(),
            "{name:?} differs"
        );
    }
    // A fit.json that is not one: refused with the file named.
    let bad = dir.join("not-a-fit.json");
    std::fs::write(&bad, r#"{"schema": "workbench.fit/0"}"#).unwrap();
    let e = workbench::solve::replot(&bad, &dir.join("never"), true)
        .unwrap_err()
        .to_string();
    assert!(e.contains("not-a-fit.json") && !e.contains('\n'), "{e}");
    assert!(!dir.join("never").exists());
}

#[test]
fn an_unchanged_rerun_reuses_fit_json() {
    let guard = default_session();
    let dir = guard.path();
    let first = solve_with(dir, "fit-cache.json", |_| {});
    assert!(!first.skipped.iter().any(|s| s.starts_with("solve:")));
    let second = solve_with(dir, "fit-cache.json", |_| {});
    assert!(
        second.skipped[0].starts_with("solve:") && second.skipped[0].contains("reused"),
        "{:?}",
        second.skipped
    );
    assert_eq!(second.sigma0_mm, first.sigma0_mm);
    assert_eq!(second.options, solve::fingerprint(&Options::new(dir)));
    // Other options: solved again.
    let other = solve_with(dir, "fit-cache.json", |o| o.fit.light_fit = LightFit::Hold);
    assert!(!other.skipped.iter().any(|s| s.starts_with("solve:")));
    // --redetect: solved again.
    let again = solve_with(dir, "fit-cache.json", |o| {
        o.fit.light_fit = LightFit::Hold;
        o.redetect = true;
    });
    assert!(!again.skipped.iter().any(|s| s.starts_with("solve:")));
}

/// On a fresh folder the fit takes the photos detection decoded; with detections.json reused it
/// decodes them itself: the two fits are the same to the bit.
#[test]
fn the_photos_decoded_once_fit_as_decoded_apart() {
    let guard = default_session();
    let dir = guard.path();
    let no_jackknife =
        |o: &mut Options| o.fit.jackknife = workbench::fit::joint::JackknifeMethod::Off;
    let shared = solve_with(dir, "fit-shared.json", no_jackknife);
    let apart = solve_with(dir, "fit-apart.json", no_jackknife);
    let said = |f: &FitFile, what: &str| f.skipped.iter().any(|s| s.contains(what));
    assert!(said(&shared, "detection: ran"), "{:?}", shared.skipped);
    assert!(
        said(&apart, "detections.json reused"),
        "{:?}",
        apart.skipped
    );
    assert_eq!(shared.parameters, apart.parameters);
    assert_eq!(shared.rmse, apart.rmse);
    assert!(shared.timings.decode_s > 0.0 && apart.timings.decode_s > 0.0);
}

/// A per-image-light session: each radius of `radii` rendered alone (from `base`) under its light
/// of `lights`, then put together with `"light": "per-image"`; `edit` may change each photo (its
/// path) and its session.json entry before they are joined.
fn per_image_session(
    base: &SessionConfig,
    radii: &[f64],
    lights: &[workbench::model::LightAngles],
    edit: impl Fn(&Path, &mut serde_json::Value),
) -> tempfile::TempDir {
    let per = tempfile::tempdir().unwrap();
    let mut images = vec![];
    for (k, (&r, &l)) in radii.iter().zip(lights).enumerate() {
        let one = make(SessionConfig {
            radii_mm: vec![r],
            light: l,
            seed: 10 + k as u64,
            ..base.clone()
        });
        let s: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(one.path().join("session.json")).unwrap(),
        )
        .unwrap();
        let mut entry = s["images"][0].clone();
        let file = entry["file"].as_str().unwrap().to_string();
        std::fs::copy(one.path().join(&file), per.path().join(&file)).unwrap();
        std::fs::copy(
            one.path().join("intrinsics.json"),
            per.path().join("intrinsics.json"),
        )
        .unwrap();
        edit(&per.path().join(&file), &mut entry);
        images.push(entry);
    }
    let sess = serde_json::json!({
        "schema": "workbench.session/1",
        "intrinsics": "intrinsics.json",
        "light": "per-image",
        "images": images,
    });
    std::fs::write(
        per.path().join("session.json"),
        serde_json::to_string_pretty(&sess).unwrap(),
    )
    .unwrap();
    per
}

/// `"light": "per-image"`: three spheres, each photographed under its own light, recover σ0 as
/// well as the same three under one light, and each photo's light is its own.
#[test]
fn one_light_per_photo() {
    use workbench::model::LightAngles;
    let radii = [35.0, 25.0, 15.0];
    let lights = [(70.0, 20.0), (-40.0, 35.0), (20.0, 50.0)];
    let angles = |(az, el): (f64, f64)| LightAngles {
        azimuth: f64::to_radians(az),
        elevation: f64::to_radians(el),
    };
    let base = SessionConfig {
        radii_mm: radii.to_vec(),
        noise: 0.005,
        ..SessionConfig::default()
    };
    let shared = make(base.clone());
    let f_shared = solve_with(shared.path(), "fit.json", |o| {
        o.fit.jackknife = workbench::fit::joint::JackknifeMethod::Off
    });
    let t = truth(shared.path());
    let per = per_image_session(&base, &radii, &lights.map(angles), |_, _| {});
    let f_per = solve_with(per.path(), "fit.json", |o| {
        o.fit.jackknife = workbench::fit::joint::JackknifeMethod::Off
    });
    let e_shared = worst(&f_shared.sigma0_mm, &t.sigma0_mm);
    let e_per = worst(&f_per.sigma0_mm, &t.sigma0_mm);
    println!(
        "σ0 worst relative error: shared light {:.3}%, one light per photo {:.3}%",
        100.0 * e_shared,
        100.0 * e_per
    );
    assert_eq!(f_per.image_lights.len(), 3);
    for (il, &l) in f_per.image_lights.iter().zip(&lights) {
        let dl = Vector3::from(il.direction)
            .angle(&angles(l).direction())
            .to_degrees();
        println!("{}: light {dl:.4}° from its truth", il.file);
        assert!(dl < 0.1, "{}: {dl}°", il.file);
    }
    // Measured 0.45% (one light per photo) and 0.43% (shared).
    assert!(e_per < 2.0 * e_shared.max(0.002), "{e_per} vs {e_shared}");
    assert!(e_per < 0.012, "{e_per}");
}

/// The tabulated CDRF (the default) fits as the closed form does: on the default session every
/// fitted parameter agrees within a hundredth of its standard error.
#[test]
fn tabulated_cdrf_fits_as_the_closed_form() {
    let guard = default_session();
    let dir = guard.path();
    let a = solve_with(dir, "fit-table.json", |o| {
        o.fit.jackknife = workbench::fit::joint::JackknifeMethod::Off
    });
    let b = solve_with(dir, "fit-closed.json", |o| {
        o.fit.jackknife = workbench::fit::joint::JackknifeMethod::Off;
        o.fit.tabulated = false;
    });
    assert!(a.options.contains("cdrf table") && b.options.contains("cdrf closed form"));
    let mut worst = (0.0f64, String::new());
    for (p, q) in a.parameters.iter().zip(&b.parameters) {
        assert_eq!(p.name, q.name);
        if p.std > 0.0 {
            let d = (p.value - q.value).abs() / p.std;
            if d > worst.0 {
                worst = (d, p.name.clone());
            }
        }
    }
    println!("largest difference: {:.2e} std ({})", worst.0, worst.1);
    // Goal 0.01; measured 3.5e-4 (sigma0_b; 1.6e-4 before the kernel's lanes).
    assert!(worst.0 < 1e-3, "{worst:?}");
}

/// A 16-bit photo's pixel values times `k` per channel, as under a weaker, tinted lamp.
fn dim(photo: &Path, k: [f64; 3]) {
    let img = image::open(photo).unwrap().into_rgb16();
    let dimmed = image::ImageBuffer::from_fn(img.width(), img.height(), |x, y| {
        let p = img.get_pixel(x, y);
        image::Rgb([0, 1, 2].map(|c| (p[c] as f64 * k[c]).round() as u16))
    });
    dimmed.save(photo).unwrap();
}

/// Per-photo light intensities (issue 34: DiLiGenT's `light_intensities.txt`): one photo of a
/// session dimmed per channel, as a weaker, tinted lamp would, and its `light_intensity` given in
/// session.json, fits as the undimmed session does; without it the fit does not.
#[test]
fn a_photos_light_intensity_divides_its_radiance() {
    let guard = default_session();
    let dir = guard.path();
    let no_jackknife =
        |o: &mut Options| o.fit.jackknife = workbench::fit::joint::JackknifeMethod::Off;
    let plain = solve_with(dir, "fit-plain.json", no_jackknife);
    let intensity = [0.5, 0.7, 0.9];
    dim(&dir.join("r25.png"), intensity);
    std::fs::remove_file(dir.join("detections.json")).unwrap();
    let sess_path = dir.join("session.json");
    let mut sess: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&sess_path).unwrap()).unwrap();
    let without = serde_json::to_string_pretty(&sess).unwrap();
    let k = sess["images"]
        .as_array()
        .unwrap()
        .iter()
        .position(|im| im["file"] == "r25.png")
        .unwrap();
    sess["images"][k]["light_intensity"] = serde_json::json!(intensity);
    std::fs::write(&sess_path, serde_json::to_string_pretty(&sess).unwrap()).unwrap();
    let given = solve_with(dir, "fit-given.json", no_jackknife);
    std::fs::write(&sess_path, without).unwrap();
    let ignored = solve_with(dir, "fit-ignored.json", no_jackknife);
    let apart = |f: &FitFile| {
        (0..3)
            .map(|c| (f.sigma0_mm[c] - plain.sigma0_mm[c]).abs() / plain.std.sigma0_mm[c])
            .chain((0..3).map(|c| (f.albedo[c] - plain.albedo[c]).abs() / plain.std.albedo[c]))
            .fold(0.0, f64::max)
    };
    println!(
        "σ0 and albedo from the undimmed fit, in its std: intensity given {:.2}, ignored {:.1}",
        apart(&given),
        apart(&ignored)
    );
    // Measured 0.59 (given: the dimmed photo's outline and noise are its own) against 90
    // (ignored).
    assert!(apart(&given) < 1.8, "{}", apart(&given));
    assert!(apart(&ignored) > 20.0, "{}", apart(&ignored));
}

/// DiLiGenT's glossy ball as a whole solve (issue 34): 48 real photos, one light per photo, each
/// photo's lamp intensity from the dataset's `light_intensities.txt`, radius 20 mm, no intrinsics.
/// Checked: the detector's lights against DiLiGenT's calibrated directions
/// ([`super::detect::diligent_ball_lights`], on the detections.json this solve wrote), the fit
/// converges, the lobe is fitted, σ0 is the small blur of an opaque ball, the solved lights
/// against the calibrated directions, and the residuals against the noise said in a note.
#[test]
fn diligent_ball_whole_solve() {
    let Some(data) = common::shared_data() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (_, truth) = common::diligent_session_with(&data.join("diligent-ball"), dir.path(), true);
    let f = solve_with(dir.path(), "fit.json", |o| o.quiet = true);
    let d: workbench::formats::detections::Detections =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("detections.json")).unwrap())
            .unwrap();
    super::detect::diligent_ball_lights(&d, &truth);
    let errs: Vec<f64> = f
        .image_lights
        .iter()
        .zip(&truth)
        .map(|(il, t)| {
            Vector3::from(il.direction)
                .angle(&Vector3::from(*t))
                .to_degrees()
        })
        .collect();
    let mean = errs.iter().sum::<f64>() / errs.len() as f64;
    let max = errs.iter().cloned().fold(0.0, f64::max);
    let spec = f.specular.expect("the lobe is fitted");
    let chi = f.convergence.chi2_per_dof.expect("χ²/dof").sqrt();
    let status = |name: &str| {
        f.parameters
            .iter()
            .find(|p| p.name == name)
            .map(|p| p.status.clone())
            .unwrap()
    };
    println!(
        "DiLiGenT ball, whole solve: converged {}, lights mean {mean:.3}° max {max:.3}° from the calibrated ones ({}), ks {:.4}, α {:.4}, σ0 {:?} mm, residuals {chi:.2}× the noise, {:.1} s",
        f.convergence.converged, f.light_fit, spec.ks, spec.alpha, f.sigma0_mm, f.timings.total_s
    );
    assert!(f.convergence.converged);
    assert_eq!(errs.len(), 48);
    // Measured: mean 0.615°, max 1.16° (the detector's lights, held: the shading pulled the
    // shared correction 14 of its errors). The issue's goal is 0.5°: not reached.
    assert!(mean < 0.7 && max < 1.5, "mean {mean}° max {max}°");
    // Measured α 0.0525 ± 0.0032, ks 0.111.
    assert!((0.035..0.075).contains(&spec.alpha), "α {}", spec.alpha);
    assert_eq!(status("alpha"), "fitted");
    // An opaque ball: a blur of a few pixels' angle at most (measured 0.56, 0.24, 0.16 mm; the
    // two smaller reported as upper bounds).
    assert!(f.sigma0_mm.iter().all(|&s| s < 1.0), "{:?}", f.sigma0_mm);
    assert!(status("sigma0_b").starts_with("upper bound"));
    // Residuals 2.2× the noise (measured): above 1.5, so a note must say the model falls short.
    assert!(chi > 1.5 && chi < 3.5, "{chi}");
    assert!(f.notes.iter().any(|n| n.contains("× the measured noise")));
    // And where: at the highlight (measured 15.2× the noise there, 2.2× on the lit side), a
    // glossy paint's peak that one GGX lobe does not follow.
    assert!(
        f.notes.iter().any(|n| n.contains("worst at the highlight")),
        "{:?}",
        f.notes
    );
}

/// A per-image-light session whose lamps differ and are not given (issue 34: DiLiGenT without
/// `light_intensities.txt` went degenerate): each photo's intensity per channel is fitted, up to
/// one common scale, and σ0 comes out as with the lamps alike.
#[test]
fn lamp_intensities_not_given_are_fitted() {
    use workbench::model::LightAngles;
    let radii = [35.0, 25.0, 15.0];
    let lamps = [[1.0, 1.0, 1.0], [0.5, 0.7, 0.9], [0.8, 0.6, 0.75]];
    let lights =
        [(70.0, 20.0), (-40.0, 35.0), (20.0, 50.0)].map(|(az, el): (f64, f64)| LightAngles {
            azimuth: az.to_radians(),
            elevation: el.to_radians(),
        });
    let base = SessionConfig {
        radii_mm: radii.to_vec(),
        noise: 0.005,
        ..SessionConfig::default()
    };
    let per = per_image_session(&base, &radii, &lights, |photo, entry| {
        let k = radii
            .iter()
            .position(|&r| entry["spheres"][0]["radius_mm"] == r)
            .unwrap();
        dim(photo, lamps[k]);
    });
    let f = solve_with(per.path(), "fit.json", |o| {
        o.fit.jackknife = workbench::fit::joint::JackknifeMethod::Off
    });
    let t = base.material.sigma0_mm;
    // Each channel's lamps over their geometric mean, fitted and true.
    let normalised = |v: Vec<[f64; 3]>| -> Vec<[f64; 3]> {
        let g: [f64; 3] = std::array::from_fn(|c| {
            (v.iter().map(|k| k[c].ln()).sum::<f64>() / v.len() as f64).exp()
        });
        v.iter()
            .map(|k| std::array::from_fn(|c| k[c] / g[c]))
            .collect()
    };
    let fitted = normalised(
        f.image_lights
            .iter()
            .map(|il| {
                assert_eq!(il.intensity_source.as_deref(), Some("fitted"));
                il.intensity.unwrap()
            })
            .collect(),
    );
    let true_lamps = normalised(lamps.to_vec());
    let off = fitted
        .iter()
        .zip(&true_lamps)
        .flat_map(|(a, b)| (0..3).map(move |c| (a[c] / b[c] - 1.0).abs()))
        .fold(0.0, f64::max);
    let e = worst(&f.sigma0_mm, &t);
    println!(
        "lamps fitted within {:.3}% of the truth; σ0 worst {:.3}%",
        100.0 * off,
        100.0 * e
    );
    assert!(f.convergence.converged);
    // Measured: the lamps within 0.47%, σ0 within 0.088% (the lamps alike, one_light_per_photo:
    // 0.40%); since the lights are combined (2026-12-04), σ0 within 0.37%: the light held at the
    // combination with the photos' detector lights.
    assert!(off < 0.015, "{off}");
    assert!(e < 0.011, "{e}");
}

/// Issue 34's scene, as a user made it: the default session (1280×960, seed 1) composited onto a
/// graded grey backdrop (8–22% of full scale) by a hard mask, each sphere's ideal ellipse (the
/// photos are distorted, so the mask lies up to about half a pixel off the outline: a disturbed
/// rim), and an 8 px stand at 30% of full scale under every other photo's sphere.
fn composite_with_stand(dir: &Path, width_px: f64, level: f64) {
    let t = truth(dir);
    for (k, im) in t.images.iter().enumerate() {
        let path = dir.join(&im.file);
        let img = image::open(&path).unwrap().into_rgb16();
        let (w, h) = (img.width() as f64, img.height() as f64);
        let inside = |x: f64, y: f64| {
            im.spheres.iter().any(|s| {
                let e = &s.ellipse;
                let th = e.angle_deg.to_radians();
                let (dx, dy) = (x - e.center_px[0], y - e.center_px[1]);
                let u = dx * th.cos() + dy * th.sin();
                let v = -dx * th.sin() + dy * th.cos();
                (u / e.axes_px[0]).powi(2) + (v / e.axes_px[1]).powi(2) <= 1.0
            })
        };
        let on_stand = |x: f64, y: f64| {
            k % 2 == 0
                && im.spheres.iter().any(|s| {
                    let e = &s.ellipse;
                    (x - e.center_px[0]).abs() <= width_px / 2.0
                        && y >= e.center_px[1] + e.axes_px[0].max(e.axes_px[1])
                })
        };
        let out = image::ImageBuffer::from_fn(img.width(), img.height(), |xi, yi| {
            let (x, y) = (xi as f64, yi as f64);
            let p = img.get_pixel(xi, yi);
            let value = |c: usize| {
                let a = p[c] as f64 / 65535.0;
                let v = if on_stand(x, y) {
                    level
                } else if inside(x, y) {
                    a
                } else {
                    a + 0.08 + 0.14 * (0.5 * x / w + 0.5 * y / h)
                };
                (v.clamp(0.0, 1.0) * 65535.0).round() as u16
            };
            image::Rgb([value(0), value(1), value(2)])
        });
        out.save(&path).unwrap();
    }
}

/// A disturbed outline (issue 34, [`composite_with_stand`]): each sphere's highlight light is
/// moved its own way, 0.13–0.86° against stated errors of 0.015–0.04°. Once the detector set
/// most of them aside and kept the two or three that agreed: 0.36° off, stating ± 0.043°. Now it
/// keeps all five as a random-effects mean whose error is their scatter (± 0.17°), says so in a
/// note, and the shading, whose error is the smaller, decides the light. Measured (2026-12-04):
/// detector 0.036° ± 0.168° (scatter τ 0.37°), light 0.070° ± 0.062° (1.1 std), σ0 0.41, 0.55,
/// 0.87% low (0.7–0.8 std); over seeds 1–8 and stands 4, 8, 14 px wide: light 0.037–0.073° at
/// 0.4–1.2 std, σ0 0.20–1.41% low within 0.9 std (docs/uncertainty.md, "The detector's light and
/// the shading's").
#[test]
fn a_disturbed_outline_leaves_the_light_to_the_shading() {
    let dir = tempfile::tempdir().unwrap();
    session::generate(&SessionConfig::default(), dir.path(), None, true).unwrap();
    composite_with_stand(dir.path(), 8.0, 0.3);
    let t = truth(dir.path());
    let f = solve_with(dir.path(), "fit.json", |_| {});
    let d: workbench::formats::detections::Detections =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("detections.json")).unwrap())
            .unwrap();
    let truth_l = Vector3::from(t.light_direction);
    let per_sphere: Vec<(f64, f64)> = d
        .images
        .iter()
        .flat_map(|im| &im.spheres)
        .map(|s| {
            let e = Vector3::from(s.light_direction.unwrap())
                .angle(&truth_l)
                .to_degrees();
            (e, s.light_std_deg.unwrap())
        })
        .collect();
    let det_err = Vector3::from(d.light_direction.unwrap())
        .angle(&truth_l)
        .to_degrees();
    let det_std = d.light_std_deg.unwrap();
    let tau = d.light_scatter_deg.unwrap();
    let err = light_err(&f, &t);
    println!(
        "spheres {per_sphere:.3?}; detector {det_err:.3}° ± {det_std:.3}° (scatter {tau:.3}°); light {err:.3}° ± {:.3}° ({}); σ0 {:.3?} ± {:.3?}",
        f.std.light_deg, f.light_fit, f.sigma0_mm, f.std.sigma0_mm
    );
    // The scene does disturb every sphere's highlight light beyond its error (else this tests
    // nothing): measured 9 to 27 of their errors.
    assert!(
        per_sphere.iter().all(|(e, s)| e > &(5.0 * s)),
        "{per_sphere:?}"
    );
    // The detector states the scatter (measured 0.37°) and its error covers its light.
    assert!((0.2..0.6).contains(&tau), "τ {tau}");
    assert!(det_err <= 3.0 * det_std, "detector {det_err}° ± {det_std}°");
    assert!(f
        .notes
        .iter()
        .any(|n| n.starts_with("the spheres' highlights disagree")));
    // Issue 34's goals: the light within 0.1° and σ0 within 1%, each within 3 of its std.
    assert!(err < 0.1, "light {err}°");
    assert!(
        err <= 3.0 * f.std.light_deg,
        "light {err}° ± {}°",
        f.std.light_deg
    );
    for c in 0..3 {
        let z = (f.sigma0_mm[c] - t.sigma0_mm[c]) / f.std.sigma0_mm[c];
        assert!(
            z.abs() < 3.0,
            "σ0[{c}] {} ± {} against {}",
            f.sigma0_mm[c],
            f.std.sigma0_mm[c],
            t.sigma0_mm[c]
        );
        assert!(rel(f.sigma0_mm[c], t.sigma0_mm[c]) < 0.01, "σ0[{c}]");
    }
}

/// The sweep behind docs/uncertainty.md's composite row, run by hand (about 3 minutes on 2
/// cores): issue 34's composite ([`composite_with_stand`]) on seeds 1–8 with stands 4, 8 and
/// 14 px wide at 30% of full scale, and 8 px at 60%. Measured (2026-12-04, late): light
/// 0.037–0.073° off at 0.4–1.2 of its stated std, σ0 0.20–1.41% low within 0.9 std (28 of 32
/// within 1% in every channel; seed 2 is 1.11–1.41% low in blue at every stand). Asserted: every
/// light within 0.1° and 3 std, every σ0 within 2% and 3 std, at least 27 of 32 within 1%.
#[test]
#[ignore = "by hand: cargo test --release --test it -- --ignored solve::disturbed_outlines_over_seeds --nocapture"]
fn disturbed_outlines_over_seeds() {
    let (mut within_1pc, mut worst_light, mut worst_z, mut worst_sigma) =
        (0, 0.0f64, 0.0f64, 0.0f64);
    for (width, level) in [(4.0, 0.3), (8.0, 0.3), (14.0, 0.3), (8.0, 0.6)] {
        for seed in 1..=8u64 {
            let dir = tempfile::tempdir().unwrap();
            let cfg = SessionConfig {
                seed,
                ..SessionConfig::default()
            };
            session::generate(&cfg, dir.path(), None, true).unwrap();
            composite_with_stand(dir.path(), width, level);
            let t = truth(dir.path());
            let f = solve_with(dir.path(), "fit.json", |o| o.quiet = true);
            let err = light_err(&f, &t);
            let z = err / f.std.light_deg;
            let zs = (0..3)
                .map(|c| ((f.sigma0_mm[c] - t.sigma0_mm[c]) / f.std.sigma0_mm[c]).abs())
                .fold(0.0, f64::max);
            let worst_rel = (0..3)
                .map(|c| rel(f.sigma0_mm[c], t.sigma0_mm[c]))
                .fold(0.0, f64::max);
            println!(
                "stand {width} px at {level}, seed {seed}: light {err:.3}° ± {:.3}° ({z:.1} std), σ0 worst {zs:.1} std, {:.2?}% off",
                f.std.light_deg,
                (0..3)
                    .map(|c| 100.0 * (f.sigma0_mm[c] / t.sigma0_mm[c] - 1.0))
                    .collect::<Vec<_>>()
            );
            within_1pc += (worst_rel < 0.01) as usize;
            worst_light = worst_light.max(err);
            worst_z = worst_z.max(z.max(zs));
            worst_sigma = worst_sigma.max(worst_rel);
        }
    }
    println!(
        "worst light {worst_light:.3}°, worst σ0 {:.2}% ({within_1pc} of 32 within 1%), worst {worst_z:.1} std",
        100.0 * worst_sigma
    );
    assert!(
        worst_light < 0.1 && worst_z < 3.0,
        "{worst_light}° {worst_z} std"
    );
    assert!(
        worst_sigma < 0.02 && within_1pc >= 27,
        "σ0 {worst_sigma}, {within_1pc}"
    );
}

/// A grey card in one of the photos (session.json's `"reference"`) gives the light's irradiance
/// when `--irradiance` does not: the soap renders with a matte patch painted beside the 35 mm
/// sphere at a known reflectance's radiance, ρE/π facing the light and ρE cos θ/π facing the
/// camera (θ from the renders' true light). The irradiance read back is the renders' own to the
/// card's 16-bit rounding (measured 2.4e-6 of 1.3e-5 facing the light; facing the camera 2.0e-5
/// of 3.1e-5 against the detected light's cos θ, which is 0.13% off the truth's), and the fit
/// equals the one given that irradiance on the command line (parameters within 1e-6). A box on the
/// sphere, and a clipped card, are refused in one line naming session.json, nothing written.
/// Without hints, detection leaves the card's blob out (without that it found two spheres).
#[test]
fn a_grey_card_gives_the_irradiance() {
    use workbench::synth::volpath::PbrTruth;
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/pbr-soap");
    let truth: PbrTruth =
        serde_json::from_str(&std::fs::read_to_string(src.join("truth.json")).unwrap()).unwrap();
    let e = truth.irradiance_in_png_units;
    let l = Vector3::from(truth.light.direction_to_light_camera_frame);
    // The card: 40 × 40 pixels at (40, 450), away from the sphere; the box inside it.
    let card = |dir: &Path, value: f64, facing: &str, box_px: [u32; 4], hint: bool| {
        let p = dir.join("r35.png");
        let mut img = image::open(&p).unwrap().into_rgb16();
        let v = (value.clamp(0.0, 1.0) * 65535.0).round() as u16;
        for y in 450..490 {
            for x in 40..80 {
                img.put_pixel(x, y, image::Rgb([v, v, v]));
            }
        }
        img.save(&p).unwrap();
        let s = dir.join("session.json");
        let mut j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&s).unwrap()).unwrap();
        j["reference"] = serde_json::json!({
            "image": "r35.png", "box_px": box_px, "reflectance": 0.5, "facing": facing
        });
        // The card is a bright blob too: detection leaves out the blob that holds its box, or
        // the sphere of its photo is hinted.
        if hint {
            j["images"][0]["spheres"][0]["center_px"] = serde_json::json!([443.2, 268.5]);
            j["images"][0]["spheres"][0]["radius_px"] = serde_json::json!(70.0);
        }
        std::fs::write(&s, serde_json::to_string_pretty(&j).unwrap()).unwrap();
    };
    let inside = [45, 455, 75, 485];
    // The card's value is rounded to 16 bits: E is read to half a level step over the value.
    let quantised = |value: f64| 1.5 * 0.5 / (value * 65535.0);
    let solve = |dir: &Path, extra: &[&str]| {
        let d = dir.to_str().unwrap();
        let mut args = vec!["--quiet", "solve", d];
        args.extend(extra);
        common::wb(&args)
    };
    let fit_of = |dir: &Path| -> FitFile {
        serde_json::from_str(&std::fs::read_to_string(dir.join("fit.json")).unwrap()).unwrap()
    };
    let ks = |f: &FitFile| f.parameters.iter().find(|p| p.name == "ks").unwrap().value;
    // Facing the light, against the same fit given the irradiance.
    let with_card = common::session_copy(&src);
    // No hint: detection leaves the card's blob out.
    card(
        with_card.path(),
        0.5 * e / std::f64::consts::PI,
        "light",
        inside,
        false,
    );
    let (code, _, err) = solve(with_card.path(), &[]);
    assert_eq!(code, 0, "{err}");
    let f = fit_of(with_card.path());
    println!("facing the light: E {:.6} (truth {e:.6})", ks(&f));
    // With the irradiance known, `--model auto` (the default) fits the medium too.
    let medium = f
        .medium
        .as_ref()
        .expect("the medium, the irradiance being known");
    let value = 0.5 * e / std::f64::consts::PI;
    assert!(
        (ks(&f) / e - 1.0).abs() < quantised(value),
        "{} {e}",
        ks(&f)
    );
    assert!(
        f.notes
            .iter()
            .any(|n| n.contains("diffuse reference in r35.png")),
        "{:?}",
        f.notes
    );
    // The same folder (the same detections) with that irradiance given: the same fit.
    let out = with_card.path().join("given.json");
    let (code, _, err) = solve(
        with_card.path(),
        &[
            "--irradiance",
            &format!("{}", ks(&f)),
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert_eq!(code, 0, "{err}");
    let g: FitFile = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    for (a, b) in f.parameters.iter().zip(&g.parameters) {
        assert!(
            (a.value - b.value).abs() <= 1e-6 * b.value.abs().max(1e-3),
            "{} {} {}",
            a.name,
            a.value,
            b.value
        );
    }
    let given = g.medium.as_ref().expect("the medium, --irradiance given");
    let (a, b) = (medium.sigma_a_per_mm.value, given.sigma_a_per_mm.value);
    for c in 0..3 {
        assert!((a[c] - b[c]).abs() <= 1e-6 * b[c], "{a:?} {b:?}");
    }
    // Facing the camera: cos θ = −l_z, read with the detected light (its error enters E as
    // tan θ × the light's error, which the note states).
    let facing_camera = common::session_copy(&src);
    card(
        facing_camera.path(),
        0.5 * e * -l.z / std::f64::consts::PI,
        "camera",
        inside,
        true,
    );
    let (code, _, err) = solve(facing_camera.path(), &["--model", "cdrf"]);
    assert_eq!(code, 0, "{err}");
    let f = fit_of(facing_camera.path());
    let det: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(facing_camera.path().join("detections.json")).unwrap(),
    )
    .unwrap();
    let detected = -det["light_direction"][2].as_f64().unwrap();
    let expected = e * -l.z / detected;
    println!(
        "facing the camera: E {:.6} (expected with the detected light {expected:.6}, truth {e:.6}, cos θ {:.4})",
        ks(&f),
        -l.z
    );
    let value = 0.5 * e * -l.z / std::f64::consts::PI;
    assert!(
        (ks(&f) / expected - 1.0).abs() < quantised(value),
        "{} {expected}",
        ks(&f)
    );
    let note = f.notes.iter().find(|n| n.contains("facing the camera"));
    println!("{note:?}");
    assert!(note.is_some(), "{:?}", f.notes);
    // Refused: a box on the sphere; a clipped card.
    // Unhinted, a box on the sphere leaves the sphere's blob in (a disc is no card): the card and
    // the sphere are then two blobs where one sphere is listed.
    for (value, box_px, hint, what) in [
        (
            0.3,
            [400, 250, 420, 270],
            true,
            "session.json: reference: box_px",
        ),
        (0.3, [400, 250, 420, 270], false, "found 2 sphere(s)"),
        (2.0, inside, true, "clipped"),
    ] {
        let dir = common::session_copy(&src);
        card(dir.path(), value, "light", box_px, hint);
        let (code, _, err) = solve(dir.path(), &[]);
        println!("refused: {}", err.trim());
        assert_ne!(code, 0);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains(what), "{err}");
        assert!(!dir.path().join("fit.json").exists());
    }
}
