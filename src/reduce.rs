//! Fewer residuals for the solver. On one sphere under one distant light the model depends on a
//! pixel's geometry only through θ = angle(n, l) and φ = angle(n, v) (and l·v, nearly constant
//! over a sphere), so pixels are pooled in (θ, φ) cells per sphere and per side of the light–view
//! plane (so that a cell is one patch of the sphere even when the light is later refined).
//!
//! Pixels are accumulated once, in fine cells of [`BASE_WIDTH`]: counts, radiance sums and the
//! first and second moments of (θ, φ), plus the member nearest the cell's centre. Coarser cells
//! are unions of fine ones (the bins nest exactly), so every reduction level costs one pass over
//! the pixels. A cell becomes one observation: the mean radiance, a virtual pixel at exactly the
//! cell's mean (θ, φ) (the view of its representative member, and the normal with those two
//! angles on that member's side), and channel weights n / √(Σσᵢ²) (the noise of the mean of
//! the members' values). Pixels near the mirror configuration (the specular highlight, where the lobe
//! changes by its whole height across a cell) are kept as they are.
//!
//! The price of a cell is the model's curvature inside it: to second order the mean of the model
//! over a cell differs from the model at its mean (θ, φ) by ½ tr(H C) (H: the model's Hessian in
//! (θ, φ), C: the covariance of the members' angles). [`Pooled::shift`] turns those biases into
//! the parameter shift they cause, (JᵀJ)⁻¹ Jᵀ b, in units of each parameter's standard error:
//! that is how the solver chooses a level.

use crate::model::{Geometry, Model, Params, N_PARAMS};
use crate::solver::Obs;
use nalgebra::{DMatrix, DVector, Vector3};
use rayon::prelude::*;
use std::collections::HashMap;

/// Width of the fine cells (radians): 0.25°.
pub const BASE_WIDTH: f64 = 0.25 * std::f64::consts::PI / 180.0;
/// The reduction levels offered, as multiples of [`BASE_WIDTH`] (0.25° to 4°).
pub const FACTORS: [u32; 5] = [1, 2, 4, 8, 16];

/// Sufficient statistics of one cell.
#[derive(Clone, Copy, Debug)]
pub struct Cell {
    pub sphere: usize,
    /// (θ bin, φ bin, side) at the cell's own width.
    pub key: (i64, i64, bool),
    pub n: f64,
    pub sum: [f64; 3],
    /// Σσ² of the members' noise per channel (σ = 1/weight; 0 weight: left out).
    pub sum_var: [f64; 3],
    /// Σθ, Σφ, Σθ², Σφ², Σθφ.
    pub moments: [f64; 5],
    /// The member nearest the cell centre, and its squared angular distance to it.
    pub rep: Obs,
    rep_d2: f64,
}

impl Cell {
    fn mean(&self) -> (f64, f64) {
        (self.moments[0] / self.n, self.moments[1] / self.n)
    }

    /// Covariance of the members' (θ, φ): [var θ, var φ, cov].
    pub fn covariance(&self) -> [f64; 3] {
        let (mt, mp) = self.mean();
        let m = &self.moments;
        [
            (m[2] / self.n - mt * mt).max(0.0),
            (m[3] / self.n - mp * mp).max(0.0),
            m[4] / self.n - mt * mp,
        ]
    }

    fn absorb(&mut self, o: &Cell) {
        self.n += o.n;
        for c in 0..3 {
            self.sum[c] += o.sum[c];
            self.sum_var[c] += o.sum_var[c];
        }
        for k in 0..5 {
            self.moments[k] += o.moments[k];
        }
        if o.rep_d2 < self.rep_d2 {
            self.rep = o.rep;
            self.rep_d2 = o.rep_d2;
        }
    }
}

/// Pixels pooled in fine cells, with the highlight pixels kept apart.
#[derive(Clone, Debug)]
pub struct Pooled {
    pub light: Vector3<f64>,
    /// Pixels within this angle (radians) of the mirror configuration are kept as they are.
    pub keep: f64,
    pub cells: Vec<Cell>,
    pub kept: Vec<Obs>,
    /// Pixels added.
    pub pixels: usize,
}

fn angles(g: &Geometry, light: &Vector3<f64>) -> (f64, f64, bool) {
    (
        g.normal.dot(light).clamp(-1.0, 1.0).acos(),
        g.normal.dot(&g.view).clamp(-1.0, 1.0).acos(),
        g.normal.dot(&g.view.cross(light)) >= 0.0,
    )
}

