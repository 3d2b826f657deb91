//! The medium fit (`solve --model medium`, docs/medium.md "The medium fit"): σa and σs′ per
//! channel and η from the spheres' pixels, by diffusion solved in each sphere
//! ([`crate::model::sphere_diffusion`], beam sources, level corrected) entering and leaving
//! through a GGX boundary ([`crate::model::boundary`]) whose roughness α the fit measures with
//! them, the joint fit's lobe α and its error as α's prior (the lobe's α, held, moved jade's σa
//! by up to +145%: docs/medium.md, "The roughness measured with the medium"). The light is held
//! where the joint fit put it, and η's prior is the joint fit's η with its error.
//!
//! Pixels near the highlight (half vector within 25° of the normal) and the rim (φ beyond 75°)
//! are left out: the lobe and the rough boundary's grazing exit rule them, and neither is in the
//! diffusion model. The absolute level needs the light's irradiance; without it one irradiance
//! per channel is fitted too, and σa and σs′ rest on the profile's shape alone (said in a note).
//!
//! Errors: σ²(JᵀJ)⁻¹ with σ² the residuals' mean square (not below 1), and with three radii or
//! more a leave-one-radius-out jackknife by one Gauss–Newton step from the fit (widened for its
//! few estimates, [`crate::stats::jackknife_widening`]); each parameter's std is the larger, and
//! the model's own error measured on physically based renders ([`MODEL_ERROR`]) is added to it.
//! The light is held, but its error is not dropped: given the pixels under the light moved along
//! its two angles ([`LightError`]), it is carried into σa, σs′ (and E) by their sensitivity, as
//! η's is (docs/medium.md, "Jade: not the outlines, not the light's place, but the light's
//! error").

mod derived;
mod errors;
mod pixels;
mod problem;

use crate::fit::observe::SphereData;
use crate::model::dipole::Medium;
use crate::model::sphere_atlas::SphereAtlas;
use crate::model::LightAngles;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector};
use problem::{physical, predicted, profiles, Problem, ALPHA, ETA};
use std::time::Instant;

pub use derived::{Derived, PerChannel};
pub use errors::{misfit, ModelError, MODEL_ERROR, WAVE_CALIBRATED};
pub use pixels::{
    block_side, described, each_pixel, fitted, fitted_obs, pixels, pixels_at_most, pixels_moved,
    pixels_seen, Px, Radius, Setup, MAX_PIXELS_A_SPHERE,
};

/// The medium fit's result.
#[derive(Clone, Debug, PartialEq)]
pub struct MediumFit {
    pub media: [Medium; 3],
    /// The irradiance per channel: the given one, or fitted.
    pub irradiance: [f64; 3],
    pub irradiance_given: bool,
    /// The boundary's GGX roughness: fitted (with its std), or held at the lobe's (std None).
    pub alpha: f64,
    pub alpha_std: Option<f64>,
    /// α's prior where it was fitted: the lobe's α and std.
    pub alpha_lobe: Option<(f64, f64)>,
    /// u = (ln σa ×3, ln σs′ ×3, ln(η − 1), ln α, [ln E ×3]) and its covariance (the stated
    /// one: the statistical errors and the model's own).
    pub u: DVector<f64>,
    pub covariance: DMatrix<f64>,
    /// Per u: the formal std and the jackknife's (None under three radii).
    pub std_formal: Vec<f64>,
    pub std_jackknife: Option<Vec<f64>>,
    /// The residuals' RMS in units of the noise (η's prior row left out).
    pub residual_over_noise: f64,
    /// The residuals' wave over its noise ([`crate::fit::wave`]).
    pub wave_over_noise: f64,
    /// Pixel-channels fitted, and the rows they were fitted as (fewer where a large sphere's
    /// pixels were fitted in blocks: [`MAX_PIXELS_A_SPHERE`]).
    pub pixels: usize,
    pub samples: usize,
    pub radii: Vec<f64>,
    /// Profiles computed (the nodes of the fit's atlas), and the solver's evaluations.
    pub profiles: usize,
    pub evaluations: usize,
    pub converged: bool,
    /// Parameters that ended at or near the edge of their range (σa_r, σs′_g, η, …;
    /// `problem::EDGE_MARGIN`).
    pub at_bounds: Vec<String>,
    /// Where η came from: the joint fit's and the pixels' (first stage) estimates.
    pub eta_sources: EtaSources,
    /// Where the first stage, from the given start, ended at the edge of the range of these
    /// parameters and was started again from η [`RESTART_ETA`] to a lower cost
    /// ([`first_stage`]): their names (empty when it was not).
    pub restarted_from: Vec<String>,
    /// Per u, the first-order change with the light's azimuth and elevation (per radian; 0 at
    /// η, which is held), when the light's error was carried ([`LightError`]).
    pub light_sensitivity: Option<[DVector<f64>; 2]>,
    /// Per u, the std the light's error alone gives (already in `covariance`).
    pub std_light: Option<Vec<f64>>,
    /// Per outline coordinate (three a sphere, [`OutlineError`]), per u, the first-order
    /// change with it (per pixel; 0 at η), when the outlines' error was carried.
    pub outline_sensitivity: Option<Vec<DVector<f64>>>,
    /// Per u, the std the outlines' error alone gives (already in `covariance`).
    pub std_outlines: Option<Vec<f64>>,
    /// Per u, the first-order change with ln(η − 1) when η is moved and the pixels refitted (0
    /// at η): what carries η's error into σa and σs′.
    pub eta_sensitivity: DVector<f64>,
    pub seconds: f64,
}

