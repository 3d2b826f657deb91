//! Exact unpolarised dielectric Fresnel reflectance, from air into a medium of index η > 1.
//!
//!     cos θt = sqrt(1 − sin²θi / η²)
//!     rs = (cos θi − η cos θt) / (cos θi + η cos θt)
//!     rp = (η cos θi − cos θt) / (η cos θi + cos θt)
//!     F = (rs² + rp²) / 2,   T = 1 − F
//!
//! By reciprocity the same T applies to light leaving the medium at the outside angle θi.

use crate::model::lanes::Real;

/// F with its derivatives with respect to cos θi and η (on one pixel or four, [`Real`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FresnelEval<T = f64> {
    pub reflectance: T,
    pub d_cos: T,
    pub d_eta: T,
}

impl<T: Real> FresnelEval<T> {
    /// Transmission T = 1 − F.
    pub fn transmission(&self) -> T {
        -self.reflectance + 1.0
    }
}

/// Fresnel reflectance for cos θi in [0, 1] (clamped) and η ≥ 1.
#[inline(always)]
pub fn eval<T: Real>(cos_i: T, eta: f64) -> FresnelEval<T> {
    let ci = cos_i.max(0.0).min(1.0);
    let si2 = -(ci * ci) + 1.0;
    let ct2 = -(si2 / (eta * eta)) + 1.0;
    // Grazing incidence onto an index-matched medium: the limit is total reflection.
    let total = ct2.le(0.0) | (ci.eq(0.0) & T::mask(eta <= 1.0));
    let reflected = FresnelEval {
        reflectance: T::splat(1.0),
        d_cos: T::splat(0.0),
        d_eta: T::splat(0.0),
    };
    if T::all(total) {
        return reflected;
    }
    let ct = ct2.sqrt();
    let e2ct = T::splat(1.0) / (ct * (eta * eta));
    let dct_dci = ci * e2ct;
    let dct_deta = si2 * e2ct / eta;
    // r = (a − b)/(a + b): dr = 2 (b da − a db) / (a + b)², one division per ratio.
    // rs: a = ci, b = η ct; rp: a = η ci, b = ct.
    let (a_s, b_s) = (ci, ct * eta);
    let (a_p, b_p) = (ci * eta, ct);
    let (inv_s, inv_p) = (T::splat(1.0) / (a_s + b_s), T::splat(1.0) / (a_p + b_p));
    let (rs, rp) = ((a_s - b_s) * inv_s, (a_p - b_p) * inv_p);
    let (ks, kp) = (inv_s * 2.0 * inv_s, inv_p * 2.0 * inv_p);
    let drs_dci = ks * (b_s - a_s * eta * dct_dci);
    let drs_deta = -ks * a_s * (ct + dct_deta * eta);
    let drp_dci = kp * (b_p * eta - a_p * dct_dci);
    let drp_deta = kp * (b_p * ci - a_p * dct_deta);
    let pick = |v: T, r: T| T::select(total, r, v);
    FresnelEval {
        reflectance: pick((rs * rs + rp * rp) * 0.5, reflected.reflectance),
        d_cos: pick(rs * drs_dci + rp * drp_dci, reflected.d_cos),
        d_eta: pick(rs * drs_deta + rp * drp_deta, reflected.d_eta),
    }
}

/// Fresnel reflectance alone (no derivatives: the renderer's inner loop).
pub fn reflectance(cos_i: f64, eta: f64) -> f64 {
    let ci = cos_i.clamp(0.0, 1.0);
    let ct2 = 1.0 - (1.0 - ci * ci) / (eta * eta);
    if ct2 <= 0.0 || (ci == 0.0 && eta <= 1.0) {
        return 1.0;
    }
    let ct = ct2.sqrt();
    let rs = (ci - eta * ct) / (ci + eta * ct);
    let rp = (eta * ci - ct) / (eta * ci + ct);
    0.5 * (rs * rs + rp * rp)
}

/// Fresnel transmission T = 1 − F.
pub fn transmission(cos_i: f64, eta: f64) -> f64 {
    1.0 - reflectance(cos_i, eta)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_incidence_and_grazing() {
        let eta: f64 = 1.5;
        let f0 = ((eta - 1.0) / (eta + 1.0)).powi(2);
        assert!((reflectance(1.0, eta) - f0).abs() < 1e-15);
        assert!((reflectance(0.0, eta) - 1.0).abs() < 1e-15);
        assert!(reflectance(0.7, 1.0) < 1e-15);
    }

    #[test]
    fn reflectance_equals_eval() {
        for eta in [1.0, 1.2, 1.5, 2.4] {
            for k in 0..=100 {
                let c = k as f64 / 100.0;
                assert!((reflectance(c, eta) - eval(c, eta).reflectance).abs() < 1e-15);
            }
        }
    }

    #[test]
    fn brewster_angle_zeroes_rp() {
        // At Brewster's angle tan θ = η, rp = 0 and F = rs²/2.
        let eta: f64 = 1.5;
        let th = eta.atan();
        let (ci, si) = (th.cos(), th.sin());
        let ct = (1.0 - si * si / (eta * eta)).sqrt();
        let rs = (ci - eta * ct) / (ci + eta * ct);
        assert!((reflectance(ci, eta) - 0.5 * rs * rs).abs() < 1e-15);
    }
}
