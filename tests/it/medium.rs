//! The physically shaped profile (issue 35): the classical dipole integrated over each sphere
//! (`model::dipole`, `model::sphere_profile`) and diffusion solved in it
//! (`model::sphere_diffusion`), predicted from the renders' own truth with no free parameter,
//! against the physically based photos' pixels.

use crate::common;
use nalgebra::Vector3;
use std::path::Path;
use workbench::fit::medium::described;
use workbench::model::boundary::Boundary;
use workbench::model::dipole::{Dipole, Medium};
use workbench::model::sphere_diffusion::{SphereDiffusion, Tabulated};
use workbench::model::sphere_profile::{over_sphere, radiance_factor};

/// Which model predicts M(θ).
#[derive(Clone, Copy, Debug)]
enum Predictor {
    /// The flat medium's dipole profile carried round the sphere by chord length.
    CarriedDipole,
    /// The diffusion equation solved in the sphere.
    ShellSources,
    /// The same with its sources along the refracted beams.
    BeamSources,
}

/// A physically based session's truth: per channel σa and σs′ (isotropic phase), η, the light
/// and the irradiance in the photos' units (both truth.json formats: `synth pbr`'s and
/// pbr-jade's).
struct Truth {
    media: [Medium; 3],
    /// The boundary's GGX roughness.
    alpha: f64,
    light: Vector3<f64>,
    irradiance: f64,
}

fn truth(dir: &Path) -> Truth {
    let t: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).unwrap()).unwrap();
    let m = &t["material"];
    let (sigma_t, albedo, eta) = if m["medium"].is_object() {
        (
            &m["medium"]["sigma_t"],
            &m["medium"]["albedo_rgb"],
            &m["boundary"]["int_ior"],
        )
    } else {
        (&m["sigma_t_per_mm"], &m["albedo_rgb"], &m["eta"])
    };
    let (sigma_t, eta) = (sigma_t.as_f64().unwrap(), eta.as_f64().unwrap());
    let alpha = m["boundary"]["alpha"]
        .as_f64()
        .or(m["alpha"].as_f64())
        .unwrap();
    let media =
        std::array::from_fn(|c| Medium::isotropic(sigma_t, albedo[c].as_f64().unwrap(), eta));
    let l = &t["light"]["direction_to_light_camera_frame"];
    Truth {
        media,
        alpha,
        light: Vector3::from_fn(|i, _| l[i].as_f64().unwrap()).normalize(),
        irradiance: t["irradiance_in_png_units"].as_f64().unwrap(),
    }
}

/// The physically based sessions: pbr-wax, pbr-soap and (with ../shared) pbr-jade.
fn render_sessions() -> Vec<std::path::PathBuf> {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut sessions = vec![
        repo.join("datasets/pbr-wax"),
        repo.join("datasets/pbr-soap"),
    ];
    if let Some(shared) = common::shared_data() {
        sessions.push(shared.join("pbr-jade"));
    }
    sessions
}

/// θ bands (degrees) the comparison is reported in.
const BANDS: [(f64, f64); 6] = [
    (0.0, 20.0),
    (20.0, 40.0),
    (40.0, 60.0),
    (60.0, 80.0),
    (80.0, 100.0),
    (100.0, 180.0),
];

/// A session loaded as `solve` loads it, quietly.
fn load_quiet(dir: &Path) -> workbench::solve::Loaded {
    workbench::solve::load(&{
        let mut o = workbench::solve::Options::new(dir);
        o.quiet = true;
        o
    })
    .unwrap()
}

/// A session loaded as `solve --model medium` loads it (with the outlines drawn for the medium),
/// quietly.
fn load_for_the_medium(dir: &Path) -> workbench::solve::Loaded {
    workbench::solve::load(&{
        let mut o = workbench::solve::Options::new(dir);
        o.quiet = true;
        o.model = workbench::solve::SolveModel::Medium;
        o
    })
    .unwrap()
}

/// Per channel, per θ band of [`BANDS`]: a mean ratio, or None.
type PerChannelBands = [[Option<f64>; 6]; 3];

/// Per radius and channel: the photos' pixels over the dipole's prediction, mean per θ band
/// (None where a band has no pixel), away from the highlight (the half vector within 25° of the
/// normal) and the rim (φ beyond 75°, where the rough boundary and the outline's pixels rule).
fn ratios(dir: &Path, predictor: Predictor) -> Vec<(String, f64, PerChannelBands)> {
    let t = truth(dir);
    let loaded = load_quiet(dir);
    loaded
        .spheres
        .iter()
        .map(|s| {
            let per_channel = std::array::from_fn(|c| {
                let d = Dipole::new(&t.media[c]);
                let sphere = match predictor {
                    Predictor::BeamSources => SphereDiffusion::with_sources(
                        &t.media[c],
                        s.radius_mm,
                        workbench::model::sphere_diffusion::Sources::Beam(4),
                    ),
                    _ => SphereDiffusion::new(&t.media[c], s.radius_mm),
                };
                let m_of = |cos_theta: f64| match predictor {
                    Predictor::CarriedDipole => over_sphere(
                        |r| d.profile(r),
                        s.radius_mm,
                        cos_theta,
                        t.media[c].eta,
                        d.reach(),
                        d.z_r,
                    ),
                    Predictor::ShellSources | Predictor::BeamSources => sphere.m(cos_theta),
                };
                let table = Tabulated::from_fn(m_of);
                let mut sums = [(0.0, 0usize); 6];
                for o in &s.obs {
                    let (n, v) = (o.geometry.normal, o.geometry.view);
                    let (cos_theta, cos_phi) = (n.dot(&t.light), n.dot(&v));
                    if !described(&n, &v, &t.light) {
                        continue;
                    }
                    let theta = cos_theta.clamp(-1.0, 1.0).acos().to_degrees();
                    let m = table.at(cos_theta);
                    let predicted = t.irradiance * radiance_factor(m, cos_phi, t.media[c].eta);
                    if predicted <= 1e-6 * t.irradiance {
                        continue;
                    }
                    let b = BANDS
                        .iter()
                        .position(|&(lo, hi)| theta >= lo && theta < hi)
                        .unwrap();
                    sums[b].0 += o.radiance[c] / predicted;
                    sums[b].1 += 1;
                }
                sums.map(|(sum, n)| (n > 20).then(|| sum / n as f64))
            });
            (s.image.clone(), s.radius_mm, per_channel)
        })
        .collect()
}

/// The table behind docs/medium.md, run by hand (about 45 s): pbr-wax, pbr-soap and (with
/// ../shared) pbr-jade's single-sphere photos, by the three predictors. Measured (2026-12-04),
/// the photos over the prediction by θ band (0–20°, …, 80–100°): the dipole carried round the
/// sphere 0.82–1.35 below 60° and 2–3 at 80–100°; diffusion solved in the sphere 0.98–1.16
/// below 60° and 1.2–2.3 at 80–100°; with its sources along the refracted beams 0.99–1.10
/// below 60°, 0.97–1.05 at 60–80° and 0.98–1.65 at 80–100°.
#[test]
#[ignore = "by hand: cargo test --release --test it -- --ignored medium::profiles_against_the_renders --nocapture"]
fn profiles_against_the_renders() {
    let sessions = render_sessions();
    for (src, predictor) in sessions.iter().flat_map(|s| {
        [
            Predictor::CarriedDipole,
            Predictor::ShellSources,
            Predictor::BeamSources,
        ]
        .map(|p| (s.clone(), p))
    }) {
        let dir = common::session_copy(&src);
        for (image, radius, per_channel) in ratios(dir.path(), predictor) {
            // pbr-jade's row.png: the spheres stand side by side and light each other's dark
            // sides (up to 60× the prediction past the terminator), which no single-sphere
            // profile holds.
            if image == "row.png" {
                continue;
            }
            for (c, bands) in per_channel.iter().enumerate() {
                println!(
                    "{predictor:?} {} {image} r {radius} {}: {}",
                    src.file_name().unwrap().to_string_lossy(),
                    ["r", "g", "b"][c],
                    bands
                        .iter()
                        .map(|b| b.map_or("   –  ".to_string(), |v| format!("{v:6.3}")))
                        .collect::<Vec<_>>()
                        .join(" ")
                );
            }
        }
    }
}

/// The photon tally of one sphere behind a smooth boundary.
fn smooth_tally(
    radius: f64,
    sigma_t: f64,
    albedo: f64,
    eta: f64,
    photons: u64,
    seed: u64,
) -> workbench::synth::photon_tally::Tally {
    tally((radius, sigma_t, albedo, eta, 0.0), photons, seed)
}

/// The photon tally of one sphere: (radius, σt, albedo, η, GGX α; α 0 is smooth).
fn tally(
    (radius, sigma_t, albedo, eta, alpha): (f64, f64, f64, f64, f64),
    photons: u64,
    seed: u64,
) -> workbench::synth::photon_tally::Tally {
    workbench::synth::photon_tally::trace(
        &workbench::synth::photon_tally::TallyScene {
            radius,
            sigma_t,
            albedo,
            eta,
            alpha,
        },
        photons,
        seed,
    )
}

/// The model's M(θ) averaged over a band of θ (uniform in cos θ, as the tally's area is).
fn band_mean(model: &SphereDiffusion, lo_deg: usize, hi_deg: usize) -> f64 {
    band_mean_of(|c| model.m(c), lo_deg, hi_deg)
}

/// Any M, given as a function of cos θ, averaged over a band of θ as [`band_mean`] does.
fn band_mean_of(m: impl Fn(f64) -> f64, lo_deg: usize, hi_deg: usize) -> f64 {
    let (c0, c1) = (
        (lo_deg as f64).to_radians().cos(),
        (hi_deg as f64).to_radians().cos(),
    );
    (0..64)
        .map(|k| m(c0 + (c1 - c0) * (k as f64 + 0.5) / 64.0))
        .sum::<f64>()
        / 64.0
}

/// The table behind docs/medium.md ("The fit's profile against the photon tally"), run by
/// hand (about 40 s): the profile the medium fit uses (the atlas's M: beam sources, level
/// corrected, entering through a GGX boundary of α 0.1) against the photon tally with the same
/// boundary, over the issue's range: radius 15 and 35 mm, σt 0.5, 1 and 3 /mm, albedo 0.7,
/// 0.9, 0.97 and 0.995, η 1.3 and 1.6; a million photons each. Per sphere, the largest
/// |tally/model − 1| over the four bands from 0 to 80° and the ratio at 80–90°.
#[test]
#[ignore = "by hand: cargo test --release --test it -- --ignored medium::the_fit_profile_against_the_photon_tally --nocapture"]
fn the_fit_profile_against_the_photon_tally() {
    use workbench::model::sphere_atlas::{Coordinates, SphereAtlas};
    let alpha = 0.1;
    let atlas = SphereAtlas::new(alpha);
    for sigma_t in [0.5, 1.0, 3.0] {
        for albedo in [0.7, 0.9, 0.97, 0.995] {
            let cells: Vec<String> = [(15.0, 1.3), (15.0, 1.6), (35.0, 1.3), (35.0, 1.6)]
                .iter()
                .map(|&(radius, eta)| {
                    let t = tally((radius, sigma_t, albedo, eta, alpha), 1_000_000, 1);
                    let m = Medium::isotropic(sigma_t, albedo, eta);
                    let profile = atlas.profile(&Coordinates::of(&m, radius, alpha));
                    let ratio = |(lo, hi): (usize, usize)| {
                        t.exitance(lo, hi).value / band_mean_of(|c| profile.value.at(c), lo, hi)
                    };
                    let lit = TALLY_BANDS[..4]
                        .iter()
                        .map(|&b| (ratio(b) - 1.0).abs())
                        .fold(0.0f64, f64::max);
                    format!("{:.1}% / {:.2}", 100.0 * lit, ratio((80, 90)))
                })
                .collect();
            println!("| {sigma_t} | {albedo} | {} |", cells.join(" | "));
        }
    }
}

/// Diffusion in the sphere from sources along the refracted beams against the photon tally
/// (independent code: a light tracer with a smooth boundary), on a wax-like 15 mm sphere, θ from
/// 0 to 90° in five bands. Measured (2026-12-04): the tally over the model 1.006–1.014, a spread
/// of 0.008; the shell below each entry point spreads 0.977–1.289 on the same tally.
#[test]
fn the_beam_sources_follow_the_photon_tally() {
    use workbench::model::sphere_diffusion::Sources;
    use workbench::synth::photon_tally::{trace, TallyScene};
    let scene = TallyScene {
        radius: 15.0,
        sigma_t: 1.0,
        albedo: 0.97,
        eta: 1.44,
        alpha: 0.0,
    };
    let tally = trace(&scene, 2_000_000, 1);
    let medium = Medium {
        sigma_a: 0.03,
        sigma_s_reduced: 0.97,
        eta: 1.44,
    };
    let ratios = |sources| {
        let model = SphereDiffusion::with_sources(&medium, 15.0, sources);
        [(0, 20), (20, 40), (40, 60), (60, 80), (80, 90)].map(|(lo, hi)| {
            let e = tally.exitance(lo, hi);
            assert!(e.std < 0.005 * e.value, "{e:?}");
            e.value / band_mean(&model, lo, hi)
        })
    };
    let spread = |r: &[f64; 5]| {
        r.iter().cloned().fold(f64::MIN, f64::max) - r.iter().cloned().fold(f64::MAX, f64::min)
    };
    let beam = ratios(Sources::Beam(4));
    println!("beam {beam:?}, shell {:?}", ratios(Sources::Shell));
    assert!(beam.iter().all(|r| (r - 1.0).abs() < 0.03), "{beam:?}");
    assert!(spread(&beam) < 0.025, "{beam:?}");
    assert!(spread(&ratios(Sources::Shell)) > 0.1);
}

/// The level correction on media it was not fitted on (other sizes, albedos and indices,
/// 1.5 million photons each): the corrected beam model within 1.5% of the tally over θ 0–60°
/// (measured at most 0.5%), where the uncorrected one is 8.5% off at albedo 0.75 (1.6% and
/// 0.9% on the other two).
#[test]
fn the_level_correction_holds_on_unseen_media() {
    use workbench::model::sphere_diffusion::Sources;
    for (radius, sigma_t, albedo, eta) in [
        (20.0, 2.0, 0.75, 1.5),
        (30.0, 0.8, 0.92, 1.38),
        (18.0, 1.5, 0.985, 1.55),
    ] {
        let tally = smooth_tally(radius, sigma_t, albedo, eta, 1_500_000, 21);
        let m = Medium::isotropic(sigma_t, albedo, eta);
        let e = tally.exitance(0, 60).value;
        let corrected = e / band_mean(&SphereDiffusion::corrected(&m, radius), 0, 60);
        let raw = e / band_mean(
            &SphereDiffusion::with_sources(&m, radius, Sources::Beam(4)),
            0,
            60,
        );
        println!("α {albedo}: corrected {corrected:.4}, uncorrected {raw:.4}");
        assert!((corrected - 1.0).abs() < 0.015, "α {albedo}: {corrected}");
        if albedo < 0.8 {
            assert!((raw - 1.0).abs() > 0.05, "α {albedo}: {raw}");
        }
    }
}

/// θ bands (degrees) of the tally comparison.
const TALLY_BANDS: [(usize, usize); 7] = [
    (0, 20),
    (20, 40),
    (40, 60),
    (60, 80),
    (80, 90),
    (90, 100),
    (100, 120),
];

/// The table behind docs/medium.md ("Against the photon tally"), run by hand (about 3 min):
/// diffusion in the sphere, with its sources on a shell and along the refracted beams, against
/// the photon tally over the issue's range (radius 15 and 35 mm, σt 0.5–3 /mm, albedo
/// 0.7–0.995, η 1.3–1.6), the tally over the model per θ band.
#[test]
#[ignore = "by hand: cargo test --release --test it -- --ignored medium::diffusion_against_the_photon_tally --nocapture"]
fn diffusion_against_the_photon_tally() {
    use workbench::model::sphere_diffusion::Sources;
    for (radius, sigma_t, albedo, eta) in range_spheres() {
        let t = smooth_tally(radius, sigma_t, albedo, eta, 2_000_000, 1);
        let m = Medium::isotropic(sigma_t, albedo, eta);
        for v in [Sources::Shell, Sources::Beam(4)] {
            let model = SphereDiffusion::with_sources(&m, radius, v);
            let cells: Vec<String> = TALLY_BANDS
                .iter()
                .map(|&(lo, hi)| {
                    let e = t.exitance(lo, hi);
                    format!("{:6.3}", e.value / band_mean(&model, lo, hi))
                })
                .collect();
            println!(
                "R {radius:4} σt {sigma_t:3} α {albedo:5} η {eta:4} {:10}: {}",
                format!("{v:?}"),
                cells.join(" ")
            );
        }
    }
}

/// The 72 smooth spheres the profiles are compared on against the photon tally (radius, σt,
/// albedo, η): radius 15 and 35 mm, σt 0.5, 1 and 3 /mm, albedo 0.7–0.995, η 1.3–1.6.
fn range_spheres() -> impl Iterator<Item = (f64, f64, f64, f64)> {
    [15.0, 35.0].into_iter().flat_map(|radius| {
        [0.5, 1.0, 3.0].into_iter().flat_map(move |sigma_t| {
            [0.7, 0.9, 0.97, 0.995].into_iter().flat_map(move |albedo| {
                [1.3, 1.44, 1.6]
                    .into_iter()
                    .map(move |eta| (radius, sigma_t, albedo, eta))
            })
        })
    })
}

