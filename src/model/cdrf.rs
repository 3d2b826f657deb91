//! Curvature-dependent reflectance function (Kubo et al. 2010): the clamped cosine
//! `max(cos θ, 0)` blurred along θ by a Gaussian of width σ = σ0 / r.
//!
//! Two forms are provided:
//!
//! * [`Convolution::Line`] — the convolution on the infinite θ line, in closed form through the
//!   Faddeeva function `w(z)` (docs/model.md, "CDRF closed form").
//! * [`Convolution::Wrapped`] — the circular convolution (θ lives on a great circle through the
//!   light's pole, so light that scatters more than π around the sphere wraps).
//!
//! workbench fits the **wrapped** form. θ = acos(n·l) is an angle on a circle; only the wrapped
//! form is 2π-periodic and therefore smooth at θ = π (light exactly behind the surface point).
//! The line form has a kink there, so its derivative with respect to the light direction is
//! unbounded for back-lit pixels, and it tends to 0 instead of the period mean 1/π for wide blurs.
//! For σ < 0.17 rad the two agree to 1e-17; they differ visibly only for σ ≳ 0.6 rad.

use crate::model::lanes::Real;
use errorfunctions::ComplexErrorFunctions;
use num_complex::Complex64;
use std::f64::consts::{FRAC_1_PI, FRAC_PI_2, PI, SQRT_2};

/// Which convolution the CDRF uses along θ.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Convolution {
    /// Convolution on the infinite line (the paper's form).
    Line,
    /// Circular (2π-periodic) convolution: the physically consistent form, and the default.
    #[default]
    Wrapped,
}

/// The CDRF and its derivatives at one (θ, σ) (or, [`Real`] lanes, at four).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CdrfEval<T = f64> {
    /// f(θ; σ), in [0, 1].
    pub value: T,
    /// ∂f/∂θ.
    pub d_theta: T,
    /// ∂²f/∂θ² (the diffusion equation gives ∂f/∂σ = σ ∂²f/∂θ²).
    pub d2_theta: T,
    /// ∂f/∂σ.
    pub d_sigma: T,
}

impl CdrfEval {
    /// ∂f/∂(cos θ): the derivative the light-direction Jacobian needs. Finite everywhere for the
    /// wrapped form (the θ → 0 and θ → π limits come from ∂²f/∂θ²).
    pub fn d_cos(&self, theta: f64) -> f64 {
        self.d_cos_at(theta.sin(), theta.cos())
    }
}

impl<T: Real> CdrfEval<T> {
    /// [`CdrfEval::d_cos`] from sin θ and cos θ (computed once for the three channels).
    #[inline(always)]
    pub fn d_cos_at(&self, s: T, c: T) -> T {
        let pole = T::select(c.gt(0.0), -self.d2_theta, self.d2_theta);
        T::select(s.abs().gt(1e-6), -self.d_theta / s, pole)
    }
}

const INV_SQRT_2PI: f64 = 0.398_942_280_401_432_7;

/// Below this σ (rad), f is max(cos θ, 0) to within 1e-300 wherever it matters; the closed form
/// is still evaluated, this only guards σ = 0 and subnormal σ.
const SIGMA_ZERO: f64 = 1e-200;

fn gauss(t: f64, sigma: f64) -> f64 {
    let u = t / sigma;
    (-0.5 * u * u).exp() * INV_SQRT_2PI / sigma
}

/// The limit σ → 0: max(cos θ, 0) with its one-sided derivatives (0 at the kink's outer side).
fn clamped_cosine(theta: f64) -> CdrfEval {
    let c = theta.cos();
    if c > 0.0 {
        CdrfEval {
            value: c,
            d_theta: -theta.sin(),
            d2_theta: -c,
            d_sigma: 0.0,
        }
    } else {
        CdrfEval {
            value: 0.0,
            d_theta: 0.0,
            d2_theta: 0.0,
            d_sigma: 0.0,
        }
    }
}

