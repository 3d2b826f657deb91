//! The CDRF tabulated for the solver's hot path: the wrapped f(θ; σ) with ∂f/∂θ and ∂f/∂σ from
//! a bicubic Hermite interpolant, whose derivatives are the exact derivatives of the interpolated
//! value (consistent, as Levenberg–Marquardt needs). The closed form ([`crate::model::cdrf`]) is
//! the reference it is built from and checked against (docs/model.md, "The tabulated CDRF").
//!
//! Coordinates: u = ln σ and τ = asinh((θ − π/2)/σ), both on uniform grids. τ puts the nodes
//! where f bends: a spacing of a few hundredths of σ at the terminator, where a narrow blur
//! rounds the clamped cosine's kink, growing to a few hundredths of a radian far from it. At
//! each node the table holds F = f, ∂F/∂τ, ∂F/∂u and ∂²F/∂τ∂u, from the closed form's value and
//! derivatives (the cross derivative by a central difference in u of the exact ∂F/∂τ).
//! Outside σ ∈ [[`SIGMA_MIN`], [`SIGMA_MAX`]] the closed form is evaluated instead.
//!
//! A fit evaluates f at a handful of widths (one per radius and channel) over many pixels: a
//! [`Slice`] is the table interpolated in u once, at one σ, leaving a cubic Hermite in τ whose
//! 513 nodes fit in the first-level cache — the same interpolant, summed in another order.

use crate::model::cdrf::{self, CdrfEval, Convolution};
use crate::model::lanes::Real;
use std::f64::consts::FRAC_PI_2;
use std::sync::OnceLock;

/// The blur widths tabulated (radians): σ0/r for σ0 ≥ 0.05 mm on spheres up to 50 mm, and wider
/// than the wrapped form needs (f is within 1e-7 of its constant mean beyond 4).
pub const SIGMA_MIN: f64 = 1e-3;
pub const SIGMA_MAX: f64 = 4.0;
/// Nodes in τ and in u (measured error: docs/model.md, "The tabulated CDRF").
const N_TAU: usize = 513;
const N_U: usize = 385;

/// The table: `nodes[j * N_TAU + i]` is [F, F_τ, F_u, F_τu] at (τ_i, u_j).
pub struct Table {
    nodes: Vec<[f64; 4]>,
    tau_max: f64,
    h_tau: f64,
    u_min: f64,
    h_u: f64,
}

/// The cubic Hermite basis on a cell at s ∈ [0, 1]: the weights of the two nodes' values and of
/// their slopes (in units of the cell), and the derivatives of both in s.
#[inline(always)]
fn hermite<T: Real>(s: T) -> ([T; 2], [T; 2], [T; 2], [T; 2]) {
    let s2 = s * s;
    let s3 = s2 * s;
    (
        [s3 * 2.0 - s2 * 3.0 + 1.0, -(s3 * 2.0) + s2 * 3.0],
        [s3 - s2 * 2.0 + s, s3 - s2],
        [s2 * 6.0 - s * 6.0, -(s2 * 6.0) + s * 6.0],
        [s2 * 3.0 - s * 4.0 + 1.0, s2 * 3.0 - s * 2.0],
    )
}

/// θ at (τ, u) and its derivatives ∂θ/∂τ and ∂θ/∂u.
fn theta_of(tau: f64, u: f64) -> (f64, f64, f64) {
    let sigma = u.exp();
    let (sh, ch) = (tau.sinh(), tau.cosh());
    (FRAC_PI_2 + sigma * sh, sigma * ch, sigma * sh)
}

/// F_τ at (τ, u) from the closed form.
fn f_tau(tau: f64, u: f64) -> f64 {
    let (theta, th_tau, _) = theta_of(tau, u);
    cdrf::eval(theta, u.exp(), Convolution::Wrapped).d_theta * th_tau
}

