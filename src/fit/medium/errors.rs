//! The medium fit's stated errors: the formal σ²(JᵀJ)⁻¹, a leave-one-radius-out jackknife by one
//! Gauss–Newton step from the fit, the held η's and the held light's and outlines' errors
//! carried in by the others' sensitivity to them (the latter two also through the pixels' η),
//! and what follows for the quantities a renderer takes (the transport mean free path, the
//! surface's diffuse albedo), by their gradients in u.

use super::problem::{Problem, ALPHA, ETA};
use levenberg_marquardt::LeastSquaresProblem;
use nalgebra::{DMatrix, DVector};

/// The model's own error, added in quadrature to every stated error: relative on σa and σs′,
/// absolute on η as the pixels alone measure it (the first stage of [`super::fit`]). Measured
/// as the fit's error against the truth of the physically based wax and soap renders with
/// their irradiance (the two bundled sessions and the six of `datasets/pbr-seeds`;
/// docs/medium.md, "The medium fit"): σa −4 to +19%, σs′ −12 to +16%, and the pixels' η 0.04 to
/// 0.10 low (rms 0.067). The statistical errors alone were 0.2–3%. Set so that each of these
/// lies within 1.5 of its stated error; the jade-like renders, not used to set them, test them.
/// Since the deepest shadow left the fit, the beams follow the transmitted light's mean
/// direction, the pixels' noise is measured as a curve in the level ([`crate::fit::noise`]) and
/// the medium's own outlines weigh the rim by its contrast (`detect::silhouette::EdgeModel`),
/// the same sessions' errors are σa −5.6 to +3.7% and σs′ +1.9 to +8.4% (docs/medium.md, "Each
/// model its own outlines"): the terms are about twice what they need, and are kept while the
/// jade-like fits lean on them. With the surface's reflection and the exit's tilt in the model
/// (2026-12-08 and 09) the pixels' η on the same eight is −0.013 to +0.007 (rms 0.006), so η's
/// term is ten times what they need, but the jade-like renders' pixels' η, up to 0.070 off,
/// need about the present term to be covered; not changed (docs/medium.md, "η: the pixels'
/// own against the combination"). With the medium's outlines on their own edge model
/// (2026-12-07, latest) the jade seeds' pixels' η is within 0.009 and pbr-jade's 0.060 off
/// (docs/medium.md, "The medium's outlines without the limb's T(φ)·cos φ term").
///
/// Where the model misses the photos by more than their noise, the misfit is the model's: the
/// terms on σa and σs′ are scaled by [`misfit`] (as a scale factor widens measurements that
/// disagree beyond their errors; [`crate::stats::inverse_variance_mean`]): the residuals' RMS
/// over the noise (the eight wax and soap fits 1.00–1.08, the jade-like ones 0.99–1.18) or their
/// wave over [`WAVE_CALIBRATED`]. η's term is not scaled: it weighs the pixels' η against the
/// joint fit's, and on the jade-like renders, where the joint fit's η is the worse (0.1–0.3
/// off), scaling it moved η and σa further from the truth (docs/medium.md).
///
/// On the boundary's roughness α, where the fit measures it, the term is relative (on ln α),
/// set the same way from the same eight sessions' whole solves (docs/medium.md, "α's model
/// term"): their α is −2 to +35% off (soap's high on all four, 0.089–0.108 for 0.08), where
/// its statistical error alone is 8–21% and soap-2's error was 2.84 of it. It is not scaled by
/// the misfit: on the jade-like renders, at 1.9–7.7 of the noise, α's statistical error alone
/// covered its error (within 1.0 of it), and scaled it would have been 40–150%.
pub const MODEL_ERROR: ModelError = ModelError {
    sigma_a: 0.10,
    sigma_s_reduced: 0.12,
    eta: 0.07,
    alpha: 0.20,
};

/// The largest wave over its noise ([`crate::fit::wave`]) among the eight wax and soap fits that
/// set [`MODEL_ERROR`], with 15 mm held out or all radii fitted (2.2–5.2, their pixels'
/// residuals 1.00–1.08 of the noise; the jade-like fits 3.4–11.7; docs/medium.md, "The noise
/// curve with the outlines weighted by their contrast"). A fit whose wave is k times this
/// carries k times the model's term. The wave grows as √(pixels a band) for the same miss, so on photos
/// of more pixels a sphere than these (about 1500–15000 a sphere) the factor is conservative.
pub const WAVE_CALIBRATED: f64 = 5.2;

