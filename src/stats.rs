//! Small statistics, written once: Student's t distribution for the error bars
//! (docs/uncertainty.md), medians and percentiles, and the robust σ from a median absolute
//! deviation that the detector, the noise model, the Huber weights and the calibration's outlier
//! test share.

use nalgebra::{SMatrix, SVector};
use std::f64::consts::PI;

/// P(|T| ≤ t) for Student's t with `dof` degrees of freedom (integer, ≥ 1), in closed form
/// (Abramowitz & Stegun 26.7.3–4): with θ = atan(t/√ν), 2θ/π + (2/π)·sin θ·Σ for odd ν and
/// sin θ·Σ for even ν, Σ a finite series in cos²θ.
pub(crate) fn t_central(t: f64, dof: u32) -> f64 {
    let nu = dof.max(1) as f64;
    let th = (t.abs() / nu.sqrt()).atan();
    let (s, c2) = (th.sin(), th.cos().powi(2));
    if dof % 2 == 1 {
        // θ + sin θ (cos θ + (2/3) cos³θ + … + (2·4···(ν−3))/(1·3···(ν−2)) cos^(ν−2) θ)
        let mut term = th.cos();
        let mut sum = if dof > 1 { term } else { 0.0 };
        let mut k = 3;
        while k < dof {
            term *= c2 * (k - 1) as f64 / k as f64;
            sum += term;
            k += 2;
        }
        2.0 / PI * (th + s * sum)
    } else {
        // sin θ (1 + (1/2) cos²θ + (1·3)/(2·4) cos⁴θ + … )
        let mut term = 1.0;
        let mut sum = 1.0;
        let mut k = 2;
        while k < dof {
            term *= c2 * (k - 1) as f64 / k as f64;
            sum += term;
            k += 2;
        }
        s * sum
    }
}

/// The t with P(|T| ≤ t) = `p` (0 < p < 1) for `dof` degrees of freedom, by bisection.
pub(crate) fn t_quantile_central(p: f64, dof: u32) -> f64 {
    let (mut lo, mut hi) = (0.0, 1.0);
    while t_central(hi, dof) < p && hi < 1e12 {
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if t_central(mid, dof) < p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// P(|Z| ≤ 2) for a standard normal Z: the coverage of ±2 standard errors.
pub(crate) const TWO_SIGMA: f64 = 0.954_499_736_103_642;

/// A Gaussian's σ per median absolute deviation: 1/Φ⁻¹(3/4) to the four places every robust
/// scale here has used (more places would move printed digits, not accuracy).
pub(crate) const MAD_SIGMA: f64 = 1.4826;

/// The median of the finite values (the mean of the middle two for an even count); NaN when there
/// are none.
pub fn median(v: &[f64]) -> f64 {
    let mut s: Vec<f64> = v.iter().cloned().filter(|x| x.is_finite()).collect();
    if s.is_empty() {
        return f64::NAN;
    }
    s.sort_by(|a, b| a.total_cmp(b));
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// A sample's robust σ: [`MAD_SIGMA`] × the median absolute deviation about its [`median`].
pub(crate) fn mad_sigma(v: &[f64]) -> f64 {
    let m = median(v);
    MAD_SIGMA * median(&v.iter().map(|x| (x - m).abs()).collect::<Vec<_>>())
}

/// The robust σ of deviations about a known centre, from their absolute values: [`MAD_SIGMA`] ×
/// their nearest-rank median ([`percentile`] at ½: the upper one of an even count).
pub(crate) fn robust_sigma(abs: Vec<f64>) -> f64 {
    MAD_SIGMA * percentile(abs, 0.5)
}

/// The q-quantile (0 ≤ q ≤ 1) of the finite values, the nearest rank; NaN when there are none.
pub fn percentile(mut v: Vec<f64>, q: f64) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    let k = ((v.len() - 1) as f64 * q).round() as usize;
    *v.select_nth_unstable_by(k, |a, b| a.total_cmp(b)).1
}

/// The jackknife covariance of `n` leave-one-out estimates, (n − 1)/n Σ (θᵢ − θ̄)(θᵢ − θ̄)ᵀ
/// (unwidened; [`jackknife_widening`] gives the factor for its standard errors).
pub fn jackknife_covariance<const D: usize>(estimates: &[SVector<f64, D>]) -> SMatrix<f64, D, D> {
    let n = estimates.len() as f64;
    let mean = estimates.iter().sum::<SVector<f64, D>>() / n;
    estimates
        .iter()
        .map(|v| (v - mean) * (v - mean).transpose())
        .sum::<SMatrix<f64, D, D>>()
        * ((n - 1.0) / n)
}

/// The factor a jackknife's standard error from `n` leave-one-out estimates is widened by,
/// t_{n−1}/2 at [`TWO_SIGMA`]: its ±2 then covers 95.4% with n − 1 degrees of freedom, as ±2σ of a
/// Gaussian does (1.42 for five estimates).
pub fn jackknife_widening(n: usize) -> f64 {
    t_quantile_central(TWO_SIGMA, n as u32 - 1) / 2.0
}

/// Inverse-variance weighted mean with its standard error, widened by √(χ²/dof) when > 1.
pub(crate) fn inverse_variance_mean(values: &[(f64, f64)]) -> (f64, f64) {
    let good: Vec<(f64, f64)> = values
        .iter()
        .cloned()
        .filter(|(v, s)| v.is_finite() && s.is_finite() && *s > 0.0)
        .collect();
    if good.is_empty() {
        return (f64::NAN, f64::INFINITY);
    }
    let w: f64 = good.iter().map(|(_, s)| 1.0 / (s * s)).sum();
    let mean = good.iter().map(|(v, s)| v / (s * s)).sum::<f64>() / w;
    let se = w.sqrt().recip();
    if good.len() < 2 {
        return (mean, se);
    }
    let chi2: f64 = good.iter().map(|(v, s)| ((v - mean) / s).powi(2)).sum();
    let birge = (chi2 / (good.len() - 1) as f64).sqrt();
    (mean, se * birge.max(1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn t_distribution_against_tabulated_quantiles() {
        // Two-sided 95% points (tables): ν = 1, 2, 4, 5, 10, 30.
        for (nu, q) in [
            (1, 12.7062),
            (2, 4.3027),
            (4, 2.7764),
            (5, 2.5706),
            (10, 2.2281),
            (30, 2.0423),
        ] {
            let t = t_quantile_central(0.95, nu);
            assert!((t - q).abs() < 1e-4, "ν {nu}: {t} vs {q}");
        }
        // ν = 1 is the Cauchy distribution: P(|T| ≤ 1) = 1/2.
        assert!((t_central(1.0, 1) - 0.5).abs() < 1e-15);
        // Large ν: the normal's ±2σ.
        assert!((t_quantile_central(TWO_SIGMA, 400) - 2.0).abs() < 0.01);
    }
}