/// The held light's error, for the medium's: the fit's pixels ([`pixels_seen`], same pixels,
/// same order) with the light moved by +`step` and −`step` rad along each of its two angles
/// (`moved[k] = [plus, minus]`: k 0 the azimuth, 1 the elevation), and the two angles'
/// covariance (rad²) as the joint fit states it.
#[derive(Clone, Debug, PartialEq)]
pub struct LightError {
    pub moved: [[Vec<Radius>; 2]; 2],
    pub step: f64,
    pub covariance: nalgebra::Matrix2<f64>,
}

impl LightError {
    /// The spheres' fitted pixels under the light of `angles` ([`pixels`]), seen under it moved
    /// by ± `step` rad along its azimuth and its elevation, with the angles' `covariance`.
    pub fn around(
        spheres: &[&SphereData],
        angles: LightAngles,
        step: f64,
        covariance: nalgebra::Matrix2<f64>,
    ) -> LightError {
        let light = angles.direction();
        let moved = |da: f64, de: f64| {
            let m = LightAngles {
                azimuth: angles.azimuth + da,
                elevation: angles.elevation + de,
            };
            pixels_seen(spheres, &light, &m.direction())
        };
        LightError {
            moved: [
                [moved(step, 0.0), moved(-step, 0.0)],
                [moved(0.0, step), moved(0.0, -step)],
            ],
            step,
            covariance,
        }
    }
}

/// The detected outlines' error, for the medium's: three coordinates a sphere (its outline's
/// centre moved across the view along two directions, and its radius grown, in pixels), with
/// `moved(k, d)` the fit's pixels ([`pixels_moved`]: same pixels, same order) with coordinate k
/// moved by d pixels, and the coordinates' covariance (px²). The spheres' geometry comes from
/// their outlines, so an outline drawn off moves every normal on its sphere (docs/medium.md,
/// "The outlines' error carried").
pub struct OutlineError<'a> {
    pub moved: Box<dyn Fn(usize, f64) -> Vec<Radius> + Sync + 'a>,
    pub step: f64,
    pub covariance: DMatrix<f64>,
}

/// The held inputs whose stated errors the medium fit carries into its own: the light's and
/// the outlines' (each None: not carried).
#[derive(Default)]
pub struct Held<'a> {
    pub light: Option<&'a LightError>,
    pub outlines: Option<&'a OutlineError<'a>>,
}

/// The two estimates of η the fit combines, each (value, std).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EtaSources {
    /// The joint fit's (the highlights and the CDRF's transmissions), its std with
    /// [`JOINT_ETA_ERROR`] and its α's difference from the medium's (`joint_eta_std`).
    pub joint: (f64, f64),
    /// Whether the joint fit's η was combined with the pixels' ([`Setup::joint_eta_combined`]);
    /// where not, the medium's η is the pixels'.
    pub joint_combined: bool,
    /// The medium's pixels with σa and σs′ free, its std with the model's own error.
    pub pixels: (f64, f64),
}

