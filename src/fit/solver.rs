//! The core of the joint fit: Levenberg–Marquardt (crate `levenberg-marquardt`) over the model's
//! parameters, mapped so that the solver cannot leave their physical range, with the Jacobian
//! from the model's analytic gradient, and standard errors and correlations from σ²(JᵀJ)⁻¹.
//!
//! Unbounded parameters u: ln σ0 (×3), ln albedo (×3), ln(η − 1), ln ks, ln α, and the light's
//! azimuth and elevation as they are, the model extensions q and b as they are, the kernel's
//! weight as logit w = ln(w / (1 − w)) and its width ratio as ln(s − 1). Parameters not free
//! are held at their given value; a [`Prior`] adds a residual (p − mean)/std.
//!
//! The photos' dark floor (a constant per channel added to every pixel: the sensor's black level
//! and stray light) can be left unknown ([`Problem::floor`]). It enters linearly with the fixed
//! Jacobian column w (the channel's weights), so it is profiled out exactly (variable
//! projection): each channel's residuals and Jacobian rows lose their w-weighted projection on w,
//! r̃ = r − w (wᵀr)/(wᵀw) and J̃ = J − w (wᵀJ)/(wᵀw). The fit of the other parameters and their
//! covariance (J̃ᵀJ̃ is the Schur complement of the floor in the full information matrix) are then
//! those of the fit with the floor free; the floor itself is −(wᵀr)/(wᵀw) (docs/pipeline.md, "The
//! dark floor").

use crate::model::lanes::{f64x4, Real};
use crate::model::{idx, Geometry, Gradient, Lanes4, Model, Params, Prepared, Rgb, N_PARAMS};
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
    // The kernel: w = 0 (one Gaussian) maps below −MAP_LIMIT and back to exactly 0; a ratio of
    // 1 or less (unused while w = 0) to the bottom of its range.
    let w = p[idx::KERNEL_WEIGHT];
    u[idx::KERNEL_WEIGHT] = if w > 0.0 {
        (w / (1.0 - w)).ln()
    } else {
        -2.0 * MAP_LIMIT
    };
    let s = p[idx::KERNEL_RATIO];
    u[idx::KERNEL_RATIO] = if s > 1.0 { (s - 1.0).ln() } else { -MAP_LIMIT };
    u
}

/// Unbounded parameters → physical ones, with dp/du (the mapping is diagonal).
pub fn from_unbounded(u: &[f64; N_PARAMS]) -> ([f64; N_PARAMS], [f64; N_PARAMS]) {
    let mut p = *u;
    let mut d = [1.0; N_PARAMS];
    for k in 0..9 {
        // Clamped: a degenerate fit that runs off to ±∞ stays finite (and is flagged by its
        // standard errors) instead of overflowing.
        let e = u[k].clamp(-MAP_LIMIT, MAP_LIMIT).exp();
        p[k] = if k == 6 { 1.0 + e } else { e };
        d[k] = if u[k].abs() < MAP_LIMIT { e } else { 0.0 };
    }
    let uw = u[idx::KERNEL_WEIGHT];
    if uw <= -MAP_LIMIT {
        p[idx::KERNEL_WEIGHT] = 0.0;
        d[idx::KERNEL_WEIGHT] = 0.0;
    } else {
        let w = 1.0 / (1.0 + (-uw.min(MAP_LIMIT)).exp());
        p[idx::KERNEL_WEIGHT] = w;
        d[idx::KERNEL_WEIGHT] = w * (1.0 - w);
    }
    let us = u[idx::KERNEL_RATIO];
    let e = us.clamp(-MAP_LIMIT, MAP_LIMIT).exp();
    p[idx::KERNEL_RATIO] = 1.0 + e;
    d[idx::KERNEL_RATIO] = if us.abs() < MAP_LIMIT { e } else { 0.0 };
    (p, d)
}

/// Bound of the unbounded (log) coordinates: e^±60 ≈ 10^±26.
pub(crate) const MAP_LIMIT: f64 = 60.0;

/// A Gaussian prior on one parameter (physical units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prior {
    pub index: usize,
    pub mean: f64,
    pub std: f64,
}

/// The least-squares problem over the free parameters.
pub struct Problem<'a> {
    pub model: Model,
    pub obs: &'a [Obs],
    /// Which parameters are fitted (in model index order).
    pub free: [bool; N_PARAMS],
    /// Current unbounded values of all parameters.
    pub u: [f64; N_PARAMS],
    /// Priors on free parameters (one residual each, after the observations').
    pub priors: Vec<Prior>,
    /// When set, the cost ½Σr² of every residual evaluation (trial steps included) is recorded.
    pub history: Option<std::sync::Mutex<Vec<f64>>>,
    /// The observations carry an unknown dark floor per channel (profiled out; module doc).
    pub floor: bool,
}

/// One evaluation of the solver's kernel: the normal equations JᵀJ, Jᵀr of `obs` at `params`
/// with the parameters in `free` fitted (no priors, no dark floor), accumulated in parallel.
pub fn normal_equations(
    model: Model,
    obs: &[Obs],
    params: &Params,
    free: [bool; N_PARAMS],
) -> Normal {
    Problem {
        model,
        obs,
        free,
        u: to_unbounded(&params.to_vec()),
        priors: vec![],
        history: None,
        floor: false,
    }
    .normal_equations()
}

