//! The sphere's surface as the light crosses it: smooth (Fresnel) or rough (GGX microfacets, the
//! renderers' rough dielectric), seen as the diffusion model needs it (docs/medium.md, "The rough
//! boundary in the model").
//!
//! Two numbers per direction. Entering: the fraction of the light arriving at cos μ from outside
//! that is transmitted, T(μ). Leaving: by reciprocity the radiance that leaves at μ from a
//! diffuse interior is proportional to the same T(μ), so the exitance M spreads over the outside
//! hemisphere as the law L/M = T(μ)/(π c), with c = ∫₀¹ T(μ) 2μ dμ so that ∫ L μ dΩ = M, tilted
//! toward grazing exits as the photon tally measures ([`exit_tilt`]).
//!
//! A rough boundary's T_α(μ) is the single-scattering microfacet transmission (Walter et al.
//! 2007): over the normals m visible from the direction o, D_o(m) = G1(o) ⟨o·m⟩ D(m)/μ, the light
//! refracts through m with 1 − F(o·m) and is masked on its way in by G1 of the refracted
//! direction. The renderer (src/synth/dielectric.rs) samples the same boundary; here it is
//! integrated by quadrature, with tan²θ_m = α² ξ/(1 − ξ), which makes D(m) cos θ_m dω uniform in
//! ξ and the azimuth.
//!
//! Against the photon tally with the renders' GGX boundary, the model's entry through T_α holds
//! the light near the terminator that Fresnel's T loses (docs/medium.md, "The rough boundary in
//! the model").

use crate::model::exit_tilt::{self, Tilt};
use crate::model::fresnel;
use crate::model::quadrature::nodes;
use crate::model::rough_level;
use crate::model::specular::smith_g1;
use std::f64::consts::PI;

/// Below this roughness the boundary is taken as smooth.
pub const SMOOTH_ALPHA: f64 = 1e-3;

/// μ nodes of a rough boundary's table: T_α at μ = (k/N)², denser toward grazing.
const TABLE: usize = 64;

/// A boundary of inside index η (outside 1) and GGX roughness α (0: smooth).
#[derive(Clone, Debug, PartialEq)]
pub struct Boundary {
    pub eta: f64,
    pub alpha: f64,
    /// T_α at μ = (k/TABLE)², k = 0..=TABLE (empty when smooth).
    table: Vec<f64>,
    /// The transmitted light's mean direction's sine from the inward normal at the same μ.
    sines: Vec<f64>,
    /// c = ∫₀¹ T(μ) 2μ dμ.
    hemispherical: f64,
    /// μ̄ = ∫₀¹ T(μ) 2μ² dμ / c.
    mean_cosine: f64,
}

impl Boundary {
    /// A smooth boundary (Fresnel's T).
    pub fn smooth(eta: f64) -> Boundary {
        Self::rough(eta, 0.0)
    }

    /// A GGX-rough boundary of roughness `alpha` (smooth below 1e-3).
    pub fn rough(eta: f64, alpha: f64) -> Boundary {
        let mut b = Boundary {
            eta,
            alpha,
            table: Vec::new(),
            sines: Vec::new(),
            hemispherical: 1.0,
            mean_cosine: 0.5,
        };
        if alpha >= SMOOTH_ALPHA {
            let rows: Vec<(f64, f64)> = (0..=TABLE)
                .map(|k| {
                    let u = k as f64 / TABLE as f64;
                    microfacet_transmission(u * u, eta, alpha)
                })
                .collect();
            b.table = rows.iter().map(|r| r.0).collect();
            b.sines = rows.iter().map(|r| r.1).collect();
        }
        // ∫₀¹ T 2μ dμ in s = √μ: ∫₀¹ T(s²) 4s³ ds, on 16 panels; μ̄ likewise.
        let moments = (0..16)
            .flat_map(|p| nodes(p as f64 / 16.0, (p + 1) as f64 / 16.0))
            .map(|(s, w)| {
                let t = w * b.transmission(s * s) * 4.0 * s * s * s;
                (t, t * s * s)
            })
            .fold((0.0, 0.0), |(a, b), (x, y)| (a + x, b + y));
        b.hemispherical = moments.0;
        b.mean_cosine = moments.1 / moments.0;
        b
    }

