//! The rough dielectric boundary of the physically based renderer ([`super::volpath`]): GGX
//! microfacets with separable Smith masking (Walter et al. 2007, "Microfacet models for
//! refraction through rough surfaces"), outside index 1, inside index η. docs/pbr.md gives the
//! formulas; this file is their code.
//!
//! Directions point away from the surface point (the convention of the whole project). `wo` is
//! the direction toward where the path came from (the camera side), `wi` toward where the light
//! comes from; `n` is the sphere's outward normal. The transmission part is the radiance BTDF:
//! it carries Walter's η_o² factor, so radiance inside the medium is η² times the radiance that
//! entered, and a path that enters and leaves gets both factors, which cancel.

use crate::model::fresnel;
use crate::model::specular::{ggx_d, smith_g1};
use nalgebra::Vector3;
use std::f64::consts::PI;

/// A rough dielectric boundary: inside index η (outside 1), GGX roughness α.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Boundary {
    pub eta: f64,
    pub alpha: f64,
}

/// A direction sampled from the boundary's BSDF.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    pub wi: Vector3<f64>,
    /// f · |n·wi| / pdf.
    pub weight: f64,
    /// Whether `wi` lies on the other side of the boundary than `wo`.
    pub transmitted: bool,
}

/// An orthonormal frame (t, b, n) around a unit vector n (Duff et al. 2017).
pub fn frame(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let s = 1f64.copysign(n.z);
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    (
        Vector3::new(1.0 + s * n.x * n.x * a, s * b, -s * n.x),
        Vector3::new(b, s + n.y * n.y * a, -n.y),
    )
}

/// Smith's G1 of a direction w for the microfacet normal h (zero when w sees the back of h).
fn g1(w: &Vector3<f64>, h: &Vector3<f64>, n: &Vector3<f64>, alpha: f64) -> f64 {
    let (wn, wh) = (w.dot(n), w.dot(h));
    if wn * wh <= 0.0 {
        return 0.0;
    }
    smith_g1(wn.abs(), alpha).0
}

impl Boundary {
    /// Index of refraction on the side of `w`.
    fn index(&self, w: &Vector3<f64>, n: &Vector3<f64>) -> f64 {
        if w.dot(n) > 0.0 {
            1.0
        } else {
            self.eta
        }
    }

    /// The BSDF f(wi, wo) (reflection when both lie on one side, transmission otherwise).
    pub fn eval(&self, wi: &Vector3<f64>, wo: &Vector3<f64>, n: &Vector3<f64>) -> f64 {
        let (ci, co) = (wi.dot(n), wo.dot(n));
        if ci == 0.0 || co == 0.0 {
            return 0.0;
        }
        let (eta_i, eta_o) = (self.index(wi, n), self.index(wo, n));
        if ci * co > 0.0 {
            let mut h = (wi + wo).normalize();
            if h.dot(n) < 0.0 {
                h = -h;
            }
            // Both on one side: the index across is the other side's.
            let across = if co > 0.0 { self.eta } else { 1.0 / self.eta };
            let f = fresnel::reflectance(wo.dot(&h).abs(), across);
            let g = g1(wi, &h, n, self.alpha) * g1(wo, &h, n, self.alpha);
            return f * ggx_d(h.dot(n), self.alpha).0 * g / (4.0 * ci.abs() * co.abs());
        }
        let Some(mut h) = (-(wi * eta_i + wo * eta_o)).try_normalize(1e-12) else {
            return 0.0;
        };
        if h.dot(n) < 0.0 {
            h = -h;
        }
        let (ih, oh) = (wi.dot(&h), wo.dot(&h));
        // A refraction pair lies on opposite sides of its microfacet.
        if ih * oh >= 0.0 {
            return 0.0;
        }
        let g = g1(wi, &h, n, self.alpha) * g1(wo, &h, n, self.alpha);
        if g == 0.0 {
            return 0.0;
        }
        let t = 1.0 - fresnel::reflectance(ih.abs(), eta_o / eta_i);
        let den = eta_i * ih + eta_o * oh;
        ih.abs() * oh.abs() * eta_o * eta_o * t * ggx_d(h.dot(n), self.alpha).0 * g
            / (ci.abs() * co.abs() * den * den)
    }