/// The factor the model's term is scaled by: the residuals' RMS over the noise, or the wave
/// over [`WAVE_CALIBRATED`], where either is above 1.
pub fn misfit(residual_over_noise: f64, wave_over_noise: f64) -> f64 {
    let w = if wave_over_noise.is_finite() {
        wave_over_noise / WAVE_CALIBRATED
    } else {
        0.0
    };
    residual_over_noise.max(w).max(1.0)
}

/// The model's own error per quantity ([`MODEL_ERROR`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelError {
    pub sigma_a: f64,
    pub sigma_s_reduced: f64,
    pub eta: f64,
    /// Relative: on ln α.
    pub alpha: f64,
}

pub(super) struct Errors {
    pub(super) covariance: DMatrix<f64>,
    pub(super) std_formal: Vec<f64>,
    pub(super) std_jackknife: Option<Vec<f64>>,
    pub(super) residual_over_noise: f64,
    /// The pixels' residuals over 5° bands of θ against their noise ([`crate::fit::wave`]).
    pub(super) wave: crate::fit::wave::Wave,
    /// d u/d ln(η − 1) of the other parameters with η moved and the pixels refitted (first
    /// order): zero at η's own index.
    pub(super) eta_sensitivity: DVector<f64>,
}

/// The errors at the problem's current parameters. `eta_held`: η was held (by a tight prior)
/// at a value of this std; it becomes η's stated error and is carried into the others by their
/// sensitivity to η, −(J_fᵀJ_f)⁻¹J_fᵀ j_η over the pixels' rows (J_f the other columns).
pub(super) fn of(problem: &Problem, eta_held: Option<f64>) -> Errors {
    let n = problem.u.len();
    let (r, jac) = match (problem.residuals(), problem.jacobian_with(true)) {
        (Some(r), Some(j)) => (r, j),
        _ => {
            return Errors {
                covariance: DMatrix::from_element(n, n, f64::NAN),
                std_formal: vec![f64::NAN; n],
                std_jackknife: None,
                residual_over_noise: f64::NAN,
                wave: crate::fit::wave::wave(std::iter::empty()),
                eta_sensitivity: DVector::zeros(n),
            }
        }
    };
    let sqrt = std_of;
    let m = problem.pixel_rows();
    // The range's wall is no measurement: a parameter past its edge is not determined.
    let mut jac = jac;
    jac.row_mut(m + 1).fill(0.0);
    let pixels_ss: f64 = r.rows(0, m).iter().map(|v| v * v).sum();
    let residual_over_noise = per_pixel_over_noise(problem, &r);
    let wave = residual_wave(problem, &r);
    let s2 = (pixels_ss / (m as f64 - n as f64).max(1.0)).max(1.0);
    let formal = inverse_of_the_determined(&(jac.transpose() * &jac)) * s2;
    let std_formal: Vec<f64> = (0..n).map(|k| sqrt(formal[(k, k)])).collect();
    let std_jackknife = jackknife(problem, &r, &jac);
    let stated: Vec<f64> = match &std_jackknife {
        // A parameter the data do not move stays not determined.
        Some(j) => std_formal
            .iter()
            .zip(j)
            .map(|(f, j)| if f.is_nan() { f64::NAN } else { f.max(*j) })
            .collect(),
        None => std_formal.clone(),
    };
    // The formal correlations, scaled to the statistical errors, and the model's own error.
    let mut covariance = DMatrix::from_fn(n, n, |a, b| {
        formal[(a, b)] / (std_formal[a] * std_formal[b]) * stated[a] * stated[b]
    });
    let eta_minus_one = problem.u[ETA].exp();
    let misfit = misfit(residual_over_noise, wave.over_noise);
    for c in 0..3 {
        covariance[(c, c)] += (misfit * MODEL_ERROR.sigma_a).powi(2);
        covariance[(3 + c, 3 + c)] += (misfit * MODEL_ERROR.sigma_s_reduced).powi(2);
    }
    if problem.setup.alpha_std.is_some() {
        covariance[(ALPHA, ALPHA)] += MODEL_ERROR.alpha.powi(2);
    }
    let eta_sensitivity = sensitivity_to_eta(&jac, m);
    match eta_held {
        None => covariance[(ETA, ETA)] += (MODEL_ERROR.eta / eta_minus_one).powi(2),
        Some(std) => carry_eta(&mut covariance, &eta_sensitivity, std / eta_minus_one),
    }
    Errors {
        covariance,
        std_formal,
        std_jackknife,
        residual_over_noise,
        wave,
        eta_sensitivity,
    }
}