impl Table {
    /// Build the table (about 0.6 M closed-form evaluations), on scoped threads rather than
    /// rayon's pool: [`Table::shared`] is first called from inside rayon tasks, and an
    /// initialiser that waited on the pool whose workers wait on it would never finish.
    pub fn build() -> Table {
        let tau_max = (FRAC_PI_2 / SIGMA_MIN).asinh();
        let h_tau = 2.0 * tau_max / (N_TAU - 1) as f64;
        let u_min = SIGMA_MIN.ln();
        let h_u = (SIGMA_MAX.ln() - u_min) / (N_U - 1) as f64;
        let du = 1e-5;
        let node = |k: usize| -> [f64; 4] {
            let (i, j) = (k % N_TAU, k / N_TAU);
            let tau = -tau_max + i as f64 * h_tau;
            let u = u_min + j as f64 * h_u;
            let sigma = u.exp();
            let (theta, th_tau, th_u) = theta_of(tau, u);
            let e = cdrf::eval(theta, sigma, Convolution::Wrapped);
            let cross = (f_tau(tau, u + du) - f_tau(tau, u - du)) / (2.0 * du);
            [
                e.value,
                e.d_theta * th_tau,
                e.d_theta * th_u + e.d_sigma * sigma,
                cross,
            ]
        };
        let mut nodes = vec![[0.0; 4]; N_U * N_TAU];
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        let per = nodes.len().div_ceil(threads);
        std::thread::scope(|scope| {
            for (c, part) in nodes.chunks_mut(per).enumerate() {
                let node = &node;
                scope.spawn(move || {
                    for (k, slot) in part.iter_mut().enumerate() {
                        *slot = node(c * per + k);
                    }
                });
            }
        });
        Table {
            nodes,
            tau_max,
            h_tau,
            u_min,
            h_u,
        }
    }

    /// The table every caller shares, built on first use.
    pub fn shared() -> &'static Table {
        static TABLE: OnceLock<Table> = OnceLock::new();
        TABLE.get_or_init(Table::build)
    }

    /// The table at one width σ ([`Slice`]); `None` outside the tabulated σ.
    pub fn slice(&self, sigma: f64) -> Option<Slice> {
        if !(SIGMA_MIN..=SIGMA_MAX).contains(&sigma) {
            return None;
        }
        let y = (sigma.ln() - self.u_min) / self.h_u;
        let j = (y as usize).min(N_U - 2);
        let (ht, gt, dht, dgt) = hermite(y - j as f64);
        let (a, b) = (self.h_tau, self.h_u);
        let nodes = (0..N_TAU)
            .map(|i| {
                // Per τ node: the value and its τ-slope (in units of the cell, ·h_τ) interpolated
                // in u, and the same of their u-derivative (in units of the cell, ·h_u).
                let mut out = [0.0; 4];
                for cj in 0..2 {
                    let n = &self.nodes[(j + cj) * N_TAU + i];
                    let (f, ft, fu, ftu) = (n[0], n[1] * a, n[2] * b, n[3] * a * b);
                    out[0] += f * ht[cj] + fu * gt[cj];
                    out[1] += ft * ht[cj] + ftu * gt[cj];
                    out[2] += f * dht[cj] + fu * dgt[cj];
                    out[3] += ft * dht[cj] + ftu * dgt[cj];
                }
                out
            })
            .collect();
        Some(Slice {
            sigma,
            nodes,
            inv_sigma: 1.0 / sigma,
            tau_max: self.tau_max,
            inv_h_tau: 1.0 / a,
            inv_h_u: 1.0 / b,
        })
    }

    /// f, ∂f/∂θ and ∂f/∂σ (∂²f/∂θ² as (∂f/∂σ)/σ, the diffusion equation's) at θ ∈ [0, π]; the
    /// closed form outside the tabulated σ.
    pub fn eval(&self, theta: f64, sigma: f64) -> CdrfEval {
        if !(SIGMA_MIN..=SIGMA_MAX).contains(&sigma)
            || !(0.0..=std::f64::consts::PI).contains(&theta)
        {
            return cdrf::eval(theta, sigma, Convolution::Wrapped);
        }
        let u = sigma.ln();
        let z = (theta - FRAC_PI_2) / sigma;
        let r = (z * z + 1.0).sqrt();
        // asinh z, as ln(|z| + √(z² + 1)) with z's sign (std's asinh guards precision this
        // coordinate does not need, at several times the cost).
        let tau = (z.abs() + r).ln().copysign(z);
        // ∂τ/∂θ = 1/(σ√(1+z²)), ∂τ/∂σ = −z/(σ√(1+z²)).
        let tau_theta = 1.0 / (sigma * r);
        let tau_sigma = -z * tau_theta;
        let x = (tau + self.tau_max) / self.h_tau;
        let y = (u - self.u_min) / self.h_u;
        let i = (x as usize).min(N_TAU - 2);
        let j = (y as usize).min(N_U - 2);
        let (s, t) = (x - i as f64, y - j as f64);
        // Cubic Hermite bases in s and in t.
        let (hs, gs, dhs, dgs) = hermite(s);
        let (ht, gt, dht, dgt) = hermite(t);
        let (a, b) = (self.h_tau, self.h_u);
        let (mut v, mut v_s, mut v_t) = (0.0, 0.0, 0.0);
        for cj in 0..2 {
            let row = &self.nodes[(j + cj) * N_TAU + i..(j + cj) * N_TAU + i + 2];
            // Per row: the node values and u-slopes interpolated in s, and their s-derivatives.
            let (mut f, mut fu, mut f_s, mut fu_s) = (0.0, 0.0, 0.0, 0.0);
            for ci in 0..2 {
                let n = &row[ci];
                let (ft, ftu) = (n[1] * a, n[3] * a);
                f += n[0] * hs[ci] + ft * gs[ci];
                fu += n[2] * hs[ci] + ftu * gs[ci];
                f_s += n[0] * dhs[ci] + ft * dgs[ci];
                fu_s += n[2] * dhs[ci] + ftu * dgs[ci];
            }
            let (fu, fu_s) = (fu * b, fu_s * b);
            v += f * ht[cj] + fu * gt[cj];
            v_s += f_s * ht[cj] + fu_s * gt[cj];
            v_t += f * dht[cj] + fu * dgt[cj];
        }
        // Back to θ and σ: ∂/∂τ = (∂/∂s)/h_τ, ∂/∂u = (∂/∂t)/h_u, u = ln σ.
        let (f_tau, f_u) = (v_s / a, v_t / b);
        let d_theta = f_tau * tau_theta;
        let d_sigma = f_tau * tau_sigma + f_u / sigma;
        CdrfEval {
            value: v,
            d_theta,
            d2_theta: d_sigma / sigma,
            d_sigma,
        }
    }
}

