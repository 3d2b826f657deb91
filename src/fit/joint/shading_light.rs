//! The shading's own light ([`shading_light`]): the light the pixels alone fit, the detector's
//! prior taken out, with its formal covariance and the spread when each region of the spheres
//! (lit side, terminator, rim, highlight: [`super::regions`]) is left out in turn, and when each
//! radius is (as the fit's own jackknife does). A model that
//! describes the photos fits the same light from every region; one that does not (the kernel's
//! shape across the terminator, a lobe that is not GGX) fits each region's light a little
//! differently, and so does a shading computed on a misplaced outline. Everything is a Newton
//! step from the joint fit on its final stage's normal equations, one pass over the
//! observations (docs/uncertainty.md, "The detector's light and the shading's").

use super::regions::{region, REGIONS};
use super::stages::JointFit;
use crate::fit::observe::{self, SphereData};
use crate::fit::solver::{to_unbounded, Normal, RawNormal};
use crate::model::{idx, LightAngles, N_PARAMS};
use nalgebra::{Matrix2, Vector2};

/// The shading's light and its errors; angles and covariances in radians, in (azimuth,
/// elevation).
pub(crate) struct ShadingLight {
    pub light: LightAngles,
    /// σ²(JᵀJ)⁻¹'s light block, with σ² the observations' χ² per degree of freedom.
    pub formal: Matrix2<f64>,
    /// The leave-one-region-out jackknife's covariance, (n − 1)/n Σ (θᵢ − θ̄)(θᵢ − θ̄)ᵀ.
    pub regions: Matrix2<f64>,
    /// The leave-one-radius-out jackknife's, widened as the fit's own (zero with fewer than 3
    /// radii): what the radii's jackknife of the fit would add to the light's error.
    pub radii: Matrix2<f64>,
    /// χ² per degree of freedom of the observations (the noise's units, Huber weights).
    pub chi2_dof: f64,
    /// Per free parameter other than the light, how its unbounded value follows the light held
    /// elsewhere: d u_k / d(azimuth, elevation) ([`crate::fit::solver::Problem::follows`]).
    pub follows: Vec<(usize, [f64; 2])>,
}

/// Regions with fewer than this fraction of the observations are not left out on their own.
const MIN_REGION: f64 = 0.01;

