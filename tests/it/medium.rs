//! The physically shaped profile (issue 35): the classical dipole integrated over each sphere
//! (`model::dipole`, `model::sphere_profile`) and diffusion solved in it
//! (`model::sphere_diffusion`), predicted from the renders' own truth with no free parameter,
//! against the physically based photos' pixels.

use crate::common;
use nalgebra::Vector3;
use std::path::Path;
use workbench::model::dipole::{Dipole, Medium};
use workbench::model::sphere_diffusion::SphereDiffusion;
use workbench::model::sphere_profile::{over_sphere, radiance_factor};

/// Which model predicts M(θ).
#[derive(Clone, Copy, Debug)]
enum Predictor {
    /// The flat medium's dipole profile carried round the sphere by chord length.
    DipoleOverSphere,
    /// The diffusion equation solved in the sphere.
    DiffusionInSphere,
}

/// A physically based session's truth: per channel σa and σs′ (isotropic phase), η, the light
/// and the irradiance in the photos' units (both truth.json formats: `synth pbr`'s and
/// pbr-jade's).
struct Truth {
    media: [Medium; 3],
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
    let media = std::array::from_fn(|c| {
        let a = albedo[c].as_f64().unwrap();
        Medium {
            sigma_a: (1.0 - a) * sigma_t,
            sigma_s_reduced: a * sigma_t,
            eta,
        }
    });
    let l = &t["light"]["direction_to_light_camera_frame"];
    Truth {
        media,
        light: Vector3::from_fn(|i, _| l[i].as_f64().unwrap()).normalize(),
        irradiance: t["irradiance_in_png_units"].as_f64().unwrap(),
    }
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

/// Per channel, per θ band of [`BANDS`]: a mean ratio, or None.
type PerChannelBands = [[Option<f64>; 6]; 3];

/// Per radius and channel: the photos' pixels over the dipole's prediction, mean per θ band
/// (None where a band has no pixel), away from the highlight (the half vector within 25° of the
/// normal) and the rim (φ beyond 75°, where the rough boundary and the outline's pixels rule).
fn ratios(dir: &Path, predictor: Predictor) -> Vec<(String, f64, PerChannelBands)> {
    let t = truth(dir);
    let loaded = workbench::solve::load(&{
        let mut o = workbench::solve::Options::new(dir);
        o.quiet = true;
        o
    })
    .unwrap();
    loaded
        .spheres
        .iter()
        .map(|s| {
            let per_channel = std::array::from_fn(|c| {
                let d = Dipole::new(&t.media[c]);
                let sphere = SphereDiffusion::new(&t.media[c], s.radius_mm);
                let m_of = |cos_theta: f64| match predictor {
                    Predictor::DipoleOverSphere => over_sphere(
                        |r| d.profile(r),
                        s.radius_mm,
                        cos_theta,
                        t.media[c].eta,
                        d.reach(),
                        d.z_r,
                    ),
                    Predictor::DiffusionInSphere => sphere.m(cos_theta),
                };
                // M(θ) tabulated every half degree, interpolated linearly.
                let table: Vec<f64> = (0..=360)
                    .map(|k| m_of((k as f64 * 0.5).to_radians().cos()))
                    .collect();
                let mut sums = [(0.0, 0usize); 6];
                for o in &s.obs {
                    let (n, v) = (o.geometry.normal, o.geometry.view);
                    let h = (t.light + v).normalize();
                    let (cos_theta, cos_phi) = (n.dot(&t.light), n.dot(&v));
                    if n.dot(&h) > 25f64.to_radians().cos() || cos_phi < 75f64.to_radians().cos() {
                        continue;
                    }
                    let theta = cos_theta.clamp(-1.0, 1.0).acos().to_degrees();
                    let k = theta * 2.0;
                    let (i, f) = (k.floor() as usize, k.fract());
                    let m = table[i.min(359)] * (1.0 - f) + table[(i + 1).min(360)] * f;
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

/// The table behind docs/medium.md, run by hand (about 30 s): pbr-wax, pbr-soap and (with
/// ../shared) pbr-jade's single-sphere photos, by both predictors. Measured (2026-12-04), the
/// photos over the prediction by θ band (0–20°, …, 80–100°): the dipole carried round the
/// sphere 0.82–1.35 below 60° and 2–3 at 80–100°; diffusion solved in the sphere 0.98–1.16
/// below 60° and 1.2–2.3 at 80–100°.
#[test]
#[ignore = "by hand: cargo test --release --test it -- --ignored medium::profiles_against_the_renders --nocapture"]
fn profiles_against_the_renders() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut sessions = vec![
        repo.join("datasets/pbr-wax"),
        repo.join("datasets/pbr-soap"),
    ];
    if let Some(shared) = common::shared_data() {
        sessions.push(shared.join("pbr-jade"));
    }
    for (src, predictor) in sessions.iter().flat_map(|s| {
        [Predictor::DipoleOverSphere, Predictor::DiffusionInSphere].map(|p| (s.clone(), p))
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