/// exp(−x²)·w(re + i|x|), the building block of every closed form here. |w| ≤ 1 on the closed
/// upper half plane, so a term whose factor exp(−x²) is below exp(−40) = 4e-18 cannot change the
/// result: its Faddeeva evaluation is skipped. For sharp blurs (the usual case) this leaves one
/// w(z) call, or none, per evaluation.
fn term(x: f64, re: f64) -> Complex64 {
    const SKIP: f64 = 40.0;
    if x * x > SKIP {
        Complex64::new(0.0, 0.0)
    } else {
        (-x * x).exp() * Complex64::new(re, x.abs()).w()
    }
}

/// Z(θ, σ) = ½ exp(iθ − σ²/2) [erf((π/2 − θ − iσ²)/(σ√2)) − erf((−π/2 − θ − iσ²)/(σ√2))],
/// evaluated for θ ≥ 0 without cancellation or overflow: every erf is rewritten as
/// erfc(x ± iy) = exp(−(x ± iy)²) w(…), and the exp(∓σ²/2) factors cancel analytically, leaving
/// exp(−x²) · w(±y + i|x|) with |w| ≤ 1 on the upper half plane.
fn z_line(theta: f64, sigma: f64) -> Complex64 {
    debug_assert!(theta >= 0.0);
    let y = sigma / SQRT_2;
    let x1 = (FRAC_PI_2 - theta) / (sigma * SQRT_2);
    let x2 = (FRAC_PI_2 + theta) / (sigma * SQRT_2);
    let i = Complex64::new(0.0, 1.0);
    let t2 = term(x2, -y);
    if x1 >= 0.0 {
        let t1 = term(x1, y);
        let lead = Complex64::from_polar((-0.5 * sigma * sigma).exp(), theta);
        lead - 0.5 * i * (t1 - t2)
    } else {
        let t1 = term(x1, -y);
        0.5 * i * (t1 + t2)
    }
}

/// The line form at any θ (it is even in θ).
fn line(theta: f64, sigma: f64) -> CdrfEval {
    if sigma < SIGMA_ZERO {
        return clamped_cosine(theta);
    }
    let z = z_line(theta.abs(), sigma);
    let value = z.re;
    let d_theta = -z.im * theta.signum();
    let d2_theta = -value + gauss(theta - FRAC_PI_2, sigma) + gauss(theta + FRAC_PI_2, sigma);
    CdrfEval {
        value,
        d_theta,
        d2_theta,
        d_sigma: sigma * d2_theta,
    }
}

/// Fourier series of the wrapped form, used for wide blurs:
/// f = 1/π + ½ e^{−σ²/2} cos θ + Σ_{n even ≥ 2} 2(−1)^{n/2+1} / (π(n²−1)) e^{−n²σ²/2} cos nθ.
fn wrapped_fourier(theta: f64, sigma: f64) -> CdrfEval {
    let s2 = sigma * sigma;
    let e1 = (-0.5 * s2).exp();
    let (sin1, cos1) = theta.sin_cos();
    let mut value = FRAC_1_PI + 0.5 * e1 * cos1;
    let mut d_theta = -0.5 * e1 * sin1;
    let mut d2_theta = -0.5 * e1 * cos1;
    let mut n = 2.0_f64;
    let mut sign = 1.0;
    loop {
        let e = (-0.5 * n * n * s2).exp();
        if e < 1e-18 {
            break;
        }
        let c = sign * 2.0 * FRAC_1_PI / (n * n - 1.0) * e;
        let (sn, cn) = (n * theta).sin_cos();
        value += c * cn;
        d_theta -= c * n * sn;
        d2_theta -= c * n * n * cn;
        sign = -sign;
        n += 2.0;
    }
    CdrfEval {
        value,
        d_theta,
        d2_theta,
        d_sigma: sigma * d2_theta,
    }
}

/// Reduce θ to [−π, π].
fn reduce(theta: f64) -> f64 {
    if (-PI..=PI).contains(&theta) {
        theta
    } else {
        theta - 2.0 * PI * (theta / (2.0 * PI)).round()
    }
}

