//! The residuals' wave: a fit's residuals averaged over bands of θ, each band's mean against its
//! own noise (docs/uncertainty.md, "The residuals' wave").
//!
//! A pixel's residual over its noise says whether the model misses that pixel by more than the
//! noise; on noisy photos (a Monte Carlo render's 3–4% per pixel) a model that misses the shading
//! by 1% everywhere passes that test, and yet every parameter the shape sets is biased, because
//! the fit averages thousands of pixels. The band means average the same pixels the fit does: in
//! each band of [`BAND_DEG`] of θ, per sphere and channel, the residuals' sum over √n is one
//! standard normal deviate when the model describes the photos and the noise is measured right.
//! Their RMS over the bands is the wave over its noise: about 1 for a model that describes the
//! photos, and the factor by which a fit's formal errors understate what the shading's shape
//! leaves unexplained when above.

use std::collections::HashMap;

/// The bands' width in θ.
pub const BAND_DEG: f64 = 5.0;
/// A band needs this many residuals to count (its mean's noise is then near Gaussian).
pub const MIN_BAND: usize = 20;

/// The wave over its noise and where it is the largest.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wave {
    /// √(mean z²) over the bands, z a band's residual sum over √n (NaN without a band).
    pub over_noise: f64,
    /// Bands counted.
    pub bands: usize,
    /// The centre of the band of largest |z| (degrees), and its z.
    pub worst_theta_deg: f64,
    pub worst_z: f64,
}

/// The wave of residuals given as (group, θ in radians, residual over its noise): a group is
/// one sphere's channel (any key that keeps them apart).
pub fn wave(rows: impl IntoIterator<Item = (usize, f64, f64)>) -> Wave {
    let mut bands: HashMap<(usize, i64), (f64, usize)> = HashMap::new();
    for (group, theta, r) in rows {
        if !(r.is_finite() && theta.is_finite()) {
            continue;
        }
        let band = (theta.to_degrees() / BAND_DEG).floor() as i64;
        let e = bands.entry((group, band)).or_insert((0.0, 0));
        e.0 += r;
        e.1 += 1;
    }
    let (mut sum_z2, mut counted) = (0.0, 0usize);
    let (mut worst_theta_deg, mut worst_z) = (f64::NAN, 0.0f64);
    for ((_, band), (sum, n)) in bands {
        if n < MIN_BAND {
            continue;
        }
        let z = sum / (n as f64).sqrt();
        sum_z2 += z * z;
        counted += 1;
        if z.abs() > worst_z.abs() {
            worst_z = z;
            worst_theta_deg = (band as f64 + 0.5) * BAND_DEG;
        }
    }
    Wave {
        over_noise: if counted > 0 {
            (sum_z2 / counted as f64).sqrt()
        } else {
            f64::NAN
        },
        bands: counted,
        worst_theta_deg,
        worst_z,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    /// Residuals of a standard normal over θ 0–120°, four groups.
    fn rows(offset: impl Fn(f64) -> f64) -> Vec<(usize, f64, f64)> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        (0..200_000)
            .map(|k| {
                let theta = (120.0 * (k as f64 + 0.5) / 200_000.0f64).to_radians();
                let g: f64 = StandardNormal.sample(&mut rng);
                (k % 4, theta, g + offset(theta))
            })
            .collect()
    }

    /// Pure noise: the wave is 1 (96 bands; its std is about 1/√(2·96) = 0.07), asserted within
    /// 0.2.
    #[test]
    fn noise_alone_is_one() {
        let w = wave(rows(|_| 0.0));
        assert_eq!(w.bands, 96);
        assert!((w.over_noise - 1.0).abs() < 0.2, "{w:?}");
    }

    /// A systematic of 0.1 σ per pixel over θ 60–70°, where each band holds about 2083 of
    /// a group's pixels: those 8 bands' z is about 0.1·√2083 = 4.6, so the wave is
    /// √((88 + 8·(1 + 4.6²))/96) ≈ 1.66, and the worst band lies in 60–70°.
    #[test]
    fn a_systematic_below_the_noise_shows() {
        let w = wave(rows(|t| {
            if (60f64.to_radians()..70f64.to_radians()).contains(&t) {
                0.1
            } else {
                0.0
            }
        }));
        let n = 200_000.0 / 4.0 / 24.0;
        let z = 0.1 * f64::sqrt(n);
        let expected = ((88.0 + 8.0 * (1.0 + z * z)) / 96.0).sqrt();
        assert!(
            (w.over_noise - expected).abs() < 0.15,
            "{w:?} vs {expected}"
        );
        assert!((60.0..70.0).contains(&w.worst_theta_deg), "{w:?}");
    }

    /// Too few residuals in a band: not counted.
    #[test]
    fn thin_bands_are_left_out() {
        let w = wave((0..19).map(|k| (0, 0.1, k as f64)));
        assert_eq!(w.bands, 0);
        assert!(w.over_noise.is_nan());
    }
}