/// The dark floor per channel as profiled out of a fit: its value (the observations' units) and
/// standard error.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Floor {
    pub value: [f64; 3],
    pub std: [f64; 3],
}

/// Per channel: Σw², Σw·r and Σw·g (g the weighted Jacobian row) over the observation rows.
#[derive(Clone, Debug)]
struct FloorSums {
    ww: [f64; 3],
    wr: [f64; 3],
    wg: [DVector<f64>; 3],
}

impl FloorSums {
    fn zero(n: usize) -> FloorSums {
        FloorSums {
            ww: [0.0; 3],
            wr: [0.0; 3],
            wg: std::array::from_fn(|_| DVector::zeros(n)),
        }
    }

    fn add(mut self, o: &FloorSums) -> FloorSums {
        for c in 0..3 {
            self.ww[c] += o.ww[c];
            self.wr[c] += o.wr[c];
            self.wg[c] += &o.wg[c];
        }
        self
    }

    /// The floor that minimises the cost, and its Jacobian row (with respect to the free
    /// parameters) per channel: f = −(wᵀr)/(wᵀw), ∂f = −(wᵀJ)/(wᵀw).
    fn solve(&self) -> ([f64; 3], [DVector<f64>; 3]) {
        let inv = self.ww.map(|w| if w > 0.0 { 1.0 / w } else { 0.0 });
        (
            [0, 1, 2].map(|c| -self.wr[c] * inv[c]),
            std::array::from_fn(|c| -&self.wg[c] * inv[c]),
        )
    }
}

/// The most parameters one channel's residual depends on: all but the other channels' σ0 and
/// albedo.
const MAX_ROW: usize = N_PARAMS - 4;

/// The channel a parameter belongs to alone (σ0 and albedo), if any.
fn channel_exclusive(k: usize) -> Option<usize> {
    match k {
        idx::SIGMA0..=2 => Some(k - idx::SIGMA0),
        idx::ALBEDO..=5 => Some(k - idx::ALBEDO),
        _ => None,
    }
}

/// One chunk's normal equations per channel over that channel's own parameters (the lower
/// triangle, row-major with stride [`MAX_ROW`]), scattered into the free parameters' matrix once
/// per chunk: a channel's row has at most [`MAX_ROW`] non-zeros, so this is half the work of the
/// dense product, on fixed-size arrays. Generic over [`Real`]: on `f64` one observation at a
/// time, on [`f64x4`] four (one a lane), their lanes summed when the chunk is scattered.
#[derive(Clone, Copy)]
struct ChunkSums<T> {
    a: [[T; MAX_ROW * MAX_ROW]; 3],
    b: [[T; MAX_ROW]; 3],
    rr: T,
    ww: [T; 3],
    wr: [T; 3],
    wg: [[T; MAX_ROW]; 3],
}

impl<T: Real> ChunkSums<T> {
    fn new() -> ChunkSums<T> {
        let z = T::splat(0.0);
        ChunkSums {
            a: [[z; MAX_ROW * MAX_ROW]; 3],
            b: [[z; MAX_ROW]; 3],
            rr: z,
            ww: [z; 3],
            wr: [z; 3],
            wg: [[z; MAX_ROW]; 3],
        }
    }

    /// One residual r of channel `ch` with its Jacobian row g (that channel's parameters) and
    /// weight w.
    #[inline(always)]
    fn add(&mut self, ch: usize, g: &[T], r: T, w: T, floor: bool) {
        let (a, b) = (&mut self.a[ch], &mut self.b[ch]);
        for (i, &gi) in g.iter().enumerate() {
            b[i] = b[i] + gi * r;
            let row = &mut a[i * MAX_ROW..i * MAX_ROW + i + 1];
            for (s, &gj) in row.iter_mut().zip(&g[..=i]) {
                *s = *s + gi * gj;
            }
        }
        self.rr = self.rr + r * r;
        if floor {
            self.ww[ch] = self.ww[ch] + w * w;
            self.wr[ch] = self.wr[ch] + w * r;
            for (s, &gi) in self.wg[ch].iter_mut().zip(g) {
                *s = *s + w * gi;
            }
        }
    }

    /// Every entry summed over its lanes into `into`.
    fn fold_into(&self, into: &mut ChunkSums<f64>) {
        let sum = |v: T| (0..T::LANES).map(|k| v.lane(k)).sum::<f64>();
        for c in 0..3 {
            for (s, &v) in into.a[c].iter_mut().zip(&self.a[c]) {
                *s += sum(v);
            }
            for (s, &v) in into.b[c].iter_mut().zip(&self.b[c]) {
                *s += sum(v);
            }
            for (s, &v) in into.wg[c].iter_mut().zip(&self.wg[c]) {
                *s += sum(v);
            }
            into.ww[c] += sum(self.ww[c]);
            into.wr[c] += sum(self.wr[c]);
        }
        into.rr += sum(self.rr);
    }
}