/// The RMS of the residuals `r` (the pixels' rows first) over their noise, per pixel: a block of
/// n pixels ([`super::MAX_PIXELS_A_SPHERE`]) whose residual is r in its mean's noise stands for
/// n pixels of mean square 1 + (r² − 1)/n (its noise's share, 1, and the misfit's, (r² − 1)/n,
/// which a mean over n pixels shows n times over), so that a misfit reads the same on a photo
/// fitted in blocks as on one fitted pixel by pixel: √(Σ (n − 1 + r²) / Σ n).
fn per_pixel_over_noise(problem: &Problem, r: &DVector<f64>) -> f64 {
    let (mut ss, mut n) = (0.0, 0.0);
    for (i, radius) in problem.radii.iter().enumerate() {
        for (c, pixels) in radius.pixels.iter().enumerate() {
            let at = problem.offset(i, c);
            for (k, px) in pixels.iter().enumerate() {
                ss += px.members - 1.0 + r[at + k] * r[at + k];
                n += px.members;
            }
        }
    }
    (ss / n).sqrt()
}

/// The wave of the pixels' residuals `r` (their rows first), one group per radius and channel.
fn residual_wave(problem: &Problem, r: &DVector<f64>) -> crate::fit::wave::Wave {
    let rows = problem.radii.iter().enumerate().flat_map(|(i, radius)| {
        (0..3).flat_map(move |c| {
            let at = problem.offset(i, c);
            radius.pixels[c]
                .iter()
                .enumerate()
                .map(move |(k, px)| (3 * i + c, px.cos_theta.clamp(-1.0, 1.0).acos(), r[at + k]))
        })
    });
    crate::fit::wave::wave(rows)
}

/// The others' sensitivity to η over the pixels' rows `..m` of `jac`: −(J_fᵀJ_f)⁻¹J_fᵀ j_η,
/// J_f the other columns (a parameter the data do not move: 0); 0 at η's index.
fn sensitivity_to_eta(jac: &DMatrix<f64>, m: usize) -> DVector<f64> {
    let je = jac.column(ETA).rows(0, m).into_owned();
    sensitivities(jac, m, 1, |_| Some(je.clone()))
        .and_then(|s| s.into_iter().next())
        .unwrap_or_else(|| DVector::zeros(jac.ncols()))
}

/// The first-order change of every parameter but η (held) when the pixels' residuals change by
/// `dr(k)` (rows `..m` of `jac`), k < `count`, and the fit follows: −(J_fᵀJ_f)⁻¹J_fᵀ dr, J_f
/// the columns other than η's (a parameter the data do not move: 0); 0 at η's index. Each `dr`
/// is taken and dropped in turn, so that many (three a sphere) cost one residual vector at a
/// time. None where a `dr` is missing, of the wrong length, or the change is not finite.
fn sensitivities(
    jac: &DMatrix<f64>,
    m: usize,
    count: usize,
    dr: impl Fn(usize) -> Option<DVector<f64>>,
) -> Option<Vec<DVector<f64>>> {
    let follow = Follow::new(jac, m, Some(ETA));
    (0..count)
        .map(|k| follow.change(&dr(k).filter(|d| d.len() == m)?))
        .collect()
}

/// How a fit's parameters follow a change of its pixels' residuals, to first order: the
/// normal equations' inverse over the columns the change may move (all but `held`) and the
/// first `rows` rows of the Jacobian (a change leaves the rows after the pixels' alone).
struct Follow {
    /// (J_fᵀJ_f)⁻¹J_fᵀ, a parameter the data do not move 0.
    gain: DMatrix<f64>,
    moved: Vec<usize>,
    n: usize,
    m: usize,
}

impl Follow {
    fn new(jac: &DMatrix<f64>, rows: usize, held: Option<usize>) -> Follow {
        let n = jac.ncols();
        let moved: Vec<usize> = (0..n).filter(|&k| Some(k) != held).collect();
        let jf = DMatrix::from_fn(rows, moved.len(), |i, k| jac[(i, moved[k])]);
        let inv = inverse_of_the_determined(&(jf.transpose() * &jf)).map(|v| {
            if v.is_nan() {
                0.0
            } else {
                v
            }
        });
        Follow {
            gain: inv * jf.transpose(),
            moved,
            n,
            m: rows,
        }
    }

