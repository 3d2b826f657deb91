//! `solve --model medium`: after the joint fit, the medium fit ([`crate::fit::medium`]) from its
//! light, η and lobe, with the held-out radius predicted by both models on the same pixels, as
//! fit.json's `"medium"` and its notes.

use super::load::Loaded;
use super::options::{Options, SolveModel};
use super::outcome::Outcome;
use super::summary::pm;
use crate::camera::outline::Outline;
use crate::detect::silhouette::EDGE_MODEL_ERROR;
use crate::error::{Error, Result};
use crate::fit::joint::identify::beyond_relative_range;
use crate::fit::medium::{
    self, misfit, Held, LightError, MediumFit, OutlineError, Radius, Setup, MODEL_ERROR,
    RESTART_ETA, WAVE_CALIBRATED,
};
use crate::fit::observe::SphereData;
use crate::formats::fit::{
    CarriedStdJson, EtaSourcesJson, MediumHoldoutJson, MediumJson, Method, PerChannelJson,
    ValueJson,
};
use crate::model::idx;

/// The profile's name in fit.json.
pub const PROFILE: &str =
    "diffusion in the sphere, beam sources, level corrected to the photon tally; GGX boundary (docs/medium.md)";

/// The notes' threshold: residuals above this many times the noise, or a wave this many times
/// [`WAVE_CALIBRATED`], are said. The goal for a model that describes the photos; on the
/// eleven physically based sessions of docs/medium.md the wax and soap fits' residuals are at
/// 1.00–1.08 of the noise and their wave at 2.2–5.2, the jade-like ones at 0.99–1.18 and
/// 3.4–11.7: pbr-jade (Mitsuba's renders, wave 11.7) is said.
const MISFIT: f64 = 1.5;

/// `--model medium` needs the joint fit's light and η.
pub(super) fn check(opts: &Options) -> Result<()> {
    if opts.model == SolveModel::Medium && opts.method != Method::Joint {
        return Err(Error::Argument(
            "--model medium starts from the joint fit's light, η and lobe: use it with --method joint".into(),
        ));
    }
    Ok(())
}

/// The spheres seated on the outlines drawn for the medium (detections.json's `medium_outline`,
/// [`crate::formats::detections::MediumOutlineJson`]): each observation's normal and view taken
/// again under its sphere's medium outline (turned onto the common light frame like its
/// photo's), as [`outline_error`] moves them; its radiance, weights and noise the same. An
/// observation the medium's outline leaves outside keeps its own (a rim pixel, beyond what the
/// medium fits). None where a sphere's detection or its medium outline is missing.
pub fn medium_spheres(l: &Loaded, spheres: &[SphereData]) -> Option<Vec<SphereData>> {
    spheres
        .iter()
        .map(|s| {
            let i = l.report.images.iter().position(|im| im.file == s.image)?;
            let d = l.detections.images.get(i)?.spheres.get(s.index)?;
            let outline = d.medium_outline?.outline.outline();
            let turn = l.frames.as_ref().and_then(|f| f.get(i).copied());
            let mut seated = s.clone();
            for (o, &px) in seated.obs.iter_mut().zip(&s.px) {
                if let Some(seen) = seen_under(&l.proj, &outline, turn, px) {
                    (o.geometry.normal, o.geometry.view) = seen;
                }
            }
            Some(seated)
        })
        .collect()
}

/// The normal and view at pixel `px` under `outline`, turned by its photo's `turn` onto the
/// common light frame; None where the pixel's ray misses the outline's sphere.
fn seen_under(
    proj: &crate::camera::outline::Projection,
    outline: &Outline,
    turn: Option<nalgebra::Rotation3<f64>>,
    [x, y]: [u32; 2],
) -> Option<(nalgebra::Vector3<f64>, nalgebra::Vector3<f64>)> {
    let q = proj.point(nalgebra::Vector2::new(x as f64, y as f64))?;
    let surf = outline.surface(&q)?;
    Some(match turn {
        Some(r) => (r * surf.normal, r * surf.view),
        None => (surf.normal, surf.view),
    })
}