/// Christensen and Burley's normalized diffusion carried round the sphere by chord length, at
/// its best: per sphere its surface albedo A and width d fitted to the photon tally's five θ
/// bands from 0 to 90° (least squares in the log of the ratio; A in closed form, ln d by golden
/// section), beside the classical dipole carried the same way with its level fitted, and the
/// beam sources' ratio with nothing fitted. Over the spheres of `diffusion_against_the_photon_tally`
/// (the same photons), the table behind docs/medium.md ("Normalized diffusion carried round the
/// sphere"); run by hand (about 2 min).
#[test]
#[ignore = "by hand: cargo test --release --test it -- --ignored medium::normalized_diffusion_against_the_photon_tally --nocapture"]
fn normalized_diffusion_against_the_photon_tally() {
    use workbench::model::normalized_diffusion::NormalizedDiffusion;
    use workbench::model::sphere_diffusion::Sources;
    let lit = &TALLY_BANDS[..5];
    for (radius, sigma_t, albedo, eta) in range_spheres() {
        let t = smooth_tally(radius, sigma_t, albedo, eta, 2_000_000, 1);
        let tally: Vec<f64> = lit
            .iter()
            .map(|&(lo, hi)| t.exitance(lo, hi).value)
            .collect();
        let m = Medium::isotropic(sigma_t, albedo, eta);
        let carried = |profile: &dyn Fn(f64) -> f64, reach: f64, scale: f64| {
            lit.iter()
                .map(|&(lo, hi)| {
                    band_mean_of(
                        |c| over_sphere(profile, radius, c, eta, reach, scale),
                        lo,
                        hi,
                    )
                })
                .collect::<Vec<f64>>()
        };
        let burley = |d: f64| {
            let p = NormalizedDiffusion {
                surface_albedo: 1.0,
                d,
            };
            carried(&|r| p.profile(r), p.reach(), d)
        };
        let misfit = |ln_d: f64| {
            let (_, r) = level_out(&tally, &burley(ln_d.exp()));
            r.iter().map(|x| x.ln().powi(2)).sum::<f64>()
        };
        let ln_d = golden_section(
            (0.02 / m.sigma_t_reduced()).ln(),
            (10.0 / m.sigma_tr()).ln(),
            misfit,
        );
        let d = ln_d.exp();
        let (a, fitted) = level_out(&tally, &burley(d));
        let dipole = Dipole::new(&m);
        let (dipole_level, dipole_shape) = level_out(
            &tally,
            &carried(&|r| dipole.profile(r), dipole.reach(), dipole.z_r),
        );
        let beam = SphereDiffusion::with_sources(&m, radius, Sources::Beam(4));
        let beam_ratios: Vec<f64> = lit
            .iter()
            .zip(&tally)
            .map(|(&(lo, hi), t)| t / band_mean(&beam, lo, hi))
            .collect();
        let cells = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x:6.3}"))
                .collect::<Vec<_>>()
                .join(" ")
        };
        println!(
                        "R {radius:4} σt {sigma_t:3} α {albedo:5} η {eta:4} | burley A {a:.3} \
                         d·σtr {:.3} d·σt′ {:.3}: {} spread {:.3} | dipole level {dipole_level:.3}: \
                         {} spread {:.3} | beam: {} spread {:.3}",
                        d * m.sigma_tr(),
                        d * m.sigma_t_reduced(),
                        cells(&fitted),
                        spread(&fitted),
                        cells(&dipole_shape),
                        spread(&dipole_shape),
                        cells(&beam_ratios),
                        spread(&beam_ratios),
                    );
    }
}

/// The largest over the smallest of `ratios`, less 1.
fn spread(ratios: &[f64]) -> f64 {
    let (lo, hi) = ratios
        .iter()
        .fold((f64::MAX, f64::MIN), |(lo, hi), &r| (lo.min(r), hi.max(r)));
    hi / lo - 1.0
}

/// The level that scales `model` to `tally` in the least squares of their log ratio (its
/// geometric mean), and the ratios with it taken out.
fn level_out(tally: &[f64], model: &[f64]) -> (f64, Vec<f64>) {
    let logs: Vec<f64> = tally.iter().zip(model).map(|(t, m)| (t / m).ln()).collect();
    let mean = logs.iter().sum::<f64>() / logs.len() as f64;
    (mean.exp(), logs.iter().map(|l| (l - mean).exp()).collect())
}

/// The minimum of a unimodal `f` on [a, b], to 1e-4 of the interval.
fn golden_section(mut a: f64, mut b: f64, f: impl Fn(f64) -> f64) -> f64 {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (f(c), f(d));
    let width = b - a;
    while b - a > 1e-4 * width {
        if fc < fd {
            b = d;
            (d, fd) = (c, fc);
            c = b - g * (b - a);
            fc = f(c);
        } else {
            a = c;
            (c, fc) = (d, fd);
            d = a + g * (b - a);
            fd = f(d);
        }
    }
    0.5 * (a + b)
}

/// The radiance's angular law in the photon tally, per exit cosine μ (ten bins), over the
/// Jensen et al. law T(μ)/π (docs/medium.md, "The exit's angular law"), run by hand (about
/// 20 s). Measured (2026-12-04), θ 0–40°: 1.07–1.16 for μ above 0.1 and 1.38–1.44 below, with
/// η 1.44–1.62; index-matched (η = 1), 0.79–1.03, rising with μ.
#[test]
#[ignore = "by hand: cargo test --release --test it -- --ignored medium::angular_law_against_the_photon_tally --nocapture"]
fn angular_law_against_the_photon_tally() {
    use workbench::synth::photon_tally::{trace, TallyScene};
    for (sigma_t, albedo, eta) in [(1.0, 0.999, 1.0), (1.0, 0.97, 1.44), (2.0, 0.9, 1.62)] {
        let t = trace(
            &TallyScene {
                radius: 25.0,
                sigma_t,
                albedo,
                eta,
                alpha: 0.0,
            },
            4_000_000,
            3,
        );
        for (lo, hi) in [(0, 40), (60, 80)] {
            let law = t.angular(lo, hi);
            let cells: Vec<String> = law
                .iter()
                .enumerate()
                .map(|(k, l)| {
                    let mu = (k as f64 + 0.5) / 10.0;
                    format!(
                        "{:5.3}",
                        l / (workbench::model::fresnel::transmission(mu, eta)
                            / std::f64::consts::PI)
                    )
                })
                .collect();
            println!(
                "σt {sigma_t} α {albedo} η {eta} θ {lo}–{hi}: {}",
                cells.join(" ")
            );
        }
    }
}

/// One channel's pixels of one sphere for the medium fit: (cos θ, cos φ, radiance, 1/σ of its
/// noise).
type Pixels = Vec<(f64, f64, f64, f64)>;

/// The pixels the comparisons use (away from the highlight and the rim), per sphere and channel.
fn fit_pixels(dir: &Path, t: &Truth) -> Vec<(f64, [Pixels; 3])> {
    let loaded = load_quiet(dir);
    loaded
        .spheres
        .iter()
        .filter(|s| s.image != "row.png")
        .map(|s| {
            let per = std::array::from_fn(|c| {
                s.obs
                    .iter()
                    .filter_map(|o| {
                        let (n, v) = (o.geometry.normal, o.geometry.view);
                        (described(&n, &v, &t.light) && o.weight[c] > 0.0).then_some((
                            n.dot(&t.light),
                            n.dot(&v),
                            o.radiance[c],
                            o.weight[c],
                        ))
                    })
                    .collect()
            });
            (s.radius_mm, per)
        })
        .collect()
}

/// The exit law's factor over T(μ)/π at μ: `law` per tenth of μ, linear between their middles
/// (one value: a constant).
fn exit(law: &[f64], mu: f64) -> f64 {
    if law.len() == 1 {
        return law[0];
    }
    let x = (mu * law.len() as f64 - 0.5).clamp(0.0, (law.len() - 1) as f64);
    let (i, f) = ((x.floor() as usize).min(law.len() - 2), x - x.floor());
    law[i] * (1.0 - f) + law[i + 1] * f
}