    /// Sample wi for a given wo: a microfacet normal from the distribution of visible normals
    /// (Heitz 2018), then reflection with probability F or refraction. `u`: three uniforms.
    pub fn sample(&self, wo: &Vector3<f64>, n: &Vector3<f64>, u: [f64; 3]) -> Sample {
        let none = Sample {
            wi: *n,
            weight: 0.0,
            transmitted: false,
        };
        let co = wo.dot(n);
        if co == 0.0 {
            return none;
        }
        // Work on wo's side: n' = ±n with n'·wo > 0.
        let ns = if co > 0.0 { *n } else { -n };
        let (t, b) = frame(&ns);
        let a = self.alpha;
        let v = Vector3::new(wo.dot(&t), wo.dot(&b), wo.dot(&ns));
        let vh = Vector3::new(a * v.x, a * v.y, v.z).normalize();
        let len2 = vh.x * vh.x + vh.y * vh.y;
        let t1 = if len2 > 0.0 {
            Vector3::new(-vh.y, vh.x, 0.0) / len2.sqrt()
        } else {
            Vector3::x()
        };
        let t2 = vh.cross(&t1);
        let r = u[0].sqrt();
        let phi = 2.0 * PI * u[1];
        let p1 = r * phi.cos();
        let s = 0.5 * (1.0 + vh.z);
        let p2 = (1.0 - s) * (1.0 - p1 * p1).sqrt() + s * r * phi.sin();
        let nh = t1 * p1 + t2 * p2 + vh * (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
        let hl = Vector3::new(a * nh.x, a * nh.y, nh.z.max(1e-12)).normalize();
        let h = t * hl.x + b * hl.y + ns * hl.z;
        let (eta_o, eta_t) = if co > 0.0 {
            (1.0, self.eta)
        } else {
            (self.eta, 1.0)
        };
        let oh = wo.dot(&h);
        if oh <= 0.0 {
            return none;
        }
        let f = fresnel::reflectance(oh, eta_t / eta_o);
        if u[2] < f {
            let wi = h * (2.0 * oh) - wo;
            if wi.dot(&ns) <= 0.0 {
                return none;
            }
            return Sample {
                wi,
                weight: g1(&wi, &h, &ns, a),
                transmitted: false,
            };
        }
        let e = eta_o / eta_t;
        let sin2 = e * e * (1.0 - oh * oh);
        if sin2 >= 1.0 {
            return none; // total internal reflection: F = 1, never reached
        }
        let wi = h * (e * oh - (1.0 - sin2).sqrt()) - wo * e;
        if wi.dot(&ns) >= 0.0 {
            return none;
        }
        Sample {
            wi,
            weight: e * e * g1(&wi, &h, &ns, a),
            transmitted: true,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn dir(theta: f64, phi: f64) -> Vector3<f64> {
        Vector3::new(
            theta.sin() * phi.cos(),
            theta.sin() * phi.sin(),
            theta.cos(),
        )
    }

    /// The sampler's mean weight of any test function equals the integral of f·|cos|·g over the
    /// sphere computed by uniform sampling: the sampler and eval describe one BSDF.
    #[test]
    fn sampling_matches_evaluation() {
        let n = Vector3::z();
        for (eta, alpha, theta_o) in [(1.5, 0.3, 0.4), (1.62, 0.1, 1.1), (1.4, 0.5, 2.5)] {
            let b = Boundary { eta, alpha };
            let wo = dir(theta_o, 0.3);
            let mut rng = ChaCha8Rng::seed_from_u64(7);
            // Test function: 1 + wi.x (tests both the albedo and the direction).
            let g = |w: &Vector3<f64>| 1.0 + w.x;
            let m = 400_000;
            let (mut s_refl, mut s_tr) = (0.0, 0.0);
            for _ in 0..m {
                let s = b.sample(&wo, &n, [rng.random(), rng.random(), rng.random()]);
                if s.transmitted {
                    s_tr += s.weight * g(&s.wi);
                } else {
                    s_refl += s.weight * g(&s.wi);
                }
            }
            let (mut q_refl, mut q_tr) = (0.0, 0.0);
            for _ in 0..m {
                let z: f64 = 2.0 * rng.random::<f64>() - 1.0;
                let ph: f64 = 2.0 * PI * rng.random::<f64>();
                let w = dir(z.acos(), ph);
                let v = b.eval(&w, &wo, &n) * w.z.abs() * g(&w) * 4.0 * PI;
                if w.z * wo.z > 0.0 {
                    q_refl += v;
                } else {
                    q_tr += v;
                }
            }
            let mm = m as f64;
            let (sr, st, qr, qt) = (s_refl / mm, s_tr / mm, q_refl / mm, q_tr / mm);
            assert!(
                (sr - qr).abs() < 0.03 * qr.max(0.02),
                "η {eta} α {alpha}: refl {sr} vs {qr}"
            );
            assert!(
                (st - qt).abs() < 0.03 * qt.max(0.02),
                "η {eta} α {alpha}: trans {st} vs {qt}"
            );
        }
    }

    /// Reciprocity of the radiance BTDF: f(wi, wo)/η_o² = f(wo, wi)/η_i²; reflection symmetric.
    #[test]
    fn btdf_reciprocity() {
        let b = Boundary {
            eta: 1.5,
            alpha: 0.2,
        };
        let n = Vector3::z();
        let out = dir(0.5, 0.2);
        let inside = dir(2.6, 3.0);
        let a = b.eval(&out, &inside, &n) / (1.5 * 1.5);
        let c = b.eval(&inside, &out, &n);
        assert!(a > 0.0 && (a - c).abs() < 1e-12 * c, "{a} {c}");
        let r1 = b.eval(&dir(0.3, 0.0), &dir(0.7, 2.0), &n);
        let r2 = b.eval(&dir(0.7, 2.0), &dir(0.3, 0.0), &n);
        assert!((r1 - r2).abs() < 1e-12 * r1);
    }

    /// As α → 0 the boundary is smooth: the transmitted energy from outside is 1 − F at the
    /// incidence angle (radiance weight η² · (1 − F) · 1/η² of the sampled refraction).
    #[test]
    fn smooth_limit_is_fresnel() {
        let b = Boundary {
            eta: 1.5,
            alpha: 0.002,
        };
        let n = Vector3::z();
        let wo = dir(0.6, 0.0);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let m = 200_000;
        let mut tr = 0.0;
        for _ in 0..m {
            let s = b.sample(&wo, &n, [rng.random(), rng.random(), rng.random()]);
            if s.transmitted {
                tr += s.weight;
            }
        }
        let want = (1.0 - fresnel::reflectance(0.6f64.cos(), 1.5)) / (1.5 * 1.5);
        assert!(
            (tr / m as f64 - want).abs() < 0.005 * want,
            "{} {want}",
            tr / m as f64
        );
    }
}