/// The medium fit after the joint fit `outcome`, on the `spheres` (seated on the medium's
/// outlines: [`medium_spheres`]) that `is_held` does not hold out.
pub(super) fn run(
    opts: &Options,
    (l, given_by): (&Loaded, &str),
    spheres: &[SphereData],
    outcome: &Outcome,
    is_held: impl Fn(&SphereData) -> bool,
    (notes, skipped): (&mut Vec<String>, &mut Vec<String>),
) -> Option<MediumJson> {
    let p = &outcome.params;
    let m = &p.material;
    let eta_std = outcome.std[idx::ETA];
    let fitted: Vec<&SphereData> = spheres.iter().filter(|s| !is_held(s)).collect();
    let setup = Setup {
        light: p.light.direction(),
        eta_prior: (
            m.eta,
            if eta_std.is_finite() && eta_std > 0.0 {
                eta_std
            } else {
                opts.fit.eta_prior.1
            },
        ),
        joint_eta_combined: joint_describes_the_photos(outcome),
        eta_alpha_slope: eta_alpha_slope(outcome),
        alpha: if outcome.specular {
            m.specular.alpha
        } else {
            0.0
        },
        alpha_std: alpha_prior_std(outcome),
        irradiance: opts.fit.irradiance,
        largest_radius: fitted.iter().map(|s| s.radius_mm).fold(1.0, f64::max),
    };
    let radii = medium::pixels(&fitted, &setup.light);
    if radii.is_empty() {
        notes.push("medium: not fitted — no sphere has pixels in every channel away from the highlight and the rim".into());
        return None;
    }
    let t0 = std::time::Instant::now();
    let start = medium::start(&radii, &setup, m.sigma0_mm);
    let light = light_error(outcome, &fitted);
    let outlines = outline_error(l, &fitted, &setup.light);
    let held = Held {
        light: light.as_ref(),
        outlines: outlines.as_ref(),
    };
    let mut f = medium::fit(&radii, &setup, &start, &held);
    // The start's scan and the held-out prediction count with the fit.
    let held: Vec<&SphereData> = spheres.iter().filter(|s| is_held(s)).collect();
    let holdout = (!held.is_empty()).then(|| holdout(&f, &setup, outcome, &held));
    f.seconds = t0.elapsed().as_secs_f64();
    if f.samples < f.pixels {
        skipped.push(format!(
            "medium pixels: {} pixel-channels fitted as {} rows, a sphere of more than {} fitted pixels in blocks of b×b pixels (each block its pixels' mean, with that mean's noise; docs/medium.md, \"Large photos: the pixels in blocks\")",
            f.pixels,
            f.samples,
            medium::MAX_PIXELS_A_SPHERE
        ));
    }
    say(&f, notes);
    Some(json(&f, holdout, given_by))
}

/// The std of the lobe's α as the medium fit's prior on the boundary's roughness, which the
/// fit then measures from the terminator and the level; None (α held at the lobe's) where the
/// joint fit has no lobe or states no error for its α.
fn alpha_prior_std(outcome: &Outcome) -> Option<f64> {
    let s = outcome.std[idx::ALPHA];
    (outcome.specular && s.is_finite() && s > 0.0).then_some(s)
}

/// Whether the joint fit's model describes the photos: its residuals' χ²/dof at most the level
/// at which it says it does not (`fit::joint::checks::CHI2_WARN`, residuals twice their noise).
/// Where it does not, its η is not combined with the medium's pixels' ([`Setup`]'s
/// `joint_eta_combined`): on the jade-like renders, whose highlights clip, the joint fit's
/// residuals are 2.3–10.8 times the noise and its η 0.1–0.3 low, 0.5–1.8 of its std, though
/// that std is already widened by the misfit (docs/medium.md, "The joint fit's η left out where
/// its model misses the photos").
fn joint_describes_the_photos(outcome: &Outcome) -> bool {
    outcome
        .convergence
        .chi2_per_dof
        .is_none_or(|c| c <= crate::fit::joint::checks::CHI2_WARN)
}

/// How the joint fit's η follows its α: ρ σ_η/σ_α from its correlation and stated errors
/// (its covariance's Σ_ηα/Σ_αα), 0 where either is not free or states no error.
fn eta_alpha_slope(outcome: &Outcome) -> f64 {
    let (e, a) = (idx::ETA, idx::ALPHA);
    let (se, sa) = (outcome.std[e], outcome.std[a]);
    let slope = correlation(outcome, e, a) * se / sa;
    if slope.is_finite() {
        slope
    } else {
        0.0
    }
}

