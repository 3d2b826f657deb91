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
//! changes by its whole height across a cell, and the (θ, φ) map is singular at the mirror point)
//! are pooled apart, in square blocks of pixels ([`Pooled::highlight_cells`]), which are as
//! smooth there as anywhere.
//!
//! The price of a cell is the model's curvature inside it: to second order the mean of the model
//! over a cell differs from the model at its mean (θ, φ) by ½ tr(H C) (H: the model's Hessian in
//! (θ, φ), C: the covariance of the members' angles). [`Pooled::shift`] turns those biases into
//! the parameter shift they cause, (JᵀJ)⁻¹ Jᵀ b, against each parameter's standard error and a
//! fixed tolerance: that is how the solver chooses a level.

use crate::fit::solver::Obs;
use crate::model::{Geometry, Model, Params, N_PARAMS};
use nalgebra::{DMatrix, DVector, Vector3};
use rayon::prelude::*;

/// Width of the fine cells (radians): 0.25°.
pub(crate) const BASE_WIDTH: f64 = 0.25 * std::f64::consts::PI / 180.0;
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
    /// Σn and Σnnᵀ (xx, yy, zz, xy, xz, yz) of the members' normals.
    pub normals: [f64; 9],
    /// A block of pixels (the highlight), not a (θ, φ) cell: its virtual pixel has the members'
    /// mean normal, and its curvature is taken in the tangent plane there.
    pub spatial: bool,
    /// The member nearest the cell centre, and its squared angular distance to it.
    pub rep: Obs,
    rep_d2: f64,
}

fn normal_moments(n: &Vector3<f64>) -> [f64; 9] {
    [
        n.x,
        n.y,
        n.z,
        n.x * n.x,
        n.y * n.y,
        n.z * n.z,
        n.x * n.y,
        n.x * n.z,
        n.y * n.z,
    ]
}

impl Cell {
    fn mean(&self) -> (f64, f64) {
        (self.moments[0] / self.n, self.moments[1] / self.n)
    }

    /// Covariance of the members' (θ, φ): [var θ, var φ, cov].
    pub(crate) fn covariance(&self) -> [f64; 3] {
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
        for k in 0..9 {
            self.normals[k] += o.normals[k];
        }
        if o.rep_d2 < self.rep_d2 {
            self.rep = o.rep;
            self.rep_d2 = o.rep_d2;
        }
    }
}

/// One sphere's observations and, when known, their pixel positions.
pub type SphereObs<'a> = (&'a [Obs], Option<&'a [[u32; 2]]>);