/// The start: the diffusion length 1/σtr from the joint fit's blur length σ0 (on the
/// physically based renders they agree within 20%), and the reduced albedo α′ from the level:
/// on the largest sphere, the α′ of [`START_ALBEDOS`] whose prediction needs the least scale
/// (weighted least squares) to meet the pixels. Without the irradiance, α′ = 0.95 and the scale
/// is E's start. One profile per candidate and channel, for the candidates whose σs′ lies in
/// the fit's range.
pub fn start(radii: &[Radius], setup: &Setup, sigma0_mm: [f64; 3]) -> Vec<f64> {
    let eta = setup.eta_prior.0.clamp(1.1, 2.4);
    let largest = radii.last().expect("a radius to fit");
    let boundary = crate::model::boundary::Boundary::rough(eta, setup.alpha);
    let medium = |a: f64, c: usize| {
        let sigma_tr = 1.0 / sigma0_mm[c].clamp(0.05, 50.0);
        let sigma_t = sigma_tr / (3.0 * (1.0 - a)).sqrt();
        Medium {
            sigma_a: (1.0 - a) * sigma_t,
            sigma_s_reduced: a * sigma_t,
            eta,
        }
    };
    // The weighted least-squares scale that brings (α′, c)'s prediction to the pixels.
    let scale = |a: f64, c: usize| {
        let m = medium(a, c);
        let t = crate::model::sphere_diffusion::SphereDiffusion::through(
            &m,
            largest.radius_mm,
            &boundary,
        )
        .tabulate();
        let (mut lp, mut pp) = (0.0, 0.0);
        for px in &largest.pixels[c] {
            let p = predicted(
                setup.irradiance.unwrap_or(1.0),
                &m,
                largest.radius_mm,
                &boundary,
                &t,
                px,
            );
            let w2 = px.weight * px.weight;
            lp += px.radiance * p * w2;
            pp += p * p * w2;
        }
        lp / pp
    };
    let mut u = vec![0.0; 8];
    u[ETA] = (eta - 1.0).ln();
    u[ALPHA] = setup.alpha.max(1e-12).ln();
    let mut e = [0.0; 3];
    for c in 0..3 {
        let a = match setup.irradiance {
            Some(_) => {
                use rayon::prelude::*;
                // Only candidates inside the fit's range: a start past it (α′ 0.999 put soap's
                // σt′R at 255) is one the fit could not take.
                let within: Vec<f64> = START_ALBEDOS
                    .iter()
                    .copied()
                    .filter(|&a| {
                        medium(a, c).sigma_s_reduced
                            <= problem::sigma_s_range(setup.largest_radius).1
                    })
                    .collect();
                let scales: Vec<f64> = within.par_iter().map(|&a| scale(a, c)).collect();
                within
                    .iter()
                    .zip(scales)
                    .filter(|(_, s)| s.is_finite() && *s > 0.0)
                    .min_by(|x, y| x.1.ln().abs().total_cmp(&y.1.ln().abs()))
                    .map_or(0.95, |(a, _)| *a)
            }
            None => 0.95,
        };
        let m = medium(a, c);
        u[c] = m.sigma_a.ln();
        u[3 + c] = m.sigma_s_reduced.ln();
        if setup.irradiance.is_none() {
            e[c] = scale(a, c).max(1e-12).ln();
        }
    }
    if setup.irradiance.is_none() {
        u.extend(e);
    }
    u
}

/// The reduced albedos [`start`] tries.
pub const START_ALBEDOS: [f64; 8] = [0.6, 0.8, 0.9, 0.95, 0.975, 0.99, 0.995, 0.999];

