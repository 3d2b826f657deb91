//! Do the stated standard errors cover the real error? Synthetic sessions over many noise seeds
//! (the truth known exactly) and the physically based jade session (the light and η known).

use crate::common;

use nalgebra::Vector3;
use std::path::Path;
use workbench::formats::fit::FitFile;
use workbench::solve::{self, Options};
use workbench::synth::session::{self, SessionConfig, SessionTruth};

/// One synthetic session (640×480, five radii, 1% noise) for a noise seed. At 320×240 σ0 comes
/// out high on every seed ([`stated_errors_at_low_resolution`]).
fn session(seed: u64) -> tempfile::TempDir {
    session_with(seed, common::camera_640x480())
}

/// [`session`] with another camera.
fn session_with(seed: u64, camera: workbench::camera::Camera) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let cfg = SessionConfig {
        camera,
        seed,
        ..SessionConfig::default()
    };
    session::generate(&cfg, dir.path(), None, true).unwrap();
    dir
}

fn solve(dir: &Path, f: impl FnOnce(&mut Options)) -> FitFile {
    let mut o = Options::new(dir);
    f(&mut o);
    solve::run(&o).unwrap()
}

fn param<'a>(f: &'a FitFile, name: &str) -> &'a workbench::formats::fit::ParamJson {
    f.parameters.iter().find(|p| p.name == name).unwrap()
}

/// Errors in units of the stated std (`std`) and of the formal one (`std_formal`): σ0 and albedo
/// per channel, α, η and the light's angle (against `light_deg`).
fn z_scores(f: &FitFile, t: &SessionTruth) -> Vec<(String, f64, f64)> {
    let mut out = vec![];
    let truth = [
        ("sigma0_r", t.sigma0_mm[0]),
        ("sigma0_g", t.sigma0_mm[1]),
        ("sigma0_b", t.sigma0_mm[2]),
        ("albedo_r", t.albedo[0]),
        ("albedo_g", t.albedo[1]),
        ("albedo_b", t.albedo[2]),
        ("alpha", t.specular.alpha),
        ("eta", t.eta),
    ];
    for (name, v) in truth {
        let p = param(f, name);
        let formal = p
            .std_formal
            .expect("jackknife on: the formal std is stated beside it");
        out.push((
            name.to_string(),
            (p.value - v) / p.std,
            (p.value - v) / formal,
        ));
    }
    let err = Vector3::from(f.light_direction).angle(&Vector3::from(t.light_direction));
    let (a, e) = (param(f, "light_azimuth"), param(f, "light_elevation"));
    let formal = (a.std_formal.unwrap().powi(2) * e.value.cos().powi(2)
        + e.std_formal.unwrap().powi(2))
    .sqrt();
    out.push((
        "light".into(),
        err / f.std.light_deg.to_radians(),
        err / formal,
    ));
    out
}

/// The z-scores ([`z_scores`]) of the default solve on each seed's session under `camera`.
fn z_over_seeds(
    camera: workbench::camera::Camera,
    seeds: std::ops::RangeInclusive<u64>,
) -> Vec<(String, f64, f64)> {
    let mut all = vec![];
    for seed in seeds {
        let dir = session_with(seed, camera);
        let t: SessionTruth =
            serde_json::from_str(&std::fs::read_to_string(dir.path().join("truth.json")).unwrap())
                .unwrap();
        let f = solve(dir.path(), |_| {});
        assert!(
            f.std_source.starts_with("larger of formal and jackknife"),
            "{}",
            f.std_source
        );
        assert!(f.jackknife.as_ref().is_some_and(|j| j.radii.len() == 5));
        all.extend(z_scores(&f, &t));
    }
    all
}

/// Per parameter: how many of its z-scores lie within ±2 (stated std) and their RMS; printed.
fn per_parameter(all: &[(String, f64, f64)]) -> Vec<(String, usize, f64)> {
    let mut names: Vec<String> = all.iter().map(|z| z.0.clone()).collect();
    names.dedup();
    names.sort();
    names.dedup();
    names
        .into_iter()
        .map(|name| {
            let zs: Vec<f64> = all.iter().filter(|z| z.0 == name).map(|z| z.1).collect();
            let within = zs.iter().filter(|z| z.abs() <= 2.0).count();
            let rms = (zs.iter().map(|z| z * z).sum::<f64>() / zs.len() as f64).sqrt();
            let shown: Vec<String> = zs.iter().map(|z| format!("{z:+.1}")).collect();
            println!(
                "{name:9} within ±2: {within}/{}, RMS {rms:.2}: {}",
                zs.len(),
                shown.join(" ")
            );
            (name, within, rms)
        })
        .collect()
}