/// The joint fit's correlation of parameters `a` and `b` (its matrix is over the free ones, in
/// their order); 0 where either is not free or it is not finite.
fn correlation(outcome: &Outcome, a: usize, b: usize) -> f64 {
    let at = |k: usize| (0..k).filter(|&j| outcome.free[j]).count();
    let c = &outcome.correlation;
    let free = outcome.free.iter().filter(|f| **f).count();
    let rho = if outcome.free[a] && outcome.free[b] && c.nrows() == free {
        c[(at(a), at(b))]
    } else {
        0.0
    };
    if rho.is_finite() {
        rho
    } else {
        0.0
    }
}

/// The step (rad) the light is moved by for the medium's sensitivity to it: small beside the
/// atlas's half-degree nodes' curvature, large beside rounding.
const LIGHT_STEP: f64 = 1e-3;

/// The joint fit's light error for the medium fit: its pixels under the light moved along the
/// azimuth and the elevation, and the two angles' covariance from the joint fit's stated std and
/// correlation. None where the joint fit states no error for the light (held without one, or
/// not determined).
fn light_error(outcome: &Outcome, fitted: &[&SphereData]) -> Option<LightError> {
    let (a, e) = (idx::AZIMUTH, idx::ELEVATION);
    let (sa, se) = (outcome.std[a], outcome.std[e]);
    if !(sa.is_finite() && se.is_finite() && sa > 0.0 && se > 0.0) {
        return None;
    }
    // A light combined from the highlights' and the shading's estimates (not free in the last
    // fit) has no correlation.
    let rho = correlation(outcome, a, e);
    Some(LightError::around(
        fitted,
        outcome.params.light,
        LIGHT_STEP,
        nalgebra::Matrix2::new(sa * sa, rho * sa * se, rho * sa * se, se * se),
    ))
}

/// The step (px) an outline is moved by for the medium's sensitivity to it.
const OUTLINE_STEP: f64 = 0.01;

/// The detected outlines' error for the medium fit (`light` the fit's): per outline (spheres
/// that stayed put between photos share one, in the order first fitted) three coordinates
/// ([`Outline::moved`]: the centre across the view along two directions, the radius), each
/// pixel of its spheres with its normal and view taken again under the moved outline (turned
/// onto the common light frame like its photo's), and the coordinates' covariance: each
/// outline's stated std with the edge model's own error ([`EDGE_MODEL_ERROR`]), its common
/// parts shared by every outline. None where a sphere's detection is not found.
pub fn outline_error<'a>(
    l: &'a Loaded,
    fitted: &'a [&'a SphereData],
    light: &nalgebra::Vector3<f64>,
) -> Option<OutlineError<'a>> {
    struct Drawn {
        outline: Outline,
        unit: f64,
        std_px: [f64; 3],
    }
    let mut drawn: Vec<Drawn> = vec![];
    // Per fitted sphere: its outline's place in `drawn`, and its photo's turn.
    let mut owner: Vec<(usize, Option<nalgebra::Rotation3<f64>>)> = vec![];
    for s in fitted {
        let i = l.report.images.iter().position(|im| im.file == s.image)?;
        let d = l
            .detections
            .images
            .get(i)?
            .spheres
            .get(s.index)?
            .medium_outline?;
        let outline = d.outline.outline();
        let at = match drawn.iter().position(|o| o.outline == outline) {
            Some(at) => at,
            None => {
                drawn.push(Drawn {
                    unit: outline.pixel_unit(&l.proj),
                    outline,
                    std_px: d.std_px,
                });
                drawn.len() - 1
            }
        };
        owner.push((at, l.frames.as_ref().and_then(|f| f.get(i).copied())));
    }
    let n = 3 * drawn.len();
    let e = EDGE_MODEL_ERROR;
    let covariance = nalgebra::DMatrix::from_fn(n, n, |a, b| {
        let (coord, common) = (a % 3, [e.common_centre, e.common_centre, e.common_radius]);
        let shared = if coord == b % 3 {
            common[coord].powi(2)
        } else {
            0.0
        };
        if a == b {
            drawn[a / 3].std_px[coord].powi(2) + e.independent.powi(2) + shared
        } else {
            shared
        }
    });
    let light = *light;
    let proj = &l.proj;
    Some(OutlineError {
        moved: Box::new(move |k, d| {
            let o = &drawn[k / 3];
            let mut shift = nalgebra::Vector3::zeros();
            shift[k % 3] = d * o.unit;
            let moved = o.outline.moved(&shift);
            medium::pixels_moved(fitted, &light, |i, p| {
                let (at, turn) = &owner[i];
                if *at != k / 3 {
                    return None;
                }
                seen_under(proj, &moved, *turn, fitted[i].px[p])
            })
        }),
        step: OUTLINE_STEP,
        covariance,
    })
}