/// The shading's light of the joint fit `jf` (module doc). `None` when its light is not free,
/// fewer than two regions are large enough, or the normal equations are singular.
pub(crate) fn shading_light(jf: &JointFit, fitted: &[&SphereData]) -> Option<ShadingLight> {
    let p = &jf.fit.params;
    if !jf.fit.free[idx::AZIMUTH] || !jf.fit.free[idx::ELEVATION] {
        return None;
    }
    let l = p.light.direction();
    let alpha = p.material.specular.alpha;
    let obs = &jf.problem.weighted;
    // Each observation's group: its region and its sphere's radius (the parts of a region, or
    // of a radius, summed are that region's, or that radius's, normal equations).
    let radii = observe::distinct_radii(fitted);
    let radius_of = observe::radius_index(fitted, &radii);
    let nr = radii.len();
    let groups: Vec<usize> = obs
        .iter()
        .zip(&jf.problem.sphere)
        .map(|(o, &s)| region(&o.geometry, &l, alpha) * nr + radius_of[s])
        .collect();
    // The pixels alone: the problem without the light's prior.
    let mut problem = super::newton::problem(jf, obs, jf.fit.free, to_unbounded(&p.to_vec()));
    problem
        .priors
        .retain(|q| q.index != idx::AZIMUTH && q.index != idx::ELEVATION);
    let parts = problem.grouped_sums(Some((&groups, REGIONS.len() * nr)));
    let total = RawNormal::sum(&parts)?;
    let (alone, _) = problem.newton_step(&total)?;
    let at_fit = Vector2::new(p.light.azimuth, p.light.elevation);
    let free: Vec<usize> = (0..N_PARAMS).filter(|&k| jf.fit.free[k]).collect();
    let at = |k: usize| free.iter().position(|&f| f == k);
    let (a, e) = (at(idx::AZIMUTH)?, at(idx::ELEVATION)?);
    let ne = problem.profiled(&total);
    let floor = if jf.fit.floor.is_some() { 3 } else { 0 };
    let dof = (3 * obs.len()).saturating_sub(free.len() + floor).max(1);
    let chi2_dof = ne.rtr_obs / dof as f64;
    let inv = ne.jtj.clone().try_inverse()?;
    let formal = Matrix2::new(inv[(a, a)], inv[(a, e)], inv[(e, a)], inv[(e, e)]) * chi2_dof;
    // The light without each region, then without each radius.
    let region_part = |g: usize| RawNormal::sum(&parts[g * nr..(g + 1) * nr]);
    let radius_part = |r: usize| {
        let of: Vec<RawNormal> = (0..REGIONS.len())
            .map(|g| parts[g * nr + r].clone())
            .collect();
        RawNormal::sum(&of)
    };
    let without = |part: Option<RawNormal>| {
        let step = step_without(&problem.profiled(&total.less(&part?)), &ne, (a, e))?;
        Some(at_fit + step)
    };
    let large = |n: usize| n as f64 >= MIN_REGION * groups.len() as f64;
    let count = |f: &dyn Fn(usize) -> bool| groups.iter().filter(|&&k| f(k)).count();
    let lefts: Vec<Vector2<f64>> = (0..REGIONS.len())
        .filter(|&g| large(count(&|k| k / nr == g)))
        .filter_map(|g| without(region_part(g)))
        .collect();
    let by_radius: Vec<Vector2<f64>> = (0..nr).filter_map(|r| without(radius_part(r))).collect();
    if lefts.len() < 2 {
        return None;
    }
    let regions = crate::stats::jackknife_covariance(&lefts);
    // The radii's as the fit's own jackknife widens it (t(n − 1)/2: src/fit/joint/jackknife.rs).
    let radii_cov = if by_radius.len() >= 3 {
        let t = crate::stats::jackknife_widening(by_radius.len());
        crate::stats::jackknife_covariance(&by_radius) * (t * t)
    } else {
        Matrix2::zeros()
    };
    let follows = problem
        .follows(&total, &[idx::AZIMUTH, idx::ELEVATION])
        .unwrap_or_default()
        .into_iter()
        .map(|(k, g)| (k, [g[0], g[1]]))
        .collect();
    Some(ShadingLight {
        light: LightAngles {
            azimuth: alone[idx::AZIMUTH],
            elevation: alone[idx::ELEVATION],
        },
        formal,
        regions,
        radii: radii_cov,
        chi2_dof,
        follows,
    })
}

/// The light's Newton step (azimuth, elevation) on the normal equations `less` of the
/// observations without one region, from the fit: the parameters that region alone determined
/// (JᵀJ's diagonal below [`KEPT_INFORMATION`] of its value over all regions, e.g. the lobe's
/// without the highlight) held at the fit, so that the step measures the light the other
/// regions fit rather than a lobe left free without data. `None` where the kept block is
/// singular. `(a, e)`: the light's positions among the free parameters.
fn step_without(less: &Normal, all: &Normal, (a, e): (usize, usize)) -> Option<Vector2<f64>> {
    let n = all.jtj.nrows();
    let kept: Vec<usize> = (0..n)
        .filter(|&i| i == a || i == e || less.jtj[(i, i)] >= KEPT_INFORMATION * all.jtj[(i, i)])
        .collect();
    let h = less.jtj.select_rows(&kept).select_columns(&kept);
    let g = less.jtr.select_rows(&kept);
    let delta = h.cholesky()?.solve(&(-g));
    let at = |i: usize| kept.iter().position(|&k| k == i);
    Some(Vector2::new(delta[at(a)?], delta[at(e)?]))
}

/// A parameter keeps at least this fraction of its information (JᵀJ's diagonal) without a
/// region, or is held at the fit in that region's leave-out step.
const KEPT_INFORMATION: f64 = 0.1;
