//! σ0 and the albedo per channel before any fit: a search over a log grid of σ0 with the albedo
//! in closed form at each point. The start of the joint fit ([`crate::fit::joint::start`]) and of
//! the paper's per-radius fits ([`crate::fit::paper`]).

use crate::fit::solver::Obs;
use crate::model::fresnel;
use crate::model::{LightAngles, Model, Params};

/// σ0 per channel by a search over a log grid, the albedo in closed form at each point (least
/// squares of a · T(φ) · f(θ; σ) against the data, weighted), without the specular term.
pub(crate) fn diffuse_start(
    model: &Model,
    obs: &[Obs],
    light: &LightAngles,
    eta: f64,
    sigma0: Option<[f64; 3]>,
) -> ([f64; 3], [f64; 3]) {
    let l = light.direction();
    let radii: Vec<f64> = obs.iter().map(|o| o.geometry.radius_mm).collect();
    let r_mid = {
        let mut r = radii.clone();
        r.sort_by(|a, b| a.total_cmp(b));
        r.get(r.len() / 2).copied().unwrap_or(20.0)
    };
    // σ = σ0/r from 0.005 to 2 rad at the middle radius.
    let grid: Vec<f64> = (0..40)
        .map(|i| r_mid * 0.005 * (400.0f64).powf(i as f64 / 39.0))
        .collect();
    let geo: Vec<(f64, f64, f64)> = obs
        .iter()
        .map(|o| {
            let g = &o.geometry;
            let t = if model.exit_fresnel {
                fresnel::transmission(g.normal.dot(&g.view), eta)
            } else {
                1.0
            };
            (g.normal.dot(&l).clamp(-1.0, 1.0).acos(), t, g.radius_mm)
        })
        .collect();
    // The profile of one Gaussian (of the transmitted irradiance when the model has it) at η.
    let plain = Params::diffuse([1.0; 3], [1.0; 3], eta, *light).material;
    let mut s0 = [0.0; 3];
    let mut a0 = [0.0; 3];
    for c in 0..3 {
        let eval = |sig0: f64| -> (f64, f64) {
            let (mut sff, mut sfl, mut sll) = (0.0, 0.0, 0.0);
            for (o, &(th, t, r)) in obs.iter().zip(&geo) {
                let f = t * model.profile(&plain, th, sig0 / r).f.value;
                let w2 = o.weight[c] * o.weight[c];
                sff += w2 * f * f;
                sfl += w2 * f * o.radiance[c];
                sll += w2 * o.radiance[c] * o.radiance[c];
            }
            let a = if sff > 0.0 {
                (sfl / sff).max(1e-6)
            } else {
                1e-3
            };
            (a, sll - 2.0 * a * sfl + a * a * sff)
        };
        match sigma0 {
            Some(s) => {
                s0[c] = s[c];
                a0[c] = eval(s[c]).0;
            }
            None => {
                let best = grid
                    .iter()
                    .map(|&g| (g, eval(g)))
                    .min_by(|a, b| a.1 .1.total_cmp(&b.1 .1))
                    .expect("grid is not empty");
                s0[c] = best.0;
                a0[c] = best.1 .0;
            }
        }
    }
    (s0, a0)
}
