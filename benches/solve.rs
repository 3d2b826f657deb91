//! Solve benchmark, run by hand (`cargo bench --bench solve [-- --quick]`):
//! 1. synthetic sessions (5 radii, 1280×960) against their truth — 16-bit PNG and 8-bit JPEG at 1%
//!    and 5% noise: the error of every parameter for the joint fit (η at its prior, and with the
//!    irradiance given) and for the paper's baseline, in the same run;
//! 2. the reduction curve: the solve stage at every reduction level (every pixel, 0.25°–4° cells,
//!    auto) — run time against the deviation from the every-pixel fit and the error against truth;
//!    a plot in `target/bench-solve/reduction.{png,svg}`;
//! 3. 5 photos of 24 MP: solve time against the time to decode the photos (same run);
//! 4. a physically based session with a `truth.json` (datasets/pbr-wax, datasets/pbr-soap,
//!    ../shared/data/pbr-jade) when `PBR_SESSION` names its folder, solved in a copy: each radius
//!    held out in turn, joint against paper, next to the render's own noise level, the light error
//!    against the truth's, and the model choice.
//!
//! Prints Markdown tables. `--quick` skips the 24 MP part and the 5% JPEG session; `--pbr-only`
//! runs part 4 alone.

use nalgebra::Vector3;
use std::path::{Path, PathBuf};
use std::time::Instant;
use workbench::fit::joint::ExtensionChoice;
use workbench::fit::joint::{self, Reduction};
use workbench::formats::fit::{FitFile, Method};
use workbench::model::N_PARAMS;
use workbench::plot::{Layer, Plot, PALETTE};
use workbench::solve::{self, Options};
use workbench::synth::session::{self, Format, SessionConfig, SessionTruth};

fn detect(dir: &Path) -> f64 {
    let t0 = Instant::now();
    workbench::detect::run(&workbench::detect::Options {
        session: dir.to_path_buf(),
        out: None,
        overlays: false,
        quiet: true,
        medium_outlines: false,
    })
    .unwrap();
    t0.elapsed().as_secs_f64()
}

fn solve_with(dir: &Path, name: &str, f: impl FnOnce(&mut Options)) -> FitFile {
    let mut o = Options::new(dir);
    // The plain model, as docs/measurements/solve.md's tables were measured (its truth has no extension).
    o.fit.extensions = ExtensionChoice::None;
    o.out = Some(dir.join(name));
    f(&mut o);
    solve::run(&o).unwrap()
}

fn worst(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    (0..3)
        .map(|c| (a[c] - b[c]).abs() / b[c])
        .fold(0.0, f64::max)
}

fn light_deg(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    Vector3::from(*a).angle(&Vector3::from(*b)).to_degrees()
}

fn accuracy(label: &str, cfg: &SessionConfig) {
    let dir = tempfile::tempdir().unwrap();
    let out = session::generate(cfg, dir.path(), None, true).unwrap();
    let t: &SessionTruth = &out.truth;
    detect(dir.path());
    let runs = [
        ("joint", solve_with(dir.path(), "a.json", |_| {})),
        (
            "joint, irradiance given",
            // The CDRF alone: these photos are its own renders (the medium is docs/medium.md's).
            solve_with(dir.path(), "b.json", |o| {
                o.fit.irradiance = Some(1.0);
                o.model = workbench::solve::SolveModel::Cdrf;
            }),
        ),
        (
            "paper",
            solve_with(dir.path(), "c.json", |o| o.method = Method::Paper),
        ),
    ];
    for (name, f) in &runs {
        let spec = f
            .specular
            .map(|s| {
                format!(
                    "{:.1} | {:.1}",
                    100.0 * (s.ks - t.specular.ks).abs() / t.specular.ks,
                    100.0 * (s.alpha - t.specular.alpha).abs() / t.specular.alpha
                )
            })
            .unwrap_or_else(|| "— | —".into());
        // Largest σ0 error in units of its stated standard error.
        let z = (0..3)
            .map(|c| (f.sigma0_mm[c] - t.sigma0_mm[c]).abs() / f.std.sigma0_mm[c])
            .fold(0.0, f64::max);
        println!(
            "| {label} | {name} | {:.2} | {z:.1} | {:.2} | {:.3} | {:.3} ± {:.3} | {spec} | {:.2} |",
            100.0 * worst(&f.sigma0_mm, &t.sigma0_mm),
            100.0 * worst(&f.albedo, &t.albedo),
            light_deg(&f.light_direction, &t.light_direction),
            f.eta - t.eta,
            f.std.eta,
            f.timings.solve_s
        );
    }
}

