//! The core of the joint fit: Levenberg–Marquardt (crate `levenberg-marquardt`) over the model's
//! parameters, mapped so that the solver cannot leave their physical range, with the Jacobian
//! from the model's analytic gradient, and standard errors and correlations from σ²(JᵀJ)⁻¹.
//!
//! Unbounded parameters u: ln σ0 (×3), ln albedo (×3), ln(η − 1), ln ks, ln α, and the light's
//! azimuth and elevation as they are. Parameters not free are held at their given value.

use crate::model::{Geometry, Model, Params, N_PARAMS};
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use rayon::prelude::*;

/// One observation: a pixel's (or a block of pixels') geometry, its RGB radiance and the weight
/// of each channel's residual (1/σ; 0 leaves a channel out).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Obs {
    pub geometry: Geometry,
    pub radiance: [f64; 3],
    pub weight: [f64; 3],
}

/// Physical parameters → unbounded ones.
pub fn to_unbounded(p: &[f64; N_PARAMS]) -> [f64; N_PARAMS] {
    let mut u = *p;
    for (k, v) in u.iter_mut().enumerate().take(9) {
        *v = if k == 6 { (p[k] - 1.0).ln() } else { p[k].ln() };
    }
    u
}

/// Unbounded parameters → physical ones, with dp/du (the mapping is diagonal).
pub fn from_unbounded(u: &[f64; N_PARAMS]) -> ([f64; N_PARAMS], [f64; N_PARAMS]) {
    let mut p = *u;
    let mut d = [1.0; N_PARAMS];
    for k in 0..9 {
        let e = u[k].exp();
        p[k] = if k == 6 { 1.0 + e } else { e };
        d[k] = e;
    }
    (p, d)
}

/// The least-squares problem over the free parameters.
pub struct Problem<'a> {
    pub model: Model,
    pub obs: &'a [Obs],
    /// Which parameters are fitted (in model index order).
    pub free: [bool; N_PARAMS],
    /// Current unbounded values of all parameters.
    pub u: [f64; N_PARAMS],
}

impl Problem<'_> {
    fn free_idx(&self) -> Vec<usize> {
        (0..N_PARAMS).filter(|&k| self.free[k]).collect()
    }

    pub fn params(&self) -> Params {
        Params::from_vec(&from_unbounded(&self.u).0)
    }

    /// Residuals (weighted model − data, three per observation) and, optionally, their Jacobian
    /// with respect to the free unbounded parameters. Evaluated in parallel.
    pub fn evaluate(&self, want_jacobian: bool) -> (DVector<f64>, Option<DMatrix<f64>>) {
        let (p, dpdu) = from_unbounded(&self.u);
        let params = Params::from_vec(&p);
        let free = self.free_idx();
        let n = free.len();
        let rows: Vec<([f64; 3], Vec<f64>)> = self
            .obs
            .par_iter()
            .map(|o| {
                let (l, g) = self.model.radiance_with_gradient(&params, &o.geometry);
                let r = [0, 1, 2].map(|c| o.weight[c] * (l[c] - o.radiance[c]));
                let mut j = vec![];
                if want_jacobian {
                    j.reserve(3 * n);
                    for (w, gc) in o.weight.iter().zip(&g) {
                        for &k in &free {
                            j.push(w * gc[k] * dpdu[k]);
                        }
                    }
                }
                (r, j)
            })
            .collect();
        let m = 3 * self.obs.len();
        let res = DVector::from_iterator(m, rows.iter().flat_map(|(r, _)| r.iter().cloned()));
        let jac = want_jacobian.then(|| {
            DMatrix::from_row_iterator(m, n, rows.iter().flat_map(|(_, j)| j.iter().cloned()))
        });
        (res, jac)
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        for (i, k) in self.free_idx().into_iter().enumerate() {
            self.u[k] = x[i];
        }
    }

    fn params(&self) -> DVector<f64> {
        let f = self.free_idx();
        DVector::from_iterator(f.len(), f.iter().map(|&k| self.u[k]))
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let r = self.evaluate(false).0;
        r.iter().all(|v| v.is_finite()).then_some(r)
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let j = self.evaluate(true).1?;
        j.iter().all(|v| v.is_finite()).then_some(j)
    }
}