/// Over 20 seeds the truth lies within ±2 stated standard errors for most of the parameters (a
/// Gaussian gives 95.4%); the formal errors alone are printed beside for comparison. Measured
/// 2026-12-01: stated 89.4%, formal alone 27.2% of 180 values (σ0, albedo, α, η, light); 88.3%
/// and 28.3% on 2026-12-04; 90.6% and 18.9% with the lights combined (2026-12-04, night). The goal
/// is 90–99% (docs/uncertainty.md); the bound asserted is 85%, 2.5 binomial standard errors below
/// what was measured, so that a change that loses coverage fails here. Per parameter (of 20, the
/// lights combined): σ0 19, 19, 19; albedo 18; α 20; η 17; light 15 (the shading's light 0.05–0.07°
/// from the detector's on these 640×480 sessions, its leave-one-out spreads 0.015–0.08°; held
/// 18 of 20 when the fit with the prior stood) — each asserted no more than three below the
/// earlier 18, 17, 19, 14 and 18 (2.5 binomial standard errors at 90%); and each parameter's z
/// RMS between 0.3 and 2.5 (measured 0.49–1.62): a std several times too large fails as one too
/// small.
#[test]
fn stated_errors_cover_the_truth_over_seeds() {
    let all = z_over_seeds(common::camera_640x480(), 1..=20);
    let n = all.len() as f64;
    let within = |k: usize| {
        all.iter()
            .filter(|z| if k == 0 { z.1.abs() } else { z.2.abs() } <= 2.0)
            .count() as f64
            / n
    };
    let (stated, formal) = (within(0), within(1));
    println!(
        "within ±2 std: stated {:.1}%, formal alone {:.1}% ({} parameter values)",
        100.0 * stated,
        100.0 * formal,
        all.len()
    );
    let per = per_parameter(&all);
    assert!((0.85..=0.99).contains(&stated), "stated coverage {stated}");
    assert!(
        formal < 0.5,
        "the formal errors alone cover {formal}: the jackknife adds nothing?"
    );
    for (name, k, rms) in per {
        let floor = match name.as_str() {
            "eta" => 11,
            "light" => 15,
            n if n.starts_with("albedo") => 14,
            _ => 16,
        };
        assert!(
            k >= floor,
            "{name}: {k} of 20 within ±2 std (floor {floor})"
        );
        assert!((0.3..2.5).contains(&rms), "{name}: z RMS {rms}");
    }
}

/// At 320×240 (spheres 20–45 px in radius) σ0 comes out high on every seed, a bias common to all
/// radii that the jackknife over radii cannot see: measured (2026-12-04, ten seeds) 0.6–3.5% high,
/// z +0.5 to +3.0 (mean +1.6), 21 of 30 within ±2 std, every one within ±3. Asserted: every σ0
/// high by less than 5% and within 3.5 of its stated std, the mean z below 2.5 (the bias stated
/// in docs/uncertainty.md), and the other parameters' coverage as at 640×480.
#[test]
fn stated_errors_at_low_resolution() {
    let all = z_over_seeds(common::camera_320x240(), 1..=10);
    let sigma: Vec<f64> = all
        .iter()
        .filter(|z| z.0.starts_with("sigma0"))
        .map(|z| z.1)
        .collect();
    let mean = sigma.iter().sum::<f64>() / sigma.len() as f64;
    println!("σ0 z at 320×240: mean {mean:+.2}");
    assert!(sigma.iter().all(|z| z.abs() < 3.5), "{sigma:?}");
    assert!(mean < 2.5, "σ0 mean z {mean}");
    let rest = all.iter().filter(|z| !z.0.starts_with("sigma0"));
    let (k, m) = rest.fold((0, 0), |(k, m), z| (k + (z.1.abs() <= 2.0) as usize, m + 1));
    println!("the other parameters within ±2 std: {k} of {m}");
    assert!(k as f64 >= 0.8 * m as f64, "{k} of {m}");
    per_parameter(&all);
}