/// Fit the medium to `radii`'s pixels from `start` (u as [`MediumFit::u`]), in two stages:
///
/// 1. σa, σs′ and η free, η's prior the joint fit's (`setup.eta_prior`);
/// 2. η held at the inverse-variance mean of the joint fit's η (its error `joint_eta_std`'s:
///    widened where the first stage's α differs from the lobe's it rests on) and the first
///    stage's, whose error is its statistical one and the model's own ([`MODEL_ERROR`]'s η) in
///    quadrature (the mean's error widened by √χ² when the two disagree beyond their errors),
///    or at the first stage's alone where the joint fit's model does not describe the photos
///    (`setup.joint_eta_combined`), and σa, σs′ fitted again from the first stage's.
///
/// The pixels alone pulled η by more than its statistical error says (0.04–0.10 low on the
/// physically based wax and soap renders, where the joint fit's η is within 0.03), so their
/// say on η is capped at the model's error; where the joint fit leaves η undetermined (jade's
/// lobe: ± 0.07–0.4) the pixels' η prevails. (Since the surface's reflection and the exit's
/// tilt entered the model, 2026-12-08 and 09, the pixels' η is within 0.013 on those renders
/// and the joint fit's −0.030 to +0.008: docs/medium.md, "η: the pixels' own against the
/// combination", measured, the combination kept.) η's stated error is the combination's, and it is
/// carried into σa and σs′ by their sensitivity to η (docs/medium.md, "The medium fit"), and so
/// are the held light's and outlines' errors, where `held` gives them: directly, and through
/// the pixels' η, which they move, and its share of the combination (docs/medium.md, "The held
/// inputs' error in η").
pub fn fit(radii: &[Radius], setup: &Setup, start: &[f64], held: &Held) -> MediumFit {
    let t0 = Instant::now();
    let atlas = match setup.alpha_std {
        Some(_) => SphereAtlas::free(setup.alpha),
        None => SphereAtlas::new(setup.alpha),
    };
    let (free, restarted) = first_stage(radii, setup, &atlas, start);
    let free_errors = errors::of(&free.0, None);
    // The pixels' η and its stated error (statistical and the model's own, as for any fit).
    let eta_minus_one = free.0.u[ETA].exp();
    let (eta_px, eta_px_std) = (
        1.0 + eta_minus_one,
        eta_minus_one * free_errors.covariance[(ETA, ETA)].max(0.0).sqrt(),
    );
    let joint = (
        setup.eta_prior.0,
        joint_eta_std(setup, problem::roughness(free.0.u.as_slice(), setup)),
    );
    // Left out (an infinite std: no weight) where the joint fit does not describe the photos.
    let joint_weighed = (
        joint.0,
        if setup.joint_eta_combined {
            joint.1
        } else {
            f64::INFINITY
        },
    );
    let combined = crate::stats::inverse_variance_mean(&[joint_weighed, (eta_px, eta_px_std)]);
    let eta = match combined {
        (v, s) if v.is_finite() && s.is_finite() => (v, s),
        _ => setup.eta_prior,
    };
    let held_setup = Setup {
        eta_prior: (eta.0, HELD * eta.1),
        ..*setup
    };
    // From the first stage moved to η to first order, the pixels refitted.
    let mut u = free.0.u.clone();
    let step = (eta.0 - 1.0).ln() - u[ETA];
    u += &free_errors.eta_sensitivity * step;
    u[ETA] = (eta.0 - 1.0).ln();
    let rebased = rebased(&atlas, radii, setup, free.0.u.as_slice(), u.as_slice());
    let second = rebased.as_ref().unwrap_or(&atlas);
    let (problem, report) = solve(radii, &held_setup, second, u, true);
    let p = physical(problem.u.as_slice(), setup);
    let mut errors = errors::of(&problem, Some(eta.1));
    let eta_sensitivity = errors.eta_sensitivity.clone();
    let eta_path = (combined.0.is_finite() && combined.1.is_finite())
        .then(|| {
            let share = pixels_share(joint_weighed.1, eta_px_std) * eta_minus_one / (eta.0 - 1.0);
            errors::EtaPath::new(&free.0, share, &eta_sensitivity)
        })
        .flatten();
    let carried = held
        .light
        .and_then(|le| carry_light(&mut errors.covariance, &problem, le, eta_path.as_ref()));
    let (light_sensitivity, std_light) = carried.unzip();
    let carried = held
        .outlines
        .and_then(|oe| carry_outlines(&mut errors.covariance, &problem, oe, eta_path.as_ref()));
    let (outline_sensitivity, std_outlines) = carried.unzip();
    let profiles = atlas.computed() + rebased.as_ref().map_or(0, SphereAtlas::computed);
    MediumFit {
        media: p.media,
        irradiance: p.irradiance,
        irradiance_given: setup.irradiance.is_some(),
        alpha: p.boundary.alpha,
        alpha_std: setup
            .alpha_std
            .map(|_| p.boundary.alpha * errors::std_of(errors.covariance[(ALPHA, ALPHA)])),
        alpha_lobe: setup.alpha_std.map(|s| (setup.alpha, s)),
        u: problem.u.clone(),
        covariance: errors.covariance,
        std_formal: errors.std_formal,
        std_jackknife: errors.std_jackknife,
        residual_over_noise: errors.residual_over_noise,
        wave_over_noise: errors.wave.over_noise,
        pixels: radii
            .iter()
            .flat_map(|r| r.pixels.iter().flatten())
            .map(|p| p.members)
            .sum::<f64>() as usize,
        samples: problem.pixel_rows(),
        radii: radii.iter().map(|r| r.radius_mm).collect(),
        profiles,
        evaluations: free.1.number_of_evaluations + report.number_of_evaluations,
        converged: free.1.termination.was_successful()
            && report.termination.was_successful()
            && p.media.iter().all(|m| m.sigma_a.is_finite()),
        at_bounds: problem::at_bounds(&p, setup),
        eta_sources: EtaSources {
            joint,
            joint_combined: setup.joint_eta_combined,
            pixels: (eta_px, eta_px_std),
        },
        restarted_from: restarted,
        light_sensitivity,
        eta_sensitivity: errors.eta_sensitivity.clone(),
        std_light,
        outline_sensitivity,
        std_outlines,
        seconds: t0.elapsed().as_secs_f64(),
    }
}

