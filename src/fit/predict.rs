//! A fit's prediction error on a sphere's pixels: relative RMSE over all of them, the lit and
//! the unlit ones — for the spheres fitted, a held-out radius, the jackknife's left-out radii and
//! the model choice.

use crate::fit::observe::SphereData;
use crate::formats::fit::HoldoutJson;
use crate::model::{Model, Params};
use serde::{Deserialize, Serialize};

/// Pixels per sphere used for RMSE and predictions (every k-th beyond this).
pub(crate) const PREDICT_PIXELS: usize = 200_000;

/// Relative RMSE of the model against a sphere's pixels (every `stride`-th), over all of them,
/// the lit ones (θ < 90° from the given light) and the unlit ones.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Prediction {
    pub pixels: usize,
    pub rmse: f64,
    pub rel_rmse: f64,
    pub lit_rel_rmse: f64,
    pub unlit_rel_rmse: f64,
}

/// `floor`: the dark floor still in the sphere's observations (a fitted one, [`Fit::floor`]), taken
/// off them first.
pub fn predict(
    model: &Model,
    p: &Params,
    s: &SphereData,
    floor: [f64; 3],
    max_pixels: usize,
) -> Prediction {
    use rayon::prelude::*;
    let stride = (s.obs.len() / max_pixels.max(1)).max(1);
    let l = p.light.direction();
    let sums = s
        .obs
        .par_iter()
        .step_by(stride)
        .map(|o| {
            let m = model.radiance(p, &o.geometry);
            let lit = o.geometry.normal.dot(&l) > 0.0;
            let mut a = [0.0; 6];
            for ((mc, oc), f) in m.iter().zip(&o.radiance).zip(&floor) {
                let oc = oc - f;
                let (d2, o2) = ((mc - oc).powi(2), oc.powi(2));
                let k = if lit { 0 } else { 2 };
                a[k] += d2;
                a[k + 1] += o2;
                a[4] += d2;
                a[5] += o2;
            }
            (a, 1usize)
        })
        .collect::<Vec<_>>()
        .into_iter()
        // In pixel order: the same result on every run.
        .fold(([0.0; 6], 0), |(a, n), (b, m)| {
            (std::array::from_fn(|i| a[i] + b[i]), n + m)
        });
    let (a, n) = sums;
    let rel = |d: f64, o: f64| if o > 0.0 { (d / o).sqrt() } else { f64::NAN };
    Prediction {
        pixels: n,
        rmse: (a[4] / (3 * n.max(1)) as f64).sqrt(),
        rel_rmse: rel(a[4], a[5]),
        lit_rel_rmse: rel(a[0], a[1]),
        unlit_rel_rmse: rel(a[2], a[3]),
    }
}

/// Predictions of the spheres of one radius combined (pixel-weighted RMS of each error).
pub(crate) fn combine_predictions(radius_mm: f64, preds: &[Prediction]) -> HoldoutJson {
    let n: f64 = preds.iter().map(|p| p.pixels as f64).sum::<f64>().max(1.0);
    let comb = |f: fn(&Prediction) -> f64| {
        (preds
            .iter()
            .map(|p| f(p).powi(2) * p.pixels as f64)
            .sum::<f64>()
            / n)
            .sqrt()
    };
    HoldoutJson {
        radius_mm,
        pixels: preds.iter().map(|p| p.pixels).sum(),
        rel_rmse: comb(|p| p.rel_rmse),
        lit_rel_rmse: comb(|p| p.lit_rel_rmse),
        unlit_rel_rmse: comb(|p| p.unlit_rel_rmse),
    }
}
