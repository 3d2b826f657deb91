//! One lamp intensity per photo and channel, where a session with one light per photo gives none
//! ([`fit_photo_intensities`]). A photometric-stereo set's lamps differ (DiLiGenT's by up to 2.4×
//! between photos and channels); fitted as one material under one intensity, the photos disagree
//! by that much and the fit goes degenerate. The photos share the material, so the shading and the
//! lobe fix each photo's intensity up to one common scale, which stays in the albedo and ks: the
//! intensities are normalised to a geometric mean of 1 per channel.
//!
//! Each round fits the material to the photos as scaled so far ([`fit_joint`], the extensions
//! off, no checks, on 1° cells; from the last round's fit after the first), then takes each photo's least-squares scale against that fit's prediction in
//! closed form (the observations' own weights), and divides the photo's observations by it; the
//! rounds stop when no intensity moves by more than [`SETTLED`], at most [`ROUNDS`]. The fit that
//! follows (`fit_session`) runs on the scaled photos; the intensities' own errors are not carried
//! into the material's (docs/uncertainty.md, "One light per photo").

use super::settings::{Extensions, Measured, Reduction, Settings, Setup};
use super::stages::fit_joint;
use crate::fit::observe::SphereData;

/// The most rounds of fit and rescaling.
pub const ROUNDS: usize = 6;
/// The rounds' fits pool pixels into 1° cells (the scales need the material near its fit, not
/// its last digit; the fit on the scaled photos that follows takes the settings' cells).
pub const ROUND_CELLS: Reduction = Reduction::Factor(4);
/// Rounds stop when every intensity moved by less than this fraction in the last one.
pub const SETTLED: f64 = 1e-3;

/// The intensities fitted, per photo (in the order the photos first appear among the spheres).
#[derive(Clone, Debug, PartialEq)]
pub struct PhotoIntensities {
    /// Photo file and its relative intensity per channel.
    pub photos: Vec<(String, [f64; 3])>,
    pub rounds: usize,
    /// The largest relative move in the last round.
    pub last_move: f64,
}

/// Fit each photo's lamp intensity (module doc) and divide its spheres' observations by it, in
/// place; `fitted` selects the spheres the fit uses (a held-out radius is scaled with its photo
/// but not fitted).
pub fn fit_photo_intensities(
    settings: &Settings,
    measured: &Measured,
    spheres: &mut [SphereData],
    fitted: impl Fn(&SphereData) -> bool,
) -> PhotoIntensities {
    let mut photos: Vec<String> = vec![];
    for s in spheres.iter() {
        if !photos.contains(&s.image) {
            photos.push(s.image.clone());
        }
    }
    let mut total = vec![[1.0; 3]; photos.len()];
    let (mut rounds, mut last_move) = (0, f64::INFINITY);
    let mut warm = None;
    while rounds < ROUNDS && last_move >= SETTLED {
        rounds += 1;
        let scales = {
            let used: Vec<&SphereData> = spheres.iter().filter(|s| fitted(s)).collect();
            let setup = Setup::new(settings, measured, Extensions::default(), ROUND_CELLS);
            // The first round from the data's start values; the later ones from the last fit.
            let setup = match warm {
                Some(p) => setup.refit(p),
                None => Setup {
                    checks: false,
                    ..setup
                },
            };
            let jf = fit_joint(&setup, &used);
            warm = Some(jf.fit.params);
            let floor = jf.fit.floor.map_or([0.0; 3], |f| f.value);
            let predict = |g: &crate::model::Geometry| {
                let r = jf.model.radiance(&jf.fit.params, g);
                [0, 1, 2].map(|c| r[c] + floor[c])
            };
            photo_scales(&photos, &used, predict)
        };
        last_move = scales
            .iter()
            .flatten()
            .map(|k| (k - 1.0).abs())
            .fold(0.0, f64::max);
        for s in spheres.iter_mut() {
            let i = photos
                .iter()
                .position(|p| *p == s.image)
                .expect("listed above");
            scale_sphere(s, &scales[i]);
        }
        for (t, k) in total.iter_mut().zip(&scales) {
            (0..3).for_each(|c| t[c] *= k[c]);
        }
    }
    PhotoIntensities {
        photos: photos.into_iter().zip(total).collect(),
        rounds,
        last_move,
    }
}