/// The physically based jade session (../shared/data/pbr-jade): the CDRF does not describe it
/// exactly, so an error its stated std does not cover must be flagged in the notes. With
/// `--entry-transmission`, measured 2026-12-01: light 0.34° off against a stated ± 0.12° (2.8 std;
/// the detector's 0.08° off, pull 0.9), η 1.29 ± 0.22 against 1.62, held-out radii 3.7–5.1%; on
/// 2026-12-04: light 0.314° ± 0.250° (the detector's 0.178° ± 0.093°, pull 2.2), η 1.27 (3.6 prior
/// σ from the prior, flagged), residuals 2.9× the noise (flagged), held out 3.5–3.8%. Then the
/// defaults on the same folder ([`jade_defaults`]).
#[test]
fn jade_errors_are_covered_or_flagged() {
    let Some(data) = common::shared_data() else {
        return;
    };
    let src = data.join("pbr-jade");
    let dir = common::session_copy(&src);
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(src.join("truth.json")).unwrap()).unwrap();
    let l: Vec<f64> = truth["light"]["direction_to_light_camera_frame"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let l = Vector3::new(l[0], l[1], l[2]);
    let f = solve(dir.path(), |o| o.fit.entry_transmission = true);
    let err = Vector3::from(f.light_direction).angle(&l).to_degrees();
    let pull = f
        .light_pull
        .expect("the detector's light and its error are known");
    let d: workbench::formats::detections::Detections =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("detections.json")).unwrap())
            .unwrap();
    let det_err = Vector3::from(d.light_direction.unwrap())
        .angle(&l)
        .to_degrees();
    let j = f.jackknife.as_ref().unwrap();
    println!(
        "jade: light {err:.3}° off (stated ± {:.3}°; detector {det_err:.3}° off, ± {:.3}°; pull {:.1}); σ0 {:.3?} ± {:.3?}; held out {:?}",
        f.std.light_deg,
        pull.detector_std_deg,
        pull.pull,
        f.sigma0_mm,
        f.std.sigma0_mm,
        j.heldout
            .iter()
            .map(|h| (h.radius_mm, (1000.0 * h.rel_rmse).round() / 10.0))
            .collect::<Vec<_>>()
    );
    for n in &f.notes {
        println!("note {n}");
    }
    // The detector's light is within 3 of its own standard errors.
    assert!(det_err < 3.0 * pull.detector_std_deg, "detector {det_err}°");
    // The fit's light and η within 3 of their stated std (the goal; measured 2.8 and 1.5).
    assert!(
        err <= 3.0 * f.std.light_deg,
        "light {err}° ± {}°",
        f.std.light_deg
    );
    assert!(
        pull.pull < workbench::fit::joint::PULL_WARN,
        "pull {}",
        pull.pull
    );
    let eta = param(&f, "eta");
    assert!(
        (eta.value - 1.62).abs() <= 3.0 * eta.std,
        "η {} ± {}",
        eta.value,
        eta.std
    );
    // η's disagreement with its prior is flagged and widens its std.
    let flagged = |what: &str| f.notes.iter().any(|n| n.contains(what));
    assert!(eta.prior_tension.is_some_and(|s| s > 2.0), "{eta:?}");
    assert!(flagged("prior σ from the prior"), "{:?}", f.notes);
    assert!(flagged("the model does not describe these photos"));
    // Every radius predicted from the others within 5.6% (measured 3.7–5.1%, later 3.5–3.8%).
    assert_eq!(j.radii.len(), 5);
    for h in &j.heldout {
        assert!(h.rel_rmse < 0.056, "{h:?}");
    }
    jade_defaults(dir.path(), &l);
}

