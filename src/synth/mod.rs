//! Ground-truth synthetic data: sphere photo sessions rendered by the project's own forward model
//! ([`session`]) and checkerboard calibration sets ([`checkerboard`]). Both are deterministic for
//! a given seed: every image row draws its noise from its own generator seeded by
//! (seed, image, row), so the parallel schedule cannot change the output.

pub mod checkerboard;
pub mod close_loop;
pub mod dielectric;
pub mod photon_tally;
pub mod session;
pub mod volpath;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;

/// The generator for one image row.
pub(crate) fn row_rng(seed: u64, image: u64, row: u64) -> ChaCha8Rng {
    // SplitMix64 finaliser over the three indices: distinct, well-mixed seeds.
    let mut z = seed
        .wrapping_add(image.wrapping_mul(0x9E37_79B9_7F4A_7C15))
        .wrapping_add(row.wrapping_mul(0xD1B5_4A32_D192_ED03));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ChaCha8Rng::seed_from_u64(z ^ (z >> 31))
}

/// Sensor noise on a linear value (full scale 1): shot noise with standard deviation `shot` at
/// full scale (variance ∝ signal) plus read noise `read`; then clipping to [0, 1] (saturation).
pub(crate) fn sensor(v: f64, shot: f64, read: f64, rng: &mut ChaCha8Rng) -> f64 {
    let sd = (shot * shot * v.max(0.0) + read * read).sqrt();
    let n: f64 = StandardNormal.sample(rng);
    (v + sd * n).clamp(0.0, 1.0)
}

/// Separable Gaussian blur of a single-channel image (edges clamped). σ ≤ 0 leaves it unchanged.
pub(crate) fn gaussian_blur(img: &mut [f64], width: usize, height: usize, sigma: f64) {
    if sigma <= 0.0 {
        return;
    }
    let r = (3.0 * sigma).ceil() as isize;
    let mut k: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let s: f64 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= s);
    let mut tmp = vec![0.0; img.len()];
    tmp.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
        for (x, out) in row.iter_mut().enumerate() {
            let mut acc = 0.0;
            for (j, kv) in k.iter().enumerate() {
                let xx = (x as isize + j as isize - r).clamp(0, width as isize - 1) as usize;
                acc += kv * img[y * width + xx];
            }
            *out = acc;
        }
    });
    img.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
        for (x, out) in row.iter_mut().enumerate() {
            let mut acc = 0.0;
            for (j, kv) in k.iter().enumerate() {
                let yy = (y as isize + j as isize - r).clamp(0, height as isize - 1) as usize;
                acc += kv * tmp[yy * width + x];
            }
            *out = acc;
        }
    });
}