impl std::ops::AddAssign for CdrfEval {
    fn add_assign(&mut self, e: CdrfEval) {
        self.value += e.value;
        self.d_theta += e.d_theta;
        self.d2_theta += e.d2_theta;
        self.d_sigma += e.d_sigma;
    }
}

/// The wrapped form from a line form and a Fourier series of the same source, θ reduced to
/// [−π, π]: the line form for σ < 0.17 (images at ±2π lie ≥ π/2 outside the support:
/// exp(−(π/2)²/2σ²) < 1e-18), the k = −1, 0, 1 images for σ < 0.85 (those at ±4π lie ≥ 5π/2
/// outside: exp(−(5π/2)²/2σ²) < 1e-18), the Fourier series above.
fn wrapped_by<T: std::ops::AddAssign>(
    theta: f64,
    sigma: f64,
    line: impl Fn(f64) -> T,
    fourier: impl Fn(f64) -> T,
) -> T {
    let t = reduce(theta);
    if sigma < 0.17 {
        line(t)
    } else if sigma < 0.85 {
        let mut acc = line(t);
        for k in [-1.0, 1.0] {
            acc += line(t + 2.0 * PI * k);
        }
        acc
    } else {
        fourier(t)
    }
}

fn wrapped(theta: f64, sigma: f64) -> CdrfEval {
    wrapped_by(
        theta,
        sigma,
        |t| line(t, sigma),
        |t| wrapped_fourier(t, sigma),
    )
}

/// The CDRF with derivatives. σ ≥ 0 in radians. Non-finite input gives non-finite output.
pub fn eval(theta: f64, sigma: f64, conv: Convolution) -> CdrfEval {
    let mut e = match conv {
        Convolution::Line => line(theta, sigma),
        Convolution::Wrapped => wrapped(theta, sigma),
    };
    // Rounding can leave values a few ulps outside [0, 1]; the function itself is inside.
    e.value = e.value.clamp(0.0, 1.0);
    e
}

/// The CDRF value alone.
pub fn value(theta: f64, sigma: f64, conv: Convolution) -> f64 {
    eval(theta, sigma, conv).value
}

/// A source profile other than the clamped cosine: g(θ) = Σₖ aₖ cos kθ on |θ| < π/2 and 0
/// outside, with the derivatives of its coefficients with respect to one parameter p (for the
/// entry-side transmission of [`crate::model::entry`], p = η). The blur of each windowed cosine has the
/// same closed form as the clamped cosine's (docs/model.md §"Entry transmission"), so
/// G_σ * g = Σₖ aₖ Bₖ(θ; σ) and ∂/∂p = Σₖ ∂aₖ/∂p Bₖ.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// aₖ, k = 0 ..= K.
    pub coeffs: Vec<f64>,
    /// ∂aₖ/∂p.
    pub d_coeffs: Vec<f64>,
    /// Fourier coefficients cₙ of the 2π-periodic g (the wrapped form for wide blurs) and ∂cₙ/∂p.
    fourier: Vec<f64>,
    d_fourier: Vec<f64>,
}

/// Harmonics of the periodic g kept for the wrapped form's Fourier branch (σ ≥ 0.85: the factor
/// exp(−n²σ²/2) is below 1e-18 from n = 11 on).
const N_FOURIER: usize = 12;

impl Series {
    /// The series with coefficients `coeffs` and their derivatives `d_coeffs`.
    pub fn new(coeffs: Vec<f64>, d_coeffs: Vec<f64>) -> Series {
        assert_eq!(coeffs.len(), d_coeffs.len());
        // S(m) = ∫_{−π/2}^{π/2} cos mθ dθ.
        let s = |m: i64| {
            if m == 0 {
                PI
            } else {
                2.0 * (m as f64 * FRAC_PI_2).sin() / m as f64
            }
        };
        // cₙ = (1/π) ∫ g cos nθ (n ≥ 1), c₀ = (1/2π) ∫ g, with
        // ∫ cos kθ cos nθ over the window = ½ (S(k − n) + S(k + n)).
        let project = |a: &[f64]| -> Vec<f64> {
            (0..N_FOURIER as i64)
                .map(|n| {
                    let sum: f64 = a
                        .iter()
                        .enumerate()
                        .map(|(k, &ak)| ak * 0.5 * (s(k as i64 - n) + s(k as i64 + n)))
                        .sum();
                    if n == 0 {
                        sum / (2.0 * PI)
                    } else {
                        sum / PI
                    }
                })
                .collect()
        };
        Series {
            fourier: project(&coeffs),
            d_fourier: project(&d_coeffs),
            coeffs,
            d_coeffs,
        }
    }