    /// Whether the boundary is smooth.
    pub fn is_smooth(&self) -> bool {
        self.table.is_empty()
    }

    /// The fraction of light arriving from outside at cos μ that enters.
    pub fn transmission(&self, mu: f64) -> f64 {
        if self.is_smooth() {
            return fresnel::transmission(mu, self.eta);
        }
        at(&self.table, mu)
    }

    /// The sine of the angle from the inward normal of the light that enters at cos μ: Snell's
    /// √(1 − μ²)/η through a smooth boundary; through a rough one, that of the transmitted
    /// light's mean direction over the microfacets. Toward grazing it is shallower than Snell's,
    /// past the critical angle (0.826 against 0.691 at μ 0.1, α 0.15, η 1.44): the facets that
    /// face a grazing light bend it less. The diffusion's beams follow it (docs/medium.md, "The
    /// beams along the transmitted light's mean direction").
    pub fn refracted_sine(&self, mu: f64) -> f64 {
        let mu = mu.clamp(0.0, 1.0);
        if self.is_smooth() {
            return (1.0 - mu * mu).sqrt() / self.eta;
        }
        at(&self.sines, mu)
    }

    /// c = ∫₀¹ T(μ) 2μ dμ: the fraction of diffuse light from outside that enters.
    pub fn hemispherical(&self) -> f64 {
        self.hemispherical
    }

    /// μ̄ = ∫₀¹ T(μ) 2μ² dμ / c: the exit-weighted mean cosine the law's tilt turns about.
    pub fn mean_cosine(&self) -> f64 {
        self.mean_cosine
    }

    /// The factor the rough boundary's losses put on the exitance of a medium of reduced albedo
    /// `reduced_albedo` on a sphere of optical radius `sigma_t_radius` (σt′R): the photon
    /// tally's, [`rough_level::factor`]; 1 when smooth.
    pub fn level(&self, reduced_albedo: f64, sigma_t_radius: f64) -> f64 {
        if self.is_smooth() {
            return 1.0;
        }
        rough_level::factor(reduced_albedo, self.eta, self.alpha, sigma_t_radius)
    }

    /// The exit law's tilt K for a medium of reduced albedo `reduced_albedo` behind this
    /// boundary ([`exit_tilt::tilt`]), with its derivatives.
    pub fn tilt(&self, reduced_albedo: f64) -> Tilt {
        exit_tilt::tilt(reduced_albedo, self.eta, self.alpha)
    }

    /// The radiance leaving at cos μ per unit exitance, T(μ)/(π c) · (1 + K (μ̄ − μ)) (1/sr),
    /// for a medium of reduced albedo `reduced_albedo` ([`exit_tilt`]).
    pub fn exit_law(&self, mu: f64, reduced_albedo: f64) -> f64 {
        self.exit_law_with_slope(mu, self.tilt(reduced_albedo).k).0
    }

    /// The law at cos μ under the tilt `k`, and its derivative in `k`.
    pub fn exit_law_with_slope(&self, mu: f64, k: f64) -> (f64, f64) {
        let untilted = self.transmission(mu) / (PI * self.hemispherical);
        let lean = untilted * (self.mean_cosine - mu);
        (untilted + k * lean, lean)
    }
}

/// A rough boundary's table (at μ = (k/TABLE)²) at cos μ, linear in √μ.
fn at(table: &[f64], mu: f64) -> f64 {
    let x = mu.clamp(0.0, 1.0).sqrt() * TABLE as f64;
    let (i, f) = ((x.floor() as usize).min(TABLE - 1), x - x.floor());
    table[i] * (1.0 - f.min(1.0)) + table[i + 1] * f.min(1.0)
}