/// One reduction level's fit on a loaded session: solve-stage seconds and the parameters.
fn level_fit(l: &solve::Loaded, opts: &Options, reduction: Reduction) -> (f64, joint::JointFit) {
    let settings = joint::Settings {
        eta_prior: opts.fit.eta_prior,
        ..joint::Settings::default()
    };
    let setup = joint::Setup::new(&settings, &l.measured, Default::default(), reduction);
    let spheres: Vec<&workbench::fit::observe::SphereData> = l.spheres.iter().collect();
    let t0 = Instant::now();
    let jf = joint::fit_joint(&setup, &spheres);
    (t0.elapsed().as_secs_f64(), jf)
}

fn reduction_curve(label: &str, dir: &Path, t: &SessionTruth, out: &Path) {
    let opts = Options::new(dir);
    let l = solve::load(&opts).unwrap();
    let levels: Vec<(String, Reduction)> = std::iter::once(("every pixel".into(), Reduction::None))
        .chain(
            workbench::fit::reduce::FACTORS
                .iter()
                .map(|&f| (format!("{}° cells", f as f64 * 0.25), Reduction::Factor(f))),
        )
        .chain(std::iter::once(("auto".into(), Reduction::Auto)))
        .collect();
    let results: Vec<(String, f64, joint::JointFit)> = levels
        .into_iter()
        .map(|(name, r)| {
            let (s, jf) = level_fit(&l, &opts, r);
            (name, s, jf)
        })
        .collect();
    let all = &results[0].2;
    let base = all.fit.params.to_vec();
    println!(
        "\n{label}: {} pixels (decode {:.2} s, same run)\n",
        all.pixels, l.timings.decode_s
    );
    println!("| level | observations | solve (s) | × every-pixel time | largest shift from every-pixel fit (std) | predicted (std) | σ0 error vs truth (%) | light error (°) |");
    println!("|---|---|---|---|---|---|---|---|");
    let mut plot = Plot::new(
        &format!("Reduction levels ({label})"),
        "solve time (s)",
        "log10 of the largest parameter shift from the every-pixel fit (std)",
    );
    plot.layers.push(Layer::HLine {
        y: (0.3f64).log10(),
        color: workbench::plot::GREY,
        dashed: true,
        label: Some("0.3 std (auto's limit)".into()),
    });
    for (k, (name, secs, jf)) in results.iter().enumerate() {
        let p = jf.fit.params.to_vec();
        let shift = (0..N_PARAMS)
            .filter(|&i| all.fit.free[i] && all.fit.std[i] > 0.0)
            .map(|i| (p[i] - base[i]).abs() / all.fit.std[i])
            .fold(0.0, f64::max);
        let m = &jf.fit.params.material;
        println!(
            "| {name}{} | {} | {secs:.2} | {:.2} | {shift:.2} | {} | {:.3} | {:.4} |",
            if name == "auto" {
                format!(" ({}°)", jf.chosen.width_deg)
            } else {
                String::new()
            },
            jf.chosen.observations,
            secs / results[0].1,
            if jf.chosen.width_deg > 0.0 && name != "every pixel" {
                let f = (jf.chosen.width_deg / 0.25).round() as u32;
                let pooled = {
                    // The prediction for this level (as `auto` computes it).
                    let sp: Vec<&workbench::fit::observe::SphereData> = l.spheres.iter().collect();
                    let mut pl = workbench::fit::reduce::Pooled::new(
                        l.measured.light.unwrap_or(Vector3::new(0.0, 0.0, -1.0)),
                        l.measured.highlight_radius.unwrap_or(0.0),
                    );
                    for (i, s) in sp.iter().enumerate() {
                        pl.add_sphere(i, &s.obs, Some(&s.px));
                    }
                    pl
                };
                format!("{:.2}", {
                    let hl = pooled.highlight_cells(jf.chosen.highlight_block_px);
                    pooled
                        .shift(
                            &pooled.merged(f),
                            &hl,
                            &jf.model,
                            &all.fit.params,
                            all.fit.free,
                        )
                        .max_std
                })
            } else {
                "—".into()
            },
            100.0 * worst(&m.sigma0_mm, &t.sigma0_mm),
            jf.fit
                .params
                .light
                .direction()
                .angle(&Vector3::from(t.light_direction))
                .to_degrees()
        );
        plot.layers.push(Layer::Points {
            xy: vec![(*secs, shift.max(1e-3).log10())],
            color: PALETTE[k % PALETTE.len()],
            size: 6,
            label: Some(format!(
                "{name}{}",
                if name == "auto" {
                    format!(" ({}°)", jf.chosen.width_deg)
                } else {
                    String::new()
                }
            )),
        });
    }
    std::fs::create_dir_all(out).unwrap();
    plot.save(&out.join("reduction")).unwrap();
}