/// Weighted residuals of one channel over every sphere for σa = e^{u0}, σs′ = e^{u1}.
fn medium_residuals(
    u: [f64; 2],
    eta: f64,
    corrected: bool,
    exit_law: &[f64],
    irradiance: f64,
    spheres: &[(f64, &Pixels)],
) -> Vec<f64> {
    use workbench::model::sphere_diffusion::Sources;
    let m = Medium {
        sigma_a: u[0].exp(),
        sigma_s_reduced: u[1].exp(),
        eta,
    };
    use rayon::prelude::*;
    spheres
        .par_iter()
        .flat_map_iter(|&(radius, px)| {
            let model = if corrected {
                SphereDiffusion::corrected(&m, radius)
            } else {
                SphereDiffusion::with_sources(&m, radius, Sources::Beam(4))
            };
            let table = Tabulated::from_fn(|c| model.m(c));
            px.iter()
                .map(|&(ct, cp, l, w)| {
                    let mm = table.at(ct);
                    let pred = irradiance * radiance_factor(mm, cp, eta) * exit(exit_law, cp);
                    (l - pred) * w
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// The fit table of docs/medium.md, run by hand (3–15 min; `SESSION=pbr-soap` for one
/// session): σa and σs′ per channel fitted to the renders' pixels (away from the highlight and
/// the rim) with diffusion in the sphere from beam sources, under four exit laws (the last also
/// with the level corrected), the light, η
/// and the irradiance held at the truth; Levenberg–Marquardt with a finite-difference Jacobian
/// in (ln σa, ln σs′) and steps of at most 0.3. Measured (2026-12-04) with the rough boundary's
/// law from the photon tally: soap σa within 1.0%, σs′ +2.5 to +6.9%, residuals 0.82–1.06×
/// the noise; wax σa −14 to +2%, σs′ −17 to +6%, 1.3–2.0×; jade σa −10 to −5%, σs′ −28 to
/// −18%, 4.3–11×.
#[test]
#[ignore = "by hand: cargo test --release --test it -- --ignored medium::fit_against_the_renders --nocapture"]
fn fit_against_the_renders() {
    let sessions = render_sessions();
    // The exit laws: Jensen et al.'s T/π; normalised by ∫T 2μ dμ; the photon tally's (its
    // radiance per unit exitance over T/π per tenth of μ, θ 0–60°, on a 25 mm sphere of the
    // channel's medium).
    let laws = |m: &Medium, alpha: f64| -> Vec<(&'static str, bool, Vec<f64>)> {
        use workbench::synth::photon_tally::{trace, TallyScene};
        let k = 2000;
        let c: f64 = (0..k)
            .map(|i| {
                let mu = (i as f64 + 0.5) / k as f64;
                workbench::model::fresnel::transmission(mu, m.eta) * 2.0 * mu / k as f64
            })
            .sum();
        let sigma_t = m.sigma_a + m.sigma_s_reduced;
        let tally = |alpha: f64| {
            trace(
                &TallyScene {
                    radius: 25.0,
                    sigma_t,
                    albedo: m.sigma_s_reduced / sigma_t,
                    eta: m.eta,
                    alpha,
                },
                4_000_000,
                5,
            )
        };
        let (smooth, rough) = (tally(0.0), tally(alpha));
        // The rough boundary's law per unit of the smooth one's exitance (the model's M).
        let level = rough.exitance(0, 60).value / smooth.exitance(0, 60).value;
        let law = |t: &workbench::synth::photon_tally::Tally, scale: f64| -> Vec<f64> {
            t.angular(0, 60)
                .iter()
                .enumerate()
                .map(|(i, l)| {
                    let mu = (i as f64 + 0.5) / 10.0;
                    scale * l
                        / (workbench::model::fresnel::transmission(mu, m.eta)
                            / std::f64::consts::PI)
                })
                .collect()
        };
        let rough_law = law(&rough, level);
        vec![
            ("T/π", false, vec![1.0]),
            ("T/(πc)", false, vec![1.0 / c]),
            ("tally", false, law(&smooth, 1.0)),
            ("rough tally", false, rough_law.clone()),
            ("rough tally, level corrected", true, rough_law),
        ]
    };
    let only = std::env::var("SESSION").ok();
    for src in sessions
        .iter()
        .filter(|s| only.as_ref().is_none_or(|o| s.ends_with(o)))
    {
        let dir = common::session_copy(src);
        let t = truth(dir.path());
        let data = fit_pixels(dir.path(), &t);
        for c in 0..3 {
            for (name, corrected, law) in laws(&t.media[c], t.alpha) {
                let eta = t.media[c].eta;
                let spheres: Vec<(f64, &Pixels)> = data.iter().map(|(r, p)| (*r, &p[c])).collect();
                let f =
                    |u: [f64; 2]| medium_residuals(u, eta, corrected, &law, t.irradiance, &spheres);
                let n = f([0.0, 0.0]).len() as f64;
                let at_truth = f([t.media[c].sigma_a.ln(), t.media[c].sigma_s_reduced.ln()]);
                let truth_cost = at_truth.iter().map(|v| v * v).sum::<f64>();
                let mut u = [
                    (t.media[c].sigma_a * 1.5).ln(),
                    (t.media[c].sigma_s_reduced * 0.7).ln(),
                ];
                let mut r = f(u);
                let cost = |r: &[f64]| r.iter().map(|v| v * v).sum::<f64>();
                let mut lambda = 1e-3;
                for _ in 0..40 {
                    let jac: Vec<Vec<f64>> = (0..2)
                        .map(|k| {
                            let mut up = u;
                            up[k] += 1e-3;
                            f(up).iter().zip(&r).map(|(a, b)| (a - b) / 1e-3).collect()
                        })
                        .collect();
                    let jtj = |a: usize, b: usize| -> f64 {
                        jac[a].iter().zip(&jac[b]).map(|(x, y)| x * y).sum()
                    };
                    let jtr = |a: usize| -> f64 { jac[a].iter().zip(&r).map(|(x, y)| x * y).sum() };
                    let (a00, a01, a11) = (
                        jtj(0, 0) * (1.0 + lambda),
                        jtj(0, 1),
                        jtj(1, 1) * (1.0 + lambda),
                    );
                    let det = a00 * a11 - a01 * a01;
                    let (g0, g1) = (jtr(0), jtr(1));
                    let mut step = [-(a11 * g0 - a01 * g1) / det, -(a00 * g1 - a01 * g0) / det];
                    // A trust region: at most 0.3 in either logarithm per step.
                    let longest = step[0].abs().max(step[1].abs());
                    if longest > 0.3 {
                        step = step.map(|v| v * 0.3 / longest);
                    }
                    let trial = [u[0] + step[0], u[1] + step[1]];
                    let rt = f(trial);
                    if cost(&rt) < cost(&r) {
                        u = trial;
                        r = rt;
                        lambda *= 0.3;
                        if step[0].abs().max(step[1].abs()) < 1e-4 {
                            break;
                        }
                    } else {
                        lambda *= 10.0;
                    }
                }
                println!(
                    "{} {name} {}: σa {:.4} (truth {:.4}, {:+.1}%) σs′ {:.3} (truth {:.3}, {:+.1}%) residual {:.2}× noise (at the truth {:.2}×)",
                    src.file_name().unwrap().to_string_lossy(),
                    ["r", "g", "b"][c],
                    u[0].exp(),
                    t.media[c].sigma_a,
                    100.0 * (u[0].exp() / t.media[c].sigma_a - 1.0),
                    u[1].exp(),
                    t.media[c].sigma_s_reduced,
                    100.0 * (u[1].exp() / t.media[c].sigma_s_reduced - 1.0),
                    (cost(&r) / (n - 2.0)).sqrt(),
                    (truth_cost / n).sqrt()
                );
            }
        }
    }
}

/// The media the level correction is fitted on: (radius mm, σt /mm, η, albedo).
fn level_media() -> Vec<(f64, f64, f64, f64)> {
    let mut out = Vec::new();
    for (radius, sigma_t) in [(25.0, 1.0), (15.0, 0.5), (35.0, 3.0)] {
        for eta in [1.3, 1.45, 1.6] {
            for albedo in [
                0.6, 0.7, 0.8, 0.85, 0.9, 0.93, 0.95, 0.97, 0.98, 0.99, 0.995, 0.999,
            ] {
                out.push((radius, sigma_t, eta, albedo));
            }
        }
    }
    out
}

/// The coefficients of `sphere_diffusion::LEVEL_FIT` by hand (about 1 min): the beam model's
/// level against the photon tally over θ 0–60° on 108 spheres (three sizes σt·R 7.5–105, η
/// 1.3–1.6, albedo 0.6–0.999, a million photons each), fitted by least squares in the terms of
/// [`workbench::model::sphere_diffusion::level_terms`], with each size left out in turn.
/// Measured (2026-12-04): residuals at most 1.1% (rms 0.4–0.6% per size), left out 1.1–2.3%.
#[test]
#[ignore = "by hand: cargo test --release --test it -- --ignored medium::level_against_the_photon_tally --nocapture"]
fn level_against_the_photon_tally() {
    use nalgebra::{DMatrix, DVector};
    use workbench::model::sphere_diffusion::{level_terms, Sources, LEVEL_FIT};
    let media = level_media();
    let rows: Vec<([f64; 8], f64)> = media
        .iter()
        .map(|&(radius, sigma_t, eta, albedo)| {
            let t = smooth_tally(radius, sigma_t, albedo, eta, 1_000_000, 11);
            let m = Medium::isotropic(sigma_t, albedo, eta);
            let model = SphereDiffusion::with_sources(&m, radius, Sources::Beam(4));
            let ratio = t.exitance(0, 60).value / band_mean(&model, 0, 60);
            (level_terms(albedo, eta, sigma_t * radius), ratio)
        })
        .collect();
    let fit = |keep: &dyn Fn(usize) -> bool| {
        let kept: Vec<&([f64; 8], f64)> = rows
            .iter()
            .enumerate()
            .filter(|(i, _)| keep(*i))
            .map(|(_, r)| r)
            .collect();
        let x = DMatrix::from_fn(kept.len(), 8, |i, j| kept[i].0[j]);
        let y = DVector::from_fn(kept.len(), |i, _| kept[i].1 - 1.0);
        x.svd(true, true).solve(&y, 1e-12).unwrap()
    };
    let residual = |c: &DVector<f64>, i: usize| {
        let (terms, ratio) = rows[i];
        ratio / (1.0 + terms.iter().zip(c.iter()).map(|(t, c)| t * c).sum::<f64>()) - 1.0
    };
    let all = fit(&|_| true);
    println!(
        "LEVEL_FIT = {:?}",
        all.iter()
            .map(|v| (v * 1e5).round() / 1e5)
            .collect::<Vec<_>>()
    );
    let committed = DVector::from_column_slice(&LEVEL_FIT);
    for (radius, sigma_t) in [(25.0, 1.0), (15.0, 0.5), (35.0, 3.0)] {
        let size: Vec<usize> = (0..rows.len())
            .filter(|&i| media[i].0 == radius && media[i].1 == sigma_t)
            .collect();
        let held = fit(&|i| !size.contains(&i));
        let worst = |c: &DVector<f64>| {
            size.iter()
                .map(|&i| residual(c, i).abs())
                .fold(0.0, f64::max)
        };
        let raw = size
            .iter()
            .map(|&i| (rows[i].1 - 1.0).abs())
            .fold(0.0, f64::max);
        println!(
            "R {radius} σt {sigma_t}: uncorrected at most {raw:.4}, fitted {:.4}, committed {:.4}, left out {:.4}",
            worst(&all),
            worst(&committed),
            worst(&held)
        );
    }
}

/// By hand (about 20 s): what the renders' rough boundary does to M(θ) and to the exit law, on
/// the sessions' media (pbr-wax's blue at 15 and 35 mm, pbr-jade's red, pbr-soap's red) and
/// pbr-wax's blue with a smooth boundary: the tally over the level-corrected beam model per θ
/// band, and the exit law over T(μ)/π per tenth of μ in three bands of θ. Measured
/// (2026-12-04): smooth 0.998–1.012 from 0 to 90°; rough α 0.15 0.95 from 0 to 60° and
/// 1.16–1.34 at 80–90°; the law below μ = 0.1 2.2–3.3 (1.3–1.5 smooth).
#[test]
#[ignore = "by hand: cargo test --release --test it -- --ignored medium::rough_boundary_against_the_photon_tally --nocapture"]
fn rough_boundary_against_the_photon_tally() {
    use workbench::model::fresnel::transmission;
    use workbench::synth::photon_tally::{trace, TallyScene};
    for (radius, sigma_t, albedo, eta, alpha) in [
        (15.0, 1.0, 0.92, 1.44, 0.15),
        (35.0, 1.0, 0.92, 1.44, 0.15),
        (15.0, 1.0, 0.92, 1.44, 0.0),
        (25.0, 2.0, 0.9, 1.62, 0.05),
        (25.0, 0.5, 0.975, 1.4, 0.08),
    ] {
        let scene = TallyScene {
            radius,
            sigma_t,
            albedo,
            eta,
            alpha,
        };
        let t = trace(&scene, 2_000_000, 1);
        let m = Medium::isotropic(sigma_t, albedo, eta);
        let boundary = Boundary::rough(eta, alpha);
        for (name, model) in [
            ("smooth model", SphereDiffusion::corrected(&m, radius)),
            (
                "rough model",
                SphereDiffusion::through(&m, radius, &boundary),
            ),
        ] {
            let cells: Vec<String> = TALLY_BANDS
                .iter()
                .map(|&(lo, hi)| {
                    format!(
                        "{:6.3}",
                        t.exitance(lo, hi).value / band_mean(&model, lo, hi)
                    )
                })
                .collect();
            println!("{scene:?} {name}: {}", cells.join(" "));
        }
        for (lo, hi) in [(0, 40), (40, 70), (70, 90)] {
            let law: Vec<String> = t
                .angular(lo, hi)
                .iter()
                .enumerate()
                .map(|(k, l)| {
                    let mu = (k as f64 + 0.5) / 10.0;
                    format!("{:.3}", l / (transmission(mu, eta) / std::f64::consts::PI))
                })
                .collect();
            println!("   law θ {lo}–{hi}°: {}", law.join(" "));
            let law: Vec<String> = t
                .angular(lo, hi)
                .iter()
                .enumerate()
                .map(|(k, l)| {
                    let mu = (k as f64 + 0.5) / 10.0;
                    format!("{:.3}", l / boundary.exit_law(mu, m.reduced_albedo()))
                })
                .collect();
            println!("   over the model's law: {}", law.join(" "));
        }
    }
}

/// The model's rough boundary (`model::boundary`, quadrature over GGX normals) against the
/// renderer's own sampled one (`synth::dielectric`, independent code): the light a direction
/// sends in, per unit. 400 000 samples per direction (standard error ≤ 8e-4); measured within
/// 1.2e-3 (α 0.15) and 1.6e-3 (α 0.05) over μ 0.1–0.95, asserted 3e-3. And the sine of the
/// transmitted light's mean direction, which the beams follow: within 3.0e-3 (asserted 8e-3),
/// where Snell's is 0.135 off at μ 0.1, α 0.15 (0.826 against 0.691). (With ξ itself as the
/// quadrature's variable, μ 0.1 at α 0.05 was 7.6e-3 off: the visible normals' weight grows as
/// (1 − ξ)^{−1/2}.)
#[test]
fn the_rough_boundary_transmits_as_the_sampled_one() {
    const SINE_TOLERANCE: f64 = 8e-3;
    use rand::{Rng, SeedableRng};
    use workbench::synth::dielectric;
    let eta = 1.44;
    for alpha in [0.05, 0.15] {
        let model = Boundary::rough(eta, alpha);
        let sampled = dielectric::Boundary { eta, alpha };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let (mut worst, mut worst_sine): (f64, f64) = (0.0, 0.0);
        for mu in [0.1f64, 0.3, 0.6, 0.95] {
            // Light arrives along −ẑ; the surface normal makes cos μ with ẑ.
            let n = Vector3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
            let k = 400_000;
            let (mut sum, mut mean) = (0.0, Vector3::zeros());
            for _ in 0..k {
                let s = sampled.sample(&Vector3::z(), &n, rng.random());
                // The radiance weight carries (1/η)²; the light's flux does not.
                if s.transmitted {
                    sum += s.weight * eta * eta;
                    mean += s.wi * s.weight;
                }
            }
            let (a, b) = (model.transmission(mu), sum / k as f64);
            worst = worst.max((a - b).abs());
            assert!(
                (a - b).abs() < 3e-3,
                "α {alpha} μ {mu}: model {a}, sampled {b}"
            );
            // The transmitted light's mean direction, its sine from the inward normal.
            let sine = mean.cross(&n).norm() / mean.norm();
            let snell = (1.0 - mu * mu).sqrt() / eta;
            let model_sine = model.refracted_sine(mu);
            println!(
                "α {alpha} μ {mu}: sine model {model_sine:.4}, sampled {sine:.4}, Snell {snell:.4}"
            );
            worst_sine = worst_sine.max((model_sine - sine).abs());
            assert!(
                (model_sine - sine).abs() < SINE_TOLERANCE,
                "α {alpha} μ {mu}: sine model {model_sine}, sampled {sine}"
            );
        }
        println!("α {alpha}: worst difference {worst:.2e}, sine {worst_sine:.2e}");
    }
}

/// The rough boundary in the model against the photon tally with the renders' GGX boundary
/// (wax-like, α 0.15, 35 mm): near the terminator Fresnel's entry misses a third of the light
/// (the tally over the model measured 1.33 at 80–90°); T_α's entry with the beams along the
/// transmitted light's mean direction, 0.986 (1.05 with Snell's beams); on the lit side the
/// rough boundary's loss of level brings the model from 4% bright to 1.001 (0.983 and 0.998
/// with the level a fit, before 2026-12-08). Asserted: 80–90°
/// within 0.96–1.04 and Fresnel's > 1.2; 0–60° within 0.98–1.02.
#[test]
fn the_rough_entry_follows_the_photon_tally() {
    let (radius, sigma_t, albedo, eta, alpha) = (35.0, 1.0, 0.92, 1.44, 0.15);
    let t = tally((radius, sigma_t, albedo, eta, alpha), 1_000_000, 3);
    let m = Medium::isotropic(sigma_t, albedo, eta);
    let rough = SphereDiffusion::through(&m, radius, &Boundary::rough(eta, alpha));
    let smooth = SphereDiffusion::corrected(&m, radius);
    let ratio =
        |model: &SphereDiffusion, lo, hi| t.exitance(lo, hi).value / band_mean(model, lo, hi);
    let (lit, terminator) = (ratio(&rough, 0, 60), ratio(&rough, 80, 90));
    let smooth_terminator = ratio(&smooth, 80, 90);
    println!("rough: 0–60° {lit:.3}, 80–90° {terminator:.3}; smooth 80–90° {smooth_terminator:.3}");
    assert!((0.98..1.02).contains(&lit), "{lit}");
    assert!((0.96..1.04).contains(&terminator), "{terminator}");
    assert!(smooth_terminator > 1.2, "{smooth_terminator}");
}

/// `solve --model medium` on a physically based session with its irradiance: σa, σs′ and η
/// against the renders' truth, and fit.json's "medium" read back.
fn medium_solve(
    src: &Path,
    extra: &[&str],
) -> (tempfile::TempDir, Truth, workbench::formats::fit::FitFile) {
    let dir = common::session_copy(src);
    let (t, f) = medium_solve_in(&dir, extra);
    (dir, t, f)
}

/// Whether the note that σa or σs′ is poorly determined is there exactly where fit.json states a
/// channel's error past half its value; returns how many such notes.
fn poorly_determined_is_said(f: &workbench::formats::fit::FitFile) -> usize {
    let m = f.medium.as_ref().expect("fit.json's medium");
    let mut said = 0;
    for (name, q) in [
        ("σa", &m.sigma_a_per_mm),
        ("σs′", &m.sigma_s_reduced_per_mm),
    ] {
        let wide = (0..3).any(|c| q.std[c].is_nan() || q.std[c] > 0.5 * q.value[c].abs());
        let note = f
            .notes
            .iter()
            .any(|n| n.starts_with(&format!("medium: {name} is poorly determined")));
        assert_eq!(
            note, wide,
            "{name}: {:?} ± {:?}, notes {:?}",
            q.value, q.std, f.notes
        );
        said += usize::from(note);
    }
    said
}

/// [`medium_solve`] on a session copied already.
fn medium_solve_in(
    dir: &tempfile::TempDir,
    extra: &[&str],
) -> (Truth, workbench::formats::fit::FitFile) {
    let t = truth(dir.path());
    let e = format!("{}", t.irradiance);
    let d = dir.path().to_str().unwrap();
    let mut args = vec![
        "--quiet",
        "solve",
        d,
        "--model",
        "medium",
        "--irradiance",
        &e,
    ];
    args.extend_from_slice(extra);
    let (code, out, err) = common::wb(&args);
    assert_eq!(code, 0, "{out}\n{err}");
    let f: workbench::formats::fit::FitFile =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("fit.json")).unwrap())
            .unwrap();
    (t, f)
}

/// Soap-like renders (σt 0.5 /mm, η 1.4, GGX α 0.08) with the irradiance, the 15 mm sphere held
/// out: measured (2026-12-06, α measured: 0.088; the joint η's error widened by its α's
/// difference) η 1.399 against 1.4; σa −1.6, −1.4, −0.6%; σs′ +2.5, +2.2, +2.2%; residuals 0.86×
/// the noise; the held-out sphere 3.86% by the medium, 7.31%
/// by the CDRF on the same pixels; α 0.088 ± 0.020 (the model's own 20% included) from the
/// lobe's 0.071 ± 0.014 (asserted within 0.025 of the truth). (With the lobe's α held, 2026-12-05: σa −0.7, −1.8, −2.3%,
/// σs′ −1.3, −2.0, −2.5%, held out 3.82%. With the deepest shadow fitted too: σa +1.4, −0.2, −1.2%,
/// held out 3.96%; before the flux along the surface and η's combination: η 1.402, σa +5 to
/// +6%, σs′ +7 to +9%, held out 4.21%. Now, 2026-12-08, the noise a curve, the rough level
/// the tally's table and the surface's reflection in the model: η 1.397; σa −0.2, +0.2, +0.9%;
/// σs′ +2.0, +1.8, +2.0%; residuals 1.00× the noise; held out 3.90% against 7.33%. With the
/// exit's tilt the tally's law, 2026-12-09: η 1.401; σa −1.2, −0.7, −0.1%; σs′ +3.4, +2.7,
/// +2.6%; residuals 1.00×; held out 3.83%; α 0.088 ± 0.022; the loop 0.0373 ± 0.0012 against
/// the model's 0.0370. With the medium's outlines on their own edge model, 2026-12-07, latest:
/// η 1.400; σa −1.5, −1.0, −0.2%; σs′ +3.4, +2.7, +2.6%; residuals 1.00×; held out 3.76%;
/// α 0.091 ± 0.022.) Asserted: η within 0.015, σa and σs′ within 5%, residuals
/// below 1.1× the noise, the held-out error within 4.2% and below the CDRF's. (Coverage is not
/// asserted here: the stated errors' model term was set from this session and wax.)
#[test]
fn the_medium_of_the_soap_renders() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/pbr-soap");
    let (dir, t, f) = medium_solve(&src, &["--holdout", "15"]);
    let m = f.medium.as_ref().expect("fit.json's medium");
    assert!((m.eta.value - 1.4).abs() < 0.015, "η {}", m.eta.value);
    // The joint fit describes these photos (its residuals 1.19 times the noise): its η is
    // combined with the pixels'.
    let sources = m.eta_sources.as_ref().expect("η's sources");
    assert_eq!(sources.joint_combined, Some(true));
    // The roughness measured, from the lobe's α as its prior.
    let lobe = m.alpha_lobe.expect("the lobe's α, α's prior");
    println!(
        "α {:.4} ± {:.4} (truth {}; the lobe's {:.4} ± {:.4})",
        m.alpha,
        m.alpha_std.expect("α measured"),
        t.alpha,
        lobe.value,
        lobe.std
    );
    assert!((m.alpha - t.alpha).abs() < 0.025, "α {}", m.alpha);
    for c in 0..3 {
        let (a, s) = (&m.sigma_a_per_mm, &m.sigma_s_reduced_per_mm);
        let ea = a.value[c] / t.media[c].sigma_a - 1.0;
        let es = s.value[c] / t.media[c].sigma_s_reduced - 1.0;
        println!(
            "channel {c}: σa {:+.1}%, σs′ {:+.1}%",
            100.0 * ea,
            100.0 * es
        );
        assert!(ea.abs() < 0.05 && es.abs() < 0.05, "channel {c}: {ea} {es}");
    }
    assert!(m.residual_over_noise < 1.1, "{}", m.residual_over_noise);
    // Every value 1.5 times or more inside its range's edges: none said to be near one.
    assert!(
        !f.notes.iter().any(|n| n.contains("edge of the range")),
        "{:?}",
        f.notes
    );
    let h = m.holdout.expect("the held-out radius");
    println!(
        "held out: medium {:.4}, CDRF {:.4}",
        h.medium_rel_rmse, h.cdrf_rel_rmse
    );
    assert!(
        h.medium_rel_rmse < 0.042 && h.medium_rel_rmse < h.cdrf_rel_rmse,
        "{h:?}"
    );
    exports_read_back(&dir.path().join("fit.json"), m);
    the_loop_closes(&dir.path().join("fit.json"), m);
    the_medium_fit_is_drawn(&dir.path().join("fit.json"));
}

/// A corner of the issue's range whose joint fit's η is far off (`datasets/pbr-range/thin-dark`:
/// σt 0.5 /mm, albedo 0.70/0.75/0.80, η 1.6, GGX α 0.1; its highlights clipped over their core,
/// so the lobe's height is not seen and the joint fit reads η 2.67). Before the surface's
/// reflection was in the medium model (2026-12-08) its first stage ran to the walls of its range
/// and was started again (`fit::medium`'s second start), and the fit ended with σs′ +24–26% and
/// η +0.12, whose medium, path-traced, met the photos 1.91 times worse than the model (the loop
/// open). Measured now (2026-12-07, latest: the medium's outlines without the edge model's
/// T(φ)·cos φ term; 15 mm held out): σa +6.3, +6.2, +6.0%, σs′ +1.9, +1.9, +2.1%, η 1.578 ± 0.071, every
/// error within 0.49 of its std, residuals 1.04 of the noise, the first stage inside its range;
/// `close-loop` at 1024 spp and 400 pixels a sphere 1.06 (3.47 ± 0.12% against the model's
/// 3.27%; the build before 0.94). At 256 spp the render's own noise, 6.3%, was twice the
/// difference it measures, and the ratio went from 0.91 to 1.24 with the pixels the new
/// outlines chose (30 mm alone 0.34 → 1.72). Asserted: σa and σs′ within the issue's 10%, η
/// within 0.06, every error within 1.5 of its std, no edge note, and the loop closed (below
/// 1.2, no note).
#[test]
fn the_thin_dark_corner_is_measured_and_its_loop_closes() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/pbr-range/thin-dark");
    let (dir, t, f) = medium_solve(&src, &["--holdout", "15"]);
    let m = f.medium.as_ref().expect("fit.json's medium");
    let mut worst = (m.eta.value - t.media[0].eta).abs() / m.eta.std;
    for c in 0..3 {
        for (name, fitted, truth) in [
            ("σa", &m.sigma_a_per_mm, t.media[c].sigma_a),
            ("σs′", &m.sigma_s_reduced_per_mm, t.media[c].sigma_s_reduced),
        ] {
            let z = (fitted.value[c] - truth).abs() / fitted.std[c];
            let off = fitted.value[c] / truth - 1.0;
            println!(
                "channel {c}: {name} {:+.1}% ± {:.1}% ({z:.2} std)",
                100.0 * off,
                100.0 * fitted.std[c] / truth
            );
            assert!(off.abs() < 0.10, "{name} channel {c}: {off}");
            worst = worst.max(z);
        }
    }
    println!(
        "η {:.3} ± {:.3}, α {:.3}; worst error {worst:.2} std; notes {:?}",
        m.eta.value, m.eta.std, m.alpha, f.notes
    );
    assert!(
        !f.notes
            .iter()
            .any(|n| n.contains("ended at or near the edge")),
        "{:?}",
        f.notes
    );
    assert!(worst < 1.5, "{worst}");
    assert!(
        (m.eta.value - t.media[0].eta).abs() < 0.06,
        "{}",
        m.eta.value
    );
    let (j, stdout) = close_loop(
        &dir.path().join("fit.json"),
        &["--spp", "1024", "--pixels", "400"],
    );
    println!(
        "thin-dark close-loop: path-traced {:.4} ± {:.4}, model {:.4}, ratio {:.3}",
        j.overall.render_rel_rmse,
        j.overall.render_rel_rmse_std,
        j.overall.medium_rel_rmse,
        j.overall.render_over_medium
    );
    assert!(j.overall.render_over_medium < 1.2, "{:?}", j.overall);
    assert!(j.notes.is_empty(), "{:?}", j.notes);
    assert!(!stdout.contains("note:"), "{stdout}");
}

/// `workbench close-loop <fit> <args> --out <loop beside fit>`: its close-loop.json and what it
/// printed.
fn close_loop(fit: &Path, args: &[&str]) -> (workbench::synth::close_loop::CloseLoopJson, String) {
    let out = fit.with_file_name("loop");
    let mut all = vec!["close-loop", fit.to_str().unwrap()];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--out", out.to_str().unwrap()]);
    let (code, stdout, err) = common::wb(&all);
    assert_eq!(code, 0, "{err}");
    let j = serde_json::from_str(&std::fs::read_to_string(out.join("close-loop.json")).unwrap())
        .unwrap();
    (j, stdout)
}

/// The bundled physically based jade (../shared/data/pbr-jade, its five single-sphere photos:
/// σt 2 /mm, albedo 0.90/0.96/0.92, η 1.62, GGX α 0.05), whose faint lobe the joint fit reads as
/// α 0.13 ± 0.12: the medium fit measures the roughness from its pixels and, with it, σa and σs′.
/// Measured (2026-12-06, 15 mm held out): α 0.049 ± 0.023 (its error includes the model's own
/// 20%, set from the wax and soap renders, not this one); σa −6.2, −7.8, +0.8%; σs′ −4.9, −3.0,
/// +2.8%; η 1.681 ± 0.104; every σa, σs′, η and α error within 0.59 of its std. (With the
/// lobe's α held: σa +48, +10, +74%, σs′ +93, +63, +133%.) Since each model has its own
/// outlines (2026-12-07; docs/medium.md, "Each model its own outlines"): α 0.043 ± 0.020,
/// σa −5.4, −2.7, −5.8%, σs′ −0.2, +7.0, +0.2%, η 1.703 ± 0.108, every error within 0.77 of its
/// std; with the rough level the tally's table (2026-12-08): α 0.043 ± 0.020, σa −5.7, −2.6,
/// −6.0%, σs′ +0.2, +7.1, +0.6%, η 1.708 ± 0.109, within 0.81; with the surface's reflection in
/// the model too: α 0.042 ± 0.019, σa −4.7, −1.4, −5.0%, σs′ −1.4, +5.3, −1.0%, η 1.699 ± 0.114,
/// within 0.70; with the exit's tilt the tally's law (2026-12-09): α 0.042 ± 0.019, σa −2.1,
/// +1.8, −2.1%, σs′ −3.5, +2.7, −3.2%, η 1.677 ± 0.114, within 0.50; with the medium's outlines
/// on their own edge model (2026-12-07, latest): α 0.049 ± 0.012, σa −1.0, +2.5, −1.1%, σs′
/// −2.6, +3.4, −2.3%, η 1.674 ± 0.075, within 0.72; with the joint fit's η left out where its
/// model misses the photos (the same day; its residuals 9.0 times the noise): α 0.049 ± 0.012,
/// σa −1.7, +1.6, −1.8%, σs′ −2.0, +4.1, −1.7%, η 1.680 ± 0.076, within 0.79. Asserted: α
/// within 0.015 of the truth (the lobe's is 0.08 off), σa and σs′ within the issue's 10%, each
/// error within 1.5 of its stated std.
#[test]
fn the_bundled_jade_is_measured_with_its_roughness() {
    let Some(data) = common::shared_data() else {
        return;
    };
    let dir = common::session_copy(&data.join("pbr-jade"));
    let session = dir.path().join("session.json");
    let mut s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&session).unwrap()).unwrap();
    // row.png's spheres stand side by side and light each other: not the model's scene.
    s["images"]
        .as_array_mut()
        .unwrap()
        .retain(|i| i["file"] != "row.png");
    std::fs::write(&session, serde_json::to_string(&s).unwrap()).unwrap();
    let (t, f) = medium_solve_in(&dir, &["--holdout", "15"]);
    let m = f.medium.as_ref().expect("fit.json's medium");
    let alpha_std = m.alpha_std.expect("α measured");
    println!("α {:.4} ± {alpha_std:.4} (truth {})", m.alpha, t.alpha);
    assert!((m.alpha - t.alpha).abs() < 0.015, "α {}", m.alpha);
    let mut worst = ((m.eta.value - t.media[0].eta).abs() / m.eta.std)
        .max((m.alpha - t.alpha).abs() / alpha_std);
    for c in 0..3 {
        for (name, fitted, truth) in [
            ("σa", &m.sigma_a_per_mm, t.media[c].sigma_a),
            ("σs′", &m.sigma_s_reduced_per_mm, t.media[c].sigma_s_reduced),
        ] {
            let off = fitted.value[c] / truth - 1.0;
            println!(
                "channel {c}: {name} {:+.1}% ± {:.1}%",
                100.0 * off,
                100.0 * fitted.std[c] / truth
            );
            assert!(off.abs() < 0.10, "channel {c}: {name} {off}");
            worst = worst.max((fitted.value[c] - truth).abs() / fitted.std[c]);
        }
    }
    println!("worst error {worst:.2} std");
    assert!(worst < 1.5, "{worst}");
}

