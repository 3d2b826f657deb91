//! A photo's noise, measured per sphere and channel (docs/uncertainty.md, "The pixels' noise").
//!
//! The shading changes little from one pixel to the next, so the differences of horizontally
//! adjacent pixels are noise, with √2 times a pixel's σ. The pairs are binned by level; each
//! bin's variance is the differences' mean square short of an impulse's (a difference beyond
//! [`IMPULSE_SIGMA`] of the bin's robust σ, from the MAD, plus [`IMPULSE_FRACTION`] of the level:
//! an edge, dust, a firefly), and the curve
//!
//! σ²(L) = a + b·L + c·L²
//!
//! is fitted to the bins: a the read noise, b the shot noise, c a noise proportional to the level
//! (a Monte Carlo render's, whose relative noise is the same at every level; a sensor's
//! pixel-to-pixel gain). Each coefficient is at least 0, and the bins are weighted by the inverse
//! variance of their variance, n/(2σ⁴), σ² from the curve (reweighted, starting from the bins'
//! own).
//!
//! Two earlier choices failed on the physically based renders (16-bit, Monte Carlo noise): the
//! curve without c, weighted by each bin's own variance, passed through the darkest bins and put
//! the bright pixels' σ 5–20 times under their scatter; and the MAD alone, for noise whose
//! kurtosis is 10–30 (a Gaussian's is 3), understates its variance by 1.2–2 times.

use crate::stats;

/// A pixel this many noise σ (of its difference from its neighbours' mean) away is an impulse,
/// not noise (an edge, dust, a firefly): a Gaussian deviate goes that far once in 10⁹ pixels.
/// The noise's bins leave out a difference this far from 0 in their robust σ, and the
/// observations a pixel this far from its neighbours
/// ([`crate::fit::observe::SphereData::impulses`]).
pub(crate) const IMPULSE_SIGMA: f64 = 6.0;
/// … and this fraction of the level: shading that is not smooth at the pixel scale (a rendered
/// session's Monte Carlo noise, a textured surface) is not taken for impulses.
pub(crate) const IMPULSE_FRACTION: f64 = 0.2;
/// … within the highlight, where the lobe itself changes fast from pixel to pixel.
pub(crate) const IMPULSE_FRACTION_HIGHLIGHT: f64 = 0.5;

/// Bins of level the pairs are grouped in, and the pairs a bin needs at least (fewer pairs in
/// all: one constant variance).
const BINS: usize = 12;
const PAIRS_PER_BIN: usize = 20;

/// σ²(L) = a + b·L + c·L² (radiance units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseCurve {
    /// a: the read noise's variance.
    pub read: f64,
    /// b: the shot noise's, per unit level.
    pub shot: f64,
    /// c: the variance of a noise proportional to the level, per unit level².
    pub relative: f64,
}

impl NoiseCurve {
    /// A constant σ.
    pub fn constant(sigma: f64) -> NoiseCurve {
        NoiseCurve {
            read: sigma * sigma,
            shot: 0.0,
            relative: 0.0,
        }
    }

    /// σ at level L (negative levels count as 0).
    pub fn sigma(&self, level: f64) -> f64 {
        let l = level.max(0.0);
        (self.read + self.shot * l + self.relative * l * l).sqrt()
    }

    /// The curve of the same pixels with their levels and σ divided by k.
    pub fn scaled(&self, k: f64) -> NoiseCurve {
        NoiseCurve {
            read: self.read / (k * k),
            shot: self.shot / k,
            relative: self.relative,
        }
    }
}

/// The curve from pairs of adjacent pixels, each (their mean level, |their difference|);
/// `floor` is the smallest σ allowed (half a level step).
pub fn measure(mut pairs: Vec<(f64, f64)>, floor: f64) -> NoiseCurve {
    let f2 = floor * floor;
    let held = |c: NoiseCurve| NoiseCurve {
        read: c.read.max(f2),
        ..c
    };
    if pairs.len() < PAIRS_PER_BIN * BINS {
        return held(NoiseCurve {
            read: variance(&pairs),
            shot: 0.0,
            relative: 0.0,
        });
    }
    pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let bins: Vec<Bin> = pairs
        .chunks(pairs.len().div_ceil(BINS))
        .map(|chunk| Bin {
            level: chunk.iter().map(|x| x.0).sum::<f64>() / chunk.len() as f64,
            variance: variance(chunk).max(f2),
            count: chunk.len() as f64,
        })
        .collect();
    // Weighted by the bins' own variances first, then by the curve's.
    let mut curve = fit(&bins, |b| b.variance);
    for _ in 0..4 {
        let c = held(curve);
        curve = fit(&bins, |b| c.sigma(b.level).powi(2));
    }
    held(curve)
}

/// One bin of pairs: its mean level, a pixel's variance there, and its number of pairs.
struct Bin {
    level: f64,
    variance: f64,
    count: f64,
}