/// What a fit returns.
#[derive(Clone, Debug, PartialEq)]
pub struct Fit {
    pub params: Params,
    pub free: [bool; N_PARAMS],
    /// Standard error of every parameter (physical units; 0 for fixed ones).
    pub std: [f64; N_PARAMS],
    /// Correlation matrix of the free parameters (in model index order).
    pub correlation: DMatrix<f64>,
    /// ½ Σ r² at the solution, and the number of residuals.
    pub cost: f64,
    pub residuals: usize,
    pub evaluations: usize,
    pub termination: String,
    pub converged: bool,
}

/// Fit the free parameters from `start`.
pub fn fit(model: Model, obs: &[Obs], start: &Params, free: [bool; N_PARAMS]) -> Fit {
    let problem = Problem {
        model,
        obs,
        free,
        u: to_unbounded(&start.to_vec()),
    };
    let (problem, report) = LevenbergMarquardt::new()
        .with_patience(200)
        .minimize(problem);
    let (p, dpdu) = from_unbounded(&problem.u);
    let (res, jac) = problem.evaluate(true);
    let m = res.len();
    let idx = problem.free_idx();
    let n = idx.len();
    let cost = 0.5 * res.norm_squared();
    let sigma2 = 2.0 * cost / (m.saturating_sub(n).max(1)) as f64;
    let mut std = [0.0; N_PARAMS];
    let mut correlation = DMatrix::zeros(n, n);
    if let Some(cov) = jac.and_then(|j| (j.transpose() * &j).try_inverse()) {
        let cov = cov * sigma2;
        for (a, &k) in idx.iter().enumerate() {
            // Unbounded → physical: σ_p = |dp/du| σ_u.
            std[k] = cov[(a, a)].max(0.0).sqrt() * dpdu[k].abs();
            for b in 0..n {
                correlation[(a, b)] = cov[(a, b)] / (cov[(a, a)] * cov[(b, b)]).sqrt();
            }
        }
    } else {
        std = [f64::INFINITY; N_PARAMS];
    }
    Fit {
        params: Params::from_vec(&p),
        free,
        std,
        correlation,
        cost,
        residuals: m,
        evaluations: report.number_of_evaluations,
        termination: format!("{:?}", report.termination),
        converged: report.termination.was_successful(),
    }
}

/// A fit with the Huber loss, by iteratively reweighted least squares around [`fit`]: residuals
/// are scaled by a robust σ (1.4826 × their median absolute value), those beyond `k` σ get weight
/// k/|r| (their square root multiplies the channel weight), and the fit is repeated from its own
/// result until no weight changes by more than 1% (at most `rounds` times). Returns the final fit
/// and the observations with their final weights.
pub fn fit_robust(
    model: Model,
    obs: &[Obs],
    start: &Params,
    free: [bool; N_PARAMS],
    k: f64,
    rounds: usize,
) -> (Fit, Vec<Obs>) {
    let mut current: Vec<Obs> = obs.to_vec();
    let mut f = fit(model, &current, start, free);
    for _ in 0..rounds {
        let probe = Problem {
            model,
            obs,
            free,
            u: to_unbounded(&f.params.to_vec()),
        };
        let (res, _) = probe.evaluate(false);
        let mut abs: Vec<f64> = res.iter().map(|r| r.abs()).filter(|r| *r > 0.0).collect();
        if abs.is_empty() {
            break;
        }
        abs.sort_by(|a, b| a.total_cmp(b));
        let sigma = 1.4826 * abs[abs.len() / 2];
        let mut changed = false;
        let next: Vec<Obs> = obs
            .iter()
            .enumerate()
            .map(|(i, o)| {
                let mut o2 = *o;
                for c in 0..3 {
                    let z = res[3 * i + c].abs() / sigma.max(1e-300);
                    let w = if z > k { (k / z).sqrt() } else { 1.0 };
                    o2.weight[c] = o.weight[c] * w;
                    if (o2.weight[c] - current[i].weight[c]).abs() > 0.01 * o.weight[c].max(1e-300)
                    {
                        changed = true;
                    }
                }
                o2
            })
            .collect();
        current = next;
        if !changed {
            break;
        }
        f = fit(model, &current, &f.params, free);
    }
    (f, current)
}