/// pbr-jade with the defaults (what docs/commands.md and the README quote), in the folder the test
/// above solved: the shading pulls the light far past PULL_WARN, so it is held at the detector's
/// and the output says so; the light's and η's errors within 3 of their stated std (measured
/// 2026-12-04: 0.178° ± 0.132°, 1.35 std; η 1.210 ± 0.588 against 1.62, 0.70 std); the model's
/// misfit flagged; every radius predicted from the other four within 10% of what was measured
/// (5.29 / 5.22 / 5.10 / 4.63 / 4.15%).
fn jade_defaults(dir: &Path, l: &Vector3<f64>) {
    let f = solve(dir, |_| {});
    let err = Vector3::from(f.light_direction).angle(l).to_degrees();
    let eta = param(&f, "eta");
    let j = f.jackknife.as_ref().unwrap();
    let held: Vec<f64> = j.heldout.iter().map(|h| 100.0 * h.rel_rmse).collect();
    println!(
        "jade, defaults: light {err:.3}° off (± {:.3}°, {}); η {:.3} ± {:.3}; held out {held:.2?}%",
        f.std.light_deg, f.light_fit, eta.value, eta.std
    );
    assert_eq!(f.light_fit, "prior, then combined");
    assert!(f
        .notes
        .iter()
        .any(|n| n.starts_with("the light combines the highlights' estimate")));
    assert!(
        err < 0.3 && err <= 3.0 * f.std.light_deg,
        "light {err}° ± {}°",
        f.std.light_deg
    );
    assert!(
        (eta.value - 1.62).abs() <= 3.0 * eta.std,
        "η {} ± {}",
        eta.value,
        eta.std
    );
    assert!(f
        .notes
        .iter()
        .any(|n| n.contains("the model does not describe these photos")));
    // Where: the Gaussian blur is not the shape of jade's scattering, and the terminator shows
    // it most (measured: lit side 11.3×, terminator 28.6×, rim 17.9×, highlight 8.5× the noise).
    assert!(
        f.notes
            .iter()
            .any(|n| n.contains("worst at the terminator")),
        "{:?}",
        f.notes
    );
    for (h, m) in held.iter().zip([5.29, 5.22, 5.10, 4.63, 4.15]) {
        assert!((h / m - 1.0).abs() < 0.1, "held out {held:?}%");
    }
}

/// One of the project's own physically based sessions (datasets/pbr-*, `workbench synth pbr`,
/// docs/pbr.md) solved with the defaults: where the shading pulls the light beyond PULL_WARN of
/// the detector's errors (wax 18 std, soap 7 std with the default extension) the light is
/// held at the detector's; the light's and η's errors lie within 3 of their stated std, and each
/// radius is predicted from the others within 10% of what was measured (2026-12-01, `workbench
/// solve datasets/pbr-<name>`).
fn pbr_session_defaults(name: &str, expect_held: bool, heldout_measured: [f64; 5]) {
    let src = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("datasets")
        .join(name);
    let dir = common::session_copy(&src);
    let truth: workbench::synth::volpath::PbrTruth =
        serde_json::from_str(&std::fs::read_to_string(src.join("truth.json")).unwrap()).unwrap();
    let l = Vector3::from(truth.light.direction_to_light_camera_frame);
    let f = solve(dir.path(), |_| {});
    let err = Vector3::from(f.light_direction).angle(&l).to_degrees();
    let pull = f.light_pull.expect("the detector's light is known");
    let eta = param(&f, "eta");
    let j = f.jackknife.as_ref().unwrap();
    let held: Vec<f64> = j.heldout.iter().map(|h| 100.0 * h.rel_rmse).collect();
    println!(
        "{name}: light {err:.3}° off (± {:.3}°, pull {:.1}, {}); η {:.3} ± {:.3} (truth {}); σ0 {:.3?} ± {:.3?}; held out {held:.2?}%",
        f.std.light_deg,
        pull.pull,
        f.light_fit,
        eta.value,
        eta.std,
        truth.material.eta,
        f.sigma0_mm,
        f.std.sigma0_mm
    );
    // The shading's light far from the detector's, the two are combined, the fit is redone at
    // the combination, and the output says so.
    let light_held = f
        .notes
        .iter()
        .any(|n| n.starts_with("the light combines the highlights' estimate"));
    assert_eq!(
        f.light_fit == "prior, then combined",
        light_held,
        "{}",
        f.light_fit
    );
    assert_eq!(light_held, expect_held, "pull {}", pull.pull);
    // The hold is taken by Newton steps from the pulled fit, which contract here (measured 9 on
    // wax, 5 on soap): neither the 16-step limit nor the give-up rule for an iteration that does
    // not contract sends it to the whole fit repeated.
    if light_held {
        let stages = &f.convergence.stages;
        let newton = stages
            .iter()
            .find(|s| s.name == "joint, the light held (Newton steps from the fit)");
        assert!(
            newton.is_some_and(|s| s.evaluations <= 16),
            "{:?}",
            stages
                .iter()
                .map(|s| (&s.name, s.evaluations))
                .collect::<Vec<_>>()
        );
    }
    assert!(
        err < 0.3 && err <= 3.0 * f.std.light_deg,
        "light {err}° ± {}°",
        f.std.light_deg
    );
    assert!(
        (eta.value - truth.material.eta).abs() <= 3.0 * eta.std,
        "η {} ± {}",
        eta.value,
        eta.std
    );
    assert_eq!(j.radii, vec![35.0, 30.0, 25.0, 20.0, 15.0]);
    for (h, m) in held.iter().zip(heldout_measured) {
        assert!(
            *h < 1.1 * m,
            "held out {held:?}% against {heldout_measured:?}%"
        );
    }
}