    /// The parameters' change for the pixels' residuals' change `d` (its rows the first of the
    /// Jacobian's; those after are unchanged). None where `d` is longer than the rows used or
    /// the change is not finite.
    fn change(&self, d: &DVector<f64>) -> Option<DVector<f64>> {
        if d.len() > self.m {
            return None;
        }
        let sk = -(self.gain.columns(0, d.len()) * d);
        let mut out = DVector::zeros(self.n);
        for (a, &i) in self.moved.iter().enumerate() {
            out[i] = sk[a];
        }
        out.iter().all(|x| x.is_finite()).then_some(out)
    }
}

/// Where η was combined from the pixels' own (the first stage, η free under its prior) and
/// the joint fit's: a held input that moves the pixels moves the pixels' η, and the combined η
/// by its `share` of it (the combination's weight on the pixels' η, times (η_px − 1)/(η − 1)
/// to go from the first stage's ln(η − 1) to the second's); the others follow η by
/// `eta_sensitivity` (d u/d ln(η − 1), 0 at η's index). The joint fit's η, read from the
/// highlight's wings, is taken not to move with the pixels (on jade-3 the truth's outlines and
/// light moved it 0.03, the pixels' 0.11: docs/medium.md, "The held inputs' error in η").
pub(super) struct EtaPath<'a> {
    /// How the first stage follows a change of the pixels' residuals (all its rows).
    first: Follow,
    share: f64,
    eta_sensitivity: &'a DVector<f64>,
}

impl<'a> EtaPath<'a> {
    /// From the first stage's problem at its end. None where its Jacobian does not evaluate.
    pub(super) fn new(
        first: &Problem,
        share: f64,
        eta_sensitivity: &'a DVector<f64>,
    ) -> Option<EtaPath<'a>> {
        let mut jac = first.jacobian_with(true)?;
        jac.row_mut(first.pixel_rows() + 1).fill(0.0);
        Some(EtaPath {
            first: Follow::new(&jac, jac.nrows(), None),
            share,
            eta_sensitivity,
        })
    }
}

/// A held input's error carried into the others (η held, as in the second stage): `dr(k)` is
/// the derivative of the pixels' residuals (rows `..m`, as `problem`'s) along the input's k-th
/// coordinate (of `cov.nrows()`: the light's two angles, or three a sphere's outline), `cov`
/// the coordinates' covariance. With `eta`, the combined η moves with the pixels' η (the first
/// stage's change for the same `dr`, all its rows in its normal equations) and the others with
/// it ([`EtaPath`]). Adds S Σ Sᵀ to `covariance`, S the parameters' sensitivities to the
/// coordinates ([`sensitivities`]), and returns S's columns.
pub(super) fn carry(
    covariance: &mut DMatrix<f64>,
    problem: &Problem,
    dr: impl Fn(usize) -> Option<DVector<f64>>,
    cov: &DMatrix<f64>,
    eta: Option<&EtaPath>,
) -> Option<Vec<DVector<f64>>> {
    let mut jac = problem.jacobian_with(true)?;
    let m = problem.pixel_rows();
    jac.row_mut(m + 1).fill(0.0);
    let held = Follow::new(&jac, m, Some(ETA));
    let s = (0..cov.nrows())
        .map(|k| {
            let d = dr(k).filter(|d| d.len() == m)?;
            let mut sk = held.change(&d)?;
            if let Some(e) = eta {
                let moved = e.share * e.first.change(&d)?[ETA];
                sk += e.eta_sensitivity * moved;
                sk[ETA] = moved;
            }
            Some(sk)
        })
        .collect::<Option<Vec<_>>>()?;
    let sm = DMatrix::from_columns(&s);
    *covariance += &sm * cov * sm.transpose();
    Some(s)
}

/// η held at a value of std `std_u` (in u = ln(η − 1)): its row and column of the covariance
/// become those of that error carried through the others' `sensitivity` to η; the others' own
/// errors stay.
fn carry_eta(covariance: &mut DMatrix<f64>, sensitivity: &DVector<f64>, std_u: f64) {
    let n = covariance.nrows();
    let var = std_u * std_u;
    for i in (0..n).filter(|&k| k != ETA) {
        for j in (0..n).filter(|&k| k != ETA) {
            covariance[(i, j)] += sensitivity[i] * sensitivity[j] * var;
        }
        covariance[(i, ETA)] = sensitivity[i] * var;
        covariance[(ETA, i)] = sensitivity[i] * var;
    }
    covariance[(ETA, ETA)] = var;
}

