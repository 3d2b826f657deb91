//! Specular lobe: GGX (Trowbridge–Reitz) microfacet distribution with separable Smith masking and
//! the exact dielectric Fresnel term, as in pbrt.
//!
//!     D(h)  = α² / (π ((n·h)² (α² − 1) + 1)²)
//!     G1(w) = 2 (n·w) / ((n·w) + sqrt(α² + (1 − α²)(n·w)²)),   G = G1(l) G1(v)
//!     fs    = ks · D · G · F(l·h; η) / (4 (n·l)(n·v))
//!
//! [`lobe`] returns the lobe times the cosine, fs · (n·l), the quantity the radiance model adds,
//! as a function of the three scalars n·l, n·v and l·v (h = (l + v)/|l + v| gives
//! n·h = (n·l + n·v)/sqrt(2 + 2 l·v) and l·h = sqrt((1 + l·v)/2)).

use crate::model::fresnel;
use crate::model::lanes::Real;
use std::f64::consts::PI;

/// GGX normal distribution D(n·h) with ∂D/∂(n·h) and ∂D/∂α (on one pixel or four, [`Real`]).
#[inline(always)]
pub fn ggx_d<T: Real>(nh: T, alpha: f64) -> (T, T, T) {
    let a2 = alpha * alpha;
    let q = nh * nh * (a2 - 1.0) + 1.0;
    let pq2 = q * PI * q;
    let pq3 = pq2 * q;
    let d = T::splat(a2) / pq2;
    let d_nh = nh * (-4.0 * a2) * (a2 - 1.0) / pq3;
    let d_a2 = T::splat(1.0) / pq2 - nh * (2.0 * a2) * nh / pq3;
    (d, d_nh, d_a2 * (2.0 * alpha))
}

/// Smith masking G1(c) for GGX with ∂G1/∂c and ∂G1/∂α.
#[inline(always)]
pub fn smith_g1<T: Real>(c: T, alpha: f64) -> (T, T, T) {
    let a2 = alpha * alpha;
    let r = (c * (1.0 - a2) * c + a2).sqrt();
    let s = c + r;
    let g = c * 2.0 / s;
    let dr_dc = c * (1.0 - a2) / r;
    let d_c = T::splat(2.0) / s - c * 2.0 * (dr_dc + 1.0) / (s * s);
    let dr_da2 = (-(c * c) + 1.0) / (r * 2.0);
    let d_a2 = c * (-2.0) * dr_da2 / (s * s);
    (g, d_c, d_a2 * (2.0 * alpha))
}

/// fs·(n·l) and its derivatives.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LobeEval<T = f64> {
    pub value: T,
    pub d_nl: T,
    pub d_lv: T,
    pub d_ks: T,
    pub d_alpha: T,
    pub d_eta: T,
}

/// The specular term fs·(n·l) = ks D G F / (4 n·v); zero unless n·l > 0 and n·v > 0.
#[inline(always)]
pub fn lobe<T: Real>(nl: T, nv: T, lv: T, ks: f64, alpha: f64, eta: f64) -> LobeEval<T> {
    let dark = nl.le(0.0) | nv.le(0.0) | lv.le(-1.0 + 1e-12);
    let zero = T::splat(0.0);
    if T::all(dark) {
        return LobeEval {
            value: zero,
            d_nl: zero,
            d_lv: zero,
            d_ks: zero,
            d_alpha: zero,
            d_eta: zero,
        };
    }
    let m2 = lv * 2.0 + 2.0;
    let m = m2.sqrt();
    let nh = ((nl + nv) / m).min(1.0);
    let lh = ((lv + 1.0) * 0.5).sqrt();
    let dnh_dnl = T::splat(1.0) / m;
    let dnh_dlv = -nh / m2;
    let dlh_dlv = T::splat(0.25) / lh;

    let (d, dd_nh, dd_a) = ggx_d(nh, alpha);
    let (gl, dgl_c, dgl_a) = smith_g1(nl, alpha);
    let (gv, _, dgv_a) = smith_g1(nv, alpha);
    let f = fresnel::eval(lh, eta);

    let k = T::splat(1.0) / (nv * 4.0);
    let kk = k * ks;
    let base = d * gl * gv * f.reflectance * k; // the lobe with ks = 1
    let value = base * ks;
    let d_nl = kk * gv * f.reflectance * (dd_nh * dnh_dnl * gl + d * dgl_c);
    let d_lv = kk * gl * gv * (dd_nh * dnh_dlv * f.reflectance + d * f.d_cos * dlh_dlv);
    let d_alpha = kk * f.reflectance * (dd_a * gl * gv + d * dgl_a * gv + d * gl * dgv_a);
    let d_eta = kk * d * gl * gv * f.d_eta;
    let lit = |v: T| T::select(dark, zero, v);
    LobeEval {
        value: lit(value),
        d_nl: lit(d_nl),
        d_lv: lit(d_lv),
        d_ks: lit(base),
        d_alpha: lit(d_alpha),
        d_eta: lit(d_eta),
    }
}

/// The value of [`lobe`] alone, without derivatives (the renderer's inner loop).
pub(crate) fn lobe_value(nl: f64, nv: f64, lv: f64, ks: f64, alpha: f64, eta: f64) -> f64 {
    if nl <= 0.0 || nv <= 0.0 || lv <= -1.0 + 1e-12 {
        return 0.0;
    }
    let nh = ((nl + nv) / (2.0 + 2.0 * lv).sqrt()).min(1.0);
    let lh = (0.5 * (1.0 + lv)).sqrt();
    let a2 = alpha * alpha;
    let q = nh * nh * (a2 - 1.0) + 1.0;
    let d = a2 / (PI * q * q);
    let g1 = |c: f64| 2.0 * c / (c + (a2 + (1.0 - a2) * c * c).sqrt());
    ks * d * g1(nl) * g1(nv) * fresnel::reflectance(lh, eta) / (4.0 * nv)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lobe_value_equals_lobe() {
        for &(nl, nv, lv) in &[
            (0.9, 0.8, 0.5),
            (0.2, 0.95, -0.3),
            (0.6, 0.1, 0.2),
            (1.0, 1.0, 1.0),
        ] {
            for &alpha in &[0.02, 0.1, 0.7] {
                let a = lobe(nl, nv, lv, 1.3, alpha, 1.45).value;
                let b = lobe_value(nl, nv, lv, 1.3, alpha, 1.45);
                assert!((a - b).abs() <= 1e-12 * a.abs().max(1.0), "{a} {b}");
            }
        }
        assert_eq!(lobe_value(-0.1, 0.5, 0.0, 1.0, 0.1, 1.5), 0.0);
    }

    /// ∫ D(h) (n·h) dω_h = 1 over the hemisphere: the normalisation of a microfacet distribution.
    #[test]
    fn ggx_is_normalised() {
        for &alpha in &[0.05, 0.2, 0.6, 1.0] {
            let n = 200_000;
            let mut acc = 0.0;
            // Substitute u = cos²θ... integrate in μ = cos θ on [0, 1] with midpoint rule in
            // t where μ = 1 − t², which clusters nodes at the peak μ → 1.
            for i in 0..n {
                let t = (i as f64 + 0.5) / n as f64;
                let mu = 1.0 - t * t;
                let dmu = 2.0 * t / n as f64;
                acc += 2.0 * PI * ggx_d(mu, alpha).0 * mu * dmu;
            }
            assert!((acc - 1.0).abs() < 1e-4, "alpha {alpha}: {acc}");
        }
    }
}