#[test]
fn own_wax_session_defaults() {
    pbr_session_defaults("pbr-wax", true, [3.51, 3.38, 3.42, 3.42, 4.05]);
}

#[test]
fn own_soap_session_defaults() {
    pbr_session_defaults("pbr-soap", true, [4.19, 4.15, 4.46, 5.30, 7.30]);
}

/// Each parameter's jackknife std from the linear estimates (the default) against the refits
/// (`--jackknife refit`) on a synthetic session: without the Huber loss the linear estimates are
/// Newton iterations on the refits' own problem, and agree with them to the refits' stopping
/// tolerance; with it (the default) the reweighting is iterated only until the steps are small
/// against the spread.
#[test]
fn linear_jackknife_matches_the_refits() {
    use workbench::fit::joint::JackknifeMethod;
    let dir = session(3);
    for robust in [false, true] {
        let run = |m| {
            solve(dir.path(), |o| {
                o.fit.robust = robust;
                o.fit.jackknife = m;
            })
        };
        let (lin, refit) = (run(JackknifeMethod::Linear), run(JackknifeMethod::Refit));
        assert_eq!(lin.jackknife.as_ref().unwrap().method, "linear");
        assert_eq!(refit.jackknife.as_ref().unwrap().method, "refit");
        let worst = lin
            .parameters
            .iter()
            .zip(&refit.parameters)
            .filter(|(_, b)| b.std_jackknife.is_some_and(|s| s > 0.0))
            .filter_map(|(a, b)| Some((a.std_jackknife? / b.std_jackknife? - 1.0).abs()))
            .fold(0.0, f64::max);
        println!(
            "robust {robust}: linear/refit jackknife std differs by at most {:.2e}; {:.3} s against {:.3} s",
            worst,
            lin.timings.jackknife_s,
            refit.timings.jackknife_s
        );
        // Measured (2026-12-03): 1.5e-5 without the Huber loss, 1.0e-2 with it; with the light
        // held at its combination with the detector's (2026-12-04), 3.0e-5 and 3.0e-2.
        assert!(worst < if robust { 0.06 } else { 9e-5 }, "{worst}");
    }
}

