//! A diffusion profile integrated over a sphere's lit surface: what a point of a translucent
//! sphere under one directional light sends out, as Penner's pre-integration does for curvature
//! but over the sphere's own surface instead of a circle (docs/medium.md).
//!
//! Light of irradiance E (on a surface facing it) enters at every point y of the sphere with
//! n_y·l > 0, transmitted by T(n_y·l; η); a profile R(r) carries it to the point x at chord
//! distance r = |x − y|; it leaves toward the camera transmitted by T(n_x·v; η), spread over the
//! hemisphere as 1/π (Jensen et al.'s BSSRDF, S = T(ωᵢ) R(r) T(ωₒ)/π). So the radiance at x is
//!
//! L(x) = E/π · T(n_x·v) · M(θ),  M(θ) = ∫_S R(|x − y|) T(n_y·l) ⟨n_y·l⟩ dA_y,
//!
//! where θ is the angle between n_x and l: by symmetry M depends on nothing else. With y at
//! chord u from x and azimuth ψ around it, dA = u du dψ exactly (a sphere's area between chords
//! u and u + du is 2πu du, as on a plane), and n_y·l = cos θ cos γ + sin θ sin γ cos ψ with
//! cos γ = 1 − u²/(2R²). On a plane (R → ∞) M(θ) = T(cos θ) cos θ · ∫R 2πr dr.

use crate::model::fresnel;
use crate::model::quadrature::{equal_panels, geometric_panels};
use std::f64::consts::PI;

/// M(θ) for a sphere of radius `radius` (mm): `profile` R(r) (1/mm²), `cos_theta` = n_x·l,
/// `reach` the distance (mm) beyond which the profile is negligible and `scale` the distance
/// on which it varies near r = 0 (both from the profile: [`crate::model::dipole::Dipole`]).
pub fn over_sphere(
    profile: impl Fn(f64) -> f64,
    radius: f64,
    cos_theta: f64,
    eta: f64,
    reach: f64,
    scale: f64,
) -> f64 {
    let ct = cos_theta.clamp(-1.0, 1.0);
    let st = (1.0 - ct * ct).sqrt();
    let u_max = (2.0 * radius).min(reach);
    geometric_panels(0.0, u_max, 0.05 * scale.min(radius), |u| {
        let cg = 1.0 - u * u / (2.0 * radius * radius);
        let sg = (1.0 - cg * cg).max(0.0).sqrt();
        profile(u) * u * ring(ct * cg, st * sg, eta)
    })
}

/// ∫₀^{2π} T(c; η) ⟨c⟩ dψ with c = a + b cos ψ: the light entering around a circle of the sphere.
fn ring(a: f64, b: f64, eta: f64) -> f64 {
    let lit = |c: f64| {
        if c > 0.0 {
            c * fresnel::transmission(c, eta)
        } else {
            0.0
        }
    };
    if b < 1e-12 {
        return 2.0 * PI * lit(a);
    }
    // c > 0 where cos ψ > −a/b: all of the circle, none of it, or |ψ| < ψ₀.
    let k = -a / b;
    if k >= 1.0 {
        return 0.0;
    }
    let psi0 = if k <= -1.0 { PI } else { k.acos() };
    2.0 * equal_panels(0.0, psi0, 4, |psi| lit(a + b * psi.cos()))
}

/// The radiance factor L/E at a point whose normal makes cos θ with the light and cos φ with
/// the view: T(cos φ; η)/π · M(θ).
pub fn radiance_factor(m_theta: f64, cos_phi: f64, eta: f64) -> f64 {
    fresnel::transmission(cos_phi, eta) / PI * m_theta
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::dipole::{Dipole, Medium};
    use nalgebra::Vector3;
    use rand::Rng;
    use rand::SeedableRng;

    fn medium() -> Medium {
        Medium {
            sigma_a: 0.05,
            sigma_s_reduced: 1.0,
            eta: 1.44,
        }
    }

    fn m_of(d: &Dipole, radius: f64, theta_deg: f64) -> f64 {
        over_sphere(
            |r| d.profile(r),
            radius,
            theta_deg.to_radians().cos(),
            1.44,
            d.reach(),
            d.z_r,
        )
    }

    /// A sphere a thousand diffusion lengths across is a plane: M(θ) → T(cos θ) cos θ · R_total,
    /// the closed form of [`Dipole::total`] (measured within 4.6e-6).
    #[test]
    fn a_large_sphere_is_a_plane() {
        let d = Dipole::new(&medium());
        for theta in [0.0f64, 30.0, 60.0, 80.0] {
            let c = f64::cos(theta.to_radians());
            let plane = fresnel::transmission(c, 1.44) * c * d.total();
            let m = m_of(&d, 1000.0 / d.sigma_tr, theta);
            println!("plane θ {theta}: {:.3e}", m / plane - 1.0);
            assert!(
                (m / plane - 1.0).abs() < 2e-5,
                "θ {theta}: {m} against {plane}"
            );
        }
    }

    /// Against a brute-force Monte Carlo integral over the sphere (points drawn uniformly on
    /// it, independent of the chord parameterisation): a sphere two diffusion lengths across,
    /// where the light wraps past the terminator. Measured within 2.2 of the Monte Carlo's
    /// standard errors over three seeds.
    #[test]
    fn the_integral_matches_monte_carlo_over_the_sphere() {
        let d = Dipole::new(&medium());
        let radius = 2.0 / d.sigma_tr;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let n = 2_000_000;
        let ys: Vec<Vector3<f64>> = (0..n)
            .map(|_| {
                let z: f64 = rng.random_range(-1.0..1.0);
                let p: f64 = rng.random_range(0.0..2.0 * PI);
                let s = (1.0 - z * z).sqrt();
                Vector3::new(s * p.cos(), s * p.sin(), z)
            })
            .collect();
        for theta in [0.0, 60.0, 100.0] {
            let t = f64::to_radians(theta);
            let x = Vector3::new(t.sin(), 0.0, t.cos());
            let l = Vector3::z();
            let (sum, sum2) = ys.iter().fold((0.0, 0.0), |(s, s2), y| {
                let c = y.dot(&l);
                let v = if c > 0.0 {
                    d.profile(radius * (x - y).norm()) * c * fresnel::transmission(c, 1.44)
                } else {
                    0.0
                };
                (s + v, s2 + v * v)
            });
            let area = 4.0 * PI * radius * radius;
            let mc = area * sum / n as f64;
            let se = area * ((sum2 / n as f64 - (sum / n as f64).powi(2)) / n as f64).sqrt();
            let m = m_of(&d, radius, theta);
            println!("θ {theta}: {m:.6e} against {mc:.6e} ± {se:.1e}");
            assert!(
                (m - mc).abs() < 4.0 * se + 1e-4 * m,
                "θ {theta}: {m} against {mc} ± {se}"
            );
        }
    }
}