impl ChunkSums<f64> {
    /// Into the free parameters' raw normal equations (JᵀJ's lower triangle).
    fn scatter(&self, layout: &[Vec<(usize, usize)>; 3], n: usize, floor: bool) -> RawNormal {
        let mut jtj = DMatrix::<f64>::zeros(n, n);
        let mut jtr = DVector::<f64>::zeros(n);
        let mut fs = FloorSums::zero(if floor { n } else { 0 });
        for (c, cols) in layout.iter().enumerate() {
            for (i, &(pi, _)) in cols.iter().enumerate() {
                jtr[pi] += self.b[c][i];
                for (j, &(pj, _)) in cols[..=i].iter().enumerate() {
                    jtj[(pi, pj)] += self.a[c][i * MAX_ROW + j];
                }
                if floor {
                    fs.wg[c][pi] += self.wg[c][i];
                }
            }
            fs.ww[c] = self.ww[c];
            fs.wr[c] = self.wr[c];
        }
        RawNormal {
            jtj,
            jtr,
            rtr: self.rr,
            floor: fs,
        }
    }
}

/// A group's sums within one chunk: observations taken one at a time, and four at a time where
/// the model evaluates them in lanes ([`Prepared::radiance_with_gradient_x4`]).
struct GroupSums {
    one: ChunkSums<f64>,
    four: Option<Box<ChunkSums<f64x4>>>,
}

impl GroupSums {
    fn new() -> GroupSums {
        GroupSums {
            one: ChunkSums::new(),
            four: None,
        }
    }

    fn scatter(mut self, layout: &[Vec<(usize, usize)>; 3], n: usize, floor: bool) -> RawNormal {
        if let Some(four) = &self.four {
            four.fold_into(&mut self.one);
        }
        self.one.scatter(layout, n, floor)
    }
}

/// What the kernel needs of the free parameters per channel: each row entry's model parameter
/// (`cols`) and dp/du (`scale`), and the row's length.
struct RowLayout {
    cols: [[usize; MAX_ROW]; 3],
    scale: [[f64; MAX_ROW]; 3],
    len: [usize; 3],
}

impl RowLayout {
    /// Channel `ch`'s weighted Jacobian row (the free parameters it depends on) from the model's
    /// gradient, into `g`; its length.
    #[inline(always)]
    fn row<T: Real>(&self, ch: usize, w: T, grad: &[T; N_PARAMS], g: &mut [T; MAX_ROW]) -> usize {
        let m = self.len[ch];
        for i in 0..m {
            g[i] = w * grad[self.cols[ch][i]] * self.scale[ch][i];
        }
        m
    }
}

impl Problem<'_> {
    /// The model at `params` for this problem's observations (the light's frame and the CDRF
    /// table's slices at their radii, computed once per evaluation).
    fn prepared(&self, params: &Params) -> Prepared {
        self.model
            .prepare(params, self.obs.iter().map(|o| o.geometry.radius_mm))
    }

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
        let prepared = self.prepared(&params);
        let free = self.free_idx();
        let n = free.len();
        let row = |o: &Obs, l: &Rgb, g: &Gradient| {
            let r = [0, 1, 2].map(|c| o.weight[c] * (l[c] - o.radiance[c]));
            let mut j = vec![];
            if want_jacobian {
                j.reserve(3 * n);
                for (w, gc) in o.weight.iter().zip(g) {
                    for &k in &free {
                        j.push(w * gc[k] * dpdu[k]);
                    }
                }
            }
            (r, j)
        };
        let rows: Vec<([f64; 3], Vec<f64>)> = self
            .obs
            .par_chunks(CHUNK)
            .flat_map_iter(|chunk| {
                let mut rows = Vec::with_capacity(chunk.len());
                each_model(&prepared, chunk, |o, l, g| rows.push(row(o, l, g)));
                rows
            })
            .collect();
        // The floor profiled out: each channel's rows lose their projection on its weights.
        let rows = if self.floor {
            let mut sums = FloorSums::zero(n);
            for ((r, j), o) in rows.iter().zip(self.obs) {
                for c in 0..3 {
                    let w = o.weight[c];
                    sums.ww[c] += w * w;
                    sums.wr[c] += w * r[c];
                    if want_jacobian {
                        for i in 0..n {
                            sums.wg[c][i] += w * j[c * n + i];
                        }
                    }
                }
            }
            let (f, df) = sums.solve();
            rows.into_iter()
                .zip(self.obs)
                .map(|((mut r, mut j), o)| {
                    for c in 0..3 {
                        r[c] += o.weight[c] * f[c];
                        if want_jacobian {
                            for i in 0..n {
                                j[c * n + i] += o.weight[c] * df[c][i];
                            }
                        }
                    }
                    (r, j)
                })
                .collect()
        } else {
            rows
        };
        let priors: Vec<&Prior> = self.priors.iter().filter(|q| self.free[q.index]).collect();
        let m = 3 * self.obs.len() + priors.len();
        let prior_res = priors.iter().map(|q| (p[q.index] - q.mean) / q.std);
        let res = DVector::from_iterator(
            m,
            rows.iter()
                .flat_map(|(r, _)| r.iter().cloned())
                .chain(prior_res),
        );
        let jac = want_jacobian.then(|| {
            let prior_rows = priors.iter().flat_map(|q| {
                free.iter()
                    .map(move |&k| if k == q.index { dpdu[k] / q.std } else { 0.0 })
            });
            DMatrix::from_row_iterator(
                m,
                n,
                rows.iter()
                    .flat_map(|(_, j)| j.iter().cloned())
                    .chain(prior_rows),
            )
        });
        (res, jac)
    }
}