/// The held-out spheres predicted by the medium and by the CDRF, on the medium's pixels (each
/// on its own, however large the sphere).
fn holdout(
    f: &MediumFit,
    setup: &Setup,
    outcome: &Outcome,
    held: &[&SphereData],
) -> MediumHoldoutJson {
    let radii: Vec<Radius> = medium::each_pixel(held, &setup.light);
    let (mut d_medium, mut d_cdrf, mut o2, mut n) = (0.0, 0.0, 0.0, 0);
    for r in &radii {
        let predicted = medium::predict(f, setup, r);
        for (pixels, predicted) in r.pixels.iter().zip(&predicted) {
            for (px, pm) in pixels.iter().zip(predicted) {
                d_medium += (pm - px.radiance).powi(2);
                o2 += px.radiance.powi(2);
                n += 1;
            }
        }
    }
    // The CDRF on the same pixels: each held sphere's observations that the medium fits.
    for s in held {
        for o in &s.obs {
            if !medium::fitted(&o.geometry.normal, &o.geometry.view, &setup.light) {
                continue;
            }
            let pred = outcome.model.radiance(&outcome.params, &o.geometry);
            for ((p, l), w) in pred.iter().zip(&o.radiance).zip(&o.weight) {
                if *w > 0.0 {
                    d_cdrf += (p - l).powi(2);
                }
            }
        }
    }
    MediumHoldoutJson {
        radius_mm: radii.first().map_or(f64::NAN, |r| r.radius_mm),
        pixels: n,
        medium_rel_rmse: (d_medium / o2).sqrt(),
        cdrf_rel_rmse: (d_cdrf / o2).sqrt(),
    }
}