/// η of the first stage's second start ([`first_stage`]): the middle of the indices of the
/// translucent solids the issue names (1.3–1.6, wax to jade), away from the range's walls.
pub const RESTART_ETA: f64 = 1.5;

/// The first stage (σa, σs′, η free) from `start`, and where it ended at the edge of its range
/// ([`problem::at_bounds`]), again from a second start: the same diffusion length, η at
/// [`RESTART_ETA`], the albedo chosen again for that η ([`start`]); the lower cost is kept, and
/// with it the names of the parameters the first start left at the edge (empty when the first
/// start's fit is kept).
///
/// The start's η is the joint fit's, and where the joint fit's η is far off the first stage can
/// end in a minimum at the walls: on the thin-dark corner of the range, whose highlight
/// is clipped over its core, the joint fit's η is 2.67 (truth 1.6) and the first stage ran η
/// and α to the walls (2.48, 0.594) with residuals 1.20 times the noise; from η 1.5 it ends at
/// η 1.73 with residuals 1.05 times the noise (docs/medium.md, "A second start where the first
/// ends at the walls"). A fit that ends inside its range is not started again, so this costs
/// nothing where the start was good.
fn first_stage<'a>(
    radii: &'a [Radius],
    setup: &'a Setup,
    atlas: &'a SphereAtlas,
    start_u: &[f64],
) -> (
    (Problem<'a>, levenberg_marquardt::MinimizationReport<f64>),
    Vec<String>,
) {
    let first = solve(
        radii,
        setup,
        atlas,
        DVector::from_column_slice(start_u),
        false,
    );
    let edges = problem::at_bounds(&physical(first.0.u.as_slice(), setup), setup);
    if edges.is_empty() {
        return (first, edges);
    }
    let again = start(
        radii,
        &Setup {
            eta_prior: (RESTART_ETA, setup.eta_prior.1),
            ..*setup
        },
        diffusion_lengths(&physical(start_u, setup).media),
    );
    let second = solve(radii, setup, atlas, DVector::from_vec(again), false);
    if second.1.objective_function < first.1.objective_function {
        (second, edges)
    } else {
        (first, vec![])
    }
}

/// Each channel's diffusion length 1/σtr (mm): what [`start`] takes as the joint fit's σ0.
fn diffusion_lengths(media: &[Medium; 3]) -> [f64; 3] {
    media.map(|m| 1.0 / m.sigma_tr())
}

/// The free atlas's M is exact at its full nodes' roughness and within 4.6e-3 half a cell from
/// it, worse further at a sharp terminator (`sphere_atlas`'s tests). So the second stage, which
/// starts at `start`, gets an atlas whose full nodes sit at its α, unless that is
/// their node already, or the first atlas's M still holds where the first stage ended
/// (`first`, whose nodes are all there): its error from the roughness within
/// [`REBASE_TOLERANCE`] ([`roughness_error`]: two profiles a radius and channel, where a new
/// atlas costs 64 nodes a point). None: the first atlas serves.
fn rebased(
    atlas: &SphereAtlas,
    radii: &[Radius],
    setup: &Setup,
    first: &[f64],
    start: &[f64],
) -> Option<SphereAtlas> {
    setup.alpha_std?;
    let moved = SphereAtlas::free(problem::roughness(start, setup));
    if moved.base() == atlas.base() {
        return None;
    }
    let off = roughness_error(atlas, radii, setup, first);
    (off.is_nan() || off > REBASE_TOLERANCE).then_some(moved)
}

/// The free atlas's error from the roughness alone at u: its change in M from its full nodes'
/// roughness to u's α against the same change computed directly (so the (x, y, η)
/// interpolation's own error, the same in both of the atlas's, cancels), over M; the largest
/// over θ 0–100°, every radius and channel. 0 for an atlas of one roughness.
fn roughness_error(atlas: &SphereAtlas, radii: &[Radius], setup: &Setup, u: &[f64]) -> f64 {
    use crate::model::boundary::Boundary;
    use crate::model::sphere_atlas::Coordinates;
    let Some(base) = atlas.base_alpha() else {
        return 0.0;
    };
    let alpha = problem::roughness(u, setup);
    let p = physical(u, setup);
    let at_base = problem::Physical {
        boundary: Boundary::rough(p.media[0].eta, base),
        ..p.clone()
    };
    let mut worst = 0.0f64;
    for r in radii {
        let (direct, direct_base) = (profiles(r.radius_mm, &p), profiles(r.radius_mm, &at_base));
        for c in 0..3 {
            let at = |a: f64| {
                atlas
                    .profile(&Coordinates::of(&p.media[c], r.radius_mm, a))
                    .value
            };
            let (m, m_base) = (at(alpha), at(base));
            for deg in 0..=100 {
                let cos = f64::to_radians(deg as f64).cos();
                let d = direct[c].at(cos);
                let change = m.at(cos) - m_base.at(cos);
                let true_change = d - direct_base[c].at(cos);
                worst = worst.max((change - true_change).abs() / d);
            }
        }
    }
    worst
}

/// How far the first stage's atlas may be off from the roughness alone ([`roughness_error`])
/// for the second stage to keep it ([`rebased`]): the error half a cell from the full nodes
/// over θ 0–90° (4.6e-3, `sphere_atlas::tests`), where the second stage would otherwise put
/// them.
const REBASE_TOLERANCE: f64 = 4.6e-3;

/// The held light's error carried into `covariance` (the fit ended at `problem`): the
/// sensitivities to the light's two angles and, per u, the std the light alone gives. None
/// where the moved pixels are not the fit's or do not evaluate.
fn carry_light(
    covariance: &mut DMatrix<f64>,
    problem: &Problem,
    le: &LightError,
    eta: Option<&errors::EtaPath>,
) -> Option<([DVector<f64>; 2], Vec<f64>)> {
    let cov = DMatrix::from_fn(2, 2, |a, b| le.covariance[(a, b)]);
    let s = errors::carry(
        covariance,
        problem,
        |k| {
            let [plus, minus] = &le.moved[k];
            residual_slope(problem, plus, minus, le.step)
        },
        &cov,
        eta,
    )?;
    let std = std_carried(&s, &cov);
    Some((s.try_into().ok()?, std))
}

/// The outlines' error carried into `covariance` (the fit ended at `problem`): the
/// sensitivities to every outline coordinate and, per u, the std the outlines alone give. None
/// where the moved pixels are not the fit's or do not evaluate.
fn carry_outlines(
    covariance: &mut DMatrix<f64>,
    problem: &Problem,
    oe: &OutlineError,
    eta: Option<&errors::EtaPath>,
) -> Option<(Vec<DVector<f64>>, Vec<f64>)> {
    let s = errors::carry(
        covariance,
        problem,
        |k| {
            let (plus, minus) = ((oe.moved)(k, oe.step), (oe.moved)(k, -oe.step));
            residual_slope(problem, &plus, &minus, oe.step)
        },
        &oe.covariance,
        eta,
    )?;
    let std = std_carried(&s, &oe.covariance);
    Some((s, std))
}

/// The pixels' residuals' central difference at `problem`'s u between the pixels `plus` and
/// `minus` (the fit's own, moved by ± `step`), over 2 `step`. A radius whose pixels did not
/// move (another sphere's outline moved) is not evaluated: its rows are 0. None where they are
/// not the fit's pixels or do not evaluate.
fn residual_slope(
    problem: &Problem,
    plus: &[Radius],
    minus: &[Radius],
    step: f64,
) -> Option<DVector<f64>> {
    let same = |moved: &[Radius]| {
        moved.len() == problem.radii.len()
            && moved.iter().zip(problem.radii).all(|(a, b)| {
                a.radius_mm == b.radius_mm && (0..3).all(|c| a.pixels[c].len() == b.pixels[c].len())
            })
    };
    if !(same(plus) && same(minus)) {
        return None;
    }
    let at = |radius: &Radius| {
        Problem::new(
            std::slice::from_ref(radius),
            problem.setup,
            problem.atlas,
            problem.u.clone(),
            true,
        )
        .residuals()
    };
    let mut out = DVector::zeros(problem.pixel_rows());
    for (r, fitted) in problem.radii.iter().enumerate() {
        if plus[r] == *fitted && minus[r] == *fitted {
            continue;
        }
        let (up, down) = (at(&plus[r])?, at(&minus[r])?);
        let rows = problem.offset(r, 0);
        let n = fitted.pixels.iter().map(Vec::len).sum::<usize>();
        for i in 0..n {
            out[rows + i] = (up[i] - down[i]) / (2.0 * step);
        }
    }
    Some(out)
}

/// The weight an inverse-variance mean of the joint fit's η (std `joint`) and the pixels' (std
/// `pixels`) gives the pixels'.
fn pixels_share(joint: f64, pixels: f64) -> f64 {
    let (wj, wp) = (joint.powi(-2), pixels.powi(-2));
    wp / (wj + wp)
}

/// Per u, the std that sensitivities `s` (one column per coordinate) give under the
/// coordinates' covariance `cov`.
fn std_carried(s: &[DVector<f64>], cov: &DMatrix<f64>) -> Vec<f64> {
    let n = s.first().map_or(0, |v| v.len());
    (0..n)
        .map(|i| {
            let si = DVector::from_fn(s.len(), |k, _| s[k][i]);
            si.dot(&(cov * &si)).max(0.0).sqrt()
        })
        .collect()
}

/// The joint fit's η's std where it is combined with the pixels': its stated one, its own
/// error ([`JOINT_ETA_ERROR`]) and, where the medium measured the roughness at `alpha`, the
/// shift of η the joint fit's own η–α correlation gives for the two roughnesses' difference
/// (`setup.eta_alpha_slope` times it), in quadrature. The joint fit's η rests on its lobe's α
/// where the highlight clips (its wings hold F(η)·α²): on the jade-like renders its α is 0.06–0.13
/// for 0.05 and its η 0.1–0.3 low. Widened rather than moved: moved, it would carry the medium's
/// own α error (soap's 0.01–0.03 high) into η (docs/medium.md, "The joint fit's η rests on its
/// α").
fn joint_eta_std(setup: &Setup, alpha: f64) -> f64 {
    let moved = match setup.alpha_std {
        Some(_) if setup.eta_alpha_slope.is_finite() => {
            setup.eta_alpha_slope * (alpha - setup.alpha)
        }
        _ => 0.0,
    };
    setup.eta_prior.1.hypot(JOINT_ETA_ERROR).hypot(moved)
}

/// The joint fit's own error on η, added in quadrature to its stated std where the two are
/// combined: on the physically based wax and soap renders its η is 0.018–0.030 low on wax
/// (2–3 of its stated std) and within 0.008 on soap (docs/medium.md, "The medium fit").
pub const JOINT_ETA_ERROR: f64 = 0.02;

/// η's prior std in the second stage, over the combination's: small enough that the pixels do
/// not move it (its residual outweighs theirs), large enough to keep the normal equations sane.
const HELD: f64 = 1e-3;

/// Levenberg–Marquardt from u (η held by its prior when `eta_held`).
fn solve<'a>(
    radii: &'a [Radius],
    setup: &'a Setup,
    atlas: &'a SphereAtlas,
    u: DVector<f64>,
    eta_held: bool,
) -> (Problem<'a>, levenberg_marquardt::MinimizationReport<f64>) {
    LevenbergMarquardt::new()
        .with_ftol(1e-8)
        .with_xtol(1e-8)
        .with_patience(30)
        .with_stepbound(1.0)
        .minimize(Problem::new(radii, setup, atlas, u, eta_held))
}