impl Problem<'_> {
    /// Standard errors (physical units, 0 for parameters not free) and the correlation matrix of
    /// the free parameters at the current values, from σ²(JᵀJ)⁻¹ with σ² = 2·cost/(m − n) over
    /// the observation rows (the prior rows are already in units of their σ); the cost ½Σr² of
    /// the observations; and the dark floor when it is profiled out: its value
    /// f = −(wᵀr)/(wᵀw) per channel and its standard error from σ²/(wᵀw) + ḡᵀCḡ, with
    /// ḡ = (wᵀJ)/(wᵀw) and C the other parameters' covariance (the two parts are uncorrelated:
    /// the parameters are fitted to residuals orthogonal to w).
    pub(crate) fn covariance_and_floor(
        &self,
    ) -> ([f64; N_PARAMS], DMatrix<f64>, f64, Option<Floor>) {
        let dpdu = from_unbounded(&self.u).1;
        let idx = self.free_idx();
        let n = idx.len();
        let m_obs = 3 * self.obs.len();
        // The prior rows' part of JᵀJ, to be left unscaled.
        let mut prior_part = DMatrix::zeros(n, n);
        for q in self.priors.iter().filter(|q| self.free[q.index]) {
            let i = idx.iter().position(|&k| k == q.index).expect("free");
            prior_part[(i, i)] += (dpdu[q.index] / q.std).powi(2);
        }
        let ne = self.normal_equations();
        let cost = 0.5 * ne.rtr_obs;
        let fitted = n + if self.floor { 3 } else { 0 };
        let sigma2 = (2.0 * cost / (m_obs.saturating_sub(fitted).max(1)) as f64).max(1e-300);
        let info = (&ne.jtj - &prior_part) / sigma2 + &prior_part;
        let mut std = [0.0; N_PARAMS];
        let mut correlation = DMatrix::zeros(n, n);
        let cov = ne.finite.then(|| info.try_inverse()).flatten();
        let floor = ne.floor.as_ref().map(|sums| {
            let (value, _) = sums.solve();
            let std = [0, 1, 2].map(|c| {
                if sums.ww[c] <= 0.0 {
                    return f64::INFINITY;
                }
                let g = &sums.wg[c] / sums.ww[c];
                let spread = match &cov {
                    Some(cv) => (g.transpose() * cv * &g)[(0, 0)],
                    None if n == 0 => 0.0,
                    None => f64::INFINITY,
                };
                (sigma2 / sums.ww[c] + spread.max(0.0)).sqrt()
            });
            Floor { value, std }
        });
        if let Some(cov) = cov {
            for (a, &k) in idx.iter().enumerate() {
                // Unbounded → physical: σ_p = |dp/du| σ_u.
                std[k] = cov[(a, a)].max(0.0).sqrt() * dpdu[k].abs();
                for b in 0..n {
                    correlation[(a, b)] = cov[(a, b)] / (cov[(a, a)] * cov[(b, b)]).sqrt();
                }
            }
        } else {
            for &k in &idx {
                std[k] = f64::INFINITY;
            }
        }
        (std, correlation, cost, floor)
    }
}

/// The normal equations of the weighted problem: JᵀJ, Jᵀr and rᵀr (observations and priors).
#[derive(Clone, Debug)]
pub struct Normal {
    pub jtj: DMatrix<f64>,
    pub jtr: DVector<f64>,
    /// rᵀr of the observation rows and of the prior rows.
    pub rtr_obs: f64,
    pub rtr_prior: f64,
    pub finite: bool,
    /// With the floor free: the per-channel sums it was profiled out with (r and J without it).
    floor: Option<FloorSums>,
}

/// The normal equations of a set of observation rows before the dark floor is profiled out and
/// before the priors: JᵀJ (full, symmetric), Jᵀr, rᵀr and the floor's sums. Sums of disjoint sets
/// add ([`RawNormal::plus`]) and subtract ([`RawNormal::less`]): the normal equations of the
/// observations less one group are the totals less the group's.
#[derive(Clone, Debug)]
pub struct RawNormal {
    jtj: DMatrix<f64>,
    jtr: DVector<f64>,
    rtr: f64,
    floor: FloorSums,
}

impl RawNormal {
    /// The sums of all the parts.
    pub fn sum(parts: &[RawNormal]) -> Option<RawNormal> {
        let (first, rest) = parts.split_first()?;
        Some(rest.iter().fold(first.clone(), |a, b| a.plus(b)))
    }

    fn zero(n: usize, floor: bool) -> RawNormal {
        RawNormal {
            jtj: DMatrix::zeros(n, n),
            jtr: DVector::zeros(n),
            rtr: 0.0,
            floor: FloorSums::zero(if floor { n } else { 0 }),
        }
    }

    /// The sums of both sets.
    pub fn plus(mut self, o: &RawNormal) -> RawNormal {
        self.jtj += &o.jtj;
        self.jtr += &o.jtr;
        self.rtr += o.rtr;
        self.floor = self.floor.add(&o.floor);
        self
    }

    /// The sums of this set without `o` (a subset of it).
    pub fn less(&self, o: &RawNormal) -> RawNormal {
        let mut floor = self.floor.clone();
        for c in 0..3 {
            floor.ww[c] -= o.floor.ww[c];
            floor.wr[c] -= o.floor.wr[c];
            if !floor.wg[c].is_empty() {
                floor.wg[c] -= &o.floor.wg[c];
            }
        }
        RawNormal {
            jtj: &self.jtj - &o.jtj,
            jtr: &self.jtr - &o.jtr,
            rtr: self.rtr - o.rtr,
            floor,
        }
    }
}

