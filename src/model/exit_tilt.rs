//! The exit law's tilt toward grazing exits, as the photon tally measures it (docs/medium.md,
//! "The exit's tilt with the surface's reflection in the model").
//!
//! Diffusion's interior radiance is nearly isotropic, so the light it sends out spreads as the
//! boundary's transmission T(μ) alone. The tally's light leans toward grazing exits more than
//! that, the more so the fewer times it scattered (a low albedo) and the lower the index:
//! its radiance per unit exitance over T(μ)/(π c) falls about linearly in the exit cosine μ,
//! with a slope K from 0.01 (albedo 0.995) to 0.34 (albedo 0.6, η 1.3). The exit law is
//! multiplied by 1 + K (μ̄ − μ) ([`crate::model::boundary::Boundary::exit_law`]), and K is the
//! least-squares law through the tally's slopes on 324 spheres (radius and σt 15 mm and 0.5, 25
//! and 1, 35 and 3 /mm; η 1.3, 1.45, 1.6; GGX α 0.05–0.25; albedo 0.6–0.995; a million
//! photons each): K = s (k₀ + k₁ s + k₂ (η − 1.45) + k₃ (α − 0.1)), s = √(1 − α′), rms 0.0125
//! about the slopes where a constant leaves 0.083
//! (`medium::rough_level_and_exit_tilt_against_the_photon_tally` prints it).

/// k₀ … k₃ of the law, from the tally's million photons a sphere.
pub const COEFFICIENTS: [f64; 4] = [0.539, -0.312, -0.606, 0.774];

/// The reduced albedo and GGX α the tally covered; the law holds its value at their ends.
pub const ALBEDO_RANGE: (f64, f64) = (0.6, 1.0);
pub const ALPHA_RANGE: (f64, f64) = (0.05, 0.25);

/// K and its derivatives in the fit's coordinates: y = ln(1 − α′), η and ln α.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Tilt {
    pub k: f64,
    pub d_y: f64,
    pub d_eta: f64,
    pub d_ln_alpha: f64,
}

/// K for a medium of reduced albedo `reduced_albedo` behind a boundary of index `eta` and GGX
/// roughness `alpha` (a smooth boundary, α 0, takes the tally's smoothest, 0.05).
pub fn tilt(reduced_albedo: f64, eta: f64, alpha: f64) -> Tilt {
    let [k0, k1, k2, k3] = COEFFICIENTS;
    let albedo = reduced_albedo.clamp(ALBEDO_RANGE.0, ALBEDO_RANGE.1);
    let a = alpha.clamp(ALPHA_RANGE.0, ALPHA_RANGE.1);
    let s = (1.0 - albedo).sqrt();
    let inner = k0 + k1 * s + k2 * (eta - 1.45) + k3 * (a - 0.1);
    // ds/dy = s/2 with y = ln(1 − α′) = 2 ln s; zero where the albedo is held at its end.
    let ds_dy = if albedo == reduced_albedo {
        s / 2.0
    } else {
        0.0
    };
    let da_dln = if a == alpha { alpha } else { 0.0 };
    Tilt {
        k: s * inner,
        d_y: (inner + k1 * s) * ds_dy,
        d_eta: s * k2,
        d_ln_alpha: s * k3 * da_dln,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each derivative against central differences in its own coordinate, inside the ranges.
    #[test]
    fn the_derivatives_follow_central_differences() {
        let h = 1e-6;
        for &(albedo, eta, alpha) in &[(0.75, 1.3, 0.1), (0.97, 1.62, 0.06), (0.9, 1.45, 0.2)] {
            let t = tilt(albedo, eta, alpha);
            let y = (1.0 - albedo).ln();
            let at_y = |y: f64| tilt(1.0 - y.exp(), eta, alpha).k;
            let d_y = (at_y(y + h) - at_y(y - h)) / (2.0 * h);
            let d_eta =
                (tilt(albedo, eta + h, alpha).k - tilt(albedo, eta - h, alpha).k) / (2.0 * h);
            let at_ln = |l: f64| tilt(albedo, eta, l.exp()).k;
            let l = alpha.ln();
            let d_ln = (at_ln(l + h) - at_ln(l - h)) / (2.0 * h);
            for (a, b) in [(t.d_y, d_y), (t.d_eta, d_eta), (t.d_ln_alpha, d_ln)] {
                assert!(
                    (a - b).abs() < 1e-8,
                    "{a} against {b} at {albedo}, {eta}, {alpha}"
                );
            }
        }
    }

    /// The law against the tally's slopes it was fitted to, by hand from its table in
    /// docs/medium.md ("The rough level and the exit's tilt over the range"): albedo 0.7
    /// at η 1.3 lies in 0.25–0.32, albedo 0.995 at η 1.6 in 0.02–0.05 (α 0.1, where the
    /// tally's ranges span the sizes and roughnesses).
    #[test]
    fn the_law_lies_in_the_tallys_ranges() {
        let dark = tilt(0.7, 1.3, 0.1).k;
        assert!((0.25..=0.32).contains(&dark), "{dark}");
        let white = tilt(0.995, 1.6, 0.1).k;
        assert!((0.02..=0.05).contains(&white), "{white}");
    }
}
