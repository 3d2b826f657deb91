//! Entry-side Fresnel transmission. Light enters the medium through its dielectric boundary with
//! transmission T(cos θ; η) = 1 − F ([`crate::model::fresnel`]), so what scattering blurs along θ is
//! the transmitted irradiance max(cos θ, 0) · T(cos θ; η), not the bare clamped cosine
//! (docs/model.md, "Entry transmission"). T darkens grazing incidence: near the terminator the
//! source falls like cos²θ instead of cos θ.
//!
//! The source is written as a windowed cosine series g(θ) = Σₖ aₖ(η) cos kθ, k = 0 ..= [`ORDER`],
//! on |θ| < π/2 (0 outside), so its blur has the CDRF's closed form term by term
//! ([`cdrf::Series`]). The aₖ are the least-squares fit on [`NODES`] angles in [0, π/2] in a basis
//! that vanishes at θ = π/2 (cos kθ for odd k, cos kθ + cos (k − 2)θ for even k), so g is
//! continuous where the window cuts it; the fit is linear in the samples, so ∂aₖ/∂η is the same
//! projection of ∂g/∂η. Order 10 leaves 1.1e-5 of the peak for η 1.2–2.4 (1e-4 at η 1.05; tests
//! below); the odd harmonics alone, orthogonal on [0, π/2], would need far more terms (5e-3 with
//! 11), because g's odd extension about π/2 kinks.

use crate::model::cdrf::Series;
use crate::model::fresnel;
use nalgebra::DMatrix;
use std::cell::RefCell;
use std::f64::consts::FRAC_PI_2;
use std::sync::OnceLock;

/// Highest harmonic of the series.
pub(crate) const ORDER: usize = 10;
/// Angles the series is fitted on.
pub(crate) const NODES: usize = 400;

fn theta_node(j: usize) -> f64 {
    FRAC_PI_2 * j as f64 / (NODES - 1) as f64
}

/// Basis function j (j = 1 ..= ORDER) at θ.
fn basis(j: usize, theta: f64) -> f64 {
    let c = (j as f64 * theta).cos();
    if j % 2 == 1 {
        c
    } else {
        c + ((j - 2) as f64 * theta).cos()
    }
}

/// The pseudo-inverse of the basis sampled on the nodes (ORDER × NODES), computed once.
fn projection() -> &'static DMatrix<f64> {
    static P: OnceLock<DMatrix<f64>> = OnceLock::new();
    P.get_or_init(|| {
        let a = DMatrix::from_fn(NODES, ORDER, |i, j| basis(j + 1, theta_node(i)));
        a.svd(true, true)
            .pseudo_inverse(1e-13)
            .expect("the SVD was computed with both U and V")
    })
}

/// Basis weights → cosine coefficients a₀ ..= a_ORDER.
fn to_coeffs(b: &[f64]) -> Vec<f64> {
    let mut a = vec![0.0; ORDER + 1];
    for (j0, &bj) in b.iter().enumerate() {
        let j = j0 + 1;
        a[j] += bj;
        if j % 2 == 0 {
            a[j - 2] += bj;
        }
    }
    a
}

/// The series of max(cos θ, 0) · T(cos θ; η), with ∂/∂η.
pub fn series(eta: f64) -> Series {
    let p = projection();
    let mut g = Vec::with_capacity(NODES);
    let mut dg = Vec::with_capacity(NODES);
    for j in 0..NODES {
        let c = theta_node(j).cos().max(0.0);
        let f = fresnel::eval(c, eta);
        g.push(c * f.transmission());
        dg.push(-c * f.d_eta);
    }
    let b = p * nalgebra::DVector::from_vec(g);
    let db = p * nalgebra::DVector::from_vec(dg);
    Series::new(to_coeffs(b.as_slice()), to_coeffs(db.as_slice()))
}

thread_local! {
    static CACHE: RefCell<Option<(u64, Series)>> = const { RefCell::new(None) };
}

/// Runs `f` with the series at η, recomputed only when η changed since this thread's last call
/// (a fit evaluates thousands of pixels at one η).
pub(crate) fn with_series<R>(eta: f64, f: impl FnOnce(&Series) -> R) -> R {
    CACHE.with(|cell| {
        let mut slot = cell.borrow_mut();
        let stale = !matches!(&*slot, Some((bits, _)) if *bits == eta.to_bits());
        if stale {
            *slot = Some((eta.to_bits(), series(eta)));
        }
        f(&slot.as_ref().expect("filled above").1)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn exact(theta: f64, eta: f64) -> f64 {
        let c = theta.cos().max(0.0);
        c * fresnel::transmission(c, eta)
    }

    #[test]
    fn series_matches_the_transmitted_cosine() {
        for (eta, tol) in [
            (1.05, 3e-4),
            (1.2, 4e-5),
            (1.5, 4e-5),
            (1.8, 4e-5),
            (2.4, 4e-5),
        ] {
            let s = series(eta);
            let mut worst: f64 = 0.0;
            for i in 0..=3000 {
                let th = FRAC_PI_2 * 1.2 * i as f64 / 3000.0;
                worst = worst.max((s.source(th) - exact(th, eta)).abs());
            }
            // Measured: 1.1e-5 (η 1.2 to 2.4); 9.9e-5 at η 1.05, where T rises steepest.
            assert!(worst < tol, "η {eta}: {worst:e}");
            // Continuous at the window's edge by construction.
            let edge: f64 = s
                .coeffs
                .iter()
                .enumerate()
                .map(|(k, a)| a * (k as f64 * FRAC_PI_2).cos())
                .sum();
            assert!(edge.abs() < 1e-12, "η {eta}: {edge:e}");
        }
    }

    #[test]
    fn eta_derivative_of_the_coefficients() {
        for eta in [1.2, 1.5, 2.0] {
            // The cosines are far from orthogonal on [0, π/2] (coefficients of tens that cancel),
            // so a step of 1e-6 is lost in rounding; 1e-4 leaves a truncation error of ~1e-9.
            let h = 1e-4;
            let (a, lo, hi) = (series(eta), series(eta - h), series(eta + h));
            for k in 0..=ORDER {
                let fd = (hi.coeffs[k] - lo.coeffs[k]) / (2.0 * h);
                let scale = a.d_coeffs[k].abs().max(1.0);
                assert!(
                    (fd - a.d_coeffs[k]).abs() < 1e-6 * scale,
                    "η {eta} k {k}: {fd} {}",
                    a.d_coeffs[k]
                );
            }
        }
    }

    #[test]
    fn cache_follows_eta() {
        let a = with_series(1.5, |s| s.coeffs.clone());
        let b = with_series(1.7, |s| s.coeffs.clone());
        assert_eq!(a, series(1.5).coeffs);
        assert_eq!(b, series(1.7).coeffs);
        assert_ne!(a, b);
    }
}