/// The notes a medium fit needs: an unknown level, a misfit, no convergence.
fn say(f: &MediumFit, notes: &mut Vec<String>) {
    if !f.irradiance_given {
        notes.push(
            "medium: no --irradiance, so the light's level was fitted with the medium: σa and σs′ rest on the profile's shape across the radii and are poorly determined (their errors say how poorly); give the irradiance to measure them (--irradiance, or a grey card in one photo: session.json's \"reference\", docs/formats.md)".into(),
        );
    }
    if f.residual_over_noise > MISFIT || f.wave_over_noise > MISFIT * WAVE_CALIBRATED {
        notes.push(format!(
            "medium: residuals {:.1}× the noise, their means over 5° bands of θ {:.1}× theirs (at most {WAVE_CALIBRATED} on the wax and soap renders): the diffusion model does not describe these photos within their noise, and σa, σs′ carry that misfit (their stated errors are widened by it; docs/medium.md names what the model leaves out)",
            f.residual_over_noise, f.wave_over_noise
        ));
    }
    if !f.restarted_from.is_empty() {
        notes.push(format!(
            "medium: started from the joint fit's η {:.3}, the fit ended with {} at the edge of the range it explores; from a second start at η {RESTART_ETA} it reached a lower cost, which is kept (docs/medium.md, \"A second start where the first ends at the walls\")",
            f.eta_sources.joint.0,
            f.restarted_from.join(", ")
        ));
    }
    if !f.at_bounds.is_empty() {
        notes.push(format!(
            "medium: {} ended at or near the edge of the range the fit explores (docs/medium.md): the photos pull it beyond what the model can say, so its value and error are not a measurement{}",
            f.at_bounds.join(", "),
            fitted_with(&f.at_bounds)
        ));
    }
    if !f.converged {
        notes.push("medium: the fit did not converge; its values are where it stopped".into());
    }
    let d = f.derived();
    for (name, q) in [("σa", d.sigma_a), ("σs′", d.sigma_s_reduced)] {
        if let Some(wide) = poorly_determined(&q) {
            notes.push(format!(
                "medium: {name} is poorly determined ({wide}): an error bar past half its value measures the error, not the value"
            ));
        }
    }
    let ((j, js), (p, ps)) = (f.eta_sources.joint, f.eta_sources.pixels);
    let (eta, eta_std) = f.derived().eta;
    notes.push(if f.eta_sources.joint_combined {
        format!(
            "medium: η {} combines the joint fit's {} and the medium's pixels' {} (their errors include each one's own error on physically based renders, and the joint fit's the shift its η–α correlation gives for its lobe's α against the α measured here; docs/medium.md)",
            pm(eta, eta_std, 3),
            pm(j, js, 3),
            pm(p, ps, 3)
        )
    } else {
        format!(
            "medium: η {} is the medium's pixels' (its error includes the model's own on physically based renders); the joint fit's {} is left out, its model not describing the photos (docs/medium.md, \"The joint fit's η left out where its model misses the photos\")",
            pm(eta, eta_std, 3),
            pm(j, js, 3)
        )
    });
    match (f.alpha_std, f.alpha_lobe) {
        (Some(std), Some((lobe, lobe_std))) => notes.push(format!(
            "medium: the boundary's roughness α {} is the medium's pixels' (its level and terminator), with the joint fit's lobe α {} as its prior; its error includes the model's own {:.0}% (docs/medium.md)",
            pm(f.alpha, std, 3),
            pm(lobe, lobe_std, 3),
            100.0 * MODEL_ERROR.alpha
        )),
        _ => notes.push(format!(
            "medium: the boundary's roughness α held at {:.3}, the joint fit's lobe's{}",
            f.alpha,
            if f.alpha > 0.0 {
                ", which states no error for it"
            } else {
                " (no lobe: a smooth boundary)"
            }
        )),
    }
    if f.radii.len() < 3 {
        notes.push(format!(
            "medium: {} radius(es), too few for the jackknife: the errors are formal only",
            f.radii.len()
        ));
    }
}

/// What was fitted with the parameters `at_bounds` names and so is no measurement either: σa
/// and σs′ where η or α is there (every channel shares them), else each one's partner in its
/// channel (σa_r with σs′_r). Empty where there is none.
fn fitted_with(at_bounds: &[String]) -> String {
    if at_bounds.iter().any(|p| p == "η" || p == "α") {
        return ", nor are σa's and σs′'s, fitted with it".into();
    }
    let partners: Vec<String> = at_bounds
        .iter()
        .filter_map(|p| {
            let other = match p.split_once('_')? {
                ("σa", c) => format!("σs′_{c}"),
                ("σs′", c) => format!("σa_{c}"),
                _ => return None,
            };
            (!at_bounds.contains(&other)).then_some(format!("{other}'s"))
        })
        .collect();
    match partners.len() {
        0 => String::new(),
        1 => format!(", nor is {}, fitted with it", partners[0]),
        _ => format!(", nor are {}, fitted with them", partners.join(" and ")),
    }
}

/// The channels of `q` whose stated error is past the joint fit's plausible range for a positive
/// parameter ([`beyond_relative_range`]), each with its relative error, as "red ± 110%, blue ±
/// 64%", or "red not determined" where its error is none (at its range's edge); None if none.
fn poorly_determined(q: &medium::PerChannel) -> Option<String> {
    let wide: Vec<String> = (0..3)
        .filter(|&c| beyond_relative_range(q.value[c], q.std[c]))
        .map(|c| {
            let name = ["red", "green", "blue"][c];
            if q.std[c].is_finite() {
                format!("{name} ± {:.0}%", 100.0 * q.std[c] / q.value[c].abs())
            } else {
                // At its range's edge: no error (fit.json's null).
                format!("{name} not determined")
            }
        })
        .collect();
    (!wide.is_empty()).then(|| wide.join(", "))
}

fn value((value, std): (f64, f64)) -> ValueJson {
    ValueJson { value, std }
}