/// The fitted medium's prediction of `radius`'s pixels, per channel (radiance units).
pub fn predict(f: &MediumFit, setup: &Setup, radius: &Radius) -> [Vec<f64>; 3] {
    predict_physical(&physical(f.u.as_slice(), setup), radius)
}

/// A medium's prediction of `radius`'s pixels (radiance units) under `irradiance`, through
/// the GGX boundary of roughness `alpha` (a medium read back from fit.json).
pub fn predict_with(
    media: [Medium; 3],
    irradiance: [f64; 3],
    alpha: f64,
    radius: &Radius,
) -> [Vec<f64>; 3] {
    let boundary = crate::model::boundary::Boundary::rough(media[0].eta, alpha);
    predict_physical(
        &problem::Physical {
            media,
            irradiance,
            boundary,
        },
        radius,
    )
}

fn predict_physical(p: &problem::Physical, radius: &Radius) -> [Vec<f64>; 3] {
    let tables = profiles(radius.radius_mm, p);
    std::array::from_fn(|c| {
        radius.pixels[c]
            .iter()
            .map(|px| {
                predicted(
                    p.irradiance[c],
                    &p.media[c],
                    radius.radius_mm,
                    &p.boundary,
                    &tables[c],
                    px,
                )
            })
            .collect()
    })
}