/// Pixels pooled in fine cells, with the highlight pixels kept apart.
#[derive(Clone, Debug)]
pub struct Pooled {
    pub light: Vector3<f64>,
    /// Pixels within this angle (radians) of the mirror configuration are kept as they are.
    pub keep: f64,
    pub cells: Vec<Cell>,
    /// The highlight pixels, as observations and as one-pixel cells (with their pixel position
    /// when known), for [`Pooled::highlight_cells`].
    pub kept: Vec<Obs>,
    kept_cells: Vec<(Cell, Option<[u32; 2]>)>,
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
            kept_cells: vec![],
            pixels: 0,
        }
    }

    /// Add one sphere's pixels (with their pixel positions, when known: the highlight is then
    /// pooled in square blocks of pixels by [`Pooled::highlight_cells`]).
    pub fn add_sphere(&mut self, sphere: usize, obs: &[Obs], px: Option<&[[u32; 2]]>) {
        let w = BASE_WIDTH;
        self.pixels += obs.len();
        let single = |o: &Obs, key: (i64, i64, bool), t: f64, p: f64, kept: bool, d2: f64| Cell {
            sphere,
            key,
            n: 1.0,
            sum: o.radiance,
            sum_var: o.weight.map(|w| {
                if w > 0.0 {
                    (w * w).recip()
                } else {
                    f64::INFINITY
                }
            }),
            moments: [t, p, t * t, p * p, t * p],
            normals: normal_moments(&o.geometry.normal),
            spatial: kept,
            rep: *o,
            rep_d2: d2,
        };
        // Per pixel, in parallel: its angles and cell (None: a highlight pixel); then the pixels
        // in cell order, accumulated run by run.
        type Keyed = (Option<(i64, i64, bool)>, f64, f64, bool);
        let keyed: Vec<Keyed> = obs
            .par_iter()
            .map(|o| {
                let g = &o.geometry;
                let h = (self.light + g.view).normalize();
                let (t, p, side) = angles(g, &self.light);
                if g.normal.dot(&h).clamp(-1.0, 1.0).acos() < self.keep {
                    (None, t, p, side)
                } else {
                    (
                        Some(((t / w).floor() as i64, (p / w).floor() as i64, side)),
                        t,
                        p,
                        side,
                    )
                }
            })
            .collect();
        let mut order: Vec<((i64, i64, bool), u32)> = keyed
            .iter()
            .enumerate()
            .filter_map(|(i, k)| k.0.map(|key| (key, i as u32)))
            .collect();
        order.par_sort_unstable();
        for (i, k) in keyed.iter().enumerate() {
            if k.0.is_none() {
                let o = &obs[i];
                self.kept.push(*o);
                self.kept_cells.push((
                    single(o, (0, 0, k.3), k.1, k.2, true, 0.0),
                    px.map(|v| v[i]),
                ));
            }
        }
        let mut cells: Vec<Cell> = vec![];
        for (key, i) in order {
            let (o, (_, t, p, _)) = (&obs[i as usize], keyed[i as usize]);
            let d2 =
                (t - (key.0 as f64 + 0.5) * w).powi(2) + (p - (key.1 as f64 + 0.5) * w).powi(2);
            let c = single(o, key, t, p, false, d2);
            match cells.last_mut() {
                Some(last) if last.key == key => last.absorb(&c),
                _ => cells.push(c),
            }
        }
        self.cells.extend(cells);
    }

    /// Pool the spheres' pixels (sphere k: `obs[k]`, with its pixel positions) in parallel.
    pub(crate) fn of_spheres(light: Vector3<f64>, keep: f64, spheres: &[SphereObs]) -> Pooled {
        let parts: Vec<Pooled> = spheres
            .par_iter()
            .enumerate()
            .map(|(k, (obs, px))| {
                let mut p = Pooled::new(light, keep);
                p.add_sphere(k, obs, *px);
                p
            })
            .collect();
        let mut out = Pooled::new(light, keep);
        for p in parts {
            out.pixels += p.pixels;
            out.cells.extend(p.cells);
            out.kept.extend(p.kept);
            out.kept_cells.extend(p.kept_cells);
        }
        out
    }

    /// The cells at every level of [`FACTORS`], each merged from the next finer one.
    pub(crate) fn pyramid(&self) -> Vec<(u32, Vec<Cell>)> {
        let mut out: Vec<(u32, Vec<Cell>)> = vec![(1, self.cells.clone())];
        for &f in &FACTORS[1..] {
            let (pf, prev) = out.last().expect("a level");
            let r = (f / pf) as i64;
            let next = group(prev, |c| {
                (c.key.0.div_euclid(r), c.key.1.div_euclid(r), c.key.2)
            });
            out.push((f, next));
        }
        out
    }

    /// The cells at `factor` × [`BASE_WIDTH`].
    pub fn merged(&self, factor: u32) -> Vec<Cell> {
        if factor <= 1 {
            return self.cells.clone();
        }
        let f = factor as i64;
        group(&self.cells, |c| {
            (c.key.0.div_euclid(f), c.key.1.div_euclid(f), c.key.2)
        })
    }

    /// The highlight pixels pooled in `block` × `block` pixel squares per sphere and side of the
    /// light–view plane (1: one cell a pixel). Pixels without a known position stay single.
    pub fn highlight_cells(&self, block: u32) -> Vec<Cell> {
        if block <= 1 {
            return self.kept_cells.iter().map(|(c, _)| *c).collect();
        }
        let b = block as i64;
        let mut blocks = vec![];
        let mut single = vec![];
        for (c, px) in &self.kept_cells {
            match px {
                Some([x, y]) => blocks.push(Cell {
                    key: (*x as i64 / b, *y as i64 / b, c.key.2),
                    ..*c
                }),
                None => single.push(*c),
            }
        }
        let mut v = group(&blocks, |c| c.key);
        v.extend(single);
        v
    }

    /// One observation per cell.
    pub fn observations(&self, cells: &[Cell]) -> Vec<Obs> {
        cells.iter().map(|c| self.virtual_obs(c)).collect()
    }

    fn virtual_obs(&self, c: &Cell) -> Obs {
        let (mt, mp) = c.mean();
        let mut geometry = c.rep.geometry;
        if c.n > 1.0 {
            if c.spatial {
                let m = Vector3::new(c.normals[0], c.normals[1], c.normals[2]);
                if m.norm() > 0.0 {
                    geometry.normal = m.normalize();
                }
            } else if let Some(n) =
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
    /// (weighted, three per cell), for the given parameters.
    pub(crate) fn biases(&self, cells: &[Cell], model: &Model, p: &Params) -> Vec<f64> {
        let h = 0.25 * BASE_WIDTH;
        let b: Vec<f64> = cells
            .par_iter()
            .flat_map_iter(|c| {
                let o = self.virtual_obs(c);
                let g = o.geometry;
                // The cell's two coordinates, their covariance and the normal at a point.
                let (mt, mp) = c.mean();
                let (t1, t2) = crate::camera::outline::tangent_basis(&g.normal);
                let [vt, vp, ct] = if c.spatial {
                    let k = c.n;
                    let nm = &c.normals;
                    let mean = Vector3::new(nm[0], nm[1], nm[2]) / k;
                    let second = nalgebra::Matrix3::new(
                        nm[3], nm[6], nm[7], nm[6], nm[4], nm[8], nm[7], nm[8], nm[5],
                    ) / k;
                    let cov = second - mean * mean.transpose();
                    [
                        t1.dot(&(cov * t1)).max(0.0),
                        t2.dot(&(cov * t2)).max(0.0),
                        t1.dot(&(cov * t2)),
                    ]
                } else {
                    c.covariance()
                };
                let at = |dt: f64, dp: f64| -> [f64; 3] {
                    let n = if c.spatial {
                        Some((g.normal + t1 * dt + t2 * dp).normalize())
                    } else {
                        normal_with_angles(&g.view, &self.light, mt + dt, mp + dp, &g.normal)
                    };
                    match n {
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
        b
    }

    /// The shift of the free parameters that pooling at `cells` causes: d = (JᵀJ)⁻¹ Jᵀ b, with J
    /// the weighted Jacobian at `p` and b the [`biases`](Self::biases), against each parameter's
    /// standard error σ(JᵀJ)⁻¹ᐟ². `cells` and `extra` together are all the observations' cells
    /// (e.g. the (θ, φ) cells and the highlight's). Sums over cells are estimated from every k-th cell when there are more than
    /// [`SHIFT_CELLS`]: d does not change with k, the standard errors shrink by √k.
    pub fn shift(
        &self,
        cells: &[Cell],
        extra: &[Cell],
        model: &Model,
        p: &Params,
        free: [bool; N_PARAMS],
    ) -> Shift {
        let k = (cells.len() + extra.len()).div_ceil(SHIFT_CELLS).max(1);
        let sub: Vec<Cell> = cells.iter().chain(extra).step_by(k).cloned().collect();
        let obs: Vec<Obs> = sub.iter().map(|c| self.virtual_obs(c)).collect();
        let problem = crate::fit::solver::Problem {
            model: *model,
            obs: &obs,
            free,
            u: crate::fit::solver::to_unbounded(&p.to_vec()),
            priors: vec![],
            history: None,
            floor: false,
        };
        let idx: Vec<usize> = (0..N_PARAMS).filter(|&i| free[i]).collect();
        let none = Shift {
            max_std: f64::INFINITY,
            within_tolerance: false,
            limiting: None,
            params: idx.clone(),
            shift: vec![f64::INFINITY; idx.len()],
            std: vec![0.0; idx.len()],
        };
        let (res, jac) = problem.evaluate(true);
        let Some(j) = jac else { return none };
        let b = DVector::from_vec(self.biases(&sub, model, p));
        let jtj: DMatrix<f64> = j.transpose() * &j;
        let Some(cov) = jtj.try_inverse() else {
            return none;
        };
        // Residual scale: weights are meant to be 1/σ, so σ² ≈ 1; use the measured one.
        let dof = res.len().saturating_sub(j.ncols()).max(1) as f64;
        let s2 = (res.norm_squared() / dof).max(1e-300);
        let d = &cov * (j.transpose() * b);
        let std: Vec<f64> = (0..d.len())
            .map(|i| (s2 * cov[(i, i)] / k as f64).sqrt())
            .collect();
        let max_std = (0..d.len())
            .map(|i| d[i].abs() / std[i])
            .fold(0.0, f64::max);
        // Each shift against what is accepted for its parameter.
        let worst = idx
            .iter()
            .enumerate()
            .map(|(i, &q)| (q, d[i].abs() / tolerance(q).max(SHIFT_STD * std[i])))
            .max_by(|a, b| a.1.total_cmp(&b.1));
        Shift {
            max_std,
            within_tolerance: worst.is_none_or(|w| w.1 <= 1.0),
            limiting: worst.map(|w| w.0),
            params: idx,
            shift: d.iter().cloned().collect(),
            std,
        }
    }
}

/// Cells used to estimate a level's shift (every k-th beyond this many).
pub(crate) const SHIFT_CELLS: usize = 10_000;
/// A shift of this many standard errors is accepted.
pub(crate) const SHIFT_STD: f64 = 0.3;

/// The shift of a parameter (in the solver's unbounded units) that is accepted whatever its
/// standard error, a tenth or less of the accuracy the rest of the chain reaches (README,
/// "Solve: measured"): 0.1% of σ0, albedo and α; 1% of ks (whose accuracy is bounded by F(η)
/// with η at its prior: 2–5%); 0.5% of η − 1 (0.002 in η); 0.005° of the light angles; 0.001 of
/// the extensions.
pub fn tolerance(param: usize) -> f64 {
    use crate::model::idx;
    match param {
        idx::AZIMUTH | idx::ELEVATION => 0.005f64.to_radians(),
        idx::ETA => 5e-3,
        idx::KS => 1e-2,
        _ => 1e-3,
    }
}

/// What pooling at a level is predicted to do to the fit.
#[derive(Clone, Debug, PartialEq)]
pub struct Shift {
    /// The largest |shift| in standard errors.
    pub max_std: f64,
    /// Every parameter's shift is below [`SHIFT_STD`] standard errors or below its
    /// [`tolerance`].
    pub within_tolerance: bool,
    /// The parameter whose shift is largest against what is accepted for it.
    pub limiting: Option<usize>,
    /// Free parameters (model indices), their shifts and standard errors (unbounded units).
    pub params: Vec<usize>,
    pub shift: Vec<f64>,
    pub std: Vec<f64>,
}

/// Merge cells with the same sphere and `key` (sorted by them): an index sort and one pass; only
/// the merged cells are copied.
fn group(cells: &[Cell], key: impl Fn(&Cell) -> (i64, i64, bool) + Sync) -> Vec<Cell> {
    let mut order: Vec<(usize, (i64, i64, bool), u32)> = cells
        .par_iter()
        .enumerate()
        .map(|(i, c)| (c.sphere, key(c), i as u32))
        .collect();
    order.par_sort_unstable();
    let mut out: Vec<Cell> = Vec::new();
    let mut last_key = None;
    for (sphere, k, i) in order {
        let c = &cells[i as usize];
        if last_key == Some((sphere, k)) {
            out.last_mut().expect("a cell").absorb(c);
        } else {
            out.push(Cell { key: k, ..*c });
            last_key = Some((sphere, k));
        }
    }
    out
}

/// The unit normal at angle θ from `light` and φ from `view`, on the side of the light–view plane
/// where `near` lies (`None` when the two directions are parallel).
pub(crate) fn normal_with_angles(
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