impl Problem<'_> {
    /// Accumulate the normal equations in parallel (chunks of observations), without forming J.
    pub fn normal_equations(&self) -> Normal {
        let raw = self.grouped_sums(None).swap_remove(0);
        self.profiled(&raw)
    }

    /// The raw normal equations ([`RawNormal`]) of each group of observations: `groups` gives
    /// each observation's group (0..count); `None`, one group of all. One pass over the
    /// observations, in parallel chunks, summed in chunk order (the same result on every run);
    /// within a chunk, runs of four of one radius and group in lanes ([`Prepared::radiance_with_gradient_x4`]), the rest
    /// one at a time.
    pub fn grouped_sums(&self, groups: Option<(&[usize], usize)>) -> Vec<RawNormal> {
        let (p, dpdu) = from_unbounded(&self.u);
        let prepared = self.prepared(&Params::from_vec(&p));
        let free = self.free_idx();
        let n = free.len();
        let floor = self.floor;
        let count = groups.map_or(1, |g| g.1);
        // Per channel, the free parameters its residual can depend on (a channel's gradient row
        // is zero at the other channels' σ0 and albedo): their positions in `free`, ascending.
        let layout: [Vec<(usize, usize)>; 3] = std::array::from_fn(|c| {
            free.iter()
                .enumerate()
                .filter(|&(_, &k)| channel_exclusive(k).is_none_or(|o| o == c))
                .map(|(i, &k)| (i, k))
                .collect()
        });
        // Per channel and row entry: the model parameter and its dp/du.
        let rows = RowLayout {
            scale: std::array::from_fn(|c| {
                std::array::from_fn(|i| layout[c].get(i).map_or(0.0, |&(_, k)| dpdu[k]))
            }),
            cols: std::array::from_fn(|c| {
                std::array::from_fn(|i| layout[c].get(i).map_or(0, |&(_, k)| k))
            }),
            len: std::array::from_fn(|c| layout[c].len()),
        };
        let group_of = |i: usize| groups.map_or(0, |g| g.0[i]);
        let mut sums = self
            .obs
            .par_chunks(CHUNK)
            .enumerate()
            .map(|(ci, chunk)| {
                let mut acc: Vec<GroupSums> = (0..count).map(|_| GroupSums::new()).collect();
                let group = |i: usize| group_of(ci * CHUNK + i);
                let together = |i: usize| (1..4).all(|k| group(i + k) == group(i));
                walk_in_fours(&prepared, chunk, together, |i, step| match step {
                    Step::Four(four, eval) => {
                        let sums = acc[group(i)]
                            .four
                            .get_or_insert_with(|| Box::new(ChunkSums::new()));
                        add_four(sums, four, eval, &rows, floor);
                    }
                    Step::One(o) => add_one(&mut acc[group(i)].one, o, &prepared, &rows, floor),
                });
                acc.into_iter()
                    .map(|a| a.scatter(&layout, n, floor))
                    .collect::<Vec<_>>()
            })
            .collect::<Vec<_>>()
            .into_iter()
            .fold(
                (0..count)
                    .map(|_| RawNormal::zero(n, floor))
                    .collect::<Vec<_>>(),
                |total, chunk| {
                    total
                        .into_iter()
                        .zip(&chunk)
                        .map(|(t, c)| t.plus(c))
                        .collect()
                },
            );
        for s in &mut sums {
            for i in 0..n {
                for j in 0..i {
                    s.jtj[(j, i)] = s.jtj[(i, j)];
                }
            }
        }
        sums
    }

    /// The normal equations of the problem from raw sums of its observation rows: the dark floor
    /// profiled out (module doc) and the priors' rows added, at the current parameters.
    pub fn profiled(&self, raw: &RawNormal) -> Normal {
        let (p, dpdu) = from_unbounded(&self.u);
        let free = self.free_idx();
        let (mut jtj, mut jtr, mut rtr) = (raw.jtj.clone(), raw.jtr.clone(), raw.rtr);
        let sums = &raw.floor;
        if self.floor {
            for c in 0..3 {
                if sums.ww[c] > 0.0 {
                    let inv = 1.0 / sums.ww[c];
                    jtj -= &sums.wg[c] * sums.wg[c].transpose() * inv;
                    jtr -= &sums.wg[c] * (sums.wr[c] * inv);
                    rtr -= sums.wr[c] * sums.wr[c] * inv;
                }
            }
            rtr = rtr.max(0.0);
        }
        let mut rtr_prior = 0.0;
        for q in self.priors.iter().filter(|q| self.free[q.index]) {
            let r = (p[q.index] - q.mean) / q.std;
            let i = free.iter().position(|&k| k == q.index).expect("free");
            let g = dpdu[q.index] / q.std;
            jtj[(i, i)] += g * g;
            jtr[i] += g * r;
            rtr_prior += r * r;
        }
        let finite = rtr.is_finite() && jtj.iter().all(|v| v.is_finite());
        Normal {
            jtj,
            jtr,
            rtr_obs: rtr,
            rtr_prior,
            finite,
            floor: self.floor.then(|| sums.clone()),
        }
    }
}