/// This build's medium model at a fixed reference: three media (σt 1 /mm, albedo 0.7, 0.95 and
/// 0.995, η 1.45) on a 20 mm sphere behind a GGX boundary of α 0.1 under unit irradiance, at
/// eight pixels (θ 10, 45, 80 and 95°, each seen 10° and 60° from its normal, across the
/// light's plane), per channel in that order. fit.json records it (`medium.model_reference`):
/// what draws or compares a fit's pixels again with the model (`plot`, `close-loop`) checks that
/// this build's model is the one the medium was fitted with.
pub fn model_reference() -> Vec<f64> {
    let media = [0.7, 0.95, 0.995].map(|albedo| Medium::isotropic(1.0, albedo, 1.45));
    let pixels: Vec<Px> = [10.0f64, 45.0, 80.0, 95.0]
        .iter()
        .flat_map(|&theta| {
            [10.0f64, 60.0].map(|phi| {
                let (t, p) = (theta.to_radians(), phi.to_radians());
                // n at θ from the light (along z); v at φ from n, across the light's plane.
                let n = nalgebra::Vector3::new(t.sin(), 0.0, t.cos());
                let v = n * p.cos() + nalgebra::Vector3::y() * p.sin();
                Px::at(&n, &v, &nalgebra::Vector3::z(), 0.0, 1.0)
            })
        })
        .collect();
    let radius = Radius {
        radius_mm: 20.0,
        pixels: std::array::from_fn(|_| pixels.clone()),
    };
    predict_with(media, [1.0; 3], 0.1, &radius)
        .into_iter()
        .flatten()
        .collect()
}