/// A jade-like render whose highlight clips on every sphere (`datasets/pbr-seeds/jade-6`: σt 2,
/// albedo 0.9/0.96/0.92, η 1.62, GGX α 0.05): the joint fit reads the clipped highlight's wings,
/// which hold F(η)·α², as α 0.094 ± 0.031 and η 1.405 ± 0.069. The medium measures α 0.041, and
/// the shift of η the joint fit's own η–α correlation gives for that difference (0.105) joins
/// the joint η's error before it is combined with the pixels' 1.696 ± 0.104. Measured
/// (2026-12-06, 15 mm held out): η 1.570 ± 0.144 (without the widening 1.494, red's σa +71%);
/// σa +38, +3, +12%; σs′ +22, −10, −2%; every σa, σs′ and η error within 0.34 of its std. With
/// the pixels' noise measured as a curve and the outlines weighing the rim by its contrast
/// (2026-12-07): η 1.539 ± 0.135 (the pixels' 1.655 ± 0.114), σa +12, +20, +13%, σs′ −9, −4,
/// −9%, every error within 0.71 of its std. With the surface's reflection in the model and the
/// exit's tilt the tally's law (2026-12-09): η 1.547 ± 0.106 (the joint fit's 1.405 ± 0.128,
/// the pixels' 1.617 ± 0.090), σa +13.5, +22.1, +14.3%, σs′ −7.2, −2.9, −7.3%, within 0.88.
/// With the medium's outlines on their own edge model (2026-12-07, latest; within 0.02 px of
/// the truth's on average): η 1.553 ± 0.095 (the joint fit's 1.405 ± 0.117, the pixels' 1.611 ±
/// 0.074), σa +13.4, +20.4, +14.0%, σs′ −5.3, −1.6, −5.5%, within 0.97: the joint fit's η, 0.2
/// low, pulled the medium's 0.06 below the pixels' own. The joint fit's residuals are 10.8
/// times the noise, so its model does not describe these photos, and its η is now left out
/// (docs/medium.md, "The joint fit's η left out where its model misses the photos"): η 1.611 ±
/// 0.078, σa +5.6, +10.6, +5.4%, σs′ +1.4, +6.1, +0.9%, within 0.65. Asserted: the joint fit's η
/// not combined and said so, η the pixels' own and within the issue's 0.03 of the truth, σa and
/// σs′ within 12%, each error within 1.5 of its stated std.
#[test]
fn the_joint_fits_eta_is_left_out_where_its_model_misses_the_photos() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/pbr-seeds/jade-6");
    let (_dir, t, f) = medium_solve(&src, &["--holdout", "15"]);
    let m = f.medium.as_ref().expect("fit.json's medium");
    let sources = m.eta_sources.as_ref().expect("η's sources");
    println!(
        "η {:.3} ± {:.3} (truth {}): the joint fit's {:.3} ± {:.3}, the pixels' {:.3} ± {:.3}",
        m.eta.value,
        m.eta.std,
        t.media[0].eta,
        sources.joint.value,
        sources.joint.std,
        sources.pixels.value,
        sources.pixels.std
    );
    assert_eq!(sources.joint_combined, Some(false));
    assert!(
        f.notes
            .iter()
            .any(|n| n.contains("left out, its model not describing the photos")),
        "{:?}",
        f.notes
    );
    assert!((m.eta.value - sources.pixels.value).abs() < 1e-9);
    assert!(
        (m.eta.value - t.media[0].eta).abs() < 0.03,
        "η {}",
        m.eta.value
    );
    let mut worst = (m.eta.value - t.media[0].eta).abs() / m.eta.std;
    for c in 0..3 {
        for (name, fitted, truth) in [
            ("σa", &m.sigma_a_per_mm, t.media[c].sigma_a),
            ("σs′", &m.sigma_s_reduced_per_mm, t.media[c].sigma_s_reduced),
        ] {
            let off = fitted.value[c] / truth - 1.0;
            println!("channel {c}: {name} {:+.1}%", 100.0 * off);
            assert!(off.abs() < 0.12, "{name} channel {c}: {off}");
            worst = worst.max((fitted.value[c] - truth).abs() / fitted.std[c]);
        }
    }
    println!("worst error {worst:.2} std");
    assert!(worst < 1.5, "{worst}");
    // Its stated errors are 21–23% of σa and σs′ (79–95% while the noise was measured short
    // and the misfit scaled the model's own): no note calls them poorly determined.
    assert_eq!(poorly_determined_is_said(&f), 0);
}

/// `workbench plot` of a medium fit draws the medium's own figures (its pixels and model
/// against θ, its residuals against θ) beside the CDRF's, each linked from index.html.
fn the_medium_fit_is_drawn(fit: &Path) {
    let out = fit.with_file_name("medium-plots");
    let (code, _, err) = common::wb(&[
        "--quiet",
        "plot",
        fit.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let index = std::fs::read_to_string(out.join("index.html")).unwrap();
    for (name, size) in [
        ("medium-radiance-theta", (1700, 1040)),
        ("medium-residual-theta", (1500, 820)),
    ] {
        let png = image::open(out.join(format!("{name}.png"))).unwrap();
        assert_eq!((png.width(), png.height()), size, "{name}");
        assert!(index.contains(&format!("src=\"{name}.png\"")), "{name}");
    }
    another_builds_medium_is_not_drawn(fit);
}

/// A fit.json whose medium was fitted with another model (its `model_reference` a millionth off
/// this build's, or absent as in files written before it) is not drawn: one line naming the
/// file, a non-zero exit, and no figures.
fn another_builds_medium_is_not_drawn(fit: &Path) {
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fit).unwrap()).unwrap();
    let reference = v["medium"]["model_reference"].as_array().unwrap().clone();
    assert_eq!(reference.len(), 24, "{reference:?}");
    for (name, edit, says) in [
        (
            "moved.fit.json",
            Some(1.0 + 1e-6),
            "another model than this build's",
        ),
        ("unrecorded.fit.json", None, "did not record its model"),
    ] {
        let mut w = v.clone();
        match edit {
            Some(f) => {
                w["medium"]["model_reference"][3] =
                    serde_json::json!(reference[3].as_f64().unwrap() * f)
            }
            None => {
                w["medium"]
                    .as_object_mut()
                    .unwrap()
                    .remove("model_reference");
            }
        }
        let path = fit.with_file_name(name);
        std::fs::write(&path, serde_json::to_string_pretty(&w).unwrap()).unwrap();
        let out = fit.with_file_name(format!("{name}-plots"));
        let (code, _, err) = common::wb(&[
            "plot",
            path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_ne!(code, 0, "{name}");
        let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
        assert_eq!(lines.len(), 1, "{err}");
        assert!(err.contains(name) && err.contains(says), "{err}");
        assert!(!out.exists(), "{name}: figures written");
    }
}

/// A jade-like render (`datasets/pbr-seeds/jade-3`: albedo 0.9, σt 2), all five radii fitted:
/// its errors must cover the truth. Until 2026-12-06 its residuals were 1.90 times the noise (a
/// noise the line σ² = a + b·L measured short) and the misfit note spoke. With the model's error scaled by the misfit the worst of σa and
/// σs′ was 2.11 of its stated std (2.61 with Snell's beams and the deepest shadow fitted;
/// unscaled 4.67); with the held light's error carried into them (2026-12-06), 1.40 (σs′_r,
/// 33% low, the light alone ± 23%); with the boundary's roughness measured (2026-12-06), 1.41
/// (σs′_r, 26% low; σa within 9.7%); with the joint η's error widened by its α's difference from
/// the medium's, 1.39; with the held light's and outlines' errors reaching η through the
/// pixels' η (2026-12-06), 1.23, and η 1.504 ± 0.090 is 1.28 of its std off (1.80 before: held,
/// η took none of their error). With the pixels' noise measured as a curve in the level
/// (`fit::noise`) that alone left σs′_r 27.5% low at 1.97 of its std, unsaid: the outlines, drawn
/// 0.22 px small, were the error. With them weighing the rim by its contrast as well
/// (2026-12-07; docs/medium.md, "The noise curve with the outlines weighted by their
/// contrast"): residuals 1.02 of the noise (the issue's goal is 1.5), σs′_r 15.6% low at 0.85
/// of its std, η 1.530 ± 0.084 at 1.07; with the surface's reflection in the model and the
/// exit's tilt the tally's law (2026-12-09): residuals 1.05, the worst error 1.03 of its std,
/// η 1.537 ± 0.069 at 1.21; with the medium's outlines on their own edge model (2026-12-07,
/// latest): residuals 1.12, the worst error 0.61 of its std, η 1.554 ± 0.068 at 0.96; with the
/// joint fit's η left out where its model misses the photos (the same day): residuals 1.11, the
/// worst error 0.41 of its std, η 1.589 ± 0.083 at 0.37. Asserted: the residuals within 1.5 of the noise and no
/// misfit said; σa, σs′ and η within 1.5 of their stated std, the coverage docs/uncertainty.md
/// asks of the medium's errors; detections.json holds the outlines drawn for the medium.
#[test]
fn a_jade_like_medium_meets_its_noise_and_its_errors_cover() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/pbr-seeds/jade-3");
    let (dir, t, f) = medium_solve(&src, &[]);
    let m = f.medium.as_ref().expect("fit.json's medium");
    assert!(m.residual_over_noise < 1.5, "{}", m.residual_over_noise);
    assert!(
        !f.notes.iter().any(|n| n.starts_with("medium: residuals")),
        "{:?}",
        f.notes
    );
    let det: workbench::formats::detections::Detections =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("detections.json")).unwrap())
            .unwrap();
    assert!(det.has_medium_outlines());
    let mut worst = 0.0f64;
    for c in 0..3 {
        for (fitted, truth) in [
            (&m.sigma_a_per_mm, t.media[c].sigma_a),
            (&m.sigma_s_reduced_per_mm, t.media[c].sigma_s_reduced),
        ] {
            let std = fitted.std[c];
            assert!(std.is_finite(), "a stated error");
            worst = worst.max((fitted.value[c] - truth).abs() / std);
        }
    }
    let eta_off = (m.eta.value - t.media[0].eta).abs() / m.eta.std;
    println!(
        "residuals {:.2}× the noise, worst error {worst:.2} std, η {:.3} ± {:.3} ({eta_off:.2} std)",
        m.residual_over_noise, m.eta.value, m.eta.std
    );
    assert!(worst < 1.5, "{worst}");
    assert!(eta_off < 1.5, "η {eta_off}");
    // Its stated errors are 15–22% of σa and σs′: no note calls them poorly determined.
    assert_eq!(poorly_determined_is_said(&f), 0);
    mitsuba_reads_and_renders_the_export(&dir.path().join("fit.json"), m);
}