impl Pooled {
    /// Pool the observations of one sphere after another (`sphere` numbers them).
    pub fn new(light: Vector3<f64>, keep: f64) -> Pooled {
        Pooled {
            light,
            keep,
            cells: vec![],
            kept: vec![],
            pixels: 0,
        }
    }

    /// Add one sphere's pixels.
    pub fn add_sphere(&mut self, sphere: usize, obs: &[Obs]) {
        let mut map: HashMap<(i64, i64, bool), Cell> = HashMap::new();
        let w = BASE_WIDTH;
        for o in obs {
            self.pixels += 1;
            let g = &o.geometry;
            let h = (self.light + g.view).normalize();
            if g.normal.dot(&h).clamp(-1.0, 1.0).acos() < self.keep {
                self.kept.push(*o);
                continue;
            }
            let (t, p, side) = angles(g, &self.light);
            let key = ((t / w).floor() as i64, (p / w).floor() as i64, side);
            let d2 =
                (t - (key.0 as f64 + 0.5) * w).powi(2) + (p - (key.1 as f64 + 0.5) * w).powi(2);
            let c = map.entry(key).or_insert(Cell {
                sphere,
                key,
                n: 0.0,
                sum: [0.0; 3],
                sum_var: [0.0; 3],
                moments: [0.0; 5],
                rep: *o,
                rep_d2: f64::INFINITY,
            });
            c.n += 1.0;
            for k in 0..3 {
                c.sum[k] += o.radiance[k];
                c.sum_var[k] += if o.weight[k] > 0.0 {
                    (o.weight[k] * o.weight[k]).recip()
                } else {
                    f64::INFINITY
                };
            }
            let m = &mut c.moments;
            m[0] += t;
            m[1] += p;
            m[2] += t * t;
            m[3] += p * p;
            m[4] += t * p;
            if d2 < c.rep_d2 {
                c.rep = *o;
                c.rep_d2 = d2;
            }
        }
        let mut cells: Vec<Cell> = map.into_values().collect();
        cells.sort_by_key(|c| c.key);
        self.cells.extend(cells);
    }

    /// The cells at `factor` × [`BASE_WIDTH`].
    pub fn merged(&self, factor: u32) -> Vec<Cell> {
        if factor <= 1 {
            return self.cells.clone();
        }
        let f = factor as i64;
        let mut map: HashMap<(usize, (i64, i64, bool)), Cell> = HashMap::new();
        for c in &self.cells {
            let key = (c.key.0.div_euclid(f), c.key.1.div_euclid(f), c.key.2);
            map.entry((c.sphere, key))
                .and_modify(|m| m.absorb(c))
                .or_insert(Cell { key, ..*c });
        }
        let mut v: Vec<Cell> = map.into_values().collect();
        v.sort_by_key(|c| (c.sphere, c.key));
        v
    }

    /// One observation per cell (and the kept pixels).
    pub fn observations(&self, cells: &[Cell]) -> Vec<Obs> {
        let mut out: Vec<Obs> = cells.iter().map(|c| self.virtual_obs(c)).collect();
        out.extend_from_slice(&self.kept);
        out
    }

    fn virtual_obs(&self, c: &Cell) -> Obs {
        let (mt, mp) = c.mean();
        let mut geometry = c.rep.geometry;
        if c.n > 1.0 {
            if let Some(n) =
                normal_with_angles(&geometry.view, &self.light, mt, mp, &geometry.normal)
            {
                geometry.normal = n;
            }
        }
        Obs {
            geometry,
            radiance: c.sum.map(|s| s / c.n),
            // The mean of n pixels of variances σᵢ²: variance Σσᵢ² / n².
            weight: c.sum_var.map(|v| {
                if v.is_finite() && v > 0.0 {
                    c.n / v.sqrt()
                } else {
                    0.0
                }
            }),
        }
    }