impl Problem<'_> {
    /// How the optimum of every other free parameter follows the free parameters `given` when
    /// those are held elsewhere, at the current parameters on the observation rows of `raw`
    /// (with the priors; the floor profiled out): the rows of −H_oo⁻¹ H_og (unbounded units),
    /// each with its parameter's index. `None` where a `given` is not free or H_oo is singular.
    pub fn follows(&self, raw: &RawNormal, given: &[usize]) -> Option<Vec<(usize, Vec<f64>)>> {
        let free = self.free_idx();
        let g: Vec<usize> = given
            .iter()
            .map(|k| free.iter().position(|f| f == k))
            .collect::<Option<_>>()?;
        let others: Vec<usize> = (0..free.len()).filter(|i| !g.contains(i)).collect();
        let h = self.profiled(raw).jtj;
        let hoo = h.select_rows(&others).select_columns(&others);
        let hog = h.select_rows(&others).select_columns(&g);
        let slopes = -(hoo.try_inverse()? * hog);
        Some(
            others
                .iter()
                .enumerate()
                .map(|(r, &i)| (free[i], slopes.row(r).iter().copied().collect()))
                .collect(),
        )
    }
}

impl Problem<'_> {
    /// The Gauss–Newton step from the current parameters on the observation rows of `raw` (with
    /// the priors; the floor profiled out): the unbounded parameters after it, and the dark floor
    /// it implies (the floor's own step, f = −(wᵀr + wᵀJ·δ)/(wᵀw); 0 when the floor is known).
    /// `None` where the normal equations are singular or not finite.
    pub fn newton_step(&self, raw: &RawNormal) -> Option<([f64; N_PARAMS], [f64; 3])> {
        let ne = self.profiled(raw);
        if !ne.finite {
            return None;
        }
        let delta = ne.jtj.clone().cholesky()?.solve(&(-&ne.jtr));
        let mut u = self.u;
        for (i, k) in self.free_idx().into_iter().enumerate() {
            u[k] += delta[i];
        }
        let floor = if self.floor {
            let f = &raw.floor;
            [0, 1, 2].map(|c| {
                if f.ww[c] > 0.0 {
                    -(f.wr[c] + f.wg[c].dot(&delta)) / f.ww[c]
                } else {
                    0.0
                }
            })
        } else {
            [0.0; 3]
        };
        u.iter().all(|v| v.is_finite()).then_some((u, floor))
    }
}

/// One step of [`walk_in_fours`]: four observations with the model evaluated on them in lanes, or
/// one observation alone.
enum Step<'a> {
    Four(&'a [Obs], &'a Lanes4),
    One(&'a Obs),
}

/// Walk `obs` in order: each run of four from index i that `together(i)` allows and that
/// [`Prepared::radiance_with_gradient_x4`] takes goes to `f` as one [`Step::Four`], every other
/// observation as a [`Step::One`]; `f` is given the step's first index.
fn walk_in_fours(
    prepared: &Prepared,
    obs: &[Obs],
    together: impl Fn(usize) -> bool,
    mut f: impl FnMut(usize, Step),
) {
    let zero = f64x4::splat(0.0);
    let mut eval: Lanes4 = ([zero; 3], [[zero; N_PARAMS]; 3]);
    let mut i = 0;
    while i < obs.len() {
        let four = obs.get(i..i + 4).filter(|four| {
            together(i)
                && prepared
                    .radiance_with_gradient_x4(four_geometries(four), &mut eval)
                    .is_some()
        });
        if let Some(four) = four {
            f(i, Step::Four(four, &eval));
            i += 4;
        } else {
            f(i, Step::One(&obs[i]));
            i += 1;
        }
    }
}

/// The model's radiance and gradient at each of `obs`, in order ([`walk_in_fours`]: four at a
/// time in lanes where it can, else one at a time).
fn each_model(prepared: &Prepared, obs: &[Obs], mut f: impl FnMut(&Obs, &Rgb, &Gradient)) {
    walk_in_fours(
        prepared,
        obs,
        |_| true,
        |_, step| match step {
            Step::Four(four, (l, grad)) => {
                for (k, o) in four.iter().enumerate() {
                    let l = l.map(|v| v.lane(k));
                    let g = grad.map(|row| row.map(|v| v.lane(k)));
                    f(o, &l, &g);
                }
            }
            Step::One(o) => {
                let (l, g) = prepared.radiance_with_gradient(&o.geometry);
                f(o, &l, &g);
            }
        },
    );
}

/// The geometry of the first four of `obs`.
fn four_geometries(obs: &[Obs]) -> [&Geometry; 4] {
    [0, 1, 2, 3].map(|k| &obs[k].geometry)
}

/// One observation's weighted residuals and Jacobian rows into `sums`.
#[inline(always)]
fn add_one(sums: &mut ChunkSums<f64>, o: &Obs, prepared: &Prepared, rows: &RowLayout, floor: bool) {
    let (l, grad) = prepared.radiance_with_gradient(&o.geometry);
    let mut g = [0.0; MAX_ROW];
    for ch in 0..3 {
        let w = o.weight[ch];
        if w == 0.0 {
            continue;
        }
        let r = w * (l[ch] - o.radiance[ch]);
        let m = rows.row(ch, w, &grad[ch], &mut g);
        sums.add(ch, &g[..m], r, w, floor);
    }
}