/// The Mitsuba export loaded by Mitsuba 3's own parser and rendered by its stock volpath
/// (`datasets/mitsuba/render_export.py`): what Mitsuba read against fit.json's medium (σt =
/// σa + σs′ per mm, albedo σs′/σt, η, α, the radius) to its float precision, and its render of the
/// sphere as loaded against this project's path tracer's render of the fitted medium (the
/// same camera and sphere; its lamp of angular radius 0.15 rad against our directional light of
/// the same irradiance, as in `pbr::renders_what_mitsuba_stock_volpath_renders`). A jade-like
/// fit, σt above 1 /mm, which Mitsuba refused as a plain `rgb` before the export wrote it over
/// its `scale`. Measured (2026-12-05, 48×48 pixels; Mitsuba 2048 spp, ours 1024): the sums over
/// θ < 80° ours/Mitsuba 0.974–0.980 per channel, 0.973–1.004 over Mitsuba seeds 1–3, whose own
/// spread is ±3% (paths find the small lamp only by chance); per 20° band 0.93–1.05. Asserted:
/// the sums within 8%.
fn mitsuba_reads_and_renders_the_export(fit: &Path, m: &workbench::formats::fit::MediumJson) {
    use workbench::camera::sphere::Sphere;
    use workbench::camera::Camera;
    use workbench::synth::volpath::{self, Scene};
    let out = fit.with_file_name("export-mitsuba");
    let (code, err) = export(fit, "mitsuba", &out);
    assert_eq!(code, 0, "{err}");
    let Some((python, pythonpath)) = common::mitsuba() else {
        return;
    };
    let (a, s) = (m.sigma_a_per_mm.value, m.sigma_s_reduced_per_mm.value);
    let sigma_t: [f64; 3] = std::array::from_fn(|c| a[c] + s[c]);
    assert!(
        sigma_t.iter().any(|&t| t > 1.0),
        "{sigma_t:?}: the case Mitsuba refused"
    );
    let radius = m.radii_mm.iter().copied().fold(f64::NAN, f64::max);
    let (size, fx, distance) = (48u32, 168.0, 10.0 * radius);
    let image = out.join("mitsuba.f32");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/mitsuba/render_export.py");
    let o = std::process::Command::new(python)
        .arg(&script)
        .arg(out.join("mitsuba.xml"))
        .args(["--out", image.to_str().unwrap()])
        .args(["--size", &size.to_string(), "--fx", &fx.to_string()])
        .args(["--distance", &distance.to_string(), "--spp", "2048"])
        .env("PYTHONPATH", &pythonpath)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // What Mitsuba's parser read, against the fit (float32: 1e-6).
    let read: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let num = |v: &serde_json::Value| v.as_f64().unwrap();
    let near = |x: f64, y: f64| (x - y).abs() <= 1e-6 * y.abs();
    assert!(near(num(&read["radius_mm"]), radius), "{read}");
    assert!(near(num(&read["alpha"]), m.alpha.max(1e-4)), "{read}");
    assert!(near(num(&read["eta"]), m.eta.value), "{read}");
    for c in 0..3 {
        assert!(near(num(&read["sigma_t_per_mm"][c]), sigma_t[c]), "{read}");
        assert!(near(num(&read["albedo"][c]), s[c] / sigma_t[c]), "{read}");
    }
    // Its render against ours of the same sphere.
    let theirs: Vec<f64> = std::fs::read(&image)
        .unwrap()
        .chunks(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64)
        .collect();
    let c0 = 0.5 * (size as f64 - 1.0);
    let cam = Camera {
        fx,
        fy: fx,
        cx: c0,
        cy: c0,
        distortion: Default::default(),
        image_size: [size, size],
    };
    let scene = Scene {
        sphere: Sphere::new(Vector3::new(0.0, 0.0, distance), radius),
        light: Vector3::new(0.0, -0.8, -0.6),
        medium: volpath::Medium {
            sigma_t,
            albedo: std::array::from_fn(|c| s[c] / sigma_t[c]),
        },
        boundary: workbench::synth::dielectric::Boundary {
            eta: m.eta.value,
            alpha: m.alpha.max(1e-4),
        },
    };
    let ours = volpath::render(&cam, &scene, 1024, 5, 0).mean();
    let (o, t) = (
        |i: usize, c: usize| ours[i][c],
        |i: usize, c: usize| theirs[3 * i + c],
    );
    let l = scene.light.normalize();
    // θ below 80°: beyond it the lamp's disc lights what the directional light leaves dark.
    let b = crate::pbr::bands(&cam, &scene.sphere, &l, &[&o, &t], 20.0, 1.5, &|_| false);
    for (k, (sums, n)) in b.iter().enumerate().take(4) {
        let r: Vec<f64> = (0..3).map(|c| sums[0][c] / sums[1][c]).collect();
        println!(
            "Mitsuba export θ {}–{}° ({n} px): ours/Mitsuba {r:.4?}",
            20 * k,
            20 * k + 20
        );
    }
    for c in 0..3 {
        let (so, st) = b
            .iter()
            .take(4)
            .fold((0.0, 0.0), |s, x| (s.0 + x.0[0][c], s.1 + x.0[1][c]));
        println!(
            "Mitsuba export, channel {c}: θ < 80°, ours/Mitsuba {:.4}",
            so / st
        );
        assert!((so / st - 1.0).abs() < 0.08, "channel {c}: {}", so / st);
    }
}

/// `close-loop`: the fitted medium path-traced back into every sphere meets the photos as well
/// as the medium model the fit minimised does (the model is independent code: diffusion in the
/// sphere, not a random walk). Measured (2026-12-05, θ up to 105°) on soap (15 mm held out of
/// the fit) at 1024 spp, 600 pixels a sphere: path-traced 4.26 ± 0.16%, model 3.91%, so 1.09 of
/// it (per radius 0.87–1.19; with the deepest shadow too 1.03, at 2000 pixels without the
/// hold-out 1.04), the CDRF 5.60%; on 2026-12-08 (α measured, the noise a curve, the rough
/// level the tally's table) 3.68 ± 0.12% against the model's 3.76%, 0.98, the CDRF 5.49%; on
/// 2026-12-07, latest (the medium's outlines on their own edge model, so other pixels and
/// centres) 4.16 ± 0.13% against 3.81%, 1.09 (per radius 0.98–1.19), the CDRF 5.46%.
/// Asserted: 0.85–1.2 overall (the issue's goal is 1.5), so no note that the loop does not
/// close, and the CDRF worse than the path-traced medium; the rendered medium is σt = σa + σs′, albedo σs′/σt; the figure is
/// drawn.
fn the_loop_closes(fit: &Path, m: &workbench::formats::fit::MediumJson) {
    let (j, _) = close_loop(fit, &["--pixels", "600"]);
    let out = fit.with_file_name("loop");
    for c in 0..3 {
        let (a, s) = (m.sigma_a_per_mm.value[c], m.sigma_s_reduced_per_mm.value[c]);
        assert!((j.rendered.sigma_t_per_mm[c] - (a + s)).abs() < 1e-12 * (a + s));
        assert!((j.rendered.albedo[c] - s / (a + s)).abs() < 1e-12);
    }
    let o = &j.overall;
    println!(
        "close-loop: path-traced {:.4} ± {:.4}, model {:.4}, CDRF {:.4}, photo noise {:.4}",
        o.render_rel_rmse,
        o.render_rel_rmse_std,
        o.medium_rel_rmse,
        o.cdrf_rel_rmse,
        o.photo_noise_rel
    );
    for r in &j.radii {
        println!(
            "  r {} mm: path-traced/model {:.3}",
            r.radius_mm, r.comparison.render_over_medium
        );
    }
    assert!((0.85..1.2).contains(&o.render_over_medium), "{o:?}");
    assert!(j.notes.is_empty(), "{:?}", j.notes);
    assert!(o.cdrf_rel_rmse > o.render_rel_rmse, "{o:?}");
    assert_eq!(j.radii.len(), 5);
    // 3° bands up to 105°, each with at least 10 pixels: at 600 pixels a sphere the bands nearest
    // the light hold about that many and come and go with the sample (19–22 a radius, measured
    // 2026-12-07); the wave is drawn through the terminator, every band from 60° to 105°.
    for r in &j.radii {
        let held: Vec<i64> = r.bands.iter().map(|b| b.theta_deg.floor() as i64).collect();
        for centre in (61..105).step_by(3) {
            assert!(held.contains(&centre), "{} mm: {held:?}", r.radius_mm);
        }
    }
    let png = image::open(out.join("close-loop.png")).unwrap();
    assert_eq!((png.width(), png.height()), (1500, 60 + 340 * 3));
}