/// A standard error from a variance: NaN stays NaN (not determined), rounding below 0 is 0.
pub(super) fn std_of(variance: f64) -> f64 {
    if variance.is_nan() {
        f64::NAN
    } else {
        variance.max(0.0).sqrt()
    }
}

/// (JᵀJ)⁻¹ over the parameters the data move (a column of zeros, a parameter held at its range's
/// edge, gets NaN and leaves the others their errors); all NaN if the rest is singular.
fn inverse_of_the_determined(jtj: &DMatrix<f64>) -> DMatrix<f64> {
    let n = jtj.nrows();
    let largest = (0..n).map(|k| jtj[(k, k)]).fold(0.0f64, f64::max);
    let moved: Vec<usize> = (0..n).filter(|&k| jtj[(k, k)] > 1e-20 * largest).collect();
    let sub = DMatrix::from_fn(moved.len(), moved.len(), |a, b| jtj[(moved[a], moved[b])]);
    let mut out = DMatrix::from_element(n, n, f64::NAN);
    if let Some(inv) = sub.try_inverse() {
        for (a, &i) in moved.iter().enumerate() {
            for (b, &j) in moved.iter().enumerate() {
                out[(i, j)] = inv[(a, b)];
            }
        }
    }
    out
}

/// Leave each radius out by one Gauss–Newton step from the fit; the estimates' spread, widened
/// for their number. None under three radii.
fn jackknife(problem: &Problem, r: &DVector<f64>, jac: &DMatrix<f64>) -> Option<Vec<f64>> {
    let k = problem.radii.len();
    if k < 3 {
        return None;
    }
    let n = problem.u.len();
    let rows = r.len();
    let estimates: Vec<DVector<f64>> = (0..k)
        .map(|left| {
            let lo = problem.offset(left, 0);
            let hi = if left + 1 < k {
                problem.offset(left + 1, 0)
            } else {
                problem.pixel_rows()
            };
            let keep: Vec<usize> = (0..rows).filter(|&i| i < lo || i >= hi).collect();
            let j = DMatrix::from_fn(keep.len(), n, |i, c| jac[(keep[i], c)]);
            let rr = DVector::from_fn(keep.len(), |i, _| r[keep[i]]);
            // The parameters the data do not move take no step.
            let inv = inverse_of_the_determined(&(j.transpose() * &j)).map(|v| {
                if v.is_nan() {
                    0.0
                } else {
                    v
                }
            });
            let step = -(inv * (j.transpose() * rr));
            &problem.u + step
        })
        .collect();
    let mean = estimates.iter().fold(DVector::zeros(n), |a, e| a + e) / k as f64;
    let widen = crate::stats::jackknife_widening(k);
    Some(
        (0..n)
            .map(|c| {
                let ss: f64 = estimates.iter().map(|e| (e[c] - mean[c]).powi(2)).sum();
                (ss * (k as f64 - 1.0) / k as f64).sqrt() * widen
            })
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::sphere_atlas::SphereAtlas;

    /// Two σs′ past their range's edge (held there by `physical`): their columns vanish and
    /// the range's wall is no measurement, so they are not determined (NaN) and the others keep
    /// finite errors. With the wall's row in the errors, its two equal columns made the normal
    /// equations singular and every error NaN (jade-6 of `datasets/pbr-seeds`).
    #[test]
    fn a_parameter_past_its_edge_leaves_the_others_determined() {
        let (setup, radii, truth) = super::super::problem::tests::fixture();
        let mut u = truth.to_vec();
        let edge = super::super::problem::sigma_s_range(setup.largest_radius)
            .1
            .ln();
        u[3] = edge + 0.01;
        u[5] = edge + 0.02;
        let atlas = SphereAtlas::free(setup.alpha);
        let problem = Problem::new(&radii, &setup, &atlas, DVector::from_vec(u), false);
        let errors = of(&problem, None);
        for (k, s) in errors.std_formal.iter().enumerate() {
            println!("u[{k}]: {s:e}");
            assert_eq!(s.is_nan(), k == 3 || k == 5, "u[{k}]: {s}");
        }
    }
}
