//! Gauss–Legendre quadrature: one 8-point rule, composed over equal or geometric panels (for
//! integrands that vary on a scale near one end and slowly far from it, as a diffusion profile
//! does).

/// Nodes (positive half) and weights of the 8-point Gauss–Legendre rule on [−1, 1].
const NODES: [f64; 4] = [
    0.183_434_642_495_649_8,
    0.525_532_409_916_329,
    0.796_666_477_413_626_7,
    0.960_289_856_497_536_3,
];
const WEIGHTS: [f64; 4] = [
    0.362_683_783_378_362,
    0.313_706_645_877_887_3,
    0.222_381_034_453_374_5,
    0.101_228_536_290_376_3,
];

/// The 8-point rule's nodes and weights on [a, b].
pub fn nodes(a: f64, b: f64) -> [(f64, f64); 8] {
    let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
    std::array::from_fn(|k| {
        let (x, w) = (NODES[k % 4], WEIGHTS[k % 4] * half);
        (
            if k < 4 {
                mid - half * x
            } else {
                mid + half * x
            },
            w,
        )
    })
}

/// ∫ₐᵇ f by the 8-point rule (exact for polynomials up to degree 15).
pub fn gauss_legendre(a: f64, b: f64, f: impl Fn(f64) -> f64) -> f64 {
    nodes(a, b).iter().map(|&(x, w)| w * f(x)).sum()
}

/// ∫ₐᵇ f over `n` equal panels.
pub fn equal_panels(a: f64, b: f64, n: usize, f: impl Fn(f64) -> f64) -> f64 {
    let h = (b - a) / n as f64;
    (0..n)
        .map(|k| gauss_legendre(a + k as f64 * h, a + (k + 1) as f64 * h, &f))
        .sum()
}

/// ∫ₐᵇ f over panels that start `first` wide at `a` and grow by half each (the last one cut at
/// `b`): dense where f varies on the scale `first`, coarse where it varies slowly.
pub fn geometric_panels(a: f64, b: f64, first: f64, f: impl Fn(f64) -> f64) -> f64 {
    let (mut lo, mut width, mut sum) = (a, first.max((b - a) * 1e-12), 0.0);
    while lo < b {
        let hi = (lo + width).min(b);
        sum += gauss_legendre(lo, hi, &f);
        lo = hi;
        width *= 1.5;
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against integrals known in closed form: a degree-15 polynomial (exact for the rule), e^x
    /// over geometric panels, and a peaked integrand, x e^{−x/0.01} on [0, 10].
    #[test]
    fn the_rules_match_closed_forms() {
        let poly = gauss_legendre(0.0, 2.0, |x| x.powi(15));
        assert!(
            (poly / (2f64.powi(16) / 16.0) - 1.0).abs() < 1e-14,
            "{poly}"
        );
        let e = geometric_panels(0.0, 3.0, 0.01, f64::exp);
        assert!((e / (3f64.exp() - 1.0) - 1.0).abs() < 1e-13, "{e}");
        let peak = geometric_panels(0.0, 10.0, 0.001, |x| x * (-x / 0.01).exp());
        assert!((peak / 1e-4 - 1.0).abs() < 1e-10, "{peak}");
        let sine = equal_panels(0.0, std::f64::consts::PI, 4, f64::sin);
        assert!((sine - 2.0).abs() < 1e-13, "{sine}");
    }
}