/// fit.json's medium; `given_by` says where a given irradiance came from.
fn json(f: &MediumFit, holdout: Option<MediumHoldoutJson>, given_by: &str) -> MediumJson {
    let d = f.derived();
    let per = |p: medium::PerChannel| PerChannelJson {
        value: p.value,
        std: p.std,
    };
    MediumJson {
        profile: PROFILE.into(),
        model_reference: Some(medium::model_reference()),
        alpha: f.alpha,
        alpha_std: f.alpha_std,
        alpha_lobe: f.alpha_lobe.map(value),
        sigma_a_per_mm: per(d.sigma_a),
        sigma_s_reduced_per_mm: per(d.sigma_s_reduced),
        eta: value(d.eta),
        eta_sources: Some(EtaSourcesJson {
            joint: value(f.eta_sources.joint),
            joint_combined: Some(f.eta_sources.joint_combined),
            pixels: value(f.eta_sources.pixels),
        }),
        mean_free_path_mm: per(d.mean_free_path),
        diffuse_albedo: per(d.diffuse_albedo),
        irradiance: per(d.irradiance),
        irradiance_source: if f.irradiance_given {
            given_by.into()
        } else {
            "fitted with the medium (no --irradiance)".into()
        },
        std_source: format!(
            "{}, and the model's own error on physically based renders (σa {:.0}%, σs′ {:.0}%, times the misfit when above 1, the residuals over the noise or their bands' wave over {WAVE_CALIBRATED}: here {:.2}; the pixels' η {}) in quadrature; η the inverse-variance mean of the joint fit's and the pixels', its error carried into σa and σs′; {}{}{}",
            if f.std_jackknife.is_some() {
                "larger of formal and jackknife"
            } else {
                "formal"
            },
            100.0 * MODEL_ERROR.sigma_a,
            100.0 * MODEL_ERROR.sigma_s_reduced,
            misfit(f.residual_over_noise, f.wave_over_noise),
            MODEL_ERROR.eta,
            if f.alpha_std.is_some() {
                format!(
                    "the boundary's roughness fitted with them (the lobe's α its prior), so its error is in theirs, and its own error includes the model's {:.0}% on α",
                    100.0 * MODEL_ERROR.alpha
                )
            } else {
                "the boundary's roughness held at the lobe's, without an error".into()
            },
            if f.std_light.is_some() {
                "; the held light's error (the joint fit's) carried into them by their sensitivity to its two angles"
            } else {
                "; the light held without a stated error, so none of it is carried"
            },
            if f.std_outlines.is_some() {
                "; the detected outlines' error (each one's stated std with the edge model's own) carried the same way"
            } else {
                ""
            }
        ),
        std_from_light: f.std_light.as_ref().map(|s| carried_std(f, s)),
        std_from_outlines: f.std_outlines.as_ref().map(|s| carried_std(f, s)),
        residual_over_noise: f.residual_over_noise,
        wave_over_noise: f.wave_over_noise.is_finite().then_some(f.wave_over_noise),
        pixels: f.pixels,
        blocks: (f.samples < f.pixels).then_some(f.samples),
        radii_mm: f.radii.clone(),
        holdout,
        converged: f.converged,
        profiles: f.profiles,
        seconds: f.seconds,
    }
}

/// σa's and σs′'s std per channel (1/mm) from a carried input's std per u (on their logarithms).
fn carried_std(f: &MediumFit, s: &[f64]) -> CarriedStdJson {
    CarriedStdJson {
        sigma_a_per_mm: std::array::from_fn(|c| f.media[c].sigma_a * s[c]),
        sigma_s_reduced_per_mm: std::array::from_fn(|c| f.media[c].sigma_s_reduced * s[3 + c]),
    }
}

#[cfg(test)]
mod tests {
    use super::fitted_with;

    #[test]
    fn what_was_fitted_with_a_parameter_at_its_edge_is_said() {
        let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(
            fitted_with(&names(&["η", "α"])),
            ", nor are σa's and σs′'s, fitted with it"
        );
        assert_eq!(
            fitted_with(&names(&["σs′_r"])),
            ", nor is σa_r's, fitted with it"
        );
        assert_eq!(
            fitted_with(&names(&["σa_g", "σs′_b"])),
            ", nor are σs′_g's and σa_b's, fitted with them"
        );
        assert_eq!(fitted_with(&names(&["σa_r", "σs′_r"])), "");
        assert_eq!(fitted_with(&[]), "");
    }
}