/// `export --to mitsuba,pbrt,blender,unreal` of a medium fit, each file read back by a parser
/// (Python's XML and Python parsers, pbrt's grammar, JSON) and its numbers against the medium's
/// (σt = σa + σs′, albedo σs′/σt, roughness √α, the mean free path per channel), to 1e-12.
fn exports_read_back(fit: &Path, m: &workbench::formats::fit::MediumJson) {
    let out = fit.with_file_name("export");
    let (code, err) = export(fit, "mitsuba,pbrt,blender,unreal", &out);
    assert_eq!(code, 0, "{err}");
    let (a, s) = (m.sigma_a_per_mm.value, m.sigma_s_reduced_per_mm.value);
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-12 * y.abs().max(1.0);
    // pbrt-v4 by its grammar: directives, quoted "type name" parameters, bracketed values.
    let pbrt = std::fs::read_to_string(out.join("pbrt.pbrt")).unwrap();
    let params = pbrt_parameters(&pbrt);
    let values = |name: &str| -> Vec<String> {
        params
            .iter()
            .filter(|(n, _)| n == name)
            .flat_map(|(_, v)| v.clone())
            .collect()
    };
    let numbers =
        |name: &str| -> Vec<f64> { values(name).iter().map(|v| v.parse().unwrap()).collect() };
    for c in 0..3 {
        assert!(close(numbers("rgb sigma_a")[c], a[c]));
        assert!(close(numbers("rgb sigma_s")[c], s[c]));
    }
    assert!(close(numbers("float eta")[0], m.eta.value));
    assert!(close(numbers("float roughness")[0], m.alpha));
    assert_eq!(values("bool remaproughness"), vec!["false"]);
    assert_eq!(
        values("string type"),
        vec!["\"homogeneous\"", "\"dielectric\""]
    );
    let Some(python) = common::system_tool("python3", "python3") else {
        return;
    };
    // Mitsuba's XML by Python's parser: the plugins and their parameters.
    let script = r#"
import sys, xml.etree.ElementTree as ET
root = ET.parse(sys.argv[1]).getroot()
assert root.tag == "scene" and root.get("version").startswith("3.")
b = root.find("bsdf[@type='roughdielectric']")
m = root.find("medium[@type='homogeneous']")
assert m.find("phase").get("type") == "isotropic"
shape = root.find("shape[@type='sphere']")
assert shape.find("ref[@name='interior']").get("id") == m.get("id")
assert shape.find("ref").get("id") == b.get("id")
v = lambda e, k: e.find("*[@name='%s']" % k).get("value")
print(v(b, "alpha"), v(b, "int_ior"), v(m, "scale"), v(m, "sigma_t"), v(m, "albedo"))
"#;
    let o = std::process::Command::new(python)
        .args(["-c", script, out.join("mitsuba.xml").to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let got: Vec<f64> = String::from_utf8_lossy(&o.stdout)
        .replace(',', " ")
        .split_whitespace()
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(close(got[0], m.alpha.max(1e-4)) && close(got[1], m.eta.value));
    // The extinction over its largest channel (Mitsuba refuses an `rgb` above 1), times `scale`.
    let scale = got[2];
    assert!((got[3..6].iter().copied().fold(0.0, f64::max) - 1.0).abs() < 1e-15);
    for c in 0..3 {
        assert!(close(scale * got[3 + c], a[c] + s[c]));
        assert!(close(got[6 + c], s[c] / (a[c] + s[c])));
    }
    // Blender's snippet by Python's parser: each input's default value.
    let script = r#"
import ast, sys
tree = ast.parse(open(sys.argv[1]).read())
for node in ast.walk(tree):
    if isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Attribute):
        t = node.targets[0]
        if t.attr == "default_value":
            name = t.value.slice.value
            v = ast.literal_eval(node.value)
            v = v if isinstance(v, tuple) else (v,)
            print(name.replace(" ", "_"), *v)
"#;
    let o = std::process::Command::new(python)
        .args(["-c", script, out.join("blender.py").to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    let input = |name: &str| -> Vec<f64> {
        let line = text
            .lines()
            .find(|l| l.starts_with(&format!("{name} ")))
            .unwrap_or_else(|| panic!("{name} in {text}"));
        line.split_whitespace()
            .skip(1)
            .map(|v| v.parse().unwrap())
            .collect()
    };
    let mfp = m.mean_free_path_mm.value;
    let (radius, colour) = (input("Subsurface_Radius"), input("Base_Color"));
    for (c, v) in mfp.iter().enumerate() {
        assert!(close(radius[c], *v));
        assert!(close(colour[c], m.diffuse_albedo.value[c]));
    }
    assert!(close(input("IOR")[0], m.eta.value));
    assert!((input("Roughness")[0].powi(2) - m.alpha).abs() < 1e-12);
    assert!(close(input("Subsurface_Scale")[0], 1e-3));
    // Unreal's values as JSON: the colour times the distance is the mean free path (cm).
    let u: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("unreal-subsurface-profile.json")).unwrap(),
    )
    .unwrap();
    let d = u["MeanFreePathDistance"].as_f64().unwrap();
    for c in 0..3 {
        assert!(close(
            u["MeanFreePathColor"][c].as_f64().unwrap() * d * 10.0,
            mfp[c]
        ));
    }
    let f0 = ((m.eta.value - 1.0) / (m.eta.value + 1.0)).powi(2);
    assert!(close(u["Specular"].as_f64().unwrap() * 0.08, f0));
}

/// `workbench export <fit> --to <to> --out <out>`: its exit code and standard error.
fn export(fit: &Path, to: &str, out: &Path) -> (i32, String) {
    let (code, _, err) = common::wb(&[
        "--quiet",
        "export",
        fit.to_str().unwrap(),
        "--to",
        to,
        "--out",
        out.to_str().unwrap(),
    ]);
    (code, err)
}

/// pbrt-v4 scene text by its grammar: `#` comments, directives (capitalised words), quoted
/// strings, and parameters as a quoted "type name" followed by one value or a bracketed list;
/// each "type name" with its values (strings keep their quotes). A list's length must fit its
/// type (rgb 3, float/bool/string 1 here).
fn pbrt_parameters(text: &str) -> Vec<(String, Vec<String>)> {
    let mut tokens: Vec<String> = vec![];
    for line in text.lines() {
        let line = line.split('#').next().unwrap();
        let mut chars = line.chars().peekable();
        while let Some(&c) = chars.peek() {
            if c.is_whitespace() {
                chars.next();
            } else if c == '"' {
                chars.next();
                let mut s = String::from("\"");
                for c in chars.by_ref() {
                    s.push(c);
                    if c == '"' {
                        break;
                    }
                }
                assert!(
                    s.len() >= 2 && s.ends_with('"'),
                    "unterminated string in {line}"
                );
                tokens.push(s);
            } else if c == '[' || c == ']' {
                tokens.push(c.to_string());
                chars.next();
            } else {
                let mut s = String::new();
                while let Some(&c) = chars.peek() {
                    if c.is_whitespace() || c == '[' || c == ']' || c == '"' {
                        break;
                    }
                    s.push(c);
                    chars.next();
                }
                tokens.push(s);
            }
        }
    }
    let directives = [
        "MakeNamedMedium",
        "MakeNamedMaterial",
        "AttributeBegin",
        "AttributeEnd",
        "MediumInterface",
        "NamedMaterial",
        "Shape",
    ];
    let mut params = vec![];
    let mut i = 0;
    while i < tokens.len() {
        let t = &tokens[i];
        let unquoted = t.trim_matches('"');
        let words: Vec<&str> = unquoted.split_whitespace().collect();
        if directives.contains(&t.as_str()) {
            i += 1;
            continue;
        }
        assert!(t.starts_with('"'), "not pbrt: {t}");
        if words.len() == 2 {
            // A parameter: its values follow, bracketed or one.
            let mut values = vec![];
            i += 1;
            if tokens[i] == "[" {
                i += 1;
                while tokens[i] != "]" {
                    values.push(tokens[i].clone());
                    i += 1;
                }
            } else {
                values.push(tokens[i].clone());
            }
            let expected = if words[0] == "rgb" { 3 } else { 1 };
            assert_eq!(values.len(), expected, "{unquoted}: {values:?}");
            params.push((unquoted.to_string(), values));
        }
        i += 1;
    }
    params
}

/// `export` of a fit without a medium: one line naming the file and what to run, nothing
/// written.
#[test]
fn export_needs_a_medium() {
    let (dir, session) = common::solved_row(&[]);
    let fit = session.join("fit.json");
    let out = dir.path().join("export");
    // One line naming fit.json and `--model medium`, nothing written.
    let refused = |code: i32, err: &str| {
        assert_ne!(code, 0);
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(
            err.contains("--model medium") && err.contains("fit.json"),
            "{err}"
        );
        assert!(!out.exists());
    };
    let (code, err) = export(&fit, "mitsuba", &out);
    refused(code, &err);
    // close-loop needs one too.
    let (code, _, err) = common::wb(&[
        "--quiet",
        "close-loop",
        fit.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    refused(code, &err);
}

/// The medium needs the joint fit's light and η: with the paper's method it is refused in one
/// line, before anything is written.
#[test]
fn the_medium_is_refused_with_the_papers_method() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/pbr-soap");
    let dir = common::session_copy(&src);
    let d = dir.path().to_str().unwrap();
    let (code, _, err) = common::wb(&[
        "--quiet", "solve", d, "--model", "medium", "--method", "paper",
    ]);
    assert_ne!(code, 0);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("--method joint"), "{err}");
    assert!(!dir.path().join("fit.json").exists());
}

/// The rough boundary's level and the exit law's tilt, run by hand (about 3 min): the photon
/// tally with the renders' GGX boundary against the model entering through it, over 324 spheres
/// (σt′R at `model::rough_level::SIGMA_T_RADII`: radius and σt 15 mm and 0.5, 25 and 1, 35 and
/// 3 /mm; η 1.3, 1.45, 1.6; α 0.05, 0.1, 0.15, 0.25; albedo 0.6–0.995), a million photons each.
/// - the level: the tally over the model without its loss, θ 0–60°, printed as the table
///   `model::rough_level::TABLE` holds, with the largest difference from the committed one;
/// - the tilt: per sphere the slope K of the tally's law over T(μ)/(π c), θ 0–80°, μ 0.2–1
///   (r = A (1 + K (μ̄ − μ)), weighted by μ), then K = s (k₀ + k₁ s + k₂ (η − 1.45) +
///   k₃ (α − 0.1)) by least squares, against the committed law's
///   (`model::exit_tilt::COEFFICIENTS`) and the constant 0.11 the model held until 2026-12-09;
///   the committed law's mean departure per sphere size, and the law with a fifth term
///   s k₄ ln(σt′R/25).
///
/// Measured (2026-12-08): the level from 0.777 to 1.013 over the nodes, the committed table
/// the same to 5e-5 (its four decimals); the tilt k = [0.539, −0.312, −0.606, 0.774], rms 0.0125
/// about slopes of 0.01–0.34, where the constant 0.11 leaves 0.083 (at 400 000 photons a
/// sphere, 2026-12-07: [0.593, −0.405, −0.663, 0.707], rms 0.018 and 0.085). Again on
/// 2026-12-09: the committed law's rms 0.0125, its mean departure −0.0030, −0.0005 and +0.0001
/// at σt′R 7.5, 25 and 105; with the size term k₄ = −0.0004 and the rms the same: the tilt does
/// not follow the sphere's size.
#[test]
#[ignore = "by hand: cargo test --release --test it -- --ignored medium::rough_level_and_exit_tilt_against_the_photon_tally --nocapture"]
fn rough_level_and_exit_tilt_against_the_photon_tally() {
    use nalgebra::{DMatrix, DVector};
    use workbench::model::exit_tilt::tilt;
    use workbench::model::rough_level::{ALBEDOS, ALPHAS, ETAS, SIGMA_T_RADII, TABLE};
    let mut rows = vec![];
    let mut table = String::new();
    let mut differs = 0.0f64;
    for (k, radius, sigma_t) in [(0, 15.0, 0.5), (1, 25.0, 1.0), (2, 35.0, 3.0)] {
        assert_eq!(radius * sigma_t, SIGMA_T_RADII[k]);
        table += "    [\n";
        for (e, eta) in ETAS.into_iter().enumerate() {
            table += "        [\n";
            for (a, alpha) in ALPHAS.into_iter().enumerate() {
                let mut line = vec![];
                for (b, albedo) in ALBEDOS.into_iter().enumerate() {
                    let t = tally((radius, sigma_t, albedo, eta, alpha), 1_000_000, 31);
                    let m = Medium::isotropic(sigma_t, albedo, eta);
                    let bd = Boundary::rough(eta, alpha);
                    let model = SphereDiffusion::through(&m, radius, &bd);
                    // The model without its loss of level.
                    let level = t.exitance(0, 60).value / band_mean(&model, 0, 60)
                        * bd.level(m.reduced_albedo(), radius * sigma_t);
                    differs = differs.max((level - TABLE[k][e][a][b]).abs());
                    line.push(format!("{level:.4}"));
                    let s = (1.0 - m.reduced_albedo()).sqrt();
                    let committed = tilt(m.reduced_albedo(), eta, alpha).k;
                    rows.push((
                        s,
                        eta,
                        alpha,
                        law_slope(&t.angular(0, 80), &bd),
                        committed,
                        k,
                    ));
                }
                table += &format!("            [{}],\n", line.join(", "));
            }
            table += "        ],\n";
        }
        table += "    ],\n";
    }
    println!("TABLE =\n{table}the committed table differs by at most {differs:.5}");
    let least_squares =
        |x: DMatrix<f64>, y: DVector<f64>| x.clone().svd(true, true).solve(&y, 1e-12).unwrap();
    let n = rows.len();
    let x = DMatrix::from_fn(n, 4, |i, j| {
        let (s, eta, alpha, ..) = rows[i];
        s * [1.0, s, eta - 1.45, alpha - 0.1][j]
    });
    let k = least_squares(x.clone(), DVector::from_fn(n, |i, _| rows[i].3));
    let rms = |fit: &dyn Fn(usize) -> f64| {
        ((0..n).map(|i| (rows[i].3 - fit(i)).powi(2)).sum::<f64>() / n as f64).sqrt()
    };
    let fitted = &x * &k;
    println!(
        "tilt K = s (k₀ + k₁ s + k₂ (η − 1.45) + k₃ (α − 0.1)), k = {:?}: rms {:.4} about the slopes; the committed law's {:.4}; a constant 0.11 {:.4}",
        k.iter().map(|v| (v * 1e4).round() / 1e4).collect::<Vec<_>>(),
        rms(&|i| fitted[i]),
        rms(&|i| rows[i].4),
        rms(&|_| 0.11)
    );
    // The committed law's bias per sphere size, and the law with a term in ln(σt′R/25).
    for (k, st_r) in SIGMA_T_RADII.iter().enumerate() {
        let own: Vec<f64> = (0..n)
            .filter(|&i| rows[i].5 == k)
            .map(|i| rows[i].3 - rows[i].4)
            .collect();
        let mean = own.iter().sum::<f64>() / own.len() as f64;
        println!("σt′R {st_r}: the tally's slope less the committed law's, mean {mean:+.4}");
    }
    let x5 = DMatrix::from_fn(n, 5, |i, j| {
        let (s, eta, alpha, .., k) = rows[i];
        s * [
            1.0,
            s,
            eta - 1.45,
            alpha - 0.1,
            (SIGMA_T_RADII[k] / 25.0).ln(),
        ][j]
    });
    let k5 = least_squares(x5.clone(), DVector::from_fn(n, |i, _| rows[i].3));
    let fitted5 = &x5 * &k5;
    println!(
        "with s k₄ ln(σt′R/25): k = {:?}, rms {:.4}",
        k5.iter()
            .map(|v| (v * 1e4).round() / 1e4)
            .collect::<Vec<_>>(),
        rms(&|i| fitted5[i])
    );
}

/// The exit law's tilt without the light that scattered once, in the photon tally (by hand,
/// about 30 s): over radius and σt 15 mm and 0.5, 25 and 1, 35 and 3 /mm, η 1.3, 1.45 and 1.6,
/// a smooth boundary and GGX α 0.05, 0.1 and 0.25, albedo 0.6–0.995, the slope K of the whole
/// law and of the multiply scattered light's (θ 0–80°), the once-scattered share of the
/// exitance, and on the smooth spheres that share at θ 0–20° against the flat medium's single
/// scattering, E α μ₀ T(μ₀) T(μ) / (4π η² (μ₀′ + μ′)) (μ′ the refracted cosines), integrated
/// over the exits. The table of docs/medium.md, "Single scattering and the exit's tilt".
#[test]
#[ignore = "by hand: cargo test --release --test it -- --ignored medium::exit_tilt_without_single_scattering --nocapture"]
fn exit_tilt_without_single_scattering() {
    use workbench::model::fresnel::transmission;
    let mut rows = vec![];
    for (radius, sigma_t) in [(15.0, 0.5), (25.0, 1.0), (35.0, 3.0)] {
        for eta in [1.3, 1.45, 1.6] {
            for alpha in [0.0, 0.05, 0.1, 0.25] {
                for albedo in [0.6, 0.7, 0.8, 0.9, 0.97, 0.995] {
                    let t = tally((radius, sigma_t, albedo, eta, alpha), 400_000, 37);
                    let b = Boundary::rough(eta, alpha);
                    let (whole, multiple) = (
                        law_slope(&t.angular(0, 80), &b),
                        law_slope(&t.multiple_angular(0, 80), &b),
                    );
                    let share = t.single_exitance(0, 80) / t.exitance(0, 80).value;
                    let (measured, flat) = if alpha == 0.0 {
                        let inside = |mu: f64| (1.0 - (1.0 - mu * mu) / (eta * eta)).sqrt();
                        let once = |mu0: f64| {
                            (0..64)
                                .map(|k| {
                                    let mu = (k as f64 + 0.5) / 64.0;
                                    albedo * mu0 * transmission(mu0, eta) * transmission(mu, eta)
                                        / (4.0 * std::f64::consts::PI * eta * eta)
                                        / (inside(mu0) + inside(mu))
                                        * 2.0
                                        * std::f64::consts::PI
                                        * mu
                                        / 64.0
                                })
                                .sum::<f64>()
                        };
                        (t.single_exitance(0, 20), band_mean_of(once, 0, 20))
                    } else {
                        (f64::NAN, f64::NAN)
                    };
                    println!(
                        "R {radius:4} σt {sigma_t:3} η {eta:4} α {alpha:4} albedo {albedo:5}: K {whole:6.3}, multiple {multiple:6.3}; once-scattered share {share:.3}; θ 0–20° once {measured:.4} flat {flat:.4}"
                    );
                    rows.push(TiltRow {
                        albedo,
                        whole,
                        multiple,
                        share,
                        once_over_flat: measured / flat,
                    });
                }
            }
        }
    }
    for albedo in [0.6, 0.7, 0.8, 0.9, 0.97, 0.995] {
        let of = |pick: &dyn Fn(&TiltRow) -> f64| {
            let v: Vec<f64> = rows
                .iter()
                .filter(|r| r.albedo == albedo)
                .map(pick)
                .filter(|v| v.is_finite())
                .collect();
            let lo = v.iter().copied().fold(f64::MAX, f64::min);
            let hi = v.iter().copied().fold(f64::MIN, f64::max);
            format!("{lo:.3}–{hi:.3}")
        };
        println!(
            "albedo {albedo}: K {}, multiple {}; once-scattered share {}; once over the flat medium's (smooth, θ 0–20°) {}",
            of(&|r| r.whole),
            of(&|r| r.multiple),
            of(&|r| r.share),
            of(&|r| r.once_over_flat)
        );
    }
    let rms = |pick: &dyn Fn(&TiltRow) -> f64| {
        let k: Vec<f64> = rows.iter().map(pick).collect();
        let mean = k.iter().sum::<f64>() / k.len() as f64;
        let sd = (k.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / k.len() as f64).sqrt();
        format!("mean {mean:.3}, rms about it {sd:.3}")
    };
    println!(
        "K: whole {}; multiple {}",
        rms(&|r| r.whole),
        rms(&|r| r.multiple)
    );
}

/// One sphere of [`exit_tilt_without_single_scattering`]: the whole law's slope, the multiply
/// scattered light's, the once-scattered share of the exitance, and (smooth spheres; NaN else)
/// the once-scattered exitance at θ 0–20° over the flat medium's formula.
struct TiltRow {
    albedo: f64,
    whole: f64,
    multiple: f64,
    share: f64,
    once_over_flat: f64,
}

/// The slope K of a tally's angular law (per μ bin, [`workbench::synth::photon_tally::Tally::angular`])
/// over the untilted T(μ)/(π c): r = A (1 + K (μ̄ − μ)) by weighted least squares over μ 0.2–1
/// (weights μ), μ̄ the boundary's exit-weighted mean cosine.
fn law_slope(law: &[f64], b: &Boundary) -> f64 {
    let bins = law.len();
    let mean = b.mean_cosine();
    let (mut s00, mut s01, mut s11, mut y0, mut y1) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (k, l) in law.iter().enumerate().skip(bins / 5) {
        let mu = (k as f64 + 0.5) / bins as f64;
        let r = l / (b.transmission(mu) / (std::f64::consts::PI * b.hemispherical()));
        let x = mean - mu;
        s00 += mu;
        s01 += mu * x;
        s11 += mu * x * x;
        y0 += mu * r;
        y1 += mu * r * x;
    }
    let det = s00 * s11 - s01 * s01;
    let (a, slope) = ((y0 * s11 - y1 * s01) / det, (s00 * y1 - s01 * y0) / det);
    slope / a
}

/// The tally's first azimuthal harmonic b (L ∝ 1 + b cos ψ, ψ from the direction away from the
/// light) in a band of θ and a bin of μ, and P1's, a(θ) sin θᵢ with a = −(1/σt′R) d ln M/dθ
/// from the model's M, averaged over the band by exitance (as the tally's ratio of sums is).
fn flux_harmonics(
    t: &workbench::synth::photon_tally::Tally,
    model: &SphereDiffusion,
    sigma_t_radius: f64,
    eta: f64,
    (lo, hi): (usize, usize),
) -> Vec<(f64, f64, f64)> {
    let table = model.tabulate();
    let (mut sum_m, mut sum_ma) = (0.0, 0.0);
    for k in 0..4 * (hi - lo) {
        let th = (lo as f64 + (k as f64 + 0.5) / 4.0).to_radians();
        let m = table.at(th.cos()) * th.sin();
        sum_m += m;
        sum_ma += m * -table.log_slope(th.cos()) / sigma_t_radius;
    }
    let a = sum_ma / sum_m;
    let counts = t.angular(lo, hi);
    t.azimuthal(lo, hi)
        .iter()
        .enumerate()
        .skip(3)
        .map(|(k, b)| {
            let mu = (k as f64 + 0.5) / 10.0;
            (*b, a * (1.0 - mu * mu).sqrt() / eta, counts[k])
        })
        .collect()
}

/// The bands of θ the flux along the surface is compared in (degrees).
const FLUX_BANDS: [(usize, usize); 5] = [(20, 40), (40, 60), (60, 75), (75, 85), (85, 95)];

/// The flux along the surface, run by hand (about 2 min): the photon tally's first azimuthal
/// harmonic against P1's over 58 spheres (radius 15 and 35 mm, σt 0.5–2, albedo 0.9–0.995,
/// η 1.4 and 1.6, GGX α 0.05 and 0.15), θ 20–95°, μ 0.3–1 (what a camera within φ 75° sees);
/// the least-squares factor over P1, c₀ + c₁ s with s = √(1 − α′), which
/// `model::tangential_flux::TANGENTIAL_FLUX` holds.
#[test]
#[ignore = "by hand: cargo test --release --test it -- --ignored medium::tangential_flux_against_the_photon_tally --nocapture"]
fn tangential_flux_against_the_photon_tally() {
    use nalgebra::{Matrix2, Vector2};
    use workbench::model::tangential_flux::{coefficient, TANGENTIAL_FLUX};
    // Per bin: the tally's harmonic, P1's, √(1 − α′), the bin's weight.
    let mut rows = vec![];
    for radius in [15.0, 35.0] {
        for sigma_t in [0.5, 1.0, 2.0] {
            for albedo in [0.9, 0.97, 0.995] {
                for (eta, alpha) in [(1.4, 0.05), (1.4, 0.15), (1.6, 0.05), (1.6, 0.15)] {
                    if albedo == 0.995 && sigma_t == 0.5 && alpha == 0.05 {
                        continue;
                    }
                    let t = tally((radius, sigma_t, albedo, eta, alpha), 1_000_000, 23);
                    let m = Medium::isotropic(sigma_t, albedo, eta);
                    let model = SphereDiffusion::through(&m, radius, &Boundary::rough(eta, alpha));
                    let s = (1.0 - m.reduced_albedo()).sqrt();
                    for band in FLUX_BANDS {
                        for (b, p, w) in flux_harmonics(&t, &model, sigma_t * radius, eta, band) {
                            rows.push((b, p, s, w));
                        }
                    }
                }
            }
        }
    }
    let (mut a, mut y) = (Matrix2::zeros(), Vector2::zeros());
    for &(b, p, s, w) in &rows {
        let x = Vector2::new(p, p * s);
        a += w * x * x.transpose();
        y += w * b * x;
    }
    let c = a.lu().solve(&y).unwrap();
    let unexplained = |k: &dyn Fn(f64) -> f64| {
        let (res, tot) = rows.iter().fold((0.0, 0.0), |(r, t), &(b, p, s, w)| {
            (r + w * (b - k(s) * p).powi(2), t + w * b * b)
        });
        res / tot
    };
    println!(
        "TANGENTIAL_FLUX = [{:.3}, {:.3}] (committed {TANGENTIAL_FLUX:?}); the harmonic's share unexplained: P1 {:.3}, fitted {:.3}, committed {:.3}",
        c[0],
        c[1],
        unexplained(&|_| 1.0),
        unexplained(&|s| c[0] + c[1] * s),
        unexplained(&|s| coefficient(1.0 - s * s)),
    );
}

/// The flux along the surface against the photon tally, on a wax-like 15 mm sphere (σt 1,
/// albedo 0.92, η 1.44, GGX α 0.15, 2 million photons): the tally's first azimuthal harmonic
/// over the model's, k(α′) · P1 (`model::tangential_flux`), weighted over μ 0.3–1 per band of θ.
/// Measured (2026-12-05): 1.01 at 40–60°, 0.94 at 60–75°, 0.93 at 75–85°, 1.03 at 85–95°, with
/// the harmonic itself 0.03, 0.06, 0.12 and 0.24 (at 85–95° the exit toward the dark side is
/// 1.6 times that toward the lit one); again on 2026-12-09, 1.022, 0.962, 0.972 and 1.073, the
/// harmonic 0.030, 0.062, 0.121 and 0.238. Asserted: 0.8–1.2 in every band, and the harmonic at
/// 75–85° above 0.08 (the separable law's 0 is refuted: its sampling error is about 0.005).
#[test]
fn the_exit_follows_the_flux_along_the_surface() {
    let (radius, sigma_t, albedo, eta, alpha) = (15.0, 1.0, 0.92, 1.44, 0.15);
    let t = tally((radius, sigma_t, albedo, eta, alpha), 2_000_000, 31);
    let m = Medium::isotropic(sigma_t, albedo, eta);
    let model = SphereDiffusion::through(&m, radius, &Boundary::rough(eta, alpha));
    let k = workbench::model::tangential_flux::coefficient(m.reduced_albedo());
    for band in FLUX_BANDS.iter().skip(1) {
        let rows = flux_harmonics(&t, &model, sigma_t * radius, eta, *band);
        let (bp, pp, w) = rows.iter().fold((0.0, 0.0, 0.0), |(a, b, c), &(bt, p, w)| {
            (a + w * bt * k * p, b + w * (k * p).powi(2), c + w)
        });
        let mean_b = rows.iter().map(|&(b, _, w)| w * b).sum::<f64>() / w;
        let ratio = bp / pp;
        println!(
            "θ {:?}: tally over model {ratio:.3}, harmonic {mean_b:.3}",
            band
        );
        assert!((0.8..1.2).contains(&ratio), "θ {band:?}: {ratio}");
        if band.0 == 75 {
            assert!(mean_b > 0.08, "{mean_b}");
        }
    }
}

/// Rewrite `dir`'s detections.json with each photo's sphere where truth.json puts it: the
/// outline's cone axis toward the centre, its half angle asin(R/|c|).
fn truth_outlines(dir: &Path) {
    let read = |f: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join(f)).unwrap()).unwrap()
    };
    let (mut det, t) = (read("detections.json"), read("truth.json"));
    for im in det["images"].as_array_mut().unwrap() {
        let file = im["file"].as_str().unwrap().to_string();
        let truth = t["images"]
            .as_array()
            .unwrap()
            .iter()
            .find(|i| i["file"] == file.as_str())
            .expect("the photo in truth.json");
        for s in im["spheres"].as_array_mut().unwrap() {
            let r = s["radius_mm"].as_f64().unwrap();
            // `synth pbr`'s truth.json gives one centre a photo; pbr-jade's a list of spheres.
            let centre = match truth["spheres"].as_array() {
                Some(list) => {
                    let same = |t: &&serde_json::Value| t["radius_mm"].as_f64() == Some(r);
                    &list.iter().find(same).expect("the sphere in truth.json")["centre_mm"]
                }
                None => &truth["centre_mm"],
            };
            let c = Vector3::from_fn(|i, _| centre[i].as_f64().unwrap());
            let axis = c.normalize();
            s["outline"]["axis"] = serde_json::json!([axis.x, axis.y, axis.z]);
            s["outline"]["half_angle_deg"] = serde_json::json!((r / c.norm()).asin().to_degrees());
            s["center_mm"] = serde_json::json!([c.x, c.y, c.z]);
        }
    }
    std::fs::write(
        dir.join("detections.json"),
        serde_json::to_string_pretty(&det).unwrap(),
    )
    .unwrap();
}

