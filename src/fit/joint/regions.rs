//! Where a fit's residuals lie, when they are above the noise ([`worst_region`]): the pixels
//! split by geometry into the lit shading, the terminator, the rim and the highlight, each
//! region's residuals in the noise's units, and what the model may lack where they are worst.
//! "The model does not describe these photos" says little; "the residuals are 4× the noise at the
//! rim and 1.1× on the lit side" names what to look at (issue 34: DiLiGenT's ball).

use crate::fit::observe::SphereData;
use crate::fit::solver::Fit;
use crate::model::Model;
use rayon::prelude::*;

/// Regions of a sphere's pixels, as [`region`] assigns them.
pub(crate) const REGIONS: [&str; 4] = ["lit side", "terminator", "rim", "highlight"];

/// What the model may lack where each region's residuals are the worst.
const LACKS: [&str; 4] = [
    "the albedo's or the scattering profile's shape across the lit side, or light from the surroundings",
    "the blur's profile across the terminator (the scattering kernel's shape) or the lamp's size",
    "the outline, the lens's blur at the silhouette, or light from the surroundings reaching the grazing view (interreflection)",
    "the lobe's shape (one GGX lobe and its Fresnel factor), or pixels clipped around the peak",
];

/// The grazing band (cos φ = n·v below this is the rim) and the terminator's (|n·l| below this).
const RIM_COS: f64 = 0.25;
const TERMINATOR_COS: f64 = 0.2;

/// The region of a pixel with normal n, view v and light l, for a lobe of roughness α: the
/// highlight within 2.5 α of the half vector (at least 3°), then the rim, then the terminator.
pub(crate) fn region(g: &crate::model::Geometry, l: &nalgebra::Vector3<f64>, alpha: f64) -> usize {
    let h = (l + g.view).normalize();
    let off = g.normal.dot(&h).clamp(-1.0, 1.0).acos();
    if off < (2.5 * alpha).max(3f64.to_radians()) {
        3
    } else if g.normal.dot(&g.view) < RIM_COS {
        2
    } else if g.normal.dot(l).abs() < TERMINATOR_COS {
        1
    } else {
        0
    }
}

/// Each region's RMS residual in the noise's units (every channel of every pixel; NaN for an
/// empty region) and its pixel count.
pub(crate) fn region_residuals(
    model: &Model,
    fit: &Fit,
    spheres: &[&SphereData],
) -> [(f64, usize); 4] {
    let p = &fit.params;
    let l = p.light.direction();
    let floor = fit.floor.map_or([0.0; 3], |f| f.value);
    let sums = spheres
        .par_iter()
        .flat_map_iter(|s| s.obs.iter())
        .fold(
            || [(0.0, 0usize); 4],
            |mut acc, o| {
                let m = model.radiance(p, &o.geometry);
                let r2: f64 = (0..3)
                    .map(|c| (o.weight[c] * (o.radiance[c] - m[c] - floor[c])).powi(2))
                    .sum();
                if r2.is_finite() {
                    let k = region(&o.geometry, &l, p.material.specular.alpha);
                    acc[k].0 += r2;
                    acc[k].1 += 1;
                }
                acc
            },
        )
        .reduce(
            || [(0.0, 0usize); 4],
            |a, b| std::array::from_fn(|k| (a[k].0 + b[k].0, a[k].1 + b[k].1)),
        );
    sums.map(|(s, n)| ((s / (3 * n) as f64).sqrt(), n))
}

/// The note for residuals above the noise: each region's level, and what the model may lack where
/// it is the worst (regions of fewer than 1% of the pixels are left out).
pub(crate) fn worst_region(model: &Model, fit: &Fit, spheres: &[&SphereData]) -> Option<String> {
    let levels = region_residuals(model, fit, spheres);
    let total: usize = levels.iter().map(|(_, n)| n).sum();
    let shown: Vec<usize> = (0..4)
        .filter(|&k| levels[k].1 * 100 >= total && levels[k].0.is_finite())
        .collect();
    let worst = *shown
        .iter()
        .max_by(|&&a, &&b| levels[a].0.total_cmp(&levels[b].0))?;
    let list: Vec<String> = shown
        .iter()
        .map(|&k| format!("{} {:.1}×", REGIONS[k], levels[k].0))
        .collect();
    Some(format!(
        "each pixel's residual over its noise, RMS by region: {}; worst at the {}, where the model may lack {}",
        list.join(", "),
        REGIONS[worst],
        LACKS[worst]
    ))
}