    /// The clamped cosine itself (a₁ = 1): a check of the general path against [`eval`].
    #[cfg(test)]
    pub(crate) fn clamped_cosine() -> Series {
        Series::new(vec![0.0, 1.0], vec![0.0, 0.0])
    }

    /// g(θ) unblurred.
    pub fn source(&self, theta: f64) -> f64 {
        if theta.cos() <= 0.0 {
            return 0.0;
        }
        self.coeffs
            .iter()
            .enumerate()
            .map(|(k, a)| a * (k as f64 * theta).cos())
            .sum()
    }
}

/// The blurred series and its derivative with respect to the series' parameter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeriesEval {
    pub f: CdrfEval,
    /// ∂f/∂p.
    pub d_param: f64,
}

impl std::ops::AddAssign for SeriesEval {
    fn add_assign(&mut self, e: SeriesEval) {
        self.f += e.f;
        self.d_param += e.d_param;
    }
}

/// Line form of the series at θ ≥ 0. For each k, Zₖ = ∫_{−π/2}^{π/2} e^{ikθ'} G_σ(θ − θ') dθ'
/// is z_line's expression with y = kσ/√2, the lead e^{ikθ − k²σ²/2} and the phases i^k, (−i)^k
/// (docs/model.md); Bₖ = Re Zₖ, and from the integral
/// ∂Zₖ/∂θ = ik Zₖ − i^k G(θ − π/2) + (−i)^k G(θ + π/2).
fn series_line_pos(theta: f64, sigma: f64, s: &Series) -> SeriesEval {
    let i = Complex64::new(0.0, 1.0);
    let x1 = (FRAC_PI_2 - theta) / (sigma * SQRT_2);
    let x2 = (FRAC_PI_2 + theta) / (sigma * SQRT_2);
    let u1 = theta - FRAC_PI_2;
    let u2 = theta + FRAC_PI_2;
    let (g1, g2) = (gauss(u1, sigma), gauss(u2, sigma));
    let (dg1, dg2) = (-u1 / (sigma * sigma) * g1, -u2 / (sigma * sigma) * g2);
    let e1 = Complex64::from_polar(1.0, theta);
    let mut rot = Complex64::new(1.0, 0.0); // e^{ikθ}
    let mut ik = Complex64::new(1.0, 0.0); // i^k
    let mut out = SeriesEval {
        f: CdrfEval::default(),
        d_param: 0.0,
    };
    for (k, (&a, &da)) in s.coeffs.iter().zip(&s.d_coeffs).enumerate() {
        if a != 0.0 || da != 0.0 {
            let kf = k as f64;
            let y = kf * sigma / SQRT_2;
            let mik = ik.conj(); // (−i)^k
            let t2 = term(x2, -y);
            let z = if x1 >= 0.0 {
                rot * (-y * y).exp() - 0.5 * (ik * term(x1, y) + mik * t2)
            } else {
                0.5 * (ik * term(x1, -y) - mik * t2)
            };
            let dz = i * kf * z - ik * g1 + mik * g2;
            let d2z = i * kf * dz - ik * dg1 + mik * dg2;
            out.f.value += a * z.re;
            out.f.d_theta += a * dz.re;
            out.f.d2_theta += a * d2z.re;
            out.d_param += da * z.re;
        }
        rot *= e1;
        ik *= i;
    }
    out.f.d_sigma = sigma * out.f.d2_theta;
    out
}