/// T_α(μ): light arriving from outside at cos μ through GGX microfacets of roughness α, 24 × 32
/// nodes over (v, azimuth) with ξ = 1 − v² (converged to 1e-5: 48 × 64 nodes move it by less);
/// and the sine of the transmitted light's mean direction from the inward normal.
fn microfacet_transmission(mu: f64, eta: f64, alpha: f64) -> (f64, f64) {
    if mu <= 0.0 {
        // Nothing enters at grazing; the direction is the limit's.
        return (0.0, microfacet_transmission(1e-9, eta, alpha).1);
    }
    let o = [(1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu];
    let g1_o = smith_g1(mu, alpha).0;
    let mut sum = 0.0;
    let mut mean = [0.0; 3];
    // ξ = 1 − v²: the visible weight grows as tan θ_m ∝ (1 − ξ)^{−1/2} toward ξ = 1, which the
    // substitution makes smooth.
    for (v, wv) in (0..3).flat_map(|p| nodes(p as f64 / 3.0, (p + 1) as f64 / 3.0)) {
        let (xi, wx) = (1.0 - v * v, 2.0 * v * wv);
        let tan2 = alpha * alpha * xi / (1.0 - xi);
        let cos_m = 1.0 / (1.0 + tan2).sqrt();
        let sin_m = (1.0 - cos_m * cos_m).sqrt();
        for (phi, wp) in (0..4).flat_map(|p| nodes(p as f64 * PI / 2.0, (p + 1) as f64 * PI / 2.0))
        {
            let m = [sin_m * phi.cos(), sin_m * phi.sin(), cos_m];
            let c = o[0] * m[0] + o[2] * m[2];
            if c <= 0.0 {
                continue;
            }
            let sin_t2 = (1.0 - c * c) / (eta * eta);
            if sin_t2 >= 1.0 {
                continue;
            }
            let cos_t = (1.0 - sin_t2).sqrt();
            // The refracted direction, into the medium: −o/η + (c/η − cos_t) m.
            let k = c / eta - cos_t;
            let t = [-o[0] / eta + k * m[0], k * m[1], -o[2] / eta + k * m[2]];
            if t[2] >= 0.0 {
                continue;
            }
            let g1_t = smith_g1(-t[2], alpha).0;
            let visible = g1_o * c / (mu * cos_m);
            let w = wx * wp / (2.0 * PI) * visible * (1.0 - fresnel::reflectance(c, eta)) * g1_t;
            sum += w;
            (0..3).for_each(|k| mean[k] += w * t[k]);
        }
    }
    let norm = (mean[0] * mean[0] + mean[1] * mean[1] + mean[2] * mean[2]).sqrt();
    (sum, if norm > 0.0 { -mean[0] / norm } else { 0.0 })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The smooth boundary's c against ∫T 2μ dμ by a plain midpoint sum; a nearly smooth rough
    /// one against Fresnel; and a rough one's T_α against the renderer's own sampled boundary
    /// (src/synth/dielectric.rs is independent code: visible normals drawn at random).
    #[test]
    fn the_rough_transmission_matches_fresnel_and_the_sampled_boundary() {
        let eta = 1.44;
        let k = 200_000;
        let c: f64 = (0..k)
            .map(|i| {
                let mu = (i as f64 + 0.5) / k as f64;
                fresnel::transmission(mu, eta) * 2.0 * mu / k as f64
            })
            .sum();
        let s = Boundary::smooth(eta);
        assert!(
            (s.hemispherical() - c).abs() < 1e-6,
            "{} {c}",
            s.hemispherical()
        );
        let nearly = Boundary::rough(eta, 2e-3);
        for mu in [0.2, 0.5, 0.9] {
            let (a, b) = (nearly.transmission(mu), fresnel::transmission(mu, eta));
            let snell = (1.0 - mu * mu).sqrt() / eta;
            assert!((nearly.refracted_sine(mu) - snell).abs() < 2e-3, "μ {mu}");
            assert!((a - b).abs() < 2e-3, "μ {mu}: {a} vs {b}");
        }
    }
}