/// The largest relative difference between two [`model_reference`]s (infinite when their
/// lengths differ or a value is not finite).
pub fn reference_difference(a: &[f64], b: &[f64]) -> f64 {
    if a.len() != b.len() || !a.iter().chain(b).all(|v| v.is_finite()) {
        return f64::INFINITY;
    }
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs() / x.abs().max(y.abs()).max(1e-300))
        .fold(0.0, f64::max)
}

impl MediumFit {
    /// The quantities a renderer takes, each std from the covariance by its gradient in u.
    pub fn derived(&self) -> Derived {
        derived::of(
            &self.media,
            self.irradiance,
            self.irradiance_given,
            &self.covariance,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The second start keeps the first's diffusion lengths: [`start`] sets each channel's
    /// 1/σtr to the σ0 it is given, and [`diffusion_lengths`] reads them back (to rounding).
    /// And a first stage that ends inside its range is kept as it is: the fixture, from its
    /// truth, is not started again.
    #[test]
    fn the_second_start_keeps_the_diffusion_length() {
        let (setup, radii, truth) = problem::tests::fixture();
        let sigma0 = [0.7, 1.9, 3.2];
        let u = start(&radii, &setup, sigma0);
        let back = diffusion_lengths(&physical(&u, &setup).media);
        for c in 0..3 {
            assert!((back[c] / sigma0[c] - 1.0).abs() < 1e-12, "{back:?}");
        }
        let atlas = SphereAtlas::free(setup.alpha);
        let (_, restarted) = first_stage(&radii, &setup, &atlas, &truth);
        assert!(restarted.is_empty(), "{restarted:?}");
    }

    /// The second stage's atlas ([`rebased`]), its full nodes 1.3 roughness cells from the
    /// boundary's α: the fixture's media (σt′R 10–23, α′ 0.87–0.95) keep it, their error from
    /// the roughness measured 1.9e-3 (the tolerance 4.6e-3); a jade-like medium (σa 0.2, σs′
    /// 1.8 /mm, η 1.62 on the same 10 and 20 mm spheres: a sharp terminator) does not, 1.2e-2.
    /// An atlas whose full nodes are at α's own node is kept without a look.
    #[test]
    fn the_second_stage_keeps_the_atlas_where_it_holds() {
        let (setup, radii, truth) = problem::tests::fixture();
        let spacing = crate::model::sphere_atlas::ALPHA_SPACING;
        let atlas = SphereAtlas::free(setup.alpha * (-1.3 * spacing).exp());
        let mut jade = truth.to_vec();
        for c in 0..3 {
            jade[c] = 0.2f64.ln();
            jade[3 + c] = 1.8f64.ln();
        }
        jade[ETA] = 0.62f64.ln();
        let (e_fixture, e_jade) = (
            roughness_error(&atlas, &radii, &setup, &truth),
            roughness_error(&atlas, &radii, &setup, &jade),
        );
        println!("from the roughness: the fixture's media {e_fixture:.1e}, jade-like {e_jade:.1e}");
        assert!(e_fixture < REBASE_TOLERANCE, "{e_fixture}");
        assert!(e_jade > REBASE_TOLERANCE, "{e_jade}");
        assert!(rebased(&atlas, &radii, &setup, &truth, &truth).is_none());
        assert!(rebased(&atlas, &radii, &setup, &jade, &jade).is_some());
        let here = SphereAtlas::free(setup.alpha);
        assert!(rebased(&here, &radii, &setup, &jade, &jade).is_none());
    }
}