/// `workbench solve --holdout 15` with the defaults, against the paper's procedure
/// (`--method paper --holdout 15`) in the same test, on the physically based sessions
/// (docs/commands.md, docs/uncertainty.md): the 15 mm sphere left out of the fit and predicted.
/// Measured (2026-12-04), joint / paper relative RMSE: wax 4.12% / 14.99%, soap 7.47% / 13.71%,
/// jade 4.24% / 20.03%.
#[test]
fn an_unseen_15_mm_sphere_is_predicted_better_than_by_the_papers_procedure() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut sessions = vec![
        (repo.join("datasets/pbr-wax"), 0.0412, 0.1499),
        (repo.join("datasets/pbr-soap"), 0.0747, 0.1371),
    ];
    if let Some(shared) = common::shared_data() {
        sessions.push((shared.join("pbr-jade"), 0.0424, 0.2003));
    }
    for (src, joint_measured, paper_measured) in sessions {
        let copy = common::session_copy(&src);
        let held = |method: &str| {
            let out = copy.path().join(format!("fit-{method}.json"));
            let dir = copy.path().to_str().unwrap();
            let args = [
                "--quiet",
                "solve",
                dir,
                "--method",
                method,
                "--holdout",
                "15",
            ];
            let (code, _, err) =
                common::wb(&[&args[..], &["--out", out.to_str().unwrap()]].concat());
            assert_eq!(code, 0, "{err}");
            let f: FitFile = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
            let h = f.holdout.expect("a held-out sphere");
            assert_eq!(h.radius_mm, 15.0);
            h.rel_rmse
        };
        let (joint, paper) = (held("joint"), held("paper"));
        let name = src.file_name().unwrap().to_string_lossy().to_string();
        println!(
            "{name}: 15 mm held out, joint {:.2}%, paper {:.2}%",
            100.0 * joint,
            100.0 * paper
        );
        // Both near what was measured (the data and the fit are deterministic; 15% either way),
        // and the joint fit at most 0.6 of the paper's error.
        for (v, m) in [(joint, joint_measured), (paper, paper_measured)] {
            assert!(
                (v / m - 1.0).abs() < 0.15,
                "{name}: {v} against {m} measured"
            );
        }
        assert!(joint < 0.6 * paper, "{name}: joint {joint}, paper {paper}");
    }
}

/// Whether `f`'s output says that `what` may be off: the shading pulling the light from the
/// highlights' estimate (for the light), or residuals beyond the noise (for anything).
fn flagged(f: &FitFile, what: &str) -> bool {
    f.notes.iter().any(|n| {
        n.starts_with("the residuals are")
            || (what == "light" && n.starts_with("the shading pulls the light"))
    })
}

/// Coverage on physically based photos (docs/uncertainty.md, "Coverage on physically based
/// sessions"): eight small `synth pbr` sessions (datasets/pbr-seeds, `scripts/pbr-seeds.sh`:
/// wax-, soap- and jade-like, eight lights, 640×480, 1024 samples a pixel), solved with the
/// defaults. Truth: the light, η and the boundary's GGX α (σ0 has none). Measured (2026-12-04,
/// the lights combined), error / stated std:
/// - light: 0.22, 0.86, 1.85, 4.81 (soap-5, flagged: the shading pulls the light), 0.57, 0.19,
///   0.20, 0.93 (with the hold before: 0.53, 0.72, 1.26, 4.04, 0.21, 1.07, 0.48, 0.77);
/// - η: +0.59, −0.69, −0.05, −0.57, −0.52, −1.49, −2.85, −2.24;
/// - α: +0.36, +7.74 (jade-6, flagged: residuals 9.7× the noise), −0.80, −0.67, −1.04, +0.08,
///   −0.93, −0.55 (before the check against the detector's α, soap's were −3.0, −1.7, −24).
///
/// Asserted: every value within 3 of its stated std or flagged in the notes, at most two
/// flagged; at least 17 of the 24 within ±2 (20 measured; 2.5 binomial std below); each
/// parameter's z RMS, the flagged values beyond 3 left out, in 0.3–2.5 (measured 0.88, 1.45,
/// 0.70), so a std ten times too large fails too.
#[test]
fn physically_based_coverage_over_seeds() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/pbr-seeds");
    let mut names: Vec<_> = std::fs::read_dir(&root)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("truth.json").exists())
        .collect();
    names.sort();
    assert_eq!(names.len(), 8, "{names:?}");
    let mut all: Vec<(String, f64, bool)> = vec![];
    for src in &names {
        let name = src.file_name().unwrap().to_string_lossy().into_owned();
        let truth: workbench::synth::volpath::PbrTruth =
            serde_json::from_str(&std::fs::read_to_string(src.join("truth.json")).unwrap())
                .unwrap();
        let dir = common::session_copy(src);
        let f = solve(dir.path(), |_| {});
        assert!(f.convergence.converged, "{name}");
        let l = Vector3::from(truth.light.direction_to_light_camera_frame);
        let light = Vector3::from(f.light_direction).angle(&l).to_degrees() / f.std.light_deg;
        let (eta, alpha) = (param(&f, "eta"), param(&f, "alpha"));
        let mut zs = vec![
            ("light", light),
            ("eta", (eta.value - truth.material.eta) / eta.std),
        ];
        if alpha.status == "fitted" {
            zs.push(("alpha", (alpha.value - truth.material.alpha) / alpha.std));
        }
        println!(
            "{name}: {}",
            zs.iter()
                .map(|(p, z)| format!(
                    "{p} {z:+.2}{}",
                    if flagged(&f, p) { " (flagged)" } else { "" }
                ))
                .collect::<Vec<_>>()
                .join(", ")
        );
        for (p, z) in zs {
            let flag = flagged(&f, p);
            assert!(
                z.abs() < 3.0 || flag,
                "{name}: {p} {z:+.2} std off, not flagged"
            );
            all.push((p.to_string(), z, flag));
        }
    }
    let flagged_n = all.iter().filter(|z| z.2 && z.1.abs() >= 3.0).count();
    let within = all.iter().filter(|z| z.1.abs() <= 2.0).count();
    println!(
        "within ±2 stated std: {within} of {}; flagged beyond 3: {flagged_n}",
        all.len()
    );
    assert!(flagged_n <= 2, "{flagged_n}");
    assert!(all.len() == 24 && within >= 17, "{within} of {}", all.len());
    for p in ["light", "eta", "alpha"] {
        let zs: Vec<f64> = all
            .iter()
            .filter(|z| z.0 == p && !(z.2 && z.1.abs() >= 3.0))
            .map(|z| z.1)
            .collect();
        let rms = (zs.iter().map(|z| z * z).sum::<f64>() / zs.len() as f64).sqrt();
        println!(
            "{p}: z RMS {rms:.2} over {} (the flagged beyond 3 left out)",
            zs.len()
        );
        assert!((0.3..2.5).contains(&rms), "{p}: z RMS {rms}");
    }
}