/// The table at one blur width σ ([`Table::slice`]): per τ node, the bicubic interpolant's value
/// and τ-slope already interpolated in u, and their u-derivatives. [`Slice::eval`] is then the
/// cubic in τ of [`Table::eval`] at that σ, the same function to rounding.
pub struct Slice {
    /// The width it holds (radians).
    pub sigma: f64,
    /// `nodes[i]` = [F, h_τ·F_τ, h_u·F_u, h_τ·h_u·F_τu] at τ_i, interpolated to σ in u.
    nodes: Vec<[f64; 4]>,
    inv_sigma: f64,
    tau_max: f64,
    inv_h_tau: f64,
    inv_h_u: f64,
}

impl Slice {
    /// [`Table::eval`] at (θ, [`Slice::sigma`]): f, ∂f/∂θ, ∂²f/∂θ² (as (∂f/∂σ)/σ) and ∂f/∂σ; the
    /// closed form outside θ ∈ [0, π].
    #[inline]
    pub fn eval(&self, theta: f64) -> CdrfEval {
        if !(0.0..=std::f64::consts::PI).contains(&theta) {
            return cdrf::eval(theta, self.sigma, Convolution::Wrapped);
        }
        self.eval_in(theta)
    }

    /// [`Slice::eval`] on one pixel or four ([`Real`]) whose θ all lie in [0, π].
    #[inline(always)]
    pub fn eval_in<T: Real>(&self, theta: T) -> CdrfEval<T> {
        // As Table::eval, with the divisions by σ and the node spacings as multiplications.
        let z = (theta - FRAC_PI_2) * self.inv_sigma;
        let r = (z * z + 1.0).sqrt();
        let tau = (z.abs() + r).ln().copysign(z);
        let tau_theta = T::splat(self.inv_sigma) / r;
        let tau_sigma = -z * tau_theta;
        let x = (tau + self.tau_max) * self.inv_h_tau;
        let cell: [usize; 4] = std::array::from_fn(|k| {
            if k < T::LANES {
                (x.lane(k) as usize).min(N_TAU - 2)
            } else {
                0
            }
        });
        let (hs, gs, dhs, dgs) = hermite(x - T::from_lanes(|k| cell[k] as f64));
        let node = |o: usize, e: usize| T::from_lanes(|k| self.nodes[cell[k] + o][e]);
        let (n00, n01, n02, n03) = (node(0, 0), node(0, 1), node(0, 2), node(0, 3));
        let (n10, n11, n12, n13) = (node(1, 0), node(1, 1), node(1, 2), node(1, 3));
        let v = n00 * hs[0] + n01 * gs[0] + n10 * hs[1] + n11 * gs[1];
        let v_s = n00 * dhs[0] + n01 * dgs[0] + n10 * dhs[1] + n11 * dgs[1];
        let v_t = n02 * hs[0] + n03 * gs[0] + n12 * hs[1] + n13 * gs[1];
        let (f_tau, f_u) = (v_s * self.inv_h_tau, v_t * self.inv_h_u);
        let d_theta = f_tau * tau_theta;
        let d_sigma = f_tau * tau_sigma + f_u * self.inv_sigma;
        CdrfEval {
            value: v,
            d_theta,
            d2_theta: d_sigma * self.inv_sigma,
            d_sigma,
        }
    }
}
