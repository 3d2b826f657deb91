//! Curvature-dependent reflectance function (Kubo et al. 2010): the clamped cosine
//! `max(cos θ, 0)` blurred along θ by a Gaussian of width σ = σ0 / r.
//!
//! Two forms are provided:
//!
//! * [`Convolution::Line`] — the convolution on the infinite θ line, in closed form through the
//!   Faddeeva function `w(z)` (see `../shared/notes/model.md` §1 and the README).
//! * [`Convolution::Wrapped`] — the circular convolution (θ lives on a great circle through the
//!   light's pole, so light that scatters more than π around the sphere wraps).
//!
//! workbench fits the **wrapped** form. θ = acos(n·l) is an angle on a circle; only the wrapped
//! form is 2π-periodic and therefore smooth at θ = π (light exactly behind the surface point).
//! The line form has a kink there, so its derivative with respect to the light direction is
//! unbounded for back-lit pixels, and it tends to 0 instead of the period mean 1/π for wide blurs.
//! For σ < 0.17 rad the two agree to 1e-17; they differ visibly only for σ ≳ 0.6 rad.

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

/// The CDRF and its derivatives at one (θ, σ).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CdrfEval {
    /// f(θ; σ), in [0, 1].
    pub value: f64,
    /// ∂f/∂θ.
    pub d_theta: f64,
    /// ∂²f/∂θ² (the diffusion equation gives ∂f/∂σ = σ ∂²f/∂θ²).
    pub d2_theta: f64,
    /// ∂f/∂σ.
    pub d_sigma: f64,
}

impl CdrfEval {
    /// ∂f/∂(cos θ): the derivative the light-direction Jacobian needs. Finite everywhere for the
    /// wrapped form (the θ → 0 and θ → π limits come from ∂²f/∂θ²).
    pub fn d_cos(&self, theta: f64) -> f64 {
        let s = theta.sin();
        if s.abs() > 1e-6 {
            -self.d_theta / s
        } else if theta.cos() > 0.0 {
            -self.d2_theta
        } else {
            self.d2_theta
        }
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
    // |w| ≤ 1 on the closed upper half plane, so a term whose factor exp(−x²) is below
    // exp(−SKIP) = 4e-18 cannot change the result: skip its Faddeeva evaluation. For sharp blurs
    // (the usual case) this leaves one w(z) call, or none, per evaluation.
    const SKIP: f64 = 40.0;
    let term = |x: f64, re: f64| {
        if x * x > SKIP {
            Complex64::new(0.0, 0.0)
        } else {
            (-x * x).exp() * Complex64::new(re, x.abs()).w()
        }
    };
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

fn wrapped(theta: f64, sigma: f64) -> CdrfEval {
    let t = reduce(theta);
    if sigma < 0.17 {
        // Images at ±2π lie ≥ π/2 outside the support: exp(−(π/2)²/2σ²) < 1e-18.
        line(t, sigma)
    } else if sigma < 0.85 {
        // Images at ±4π lie ≥ 5π/2 outside the support: exp(−(5π/2)²/2σ²) < 1e-18.
        let mut acc = line(t, sigma);
        for k in [-1.0, 1.0] {
            let e = line(t + 2.0 * PI * k, sigma);
            acc.value += e.value;
            acc.d_theta += e.d_theta;
            acc.d2_theta += e.d2_theta;
            acc.d_sigma += e.d_sigma;
        }
        acc
    } else {
        wrapped_fourier(t, sigma)
    }
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

/// The CDRF with a kernel of two Gaussians, (1 − w)·f(θ; σ) + w·f(θ; s·σ): a weight w ∈ [0, 1)
/// moved to a Gaussian s > 1 times wider (docs/kernel.md). Sums of Gaussians approximate
/// diffusion profiles (a sharp core, a long tail); the blur is linear in its kernel, so the closed
/// form and every derivative carry over term by term. w = 0 is the plain CDRF (one evaluation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MixtureEval {
    /// Value and ∂/∂θ, ∂²/∂θ², ∂/∂σ (σ the core's width; the tail's is s·σ).
    pub f: CdrfEval,
    /// ∂f/∂w.
    pub d_weight: f64,
    /// ∂f/∂s.
    pub d_ratio: f64,
}

/// [`MixtureEval`] at (θ, σ) for weight `w` and width ratio `s`.
pub fn mixture(theta: f64, sigma: f64, w: f64, s: f64, conv: Convolution) -> MixtureEval {
    let core = eval(theta, sigma, conv);
    if w == 0.0 {
        return MixtureEval {
            f: core,
            d_weight: 0.0,
            d_ratio: 0.0,
        };
    }
    let tail = eval(theta, s * sigma, conv);
    let mix = |a: f64, b: f64| (1.0 - w) * a + w * b;
    MixtureEval {
        f: CdrfEval {
            value: mix(core.value, tail.value),
            d_theta: mix(core.d_theta, tail.d_theta),
            d2_theta: mix(core.d2_theta, tail.d2_theta),
            d_sigma: mix(core.d_sigma, s * tail.d_sigma),
        },
        d_weight: tail.value - core.value,
        d_ratio: w * sigma * tail.d_sigma,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