fn series_line(theta: f64, sigma: f64, s: &Series) -> SeriesEval {
    if sigma < SIGMA_ZERO {
        // The unblurred source with its one-sided derivatives.
        let inside = theta.cos() > 0.0;
        let mut f = CdrfEval::default();
        let mut d_param = 0.0;
        if inside {
            for (k, (&a, &da)) in s.coeffs.iter().zip(&s.d_coeffs).enumerate() {
                let kf = k as f64;
                let (sn, cn) = (kf * theta).sin_cos();
                f.value += a * cn;
                f.d_theta -= a * kf * sn;
                f.d2_theta -= a * kf * kf * cn;
                d_param += da * cn;
            }
        }
        return SeriesEval { f, d_param };
    }
    let mut e = series_line_pos(theta.abs(), sigma, s);
    e.f.d_theta *= theta.signum();
    e
}

fn series_fourier(theta: f64, sigma: f64, s: &Series) -> SeriesEval {
    let s2 = sigma * sigma;
    let mut f = CdrfEval {
        value: s.fourier[0],
        d_theta: 0.0,
        d2_theta: 0.0,
        d_sigma: 0.0,
    };
    let mut d_param = s.d_fourier[0];
    for n in 1..N_FOURIER {
        let nf = n as f64;
        let e = (-0.5 * nf * nf * s2).exp();
        let (sn, cn) = (nf * theta).sin_cos();
        let c = s.fourier[n] * e;
        f.value += c * cn;
        f.d_theta -= c * nf * sn;
        f.d2_theta -= c * nf * nf * cn;
        d_param += s.d_fourier[n] * e * cn;
    }
    f.d_sigma = sigma * f.d2_theta;
    SeriesEval { f, d_param }
}