fn large(out: &Path) {
    let mut cam = session::default_camera();
    cam.fx *= 6000.0 / 1280.0;
    cam.fy = cam.fx;
    cam.cx = 2999.5;
    cam.cy = 1999.5;
    cam.image_size = [6000, 4000];
    let cfg = SessionConfig {
        camera: cam,
        ..SessionConfig::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let gen = session::generate(&cfg, dir.path(), None, true).unwrap();
    let det = detect(dir.path());
    let f = solve_with(dir.path(), "fit.json", |_| {});
    let r = f.reduction.as_ref().unwrap();
    println!(
        "\n24 MP: 5 photos, {} pixels on the spheres; detection {det:.1} s; decode {:.2} s; samples {:.2} s; solve {:.2} s ({}° cells, {} observations) = {:.2}× the decode time; σ0 error {:.3}%, light {:.4}°",
        r.pixels,
        f.timings.decode_s,
        f.timings.samples_s,
        f.timings.solve_s,
        r.chosen.width_deg,
        r.chosen.observations,
        f.timings.solve_s / f.timings.decode_s,
        100.0 * worst(&f.sigma0_mm, &gen.truth.sigma0_mm),
        light_deg(&f.light_direction, &gen.truth.light_direction)
    );
    let _ = out;
}

/// Part 4 on a physically based session with a `truth.json` (`workbench synth pbr`'s, as
/// datasets/pbr-wax, or ../shared/data/pbr-jade's), solved in a copy of its folder.
fn pbr(src: &Path) {
    let copy = tempfile::tempdir().unwrap();
    for e in std::fs::read_dir(src).unwrap() {
        let p = e.unwrap().path();
        if p.is_file() {
            std::fs::copy(&p, copy.path().join(p.file_name().unwrap())).unwrap();
        }
    }
    let dir = copy.path();
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap()).unwrap();
    let l_true: [f64; 3] =
        serde_json::from_value(truth["light"]["direction_to_light_camera_frame"].clone()).unwrap();
    // Each photo's radius (one sphere a photo) and the render's own relative noise.
    let noise: Vec<(f64, f64)> = truth["images"]
        .as_array()
        .unwrap()
        .iter()
        .map(|im| {
            let r = im["radius_mm"]
                .as_f64()
                .or_else(|| im["spheres"][0]["radius_mm"].as_f64())
                .unwrap();
            (r, im["noise_rel_median_lit"].as_f64().unwrap())
        })
        .collect();
    println!(
        "\nPhysically based session {} ({})\n",
        src.display(),
        truth["what"].as_str().unwrap_or("")
    );
    let joint = solve_with(dir, "fit-bench-joint.json", |_| {});
    let paper = solve_with(dir, "fit-bench-paper.json", |o| o.method = Method::Paper);
    for (n, f) in [("joint", &joint), ("paper", &paper)] {
        println!(
            "{n}: σ0 {:.3?} ± {:.3?} mm, albedo {:.4?}, η {:.3} ± {:.3}, light error {:.3}° (stated ± {:.3}°), rel. RMSE {:.4}",
            f.sigma0_mm,
            f.std.sigma0_mm,
            f.albedo,
            f.eta,
            f.std.eta,
            light_deg(&f.light_direction, &l_true),
            f.std.light_deg,
            f.rmse.relative
        );
    }
    if let Some(pr) = &paper.per_radius {
        for r in pr {
            println!("paper r {} mm: σ0 {:.3?} mm", r.radius_mm, r.sigma0_mm);
        }
    }
    println!("\n| held-out radius (mm) | render noise (rel.) | joint rel. RMSE | joint lit / unlit | paper rel. RMSE | paper lit / unlit |");
    println!("|---|---|---|---|---|---|");
    for &(r, nz) in &noise {
        let j = solve_with(dir, "fit-bench-h.json", |o| o.holdout = Some(r));
        let p = solve_with(dir, "fit-bench-hp.json", |o| {
            o.holdout = Some(r);
            o.method = Method::Paper;
        });
        let (jh, ph) = (j.holdout.unwrap(), p.holdout.unwrap());
        println!(
            "| {r} | {nz:.4} | {:.4} | {:.4} / {:.4} | {:.4} | {:.4} / {:.4} |",
            jh.rel_rmse,
            jh.lit_rel_rmse,
            jh.unlit_rel_rmse,
            ph.rel_rmse,
            ph.lit_rel_rmse,
            ph.unlit_rel_rmse
        );
    }
    let auto = solve_with(dir, "fit-bench-auto.json", |o| {
        o.fit.extensions = ExtensionChoice::Auto
    });
    if let Some(mc) = &auto.model_choice {
        for c in &mc.candidates {
            println!(
                "model {}: held-out rel. RMSE {:.4}",
                c.extensions, c.heldout_rel_rmse
            );
        }
        println!("chosen {} ({})", mc.chosen, mc.reason);
    }
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    if std::env::args().any(|a| a == "--pbr-only") {
        match std::env::var("PBR_SESSION") {
            Ok(p) => pbr(Path::new(&p)),
            Err(_) => println!("--pbr-only needs PBR_SESSION"),
        }
        return;
    }
    let out = PathBuf::from("target/bench-solve");
    println!("| session | method | σ0 error (%) | σ0 error / std | albedo error (%) | light error (°) | η error ± std | ks error (%) | α error (%) | solve (s) |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let base = SessionConfig::default();
    let mut cases = vec![
        ("16-bit PNG, 1% noise", base.clone()),
        (
            "16-bit PNG, 5% noise",
            SessionConfig {
                noise: 0.05,
                ..base.clone()
            },
        ),
        (
            "8-bit JPEG, 1% noise",
            SessionConfig {
                format: Format::Jpeg,
                ..base.clone()
            },
        ),
    ];
    if !quick {
        cases.push((
            "8-bit JPEG, 5% noise",
            SessionConfig {
                format: Format::Jpeg,
                noise: 0.05,
                ..base.clone()
            },
        ));
    }
    for (label, cfg) in &cases {
        accuracy(label, cfg);
    }
    let dir = tempfile::tempdir().unwrap();
    let gen = session::generate(&base, dir.path(), None, true).unwrap();
    detect(dir.path());
    reduction_curve("5 radii, 1280×960, 1% noise", dir.path(), &gen.truth, &out);
    if !quick {
        large(&out);
    }
    if let Ok(p) = std::env::var("PBR_SESSION") {
        pbr(Path::new(&p));
    } else {
        println!("\n(no PBR_SESSION: physically based part skipped)");
    }
}