/// Each photo's least-squares scale per channel against the prediction, Σ w²·y·p / Σ w²·p² over
/// its fitted observations, normalised to a geometric mean of 1 per channel over the photos that
/// have any (1 for a photo without).
fn photo_scales(
    photos: &[String],
    used: &[&SphereData],
    predict: impl Fn(&crate::model::Geometry) -> [f64; 3] + Sync,
) -> Vec<[f64; 3]> {
    use rayon::prelude::*;
    let sums: Vec<[[f64; 2]; 3]> = photos
        .par_iter()
        .map(|p| {
            let mut acc = [[0.0; 2]; 3];
            for s in used.iter().filter(|s| s.image == *p) {
                for o in &s.obs {
                    let m = predict(&o.geometry);
                    for c in 0..3 {
                        let w2 = o.weight[c] * o.weight[c];
                        if w2 > 0.0 && m[c].is_finite() && o.radiance[c].is_finite() {
                            acc[c][0] += w2 * o.radiance[c] * m[c];
                            acc[c][1] += w2 * m[c] * m[c];
                        }
                    }
                }
            }
            acc
        })
        .collect();
    let raw: Vec<[Option<f64>; 3]> = sums
        .iter()
        .map(|a| a.map(|[ym, mm]| (mm > 0.0 && ym > 0.0).then(|| ym / mm)))
        .collect();
    let centre: [f64; 3] = std::array::from_fn(|c| {
        let logs: Vec<f64> = raw.iter().filter_map(|k| k[c]).map(f64::ln).collect();
        if logs.is_empty() {
            1.0
        } else {
            (logs.iter().sum::<f64>() / logs.len() as f64).exp()
        }
    });
    raw.iter()
        .map(|k| std::array::from_fn(|c| k[c].map_or(1.0, |v| v / centre[c])))
        .collect()
}

/// A sphere's observations as if its lamp were `k` times weaker per channel: the radiance, the
/// noise and the floor divided by k, the weights (1/σ) multiplied.
fn scale_sphere(s: &mut SphereData, k: &[f64; 3]) {
    for o in s.obs.iter_mut() {
        o.radiance = std::array::from_fn(|c| o.radiance[c] / k[c]);
        o.weight = std::array::from_fn(|c| o.weight[c] * k[c]);
    }
    for w in s.curve_weight.iter_mut() {
        *w = std::array::from_fn(|c| w[c] * k[c]);
    }
    s.noise_curve = std::array::from_fn(|c| s.noise_curve[c].scaled(k[c]));
    s.noise = std::array::from_fn(|c| s.noise[c] / k[c]);
    // σ² = a + b·L: with L and σ over k, a over k² and b over k.
    s.noise_model = std::array::from_fn(|c| {
        let [a, b] = s.noise_model[c];
        [a / (k[c] * k[c]), b / k[c]]
    });
    if let Some(f) = s.floor.as_mut() {
        (0..3).for_each(|c| f[c] /= k[c]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::solver::Obs;
    use crate::model::Geometry;
    use nalgebra::Vector3;

    fn sphere(image: &str, values: &[[f64; 3]]) -> SphereData {
        let g = Geometry {
            normal: Vector3::new(0.0, 0.0, -1.0),
            view: Vector3::new(0.0, 0.0, -1.0),
            radius_mm: 20.0,
        };
        SphereData {
            image: image.into(),
            index: 0,
            radius_mm: 20.0,
            obs: values
                .iter()
                .map(|&radiance| Obs {
                    geometry: g,
                    radiance,
                    weight: [2.0; 3],
                })
                .collect(),
            px: vec![[0, 0]; values.len()],
            pixels: values.len(),
            saturated: 0,
            edge: 0,
            impulses: 0,
            noise: [0.5; 3],
            noise_model: [[0.25, 0.0]; 3],
            noise_curve: [crate::fit::noise::NoiseCurve::constant(0.5); 3],
            curve_weight: vec![[2.0; 3]; values.len()],
            floor: None,
            crop: crate::fit::observe::Crop {
                x0: 0,
                y0: 0,
                step: 1,
                width: 0,
                height: 0,
                rgb: vec![],
                gain: 1.0,
            },
        }
    }

    /// Scales from a known prediction: photo b at (2, 1, 0.5) times photo a, normalised to a
    /// geometric mean of 1; a scaled sphere then predicts as the other.
    #[test]
    fn scales_are_least_squares_ratios_with_a_geometric_mean_of_one() {
        let a = sphere("a", &[[1.0, 2.0, 4.0], [0.5, 1.0, 2.0]]);
        let b = sphere("b", &[[2.0, 2.0, 2.0], [1.0, 1.0, 1.0]]);
        let photos = vec!["a".to_string(), "b".to_string()];
        // A prediction exactly photo a's values: the first observation (1, 2, 4), the second
        // half of it; both observations share the geometry, so the prediction is their mean.
        let k = photo_scales(&photos, &[&a, &b], |_| [0.75, 1.5, 3.0]);
        for c in 0..3 {
            let ratio = k[1][c] / k[0][c];
            let want = [2.0, 1.0, 0.5][c];
            assert!((ratio - want).abs() < 1e-12, "channel {c}: {ratio}");
            assert!((k[0][c] * k[1][c] - 1.0).abs() < 1e-12);
        }
        let mut b2 = b.clone();
        scale_sphere(&mut b2, &[2.0, 1.0, 0.5]);
        assert_eq!(b2.obs[0].radiance, [1.0, 2.0, 4.0]);
        assert_eq!(b2.obs[0].weight, [4.0, 2.0, 1.0]);
    }
}