/// A clipped highlight's η (`datasets/pbr-range/thin-dark`: η 1.6, GGX α 0.1, 253 pixels clipped
/// on its 35 mm sphere), solved with the defaults and truth.json's irradiance, the CDRF alone (the
/// joint fit's η is the subject; the medium's part, fitted by default there, is not): the lobe's wings
/// hold F(η) α², and the joint fit reads η 2.68 with α 0.043 (the detector's lobe fits 0.093).
/// With α held at the detector's the highlight says 1.498, and that difference joins η's std:
/// measured 2.68 ± 1.00, 1.07 std from the truth (± 0.30 and 3.6 std before 2026-12-07;
/// docs/uncertainty.md, "η with the detector's α"). Asserted: the note, η within 2 of its
/// stated std, and the η the note gives within 0.15 of the truth (measured 0.10).
#[test]
fn a_clipped_highlights_eta_is_covered_with_the_detectors_alpha() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/pbr-range/thin-dark");
    let dir = common::session_copy(&src);
    let t: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(src.join("truth.json")).unwrap()).unwrap();
    let truth = t["material"]["eta"].as_f64().unwrap();
    let f = solve(dir.path(), |o| {
        o.quiet = true;
        o.fit.irradiance = t["irradiance_in_png_units"].as_f64();
        o.model = workbench::solve::SolveModel::Cdrf;
    });
    let eta = param(&f, "eta");
    let note = f
        .notes
        .iter()
        .find(|n| n.contains("on the highlight with α held at the detector's"))
        .unwrap_or_else(|| panic!("{:?}", f.notes));
    let at_detector: f64 = note
        .split(", ")
        .nth(1)
        .and_then(|p| p.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{note}"));
    println!(
        "η {:.3} ± {:.3} (truth {truth}), {:.2} std; at the detector's α {at_detector}",
        eta.value,
        eta.std,
        (eta.value - truth).abs() / eta.std
    );
    assert!((eta.value - truth).abs() < 2.0 * eta.std, "{eta:?}");
    assert!((at_detector - truth).abs() < 0.15, "{at_detector}");
}
