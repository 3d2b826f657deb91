//! Start values from the data, before any fit: the light (the detector's, or from the shading
//! when there is no highlight), σ0 and the albedo per channel by a grid search with the albedo in
//! closed form, the lobe's ks by linear least squares on the highlight, the two-Gaussian kernel's
//! shape. Good starts are what let each Levenberg–Marquardt stage converge in a few steps.

use super::settings::{Setup, ALPHA_PRIOR};
use crate::fit::observe::SphereData;
use crate::fit::reduce::Pooled;
use crate::fit::sigma_grid::diffuse_start;
use crate::model::fresnel;
use crate::model::{idx, LightAngles, Params, N_PARAMS};
use nalgebra::Vector3;

/// Start of the two-Gaussian kernel: tail weight and width ratio.
pub(crate) const KERNEL_START: (f64, f64) = (0.2, 3.0);

/// The light from the shading alone (a start value when no highlight was found). Where the
/// blur's kernel does not reach the terminator (θ < 90° − 3σ) the CDRF is cos θ · exp(−σ²/2),
/// so L / T(φ) = a′ n·l is linear in b = a′ l: a least-squares fit of b over the brightest
/// pixels (green, L/T above 40% of its maximum), repeated once over the pixels with θ < 60° from
/// the first estimate, gives l = b / |b| (single-light photometric stereo).
pub(crate) fn light_from_shading(spheres: &[&SphereData], eta: f64) -> Vector3<f64> {
    let pts: Vec<(Vector3<f64>, f64)> = spheres
        .iter()
        .flat_map(|sp| sp.obs.iter())
        .map(|o| {
            let g = &o.geometry;
            let t = fresnel::transmission(g.normal.dot(&g.view), eta).max(1e-3);
            (g.normal, o.radiance[1] / t)
        })
        .collect();
    type Pick<'a> = &'a dyn Fn(&(Vector3<f64>, f64)) -> bool;
    let solve = |use_pt: Pick| -> Option<Vector3<f64>> {
        let mut a = nalgebra::Matrix3::<f64>::zeros();
        let mut b = Vector3::zeros();
        for p in pts.iter().filter(|p| use_pt(p)) {
            a += p.0 * p.0.transpose();
            b += p.0 * p.1;
        }
        let x = a.try_inverse()? * b;
        (x.norm() > 0.0).then(|| x.normalize())
    };
    let max = pts.iter().map(|p| p.1).fold(0.0, f64::max);
    let Some(l1) = solve(&|p| p.1 > 0.4 * max) else {
        return Vector3::new(0.0, 0.0, -1.0);
    };
    let c60 = 60f64.to_radians().cos();
    solve(&|p| p.0.dot(&l1) > c60 && p.1 > 0.05 * max).unwrap_or(l1)
}

/// The start light: the detector's, else the shading's ([`light_from_shading`]) at the prior η.
pub(crate) fn light(setup: &Setup, spheres: &[&SphereData]) -> Vector3<f64> {
    setup
        .measured
        .light
        .unwrap_or_else(|| light_from_shading(spheres, setup.settings.eta_prior.0))
}

/// The start of every parameter: σ0 and the albedo from a grid search on 4° cells (none with a
/// warm start), η at its prior's mean, the light as given or `light0`, α the detector's.
pub(crate) fn params(setup: &Setup, pooled: &Pooled, light0: Vector3<f64>) -> Params {
    let start_light = setup
        .settings
        .start_light
        .unwrap_or_else(|| LightAngles::from_direction(&light0));
    let (eta_mean, _) = setup.settings.eta_prior;
    let (s0, a0) = if setup.warm.is_some() {
        ([1.0; 3], [1.0; 3])
    } else {
        let coarse = pooled.observations(&pooled.merged(16));
        diffuse_start(
            &setup.model(),
            &coarse,
            &start_light,
            eta_mean,
            setup.settings.start_sigma0,
        )
    };
    let mut p = Params::diffuse(s0, a0, eta_mean, start_light);
    p.material.specular.alpha = setup.measured.alpha.unwrap_or(ALPHA_PRIOR);
    p
}

/// The two-Gaussian kernel's start when it is first freed: a fifth of the weight in a tail three
/// times wider, the core narrowed so that the kernel's variance stays the plain fit's:
/// σ² = (1 − w + w·s²)·σ_core².
pub(crate) fn kernel(p: &mut Params) {
    let (w, s) = (KERNEL_START.0, KERNEL_START.1);
    let shrink = (1.0 - w + w * s * s).sqrt();
    p.material.kernel_weight = w;
    p.material.kernel_ratio = s;
    for v in p.material.sigma0_mm.iter_mut() {
        *v /= shrink;
    }
}

/// The lobe's start: ks from the highlight's pixels less the diffuse fit (or the irradiance
/// given); without a usable highlight the lobe is off. Returns whether it is on.
pub(crate) fn specular_start(
    setup: &Setup,
    pooled: &Pooled,
    highlight: bool,
    p: &mut Params,
    status: &mut [String; N_PARAMS],
    notes: &mut Vec<String>,
) -> bool {
    let model = setup.model();
    let specular = highlight && !pooled.kept.is_empty();
    if specular && setup.warm.is_none() {
        let mut unit = *p;
        unit.material.albedo = [0.0; 3];
        unit.material.specular.ks = 1.0;
        let (mut num, mut den) = (0.0, 0.0);
        for o in &pooled.kept {
            let d = model.radiance(p, &o.geometry);
            let s = model.radiance(&unit, &o.geometry);
            for c in 0..3 {
                let w2 = o.weight[c] * o.weight[c];
                num += w2 * s[c] * (o.radiance[c] - d[c]);
                den += w2 * s[c] * s[c];
            }
        }
        p.material.specular.ks = match setup.settings.irradiance {
            Some(e) => e,
            None if den > 0.0 && num > 0.0 => num / den,
            None => 1e-3,
        };
    } else {
        status[idx::KS] = if setup.measured.light.is_none() {
            "off: no usable highlight".into()
        } else {
            "off: no highlight pixels".into()
        };
        status[idx::ALPHA] = status[idx::KS].clone();
        notes.push("no usable highlight: specular lobe off (ks = 0)".into());
    }
    specular
}