    /// The second-order bias of each cell's mean against the model at its virtual pixel
    /// (weighted, three per cell, then zeros for the kept pixels), for the given parameters.
    pub fn biases(&self, cells: &[Cell], model: &Model, p: &Params) -> Vec<f64> {
        let h = 0.25 * BASE_WIDTH;
        let mut b: Vec<f64> = cells
            .par_iter()
            .flat_map_iter(|c| {
                let o = self.virtual_obs(c);
                let [vt, vp, ct] = c.covariance();
                let (mt, mp) = c.mean();
                let g = o.geometry;
                let at = |dt: f64, dp: f64| -> [f64; 3] {
                    match normal_with_angles(&g.view, &self.light, mt + dt, mp + dp, &g.normal) {
                        Some(n) => model.radiance(p, &Geometry { normal: n, ..g }),
                        None => [f64::NAN; 3],
                    }
                };
                let f0 = at(0.0, 0.0);
                let (ftp, ftm, fpp, fpm) = (at(h, 0.0), at(-h, 0.0), at(0.0, h), at(0.0, -h));
                let (fpp2, fpm2, fmp2, fmm2) = (at(h, h), at(h, -h), at(-h, h), at(-h, -h));
                (0..3).map(move |k| {
                    let htt = (ftp[k] - 2.0 * f0[k] + ftm[k]) / (h * h);
                    let hpp = (fpp[k] - 2.0 * f0[k] + fpm[k]) / (h * h);
                    let htp = (fpp2[k] - fpm2[k] - fmp2[k] + fmm2[k]) / (4.0 * h * h);
                    let bias = 0.5 * (htt * vt + hpp * vp + 2.0 * htp * ct);
                    let v = bias * o.weight[k];
                    if v.is_finite() {
                        v
                    } else {
                        0.0
                    }
                })
            })
            .collect();
        b.extend(std::iter::repeat_n(0.0, 3 * self.kept.len()));
        b
    }

    /// The shift of the free parameters that pooling at `cells` causes, in units of their
    /// standard errors: (JᵀJ)⁻¹ Jᵀ b / σ, with J the weighted Jacobian at `p` and b the
    /// [`biases`](Self::biases). Returns the largest |shift| over the parameters (∞ when JᵀJ is
    /// singular).
    pub fn shift(&self, cells: &[Cell], model: &Model, p: &Params, free: [bool; N_PARAMS]) -> f64 {
        let obs = self.observations(cells);
        let problem = crate::solver::Problem {
            model: *model,
            obs: &obs,
            free,
            u: crate::solver::to_unbounded(&p.to_vec()),
            priors: vec![],
            history: None,
        };
        let (res, jac) = problem.evaluate(true);
        let Some(j) = jac else { return f64::INFINITY };
        let b = DVector::from_vec(self.biases(cells, model, p));
        let jtj: DMatrix<f64> = j.transpose() * &j;
        let Some(cov) = jtj.clone().try_inverse() else {
            return f64::INFINITY;
        };
        // Residual scale: weights are meant to be 1/σ, so σ² ≈ 1; use the measured one.
        let dof = res.len().saturating_sub(j.ncols()).max(1) as f64;
        let s2 = (res.norm_squared() / dof).max(1e-300);
        let d = &cov * (j.transpose() * b);
        (0..d.len())
            .map(|k| d[k].abs() / (s2 * cov[(k, k)]).sqrt())
            .fold(0.0, f64::max)
    }
}

/// The unit normal at angle θ from `light` and φ from `view`, on the side of the light–view plane
/// where `near` lies (`None` when the two directions are parallel).
pub fn normal_with_angles(
    view: &Vector3<f64>,
    light: &Vector3<f64>,
    theta: f64,
    phi: f64,
    near: &Vector3<f64>,
) -> Option<Vector3<f64>> {
    let w = view.dot(light);
    let s2 = 1.0 - w * w;
    if s2 < 1e-12 {
        return None;
    }
    let (ct, cp) = (theta.cos(), phi.cos());
    let a = (cp - w * ct) / s2;
    let b = (ct - w * cp) / s2;
    let e = view.cross(light) / s2.sqrt();
    let in_plane = view * a + light * b;
    let g = (1.0 - in_plane.norm_squared()).max(0.0).sqrt();
    let sign = if near.dot(&e) < 0.0 { -1.0 } else { 1.0 };
    Some((in_plane + e * (sign * g)).normalize())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn virtual_normal_has_the_asked_angles_on_the_asked_side() {
        let v = Vector3::new(0.1, -0.05, -1.0).normalize();
        let l = Vector3::new(0.8, -0.3, -0.5).normalize();
        let e = v.cross(&l);
        // Feasible pairs: |θ − φ| ≤ angle(v, l) ≈ 0.93 ≤ θ + φ.
        for (t, p) in [(0.5, 0.6), (1.2, 0.9), (0.7, 1.4)] {
            for side in [1.0, -1.0] {
                let n = normal_with_angles(&v, &l, t, p, &(e * side)).unwrap();
                assert!((n.norm() - 1.0).abs() < 1e-12);
                assert!((n.dot(&l).acos() - t).abs() < 1e-9, "θ");
                assert!((n.dot(&v).acos() - p).abs() < 1e-9, "φ");
                assert!(n.dot(&e) * side >= 0.0);
            }
        }
    }
}