/// [`add_one`] for four observations at once, from the model in lanes (`eval`); a channel left
/// out of an observation (weight 0) adds nothing in its lane.
#[inline(always)]
fn add_four(
    sums: &mut ChunkSums<f64x4>,
    obs: &[Obs],
    (l, grad): &Lanes4,
    rows: &RowLayout,
    floor: bool,
) {
    let zero = f64x4::splat(0.0);
    let mut g = [zero; MAX_ROW];
    for ch in 0..3 {
        let w = f64x4::from_lanes(|k| obs[k].weight[ch]);
        let off = w.eq(0.0);
        if <f64x4 as Real>::all(off) {
            continue;
        }
        let y = f64x4::from_lanes(|k| obs[k].radiance[ch]);
        let r = f64x4::select(off, zero, w * (l[ch] - y));
        let m = rows.row(ch, w, &grad[ch], &mut g);
        if <f64x4 as Real>::any(off) {
            for gi in &mut g[..m] {
                *gi = f64x4::select(off, zero, *gi);
            }
        }
        sums.add(ch, &g[..m], r, w, floor);
    }
}

/// Observations per parallel chunk of the normal equations.
const CHUNK: usize = 2048;

/// The same least-squares problem, reduced to n + 1 residuals: with JᵀJ = RᵀR (Cholesky), the
/// residuals r̃ = (R⁻ᵀJᵀr, √(rᵀr − ‖R⁻ᵀJᵀr‖²)) and the Jacobian (R; 0) have the same norm, the
/// same gradient Jᵀr and the same JᵀJ as the full problem, so Levenberg–Marquardt takes the same
/// steps — but its QR costs O(n³) instead of O(m·n²) and J (m × n) is never stored. The normal
/// equations are accumulated in parallel ([`Problem::normal_equations`]).
pub struct Reduced<'a> {
    pub problem: Problem<'a>,
    cache: Option<(DVector<f64>, DMatrix<f64>)>,
}

impl<'a> Reduced<'a> {
    pub fn new(problem: Problem<'a>) -> Self {
        let mut r = Reduced {
            problem,
            cache: None,
        };
        r.refresh();
        r
    }

    fn refresh(&mut self) {
        let ne = self.problem.normal_equations();
        let rtr = ne.rtr_obs + ne.rtr_prior;
        if let Some(h) = &self.problem.history {
            h.lock()
                .expect("history lock")
                .push(if ne.finite { 0.5 * rtr } else { f64::NAN });
        }
        if !ne.finite {
            self.cache = None;
            return;
        }
        let n = ne.jtr.len();
        let scale = (0..n)
            .map(|i| ne.jtj[(i, i)])
            .fold(0.0, f64::max)
            .max(1e-300);
        let mut ridge = 0.0;
        let chol = loop {
            let mut a = ne.jtj.clone();
            for i in 0..n {
                a[(i, i)] += ridge;
            }
            if let Some(c) = a.cholesky() {
                break Some(c);
            }
            ridge = if ridge == 0.0 {
                1e-14 * scale
            } else {
                ridge * 100.0
            };
            if ridge > 1e-4 * scale {
                break None;
            }
        };
        let Some(chol) = chol else {
            self.cache = None;
            return;
        };
        let l = chol.l();
        let r1 = l
            .solve_lower_triangular(&ne.jtr)
            .unwrap_or_else(|| DVector::zeros(n));
        let rest = (rtr - r1.norm_squared()).max(0.0).sqrt();
        let mut res = DVector::zeros(n + 1);
        res.rows_mut(0, n).copy_from(&r1);
        res[n] = rest;
        let mut jac = DMatrix::zeros(n + 1, n);
        jac.rows_mut(0, n).copy_from(&l.transpose());
        self.cache = Some((res, jac));
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Reduced<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.problem.set_params(x);
        self.refresh();
    }