/// A physically based session with truth.json by name: in `datasets/`, `datasets/pbr-seeds/`,
/// `datasets/pbr-range/` or ../shared/data/ (`pbr-jade`).
fn physically_based_session(name: &str) -> std::path::PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets");
    [
        root.join(name),
        root.join("pbr-seeds").join(name),
        root.join("pbr-range").join(name),
    ]
    .into_iter()
    .chain(common::shared_data().map(|s| s.join(name)))
    .find(|p| p.join("truth.json").exists())
    .unwrap_or_else(|| panic!("no physically based session {name} with truth.json"))
}

/// The photos over the medium fit's model at the truth (its medium, η, roughness, light and
/// irradiance), per band of θ past the lit side, every sphere and channel of a physically based
/// session (`SESSION`, default `pbr-wax`; `datasets/`, `datasets/pbr-seeds/`, `datasets/pbr-range/`
/// or ../shared/data/, e.g. `pbr-jade`), every pixel off
/// the highlight and the rim, so past the fit's θ limit too. The table of docs/medium.md, "The
/// deepest shadow fitted"; by hand (about 10 s):
/// `cargo test --release --test it -- --ignored medium::the_renders_over_the_model_at_the_truth --nocapture`.
#[test]
#[ignore]
fn the_renders_over_the_model_at_the_truth() {
    let name = std::env::var("SESSION").unwrap_or_else(|_| "pbr-wax".into());
    // `TRUTH_OUTLINES=1`: every sphere's outline replaced by the truth's (its centre from
    // truth.json), so the geometry is not the detector's.
    let truth_outlines = std::env::var("TRUTH_OUTLINES").is_ok_and(|v| v == "1");
    // `BANDS=0,20,40` for other edges of θ (degrees); `BY=phi` bands the view angle φ instead.
    let edges: Vec<f64> = std::env::var("BANDS").map_or_else(
        |_| {
            vec![
                60.0, 70.0, 80.0, 85.0, 90.0, 95.0, 100.0, 105.0, 110.0, 120.0,
            ]
        },
        |b| b.split(',').map(|v| v.trim().parse().unwrap()).collect(),
    );
    let by_phi = std::env::var("BY").is_ok_and(|b| b == "phi");
    let (what, bands) = (if by_phi { "φ" } else { "θ" }, edges.as_slice());
    println!("{name}: photos / model at the truth, {what} bands {bands:?}");
    for (radius_mm, c, ratios) in ratios_at_the_truth(&name, truth_outlines, bands, by_phi) {
        let cells: Vec<String> = ratios
            .iter()
            .map(|r| r.map_or_else(|| "—".into(), |r| format!("{r:.3}")))
            .collect();
        println!("  {radius_mm} mm, channel {c}: {}", cells.join(" "));
        assert!(ratios.iter().any(Option::is_some), "pixels in some band");
    }
}

/// The photos over the medium model at the truth of session `name` (its medium, η, roughness,
/// light and irradiance), summed
/// per band of θ (or of the view angle φ, `by_phi`) between the `bands`' edges in degrees: per
/// sphere and channel, (radius, channel, each band's ratio, `None` where it has no pixel). With
/// `outlines_at_truth` every outline is where truth.json puts it.
fn ratios_at_the_truth(
    name: &str,
    outlines_at_truth: bool,
    bands: &[f64],
    by_phi: bool,
) -> Vec<(f64, usize, Vec<Option<f64>>)> {
    use workbench::fit::medium::{predict_with, Px, Radius};
    let dir = common::session_copy(&physically_based_session(name));
    if outlines_at_truth {
        load_quiet(dir.path());
        truth_outlines(dir.path());
    }
    let t = truth(dir.path());
    let loaded = load_quiet(dir.path());
    let mut rows = vec![];
    for s in &loaded.spheres {
        let radius = Radius {
            radius_mm: s.radius_mm,
            pixels: std::array::from_fn(|c| {
                s.obs
                    .iter()
                    .filter(|o| {
                        described(&o.geometry.normal, &o.geometry.view, &t.light)
                            && o.weight[c] > 0.0
                    })
                    .map(|o| {
                        let (n, v) = (o.geometry.normal, o.geometry.view);
                        Px::at(&n, &v, &t.light, o.radiance[c], o.weight[c])
                    })
                    .collect()
            }),
        };
        let predicted = predict_with(t.media, [t.irradiance; 3], t.alpha, &radius);
        for (c, (pixels, predicted)) in radius.pixels.iter().zip(&predicted).enumerate() {
            let mut sums = vec![(0.0, 0.0); bands.len() - 1];
            for (px, p) in pixels.iter().zip(predicted) {
                let cos = if by_phi { px.cos_phi } else { px.cos_theta };
                let theta = cos.clamp(-1.0, 1.0).acos().to_degrees();
                if let Some(b) = bands.windows(2).position(|w| (w[0]..w[1]).contains(&theta)) {
                    sums[b].0 += px.radiance;
                    sums[b].1 += p;
                }
            }
            let ratios = sums
                .iter()
                .map(|&(l, p)| (p > 0.0).then(|| l / p))
                .collect();
            rows.push((s.radius_mm, c, ratios));
        }
    }
    rows
}

/// The exit's tilt as the photon tally's law (`model::exit_tilt`) holds how the renders fall
/// with the view angle where a constant tilt does not: on the dense corners of the issue's range
/// (`datasets/pbr-range/dense-dark`, albedo 0.7–0.8, η 1.3; `dense-white`, albedo 0.985–0.995,
/// η 1.6; σt 3 /mm), the photos over the model at the truth, every outline where truth.json puts
/// it, in bands of φ 0–20, 20–35, 35–50, 50–62 and 62–75°, mean over spheres and channels, last
/// band less the first. Measured +0.002 and −0.000 (2026-12-09; with the constant 0.11 the
/// model held before, +0.075 and −0.040: docs/medium.md, "The exit's tilt with the surface's
/// reflection in the model"), asserted within 0.01.
#[test]
fn the_exit_tilt_holds_the_dense_corners_fall_with_the_view_angle() {
    let bands = [0.0, 20.0, 35.0, 50.0, 62.0, 75.0];
    for name in ["dense-dark", "dense-white"] {
        let rows = ratios_at_the_truth(name, true, &bands, true);
        let slopes: Vec<f64> = rows
            .iter()
            .map(|(.., r)| r[r.len() - 1].expect("pixels at φ 62–75°") - r[0].expect("at 0–20°"))
            .collect();
        let mean = slopes.iter().sum::<f64>() / slopes.len() as f64;
        println!(
            "{name}: φ slope {mean:+.4} over {} spheres and channels",
            slopes.len()
        );
        assert!(mean.abs() < 0.01, "{name}: {mean}");
    }
}

/// The medium's first-order sensitivity to the held light (what carries the light's stated
/// error into σa and σs′: `fit::medium::LightError`) against the fit itself rerun with the
/// light moved: on the soap renders, with the truth's light, η, roughness and irradiance, the
/// light moved by 0.3° in azimuth and then in elevation, every σa, σs′ and η moves as the
/// sensitivities to the light say (η's through the pixels' η and its share of the combination,
/// the others' with it).
/// Also: the light's std is in the stated covariance.
#[test]
fn the_light_sensitivity_follows_refits() {
    use workbench::fit::medium::{fit, pixels, pixels_seen, start, Held, LightError};
    use workbench::model::LightAngles;
    let (_dir, t, loaded, setup, sigma0) = soap_from_its_truth();
    let spheres: Vec<_> = loaded.spheres.iter().collect();
    let angles = LightAngles::from_direction(&t.light);
    let l = angles.direction();
    let moved = |da: f64, de: f64| {
        let mut m = angles;
        m.azimuth += da;
        m.elevation += de;
        pixels_seen(&spheres, &l, &m.direction())
    };
    let std = 0.3f64.to_radians();
    let light = LightError::around(
        &spheres,
        angles,
        1e-3,
        nalgebra::Matrix2::identity() * std * std,
    );
    let radii = pixels(&spheres, &l);
    let f0 = fit(
        &radii,
        &setup,
        &start(&radii, &setup, sigma0),
        &Held {
            light: Some(&light),
            ..Held::default()
        },
    );
    let without = fit(&radii, &setup, f0.u.as_slice(), &Held::default());
    let s = f0
        .light_sensitivity
        .clone()
        .expect("the light's sensitivity");
    let std_light = f0.std_light.clone().expect("the light's std");
    let (mut worst, mut worst_eta): (f64, f64) = (0.0, 0.0);
    for (k, (da, de)) in [(std, 0.0), (0.0, std)].into_iter().enumerate() {
        let f1 = fit(&moved(da, de), &setup, f0.u.as_slice(), &Held::default());
        println!(
            "angle {k}: η {:.5} → {:.5}",
            f0.media[0].eta, f1.media[0].eta
        );
        let (w, we) = against_refit(&format!("angle {k}"), &s[k], std, &f0, &f1, 1e-3);
        (worst, worst_eta) = (worst.max(w), worst_eta.max(we));
    }
    println!(
        "worst |refit − first order| over max(|first order|, 1e-3): σa, σs′ {worst:.3}, η {worst_eta:.3}"
    );
    // Measured 0.039 and 0.154 (2026-12-09, the exit's tilt following η and the albedo; 0.031
    // and 0.086 on 2026-12-06; η's is the first stage's change taken at the second stage's end,
    // and its first order).
    assert!(worst < 0.1, "{worst}");
    assert!(worst_eta < 0.25, "{worst_eta}");
    // The light's part is in the stated variance: it adds std_light² to what the fit without
    // the light states.
    assert_carried(&f0, &without, &std_light, "light's");
}

/// A sphere of more pixels than the medium fit takes one by one is fitted in blocks of pixels
/// (`fit::medium::MAX_PIXELS_A_SPHERE`), and blocks fit as the pixels do: on the soap renders
/// (1 700–10 000 fitted pixels a sphere), with the truth's light, η ± 0.02, roughness and
/// irradiance, every sphere brought to at most 1 500 samples (blocks of 2×2 and 3×3 pixels).
/// Measured (2026-12-08): σa, σs′ and η within 0.029 stated std of the pixels' fit; the stated
/// std within 0.12% of the pixels' (8–10% wider without the blocks' noise factor,
/// `fit::medium::pixels`' `block_noise_factor`, 1.01–1.63 on these renders), the formal one 5%
/// wider (the blocks' mean square holds the misfit n times over); the residuals per pixel over
/// the noise 0.996 against the pixels' 1.001; σa and σs′ within 1.3% of the truth (the pixels
/// 1.6%). Asserted at about three times those.
#[test]
fn blocks_of_pixels_fit_as_the_pixels_do() {
    use workbench::fit::medium::{fit, pixels, pixels_at_most, start, Held};
    let (_dir, t, loaded, setup, sigma0) = soap_from_its_truth();
    let spheres: Vec<_> = loaded.spheres.iter().collect();
    let each = pixels(&spheres, &t.light);
    let blocks = pixels_at_most(&spheres, &t.light, 1500);
    let count = |r: &[workbench::fit::medium::Radius]| -> Vec<usize> {
        r.iter().map(|r| r.pixels[0].len()).collect()
    };
    println!("pixels {:?}, blocks {:?}", count(&each), count(&blocks));
    for (p, b) in count(&each).iter().zip(count(&blocks)) {
        assert!(
            *p > 1500 && b <= 1500 && 4 * b <= *p + 4 * 1500 / 10,
            "{p} → {b}"
        );
    }
    let fitted = |radii: &[workbench::fit::medium::Radius]| {
        fit(
            radii,
            &setup,
            &start(radii, &setup, sigma0),
            &Held::default(),
        )
    };
    let (fp, fb) = (fitted(&each), fitted(&blocks));
    let std = |f: &workbench::fit::medium::MediumFit, i: usize| f.covariance[(i, i)].sqrt();
    let mut worst: f64 = 0.0;
    for i in 0..7 {
        let apart = (fb.u[i] - fp.u[i]).abs() / std(&fp, i);
        println!(
            "u[{i}]: pixels {:+.5} ± {:.5}, blocks {:+.5} ± {:.5}: {apart:.3} std apart",
            fp.u[i],
            std(&fp, i),
            fb.u[i],
            std(&fb, i)
        );
        worst = worst.max(apart);
        assert!((std(&fb, i) / std(&fp, i) - 1.0).abs() < 0.004, "u[{i}]");
    }
    println!(
        "wave over its noise: pixels {:.3}, blocks {:.3}; formal std of u[0]: pixels {:.5}, blocks {:.5}",
        fp.wave_over_noise, fb.wave_over_noise, fp.std_formal[0], fb.std_formal[0]
    );
    let off = |f: &workbench::fit::medium::MediumFit| {
        (0..3)
            .flat_map(|c| {
                [
                    f.media[c].sigma_a / t.media[c].sigma_a - 1.0,
                    f.media[c].sigma_s_reduced / t.media[c].sigma_s_reduced - 1.0,
                ]
            })
            .fold(0.0f64, |m, e| m.max(e.abs()))
    };
    println!(
        "largest σa, σs′ error: pixels {:.4}, blocks {:.4}; residuals over the noise: pixels {:.3}, blocks {:.3}",
        off(&fp),
        off(&fb),
        fp.residual_over_noise,
        fb.residual_over_noise
    );
    assert!(worst < 0.1, "{worst}");
    assert!(off(&fb) < 0.04, "{}", off(&fb));
    assert!((fb.std_formal[0] / fp.std_formal[0] - 1.0).abs() < 0.15);
    assert!((fb.residual_over_noise - fp.residual_over_noise).abs() < 0.015);
}