/// A pixel's variance from pairs (level, |difference|): half the differences' mean square,
/// short of the impulses. The cut starts from the differences' robust σ (the MAD's) and moves
/// with the mean square it keeps, three times: heavy-tailed noise keeps its tails, an edge
/// stays out.
fn variance(pairs: &[(f64, f64)]) -> f64 {
    if pairs.is_empty() {
        return 0.0;
    }
    let mut sigma_d = stats::robust_sigma(pairs.iter().map(|x| x.1).collect());
    for _ in 0..3 {
        let (mut sum, mut n) = (0.0, 0.0);
        for (level, d) in pairs {
            if *d <= IMPULSE_SIGMA * sigma_d + IMPULSE_FRACTION * level.abs() {
                sum += d * d;
                n += 1.0;
            }
        }
        if n == 0.0 {
            break;
        }
        sigma_d = (sum / n).sqrt();
    }
    0.5 * sigma_d * sigma_d
}

/// The least-squares curve over the bins, each weighted by count/(2 v²) with v its `expected`
/// variance: among the curves with a subset of (a, b, c) free and the rest 0, the best one whose
/// coefficients are all ≥ 0.
fn fit(bins: &[Bin], expected: impl Fn(&Bin) -> f64) -> NoiseCurve {
    let weights: Vec<f64> = bins
        .iter()
        .map(|b| b.count / (2.0 * expected(b).powi(2).max(f64::MIN_POSITIVE)))
        .collect();
    let basis = |l: f64| [1.0, l, l * l];
    let mut best: Option<(f64, [f64; 3])> = None;
    for subset in 1u8..8 {
        let free: Vec<usize> = (0..3).filter(|k| subset & (1 << k) != 0).collect();
        let n = free.len();
        let mut ata = nalgebra::DMatrix::<f64>::zeros(n, n);
        let mut atb = nalgebra::DVector::<f64>::zeros(n);
        for (b, w) in bins.iter().zip(&weights) {
            let x = basis(b.level);
            for (i, &p) in free.iter().enumerate() {
                atb[i] += w * x[p] * b.variance;
                for (j, &q) in free.iter().enumerate() {
                    ata[(i, j)] += w * x[p] * x[q];
                }
            }
        }
        let Some(sol) = ata.cholesky().map(|c| c.solve(&atb)) else {
            continue;
        };
        if sol.iter().any(|v| *v < 0.0 || !v.is_finite()) {
            continue;
        }
        let mut coef = [0.0; 3];
        for (i, &p) in free.iter().enumerate() {
            coef[p] = sol[i];
        }
        let sse: f64 = bins
            .iter()
            .zip(&weights)
            .map(|(b, w)| {
                let x = basis(b.level);
                w * (b.variance - (0..3).map(|k| coef[k] * x[k]).sum::<f64>()).powi(2)
            })
            .sum();
        if best.is_none_or(|(s, _)| sse < s) {
            best = Some((sse, coef));
        }
    }
    let [read, shot, relative] = best.map_or([0.0; 3], |b| b.1);
    NoiseCurve {
        read,
        shot,
        relative,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    /// Adjacent pixel pairs of a smooth ramp from 0.01 to 1, each pixel with noise of σ(L):
    /// σ times `draw` of a standard normal deviate.
    fn pairs(sigma: impl Fn(f64) -> f64, draw: impl Fn(f64) -> f64) -> Vec<(f64, f64)> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut deviate = move || draw(StandardNormal.sample(&mut rng));
        (0..60_000)
            .map(|k| {
                let level = 0.01 + 0.99 * k as f64 / 60_000.0;
                let s = sigma(level);
                let a = level + s * deviate();
                let b = level + s * deviate();
                (0.5 * (a + b), (a - b).abs())
            })
            .collect()
    }

    /// A sensor's noise: read and shot, Gaussian. σ recovered within 0.7% at every level
    /// (2.4% with another draw; asserted 6%).
    #[test]
    fn a_sensors_read_and_shot_noise_is_measured() {
        let truth = |l: f64| (1e-5 + 4e-4 * l).sqrt();
        let c = measure(pairs(truth, |g| g), 1e-6);
        for l in [0.05, 0.1, 0.3, 0.6, 0.95] {
            let r = c.sigma(l) / truth(l);
            assert!((r - 1.0).abs() < 0.06, "at {l}: {r} ({c:?})");
        }
    }

    /// A Monte Carlo render's noise: σ proportional to the level, heavy-tailed (a centred
    /// Gaussian square, kurtosis 15). Its standard deviation recovered within 5% at every level
    /// (0.95–0.99; 0.94–1.01 with another draw; the impulses' cut takes the far tail), asserted
    /// 12%.
    #[test]
    fn a_renders_relative_heavy_tailed_noise_is_measured() {
        // A unit-variance, zero-mean, heavy-tailed deviate: (g² − 1)/√2.
        let heavy = |g: f64| (g * g - 1.0) / std::f64::consts::SQRT_2;
        let truth = |l: f64| 0.05 * l;
        let c = measure(pairs(truth, heavy), 1e-6);
        for l in [0.05, 0.1, 0.3, 0.6, 0.95] {
            let r = c.sigma(l) / truth(l);
            assert!((r - 1.0).abs() < 0.12, "at {l}: {r} ({c:?})");
        }
    }

    /// Scaling the pixels by 1/k scales σ by 1/k at the scaled level.
    #[test]
    fn the_scaled_curve_is_the_scaled_pixels() {
        let c = NoiseCurve {
            read: 1e-4,
            shot: 3e-3,
            relative: 2e-3,
        };
        let k = 2.5;
        for l in [0.0, 0.1, 0.7] {
            assert!((c.scaled(k).sigma(l / k) - c.sigma(l) / k).abs() < 1e-15);
        }
    }
}