    fn params(&self) -> DVector<f64> {
        LeastSquaresProblem::params(&self.problem)
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        self.cache.as_ref().map(|c| c.0.clone())
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        self.cache.as_ref().map(|c| c.1.clone())
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
        let ok = r.iter().all(|v| v.is_finite());
        if let Some(h) = &self.history {
            h.lock().expect("history lock").push(if ok {
                0.5 * r.norm_squared()
            } else {
                f64::NAN
            });
        }
        ok.then_some(r)
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
    /// ½ Σ r² at the solution (observations only, priors excluded), and the number of
    /// observation residuals.
    pub cost: f64,
    pub residuals: usize,
    pub evaluations: usize,
    pub termination: String,
    pub converged: bool,
    /// Cost at every residual evaluation, trial steps included.
    pub history: Vec<f64>,
    /// The dark floor, when it was profiled out ([`fit_with_floor`]).
    pub floor: Option<Floor>,
}

/// The observations less a dark floor per channel (the observations' units).
pub(crate) fn less_floor(obs: &[Obs], floor: [f64; 3]) -> Vec<Obs> {
    obs.iter()
        .map(|o| {
            let mut o = *o;
            for (v, f) in o.radiance.iter_mut().zip(&floor) {
                *v -= f;
            }
            o
        })
        .collect()
}

impl Fit {
    /// The floor to add to the model's radiance to predict the observations (0 when known).
    pub(crate) fn floor_value(&self) -> [f64; 3] {
        self.floor.map_or([0.0; 3], |f| f.value)
    }
}

/// Fit the free parameters from `start` (with priors on some of them).
pub fn fit(
    model: Model,
    obs: &[Obs],
    start: &Params,
    free: [bool; N_PARAMS],
    priors: &[Prior],
) -> Fit {
    fit_with_floor(model, obs, start, free, priors, false)
}

/// The Levenberg–Marquardt stopping tolerance (relative reduction of the cost, actual and
/// predicted, and relative size of the scaled step): 10⁻¹⁰ instead of the crate's 30ε ≈
/// 7·10⁻¹⁵, which spent the last third of each solve's evaluations on changes at rounding level.
/// A last step that lowers a cost of m residuals by 10⁻¹⁰ of itself moves the parameters by
/// √(2·10⁻¹⁰·m) standard errors (0.01 for the demo's 460 000), and the converging steps shrink
/// quadratically: the fits stopped at 10⁻¹⁰ differ from those at 30ε by at most 0.0005 formal
/// standard errors on the demo and the physically based sessions (docs/measurements/speed.md,
/// "Solve: fixed costs").
pub(crate) const LM_TOL: f64 = 1e-10;

/// [`fit`], with the observations' dark floor unknown when `floor` is set (profiled out; module
/// doc): [`Fit::floor`] then holds it.
pub fn fit_with_floor(
    model: Model,
    obs: &[Obs],
    start: &Params,
    free: [bool; N_PARAMS],
    priors: &[Prior],
    floor: bool,
) -> Fit {
    let problem = Problem {
        model,
        obs,
        free,
        u: to_unbounded(&start.to_vec()),
        priors: priors.to_vec(),
        history: Some(std::sync::Mutex::new(vec![])),
        floor,
    };
    let (reduced, report) = LevenbergMarquardt::new()
        .with_ftol(LM_TOL)
        .with_xtol(LM_TOL)
        .with_patience(200)
        .minimize(Reduced::new(problem));
    let problem = reduced.problem;
    let p = from_unbounded(&problem.u).0;
    let (std, correlation, cost, floor) = problem.covariance_and_floor();
    let m_obs = 3 * obs.len();
    let history = problem
        .history
        .map(|h| h.into_inner().unwrap_or_default())
        .unwrap_or_default();
    let finite = p.iter().all(|v| v.is_finite()) && cost.is_finite();
    Fit {
        params: Params::from_vec(&p),
        free,
        std,
        correlation,
        cost,
        residuals: m_obs,
        evaluations: report.number_of_evaluations,
        termination: format!("{:?}", report.termination),
        converged: report.termination.was_successful() && finite,
        history,
        floor,
    }
}

/// Robust weights of the Huber loss: residuals scaled by a robust σ (1.4826 × their median
/// absolute value); those beyond `k` σ get weight k/|r| (its square root multiplies the channel
/// weight). Returns the reweighted observations, how many channel residuals were down-weighted,
/// and whether any weight moved by more than 1% from `current`. `floor`: the fit's dark floor
/// (added to the model), 0 when it is known.
pub(crate) fn huber_weights(
    model: &Model,
    obs: &[Obs],
    current: &[Obs],
    p: &Params,
    floor: [f64; 3],
    k: f64,
) -> (Vec<Obs>, usize, bool) {
    let shifted = less_floor(obs, floor);
    let probe = Problem {
        model: *model,
        obs: &shifted,
        free: [false; N_PARAMS],
        u: to_unbounded(&p.to_vec()),
        priors: vec![],
        history: None,
        floor: false,
    };
    let (res, _) = probe.evaluate(false);
    let abs: Vec<f64> = res.iter().map(|r| r.abs()).filter(|r| *r > 0.0).collect();
    if abs.is_empty() {
        return (obs.to_vec(), 0, false);
    }
    let sigma = crate::stats::robust_sigma(abs);
    let mut changed = false;
    let mut down = 0;
    let next = obs
        .iter()
        .enumerate()
        .map(|(i, o)| {
            let mut o2 = *o;
            for c in 0..3 {
                let z = res[3 * i + c].abs() / sigma.max(1e-300);
                let w = if z > k {
                    down += 1;
                    (k / z).sqrt()
                } else {
                    1.0
                };
                o2.weight[c] = o.weight[c] * w;
                if (o2.weight[c] - current[i].weight[c]).abs() > 0.01 * o.weight[c].max(1e-300) {
                    changed = true;
                }
            }
            o2
        })
        .collect();
    (next, down, changed)
}

/// A fit with the Huber loss, by iteratively reweighted least squares around [`fit`]
/// ([`huber_weights`]), repeated from its own result until no weight changes by more than 1%
/// (at most `rounds` times). Returns the final fit, the observations with their final weights
/// and the number of down-weighted channel residuals. `floor`: as in [`fit_with_floor`].
#[allow(clippy::too_many_arguments)]
pub fn fit_robust(
    model: Model,
    obs: &[Obs],
    start: &Params,
    free: [bool; N_PARAMS],
    priors: &[Prior],
    floor: bool,
    k: f64,
    rounds: usize,
) -> (Fit, Vec<Obs>, usize) {
    let fit = |o: &[Obs], p: &Params| fit_with_floor(model, o, p, free, priors, floor);
    let mut current: Vec<Obs> = obs.to_vec();
    let mut f = fit(&current, start);
    let mut down = 0;
    for _ in 0..rounds {
        let (next, d, changed) =
            huber_weights(&model, obs, &current, &f.params, f.floor_value(), k);
        down = d;
        current = next;
        if !changed {
            break;
        }
        let mut history = std::mem::take(&mut f.history);
        let evaluations = f.evaluations;
        f = fit(&current, &f.params);
        history.extend(&f.history);
        f.history = history;
        f.evaluations += evaluations;
    }
    (f, current, down)
}