/// A sensitivity `s` (per u) times a move `by` against the refit's change from `f0` to `f1`:
/// the largest |refit − first order| over max(|first order|, `floor`) over σa and σs′, and η's
/// over max(|first order|, 1e-3) (ln(η − 1) moves of 1e-3, 4e-4 in η, a fiftieth of the
/// tightest prior's std these fits are given, are no error an outline or the light could carry).
fn against_refit(
    what: &str,
    s: &nalgebra::DVector<f64>,
    by: f64,
    f0: &workbench::fit::medium::MediumFit,
    f1: &workbench::fit::medium::MediumFit,
    floor: f64,
) -> (f64, f64) {
    let (mut worst, mut worst_eta): (f64, f64) = (0.0, 0.0);
    for (i, s) in s.iter().take(7).enumerate() {
        let refit = f1.u[i] - f0.u[i];
        let said = s * by;
        println!("{what}, u[{i}]: refit {refit:+.5}, sensitivity {said:+.5}");
        let off = (refit - said).abs() / said.abs().max(if i == 6 { 1e-3 } else { floor });
        if i == 6 {
            worst_eta = worst_eta.max(off);
        } else {
            worst = worst.max(off);
        }
    }
    (worst, worst_eta)
}

/// A carried input's std per u (`std`, σa's and σs′'s) is what the stated covariance of `with`
/// gained over `without` (the same fit without that input's error).
fn assert_carried(
    with: &workbench::fit::medium::MediumFit,
    without: &workbench::fit::medium::MediumFit,
    std: &[f64],
    what: &str,
) {
    for (i, s) in std.iter().take(6).enumerate() {
        let (added, var) = (with.covariance[(i, i)] - without.covariance[(i, i)], s * s);
        println!("u[{i}]: {what} variance {var:.3e}, added {added:.3e}");
        assert!(
            (added - var).abs() <= 1e-3 * var + 1e-12,
            "u[{i}]: {added} against {var}"
        );
    }
}

/// The soap renders (`datasets/pbr-soap`) loaded, with the medium fit's setup from their truth
/// (light, η ± 0.02, roughness held, irradiance) and the start from the truth's diffusion
/// length: the copy, the truth, the loaded session, the setup and σ0.
fn soap_from_its_truth() -> (
    tempfile::TempDir,
    Truth,
    workbench::solve::Loaded,
    workbench::fit::medium::Setup,
    [f64; 3],
) {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("datasets/pbr-soap");
    let dir = common::session_copy(&src);
    let t = truth(dir.path());
    let loaded = load_for_the_medium(dir.path());
    let setup = workbench::fit::medium::Setup {
        light: t.light,
        eta_prior: (t.media[0].eta, 0.02),
        joint_eta_combined: true,
        eta_alpha_slope: 0.0,
        alpha: t.alpha,
        alpha_std: None,
        irradiance: Some(t.irradiance),
        largest_radius: 35.0,
    };
    let sigma0 = t
        .media
        .map(|m| 1.0 / (3.0 * m.sigma_a * m.sigma_t_reduced()).sqrt());
    (dir, t, loaded, setup, sigma0)
}

/// The medium's first-order sensitivity to the detected outlines (what carries their error
/// into σa and σs′: `fit::medium::OutlineError`) against the fit itself rerun with an outline
/// moved: on the soap renders, with the truth's light, η, roughness and irradiance, the
/// largest sphere's outline grown by 0.3 px and the smallest one's centre moved by 0.3 px
/// (the size of the jade-like renders' outline errors, docs/medium.md), every σa, σs′ and η
/// moves as the sensitivities to that outline coordinate say (η's through the pixels' η). Also: the outlines' part is
/// in the stated covariance, and the outlines as detected give the pixels as observed (the
/// moved pixels at no move are the fit's own).
#[test]
fn the_outline_sensitivity_follows_refits() {
    use workbench::fit::medium::{fit, pixels, start, Held};
    let (_dir, t, loaded, setup, sigma0) = soap_from_its_truth();
    let seated = workbench::solve::medium_spheres(&loaded, &loaded.spheres)
        .expect("every sphere's medium outline");
    let spheres: Vec<_> = seated.iter().collect();
    let l = t.light;
    let outlines =
        workbench::solve::outline_error(&loaded, &spheres, &l).expect("every sphere's outline");
    let radii = pixels(&spheres, &l);
    // Not moved, the outlines give the observations' own geometry.
    let same = (outlines.moved)(0, 0.0);
    assert_eq!(same.len(), radii.len());
    for (a, b) in same.iter().zip(&radii) {
        for c in 0..3 {
            for (p, q) in a.pixels[c].iter().zip(&b.pixels[c]) {
                assert!((p.cos_theta - q.cos_theta).abs() < 1e-12);
                assert!((p.cos_phi - q.cos_phi).abs() < 1e-12);
            }
        }
    }
    let held = Held {
        outlines: Some(&outlines),
        ..Held::default()
    };
    let f0 = fit(&radii, &setup, &start(&radii, &setup, sigma0), &held);
    let without = fit(&radii, &setup, f0.u.as_slice(), &Held::default());
    let s = f0
        .outline_sensitivity
        .clone()
        .expect("the outlines' sensitivity");
    let std_outlines = f0.std_outlines.clone().expect("the outlines' std");
    let (largest, smallest) = {
        let by_radius = |a: &&&workbench::fit::observe::SphereData,
                         b: &&&workbench::fit::observe::SphereData| {
            a.radius_mm.total_cmp(&b.radius_mm)
        };
        let at = |s: &workbench::fit::observe::SphereData| {
            spheres.iter().position(|x| std::ptr::eq(*x, s)).unwrap()
        };
        (
            at(spheres.iter().max_by(by_radius).unwrap()),
            at(spheres.iter().min_by(by_radius).unwrap()),
        )
    };
    let d = 0.3;
    let (mut worst, mut worst_eta): (f64, f64) = (0.0, 0.0);
    for k in [3 * largest + 2, 3 * smallest] {
        let f1 = fit(
            &(outlines.moved)(k, d),
            &setup,
            f0.u.as_slice(),
            &Held::default(),
        );
        let (w, we) = against_refit(&format!("coordinate {k}"), &s[k], d, &f0, &f1, 1e-4);
        (worst, worst_eta) = (worst.max(w), worst_eta.max(we));
    }
    println!(
        "worst |refit − first order| over max(|first order|, 1e-4; η's 1e-3): σa, σs′ {worst:.3}, η {worst_eta:.3}"
    );
    // Measured 0.049 and 0.052 (2026-12-07, latest, the medium's outlines on their own edge
    // model; 0.068 and 0.062 on 2026-12-09, the exit's tilt following η and the albedo; 0.030,
    // and 0.163 over η's floor of 1e-4 then, on 2026-12-06): the second order of a 0.3 px move;
    // η's moves by 6e-5 to 2.8e-3 in ln(η − 1).
    assert!(worst < 0.1, "{worst}");
    assert!(worst_eta < 0.2, "{worst_eta}");
    assert_carried(&f0, &without, &std_outlines, "the outlines'");
}

/// The medium fit given the truth's inputs (by hand, about 10 s): a session of
/// `datasets/pbr-seeds`, `datasets/pbr-range` or ../shared/data (`SESSION`, default jade-6) with every outline where truth.json puts it,
/// the truth's light, irradiance and roughness, η's prior the truth's ± 0.02, and the 20–35 mm
/// spheres, from three starts (the truth itself, the start from the truth's diffusion length, the
/// start from the joint fit's σ0 of jade-6). `ETA=1.405:0.069` replaces η's prior by the joint
/// fit's (jade-6's); `ALPHA=0.091` holds the roughness there, `ALPHA=0.094:0.031` makes it the
/// prior of the α the fit measures (as `solve` does with the lobe's). The tables of
/// docs/medium.md, "Jade: not the outlines, not the light's place, but the light's error" and
/// "The roughness measured with the medium":
/// `cargo test --release --test it -- --ignored medium::the_fit_from_the_truths_inputs --nocapture`.
#[test]
#[ignore]
fn the_fit_from_the_truths_inputs() {
    use workbench::fit::medium::{fit, pixels, start, Held, MediumFit, Setup};
    let name = std::env::var("SESSION").unwrap_or_else(|_| "jade-6".into());
    let dir = common::session_copy(&physically_based_session(&name));
    load_quiet(dir.path());
    truth_outlines(dir.path());
    let t = truth(dir.path());
    let loaded = load_quiet(dir.path());
    // pbr-jade's row.png is left out: its spheres light each other's dark sides.
    let spheres: Vec<_> = loaded
        .spheres
        .iter()
        .filter(|s| s.radius_mm > 16.0 && s.image != "row.png")
        .collect();
    // ALPHA=value holds α there; ALPHA=value:std makes it the prior of α the fit measures.
    let alpha = std::env::var("ALPHA").map_or((t.alpha, None), |v| match v.split_once(':') {
        Some((a, b)) => (a.parse().unwrap(), Some(b.parse().unwrap())),
        None => (v.parse().unwrap(), None),
    });
    let setup = Setup {
        light: t.light,
        eta_prior: std::env::var("ETA").map_or((t.media[0].eta, 0.02), |v| {
            let (a, b) = v.split_once(':').expect("ETA=value:std");
            (a.parse().unwrap(), b.parse().unwrap())
        }),
        joint_eta_combined: true,
        eta_alpha_slope: 0.0,
        alpha: alpha.0,
        alpha_std: alpha.1,
        // IRRADIANCE_SCALE=0.945: the truth's irradiance times that (pbr-jade's photos are
        // 5–7% darker than its truth renders, docs/pbr.md).
        irradiance: Some(
            t.irradiance
                * std::env::var("IRRADIANCE_SCALE").map_or(1.0, |v| v.parse::<f64>().unwrap()),
        ),
        largest_radius: 35.0,
    };
    let radii = pixels(&spheres, &t.light);
    let mut truth_u: Vec<f64> = t.media.iter().map(|m| m.sigma_a.ln()).collect();
    truth_u.extend(t.media.iter().map(|m| m.sigma_s_reduced.ln()));
    truth_u.push((t.media[0].eta - 1.0).ln());
    truth_u.push(t.alpha.ln());
    let sigma0 = t
        .media
        .map(|m| 1.0 / (3.0 * m.sigma_a * m.sigma_t_reduced()).sqrt());
    let off = |f: &MediumFit, of: fn(&Medium) -> f64| -> Vec<f64> {
        (0..3)
            .map(|c| (1000.0 * (of(&f.media[c]) / of(&t.media[c]) - 1.0)).round() / 10.0)
            .collect()
    };
    for (what, u0) in [
        ("the truth", truth_u),
        (
            "the start from the truth's diffusion length",
            start(&radii, &setup, sigma0),
        ),
        (
            "the start from σ0 0.45, 0.8, 0.57 mm",
            start(&radii, &setup, [0.45, 0.8, 0.57]),
        ),
    ] {
        let f = fit(&radii, &setup, &u0, &Held::default());
        println!(
            "from {what}: σa {:?}%, σs′ {:?}%, η {:.3}, α {:.4} ± {:.4}, residuals {:.2}× the noise, {} profiles, {:.1} s",
            off(&f, |m| m.sigma_a),
            off(&f, |m| m.sigma_s_reduced),
            f.media[0].eta,
            f.alpha,
            f.alpha_std.unwrap_or(0.0),
            f.residual_over_noise,
            f.profiles,
            f.seconds
        );
        assert!(f.converged, "from {what}");
    }
}

/// The tally over the model on a sphere of optical radius `sigma_t_radius` (a 25 mm one), M over
/// θ 0–60°, the rough boundary's loss of level (`model::rough_level`) included.
fn rough_level_off(sigma_t_radius: f64, albedo: f64, eta: f64, alpha: f64, seed: u64) -> f64 {
    let (radius, sigma_t) = (25.0, sigma_t_radius / 25.0);
    let t = tally((radius, sigma_t, albedo, eta, alpha), 1_000_000, seed);
    let model = SphereDiffusion::through(
        &Medium::isotropic(sigma_t, albedo, eta),
        radius,
        &Boundary::rough(eta, alpha),
    );
    t.exitance(0, 60).value / band_mean(&model, 0, 60) - 1.0
}

/// The rough level's table off its nodes, run by hand (about 1 min): 40 media drawn uniformly
/// in ln σt′R 7.5–105, η 1.3–1.6, ln α 0.05–0.25 and s = √(1 − α′) 0.071–0.632, a million photons
/// each; the tally over the model, θ 0–60°. Measured (2026-12-08): within 0.79% (rms 0.41%;
/// from albedo 0.97 up 0.74%, rms 0.45%), where the five-term fit in α^{3/2} it replaced was
/// 1.67% off (rms 0.53%; from 0.97 up rms 0.67%) and a fourteen-term one in α and α² 1.22%
/// (rms 0.52%) on the same media (docs/medium.md, "The rough boundary in the model").
#[test]
#[ignore = "by hand: cargo test --release --test it -- --ignored medium::rough_level_on_unseen_media --nocapture"]
fn rough_level_on_unseen_media() {
    let mut state = 12345u64;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let (mut all, mut high) = (vec![], vec![]);
    for i in 0..40 {
        let sigma_t_radius = (7.5f64.ln() + next() * (105.0f64 / 7.5).ln()).exp();
        let eta = 1.3 + 0.3 * next();
        let alpha = (0.05f64.ln() + next() * 5.0f64.ln()).exp();
        let s = 0.071 + next() * (0.632 - 0.071);
        let albedo = 1.0 - s * s;
        let off = rough_level_off(sigma_t_radius, albedo, eta, alpha, 100 + i);
        println!("σt′R {sigma_t_radius:5.1} η {eta:.3} α {alpha:.3} albedo {albedo:.4}: {off:+.4}");
        all.push(off);
        if albedo >= 0.97 {
            high.push(off);
        }
    }
    let summary = |v: &[f64]| {
        let max = v.iter().map(|v| v.abs()).fold(0.0, f64::max);
        let rms = (v.iter().map(|v| v * v).sum::<f64>() / v.len() as f64).sqrt();
        format!("within {max:.4} (rms {rms:.4}, {} media)", v.len())
    };
    println!("all {}; albedo ≥ 0.97 {}", summary(&all), summary(&high));
}

/// The rough level's table holds between its nodes: on four media at none of them (thin-white-,
/// jade-, wax-like and a dark one; σt′R, albedo, η and α all between nodes), the photon tally
/// over the model over θ 0–60° within 0.6% (measured 0.00–0.21%; the five-term fit in α^{3/2} the
/// table replaced was 0.26–0.87% off on them, the thin-white-like medium the worst, and fails).
#[test]
fn the_rough_level_holds_on_unseen_media() {
    for (sigma_t_radius, albedo, eta, alpha) in [
        (12.0, 0.993, 1.32, 0.11),
        (60.0, 0.93, 1.58, 0.06),
        (30.0, 0.955, 1.42, 0.13),
        (40.0, 0.75, 1.52, 0.2),
    ] {
        let off = rough_level_off(sigma_t_radius, albedo, eta, alpha, 7);
        println!("σt′R {sigma_t_radius} albedo {albedo} η {eta} α {alpha}: {off:+.4}");
        assert!(
            off.abs() < 0.006,
            "{off} at σt′R {sigma_t_radius}, albedo {albedo}"
        );
    }
}