/// The blurred series with derivatives, in either convolution (the same branches as [`eval`]).
pub fn eval_series(theta: f64, sigma: f64, s: &Series, conv: Convolution) -> SeriesEval {
    let mut e = match conv {
        Convolution::Line => series_line(theta, sigma, s),
        Convolution::Wrapped => wrapped_by(
            theta,
            sigma,
            |t| series_line(t, sigma, s),
            |t| series_fourier(t, sigma, s),
        ),
    };
    // The series approximates a non-negative source to ~1e-5; keep the result non-negative.
    e.f.value = e.f.value.max(0.0);
    e
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The series path with the clamped cosine as its only term is the closed form [`eval`]:
    /// value and derivatives, on both convolutions, sharp to wide blurs, lit and unlit θ.
    #[test]
    fn series_of_the_clamped_cosine_is_the_closed_form() {
        let s = Series::clamped_cosine();
        let mut worst = 0.0f64;
        for conv in [Convolution::Line, Convolution::Wrapped] {
            for &sigma in &[0.01, 0.1, 0.4, 1.0, 2.5] {
                for k in 0..=40 {
                    let theta = PI * k as f64 / 40.0;
                    let (a, b) = (
                        eval_series(theta, sigma, &s, conv).f,
                        eval(theta, sigma, conv),
                    );
                    for (x, y) in [
                        (a.value, b.value),
                        (a.d_theta, b.d_theta),
                        (a.d_sigma, b.d_sigma),
                    ] {
                        worst = worst.max((x - y).abs());
                    }
                }
            }
        }
        // Measured: 1.4e-16 (rounding).
        println!("largest difference {worst:.2e}");
        assert!(worst < 4e-16, "{worst:e}");
    }

    #[test]
    fn limits() {
        for &t in &[0.0, 0.3, 1.0, 1.5, 1.6, 2.5, PI] {
            let c = t.cos().max(0.0);
            assert!((value(t, 1e-7, Convolution::Wrapped) - c).abs() < 1e-6);
            assert!((value(t, 1e-7, Convolution::Line) - c).abs() < 1e-6);
            assert!((value(t, 60.0, Convolution::Wrapped) - FRAC_1_PI).abs() < 1e-12);
            assert!(value(t, 1e9, Convolution::Line) < 1e-9);
        }
    }

    /// The general series path with a₁ = 1 is the clamped cosine's closed form, on every branch.
    #[test]
    fn series_of_the_clamped_cosine_is_the_cdrf() {
        let s = Series::clamped_cosine();
        for conv in [Convolution::Wrapped, Convolution::Line] {
            for sigma in [1e-250, 0.01, 0.1, 0.3, 0.8, 1.5, 4.0] {
                for i in 0..=60 {
                    let t = -PI + 2.0 * PI * i as f64 / 60.0 + 1e-3;
                    let a = eval(t, sigma, conv);
                    let b = eval_series(t, sigma, &s, conv).f;
                    let ok = |x: f64, y: f64| (x - y).abs() < 1e-12 * (1.0 + x.abs());
                    assert!(
                        ok(a.value, b.value)
                            && ok(a.d_theta, b.d_theta)
                            && ok(a.d2_theta, b.d2_theta)
                            && ok(a.d_sigma, b.d_sigma),
                        "{conv:?} σ {sigma} θ {t}: {a:?} {b:?}"
                    );
                }
            }
        }
    }

    /// Every derivative of a blurred series with several harmonics against central differences.
    #[test]
    fn series_derivatives_match_finite_differences() {
        let a = [0.1, 0.7, -0.2, 0.05, 0.3, -0.04];
        let da = vec![0.3, -0.1, 0.2, 0.4, -0.5, 0.1];
        let at = |p: f64| {
            Series::new(
                a.iter().zip(&da).map(|(x, d)| x + p * d).collect(),
                da.clone(),
            )
        };
        let s = at(0.0);
        for conv in [Convolution::Wrapped, Convolution::Line] {
            for sigma in [0.05, 0.3, 1.2] {
                for i in 0..24 {
                    let t = 0.05 + 3.0 * i as f64 / 24.0;
                    let e = eval_series(t, sigma, &s, conv);
                    let h = 1e-5;
                    let v = |t: f64, sg: f64, p: f64| eval_series(t, sg, &at(p), conv).f.value;
                    let dt = (v(t + h, sigma, 0.0) - v(t - h, sigma, 0.0)) / (2.0 * h);
                    let ds = (v(t, sigma + h, 0.0) - v(t, sigma - h, 0.0)) / (2.0 * h);
                    let dp = (v(t, sigma, h) - v(t, sigma, -h)) / (2.0 * h);
                    let d2 = (eval_series(t + h, sigma, &s, conv).f.d_theta
                        - eval_series(t - h, sigma, &s, conv).f.d_theta)
                        / (2.0 * h);
                    let ok = |x: f64, y: f64| (x - y).abs() < 1e-6 * (1.0 + x.abs());
                    assert!(
                        ok(e.f.d_theta, dt),
                        "{conv:?} σ {sigma} θ {t}: ∂θ {} {dt}",
                        e.f.d_theta
                    );
                    assert!(
                        ok(e.f.d_sigma, ds),
                        "{conv:?} σ {sigma} θ {t}: ∂σ {} {ds}",
                        e.f.d_sigma
                    );
                    assert!(
                        ok(e.d_param, dp),
                        "{conv:?} σ {sigma} θ {t}: ∂p {} {dp}",
                        e.d_param
                    );
                    assert!(
                        ok(e.f.d2_theta, d2),
                        "{conv:?} σ {sigma} θ {t}: ∂²θ {} {d2}",
                        e.f.d2_theta
                    );
                }
            }
        }
    }

    #[test]
    fn fourier_and_images_agree_at_switch() {
        for &t in &[0.0, 0.7, 1.57, 2.2, 3.0] {
            let a = wrapped_fourier(t, 0.85);
            let mut b = line(t, 0.85);
            for k in [-2.0, -1.0, 1.0, 2.0] {
                let e = line(t + 2.0 * PI * k, 0.85);
                b.value += e.value;
                b.d_theta += e.d_theta;
                b.d_sigma += e.d_sigma;
            }
            assert!(
                (a.value - b.value).abs() < 1e-13,
                "{t}: {} {}",
                a.value,
                b.value
            );
            assert!((a.d_theta - b.d_theta).abs() < 1e-12);
            assert!((a.d_sigma - b.d_sigma).abs() < 1e-12);
        }
    }
}
